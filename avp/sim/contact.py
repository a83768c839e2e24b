"""Contact with the perch pad and the success criterion of a perch.

The pad is a finite square (or disc) of half-size ``half_size`` centred at ``p_W`` in the plane
through it with normal ``s3`` (``R_WS = [s1 s2 s3]``, ``s3`` pointing to the side the vehicle
arrives from). Contact happens when the centre of mass reaches the pad plane, i.e. the signed
distance ``(p_W - c) . s3`` goes from positive to ``<= 0`` between two simulation steps; the
crossing is located by linear interpolation inside the step (steps are <= 2 ms).

Reported at contact: the point in S coordinates, the angle between ``b3`` and ``s3`` (at contact
the paper requires ``b3 = s3``, (12)), the normal speed ``-v . s3`` (positive into the pad) and
the tangential velocity ``(v . s1, v . s2)``.

Two judgements, our choice (the paper gives no numbers):

- :class:`SuccessCriteria` judges a touch, when there is one (:attr:`Contact.success`): the
  point is inside the pad, the attitude error is at most 15 deg, the normal speed is in
  ``[0.05, 1.0] m/s`` (the plan asks for 0.3 m/s: enough to engage Velcro, slow enough not to
  bounce) and the tangential speed is at most 3 m/s (the plan slides 2 m/s down the slope).
- :class:`PerchCriteria` judges the pose at the plan's contact time (:func:`judge_perch`); it is
  the simulator's outcome (``SimResult.outcome``, the success rates of ``docs/simulation.md``).
  Its plane tolerance (3 cm) is on either side: a vehicle that stops up to 3 cm short of the
  plane counts as perched without touching it (``SimResult.contact`` is then ``None``), as a
  gripper or landing gear reaching 3 cm beyond the centre of mass would touch.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from .. import _validate as v
from ..errors import ConfigError
from ..frames import Array, project_so3
from .vehicle import RigidBodyState

__all__ = ["GROUND", "Contact", "PerchCriteria", "PerchOutcome", "PerchPad", "SuccessCriteria", "detect_contact",
           "ground_contact", "judge_perch"]

GROUND = "ground"
"""The failure a :class:`Contact` with the ground carries (:func:`ground_contact`)."""


@dataclass(frozen=True, eq=False)
class PerchPad:
    """A finite pad: centre ``p_W`` (m), rotation ``R_WS``, half-size (m) and shape."""

    p_W: Any
    R_WS: Any
    half_size: float = 0.15
    shape: Literal["square", "disc"] = "square"

    def __post_init__(self) -> None:
        object.__setattr__(self, "p_W", v.vector("pad.p_W", self.p_W))
        object.__setattr__(self, "R_WS", np.array(v.rotation("pad.R_WS", self.R_WS)))
        object.__setattr__(self, "half_size", v.positive_float("pad.half_size", self.half_size))
        if self.shape not in ("square", "disc"):
            raise ConfigError("pad.shape", f"expected 'square' or 'disc', got {self.shape!r}")

    def signed_distance(self, p_W: Array) -> float:
        """Distance (m) of ``p_W`` from the pad plane along ``s3`` (> 0 on the approach side)."""
        return float((np.asarray(p_W) - self.p_W) @ self.R_WS[:, 2])

    def contains(self, p_S: Array) -> bool:
        """Whether the in-plane coordinates ``p_S[:2]`` lie on the pad."""
        if self.shape == "square":
            return bool(max(abs(p_S[0]), abs(p_S[1])) <= self.half_size)
        return bool(np.hypot(p_S[0], p_S[1]) <= self.half_size)


@v.typed_keywords("criteria")
@dataclass(frozen=True)
class SuccessCriteria:
    """Thresholds of a successful touch (module docstring): angles in rad, speeds in m/s.

    ``max_attitude_error`` is in ``(0, pi]`` (the angle between ``b3`` and ``s3``);
    ``0 <= normal_speed_min < normal_speed_max``; ``normal_speed_max`` and
    ``max_tangential_speed`` are positive, ``inf`` for no limit.
    """

    max_attitude_error: float = float(np.deg2rad(15.0))
    normal_speed_min: float = 0.05
    normal_speed_max: float = 1.0
    max_tangential_speed: float = 3.0

    def __post_init__(self) -> None:
        att = v.positive_float("criteria.max_attitude_error", self.max_attitude_error)
        if att > math.pi:
            raise ConfigError("criteria.max_attitude_error", f"must be in (0, pi] rad (the angle between b3 and s3), "
                                                             f"got {att}")
        lo = v.nonnegative_float("criteria.normal_speed_min", self.normal_speed_min)
        hi = v.positive_float("criteria.normal_speed_max", self.normal_speed_max, allow_inf=True)
        if lo >= hi:
            raise ConfigError("criteria.normal_speed_min", f"({lo} m/s) must be below criteria.normal_speed_max "
                                                           f"({hi} m/s)")
        tangential = v.positive_float("criteria.max_tangential_speed", self.max_tangential_speed, allow_inf=True)
        for name, val in (("max_attitude_error", att), ("normal_speed_min", lo), ("normal_speed_max", hi),
                          ("max_tangential_speed", tangential)):
            object.__setattr__(self, name, val)


@dataclass(frozen=True, eq=False)
class Contact:
    """The vehicle reaching the pad plane.

    Attributes
    ----------
    t:
        Time of the crossing (s).
    p_S:
        Contact point in S coordinates (m); ``p_S[2]`` is 0 up to rounding.
    p_W, v_W, R_WB:
        Interpolated vehicle state at the crossing.
    attitude_error:
        Angle between ``b3`` and ``s3`` (rad).
    normal_speed:
        ``-v . s3`` (m/s), positive into the pad.
    v_tangential_S:
        ``(v . s1, v . s2)`` (m/s).
    inside:
        Whether the point lies on the pad.
    failures:
        Names of the violated criteria (empty on success).
    """

    t: float
    p_S: Array
    p_W: Array
    v_W: Array
    R_WB: Array
    attitude_error: float
    normal_speed: float
    v_tangential_S: Array
    inside: bool
    failures: tuple[str, ...] = field(default=())

    @property
    def success(self) -> bool:
        """True when every success criterion holds."""
        return not self.failures


def _crossing(prev: RigidBodyState, new: RigidBodyState, d0: float, d1: float, t_prev: float,
              t_new: float) -> tuple[float, Array, Array, Array] | None:
    """Time, position, velocity and attitude where a signed distance going from ``d0 > 0`` to
    ``d1 <= 0`` over the step crosses zero (linear interpolation), or None without a crossing."""
    if not (d0 > 0.0 >= d1):
        return None
    lam = d0 / (d0 - d1)
    p_W = prev.p_W + lam * (new.p_W - prev.p_W)
    v_W = prev.v_W + lam * (new.v_W - prev.v_W)
    R_WB = project_so3(prev.R_WB + lam * (new.R_WB - prev.R_WB))
    return float(t_prev + lam * (t_new - t_prev)), p_W, v_W, R_WB


def ground_contact(prev: RigidBodyState, new: RigidBodyState, t_prev: float, t_new: float,
                   ground_z: float) -> Contact | None:
    """The crash if the centre of mass went below the ground ``z = ground_z`` between ``prev``
    and ``new``: a :class:`Contact` with the ground plane (``S = W`` shifted to the ground,
    ``inside`` False) whose only failure is :data:`GROUND`."""
    crossing = _crossing(prev, new, float(prev.p_W[2]) - ground_z, float(new.p_W[2]) - ground_z, t_prev, t_new)
    if crossing is None:
        return None
    t, p_W, v_W, R_WB = crossing
    return Contact(
        t=t,
        p_S=np.array([p_W[0], p_W[1], 0.0]),
        p_W=p_W,
        v_W=v_W,
        R_WB=R_WB,
        attitude_error=float(np.arccos(np.clip(R_WB[2, 2], -1.0, 1.0))),
        normal_speed=float(-v_W[2]),
        v_tangential_S=v_W[:2].copy(),
        inside=False,
        failures=(GROUND,),
    )


def detect_contact(
    prev: RigidBodyState,
    new: RigidBodyState,
    pad: PerchPad,
    t_prev: float,
    t_new: float,
    criteria: SuccessCriteria = SuccessCriteria(),
) -> Contact | None:
    """The contact if the centre of mass crossed the pad plane between ``prev`` and ``new``.

    Returns None unless the signed distance goes from ``> 0`` to ``<= 0`` in this step.
    """
    crossing = _crossing(prev, new, pad.signed_distance(prev.p_W), pad.signed_distance(new.p_W), t_prev, t_new)
    if crossing is None:
        return None
    t, p_W, v_W, R_WB = crossing
    R_WS = pad.R_WS
    p_S = R_WS.T @ (p_W - pad.p_W)
    v_S = R_WS.T @ v_W
    att = float(np.arccos(np.clip(R_WB[:, 2] @ R_WS[:, 2], -1.0, 1.0)))
    inside = pad.contains(p_S)
    v_n = float(-v_S[2])
    v_t = v_S[:2].copy()
    failures = []
    if not inside:
        failures.append("outside_pad")
    if att > criteria.max_attitude_error:
        failures.append("attitude")
    if not criteria.normal_speed_min <= v_n <= criteria.normal_speed_max:
        failures.append("normal_speed")
    if float(np.hypot(v_t[0], v_t[1])) > criteria.max_tangential_speed:
        failures.append("tangential_speed")
    return Contact(
        t=t,
        p_S=p_S,
        p_W=p_W,
        v_W=v_W,
        R_WB=R_WB,
        attitude_error=att,
        normal_speed=v_n,
        v_tangential_S=v_t,
        inside=inside,
        failures=tuple(failures),
    )


@v.typed_keywords("perch_criteria")
@dataclass(frozen=True)
class PerchCriteria:
    """Success of a perch judged at the plan's contact time (the evaluation's definition).

    At ``t_eval`` = the final committed plan's contact time ``t_f`` (or the moment the centre of
    mass reaches the pad plane, if that comes first, since the vehicle cannot pass the wall):

    - ``|signed distance to the pad plane| <= plane_tolerance`` (m),
    - in-plane distance from the pad centre ``< center_tolerance`` (m),
    - angle between ``b3`` and ``s3`` ``<= attitude_tolerance`` (rad).

    The tolerances are positive and finite.
    """

    plane_tolerance: float = 0.03
    center_tolerance: float = 0.10
    attitude_tolerance: float = float(np.deg2rad(10.0))

    def __post_init__(self) -> None:
        for name in ("plane_tolerance", "center_tolerance", "attitude_tolerance"):
            object.__setattr__(self, name, v.positive_float(f"perch_criteria.{name}", getattr(self, name)))


@dataclass(frozen=True, eq=False, kw_only=True)
class PerchOutcome:
    """The vehicle at ``t`` judged against :class:`PerchCriteria`.

    ``error_S`` is the position error in the true pad frame ``(s1, s2, normal)`` (m);
    ``attitude_error`` the angle between ``b3`` and ``s3`` (rad).
    """

    t: float
    error_S: Array
    attitude_error: float
    failures: tuple[str, ...]

    @property
    def success(self) -> bool:
        return not self.failures


def judge_perch(t: float, p_W: Array, R_WB: Array, pad: PerchPad,
                criteria: PerchCriteria = PerchCriteria()) -> PerchOutcome:
    """:class:`PerchOutcome` of the pose ``(p_W, R_WB)`` at time ``t`` for ``pad``."""
    e = pad.R_WS.T @ (np.asarray(p_W, dtype=float) - pad.p_W)
    att = float(np.arccos(np.clip(np.asarray(R_WB)[:, 2] @ pad.R_WS[:, 2], -1.0, 1.0)))
    failures = []
    if abs(float(e[2])) > criteria.plane_tolerance:
        failures.append("plane")
    if float(np.hypot(e[0], e[1])) >= criteria.center_tolerance:
        failures.append("center")
    if att > criteria.attitude_tolerance:
        failures.append("attitude")
    return PerchOutcome(t=float(t), error_S=e, attitude_error=att, failures=tuple(failures))
