"""Public value types at the planner boundary: the vehicle :class:`State` and the
:class:`PerchTarget` with its frame S (``docs/conventions.md``).

All vectors are in the world frame W (z up) unless a name says otherwise; SI units.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np

from . import _validate as v
from . import frames
from ._typing import Array
from ._values import fields_equal, fields_hash
from .errors import ConfigError

__all__ = ["PerchTarget", "State"]

_ZERO3 = (0.0, 0.0, 0.0)


@v.typed_keywords("state")
@dataclass(frozen=True, eq=False)
class State:
    """Flat-output state of the vehicle at ``time``: the initial condition of a plan.

    Parameters
    ----------
    position, velocity, acceleration, jerk:
        ``x`` and its derivatives in W (m, m/s, m/s^2, m/s^3).
    yaw, yaw_rate:
        ``psi`` (rad) and its rate (rad/s), the fourth flat output.
    time:
        Absolute time of this state (s); a plan starts here.

    Each must be finite and within a flight's magnitudes (``avp._validate.LIMITS``: 1000 km,
    1 km/s, 1e4 m/s^2, 1e6 m/s^3, 1e6 rad, 1e3 rad/s, 1e10 s); beyond them the planner's
    arithmetic overflows or loses the millisecond, so they are refused (``ConfigError``).
    Any clock works up to that limit (a UNIX timestamp, ROS time): a plan holds its start and
    its knots relative to it (:attr:`Trajectory.knots_rel <avp.trajectory.Trajectory.knots_rel>`),
    so it is the plan made at time 0, shifted, and its certificates hold as they do at 0. Only
    absolute times themselves are rounded to the clock (2.4e-7 s at UNIX time).
    """

    position: Array
    velocity: Array = field(default_factory=lambda: np.zeros(3))
    acceleration: Array = field(default_factory=lambda: np.zeros(3))
    jerk: Array = field(default_factory=lambda: np.zeros(3))
    yaw: float = 0.0
    yaw_rate: float = 0.0
    time: float = 0.0

    __eq__ = fields_equal  # values, not identity (module _values)
    __hash__ = fields_hash

    def __post_init__(self) -> None:
        for name in ("position", "velocity", "acceleration", "jerk"):
            object.__setattr__(self, name, v.frozen_array(f"state.{name}", getattr(self, name), (3,)))
            v.within(f"state.{name}", getattr(self, name), name)
        for name in ("yaw", "yaw_rate", "time"):
            object.__setattr__(self, name, v.finite_float(f"state.{name}", getattr(self, name)))
            v.within(f"state.{name}", getattr(self, name), name)

    @classmethod
    def hover(cls, position: Any, yaw: float = 0.0, time: float = 0.0) -> State:
        """At rest at ``position`` with heading ``yaw``."""
        return cls(position=position, yaw=yaw, time=time)

    def derivatives(self) -> Array:
        """Rows: position, velocity, acceleration, jerk (shape ``(4, 3)``)."""
        return np.stack([self.position, self.velocity, self.acceleration, self.jerk])


@v.typed_keywords("target")
@dataclass(frozen=True, eq=False)
class PerchTarget:
    """A perch pad: its centre ``point`` and orientation ``R_WS = [s1 s2 s3]``.

    ``s3`` is the pad's outward normal on the side the vehicle arrives from (at contact
    ``b3 = s3``), ``s1`` the up-slope tangent, ``s2 = s3 x s1`` (always horizontal unless the
    pad is level), as :meth:`from_incline` and :meth:`from_normal` build them. A frame given
    directly (a fiducial's, say) or with ``up_slope`` may turn ``s1`` about ``s3``: the
    contact attitude and the slide ``ContactVelocity.slope`` (along ``s1``) then turn with it,
    and a replanner takes each estimate's ``s1`` as given. Incline is the angle between
    ``s3`` and ``e3``: 0 floor, 90 deg wall, 180 deg ceiling.

    A plan ends with ``attitude(t_f)[:, 2] == s3`` (thrust axis along the normal) for every
    target, and with ``attitude(t_f) == R_WS`` exactly (to rounding) whenever the frame's roll in
    the attitude construction (13) (yaw-pitch-roll, ``cos(roll) = |s3z| / sqrt(s2z^2 + s3z^2)``) is
    at most :data:`avp.frames.MAX_CONTACT_ROLL` (75.5 deg); ``from_incline`` and ``from_normal``
    without ``up_slope`` always give roll 0. Beyond it (a horizontal normal with a tilted or
    vertical ``s2``) the rotation about ``s3`` is the closest the construction reaches, off by
    :func:`avp.frames.contact_frame_error` (the plan's log says so).

    The target is static; :meth:`at` is the hook a moving target overrides (roadmap: moving
    platforms, as in Gao et al., "Adaptive Tracking and Perching for Quadrotor in Dynamic Scenarios").
    """

    point: Array
    R_WS: Array

    __eq__ = fields_equal  # values, not identity (module _values)
    __hash__ = fields_hash

    def __post_init__(self) -> None:
        object.__setattr__(self, "point", v.frozen_array("target.point", self.point, (3,)))
        v.within("target.point", self.point, "position")
        object.__setattr__(self, "R_WS", v.rotation("target.R_WS", self.R_WS))

    # -- constructors ---------------------------------------------------------------------
    @classmethod
    def from_normal(
        cls,
        point: Any,
        normal: Any,
        up_slope: Any | None = None,
        approach_heading: float | None = None,
    ) -> PerchTarget:
        """Build S from the outward ``normal`` (``s3``).

        ``s1`` is ``up_slope`` (projected onto the pad plane) when given, else the projection
        of ``e3`` onto the pad plane; for a level pad (floor or ceiling), where that
        projection vanishes, it is the horizontal ``approach_heading`` (rad, direction the
        vehicle flies in; default 0 = +x).
        """
        s3 = v.unit_vector("target.normal", normal)
        if up_slope is not None:
            raw = v.unit_vector("target.up_slope", up_slope)
            field_name = "target.up_slope"
        else:
            raw = np.array([0.0, 0.0, 1.0])
            field_name = "target.normal"
        s1 = raw - np.dot(raw, s3) * s3
        if np.linalg.norm(s1) < 1e-9:
            if up_slope is not None:
                raise ConfigError(field_name, "is parallel to the normal; pass a tangent direction")
            heading = 0.0 if approach_heading is None else v.finite_float("target.approach_heading", approach_heading)
            h = np.array([math.cos(heading), math.sin(heading), 0.0])
            s1 = h - np.dot(h, s3) * s3
        s1 = s1 / np.linalg.norm(s1)
        s2 = np.cross(s3, s1)
        return cls(point=point, R_WS=np.column_stack([s1, s2, s3]))

    @classmethod
    def from_incline(cls, point: Any, incline: float, heading: float = 0.0) -> PerchTarget:
        """A pad inclined by ``incline`` (rad, 0 floor .. pi/2 wall .. pi ceiling) that faces a
        vehicle flying horizontally along ``heading`` (rad): ``s3 = cos(i) e3 - sin(i) h``,
        ``s1 = sin(i) e3 + cos(i) h`` and ``s2 = e3 x h``, continuous in ``i`` on ``[0, pi]``
        (a floor has ``s1 = h``, a ceiling ``s1 = -h``)."""
        inc = v.finite_float("target.incline", incline)
        if not 0.0 <= inc <= math.pi:
            raise ConfigError("target.incline", f"must be in [0, pi] rad (0 floor, pi ceiling), got {inc}")
        hd = v.finite_float("target.heading", heading)
        h = np.array([math.cos(hd), math.sin(hd), 0.0])
        e3 = np.array([0.0, 0.0, 1.0])
        # The frame turns about s2 = e3 x h with the incline, continuously up to a ceiling
        # (s1 = -h at pi): from_normal's level-pad fallback (s1 = +h) would flip it at pi.
        s3 = math.cos(inc) * e3 - math.sin(inc) * h
        s1 = math.sin(inc) * e3 + math.cos(inc) * h
        return cls(point=point, R_WS=np.column_stack([s1, np.cross(s3, s1), s3]))

    # -- frame axes -----------------------------------------------------------------------
    @property
    def s1(self) -> Array:
        """Up-slope unit tangent (W)."""
        return self.R_WS[:, 0]

    @property
    def s2(self) -> Array:
        """``s3 x s1`` (W)."""
        return self.R_WS[:, 1]

    @property
    def s3(self) -> Array:
        """Outward unit normal (W)."""
        return self.R_WS[:, 2]

    @cached_property
    def incline(self) -> float:
        """Angle between ``s3`` and ``e3`` (rad); computed once (``R_WS`` is read-only)."""
        return float(math.acos(max(-1.0, min(1.0, float(self.R_WS[2, 2])))))

    @cached_property
    def _contact_yaw(self) -> float:
        """Terminal yaw ``psi`` (rad) of :func:`avp.frames.contact_yaw` (13), computed once per
        pad (every QP of a plan and every fraction of a replan step uses it)."""
        return frames.contact_yaw(self.R_WS)[0]

    @cached_property
    def _frame_errors(self) -> dict[float, float]:
        """:meth:`_frame_error` by gravity, filled on use."""
        return {}

    def _frame_error(self, g: float) -> float:
        """:func:`avp.frames.contact_frame_error` of this pad's frame (rad) for gravity ``g``
        (m/s^2), computed once per ``g``: 0 when the contact attitude reproduces ``R_WS``."""
        cache = self._frame_errors
        if g not in cache:
            cache[g] = frames.contact_frame_error(self.R_WS, g)
        return cache[g]

    @cached_property
    def _velocities_W(self) -> dict[tuple[str, ...], Array]:
        """:meth:`_velocity_W` by the exact bits of ``v_S``, filled on use."""
        return {}

    def _velocity_W(self, v_S: tuple[float, float, float]) -> Array:
        """The world velocity (m/s, W) whose S components are ``v_S``: ``solve(R_WS^T, v_S)``,
        not ``R_WS v_S`` (the same for an orthonormal frame, and exactly the per-direction
        conditions ``s_i . v = v_S,i`` for a frame orthonormal only to rounding). Computed once
        per ``v_S``, keyed by its exact bits (``-0.0`` is not ``0.0``); read-only."""
        key = tuple(float(x).hex() for x in v_S)
        cache = self._velocities_W
        v_W = cache.get(key)
        if v_W is None:
            v_W = np.linalg.solve(self.R_WS.T, np.array(v_S, dtype=float))
            v_W.setflags(write=False)
            cache[key] = v_W
        return v_W

    def at(self, time: float) -> PerchTarget:
        """Pose at ``time``; a static target returns itself."""
        return self

    def to_world(self, v_S: Any) -> Array:
        """Vector in S coordinates to W."""
        return self.R_WS @ np.asarray(v_S, dtype=float)

    def to_target_frame(self, v_W: Any) -> Array:
        """Vector in W to S coordinates."""
        return self.R_WS.T @ np.asarray(v_W, dtype=float)
