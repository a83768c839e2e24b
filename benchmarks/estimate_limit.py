"""What the target estimate allows: AVP's success next to the ideal perch on its own estimates
(avp.sim.limit), on the realistic SimConfig.

    python benchmarks/estimate_limit.py --trials 100                      # wall, 60 and 45 deg, 4.5 / 7.5 m
    python benchmarks/estimate_limit.py --trials 30 --inclines 90 --distances 4.5
    python benchmarks/estimate_limit.py --trials 40 --inclines 90 --backend rotorpy  # pip install "avp[rotorpy]"

For every seed it flies AVP once (avp's model), then re-fuses the detections the run delivered up
to ``tau`` s before contact and judges an ideal vehicle that reaches that estimate exactly (no
tracking error), with the simulator's own criteria. Columns:

- ``filter`` / ``known b``: the run's user-side filter, and the same detections with the camera's
  true scale error removed (knowledge no filter has);
- ``@0``: aimed at the estimate; ``best n``: at the best constant offset along the normal for the
  whole cell (in hindsight; ``off`` in cm, > 0 in front of the pad); ``best n,s1``: at the best
  constant offset along the normal and the slope (``s1`` in cm, < 0 down the slope: an early
  contact lands up the slope). The best aim approximately bounds a closed loop whose own errors
  are independent of the estimate's (``avp.sim.limit``).

Long (~0.7 s per trial on one core with avp's model, 2-4 s with rotorpy); not part of the test
suite.
"""

from __future__ import annotations

import time
import warnings

import numpy as np
from _grid import grid_parser

from avp.sim.evaluate import SimConfig, wilson_interval
from avp.sim.limit import estimate_limit
from avp.sim.run import Mode, simulate

OFFSETS = np.round(np.arange(-0.03, 0.0301, 0.0025), 4)  # along the normal (m)
SLOPE_OFFSETS = np.round(np.arange(-0.10, 0.0001, 0.01), 3)  # along s1 (m), down the slope


def main() -> None:
    ap = grid_parser(__doc__)
    ap.add_argument("--taus", type=float, nargs="+", default=[0.6, 0.45, 0.25],
                    help="how long before contact the estimate is taken (s)")
    ap.add_argument("--backend", default="avp", choices=["avp", "rotorpy"], help="simulator back-end")
    args = ap.parse_args()
    warnings.filterwarnings("ignore")
    cfg = SimConfig(backend=args.backend)
    taus = tuple(args.taus)
    print(f"AVP on the realistic SimConfig ({args.backend} back-end), {args.trials} seeds per cell (seeds {args.seed}..), Wilson 95 % CI; "
          f"ideal perch on the estimate tau s before contact. rms_n: rms normal error of the estimate (cm)")
    print(f"{'incline':>7s} {'dist':>5s} {'AVP':>17s} {'tau':>5s} | {'filter @0':>9s} {'best n':>6s} {'off':>5s} "
          f"{'best n,s1':>9s} {'off n,s1':>11s} {'rms_n':>5s} | {'known b @0':>10s} {'best n':>6s} {'best n,s1':>9s} "
          f"{'rms_n':>5s}")
    for inc in args.inclines:
        for dist in args.distances:
            t0 = time.perf_counter()
            sc = cfg.scenario(inc, dist)
            real = 0
            # ok[tau][which, normal offset, slope offset] counts ideal successes; err: normal errors
            ok = {tau: np.zeros((2, OFFSETS.size, SLOPE_OFFSETS.size), dtype=int) for tau in taus}
            err: dict[float, list[list[float]]] = {tau: [[], []] for tau in taus}
            n = 0
            for s in range(args.seed, args.seed + args.trials):
                r = simulate(sc, Mode.AVP, seed=s)
                n += 1
                real += int(r.success)
                for lim in estimate_limit(r, taus):
                    for j, off in enumerate(OFFSETS):
                        for k, off1 in enumerate(SLOPE_OFFSETS):
                            for which, outcome in enumerate(lim.judge(float(off), float(off1))):
                                ok[lim.tau][which, j, k] += int(outcome is not None and outcome.success)
                    for which in (0, 1):
                        err[lim.tau][which].append(lim.normal_error[which])
            lo, hi = wilson_interval(real, n)
            for i, tau in enumerate(taus):
                head = (f"{inc:7.0f} {dist:5.1f} {real:3d}/{n:<3d} [{100 * lo:3.0f},{100 * hi:3.0f}]" if i == 0
                        else " " * 31)
                zero, no_slope = int(np.argmin(np.abs(OFFSETS))), int(np.argmin(np.abs(SLOPE_OFFSETS)))
                cells = []
                for which in (0, 1):
                    grid = ok[tau][which]
                    best_n = int(np.argmax(grid[:, no_slope]))
                    best_2 = np.unravel_index(int(np.argmax(grid)), grid.shape)
                    e = np.asarray(err[tau][which], dtype=float)
                    rms = float(np.sqrt(np.nanmean(e ** 2))) if e.size else float("nan")
                    cells.append((100 * grid[zero, no_slope] / n, 100 * grid[best_n, no_slope] / n, 100 * OFFSETS[best_n],
                                  100 * grid[best_2] / n, 100 * OFFSETS[best_2[0]], 100 * SLOPE_OFFSETS[best_2[1]], 100 * rms))
                f, k = cells
                print(f"{head} {tau:5.2f} | {f[0]:8.0f}% {f[1]:5.0f}% {f[2]:+5.2f} {f[3]:8.0f}% {f[4]:+5.2f},{f[5]:+5.1f} "
                      f"{f[6]:5.2f} | {k[0]:9.0f}% {k[1]:5.0f}% {k[3]:8.0f}% {k[6]:5.2f}", flush=True)
            print(f"{'':7s} [{time.perf_counter() - t0:.0f} s]", flush=True)


if __name__ == "__main__":
    main()
