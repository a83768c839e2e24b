"""Closed-loop perching runs: one-shot planning versus active visual perching (Sec. VI-C).

:func:`simulate` flies one perch in the simulator and records what the paper's Tables V and VI
measure. One run:

1. The vehicle hovers at the start of the :class:`SimScenario`. The camera
   (:class:`~avp.sim.camera.CameraSensor`) takes ``initial_frames`` detections of the pad and the
   user-side :class:`~avp.sim.estimator.TargetEstimator` fuses them: that is the first target
   estimate. If the pad is not visible from the start there is no run.
2. ``Mode.ONE_SHOT`` plans once from that estimate and odometry and flies the plan (a relaxed
   plan only with ``ReplanConfig.allow_relaxed``, the same rule as AVP's and ``avp.plan``'s).
   ``Mode.AVP`` hands the estimate to a :class:`~avp.replan.Replanner` and calls
   :meth:`~avp.replan.Replanner.step` every ``1 / replan_rate_hz`` s (30 Hz) with the odometry
   estimate and the current fused target; the camera keeps detecting while the pad is in view.
3. The SE(3) controller tracks the reference at 500 Hz on odometry; its commands go through the
   vehicle's mixer and motor lag (:mod:`~avp.sim.vehicle`), or drive rotorpy's vehicle with
   ``SimScenario(backend="rotorpy")`` (:mod:`~avp.sim.backend`). After the end of the committed plan
   the reference continues from its final flat state (:class:`AfterPlan`) until the pad plane is
   reached or ``timeout`` s have passed.

One vehicle, one camera: the planner configuration and the simulated vehicle and camera share
their objects. Without an explicit ``config`` the planner gets ``sc.vehicle.limits`` and
``sc.camera.camera``; with one, the simulator flies ``config.limits`` and ``config.fov.camera``
(:attr:`SimResult.vehicle`, :attr:`SimResult.camera` are what flew).

Success (:class:`~avp.sim.contact.PerchCriteria`) is judged at the final committed plan's
contact time (or at the plane crossing if earlier): within 3 cm of the pad plane, less than 10 cm
from the pad centre in the plane, ``b3`` within 10 deg of ``s3``. The crossing itself
(:class:`~avp.sim.contact.Contact`) is recorded too.

Determinism: all randomness comes from ``seed`` through independent streams (odometry, camera
noise, per-run camera bias draws), so the same seed gives the same run and both modes of a seed
share the initial detections, the odometry stream's draws and the camera bias (paired
comparison). By default simulated time does not advance while a plan is solved; wall-clock solve
times are recorded but never change the trajectory as long as the
:class:`~avp.replan.ReplanConfig` has ``deadline=None`` and ``adapt_latency=False`` (the default
here) and ``SimScenario.compute_slowdown`` is 0 (the default: with a slowdown each step takes
simulated time measured on this computer, so a seed no longer repeats bit for bit).
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import Enum
from typing import Any

import numpy as np

from .. import _validate as v
from ..background import BackgroundReplanner, BackgroundStep, PlanningWorker
from ..camera import Camera
from ..config import GROUND_CLEARANCE, ContactVelocity, PlannerConfig, VehicleLimits
from ..errors import AvpError, ConfigError
from ..frames import Array, yaw_from_b2
from ..moving import MovingConfig, MovingReplanner, plan_moving_detailed
from ..planner import plan_detailed
from ..platform import MotionModel, MovingTarget, rot_z
from ..qp.moving import TerminalYaw
from ..replan import ReplanAction, ReplanConfig, Replanner, ReplanStep
from ..trajectory import Trajectory
from ..types import PerchTarget, State
from .backend import Backend, Plant, plant, require_rotorpy, rotorpy_gains
from .camera import CameraMeasurement, CameraParams, CameraSensor
from .contact import (
    GROUND,
    Contact,
    PerchCriteria,
    PerchOutcome,
    PerchPad,
    SuccessCriteria,
    detect_contact,
    ground_contact,
    judge_perch,
)
from .controller import ControllerGains, FlatReference, planar_drag
from .estimator import PlatformEstimator, TargetEstimator
from .flight import DT_CONTROL, check_dt, fly
from .odometry import Odometry, OdometryNoise
from .vehicle import RigidBodyState, VehicleParams

__all__ = ["GROUND_CLEARANCE", "AfterPlan", "Mode", "PlatformMotion", "SimResult", "SimScenario", "sim_config", "simulate"]


_step_clock = time.perf_counter
"""The wall clock (s) that times a replanning step here, scaled by
``SimScenario.compute_slowdown``: the replanner's own clock (``avp.replan._clock``), so a
``deadline`` and the simulated step are measured alike (tests replace it)."""




def sim_config(
    tilt_rate_max: float | None = None,
    *,
    limits: VehicleLimits | None = None,
    camera: Camera | None = None,
    ground_z: float | None = None,
    alpha_nominal: float | None = None,
    contact_velocity: ContactVelocity | None = None,
) -> PlannerConfig:
    """The planner configuration :func:`simulate` uses by default: :class:`PlannerConfig`'s
    defaults with the simulated vehicle's ``limits`` and camera (the same objects), optionally
    with another tilt-rate limit, the planner's ground limit ``ground_z`` (m; :func:`simulate`
    passes the world's ground plus :data:`GROUND_CLEARANCE`) and the contact thrust on steep pads
    ``alpha_nominal`` (m/s^2; ``None``: the planner's default; :func:`simulate` passes the
    scenario's), and the ``contact_velocity`` (``None``: the planner's default; :func:`simulate`
    passes the scenario's).

    Both defaults come from closed-loop runs here: without a rate bound, replans from a noisy
    state close to contact certified only after the relaxations and spun at 100+ rad/s (126
    rad/s, 134 deg at contact); with the duration search on replans the contact time drifted
    from 2.5 s to 20 s at 7.5 m. docs/simulation.md has the measurements.
    """
    base = PlannerConfig()
    lim = limits if limits is not None else base.limits
    if tilt_rate_max is not None:
        lim = dataclasses.replace(lim, tilt_rate_max=float(tilt_rate_max))
    fov = base.fov if camera is None else dataclasses.replace(base.fov, camera=camera)
    workspace = base.workspace if ground_z is None else dataclasses.replace(base.workspace, ground_z=float(ground_z))
    alpha = base.alpha_nominal if alpha_nominal is None else float(alpha_nominal)
    contact = base.contact_velocity if contact_velocity is None else contact_velocity
    return dataclasses.replace(base, limits=lim, fov=fov, workspace=workspace, alpha_nominal=alpha,
                               contact_velocity=contact)


class Mode(Enum):
    """How the perch is planned."""

    ONE_SHOT = "one-shot: plan once from the first target estimate"
    AVP = "avp: replan at 30 Hz with the fused target estimate"

    @classmethod
    def parse(cls, value: Mode | str) -> Mode:
        """A :class:`Mode`, or its name (``"one_shot"``, ``"one-shot"``, ``"avp"``)."""
        if isinstance(value, Mode):
            return value
        key = str(value).strip().upper().replace("-", "_")
        if key in cls.__members__:
            return cls[key]
        raise ConfigError("mode", f"expected one of {[m.name.lower() for m in cls]}, got {value!r}")


class AfterPlan(Enum):
    """Reference after the end of the committed plan when the pad has not been touched yet."""

    HOLD_ACCELERATION = "hold: the final flat state continued at constant acceleration"
    IDLE_THRUST = "idle: the final attitude kept and the thrust cut to the vehicle's minimum"


@v.typed_keywords("platform")
@dataclass(frozen=True)
class PlatformMotion:
    """The pad carried by a moving platform (Gao et al., "Adaptive Tracking and Perching for
    Quadrotor in Dynamic Scenarios"): :class:`avp.platform.MovingTarget`'s state at ``t = 0``.

    With a platform, :func:`simulate` first flies ``tracking_time`` s behind the pad at the
    pad's velocity (the SE(3) controller on odometry, camera detecting), fuses the detections
    with the user-side :class:`~avp.sim.estimator.PlatformEstimator` and plans with
    :class:`~avp.moving.MovingReplanner` (AVP) or :func:`~avp.moving.plan_moving_detailed`
    (one-shot) against the estimated platform, which the model predicts to contact.

    Parameters
    ----------
    speed:
        Horizontal speed ``v_h`` (m/s) of the platform.
    heading:
        Direction of travel (rad) from +x towards +y; 0: away from the vehicle's start, Gao et
        al.'s chase.
    turn_rate:
        ``omega`` (rad/s) of the CTRV model (0: straight).
    vertical_speed:
        ``v_v`` (m/s).
    tracking_time:
        Time (s) spent tracking and detecting before the first plan.
    window:
        Detections of the last ``window`` s are fitted by the platform filter (4 s; 2 s fitted
        turn rates 5 times worse on the realistic moving grid: docs/moving.md).
    """

    speed: float = 0.0
    heading: float = 0.0
    turn_rate: float = 0.0
    vertical_speed: float = 0.0
    tracking_time: float = 2.0
    window: float = 4.0

    def __post_init__(self) -> None:
        for name in ("speed", "heading", "turn_rate", "vertical_speed"):
            object.__setattr__(self, name, v.finite_float(f"scenario.platform.{name}", getattr(self, name)))
        for name in ("tracking_time", "window"):  # s
            object.__setattr__(self, name, v.positive_float(f"scenario.platform.{name}", getattr(self, name)))

    @property
    def model(self) -> MotionModel:
        """CTRV when turning, else constant velocity."""
        return MotionModel.CTRV if self.turn_rate != 0.0 else MotionModel.CONSTANT_VELOCITY


MAX_OFFSET = 100.0
"""Largest stand-off, lateral offset and height of a :class:`SimScenario`'s start from the pad
(m): ten times the default camera's 10 m range, far beyond any perch approach (a start 100 km
away broke the simulated camera's arithmetic, one 1e300 m away gave NaN results)."""

MAX_INITIAL_FRAMES = 100
"""Most detections :class:`SimScenario` fuses at hover before the first plan: 10 s at the
camera's 10 Hz (a million took minutes)."""


@v.typed_keywords("scenario")
@dataclass(frozen=True, eq=False)
class SimScenario:
    """Where the pad is, where the vehicle starts, and how noisy the world is.

    The pad centre is at ``(distance, 0, pad_height)`` (heading 0: the vehicle faces +x), inclined
    by ``incline`` (rad; 0 floor, pi/2 wall). The vehicle hovers at
    ``pad - distance e1 + height e3 + lateral s2``.

    Parameters
    ----------
    incline:
        Pad incline (rad).
    distance:
        Horizontal stand-off (m) from the pad centre along the heading: positive, at most
        100 m (``MAX_OFFSET``, ten times the default camera's range).
    lateral:
        Start offset along the pad's ``s2`` (m), within +-100 m (``MAX_OFFSET``).
    height:
        Start height above the pad centre (m), within +-100 m (``MAX_OFFSET``); ``None``: +1 m
        (above the pad) for inclines below 45 deg, else 0.
    pad_height:
        Height of the pad centre (m), within +-100 m (``MAX_OFFSET``).
    pad_half_size:
        Half the side of the square pad (m); the paper's pad is about 0.3 m wide.
    camera:
        :class:`~avp.sim.camera.CameraParams`: the planner's :class:`avp.Camera` plus rate,
        latency, dropouts, range-growing noise, scale bias and normal tilt.
    odometry:
        :class:`~avp.sim.odometry.OdometryNoise` (rate, white noise, drift), or ``None`` for
        perfect state estimation.
    vehicle:
        :class:`~avp.sim.vehicle.VehicleParams`: the planner's ``VehicleLimits`` plus inertia,
        rotors, mixer and motor lag.
    gains, criteria, perch_criteria:
        Controller gains, the contact record's thresholds and the success criterion
        (:class:`~avp.sim.contact.PerchCriteria`).
    initial_frames:
        Detections fused at hover before the first plan (10 Hz apart): 1 to 100
        (``MAX_INITIAL_FRAMES``, 10 s of hover).
    filter_scale_error, filter_range_ratio, filter_estimate_scale:
        The user-side target filter's settings (:class:`~avp.sim.estimator.TargetEstimator`).
    aim_normal, aim_slope:
        Where the user-side code aims, off the estimated pad centre (m): ``aim_normal`` into the
        pad (along ``-s3``) and ``aim_slope`` down the slope (along ``-s1``, times
        ``sin(incline)`` like the contact velocity's slide: nothing on a level pad), both in the
        estimated frame; a static pad only. A pad estimated too shallow is missed short of its
        plane, one estimated too deep is met early, and the slide then carries the contact up
        the slope (about 6.7 cm per cm on a wall). Aiming deeper and lower centres the contacts
        on the success window (docs/simulation.md has the measurements). 0: aim at the estimate.
    alpha_nominal:
        The contact thrust on steep pads the user-side configuration asks of the planner
        (``PlannerConfig.alpha_nominal``, m/s^2) when :func:`simulate` builds the planner's
        configuration (and the campaign runner's, unless its ``[planner]`` table sets it); a
        ``config`` passed to :func:`simulate` is used as given. ``None``: the planner's default
        (4, the paper's). ``SimConfig`` flies 6.
    contact_velocity:
        The velocity at contact the user-side configuration asks of the planner
        (:class:`avp.ContactVelocity`), built into the planner's configuration as
        ``alpha_nominal`` is (a ``config`` passed to :func:`simulate` is used as given; in a file
        the table ``[scenario.contact_velocity]``). ``None``: the planner's default, the paper's
        0.3 m/s into the pad and 2 m/s down the slope. The ratio of slide to normal speed is how
        many centimetres along the slope an early contact lands per centimetre of depth error
        (6.7 with the paper's); ``SimConfig`` sets it from ``contact_normal`` / ``contact_slope``.
    replan_rate_hz:
        Rate of :meth:`Replanner.step` calls in AVP mode.
    timeout:
        Time (s) after the end of the committed plan without contact that counts as a miss.
    after_plan:
        :class:`AfterPlan`. ``HOLD_ACCELERATION`` keeps ``a(t_f) = alpha s3 - g e3``, whose
        ``alpha s3`` part pushes away from the pad: a vehicle whose plan ends short of the true pad
        plane turns back after ``v_n^2 / (2 alpha)`` (1.1 cm at 0.3 m/s and 4 m/s^2) and misses.
        ``IDLE_THRUST`` keeps ``b3`` and drops the thrust to ``vehicle.thrust_floor`` (the motors at
        idle), so the vehicle coasts on into the pad.
    platform:
        :class:`PlatformMotion`: the pad rides a platform (constant velocity, or CTRV with a turn
        rate); in a file the table ``[scenario.platform]`` with its fields ``speed`` (m/s),
        ``heading`` (rad), ``turn_rate`` (rad/s), ``vertical_speed`` (m/s), ``tracking_time``
        and ``window`` (s); ``None``: a static pad.
    backend:
        :class:`~avp.sim.backend.Backend` (or its name): what integrates the vehicle, ``"avp"``
        (model (1), default) or ``"rotorpy"`` (rotorpy's ``Multirotor`` with parameters from
        ``vehicle``; needs ``pip install "avp[rotorpy]"``, else a ``ConfigError`` here). The rest
        of the loop, avp's feed-forward controller included, is the same; with
        ``gains.rotor_drag=None`` :func:`simulate` feeds rotorpy's rotor drag forward.
    compute_slowdown:
        The onboard computer's speed, as how many times slower than the computer running the
        simulation it is (0: planning takes no simulated time, as an ideal computer). Each AVP
        replanning step then lasts ``compute_slowdown`` times its wall time here
        (``time.perf_counter``, the clock of the replanner's ``deadline``; the step call only,
        not the simulated sensors and filter) of simulated time: the vehicle flies the plan
        committed before the step until the step is done, a new plan takes over at its switch
        time ``t_ex`` or, when it arrives later, at its arrival, and the 30 Hz loop's next step
        starts only when the computer is free (a tick that finds it busy is skipped). ``ReplanConfig.deadline``
        and ``adapt_latency`` act on the onboard computer's times: the replanner here is given
        ``deadline / compute_slowdown`` and ``latency_margin * compute_slowdown`` (so its
        reasons quote the scaled deadline, and ``ReplanStep.solve_time`` is this computer's).
        The first plan, made at hover, is not delayed. With a slowdown the runs depend on this
        computer's timings and load (run it on an otherwise idle computer, one process per
        core), so a seed no longer repeats bit for bit. ``bench_pipeline.py`` run on
        both computers gives the factor (the ratio of their ``plan()`` medians).
    ground_z:
        Height (m) of the ground of the simulated world, or ``None`` for none. A vehicle whose
        centre of mass goes below it before the plan's contact time has crashed (outcome
        ``"crash: ground"``), whatever the plan said. The default planner configuration (:func:`sim_config`) is given the same ground as
        a workspace limit; a configuration passed to :func:`simulate` keeps its own.
    """

    incline: float = math.pi / 2
    distance: float = 4.5
    lateral: float = 0.0
    height: float | None = None
    pad_height: float = 1.5
    pad_half_size: float = 0.15
    camera: CameraParams = field(default_factory=CameraParams)
    odometry: OdometryNoise | None = field(default_factory=OdometryNoise)
    vehicle: VehicleParams = field(default_factory=VehicleParams)
    gains: ControllerGains = field(default_factory=ControllerGains)
    criteria: SuccessCriteria = field(default_factory=SuccessCriteria)
    perch_criteria: PerchCriteria = field(default_factory=PerchCriteria)
    initial_frames: int = 1
    filter_scale_error: float = 0.0
    filter_range_ratio: float | None = None
    filter_estimate_scale: bool = False
    aim_normal: float = 0.0
    aim_slope: float = 0.0
    alpha_nominal: float | None = None
    contact_velocity: ContactVelocity | None = None
    replan_rate_hz: float = 30.0
    timeout: float = 0.5
    after_plan: AfterPlan = AfterPlan.HOLD_ACCELERATION
    platform: PlatformMotion | None = None
    backend: Backend = Backend.AVP
    ground_z: float | None = 0.0
    compute_slowdown: float = 0.0

    def __post_init__(self) -> None:
        v.flags("scenario", self)
        object.__setattr__(self, "backend", Backend.parse(self.backend))
        object.__setattr__(self, "compute_slowdown",
                           v.nonnegative_float("scenario.compute_slowdown", self.compute_slowdown))
        if self.backend is Backend.ROTORPY:
            require_rotorpy()
        for name, cls, optional in _PARTS:
            part = getattr(self, name)
            if not (isinstance(part, cls) or (optional and part is None)):
                where = "avp.sim.run" if cls is PlatformMotion else "avp.sim"
                raise ConfigError(f"scenario.{name}", f"must be an {where}.{cls.__name__}{' or None' if optional else ''}, "
                                  f"got {type(part).__name__}: pass {where}.{cls.__name__}(...)")
        incline = v.finite_float("scenario.incline", self.incline)
        if not 0.0 <= incline <= math.pi:
            raise ConfigError("scenario.incline", f"must be in [0, pi] rad (0 to 180 deg), got {incline}")
        object.__setattr__(self, "incline", incline)
        distance = v.finite_float("scenario.distance", self.distance)
        if not 0.0 < distance <= MAX_OFFSET:
            raise ConfigError("scenario.distance", f"must be a positive length of at most {MAX_OFFSET:g} m "
                                                   f"(a perch approach), got {distance}")
        object.__setattr__(self, "distance", distance)
        for name in ("lateral", "height"):
            value = getattr(self, name)
            if value is None and name == "height":
                continue
            value = v.finite_float(f"scenario.{name}", value)
            if abs(value) > MAX_OFFSET:
                raise ConfigError(f"scenario.{name}", f"must be within +-{MAX_OFFSET:g} m of the pad "
                                                      f"(a perch approach), got {value}")
            object.__setattr__(self, name, value)
        object.__setattr__(self, "pad_height", v.finite_float("scenario.pad_height", self.pad_height))
        if abs(self.pad_height) > MAX_OFFSET:
            raise ConfigError("scenario.pad_height", f"must be within {MAX_OFFSET:g} m of the ground, got "
                                                     f"{self.pad_height:g}")
        object.__setattr__(self, "initial_frames", v.integer(
            "scenario.initial_frames", self.initial_frames, 1, MAX_INITIAL_FRAMES,
            hint=f"(detections before the first plan, {MAX_INITIAL_FRAMES} at most: 10 s of hover at 10 Hz)"))
        for name, window in (("aim_normal", self.perch_criteria.plane_tolerance),
                             ("aim_slope", self.perch_criteria.center_tolerance)):
            val = v.finite_float(f"scenario.{name}", getattr(self, name))
            if abs(val) >= window:
                raise ConfigError(f"scenario.{name}", f"an aim of {val} m leaves the success window "
                                  f"({window} m); aim inside it")
            object.__setattr__(self, name, val)
        if self.alpha_nominal is not None:
            object.__setattr__(self, "alpha_nominal", v.positive_float("scenario.alpha_nominal", self.alpha_nominal))
        if self.contact_velocity is not None and not isinstance(self.contact_velocity, ContactVelocity):
            raise ConfigError("scenario.contact_velocity", "must be an avp.ContactVelocity or None, got "
                              f"{type(self.contact_velocity).__name__}")
        if self.platform is not None and (self.aim_normal or self.aim_slope):
            raise ConfigError("scenario.aim_normal", "the aim is defined for a static pad; set aim_normal = "
                              "aim_slope = 0 with a platform")
        for name in ("replan_rate_hz", "timeout", "pad_half_size"):
            object.__setattr__(self, name, v.positive_float(f"scenario.{name}", getattr(self, name)))
        if self.ground_z is not None:
            object.__setattr__(self, "ground_z", v.finite_float("scenario.ground_z", self.ground_z))
            if self.start()[2] <= self.ground_z:
                raise ConfigError("scenario.ground_z", f"the start ({self.start()[2]:.3g} m high) is not above the "
                                  f"ground at {self.ground_z:g} m: raise pad_height or height, or lower ground_z")
            if self.pad_height < self.ground_z:
                raise ConfigError("scenario.ground_z", f"the pad ({self.pad_height:g} m high) is below the ground at "
                                  f"{self.ground_z:g} m: raise pad_height or lower ground_z")

    @property
    def planner_ground_z(self) -> float | None:
        """The ground limit (m) the default planner configuration keeps: :attr:`ground_z` plus
        :data:`GROUND_CLEARANCE` (None without a ground)."""
        return None if self.ground_z is None else self.ground_z + GROUND_CLEARANCE

    @property
    def start_height(self) -> float:
        """Start height above the pad centre (m)."""
        if self.height is not None:
            return float(self.height)
        return 1.0 if self.incline < math.pi / 4 else 0.0

    def target(self) -> PerchTarget:
        """The true pad as a :class:`~avp.types.PerchTarget`."""
        return PerchTarget.from_incline([self.distance, 0.0, self.pad_height], self.incline, heading=0.0)

    def target_filter(self) -> TargetEstimator:
        """A fresh user-side filter of a static pad with this scenario's settings."""
        return TargetEstimator(self.filter_scale_error, self.filter_range_ratio, self.filter_estimate_scale)

    def pad(self) -> PerchPad:
        """The true pad (at ``t = 0``) as a :class:`~avp.sim.contact.PerchPad`."""
        t = self.target()
        return PerchPad(t.point, t.R_WS, half_size=self.pad_half_size)

    def moving_target(self) -> MovingTarget | None:
        """The true pad on its platform at ``t = 0`` (None without :attr:`platform`)."""
        m = self.platform
        if m is None:
            return None
        return MovingTarget.from_pad(self.target(), heading=m.heading, speed=m.speed, turn_rate=m.turn_rate,
                                     vertical_speed=m.vertical_speed, time=0.0, model=m.model)

    def start(self) -> Array:
        """Hover position (m) at the start."""
        t = self.target()
        return t.point + np.array([-self.distance, 0.0, self.start_height]) + self.lateral * t.s2

    def without_noise(self) -> SimScenario:
        """The same scenario with a perfect camera and perfect odometry."""
        return dataclasses.replace(self, camera=self.camera.ideal(), odometry=None)

    def ideal(self) -> SimScenario:
        """:meth:`without_noise` on an ideal vehicle (instant thrust and moments, no mixer)."""
        vehicle = dataclasses.replace(self.vehicle, mixer=False, motor_time_constant=0.0)
        return dataclasses.replace(self.without_noise(), vehicle=vehicle)


@dataclass(frozen=True, eq=False, kw_only=True)
class SimResult:
    """Everything one :func:`simulate` run recorded.

    Attributes
    ----------
    scenario, mode, seed:
        What was run.
    outcome:
        ``"success"``, ``"failed: <criteria>"``, ``"miss: no contact"``, ``"no initial detection"``,
        ``"no plan: <status>"`` or ``"crash: ground"`` (below ``scenario.ground_z`` before the
        plan's contact time; a fall after it, with the perch already judged, ends the run only).
    contact:
        :class:`~avp.sim.contact.Contact` (point in S, attitude error, speeds, failures) or None.
    interception:
        Contact point in S coordinates ``(s1, s2)`` (m): ``s1`` along the slope (vertical on a wall),
        ``s2`` lateral. The paper's Table VI calls these ``s3`` and ``s2``. None without contact.
    initial_target, initial_estimate_error:
        First target handed to the planner (the estimate, aimed by ``aim_normal`` /
        ``aim_slope``) and the first estimate's own position error (m, W) w.r.t. the true pad
        (without the aim).
    first_plan, final_plan:
        The first committed plan and the last one (the same for one-shot).
    steps:
        :class:`~avp.replan.ReplanStep` records (AVP; one-shot: empty).
    anticipation_error:
        ``(n, 3)``: anticipated position at ``t_ex`` minus the true position when the vehicle got
        there, for every committed replan (Table V).
    anticipation_t:
        ``(n,)`` the ``t_ex`` of those replans.
    solve_times:
        Wall-clock seconds of each planning call (first plan included).
    path_t, path_p:
        True time and position at every control step (500 Hz), from the start of the flight.
    visible:
        Whether the pad centre was in the camera's FoV (and range) at each ``path_t``.
    detections:
        ``(n, 4)``: time, true camera-pad distance (m), position error of the detection (m) and of
        the fused estimate after it (m), for every detection including the initial ones.
    path_drift:
        ``(n, 3)``: the odometry's drift (the random-walk part of believed minus true position,
        m) at every ``path_t`` (zeros without odometry noise).
    measurements:
        The :class:`~avp.sim.camera.CameraMeasurement` objects handed to the target filter, in
        order (what :mod:`avp.sim.limit` re-fuses).
    detector_scale:
        The camera's per-run scale error ``b`` (:class:`~avp.sim.camera.CameraParams`).
    t_plan:
        Time the first plan starts (s).
    perch:
        :class:`~avp.sim.contact.PerchOutcome` at the final plan's contact time (the success
        criterion), None without a plan.
    vehicle, camera:
        The simulated vehicle and camera (their ``limits`` / ``camera`` are the planner's).
    step_delays, skipped_ticks, late_commits:
        With ``scenario.compute_slowdown``: the simulated duration (s) of every replanning step
        after the first plan, the loop's ticks skipped because the computer was still busy, and
        the committed plans that arrived after their switch time ``t_ex`` (flown from their
        arrival). Empty and 0 without a slowdown.
    """

    scenario: SimScenario
    mode: Mode
    seed: int
    outcome: str
    contact: Contact | None
    interception: Array | None
    initial_target: PerchTarget | None
    initial_estimate_error: Array | None
    first_plan: Trajectory | None
    final_plan: Trajectory | None
    steps: tuple[ReplanStep, ...]
    anticipation_error: Array
    anticipation_t: Array
    solve_times: Array
    path_t: Array
    path_p: Array
    visible: Array
    detections: Array
    t_plan: float
    perch: PerchOutcome | None = None
    vehicle: VehicleParams | None = None
    camera: CameraParams | None = None
    measurements: tuple[CameraMeasurement, ...] = ()
    detector_scale: float = 0.0
    path_drift: Array | None = None
    step_delays: Array | None = None
    skipped_ticks: int = 0
    late_commits: int = 0

    @property
    def success(self) -> bool:
        """The perch meets :class:`~avp.sim.contact.PerchCriteria` at the plan's contact time."""
        return self.perch is not None and self.perch.success

    def actions(self) -> dict[str, int]:
        """How often each :class:`~avp.replan.ReplanAction` occurred (AVP)."""
        out: dict[str, int] = {}
        for s in self.steps:
            out[s.action.name] = out.get(s.action.name, 0) + 1
        return out

    @property
    def visible_fraction(self) -> float:
        """Share of the flight time with the pad in the FoV."""
        return float(np.mean(self.visible)) if self.visible.size else 0.0


_PARTS = (("camera", CameraParams, False), ("odometry", OdometryNoise, True), ("vehicle", VehicleParams, False),
          ("gains", ControllerGains, False), ("criteria", SuccessCriteria, False),
          ("perch_criteria", PerchCriteria, False), ("platform", PlatformMotion, True))
"""The fields of :class:`SimScenario` holding settings objects: name, class, whether ``None`` is allowed."""


def _hold(traj: Trajectory, t: float, idle_accel: float | None = None) -> FlatReference:
    """The plan's final flat state continued at constant acceleration (zero jerk, constant yaw);
    with ``idle_accel`` (m/s^2) the thrust vector ``a + g e3`` is first scaled to that magnitude."""
    f = traj.flat_output(traj.tf)
    h = t - traj.tf
    a = np.asarray(f.acceleration, dtype=float)
    if idle_accel is not None:
        g_e3 = np.array([0.0, 0.0, traj.g])
        thrust = a + g_e3
        a = thrust * (idle_accel / max(float(np.linalg.norm(thrust)), 1e-9)) - g_e3
    v = np.asarray(f.velocity, dtype=float)
    z = np.zeros(3)
    return FlatReference(np.asarray(f.position) + v * h + 0.5 * a * h * h, v + a * h, a, z, z,
                         float(f.yaw), 0.0, 0.0)


def _odometry_state(b: RigidBodyState, t: float, ref: Any) -> State:
    """What the planner gets from a (noisy) odometry sample ``b`` at ``t``."""
    R = b.R_WB
    b2 = R[:, 1]
    b2_dot = R @ np.array([-b.omega_B[2], 0.0, b.omega_B[0]])
    den = b2[0] ** 2 + b2[1] ** 2
    yaw_rate = float((b2[0] * b2_dot[1] - b2[1] * b2_dot[0]) / den) if den > 1e-9 else 0.0
    return State(position=b.p_W, velocity=b.v_W, acceleration=np.asarray(ref.acceleration, dtype=float),
                 jerk=np.asarray(ref.jerk, dtype=float), yaw=yaw_from_b2(b2), yaw_rate=yaw_rate, time=t)


def _estimate_target(est: TargetEstimator, sc: SimScenario) -> PerchTarget | None:
    """The target the user-side code hands the planner: the fused estimate, aimed by
    ``sc.aim_normal`` / ``sc.aim_slope``."""
    e = est.estimate()
    if e is None:
        return None
    target = PerchTarget(point=e.p_W, R_WS=e.R_WS)
    if sc.aim_normal == 0.0 and sc.aim_slope == 0.0:
        return target
    down = sc.aim_slope * math.sin(target.incline)
    return PerchTarget(point=e.p_W - sc.aim_normal * target.s3 - down * target.s1, R_WS=e.R_WS)


def _shared(sc: SimScenario, config: PlannerConfig | None) -> tuple[SimScenario, PlannerConfig]:
    """Scenario and planner configuration sharing one vehicle and one camera object."""
    if config is None:
        return sc, sim_config(limits=sc.vehicle.limits, camera=sc.camera.camera, ground_z=sc.planner_ground_z,
                              alpha_nominal=sc.alpha_nominal, contact_velocity=sc.contact_velocity)
    vehicle = sc.vehicle if sc.vehicle.limits is config.limits else dataclasses.replace(sc.vehicle, limits=config.limits)
    camera = sc.camera if sc.camera.camera is config.fov.camera else dataclasses.replace(sc.camera, camera=config.fov.camera)
    return dataclasses.replace(sc, vehicle=vehicle, camera=camera), config


def pad_contact(prev: RigidBodyState, new: RigidBodyState, t_prev: float, t_new: float, platform: MovingTarget,
                half_size: float, criteria: SuccessCriteria) -> Contact | None:
    """:func:`~avp.sim.contact.detect_contact` against a pad on a moving ``platform``: both
    states taken relative to the pad at ``t_new`` (position shifted by the pad's displacement,
    velocity minus the pad's; the pad turns by ``omega dt < 1e-3`` rad in a step), so the
    contact reports the point on the pad, the attitude error against its normal and the
    *relative* normal and tangential speeds."""
    pad_new = platform.at(t_new)
    if float((new.p_W - pad_new.point) @ pad_new.s3) > 0.5:  # far from the plane: skip the work
        return None
    pad_prev = platform.at(t_prev)
    shift = pad_new.point - pad_prev.point
    prev_rel = RigidBodyState(prev.p_W + shift, prev.v_W - pad_prev.velocity, prev.R_WB, prev.omega_B)
    new_rel = RigidBodyState(new.p_W, new.v_W - pad_new.velocity, new.R_WB, new.omega_B)
    pad = PerchPad(pad_new.point, pad_new.R_WS, half_size=half_size)
    return detect_contact(prev_rel, new_rel, pad, t_prev, t_new, criteria)


def closed_loop(
    state: RigidBodyState,
    reference: Callable[[float], Any],
    t0: float,
    t_end: Callable[[], float],
    max_time: float,
    period: float,
    dt: float,
    vehicle: VehicleParams,
    gains: ControllerGains,
    tick: Callable[[float, RigidBodyState], None] | None,
    hook: Callable[[RigidBodyState, RigidBodyState, float, float], Any],
    odometry: Odometry | OdometryNoise | None,
    rng: np.random.Generator | None = None,
    plant: Plant | None = None,
) -> tuple[RigidBodyState, Any]:
    """The replanning loop shared by the simulators: every ``period`` s (from ``t0``) call
    ``tick(t, state)`` (not at ``t0``: the first plan is made before), then fly the reference
    for one period at ``1 / dt`` Hz (:func:`~avp.sim.flight.fly` with ``hook``), until the hook
    reports an event, ``t > t_end()`` or ``t - t0 > max_time``. ``plant``: the back-end's
    integrator (:mod:`~avp.sim.backend`; default avp's). Returns the final true state and the
    event (None without one)."""
    k = n = 0  # control steps flown since t0, replanning ticks
    while True:
        t = t0 + k * dt
        if t > t_end() or t - t0 > max_time:
            return state, None
        if tick is not None and n > 0:
            tick(t, state)
        n += 1
        k_next = max(int(round(n * period / dt)), k + 1)
        res = fly(state, reference, t, (k_next - k) * dt, vehicle, gains, dt=dt, odometry=odometry, rng=rng, stop=hook,
                  plant=plant)
        state, k = res.state, k_next
        if res.event is not None:
            return state, res.event


def _track(state: RigidBodyState, platform: MovingTarget, sc: SimScenario, detect: Callable[[float, RigidBodyState], None],
           odo: Odometry | None, dt: float, plant: Plant | None = None) -> tuple[RigidBodyState, float]:
    """Fly ``sc.platform.tracking_time`` s from ``state`` (given the pad's velocity) keeping the
    start's offset from the moving pad in the platform's frame (turning with it, yaw too),
    detecting at every control step."""
    assert sc.platform is not None
    offset = state.p_W - platform.point
    z = np.zeros(3)
    w = platform.omega
    yaw0 = yaw_from_b2(state.R_WB[:, 1])

    def track(tt: float) -> Any:
        p = platform.at(tt)
        r = rot_z(w * tt) @ offset
        wr = np.array([-w * r[1], w * r[0], 0.0])  # omega e3 x r
        return FlatReference(p.point + r, p.velocity + wr, p.acceleration - w * w * np.array([r[0], r[1], 0.0]),
                             z, z, yaw0 + w * tt, w, 0.0)

    def hook(prev: RigidBodyState, new: RigidBodyState, t_prev: float, t_new: float) -> None:
        detect(t_new, new)

    start = RigidBodyState(state.p_W, track(0.0).velocity, state.R_WB)
    detect(0.0, start)
    res = fly(start, track, 0.0, sc.platform.tracking_time, sc.vehicle, sc.gains, dt=dt, odometry=odo, stop=hook,
              plant=plant)
    return res.state, res.t


def simulate(
    scenario: SimScenario | None = None,
    mode: Mode | str = Mode.AVP,
    *,
    seed: int = 0,
    config: PlannerConfig | None = None,
    replan: ReplanConfig | None = None,
    dt: float = DT_CONTROL,
    max_time: float = 20.0,
    moving: MovingConfig | None = None,
    plan_drag: bool | None = None,
    background: bool | PlanningWorker = False,
) -> SimResult:
    """Fly one perch of ``scenario`` in ``mode`` (module docstring) and record it.

    Parameters
    ----------
    scenario:
        :class:`SimScenario` (default: 90 deg wall, 4.5 m, default noise).
    mode:
        :class:`Mode` (or ``"one_shot"`` / ``"avp"``).
    seed:
        Seed of every random stream of the run: an integer >= 0.
    config:
        Planner configuration (default :func:`sim_config` with the scenario's vehicle and camera);
        its ``limits`` and ``fov.camera`` are what the simulator flies.
    replan:
        Replanning policy (default ``ReplanConfig()``: deterministic).
    dt:
        Control and integration step (s), in [0.1, 2] ms (:data:`~avp.sim.flight.DT_MIN`,
        :data:`~avp.sim.flight.DT_MAX`).
    max_time:
        Hard cap on simulated time (s) after the first plan (positive).
    moving:
        Terminal map and arrival-time search on a moving pad (``scenario.platform``; default
        ``MovingConfig(yaw=TerminalYaw.PAD)``: the yaw at contact follows the detected pad, not
        the noisy heading of the fitted velocity).
    plan_drag:
        On rotorpy with the drag fed forward (``gains.rotor_drag=None``), give the planner that
        drag's planar coefficient at the pad's contact thrust (``limits.rotor_drag``,
        :func:`~avp.sim.controller.planar_drag`), so that it plans the thrust along the normal
        at contact, as the controller will fly it. The contact thrust is the static planner's
        ``contact_alpha(incline)``; on a moving pad, whose contact thrust is free in the limits,
        ``d`` (which scales with its square root) is that value's, not the plan's. Default
        (None): when the planner's ``limits.rotor_drag`` is 0, that of ``config`` or, without
        one, of the scenario's vehicle (a nonzero drag there is the user's and is kept; an
        explicit 0 cannot be told from the default, so pass ``False`` for it). The campaign
        runner and ``avp simulate`` give it unless the configuration sets ``rotor_drag``. A planner that knows
        no drag, on a vehicle whose controller feeds it forward, plans a contact it cannot fly
        (on rotorpy's wall ``b3`` arrives 9 deg off ``s3``): pass ``False`` to fly one anyway.
    background:
        ``Mode.AVP`` only: run the replanner in a worker process
        (:class:`~avp.background.BackgroundReplanner`), on a new worker (``True``, closed at the
        end) or on the :class:`~avp.background.PlanningWorker` given (left open, for the next
        run). Each step's request is adopted at the next control step, at the same simulated
        time (:meth:`~avp.background.BackgroundReplanner.poll` with ``wait``): time stands still
        while a plan is made, as for the replanner in the loop, so the flight is the same, plans
        bit for bit; what differs is the loop's own cost (``benchmarks/bench_background.py``).
        Not with ``scenario.compute_slowdown`` (which models a step that plans in the loop).
    """
    if not (background is False or background is True or isinstance(background, PlanningWorker)):
        raise ConfigError("background", f"expected True, False or an avp.PlanningWorker, got {background!r}")
    if background is not False:
        sc0 = scenario if scenario is not None else SimScenario()
        if Mode.parse(mode) is not Mode.AVP:
            raise ConfigError("background", "runs the replanner of Mode.AVP; a one-shot flight has none")
        if sc0.compute_slowdown:
            raise ConfigError("background", "plans in a worker process; scenario.compute_slowdown models a step "
                              "that plans in the loop: use one or the other")
    worker = PlanningWorker() if background is True else background if background is not False else None
    try:
        return _simulate(scenario, mode, seed, config, replan, dt, max_time, moving, plan_drag, worker)
    finally:
        if background is True and worker is not None:
            worker.close()


def _simulate(
    scenario: SimScenario | None, mode: Mode | str, seed: int, config: PlannerConfig | None,
    replan: ReplanConfig | None, dt: float, max_time: float, moving: MovingConfig | None,
    plan_drag: bool | None, worker: PlanningWorker | None,
) -> SimResult:
    """:func:`simulate`, its replanner in ``worker`` when one is given."""
    dt = check_dt(dt)
    seed = v.integer("seed", seed, 0, hint="(a random generator seed)")
    max_time = v.positive_float("max_time", max_time, allow_inf=True)  # inf: the plan's end and the timeout
    if plan_drag is not None:
        if not isinstance(plan_drag, (bool, np.bool_)):
            raise ConfigError("plan_drag", f"expected True, False or None, got {plan_drag!r} ({type(plan_drag).__name__})")
        plan_drag = bool(plan_drag)
    sc, cfg = _shared(scenario if scenario is not None else SimScenario(), config)
    if sc.backend is Backend.ROTORPY and sc.gains.rotor_drag is None:  # the back-end's drag model
        sc = dataclasses.replace(sc, gains=rotorpy_gains(sc.gains))
        if plan_drag if plan_drag is not None else cfg.limits.rotor_drag == 0.0:
            # the planner knows the drag the controller feeds forward, at the contact
            # thrust: at contact the thrust, not the acceleration, is along the normal
            drag = planar_drag(sc.vehicle, sc.gains.rotor_drag, cfg.contact_alpha(sc.incline))
            limits = dataclasses.replace(cfg.limits, rotor_drag=drag)
            cfg = dataclasses.replace(cfg, limits=limits)
            sc = dataclasses.replace(sc, vehicle=dataclasses.replace(sc.vehicle, limits=limits))
    mode = Mode.parse(mode)
    rcfg = replan if replan is not None else ReplanConfig()
    slowdown = sc.compute_slowdown
    if slowdown:  # the onboard computer's budget and latency, on this computer's clock
        rcfg = dataclasses.replace(rcfg, deadline=None if rcfg.deadline is None else rcfg.deadline / slowdown,
                                   latency_margin=rcfg.latency_margin * slowdown)
    streams = np.random.SeedSequence(int(seed)).spawn(4)
    rng_odo, rng_cam, rng_bias, _ = (np.random.default_rng(s) for s in streams)

    truth, pad = sc.target(), sc.pad()
    platform = sc.moving_target()
    mcfg = moving if moving is not None else MovingConfig(yaw=TerminalYaw.PAD)

    def truth_at(tt: float) -> PerchTarget:
        return truth if platform is None else platform.at(tt)

    idle = sc.vehicle.thrust_floor / sc.vehicle.mass if sc.after_plan is AfterPlan.IDLE_THRUST else None
    vehicle_plant = plant(sc.backend, sc.vehicle)
    camera = CameraSensor(sc.camera, rng_bias)
    estimator: TargetEstimator | PlatformEstimator
    if sc.platform is None:
        estimator = sc.target_filter()
    else:
        estimator = PlatformEstimator(sc.platform.window, sc.filter_scale_error, sc.platform.turn_rate != 0.0,
                                      sc.filter_estimate_scale)
    odo = None if sc.odometry is None else Odometry(sc.odometry, rng_odo)
    state = RigidBodyState(sc.start())
    detections: list[tuple[float, float, float, float]] = []
    measurements: list[CameraMeasurement] = []

    def believed(t: float, s: RigidBodyState) -> RigidBodyState:
        return s if odo is None else odo.sample(t, s)

    def detect(t: float, s: RigidBodyState) -> None:
        pad_t = truth_at(t)
        for m in camera.poll(t, s, pad_t.point, pad_t.R_WS, rng_cam, believed(t, s)):
            _fuse(m, t)

    def _fuse(m: CameraMeasurement, t: float) -> None:
        estimator.update(m)
        measurements.append(m)
        e = estimator.estimate()
        assert e is not None
        detections.append((t, m.distance, float(np.linalg.norm(m.p_W - truth_at(m.t).point)),
                           float(np.linalg.norm(e.p_W - truth_at(e.t_last).point))))

    def estimate_target() -> PerchTarget | None:
        if isinstance(estimator, PlatformEstimator):
            return estimator.target(platform.model if platform is not None else MotionModel.CTRV)
        return _estimate_target(estimator, sc)

    # 1. hover and detect (until the initial frames have been delivered); on a platform, track it
    t = 0.0
    if platform is None:
        period_cam = 1.0 / sc.camera.rate_hz
        k = 0
        while estimator.n_measurements < sc.initial_frames and k < sc.initial_frames + 10:
            t = k * period_cam + sc.camera.phase
            detect(t, state)
            if sc.camera.latency > 0:
                t = t + sc.camera.latency
                detect(t, state)
            k += 1
    else:
        assert sc.platform is not None
        state, t = _track(state, platform, sc, detect, odo, dt, vehicle_plant)
    t_plan = t
    initial = estimate_target()
    first_estimate = estimator.estimate() if platform is None else None  # the estimate itself, not the aim
    initial_point = (first_estimate.p_W if first_estimate is not None
                     else (initial.point if initial is not None else None))
    empty = np.zeros((0, 3))
    # the computer's time (scenario.compute_slowdown): busy until, and (until, the plan flown)
    # while a late plan is on its way
    busy_until = -math.inf
    held: tuple[float, Trajectory] | None = None
    step_delays: list[float] = []
    skipped = late = 0

    def finish(outcome: str, contact: Contact | None = None, **kw: Any) -> SimResult:
        base: dict[str, Any] = dict(
            scenario=sc, mode=mode, seed=int(seed), outcome=outcome, contact=contact,
            interception=None if contact is None else contact.p_S[:2].copy(),
            initial_target=initial,
            initial_estimate_error=None if initial_point is None else initial_point - truth_at(t_plan).point,
            first_plan=None, final_plan=None, steps=(), anticipation_error=empty,
            anticipation_t=np.zeros(0), solve_times=np.zeros(0), path_t=np.zeros(0),
            path_p=empty, path_drift=empty, visible=np.zeros(0, dtype=bool),
            detections=np.array(detections, dtype=float).reshape(-1, 4), t_plan=t_plan,
            vehicle=sc.vehicle, camera=sc.camera, measurements=tuple(measurements),
            detector_scale=camera.scale,
        )
        base.update(step_delays=np.array(step_delays, dtype=float), skipped_ticks=skipped, late_commits=late)
        base.update(kw)
        return SimResult(**base)

    if initial is None or (platform is not None and estimator.n_measurements < 2):
        return finish("no initial detection")

    # 2. first plan (both modes from the same odometry sample)
    zero_ref = FlatReference(np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(3))
    start = _odometry_state(believed(t_plan, state), t_plan, zero_ref)
    solve_times: list[float] = []
    replanner: Replanner | BackgroundReplanner | None = None
    if mode is Mode.AVP:
        inner = Replanner(initial, cfg, rcfg) if platform is None else MovingReplanner(initial, cfg, rcfg, mcfg)  # type: ignore[arg-type]
        replanner = inner if worker is None else BackgroundReplanner(inner, worker=worker, wait=True)
        out = replanner.step(t_plan, start, initial)
        first = out.adopted if isinstance(out, BackgroundStep) else out
        assert first is not None  # a first plan is waited for
        solve_times.append(first.solve_time)
        if replanner.trajectory is None:
            return finish(f"no plan: {first.reason}", steps=tuple(replanner.history),
                          solve_times=np.array(solve_times))
        plan0: Trajectory = replanner.trajectory
    else:
        w0 = time.perf_counter()
        try:
            result: Any = (plan_detailed(start, initial, cfg) if platform is None
                           else plan_moving_detailed(start, initial, cfg, mcfg))  # type: ignore[arg-type]
            reason = "" if result is not None and result.ok else (result.status.value if result else "")
        except AvpError as exc:
            result, reason = None, f"{type(exc).__name__}: {exc}"
        solve_times.append(time.perf_counter() - w0)
        if result is not None and result.ok and getattr(result, "relaxations", ()) and not rcfg.allow_relaxed:
            reason = "relaxed plan (allow_relaxed is off)"  # as avp.plan(...) refuses it by default
            result = None
        if result is None or not result.ok or result.trajectory is None:
            return finish(f"no plan: {reason}", solve_times=np.array(solve_times))
        plan0 = result.trajectory

    def committed() -> Trajectory:
        return replanner.trajectory if replanner is not None else plan0  # type: ignore[return-value]

    def flown() -> Trajectory:
        """The plan the vehicle flies at the last simulated time: ``committed()``, or the one
        before it while a late plan is on its way (``compute_slowdown``)."""
        if held is not None and path_t and path_t[-1] < held[0]:
            return held[1]
        return committed()

    def reference(tt: float) -> Any:
        if held is not None and tt < held[0]:  # the new plan has not arrived: fly the one before it
            traj = held[1]  # started: a step commits only once the committed plan has (Replanner)
            return _hold(traj, tt, idle) if tt > traj.tf else traj.flat_output(max(tt, traj.t0))
        if isinstance(replanner, BackgroundReplanner) and replanner.pending:
            # the request of the tick just made, adopted at its first control step (the same time:
            # simulated time stands still while it is planned, as for the replanner in the loop)
            adopt(replanner.poll(tt, wait=True))
        traj = committed()
        if tt > traj.tf:
            return _hold(traj, tt, idle)
        if replanner is not None:
            return replanner.reference(tt)
        return traj.flat_output(max(tt, traj.t0))

    # 3. closed loop
    path_t: list[float] = []
    path_p: list[Array] = []
    path_R: list[Array] = []
    path_drift: list[Array] = []
    visible: list[bool] = []
    pending: list[tuple[float, Array]] = []  # (t_ex, anticipated position) of committed replans
    antic_err: list[Array] = []
    antic_t: list[float] = []

    def hook(prev: RigidBodyState, new: RigidBodyState, t_prev: float, t_new: float) -> Contact | None:
        path_t.append(t_new)
        path_p.append(new.p_W)
        path_R.append(new.R_WB)
        pad_t = truth_at(t_new)
        visible.append(camera.visible(new, pad_t.point, pad_t.R_WS))
        while pending and pending[0][0] <= t_new + 1e-9:
            t_ex, p_ant = pending.pop(0)
            lam = min(max((t_ex - t_prev) / (t_new - t_prev), 0.0), 1.0)
            antic_err.append(p_ant - (prev.p_W + lam * (new.p_W - prev.p_W)))
            antic_t.append(t_ex)
        detect(t_new, new)  # samples the odometry at t_new (the believed pose of a detection)
        path_drift.append(np.zeros(3) if odo is None else odo.drift.copy())
        hit = (detect_contact(prev, new, pad, t_prev, t_new, sc.criteria) if platform is None
               else pad_contact(prev, new, t_prev, t_new, platform, sc.pad_half_size, sc.criteria))
        crash = None if sc.ground_z is None else ground_contact(prev, new, t_prev, t_new, sc.ground_z)
        if crash is not None and (hit is None or crash.t < hit.t):  # whichever came first in the step
            return crash
        return hit

    path_t.append(t_plan)
    path_p.append(state.p_W)
    path_R.append(state.R_WB)
    path_drift.append(np.zeros(3) if odo is None else odo.drift.copy())
    pad0 = truth_at(t_plan)
    visible.append(camera.visible(state, pad0.point, pad0.R_WS))

    def tick(t: float, state: RigidBodyState) -> None:
        nonlocal busy_until, held, skipped, late
        assert replanner is not None
        if t < busy_until:  # the onboard computer is still on the previous step
            skipped += 1
            return
        before = committed()
        odometry, estimate = _odometry_state(believed(t, state), t, reference(t)), estimate_target()
        if isinstance(replanner, BackgroundReplanner):  # sends; the next control step adopts (reference)
            adopt(replanner.step(t, odometry, estimate))
            return
        c0 = _step_clock()
        s = replanner.step(t, odometry, estimate)
        elapsed = _step_clock() - c0
        if slowdown:
            delay = slowdown * elapsed
            step_delays.append(delay)
            busy_until = t + delay
            if committed() is not before and t + delay > s.t_ex:  # arrives after its switch time
                held = (t + delay, before)
                late += 1
        record(s)

    def record(s: ReplanStep) -> None:
        """A step's solve time and, for a committed replan, its anticipated start (checked
        against the flight at ``t_ex`` by ``hook``)."""
        if s.solved:
            solve_times.append(s.solve_time)
        if s.action in (ReplanAction.REPLANNED, ReplanAction.PARTIAL) and s.anticipated is not None:
            pending.append((s.t_ex, s.anticipated.position.copy()))

    def adopt(out: BackgroundStep | None) -> None:
        """The bookkeeping of a step a background call adopted (if any)."""
        nonlocal late
        if out is not None and out.adopted is not None:
            late += out.late > 0.0
            record(out.adopted)

    state, contact = closed_loop(
        state, reference, t_plan, lambda: flown().tf + sc.timeout, max_time, 1.0 / sc.replan_rate_hz, dt,
        sc.vehicle, sc.gains, tick if replanner is not None else None, hook, odo, plant=vehicle_plant)

    final = flown()  # a plan still on its way when the flight ended was never flown
    pt, pp, pR = np.array(path_t), np.array(path_p).reshape(-1, 3), np.array(path_R).reshape(-1, 3, 3)
    if contact is not None and GROUND in contact.failures:
        if contact.t > final.tf:  # after the contact time, where the perch is judged: a miss, judged below
            contact = None
        else:
            return finish(
                "crash: ground", None, first_plan=plan0, final_plan=final,
                steps=tuple(replanner.history) if replanner is not None else (),
                anticipation_error=np.array(antic_err, dtype=float).reshape(-1, 3),
                anticipation_t=np.array(antic_t, dtype=float),
                solve_times=np.array(solve_times, dtype=float), path_t=pt, path_p=pp, path_drift=np.array(path_drift).reshape(-1, 3),
                visible=np.array(visible, dtype=bool),
            )
    t_eval = min(final.tf, contact.t) if contact is not None else final.tf
    if platform is not None:
        # the pad at the time of the judged pose; a contact's pose is relative to the pad at the
        # end of its control step (pad_contact), the last recorded time
        judged = pt[-1] if (contact is not None and contact.t <= final.tf) or t_eval > pt[-1] else t_eval
        pad_eval = platform.at(float(judged))
        pad = PerchPad(pad_eval.point, pad_eval.R_WS, half_size=sc.pad_half_size)
    if contact is not None and contact.t <= final.tf:
        perch = judge_perch(contact.t, contact.p_W, contact.R_WB, pad, sc.perch_criteria)
    elif t_eval <= pt[-1]:
        i = int(np.clip(np.searchsorted(pt, t_eval), 1, pt.size - 1))
        lam = (t_eval - pt[i - 1]) / max(pt[i] - pt[i - 1], 1e-12)
        p_e = pp[i - 1] + lam * (pp[i] - pp[i - 1])
        perch = judge_perch(t_eval, p_e, pR[i] if lam > 0.5 else pR[i - 1], pad, sc.perch_criteria)
    else:
        perch = judge_perch(pt[-1], pp[-1], pR[-1], pad, sc.perch_criteria)
    if perch.success:
        outcome = "success"
    else:
        outcome = "failed: " + ", ".join(perch.failures)
    return finish(
        outcome, contact, perch=perch,
        first_plan=plan0, final_plan=final,
        steps=tuple(replanner.history) if replanner is not None else (),
        anticipation_error=np.array(antic_err, dtype=float).reshape(-1, 3),
        anticipation_t=np.array(antic_t, dtype=float),
        solve_times=np.array(solve_times, dtype=float),
        path_t=pt, path_p=pp, path_drift=np.array(path_drift).reshape(-1, 3),
        visible=np.array(visible, dtype=bool),
    )
