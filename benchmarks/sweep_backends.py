"""One-shot vs AVP on both simulator back-ends (avp's model (1) and rotorpy's Multirotor), the
realistic SimConfig and its perfect-estimate variant: success with Wilson 95 % intervals.

    python benchmarks/sweep_backends.py --trials 20                 # 90 deg wall and 45 deg slope at 4.5 m
    python benchmarks/sweep_backends.py --trials 100 --inclines 90 --backends rotorpy --estimates realistic \
        --modes avp --compute-slowdown 8 [--deadline-ms 20]        # on an onboard computer 8 times slower
    python benchmarks/sweep_backends.py --trials 100 --inclines 90 --backends rotorpy --estimates realistic \
        --contact-normal -0.4 --contact-slope -1.4                 # another contact velocity (the paper's: -0.3, -2)

Without rotorpy (``pip install "avp[rotorpy]"``) only avp's back-end runs. The rotorpy back-end
feeds rotorpy's rotor drag forward in avp's controller (``SimConfig.drag_feedforward``);
``--no-drag-feedforward`` flies it without; ``--no-lag-feedforward`` flies the controller without
its thrust lead on either back-end (``SimConfig.lag_feedforward``). Long (rotorpy: ~2-4 s per
trial on one core); not part of the test suite.
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib.util
import time
import warnings

import numpy as np
from _grid import add_timing_options, add_vehicle_options, replan_config

from avp.sim.evaluate import SimConfig, sweep


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=20)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--inclines", type=float, nargs="+", default=[90.0, 45.0])
    ap.add_argument("--distances", type=float, nargs="+", default=[4.5])
    ap.add_argument("--backends", nargs="+", default=["avp", "rotorpy"], choices=["avp", "rotorpy"])
    ap.add_argument("--estimates", nargs="+", default=["realistic", "perfect"], choices=["realistic", "perfect"],
                    help="which estimate variants to run (one each on two processes halves the wall time)")
    ap.add_argument("--no-drag-feedforward", action="store_true", help="rotorpy without the drag feed-forward")
    ap.add_argument("--no-lag-feedforward", action="store_true", help="the controller without its thrust lead")
    ap.add_argument("--modes", nargs="+", default=["one_shot", "avp"], choices=["one_shot", "avp"])
    ap.add_argument("--compute-slowdown", type=float, default=0.0,
                    help="SimConfig.compute_slowdown: an onboard computer this many times slower than this one")
    add_timing_options(ap)
    add_vehicle_options(ap)
    args = ap.parse_args()
    replan = replan_config(args)
    backends = [b for b in args.backends if b == "avp" or importlib.util.find_spec("rotorpy") is not None]
    if len(backends) < len(args.backends):
        print('rotorpy is not installed (pip install "avp[rotorpy]"): avp back-end only')
    warnings.filterwarnings("ignore")
    base = SimConfig(n_trials=args.trials, seed=args.seed, inclines_deg=tuple(args.inclines),
                     distances=tuple(args.distances), drag_feedforward=not args.no_drag_feedforward,
                     lag_feedforward=not args.no_lag_feedforward, modes=tuple(args.modes),
                     compute_slowdown=args.compute_slowdown, contact_normal=args.contact_normal,
                     contact_slope=args.contact_slope, camera_uptilt_deg=args.camera_uptilt_deg)
    rows = []
    for backend in backends:
        for label, cfg in (("realistic", base), ("perfect", base.perfect_estimate())):
            if label not in args.estimates:
                continue
            t0 = time.perf_counter()
            res = sweep(dataclasses.replace(cfg, backend=backend), replan=replan)
            wall = time.perf_counter() - t0
            for p in res.points:
                lo, hi = p.interval
                att = float(np.mean(p.attitude)) if p.attitude.size else float("nan")
                en = float(np.mean(np.abs(p.errors_S[:, 2]))) if p.errors_S.size else float("nan")
                rows.append((backend, label, p.incline_deg, p.distance, p.mode, p.successes, p.n, lo, hi, en, att,
                             ", ".join(f"{k} x{v}" for k, v in sorted(p.outcomes.items()) if k != "success")))
            print(f"[{backend} {label}: {wall:.0f} s]", flush=True)
            if args.compute_slowdown:
                print(res.table_compute(), flush=True)
    print(f"\nSuccess at the plan's contact time, {args.trials} paired seeds per row (seeds {args.seed}..), "
          f"Wilson 95 % CI; |e_n| mean normal error (m), att mean b3-s3 angle (deg)")
    print(f"{'backend':8s} {'estimate':9s} {'incline':>7s} {'dist':>5s} {'mode':9s} {'success':>8s} {'95% CI':>13s} "
          f"{'|e_n|':>6s} {'att':>5s}  failures")
    for b, lab, inc, d, m, k, n, lo, hi, en, att, fails in rows:
        print(f"{b:8s} {lab:9s} {inc:7.0f} {d:5.1f} {m:9s} {k:3d}/{n:<4d} [{100 * lo:4.0f},{100 * hi:4.0f}] % "
              f"{en:6.3f} {att:5.1f}  {fails}")


if __name__ == "__main__":
    main()
