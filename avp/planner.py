"""Planning entry points: :func:`plan` (returns a :class:`Trajectory` or raises) and
:func:`plan_detailed` (returns a :class:`PlanResult` that says what happened)."""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from enum import Enum
from typing import Any

import numpy as np

from . import _validate as v
from ._blas import serial
from ._typing import Array
from .attempt import Attempt, no_time_for, solve_at
from .bounds import BoundReport, certify_trajectory
from .config import PlannerConfig, PreImpactMode, Relaxation, _default_planner_config
from .errors import (
    BoundsNotCertifiedError,
    ConfigError,
    InfeasibleError,
    PlanningError,
    RelaxedPlanError,
    SolverError,
    WorkspaceNotCertifiedError,
)
from .frames import MAX_CONTACT_ROLL, thrust_vector
from .platform import MovingTarget
from .qp.assemble import ConstraintBlock
from .qp.layout import DecisionLayout, layout_for
from .qp.perching import flip_time, is_overhang
from .request import check_request
from .safety import SafetyReport, check_endpoints
from .solve import WARM_START_SOLVERS, QpOutcome
from .time_search import _ONE, DurationSearch, _excess
from .timing import check_durations, initial_durations
from .trajectory import Provenance, Trajectory
from .types import PerchTarget, State

__all__ = ["PlanResult", "PlanStatus", "PlanTimings", "plan", "plan_detailed"]


MAX_GUESS = 1e9
"""Largest normalised coefficient of a warm start's fit that is passed to a back-end."""

STILL_SPEED = 0.1
"""A start closer than ``config.min_distance`` to the target is rejected only when slower than
this (m/s): a vehicle at rest on the target has nothing to plan, while a replan from a moving
vehicle just before contact is well posed."""


class PlanStatus(Enum):
    """Outcome of a plan (readable values, as rotorpy's ExitStatus)."""

    SOLVED = "solved: every constraint met"
    SOLVED_WITHOUT_FOV = "solved after dropping the field-of-view rows (16, or a deadline)"
    SOLVED_RELAXED = "solved with soft constraints relaxed (see relaxations)"
    INFEASIBLE = "infeasible: the perching constraints admit no trajectory"
    SOLVER_FAILED = "solver failed: no usable solution from the QP back-end"
    BOUNDS_NOT_CERTIFIED = "actuator bounds not certified within the allowed time changes"
    WORKSPACE_NOT_CERTIFIED = "no trajectory keeps the workspace limits certified (see safety)"
    OUT_OF_TIME = "stopped at the deadline before a certified plan (see log)"
    """Only with ``plan_detailed(deadline=...)``. Like the other failures, ``ok`` is False; a
    ``trajectory``, if set, is the last uncertified attempt, for diagnostics only."""

    @property
    def has_trajectory(self) -> bool:
        """A certified trajectory was returned (possibly relaxed: check ``relaxations``)."""
        return self in (PlanStatus.SOLVED, PlanStatus.SOLVED_WITHOUT_FOV, PlanStatus.SOLVED_RELAXED)


@dataclass(frozen=True, kw_only=True)
class PlanTimings:
    """Wall-clock seconds spent in each stage (summed over re-solves)."""

    build: float = 0.0
    solve: float = 0.0
    certify: float = 0.0
    total: float = 0.0


@dataclass(frozen=True, kw_only=True)
class PlanResult:
    """Everything a plan produced.

    Attributes
    ----------
    status:
        :class:`PlanStatus`.
    trajectory:
        The plan, or ``None`` when there is none to give.
    durations:
        Segment durations of the last QP solved (s).
    qp:
        Outcome of the last QP solve (solver, residuals, the qpsolvers ``Solution``).
    log:
        Human-readable record of what the planner did, in order.
    timings:
        :class:`PlanTimings`.
    fov_dropped:
        The FoV rows were dropped as incompatible (16), or, with a ``deadline``, for lack of time
        (the log says which).
    duration_scale_steps:
        QP re-solves made by the time search and relaxations after the first one.
    bounds:
        The :class:`~avp.bounds.BoundReport` of the returned (or last) trajectory.
    relaxations:
        What was relaxed for the returned (or, on failure, the last) trajectory
        (:class:`~avp.config.Relaxation`); a certified plan has it non-empty exactly when the
        status is ``SOLVED_RELAXED``.
    safety:
        The :class:`~avp.safety.SafetyReport` (workspace certificates) of the returned (or last)
        trajectory; ``None`` when no workspace limit is active or nothing was solved.
    """

    status: PlanStatus
    trajectory: Trajectory | None
    durations: Array
    qp: QpOutcome | None
    log: tuple[str, ...] = ()
    timings: PlanTimings = field(default_factory=PlanTimings)
    fov_dropped: bool = False
    duration_scale_steps: int = 0
    bounds: BoundReport | None = None
    relaxations: tuple[Relaxation, ...] = ()
    safety: SafetyReport | None = None

    @property
    def ok(self) -> bool:
        return self.status.has_trajectory and self.trajectory is not None

    def __repr__(self) -> str:
        """One line: the status, the plan and what stands behind it (the QP's arrays, the
        certificates' cells and the log are attributes, not part of the repr)."""
        parts = [f"status={self.status.name}", f"trajectory={self.trajectory!r}",
                 f"durations={np.round(self.durations, 4).tolist()}",
                 f"attempts={self.duration_scale_steps + 1}"]  # the first attempt always runs
        if self.trajectory is None:  # else its provenance (in its repr) says all of this
            if self.relaxations:
                parts.append(f"relaxations={[r.name for r in self.relaxations]}")
            if self.bounds is not None:
                parts.append(f"bounds_certified={self.bounds.certified}")
            if self.safety is not None:
                parts.append(f"workspace_certified={self.safety.certified}")
        parts.append(f"total={self.timings.total * 1e3:.3f} ms, {len(self.log)} log lines")
        return f"PlanResult({', '.join(parts)})"


def _check_inputs(state: Any, target: Any, config: Any) -> PlannerConfig:
    if not isinstance(state, State):
        raise ConfigError("state", f"expected avp.State, got {type(state).__name__}")
    if not isinstance(target, PerchTarget):
        raise ConfigError("target", f"expected avp.PerchTarget, got {type(target).__name__}")
    if isinstance(target, MovingTarget) and not target.is_static:
        raise ConfigError("target", "is a moving pad: plan with avp.plan_moving (or pass target.static())")
    if config is None:  # one shared frozen default: its stage configurations are cached (_derived)
        config = _default_planner_config()
    if not isinstance(config, PlannerConfig):
        raise ConfigError("config", f"expected avp.PlannerConfig, got {type(config).__name__}")
    distance = float(np.linalg.norm(target.point - state.position))
    if distance < config.min_distance and float(np.linalg.norm(state.velocity)) < STILL_SPEED:
        raise ConfigError(
            "target.point",
            f"is {distance:.3f} m from a start state at rest (config.min_distance = "
            f"{config.min_distance} m); a perch needs a target away from the vehicle",
        )
    config.contact_alpha(target.incline)  # raises ConfigError when the limits leave no room
    check_endpoints(state, target, config)
    return config


def _certify(traj: Trajectory, cfg: PlannerConfig) -> BoundReport:
    """Algorithm 1 on every bound and segment (Rust), with the limits mass-normalised.

    The floating-point path runs first: a proven violation already fails the plan, so the exact
    fallback (up to :data:`~avp.bounds.EXACT_BUDGET` on near-tangent cells) runs only when that
    path left cells undecided and proved nothing violated. A failed plan's report may then keep
    UNKNOWN cells next to its proven violations; a certified one is decided everywhere."""
    fast = certify_trajectory(traj, cfg.limits, cfg.g, exact=False)
    if fast.certified or fast.violations or not fast.unknown:
        return fast
    return certify_trajectory(traj, cfg.limits, cfg.g)


_DERIVED: dict[tuple[int, object], tuple[PlannerConfig, PlannerConfig]] = {}
"""Configurations :func:`plan_detailed` derives from another (a stage's, one without FoV rows),
by the identity of the one they derive from and what was changed (:func:`_derived`)."""

_DERIVED_SIZE = 64
"""Entries of :data:`_DERIVED` kept (all are dropped when it is full)."""


def _derived(cfg: PlannerConfig, change: object, make: Callable[[], PlannerConfig]) -> PlannerConfig:
    """``make()``, a configuration derived from ``cfg`` by ``change``, built once per ``cfg``
    object. ``dataclasses.replace`` validates every field again (about 50 us a call); the
    replanner passes the same configuration at every step, so its stages' configurations are
    the same objects at every call. The entry keeps ``cfg`` alive, so its ``id`` is not reused
    while it is cached; a frozen configuration derives the same values every time."""
    key = (id(cfg), change)
    hit = _DERIVED.get(key)
    if hit is not None and hit[0] is cfg:
        return hit[1]
    out = make()
    if len(_DERIVED) >= _DERIVED_SIZE:
        _DERIVED.clear()
    _DERIVED[key] = (cfg, out)
    return out


def _relax(cfg: PlannerConfig, relaxation: Relaxation, target: PerchTarget) -> PlannerConfig:
    """``cfg`` with one more :class:`Relaxation` applied (cached per ``cfg``, :func:`_derived`;
    ``ALPHA_RANGE`` depends on the pad's incline too)."""
    change = (relaxation, target.incline) if relaxation is Relaxation.ALPHA_RANGE else relaxation
    return _derived(cfg, change, lambda: _relaxed(cfg, relaxation, target))


def _relaxed(cfg: PlannerConfig, relaxation: Relaxation, target: PerchTarget) -> PlannerConfig:
    if relaxation is Relaxation.ALPHA_RANGE:
        alpha = cfg.contact_alpha(target.incline)
        # Around the nominal alpha (min-snap otherwise drives it to an extreme) and strictly
        # inside the thrust limits (a touching bound counts as violated).
        lo, hi = cfg.limits.accel_min, cfg.limits.accel_max
        margin = 0.05 * (hi - lo)
        return replace(cfg, alpha_range=(max(lo + margin, 0.5 * alpha), min(hi - margin, 2.0 * alpha)))
    if relaxation is Relaxation.FREE_SLIDE:
        return replace(cfg, contact_velocity=replace(cfg.contact_velocity, slope=None))
    if relaxation is Relaxation.CONE_BAND:
        return replace(cfg, pre_impact=PreImpactMode.CONE)
    return replace(cfg, pre_impact=PreImpactMode.OFF)


def _fit_initvals(warm: Trajectory, layout: DecisionLayout, knots: Array) -> Array:
    """Least-squares projection of ``warm`` onto the spline space of ``knots`` (normalised
    coefficients): an initial guess for back-ends that take one."""
    u = layout.fit_nodes
    out = np.empty((4, layout.n_segments, layout.n_coeffs))
    with np.errstate(over="ignore", invalid="ignore"):
        for i in range(layout.n_segments):
            t = np.clip(knots[i] + u * (knots[i + 1] - knots[i]), warm.t0, warm.tf)
            out[:, i, :] = (layout.fit_pinv @ warm.evaluate(t)).T
    return out.reshape(-1)


@serial  # one BLAS thread: no helper threads spinning after the call (avp._blas)
def plan_detailed(
    state: State,
    target: PerchTarget,
    config: PlannerConfig | None = None,
    *,
    durations: Any = None,
    previous: Trajectory | None = None,
    warm_start: Trajectory | None = None,
    deadline: float | None = None,
) -> PlanResult:
    """Plan a perch and report what happened; raises only for bad input or a missing solver.

    Solves the perching QP (5), certifies the vehicle limits on the whole trajectory (Alg. 1,
    Rust), and when a bound fails searches the total duration (``config.bounds``), then relaxes
    the problem step by step (:class:`~avp.config.Relaxation`), recording each change in ``log``.
    Runs with one BLAS thread, process-wide while it runs (``avp._blas``).

    Parameters
    ----------
    state:
        Start state; the plan starts at ``state.time``.
    target:
        Perch pad (point and ``R_WS``).
    config:
        :class:`PlannerConfig` (paper defaults when ``None``).
    durations:
        Segment durations (s) overriding the allocation rule. The time search still scales them
        when a bound fails; pass ``BoundsPolicy(factors=(), max_steps=0, relaxations=())`` to keep
        them (``max_steps=0`` for :attr:`TimeSearch.PAPER <avp.TimeSearch.PAPER>`, which grows
        them by ``growth`` otherwise).
    previous:
        The committed plan when replanning. It marks the call as a replan: the FoV stage then
        takes one SQP step on the new plan's FoV-free solution and keeps it without a visibility
        score (:mod:`avp.attempt`); the plan's coefficients are not used. On an overhang, a
        committed plan planned without :class:`~avp.config.OverhangFlip`'s waypoint (its
        ``provenance.overhang_waypoint`` is ``False``) is replanned without it first, then
        with it, before any relaxation: a wall estimate that tips past ``flip.min_incline``
        mid-flight does not start with a search through a waypoint the committed plan never
        had. A plan found without it records ``False`` again, so this holds for the rest of
        a flight whose first plan had no waypoint, for as long as such plans certify.
    warm_start:
        A plan whose shape seeds the back-end's initial guess (ProxQP, OSQP; DAQP ignores it).
    deadline:
        A time budget (s, wall clock, from the call): an attempt after the first (a time-search
        step, a stage, the FoV re-solve of a certified step), or a workspace refinement round
        within one, starts only while it, predicted as slow as the slowest so far, fits (an
        attempt cut short is not certified and says so; the first attempt's first round always
        runs). When none fits the plan ends with ``PlanStatus.OUT_OF_TIME`` (``ok`` is False),
        or, when only the FoV re-solve is left, with its certified FoV-free plan and
        ``fov_dropped`` set (``SOLVED_WITHOUT_FOV``, or ``SOLVED_RELAXED`` for a relaxed one).
        ``None``: no budget (the decisions then do not depend on the machine's speed).
    """
    t_start = time.perf_counter()
    if deadline is not None:
        deadline = v.positive_float("deadline", deadline)
    deadline_at = None if deadline is None else t_start + deadline
    cfg = _check_inputs(state, target, config)
    for name, value in (("previous", previous), ("warm_start", warm_start)):
        if value is not None and not isinstance(value, Trajectory):
            raise ConfigError(name, f"expected avp.Trajectory or None, got {type(value).__name__}")
    T0 = check_durations(durations, cfg) if durations is not None else initial_durations(state, target, cfg)
    check_request(state, target, cfg, float(T0.sum()))  # physical sense of the request
    log: list[str] = [f"durations {np.round(T0, 4).tolist()} s ({'given' if durations is not None else 'allocated'})"]
    frame_error = target._frame_error(cfg.g)
    if frame_error > 1e-6:
        log.append(f"contact attitude: R_WS is not representable by the attitude construction (13) (roll "
                   f"beyond {math.degrees(MAX_CONTACT_ROLL):.1f} deg); b3 = s3 exactly, the rotation about s3 "
                   f"differs from R_WS by {math.degrees(frame_error):.2f} deg")
    build = solve = certify = 0.0
    attempts = 0
    slowest = 0.0  # the longest attempt so far (s): the predicted cost of the next (deadline)
    cut_short = False  # an attempt's refinement rounds were cut by the deadline

    def out_of_time() -> bool:
        """With a deadline: no further attempt, as slow as the slowest so far, fits."""
        if attempts == 0 or not no_time_for(slowest, deadline_at):
            return False
        log.append(f"deadline {(deadline or 0.0) * 1e3:.2f} ms: stopped after {attempts} attempt(s) in "
                   f"{(time.perf_counter() - t_start) * 1e3:.2f} ms (the next predicted {slowest * 1e3:.2f} ms)")
        return True

    def stopped() -> PlanResult:
        """``OUT_OF_TIME`` with the last attempt (uncertified, for diagnostics)."""
        return finish(PlanStatus.OUT_OF_TIME, last, T0 if last is None or last.trajectory is None
                      else last.trajectory.durations)
    relaxed: list[Relaxation] = []
    last: Attempt | None = None
    unsafe: Attempt | None = None  # latest attempt whose bounds held but whose workspace did not
    unsafe_report: BoundReport | None = None  # its (certified) bound report
    report: BoundReport | None = None

    def finish(status: PlanStatus, attempt: Attempt | None, T: Array) -> PlanResult:
        traj = attempt.trajectory if attempt else None
        if traj is not None:
            traj.provenance = Provenance(
                status=status.value,
                relaxations=tuple(r.name for r in attempt.relaxations) if attempt else (),
                bounds_certified=bool(report is not None and report.certified and status.has_trajectory),
                workspace_certified=bool(attempt is not None and attempt.safe and attempt.safety is not None),
                fov_dropped=bool(attempt and attempt.fov_dropped),
                overhang_waypoint=bool(attempt and attempt.waypoint),
            )
        return PlanResult(
            status=status, trajectory=traj, durations=T, qp=attempt.outcome if attempt else None,
            log=tuple(log),
            timings=PlanTimings(build=build, solve=solve, certify=certify, total=time.perf_counter() - t_start),
            fov_dropped=bool(attempt and attempt.fov_dropped), duration_scale_steps=max(attempts - 1, 0),
            bounds=report, relaxations=attempt.relaxations if attempt else (),
            safety=attempt.safety if attempt else None,
        )

    def solved(attempt: Attempt) -> PlanStatus:
        if relaxed:
            return PlanStatus.SOLVED_RELAXED
        return PlanStatus.SOLVED_WITHOUT_FOV if attempt.fov_dropped else PlanStatus.SOLVED

    def within_sampled(traj: Trajectory) -> bool:
        # A sample beyond a limit is a proven violation of the certified quantity, so the SQP
        # step of the first plan would be wasted: the time search starts without it.
        # the kernel at scale 1 (s^-2 = 1) on checked arguments: scaled_excess without its validation
        return float(_excess(traj, cfg.limits, cfg.g, _ONE, per_segment=4)[0]) <= 0.0

    # The initial workspace rows depend on the durations, the start and the target only (never
    # relaxed): built once per durations of this plan.
    ws_rows: dict[bytes, tuple[ConstraintBlock, ...]] = {}

    # Stages: as asked; on an overhang, without the horizontal-thrust waypoint (a planner
    # heuristic, not a user constraint: a plan found without it is still SOLVED); then the
    # relaxations, cumulatively on the configuration as asked.
    # A replan of a committed plan planned without the waypoint (its pad was no overhang, or the
    # waypoint was dropped) searches without it first, then with it; both before any relaxation.
    stages: list[Relaxation | str | None] = [None]
    if cfg.bounds.certify and is_overhang(target, cfg):
        prov = previous.provenance if previous is not None else None
        if prov is not None and prov.overhang_waypoint is False:
            stages = [_WITHOUT_WAYPOINT, None]
        else:
            stages.append(_WITHOUT_WAYPOINT)
    if cfg.bounds.certify:
        # The band relaxations that relax nothing are not run: CONE_BAND where the band is the
        # cone already (CONE, or an overhang's PAPER band with OverhangFlip.cone_band), where it
        # would repeat the previous stage's solves, or where there is no band (OFF), where it
        # would add one; NO_BAND without a band. Each would report a relaxation that did not happen.
        off = cfg.pre_impact is PreImpactMode.OFF
        cone = cfg.pre_impact is PreImpactMode.CONE or (
            cfg.pre_impact is PreImpactMode.PAPER and cfg.flip.cone_band and is_overhang(target, cfg))
        moot = {Relaxation.CONE_BAND} if cone else {Relaxation.CONE_BAND, Relaxation.NO_BAND} if off else set()
        stages += [r for r in cfg.bounds.relaxations if r not in moot]
    stage_cfg = cfg
    for stage in stages:
        if stage is _WITHOUT_WAYPOINT:
            # the waypoint off; the band as asked (flip.enabled off would also drop cone_band's cone)
            stage_cfg = _without_waypoint(cfg)
            log.append(("overhang: searching again without the horizontal-thrust waypoint" if stage is not stages[0]
                        else "overhang: the committed plan has no horizontal-thrust waypoint: replanning without it")
                       + " (a planner heuristic; nothing the request asked is relaxed)")
        elif stage is None and stage is not stages[0]:
            stage_cfg = cfg
            log.append("overhang: searching again with the horizontal-thrust waypoint (nothing the request "
                       "asked is relaxed)")
        elif isinstance(stage, Relaxation):
            stage_cfg = _relax(cfg if not relaxed else stage_cfg, stage, target)
            relaxed.append(stage)
            log.append(f"relaxing: {stage.value} (the workspace limits stay)")
        search = DurationSearch(cfg.bounds, reach=not isinstance(stage, Relaxation))  # reach: nothing relaxed yet
        search_cfg: PlannerConfig | None = None  # stage_cfg without FoV rows, built when first needed
        factor: float | None = 1.0
        while factor is not None:
            if out_of_time():
                return stopped()
            T = T0 * factor
            if factor != 1.0 or stage is not stages[0]:
                log.append(f"durations x{factor:.4g}: total {T.sum():.3f} s")
            initvals = None
            if warm_start is not None and cfg.solver in WARM_START_SOLVERS:
                knots = state.time + np.concatenate([[0.0], np.cumsum(T)])
                initvals = _fit_initvals(warm_start, layout_for(cfg.n_segments, cfg.degree), knots)
                if not (np.isfinite(initvals).all() and float(np.abs(initvals).max()) < MAX_GUESS):
                    log.append("warm start not used: its fit to these knots is not finite or beyond "
                               f"{MAX_GUESS:g} (a guess that large stalls iterative back-ends)")
                    initvals = None
            # The search runs without the FoV rows after the first solve; the rows are added back
            # once a duration certifies (they change the plan little and cost 2-3 QPs each).
            first = stage is stages[0] and factor == 1.0
            if not first and search_cfg is None:
                search_cfg = stage_cfg if not stage_cfg.fov.enabled else _without_fov(stage_cfg)
            attempt_cfg = stage_cfg if first or search_cfg is None else search_cfg
            t_attempt = time.perf_counter()
            attempt = solve_at(state, target, attempt_cfg, T, previous=previous, initvals=initvals,
                               worth_fov=within_sampled if first and cfg.bounds.certify else None,
                               ws_rows=ws_rows, deadline_at=deadline_at)
            slowest = max(slowest, time.perf_counter() - t_attempt)
            cut_short = cut_short or attempt.out_of_time
            log.extend(attempt.log)
            attempt.relaxations = tuple(relaxed)
            attempt.waypoint = stage is not _WITHOUT_WAYPOINT and flip_time(target, stage_cfg, float(T.cumsum()[-1])) is not None
            attempts += 1
            build += attempt.build
            solve += attempt.solve
            certify += attempt.certify
            if attempt.trajectory is None:
                if last is None or last.trajectory is None:
                    last = attempt
                if not cfg.bounds.certify:
                    status = PlanStatus.INFEASIBLE if _infeasible(attempt) else PlanStatus.SOLVER_FAILED
                    return finish(status, attempt, T)
                factor = search.next(None, True, cfg.limits, cfg.g)
                continue
            last = attempt
            if not cfg.bounds.certify:
                if not attempt.safe:
                    status = PlanStatus.OUT_OF_TIME if attempt.out_of_time else PlanStatus.WORKSPACE_NOT_CERTIFIED
                    return finish(status, attempt, T)
                return finish(solved(attempt), attempt, T)
            t_cert = time.perf_counter()
            report = _certify(attempt.trajectory, cfg)
            certify += time.perf_counter() - t_cert
            slowest = max(slowest, time.perf_counter() - t_attempt)
            if report.certified and attempt.safe:
                log.append("bounds certified (Algorithm 1, exact)")
                if attempt_cfg is not stage_cfg and out_of_time():
                    log.append("FoV rows not added back: no time for the re-solve")
                    attempt.fov_dropped = True
                elif attempt_cfg is not stage_cfg:
                    with_fov, fov_report = _with_fov(state, target, stage_cfg, T, log, previous, initvals, attempt,
                                                     report, ws_rows, deadline_at)
                    with_fov.relaxations, with_fov.waypoint = attempt.relaxations, attempt.waypoint
                    attempts += 1
                    build, solve, certify = (build + with_fov.build, solve + with_fov.solve,
                                             certify + with_fov.certify + fov_report[1])
                    if fov_report[0] is not None:
                        report = fov_report[0]
                        return finish(solved(with_fov), with_fov, T)
                    attempt.fov_dropped = True
                return finish(solved(attempt), attempt, T)
            if report.certified:
                unsafe, unsafe_report = attempt, report
                log.append("bounds certified, workspace not: trying other durations")
            else:
                log.append("bounds: " + "; ".join(str(x) for x in report.violations[:3])
                           + ("; undecided: " + str(report.unknown) if report.unknown else ""))
            factor = search.next(attempt.trajectory, not report.certified, cfg.limits, cfg.g)
            if factor is None and search.predicted and not report.certified:
                log.append(f"time search: no total duration predicted to meet the bounds after {search.predicted} "
                           f"step(s) (the violation does not scale away)")
    if cut_short:  # not every duration was tried in full: no verdict on the request
        log.append(f"no certified plan ({attempts} solves): the deadline cut workspace refinement short")
        return stopped()
    if last is None or last.trajectory is None:
        return finish(PlanStatus.INFEASIBLE if last is None or _infeasible(last) else PlanStatus.SOLVER_FAILED, last, T0)
    if unsafe is not None and unsafe.trajectory is not None:
        report = unsafe_report
        failed = ", ".join(unsafe.safety.failed) if unsafe.safety is not None else "workspace"
        log.append(f"no duration in the search and no relaxation kept the workspace certified "
                   f"({attempts} solves): {failed} could not be met")
        return finish(PlanStatus.WORKSPACE_NOT_CERTIFIED, unsafe, unsafe.trajectory.durations)
    log.append(f"no duration in the search and no relaxation gave certified bounds ({attempts} solves); "
               + _measured(last.trajectory, target, cfg))
    return finish(PlanStatus.BOUNDS_NOT_CERTIFIED, last, last.trajectory.durations)


def _without_waypoint(cfg: PlannerConfig) -> PlannerConfig:
    """``cfg`` without :class:`~avp.config.OverhangFlip`'s waypoint and the band as asked
    (``flip.enabled`` off would also drop ``cone_band``'s cone); cached per ``cfg``
    (:func:`_derived`)."""
    def make() -> PlannerConfig:
        cone = cfg.pre_impact is PreImpactMode.PAPER and cfg.flip.cone_band
        return replace(cfg, flip=replace(cfg.flip, enabled=False), pre_impact=PreImpactMode.CONE if cone else cfg.pre_impact)
    return _derived(cfg, _WITHOUT_WAYPOINT, make)


def _without_fov(cfg: PlannerConfig) -> PlannerConfig:
    """``cfg`` without the FoV rows (the time search's; cached per ``cfg``, :func:`_derived`)."""
    return _derived(cfg, "without FoV", lambda: replace(cfg, fov=replace(cfg.fov, enabled=False)))


_WITHOUT_WAYPOINT = "without the overhang waypoint"
"""The :func:`plan_detailed` stage that drops :class:`~avp.config.OverhangFlip`'s waypoint."""


def _measured(traj: Trajectory, target: PerchTarget, cfg: PlannerConfig) -> str:
    """The last plan's extremes on a 1 ms grid against the limits, for the failure message. The
    tilt rate is ``|b3'| = |P f'| / |f|`` (``P = I - b3 b3^T``, ``f = a + g e3 + d v``, ``f' =
    j + d a``: the thrust the certificate bounds), which equals the roll-pitch part
    ``|(w_x, w_y)|`` of the body rates (22) without the attitude."""
    acc, j, _ = traj._thrust_terms(traj.sample(1e-3), cfg.limits.rotor_drag, jerk=True)
    assert j is not None
    f = thrust_vector(acc, traj.g)
    f_norm = np.linalg.norm(f, axis=1)
    b3 = f / f_norm[:, None]
    tilt = float((np.linalg.norm(j - np.sum(j * b3, axis=1)[:, None] * b3, axis=1) / f_norm).max())
    lim = cfg.limits
    return (f"the last plan ({traj.duration:.2f} s, incline {np.degrees(target.incline):.0f} deg) measured "
            f"thrust {f_norm.min():.2f}..{f_norm.max():.2f} m/s^2 against limits {lim.accel_min:.2f}..{lim.accel_max:.2f}, "
            f"tilt rate up to {tilt:.1f} rad/s against {lim.tilt_rate_max:g}")


def _with_fov(
    state: State, target: PerchTarget, cfg: PlannerConfig, T: Array, log: list[str],
    previous: Trajectory | None, initvals: Array | None, seed: Attempt, seed_report: BoundReport,
    ws_rows: dict[bytes, tuple[ConstraintBlock, ...]] | None = None, deadline_at: float | None = None,
) -> tuple[Attempt, tuple[BoundReport | None, float]]:
    """Re-solve a certified search step ``seed`` (bounds: ``seed_report``) with the FoV rows (the
    SQP starts from that step's plan); ``(attempt, (report, seconds))`` with ``report`` set only
    when that plan certifies too (bounds and workspace)."""
    attempt = solve_at(state, target, cfg, T, previous=previous, initvals=initvals, seed=seed, ws_rows=ws_rows,
                       deadline_at=deadline_at)
    log.extend(attempt.log)
    if attempt.out_of_time:
        log.append("FoV rows dropped: the re-solve with them was cut short by the deadline")
        return attempt, (None, 0.0)
    if attempt.trajectory is None or not attempt.safe or attempt.fov_dropped:
        log.append("FoV rows dropped (16): the plan with them did not solve or certify")
        return attempt, (None, 0.0)
    if attempt.trajectory is seed.trajectory:  # the rows held at the search step's plan: certified already
        log.append("FoV rows hold at the certified plan: bounds certified")
        return attempt, (seed_report, 0.0)
    t0 = time.perf_counter()
    report = _certify(attempt.trajectory, cfg)
    seconds = time.perf_counter() - t0
    if not report.certified:
        log.append("FoV rows dropped: the plan with them did not certify the bounds")
        return attempt, (None, seconds)
    log.append("FoV rows added back: bounds certified")
    return attempt, (report, seconds)


def _infeasible(attempt: Attempt) -> bool:
    o = attempt.outcome
    return o is None or (o.solution is not None and not o.solution.found)


def plan(
    state: State,
    target: PerchTarget,
    config: PlannerConfig | None = None,
    *,
    durations: Any = None,
    allow_relaxed: bool = False,
) -> Trajectory:
    """Plan a perch; return the :class:`Trajectory` or raise a :class:`PlanningError`.

    The trajectory's bounds and workspace limits are certified. A plan that needed relaxed soft
    constraints (``PlanStatus.SOLVED_RELAXED``) is returned only with ``allow_relaxed=True``;
    it says so in ``traj.provenance``.

    Raises
    ------
    ConfigError
        Bad input (names the field).
    InfeasibleError, SolverError, BoundsNotCertifiedError, WorkspaceNotCertifiedError
        No trajectory; ``exc.result`` is the :class:`PlanResult`.
    RelaxedPlanError
        Only a relaxed plan exists and ``allow_relaxed`` is false (``exc.result.trajectory``
        holds it).
    """
    allow_relaxed = v.boolean("allow_relaxed", allow_relaxed)
    result = plan_detailed(state, target, config, durations=durations)
    if result.ok and result.trajectory is not None:
        if result.status is PlanStatus.SOLVED_RELAXED and not allow_relaxed:
            raise RelaxedPlanError(
                "a certified plan exists only with relaxed soft constraints ("
                + ", ".join(r.name for r in result.relaxations)
                + "); pass allow_relaxed=True to accept it, or change the request", result)
        return result.trajectory
    message = f"no perching trajectory: {result.status.value}; " + "; ".join(result.log[-2:])
    if result.status is PlanStatus.INFEASIBLE:
        raise InfeasibleError(message, result)
    if result.status is PlanStatus.SOLVER_FAILED:
        raise SolverError(message, result)
    if result.status is PlanStatus.BOUNDS_NOT_CERTIFIED:
        raise BoundsNotCertifiedError(message, result)
    if result.status is PlanStatus.WORKSPACE_NOT_CERTIFIED:
        raise WorkspaceNotCertifiedError(message, result)
    raise PlanningError(message, result)


def planning_error(status: PlanStatus) -> type[PlanningError]:
    """The :class:`~avp.errors.PlanningError` subclass that reports a plan ending in ``status``
    (:func:`avp.moving.plan_moving` raises it; ``plan`` above spells out the same mapping)."""
    return {
        PlanStatus.INFEASIBLE: InfeasibleError,
        PlanStatus.SOLVER_FAILED: SolverError,
        PlanStatus.BOUNDS_NOT_CERTIFIED: BoundsNotCertifiedError,
        PlanStatus.WORKSPACE_NOT_CERTIFIED: WorkspaceNotCertifiedError,
    }.get(status, PlanningError)
