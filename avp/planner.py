"""Planning entry points: :func:`plan` (returns a :class:`Trajectory` or raises) and
:func:`plan_detailed` (returns a :class:`PlanResult` that says what happened)."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from enum import Enum
from typing import Any

import numpy as np
import numpy.typing as npt

from .config import PlannerConfig
from .errors import ConfigError, InfeasibleError, PlanningError, SolverError
from .qp.assemble import build_perching_qp
from .solve import QpOutcome, solve_perching_qp
from .timing import check_durations, initial_durations
from .trajectory import Trajectory
from .types import PerchTarget, State

__all__ = ["PlanStatus", "PlanTimings", "PlanResult", "plan", "plan_detailed"]

Array = npt.NDArray[np.float64]


class PlanStatus(Enum):
    """Outcome of a plan (readable values, as rotorpy's ExitStatus)."""

    SOLVED = "solved: every constraint met"
    SOLVED_WITHOUT_FOV = "solved after dropping the field-of-view rows (16)"
    INFEASIBLE = "infeasible: the perching constraints admit no trajectory"
    SOLVER_FAILED = "solver failed: no usable solution from the QP back-end"
    BOUNDS_NOT_CERTIFIED = "actuator bounds not certified within the allowed time changes"

    @property
    def has_trajectory(self) -> bool:
        return self in (PlanStatus.SOLVED, PlanStatus.SOLVED_WITHOUT_FOV)


@dataclass(frozen=True)
class PlanTimings:
    """Wall-clock seconds spent in each stage (summed over re-solves)."""

    build: float = 0.0
    solve: float = 0.0
    certify: float = 0.0
    total: float = 0.0


@dataclass(frozen=True)
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
    """

    status: PlanStatus
    trajectory: Trajectory | None
    durations: Array
    qp: QpOutcome | None
    log: tuple[str, ...] = ()
    timings: PlanTimings = field(default_factory=PlanTimings)
    fov_dropped: bool = False
    duration_scale_steps: int = 0
    bounds: Any = None

    @property
    def ok(self) -> bool:
        return self.status.has_trajectory and self.trajectory is not None


def _check_inputs(state: Any, target: Any, config: Any) -> PlannerConfig:
    if not isinstance(state, State):
        raise ConfigError("state", f"expected avp.State, got {type(state).__name__}")
    if not isinstance(target, PerchTarget):
        raise ConfigError("target", f"expected avp.PerchTarget, got {type(target).__name__}")
    if config is None:
        config = PlannerConfig()
    if not isinstance(config, PlannerConfig):
        raise ConfigError("config", f"expected avp.PlannerConfig, got {type(config).__name__}")
    distance = float(np.linalg.norm(target.point - state.position))
    if distance < config.min_distance:
        raise ConfigError(
            "target.point",
            f"is {distance:.3f} m from the start state (config.min_distance = {config.min_distance} m); "
            "a perch needs a target away from the vehicle",
        )
    return config


@dataclass
class _Attempt:
    """One QP solve at fixed durations (internal)."""

    outcome: QpOutcome | None
    trajectory: Trajectory | None
    fov_dropped: bool
    build: float
    solve: float


def _solve_at(
    state: State,
    target: PerchTarget,
    cfg: PlannerConfig,
    T: Array,
    log: list[str],
    previous: Trajectory | None = None,
) -> _Attempt:
    """Build and solve the perching QP for durations ``T``.

    Field-of-view rows (8)-(9) and the fallback (16) plug in here: see :mod:`avp.perception`.
    """
    t0 = time.perf_counter()
    qp = build_perching_qp(state, target, cfg, T)
    build = time.perf_counter() - t0
    try:
        outcome = solve_perching_qp(qp, cfg)
    except InfeasibleError as exc:
        log.append(str(exc))
        return _Attempt(None, None, False, build, 0.0)
    log.append(f"QP {cfg.solver}: {outcome.status.value} (max violation {outcome.max_violation:.1e})")
    traj = None
    if outcome.ok and outcome.c_hat is not None:
        coeffs = qp.layout.to_physical(outcome.c_hat, T)
        knots = state.time + np.concatenate([[0.0], np.cumsum(T)])
        traj = Trajectory(coeffs, knots, g=cfg.g)
    return _Attempt(outcome, traj, False, build + outcome.build_time, outcome.solve_time)


def plan_detailed(
    state: State,
    target: PerchTarget,
    config: PlannerConfig | None = None,
    *,
    durations: Any = None,
    previous: Trajectory | None = None,
) -> PlanResult:
    """Plan a perch and report what happened; raises only for bad input or a missing solver.

    Parameters
    ----------
    state:
        Start state; the plan starts at ``state.time``.
    target:
        Perch pad (point and ``R_WS``).
    config:
        :class:`PlannerConfig` (paper defaults when ``None``).
    durations:
        Segment durations (s) overriding the allocation rule.
    previous:
        The committed plan when replanning (linearisation point of the FoV rows (8)).
    """
    t_start = time.perf_counter()
    cfg = _check_inputs(state, target, config)
    T = check_durations(durations, cfg) if durations is not None else initial_durations(state, target, cfg)
    log: list[str] = [f"durations {np.round(T, 4).tolist()} s ({'given' if durations is not None else 'allocated'})"]
    attempt = _solve_at(state, target, cfg, T, log, previous)
    timings = PlanTimings(build=attempt.build, solve=attempt.solve, total=time.perf_counter() - t_start)
    outcome = attempt.outcome
    if attempt.trajectory is None:
        if outcome is None or (outcome.solution is not None and not outcome.solution.found):
            status = PlanStatus.INFEASIBLE
        else:
            status = PlanStatus.SOLVER_FAILED
        return PlanResult(status, None, T, outcome, tuple(log), timings, attempt.fov_dropped)
    status = PlanStatus.SOLVED_WITHOUT_FOV if attempt.fov_dropped else PlanStatus.SOLVED
    return PlanResult(status, attempt.trajectory, T, outcome, tuple(log), timings, attempt.fov_dropped)


def plan(
    state: State,
    target: PerchTarget,
    config: PlannerConfig | None = None,
    *,
    durations: Any = None,
) -> Trajectory:
    """Plan a perch; return the :class:`Trajectory` or raise a :class:`PlanningError`.

    Raises
    ------
    ConfigError
        Bad input (names the field).
    InfeasibleError, SolverError, BoundsNotCertifiedError
        No trajectory; ``exc.result`` is the :class:`PlanResult`.
    """
    result = plan_detailed(state, target, config, durations=durations)
    if result.ok and result.trajectory is not None:
        return result.trajectory
    message = f"no perching trajectory: {result.status.value}; " + "; ".join(result.log[-2:])
    if result.status is PlanStatus.INFEASIBLE:
        raise InfeasibleError(message, result)
    if result.status is PlanStatus.SOLVER_FAILED:
        raise SolverError(message, result)
    raise PlanningError(message, result)
