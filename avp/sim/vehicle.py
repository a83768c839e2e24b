"""Rigid-body quadrotor dynamics (1) with rotor-level actuation, integrated with RK4.

The model is the paper's (1)::

    p_W' = v_W,   m v_W' = tau R_WB e3 - m g e3,
    R_WB' = R_WB hat(omega_B),   J omega_B' + omega_B x J omega_B = M_B

One vehicle. :class:`VehicleParams` *holds* the planner's :class:`avp.config.VehicleLimits`
(mass and collective thrust limits: the numbers the planner certifies) and adds what only the
simulator needs: inertia, arm length, rotor constants and the motor time constant. The per-rotor
thrust limits are the planner's collective limits divided by four, so a plan certified against
``VehicleLimits`` is flown by a vehicle with exactly those limits.

Actuation (each piece can be switched off for ablations):

- **Mixer** (``mixer=True``): the controller's collective thrust ``tau`` and moment ``M_B`` are
  allocated to four rotors of an X frame (rotor ``i`` at ``arm_length (cos th_i, sin th_i, 0)``,
  ``th_i = 45 + 90 i`` deg, spinning alternately, drag torque ``+-drag_ratio * T_i`` about
  ``b3``). Per-rotor thrusts outside ``[T_min, T_max]`` are desaturated as flight stacks do: first
  the yaw moment is dropped, then the collective is shifted (roll/pitch keep priority), then the
  rotors are clipped. ``mixer=False``: ``tau`` is clipped to the collective limits and ``M_B`` to
  the per-axis box :attr:`VehicleParams.moment_max` that the rotors could deliver at hover.
- **Motor lag** (``motor_time_constant > 0``): each rotor speed ``w_i`` (``T_i = k_f w_i^2``)
  follows its command through a first-order lag, integrated exactly over a step with the command
  held; the thrusts of the mid-step speeds are held over the RK4 step. ``0`` makes the rotors
  instantaneous. The lag is the state :attr:`RigidBodyState.rotor_speeds`.

Default vehicle: 0.5 kg, ``J = diag(3.65, 3.68, 7.03) g m^2``, 0.17 m arms, ``k_f = 5.57e-6
N/(rad/s)^2`` and ``k_m = 1.36e-7 N m/(rad/s)^2`` (drag ratio 0.0244 m): the AscTec-Hummingbird
class vehicle of the rotorpy simulator. Motor time constant 20 ms (tens of ms is typical of
small brushless motors with their ESCs). One :func:`step` is one classical RK4 step on
``(p_W, v_W, R_WB, omega_B)``; ``R_WB`` is projected back onto SO(3), which keeps RK4's order
for ``dt <= 2 ms`` (``tests/test_sim_dynamics.py``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .. import _validate as v
from ..config import VehicleLimits
from ..errors import ConfigError
from ..frames import GRAVITY, Array, cross, hat, project_so3

__all__ = ["RigidBodyState", "VehicleParams", "step"]

_E3 = np.array([0.0, 0.0, 1.0])


@v.typed_keywords("vehicle")
@dataclass(frozen=True, eq=False)
class VehicleParams:
    """The simulated quadrotor: the planner's :class:`~avp.config.VehicleLimits` plus physics.

    Parameters
    ----------
    limits:
        The planner's vehicle (mass, collective thrust limits in N). Pass the same object the
        planner uses (:func:`avp.sim.run.simulate` does).
    inertia:
        Inertia ``J`` about the centre of mass in B (kg m^2): a 3-vector (diagonal) or 3x3.
    arm_length:
        Centre-to-rotor distance (m), X frame.
    thrust_coefficient:
        ``k_f`` (N/(rad/s)^2): rotor thrust ``T = k_f w^2``.
    drag_coefficient:
        ``k_m`` (N m/(rad/s)^2): rotor drag torque ``k_m w^2`` about ``b3``.
    motor_time_constant:
        First-order lag of the rotor speeds (s); 0: instantaneous rotors.
    mixer:
        Allocate to four rotors with per-rotor limits (module docstring); False: collective clip
        and a per-axis moment box.
    rotor_idle_fraction:
        A rotor's least thrust (motors at idle) as a fraction of its most, ``thrust_max / 4``.
        The rotors reach down to :attr:`thrust_floor` ``= min(limits.thrust_min, rotor_idle_fraction
        x limits.thrust_max)``: a planner may certify a higher floor than the motors' idle to keep
        authority for feedback (Gao et al. plan at >= 5 N of 17 N), and the vehicle is not limited
        to the planner's choice. 0.05 leaves the default vehicle's floor at the planner's 0.25 N;
        with Gao et al.'s limits the rotors reach 0.85 N instead of 5 N. With the rotors floored at
        the planned 5 N, odometry noise alone left the vehicle 4-5 cm short of a moving plane at
        contact: the plans ride 0.1-0.6 m/s^2 above that floor and feedback could only add thrust.
    g:
        Gravity (m/s^2).
    """

    limits: VehicleLimits = field(default_factory=VehicleLimits)
    inertia: Any = (3.65e-3, 3.68e-3, 7.03e-3)
    arm_length: float = 0.17
    thrust_coefficient: float = 5.57e-6
    drag_coefficient: float = 1.36e-7
    motor_time_constant: float = 0.02
    mixer: bool = True
    rotor_idle_fraction: float = 0.05
    g: float = GRAVITY
    J: Array = field(init=False, repr=False)
    J_inv: Array = field(init=False, repr=False)
    allocation: Array = field(init=False, repr=False)
    allocation_inv: Array = field(init=False, repr=False)

    def __post_init__(self) -> None:
        v.flags("vehicle", self)
        if not isinstance(self.limits, VehicleLimits):
            raise ConfigError("vehicle.limits", f"must be an avp.config.VehicleLimits, got {type(self.limits).__name__}")
        if isinstance(self.inertia, (str, bytes)) or v.holds_booleans(self.inertia):
            raise ConfigError("vehicle.inertia", f"expected 3 principal moments or a symmetric 3x3 (kg m^2), got {self.inertia!r}")
        try:
            J = np.array(self.inertia, dtype=float)
        except (TypeError, ValueError, OverflowError) as exc:
            raise ConfigError("vehicle.inertia", "expected 3 principal moments or a symmetric 3x3 (kg m^2), "
                                                 f"got {self.inertia!r}") from exc
        if J.shape == (3,):
            J = np.diag(J)
        if J.shape != (3, 3) or not np.all(np.isfinite(J)) or not np.allclose(J, J.T):
            raise ConfigError("vehicle.inertia", "expected 3 principal moments or a symmetric 3x3")
        if np.min(np.linalg.eigvalsh(J)) <= 0:
            raise ConfigError("vehicle.inertia", "must be positive definite")
        for name in ("arm_length", "thrust_coefficient", "drag_coefficient"):
            v.positive_float(f"vehicle.{name}", getattr(self, name))
        tau = v.finite_float("vehicle.motor_time_constant", self.motor_time_constant)
        if tau < 0:
            raise ConfigError("vehicle.motor_time_constant", f"must be >= 0 s (0: no lag), got {tau}")
        if not math.isfinite(self.limits.thrust_max):
            raise ConfigError("vehicle.limits", "thrust_max must be finite for a simulated vehicle")
        idle = v.finite_float("vehicle.rotor_idle_fraction", self.rotor_idle_fraction)
        if not 0.0 <= idle < 1.0:
            raise ConfigError("vehicle.rotor_idle_fraction", f"must be in [0, 1) (a fraction of a rotor's maximum), got {idle}")
        theta = np.deg2rad(45.0 + 90.0 * np.arange(4))
        x, y = self.arm_length * np.cos(theta), self.arm_length * np.sin(theta)
        spin = np.array([1.0, -1.0, 1.0, -1.0])
        A = np.vstack([np.ones(4), y, -x, spin * self.drag_ratio])  # [tau, Mx, My, Mz] = A T
        object.__setattr__(self, "J", J)
        object.__setattr__(self, "J_inv", np.linalg.inv(J))
        object.__setattr__(self, "allocation", A)
        object.__setattr__(self, "allocation_inv", np.linalg.inv(A))

    @classmethod
    def ideal(cls, limits: VehicleLimits | None = None, **kw: Any) -> VehicleParams:
        """Instant thrust and moments within a box: no mixer, no motor lag (the old simulator)."""
        return cls(limits=limits if limits is not None else VehicleLimits(), mixer=False,
                   motor_time_constant=0.0, **kw)

    # -- derived ---------------------------------------------------------------------------
    @property
    def mass(self) -> float:
        """Mass (kg), from :attr:`limits`."""
        return float(self.limits.mass)

    @property
    def thrust_min(self) -> float:
        """The planner's certified collective thrust floor (N), from :attr:`limits`; the rotors
        themselves reach down to :attr:`thrust_floor`."""
        return float(self.limits.thrust_min)

    @property
    def thrust_max(self) -> float:
        """Collective thrust ceiling (N), from :attr:`limits`."""
        return float(self.limits.thrust_max)

    @property
    def thrust_floor(self) -> float:
        """Least collective thrust the rotors deliver (N): the planner's floor or the motors' idle,
        whichever is lower (:attr:`rotor_idle_fraction`)."""
        return float(min(self.limits.thrust_min, self.rotor_idle_fraction * self.limits.thrust_max))

    @property
    def rotor_thrust_limits(self) -> tuple[float, float]:
        """Per-rotor thrust range ``(T_min, T_max)`` (N): ``(thrust_floor, thrust_max) / 4``."""
        return self.thrust_floor / 4.0, self.thrust_max / 4.0

    @property
    def drag_ratio(self) -> float:
        """``k_m / k_f`` (m): yaw torque per newton of rotor thrust."""
        return self.drag_coefficient / self.thrust_coefficient

    @property
    def moment_max(self) -> Array:
        """Per-axis moment (N m) the rotors deliver around hover (the ``mixer=False`` box)."""
        t_lo, t_hi = self.rotor_thrust_limits
        d = min(self.hover_thrust / 4.0 - t_lo, t_hi - self.hover_thrust / 4.0)
        lever = self.arm_length / math.sqrt(2.0)
        return np.array([4 * lever * d, 4 * lever * d, 4 * self.drag_ratio * d])

    @property
    def hover_thrust(self) -> float:
        """Thrust that balances gravity, ``m g`` (N)."""
        return self.mass * self.g

    def rotor_speed(self, thrust: Array) -> Array:
        """Rotor speeds (rad/s) giving ``thrust`` (N)."""
        return np.sqrt(np.maximum(thrust, 0.0) / self.thrust_coefficient)

    def clip_thrust(self, thrust: float) -> float:
        """``thrust`` clipped to ``[thrust_floor, thrust_max]`` (N)."""
        return float(min(max(thrust, self.thrust_floor), self.thrust_max))

    def clip_moment(self, moment_B: Array) -> Array:
        """``moment_B`` clipped per axis to ``+-moment_max`` (N m)."""
        mm = self.moment_max
        return np.clip(moment_B, -mm, mm)

    def mix(self, thrust: float, moment_B: Array) -> Array:
        """Per-rotor thrusts (N) for a collective ``thrust`` and ``moment_B``, desaturated
        (yaw dropped, then the collective shifted, then clipped: module docstring)."""
        lo, hi = self.rotor_thrust_limits
        Ainv = self.allocation_inv
        T = Ainv @ np.array([thrust, moment_B[0], moment_B[1], moment_B[2]])
        if np.all((T >= lo) & (T <= hi)):
            return T
        T = Ainv @ np.array([thrust, moment_B[0], moment_B[1], 0.0])
        if np.max(T) - np.min(T) <= hi - lo:
            shift = max(lo - np.min(T), 0.0) - max(np.max(T) - hi, 0.0)
            T = T + shift
        return np.clip(T, lo, hi)

    def wrench(self, rotor_thrust: Array) -> tuple[float, Array]:
        """Collective thrust (N) and body moment (N m) of the rotor thrusts."""
        w = self.allocation @ rotor_thrust
        return float(w[0]), w[1:]


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
    rotor_speeds:
        Rotor speeds (rad/s) for the motor lag; ``None``: at hover.
    """

    p_W: Array
    v_W: Array = field(default_factory=lambda: np.zeros(3))
    R_WB: Array = field(default_factory=lambda: np.eye(3))
    omega_B: Array = field(default_factory=lambda: np.zeros(3))
    rotor_speeds: Array | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "p_W", v.vector("state.p_W", self.p_W))
        object.__setattr__(self, "v_W", v.vector("state.v_W", self.v_W))
        object.__setattr__(self, "R_WB", np.array(v.rotation("state.R_WB", self.R_WB)))
        object.__setattr__(self, "omega_B", v.vector("state.omega_B", self.omega_B))
        if self.rotor_speeds is not None:
            object.__setattr__(self, "rotor_speeds", v.vector("state.rotor_speeds", self.rotor_speeds, 4))

    @classmethod
    def _trusted(cls, p_W: Array, v_W: Array, R_WB: Array, omega_B: Array,
                 rotor_speeds: Array | None = None) -> RigidBodyState:
        # Internal fast path: the integrator's outputs are finite and R_WB is projected.
        obj = object.__new__(cls)
        for name, val in (("p_W", p_W), ("v_W", v_W), ("R_WB", R_WB), ("omega_B", omega_B),
                          ("rotor_speeds", rotor_speeds)):
            object.__setattr__(obj, name, val)
        return obj


def _derivative(
    v: Array, R: Array, w: Array, thrust: float, moment: Array, params: VehicleParams
) -> tuple[Array, Array, Array, Array]:
    acc = (thrust / params.mass) * R[:, 2] - params.g * _E3
    R_dot = R @ hat(w)
    w_dot = params.J_inv @ (moment - cross(w, params.J @ w))
    return v, acc, R_dot, w_dot


def _actuate(
    state: RigidBodyState, thrust: float, moment_B: Array, dt: float, params: VehicleParams
) -> tuple[float, Array, Array | None]:
    """Thrust and moment held over the step, and the rotor speeds at its end."""
    if not params.mixer:
        return params.clip_thrust(float(thrust)), params.clip_moment(np.asarray(moment_B, dtype=float)), None
    T_cmd = params.mix(float(thrust), np.asarray(moment_B, dtype=float))
    tau_m = params.motor_time_constant
    if tau_m <= 0.0:
        tau, M = params.wrench(T_cmd)
        return tau, M, None
    w_cmd = params.rotor_speed(T_cmd)
    w0 = state.rotor_speeds
    if w0 is None:
        w0 = np.full(4, float(params.rotor_speed(np.array(params.hover_thrust / 4.0))))
    w_mid = w_cmd + (w0 - w_cmd) * math.exp(-0.5 * dt / tau_m)
    w_end = w_cmd + (w0 - w_cmd) * math.exp(-dt / tau_m)
    tau, M = params.wrench(params.thrust_coefficient * w_mid**2)
    return tau, M, w_end


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
        Collective thrust command ``tau`` (N).
    moment_B:
        Body moment command ``M`` (N m).
    dt:
        Step (s); keep it at or below 2 ms.
    params:
        Vehicle; the defaults of :class:`VehicleParams` when omitted. Its mixer and motor lag
        turn the commands into the thrust and moment that act (module docstring).

    Returns
    -------
    RigidBodyState
        The state after ``dt``, with ``R_WB`` projected onto SO(3).
    """
    if params is None:
        params = _DEFAULT_PARAMS
    if not (dt > 0 and np.isfinite(dt)):
        raise ConfigError("dt", f"must be a positive number of seconds, got {dt}")
    tau, M, rotor = _actuate(state, thrust, moment_B, dt, params)
    p, v_, R, w = state.p_W, state.v_W, state.R_WB, state.omega_B

    k1 = _derivative(v_, R, w, tau, M, params)
    h = 0.5 * dt
    k2 = _derivative(v_ + h * k1[1], R + h * k1[2], w + h * k1[3], tau, M, params)
    k3 = _derivative(v_ + h * k2[1], R + h * k2[2], w + h * k2[3], tau, M, params)
    k4 = _derivative(v_ + dt * k3[1], R + dt * k3[2], w + dt * k3[3], tau, M, params)
    c = dt / 6.0
    p_new = p + c * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
    v_new = v_ + c * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
    R_new = project_so3(R + c * (k1[2] + 2 * k2[2] + 2 * k3[2] + k4[2]))
    w_new = w + c * (k1[3] + 2 * k2[3] + 2 * k3[3] + k4[3])
    return RigidBodyState._trusted(p_new, v_new, R_new, w_new, rotor)


_DEFAULT_PARAMS = VehicleParams()
