"""Simulator back-ends: which rigid-body model integrates the vehicle between control steps.

:func:`~avp.sim.run.simulate` runs one closed loop (hover and detect, first plan, 30 Hz
:meth:`~avp.replan.Replanner.step`, odometry, camera, target filter, contact and success
judging) for every back-end; only the *plant* differs, the function that advances the true
state over one control step with the controller's command held. The controller is avp's
geometric SE(3) controller (2) with body-rate (22) and angular-acceleration feed-forward from the
flatness map (:func:`avp.sim.controller.control`) on both.

- :attr:`Backend.AVP` (default): :func:`avp.sim.vehicle.step`, the paper's model (1) with RK4,
  avp's rotor mixer and first-order motor lag.
- :attr:`Backend.ROTORPY`: rotorpy's ``Multirotor`` (``pip install "avp[rotorpy]"``; rotorpy >= 3.0),
  an independent simulator: its own quaternion dynamics integrated by ``scipy``'s RK45, its own
  first-order rotor-speed dynamics and its aerodynamics (parasitic frame drag, rotor drag
  ("H-force"), induced inflow and translational lift), which avp's planner and model (1) do
  not have. Its parameters are derived from the scenario's :class:`~avp.sim.vehicle.VehicleParams`
  by :func:`rotorpy_params`, so it flies the mass and thrust limits the planner certified:
  mass, inertia, the X-frame rotor positions and spin directions in avp's rotor order (rotorpy's
  allocation matrix is then avp's), ``k_eta = thrust_coefficient``, ``k_m = drag_coefficient``,
  ``tau_m = motor_time_constant`` and rotor speed limits ``sqrt(T_lim / 4 / k_eta)`` from the
  collective thrust limits; the aerodynamic coefficients are rotorpy's AscTec-Hummingbird ones
  (the vehicle avp's defaults also describe), :data:`HUMMINGBIRD_AERO`. With those set to zero
  rotorpy and avp's model agree to micrometres over a whole perch (``tests/test_sim_rotorpy.py``);
  with them, the controller needs rotor drag fed forward (:func:`rotorpy_gains`) to reach the
  pad plane on time.

  Control input: with ``VehicleParams.mixer`` the controller's thrust and moment go through
  avp's desaturating mixer (:meth:`~avp.sim.vehicle.VehicleParams.mix`, as a flight stack would
  run it) and rotorpy gets ``cmd_motor_speeds``; rotorpy's own ``cmd_ctbm`` would allocate
  without desaturation, clipping each rotor on its own, which at saturation changes the roll and
  pitch moment the attitude loop asked for. With ``mixer=False`` rotorpy gets ``cmd_ctbm``
  (collective thrust clipped to the limits, moment to the hover box) and allocates it itself.
  With ``motor_time_constant = 0`` the rotors take their commanded speed at the start of each
  step (rotorpy's lag then has nothing to do). State conventions: rotorpy's quaternion is
  ``[x, y, z, w]`` (scipy's order), its ``w`` the body rates ``omega_B``, its gravity 9.81 m/s^2
  (a vehicle with another ``g`` is a :class:`~avp.errors.ConfigError`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from enum import Enum
from typing import Any

import numpy as np

from ..errors import ConfigError
from ..frames import Array
from .controller import ControllerGains
from .vehicle import RigidBodyState, VehicleParams, step

__all__ = ["HUMMINGBIRD_AERO", "ROTORPY_ROTOR_DRAG", "Backend", "Plant", "RotorpyPlant", "plant", "rotorpy_gains",
           "rotorpy_params"]

Plant = Callable[[RigidBodyState, float, Array, float], RigidBodyState]
"""``plant(state, thrust, moment_B, dt) -> state after dt`` with the command (N, N m) held."""

ROTORPY_HINT = 'rotorpy is not installed: pip install "avp[rotorpy]" (or choose backend "avp")'

HUMMINGBIRD_AERO: dict[str, float] = {
    "c_Dx": 0.5e-2, "c_Dy": 0.5e-2, "c_Dz": 1e-2,  # parasitic drag, N/(m/s)^2
    "k_d": 1.19e-4,  # rotor drag, N/(rad/s * m/s)
    "k_z": 2.32e-4,  # induced inflow, N/(rad/s * m/s)
    "k_h": 3.39e-3,  # translational lift, N/(m/s)^2
    "k_flap": 0.0,  # flapping moment, N m/(rad/s * m/s)
}
"""rotorpy's AscTec-Hummingbird aerodynamic coefficients (``rotorpy.vehicles.hummingbird_params``)."""

ROTORPY_ROTOR_DRAG = (HUMMINGBIRD_AERO["k_d"], HUMMINGBIRD_AERO["k_d"], HUMMINGBIRD_AERO["k_z"])
"""Per-rotor drag along ``b1, b2, b3`` (N per rad/s per m/s) that :func:`rotorpy_gains` feeds forward."""


def rotorpy_gains(gains: ControllerGains | None = None) -> ControllerGains:
    """``gains`` (default :class:`~avp.sim.controller.ControllerGains`) with rotorpy's rotor drag
    fed forward (:func:`~avp.sim.controller.drag_acceleration`): the controller knows the drag
    model of the vehicle it flies, as a calibrated flight stack does. Without it rotor drag
    (about 1.8 m/s^2 at 4 m/s) leaves the vehicle 3-4 cm short of the pad plane at the plan's
    contact time (docs/simulation.md)."""
    return dataclasses.replace(gains if gains is not None else ControllerGains(), rotor_drag=ROTORPY_ROTOR_DRAG)


class Backend(Enum):
    """Which model integrates the vehicle (module docstring)."""

    AVP = "avp: the paper's rigid-body model (1), RK4, avp's mixer and motor lag"
    ROTORPY = "rotorpy: rotorpy's Multirotor (rotor dynamics, drag), parameters from avp's vehicle"

    @classmethod
    def parse(cls, value: Backend | str, field: str = "scenario.backend") -> Backend:
        """A :class:`Backend`, or its name (``"avp"``, ``"rotorpy"``, any case)."""
        if isinstance(value, Backend):
            return value
        key = str(value).strip().upper()
        if key in cls.__members__:
            return cls[key]
        raise ConfigError(field, f"expected one of {[b.name.lower() for b in cls]}, got {value!r}")


def require_rotorpy(field: str = "scenario.backend") -> None:
    """Raise :class:`ConfigError` (naming ``field``, saying how to install) without rotorpy."""
    try:
        import rotorpy.vehicles.multirotor  # noqa: F401
    except ImportError as exc:
        raise ConfigError(field, ROTORPY_HINT) from exc


def rotorpy_params(vehicle: VehicleParams, aero: dict[str, float] | None = None) -> dict[str, Any]:
    """rotorpy's ``quad_params`` dictionary for avp's ``vehicle`` (module docstring).

    ``aero``: the aerodynamic coefficients (default :data:`HUMMINGBIRD_AERO`; zeros switch
    rotorpy's aerodynamics off term by term).
    """
    if abs(vehicle.g - 9.81) > 1e-12:
        raise ConfigError("scenario.vehicle.g", f"rotorpy's gravity is 9.81 m/s^2, got {vehicle.g}")
    J = vehicle.J
    theta = np.deg2rad(45.0 + 90.0 * np.arange(4))  # avp's rotor order (VehicleParams)
    t_lo, t_hi = vehicle.rotor_thrust_limits
    kf = vehicle.thrust_coefficient
    return {
        "mass": vehicle.mass,
        "Ixx": J[0, 0], "Iyy": J[1, 1], "Izz": J[2, 2], "Ixy": J[0, 1], "Iyz": J[1, 2], "Ixz": J[0, 2],
        "num_rotors": 4,
        "rotor_radius": 0.10,
        "rotor_pos": {f"r{i + 1}": vehicle.arm_length * np.array([math.cos(th), math.sin(th), 0.0])
                      for i, th in enumerate(theta)},
        "rotor_directions": np.array([1, -1, 1, -1]),
        "rI": np.zeros(3),
        **(HUMMINGBIRD_AERO if aero is None else aero),
        "k_eta": kf,
        "k_m": vehicle.drag_coefficient,
        "tau_m": vehicle.motor_time_constant if vehicle.motor_time_constant > 0 else 1.0,
        "rotor_speed_min": math.sqrt(t_lo / kf),
        "rotor_speed_max": math.sqrt(t_hi / kf),
        "motor_noise_std": 0.0,
    }


class RotorpyPlant:
    """:data:`Plant` backed by rotorpy's ``Multirotor`` for ``vehicle`` (module docstring).

    Each call converts the :class:`~avp.sim.vehicle.RigidBodyState` to rotorpy's state
    dictionary (rotor speeds in avp's rotor order, which :func:`rotorpy_params` makes rotorpy's;
    hover speeds when unset), lets ``Multirotor.step`` integrate ``dt`` with rotorpy's RK45 and
    converts back.
    """

    def __init__(self, vehicle: VehicleParams, aero: dict[str, float] | None = None) -> None:
        require_rotorpy()
        from rotorpy.vehicles.multirotor import Multirotor
        from scipy.spatial.transform import Rotation

        self.vehicle = vehicle
        self.params = rotorpy_params(vehicle, aero)
        self._rotation = Rotation
        abstraction = "cmd_motor_speeds" if vehicle.mixer else "cmd_ctbm"
        self.multirotor = Multirotor(self.params, control_abstraction=abstraction, aero=True)
        self._hover = np.full(4, math.sqrt(vehicle.hover_thrust / 4.0 / vehicle.thrust_coefficient))
        self._dt = -1.0

    def __call__(self, state: RigidBodyState, thrust: float, moment_B: Array, dt: float) -> RigidBodyState:
        veh, mr = self.vehicle, self.multirotor
        if dt != self._dt:  # RK45's first step is the whole step (it is short): no step-size search
            mr.integrator_kwargs = {"method": "RK45", "first_step": dt}
            self._dt = dt
        rotor = self._hover if state.rotor_speeds is None else state.rotor_speeds
        if veh.mixer:
            cmd_w = np.sqrt(np.maximum(veh.mix(float(thrust), np.asarray(moment_B, dtype=float)), 0.0)
                            / veh.thrust_coefficient)
            control: dict[str, Any] = {"cmd_motor_speeds": cmd_w}
        else:
            control = {"cmd_thrust": veh.clip_thrust(float(thrust)),
                       "cmd_moment": veh.clip_moment(np.asarray(moment_B, dtype=float))}
        s = {"x": state.p_W.copy(), "v": state.v_W.copy(), "q": self._rotation.from_matrix(state.R_WB).as_quat(),
             "w": state.omega_B.copy(), "wind": np.zeros(3), "rotor_speeds": np.array(rotor, dtype=float)}
        if veh.motor_time_constant <= 0.0:  # instantaneous rotors: start the step at the command
            s["rotor_speeds"] = np.clip(mr.get_cmd_motor_speeds(s, control), mr.rotor_speed_min, mr.rotor_speed_max)
        out = mr.step(s, control, dt)
        R = self._rotation.from_quat(out["q"]).as_matrix()
        return RigidBodyState._trusted(np.asarray(out["x"], dtype=float), np.asarray(out["v"], dtype=float), R,
                                       np.asarray(out["w"], dtype=float), np.asarray(out["rotor_speeds"], dtype=float))


def plant(backend: Backend | str, vehicle: VehicleParams) -> Plant:
    """The :data:`Plant` of ``backend`` for ``vehicle``; :class:`ConfigError` (field
    ``scenario.backend``) when rotorpy is asked for and not installed."""
    b = Backend.parse(backend)
    if b is Backend.ROTORPY:
        return RotorpyPlant(vehicle)

    def avp_step(state: RigidBodyState, thrust: float, moment_B: Array, dt: float) -> RigidBodyState:
        return step(state, thrust, moment_B, dt, vehicle)

    return avp_step
