"""Active replanning (Sec. IV): a :class:`Replanner` that user code calls from its own loop
(30 Hz in the paper) with odometry and the latest target estimate.

Each :meth:`Replanner.step` anticipates the state at the moment a new plan can take over (6),
``t_ex = t_rp + latency``, replans from there to the (re-estimated) target with the FoV rows
linearised around the committed plan, and commits the new plan if it is usable. It keeps the
committed plan when a solve fails or comes too late, and stops replanning near contact. It never
raises for a planning or solver failure: the :class:`ReplanStep` says what happened.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from enum import Enum

import numpy as np
import numpy.typing as npt

from . import _avp_rust
from . import _validate as v
from .config import PlannerConfig
from .errors import AvpError, ConfigError
from .planner import PlanResult, plan_detailed
from .trajectory import FlatOutput, Trajectory
from .types import PerchTarget, State

__all__ = ["ReplanAction", "ReplanConfig", "ReplanStep", "Replanner", "anticipate"]

Array = npt.NDArray[np.float64]


class ReplanAction(Enum):
    """What one :meth:`Replanner.step` did."""

    INITIAL_PLAN = "initial plan committed"
    REPLANNED = "replanned: new plan committed from t_ex"
    KEPT_PREVIOUS = "kept the committed plan (replanning failed or came too late)"
    FROZEN_NEAR_CONTACT = "too close to contact: committed plan kept without replanning"
    NO_PLAN = "no plan yet: the first plan failed"


@dataclass(frozen=True)
class ReplanConfig:
    """Replanning policy.

    Parameters
    ----------
    latency:
        Time (s) between the odometry sample ``t_rp`` and the switch to the new plan ``t_ex``.
    adapt_latency:
        If true, use ``max(latency, latency_margin * recent median solve time)``.
    latency_margin:
        Safety factor on the measured solve time.
    freeze_horizon:
        No replanning when less than this (s) is left to contact (at least the band window).
    deadline:
        A solve slower than this (s, wall clock) is discarded as too late; ``None``: no deadline
        (use ``None`` in simulation for deterministic runs).
    measured_orders:
        Derivative orders taken from odometry (2: position and velocity, yaw and yaw rate);
        higher orders come from the committed plan, so commands stay continuous (6).
    warm_start:
        Pass the committed plan as initial guess to back-ends that accept one.
    search_on_replan:
        Let replans run the duration search and relaxations of ``config.bounds``. Off by
        default: a replan keeps the committed contact time and, if its bounds do not certify,
        the committed plan is kept (in closed loop the search made the contact time drift and
        let relaxed plans through; it also cost up to 55 solves per step).
    """

    latency: float = 0.02
    adapt_latency: bool = False
    latency_margin: float = 1.5
    freeze_horizon: float = 0.25
    deadline: float | None = None
    measured_orders: int = 2
    warm_start: bool = True
    search_on_replan: bool = False

    def __post_init__(self) -> None:
        v.positive_float("replan.latency", self.latency)
        v.positive_float("replan.latency_margin", self.latency_margin)
        v.positive_float("replan.freeze_horizon", self.freeze_horizon)
        if self.deadline is not None:
            v.positive_float("replan.deadline", self.deadline)
        if not 0 <= self.measured_orders <= 5:
            raise ConfigError("replan.measured_orders", "must be in 0..5 (0: all orders from the plan)")


@dataclass(frozen=True)
class ReplanStep:
    """Record of one :meth:`Replanner.step`.

    ``trajectory`` is the committed plan after the step (what to track from ``t_ex`` on; before
    ``t_ex`` keep tracking the previous one, or call :meth:`Replanner.reference`).
    """

    t: float
    action: ReplanAction
    trajectory: Trajectory | None
    reason: str
    t_ex: float
    anticipated: State | None = None
    result: PlanResult | None = None
    solve_time: float = 0.0


def anticipate(plan: Trajectory, odometry: State, t_rp: float, t_ex: float, measured_orders: int = 2) -> State:
    """Anticipated start state (6) at ``t_ex`` from odometry taken at ``t_rp``.

    ``x0^(k) = x_n^(k) + P^(k)(t_ex) - P^(k)(t_rp)`` for ``k = 0..4`` and yaw; orders at or
    above ``measured_orders`` use the plan's own value at ``t_rp`` as ``x_n^(k)`` (odometry
    rarely measures jerk or snap). Computed in Rust (``avp._avp_rust.anticipate``).
    """
    odo = plan.derivatives(t_rp)  # (5, 4): the plan's own values
    measured = np.zeros((5, 4))
    measured[:4, :3] = odometry.derivatives()
    measured[0, 3], measured[1, 3] = odometry.yaw, odometry.yaw_rate
    odo[:measured_orders] = measured[:measured_orders]
    try:
        x0 = _avp_rust.anticipate(plan.coefficients, plan.knots, np.ascontiguousarray(odo), float(t_rp), float(t_ex))
    except ValueError as exc:
        raise ConfigError("t", str(exc)) from exc
    return State(position=x0[0, :3], velocity=x0[1, :3], acceleration=x0[2, :3], jerk=x0[3, :3],
                 yaw=float(x0[0, 3]), yaw_rate=float(x0[1, 3]), time=float(t_ex))


class Replanner:
    """Replans a perch from a user-owned loop.

    Parameters
    ----------
    target:
        Initial target estimate.
    config:
        Planner configuration (FoV rows are linearised around the committed plan).
    replan:
        :class:`ReplanConfig`.
    trajectory:
        An already committed plan (otherwise the first :meth:`step` plans from odometry).
    """

    def __init__(
        self,
        target: PerchTarget,
        config: PlannerConfig | None = None,
        replan: ReplanConfig | None = None,
        trajectory: Trajectory | None = None,
    ) -> None:
        if not isinstance(target, PerchTarget):
            raise ConfigError("target", f"expected avp.PerchTarget, got {type(target).__name__}")
        self.config = config if config is not None else PlannerConfig()
        self.replan = replan if replan is not None else ReplanConfig()
        self._replan_config = self.config
        if not self.replan.search_on_replan:
            self._replan_config = replace(
                self.config, bounds=replace(self.config.bounds, factors=(), max_steps=0, relaxations=())
            )
        self.target = target
        self.trajectory: Trajectory | None = trajectory
        self._previous: Trajectory | None = None
        self._solve_times: list[float] = []
        self.history: list[ReplanStep] = []

    # -- policy ----------------------------------------------------------------------------
    @property
    def latency(self) -> float:
        """Latency (s) used for ``t_ex``: fixed, or adapted to measured solve times."""
        if not self.replan.adapt_latency or not self._solve_times:
            return self.replan.latency
        recent = float(np.median(self._solve_times[-15:]))
        return max(self.replan.latency, self.replan.latency_margin * recent)

    def reference(self, t: float) -> FlatOutput:
        """Flat output to track at ``t``: the previous plan until the committed one starts."""
        traj = self.trajectory
        if traj is None:
            raise ConfigError("t", "no plan committed yet; call step() first")
        if t < traj.t0 and self._previous is not None:
            traj = self._previous
        return traj.flat_output(min(max(t, traj.t0), traj.tf))

    def step(self, t: float, odometry: State, target_estimate: PerchTarget | None = None) -> ReplanStep:
        """One replanning cycle at time ``t`` with ``odometry`` (a :class:`State` at ``t``).

        Raises only for bad input (:class:`~avp.errors.ConfigError`); planning failures are
        reported in the returned :class:`ReplanStep`.
        """
        t = v.finite_float("t", t)
        if not isinstance(odometry, State):
            raise ConfigError("odometry", f"expected avp.State, got {type(odometry).__name__}")
        if target_estimate is not None:
            if not isinstance(target_estimate, PerchTarget):
                raise ConfigError("target_estimate", f"expected avp.PerchTarget, got {type(target_estimate).__name__}")
            self.target = target_estimate
        step = self._initial(t, odometry) if self.trajectory is None else self._replan(t, odometry)
        self.history.append(step)
        return step

    def _initial(self, t: float, odometry: State) -> ReplanStep:
        state = State(position=odometry.position, velocity=odometry.velocity,
                      acceleration=odometry.acceleration, jerk=odometry.jerk,
                      yaw=odometry.yaw, yaw_rate=odometry.yaw_rate, time=t)
        result, elapsed, error = self._plan(state, None, None, self.config)
        if result is None or not result.ok:
            reason = error or (result.status.value if result else "planning failed")
            return ReplanStep(t, ReplanAction.NO_PLAN, None, reason, t, state, result, elapsed)
        self.trajectory = result.trajectory
        return ReplanStep(t, ReplanAction.INITIAL_PLAN, self.trajectory, "first plan", t, state, result, elapsed)

    def _replan(self, t: float, odometry: State) -> ReplanStep:
        committed = self.trajectory
        assert committed is not None
        t_ex = t + self.latency
        remaining = committed.tf - t_ex
        if remaining < max(self.replan.freeze_horizon, self.config.t_k):
            return ReplanStep(t, ReplanAction.FROZEN_NEAR_CONTACT, committed,
                              f"{max(remaining, 0.0):.3f} s to contact", t_ex)
        if t < committed.t0:
            return ReplanStep(t, ReplanAction.KEPT_PREVIOUS, committed,
                              "the committed plan has not started yet", t_ex)
        start = anticipate(committed, odometry, t, t_ex, self.replan.measured_orders)
        durations = np.full(self.config.n_segments, remaining / self.config.n_segments)
        result, elapsed, error = self._plan(start, durations, committed, self._replan_config)
        if error is not None or result is None:
            return ReplanStep(t, ReplanAction.KEPT_PREVIOUS, committed, error or "planning failed", t_ex, start, result, elapsed)
        if not result.ok:
            return ReplanStep(t, ReplanAction.KEPT_PREVIOUS, committed, result.status.value, t_ex, start, result, elapsed)
        if self.replan.deadline is not None and elapsed > self.replan.deadline:
            return ReplanStep(t, ReplanAction.KEPT_PREVIOUS, committed,
                              f"too late: solve took {elapsed * 1e3:.1f} ms > deadline "
                              f"{self.replan.deadline * 1e3:.1f} ms", t_ex, start, result, elapsed)
        self._previous = committed
        self.trajectory = result.trajectory
        return ReplanStep(t, ReplanAction.REPLANNED, self.trajectory, "ok", t_ex, start, result, elapsed)

    def _plan(
        self, state: State, durations: Array | None, previous: Trajectory | None, config: PlannerConfig
    ) -> tuple[PlanResult | None, float, str | None]:
        t0 = time.perf_counter()
        try:
            result = self._solve(state, durations, previous, config)
        except AvpError as exc:  # never raise for a planning or solver failure
            elapsed = time.perf_counter() - t0
            self._solve_times.append(elapsed)
            return None, elapsed, f"{type(exc).__name__}: {exc}"
        elapsed = time.perf_counter() - t0
        self._solve_times.append(elapsed)
        return result, elapsed, None

    def _solve(
        self, state: State, durations: Array | None, previous: Trajectory | None, config: PlannerConfig
    ) -> PlanResult:
        """One planning call (the hook a subclass for another target model overrides)."""
        return plan_detailed(
            state, self.target, config, durations=durations, previous=previous,
            warm_start=previous if self.replan.warm_start else None,
        )
