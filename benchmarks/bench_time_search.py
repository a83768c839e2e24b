"""The time searches compared on tight vehicle limits: statuses, solves per plan, CPU time.

    python benchmarks/bench_time_search.py [--random 60] [--seed 5]

Runs every search (:class:`avp.TimeSearch`: SCALING, the default; BIDIRECTIONAL, the fixed
factor list; PAPER) on

* the tight-limit grid of the tests: the 12 standard scenarios (inclines 0-90 deg, stand-offs
  1.5 / 3.5 / 7.5 m) under two limit sets (thrust 2-13 m/s^2, thrust rate 60 m/s^3, tilt rate
  4 rad/s; and Gao et al.'s thrust 5-17 m/s^2, rate 3 rad/s);
* ``--random`` requests drawn as in ``tests/test_bounds_planner.py`` (incline 0-90 deg, 1.5-7.5 m,
  thrust min 0.5-3.5 and max 12-20 m/s^2, tilt rate 3-10 rad/s).

Prints, per search and set, the status counts, the mean and max of the durations tried per plan
and the median / mean CPU time of ``plan_detailed`` (``time.thread_time``), then every request
whose status or number of relaxations differs from SCALING's. Nothing is asserted.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections import Counter
from dataclasses import replace
from pathlib import Path

import numpy as np

import avp

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
from scenarios import standard_grid

TIGHT = avp.VehicleLimits(mass=0.5, thrust_min=0.5 * 2.0, thrust_max=0.5 * 13.0, thrust_rate_max=0.5 * 60.0,
                          tilt_rate_max=4.0)
GAO = avp.VehicleLimits(mass=1.0, thrust_min=5.0, thrust_max=17.0, tilt_rate_max=3.0)


def grid_cases() -> list[tuple[str, avp.State, avp.PerchTarget, avp.VehicleLimits]]:
    return [(f"{s.name} {label}", s.state, s.target, lim)
            for label, lim in (("tight", TIGHT), ("gao", GAO)) for s in standard_grid()]


def random_cases(n: int, seed: int) -> list[tuple[str, avp.State, avp.PerchTarget, avp.VehicleLimits]]:
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        incline = rng.uniform(0.0, math.pi / 2)
        distance = rng.uniform(1.5, 7.5)
        pad = np.array([0.0, 0.0, 2.0])
        target = avp.PerchTarget.from_incline(pad, incline)
        start = pad - np.array([distance, 0.0, 0.0]) + np.array([0.0, rng.uniform(-1, 1), rng.uniform(-0.5, 1.0)])
        if (start - pad) @ target.s3 < 0.1:
            start[2] = pad[2] + 0.1 + rng.uniform(0.0, 1.0)
        limits = avp.VehicleLimits(mass=1.0, thrust_min=rng.uniform(0.5, 3.5), thrust_max=rng.uniform(12.0, 20.0),
                                   tilt_rate_max=rng.uniform(3.0, 10.0))
        out.append((f"random {i}", avp.State.hover(start), target, limits))
    return out


def run(cases, search: avp.TimeSearch) -> list[tuple[str, str, int, int, float]]:
    rows = []
    for name, state, target, limits in cases:
        cfg = avp.PlannerConfig(limits=limits)
        cfg = replace(cfg, bounds=replace(cfg.bounds, time_search=search))
        c0 = time.thread_time()
        try:
            r = avp.plan_detailed(state, target, cfg)
            rows.append((name, r.status.name, len(r.relaxations), r.duration_scale_steps + 1, time.thread_time() - c0))
        except avp.ConfigError as exc:
            rows.append((name, f"ConfigError({exc.field})", 0, 0, time.thread_time() - c0))
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--random", type=int, default=60)
    ap.add_argument("--seed", type=int, default=5)
    args = ap.parse_args()
    sets = {"tight-limit grid": grid_cases(), f"{args.random} random requests": random_cases(args.random, args.seed)}
    for label, cases in sets.items():
        run(cases[:2], avp.TimeSearch.SCALING)  # first calls (imports, caches) are not measured
        results = {s: run(cases, s) for s in avp.TimeSearch}
        print(f"{label} ({len(cases)} requests)")
        print(f"  {'search':<14} {'durations/plan':>15} {'max':>4} {'CPU median ms':>14} {'CPU mean ms':>12}  statuses")
        for s, rows in results.items():
            solves = [r[3] for r in rows]
            cpu = np.array([r[4] for r in rows]) * 1e3
            counts = dict(Counter(r[1] for r in rows))
            print(f"  {s.name:<14} {np.mean(solves):>15.2f} {max(solves):>4} {np.median(cpu):>14.2f} {cpu.mean():>12.2f}  {counts}")
        base = results[avp.TimeSearch.SCALING]
        for s, rows in results.items():
            for a, b in zip(base, rows, strict=True):
                if a[1:3] != b[1:3]:
                    print(f"  differs: {a[0]}: SCALING {a[1]} ({a[2]} relaxed), {s.name} {b[1]} ({b[2]} relaxed)")


if __name__ == "__main__":
    main()
