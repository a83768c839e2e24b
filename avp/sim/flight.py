"""Vehicle + controller in closed loop for one stretch of time: the inner loop of a simulation.

:func:`fly` runs the controller (2) at ``1/dt`` Hz (default 500 Hz) on odometry (optionally noisy)
and advances the dynamics (1) by one RK4 step per control step with the command held (or another
back-end's plant, :mod:`~avp.sim.backend`). A ``stop`` hook, called after each step with the
previous and new true states, ends the stretch early (e.g. :func:`~avp.sim.contact.detect_contact`). A closed-loop runner then only has to call :func:`fly`
once per camera frame or replanning period, feed the camera and estimator, and replan.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from .. import _validate as v
from ..errors import ConfigError
from ..frames import Array
from .backend import Plant
from .controller import ControllerGains, FlatReferenceLike, control
from .odometry import Odometry, OdometryNoise, noisy_odometry
from .vehicle import RigidBodyState, VehicleParams, step

__all__ = ["DT_CONTROL", "FlightResult", "Trace", "fly"]

DT_CONTROL = 0.002
"""Default control and integration step (s): 500 Hz."""

DT_MIN = 1e-4
"""Smallest control and integration step (s) the simulators take: 10 kHz, twenty times finer
than :data:`DT_CONTROL` (a finer step changes nothing the model resolves, and a 20 s run would
take millions of steps)."""

DT_MAX = DT_CONTROL
"""Largest step (s): the integrator and the contact interpolation assume ``dt <= 2 ms``."""


def check_dt(value: Any, field: str = "dt") -> float:
    """``value`` as a control step (s) in ``[DT_MIN, DT_MAX]``, else a :class:`ConfigError` on
    ``field``."""
    dt = v.finite_float(field, value)
    if not DT_MIN * (1 - 1e-6) <= dt <= DT_MAX * (1 + 1e-6):  # a float32 of 2 ms is 2.0000001e-3
        raise ConfigError(field, f"must be in [{DT_MIN:g}, {DT_MAX:g}] s (500 Hz to 10 kHz), got {dt}; "
                                 f"the default is {DT_CONTROL:g} s")
    return dt

StopHook = Callable[[RigidBodyState, RigidBodyState, float, float], Any]


@dataclass(frozen=True, eq=False)
class Trace:
    """Per-step log of a stretch: true state at the end of each step (``t``) and the command
    (``thrust``, ``moment_B``, desired attitude) held during that step."""

    t: Array
    p_W: Array
    v_W: Array
    R_WB: Array
    omega_B: Array
    thrust: Array
    moment_B: Array
    R_WB_des: Array


@dataclass(frozen=True, eq=False, kw_only=True)
class FlightResult:
    """End of a stretch: true ``state`` at time ``t`` (s), the stop hook's ``event`` (or None)."""

    state: RigidBodyState
    t: float
    event: Any = None
    trace: Trace | None = None


def fly(
    state: RigidBodyState,
    reference: Callable[[float], FlatReferenceLike],
    t0: float,
    duration: float,
    params: VehicleParams | None = None,
    gains: ControllerGains = ControllerGains(),
    *,
    dt: float = DT_CONTROL,
    odometry: OdometryNoise | Odometry | None = None,
    rng: np.random.Generator | None = None,
    stop: StopHook | None = None,
    record: bool = False,
    plant: Plant | None = None,
) -> FlightResult:
    """Fly ``reference`` from ``state`` at ``t0`` for ``duration`` s (rounded to steps of ``dt``).

    Parameters
    ----------
    state:
        True state at ``t0``.
    reference:
        ``t -> FlatReference`` (or any object with its fields) evaluated at each control step.
    t0, duration:
        Start time and length of the stretch (s).
    params, gains:
        Vehicle and controller.
    dt:
        Control and integration step (s); at most 2 ms (>= 500 Hz).
    odometry, rng:
        What the controller sees: an :class:`~avp.sim.odometry.Odometry` stream (shared with
        the rest of the robot), or memoryless :class:`OdometryNoise` drawn from ``rng``.
    stop:
        ``stop(prev, new, t_prev, t_new)``; a non-None return ends the stretch at ``t_new`` and
        is returned as ``event``.
    record:
        Keep a :class:`Trace` of every step.
    plant:
        What advances the true state over a step (:mod:`~avp.sim.backend`, e.g. rotorpy's
        vehicle); default :func:`~avp.sim.vehicle.step` with ``params``.
    """
    if params is None:
        params = VehicleParams()
    if not 0.0 < dt <= 0.002 + 1e-12:
        raise ConfigError("dt", f"must be in (0, 0.002] s (>= 500 Hz), got {dt}")
    if isinstance(odometry, OdometryNoise) and rng is None:
        raise ConfigError("rng", "odometry noise needs an explicit np.random.Generator")
    n_steps = max(int(round(duration / dt)), 0)
    log: dict[str, list[Any]] = {k: [] for k in Trace.__dataclass_fields__}
    t, event = float(t0), None
    for k in range(n_steps):
        if odometry is None:
            seen = state
        elif isinstance(odometry, Odometry):
            seen = odometry.sample(t, state)
        else:
            seen = noisy_odometry(state, odometry, rng)  # type: ignore[arg-type]
        cmd = control(seen, reference(t), params, gains)
        if plant is None:
            new = step(state, cmd.thrust, cmd.moment_B, dt, params)
        else:
            new = plant(state, cmd.thrust, cmd.moment_B, dt)
        t_new = float(t0) + (k + 1) * dt
        if record:
            for key, val in (
                ("t", t_new), ("p_W", new.p_W), ("v_W", new.v_W), ("R_WB", new.R_WB),
                ("omega_B", new.omega_B), ("thrust", cmd.thrust), ("moment_B", cmd.moment_B),
                ("R_WB_des", cmd.R_WB_des),
            ):
                log[key].append(val)
        event = stop(state, new, t, t_new) if stop is not None else None
        state, t = new, t_new
        if event is not None:
            break
    trace = None
    if record:
        trace = Trace(**{k: np.array(v, dtype=float) for k, v in log.items()})
    return FlightResult(state=state, t=t, event=event, trace=trace)
