"""Bad input raises a typed AvpError subclass that names the field."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import assume, example, given, settings
from hypothesis import strategies as st
from scenarios import standard

import avp
from avp import _validate
from avp._validate import LIMITS


def field_of(exc_info: pytest.ExceptionInfo[avp.ConfigError]) -> str:
    return exc_info.value.field


@pytest.mark.parametrize(
    "kwargs, field",
    [
        ({"position": [0, 0]}, "state.position"),
        ({"position": [0, 0, np.nan]}, "state.position"),
        ({"position": [0, 0, 1], "velocity": [np.inf, 0, 0]}, "state.velocity"),
        ({"position": [0, 0, 1], "yaw": float("nan")}, "state.yaw"),
        ({"position": "abc"}, "state.position"),
    ],
)
def test_state_validation(kwargs, field) -> None:
    with pytest.raises(avp.ConfigError) as exc:
        avp.State(**kwargs)
    assert field_of(exc) == field
    assert isinstance(exc.value, avp.AvpError) and isinstance(exc.value, ValueError)


def test_target_rotation_must_be_orthonormal_and_proper() -> None:
    with pytest.raises(avp.ConfigError, match="orthonormal") as exc:
        avp.PerchTarget([0, 0, 0], np.diag([1.0, 2.0, 1.0]))
    assert field_of(exc) == "target.R_WS"
    with pytest.raises(avp.ConfigError, match="determinant"):
        avp.PerchTarget([0, 0, 0], np.diag([1.0, 1.0, -1.0]))
    with pytest.raises(avp.ConfigError) as exc:
        avp.PerchTarget.from_normal([0, 0, 0], [0, 0, 0])
    assert field_of(exc) == "target.normal"
    with pytest.raises(avp.ConfigError) as exc:
        avp.PerchTarget.from_incline([0, 0, 0], math.radians(200))
    assert field_of(exc) == "target.incline"


def test_from_incline_geometry() -> None:
    for inc in np.radians([0, 30, 60, 90, 135, 180]):
        t = avp.PerchTarget.from_incline([1, 2, 3], inc, heading=0.3)
        assert math.isclose(t.incline, inc, abs_tol=1e-9)
        assert abs(t.s2[2]) < 1e-12  # s2 horizontal
        assert np.allclose(t.R_WS.T @ t.R_WS, np.eye(3))
        h = np.array([math.cos(0.3), math.sin(0.3), 0])
        assert t.s3 @ h <= 1e-12  # faces the approaching vehicle
        if 0 < inc < math.pi:
            assert t.s1[2] > 0  # up-slope


@pytest.mark.parametrize(
    "kwargs, field",
    [
        ({"thrust_min": 5.0, "thrust_max": 4.0}, "limits.thrust_min"),
        ({"thrust_min": 4.0, "thrust_max": 4.0}, "limits.thrust_min"),
        ({"mass": 0.0}, "limits.mass"),
        ({"thrust_max": float("nan")}, "limits.thrust_max"),
        ({"body_rate_max": -1.0}, "limits.body_rate_max"),
    ],
)
def test_limits_validation(kwargs, field) -> None:
    with pytest.raises(avp.ConfigError) as exc:
        avp.VehicleLimits(**kwargs)
    assert field_of(exc) == field


@pytest.mark.parametrize(
    "kwargs, field",
    [
        ({"n_segments": 0}, "config.n_segments"),
        ({"degree": 5}, "config.degree"),
        ({"alpha": -1.0}, "config.alpha"),
        ({"dt": 0.0}, "config.dt"),
        ({"alpha": 50.0}, "config.alpha"),  # above thrust_max / mass
        ({"pre_impact": "paper"}, "config.pre_impact"),
    ],
)
def test_config_validation(kwargs, field) -> None:
    with pytest.raises(avp.ConfigError) as exc:
        avp.PlannerConfig(**kwargs)
    assert field_of(exc) == field


def test_target_at_start_point_is_rejected() -> None:
    sc = standard(90, 3.5)
    with pytest.raises(avp.ConfigError, match="away from the vehicle") as exc:
        avp.plan(avp.State.hover(sc.target.point), sc.target)
    assert field_of(exc) == "target.point"


@pytest.mark.parametrize("durations", [[0.5, -0.1, 0.5], [0.5, 0.5], [0.5, np.nan, 0.5], [0.0, 1, 1]])
def test_bad_durations(durations) -> None:
    sc = standard(90, 3.5)
    with pytest.raises(avp.ConfigError) as exc:
        avp.plan(sc.state, sc.target, durations=durations)
    assert field_of(exc) == "durations"


def test_wrong_argument_types() -> None:
    sc = standard(90, 3.5)
    with pytest.raises(avp.ConfigError) as exc:
        avp.plan([0, 0, 0], sc.target)  # type: ignore[arg-type]
    assert field_of(exc) == "state"
    with pytest.raises(avp.ConfigError) as exc:
        avp.plan(sc.state, sc.target, {"alpha": 4})  # type: ignore[arg-type]
    assert field_of(exc) == "config"


def _pinned_band_config(**kw) -> avp.PlannerConfig:
    """One degree-7 segment whose band (14) has zero width (q = 0, no floor): the degree-5
    acceleration must equal c0 at 15 samples, hence everywhere, contradicting a(t0) = 0."""
    return avp.PlannerConfig(n_segments=1, q=0.0, band_min_width=0.0, **kw)


def test_infeasible_is_a_result_and_plan_raises_with_it() -> None:
    sc = standard(90, 3.5)
    config = _pinned_band_config(bounds=avp.BoundsPolicy(relaxations=()))
    result = avp.plan_detailed(sc.state, sc.target, config)
    assert not result.ok and result.trajectory is None
    assert result.status is avp.PlanStatus.INFEASIBLE
    with pytest.raises(avp.InfeasibleError) as exc:
        avp.plan(sc.state, sc.target, config)
    assert exc.value.result is not None and exc.value.result.status is result.status


def test_relaxations_are_applied_in_order_and_reported() -> None:
    """The same problem becomes feasible once the band is widened (alpha range) or dropped;
    the result lists the relaxations, a prefix of the policy's order, and the log says why."""
    sc = standard(90, 3.5)
    config = _pinned_band_config()
    result = avp.plan_detailed(sc.state, sc.target, config)
    assert result.status is avp.PlanStatus.SOLVED_RELAXED and result.ok
    order = avp.BoundsPolicy().relaxations
    assert 1 <= len(result.relaxations) and result.relaxations == order[: len(result.relaxations)]
    for relaxation in result.relaxations:
        assert f"relaxing: {relaxation.value} (the workspace limits stay)" in result.log
    # the trajectory remembers it, plan() refuses it unless asked
    prov = result.trajectory.provenance
    assert prov is not None and prov.relaxations == tuple(r.name for r in result.relaxations)
    assert "RELAXED" in repr(result.trajectory)
    with pytest.raises(avp.RelaxedPlanError) as exc:
        avp.plan(sc.state, sc.target, config)
    assert exc.value.result.status is avp.PlanStatus.SOLVED_RELAXED
    traj = avp.plan(sc.state, sc.target, config, allow_relaxed=True)
    assert traj.provenance is not None and traj.provenance.relaxed


@pytest.mark.parametrize("error", [
    avp.ConfigError("limits.thrust_max", "must be finite"),
    avp.PlanningError("no plan"),
    avp.InfeasibleError("infeasible"),
    avp.SolverError("back-end failed"),
])
def test_errors_survive_pickling(error) -> None:
    # pool and Ray workers return a trial's error by pickle
    import pickle

    again = pickle.loads(pickle.dumps(error))
    assert type(again) is type(error)
    assert str(again) == str(error) and again.args == error.args
    if isinstance(error, avp.ConfigError):
        assert (again.field, again.message) == (error.field, error.message)


@pytest.mark.parametrize("make, field", [
    # enum members given as their names: before, accepted and silently ignored (no relaxation ran)
    (lambda: avp.BoundsPolicy(relaxations=("free_slide",)), "bounds.relaxations[0]"),
    (lambda: avp.BoundsPolicy(time_search="paper"), "bounds.time_search"),
    (lambda: avp.BoundsPolicy(relaxations="nope"), "bounds.relaxations"),
    (lambda: avp.BoundsPolicy(factors=(1.2, "x")), "bounds.factors[1]"),
    # nested configuration of the wrong type: before, a bare AttributeError deep in planning
    (lambda: avp.PlannerConfig(limits={"mass": 0.5}), "config.limits"),
    (lambda: avp.PlannerConfig(contact_velocity={"normal": -0.3}), "config.contact_velocity"),
    (lambda: avp.PlannerConfig(fov=None), "config.fov"),
    (lambda: avp.PlannerConfig(time_allocation=None), "config.time_allocation"),
    (lambda: avp.PlannerConfig(bounds="x"), "config.bounds"),  # was an AttributeError on .certify
    (lambda: avp.PlannerConfig(bounds=None, workspace="x"), "config.bounds"),
    (lambda: avp.PlannerConfig(alpha_range=5.0), "config.alpha_range"),
    (lambda: avp.PlannerConfig(alpha_range=("a", 6.0)), "config.alpha_range"),
    (lambda: avp.Workspace(half_spaces=avp.HalfSpace(point=[0, 0, 3], normal=[0, 0, -1])), "workspace.half_spaces"),
    (lambda: avp.Workspace(spheres=avp.Sphere(center=[1, 0, 1], radius=0.2)), "workspace.spheres"),
    # numbers as strings or bools: before, validated and then stored as given
    (lambda: avp.VehicleLimits(mass="0.5"), "limits.mass"),
    (lambda: avp.VehicleLimits(mass=True), "limits.mass"),
    (lambda: avp.VehicleLimits(mass=np.True_), "limits.mass"),  # NumPy's bool: float() took it as 1.0
    (lambda: avp.VehicleLimits(thrust_min=np.False_), "limits.thrust_min"),
    (lambda: avp.ReplanConfig(latency=np.bool_(True)), "replan.latency"),
    (lambda: avp.VehicleLimits(mass=np.array(True)), "limits.mass"),  # a 0-d boolean array too
    (lambda: avp.VehicleLimits(thrust_min="1"), "limits.thrust_min"),
    (lambda: avp.VehicleLimits(tilt_rate_max="10"), "limits.tilt_rate_max"),
    (lambda: avp.ReplanConfig(latency="0.02"), "replan.latency"),
    # the replanner's configurations in the wrong places: before, a bare AttributeError
    (lambda: avp.Replanner(standard(90.0, 3.5).target, avp.ReplanConfig()), "config"),
    (lambda: avp.Replanner(standard(90.0, 3.5).target, replan={"latency": 0.02}), "replan"),
])
def test_configuration_objects_check_their_types(make, field) -> None:
    with pytest.raises(avp.ConfigError) as exc:
        make()
    assert exc.value.field == field


def _simulator_settings():
    from avp.sim.camera import CameraParams
    from avp.sim.contact import PerchPad
    from avp.sim.line_run import LineCriteria, LineDetector, LineScenario
    from avp.sim.odometry import OdometryNoise
    from avp.sim.platform import PlatformNoise
    from avp.sim.run import PlatformMotion

    line = avp.LineTarget.segment([0.0, 0.0, 1.0], [1.0, 0.0, 1.0])
    return [
        (lambda: CameraParams(rate_hz="30"), "camera.rate_hz"),
        (lambda: CameraParams(min_range=None), "camera.min_range"),
        (lambda: CameraParams(dropout=True), "camera.dropout"),
        (lambda: CameraParams(latency=-0.01), "camera.latency"),
        (lambda: OdometryNoise(sigma_p="0.01"), "odometry.sigma_p"),
        (lambda: OdometryNoise(rate_hz=None), "odometry.rate_hz"),
        (lambda: PlatformNoise(sigma_heading="0.1"), "platform_noise.sigma_heading"),
        (lambda: PlatformMotion(speed=None), "scenario.platform.speed"),
        (lambda: PlatformMotion(window="1"), "scenario.platform.window"),
        (lambda: LineDetector(sigma="0"), "detector.sigma"),
        (lambda: LineCriteria(gripper=-0.01), "criteria.gripper"),
        (lambda: LineCriteria(angle=math.nan), "criteria.angle"),
        (lambda: LineCriteria(angle=4.0), "criteria.angle"),
        (lambda: LineCriteria(speed="0.3"), "criteria.speed"),
        (lambda: LineCriteria(clearance=-0.02), "criteria.clearance"),
        (lambda: LineScenario(line, [-3.0, 0.0, 1.0], initial_frames="3"), "scenario.initial_frames"),
        (lambda: LineScenario(line, [-3.0, 0.0, 1.0], initial_frames=10**6), "scenario.initial_frames"),
        (lambda: LineScenario(line, [-3.0, 0.0, 1.0], replan_rate_hz=None), "scenario.replan_rate_hz"),
        (lambda: LineScenario(line, 1.0), "scenario.start"),
        (lambda: PerchPad([0.0, 0.0, 1.0], np.eye(3), half_size="0.15"), "pad.half_size"),
    ]


@pytest.mark.parametrize("index", range(20))
def test_simulator_settings_refuse_wrong_types_with_config_errors(index) -> None:
    """The simulator's noise, camera, platform, line and pad settings were checked with
    ``math.isfinite`` / ``np.isfinite`` or comparisons: a string or ``None`` was a TypeError, a
    boolean or a string that compared was taken, and the line criteria were not checked."""
    settings = _simulator_settings()
    assert len(settings) == 20
    make, field = settings[index]
    with pytest.raises(avp.ConfigError) as exc:
        make()
    assert exc.value.field == field


def test_simulator_settings_are_stored_as_floats() -> None:
    from avp.sim.line_run import LineCriteria, LineScenario
    from avp.sim.odometry import OdometryNoise

    assert type(OdometryNoise(sigma_p=np.float32(0.5)).sigma_p) is float
    c = LineCriteria(gripper=1, angle=math.pi, speed=math.inf, clearance=0)
    assert (c.gripper, c.angle, c.speed, c.clearance) == (1.0, math.pi, math.inf, 0.0) and type(c.gripper) is float
    sc = LineScenario(avp.LineTarget.segment([0.0, 0.0, 1.0], [1.0, 0.0, 1.0]), (-3, 0, 1), initial_frames=np.int64(100))
    assert sc.initial_frames == 100 and sc.start.tolist() == [-3.0, 0.0, 1.0]


def _switch_configs():
    """``{configuration class: (field prefix, constructor taking keyword arguments)}``."""
    from avp.line_planner import LineOptions
    from avp.moving import MovingConfig
    from avp.platform import MovingTarget
    from avp.sim.controller import ControllerGains
    from avp.sim.evaluate import SimConfig
    from avp.sim.platform import MovingSimScenario
    from avp.sim.run import SimScenario
    from avp.sim.vehicle import VehicleParams

    pad = MovingTarget(point=[0.0, 0.0, 1.0], R_WS=np.eye(3), heading=0.0, speed=1.0)
    plain = [(avp.ContactVelocity, "contact_velocity"), (avp.OverhangFlip, "flip"), (avp.BoundsPolicy, "bounds"),
             (avp.Workspace, "workspace"), (avp.FovConfig, "fov"), (avp.ReplanConfig, "replan"),
             (LineOptions, "options"), (MovingConfig, "moving"), (SimConfig, "sim"), (SimScenario, "scenario"),
             (VehicleParams, "vehicle"), (ControllerGains, "gains")]
    out = {cls: (prefix, cls) for cls, prefix in plain}
    out[MovingSimScenario] = ("scenario", lambda **kw: MovingSimScenario(pad, **kw))
    return out


def _dataclasses_with_switches():
    """Every dataclass of the package with an ``__init__`` field annotated ``bool``, and whether
    it can be built without arguments (the configurations can; the result records cannot)."""
    import dataclasses
    import importlib
    import pkgutil

    found = {}
    for info in pkgutil.walk_packages(avp.__path__, "avp."):
        if info.name.endswith("__main__"):
            continue
        for obj in vars(importlib.import_module(info.name)).values():
            if isinstance(obj, type) and dataclasses.is_dataclass(obj) and any(
                    f.init and f.type in ("bool", bool) for f in dataclasses.fields(obj)):
                try:
                    obj()
                    found[obj] = True
                except (TypeError, avp.AvpError):
                    found[obj] = False
    return found


def test_switches_take_only_true_or_false() -> None:
    """Every ``bool`` field of the configuration dataclasses refuses a value whose truth would
    silently switch it (``allow_relaxed="no"`` allowed relaxed plans), naming the field; a
    NumPy boolean is stored as Python's. Every dataclass with switches that builds without
    arguments (a configuration) is among those checked."""
    import dataclasses

    configs = _switch_configs()
    scanned = _dataclasses_with_switches()
    assert {cls for cls, default in scanned.items() if default} <= set(configs)
    for cls, (prefix, make) in configs.items():
        switches = [f.name for f in dataclasses.fields(cls) if f.init and f.type in ("bool", bool)]
        assert switches, cls
        for name in switches:
            for bad in ("no", 0, 1, None, 0.0, np.array(True)):
                with pytest.raises(avp.ConfigError) as exc:
                    make(**{name: bad})
                assert exc.value.field == f"{prefix}.{name}" and "True or False" in exc.value.message
            flipped = not getattr(make(), name)
            made = make(**{name: np.bool_(flipped)})
            assert type(getattr(made, name)) is bool and getattr(made, name) is flipped


def test_checked_numbers_are_stored_as_floats() -> None:
    lim = avp.VehicleLimits(mass=1, thrust_max=20, thrust_min=0, tilt_rate_max=10)
    assert all(type(getattr(lim, n)) is float for n in ("mass", "thrust_max", "thrust_min", "tilt_rate_max"))
    bounds = avp.BoundsPolicy(relaxations=[avp.config.Relaxation.FREE_SLIDE], factors=[1.2, 2])
    assert bounds.relaxations == (avp.config.Relaxation.FREE_SLIDE,) and bounds.factors == (1.2, 2.0)
    assert all(type(f) is float for f in bounds.factors)


def test_value_types_compare_and_hash_by_value() -> None:
    """``State``, ``PerchTarget`` (and ``MovingTarget``, ``LineTarget``) hold arrays: ``==`` raised
    "truth value of an array is ambiguous" and ``hash`` a TypeError, so ``if estimate !=
    last_estimate`` crashed. Now equal fields (arrays element-wise) make equal objects."""
    import dataclasses

    from avp.platform import MovingTarget

    t = standard(90.0, 3.5).target
    same = avp.PerchTarget(point=t.point.copy(), R_WS=t.R_WS.copy())
    moved = avp.PerchTarget(point=t.point + [0.0, 0.0, 1e-9], R_WS=t.R_WS)
    assert t == same and hash(t) == hash(same) and len({t, same}) == 1
    assert t != moved and not (t == moved)
    s = avp.State.hover([0.0, 0.0, 1.0])
    assert s == avp.State.hover([0.0, 0.0, 1.0]) and s != avp.State.hover([0.0, 0.0, 1.0], yaw=0.1)
    assert s != t and (s == 3) is False
    m = MovingTarget(point=t.point, R_WS=t.R_WS, heading=0.1, speed=1.0)
    assert m == MovingTarget(point=t.point, R_WS=t.R_WS, heading=0.1, speed=1.0)
    assert m != dataclasses.replace(m, speed=2.0) and m != same  # the platform state counts, and the type
    line = avp.LineTarget(vertices=[[0.0, 0.0, 2.0], [4.0, 0.0, 2.0]])
    assert line == avp.LineTarget(vertices=[[0.0, 0.0, 2.0], [4.0, 0.0, 2.0]])
    assert avp.State.hover([0.0, 0.0, -0.0]) == avp.State.hover([0.0, 0.0, 0.0])
    assert hash(avp.State.hover([0.0, 0.0, -0.0])) == hash(avp.State.hover([0.0, 0.0, 0.0]))


# -- magnitudes and sizes that are not a flight: typed errors, fast, not overflows or hangs ---------

_S = avp.State.hover([0.0, 0.0, 1.5])
_T = avp.PerchTarget.from_incline([3.5, 0.0, 1.5], math.pi / 2)


@pytest.mark.parametrize(
    "make, field",
    [
        (lambda: avp.State.hover([0.0, 0.0, 1.5], time=1e14), "state.time"),  # float64 knots lose the ms
        (lambda: avp.State(position=[0.0, 0.0, 1.0], velocity=[1e300, 0.0, 0.0]), "state.velocity"),
        (lambda: avp.State(position=[2e6, 0.0, 1.0]), "state.position"),
        (lambda: avp.PerchTarget.from_incline([1e300, 0.0, 1.5], math.pi / 2), "target.point"),
        (lambda: avp.PlannerConfig(n_segments=200), "config.n_segments"),
        (lambda: avp.PlannerConfig(cone_facets=10**7), "config.cone_facets"),
        (lambda: avp.PlannerConfig(dt=1.0), "config.dt"),  # the band (14) would have no sample
        (lambda: avp.PlannerConfig(dt=1e-7), "config.dt"),  # 1.5 million band samples
        (lambda: avp.PlannerConfig(dt=1e-300), "config.dt"),
        (lambda: avp.Workspace(samples_per_segment=10**8), "workspace.samples_per_segment"),
        (lambda: avp.ReplanConfig(retime_fraction=math.nan), "replan.retime_fraction"),
        (lambda: avp.ReplanConfig(retime_fraction=1.5), "replan.retime_fraction"),
        (lambda: avp.LineOptions(guide_dt=1e-9), "options.guide_dt"),
        (lambda: avp.plan(_S, _T).sample(1e-9), "dt"),
        (lambda: avp.plan(_S, _T).sample(0.0), "dt"),
        (lambda: avp.plan(_S, _T).to_json(rate=1e9), "rate"),
        (lambda: avp.plan(_S, _T).thrust(0.5, mass=-1.0), "mass"),
        (lambda: avp.Trajectory(np.zeros((3, 4, 8)), [0.0, 1.0, 2.0, 3.0], g=math.nan), "g"),
        (lambda: avp.Trajectory(np.zeros((0, 4, 8)), [0.0]), "coefficients"),
        (lambda: avp.plan(_S, _T, allow_relaxed="no"), "allow_relaxed"),
        (lambda: avp.plan_detailed(_S, _T, warm_start="x"), "warm_start"),
        (lambda: avp.plan_detailed(_S, _T, durations=[1e300] * 3), "durations"),  # was OverflowError
        (lambda: avp.TimeAllocation(min_duration=1e300), "time_allocation.min_duration"),
        (lambda: avp.TimeAllocation(attitude_time="x"), "time_allocation.attitude_time"),  # was TypeError
        (lambda: avp.BoundsPolicy(factors=(1e300,)), "bounds.factors[0]"),
        (lambda: avp.BoundsPolicy(growth=1e300), "bounds.growth"),
        (lambda: avp.BoundsPolicy(max_steps=1.5), "bounds.max_steps"),  # was TypeError when planning
        (lambda: avp.MovingTarget.on_platform([0, 0, 1], incline=0.5, speed=1.0, turn_rate=1e300), "target.turn_rate"),
        (lambda: avp.LineOptions(recovery_distance=1e300), "options.recovery_distance"),
        (lambda: avp.PlannerConfig(degree=2, position_cost_order=1, yaw_cost_order=1, continuity_order=1),
         "config.degree"),  # was IndexError when planning
        (lambda: avp.PlannerConfig(continuity_order=0), "config.continuity_order"),  # jumps at knots, "certified"
        (lambda: avp.PlannerConfig(limits=avp.VehicleLimits(thrust_max=3.0)), "limits.thrust_max"),  # cannot hover
        (lambda: avp.PlannerConfig(solver_options=3), "config.solver_options"),  # was SolverError when planning
        (lambda: avp.plan(_S, _T, avp.PlannerConfig(solver="osqp", solver_options={"foo": 1})),
         "config.solver_options"),  # OSQP's own words: "Unrecognized settings ['foo']"
        (lambda: avp.plan(_S, _T, avp.PlannerConfig(solver="proxqp", solver_options={"foo": 1})),
         "config.solver_options"),  # ProxQP lists the keywords it was given
        (lambda: avp.PlannerConfig(degree=3, position_cost_order=2, yaw_cost_order=2), "config.degree"),
        (lambda: avp.plan_moving(avp.State(position=[3, 0, 1], velocity=[2, 0, 0]),
                                 avp.MovingTarget.on_platform([0, 0, 1], incline=0.5, speed=2)),
         "state.position"),  # behind the moving pad: was WorkspaceNotCertifiedError after solving
        (lambda: avp.PlannerConfig(solver_options=(("eps",),)), "config.solver_options"),
        (lambda: avp.plan(_S, _T, avp.PlannerConfig(solver_options={"no_such_setting": 1})),
         "config.solver_options"),  # was SolverError "unexpected keyword argument"
        # wrong types and sizes that raised raw TypeError / AttributeError / KernelError / OSError
        (lambda: avp.metrics.visibility(avp.plan(_S, _T), avp.LineTarget.segment([0, 0, 1], [1, 0, 1])), "target"),
        (lambda: avp.metrics.visibility(avp.plan(_S, _T), _T, camera="x"), "camera"),
        (lambda: avp.metrics.visibility("x", _T), "trajectory"),
        (lambda: avp.FovConfig(n_points=100000), "fov.n_points"),
        (lambda: avp.plan(_S, _T)(0.5, 100), "order"),
        (lambda: avp.plan(_S, _T)("x"), "t"),
        (lambda: avp.Trajectory.from_json(None), "source"),
        (lambda: avp.Trajectory.from_json("[]"), "source"),  # a path (only "{" starts JSON text): not found
        (lambda: avp.OverhangFlip(min_incline="x"), "flip.min_incline"),
        (lambda: avp.Workspace(body_offset="x"), "workspace.body_offset"),
        (lambda: avp.PlannerConfig(q="x"), "config.q"),
        (lambda: avp.ReplanConfig(partial_fractions=None), "replan.partial_fractions"),
        (lambda: avp.LineOptions(flip_window=None), "options.flip_window"),
        (lambda: avp.LineTarget.segment([0, 0, 1], [1, 0, 1], grasp_range=None), "line.grasp_range"),
        (lambda: avp.moving.MovingConfig(max_duration=1e-300), "moving.max_duration"),  # was "coefficients: NaN"
        (lambda: avp.VehicleLimits(thrust_max=1e300), "limits.thrust_max"),  # was about an alpha_range never set
        (lambda: avp.MovingReplanner(avp.MovingTarget.on_platform([0, 0, 1], incline=0.5, speed=1.0), moving="x"),
         "moving"),  # was caught only at the first step
        (lambda: avp.LineReplanner(avp.LineTarget.segment([0, -1, 1], [0, 1, 1]), options="x"), "options"),
        (lambda: avp.plan_line(_S, avp.LineTarget.segment([3, -1.5, 2.5], [3, 1.5, 2.5]), perch_search="no"),
         "perch_search"),
        (lambda: avp.State(position=[True, 0.0, 1.0]), "state.position"),
        # coordinates and sizes of the world beyond a flight (overflow warnings, then a wrong field or
        # INFEASIBLE): the line's vertices said "duration: ... inf"
        (lambda: avp.plan_line(_S, avp.LineTarget.segment([3, -1.5, 2.5], [3, 1.5, 1e300])), "line.vertices"),
        (lambda: avp.LineTarget.segment([3, -1.5, 2.5], [3, 1.5, 2.5], gripper_offset=1e300), "line.gripper_offset"),
        (lambda: avp.Sphere(center=[1e300, 0.0, 0.0], radius=0.3), "workspace.spheres.center"),
        (lambda: avp.Sphere(center=[0.0, 0.0, 0.0], radius=1e300), "workspace.spheres.radius"),
        (lambda: avp.HalfSpace(point=[0.0, 0.0, 1e300], normal=[0.0, 0.0, -1.0]), "workspace.half_spaces.point"),
        (lambda: avp.Workspace(ground_z=-1e300), "workspace.ground_z"),
        (lambda: avp.Workspace(body_offset=1e300), "workspace.body_offset"),
        (lambda: avp.LineOptions(recovery_point=[0.0, 0.0, 1e300]), "options.recovery_point"),
        # a body-rate certificate beyond the kernel's degree 40 (it raised mid-plan)
        (lambda: avp.PlannerConfig(degree=12, limits=avp.VehicleLimits(body_rate_max=10.0)), "config.degree"),
        (lambda: avp.PlannerConfig(degree=11, limits=avp.VehicleLimits(body_rate_max=10.0, rotor_drag=0.3)),
         "config.degree"),
    ],
)
def test_unphysical_sizes_are_typed_errors(make, field) -> None:
    with pytest.raises(avp.ConfigError) as exc:
        make()
    assert field_of(exc) == field


def test_the_band_keeps_its_samples_while_dt_is_valid() -> None:
    """dt up to t_k still gives the band (14) a sample: a plan with it differs from one without
    the band (before, dt > 2 t_k silently dropped every sample and still said SOLVED)."""
    cfg = avp.PlannerConfig(dt=0.15)
    assert cfg.band_samples == 1
    on = avp.plan_detailed(_S, _T, cfg)
    off = avp.plan_detailed(_S, _T, avp.PlannerConfig(dt=0.15, pre_impact=avp.PreImpactMode.OFF))
    assert on.ok and not np.array_equal(on.trajectory.coefficients, off.trajectory.coefficients)


def test_a_coarse_visibility_grid_still_samples_both_ends() -> None:
    """dt far beyond the plan: the grid is its two ends (it was empty: argmax of nothing)."""
    traj = avp.plan(_S, _T)
    assert np.array_equal(traj.sample(1e300), [traj.t0, traj.tf])
    vis = avp.metrics.visibility(traj, _T, dt=1e300)
    assert 0.0 <= vis.time_fraction <= 1.0 and 0.0 <= vis.path_fraction <= 1.0


def test_huge_vectors_are_normalised_without_overflow() -> None:
    assert np.allclose(avp.HalfSpace(point=(0, 0, 0), normal=[1e200, 1e200, 0]).normal, [0.5**0.5, 0.5**0.5, 0])
    line = avp.LineTarget(vertices=[[3, -2, 1.5], [3, 2, 1.5]], side=[-1e200, 0, 0], pitch=1.0)
    assert np.array_equal(line.side, [-1.0, 0.0, 0.0])


def test_a_warm_start_too_large_to_fit_is_dropped_not_iterated() -> None:
    """A finite but absurd warm start (coefficients 1e300): its fit overflows, so it is not
    handed to the iterative back-end (it stalled proxqp for minutes); the log says so."""
    if "proxqp" not in avp.solve.available_solvers():
        pytest.skip("proxqp is not installed")
    wild = avp.Trajectory(np.full((3, 4, 8), 1e300), [0.0, 1.0, 2.0, 3.0])
    res = avp.plan_detailed(_S, _T, avp.PlannerConfig(solver="proxqp"), warm_start=wild)
    assert res.ok and any(line.startswith("warm start not used") for line in res.log)


def test_a_json_file_that_is_not_an_object_is_a_typed_error(tmp_path) -> None:
    path = tmp_path / "list.json"
    path.write_text("[1, 2]")
    with pytest.raises(avp.ConfigError) as exc:
        avp.Trajectory.from_json(path)
    assert field_of(exc) == "json"


def test_relaxing_to_the_cone_band_keeps_a_valid_dt() -> None:
    """dt is checked whatever pre_impact is: a relaxation that turns the band on mid-search
    (CONE_BAND) cannot meet a dt that gives it no sample (it raised from inside the search)."""
    with pytest.raises(avp.ConfigError) as exc:
        avp.PlannerConfig(pre_impact=avp.PreImpactMode.OFF, dt=1.0)
    assert field_of(exc) == "config.dt"


def test_whole_number_float_orders_still_evaluate() -> None:
    traj = avp.plan(_S, _T)
    assert np.array_equal(traj(0.5, 1.0), traj(0.5, 1))
    assert np.array_equal(traj.derivatives(0.5, np.arange(3.0)), traj.derivatives(0.5, (0, 1, 2)))


def test_a_default_moving_plan_logs_no_unused_setting() -> None:
    pad = avp.MovingTarget.on_platform([0.0, 0.0, 1.0], incline=0.5, speed=1.0)
    res = avp.moving.plan_moving_detailed(avp.State(position=[-3.0, 0.0, 1.0], velocity=pad.velocity), pad)
    assert not any(line.startswith("config:") for line in res.log)


def test_broken_export_files_are_typed_errors(tmp_path) -> None:
    """A CSV row longer than its header (was read as a higher degree), a non-number field, a
    file that is not an NPZ and a single .npy array: ConfigError naming the path."""
    traj = avp.plan(_S, _T)
    good = traj.to_csv(tmp_path / "plan.csv")
    lines = good.read_text().splitlines()
    for broken in (lines[:2] + [lines[2] + ",0.0"] + lines[3:], lines[:2] + [lines[2].replace(lines[2].split(",")[-1], "x")] + lines[3:]):
        bad = tmp_path / "bad.csv"
        bad.write_text("\n".join(broken) + "\n")
        with pytest.raises(avp.ConfigError) as exc:
            avp.Trajectory.from_csv(bad)
        assert field_of(exc) == "path"
    assert np.array_equal(avp.Trajectory.from_csv(good).coefficients, traj.coefficients)
    junk = tmp_path / "junk.npz"
    junk.write_bytes(b"not a zip file at all")
    single = tmp_path / "single.npy"
    np.save(single, np.zeros(3))
    for path in (junk, single):
        with pytest.raises(avp.ConfigError) as exc:
            avp.Trajectory.from_npz(path)
        assert field_of(exc) == "path"


def test_a_degree_beyond_the_body_rate_kernel_plans_when_nothing_is_certified() -> None:
    """The degree refusal (a body-rate certificate past the kernel's degree 40) is about the
    certificate: without one the static planner still plans; the moving planner, which always
    certifies, says so at its certificate."""
    cfg = avp.PlannerConfig(degree=12, limits=avp.VehicleLimits(body_rate_max=10.0),
                            bounds=avp.BoundsPolicy(certify=False))
    assert avp.plan_detailed(_S, _T, cfg).trajectory is not None
    pad = avp.MovingTarget.on_platform([0.0, 0.0, 1.0], incline=0.5, speed=2.0)
    with pytest.raises(avp.ConfigError) as exc:
        avp.moving.plan_moving_detailed(avp.State(position=[-3.0, 0.0, 1.0], velocity=[2.0, 0.0, 0.0]), pad, cfg)
    assert field_of(exc) == "config.degree"


@pytest.mark.parametrize("make,field", [
    (lambda: avp.PlannerConfig(degre=7), "config.degre"),
    (lambda: avp.VehicleLimits(mas=1.0), "limits.mas"),
    (lambda: avp.State(positon=[0.0, 0.0, 1.0]), "state.positon"),
    (lambda: avp.LineTarget(vertices=[[0.0, 0.0, 1.0], [1.0, 0.0, 1.0]], pich=1.0), "line.pich"),
    (lambda: avp.ReplanConfig(latancy=0.1), "replan.latancy"),
    (lambda: avp.Workspace(ground=0.0), "workspace.ground"),
    (lambda: __import__("avp.sim.run", fromlist=["SimScenario"]).SimScenario(distanse=2.0), "scenario.distanse"),
    (lambda: __import__("avp.sim.vehicle", fromlist=["VehicleParams"]).VehicleParams(mas=1.0), "vehicle.mas"),
])
def test_a_misspelt_setting_is_a_config_error_naming_it(make, field) -> None:
    """A keyword a public dataclass does not take was Python's TypeError; it is a ConfigError on
    the keyword that lists the settings. Valid keywords, replace() and pickling are unchanged."""
    import pickle

    with pytest.raises(avp.ConfigError) as exc:
        make()
    assert exc.value.field == field and "setting" in str(exc.value)
    cfg = dataclasses.replace(avp.PlannerConfig(), degree=8)
    assert cfg.degree == 8 and pickle.loads(pickle.dumps(cfg)) == cfg


_ENTRY = st.one_of(st.floats(allow_nan=True, allow_infinity=True, width=64),
                   st.sampled_from([0.0, -0.0, 1e300, -1e300, 1e7, 999_999.0, 1e6, math.nan, math.inf]))


@settings(max_examples=400, deadline=None)
@given(st.lists(_ENTRY, min_size=1, max_size=20), st.sampled_from(sorted(LIMITS)))
def test_the_validators_small_array_paths_decide_as_numpy(entries, kind) -> None:
    """The Python loops ``within`` and ``frozen_array`` take on small float arrays (and floats)
    refuse exactly what NumPy's reductions refuse: ``max |x| > limit`` with NaN propagating
    (never a refusal by ``within``), and any non-finite entry."""
    arr = np.array(entries)
    limit = LIMITS[kind][0]
    for value in (arr, arr.reshape(1, -1), float(entries[0])):
        numpy_refuses = bool(float(np.max(np.abs(value))) > limit)
        try:
            _validate.within("x", value, kind)
        except avp.ConfigError:
            refused = True
        else:
            refused = False
        assert refused == numpy_refuses
    assert _validate._all_finite(arr) == bool(np.isfinite(arr).all())


@settings(max_examples=300, deadline=None)
@given(st.lists(st.floats(-2.0, 2.0), min_size=9, max_size=9))
@example([0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0, 2.2250738585e-313, 0.0])  # a subnormal pivot for np.linalg.det
def test_the_rotation_check_decides_as_numpy(entries) -> None:
    """``rotation`` (a Python determinant) accepts exactly the matrices NumPy's
    ``R^T R - I`` and ``det`` accept, away from the tolerance's edge; rotations always pass."""
    R = np.array(entries).reshape(3, 3)
    err = float(np.max(np.abs(R.T @ R - np.eye(3))))
    with np.errstate(all="ignore"):  # the oracle's LU warns on a subnormal pivot (entries 2e-313)
        det = float(np.linalg.det(R))
    tol = _validate.ORTHONORMAL_TOL
    assume(abs(err - tol) > 1e-12 and abs(abs(det - 1.0) - tol) > 1e-12)
    try:
        _validate.rotation("R", R)
    except avp.ConfigError:
        accepted = False
    else:
        accepted = True
    assert accepted == (err <= tol and abs(det - 1.0) <= tol)
    q = np.array(entries[:4]) + [1e-3, 0.0, 0.0, 0.0]
    q /= np.linalg.norm(q)
    w, x, y, z = q
    Rq = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                   [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                   [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])
    assert np.array_equal(_validate.rotation("R", Rq), Rq)
    with pytest.raises(avp.ConfigError, match="determinant"):
        _validate.rotation("R", -Rq)


def _float_fields(cls):
    """(name, default) of the ``float`` fields of a dataclass with a finite default."""
    out = []
    for f in dataclasses.fields(cls):
        if f.type in ("float", "float | None") and isinstance(f.default, float) and math.isfinite(f.default):
            out.append((f.name, f.default))
    return out


_CONFIG_CLASSES = [avp.PlannerConfig, avp.FovConfig, avp.TimeAllocation, avp.OverhangFlip, avp.Workspace,
                   avp.ReplanConfig, avp.VehicleLimits, avp.ContactVelocity]


@pytest.mark.parametrize("cls", _CONFIG_CLASSES, ids=lambda c: c.__name__)
@pytest.mark.parametrize("kind", ["Decimal", "Fraction", "float32", "float64", "0-d array", "int"])
def test_a_real_number_of_another_type_is_stored_as_a_float(cls, kind) -> None:
    """A float setting given as a ``Decimal``, a ``Fraction``, a NumPy scalar, a 0-d array or an
    int is stored as the Python float it stands for: the planner's arithmetic (``float + Decimal``,
    hashing an array) then never meets it. The value kept is the default itself where the type
    can carry it exactly."""
    from decimal import Decimal
    from fractions import Fraction

    for name, default in _float_fields(cls):
        value = {"Decimal": Decimal(repr(default)), "Fraction": Fraction(default), "float32": np.float32(default),
                 "float64": np.float64(default), "0-d array": np.array(default), "int": round(default)}[kind]
        if kind == "int" and value == 0 and default != 0:
            continue  # a zero where the setting needs a positive number: refused, another test's business
        try:
            obj = cls(**{name: value})
        except avp.ConfigError:
            assert kind == "int", (name, value)  # an int can fall outside a setting's range
            continue
        stored = getattr(obj, name)
        assert type(stored) is float, (name, type(stored))
        assert stored == float(value)


def test_typed_keywords_follows_the_constructor_with_kw_only_fields_and_init_vars() -> None:
    """Positional arguments were matched to the init fields in declaration order: a ``kw_only``
    field declared between two float fields shifted the second onto it (a ``Decimal`` stored as
    given), and an ``InitVar`` (no field) shifted every later one and was refused as a keyword."""
    from decimal import Decimal

    @_validate.typed_keywords("demo")
    @dataclasses.dataclass
    class Demo:
        a: float = 0.0
        label: str = dataclasses.field(default="x", kw_only=True)
        b: float = 0.0

    d = Demo(Decimal("1.5"), Decimal("2.5"), label="y")
    assert (d.a, d.b, d.label) == (1.5, 2.5, "y") and type(d.b) is float

    @_validate.typed_keywords("demo")
    @dataclasses.dataclass
    class WithInitVar:
        name: str = "n"
        unit: dataclasses.InitVar[str] = "m"
        y: float = 0.0

        def __post_init__(self, unit: str) -> None:
            self.name = f"{self.name} [{unit}]"

    w = WithInitVar("n", "s", Decimal("0.25"))
    assert (w.name, w.y, type(w.y)) == ("n [s]", 0.25, float)
    assert WithInitVar(unit="km", y=np.float32(0.5)).name == "n [km]"
    with pytest.raises(avp.ConfigError, match=r"^demo.units: is not a WithInitVar setting; use one of 'name', 'unit', 'y'"):
        WithInitVar(units="km")
    with pytest.raises(TypeError, match="above @dataclass"):
        _validate.typed_keywords("demo")(type("Plain", (), {}))


def test_planning_and_replanning_take_settings_of_other_real_types() -> None:
    """Found by fuzzing: a 0-d array ``g`` made planning hash an array, a ``Decimal`` latency made
    the second replanning step add a float to a Decimal (a TypeError out of ``step``)."""
    from decimal import Decimal

    state, target = avp.State.hover([0.0, 0.0, 1.5]), avp.PerchTarget.from_incline([3.5, 0.0, 1.5], math.pi / 2)
    for cfg in (avp.PlannerConfig(g=np.array(9.81)), avp.PlannerConfig(t_k=Decimal("0.15")),
                avp.PlannerConfig(fov=avp.FovConfig(gate=Decimal("0.1")))):
        assert avp.plan_detailed(state, target, cfg).ok
    rp = avp.Replanner(target, replan=avp.ReplanConfig(latency=Decimal("0.02")))
    rp.step(0.0, state)
    assert rp.step(0.1, state).action is not None


@pytest.mark.parametrize("make, field", [
    (lambda: avp.State(position=[10**400, 0, 0]), "state.position"),
    (lambda: avp.VehicleLimits(mass=10**400), "limits.mass"),
    (lambda: avp.VehicleLimits(body_rate_max=10**400), "limits.body_rate_max"),
    (lambda: avp.PlannerConfig(t_k=10**400), "config.t_k"),
    (lambda: avp.ContactVelocity(slope=1e300), "contact_velocity.slope"),
    (lambda: avp.ContactVelocity(normal=-2e3), "contact_velocity.normal"),
])
def test_numbers_beyond_the_float_range_or_a_flight_are_refused(make, field) -> None:
    """Found by fuzzing: a huge int raised OverflowError; a contact velocity of 1e300 m/s passed
    the checks and overflowed in the planner's reachability test."""
    with pytest.raises(avp.ConfigError) as exc:
        make()
    assert field_of(exc) == field


@pytest.mark.parametrize("durations", [[True, 1, 1], np.array([True, True, True]), [[1, 1, 1]], [1, 1, 10**400]])
def test_durations_that_are_not_a_flat_list_of_numbers_are_refused(durations) -> None:
    state, target = avp.State.hover([0.0, 0.0, 1.5]), avp.PerchTarget.from_incline([3.5, 0.0, 1.5], math.pi / 2)
    with pytest.raises(avp.ConfigError) as exc:
        avp.plan_detailed(state, target, durations=durations)
    assert field_of(exc) == "durations"


@pytest.mark.parametrize("kwargs, field", [({"g": "x"}, "g"), ({"g": 0.0}, "g"), ({"g": -9.81}, "g"),
                                           ({"exact": "yes"}, "exact")])
def test_certify_spline_checks_g_and_exact(kwargs, field) -> None:
    """Found by fuzzing: ``g="x"`` raised a bare ValueError, ``exact="yes"`` a TypeError, and a
    zero or negative gravity was taken."""
    from avp.bounds import certify_spline

    c = np.zeros((1, 4, 8))
    with pytest.raises(avp.ConfigError) as exc:
        certify_spline(c, [0.0, 1.0], thrust_min=1.0, thrust_max=20.0, **kwargs)
    assert field_of(exc) == field


def test_more_fuzzed_inputs_are_typed_errors() -> None:
    """Second review of the fuzzing fixes: a signalling NaN Decimal, an inertia with a nested
    boolean or an int beyond the float range, NumPy booleans as a bias sign, a pad 1e12 m high,
    and export or sample rates so high that the count of samples overflows."""
    from decimal import Decimal

    from avp.sim.camera import CameraParams
    from avp.sim.evaluate import SimConfig
    from avp.sim.run import SimScenario
    from avp.sim.vehicle import VehicleParams

    cases = [
        (lambda: avp.PlannerConfig(q=Decimal("sNaN")), "config.q"),
        (lambda: VehicleParams(inertia=[[True, 0, 0], [0, 1e-3, 0], [0, 0, 1e-3]]), "vehicle.inertia"),
        (lambda: VehicleParams(inertia=[10**400, 1e-3, 1e-3]), "vehicle.inertia"),
        (lambda: SimConfig(camera_bias_sign=np.True_), "sim.camera_bias_sign"),
        (lambda: CameraParams(bias_sign=True), "camera.bias_sign"),
        (lambda: SimScenario(pad_height=1e12), "scenario.pad_height"),
    ]
    for make, field in cases:
        with pytest.raises(avp.ConfigError) as exc:
            make()
        assert field_of(exc) == field
    traj = avp.plan(avp.State.hover([0.0, 0.0, 1.5]), avp.PerchTarget.from_incline([3.5, 0.0, 1.5], math.pi / 2))
    from avp.export import sample_table

    with pytest.raises(avp.ConfigError) as exc:
        sample_table(traj, rate=1e308)
    assert field_of(exc) == "rate"
    with pytest.raises(avp.ConfigError) as exc:
        traj.sample(1e-308)
    assert field_of(exc) == "dt"
