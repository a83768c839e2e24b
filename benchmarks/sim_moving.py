"""Closed-loop perching on moving platforms (Gao et al., "Adaptive Tracking and Perching for
Quadrotor in Dynamic Scenarios", T-RO 2023): the grid of benchmarks/bench_moving.py flown for
seeded trials, in one of two simulators:

* default: :func:`avp.sim.platform.simulate_moving` (500 Hz SE(3) control, 30 Hz replanning
  with :class:`avp.moving.MovingReplanner`, odometry white noise, white noise on directly
  measured platform states fused by a fixed-gain filter);
* ``--realistic``: :func:`avp.sim.run.simulate` with a :class:`avp.sim.run.PlatformMotion`, the
  realistic point of :class:`avp.sim.evaluate.SimConfig` (rotor mixer and 20 ms motor lag,
  200 Hz odometry with white noise and drift, camera detections of the moving pad only in the
  FoV and range at 10 Hz with 50 ms latency, 10 % dropouts, range-growing noise, a 3 % range
  scale bias of random sign and a 2 deg normal tilt), the platform state fitted from those
  detections by :class:`avp.sim.estimator.PlatformEstimator` after 2 s of tracking. Both modes
  plan with Gao et al.'s limits (1 kg, thrust 5-17 N, tilt rate 3 rad/s); the realistic one also
  flies a vehicle with those limits, the default one avp's default vehicle (0.5 kg, 0.25-9.81 N:
  0.5-19.6 m/s^2, headroom above the plans).

Prints per case Gao et al.'s Table VIII columns (target speed, drone max/mean speed from the
first plan to contact, contact error from the pad centre) and the success rate with its Wilson
95 % interval. Success: default mode, contact on the 0.3 m pad with attitude error <= 15 deg,
relative normal speed in [0.05, 1] m/s, relative tangential speed <= 3 m/s; ``--realistic``,
the static simulator's criterion against the moving pad (at the plan's contact time: within 3 cm
of the pad plane, < 10 cm from its centre, b3 within 10 deg of s3).

    python benchmarks/sim_moving.py [--seeds 10] [--realistic] [--mode avp|one_shot]
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import time
from collections import Counter

import numpy as np
from bench_moving import CONFIG, LIMITS, grid

from avp.platform import MovingTarget
from avp.sim.evaluate import SimConfig, wilson_interval
from avp.sim.platform import MovingSimScenario, simulate_moving
from avp.sim.run import PlatformMotion, SimScenario, simulate

BEHIND = 3.0
"""Start distance (m) behind the pad along the heading, as bench_moving's."""


def realistic_scenario(target: MovingTarget, height: float) -> SimScenario:
    """``target`` (at t = 0, heading 0) as a :class:`SimScenario` at SimConfig's realistic point."""
    incline = math.acos(float(np.clip(target.s3[2], -1.0, 1.0)))
    sc = SimConfig().scenario(math.degrees(incline), BEHIND)
    platform = PlatformMotion(speed=target.speed, heading=target.heading, turn_rate=target.omega)
    return dataclasses.replace(sc, vehicle=dataclasses.replace(sc.vehicle, limits=LIMITS), height=height,
                               pad_height=float(target.point[2]), platform=platform,
                               aim_normal=0.0, aim_slope=0.0)  # the aim is for a static pad


def realistic_run(target: MovingTarget, height: float, seed: int, mode: str) -> tuple[bool, str, float, float, float]:
    """(success, outcome, contact error m, max speed, mean speed) of one realistic trial."""
    sc = realistic_scenario(target, height)
    cfg = dataclasses.replace(CONFIG, fov=dataclasses.replace(CONFIG.fov, camera=sc.camera.camera))
    r = simulate(sc, mode, seed=seed, config=cfg)
    err = float(np.hypot(*r.perch.error_S[:2])) if r.perch is not None else math.nan
    if r.path_p.shape[0] > 1:
        speed = np.linalg.norm(np.diff(r.path_p, axis=0), axis=1) / np.diff(r.path_t)
        vmax, vavg = float(speed.max()), float(speed.mean())
    else:
        vmax = vavg = math.nan
    return r.success, r.outcome, err, vmax, vavg


def simple_run(target: MovingTarget, height: float, seed: int, mode: str) -> tuple[bool, str, float, float, float]:
    r = simulate_moving(MovingSimScenario(target, height=height), seed=seed, config=CONFIG)
    return r.success, r.outcome, r.error, r.speed_max, r.speed_mean


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--realistic", action="store_true", help="avp.sim.run.simulate with SimConfig's realism")
    ap.add_argument("--mode", choices=("avp", "one_shot"), default="avp", help="with --realistic: planning mode")
    ap.add_argument("--cases", default="", help="only cases whose name contains this text")
    args = ap.parse_args()
    run = realistic_run if args.realistic else simple_run
    print(f"simulator: {'realistic (avp.sim.run.simulate), mode ' + args.mode if args.realistic else 'simplified (simulate_moving)'}"
          f", seeds 0..{args.seeds - 1}")
    print(f"{'case':<32} {'success':>8} {'95% CI':>13} {'target m/s':>10} {'drone max/avg m/s':>17} "
          f"{'error cm':>15}  failures")
    total = ok = 0
    w0 = time.perf_counter()
    for name, target, height in grid():
        if args.cases not in name:
            continue
        runs = [run(target, height, s, args.mode) for s in range(args.seeds)]
        n_ok = sum(r[0] for r in runs)
        total += len(runs)
        ok += n_ok
        err = np.array([r[2] for r in runs if math.isfinite(r[2])]) * 100
        vmax = np.nanmean([r[3] for r in runs])
        vavg = np.nanmean([r[4] for r in runs])
        fails = Counter(r[1] for r in runs if not r[0])
        lo, hi = wilson_interval(n_ok, len(runs))
        err_txt = f"{np.mean(err):5.2f} (max {np.max(err):4.1f})" if err.size else "-"
        print(f"{name:<32} {n_ok:>3}/{len(runs):<4} [{100 * lo:4.0f},{100 * hi:4.0f}] % {abs(target.speed):10.1f} "
              f"{vmax:8.2f}/{vavg:<8.2f} {err_txt:>15}  " + "; ".join(f"{k} x{v}" for k, v in fails.items()),
              flush=True)
    lo, hi = wilson_interval(ok, total)
    print(f"\noverall success {ok}/{max(total, 1)} = {100.0 * ok / max(total, 1):.1f} % "
          f"(Wilson 95 % [{100 * lo:.1f}, {100 * hi:.1f}] %) in {time.perf_counter() - w0:.0f} s")


if __name__ == "__main__":
    main()
