"""The benchmark setting of Gao et al., "Adaptive Tracking and Perching for Quadrotor in Dynamic Scenarios" (Table IV), which reports that Mao et al.'s
planner fails at 90 deg: rest start 3 m from the pad at its height, mass-normalised thrust in
[5, 17] m/s^2, body rate <= 3 rad/s (a planar perch has no roll or yaw motion, so the tilt-rate
bound is the body-rate bound). Reports whether avp finds a certified plan, the durations, what
it relaxed, the solves per plan and how long planning took (median of repeats, wall clock and
CPU time of the calling thread; the CPU time is what the machine's load does not inflate).

    python benchmarks/bench_gao_perch.py [--repeats 5] [--time-search BIDIRECTIONAL]
"""

from __future__ import annotations

import argparse
import math
import time
from dataclasses import replace

import numpy as np

import avp

LIMITS = avp.VehicleLimits(mass=1.0, thrust_min=5.0, thrust_max=17.0, tilt_rate_max=3.0)
CASES = {
    "paper contact velocity (0.3 in, slide)": dict(),
    "near rest-to-rest (0.05 m/s into the pad)": dict(
        alpha=5.5,
        contact_velocity=avp.ContactVelocity(normal=-0.05, slope=0.0, lateral=0.0),
        bounds=avp.BoundsPolicy(relaxations=(avp.Relaxation.CONE_BAND, avp.Relaxation.NO_BAND, avp.Relaxation.ALPHA_RANGE)),
    ),
    "paper band only, no relaxation": dict(alpha=5.5, bounds=avp.BoundsPolicy(relaxations=())),
}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--time-search", choices=[m.name for m in avp.TimeSearch], default=None,
                    help="override BoundsPolicy.time_search (default: the configuration's)")
    args = ap.parse_args()
    print(f"{'case':<40} {'incl':>4} {'status':<22} {'T (s)':>6} {'thrust (m/s^2)':>15} {'|w| max':>7} "
          f"{'solves':>6} {'median ms':>9} {'CPU ms':>7}  relaxed")
    for name, kw in CASES.items():
        for inc in (30, 60, 90):
            target = avp.PerchTarget.from_incline([3.0, 0.0, 1.5], math.radians(inc))
            state = avp.State.hover([0.0, 0.0, 1.5])
            config = avp.PlannerConfig(limits=LIMITS, **kw)
            if args.time_search is not None:
                config = replace(config, bounds=replace(config.bounds, time_search=avp.TimeSearch[args.time_search]))
            times, cpu = [], []
            for _ in range(args.repeats):
                t0, c0 = time.perf_counter(), time.thread_time()
                result = avp.plan_detailed(state, target, config)
                times.append(time.perf_counter() - t0)
                cpu.append(time.thread_time() - c0)
            tr = result.trajectory
            thrust = rates = "-"
            T = "-"
            if tr is not None and result.ok:
                t = tr.sample(1e-4)
                f = tr.thrust(t)
                thrust = f"[{f.min():.2f}, {f.max():.2f}]"
                rates = f"{np.linalg.norm(tr.body_rates(t), axis=1).max():.2f}"
                T = f"{tr.duration:.2f}"
            relaxed = ", ".join(r.name for r in result.relaxations) or "-"
            print(f"{name:<40} {inc:>4} {result.status.name:<22} {T:>6} {thrust:>15} {rates:>7} "
                  f"{result.duration_scale_steps + 1:>6} {np.median(times) * 1e3:9.1f} {np.median(cpu) * 1e3:7.1f}  {relaxed}")


if __name__ == "__main__":
    main()
