"""Contact detection and success criterion of avp.sim.contact."""

from __future__ import annotations

import numpy as np
import pytest

from avp.errors import ConfigError
from avp.frames import expm_so3
from avp.sim import FlatReference, PerchPad, RigidBodyState, detect_contact, fly

WALL = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]]).T  # s1=e3, s2=e2, s3=-e1
PAD = PerchPad(p_W=[5.0, 0.0, 2.0], R_WS=WALL, half_size=0.15)


def crossing(tilt_deg=10.0, v=(0.3, 0.0, -2.0), y=0.06, z=1.88):
    """States 1 cm either side of the wall plane x = 5, the crossing half way (at t = 1.001 s)."""
    R = WALL @ expm_so3(np.deg2rad([0.0, tilt_deg, 0.0]))  # b3 tilted by tilt_deg about s2
    dp = 0.01 * np.array(v) / v[0]
    mid = np.array([5.0, y, z])
    return RigidBodyState(mid - dp, v, R), RigidBodyState(mid + dp, v, R)


def test_constructed_crossing_reports_point_angles_and_speeds():
    prev, new = crossing()
    c = detect_contact(prev, new, PAD, 1.0, 1.002)
    assert c.t == pytest.approx(1.001)
    np.testing.assert_allclose(c.p_S, [-0.12, 0.06, 0.0], atol=1e-12)  # (z - 2, y, 0)
    assert np.rad2deg(c.attitude_error) == pytest.approx(10.0)
    assert c.normal_speed == pytest.approx(0.3)
    np.testing.assert_allclose(c.v_tangential_S, [-2.0, 0.0], atol=1e-12)  # 2 m/s down the slope
    assert c.inside and c.success and c.failures == ()


@pytest.mark.parametrize(
    "kwargs, failure",
    [
        (dict(y=0.2), "outside_pad"),
        (dict(tilt_deg=20.0), "attitude"),
        (dict(v=(1.5, 0.0, -2.0)), "normal_speed"),
        (dict(v=(0.3, 0.0, -3.5)), "tangential_speed"),
    ],
)
def test_each_criterion_can_fail(kwargs, failure):
    c = detect_contact(*crossing(**kwargs), PAD, 1.0, 1.002)
    assert c is not None and not c.success and c.failures == (failure,)


def test_no_contact_without_a_crossing_from_the_front():
    prev, new = crossing()
    assert detect_contact(prev, prev, PAD, 0.0, 0.002) is None  # still in front
    assert detect_contact(new, prev, PAD, 0.0, 0.002) is None  # coming out from behind


def test_disc_pad_and_bad_pad():
    disc = PerchPad(p_W=[5.0, 0.0, 2.0], R_WS=WALL, half_size=0.15, shape="disc")
    c = detect_contact(*crossing(y=0.12, z=1.88), disc, 0.0, 0.002)  # corner of the square
    assert not c.inside and c.failures == ("outside_pad",)
    with pytest.raises(ConfigError, match="pad.R_WS"):
        PerchPad(p_W=np.zeros(3), R_WS=np.ones((3, 3)))


def test_fly_stops_at_contact_on_a_floor_pad():
    floor = PerchPad(p_W=np.zeros(3), R_WS=np.eye(3))

    def descend(t):  # 0.5 m/s straight down through the pad (the start is on the reference)
        z = np.zeros(3)
        return FlatReference([0.0, 0.0, 0.5 - 0.5 * t], [0.0, 0.0, -0.5], z, z, z)

    start = RigidBodyState(np.array([0.0, 0.0, 0.5]), v_W=[0.0, 0.0, -0.5])
    hook = lambda a, b, ta, tb: detect_contact(a, b, floor, ta, tb)
    res = fly(start, descend, 0.0, 3.0, stop=hook)
    c = res.event
    assert c is not None and res.t < 1.01
    assert c.t == pytest.approx(1.0, abs=1e-3)
    assert c.normal_speed == pytest.approx(0.5, abs=1e-3) and c.attitude_error < 1e-6
    assert c.success


def test_ground_crossing_is_a_crash_at_the_interpolated_time():
    from avp.sim.contact import GROUND, ground_contact
    prev = RigidBodyState([1.0, 2.0, 0.01], [1.0, 0.0, -3.0], np.eye(3))
    new = RigidBodyState([1.0, 2.0, -0.02], [1.0, 0.0, -3.0], np.eye(3))
    c = ground_contact(prev, new, 1.0, 1.003, ground_z=0.0)
    assert c is not None and c.failures == (GROUND,) and not c.success and not c.inside
    assert c.t == pytest.approx(1.001)
    np.testing.assert_allclose(c.p_W, [1.0, 2.0, 0.0], atol=1e-12)
    assert c.normal_speed == pytest.approx(3.0)
    assert ground_contact(prev, prev, 1.0, 1.003, ground_z=0.0) is None  # still above
    assert ground_contact(new, prev, 1.0, 1.003, ground_z=0.0) is None  # climbing out
    assert ground_contact(prev, new, 1.0, 1.003, ground_z=-0.05) is None  # a lower ground


def test_a_plan_through_the_ground_crashes_and_the_default_planner_keeps_clear():
    """A 150 deg overhang 2 m up: the flip costs more height than there is. A planner told of no
    ground dives through it and the simulated world ends the run (the committed plan itself goes
    below z = 0: checked on the plan, not on the sim's verdict); the default configuration keeps
    GROUND_CLEARANCE above the ground and honestly finds no plan."""
    import math

    from avp.sim.run import GROUND_CLEARANCE, SimScenario, _shared, sim_config, simulate

    sc = SimScenario(incline=math.radians(150), distance=3.0, pad_height=2.0, odometry=None)
    free = sim_config(limits=sc.vehicle.limits, camera=sc.camera.camera)
    assert free.workspace.ground_z is None
    r = simulate(sc, "one_shot", seed=0, config=free)
    assert r.outcome == "crash: ground" and not r.success and r.contact is None
    plan = r.first_plan
    assert plan(plan.sample(1e-3))[:, 2].min() < 0.0
    assert r.path_p[:, 2].min() > -0.02  # the run ended at the crash
    assert _shared(sc, None)[1].workspace.ground_z == pytest.approx(sc.ground_z + GROUND_CLEARANCE)
    d = simulate(sc, "one_shot", seed=0)
    assert d.outcome.startswith("no plan")
    with pytest.raises(ConfigError, match="scenario.ground_z"):
        SimScenario(pad_height=0.5, ground_z=1.0)


@pytest.mark.parametrize("name", ["plane_tolerance", "center_tolerance", "attitude_tolerance"])
@pytest.mark.parametrize("bad", [-1.0, 0.0, -np.inf, np.inf, np.nan, "0.1", True, None])
def test_perch_criteria_need_positive_finite_tolerances(name, bad):
    """A negative tolerance was accepted (and the scenario blamed ``scenario.aim_normal``)."""
    from avp.sim import PerchCriteria
    from avp.sim.run import SimScenario

    with pytest.raises(ConfigError) as info:
        SimScenario(perch_criteria=PerchCriteria(**{name: bad}))
    assert info.value.field == f"perch_criteria.{name}"
    assert PerchCriteria(**{name: 1}).__dict__[name] == 1.0


@pytest.mark.parametrize("name,bad", [
    *[(n, b) for n in ("max_attitude_error", "normal_speed_max", "max_tangential_speed")
      for b in (-1.0, 0.0, -np.inf, np.nan, "1", True, None)],
    *[("normal_speed_min", b) for b in (-0.1, np.inf, np.nan, "0.05", True, None)],
    ("max_attitude_error", np.inf), ("max_attitude_error", 3.2),
])
def test_success_criteria_refuse_thresholds_no_touch_meets(name, bad):
    """A NaN, a negative, a string or a boolean threshold was taken (a NaN speed bound judged
    every touch a failure, a string made detect_contact raise a TypeError mid-run)."""
    from avp.sim import SuccessCriteria

    with pytest.raises(ConfigError) as info:
        SuccessCriteria(**{name: bad})
    assert info.value.field == f"criteria.{name}"


def test_success_criteria_take_floats_and_no_limit():
    from avp.sim import SuccessCriteria

    c = SuccessCriteria(max_attitude_error=np.pi, normal_speed_min=0, normal_speed_max=np.inf,
                        max_tangential_speed=np.float32(2.5))
    assert (c.max_attitude_error, c.normal_speed_min, c.normal_speed_max, c.max_tangential_speed) == (
        np.pi, 0.0, np.inf, 2.5) and type(c.normal_speed_min) is float
    prev, new = crossing()
    assert detect_contact(prev, new, PAD, 1.0, 1.002, c).success
    with pytest.raises(ConfigError, match=r"^criteria.normal_speed_min: \(1.0 m/s\) must be below"):
        SuccessCriteria(normal_speed_min=1.0, normal_speed_max=1.0)
