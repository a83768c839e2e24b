"""Closed-loop perching on a moving platform (Gao et al., "Adaptive Tracking and Perching for
Quadrotor in Dynamic Scenarios", T-RO 2023): the true platform follows its motion model
(:class:`~avp.platform.MovingTarget`, constant velocity or CTRV), the vehicle starts tracking it
(moving with it, behind the pad), and a :class:`~avp.moving.MovingReplanner` replans at 30 Hz
from noisy odometry and noisy platform-state estimates while the SE(3) controller flies the
committed plan at 500 Hz (:func:`~avp.sim.flight.fly`).

Effects modelled: odometry noise (:class:`~avp.sim.odometry.OdometryNoise`, on the controller and
the planner), white noise on every 30 Hz platform-state measurement (:class:`PlatformNoise`:
position, velocity, heading, turn rate) fused by a fixed-gain filter (:class:`PlatformFilter`; a
stand-in for Gao et al.'s GPS/vision EKF, not a camera model), actuator limits of
:class:`~avp.sim.vehicle.VehicleParams`. Not modelled: the camera and its
field of view (the static simulator's :mod:`~avp.sim.camera`), platform accelerations the model
does not predict, wind.

Contact is detected in the pad's frame: between two control steps the vehicle's state is taken
relative to the pad (position shifted by the pad's displacement, velocity minus the pad's), so
:func:`~avp.sim.contact.detect_contact` reports the contact point on the pad, the attitude error
against the pad's normal and the *relative* normal and tangential speeds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .. import _validate as v
from ..config import PlannerConfig
from ..errors import ConfigError
from ..frames import Array
from ..moving import MovingConfig, MovingReplanner
from ..platform import MovingTarget, rot_z
from ..replan import ReplanConfig
from ..trajectory import Trajectory
from .contact import Contact, SuccessCriteria
from .controller import ControllerGains, FlatReference
from .flight import DT_CONTROL, check_dt
from .odometry import OdometryNoise, noisy_odometry
from .run import _hold, _odometry_state, closed_loop, pad_contact
from .vehicle import RigidBodyState, VehicleParams

__all__ = ["MovingSimResult", "MovingSimScenario", "PlatformFilter", "PlatformNoise", "noisy_platform", "simulate_moving"]


@v.typed_keywords("platform_noise")
@dataclass(frozen=True)
class PlatformNoise:
    """Standard deviations of the white noise on each platform-state estimate."""

    sigma_position: float = 0.03  # m, per axis
    sigma_velocity: float = 0.05  # m/s, along and across the heading
    sigma_heading: float = 0.01  # rad
    sigma_turn_rate: float = 0.005  # rad/s

    def __post_init__(self) -> None:
        for name in ("sigma_position", "sigma_velocity", "sigma_heading", "sigma_turn_rate"):
            object.__setattr__(self, name, v.nonnegative_float(f"platform_noise.{name}", getattr(self, name)))


def noisy_platform(truth: MovingTarget, noise: PlatformNoise | None, rng: np.random.Generator) -> MovingTarget:
    """An estimate of ``truth`` (same time): its pose, speed, heading and turn rate with noise;
    the pad frame is turned about ``e3`` by the heading error."""
    if noise is None:
        return truth
    n = rng.standard_normal(7)
    dpsi = noise.sigma_heading * n[5]
    v = truth.velocity[:2] + noise.sigma_velocity * n[3:5]
    speed = math.copysign(float(np.hypot(*v)), truth.speed) if truth.speed != 0.0 else float(noise.sigma_velocity * n[3])
    return MovingTarget(
        point=truth.point + noise.sigma_position * n[0:3], R_WS=rot_z(dpsi) @ truth.R_WS,
        heading=truth.heading + dpsi, speed=speed, turn_rate=truth.turn_rate + noise.sigma_turn_rate * n[6],
        vertical_speed=truth.vertical_speed, time=truth.time, model=truth.model,
    )


class PlatformFilter:
    """Fixed-gain (alpha) filter of the platform estimates, a stand-in for Gao et al.'s EKF: each
    new measurement ``m`` at ``t`` moves the model's prediction of the fused state toward it,
    ``x <- x_pred + gain (m - x_pred)`` for the position, heading (wrapped), speed and turn rate;
    the pad frame turns with the heading correction. ``gain = 1`` passes measurements through."""

    def __init__(self, gain: float) -> None:
        if not (math.isfinite(gain) and 0.0 < gain <= 1.0):
            raise ConfigError("filter_gain", f"must be in (0, 1], got {gain}")
        self.gain = gain
        self.fused: MovingTarget | None = None

    def update(self, m: MovingTarget) -> MovingTarget:
        if self.fused is None or self.gain == 1.0:
            self.fused = m
            return m
        p = self.fused.at(m.time)
        k = self.gain
        dpsi = k * math.remainder(m.heading - p.heading, 2.0 * math.pi)
        self.fused = MovingTarget(
            point=p.point + k * (m.point - p.point), R_WS=rot_z(dpsi) @ p.R_WS, heading=p.heading + dpsi,
            speed=p.speed + k * (m.speed - p.speed), turn_rate=p.turn_rate + k * (m.turn_rate - p.turn_rate),
            vertical_speed=p.vertical_speed + k * (m.vertical_speed - p.vertical_speed), time=m.time, model=p.model,
        )
        return self.fused


@v.typed_keywords("scenario")
@dataclass(frozen=True, eq=False)
class MovingSimScenario:
    """A platform and a vehicle tracking it.

    ``target`` is the true platform at ``time = 0``. The vehicle starts ``behind`` m behind the
    pad along the heading and ``height`` m above it, moving with the platform's velocity, level,
    yawed to the heading.
    """

    target: MovingTarget
    behind: float = 3.0
    height: float = 0.0
    pad_half_size: float = 0.15
    odometry: OdometryNoise | None = field(default_factory=OdometryNoise)
    platform_noise: PlatformNoise | None = field(default_factory=PlatformNoise)
    vehicle: VehicleParams = field(default_factory=VehicleParams)
    gains: ControllerGains = field(default_factory=ControllerGains)
    criteria: SuccessCriteria = field(default_factory=SuccessCriteria)
    replan_rate_hz: float = 30.0
    timeout: float = 0.5
    filter_gain: float = 0.2
    """Gain of the :class:`PlatformFilter` on the 30 Hz platform estimates (1: raw estimates)."""
    idle_after_plan: bool = True
    """After the committed plan ends short of the pad: keep the attitude and cut the thrust to the
    vehicle's minimum (the static simulator's ``AfterPlan.IDLE_THRUST``), instead of holding
    ``a(t_f)``, whose ``alpha s3`` part pushes away from the pad."""

    def __post_init__(self) -> None:
        v.flags("scenario", self)
        if not isinstance(self.target, MovingTarget):
            raise ConfigError("scenario.target", f"expected avp.platform.MovingTarget, got {type(self.target).__name__}")
        for name in ("behind", "height", "pad_half_size", "replan_rate_hz", "timeout"):
            if not math.isfinite(getattr(self, name)):
                raise ConfigError(f"scenario.{name}", "must be finite")
        for name in ("pad_half_size", "replan_rate_hz", "timeout"):
            if getattr(self, name) <= 0.0:
                raise ConfigError(f"scenario.{name}", "must be positive")

    def start(self) -> RigidBodyState:
        tgt = self.target.at(0.0)
        h = np.array([math.cos(tgt.heading), math.sin(tgt.heading), 0.0])
        p = tgt.point - self.behind * h + np.array([0.0, 0.0, self.height])
        return RigidBodyState(p, tgt.velocity, rot_z(tgt.heading))


@dataclass(frozen=True, eq=False, kw_only=True)
class MovingSimResult:
    """One :func:`simulate_moving` run.

    ``outcome``: ``"success"``, ``"failed: <criteria>"``, ``"miss: no contact"`` or
    ``"no plan: <reason>"``. ``contact`` is relative to the pad (point in S, relative speeds).
    ``error``: contact point's distance from the pad centre (m). ``speed_max``, ``speed_mean``:
    the vehicle's ground speed from the first plan to contact (Gao et al.'s Table VIII columns).
    """

    outcome: str
    contact: Contact | None
    error: float
    speed_max: float
    speed_mean: float
    target_speed: float
    replans: int
    solve_times: Array
    first_plan: Trajectory | None
    final_plan: Trajectory | None

    @property
    def success(self) -> bool:
        return self.contact is not None and self.contact.success


def simulate_moving(
    scenario: MovingSimScenario,
    *,
    seed: int = 0,
    config: PlannerConfig | None = None,
    moving: MovingConfig | None = None,
    replan: ReplanConfig | None = None,
    dt: float = DT_CONTROL,
    max_time: float = 15.0,
) -> MovingSimResult:
    """Fly one perch on the moving platform of ``scenario`` (module docstring). ``seed``: an
    integer >= 0; ``dt`` (s) in [0.1, 2] ms; ``max_time`` (s) positive."""
    dt = check_dt(dt)
    seed = v.integer("seed", seed, 0, hint="(a random generator seed)")
    max_time = v.positive_float("max_time", max_time, allow_inf=True)
    sc = scenario
    rcfg = replan if replan is not None else ReplanConfig(deadline=None)
    rng_ctrl, rng_plan, rng_est = (np.random.default_rng(s) for s in np.random.SeedSequence(int(seed)).spawn(3))
    truth, odo = sc.target, sc.odometry
    state = sc.start()
    speeds: list[float] = []
    zero_ref = FlatReference(np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(3))

    def finish(outcome: str, contact: Contact | None = None, rp: MovingReplanner | None = None,
               first: Trajectory | None = None) -> MovingSimResult:
        error = float(np.hypot(*contact.p_S[:2])) if contact is not None else math.nan
        sp = np.array(speeds) if speeds else np.array([math.nan])
        hist = rp.history if rp is not None else []
        return MovingSimResult(outcome=outcome, contact=contact, error=error, speed_max=float(np.max(sp)), speed_mean=float(np.mean(sp)), target_speed=abs(truth.speed), replans=sum(1 for s in hist if s.action.name == "REPLANNED"), solve_times=np.array([s.solve_time for s in hist if s.solve_time > 0.0]), first_plan=first, final_plan=rp.trajectory if rp is not None else None)

    believed = state if odo is None else noisy_odometry(state, odo, rng_plan)
    filt = PlatformFilter(sc.filter_gain)
    rp = MovingReplanner(filt.update(noisy_platform(truth.at(0.0), sc.platform_noise, rng_est)), config, rcfg, moving)
    step0 = rp.step(0.0, _odometry_state(believed, 0.0, zero_ref), rp.target)
    if rp.trajectory is None:
        return finish(f"no plan: {step0.reason}", rp=rp)
    first = rp.trajectory

    def reference(tt: float) -> Any:
        traj = rp.trajectory
        assert traj is not None
        return _hold(traj, tt, idle) if tt > traj.tf else rp.reference(tt)

    def hook(prev: RigidBodyState, new: RigidBodyState, t_prev: float, t_new: float) -> Contact | None:
        speeds.append(float(np.linalg.norm(new.v_W)))
        return pad_contact(prev, new, t_prev, t_new, truth, sc.pad_half_size, sc.criteria)

    def tick(t: float, state: RigidBodyState) -> None:
        b = state if odo is None else noisy_odometry(state, odo, rng_plan)
        est = filt.update(noisy_platform(truth.at(t), sc.platform_noise, rng_est))
        rp.step(t, _odometry_state(b, t, reference(t)), est)

    def t_end() -> float:
        assert rp.trajectory is not None
        return rp.trajectory.tf + sc.timeout

    idle = sc.vehicle.thrust_floor / sc.vehicle.mass if sc.idle_after_plan else None
    state, contact = closed_loop(state, reference, 0.0, t_end, max_time, 1.0 / sc.replan_rate_hz, dt, sc.vehicle,
                                 sc.gains, tick, hook, odo, rng_ctrl if odo is not None else None)
    if contact is None:
        return finish("miss: no contact", None, rp, first)
    return finish("success" if contact.success else "failed: " + ", ".join(contact.failures), contact, rp, first)
