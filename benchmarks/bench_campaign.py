"""Campaign throughput: closed-loop trials per minute, serial vs a local process pool vs Ray, on
the same grid in one run (speed-ups are relative to serial), and a check that every backend gives
the same rows.

    python benchmarks/bench_campaign.py [--seeds 6] [--workers N] [--repeats 1]

Ray is used only when installed (``pip install "avp[ray]"``). The pool and Ray pay a start-up cost
(spawned workers import numpy, scipy and avp; Ray also starts its raylet), included in the times,
as a user would pay it for one campaign. On a machine with other load, the load average printed
says how many cores the run actually had.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import statistics
import time
import warnings

from avp import campaign


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=6, help="seeds per cell and mode")
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--repeats", type=int, default=1, help="runs per backend (median reported)")
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    trials = campaign.grid([90.0], [1.5, 4.5], [0.0], [None], ["one_shot", "avp"], range(args.seeds))
    backends = ["serial", "pool"] + (["ray"] if importlib.util.find_spec("ray") else [])
    print(f"{len(trials)} trials (90 deg wall, 1.5 and 4.5 m, both modes, {args.seeds} seeds); "
          f"{os.cpu_count()} CPUs, {args.workers} workers; load average before: {os.getloadavg()[0]:.2f}")
    runner = campaign.Runner()
    reference: dict[str, dict] | None = None
    cpu_per_trial = float("nan")
    base = None
    print(f"{'backend':8s} {'median s':>9s} {'trials/min':>11s} {'speed-up':>9s} {'rows equal':>11s}")
    for backend in backends:
        walls = []
        for _ in range(args.repeats):
            t0, c0 = time.perf_counter(), time.process_time()
            rows = {t.trial_id: r for t, r in campaign.execute(runner, trials, backend=backend, workers=args.workers)}
            walls.append(time.perf_counter() - t0)
            if backend == "serial":
                cpu_per_trial = (time.process_time() - c0) / len(trials)
            if backend == "ray":
                import ray

                ray.shutdown()
        wall = statistics.median(walls)
        if reference is None:
            reference, base = rows, wall
        same = all(campaign.rows_equal(rows[k], reference[k]) for k in reference)
        print(f"{backend:8s} {wall:9.1f} {60 * len(trials) / wall:11.1f} {base / wall:8.2f}x {same!s:>11s}")
    print(f"load average after: {os.getloadavg()[0]:.2f}")
    print(f"serial CPU time per trial {cpu_per_trial:.2f} s: {60 / cpu_per_trial:.0f} trials/min per free core "
          "(the ceiling a pool or Ray approaches per core when nothing else runs)")


if __name__ == "__main__":
    main()
