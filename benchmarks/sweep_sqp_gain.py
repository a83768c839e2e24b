"""What ``FovConfig.sqp_min_gain`` trades: ``plan()`` CPU time against the visibility of the plan.

    python benchmarks/sweep_sqp_gain.py [--perches 600] [--gains 0 0.002 0.005 0.01]

Plans the same random perches (incline 20-100 deg, 1.2-8 m ahead, heights 1-2.5 m, lateral
offsets up to 1.5 m, seeded) once per threshold and prints the median / p95 / p99 CPU time of
``plan_detailed``, the scored SQP steps, and against the first threshold how many plans changed
status and how much their visibility (the mean of the time and path fractions on the SQP's
200-sample grid, ``avp.perception._SCORE_GRID``) moved.
"""

from __future__ import annotations

import argparse
import math
import time
from dataclasses import replace

import numpy as np

import avp
from avp.metrics import visibility
from avp.perception import _SCORE_GRID


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--perches", type=int, default=600)
    ap.add_argument("--gains", type=float, nargs="+", default=[0.0, 0.002, 0.005, 0.01])
    ap.add_argument("--seed", type=int, default=11)
    args = ap.parse_args()
    rng = np.random.default_rng(args.seed)
    cases = []
    for _ in range(args.perches):
        inc, d, z, y = rng.uniform(20, 100), rng.uniform(1.2, 8.0), rng.uniform(1.0, 2.5), rng.uniform(-1.5, 1.5)
        state = avp.State.hover([0.0, 0.0, z + rng.uniform(-0.8, 0.8)])
        cases.append((state, avp.PerchTarget.from_incline([d, y, z], math.radians(inc))))
    results: dict[float, tuple[np.ndarray, list[str]]] = {}
    for gain in args.gains:
        cfg = avp.PlannerConfig()
        cfg = replace(cfg, fov=replace(cfg.fov, sqp_min_gain=gain))
        vis, cpu, status, steps = [], [], [], 0
        for state, target in cases:
            try:
                c0 = time.thread_time()
                result = avp.plan_detailed(state, target, cfg)
                cpu.append(time.thread_time() - c0)
            except avp.AvpError as exc:
                vis.append(math.nan)
                status.append(type(exc).__name__)
                continue
            status.append(result.status.name)
            traj = result.trajectory
            if traj is None:
                vis.append(math.nan)
                continue
            v = visibility(traj, target, cfg.fov.camera, dt=traj.duration / _SCORE_GRID)
            vis.append((v.time_fraction + v.path_fraction) / 2)
            steps += sum(1 for line in result.log if line.startswith("SQP step") and "visibility" in line)
        ms = np.array(cpu) * 1e3
        print(f"sqp_min_gain {gain:g}: CPU median {np.median(ms):.3f}, p95 {np.percentile(ms, 95):.3f}, "
              f"p99 {np.percentile(ms, 99):.3f} ms; {steps} scored SQP steps")
        results[gain] = (np.array(vis), status)
    base_vis, base_status = results[args.gains[0]]
    for gain in args.gains[1:]:
        vis, status = results[gain]
        d = vis - base_vis
        d = d[np.isfinite(d)]
        if d.size == 0:
            print(f"sqp_min_gain {gain:g}: no plan to compare")
            continue
        same = sum(a == b for a, b in zip(status, base_status, strict=True))
        print(f"sqp_min_gain {gain:g} against {args.gains[0]:g}: same status {same}/{len(cases)}; visibility "
              f"(points) mean {d.mean() * 100:+.3f}, lowest {d.min() * 100:+.2f}, lower in {int(np.sum(d < -1e-9))}, "
              f"by more than half a point in {int(np.sum(d < -0.005))}")


if __name__ == "__main__":
    main()
