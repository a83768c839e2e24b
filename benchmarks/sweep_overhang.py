"""Overhangs and ceilings: 54 perches at inclines 100-180 deg, stand-offs 2/3/5 m,
starts at rest 1.5/3/4 m below the pad, default limits; how many plan SOLVED (every certificate,
nothing relaxed) with the overhang rows (`avp.OverhangFlip`), without them, and with them but the
componentwise band (14), and plan_detailed median / p95 per variant in the same run.

    python benchmarks/sweep_overhang.py
"""

from __future__ import annotations

import argparse
import collections
import itertools
import math
import time

import numpy as np

import avp

INCLINES = (100, 120, 135, 150, 165, 180)


def sweep(config: avp.PlannerConfig) -> tuple[dict[int, int], dict[str, int], list[float]]:
    solved: dict[int, int] = collections.Counter()
    statuses: dict[str, int] = collections.Counter()
    times = []
    for standoff, below in itertools.product((2.0, 3.0, 5.0), (1.5, 3.0, 4.0)):
        for incline in INCLINES:
            target = avp.PerchTarget.from_incline([standoff, 0.0, 3.0], math.radians(incline))
            t0 = time.perf_counter()
            result = avp.plan_detailed(avp.State.hover([0.0, 0.0, 3.0 - below]), target, config)
            times.append(time.perf_counter() - t0)
            statuses[result.status.name] += 1
            solved[incline] += result.status is avp.PlanStatus.SOLVED
    return dict(solved), dict(statuses), times


def main() -> None:
    variants = {
        "overhang rows (default)": avp.PlannerConfig(),
        "no overhang rows": avp.PlannerConfig(flip=avp.OverhangFlip(enabled=False)),
        "rows, componentwise band": avp.PlannerConfig(flip=avp.OverhangFlip(cone_band=False)),
    }
    for name, config in variants.items():
        solved, statuses, times = sweep(config)
        print(f"{name:<26} SOLVED {sum(solved.values())}/{len(times)} per incline {solved}")
        print(f"{'':<26} statuses {statuses}; plan_detailed median {1e3 * np.median(times):.0f} ms, "
              f"p95 {1e3 * np.percentile(times, 95):.0f} ms")


if __name__ == "__main__":
    argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter).parse_args()
    main()
