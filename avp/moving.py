"""Perching on a moving platform: arrival-time search over the terminal map of Gao et al.,
"Adaptive Tracking and Perching for Quadrotor in Dynamic Scenarios" (IEEE T-RO 2023), Sec. V-D.

For a fixed duration ``T`` the pad's state at ``t_f = t_0 + T`` is predicted by the platform
model (:mod:`avp.platform`) and the perching QP is linear (:mod:`avp.qp.moving`). The arrival
time is then searched in one dimension (``docs/moving.md``):

1. ``T_1`` is the fixed point of the time-allocation rule (:class:`~avp.config.TimeAllocation`)
   with the gap to the *predicted* pad that the vehicle must add to coasting and its speed
   relative to the pad (three iterations).
2. Each candidate ``T`` is solved and its actuator bounds certified (Algorithm 1, Rust
   kernels, :func:`avp.bounds.certify_spline`). Its score is the certified cost
   ``Phi(T) = J(T) + rho_T T``: the QP objective (snap integral plus slip cost ``w |nu|^2``, in
   physical units) plus a time weight, as the time regularisation of Gao et al. (their (53));
   an uncertified or infeasible ``T`` scores ``+inf``.
3. Bracketing: while ``T`` is not certified it is multiplied by ``growth``; when the reason
   changes between two failures (tilt rate, then thrust) the window between them is bisected.
   Once one ``T`` certifies, a second certified point one growth step away (shorter first) and
   one log-log secant step to the minimiser of ``Phi`` under ``J ~ T^-k``. At most
   ``max_solves`` QP solves.
   The static workspace regions (ground, half-spaces, spheres, speed: :mod:`avp.safety`) have
   QP rows in every candidate and are certified on its solution, with refinement rounds as on a
   static pad; a candidate that keeps failing them scores ``+inf``.
4. The best-scoring certified candidate gets the moving-plane clearance certificate
   (:mod:`avp.moving_clearance`); if it fails, the next best is tried.

The result is the best certified candidate *evaluated*, not a proven global minimiser of ``Phi``
(certification is not monotone in ``T``). A platform that outruns the vehicle (no duration up
to ``max_duration`` certifies) is an honest ``BOUNDS_NOT_CERTIFIED`` result; :func:`plan_moving`
raises the matching :class:`~avp.errors.PlanningError`.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from . import _validate as v
from ._blas import serial
from ._typing import Array
from ._validate import LIMITS
from .bounds import BoundReport, certify_trajectory
from .config import FovConfig, PlannerConfig, Workspace
from .errors import (
    ConfigError,
    InfeasibleError,
)
from .moving_clearance import ClearanceReport, certify_moving_clearance
from .planner import STILL_SPEED, PlanStatus, planning_error
from .platform import MovingTarget
from .qp.moving import MovingQpBuilder, TerminalYaw, contact_point, objective
from .replan import ReplanConfig, Replanner, _target_change
from .safety import (
    RESIDUAL_TOL,
    TOUCH_TOL,
    SafetyReport,
    certify_workspace,
    check_start,
    contact_position,
    outside,
    refinement_blocks,
    regions_for,
)
from .solve import solve_perching_qp
from .trajectory import Provenance, Trajectory
from .types import PerchTarget, State

__all__ = [
    "ContactErrors", "MovingConfig", "MovingPlanResult", "MovingReplanner", "contact_errors", "plan_moving",
    "plan_moving_detailed",
]


RETIME_RANGE = (0.1, 10.0)
"""Factors :attr:`MovingConfig.retime` may hold: a nudge of the fixed duration (a factor
outside it is another plan, not a retime of this one)."""

MAX_SOLVES = 1000
"""Largest :attr:`MovingConfig.max_solves`. A search needs far fewer: growing ``T`` by the
default ``growth`` 1.25 crosses the whole range of durations (0.01 s to the 1e4 s duration
limit) in 62 solves, and a geometric bisection reaches the float resolution of ``T`` in about
60. A candidate takes milliseconds with the default spline, so 1000 solves are seconds of
search; beyond, a search that cannot certify runs for minutes."""


@v.typed_keywords("moving")
@dataclass(frozen=True)
class MovingConfig:
    """Terminal map and arrival-time search for a moving pad (Gao et al. Sec. V-D, VI).

    Parameters
    ----------
    normal_speed:
        ``v_n`` (m/s, > 0): relative speed into the surface at contact (their (45)).
    slip_max:
        Bound on each tangential relative speed ``|nu_x|, |nu_y|`` (m/s) (their (46)); 0 asks
        for zero tangential relative velocity (equality rows).
    slip_weight:
        ``w`` of the slip cost ``w |nu|^2`` (their (47)), in units of the snap cost per (m/s)^2.
    zero_jerk:
        ``p'''(t_f) = 0`` (their Sec. V-D): no body rate at contact.
    yaw:
        :class:`~avp.qp.moving.TerminalYaw`.
    contact_thrust_margin:
        The contact thrust ``alpha`` is free in the thrust limits shrunk by this fraction of their
        span at each end (their ``tau_e``, (50)); ``None`` keeps ``config.alpha_range`` /
        ``config.alpha``.
    time_weight:
        ``rho_T`` of the searched score ``J(T) + rho_T T``.
    growth:
        Factor on ``T`` while no candidate is certified (> 1).
    max_solves:
        QP solves per plan at most, in [1, :data:`MAX_SOLVES`] (why that bound: there).
    max_duration:
        Longest duration tried (s).
    retime:
        With a fixed ``duration`` (replans): factors tried in order on it when the plan at the
        given duration does not certify (a plan planned at the edge of the limits would
        otherwise keep the stale plan); ``()`` keeps the duration strictly. Each factor is in
        :data:`RETIME_RANGE`; a factor that takes the duration beyond the duration limit
        (``avp._validate.LIMITS``, as ``duration``) is not tried.

    The landing-gear offset ``l`` (their (43): the CoM at contact is ``rho + l s3``) and the
    clearance switch come from ``config.workspace`` (``body_offset``, ``perch_clearance``), as for
    a static pad.
    """

    normal_speed: float = 0.3
    slip_max: float = 1.0
    slip_weight: float = 1000.0
    zero_jerk: bool = True
    yaw: TerminalYaw = TerminalYaw.HEADING
    contact_thrust_margin: float | None = 0.05
    time_weight: float = 1000.0
    growth: float = 1.25
    max_solves: int = 7
    max_duration: float = 12.0
    retime: tuple[float, ...] = (1.03, 0.97)

    def __post_init__(self) -> None:
        v.flags("moving", self)
        v.positive_float("moving.normal_speed", self.normal_speed)
        for name in ("slip_max", "slip_weight", "time_weight"):
            val = v.finite_float(f"moving.{name}", getattr(self, name))
            if val < 0.0:
                raise ConfigError(f"moving.{name}", f"must be >= 0, got {val}")
        if self.contact_thrust_margin is not None:
            m = v.finite_float("moving.contact_thrust_margin", self.contact_thrust_margin)
            if not 0.0 <= m < 0.5:
                raise ConfigError("moving.contact_thrust_margin", f"must be in [0, 0.5), got {m}")
        g = v.finite_float("moving.growth", self.growth)
        if not 1.0 < g <= 10.0:
            raise ConfigError("moving.growth", f"must be in (1, 10] (as BoundsPolicy.growth), got {g}")
        v.integer("moving.max_solves", self.max_solves, 1, MAX_SOLVES, "(QP solves of the arrival-time search)")
        if not 1e-2 <= v.positive_float("moving.max_duration", self.max_duration) <= LIMITS["duration"][0]:
            raise ConfigError("moving.max_duration", f"must be in [0.01, {LIMITS['duration'][0]:g}] s, got {self.max_duration}")
        if any(not RETIME_RANGE[0] <= v.finite_float("moving.retime", f) <= RETIME_RANGE[1]
               for f in v.sequence("moving.retime", self.retime, "factors")):
            raise ConfigError("moving.retime", f"every factor must be in [{RETIME_RANGE[0]:g}, {RETIME_RANGE[1]:g}] "
                                               f"(a nudge of the fixed duration), got {self.retime}")
        if not isinstance(self.yaw, TerminalYaw):
            raise ConfigError("moving.yaw", f"must be an avp.qp.moving.TerminalYaw, got {self.yaw!r}")


@dataclass(frozen=True)
class Candidate:
    """One arrival time tried by the search."""

    duration: float
    score: float
    objective: float
    certified: bool
    note: str


@dataclass(frozen=True)
class ContactErrors:
    """Contact state of a plan against the predicted pad (at ``t_f``).

    ``position``: ``|p(t_f) - (rho + l s3)|`` (m); ``attitude``: angle between ``b3`` and ``s3``
    (rad); ``normal_velocity``: ``(v - v_pad) . s3 + v_n`` (m/s, 0 when as asked); ``slip``:
    tangential relative velocity ``(nu_x, nu_y)`` (m/s); ``thrust``: contact thrust (m/s^2).
    """

    position: float
    attitude: float
    normal_velocity: float
    slip: tuple[float, float]
    thrust: float


@dataclass(frozen=True, kw_only=True)
class MovingPlanResult:
    """Outcome of :func:`plan_moving_detailed` (duck-compatible with ``PlanResult``: ``status``,
    ``ok``, ``trajectory``, ``log``)."""

    status: PlanStatus
    trajectory: Trajectory | None
    pad: MovingTarget | None
    durations: Array
    bounds: BoundReport | None = None
    clearance: ClearanceReport | None = None
    score: float = math.inf
    candidates: tuple[Candidate, ...] = ()
    log: tuple[str, ...] = ()
    solve_time: float = 0.0
    total_time: float = 0.0
    contact: ContactErrors | None = field(default=None)
    safety: SafetyReport | None = None

    @property
    def ok(self) -> bool:
        return self.status.has_trajectory and self.trajectory is not None

    @property
    def arrival_time(self) -> float:
        """``t_f`` (s), NaN without a plan."""
        return float(self.trajectory.tf) if self.trajectory is not None else math.nan

    @property
    def n_solves(self) -> int:
        return len(self.candidates)


def _predicted_now(target: MovingTarget, time: float, field: str) -> MovingTarget:
    """``target`` predicted at ``time``; a pad predicted beyond a flight's positions
    (``avp._validate.LIMITS``) is a :class:`ConfigError` on ``field``: an estimate stamped on
    another clock than the state's (a UNIX time against a loop's seconds, say)."""
    pad = target.at(time)
    size = float(np.max(np.abs(pad.point)))
    if not size <= LIMITS["position"][0]:
        raise ConfigError(field, f"the pad predicted at t = {time:.6g} s from the estimate at {target.time:.6g} s "
                          f"lies {size:.3g} m out (beyond {LIMITS['position'][0]:g} m): stamp the estimate on the "
                          "same clock as the state")
    return pad


def contact_errors(
    traj: Trajectory, target: MovingTarget, moving: MovingConfig | None = None, body_offset: float = 0.0,
    rotor_drag: float = 0.0,
) -> ContactErrors:
    """Contact state of ``traj`` against ``target`` predicted at ``traj.tf`` (``body_offset`` as
    ``config.workspace.body_offset``; the thrust ``a + g e3 + d v`` with ``d = rotor_drag`` as
    ``config.limits.rotor_drag``)."""
    moving = moving if moving is not None else MovingConfig()
    pad = target.at(traj.t0, traj.duration)
    p, vel, acc = (traj(traj.tf, order) for order in (0, 1, 2))
    f = acc + np.array([0.0, 0.0, traj.g]) + rotor_drag * vel
    b3 = f / np.linalg.norm(f)
    rel = vel - pad.velocity
    return ContactErrors(
        position=float(np.linalg.norm(p - contact_point(pad, body_offset))),
        attitude=float(math.atan2(np.linalg.norm(np.cross(b3, pad.s3)), float(b3 @ pad.s3))),
        normal_velocity=float(rel @ pad.s3 + moving.normal_speed),
        slip=(float(rel @ pad.s1), float(rel @ pad.s2)),
        thrust=float(np.linalg.norm(f)),
    )


NOT_USED = ("contact_velocity", "fov", "flip.thrust", "flip.turn_rate", "bounds.certify", "bounds.time_search",
            "bounds.factors", "bounds.growth", "bounds.max_steps", "bounds.relaxations")
"""The :class:`~avp.config.PlannerConfig` settings of a static perch that the moving planner does
not use (``docs/moving.md``): the contact velocity is :class:`MovingConfig`'s (``normal_speed``,
``slip_max``), the FoV rows are not formulated for a moving pad, the overhang's horizontal-thrust
waypoint is not built (``flip.enabled``, ``min_incline`` and ``cone_band`` act through the band),
and the arrival-time search with its certified bounds replaces ``bounds`` (never off, never
relaxed). :func:`plan_moving_detailed` logs the ones set away from their defaults."""


def _planner_config(config: PlannerConfig | None, moving: MovingConfig) -> PlannerConfig:
    cfg = config if config is not None else PlannerConfig()
    if not isinstance(cfg, PlannerConfig):
        raise ConfigError("config", f"expected avp.PlannerConfig, got {type(cfg).__name__}")
    # The FoV rows (8) aim at a static pad; for a moving pad they are not formulated (docs/moving.md).
    changes: dict[str, Any] = {}
    if isinstance(cfg.fov, FovConfig) and cfg.fov.enabled:
        changes["fov"] = replace(cfg.fov, enabled=False)
    if moving.contact_thrust_margin is not None:
        lo, hi = cfg.limits.accel_min, cfg.limits.accel_max
        m = moving.contact_thrust_margin * (hi - lo)
        changes["alpha_range"] = (lo + m, hi - m)
    return replace(cfg, **changes) if changes else cfg


def _initial_duration(state: State, target: MovingTarget, cfg: PlannerConfig, moving: MovingConfig) -> float:
    """Fixed point of the allocation rule (three iterations) with the displacement the vehicle
    must add to coasting, ``rho(t_0 + T) + l s3 - (p_0 + v_0 T)``, and its speed relative to the
    predicted pad (a vehicle already tracking the platform only closes the gap)."""
    T = cfg.time_allocation.total(float(np.linalg.norm(target.point - state.position)), 0.0)
    for _ in range(3):
        pad = target.at(state.time, T)
        gap = contact_point(pad, cfg.workspace.body_offset) - (state.position + T * state.velocity)
        T = cfg.time_allocation.total(float(np.linalg.norm(gap)), float(np.linalg.norm(state.velocity - pad.velocity)))
    return min(T, moving.max_duration)


@dataclass
class _Eval:
    T: float
    pad: MovingTarget
    traj: Trajectory | None
    report: BoundReport | None
    objective: float
    score: float
    note: str
    clearance: ClearanceReport | None = None
    safety: SafetyReport | None = None

    @property
    def failure(self) -> frozenset[str]:
        """Why the candidate is not certified: the violated bounds (empty when certified)."""
        if math.isfinite(self.score):
            return frozenset()
        if self.report is None:
            return frozenset({"qp"})
        if self.safety is not None and not self.safety.certified:
            return frozenset(f"workspace: {name}" for name in self.safety.failed)
        return frozenset(x.bound.value for x in self.report.violations) or frozenset({"undecided"})


@serial  # one BLAS thread: no helper threads spinning after the call (avp._blas)
def plan_moving_detailed(
    state: State,
    target: MovingTarget,
    config: PlannerConfig | None = None,
    moving: MovingConfig | None = None,
    *,
    duration: float | None = None,
) -> MovingPlanResult:
    """Plan a perch on a moving pad; never raises for infeasibility (module docstring).

    Parameters
    ----------
    state:
        Start state (the plan starts at ``state.time``).
    target:
        :class:`~avp.platform.MovingTarget` (its state at ``target.time``; predicted from there).
    config:
        :class:`~avp.config.PlannerConfig`: limits, spline, cost, pre-impact band. Its FoV rows
        are not used and, with ``moving.contact_thrust_margin``, the contact thrust is free.
    moving:
        :class:`MovingConfig`.
    duration:
        Fixed total duration (s): no arrival-time search (replanning keeps the contact time);
        at most the duration limit (``avp._validate.LIMITS``, 1e4 s, on the total as for ``avp.plan_line``;
        ``avp.plan`` applies it to each segment).
    """
    t_start = time.perf_counter()
    if not isinstance(state, State):
        raise ConfigError("state", f"expected avp.State, got {type(state).__name__}")
    if not isinstance(target, MovingTarget):
        raise ConfigError("target", f"expected avp.platform.MovingTarget, got {type(target).__name__}")
    mcfg = moving if moving is not None else MovingConfig()
    if not isinstance(mcfg, MovingConfig):
        raise ConfigError("moving", f"expected avp.moving.MovingConfig, got {type(mcfg).__name__}")
    cfg = _planner_config(config, mcfg)
    lim = cfg.limits
    log: list[str] = []
    unused = config.changed(NOT_USED) if config is not None else []  # the user's, not the FoV-free copy
    if unused:
        log.append("config: the moving planner does not use " + ", ".join(unused) + " (set away from the defaults; "
                   "docs/moving.md)")
    pad_now = _predicted_now(target, state.time, "target.time")  # the pad where it is at the start
    gap = float(np.linalg.norm(pad_now.point - state.position))
    if gap < cfg.min_distance and float(np.linalg.norm(state.velocity - pad_now.velocity)) < STILL_SPEED:
        raise ConfigError("target.point", f"is {gap:.3f} m from a start at rest relative to the pad (config.min_distance "
                          f"= {cfg.min_distance} m); a perch needs a pad away from the vehicle")
    if cfg.workspace.perch_clearance:  # the clearance h(t) > 0 (avp.moving_clearance) at its first instant
        h0 = float(pad_now.s3 @ (state.position - contact_point(pad_now, cfg.workspace.body_offset)))
        if h0 <= TOUCH_TOL:
            raise ConfigError("state.position", f"lies on or behind the moving pad's plane at the start (margin {h0:.4g} m "
                              f"to the pad predicted at t = {state.time:.6g} s): no plan keeps its clearance; start "
                              "on the side the pad's normal s3 points to (or check the normal's sign and the pad's motion)")
    # the static limits (ground, half-spaces, spheres, speed) as avp.plan checks them: the start,
    # and the contact point of a pad that does not move (a moving one's is known per duration)
    check_start(state, pad_now.static(), cfg.workspace, contact=target.is_static)
    evals: list[_Eval] = []
    solve_time = 0.0
    builder = MovingQpBuilder(state, cfg, mcfg.normal_speed, mcfg.slip_max, mcfg.slip_weight, mcfg.zero_jerk,
                              mcfg.yaw, cfg.workspace.body_offset)

    ws = cfg.workspace
    static_cfg = builder.static_config  # the workspace without the perch plane, which moves
    check_static = static_cfg.workspace.active

    def evaluate(T: float) -> _Eval:
        nonlocal solve_time
        pad = target.at(state.time, T)
        t0 = time.perf_counter()
        qp = builder.build(pad, T)
        safety: SafetyReport | None = None
        for round_index in range(ws.refinement_rounds + 1 if check_static else 1):
            try:
                out = solve_perching_qp(qp, cfg)
            except InfeasibleError as exc:
                solve_time += time.perf_counter() - t0
                return _Eval(T, pad, None, None, math.inf, math.inf, f"infeasible: {exc}")
            solve_time += time.perf_counter() - t0
            if not out.ok or out.c_hat is None:
                return _Eval(T, pad, None, None, math.inf, math.inf, f"QP {out.status.value}")
            traj = qp.trajectory(out.c_hat, cfg.g)
            report = certify_trajectory(traj, lim, cfg.g)
            J = objective(qp, out.c_hat, cfg)
            if not report.certified:
                note = "; ".join(str(x) for x in report.violations[:2]) or "bounds undecided"
                return _Eval(T, pad, traj, report, J, math.inf, note)
            if not check_static:
                break
            # the static limits (ground, half-spaces, spheres, speed) as the static planner
            # does (avp.attempt): certify, and re-solve with refined rows around violations
            safety = certify_workspace(traj, pad.static(), static_cfg.workspace)
            if safety.certified or round_index == ws.refinement_rounds:
                break
            log.append(f"T = {T:.4f} s: workspace refinement round {round_index + 1}: "
                       + "; ".join(str(c) for c in safety.checks if not c.certified))
            t0 = time.perf_counter()
            qp = qp.with_inequalities(*refinement_blocks(qp.layout, qp.knots_rel, traj, safety, round_index + 1,
                                                         static_cfg))
        if safety is not None and not safety.certified:
            return _Eval(T, pad, traj, report, J, math.inf, "workspace NOT certified: " + "; ".join(safety.failed),
                         safety=safety)
        return _Eval(T, pad, traj, report, J, J + mcfg.time_weight * T, "bounds certified", safety=safety)

    def run(T: float) -> _Eval:
        e = evaluate(T)
        evals.append(e)
        log.append(f"T = {T:.4f} s: {e.note}" + (f", score {e.score:.4g}" if math.isfinite(e.score) else ""))
        return e

    if duration is not None:
        T = v.positive_float("duration", duration)
        v.within("duration", T, "duration")
        for factor in (1.0, *mcfg.retime):  # a fixed arrival time, nudged only if uncertified
            if T * factor > LIMITS["duration"][0]:
                log.append(f"T = {T * factor:.4g} s (retime x{factor:g}): not tried, beyond the duration limit "
                           f"{LIMITS['duration'][0]:g} s")
                continue
            if math.isfinite(run(T * factor).score):
                break
    else:
        _search(run, _initial_duration(state, target, cfg, mcfg), mcfg, log)
    best = _pick(evals, target, cfg, log)
    total = time.perf_counter() - t_start
    candidates = tuple(Candidate(e.T, e.score, e.objective, math.isfinite(e.score), e.note) for e in evals)
    if best is not None and best.traj is not None:
        regions = [r for r in (best.clearance, best.safety) if r is not None]
        best.traj.provenance = Provenance(  # travels with the trajectory (exports included), as avp.plan's
            status=PlanStatus.SOLVED.value, bounds_certified=bool(best.report is not None and best.report.certified),
            workspace_certified=bool(regions) and all(r.certified for r in regions))
        return MovingPlanResult(status=PlanStatus.SOLVED, trajectory=best.traj, pad=best.pad, durations=best.traj.durations, bounds=best.report, clearance=best.clearance, score=best.score, candidates=candidates, log=tuple(log), solve_time=solve_time, total_time=total, contact=contact_errors(best.traj, target, mcfg, cfg.workspace.body_offset, cfg.limits.rotor_drag), safety=best.safety)
    last = evals[-1]
    outside_note = _pad_outside(evals, static_cfg.workspace)
    if outside_note is not None or any(e.clearance is not None or e.safety is not None for e in evals):
        # (the pad out of the workspace at every arrival time: no trajectory keeps it, whatever the limits)
        status = PlanStatus.WORKSPACE_NOT_CERTIFIED
    elif all(e.traj is None for e in evals):
        status = PlanStatus.INFEASIBLE if any(e.note.startswith("infeasible") or "no solution" in e.note for e in evals) \
            else PlanStatus.SOLVER_FAILED
    else:
        status = PlanStatus.BOUNDS_NOT_CERTIFIED
        speed = float(np.linalg.norm(target.velocity))
        log.append(f"no certified arrival time up to {max(e.T for e in evals):.2f} s (platform speed "
                   f"{speed:.2f} m/s); the limits may not allow catching this platform")
    if outside_note is not None:  # the geometry, not the limits: said last (plan_moving's message ends with it)
        log.append(outside_note)
    return MovingPlanResult(status=status, trajectory=None, pad=last.pad, durations=np.full(cfg.n_segments, last.T / cfg.n_segments), bounds=last.report, clearance=next((e.clearance for e in reversed(evals) if e.clearance is not None), None), score=math.inf, candidates=candidates, log=tuple(log), solve_time=solve_time, total_time=total, contact=None, safety=next((e.safety for e in reversed(evals) if e.safety is not None), None))


def _pad_outside(evals: list[_Eval], static: Workspace) -> str | None:
    """A log line when the pad's contact point lay outside the static workspace limits
    (``static``: ground, half-spaces, spheres) at every arrival time tried: no plan could reach
    it, whatever the vehicle's limits (``None`` otherwise)."""
    if not evals:
        return None
    names: set[str] = set()
    for e in evals:
        pad = e.pad.static()
        p_c = contact_position(pad, static)
        hit = [r.name for r in regions_for(pad, static) if r.kind != "speed" and outside(r, p_c, False) is not None]
        if not hit:
            return None
        names.update(hit)
    Ts = [e.T for e in evals]
    return (f"the pad's contact point lies outside the workspace limit(s) {', '.join(sorted(names))} at every "
            f"arrival time tried ({min(Ts):.3g}-{max(Ts):.3g} s): check the pad's position and motion and the "
            "workspace limits")


def _search(run: Any, T1: float, mcfg: MovingConfig, log: list[str]) -> None:
    """Arrival-time search (module docstring, step 3); ``run(T)`` evaluates and records ``T``."""
    log.append(f"initial arrival-time guess {T1:.4f} s")
    T, n, grew = T1, 0, False
    best: _Eval | None = None
    prev: _Eval | None = None
    while n < mcfg.max_solves:  # bracket: grow T until certified
        e = run(T)
        n += 1
        if math.isfinite(e.score):
            best = e
            break
        if prev is not None and e.failure != prev.failure:
            # The reason changed between prev.T and T (e.g. tilt rate -> thrust): a certified
            # window, if any, lies between them; bisect geometrically.
            _bisect(run, prev, e, mcfg.max_solves - n)
            return  # the window is narrow: no refinement around it
        if T >= mcfg.max_duration:
            return
        prev = e
        T, grew = min(T * mcfg.growth, mcfg.max_duration), True
    if best is None:
        return
    # Refine: a second certified point one growth step away (shorter first unless shorter is
    # known to fail), then one log-log secant step to the minimiser of J + rho T under J ~ T^-k.
    fail_below = prev.T if prev is not None and prev.T < best.T else 0.0
    cert = [best]
    for factor in ((1.0 / mcfg.growth, mcfg.growth) if not grew else (mcfg.growth,)):
        if n >= mcfg.max_solves or best.T * factor > mcfg.max_duration:
            return
        e = run(best.T * factor)
        n += 1
        if math.isfinite(e.score):
            cert.append(e)
            break
        if factor < 1.0:
            fail_below = max(fail_below, e.T)
    if len(cert) < 2 or n >= mcfg.max_solves or mcfg.time_weight == 0.0:
        return
    a, b = sorted(cert, key=lambda c: c.T)
    if not a.objective > b.objective > 0.0:
        return
    k = math.log(a.objective / b.objective) / math.log(b.T / a.T)
    T_star = (k * b.objective * b.T**k / mcfg.time_weight) ** (1.0 / (k + 1.0))
    T_star = min(max(T_star, fail_below * 1.02, a.T / mcfg.growth**2), b.T * mcfg.growth**2, mcfg.max_duration)
    if all(abs(T_star - c.T) > 0.03 * c.T for c in cert):
        run(T_star)


def _bisect(run: Any, lo: _Eval, hi: _Eval, budget: int) -> None:
    """Geometric bisection between two uncertified durations that fail for different reasons,
    until one certifies or the budget is spent."""
    for _ in range(budget):
        e = run(math.sqrt(lo.T * hi.T))
        if math.isfinite(e.score):
            return
        if e.failure == lo.failure:
            lo = e
        else:
            hi = e


def _pick(evals: list[_Eval], target: MovingTarget, cfg: PlannerConfig, log: list[str]) -> _Eval | None:
    """Best certified candidate that also passes the moving-plane clearance certificate (the
    static workspace regions were certified when it was evaluated: a candidate that failed them
    scores ``+inf``)."""
    ws = cfg.workspace
    for e in sorted((e for e in evals if math.isfinite(e.score)), key=lambda e: e.score):
        assert e.traj is not None
        if ws.perch_clearance:
            e.clearance = certify_moving_clearance(e.traj, target, ws.body_offset, RESIDUAL_TOL)
            log.append(f"T = {e.T:.4f} s: {e.clearance.summary()}")
            if not e.clearance.certified:
                continue
        if e.safety is not None:
            log.append(f"T = {e.T:.4f} s: workspace certified")
        return e
    return None


def plan_moving(
    state: State,
    target: MovingTarget,
    config: PlannerConfig | None = None,
    moving: MovingConfig | None = None,
    *,
    duration: float | None = None,
) -> Trajectory:
    """:func:`plan_moving_detailed` (``duration`` as there: a fixed arrival time), returning the
    trajectory or raising a :class:`~avp.errors.PlanningError` subclass with ``.result``."""
    result = plan_moving_detailed(state, target, config, moving, duration=duration)
    if result.ok and result.trajectory is not None:
        return result.trajectory
    message = f"no perching trajectory on the moving pad: {result.status.value}; " + "; ".join(result.log[-2:])
    raise planning_error(result.status)(message, result)


class MovingReplanner(Replanner):
    """:class:`~avp.replan.Replanner` for a pad on a moving platform.

    ``step(t, odometry, target_estimate)`` takes the latest platform-state estimate as a
    :class:`~avp.platform.MovingTarget` (pad pose and platform state at its own ``time``), which
    the motion model predicts to the contact time. The first plan searches the arrival time; a
    replan anticipates the start state (6) exactly as for a static pad and keeps the committed
    contact time (``duration = t_f - t_ex``), so only the predicted pad changes, unless that
    plan does not certify: the planner then tries the time left scaled by ``MovingConfig.retime``
    (:func:`plan_moving_detailed` ``duration``), and a step that commits such a plan reports
    the scale in ``time_factor`` and its reason.

    A step compares estimates where they put the pad at the committed contact time. When a
    step commits nothing (or is frozen near contact) and that predicted pad is farther than
    ``reach_tolerance`` from the committed contact point, it says ``CANNOT_REACH``, the cue to
    abort, as for a static pad. The pad policy's other steps do not apply here: every estimate
    moves the pad, so a step never holds (``target_tolerance``), and a correction is full or
    none (no ``reach_acceleration`` budget, ``partial_fractions`` or ``retime_retries``), because
    partial corrections blend two pad frames. A full correction is committed only when its plan
    is certified.
    """

    def __init__(
        self,
        target: MovingTarget,
        config: PlannerConfig | None = None,
        replan: ReplanConfig | None = None,
        moving: MovingConfig | None = None,
        trajectory: Trajectory | None = None,
    ) -> None:
        if not isinstance(target, MovingTarget):
            raise ConfigError("target", f"expected avp.platform.MovingTarget, got {type(target).__name__}")
        super().__init__(target, config, replan, trajectory)
        self.moving = moving if moving is not None else MovingConfig()
        if not isinstance(self.moving, MovingConfig):
            raise ConfigError("moving", f"expected avp.moving.MovingConfig or None, got {type(self.moving).__name__}")
        # replans keep the committed contact time through ``duration`` (_solve); the moving
        # planner has no duration schedule or relaxations for ``search_on_replan`` to turn off
        self._replan_config = self.config

    _target_type = MovingTarget

    @classmethod
    def _check_input(cls, t: Any, odometry: Any, target_estimate: Any, last_t: float | None,
                     first_target: PerchTarget | None) -> float:
        """:meth:`Replanner._check_input <avp.replan.Replanner._check_input>` and the estimate's
        time: the pad predicted now from it stays within the time limit."""
        t = super()._check_input(t, odometry, target_estimate, last_t, first_target)
        if target_estimate is not None:
            _predicted_now(target_estimate, t, "target_estimate.time")
        elif isinstance(first_target, MovingTarget):  # the constructor's estimate plans the first step
            _predicted_now(first_target, t, "target.time")
        return t

    def _change(self, a: Any, b: Any) -> tuple[float, float]:
        """Distance (m) and angle (rad) between the pads that ``a`` and ``b`` predict at the
        committed contact time (the plan's end, which replans keep)."""
        t_c = self.trajectory.tf if self.trajectory is not None else float(b.time)
        return _target_change(a.at(t_c), b.at(t_c))

    @property
    def _reach_cue(self) -> bool:
        return True

    def _solve(  # type: ignore[override]  # returns the duck-compatible MovingPlanResult
        self, state: State, durations: Array | None, previous: Trajectory | None, config: PlannerConfig,
        deadline: float | None = None,  # not used: this planner has no time budget
    ) -> MovingPlanResult:
        assert isinstance(self.target, MovingTarget)
        duration = float(np.sum(durations)) if durations is not None else None
        return plan_moving_detailed(state, self.target, config, self.moving, duration=duration)
