"""Workspace safety sweep: how many varied perches plan with every certificate, which status the
rest end with, how many returned paths would have gone through the pad's plane or the ground
without the workspace rows, and ``plan()`` latency with the rows against without them, measured
interleaved in one run.

    python benchmarks/bench_safety.py [--scenarios 240] [--seed 0] [--repeats 3]

Scenarios: inclines 0-180 deg, stand-offs 1-8 m along the pad's normal, lateral and height
offsets, starts on the outward side and at least 0.3 m above a ground at z = 0, some moving (up to
3 m/s) with yaw offsets. Every returned trajectory is also checked on a 0.5 ms grid (independent
of the certificate). Timings are wall-clock on this machine; nothing here is asserted.
"""

from __future__ import annotations

import argparse
import math
import time
from collections import Counter

import numpy as np

import avp

GRID = 5e-4


def scenarios(n: int, seed: int) -> list[tuple[float, avp.State, avp.PerchTarget]]:
    rng = np.random.default_rng(seed)
    out = []
    while len(out) < n:
        inc = float(rng.uniform(0.0, 180.0)) if len(out) % 10 else float(rng.choice([0.0, 90.0, 180.0]))
        target = avp.PerchTarget.from_incline([0.0, 0.0, 3.5], math.radians(inc))
        stand = rng.uniform(1.0, 8.0)
        p0 = target.point + stand * target.s3 + rng.uniform(-2, 2) * target.s2 + rng.uniform(-1, 1.5) * np.array([0, 0, 1.0])
        if p0[2] < 0.3 or (p0 - target.point) @ target.s3 < 0.5:
            continue
        moving = rng.random() < 0.4
        v0 = rng.uniform(0, 3.0) * np.append(rng.normal(size=2), 0.0) if moving else np.zeros(3)
        v0 = v0 / max(np.linalg.norm(v0), 1e-9) * min(np.linalg.norm(v0), 3.0) if moving else v0
        yaw = float(rng.uniform(-math.pi, math.pi)) if moving else 0.0
        out.append((inc, avp.State(position=p0, velocity=v0, yaw=yaw), target))
    return out


def crossings(traj: avp.Trajectory, target: avp.PerchTarget) -> tuple[float, float]:
    """Smallest clearance from the pad's plane and the ground before contact (m), sampled."""
    ts = np.arange(traj.t0, traj.tf, GRID)
    p = traj(ts)
    return float(((p - target.point) @ target.s3).min()), float(p[:, 2].min())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenarios", type=int, default=240)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    cases = scenarios(args.scenarios, args.seed)
    safe = avp.PlannerConfig(workspace=avp.Workspace(ground_z=0.0))
    unsafe = avp.PlannerConfig(workspace=avp.Workspace(perch_clearance=False))
    legacy = avp.PlannerConfig(alpha=4.0, workspace=avp.Workspace(perch_clearance=False))  # before the safety work
    statuses: Counter[str] = Counter()
    by_band: dict[str, Counter[str]] = {}
    through_before = 0
    solved_before = 0
    through_legacy = 0
    solved_legacy = 0
    violations_after = 0
    t_safe: list[float] = []
    t_unsafe: list[float] = []
    solves: list[int] = []
    for inc, state, target in cases:
        band = "0-30" if inc < 30 else "30-90" if inc <= 90 else "90-150" if inc < 150 else "150-180"
        for _ in range(args.repeats):  # interleaved: same case, both configurations
            t0 = time.perf_counter()
            r_unsafe = avp.plan_detailed(state, target, unsafe)
            t_unsafe.append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            r = avp.plan_detailed(state, target, safe)
            t_safe.append(time.perf_counter() - t0)
        r_legacy = avp.plan_detailed(state, target, legacy)
        if r_legacy.ok and r_legacy.trajectory is not None:
            solved_legacy += 1
            clear, zmin = crossings(r_legacy.trajectory, target)
            through_legacy += clear <= 0.0 or zmin <= 0.0
        statuses[r.status.name] += 1
        by_band.setdefault(band, Counter())[r.status.name] += 1
        solves.append(r.duration_scale_steps + 1)
        if r_unsafe.ok and r_unsafe.trajectory is not None:
            solved_before += 1
            clear, zmin = crossings(r_unsafe.trajectory, target)
            through_before += clear <= 0.0 or zmin <= 0.0
        if r.ok and r.trajectory is not None:
            clear, zmin = crossings(r.trajectory, target)
            violations_after += clear <= 0.0 or zmin <= 0.0
    n = len(cases)
    print(f"{n} scenarios (seed {args.seed}), ground at z = 0")
    print("status with the workspace rows and certificates:")
    for name, count in statuses.most_common():
        print(f"  {name:<26} {count:4d}  ({100 * count / n:.1f} %)")
    print("by incline band (deg):")
    for band in ("0-30", "30-90", "90-150", "150-180"):
        c = by_band.get(band, Counter())
        total = sum(c.values())
        ok = c["SOLVED"] + c["SOLVED_WITHOUT_FOV"]
        print(f"  {band:<8} {total:4d} cases: solved {ok}, relaxed {c['SOLVED_RELAXED']}, "
              f"other {total - ok - c['SOLVED_RELAXED']}")
    print(f"without the rows (perch clearance off, no ground): {solved_before} plans returned, "
          f"{through_before} of them cross the pad's plane or the ground on a 0.5 ms grid")
    print(f"the previous release's behaviour (alpha = 4, no rows): {solved_legacy} plans returned, "
          f"{through_legacy} of them cross the pad's plane or the ground")
    print(f"with the rows: {violations_after} returned plans cross either (must be 0)")
    ms = lambda x: np.percentile(np.asarray(x) * 1e3, [50, 95, 99])  # noqa: E731
    a, b = ms(t_unsafe), ms(t_safe)
    print(f"plan_detailed latency (ms)    median    p95     p99   ({args.repeats} repeats per case, interleaved)")
    print(f"  without workspace rows      {a[0]:7.2f} {a[1]:7.2f} {a[2]:7.2f}")
    print(f"  with workspace rows         {b[0]:7.2f} {b[1]:7.2f} {b[2]:7.2f}   median ratio {b[0] / a[0]:.2f}")
    print(f"solves per plan with rows: median {np.median(solves):.0f}, max {max(solves)}")


if __name__ == "__main__":
    main()
