"""The loop's cost of replanning in a worker process (``avp.BackgroundReplanner``) against the
synchronous ``Replanner.step``, in the same simulated 30 Hz closed loops, interleaved run by run.

    python benchmarks/bench_background.py [--seeds 6] [--distances 1.5 4.5 7.5] [--inclines 90 45]
                                          [--latency-ms MS] [--gc-freeze] [--gc-between-steps]
                                          [--realistic] [--backend avp|rotorpy]

For every seed, distance and incline, ``avp.sim.run.simulate`` flies the perch twice with the
same ``ReplanConfig``: with the replanner in the loop (``Replanner.step``, what
``benchmarks/bench_replan.py`` measures) and with ``background=`` a shared ``PlanningWorker``.
The simulator then sends each tick's request with ``BackgroundReplanner.step`` and adopts the
answer with ``poll(wait=True)`` at the next control step, at the same simulated time: the loop's
cost of a cycle is that step and that poll. Each call is timed with ``time.thread_time`` (the CPU
of the loop's thread: the wait for the worker, which real time spends flying, is not counted;
the wall time is printed too); the first cycle (the initial plan, waited for in both) is not
counted. Also printed: the worker's own CPU per adopted solving step (the planning that moved off
the loop, not removed), the outcomes of both runs, the plans adopted after their switch time
(none in the simulator, which adopts at the request's own time) and the runs whose adopted steps
are the loop's, actions, fractions, solves and plans bit for bit (all of them: the worker runs the
same code on the same input). Nothing is asserted by the tests; these numbers are for this
machine and its load.
"""

from __future__ import annotations

import argparse
import gc
import time
import warnings
from collections import Counter
from typing import Any

import numpy as np
from _grid import add_loop_options, collector_off, loop_scenario

import avp.sim.run as sim_run
from avp.background import BackgroundReplanner, BackgroundStep, PlanningWorker
from avp.replan import ReplanConfig, Replanner, ReplanStep
from avp.sim.run import Mode, simulate

HEAD = f"{'steps':>6} {'median':>7} {'p95':>7} {'p99':>7} {'max':>7} {'>1.5 ms':>8} {'>5 ms':>6}"
_BETWEEN = [False]  # --gc-between-steps


def stats(ms: np.ndarray) -> str:
    if ms.size == 0:
        return f"{0:6d} {'-':>7} {'-':>7} {'-':>7} {'-':>7} {'-':>8} {'-':>6}"
    p95, p99 = np.percentile(ms, [95, 99])
    return (f"{ms.size:6d} {np.median(ms):7.3f} {p95:7.3f} {p99:7.3f} {ms.max():7.2f} "
            f"{int((ms > 1.5).sum()):8d} {int((ms > 5.0).sum()):6d}")


def _timed(call: Any, records: list[dict[str, Any]], *args: Any) -> Any:
    with collector_off(_BETWEEN[0]):
        w0, c0 = time.perf_counter(), time.thread_time()
        out = call(*args)
        c1, w1 = time.thread_time(), time.perf_counter()
    records.append(dict(cpu=c1 - c0, wall=w1 - w0, out=out))
    return out


class TimedReplanner(Replanner):
    """The synchronous replanner, each step timed (in this process only: never pickled)."""

    records: list[dict[str, Any]] = []  # noqa: RUF012 - one list per run, swapped by main()

    def step(self, t: float, odometry: Any, target_estimate: Any = None) -> ReplanStep:
        return _timed(super().step, TimedReplanner.records, t, odometry, target_estimate)  # type: ignore[no-any-return]


class TimedBackground(BackgroundReplanner):
    """The background replanner's loop-side calls, timed: a cycle is a step (it sends) and the
    poll that adopts its answer (the simulator's next control step)."""

    records: list[dict[str, Any]] = []  # noqa: RUF012

    def step(self, t: float, odometry: Any, target_estimate: Any = None, *,
             wait: bool | None = None) -> BackgroundStep:
        out = _timed(lambda *a: super(TimedBackground, self).step(*a, wait=wait),
                     TimedBackground.records, t, odometry, target_estimate)
        rec = TimedBackground.records[-1]
        rec.update(step_cpu=rec["cpu"], poll_cpu=0.0, adopted=out.adopted, plan_cpu=out.plan_cpu)
        return out  # type: ignore[no-any-return]

    def poll(self, t: float, *, wait: bool = False) -> BackgroundStep | None:
        polls: list[dict[str, Any]] = []
        out = _timed(lambda tt: super(TimedBackground, self).poll(tt, wait=wait), polls, t)
        if TimedBackground.records and out is not None:  # the cycle's adoption
            rec = TimedBackground.records[-1]
            rec["cpu"] += polls[0]["cpu"]
            rec["wall"] += polls[0]["wall"]
            rec["poll_cpu"] += polls[0]["cpu"]
            rec.update(adopted=out.adopted, plan_cpu=out.plan_cpu)
        return out  # type: ignore[no-any-return]


def _decisions(steps: tuple[ReplanStep, ...]) -> list[tuple[Any, ...]]:
    """Each step's action, fraction, solves and committed plan (its coefficients' bytes)."""
    return [(s.action.name, s.fraction, s.n_solves,
             s.trajectory.coefficients.tobytes() if s.committed and s.trajectory is not None else b"")
            for s in steps]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    add_loop_options(ap, seeds=6)
    ap.add_argument("--latency-ms", type=float, default=None,
                    help="ReplanConfig.latency (ms) of both runs (default: ReplanConfig's)")
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    _BETWEEN[0] = args.gc_between_steps
    sim_run.BackgroundReplanner = TimedBackground  # type: ignore[misc]  # the loop builds this class

    def in_loop(timed: bool) -> None:
        """The loop's synchronous replanner timed, or the library's (the worker's copy is
        pickled: it must be a class the worker imports)."""
        sim_run.Replanner = TimedReplanner if timed else Replanner  # type: ignore[misc]
    rcfg = ReplanConfig() if args.latency_ms is None else ReplanConfig(latency=args.latency_ms * 1e-3)

    worker = PlanningWorker()
    try:
        if args.gc_freeze:  # not counted: a set-up run of each
            first = loop_scenario(args, args.inclines[0], args.distances[0])
            in_loop(True)
            simulate(first, Mode.AVP, seed=10**6, replan=rcfg)
            in_loop(False)
            simulate(first, Mode.AVP, seed=10**6, replan=rcfg, background=worker)
            gc.collect()
            gc.freeze()
        sync_rows: list[dict[str, Any]] = []
        bg_rows: list[dict[str, Any]] = []
        outcomes: dict[str, Counter[str]] = {"in the loop": Counter(), "background": Counter()}
        late = same = runs = 0
        for inc in args.inclines:
            for d in args.distances:
                for seed in range(args.seeds):
                    sc = loop_scenario(args, inc, d)
                    TimedReplanner.records = []
                    in_loop(True)
                    a = simulate(sc, Mode.AVP, seed=seed, replan=rcfg)
                    sync_rows += TimedReplanner.records[1:]
                    TimedBackground.records = []
                    in_loop(False)
                    b = simulate(sc, Mode.AVP, seed=seed, replan=rcfg, background=worker)
                    bg_rows += TimedBackground.records[1:]
                    outcomes["in the loop"][a.outcome.split(":")[0]] += 1
                    outcomes["background"][b.outcome.split(":")[0]] += 1
                    late += b.late_commits
                    same += _decisions(a.steps) == _decisions(b.steps)
                    runs += 1
    finally:
        worker.close()

    def ms(rows: list[dict[str, Any]], key: str, keep: Any = None) -> np.ndarray:
        return np.array([r[key] for r in rows if keep is None or keep(r)]) * 1e3

    solving = lambda r: r["out"].solved
    adopted = lambda r: r["adopted"] is not None
    adopted_solving = lambda r: r["adopted"] is not None and r["adopted"].solved
    print(f"{runs} closed-loop runs of each (inclines {args.inclines} deg, distances {args.distances} m, "
          f"{args.seeds} seeds, latency {rcfg.latency * 1e3:g} ms{', realistic' if args.realistic else ''}, "
          f"{args.backend}); ms per loop call:")
    print(f"{'':<52} {HEAD}")
    print(f"{'Replanner.step in the loop, CPU':<52} {stats(ms(sync_rows, 'cpu'))}")
    print(f"{'  steps with a solve, CPU':<52} {stats(ms(sync_rows, 'cpu', solving))}")
    print(f"{'BackgroundReplanner, a cycle (step + poll), CPU':<52} {stats(ms(bg_rows, 'cpu'))}")
    print(f"{'  step (sends), CPU':<52} {stats(ms(bg_rows, 'step_cpu'))}")
    print(f"{'  poll (adopts), CPU':<52} {stats(ms(bg_rows, 'poll_cpu', adopted))}")
    print(f"{'  cycles that adopted a solving step, CPU':<52} {stats(ms(bg_rows, 'cpu', adopted_solving))}")
    print(f"{'  wall (waits for the worker included)':<52} {stats(ms(bg_rows, 'wall'))}")
    plan = np.array([r["plan_cpu"] for r in bg_rows if adopted_solving(r)]) * 1e3
    print(f"{'  the worker on those solving steps, CPU':<52} {stats(plan)}")
    print(f"\noutcomes: {dict(outcomes['in the loop'])} in the loop, {dict(outcomes['background'])} in the "
          f"background; adopted after their switch time: {late}; runs whose adopted steps are the loop's "
          f"(actions, fractions, solves, plans bit for bit): {same} of {runs}")


if __name__ == "__main__":
    main()
