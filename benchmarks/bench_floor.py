"""The compute floor of a replanning call: what each stage of ``plan_detailed`` costs, measured
by taking it away.

    python benchmarks/bench_floor.py [--seeds 2] [--distances 1.5 4.5 7.5] [--inclines 90 45] [--rounds 7]
                                     [--first-plans]

Records every replanning call (``plan_detailed`` with the committed plan as ``previous``) that
the ``Replanner`` makes in closed-loop runs of ``avp.sim.run.simulate`` in ``Mode.AVP`` (avp's
vehicle model, ``SimScenario``'s defaults), or with ``--first-plans`` the default ``plan()``
calls of ``bench_pipeline.py``'s twelve standard scenarios (no previous plan: the FoV SQP steps
with their visibility scores), then replays the calls back to back with one BLAS thread, timed
with ``time.thread_time`` (the minimum over ``--rounds`` of the mean per call):

* as they are: the full cost;
* with one stage *taken away*: a first pass records the stage's results in call order, and the
  timed passes return those results instead of computing them, in rounds that alternate with
  rounds that compute them (each row's "with" and "without" columns, so that both see the same
  machine load). The planner around the stage
  does the same work on the same values (the digest of every call's status, log and plan is
  checked against the full replay's), so the difference is what the stage costs in the call,
  its Python objects, caches and NumPy calls included: the most a compiled version of it could
  save;
* with every stage taken away: what is left is the orchestration (the time search, the FoV
  stage and the workspace rounds, the input checks, logs and result objects), the floor of a
  design that keeps those decisions in Python;
* ``daqp.solve`` alone on the reduced QPs of the same calls, with its inputs prepared outside
  the timing: the back-end's own share of the solve stage.

The stages: building the QP (``build_perching_qp``), the workspace rows (``workspace_blocks``
and ``refinement_blocks``), the FoV linearisation (``perception.linearise_on``) and the FoV
rows it builds when a QP needs them (``qp.fov.fov_rows``), the visibility score of a first plan's
SQP steps (``perception._scores``) and the sampled limit check before them
(``time_search.scaled_excess``), reducing and solving the QPs
(``solve_perching_qp``; and, each taken away alone, its parts: the equality elimination and
reduced rows of ``PerchingQp.reduce``, the DAQP call with its solution object, the lift and the
feasibility check of ``solve._outcome``), the bound certificate (``planner._certify``) and the workspace certificate
(``certify_workspace``). Nothing is asserted; the numbers are for this machine and its load.
"""

from __future__ import annotations

import argparse
import hashlib
import math
import time
from collections.abc import Callable
from typing import Any, ClassVar

import numpy as np

import avp.attempt as attempt
import avp.perception as perception
import avp.planner as planner
import avp.qp.fov as qp_fov
import avp.sim.run as sim_run
import avp.solve as solve
from avp._blas import serial_blas
from avp.config import PlannerConfig
from avp.planner import plan_detailed
from avp.qp import assemble
from avp.replan import Replanner
from avp.sim.run import Mode, SimScenario, simulate

STAGES: tuple[tuple[str, tuple[tuple[Any, str], ...]], ...] = (
    ("build the QP", ((attempt, "build_perching_qp"),)),
    ("workspace rows", ((attempt, "workspace_blocks"), (attempt, "refinement_blocks"))),
    ("FoV linearisation (8)-(9)", ((perception, "linearise_on"),)),
    ("FoV rows built (when a QP needs them)", ((qp_fov, "fov_rows"),)),
    ("reduce and solve the QPs (DAQP included)", ((attempt, "solve_perching_qp"),)),
    ("  of which: the reduction (elimination, reduced rows)", ((assemble.PerchingQp, "reduce"),)),
    ("  of which: the DAQP call and its solution object", ((solve, "_solve_two_sided"),)),
    ("  of which: the lift and the feasibility check", ((solve, "_outcome"),)),
    ("FoV visibility score (first plans' SQP steps)", ((perception, "_scores"),)),
    ("sampled limit check before the SQP (first plans)", ((planner, "scaled_excess"),)),
    ("bound certificate (Algorithm 1)", ((planner, "_certify"),)),
    ("workspace certificate", ((attempt, "certify_workspace"),)),
)

Call = tuple[Any, ...]


class RecordingReplanner(Replanner):
    """The library's replanner; each planning call's arguments kept (replans only)."""

    calls: ClassVar[list[Call]] = []

    def _plan(self, state: Any, target: Any, durations: Any, previous: Any, config: Any,
              deadline: Any = None) -> Any:
        if previous is not None:
            RecordingReplanner.calls.append((state, target, durations, previous, config, deadline))
        return super()._plan(state, target, durations, previous, config, deadline)


def replay(calls: list[Call]) -> str:
    """Every call planned again; a digest of the statuses, logs and plans."""
    h = hashlib.sha1()
    for state, target, durations, previous, config, deadline in calls:
        try:
            r = plan_detailed(state, target, config, durations=durations, previous=previous,
                              warm_start=previous, deadline=deadline)
        except Exception as exc:  # the step turned the same failure into a result
            h.update(repr(exc).encode())
            continue
        h.update(r.status.name.encode())
        h.update("\n".join(r.log).encode())
        if r.trajectory is not None:
            h.update(r.trajectory.coefficients.tobytes())
    return h.hexdigest()[:16]


def timed(calls: list[Call], rounds: int, before: Callable[[], None] = lambda: None) -> tuple[float, str]:
    """Seconds per call (minimum over ``rounds`` of the mean) and the last round's digest."""
    best, digest = math.inf, ""
    for _ in range(rounds):
        before()
        c0 = time.thread_time()
        digest = replay(calls)
        best = min(best, (time.thread_time() - c0) / len(calls))
    return best, digest


class Tape:
    """The results of some functions, recorded in call order and then played back (``play``)
    or computed again (``through``)."""

    def __init__(self, functions: tuple[tuple[Any, str], ...]) -> None:
        self.functions = functions
        self.originals = [getattr(mod, name) for mod, name in functions]
        self.tapes: list[list[Any]] = [[] for _ in functions]
        self.positions = [0] * len(functions)
        self.mode = "record"

    def __enter__(self) -> Tape:
        for k, ((mod, name), fn) in enumerate(zip(self.functions, self.originals, strict=True)):
            setattr(mod, name, self._wrap(k, fn))
        return self

    def __exit__(self, *exc: object) -> None:
        for (mod, name), fn in zip(self.functions, self.originals, strict=True):
            setattr(mod, name, fn)

    def _wrap(self, k: int, fn: Callable[..., Any]) -> Callable[..., Any]:
        tape = self.tapes[k]

        def stage(*args: Any, **kw: Any) -> Any:
            if self.mode == "play":
                i = self.positions[k]
                self.positions[k] = i + 1
                return tape[i]
            out = fn(*args, **kw)
            if self.mode == "record":
                tape.append(out)
            return out
        return stage

    def set(self, mode: str) -> None:
        self.mode = mode
        self.positions = [0] * len(self.functions)


def taken_away(calls: list[Call], functions: tuple[tuple[Any, str], ...], rounds: int,
               digest: str) -> tuple[float, float]:
    """Seconds per call as they are and with ``functions`` answering from a recording of their
    results, in alternate rounds (the same machine load for both)."""
    with Tape(functions) as tape:
        replay(calls)
        tape.set("through")
        full, _ = timed(calls, 1)
        tape.set("play")
        away, got = timed(calls, 1)
        for _ in range(rounds - 1):
            tape.set("through")
            full = min(full, timed(calls, 1)[0])
            tape.set("play")
            away = min(away, timed(calls, 1)[0])
    if got != digest:
        raise SystemExit(f"the replay with {[name for _, name in functions]} taken away planned differently "
                         f"({got} != {digest}): the stage's results depend on more than the call order")
    return full, away


def daqp_alone(calls: list[Call], rounds: int) -> tuple[float, int]:
    """Seconds per call of ``daqp.solve`` on the calls' reduced QPs, and their number."""
    import daqp  # type: ignore[import-not-found]

    qps: list[tuple[Any, ...]] = []
    original = solve._solve_two_sided

    def record(H: Any, g: Any, G: Any, lower: Any, upper: Any, options: dict[str, Any]) -> Any:
        opts = {k: v for k, v in options.items() if k != "verbose"}
        qps.append((np.array(H), g, np.ascontiguousarray(G), np.where(np.isfinite(upper), upper, solve._INF),
                    np.where(np.isfinite(lower), lower, -solve._INF), np.zeros(G.shape[0], dtype=np.intc), opts))
        return original(H, g, G, lower, upper, options)

    solve._solve_two_sided = record  # type: ignore[assignment]
    try:
        replay(calls)
    finally:
        solve._solve_two_sided = original  # type: ignore[assignment]
    best = math.inf
    for _ in range(rounds):
        c0 = time.thread_time()
        for H, g, G, bu, bl, sense, opts in qps:
            daqp.solve(H, g, G, bu, bl, sense, **opts)
        best = min(best, (time.thread_time() - c0) / len(calls))
    return best, len(qps)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--distances", type=float, nargs="+", default=[1.5, 4.5, 7.5])
    ap.add_argument("--inclines", type=float, nargs="+", default=[90.0, 45.0], help="degrees")
    ap.add_argument("--rounds", type=int, default=7)
    ap.add_argument("--first-plans", action="store_true",
                    help="the default plan() of bench_pipeline.py's standard scenarios instead of replans")
    args = ap.parse_args()
    if args.first_plans:
        from bench_plan import scenarios

        config = PlannerConfig()
        calls: list[Call] = [(state, target, None, None, config, None) for state, target in scenarios()]
        what = f"{len(calls)} first plans (the standard scenarios of bench_pipeline.py, default configuration)"
    else:
        sim_run.Replanner = RecordingReplanner  # type: ignore[misc]  # the loop builds this class
        for inc in args.inclines:
            for d in args.distances:
                for seed in range(args.seeds):
                    simulate(SimScenario(distance=d, incline=math.radians(inc)), Mode.AVP, seed=seed)
        calls = RecordingReplanner.calls
        n_runs = len(args.inclines) * len(args.distances) * args.seeds
        what = (f"{len(calls)} replanning calls of {n_runs} closed-loop runs (inclines {args.inclines} deg, "
                f"distances {args.distances} m, {args.seeds} seeds)")
    with serial_blas():  # as Replanner.step plans (avp._blas)
        digest = replay(calls)  # warm: the caches as a loop that has run for a while has them
        full, got = timed(calls, args.rounds)
        assert got == digest, "two replays of the same calls planned differently"
        rows = [(label, *taken_away(calls, fns, args.rounds, digest)) for label, fns in STAGES]
        every_full, every = taken_away(calls, tuple(f for label, fns in STAGES if not label.startswith(" ") for f in fns),
                           args.rounds, digest)
        back_end, n_qps = daqp_alone(calls, args.rounds)
    print(f"{what}, replayed with one BLAS thread; CPU ms per call (minimum over {args.rounds} rounds of the "
          "mean):")
    print(f"  {'as they are':<58} {full * 1e3:7.3f}")
    print(f"  {'stage taken away (alternate rounds with and without)':<58} {'with':>7} {'without':>7} "
          f"{'saved':>7} {'share':>6}")
    for label, with_it, seconds in [*rows, ("every stage: the orchestration left", every_full, every)]:
        saved = with_it - seconds
        print(f"  {label:<58} {with_it * 1e3:7.3f} {seconds * 1e3:7.3f} {saved * 1e3:7.3f} {saved / with_it:6.1%}")
    print(f"  daqp.solve alone on the calls' {n_qps} reduced QPs ({n_qps / len(calls):.2f} per call): "
          f"{back_end * 1e3:.3f} ms per call")


if __name__ == "__main__":
    main()
