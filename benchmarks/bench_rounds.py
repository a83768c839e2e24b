"""Per-case CPU time of plan_detailed (minimum over rounds of the round's median) and a plan digest.

The CPU time is the calling thread's and the process's (every thread: BLAS helper threads too).

The digest is for bit-for-bit comparisons between two versions of the code.

    python benchmarks/bench_rounds.py [--rounds 8] [--repeats 7]

On a shared host the wall clock and even the CPU time of single calls move by tens of per cent
from minute to minute (other tenants' load changes the caches and the clock). A round takes
``--repeats`` plans of every case in turn; the round's median per case, minimised over the
rounds, is the cost of the case when the host is quietest, which is what two versions of the
code can be compared by when they run alternately (a ``git worktree`` of the other version on
``PYTHONPATH``, with the compiled ``avp/_avp_rust*.so`` copied into it or built there: git does
not track it). The cases: the 12 standard scenarios of ``bench_plan.py`` with the default
configuration, and the 30, 60 and 90 deg perches of Gao et al.'s setting
(``bench_gao_perch.py``). The digest covers each case's status, log, coefficients and knots,
of a first call and of a second one (with the caches the first filled): two versions that
print the same digest planned every case identically, bit for bit; a second digest leaves the
logs out, for a change that words or drops log lines and should plan the same. Nothing is
asserted.
"""

from __future__ import annotations

import argparse
import gc
import hashlib
import math
import time

import numpy as np
from bench_plan import scenarios

import avp

GAO = avp.VehicleLimits(mass=1.0, thrust_min=5.0, thrust_max=17.0, tilt_rate_max=3.0)


def cases() -> list[tuple[str, avp.State, avp.PerchTarget, avp.PlannerConfig]]:
    out = [(f"standard {i}", s, t, avp.PlannerConfig()) for i, (s, t) in enumerate(scenarios())]
    for incline in (30, 60, 90):
        out.append((f"Gao {incline} deg", avp.State.hover([0.0, 0.0, 1.5]),
                    avp.PerchTarget.from_incline([3.0, 0.0, 1.5], math.radians(incline)), avp.PlannerConfig(limits=GAO)))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=8)
    ap.add_argument("--repeats", type=int, default=7, help="plans of each case per round")
    args = ap.parse_args()
    todo = cases()
    digest, plans = hashlib.sha256(), hashlib.sha256()
    for _name, state, target, config in todo:  # not measured: the first call fills the caches
        for _ in range(2):
            result = avp.plan_detailed(state, target, config)
            digest.update(result.status.name.encode() + "\n".join(result.log).encode())
            plans.update(result.status.name.encode())
            if result.trajectory is not None:
                digest.update(result.trajectory.coefficients.tobytes() + result.trajectory.knots.tobytes())
                plans.update(result.trajectory.coefficients.tobytes() + result.trajectory.knots.tobytes())
    gc.disable()  # the collector's pauses are not the planner's cost
    best = {name: math.inf for name, *_ in todo}
    best_process = dict(best)
    for _ in range(args.rounds):
        for name, state, target, config in todo:
            cpu, process = [], []
            for _ in range(args.repeats):
                c0, p0 = time.thread_time(), time.process_time()
                avp.plan_detailed(state, target, config)
                cpu.append(time.thread_time() - c0)
                process.append(time.process_time() - p0)
            best[name] = min(best[name], float(np.median(cpu)))
            best_process[name] = min(best_process[name], float(np.median(process)))
    gc.enable()
    print(f"{'case':<16} {'CPU ms':>8} {'process':>8}   (minimum over {args.rounds} rounds of the median of "
          f"{args.repeats}; CPU: the calling thread's, process: every thread's, BLAS helpers included)")
    for name, value in best.items():
        print(f"{name:<16} {value * 1e3:8.3f} {best_process[name] * 1e3:8.3f}")
    standard = [v for k, v in best.items() if k.startswith("standard")]
    print(f"standard scenarios: median {np.median(standard) * 1e3:.3f} ms, mean {np.mean(standard) * 1e3:.3f} ms")
    print(f"digest of every plan (status, log, coefficients, knots): {digest.hexdigest()[:16]}")
    print(f"digest without the logs (status, coefficients, knots): {plans.hexdigest()[:16]}")


if __name__ == "__main__":
    main()
