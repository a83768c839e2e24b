"""Active replanning (Sec. IV): a :class:`Replanner` that user code calls from its own loop
(30 Hz in the paper) with odometry and the latest target estimate.

Each :meth:`Replanner.step` plans from the moment a new plan can take over,
``t_ex = t_rp + latency``, to the (re-estimated) target with the FoV rows (one SQP step on the
new plan's FoV-free solution, :mod:`avp.attempt`), and commits the new plan only if it is
certified. The policy
(:class:`ReplanConfig`, every knob measured in ``docs/simulation.md``):

- **Anchoring.** While odometry agrees with the committed reference (tracking error below
  ``anchor_position`` / ``anchor_velocity``), the new plan starts from the committed plan's own
  state at ``t_ex``: odometry noise never enters the reference. On real divergence it
  re-anchors on odometry with the anticipation (6).
- **Hold.** With the estimate unchanged (no new detection: the pad left the view) and tracking
  good, there is nothing to correct: the committed plan is kept without a solve (``HELD``).
- **Reach budget.** The contact point may move by at most ``0.5 reach_acceleration T^2`` with
  ``T`` the time left; larger corrections are clipped to the budget, and if the full correction
  does not certify, the fractions ``partial_fractions`` of it are tried: a partial, certified
  correction is preferred over none (``PARTIAL``). The full correction first, then the
  smallest fraction; only if that certifies, the ones between, largest first: a step that
  cannot correct at all costs two solves, not one per fraction, plus the retimed retries below.
- **Retimed retries.** A full correction whose plan fails only a certificate (trackability or
  actuator bounds) is solved again with the time left scaled by each of ``retime_retries``
  (a few per cent either side) before the partial fractions: those certificates are not
  monotone in the time left, and a late correction often certifies at a nearby contact time.
  Not with less than ``retime_min_time`` left (none certified there), not for a subclass with
  its own target model (it keeps the committed contact time), with a ``deadline`` only while
  a retry and the smallest fraction (when there is one), each as slow as the step's first
  solve, still fit in it (a step that goes on from a retry the step before could not make
  begins with it), and (``retime_backoff``) not while nothing was committed since the retries
  all ran and failed, in one step or, cut by the deadline, over several.
- **Deadline.** With ``deadline``, a solve starts only while it is predicted to fit. A step cut
  before its partial corrections leaves the rest of its order (the retimed retries still due,
  then the fractions) to the next step that solves, which goes on from there rather than
  beginning again with the full correction: with time for one solve per step, a full correction
  that fails would otherwise take every step. A held step (the estimate back at the committed
  target) drops what was left; without a deadline nothing is carried over.
- **Certified commits.** A plan is committed only if ``result.ok`` (no relaxed plan unless
  ``allow_relaxed``), its actuator bounds are certified and its snap is certified below
  ``snap_max`` (:mod:`avp.trackability`), which bounds the angular acceleration.
- **Freeze** within ``freeze_horizon`` s of contact (no replan can be tracked there).
- **Cannot reach.** When the committed contact point is farther from the latest estimate than
  ``reach_tolerance``, or the committed pad's normal turned from it by more than
  ``reach_angle_tolerance``, and no certified plan closes the gap, the step's action is
  ``CANNOT_REACH`` with the numbers (``target_error``, ``target_angle``, ``reach_budget``): the
  user's cue to abort or go around.
- **Off track.** A step that keeps the plan (``KEPT_PREVIOUS``, frozen, ``CANNOT_REACH``) while
  the odometry is beyond the anchors from the plan being flown says ``off_track`` (with
  ``tracking_error``): that plan does not start where the vehicle is, the vehicle's own cue.
  Neither cue gates outliers: a one-frame jump of the estimate within the budget is replanned
  to, an odometry glitch beyond the anchors starts the next plan from it (filter upstream).

It never raises for a planning or solver failure (including ``ValueError`` / ``LinAlgError`` from
inside planning): the :class:`ReplanStep` says what happened.
"""

from __future__ import annotations

import itertools
import math
import time
from dataclasses import dataclass, replace
from enum import Enum
from typing import Any

import numpy as np

from . import _avp_rust
from . import _validate as v
from ._blas import serial_blas
from ._blas import warm as _warm_blas
from ._typing import Array
from ._validate import LIMITS
from .config import PlannerConfig, ReplanConfig
from .errors import AvpError, ConfigError
from .planner import PlanResult, PlanStatus, plan_detailed
from .safety import contact_position
from .trackability import SnapReport, certify_snap, trackability_peaks
from .trajectory import FlatOutput, Trajectory
from .types import PerchTarget, State

__all__ = ["ReplanAction", "ReplanConfig", "ReplanStep", "Replanner", "anticipate"]




_PLANNING_ERRORS = (AvpError, ValueError, ArithmeticError, np.linalg.LinAlgError, RuntimeError)
"""Exceptions a planning call may raise that :meth:`Replanner.step` turns into a result."""

_NOT_RETIMED = ("; the full correction was not retimed (its retries all failed at an earlier step, nothing "
                "committed since)")
"""What a step's reason adds when ``retime_backoff`` held its retries."""

_clock = time.perf_counter
"""The wall clock (s) of the solve times and of ``ReplanConfig.deadline`` (tests replace it)."""


class _StepClock:
    """``ReplanConfig.deadline`` (s) of one replanning step: the wall time used since the step's
    policy began (:meth:`Replanner._replan`), and the predicted cost (s) of one more planning
    attempt (the step's first: its solve and certificates)."""

    def __init__(self, deadline: float | None) -> None:
        self.deadline = deadline
        self.t0 = _clock()
        self.per_attempt: float | None = None

    def used(self) -> float:
        """Seconds since the step began."""
        return _clock() - self.t0

    def fits(self, n: int) -> bool:
        """No deadline, or ``n`` more attempts, each as slow as the first, still fit."""
        return self.deadline is None or self.per_attempt is None or self.used() + n * self.per_attempt <= self.deadline

    def left(self) -> float | None:
        """The time left (s) for a planning call (``None``: no deadline)."""
        return None if self.deadline is None else max(self.deadline - self.used(), 1e-6)

    def overrun(self) -> bool:
        """The step is past its deadline."""
        return self.deadline is not None and self.used() > self.deadline


class ReplanAction(Enum):
    """What one :meth:`Replanner.step` did."""

    INITIAL_PLAN = "initial plan committed"
    REPLANNED = "replanned: new plan committed from t_ex"
    PARTIAL = "replanned: a certified partial correction towards the new estimate committed"
    HELD = "held: estimate unchanged and tracking good, committed plan kept without a solve"
    KEPT_PREVIOUS = "kept the committed plan (replanning failed, was not certified or came too late)"
    FROZEN_NEAR_CONTACT = "too close to contact: committed plan kept without replanning"
    CANNOT_REACH = "the latest estimate is beyond what a certified plan reaches in the time left"
    NO_PLAN = "no plan yet: the first plan failed"


_KEEPS = (ReplanAction.KEPT_PREVIOUS, ReplanAction.FROZEN_NEAR_CONTACT, ReplanAction.CANNOT_REACH)
"""The actions of a step that flies on with the plan it had."""


@dataclass(frozen=True, kw_only=True)
class ReplanStep:
    """Record of one :meth:`Replanner.step`.

    ``trajectory`` is the committed plan after the step (what to track from ``t_ex`` on; before
    ``t_ex`` keep tracking the previous one, or call :meth:`Replanner.reference`).

    ``target_error`` (m) is the distance from the committed plan's contact point to the latest
    estimate after the step (for a moving pad, to the pad the estimate predicts at the contact
    time; for a line, from the committed plan's grasp point to the estimated line);
    ``target_angle`` (rad) the angle between the committed pad's normal and the estimate's (for
    a line, between the committed grasped piece and the estimate's piece closest to the grasp
    point, unsigned);
    ``reach_budget`` (m) how far the contact point could move in the time left (``inf``
    where no budget applies: a moving pad, a line); ``fraction`` the share of the requested correction committed (0 when nothing
    was); ``anchored`` whether the plan started from the committed reference (True) or from
    odometry; ``snap`` the trackability certificate of the committed plan, when one was checked;
    ``time_factor`` the committed plan's time left over the nominal one (``retime_retries``, or
    a moving pad's ``MovingConfig.retime``: other than 1 when the nominal time failed a
    certificate).

    ``tracking_error`` (m) and ``tracking_velocity_error`` (m/s): how far the odometry was from
    the plan being flown at ``t`` (:meth:`Replanner.plan_at`; NaN for a first plan and outside
    that plan's times, as past its end);
    ``off_track``: they were beyond ``ReplanConfig.anchor_position`` / ``anchor_velocity``, the
    committed plan had started (before its ``t0`` it was just planned, from odometry when the
    vehicle was off) and the step committed nothing, so the plan flown on does not start where
    the vehicle is (the reason says so). ``CANNOT_REACH`` is about the pad; ``off_track`` is the
    vehicle's own cue to abort or go around when it persists (a controller recovering from a
    gust may be off for a step or two).
    """

    t: float
    action: ReplanAction
    trajectory: Trajectory | None
    reason: str
    t_ex: float
    anticipated: State | None = None
    result: PlanResult | None = None
    solve_time: float = 0.0
    target_error: float = 0.0
    target_angle: float = 0.0
    reach_budget: float = float("inf")
    fraction: float = 0.0
    anchored: bool = False
    n_solves: int = 0
    snap: SnapReport | None = None
    time_factor: float = 1.0
    tracking_error: float = math.nan
    tracking_velocity_error: float = math.nan
    off_track: bool = False

    @property
    def solved(self) -> bool:
        """Whether the step ran at least one planning call."""
        return self.n_solves > 0

    @property
    def committed(self) -> bool:
        """Whether the step committed a new plan."""
        return self.fraction > 0.0 or self.action is ReplanAction.INITIAL_PLAN


def anticipate(plan: Trajectory, odometry: State, t_rp: float, t_ex: float, measured_orders: int = 2) -> State:
    """Anticipated start state (6) at ``t_ex`` from odometry taken at ``t_rp``.

    ``x0^(k) = x_n^(k) + P^(k)(t_ex) - P^(k)(t_rp)`` for ``k = 0..4`` and yaw; orders at or
    above ``measured_orders`` use the plan's own value at ``t_rp`` as ``x_n^(k)`` (odometry
    rarely measures jerk or snap). Computed in Rust (``avp._avp_rust.anticipate``). The measured
    yaw is taken on the plan's branch (a multiple of 2 pi added: odometry wraps its yaw, a plan
    does not), so the new plan's yaw continues the committed one's.
    """
    odo = plan.derivatives(t_rp)  # (5, 4): the plan's own values
    measured = np.zeros((5, 4))
    measured[:4, :3] = odometry.derivatives()
    yaw = odometry.yaw
    turns = round((float(odo[0, 3]) - yaw) / (2.0 * math.pi))
    if turns:
        yaw += 2.0 * math.pi * turns
    measured[0, 3], measured[1, 3] = yaw, odometry.yaw_rate
    odo[:measured_orders] = measured[:measured_orders]
    try:
        # on the plan's exact durations, in times since its start (any clock value)
        x0 = _avp_rust.anticipate(plan.coefficients, plan.knots_rel, np.ascontiguousarray(odo),
                                  float(t_rp) - plan.t0, float(t_ex) - plan.t0)
    except ValueError as exc:
        raise ConfigError("t", str(exc)) from exc
    return State(position=x0[0, :3], velocity=x0[1, :3], acceleration=x0[2, :3], jerk=x0[3, :3],
                 yaw=float(x0[0, 3]), yaw_rate=float(x0[1, 3]), time=float(t_ex))


def _plan_state(plan: Trajectory, t: float) -> State:
    """The committed plan's own flat state at ``t`` (an anchored start)."""
    d = plan.derivatives(min(max(t, plan.t0), plan.tf))
    return State(position=d[0, :3], velocity=d[1, :3], acceleration=d[2, :3], jerk=d[3, :3],
                 yaw=float(d[0, 3]), yaw_rate=float(d[1, 3]), time=float(t))


def _knots_after(plan: Trajectory, t: float) -> tuple[float, Array]:
    """``t`` and the plan's interior knots after it (its contact time excluded), relative to
    the plan's start (:attr:`~avp.trajectory.Trajectory.knots_rel`, exact at any clock value)."""
    rel, t_rel = plan.knots_rel, float(t) - plan.t0
    # a knot within the clock's resolution of t is t itself (t may be a knot rounded to the clock)
    after = t_rel + 4.0 * math.ulp(abs(float(t)))
    return t_rel, rel[(rel > after) & (rel < rel[-1])]


def _blend(a: PerchTarget, b: PerchTarget, f: float) -> PerchTarget:
    """The target a fraction ``f`` of the way from ``a`` to ``b`` (point and frame)."""
    if f >= 1.0:
        return b
    point = a.point + f * (b.point - a.point)
    normal = (1.0 - f) * a.s3 + f * b.s3
    up = (1.0 - f) * a.s1 + f * b.s1
    try:
        return PerchTarget.from_normal(point, normal, up_slope=up)
    except ConfigError:
        return PerchTarget(point=point, R_WS=a.R_WS)


_TIME_LIMIT = LIMITS["time"][0]


def _step_time(t: Any) -> float:
    """A step's ``t`` as a float: finite and within the time limit (``ConfigError`` on ``t``)."""
    t = v.finite_float("t", t)
    if abs(t) > _TIME_LIMIT:
        v.within("t", t, "time")  # raises, with the message
    return t


def check_step_time(t: Any, last_t: float | None) -> float:
    """A step's ``t`` as a float: finite, within the time limit and not before ``last_t`` (the
    previous step's; ``ConfigError`` on ``t``)."""
    t = _step_time(t)
    if last_t is not None and t < last_t:
        raise ConfigError("t", f"went back from {last_t:.6g} s to {t:.6g} s: steps must come in time "
                          "order on one clock (after a clock reset, build a new Replanner)")
    return t


def flown_plan(committed: Trajectory | None, previous: Trajectory | None, t: float) -> Trajectory:
    """The plan flown at ``t``: ``previous`` before the ``committed`` plan's start, ``committed``
    from then on (:meth:`Replanner.plan_at`)."""
    if committed is None:
        raise ConfigError("t", "no plan committed yet; call step() first")
    if t < committed.t0 and previous is not None:
        return previous
    return committed


def _target_change(a: PerchTarget, b: PerchTarget) -> tuple[float, float]:
    """Distance (m) between the pad centres and angle (rad) between the normals. A turn of the
    pad about its normal is not a change: the committed contact yaw stays (on a level pad built
    from a normal, ``PerchTarget.from_normal``, that rotation is noise)."""
    p = b.point - a.point
    return math.sqrt(float(p @ p)), math.acos(min(max(float(a.s3 @ b.s3), -1.0), 1.0))


class Replanner:
    """Replans a perch from a user-owned loop (module docstring for the policy).

    Parameters
    ----------
    target:
        Initial target estimate.
    config:
        Planner configuration (a replan's FoV stage takes one SQP step, :mod:`avp.attempt`).
    replan:
        :class:`ReplanConfig`.
    trajectory:
        An already committed plan (otherwise the first :meth:`step` plans from odometry); it
        must end at ``target``'s contact point (the pad centre, or ``workspace.body_offset``
        off it along the normal; within ``replan.target_tolerance``, for a static pad; a
        ``ConfigError`` otherwise: pass the target it was planned for and the newer estimate to
        :meth:`step`), and replans certify their snap against its peaks as against a first
        plan's.
    """

    def __init__(
        self,
        target: PerchTarget,
        config: PlannerConfig | None = None,
        replan: ReplanConfig | None = None,
        trajectory: Trajectory | None = None,
    ) -> None:
        if not isinstance(target, self._target_type):
            raise ConfigError("target", f"expected avp.{self._target_type.__name__}, got {type(target).__name__}")
        if config is not None and not isinstance(config, PlannerConfig):
            hint = " (a ReplanConfig goes in replan=...)" if isinstance(config, ReplanConfig) else ""
            raise ConfigError("config", f"expected avp.PlannerConfig or None, got {type(config).__name__}{hint}")
        if replan is not None and not isinstance(replan, ReplanConfig):
            raise ConfigError("replan", f"expected avp.ReplanConfig or None, got {type(replan).__name__}")
        if trajectory is not None and not isinstance(trajectory, Trajectory):
            raise ConfigError("trajectory", f"expected avp.Trajectory or None, got {type(trajectory).__name__}")
        self.config = config if config is not None else PlannerConfig()
        self.replan = replan if replan is not None else ReplanConfig()
        if trajectory is not None and self._static_pad:
            contact = contact_position(target, self.config.workspace)  # body_offset along the normal
            miss = float(np.linalg.norm(trajectory.evaluate(trajectory.tf)[:3] - contact))
            if miss > self.replan.target_tolerance:
                raise ConfigError("trajectory", f"ends {miss:.3f} m from its contact point at target.point (more "
                                  f"than replan.target_tolerance {self.replan.target_tolerance:g} m): pass the "
                                  "target (and config) the plan was made for, and give the newer estimate to step()")
        self._replan_config = self.config
        if not self.replan.search_on_replan:
            self._replan_config = replace(
                self.config, bounds=replace(self.config.bounds, factors=(), max_steps=0, relaxations=())
            )
        self.target = target
        self.committed_target: PerchTarget = target
        self.trajectory: Trajectory | None = trajectory
        self._previous: Trajectory | None = None
        self._solve_times: list[float] = []
        self.history: list[ReplanStep] = []
        self._last_t: float | None = None  # the previous step's time (steps may not go back)
        self._retries_failed = False  # a step's retimed retries all ran and failed, nothing committed since
        self._resume: int | None = None
        """Where the next solving step begins its candidates when the deadline cut the last one
        (``_replan``): the index of the first untried retimed retry (``retime_retries[i - 1]``),
        or 0 for the partial corrections; ``None``: from the start."""
        self.snap_limits: tuple[float, float] = (self.replan.snap_max, self.replan.snap_thrust_max)
        """``(snap_max, snap_thrust_max)`` certified on replans (raised to the first plan's peak,
        or to that of the ``trajectory`` handed in)."""
        if trajectory is not None:
            self._raise_snap_limits(trajectory)
        _warm_blas()  # a first-call cost paid here, not in a step

    # -- policy ----------------------------------------------------------------------------
    @property
    def latency(self) -> float:
        """Latency (s) used for ``t_ex``: fixed, or adapted to measured solve times."""
        if not self.replan.adapt_latency or not self._solve_times:
            return self.replan.latency
        recent = float(np.median(self._solve_times[-15:]))
        return max(self.replan.latency, self.replan.latency_margin * recent)

    @property
    def cannot_reach(self) -> bool:
        """The last step reported ``CANNOT_REACH``."""
        return bool(self.history) and self.history[-1].action is ReplanAction.CANNOT_REACH

    def plan_at(self, t: float) -> Trajectory:
        """The plan being flown at ``t`` (s, one time): the previous plan until the committed one
        starts (at its ``t0``, the step's ``t_ex``), the committed one from then on. For a
        controller's feed-forward beyond the flat outputs of :meth:`reference`: its
        ``attitude``, ``thrust`` and ``body_rates`` take times within the plan, so clip ``t`` to
        ``[plan.t0, plan.tf]`` as :meth:`reference` does. After contact (``t > tf``) the perch
        is over: what the vehicle does then (hold, cut thrust) is the controller's."""
        return self._flown(v.finite_float("t", t))

    def _flown(self, t: float) -> Trajectory:
        return flown_plan(self.trajectory, self._previous, t)

    def reference(self, t: float) -> FlatOutput:
        """Flat output to track at ``t`` (s, one time), of :meth:`plan_at`; held at the plans'
        end points outside them (after contact: the contact state, position with the contact
        velocity and acceleration, not a kinematically consistent continuation)."""
        t = v.finite_float("t", t)
        traj = self._flown(t)
        return traj.flat_output(min(max(t, traj.t0), traj.tf))

    def step(self, t: float, odometry: State, target_estimate: PerchTarget | None = None) -> ReplanStep:
        """One replanning cycle at time ``t`` with ``odometry`` (a :class:`State` at ``t``).

        ``t`` is the one clock of the loop (s): ``odometry.time`` is not read, and ``t`` may not
        go back from the previous step's (a clock reset needs a new :class:`Replanner`).

        Raises only for bad input (:class:`~avp.errors.ConfigError`); planning failures of any
        kind are reported in the returned :class:`ReplanStep`.
        """
        t = self._check_input(t, odometry, target_estimate, self._last_t, self.target if self.trajectory is None else None)
        if target_estimate is not None:
            self.target = target_estimate
        step = self._initial(t, odometry) if self.trajectory is None else self._replan(t, odometry)
        self._last_t = t
        self.history.append(step)
        return step

    # -- certification ---------------------------------------------------------------------
    def _certified(self, result: PlanResult | None,
                   trackability: bool = True) -> tuple[bool, str, SnapReport | None, bool]:
        """Whether ``result`` may be committed, why not, its snap certificate, and whether it
        failed only a certificate: a solved, unrelaxed plan whose actuator bounds or
        trackability did not certify (what ``ReplanConfig.retime_retries`` retries with
        another time left). Infeasible, failed, relaxed or workspace-uncertified plans and a
        certificate that raised are not retried."""
        if result is None or result.trajectory is None:
            return False, result.status.value if result is not None else "planning failed", None, False
        relaxations = tuple(getattr(result, "relaxations", ()))  # a MovingPlanResult has none
        relaxed = bool(relaxations) or result.status is PlanStatus.SOLVED_RELAXED
        if not result.ok:
            only_bounds = result.status is PlanStatus.BOUNDS_NOT_CERTIFIED and not relaxed
            return False, result.status.value, None, only_bounds
        if not self.replan.allow_relaxed and relaxed:
            return False, "relaxed plan (allow_relaxed is off)", None, False
        if self.config.bounds.certify and (result.bounds is None or not result.bounds.certified):
            return False, "actuator bounds not certified", None, True
        if not trackability:
            return True, "ok", None, False
        try:
            snap = certify_snap(result.trajectory, self.snap_limits[0], snap_thrust_max=self.snap_limits[1])
        except _PLANNING_ERRORS as exc:
            return False, f"snap certificate failed: {type(exc).__name__}: {exc}", None, False
        if not snap.certified:
            return False, snap.summary(), snap, True
        return True, "ok", snap, False

    def _initial(self, t: float, odometry: State) -> ReplanStep:
        state = State(position=odometry.position, velocity=odometry.velocity,
                      acceleration=odometry.acceleration, jerk=odometry.jerk,
                      yaw=odometry.yaw, yaw_rate=odometry.yaw_rate, time=t)
        result, elapsed, error = self._plan(state, self.target, None, None, self.config)
        ok, why, snap, _ = self._certified(result, trackability=False)
        if not ok:
            return ReplanStep(t=t, action=ReplanAction.NO_PLAN, trajectory=None, reason=error or why, t_ex=t, anticipated=state, result=result, solve_time=elapsed, n_solves=1, snap=snap)
        assert result is not None and result.trajectory is not None
        self.trajectory = result.trajectory
        self.committed_target = self.target
        self._raise_snap_limits(self.trajectory)
        return ReplanStep(t=t, action=ReplanAction.INITIAL_PLAN, trajectory=self.trajectory, reason="first plan", t_ex=t, anticipated=state, result=result, solve_time=elapsed, fraction=1.0, n_solves=1, snap=snap)

    def _raise_snap_limits(self, first: Trajectory) -> None:
        """Replans certify ``max(limit, 1.05 x the first plan's sampled peak)``
        (``ReplanConfig.snap_max``, ``snap_thrust_max``): a replan need not be smoother than
        the plan it corrects."""
        s_peak, k_peak = trackability_peaks(first)
        self.snap_limits = (max(self.replan.snap_max, 1.05 * s_peak), max(self.replan.snap_thrust_max, 1.05 * k_peak))

    def _replan(self, t: float, odometry: State) -> ReplanStep:
        committed = self.trajectory
        assert committed is not None
        rc = self.replan
        clock = _StepClock(rc.deadline)
        t_ex = self._switch_time(committed, t + self.latency)
        remaining = committed.tf - t_ex
        committed_target = self.committed_target
        shift, turn = self._change(committed_target, self.target)
        budget = 0.5 * rc.reach_acceleration * max(remaining, 0.0) ** 2
        # tracking: the odometry against the plan being flown at t (the previous plan until the
        # committed one starts); not measured past its end (contact: the perch is over)
        flown = self._flown(t)
        e_p = e_v = math.nan
        if flown.t0 <= t <= flown.tf:
            ref = flown.derivatives(t)
            e_p = float(np.linalg.norm(odometry.position - ref[0, :3]))
            e_v = float(np.linalg.norm(odometry.velocity - ref[1, :3]))
        anchored = e_p <= rc.anchor_position and e_v <= rc.anchor_velocity

        def tracking() -> str:  # for the reasons of the steps that report it (not on the hold path)
            return (f"odometry {e_p:.3f} m / {e_v:.3f} m/s from the reference (anchors {rc.anchor_position:g} m, "
                    f"{rc.anchor_velocity:g} m/s)")

        def record(action: ReplanAction, reason: str, cue: bool = True, **kw: object) -> ReplanStep:
            """The step's record; ``cue=False``: a step that tried nothing (the committed plan has
            not started) is never ``CANNOT_REACH``, whatever the estimate says."""
            err, ang = self._reach_error(*((shift, turn) if self.committed_target is committed_target
                                           else self._change(self.committed_target, self.target)))
            if cue and action in (ReplanAction.KEPT_PREVIOUS, ReplanAction.FROZEN_NEAR_CONTACT, ReplanAction.PARTIAL) \
                    and (err > rc.reach_tolerance or ang > rc.reach_angle_tolerance) and self._reach_cue:
                limit = (f"budget {budget:.3f} m in {max(remaining, 0.0):.2f} s" if self._static_pad
                         else f"{max(remaining, 0.0):.2f} s left")
                reason = (f"{action.name.lower()}: committed contact point {err:.3f} m and "
                          f"{math.degrees(ang):.1f} deg from the estimate (tolerances {rc.reach_tolerance:.3f} m, "
                          f"{math.degrees(rc.reach_angle_tolerance):.1f} deg; {limit}); {reason}")
                action = ReplanAction.CANNOT_REACH
            # the plan flown on does not start where the vehicle is: it has started (before its t0 it
            # was planned from odometry or the reference just now) and the step committed nothing
            off_track = (not anchored and not math.isnan(e_p) and t >= committed.t0 and action in _KEEPS
                         and kw.get("fraction", 0.0) == 0.0)
            if off_track:
                reason = f"off track: {tracking()}; {reason}"
            return ReplanStep(t=t, action=action, trajectory=self.trajectory, reason=reason, t_ex=t_ex, target_error=err, target_angle=ang, reach_budget=budget if self._static_pad else math.inf, tracking_error=e_p, tracking_velocity_error=e_v, off_track=off_track, **kw)  # type: ignore[arg-type]

        if remaining < max(rc.freeze_horizon, self.config.t_k):
            return record(ReplanAction.FROZEN_NEAR_CONTACT,
                          f"contact in {max(committed.tf - t, 0.0):.3f} s ({max(remaining, 0.0):.3f} s after the "
                          f"switch time t_ex; freeze_horizon {rc.freeze_horizon:g} s)")
        if t < committed.t0:
            return record(ReplanAction.KEPT_PREVIOUS, "the committed plan has not started yet", cue=False)

        if anchored and shift <= rc.target_tolerance and turn <= rc.target_tolerance and self._can_hold:
            self._resume = None  # nothing to correct: what a cut step left is moot
            return record(ReplanAction.HELD, f"tracking {e_p:.3f} m / {e_v:.3f} m/s, estimate {shift:.4f} m and "
                          f"{math.degrees(turn):.2f} deg from the committed target", anchored=True)
        try:
            start = _plan_state(committed, t_ex) if anchored else anticipate(committed, odometry, t, t_ex, rc.measured_orders)
        except ConfigError as exc:
            return record(ReplanAction.KEPT_PREVIOUS, f"no start state: {exc}")
        f_max = 1.0 if shift <= budget or not self._static_pad else budget / shift
        # a normal turned by 90 deg or more (flipped): a blend of the two frames barely turns below
        # half the correction and flips past it (degenerate when opposite, _blend)
        flipped = self._static_pad and float(self.committed_target.s3 @ self.target.s3) <= 0.0
        if flipped and f_max < 1.0:
            return record(ReplanAction.KEPT_PREVIOUS, f"the estimated normal turned by {math.degrees(turn):.0f} deg "
                          f"and its centre moved {shift:.3f} m, beyond the budget {budget:.3f} m: no partial "
                          "correction blends two such frames")
        fractions = rc.partial_fractions if self._static_pad and not flipped else (1.0,)
        too_small = ""  # set when partial_min_correction left fractions out
        if anchored and rc.partial_min_correction > 0.0 and len(fractions) > 1:
            worth = tuple(fr for fr in fractions[1:]
                          if fr * f_max * max(shift, turn) > rc.partial_min_correction)
            if len(worth) < len(fractions) - 1:
                too_small = (f"; {len(fractions) - 1 - len(worth)} partial correction(s) not tried (at most "
                             f"partial_min_correction {rc.partial_min_correction:g})")
                fractions = (fractions[0], *worth)
        elapsed_total, n_solves, last_reason = 0.0, 0, ""
        last_result: PlanResult | None = None
        smallest: tuple[PlanResult, SnapReport | None, PerchTarget, float] | None = None
        backoff_note = ""  # set when the full correction was not retried (retime_backoff)

        def commit(result: PlanResult, snap: SnapReport | None, goal: PerchTarget, f: float,
                   time_factor: float = 1.0, note: str = "") -> ReplanStep:
            self._retries_failed = False
            self._previous = committed
            assert result.trajectory is not None
            # against the goal's own nominal time: a planner may retime by itself (MovingConfig.retime,
            # the duration search with search_on_replan)
            moved = result.trajectory.duration / self._retimed(remaining, goal)
            if abs(moved - time_factor) > 1e-9 * time_factor:
                time_factor = moved
            self.trajectory = result.trajectory
            self.committed_target = goal
            action = ReplanAction.REPLANNED if f >= 1.0 else ReplanAction.PARTIAL
            reason = "ok" if f >= 1.0 else (f"{f:.0%} of the correction ({shift:.3f} m and {math.degrees(turn):.1f} deg "
                                            f"requested, budget {budget:.3f} m)")
            if not anchored:
                reason += f"; planned from odometry: {tracking()}"
            if time_factor != 1.0:
                reason += f" (time left x{time_factor:.4g}: the nominal time failed a certificate)"
            if f < 1.0 or time_factor != 1.0:
                reason += backoff_note
            return record(action, reason + note, anticipated=start, result=result, solve_time=elapsed_total,
                          fraction=f, anchored=anchored, n_solves=n_solves, snap=snap, time_factor=time_factor)

        def out_of_time(reason: str, result: PlanResult | None) -> ReplanStep:
            """The deadline ended the step: a certified smallest correction at hand is committed,
            else the committed plan is kept, and when no partial correction was tried the next
            solving step goes on from where this one stopped (``_resume``)."""
            if smallest is not None:
                return commit(*smallest)
            if not fraction_tried and (pending_retry is not None or len(order) > 1):
                self._resume = pending_retry if pending_retry is not None else 0
            return record(ReplanAction.KEPT_PREVIOUS,
                          f"deadline {(clock.deadline or 0.0) * 1e3:.1f} ms: {reason}{backoff_note}{too_small}",
                          anticipated=start, result=result, solve_time=elapsed_total, anchored=anchored,
                          n_solves=n_solves)

        # Order: the full (first) fraction, then the smallest; only if the smallest certifies,
        # the ones between, largest first (a step that cannot correct at all costs two solves
        # and the failed retimed retries).
        # With a deadline, a solve starts only while it is predicted to fit, and a certified
        # smallest correction is committed when the time runs out.
        probe_smallest = len(fractions) >= 3
        fraction_tried = False  # a partial correction was solved in this step
        pending_retry: int | None = None  # the next retimed retry of the full correction, when one is due
        order = [fractions[0], fractions[-1], *fractions[1:-1]] if probe_smallest else list(fractions)
        # where a step the deadline cut left off (module docstring, "Deadline")
        resume = self._resume if rc.deadline is not None else None
        self._resume = None
        if resume == 0 and len(order) < 2:  # no fraction to begin with
            resume = None
        if resume == 0:
            order = order[1:]
            backoff_note = ("; began with the partial corrections (the deadline cut the previous solving step "
                            "before them)")
        for k, frac in enumerate(order):
            is_full = k == 0 and resume != 0
            is_smallest = probe_smallest and k == (0 if resume == 0 else 1)
            f = frac * f_max
            if not clock.fits(1):
                return out_of_time(f"no time for {100 * f:.3g} % of the correction after {n_solves} solve(s) "
                                   f"in {clock.used() * 1e3:.1f} ms; {last_reason}", last_result)
            fraction_tried = fraction_tried or not is_full
            goal = _blend(self.committed_target, self.target, f) if f < 1.0 else self.target
            total = self._retimed(remaining, goal)
            # The full correction is solved again with the time left scaled (retime_retries) when
            # its plan at the nominal time fails only a certificate; a static pad only (the
            # subclasses keep the committed contact time), not in the last retime_min_time, and
            # (retime_backoff) not again while nothing was committed since retries all failed.
            retry = is_full and self._static_pad and remaining >= rc.retime_min_time
            backed_off = retry and rc.retime_backoff and self._retries_failed and bool(rc.retime_retries)
            all_factors = (1.0, *rc.retime_retries) if retry and not backed_off else (1.0,)
            # a step resuming at a retry: the nominal time failed only a certificate at the step before
            first = resume if is_full and resume and resume < len(all_factors) else 0
            factors = all_factors[first:]
            if first:
                backoff_note = (f"; began with the retimed retry x{factors[0]:g} (the deadline cut the previous "
                                f"solving step before it)")
            nominal: tuple[PlanResult | None, str] | None = None  # reported if no retry certifies
            tried: list[float] = []
            retryable = False  # the first plan of this correction failed only a certificate
            late: str | None = None  # set when a plan ended past the deadline
            room = 2 if k + 1 < len(order) else 1  # a retry, and the smallest fraction when one follows
            for factor in factors:
                if nominal is not None and not clock.fits(room):
                    break  # a retry and then the smallest fraction would not fit the deadline: go to the fractions
                tried.append(factor)
                durations = self._durations(committed, t_ex, factor * total)
                t_attempt = clock.used()
                result, elapsed, error = self._plan(start, goal, durations, committed, self._replan_config,
                                                    deadline=clock.left())
                elapsed_total += elapsed
                n_solves += 1
                last_result = result
                ok, why, snap, only_certificate = self._certified(result)
                if error is not None:
                    why, only_certificate = error, False
                if nominal is None:  # only a plan that failed a certificate is retried (a resumed
                    retryable = only_certificate or first > 0  # retry's nominal did, the step before)
                nxt = first + len(tried)
                pending_retry = nxt if not ok and retryable and nxt < len(all_factors) else None
                if clock.per_attempt is None:
                    clock.per_attempt = clock.used() - t_attempt
                if not ok and nominal is None:
                    nominal = (result, why)
                if clock.overrun():  # this plan and its certificates ended past the deadline
                    late = f"the step took {clock.used() * 1e3:.1f} ms"
                    break
                if ok or not retryable:
                    break  # certified, or not a plan a retry may fix
            if not ok and nominal is not None:  # report the first plan of the correction and its reason (the
                # nominal time's; in a step that began with a retry, that retry's, as its reason says)
                last_result, why = nominal[0], nominal[1]
                if len(tried) > 1:
                    why += " (also at time left " + ", ".join(f"x{x:g}" for x in tried[1:]) + ")"
                if len(all_factors) > 1 and first + len(tried) == len(all_factors):  # every retry ran
                    self._retries_failed = True
                elif backed_off and nominal[0] is not None and only_certificate:
                    backoff_note = _NOT_RETIMED
            if late is not None:  # the step ends here
                if ok:  # certified: committed (discarding it would save no time), and no further solve
                    assert result is not None
                    return commit(result, snap, goal, f, factor,
                                  note=f"; past the deadline of {(clock.deadline or 0.0) * 1e3:.1f} ms ({late})")
                return out_of_time(f"too late: {late}", result)
            if ok:
                assert result is not None
                if not is_smallest:
                    return commit(result, snap, goal, f, tried[-1])
                smallest = (result, snap, goal, f)  # kept; a larger fraction between may certify
                continue
            last_reason = why
            if is_smallest:
                break  # not even the smallest correction certifies
        if smallest is not None:
            return commit(*smallest)
        if pending_retry is not None and not fraction_tried:  # no fraction to try: the deadline cut the retries
            self._resume = pending_retry
            backoff_note += "; the deadline left the retimed retries still due to the next step"
        return record(ReplanAction.KEPT_PREVIOUS, last_reason + backoff_note + too_small, anticipated=start, result=last_result,
                      solve_time=elapsed_total, anchored=anchored, n_solves=n_solves)

    def _durations(self, committed: Trajectory, t_ex: float, total: float) -> Array:
        """Segment durations of a replan from ``t_ex``, summing to ``total``.

        With ``replan.keep_knots``: the committed plan's own knots after ``t_ex`` (see
        :meth:`_switch_time`), the longest piece halved until there are ``n_segments``, scaled to
        ``total``. The committed plan's remainder is then a spline of the new layout, so a replan
        to the committed target can return it and a small correction changes the plan, and its
        certificates, a little. Not exactly where a piece was halved: continuity stops at snap,
        so the halves may leave the committed polynomial (measured 8 mm at 0.9 s into a wall
        perch, against 0.9 mm without the halving); nor after a retiming (``retime_normal``
        rescales every piece). Off, or for a replanner with its own target model (only the
        total matters there): ``n_segments`` equal pieces.
        """
        n = self.config.n_segments
        if not self._keeps_knots:
            return np.full(n, total / n)
        t_rel, inner = _knots_after(committed, t_ex)
        pieces = list(np.diff(np.concatenate(([t_rel], inner, [committed.duration]))))
        while len(pieces) < n:
            i = int(np.argmax(pieces))
            pieces[i:i + 1] = [0.5 * pieces[i], 0.5 * pieces[i]]
        while len(pieces) > n:  # a committed plan with more segments: merge the shortest pair
            i = int(np.argmin([a + b for a, b in itertools.pairwise(pieces)]))
            pieces[i:i + 2] = [pieces[i] + pieces[i + 1]]
        out = np.asarray(pieces, dtype=float)
        return out * (total / float(out.sum()))

    def _switch_time(self, committed: Trajectory, t_ex: float) -> float:
        """``t_ex``, or with ``replan.keep_knots`` the committed plan's next knot when it comes
        within ``keep_knots_min`` of an equal share of the time left: a first segment that short
        would be ill-conditioned, and merging it into the next loses the knot (the committed
        remainder is then no longer a spline of the new layout). The switch only comes later.
        Not when the layout does not use the knots (:meth:`_durations`)."""
        if not self._keeps_knots:
            return t_ex
        n = self.config.n_segments
        t_rel, inner = _knots_after(committed, t_ex)
        reach = self.replan.keep_knots_min * (committed.duration - t_rel) / n
        return committed.t0 + float(inner[0]) if inner.size and inner[0] <= t_rel + reach else t_ex

    def _retimed(self, remaining: float, goal: PerchTarget) -> float:
        """Time left after moving the contact time with the normal part of the correction."""
        v_n = self.config.contact_velocity.normal
        if not self._static_pad or not self.replan.retime_normal or v_n is None or abs(v_n) < 1e-6:
            return remaining
        dn = float((goal.point - self.committed_target.point) @ self.committed_target.s3)
        cap = self.replan.retime_fraction * remaining
        return remaining + float(np.clip(-dn / abs(v_n), -cap, cap))

    def _plan(
        self, state: State, target: PerchTarget, durations: Array | None, previous: Trajectory | None,
        config: PlannerConfig, deadline: float | None = None,
    ) -> tuple[PlanResult | None, float, str | None]:
        t0 = _clock()
        try:
            with serial_blas():  # no wait for a second core (avp._blas)
                if target is self.target and deadline is None:  # a hook written without the deadline works
                    result = self._solve(state, durations, previous, config)
                elif target is self.target:
                    result = self._solve(state, durations, previous, config, deadline=deadline)
                else:  # a blended (partial) target: only the static-pad hook plans to another target
                    result = Replanner._solve(self, state, durations, previous, config, target=target,
                                              deadline=deadline)
        except _PLANNING_ERRORS as exc:  # never raise for a planning or solver failure
            elapsed = _clock() - t0
            self._solve_times.append(elapsed)
            return None, elapsed, f"{type(exc).__name__}: {exc}"
        elapsed = _clock() - t0
        self._solve_times.append(elapsed)
        return result, elapsed, None

    def _solve(
        self, state: State, durations: Array | None, previous: Trajectory | None, config: PlannerConfig,
        target: PerchTarget | None = None, deadline: float | None = None,
    ) -> PlanResult:
        """One planning call to ``target`` (default: the latest estimate) within ``deadline`` (s,
        :func:`avp.plan_detailed`); the hook a subclass for another target model overrides (it
        then plans to its own ``self.target``, and the policy uses full corrections only: no
        blending or reach budget, and ``CANNOT_REACH`` only where it sets :attr:`_reach_cue`; its
        planner may ignore the deadline)."""
        return plan_detailed(
            state, target if target is not None else self.target, config, durations=durations,
            previous=previous, warm_start=previous if self.replan.warm_start else None, deadline=deadline,
        )

    _target_type: type = PerchTarget
    """The target class :meth:`step` accepts (a subclass for another target model sets its own)."""

    @classmethod
    def _check_input(cls, t: Any, odometry: Any, target_estimate: Any, last_t: float | None,
                     first_target: PerchTarget | None) -> float:
        """:meth:`step`'s input checks (``ConfigError`` naming the argument), ``t`` as a float;
        ``last_t`` is the previous step's time and ``first_target`` the estimate a first plan
        would use when ``target_estimate`` is ``None`` (``None`` once a plan is committed). A
        subclass adds its own (a moving pad: the estimate's time). A class method, so that
        :class:`avp.BackgroundReplanner` checks a call before sending it to its worker."""
        t = check_step_time(t, last_t)
        if not isinstance(odometry, State):
            raise ConfigError("odometry", f"expected avp.State, got {type(odometry).__name__}")
        if target_estimate is not None and not isinstance(target_estimate, cls._target_type):
            raise ConfigError("target_estimate",
                              f"expected avp.{cls._target_type.__name__}, got {type(target_estimate).__name__}")
        return t

    def _change(self, a: Any, b: Any) -> tuple[float, float]:
        """Distance (m) and angle (rad) between two target estimates (the hold and reach tests).
        A function of its two arguments only: a step computes it once for an unchanged pair."""
        return _target_change(a, b)

    def _reach_error(self, shift: float, turn: float) -> tuple[float, float]:
        """``target_error`` (m) and ``target_angle`` (rad) of a step, from :meth:`_change` of the
        committed target and the estimate (``shift``, ``turn``): for a pad they are those; a
        target model whose contact is not its estimate's centre (a line) overrides it."""
        return shift, turn

    @property
    def _reach_cue(self) -> bool:
        """Whether a step that leaves the committed contact point farther than
        ``reach_tolerance`` from the estimate, or its normal turned by more than
        ``reach_angle_tolerance`` (:meth:`_reach_error`), says ``CANNOT_REACH`` (a static pad;
        a moving pad and a line set it too)."""
        return self._static_pad

    @property
    def _can_hold(self) -> bool:
        """Whether an unchanged estimate with good tracking keeps the plan without a solve."""
        return self._static_pad

    @property
    def _keeps_knots(self) -> bool:
        """Whether replans lay their segments on the committed knots (``replan.keep_knots``, a
        static pad only: :meth:`_durations`, :meth:`_switch_time`)."""
        return self.replan.keep_knots and self._static_pad

    @property
    def _static_pad(self) -> bool:
        """Whether planning uses this class's static-pad hook (partial corrections available)."""
        return type(self)._solve is Replanner._solve
