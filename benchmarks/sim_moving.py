"""Closed-loop perching on moving platforms (Gao et al., "Adaptive Tracking and Perching for
Quadrotor in Dynamic Scenarios", T-RO 2023): the grid of benchmarks/bench_moving.py flown in
:func:`avp.sim.platform.simulate_moving` (500 Hz SE(3) control, 30 Hz replanning with
:class:`avp.moving.MovingReplanner`, odometry noise, white noise on the platform-state estimates,
the default vehicle: 0.5 kg, thrust up to 17 m/s^2 mass-normalised) for seeded trials.

Prints per case Gao et al.'s Table VIII columns (target speed, drone max/mean speed, contact error
from the pad centre) and the success rate (contact on the 0.3 m pad, attitude error <= 15 deg,
relative normal speed in [0.05, 1] m/s, relative tangential speed <= 3 m/s).

    python benchmarks/sim_moving.py [--seeds 10]
"""

from __future__ import annotations

import argparse
from collections import Counter

import numpy as np
from bench_moving import CONFIG, grid

from avp.sim.platform import MovingSimScenario, simulate_moving


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=10)
    args = ap.parse_args()
    print(f"{'case':<32} {'success':>8} {'target m/s':>10} {'drone max/avg m/s':>17} {'error cm':>12}  failures")
    total = ok = 0
    for name, target, height in grid():
        runs = [simulate_moving(MovingSimScenario(target, height=height), seed=s, config=CONFIG)
                for s in range(args.seeds)]
        succ = [r for r in runs if r.success]
        total += len(runs)
        ok += len(succ)
        err = np.array([r.error for r in runs if r.contact is not None]) * 100
        vmax = np.mean([r.speed_max for r in runs])
        vavg = np.mean([r.speed_mean for r in runs])
        fails = Counter(r.outcome for r in runs if not r.success)
        err_txt = f"{np.mean(err):5.2f} (max {np.max(err):4.1f})" if err.size else "-"
        print(f"{name:<32} {len(succ):>3}/{len(runs):<4} {target.speed:10.1f} {vmax:8.2f}/{vavg:<8.2f} {err_txt:>12}  "
              + "; ".join(f"{k} x{v}" for k, v in fails.items()))
    print(f"\noverall success {ok}/{total} = {100.0 * ok / max(total, 1):.1f} %")


if __name__ == "__main__":
    main()
