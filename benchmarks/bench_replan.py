"""Replanning step latency inside the simulated 30 Hz loop: median, p95 and max of the wall-clock
time of ``Replanner.step`` (anticipation + QP + FoV rows + certificate), as a fraction of the
33 ms cycle, per stand-off; baseline in the same run: the same steps' plan without FoV rows.

    python benchmarks/bench_replan.py [--trials 5]
"""

from __future__ import annotations

import argparse
import dataclasses
import warnings

import numpy as np

import avp
from avp.sim.run import Mode, SimScenario, simulate

CYCLE = 1.0 / 30.0


def latencies(distance: float, trials: int, config: avp.PlannerConfig) -> np.ndarray:
    out = []
    for seed in range(trials):
        r = simulate(SimScenario(distance=distance), Mode.AVP, seed=seed, config=config)
        out.extend(r.solve_times[1:])  # the first entry is the initial plan, not a replan
    return np.array(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=5)
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    default = avp.PlannerConfig()
    no_fov = dataclasses.replace(default, fov=avp.FovConfig(enabled=False))
    print(f"{'stand-off':>9} {'config':<10} {'steps':>6} {'median ms':>9} {'p95 ms':>8} {'max ms':>8} "
          f"{'median/cycle':>12} {'p95/cycle':>9}")
    for d in (1.5, 4.5, 7.5):
        for name, cfg in (("default", default), ("no FoV", no_fov)):
            s = latencies(d, args.trials, cfg)
            med, p95 = np.median(s), np.percentile(s, 95)
            print(f"{d:>8.1f}m {name:<10} {s.size:>6} {med * 1e3:9.2f} {p95 * 1e3:8.2f} {s.max() * 1e3:8.2f} "
                  f"{med / CYCLE:11.1%} {p95 / CYCLE:9.1%}")


if __name__ == "__main__":
    main()
