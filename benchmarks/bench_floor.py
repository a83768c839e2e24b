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
  stage and the workspace rounds, the input checks, logs and result objects) and the numeric
  work outside the stages (trajectory objects, the endpoint checks, the time search's own
  sampling), the floor of a design that keeps those decisions in Python;
* the reduced QPs of the same calls back to back: ``daqp.solve`` alone, its inputs prepared
  outside the timing (in the least-distance form avp gives it: the back-end's own share of the
  solve stage), and with avp's wrapper.

A played-back result is returned as its producer returned it: a shallow copy without the
values cached on it afterwards (a FoV linearisation's rows, a QP's reduction), so the planner
computes those again where it did; a recorded exception is raised again. Differences of about
0.02 ms are noise (two rounds of the same code differ by that much).

The stages: building the QP (``build_perching_qp``), the workspace rows (``workspace_blocks``
and ``refinement_blocks``), the FoV linearisation (``perception.linearise_on``) and the FoV
rows it builds when a QP needs them (``qp.fov.fov_rows``), the visibility score of a first plan's
SQP steps (``perception._scores``) and the sampled limit check before them (the excess
kernel's call, ``time_search._excess``, as the planner makes it there; the time search's own
sampling stays), reducing and solving the QPs (``solve_perching_qp``; and, each taken away alone, its parts: the equality elimination and
reduced rows of ``PerchingQp.reduce``, the DAQP call with its solution object, the lift and the
feasibility check of ``solve._outcome``), the bound certificate (``planner._certify``) and the workspace certificate
(``certify_workspace``). Nothing is asserted; the numbers are for this machine and its load.
"""

from __future__ import annotations

import argparse
import dataclasses
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
    ("sampled limit check before the SQP (first plans)", ((planner, "_excess"),)),
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


def _state(value: Any) -> Any:
    """What of ``value`` its producer made: the keys of every dataclass's ``__dict__`` (its
    fields and the cached values filled so far), in nested dataclasses and tuples too."""
    if isinstance(value, tuple):
        return tuple(_state(v) for v in value)
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        d = value.__dict__
        return frozenset(d), {k: _state(v) for k, v in d.items()
                              if isinstance(v, tuple) or (dataclasses.is_dataclass(v) and not isinstance(v, type))}
    return None


def _as_recorded(value: Any, state: Any) -> Any:
    """``value`` as its producer returned it: a shallow copy without the cached values that later
    code filled in (the same object when there are none), so the planner computes them again."""
    if state is None:
        return value
    if isinstance(value, tuple):
        items = tuple(_as_recorded(v, st) for v, st in zip(value, state, strict=True))
        return value if all(a is b for a, b in zip(items, value, strict=True)) else type(value)(items)
    keys, children = state
    d = value.__dict__
    fresh = {k: _as_recorded(d[k], st) for k, st in children.items()}
    if len(d) == len(keys) and all(fresh[k] is d[k] for k in fresh):
        return value
    copy = object.__new__(type(value))
    object.__setattr__(copy, "__dict__", {k: fresh.get(k, d[k]) for k in keys})
    return copy


class Tape:
    """The results of some functions, recorded in call order (returned values with what their
    producer had computed of them, raised exceptions) and then played back (``play``) or
    computed again (``through``)."""

    def __init__(self, functions: tuple[tuple[Any, str], ...]) -> None:
        self.functions = functions
        self.originals = [getattr(mod, name) for mod, name in functions]
        self.tapes: list[list[tuple[bool, Any, Any]]] = [[] for _ in functions]
        self.positions = [0] * len(functions)
        self.mode = "record"

    def __enter__(self) -> Tape:
        for k, ((mod, name), fn) in enumerate(zip(self.functions, self.originals, strict=True)):
            setattr(mod, name, self._wrap(k, fn))
        return self

    def __exit__(self, *exc: object) -> None:
        for (mod, name), fn in zip(self.functions, self.originals, strict=True):
            setattr(mod, name, fn)

    @property
    def recorded(self) -> int:
        return sum(map(len, self.tapes))

    def _wrap(self, k: int, fn: Callable[..., Any]) -> Callable[..., Any]:
        tape = self.tapes[k]

        def stage(*args: Any, **kw: Any) -> Any:
            if self.mode == "play":
                i = self.positions[k]
                self.positions[k] = i + 1
                raised, value, state = tape[i]
                if raised:
                    raise value
                return _as_recorded(value, state)
            if self.mode != "record":
                return fn(*args, **kw)
            try:
                out = fn(*args, **kw)
            except Exception as exc:  # the planner catches some (InfeasibleError): play them back too
                tape.append((True, exc, None))
                raise
            tape.append((False, out, _state(out)))
            return out
        return stage

    def set(self, mode: str) -> None:
        self.mode = mode
        self.positions = [0] * len(self.functions)


def taken_away(calls: list[Call], functions: tuple[tuple[Any, str], ...], rounds: int,
               digest: str) -> tuple[float, float, int]:
    """Seconds per call as they are and with ``functions`` answering from a recording of their
    results, in alternate rounds (the same machine load for both), and the number of results
    recorded (0: the calls never reach them)."""
    full = away = math.inf
    with Tape(functions) as tape:
        replay(calls)
        for _ in range(rounds):
            for mode in ("through", "play"):
                tape.set(mode)
                seconds, got = timed(calls, 1)
                if got != digest:
                    raise SystemExit(f"the replay with {[name for _, name in functions]} in mode {mode!r} planned "
                                     f"differently ({got} != {digest}): the stage's results depend on more than "
                                     "the call order")
                if mode == "through":
                    full = min(full, seconds)
                else:
                    away = min(away, seconds)
    return full, away, tape.recorded


def back_end_alone(calls: list[Call], rounds: int) -> tuple[float, float, int]:
    """Seconds per call of ``daqp.solve`` on the calls' reduced QPs (its inputs prepared outside
    the timing) and of ``solve._solve_two_sided`` (the same call with its input preparation and
    solution object), each run back to back; and the number of QPs."""
    import daqp  # type: ignore[import-not-found]

    qps: list[tuple[Any, ...]] = []
    original = solve._solve_two_sided

    def record(H: Any, g: Any, G: Any, lower: Any, upper: Any, options: dict[str, Any], ldp: Any = None) -> Any:
        opts = {k: v for k, v in options.items() if k != "verbose"}
        bu, bl = np.where(np.isfinite(upper), upper, solve._INF), np.where(np.isfinite(lower), lower, -solve._INF)
        sense = np.zeros(G.shape[0], dtype=np.intc)
        if ldp is not None and solve._VARIABLE_OPTIONS.isdisjoint(opts):  # the least-distance form, as avp gives it
            inputs = (np.eye(H.shape[0]), ldp.v, ldp.M, bu, bl, sense, opts)
        else:
            inputs = (np.array(H), g, np.ascontiguousarray(G), bu, bl, sense, opts)
        qps.append(((H, g, G, lower, upper, options, ldp), inputs))
        return original(H, g, G, lower, upper, options, ldp)

    solve._solve_two_sided = record  # type: ignore[assignment]
    try:
        replay(calls)
    finally:
        solve._solve_two_sided = original  # type: ignore[assignment]
    bare = wrapped = math.inf
    for _ in range(rounds):
        c0 = time.thread_time()
        for _args, (H, g, G, bu, bl, sense, opts) in qps:
            daqp.solve(H, g, G, bu, bl, sense, **opts)
        c1 = time.thread_time()
        for args, _ in qps:
            original(*args)
        c2 = time.thread_time()
        bare, wrapped = min(bare, (c1 - c0) / len(calls)), min(wrapped, (c2 - c1) / len(calls))
    return bare, wrapped, len(qps)


def _positive(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {value}")
    return value


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=_positive, default=2)
    ap.add_argument("--distances", type=float, nargs="+", default=[1.5, 4.5, 7.5])
    ap.add_argument("--inclines", type=float, nargs="+", default=[90.0, 45.0], help="degrees")
    ap.add_argument("--rounds", type=_positive, default=7)
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
    if not calls:
        raise SystemExit("no planning call to replay: the runs made no replanning call")
    with serial_blas():  # as Replanner.step plans (avp._blas)
        digest = replay(calls)  # warm: the caches as a loop that has run for a while has them
        full, got = timed(calls, args.rounds)
        if got != digest:
            raise SystemExit(f"two replays of the same calls planned differently ({got} != {digest})")
        rows = [(label, *taken_away(calls, fns, args.rounds, digest)) for label, fns in STAGES]
        whole = tuple(f for label, fns in STAGES if not label.startswith(" ") for f in fns)
        rows.append(("every stage: what is left", *taken_away(calls, whole, args.rounds, digest)))
        daqp_ms, wrapper_ms, n_qps = back_end_alone(calls, args.rounds)
    print(f"{what}, replayed with one BLAS thread; CPU ms per call (minimum over {args.rounds} rounds of the "
          "mean):")
    print(f"  {'as they are':<58} {full * 1e3:7.3f}")
    print(f"  {'stage taken away (alternate rounds with and without)':<58} {'with':>7} {'without':>7} "
          f"{'saved':>7} {'share':>6}")
    for label, with_it, seconds, recorded in rows:
        if not recorded:
            print(f"  {label:<58} {'not called':>30}")
            continue
        saved = with_it - seconds
        print(f"  {label:<58} {with_it * 1e3:7.3f} {seconds * 1e3:7.3f} {saved * 1e3:7.3f} {saved / with_it:6.1%}")
    print(f"  the calls' {n_qps} reduced QPs ({n_qps / len(calls):.2f} per call), back to back: daqp.solve alone "
          f"{daqp_ms * 1e3:.3f} ms per call, with avp's wrapper (solve._solve_two_sided) {wrapper_ms * 1e3:.3f}")


if __name__ == "__main__":
    main()
