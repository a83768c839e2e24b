"""Soundness sweep of the body-rate certificate (issue 8, item 7): random perches with moving
starts (up to 5 m/s), any yaw, yaw rates up to 5 rad/s, inclines 0-180 deg and pads with a
custom up-slope, planned with ``VehicleLimits(body_rate_max=14)``. For every plan returned as
certified, the true body rate is recomputed independently (Euler-angle attitude from scipy,
differentiated numerically on a 0.5 ms grid) and compared with the limit.

    python benchmarks/sweep_body_rate.py [--n 200] [--seed 0]

Prints how many plans were certified, the largest true/limit ratio among them, the status
counts and plan() median / p95. Run from the checkout (it imports tests/oracles.py).
"""

from __future__ import annotations

import argparse
import collections
import math
import sys
import time
from pathlib import Path

import numpy as np

import avp

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from oracles import body_rate_norm_numeric


def request(rng: np.random.Generator) -> tuple[avp.State, avp.PerchTarget]:
    heading = rng.uniform(-math.pi, math.pi)
    h = np.array([math.cos(heading), math.sin(heading), 0.0])
    start = np.array([0.0, 0.0, 2.0])
    while True:
        pad = start + rng.uniform(1.5, 6.0) * h + [0.0, 0.0, rng.uniform(-1.0, 1.0)]
        incline = rng.uniform(0.0, math.pi)
        normal = math.cos(incline) * np.array([0.0, 0.0, 1.0]) - math.sin(incline) * h
        if rng.random() < 0.5:
            target = avp.PerchTarget.from_incline(pad, incline, heading)
        else:
            up = rng.uniform(-1.0, 1.0, 3)
            if np.linalg.norm(np.cross(up, normal)) < 0.1:
                continue
            target = avp.PerchTarget.from_normal(pad, normal, up_slope=up)
        if (start - pad) @ target.s3 > 0.2:
            break
    v = rng.normal(size=3)
    v *= rng.uniform(0.0, 5.0) / np.linalg.norm(v)
    return avp.State(position=start, velocity=v, yaw=rng.uniform(-math.pi, math.pi),
                     yaw_rate=rng.uniform(-5.0, 5.0)), target


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=200)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--limit", type=float, default=14.0)
    args = ap.parse_args()
    rng = np.random.default_rng(args.seed)
    config = avp.PlannerConfig(limits=avp.VehicleLimits(body_rate_max=args.limit))
    statuses: collections.Counter[str] = collections.Counter()
    times, ratios = [], []
    for _ in range(args.n):
        state, target = request(rng)
        t0 = time.perf_counter()
        try:
            result = avp.plan_detailed(state, target, config)
        except avp.ConfigError as exc:
            statuses[f"ConfigError({exc.field})"] += 1
            continue
        times.append(time.perf_counter() - t0)
        statuses[result.status.name] += 1
        if result.ok and result.bounds is not None and result.bounds.certified:
            _, w = body_rate_norm_numeric(result.trajectory)
            ratios.append(float(w.max()) / args.limit)
    print(f"{args.n} requests, body_rate_max = {args.limit} rad/s: {len(ratios)} certified; "
          f"max true/limit among them {max(ratios, default=float('nan')):.3f}")
    print("statuses:", dict(statuses))
    print(f"plan_detailed: median {1e3 * np.median(times):.1f} ms, p95 {1e3 * np.percentile(times, 95):.1f} ms")


if __name__ == "__main__":
    main()
