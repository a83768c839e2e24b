"""What the target estimate allows: AVP's success next to the ideal perch on its own estimates
(avp.sim.limit), on the realistic SimConfig.

    python benchmarks/estimate_limit.py --trials 100                      # wall, 60 and 45 deg, 4.5 / 7.5 m
    python benchmarks/estimate_limit.py --trials 30 --inclines 90 --distances 4.5

For every seed it flies AVP once (avp's model), then re-fuses the detections the run delivered up
to ``tau`` s before contact and judges an ideal vehicle that reaches that estimate exactly (no
tracking error), with the simulator's own criteria. Columns:

- ``filter`` / ``known b``: the run's user-side filter, and the same detections with the camera's
  true scale error removed (knowledge no filter has);
- ``@0``: aimed at the estimate; ``best``: aimed at the best constant offset along the normal for
  the whole cell (in hindsight; ``off`` in cm, > 0 in front of the pad). The best offset is a
  ceiling for any closed loop whose own errors are independent of the estimate's errors.

Long (~0.7 s per trial on one core, plus the re-fusion); not part of the test suite.
"""

from __future__ import annotations

import argparse
import time
import warnings

import numpy as np

from avp.sim.evaluate import SimConfig, wilson_interval
from avp.sim.limit import estimate_limit
from avp.sim.run import Mode, simulate

OFFSETS = np.round(np.arange(-0.03, 0.0301, 0.0025), 4)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=100)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--inclines", type=float, nargs="+", default=[90.0, 60.0, 45.0])
    ap.add_argument("--distances", type=float, nargs="+", default=[4.5, 7.5])
    ap.add_argument("--taus", type=float, nargs="+", default=[0.6, 0.45, 0.25],
                    help="how long before contact the estimate is taken (s)")
    args = ap.parse_args()
    warnings.filterwarnings("ignore")
    cfg = SimConfig()
    taus = tuple(args.taus)
    print(f"AVP on the realistic SimConfig, {args.trials} seeds per cell (seeds {args.seed}..), Wilson 95 % CI; "
          f"ideal perch on the estimate tau s before contact. rms_n: rms normal error of the estimate (cm)")
    print(f"{'incline':>7s} {'dist':>5s} {'AVP':>17s} {'tau':>5s} | {'filter @0':>9s} {'best':>5s} {'off':>5s} "
          f"{'rms_n':>5s} | {'known b @0':>10s} {'best':>5s} {'off':>5s} {'rms_n':>5s}")
    for inc in args.inclines:
        for dist in args.distances:
            t0 = time.perf_counter()
            sc = cfg.scenario(inc, dist)
            real = 0
            # ok[tau][which][offset index] counts ideal successes; err[tau][which] normal errors
            ok = {tau: np.zeros((2, OFFSETS.size), dtype=int) for tau in taus}
            err: dict[float, list[list[float]]] = {tau: [[], []] for tau in taus}
            n = 0
            for s in range(args.seed, args.seed + args.trials):
                r = simulate(sc, Mode.AVP, seed=s)
                n += 1
                real += int(r.success)
                for lim in estimate_limit(r, taus):
                    for j, off in enumerate(OFFSETS):
                        for which, outcome in enumerate(lim.judge(float(off))):
                            ok[lim.tau][which, j] += int(outcome is not None and outcome.success)
                    for which in (0, 1):
                        err[lim.tau][which].append(lim.normal_error[which])
            lo, hi = wilson_interval(real, n)
            for i, tau in enumerate(taus):
                head = (f"{inc:7.0f} {dist:5.1f} {real:3d}/{n:<3d} [{100 * lo:3.0f},{100 * hi:3.0f}]" if i == 0
                        else " " * 31)
                cols = []
                zero = int(np.argmin(np.abs(OFFSETS)))
                for which in (0, 1):
                    best = int(np.argmax(ok[tau][which]))
                    e = np.asarray(err[tau][which], dtype=float)
                    rms = float(np.sqrt(np.nanmean(e ** 2))) if e.size else float("nan")
                    cols.append(f"{100 * ok[tau][which, zero] / n:8.0f}% {100 * ok[tau][which, best] / n:4.0f}% "
                                f"{100 * OFFSETS[best]:+5.2f} {100 * rms:5.2f}")
                print(f"{head} {tau:5.2f} | {cols[0]} | {cols[1]:>25s}", flush=True)
            print(f"{'':7s} [{time.perf_counter() - t0:.0f} s]", flush=True)


if __name__ == "__main__":
    main()
