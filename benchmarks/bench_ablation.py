"""What each stage of a plan costs where it runs: the plan's CPU time with the stage replayed.

    python benchmarks/bench_ablation.py [--scenario 8] [--plans 200] [--rounds 3] [STAGE ...]

A stage timed by a wrapper (``bench_pipeline.py``) or in a tight loop of its own is cheaper
than it is inside a plan: there, its code and data are no longer in the caches the rest of the
plan used, and every Python and NumPy call pays for that (on the development machine a solve
costs 2-3 times its tight-loop time). This script measures the cost in place by ablation: it
plans a standard scenario of ``bench_plan.py`` once with the stage's function recording what
it returns, then plans it again ``--plans`` times with the function replaced by a replay of
those results (the same objects in the same order, so the plan takes the same path), and
compares the median calling-thread CPU time per plan with that of unmodified plans measured
just before. The difference is what the stage's calls cost in place. Each round measures every
stage in turn; the table keeps each stage's smallest medians over the rounds (the host's
quietest moment). Nothing is asserted.

Stages (``module.function`` as the planner calls it): the QP solve and its parts, the FoV
linearisation, the visibility score, the trajectory objects, the bound and workspace
certificates. Replaying a stage also skips what the planner computes lazily on its results
later (a replayed linearisation's blocks are already built), as it should: that work belongs
to the stage.
"""

from __future__ import annotations

import argparse
import gc
import statistics
import time
from collections.abc import Callable
from typing import Any

import daqp
from bench_plan import scenarios

import avp
import avp.attempt as attempt
import avp.perception as perception
import avp.planner as planner
import avp.solve as solve

STAGES: dict[str, tuple[Any, str]] = {
    "QP solve (solve_perching_qp)": (attempt, "solve_perching_qp"),
    "  DAQP and its wrapper (_solve_two_sided)": (solve, "_solve_two_sided"),
    "    daqp.solve": (daqp, "solve"),
    "  judging the answer (_outcome)": (solve, "_outcome"),
    "QP rows (build_perching_qp)": (attempt, "build_perching_qp"),
    "FoV linearisation (linearise_on)": (perception, "linearise_on"),
    "visibility score (_scores)": (perception, "_scores"),
    "trajectory objects (_trajectory)": (attempt, "_trajectory"),
    "KKT check (16) (incompatibility)": (attempt, "incompatibility"),
    "bound certificates (certify_trajectory)": (planner, "certify_trajectory"),
    "workspace certificates (certify_workspace)": (attempt, "certify_workspace"),
}


def _median_cpu(plan: Callable[[], object], n: int, before: Callable[[], None] = lambda: None) -> float:
    """Median calling-thread CPU (us) of ``n`` calls of ``plan`` (``before`` runs untimed
    before each), with the garbage collector off while they run."""
    gc.collect()
    gc.disable()
    try:
        out = []
        for _ in range(n):
            before()
            t0 = time.thread_time_ns()
            plan()
            out.append(time.thread_time_ns() - t0)
    finally:
        gc.enable()
    return statistics.median(out) / 1e3


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("stages", nargs="*", help=f"stages to ablate (default: all): {', '.join(s.strip() for s in STAGES)}")
    ap.add_argument("--scenario", type=int, default=8, help="standard scenario (8: three SQP steps; 0: none)")
    ap.add_argument("--plans", type=int, default=200, help="plans per measurement")
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args()
    chosen = {k: v for k, v in STAGES.items() if not args.stages or k.strip() in args.stages
              or v[1] in args.stages}
    state, target = scenarios()[args.scenario]
    cfg = avp.PlannerConfig()

    def plan() -> object:
        return avp.plan_detailed(state, target, cfg)

    for _ in range(50):  # warm: caches, first-call costs
        plan()
    best: dict[str, tuple[float, float, int]] = {}
    for _ in range(args.rounds):
        for label, (module, name) in chosen.items():
            original = getattr(module, name)
            recorded: list[object] = []
            position = [0]

            def recording(*a: Any, _f: Callable[..., Any] = original, _r: list[object] = recorded, **k: Any) -> Any:
                out = _f(*a, **k)
                _r.append(out)
                return out

            def replaying(*a: Any, _r: list[object] = recorded, _p: list[int] = position, **k: Any) -> Any:
                out = _r[_p[0]]
                _p[0] += 1
                return out

            base = _median_cpu(plan, args.plans)
            setattr(module, name, recording)
            try:
                plan()
                setattr(module, name, replaying)
                without = _median_cpu(plan, args.plans, before=lambda p=position: p.__setitem__(0, 0))
            finally:
                setattr(module, name, original)
            old = best.get(label)
            best[label] = (min(base, old[0]) if old else base, min(without, old[1]) if old else without,
                           len(recorded))
    print(f"standard scenario {args.scenario}: median CPU per plan (us, calling thread), smallest over "
          f"{args.rounds} rounds of {args.plans} plans; 'in place' = with the stage minus with it replayed")
    print(f"  {'stage':<46} {'calls':>5} {'plan':>8} {'replayed':>9} {'in place':>9} {'per call':>9}")
    for label, (base, without, calls) in best.items():
        saved = base - without
        print(f"  {label:<46} {calls:>5} {base:8.0f} {without:9.0f} {saved:9.0f} "
              f"{saved / calls if calls else float('nan'):9.1f}")


if __name__ == "__main__":
    main()
