"""Closed-loop line perches in the realistic simulator: :func:`simulate_line`.

One run of a :class:`LineScenario`:

1. The vehicle hovers at ``start``. The line detector (:class:`LineDetector`) delivers
   ``initial_frames`` detections; their fusion is the first line estimate.
2. ``Mode.ONE_SHOT`` plans once with :func:`avp.plan_line` from odometry; ``Mode.AVP`` hands the
   estimate to a :class:`~avp.line_replan.LineReplanner` stepped at ``replan_rate_hz`` with
   odometry and the current fused estimate.
3. The SE(3) controller tracks the reference at 500 Hz on odometry through the vehicle's rotor
   mixer and motor lag (:mod:`~avp.sim.vehicle`, the same models as :func:`avp.sim.simulate`)
   until the committed plan's contact time ``t_f``.

**Detections.** A detection is the true line translated by the odometry position error at that
instant (the line is seen from the believed pose) plus white noise of standard deviation
``sigma + sigma_per_metre * range`` per axis (range: vehicle to grasp point); the estimate is the
inverse-variance weighted mean of the translations. The model has no field of view, no rotation
error of the line and no false detections: a line detector (Paneque et al. use a camera, Li et
al. a LiDAR) is assumed to keep the line in view.

**Success** (:class:`LineCriteria`, a gripper's capture envelope, assumed: no seed gives one): at
``t_f`` the true gripper (CoM ``- r b3``) is within ``gripper`` of the true line, ``b3`` within
``angle`` of the commanded normal, the speed below ``speed``, and the true CoM never came closer
to the line than ``r - clearance`` before ``t_f - 0.05`` s. There is no contact model: what
happens after ``t_f`` (the grasp) is not simulated.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .. import _validate as v
from .._typing import Array
from ..config import PlannerConfig, ReplanConfig, Workspace
from ..errors import AvpError, ConfigError
from ..line import LineTarget
from ..line_planner import LineOptions, plan_line
from ..line_replan import LineReplanner
from ..replan import ReplanStep
from ..trajectory import Trajectory
from .controller import ControllerGains, FlatReference
from .flight import DT_CONTROL, check_dt, fly
from .odometry import Odometry, OdometryNoise
from .run import MAX_INITIAL_FRAMES, Mode, _odometry_state
from .vehicle import RigidBodyState, VehicleParams

__all__ = ["LineCriteria", "LineDetector", "LineScenario", "LineSimResult", "simulate_line"]


@v.typed_keywords("detector")
@dataclass(frozen=True)
class LineDetector:
    """Line detection model (module docstring): rate (Hz) and per-axis noise ``sigma +
    sigma_per_metre * range`` (m)."""

    rate_hz: float = 30.0
    sigma: float = 0.005
    sigma_per_metre: float = 0.01

    def __post_init__(self) -> None:
        object.__setattr__(self, "rate_hz", v.positive_float("detector.rate_hz", self.rate_hz))
        for name in ("sigma", "sigma_per_metre"):
            object.__setattr__(self, name, v.nonnegative_float(f"detector.{name}", getattr(self, name)))


@v.typed_keywords("criteria")
@dataclass(frozen=True)
class LineCriteria:
    """Success of a line perch at the contact time (module docstring): distances in m, ``angle``
    in rad, ``speed`` in m/s. ``gripper`` and ``speed`` are positive (``speed`` ``inf``: no
    limit), ``angle`` in ``(0, pi]``, ``clearance`` >= 0."""

    gripper: float = 0.03
    angle: float = math.radians(10.0)
    speed: float = 0.3
    clearance: float = 0.02

    def __post_init__(self) -> None:
        object.__setattr__(self, "gripper", v.positive_float("criteria.gripper", self.gripper))
        angle = v.positive_float("criteria.angle", self.angle)
        if angle > math.pi:
            raise ConfigError("criteria.angle", f"must be in (0, pi] rad, got {angle}")
        object.__setattr__(self, "angle", angle)
        object.__setattr__(self, "speed", v.positive_float("criteria.speed", self.speed, allow_inf=True))
        object.__setattr__(self, "clearance", v.nonnegative_float("criteria.clearance", self.clearance))


@v.typed_keywords("scenario")
@dataclass(frozen=True, eq=False)
class LineScenario:
    """A line, a hover start and the noise of the world.

    ``ground_z`` is the minimum height given to the planner (``config.workspace.ground_z``) when
    :func:`simulate_line` builds the configuration.
    """

    line: LineTarget
    start: Any
    ground_z: float | None = None
    detector: LineDetector = field(default_factory=LineDetector)
    odometry: OdometryNoise | None = field(default_factory=OdometryNoise)
    vehicle: VehicleParams = field(default_factory=VehicleParams)
    gains: ControllerGains = field(default_factory=ControllerGains)
    criteria: LineCriteria = field(default_factory=LineCriteria)
    initial_frames: int = 1
    replan_rate_hz: float = 30.0

    def __post_init__(self) -> None:
        if not isinstance(self.line, LineTarget):
            raise ConfigError("scenario.line", f"expected avp.LineTarget, got {type(self.line).__name__}")
        object.__setattr__(self, "start", np.array(v.frozen_array("scenario.start", self.start, (3,))))
        object.__setattr__(self, "initial_frames", v.integer(
            "scenario.initial_frames", self.initial_frames, 1, MAX_INITIAL_FRAMES,
            hint=f"(detections before the first plan, {MAX_INITIAL_FRAMES} at most, as SimScenario's)"))
        object.__setattr__(self, "replan_rate_hz", v.positive_float("scenario.replan_rate_hz", self.replan_rate_hz))


@dataclass(frozen=True, eq=False, kw_only=True)
class LineSimResult:
    """One :func:`simulate_line` run: the outcome, the figures the criteria judge (gripper
    distance m, attitude error rad, speed m/s, clearance ``min dist - r`` m), the plans, the
    replanning steps, the wall-clock solve times and the true path (500 Hz)."""

    mode: Mode
    seed: int
    outcome: str
    gripper_error: float = math.nan
    angle_error: float = math.nan
    speed: float = math.nan
    clearance: float = math.nan
    estimate_error: float = math.nan
    first_plan: Trajectory | None = None
    final_plan: Trajectory | None = None
    recovery: Trajectory | None = None
    steps: tuple[ReplanStep, ...] = ()
    solve_times: Array = field(default_factory=lambda: np.zeros(0))
    path_t: Array = field(default_factory=lambda: np.zeros(0))
    path_p: Array = field(default_factory=lambda: np.zeros((0, 3)))

    @property
    def success(self) -> bool:
        return self.outcome == "success"


class _Fusion:
    """Inverse-variance mean of detected line translations."""

    def __init__(self) -> None:
        self.w = 0.0
        self.sum = np.zeros(3)

    def add(self, offset: Array, sigma: float) -> None:
        wi = 1.0 / max(sigma, 1e-6) ** 2
        self.w += wi
        self.sum += wi * offset

    def offset(self) -> Array:
        return self.sum / self.w


def _translated(line: LineTarget, offset: Array) -> LineTarget:
    return dataclasses.replace(line, vertices=line.vertices + offset)


def simulate_line(
    scenario: LineScenario,
    mode: Mode | str = Mode.AVP,
    *,
    seed: int = 0,
    config: PlannerConfig | None = None,
    replan: ReplanConfig | None = None,
    options: LineOptions | None = None,
    dt: float = DT_CONTROL,
) -> LineSimResult:
    """Fly one line perch of ``scenario`` (module docstring). ``config`` defaults to
    :class:`~avp.config.PlannerConfig` with the scenario vehicle's limits and ``ground_z``; the
    simulator flies ``config.limits``. ``seed``: an integer >= 0; ``dt`` (s) in [0.1, 2] ms."""
    if not isinstance(scenario, LineScenario):
        raise ConfigError("scenario", f"expected avp.sim.LineScenario, got {type(scenario).__name__}")
    dt = check_dt(dt)
    seed = v.integer("seed", seed, 0, hint="(a random generator seed)")
    mode = Mode.parse(mode)
    sc = scenario
    cfg = config if config is not None else PlannerConfig(limits=sc.vehicle.limits, workspace=Workspace(ground_z=sc.ground_z))
    vehicle = sc.vehicle if sc.vehicle.limits is cfg.limits else dataclasses.replace(sc.vehicle, limits=cfg.limits)
    rcfg = replan if replan is not None else ReplanConfig()
    streams = np.random.SeedSequence(int(seed)).spawn(3)
    rng_odo, rng_det, _ = (np.random.default_rng(s) for s in streams)
    odo = None if sc.odometry is None else Odometry(sc.odometry, rng_odo)
    truth, r = sc.line, sc.line.gripper_offset
    grasp_true = truth.contact(sc.start, 0.0).grasp_point(truth.grasp if truth.grasp is not None else 0.5 * sum(truth.grasp_range))
    fusion = _Fusion()

    def believed(t: float, s: RigidBodyState) -> RigidBodyState:
        return s if odo is None else odo.sample(t, s)

    def detect(t: float, s: RigidBodyState) -> None:
        b = believed(t, s)
        sigma = sc.detector.sigma + sc.detector.sigma_per_metre * float(np.linalg.norm(grasp_true - s.p_W))
        fusion.add((b.p_W - s.p_W) + rng_det.normal(0.0, sigma, 3), sigma)

    state = RigidBodyState(sc.start)
    period_det = 1.0 / sc.detector.rate_hz
    for k in range(sc.initial_frames):
        detect(k * period_det, state)
    t_plan = (sc.initial_frames - 1) * period_det
    estimate = _translated(truth, fusion.offset())
    zero = np.zeros(3)
    start = _odometry_state(believed(t_plan, state), t_plan, FlatReference(zero, zero, zero, zero, zero))
    solve_times: list[float] = []
    replanner: LineReplanner | None = None
    if mode is Mode.AVP:
        replanner = LineReplanner(estimate, cfg, rcfg, options)
        first = replanner.step(t_plan, start, estimate)
        solve_times.append(first.solve_time)
        if replanner.trajectory is None:
            return LineSimResult(mode=mode, seed=int(seed), outcome=f"no plan: {first.reason}", steps=tuple(replanner.history),
                                 solve_times=np.array(solve_times))
        plan0: Trajectory = replanner.trajectory
        recovery = replanner.recovery
    else:
        w0 = time.perf_counter()
        try:
            res = plan_line(start, estimate, cfg, options)
            reason = res.status.value
        except AvpError as exc:
            res, reason = None, f"{type(exc).__name__}: {exc}"
        solve_times.append(time.perf_counter() - w0)
        if res is None or not res.ok or res.perch is None:
            return LineSimResult(mode=mode, seed=int(seed), outcome=f"no plan: {reason}", solve_times=np.array(solve_times))
        plan0, recovery = res.perch, res.recovery

    def committed() -> Trajectory:
        return replanner.trajectory if replanner is not None else plan0  # type: ignore[return-value]

    def reference(tt: float) -> Any:
        if replanner is not None:
            return replanner.reference(tt)
        return plan0.flat_output(min(max(tt, plan0.t0), plan0.tf))

    path_t, path_p, path_R = [t_plan], [state.p_W], [state.R_WB]
    next_det = [t_plan + period_det]

    def hook(prev: RigidBodyState, new: RigidBodyState, t_prev: float, t_new: float) -> None:
        path_t.append(t_new)
        path_p.append(new.p_W)
        path_R.append(new.R_WB)
        if t_new >= next_det[0] - 1e-9:
            detect(t_new, new)
            next_det[0] += period_det
        return None

    period = 1.0 / sc.replan_rate_hz
    k, n = 0, 0
    while True:
        t = t_plan + k * dt
        if t >= committed().tf - 1e-9:
            break
        if replanner is not None and n > 0:
            s = replanner.step(t, _odometry_state(believed(t, state), t, reference(t)),
                               _translated(truth, fusion.offset()))
            if s.solved:
                solve_times.append(s.solve_time)
        n += 1
        k_next = max(int(round(n * period / dt)), k + 1)
        k_next = min(k_next, max(int(math.ceil((committed().tf - t_plan) / dt - 1e-9)), k + 1))
        out = fly(state, reference, t, (k_next - k) * dt, vehicle, sc.gains, dt=dt, odometry=odo, stop=hook)
        state, k = out.state, k_next

    final = committed()
    if replanner is not None:
        recovery = replanner.recovery
    pt, pp = np.array(path_t), np.array(path_p).reshape(-1, 3)
    b3 = state.R_WB[:, 2]
    n_cmd = final.attitude(final.tf)[:, 2]
    e_grip = truth.distance(state.p_W - r * b3)
    e_ang = math.acos(min(1.0, max(-1.0, float(b3 @ n_cmd))))
    speed = float(np.linalg.norm(state.v_W))
    before = pt < final.tf - 0.05
    d_min = min((truth.distance(p) for p in pp[before]), default=math.inf) - r
    crit = sc.criteria
    fails = [name for name, bad in (("gripper", e_grip > crit.gripper), ("attitude", e_ang > crit.angle),
                                    ("speed", speed > crit.speed), ("clearance", d_min < -crit.clearance)) if bad]
    return LineSimResult(
        mode=mode, seed=int(seed), outcome="success" if not fails else "failed: " + ", ".join(fails),
        gripper_error=e_grip, angle_error=e_ang, speed=speed, clearance=d_min,
        estimate_error=float(np.linalg.norm(fusion.offset())), first_plan=plan0, final_plan=final,
        recovery=recovery, steps=tuple(replanner.history) if replanner is not None else (),
        solve_times=np.array(solve_times), path_t=pt, path_p=pp,
    )
