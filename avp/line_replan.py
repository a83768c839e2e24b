"""Replanning a line perch: :class:`LineReplanner`, the :class:`~avp.replan.Replanner` policy with
:func:`~avp.line_planner.plan_line` as its planning call.

``step(t, odometry, line_estimate)`` takes the latest line estimate as a
:class:`~avp.line.LineTarget`. The first plan searches the duration; a replan anticipates the
start state (6) exactly as for a pad (anchored on the committed plan while tracking is good) and
keeps the committed contact time (``duration = t_f - t_ex``, no duration search), so only the
line estimate changes. A plan is committed only when every certificate of
:func:`~avp.line_planner.plan_line` holds (clearance, height, corridor, flip, actuator bounds,
recovery) and the trackability certificate of :mod:`avp.trackability` holds too. Corrections are
full ones: the partial corrections of the pad policy blend two pad frames and do not apply to a
line. A step that keeps a plan whose grasp point (the contact CoM less ``gripper_offset`` along
its thrust axis) is farther than ``ReplanConfig.reach_tolerance`` from the estimated line, or
whose grasped piece turned from the estimate's piece there by more than
``reach_angle_tolerance``, says ``CANNOT_REACH`` (``ReplanStep.target_error``,
``target_angle``): the gripper would close beside the line. A line moved along itself keeps a
plan that still grasps it. The recovery of the last committed plan is
:attr:`LineReplanner.recovery`.
"""

from __future__ import annotations

import dataclasses
import math
from enum import Enum
from typing import Any

import numpy as np

from ._typing import Array
from .config import PlannerConfig, ReplanConfig
from .errors import ConfigError
from .line import LineTarget
from .line_planner import LineOptions, LinePlanResult, plan_line
from .replan import Replanner, ReplanStep
from .trajectory import Trajectory
from .types import State

__all__ = ["LineReplanner", "line_change"]


def line_change(a: LineTarget, b: LineTarget) -> tuple[float, float]:
    """Largest vertex displacement (m) and largest angle (rad) between matching pieces of two
    estimates of one line (``inf`` when their vertex counts differ)."""
    if a.vertices.shape != b.vertices.shape:
        return math.inf, math.inf
    shift = float(np.max(np.linalg.norm(a.vertices - b.vertices, axis=1)))
    turn = 0.0
    for k in range(a.n_pieces):
        da, db = np.diff(a.vertices[k:k + 2], axis=0)[0], np.diff(b.vertices[k:k + 2], axis=0)[0]
        c = float(da @ db) / (float(np.linalg.norm(da)) * float(np.linalg.norm(db)))
        turn = max(turn, math.acos(min(1.0, max(-1.0, c))))
    return shift, turn


def _close(x: Any, y: Any, tol: float) -> bool:
    """Numbers and arrays within ``tol`` of each other, element-wise; anything else equal."""
    if x is None or y is None:
        return x is y
    if isinstance(x, Enum) or isinstance(y, Enum):
        return bool(x == y)
    try:
        xa, ya = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    except (TypeError, ValueError):
        return bool(x == y)
    return xa.shape == ya.shape and bool(np.all(np.abs(xa - ya) <= tol))


class LineReplanner(Replanner):
    """:class:`~avp.replan.Replanner` for a perch on a line (module docstring).

    Parameters
    ----------
    target:
        Initial line estimate.
    config, replan, trajectory:
        As for :class:`~avp.replan.Replanner`.
    options:
        :class:`~avp.line_planner.LineOptions` of every planning call.
    """

    _target_type = LineTarget

    def __init__(
        self,
        target: LineTarget,
        config: PlannerConfig | None = None,
        replan: ReplanConfig | None = None,
        options: LineOptions | None = None,
        trajectory: Trajectory | None = None,
    ) -> None:
        super().__init__(target, config, replan, trajectory)  # type: ignore[arg-type]
        self.options = options if options is not None else LineOptions()
        if not isinstance(self.options, LineOptions):
            raise ConfigError("options", f"expected avp.LineOptions or None, got {type(self.options).__name__}")
        self.recovery: Trajectory | None = None
        """Recovery of the last committed plan (None before the first plan or without recovery)."""
        self.last_result: LinePlanResult | None = None
        """Result of the last committed planning call."""

    def step(self, t: float, odometry: State, target_estimate: LineTarget | None = None) -> ReplanStep:  # type: ignore[override]
        step = super().step(t, odometry, target_estimate)  # type: ignore[arg-type]
        if step.committed and isinstance(step.result, LinePlanResult):
            self.last_result = step.result
            self.recovery = step.result.recovery
        return step

    def _change(self, a: Any, b: Any) -> tuple[float, float]:
        return line_change(a, b)

    def _reach_error(self, shift: float, turn: float) -> tuple[float, float]:
        """The committed grasp point's distance (m) to the estimated line, and the angle (rad,
        unsigned) between the committed grasped piece and the estimate's piece closest to that
        point (module docstring)."""
        traj, committed, estimate = self.trajectory, self.committed_target, self.target
        assert traj is not None and isinstance(committed, LineTarget) and isinstance(estimate, LineTarget)
        b3 = traj.attitude(traj.tf, rotor_drag=self.config.limits.rotor_drag)[:, 2]
        grasp = traj(traj.tf) - committed.gripper_offset * b3
        k, distance = estimate.closest(grasp)
        A, B = committed.piece(committed.grasp_piece)
        C, D = estimate.piece(k)
        d_committed, d_estimate = B - A, D - C
        c = abs(float(d_committed @ d_estimate)) / (float(np.linalg.norm(d_committed)) * float(np.linalg.norm(d_estimate)))
        return distance, math.acos(min(1.0, c))

    @property
    def _reach_cue(self) -> bool:
        return True

    @property
    def _can_hold(self) -> bool:
        """Only while the estimate's other fields stay within ``replan.target_tolerance`` of
        the committed line's (m, rad, grasp fraction; names and counts exactly): a new
        ``pitch``, ``grasp``, radius, gripper offset or side asks for another perch. The
        vertices are compared by :func:`line_change`."""
        a, b, tol = self.committed_target, self.target, self.replan.target_tolerance
        return all(_close(getattr(a, f.name), getattr(b, f.name), tol)
                   for f in dataclasses.fields(LineTarget) if f.name != "vertices")

    def _solve(  # type: ignore[override]  # returns the duck-compatible LinePlanResult
        self, state: State, durations: Array | None, previous: Trajectory | None, config: PlannerConfig,
        deadline: float | None = None,  # not used: this planner has no time budget
    ) -> LinePlanResult:
        assert isinstance(self.target, LineTarget)
        if durations is None:  # the first plan: the duration search of ``config``
            return plan_line(state, self.target, config, self.options)
        # a replan: the perch keeps the committed contact time unless ``search_on_replan``;
        # the recovery always searches its duration with the user's ``config.bounds``
        return plan_line(state, self.target, self.config, self.options, duration=float(np.sum(durations)),
                         perch_search=self.replan.search_on_replan)
