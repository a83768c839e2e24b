"""Geometric SE(3) tracking controller (2) (Lee, Leok, McClamroch 2010) with flatness feed-forward.

For a flat-output reference (position ``x_d`` and derivatives up to snap, yaw and two of its
derivatives) the controller computes::

    f_W   = m (-k_x e_x - k_v e_v + g e3 + a_d)                      force command in W
    tau   = f_W . R_WB e3 (+ thrust_lead)                            (2), then clipped to the limits
    R_C   = attitude(f_W / m - g e3, yaw)                            (11), (13)
    e_R   = 1/2 vee(R_C^T R - R^T R_C),   e_W = omega_B - R^T R_C Omega_C
    M     = J(-k_R e_R - k_W e_W) + omega x J omega
            - J (hat(omega) R^T R_C Omega_C - R^T R_C Omega_C')       (2)

The gains are normalised by the mass and the inertia (``K_x = m k_x``, ``K_R = J k_R``), so one
set fits any vehicle; the defaults place the translational loop near 5 rad/s and the attitude
loop near 20 rad/s, both with damping ~0.9. (The paper prints ``hat(Omega_C)`` in the last term
of (2); Lee et al.'s controller, which (2) cites, has the angular acceleration ``Omega_C'``.)

Feed-forward: ``Omega_C`` is the body rate of the reference from its jerk, (22) plus the yaw
term, via :func:`avp.frames.body_rates`. ``Omega_C'`` is the time derivative of that map along
the reference: a central difference of ``body_rates`` on the curve
``h -> (a + h j + h^2/2 s, j + h s, psi + h psi' + h^2/2 psi'', psi' + h psi'')``, whose
derivative at ``h = 0`` is exactly ``Omega'`` (it only needs the reference up to snap);
``h = 1e-4 s`` makes the truncation error ``O(h^2)`` negligible. Without this feed-forward the
attitude lags the reference by roughly ``(k_W / k_R) |Omega|`` (the design notes measured
12-50 deg at contact on perching plans). On a vehicle with rotor drag (rotorpy's,
:mod:`~avp.sim.backend`) ``ControllerGains.rotor_drag`` adds the drag at the reference velocity
to the commanded acceleration (:func:`drag_acceleration`).

Rotor lag. With ``ControllerGains.lag_feedforward`` and a vehicle whose rotors lag
(``VehicleParams.motor_time_constant = tau_m > 0`` with the mixer: rotor speeds through a
first-order lag) the collective thrust is led by the reference's thrust rate,
``tau + tau_m m (j_d . R_WB e3)`` (:func:`thrust_lead`; ``m j_d . b3`` is the rate of
``m |a_d + g e3|`` along the reference). For small changes a first-order lag on the rotor speeds
(``T = k_f w^2``) acts as one on the thrust, ``T' = (T_cmd - T) / tau_m``, so commanding
``T + tau_m T'`` delivers the reference's thrust up to the rotors' limits (the neglected command
term ``tau_m^2 T'^2 / (4 T)`` is about 1 % of the lead on a wall perch). The moments are not led. Without the lead, a
20 ms lag left the vehicle 1.2 cm above the reference in the final pitch-up on the wall at
4.5 m (avp's model, perfect estimate; 0.06 cm with it) and lost perches on rotorpy
(docs/simulation.md).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from .. import _validate as v
from ..errors import ConfigError
from ..frames import Array, attitude, body_rates, cross, hat, vee
from .vehicle import RigidBodyState, VehicleParams

__all__ = [
    "ControlOutput",
    "ControllerGains",
    "FlatReference",
    "angular_acceleration",
    "control",
    "drag_acceleration",
    "planar_drag",
    "thrust_lead",
]

logger = logging.getLogger(__name__)

FD_STEP = 1e-4
"""Step ``h`` (s) of the central difference that gives the angular-acceleration feed-forward."""


class FlatReferenceLike(Protocol):
    """Anything with the fields of :class:`FlatReference` (e.g. a one-time ``FlatOutput``)."""

    position: Any
    velocity: Any
    acceleration: Any
    jerk: Any
    snap: Any
    yaw: Any
    yaw_rate: Any
    yaw_acceleration: Any


@dataclass(frozen=True, eq=False)
class FlatReference:
    """Flat outputs (3) and their derivatives at one time, in W (SI units, yaw in rad)."""

    position: Array
    velocity: Array
    acceleration: Array
    jerk: Array
    snap: Array
    yaw: float = 0.0
    yaw_rate: float = 0.0
    yaw_acceleration: float = 0.0

    def __post_init__(self) -> None:
        for name in ("position", "velocity", "acceleration", "jerk", "snap"):
            object.__setattr__(self, name, v.vector(f"reference.{name}", getattr(self, name)))
        for name in ("yaw", "yaw_rate", "yaw_acceleration"):
            object.__setattr__(self, name, float(getattr(self, name)))

    @classmethod
    def hover(cls, position: Any, yaw: float = 0.0) -> FlatReference:
        """At rest at ``position`` (m) with heading ``yaw`` (rad)."""
        z = np.zeros(3)
        return cls(position, z, z, z, z, yaw, 0.0, 0.0)


@v.typed_keywords("gains")
@dataclass(frozen=True)
class ControllerGains:
    """Normalised gains of (2): ``K_x = m k_x``, ``K_v = m k_v``, ``K_R = J k_R``, ``K_W = J k_W``.

    Each is a scalar or a 3-vector (diagonal). Units: ``k_x`` 1/s^2, ``k_v`` 1/s, ``k_R`` 1/s^2,
    ``k_omega`` 1/s. ``feedforward`` switches ``Omega_C`` and ``Omega_C'`` (set both to zero
    when False, for ablations). ``rotor_drag``: the per-rotor drag coefficients ``(k_d, k_d,
    k_z)`` (N per rad/s per m/s) fed forward by :func:`drag_acceleration` (a calibrated drag
    model, as a flight stack would have), or ``None``: :func:`control` feeds no drag forward and
    :func:`avp.sim.run.simulate` uses its back-end's drag model (none for avp's model (1),
    rotorpy's for rotorpy: :func:`avp.sim.backend.rotorpy_gains`); ``(0, 0, 0)`` switches the
    feed-forward off everywhere. ``lag_feedforward``: lead the collective thrust by the rotors'
    lag (:func:`thrust_lead`, module docstring); False: the controller without the lead.
    """

    k_x: Any = 25.0
    k_v: Any = 9.0
    k_R: Any = 400.0
    k_omega: Any = 36.0
    feedforward: bool = True
    rotor_drag: Any = None
    lag_feedforward: bool = True

    def __post_init__(self) -> None:
        v.flags("gains", self)
        for name in ("k_x", "k_v", "k_R", "k_omega"):
            object.__setattr__(self, name, _gain(f"gains.{name}", getattr(self, name)))
        if self.rotor_drag is not None:
            k = v.frozen_array("gains.rotor_drag", self.rotor_drag, (3,))
            if np.any(k < 0.0):
                raise ConfigError("gains.rotor_drag", f"drag coefficients are >= 0 (N per rad/s per m/s), got {k.tolist()}")
            object.__setattr__(self, "rotor_drag", tuple(float(x) for x in k))


def _gain(field: str, value: Any) -> float | tuple[float, float, float]:
    """A positive finite gain: a scalar, or a 3-vector (a diagonal) as a tuple."""
    if isinstance(value, (int, float, np.floating, np.integer)) and not isinstance(value, (bool, np.bool_)):
        return v.positive_float(field, value)
    try:
        k = v.frozen_array(field, value, (3,))
    except ConfigError as exc:
        raise ConfigError(field, f"expected a positive gain or three (a diagonal), got {value!r}") from exc
    if not np.all(k > 0.0):
        raise ConfigError(field, f"gains are > 0, got {k.tolist()}")
    return (float(k[0]), float(k[1]), float(k[2]))


@dataclass(frozen=True, eq=False)
class ControlOutput:
    """One controller evaluation: commands (already within the vehicle's limits) and set-points."""

    thrust: float
    moment_B: Array
    R_WB_des: Array
    omega_B_des: Array
    alpha_B_des: Array


def angular_acceleration(
    ref: FlatReferenceLike, g: float, h: float = FD_STEP
) -> tuple[Array, Array]:
    """Body rate ``Omega_C`` (22) and angular acceleration ``Omega_C'`` of the reference.

    Returns ``(Omega_C, Omega_C')`` in rad/s and rad/s^2 (body frame of the reference attitude).
    ``Omega_C'`` is a central difference along the flat-output Taylor curve (module docstring).
    """
    a, j, s = (np.asarray(x, dtype=float) for x in (ref.acceleration, ref.jerk, ref.snap))
    psi, dpsi, ddpsi = float(ref.yaw), float(ref.yaw_rate), float(ref.yaw_acceleration)
    hs = np.array([-h, 0.0, h])
    acc = a + hs[:, None] * j + 0.5 * hs[:, None] ** 2 * s
    jerk = j + hs[:, None] * s
    yaw = psi + hs * dpsi + 0.5 * hs**2 * ddpsi
    yaw_rate = dpsi + hs * ddpsi
    with np.errstate(divide="ignore", invalid="ignore"):  # singular references give NaN
        W = body_rates(acc, jerk, yaw, yaw_rate, g)
    return W[1], (W[2] - W[0]) / (2.0 * h)


def drag_acceleration(R: Array, v_W: Array, ref: FlatReferenceLike, params: VehicleParams, rotor_drag: Any) -> Array:
    """Acceleration (m/s^2, W) that cancels linear rotor drag at velocity ``v_W`` (Faessler,
    Franchi, Scaramuzza, "Differential Flatness of Quadrotor Dynamics Subject to Rotor Drag"):
    ``R D R^T v_W`` with ``D = diag(rotor_drag) * sum_i w_i / m``, the rotor speeds ``w_i`` of
    the reference's thrust ``m |a + g e3|`` shared by four rotors (``T = k_f w^2``).
    ``rotor_drag``: per-rotor drag coefficients along ``b1, b2, b3`` (N per rad/s per m/s;
    rotorpy's ``k_d, k_d, k_z``)."""
    a_ref = np.asarray(ref.acceleration, dtype=float) + np.array([0.0, 0.0, params.g])
    D = np.asarray(rotor_drag, dtype=float) * _rotor_speed_sum(params, float(np.linalg.norm(a_ref))) / params.mass
    return R @ (D * (R.T @ v_W))


def planar_drag(params: VehicleParams, rotor_drag: Any, accel: float) -> float:
    """The planner's mass-normalised rotor drag ``d`` (1/s, :class:`avp.VehicleLimits`
    ``rotor_drag``) of the drag model :func:`drag_acceleration` feeds forward, at the
    mass-normalised thrust ``accel`` (m/s^2): ``rotor_drag[0] * sum_i w_i / m``, the drag in the
    rotor plane (``b1``; ``b2`` must match). At a perch's contact thrust this makes the
    planner's contact condition (thrust along the normal) the controller's."""
    k = np.asarray(rotor_drag, dtype=float)
    if k.shape != (3,) or k[0] != k[1]:
        raise ConfigError("gains.rotor_drag", f"needs equal b1 and b2 coefficients for a planar drag, got {rotor_drag}")
    return float(k[0] * _rotor_speed_sum(params, float(accel)) / params.mass)


def thrust_lead(R: Array, ref: FlatReferenceLike, params: VehicleParams) -> float:
    """Thrust (N) that leads the collective by the rotors' first-order lag (module docstring):
    ``tau_m m (j_d . R e3)`` with ``tau_m = params.motor_time_constant``. 0 where
    :class:`VehicleParams` has no lag: ``tau_m = 0``, or ``mixer=False`` (avp's model then
    clips the collective without a rotor lag; rotorpy's ``cmd_ctbm`` lags its rotors all the
    same, so with ``mixer=False`` rotorpy flies unled)."""
    tau_m = params.motor_time_constant
    if tau_m <= 0.0 or not params.mixer:
        return 0.0
    return float(tau_m * params.mass * (np.asarray(ref.jerk, dtype=float) @ R[:, 2]))


def _rotor_speed_sum(params: VehicleParams, accel: float) -> float:
    """``sum_i w_i`` (rad/s) of four rotors sharing the thrust ``m accel`` (clipped to the
    vehicle's range), ``T_i = k_f w_i^2``."""
    thrust = params.clip_thrust(params.mass * accel)
    return 4.0 * math.sqrt(thrust / 4.0 / params.thrust_coefficient)


def control(
    state: RigidBodyState,
    ref: FlatReferenceLike,
    params: VehicleParams | None = None,
    gains: ControllerGains = ControllerGains(),
) -> ControlOutput:
    """Thrust and moment of the geometric controller (2) tracking ``ref`` from ``state``.

    Parameters
    ----------
    state:
        The state the controller believes (true state, or odometry with noise).
    ref:
        Flat-output reference at the current time.
    params:
        Vehicle (mass, inertia, limits); :class:`VehicleParams` defaults when omitted.
    gains:
        Normalised gains and the feed-forward switch.

    Returns
    -------
    ControlOutput
        ``thrust`` (N) and ``moment_B`` (N m) clipped to the limits, with the desired attitude
        ``R_WB_des`` (13), rate ``omega_B_des`` (22) and angular acceleration ``alpha_B_des``.
    """
    if params is None:
        params = _DEFAULT_PARAMS
    m, g, J = params.mass, params.g, params.J
    R, w = state.R_WB, state.omega_B
    e_x = state.p_W - np.asarray(ref.position, dtype=float)
    e_v = state.v_W - np.asarray(ref.velocity, dtype=float)
    k_x, k_v = np.asarray(gains.k_x), np.asarray(gains.k_v)
    a_cmd = -k_x * e_x - k_v * e_v + np.asarray(ref.acceleration, dtype=float)
    if gains.rotor_drag is not None:
        a_cmd = a_cmd + drag_acceleration(R, np.asarray(ref.velocity, dtype=float), ref, params, gains.rotor_drag)
    f_W = m * (a_cmd + np.array([0.0, 0.0, g]))
    thrust = float(f_W @ R[:, 2])
    if gains.lag_feedforward:
        thrust += thrust_lead(R, ref, params)
    thrust = params.clip_thrust(thrust)

    with np.errstate(divide="ignore", invalid="ignore"):
        R_C = attitude(a_cmd, float(ref.yaw), g)
    if not np.all(np.isfinite(R_C)):
        # Free fall commanded or roll at +-90 deg: the construction (13) is singular; hold attitude.
        logger.debug("desired attitude singular (thrust %.3g N); holding the current one", thrust)
        R_C = R
    if gains.feedforward:
        W_C, dW_C = angular_acceleration(ref, g)
        if not (np.all(np.isfinite(W_C)) and np.all(np.isfinite(dW_C))):
            W_C, dW_C = np.zeros(3), np.zeros(3)
    else:
        W_C, dW_C = np.zeros(3), np.zeros(3)

    RtRc = R.T @ R_C
    e_R = 0.5 * vee(R_C.T @ R - RtRc)
    e_W = w - RtRc @ W_C
    moment = (
        J @ (-np.asarray(gains.k_R) * e_R - np.asarray(gains.k_omega) * e_W)
        + cross(w, J @ w)
        - J @ (hat(w) @ RtRc @ W_C - RtRc @ dW_C)
    )
    if not params.mixer:  # with a mixer the rotors' limits act in VehicleParams.mix
        moment = params.clip_moment(moment)
    return ControlOutput(thrust, moment, R_C, W_C, dW_C)


_DEFAULT_PARAMS = VehicleParams()
