"""Command line: ``avp demo`` plans a perch, prints a summary and writes a plot.

``python -m avp demo --help`` lists the flags. Degrees appear only here (``--incline-deg``).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections.abc import Sequence

import numpy as np

from .config import PlannerConfig
from .errors import AvpError
from .frames import rotation_error_angle
from .planner import plan_detailed
from .types import PerchTarget, State


def _demo_parser(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = sub.add_parser("demo", help="plan one perch, print a summary, write a PNG")
    p.add_argument("--incline-deg", type=float, default=90.0, help="pad incline: 0 floor, 90 wall (default), 180 ceiling")
    p.add_argument("--distance", type=float, default=3.5, help="horizontal stand-off from the pad (m), default 3.5")
    p.add_argument("--lateral", type=float, default=0.0, help="lateral offset of the start along s2 (m)")
    p.add_argument("--height", type=float, default=None, help="start height above the pad (m); default 0, or 1 below 45 deg incline")
    p.add_argument("--solver", default=PlannerConfig.solver, help="qpsolvers back-end (daqp, proxqp, osqp)")
    p.add_argument("--output", default="perch_demo.png", help="PNG path for the plot")
    p.add_argument("--no-plot", action="store_true", help="skip the plot")


def demo(args: argparse.Namespace) -> int:
    incline = math.radians(args.incline_deg)
    height = args.height if args.height is not None else (1.0 if args.incline_deg < 45 else 0.0)
    pad = np.array([args.distance, 0.0, 1.5])
    target = PerchTarget.from_incline(pad, incline, heading=0.0)
    start = pad + np.array([-args.distance, 0.0, height]) + args.lateral * target.s2
    state = State.hover(start)
    config = PlannerConfig(solver=args.solver)
    t0 = time.perf_counter()
    result = plan_detailed(state, target, config)
    first_call = time.perf_counter() - t0
    repeat = plan_detailed(state, target, config)  # steady state: caches and imports warm
    print(f"avp demo: perch on a {args.incline_deg:g} deg pad, {args.distance:g} m away "
          f"(lateral {args.lateral:g} m, height {height:g} m), solver {args.solver}")
    print(f"  status          : {result.status.value}")
    for line in result.log:
        print(f"    - {line}")
    traj = result.trajectory
    if traj is None:
        print("  no trajectory")
        return 1
    tf = traj.tf
    pos_err = float(np.linalg.norm(traj(tf) - target.point))
    b3 = traj.attitude(tf)[:, 2]
    att_err = math.degrees(math.acos(max(-1.0, min(1.0, float(b3 @ target.s3)))))
    frame_err = math.degrees(float(rotation_error_angle(traj.attitude(tf), target.R_WS)))
    v_S = target.to_target_frame(traj(tf, 1))
    want = config.contact_velocity.components(target.incline)
    v_err = max((abs(v_S[i] - w) for i, w in enumerate(want) if w is not None), default=0.0)
    ts = traj.sample(1e-3)
    thrust = traj.thrust(ts)
    rates = np.linalg.norm(traj.body_rates(ts), axis=-1)
    print(f"  duration        : {traj.duration:.3f} s ({traj.n_segments} segments, degree {traj.degree})")
    print(f"  contact position: {np.round(traj(tf), 4).tolist()} m (error {pos_err * 1e3:.2e} mm)")
    print(f"  attitude error  : b3 vs s3 {att_err:.2e} deg, R_WB vs R_WS {frame_err:.2e} deg")
    print(f"  contact velocity: v_S = {np.round(v_S, 4).tolist()} m/s (error {v_err * 1e3:.2e} mm/s)")
    print(f"  peak thrust     : {thrust.max():.2f} m/s^2 ({thrust.max() * config.limits.mass:.2f} N at "
          f"{config.limits.mass} kg), min {thrust.min():.2f} m/s^2; peak body rate {rates.max():.2f} rad/s")
    tm = repeat.timings
    print(f"  solve time      : {tm.total * 1e3:.2f} ms (build {tm.build * 1e3:.2f}, QP {tm.solve * 1e3:.2f}, "
          f"certificate {tm.certify * 1e3:.2f}); first call {first_call * 1e3:.1f} ms with one-time setup")
    if not args.no_plot:
        from .plotting import plot_perch

        out = plot_perch(traj, target, args.output, title=f"{args.incline_deg:g} deg pad, {args.distance:g} m")
        print(f"  plot            : {out}")
    return 0


def _simulate_parser(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = sub.add_parser("simulate", help="closed-loop trials: one-shot planning vs AVP replanning")
    p.add_argument("--trials", type=int, default=5, help="seeded trials per distance and mode (default 5)")
    p.add_argument("--incline-deg", type=float, default=90.0, help="pad incline (default 90: wall)")
    p.add_argument("--distance", type=float, nargs="+", default=[4.5, 7.5], help="stand-off(s) in m (default 4.5 7.5)")
    p.add_argument("--lateral", type=float, default=0.0, help="start offset along s2 (m)")
    p.add_argument("--height", type=float, default=None, help="start height above the pad (m)")
    p.add_argument("--seed", type=int, default=0, help="first seed (default 0)")
    p.add_argument("--output-dir", default="avp_simulation", help="directory for the plots")
    p.add_argument("--no-plot", action="store_true", help="skip the plots")


def simulate(args: argparse.Namespace) -> int:
    from .sim.evaluate import compare  # the core never imports avp.sim at import time

    if args.trials < 1:
        print("avp: error: --trials must be >= 1", file=sys.stderr)
        return 2
    comp = compare(args.trials, inclines=[math.radians(args.incline_deg)], distances=args.distance,
                   lateral_offsets=[args.lateral], height_offsets=[args.height], seed=args.seed)
    print(comp.report())
    if not args.no_plot:
        for path in comp.plot(args.output_dir):
            print(f"plot: {path}")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="avp", description="Active visual perching planner")
    sub = parser.add_subparsers(dest="command", required=True)
    _demo_parser(sub)
    _simulate_parser(sub)
    args = parser.parse_args(argv)
    try:
        if args.command == "demo":
            return demo(args)
        if args.command == "simulate":
            return simulate(args)
    except AvpError as exc:
        print(f"avp: error: {exc}", file=sys.stderr)
        return 2
    return 1  # pragma: no cover


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
