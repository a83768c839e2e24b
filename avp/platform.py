"""Moving perch pads: a platform motion model and the pad's predicted pose and velocity.

The platform state follows Gao et al., "Adaptive Tracking and Perching for Quadrotor in Dynamic
Scenarios" (IEEE T-RO 2023), eq. (4): position ``rho`` (the pad centre), heading ``theta``,
horizontal speed ``v_h``, vertical speed ``v_v`` and turn rate ``omega``. Two prediction models:

* :attr:`MotionModel.CONSTANT_VELOCITY`: ``rho(t) = rho_0 + v (t - t_0)``, heading fixed
  (``turn_rate`` is ignored);
* :attr:`MotionModel.CTRV` (constant turn rate and velocity, Gao et al.'s model):
  ``theta(t) = theta_0 + omega dt`` and ``d rho / dt = (v_h cos theta, v_h sin theta, v_v)``,
  integrated in closed form.

The pad frame turns with the heading, as in Gao et al.'s ``z_s = R_z(theta) z_s_bar`` (its eq. (7)):
``R_WS(t) = R_z(theta(t) - theta_0) R_WS(t_0)``. A :class:`MovingTarget` *is* a
:class:`~avp.types.PerchTarget` (its ``point`` and ``R_WS`` are the pose at ``time``);
:meth:`MovingTarget.at` returns the target re-anchored at another time. Plan with
:func:`avp.moving.plan_moving`; the static :func:`avp.plan` would treat it as a pad frozen at
its current pose.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from enum import Enum
from typing import Any

import numpy as np

from . import _validate as v
from ._typing import Array
from .errors import ConfigError
from .types import PerchTarget

__all__ = ["MotionModel", "MovingTarget", "rot_z"]



class MotionModel(Enum):
    """How the platform's state is predicted."""

    CONSTANT_VELOCITY = "constant velocity: straight line at the current velocity, heading fixed"
    CTRV = "constant turn rate and velocity (Gao et al. eq. (4))"


def rot_z(angle: float) -> Array:
    """Rotation by ``angle`` (rad) about ``e3``."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


_FIELD_NAMES: dict[type, frozenset[str]] = {}


def _field_names(cls: type) -> frozenset[str]:
    """The dataclass fields of ``cls`` (what :meth:`MovingTarget.at` copies), once per class."""
    names = _FIELD_NAMES.get(cls)
    if names is None:
        names = _FIELD_NAMES[cls] = frozenset(f.name for f in fields(cls))
    return names


def _sinc(x: Array) -> Array:
    """``sin(x) / x`` with its limit 1 at 0 (series below 1e-4, exact to rounding there)."""
    small = np.abs(x) < 1e-4
    safe = np.where(small, 1.0, x)
    return np.where(small, 1.0 - x * x / 6.0, np.sin(safe) / safe)


@v.typed_keywords("target")
@dataclass(frozen=True, eq=False)  # PerchTarget's value equality, over these fields too
class MovingTarget(PerchTarget):
    """A perch pad carried by a moving platform.

    ``point`` and ``R_WS`` are the pad pose at ``time`` (as for a static
    :class:`~avp.types.PerchTarget`); the remaining fields are the platform state (Gao et al.
    eq. (4)) at that time.

    Parameters
    ----------
    heading:
        ``theta`` (rad): direction of horizontal travel, from +x towards +y.
    speed:
        ``v_h`` (m/s) along the heading; negative means reversing.
    turn_rate:
        ``omega`` (rad/s), positive counter-clockwise; ignored by CONSTANT_VELOCITY.
    vertical_speed:
        ``v_v`` (m/s).
    time:
        Time (s) of this state.
    model:
        :class:`MotionModel`.
    """

    heading: float = 0.0
    speed: float = 0.0
    turn_rate: float = 0.0
    vertical_speed: float = 0.0
    time: float = 0.0
    model: MotionModel = MotionModel.CTRV

    def __post_init__(self) -> None:
        super().__post_init__()
        for name, kind in (("heading", "yaw"), ("speed", "velocity"), ("turn_rate", "yaw_rate"),
                           ("vertical_speed", "velocity"), ("time", "time")):
            object.__setattr__(self, name, v.finite_float(f"target.{name}", getattr(self, name)))
            v.within(f"target.{name}", getattr(self, name), kind)
        if not isinstance(self.model, MotionModel):
            raise ConfigError("target.model", f"must be an avp.platform.MotionModel, got {self.model!r}")

    # -- constructors ---------------------------------------------------------------------
    @classmethod
    def on_platform(
        cls,
        point: Any,
        *,
        incline: float = 0.0,
        heading: float = 0.0,
        speed: float = 0.0,
        turn_rate: float = 0.0,
        vertical_speed: float = 0.0,
        time: float = 0.0,
        model: MotionModel = MotionModel.CTRV,
    ) -> MovingTarget:
        """A pad at ``point`` inclined by ``incline`` (rad) that faces backwards along the
        platform's ``heading`` (``s3 = cos(i) e3 - sin(i) h``, the roof for ``incline = 0``, a
        plane in the trunk for ``incline > 0``), so a vehicle following the platform perches on
        it; see :meth:`PerchTarget.from_incline`."""
        pad = PerchTarget.from_incline(point, incline, heading)
        return cls(point=pad.point, R_WS=pad.R_WS, heading=heading, speed=speed, turn_rate=turn_rate,
                   vertical_speed=vertical_speed, time=time, model=model)

    @classmethod
    def from_pad(cls, pad: PerchTarget, **platform: Any) -> MovingTarget:
        """A static ``pad`` carried by a platform with the given state fields."""
        return cls(point=pad.point, R_WS=pad.R_WS, **platform)

    # -- prediction -----------------------------------------------------------------------
    @property
    def omega(self) -> float:
        """Turn rate used by the model (rad/s): 0 for CONSTANT_VELOCITY."""
        return self.turn_rate if self.model is MotionModel.CTRV else 0.0

    @property
    def velocity(self) -> Array:
        """Pad velocity at ``time`` (m/s, W): ``(v_h cos theta, v_h sin theta, v_v)``."""
        return np.array([self.speed * math.cos(self.heading), self.speed * math.sin(self.heading),
                         self.vertical_speed])

    @property
    def acceleration(self) -> Array:
        """Pad acceleration at ``time`` (m/s^2, W): ``v_h omega (-sin theta, cos theta, 0)``."""
        k = self.speed * self.omega
        return np.array([-k * math.sin(self.heading), k * math.cos(self.heading), 0.0])

    @property
    def is_static(self) -> bool:
        """The pad does not move (zero speeds; a turn without speed still turns the pad)."""
        return self.speed == 0.0 and self.vertical_speed == 0.0 and self.omega == 0.0

    def heading_at(self, time: float) -> float:
        """``theta(time)`` (rad), not wrapped."""
        return self.heading + self.omega * (float(time) - self.time)

    def predict(self, times: Any) -> tuple[Array, Array, Array]:
        """Vectorised prediction at ``times`` (s): pad points ``(m, 3)``, headings ``(m,)`` and
        outward normals ``s3`` ``(m, 3)``.

        CTRV in closed form: ``rho(t) = rho_0 + v_h dt sinc(w dt / 2) (cos, sin)(theta_0 + w dt / 2)
        + v_v dt e3`` (the chord of the arc; ``w -> 0`` is the straight line without cancellation).
        """
        t, _, _ = v.finite_times("times", times)
        return self._predict(np.atleast_1d(t) - self.time)

    def _predict(self, dt: Array) -> tuple[Array, Array, Array]:
        """:meth:`predict` at ``dt`` (s) after ``time``."""
        w = self.omega
        half = 0.5 * w * dt
        chord = self.speed * dt * _sinc(half)
        mid = self.heading + half
        points = self.point + np.stack([chord * np.cos(mid), chord * np.sin(mid), self.vertical_speed * dt], axis=-1)
        heading = self.heading + w * dt
        c, s = np.cos(w * dt), np.sin(w * dt)
        n = self.s3
        s3 = np.stack([c * n[0] - s * n[1], s * n[0] + c * n[1], np.full_like(dt, n[2])], axis=-1)
        return points, heading, s3

    def at(self, time: float, after: float = 0.0) -> MovingTarget:
        """The target at ``time + after``: predicted pad pose and platform state (any sign of
        ``time + after - self.time``); the pad frame turns with the heading. The prediction
        runs over ``(time - self.time) + after``, so a plan's pad at contact, ``at(t0,
        duration)``, is not rounded to the clock as ``t0 + duration`` would be."""
        t = v.finite_float("time", time)
        dt = (t - self.time) + v.finite_float("after", after) if after else t - self.time
        points, heading, _ = self._predict(np.array([dt]))
        w_dt = self.omega * dt
        R = rot_z(w_dt) @ self.R_WS if w_dt != 0.0 else self.R_WS
        # Derived from validated fields: skip re-validation (it dominates the cost of at()).
        out = object.__new__(type(self))
        # the fields only: what the pad caches from R_WS (PerchTarget.incline, its contact yaw...)
        # belongs to this pose, not to the turned one
        names = _field_names(type(self))
        out.__dict__.update({k: value for k, value in self.__dict__.items() if k in names})
        point = points[0]
        for arr in (point, R):
            arr.setflags(write=False)
        object.__setattr__(out, "point", point)
        object.__setattr__(out, "R_WS", R)
        object.__setattr__(out, "heading", float(heading[0]))
        object.__setattr__(out, "time", t + after if after else t)
        return out

    def velocity_at(self, time: float) -> Array:
        """Pad velocity at ``time`` (m/s, W)."""
        return self.at(time).velocity

    def static(self) -> PerchTarget:
        """The pad pose at ``time`` as a plain (static) :class:`~avp.types.PerchTarget`."""
        # The fields are validated (read-only) already: skip re-validating the rotation.
        out = object.__new__(PerchTarget)
        object.__setattr__(out, "point", self.point)
        object.__setattr__(out, "R_WS", self.R_WS)
        return out
