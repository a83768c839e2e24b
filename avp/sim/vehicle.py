"""Rigid-body quadrotor dynamics (1) with actuator limits, integrated with RK4.

The model is the paper's (1)::

    p_W' = v_W,   m v_W' = tau R_WB e3 - m g e3,
    R_WB' = R_WB hat(omega_B),   J omega_B' + omega_B x J omega_B = M_B

with the collective thrust ``tau`` (N) and body moment ``M_B`` (N m) held constant over a step
(zero-order hold, as a digital controller does). One :func:`step` is one classical RK4 step on
``(p_W, v_W, R_WB, omega_B)`` with ``R_WB`` integrated as a 3x3 matrix; the result is projected
back onto SO(3) (polar factor). For ``dt <= 2 ms`` (>= 500 Hz, the intended use) the projection
moves ``R_WB`` by ``O(dt^5)`` per step, so the scheme keeps RK4's fourth order (checked in
``tests/test_sim_dynamics.py``).

Default vehicle: 0.5 kg with the inertia of an AscTec-Hummingbird-class quadrotor (the vehicle of
the rotorpy simulator the design notes used): ``J = diag(3.65, 3.68, 7.03) g m^2``. Thrust limits
are the mass-normalised ``0.5 .. 17 m/s^2`` of the planner's defaults (0.25 .. 8.5 N). Moments
are limited per body axis (a box, not a motor mixer): roll/pitch ``0.5 N m`` (an X frame with
0.17 m arms and 2.1 N per rotor gives ``2 * 0.12 m * 2.1 N ~ 0.5 N m``), yaw ``0.1 N m`` (rotor
drag torque).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import ConfigError
from ..frames import GRAVITY
from ._so3 import Array, as_rotation, as_vector, cross, hat, project_so3

__all__ = ["RigidBodyState", "VehicleParams", "step"]

_E3 = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True, eq=False)
class VehicleParams:
    """Physical parameters and actuator limits of the simulated quadrotor.

    Parameters
    ----------
    mass:
        Mass ``m`` (kg).
    inertia:
        Inertia ``J`` about the centre of mass in B (kg m^2): a 3-vector (diagonal) or 3x3.
    thrust_min, thrust_max:
        Collective thrust limits ``tau`` (N); commands are clipped to them.
    moment_max:
        Per-axis limits ``|M_i| <= moment_max[i]`` (N m) in B; ``inf`` means none.
    g:
        Gravity (m/s^2).
    """

    mass: float = 0.5
    inertia: Any = (3.65e-3, 3.68e-3, 7.03e-3)
    thrust_min: float = 0.25
    thrust_max: float = 8.5
    moment_max: Any = (0.5, 0.5, 0.1)
    g: float = GRAVITY
    J: Array = field(init=False, repr=False)
    J_inv: Array = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if not (np.isfinite(self.mass) and self.mass > 0):
            raise ConfigError("params.mass", f"must be a positive number of kg, got {self.mass}")
        J = np.array(self.inertia, dtype=float)
        if J.shape == (3,):
            J = np.diag(J)
        if J.shape != (3, 3) or not np.all(np.isfinite(J)) or not np.allclose(J, J.T):
            raise ConfigError("params.inertia", "expected 3 principal moments or a symmetric 3x3")
        if np.min(np.linalg.eigvalsh(J)) <= 0:
            raise ConfigError("params.inertia", "must be positive definite")
        if not (0.0 <= self.thrust_min < self.thrust_max < np.inf):
            raise ConfigError(
                "params.thrust_min", "need 0 <= thrust_min < thrust_max < inf (N)"
            )
        try:
            mmax = np.broadcast_to(np.array(self.moment_max, dtype=float), (3,)).copy()
        except (TypeError, ValueError):
            mmax = np.full(3, np.nan)
        if np.any(np.isnan(mmax)) or np.any(mmax <= 0):
            raise ConfigError("params.moment_max", "expected 3 positive limits (N m), inf allowed")
        object.__setattr__(self, "moment_max", mmax)
        object.__setattr__(self, "J", J)
        object.__setattr__(self, "J_inv", np.linalg.inv(J))

    @property
    def hover_thrust(self) -> float:
        """Thrust that balances gravity, ``m g`` (N)."""
        return self.mass * self.g

    def clip_thrust(self, thrust: float) -> float:
        """``thrust`` clipped to ``[thrust_min, thrust_max]`` (N)."""
        return float(min(max(thrust, self.thrust_min), self.thrust_max))

    def clip_moment(self, moment_B: Array) -> Array:
        """``moment_B`` clipped per axis to ``+-moment_max`` (N m)."""
        return np.clip(moment_B, -self.moment_max, self.moment_max)


@dataclass(frozen=True, eq=False)
class RigidBodyState:
    """Full state of the rigid body.

    Parameters
    ----------
    p_W:
        Position of the centre of mass in W (m).
    v_W:
        Velocity in W (m/s).
    R_WB:
        Attitude, columns ``b1, b2, b3`` in W.
    omega_B:
        Angular velocity in B (rad/s), ``hat(omega_B) = R_WB^T R_WB'``.
    """

    p_W: Array
    v_W: Array = field(default_factory=lambda: np.zeros(3))
    R_WB: Array = field(default_factory=lambda: np.eye(3))
    omega_B: Array = field(default_factory=lambda: np.zeros(3))

    def __post_init__(self) -> None:
        object.__setattr__(self, "p_W", as_vector("state.p_W", self.p_W))
        object.__setattr__(self, "v_W", as_vector("state.v_W", self.v_W))
        object.__setattr__(self, "R_WB", as_rotation("state.R_WB", self.R_WB))
        object.__setattr__(self, "omega_B", as_vector("state.omega_B", self.omega_B))

    @classmethod
    def _trusted(cls, p_W: Array, v_W: Array, R_WB: Array, omega_B: Array) -> RigidBodyState:
        # Internal fast path: the integrator's outputs are finite and R_WB is projected.
        obj = object.__new__(cls)
        for name, val in (("p_W", p_W), ("v_W", v_W), ("R_WB", R_WB), ("omega_B", omega_B)):
            object.__setattr__(obj, name, val)
        return obj


def _derivative(
    v: Array, R: Array, w: Array, thrust: float, moment: Array, params: VehicleParams
) -> tuple[Array, Array, Array, Array]:
    acc = (thrust / params.mass) * R[:, 2] - params.g * _E3
    R_dot = R @ hat(w)
    w_dot = params.J_inv @ (moment - cross(w, params.J @ w))
    return v, acc, R_dot, w_dot


def step(
    state: RigidBodyState,
    thrust: float,
    moment_B: Array,
    dt: float,
    params: VehicleParams | None = None,
) -> RigidBodyState:
    """Advance the dynamics (1) by ``dt`` seconds with one RK4 step.

    Parameters
    ----------
    state:
        State at the start of the step.
    thrust:
        Collective thrust command ``tau`` (N), clipped to the vehicle's limits.
    moment_B:
        Body moment command ``M`` (N m), clipped per axis.
    dt:
        Step (s); keep it at or below 2 ms.
    params:
        Vehicle; the defaults of :class:`VehicleParams` when omitted.

    Returns
    -------
    RigidBodyState
        The state after ``dt``, with ``R_WB`` projected onto SO(3).
    """
    if params is None:
        params = _DEFAULT_PARAMS
    if not (dt > 0 and np.isfinite(dt)):
        raise ConfigError("dt", f"must be a positive number of seconds, got {dt}")
    tau = params.clip_thrust(float(thrust))
    M = params.clip_moment(np.asarray(moment_B, dtype=float))
    p, v, R, w = state.p_W, state.v_W, state.R_WB, state.omega_B

    k1 = _derivative(v, R, w, tau, M, params)
    h = 0.5 * dt
    k2 = _derivative(v + h * k1[1], R + h * k1[2], w + h * k1[3], tau, M, params)
    k3 = _derivative(v + h * k2[1], R + h * k2[2], w + h * k2[3], tau, M, params)
    k4 = _derivative(v + dt * k3[1], R + dt * k3[2], w + dt * k3[3], tau, M, params)
    c = dt / 6.0
    p_new = p + c * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
    v_new = v + c * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
    R_new = project_so3(R + c * (k1[2] + 2 * k2[2] + 2 * k3[2] + k4[2]))
    w_new = w + c * (k1[3] + 2 * k2[3] + 2 * k3[3] + k4[3])
    return RigidBodyState._trusted(p_new, v_new, R_new, w_new)


_DEFAULT_PARAMS = VehicleParams()
