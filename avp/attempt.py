"""One attempt of the planner: the perching QP (5) solved at fixed segment durations.

:func:`solve_at` is the one home of "solve one QP at fixed durations": it builds the QP with
the workspace rows (:mod:`avp.safety`), solves it, optionally with the field-of-view rows as a
stage (below), certifies the workspace limits and re-solves with refined rows around proven
violations (``workspace.refinement_rounds``). It returns an :class:`Attempt` that carries its
own log lines and timings; the planner (:mod:`avp.planner`) keeps only the time search and the
relaxations.

FoV stage (``config.fov.enabled``; rows (8)-(9), SQP steps, fallback (16)), at the given
durations:

* **Replanning** (a ``previous`` plan is given): solve without FoV rows, linearise the cone (7)
  at ``n_p`` points of that solution and solve again with the rows (one SQP step); if that is
  incompatible (16), return the solution without them. (Linearising on the previous plan, as the
  paper does, centres the trust region (9) on a plan that ends at the previous target estimate and
  starts from the previous anticipated state: in the realistic closed loop 215 of 372 of those
  QPs were incompatible, so most replans flew without FoV rows; ``docs/perception.md``.) The
  step is kept without a visibility score.
* **First plan** (no previous plan): solve without FoV rows, linearise around that solution and
  solve again (an SQP step); repeat, at most ``fov.sqp_iterations`` times, while the visibility
  (:func:`avp.metrics.visibility` on a 200-sample grid, time + path fraction) improves; a step
  that does not improve it is discarded (so FoV on never lowers the visibility of a first plan,
  counted in the cone narrowed by ``fov.margin``, :attr:`~avp.config.FovConfig.score_camera`),
  and after a kept step that gained less than ``fov.sqp_min_gain`` (default 0) no further step is
  taken. If the first FoV step is incompatible, the FoV-free solution is returned and the result says
  the rows were dropped.
* In both, when every FoV row holds at the solution without FoV rows, that solution is also
  optimal with them and is returned without a second solve.

Incompatibility (16) is declared when the back-end reports no solution, raises, or returns a point
whose KKT residuals are out of tolerance (:func:`avp.solve.incompatibility`, next to the back-end
table :data:`avp.solve.BACKENDS`). The FoV rows themselves are built by :mod:`avp.perception`.
"""

from __future__ import annotations

import os
import threading
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import partial

import numpy as np

from . import perception
from ._typing import Array
from .config import PlannerConfig, Relaxation
from .errors import InfeasibleError, SolverError
from .qp.assemble import ConstraintBlock, PerchingQp, build_perching_qp
from .qp.fov import FovLinearisation, fov_times
from .qp.layout import layout_for
from .safety import SafetyReport, certify_workspace, refinement_blocks, workspace_blocks
from .solve import QpOutcome, incompatibility, solve_perching_qp
from .trajectory import Trajectory
from .types import PerchTarget, State

__all__ = ["Attempt", "solve_at", "solve_rows"]


@dataclass
class Attempt:
    """What one attempt at fixed durations produced.

    Attributes
    ----------
    outcome, trajectory:
        The last QP solve of the returned plan and its trajectory (``None``: no solution).
    fov_dropped:
        The plan was solved without FoV rows because they were incompatible (16).
    build, solve, certify:
        Seconds spent assembling, in the back-end and in the workspace certificates.
    log:
        What happened, one line per step, in order.
    safety:
        The workspace certificates of the trajectory (``None``: no workspace limit active or no
        trajectory).
    relaxations:
        Set by the planner: what was relaxed for this attempt.
    waypoint:
        Set by the planner: the QP had :class:`~avp.config.OverhangFlip`'s waypoint rows.
    refined:
        Solved with workspace refinement rows, not the initial rows only.
    rows, rounds:
        The workspace rows the plan was solved with (initial and refinement) and the refinement
        rounds that added them (0: the initial rows only).
    qp:
        The QP solved when it had no FoV rows (a later FoV stage at the same durations starts
        from it).
    sqp_steps, linearisation:
        FoV steps kept and the linearisation of the returned plan's rows.
    out_of_time:
        A refinement round was not started for lack of time (a deadline): the workspace is not
        certified because the attempt was cut short, not because no plan keeps it.
    """

    outcome: QpOutcome | None
    trajectory: Trajectory | None
    fov_dropped: bool = False
    build: float = 0.0
    solve: float = 0.0
    certify: float = 0.0
    log: tuple[str, ...] = ()
    safety: SafetyReport | None = None
    relaxations: tuple[Relaxation, ...] = ()
    waypoint: bool = False
    refined: bool = False
    rows: tuple[ConstraintBlock, ...] = ()
    rounds: int = 0
    qp: PerchingQp | None = None
    sqp_steps: int = 0
    linearisation: FovLinearisation | None = None
    out_of_time: bool = False

    @property
    def safe(self) -> bool:
        return self.safety is None or self.safety.certified


_CAPTURE = threading.RLock()
"""Held while an FoV solve's warnings are captured. ``warnings.catch_warnings`` swaps the
process's filter list and warning display and puts back the ones it found: two threads inside
it at once, the second leaving last, would put back the first's "always" filter and recorder
for good (every later warning of the process, under any filter, appended to a list nobody
reads). Threads planning with avp take turns here instead, so FoV solves of different threads
run one at a time (two threads planning standard scenario 8 together took about 4 % longer);
a wait here is in no build or solve time, and a deadline (wall time) learns of it only after
the solve. Another library's ``catch_warnings`` in another thread can still interleave with
this one, and a warning another thread raises meanwhile is captured into this log: Python's
filters are the process's, not a thread's. A fork waits for a capture in progress (the child
starts with the filters as they were, and this lock free)."""

if hasattr(os, "register_at_fork"):  # the forking thread holds the lock over the fork, then frees it in both
    os.register_at_fork(before=_CAPTURE.acquire, after_in_parent=_CAPTURE.release, after_in_child=_CAPTURE.release)


@dataclass
class _Ledger:
    """The log lines and seconds an attempt accumulates (returned with it)."""

    log: list[str] = field(default_factory=list)
    build: float = 0.0
    solve: float = 0.0

    def attempt(self, outcome: QpOutcome | None, trajectory: Trajectory | None, **kw: object) -> Attempt:
        return Attempt(outcome, trajectory, build=self.build, solve=self.solve, log=tuple(self.log), **kw)  # type: ignore[arg-type]

    def run(self, qp: PerchingQp, cfg: PlannerConfig, label: str, strict: bool,
            initvals: Array | None) -> tuple[QpOutcome | None, str | None]:
        """Solve ``qp``; ``(outcome, None)`` or ``(None, reason)``. ``strict``: back-end errors
        raise and warnings go to the caller's filters; otherwise (an FoV QP, where they are
        expected on an incompatible problem (16)) both are logged."""
        try:
            if strict:  # warnings reach the caller's filters as they are
                out = solve_perching_qp(qp, cfg, initvals)
            else:
                with _CAPTURE, warnings.catch_warnings(record=True) as caught:  # one thread at a time
                    warnings.simplefilter("always")
                    out = solve_perching_qp(qp, cfg, initvals)
                self.log.extend(f"{label}: {w.category.__name__}: {w.message}" for w in caught)
        except InfeasibleError as exc:
            self.log.append(f"{label}: {exc}")
            return None, str(exc)
        except SolverError as exc:
            if strict:
                raise
            self.log.append(f"{label}: {exc}")
            return None, str(exc)
        self.build += out.build_time
        self.solve += out.solve_time
        return out, None


def no_time_for(predicted: float, deadline_at: float | None) -> bool:
    """A step of ``predicted`` seconds started now would end after ``deadline_at`` (a
    ``time.perf_counter`` instant; ``None``: no deadline)."""
    return deadline_at is not None and time.perf_counter() + predicted > deadline_at


def _trajectory(qp: PerchingQp, outcome: QpOutcome, g: float) -> Trajectory | None:
    if not outcome.ok or outcome.c_hat is None:
        return None
    return qp.trajectory(outcome.c_hat, g)


def solve_at(
    state: State,
    target: PerchTarget,
    cfg: PlannerConfig,
    T: Array,
    *,
    previous: Trajectory | None = None,
    initvals: Array | None = None,
    seed: Attempt | None = None,
    worth_fov: Callable[[Trajectory], bool] | None = None,
    ws_rows: dict[bytes, tuple[ConstraintBlock, ...]] | None = None,
    deadline_at: float | None = None,
) -> Attempt:
    """Solve at durations ``T`` with the workspace rows, certify the workspace limits, and
    re-solve with refined rows around proven violations (``workspace.refinement_rounds``).

    ``previous``: the committed plan when replanning (the FoV stage then takes one SQP step).
    ``initvals``: normalised coefficients that warm-start back-ends taking a guess. ``seed``: an
    attempt at the same durations without FoV rows; the FoV stage starts from its QP, its
    workspace rows (refinement rows included) and its solution, and its workspace certificate is
    reused when the stage returns that same plan; further refinement rounds, if the FoV plan
    needs them, continue the search step's (``refinement_margin`` grows with the round). A refined seed
    is not re-derived from the initial rows: when the FoV rows hold at its solution, that
    certified solution is the plan. ``worth_fov``: a test of a first plan's
    FoV-free solution; ``False`` skips the SQP step (the planner: a sampled limit is already
    broken, a time search follows). ``ws_rows``: initial workspace rows by durations, shared by
    the attempts of one plan. ``deadline_at``: a ``time.perf_counter`` instant; a refinement
    round starts only while it, predicted as slow as the slowest round so far, ends before it
    (the attempt is returned uncertified otherwise, and says so).
    """
    ws = cfg.workspace
    if not ws.active:
        return solve_rows(state, target, cfg, T, (), previous=previous, initvals=initvals, seed=seed,
                          worth_fov=worth_fov)
    t0 = time.perf_counter()
    layout = layout_for(cfg.n_segments, cfg.degree)
    knots_rel = np.concatenate([[0.0], np.cumsum(T)])
    key = T.tobytes()
    first_round = 0
    if seed is not None and seed.refined:  # start where the search step's refinement ended
        extra, first_round = seed.rows, seed.rounds
    elif ws_rows is not None and key in ws_rows:  # the same durations in another stage of the plan
        extra = ws_rows[key]
    else:
        extra = workspace_blocks(layout, knots_rel, state, target, cfg)
        if ws_rows is not None:
            ws_rows[key] = extra
    build, solve, certify = time.perf_counter() - t0, 0.0, 0.0
    log: list[str] = []
    last_round = first_round + ws.refinement_rounds
    slowest = rows_build = 0.0  # the slowest round (s) and the last refinement rows' build
    for round_index in range(first_round, last_round + 1):
        t_round = time.perf_counter()  # a round: its solve and certificate (plus its rows' build below)
        attempt = solve_rows(state, target, cfg, T, extra, previous=previous, initvals=initvals,
                             seed=seed if round_index == first_round else None, worth_fov=worth_fov)
        attempt.refined, attempt.rows, attempt.rounds = round_index > 0, extra, round_index
        log.extend(attempt.log)
        build += attempt.build
        solve += attempt.solve
        attempt.build, attempt.solve = build, solve
        if attempt.trajectory is None:
            attempt.certify, attempt.log = certify, tuple(log)
            return attempt
        t_cert = time.perf_counter()
        if seed is not None and round_index == first_round and attempt.trajectory is seed.trajectory \
                and seed.safety is not None:
            report = seed.safety  # the FoV stage returned the search step's own plan, certified
        else:
            report = certify_workspace(attempt.trajectory, target, ws)
        certify += time.perf_counter() - t_cert
        attempt.certify, attempt.safety = certify, report
        if report.certified:
            log.append("workspace certified (" + ", ".join(c.region.name for c in report.checks) + ")")
            attempt.log = tuple(log)
            return attempt
        log.append("workspace: " + "; ".join(str(c) for c in report.checks if not c.certified))
        if round_index == last_round:
            attempt.log = tuple(log)
            return attempt
        slowest = max(slowest, time.perf_counter() - t_round + rows_build)
        if no_time_for(slowest, deadline_at):
            log.append(f"deadline: no time for refinement round {round_index + 1} (predicted {slowest * 1e3:.2f} ms)")
            attempt.log, attempt.out_of_time = tuple(log), True
            return attempt
        tb = time.perf_counter()
        extra = extra + refinement_blocks(layout, knots_rel, attempt.trajectory, report, round_index + 1, cfg)
        rows_build = time.perf_counter() - tb
        build += rows_build
    raise AssertionError("unreachable")  # pragma: no cover


def solve_rows(
    state: State,
    target: PerchTarget,
    cfg: PlannerConfig,
    T: Array,
    extra: tuple[ConstraintBlock, ...],
    *,
    previous: Trajectory | None = None,
    initvals: Array | None = None,
    seed: Attempt | None = None,
    worth_fov: Callable[[Trajectory], bool] | None = None,
) -> Attempt:
    """Build and solve the perching QP at durations ``T`` with the ``extra`` inequality rows,
    through the FoV stage when ``cfg.fov.enabled`` (module docs); no workspace certificate."""
    if cfg.fov.enabled:
        return solve_fov(state, target, cfg, T, extra, previous=previous, initvals=initvals, seed=seed,
                         worth_fov=worth_fov)
    ledger = _Ledger()
    t0 = time.perf_counter()
    qp = build_perching_qp(state, target, cfg, T)
    if extra:
        qp = qp.with_inequalities(*extra)
    ledger.build = time.perf_counter() - t0
    try:
        outcome = solve_perching_qp(qp, cfg, initvals)
    except InfeasibleError as exc:
        ledger.log.append(str(exc))
        return ledger.attempt(None, None)
    ledger.build += outcome.build_time
    ledger.solve += outcome.solve_time
    ledger.log.append(f"QP {cfg.solver}: {outcome.status.value} (max violation {outcome.max_violation:.1e})")
    return ledger.attempt(outcome, _trajectory(qp, outcome, cfg.g), qp=qp)


def solve_fov(
    state: State,
    target: PerchTarget,
    cfg: PlannerConfig,
    T: Array,
    extra: tuple[ConstraintBlock, ...] = (),
    *,
    previous: Trajectory | None = None,
    initvals: Array | None = None,
    seed: Attempt | None = None,
    worth_fov: Callable[[Trajectory], bool] | None = None,
) -> Attempt:
    """The FoV stage (module docs): the QP at durations ``T`` with FoV rows (8)-(9) and the
    fallback (16). ``fov_dropped`` is ``True`` when the returned plan was solved without FoV rows
    because the rows were incompatible. ``extra`` rows are part of every QP, with or without FoV.

    Raises
    ------
    SolverError
        The back-end is missing or failed on the FoV-free QP.
    """
    ledger = _Ledger()
    first = None
    if seed is not None and seed.qp is not None and seed.outcome is not None and seed.trajectory is not None:
        first = (seed.qp, seed.outcome, seed.trajectory)
    t0 = time.perf_counter()
    if first is not None:
        base = first[0]
    else:
        base = build_perching_qp(state, target, cfg, T)
        if extra:
            base = base.with_inequalities(*extra)
    ledger.build = time.perf_counter() - t0
    fov_cfg = perception._fov_config(cfg)
    log = ledger.log

    def plain(label: str) -> tuple[QpOutcome | None, Trajectory | None]:
        out, _err = ledger.run(base, cfg, label, True, initvals)
        if out is None:
            return None, None
        log.append(f"{label} {cfg.solver}: {out.status.value} (max violation {out.max_violation:.1e})")
        return out, _trajectory(base, out, cfg.g)

    def with_rows(reference: Trajectory, label: str, optimum: QpOutcome | None = None,
                  worth: Callable[[], bool] | None = None,
                  ) -> tuple[QpOutcome | None, Trajectory | None, str | None, FovLinearisation]:
        """The QP with FoV rows linearised on ``reference``. ``optimum``: the FoV-free solution
        whose trajectory ``reference`` is; when every row holds there it is also an optimum with
        the rows (the rows only shrink the feasible set, and it stays in it), so it is returned
        without a solve; so it is too when ``worth()`` is False (a first plan whose FoV-free
        solution already breaks a sampled limit: a time search follows)."""
        tb = time.perf_counter()
        # with the FoV-free optimum, the rows may hold there and never be needed: built on demand
        lin = perception.linearise_on(base, reference, target, cfg, build_blocks=optimum is None)
        ledger.build += time.perf_counter() - tb
        n_vis = np.count_nonzero(lin.h0 <= 0.0)
        desc = (f"{label}: {np.count_nonzero(lin.placed)}/{lin.times.size} FoV points placed "
                f"({np.count_nonzero(lin.progress)} progress-only, {n_vis} visible at linearisation)")
        if optimum is not None and optimum.c_hat is not None and lin.hold_at_linearisation:
            held = "every row holds" if lin.placed.any() else "no row placed"
            log.append(f"{desc}; {held} at the solution without them: that solution, not re-solved")
            return optimum, reference, None, lin
        if optimum is not None and worth is not None and not worth():
            log.append(f"{desc}; not solved: the plan without FoV rows already violates a vehicle limit "
                       "(a time search follows)")
            return optimum, reference, None, lin
        tb = time.perf_counter()
        qp = base.with_inequalities(*lin.blocks)
        ledger.build += time.perf_counter() - tb
        out, err = ledger.run(qp, fov_cfg, label, False, initvals)
        why = err if out is None else incompatibility(out)
        if why is not None or out is None:
            log.append(f"{desc}; incompatible (16): {why}")
            return out, None, why, lin
        log.append(f"{desc}; {fov_cfg.solver}: solved (max violation {out.max_violation:.1e})")
        return out, _trajectory(qp, out, cfg.g), None, lin

    replan = previous is not None
    out0: QpOutcome | None
    traj0: Trajectory | None
    if first is not None:
        _qp, out0, traj0 = first
        log.append("QP (before FoV): the search step's solution at these durations")
    else:
        out0, traj0 = plain("QP (replan, before FoV)" if replan else "QP (first plan, before FoV)")
    if traj0 is None or out0 is None:
        return ledger.attempt(out0, None)
    if fov_times(0.0, float(T.sum()), cfg.fov).size == 0:
        log.append("no FoV points: the gate covers the whole plan")
        return ledger.attempt(out0, traj0, qp=base)
    worth0 = partial(worth_fov, traj0) if not replan and worth_fov is not None else None
    best_out, best_traj = out0, traj0
    best_score: float | None = None  # scored with the first step's plan, in one pass
    best_lin: FovLinearisation | None = None
    steps = 0
    for k in range(1 if replan else cfg.fov.sqp_iterations):
        label = "QP + FoV (linearised on that solution)" if replan else f"SQP step {k + 1}"
        out, traj, why, lin = with_rows(best_traj, label, optimum=out0 if k == 0 else None,
                                        worth=worth0 if k == 0 else None)
        if out is out0:  # the rows hold at the FoV-free optimum (its fixed point), or no step is worth it
            best_lin = lin
            break
        if why is not None or traj is None or out is None:
            if k == 0:
                log.append("FoV rows dropped (16): returning the plan without them")
                return ledger.attempt(out0, traj0, fov_dropped=True, linearisation=lin, qp=base)
            break
        if replan:  # one step, kept: no visibility score in the loop
            best_out, best_traj, best_lin, steps = out, traj, lin, 1
            break
        if best_score is None:
            best_score, score = perception._scores((traj0, traj), target, cfg)
        else:
            (score,) = perception._scores((traj,), target, cfg)
        log.append(f"SQP step {k + 1}: visibility time+path {score / 2:.3f} (was {best_score / 2:.3f})")
        if score <= best_score + 1e-4:
            if k == 0 and score < best_score - 1e-4:
                log.append("SQP step 1 lowered the visibility: keeping the first solution")
            break
        gain = (score - best_score) / 2
        best_out, best_traj, best_score, best_lin, steps = out, traj, score, lin, k + 1
        if gain < cfg.fov.sqp_min_gain and k + 1 < cfg.fov.sqp_iterations:
            log.append(f"SQP: the step raised the visibility by {gain:.4f} < fov.sqp_min_gain "
                       f"{cfg.fov.sqp_min_gain:g}: no further step")
            break
    return ledger.attempt(best_out, best_traj, sqp_steps=steps, linearisation=best_lin,
                          qp=base if steps == 0 else None)
