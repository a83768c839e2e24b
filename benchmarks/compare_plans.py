"""Whether two versions of the code plan the same, to rounding: first plans of a seeded corpus.

    python benchmarks/compare_plans.py --save before.npz [--perches 600]
    python benchmarks/compare_plans.py --compare before.npz

A speed change that moves floating-point operations (a kernel summing in another order than
BLAS) changes plans in the last bits, so ``bench_rounds.py``'s digests differ; this says by how
much and whether any decision moved. The corpus: the 12 standard scenarios of ``bench_plan.py``,
Gao et al.'s 30/60/90 deg perches (``bench_rounds.py``), and ``--perches`` random perches
(incline 20-100 deg, 1.2-8 m ahead, heights 1-2.5 m, lateral offsets up to 1.5 m, seeded as in
``sweep_sqp_gain.py``), the standard and random perches each planned with the default
configuration and with rotor drag (``VehicleLimits(rotor_drag=0.3)``), Gao et al.'s with their
tight limits. Per plan it keeps the status (or the error's type), the
log with its numbers masked (the decisions: durations tried, SQP steps, points placed,
relaxations, certificates), the visibility of its SQP score and the coefficients.

``--compare`` prints how many plans have the same status and decisions, the largest coefficient
difference relative to the plan's largest coefficient, and the largest visibility change, and
lists the plans whose decisions differ (with the first differing log line). Nothing is asserted.
"""

from __future__ import annotations

import argparse
import math
import re
from dataclasses import replace

import numpy as np
from bench_plan import scenarios
from bench_rounds import GAO

import avp
from avp.metrics import visibility
from avp.perception import _SCORE_GRID

_NUMBER = re.compile(r"[-+]?\d+\.?\d*(?:e[-+]?\d+)?")


def corpus(perches: int, seed: int) -> list[tuple[str, avp.State, avp.PerchTarget, avp.PlannerConfig]]:
    base = avp.PlannerConfig()
    drag = replace(base, limits=replace(base.limits, rotor_drag=0.3))
    cases: list[tuple[str, avp.State, avp.PerchTarget, avp.PlannerConfig]] = []
    for i, (s, t) in enumerate(scenarios()):
        cases.append((f"standard {i}", s, t, base))
    for incline in (30, 60, 90):
        cases.append((f"Gao {incline}", avp.State.hover([0.0, 0.0, 1.5]),
                      avp.PerchTarget.from_incline([3.0, 0.0, 1.5], math.radians(incline)), avp.PlannerConfig(limits=GAO)))
    rng = np.random.default_rng(seed)
    for j in range(perches):
        inc, d, z, y = rng.uniform(20, 100), rng.uniform(1.2, 8.0), rng.uniform(1.0, 2.5), rng.uniform(-1.5, 1.5)
        state = avp.State.hover([0.0, 0.0, z + rng.uniform(-0.8, 0.8)])
        cases.append((f"random {j}", state, avp.PerchTarget.from_incline([d, y, z], math.radians(inc)), base))
    return cases + [(f"{name}, drag 0.3", s, t, drag) for name, s, t, c in cases if c is base]


def run(perches: int, seed: int) -> dict[str, dict[str, object]]:
    out: dict[str, dict[str, object]] = {}
    for name, state, target, cfg in corpus(perches, seed):
        try:
            result = avp.plan_detailed(state, target, cfg)
        except avp.AvpError as exc:
            out[name] = {"status": type(exc).__name__, "log": "", "coeffs": np.zeros(0), "vis": math.nan}
            continue
        traj = result.trajectory
        vis = math.nan
        coeffs = np.zeros(0)
        if traj is not None:
            coeffs = traj.coefficients.ravel()
            v = visibility(traj, target, cfg.fov.camera, dt=traj.duration / _SCORE_GRID, rotor_drag=cfg.limits.rotor_drag)
            vis = (v.time_fraction + v.path_fraction) / 2
        masked = "\n".join(_NUMBER.sub("#", line) for line in result.log)
        out[name] = {"status": result.status.name, "log": masked, "coeffs": coeffs, "vis": vis}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--perches", type=int, default=600)
    ap.add_argument("--seed", type=int, default=11)
    ap.add_argument("--save", help="write this version's plans to this .npz file")
    ap.add_argument("--compare", help="compare this version's plans with a file written by --save")
    args = ap.parse_args()
    mine = run(args.perches, args.seed)
    if args.save:
        flat: dict[str, object] = {}
        for name, rec in mine.items():
            for key, val in rec.items():
                flat[f"{name}|{key}"] = np.asarray(val)
        np.savez_compressed(args.save, **flat)  # type: ignore[arg-type]
        print(f"{len(mine)} plans written to {args.save}")
    if not args.compare:
        return
    with np.load(args.compare) as data:
        ref: dict[str, dict[str, object]] = {}
        for key in data.files:
            name, field = key.split("|")
            ref.setdefault(name, {})[field] = data[key]
    both = [n for n in mine if n in ref]
    same_status = [n for n in both if str(ref[n]["status"]) == mine[n]["status"]]
    same_log = [n for n in same_status if str(ref[n]["log"]) == mine[n]["log"]]
    rel, dvis = [], []
    for n in same_log:
        a, b = np.asarray(mine[n]["coeffs"]), np.asarray(ref[n]["coeffs"])
        if a.size and a.shape == b.shape:
            rel.append(float(np.max(np.abs(a - b)) / max(float(np.max(np.abs(b))), 1e-300)))
            dvis.append(abs(float(mine[n]["vis"]) - float(ref[n]["vis"])))
    print(f"compared with {args.compare}: {len(both)} plans in both; same status {len(same_status)}; "
          f"same status and decisions (log, numbers masked) {len(same_log)}")
    if rel:
        r = np.array(rel)
        worst = [n for n in same_log if np.asarray(mine[n]["coeffs"]).size][int(np.argmax(r))]
        print(f"  coefficients, largest difference over the plan's largest coefficient: median {np.median(r):.1e}, "
              f"max {r.max():.1e} ({worst}); bit for bit {int(np.sum(r == 0.0))} of {r.size}")
        print(f"  visibility (SQP score grid), largest change {max(dvis):.1e}")
    for n in [n for n in both if n not in same_log][:20]:
        old, new = str(ref[n]["log"]).splitlines(), str(mine[n]["log"]).splitlines()
        first = next((i for i, (x, y) in enumerate(zip(old, new, strict=False)) if x != y), min(len(old), len(new)))
        print(f"  {n}: status {ref[n]['status']} -> {mine[n]['status']}; first different line {first}:")
        print(f"    before: {old[first] if first < len(old) else '(none)'}")
        print(f"    now:    {new[first] if first < len(new) else '(none)'}")


if __name__ == "__main__":
    main()
