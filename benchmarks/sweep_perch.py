"""One-shot vs AVP in the realistic simulator: success with Wilson 95 % intervals over a grid
of conditions and one-at-a-time noise axes, errors in s1/s2/normal, plots, replan step latency.

    python benchmarks/sweep_perch.py --trials 100                       # base grid (the target)
    python benchmarks/sweep_perch.py --trials 30 --axes --out sweep_out  # + success vs each knob
    python benchmarks/sweep_perch.py --trials 20 --perfect               # perfect estimate
    python benchmarks/sweep_perch.py --trials 100 --inclines 90 --slowdowns 2 4 8 [--deadline-ms 20]
                                     # AVP on an onboard computer 2, 4, 8 times slower than this one

Wraps :func:`avp.sim.evaluate.sweep` (the API the CLI wires to). Long: ~1 s per trial and mode
on one core; not part of the test suite.
"""

from __future__ import annotations

import dataclasses
import warnings

from _grid import add_timing_options, add_vehicle_options, grid_parser, replan_config

from avp.sim.evaluate import SimConfig, sweep

AXES = {
    "camera_scale_bias": (0.0, 0.015, 0.03, 0.06),
    "odometry_sigma_p": (0.0, 0.003, 0.01),
    "odometry_drift": (0.0, 0.005, 0.02),
    "motor_time_constant": (0.0, 0.02, 0.04),
    "camera_noise_scale": (0.0, 1.0, 2.0),
    "camera_latency": (0.0, 0.05, 0.1),
}


def main() -> None:
    ap = grid_parser(__doc__)
    ap.add_argument("--axes", action="store_true", help="also vary each knob of AXES one at a time")
    ap.add_argument("--axis-inclines", type=float, nargs="+", default=[90.0],
                    help="conditions for the one-at-a-time axes (fewer to save time)")
    ap.add_argument("--perfect", action="store_true", help="perfect target estimate and odometry")
    ap.add_argument("--out", default=None, help="directory for the plots")
    ap.add_argument("--slowdowns", type=float, nargs="+", default=None,
                    help="also vary SimConfig.compute_slowdown: an onboard computer this many times slower "
                         "than this one (each step takes that many times its wall time of simulated time; AVP only, "
                         "not with --axes)")
    add_timing_options(ap)
    add_vehicle_options(ap)
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    cfg = SimConfig(n_trials=args.trials, seed=args.seed, inclines_deg=tuple(args.inclines),
                    distances=tuple(args.distances), contact_normal=args.contact_normal,
                    contact_slope=args.contact_slope, camera_uptilt_deg=args.camera_uptilt_deg)
    if args.perfect:
        cfg = cfg.perfect_estimate()
    replan = replan_config(args)
    if args.slowdowns and args.axes:
        ap.error("--slowdowns is a sweep of its own: run it without --axes")
    if args.slowdowns:
        cfg = dataclasses.replace(cfg, modes=("avp",))  # one-shot plans once, at hover: no slowdown
        res = sweep(cfg, {"compute_slowdown": args.slowdowns}, progress=True, replan=replan)
        print(res.report(), flush=True)
        print(res.table_compute(), flush=True)
        return
    res = sweep(cfg, progress=True, replan=replan)
    print(res.report(), flush=True)
    if args.axes:
        axis_cfg = dataclasses.replace(cfg, inclines_deg=tuple(args.axis_inclines))
        ax = sweep(axis_cfg, AXES, include_base=False, progress=True, replan=replan)
        print(ax.report(), flush=True)
        if args.out:
            for p in ax.plot(args.out):
                print("wrote", p)


if __name__ == "__main__":
    main()
