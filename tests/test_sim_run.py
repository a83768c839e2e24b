"""Closed loop (avp.sim.run): one-shot vs AVP, replanning through solver failures, anticipation (6)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.polynomial import polynomial as P

import avp
import avp.replan
from avp.cli import main
from avp.replan import anticipate
from avp.sim.run import Mode, SimScenario, simulate

WALL_45 = SimScenario(distance=4.5)


def test_noise_free_single_plan_is_tracked_to_contact():
    r = simulate(WALL_45.ideal(), Mode.ONE_SHOT, seed=0)
    assert r.outcome == "success", r.outcome
    c = r.contact
    assert np.max(np.abs(c.p_S[:2])) < 0.02  # 2 cm in the pad plane
    assert math.degrees(c.attitude_error) < 2.0
    assert abs(c.normal_speed - 0.3) < 0.05 and abs(c.v_tangential_S[0] + 2.0) < 0.1
    assert abs(c.t - r.first_plan.tf) < 0.05
    assert not r.steps and r.first_plan is r.final_plan
    assert r.visible[0] and not r.visible[-1]  # sees the pad at hover, loses it in the pitch-up


def test_motor_lag_costs_centimetres_along_the_slide_unless_the_thrust_leads():
    ideal = simulate(WALL_45.ideal(), Mode.ONE_SHOT, seed=0)
    sc = WALL_45.without_noise()  # 20 ms motor lag, mixer
    assert sc.vehicle.motor_time_constant == 0.02 and sc.gains.lag_feedforward
    led = simulate(sc, Mode.ONE_SHOT, seed=0)
    lagged = simulate(dataclasses.replace(sc, gains=dataclasses.replace(sc.gains, lag_feedforward=False)),
                      Mode.ONE_SHOT, seed=0)
    # unled, the lag delays the slide (2 m/s along s1) by about one time constant: cm (2.7), not mm
    assert 0.01 < abs(lagged.contact.p_S[0]) < 0.08 and abs(ideal.contact.p_S[0]) < 0.02
    # the thrust lead (ControllerGains.lag_feedforward) gives the contact of instant rotors back
    assert abs(led.contact.p_S[0]) < 0.005
    assert lagged.success and led.success  # inside the 10 cm / 3 cm / 10 deg criterion at t_f


def test_no_thrust_lead_without_a_rotor_lag():
    """avp's model lags its rotors only through the mixer: without it (or with instant rotors)
    ``thrust_lead`` is 0 and the controller's thrust is the unled one, to the bit."""
    from avp.sim.controller import ControllerGains, FlatReference, control, thrust_lead
    from avp.sim.vehicle import RigidBodyState, VehicleParams

    ref = FlatReference([0.0, 0.0, 1.0], [1.0, 0.0, 0.5], [2.0, 0.0, 1.0], [5.0, 1.0, 20.0], [0.0, 0.0, 0.0],
                        0.0, 0.0, 0.0)
    state = RigidBodyState([0.0, 0.0, 1.0], [1.0, 0.0, 0.5])
    for veh in (VehicleParams(mixer=False), VehicleParams(motor_time_constant=0.0)):
        assert thrust_lead(np.eye(3), ref, veh) == 0.0
        led = control(state, ref, veh, ControllerGains(lag_feedforward=True))
        assert led.thrust == control(state, ref, veh, ControllerGains(lag_feedforward=False)).thrust
    veh = VehicleParams()
    assert thrust_lead(np.eye(3), ref, veh) == pytest.approx(veh.motor_time_constant * veh.mass * 20.0)


def test_seeded_runs_are_deterministic():
    a, b = simulate(WALL_45, "avp", seed=7), simulate(WALL_45, "avp", seed=7)
    c = simulate(WALL_45, "avp", seed=8)
    np.testing.assert_array_equal(a.path_p, b.path_p)
    np.testing.assert_array_equal(a.detections, b.detections)
    assert a.outcome == b.outcome
    assert not np.array_equal(a.initial_estimate_error, c.initial_estimate_error)
    # both modes of a seed start from the same detection (paired comparison)
    o = simulate(dataclasses.replace(WALL_45, timeout=0.05), "one_shot", seed=7)
    np.testing.assert_array_equal(o.initial_estimate_error, a.initial_estimate_error)


def test_avp_beats_one_shot_under_localisation_noise_at_7_5_m():
    sc = SimScenario(distance=7.5)
    runs = {m: [simulate(sc, m, seed=s) for s in range(3)] for m in Mode}

    def mean_error(rs):  # a run without contact counts as 1 m off
        return np.mean([np.linalg.norm(r.interception) if r.interception is not None else 1.0 for r in rs])

    one, avp_ = runs[Mode.ONE_SHOT], runs[Mode.AVP]
    assert mean_error(avp_) < mean_error(one)
    assert sum(r.success for r in avp_) >= sum(r.success for r in one)
    # far detections are noisier than near ones (Fig. 9): the fused estimate improves in flight
    for r in avp_:
        if r.final_plan is not None:  # a run without a (non-relaxed) first plan never flies
            assert r.detections[-1, 3] < np.linalg.norm(r.initial_estimate_error)


def _poly_eval(coeffs, knots, t, order):
    i = int(np.clip(np.searchsorted(knots, t, side="right") - 1, 0, len(knots) - 2))
    u = t - knots[i]
    return np.array([P.polyval(u, P.polyder(coeffs[i, a], order)) if order else P.polyval(u, coeffs[i, a])
                     for a in range(4)])


@settings(max_examples=40)
@given(
    data=st.data(),
    n_seg=st.integers(1, 4),
    degree=st.integers(3, 9),
    measured=st.integers(0, 4),
)
def test_anticipation_matches_direct_evaluation(data, n_seg, degree, measured):
    rng = np.random.default_rng(data.draw(st.integers(0, 2**32 - 1)))
    coeffs = rng.normal(size=(n_seg, 4, degree + 1))
    knots = np.concatenate([[0.3], 0.3 + np.cumsum(rng.uniform(0.2, 1.0, n_seg))])
    traj = avp.Trajectory(coeffs, knots)
    i_rp = data.draw(st.integers(0, n_seg - 1))
    i_ex = data.draw(st.integers(i_rp, n_seg - 1))
    f_rp = data.draw(st.floats(0.02, 0.98))
    f_ex = data.draw(st.floats(f_rp if i_ex == i_rp else 0.02, 0.98))
    t_rp = knots[i_rp] + f_rp * (knots[i_rp + 1] - knots[i_rp])
    t_ex = knots[i_ex] + f_ex * (knots[i_ex + 1] - knots[i_ex])
    odo = avp.State(position=rng.normal(size=3), velocity=rng.normal(size=3), acceleration=rng.normal(size=3),
                    jerk=rng.normal(size=3), yaw=float(rng.normal()), yaw_rate=float(rng.normal()), time=t_rp)
    x0 = anticipate(traj, odo, t_rp, t_ex, measured)
    # the measured yaw on the plan's branch (odometry wraps it, a plan does not)
    plan_yaw = _poly_eval(coeffs, knots, t_rp, 0)[3]
    yaw = odo.yaw + 2.0 * math.pi * round((plan_yaw - odo.yaw) / (2.0 * math.pi))
    meas = [np.append(odo.position, yaw), np.append(odo.velocity, odo.yaw_rate),
            np.append(odo.acceleration, 0.0), np.append(odo.jerk, 0.0)]
    got = [np.append(x0.position, x0.yaw), np.append(x0.velocity, x0.yaw_rate),
           np.append(x0.acceleration, np.nan), np.append(x0.jerk, np.nan)]
    for k in range(4):
        at_ex, at_rp = _poly_eval(coeffs, knots, t_ex, k), _poly_eval(coeffs, knots, t_rp, k)
        base = meas[k] if k < measured else at_rp
        want = base + at_ex - at_rp
        axes = 4 if k < 2 else 3  # the State carries yaw and its rate only
        scale = 1.0 + np.max(np.abs(np.concatenate([at_ex, at_rp, base])))
        np.testing.assert_allclose(got[k][:axes], want[:axes], rtol=0, atol=1e-9 * scale)
    assert x0.time == t_ex


def test_cli_simulate_prints_the_tables(capsys, tmp_path):
    assert main(["simulate", "--trials", "1", "--distance", "1.5", "--seed", "3",
                 "--output-dir", str(tmp_path / "out")]) == 0
    text = capsys.readouterr().out
    for key in ("Success rate", "Interception error", "Anticipation error", "latency", "one_shot", "avp"):
        assert key in text
    pngs = sorted(p.name for p in (tmp_path / "out").glob("*.png"))
    assert pngs == ["estimate_error.png", "paths_0_1.5m.png", "visibility.png"]


def test_the_user_side_aims_deeper_and_down_the_slope_by_the_scenarios_offsets():
    """With an exact detector and exact odometry the first target handed to the planner is the
    pad moved ``aim_normal`` into it and ``aim_slope sin(incline)`` down its slope (along -s1):
    nothing down a level pad."""
    from avp.sim.evaluate import SimConfig

    for incline in (60.0, 0.0):
        cfg = SimConfig(aim_normal=0.012, aim_slope=0.05).perfect_estimate()
        sc = cfg.scenario(incline, 3.0)
        r = simulate(sc, Mode.ONE_SHOT, seed=0, max_time=0.05)
        pad = sc.target()
        want = pad.point - 0.012 * pad.s3 - 0.05 * math.sin(math.radians(incline)) * pad.s1
        np.testing.assert_allclose(r.initial_target.point, want, atol=1e-9)
        np.testing.assert_allclose(r.initial_target.R_WS, pad.R_WS, atol=1e-9)
        np.testing.assert_allclose(r.initial_estimate_error, 0.0, atol=1e-9)  # the estimate's own error


def test_an_aim_beyond_the_success_window_is_refused():
    import pytest

    from avp.errors import ConfigError

    with pytest.raises(ConfigError, match="aim_slope"):
        SimScenario(aim_slope=0.2)
    with pytest.raises(ConfigError, match="aim_normal"):
        SimScenario(aim_normal=float("nan"))
    with pytest.raises(ConfigError, match="aim_normal"):
        SimScenario(aim_normal=0.05)  # beyond the 3 cm plane tolerance
    from avp.sim.run import PlatformMotion

    with pytest.raises(ConfigError, match="static pad"):
        SimScenario(aim_slope=0.05, platform=PlatformMotion(speed=1.0))
    assert SimScenario(aim_normal=np.float32(0.01)).aim_normal == pytest.approx(0.01)


def test_the_simulated_user_asks_for_its_contact_thrust():
    """``SimConfig.alpha_nominal`` reaches the planner configuration :func:`simulate` builds (the
    scenario carries it); a scenario without it gets the planner's default."""
    import pytest

    from avp.errors import ConfigError
    from avp.sim.evaluate import SimConfig
    from avp.sim.run import _shared

    sc = SimConfig().scenario(90.0, 4.5)
    assert sc.alpha_nominal == SimConfig().alpha_nominal == 6.0
    assert _shared(sc, None)[1].contact_alpha(sc.incline) == 6.0
    assert _shared(SimScenario(distance=4.5), None)[1].alpha_nominal == avp.config.ALPHA_NOMINAL
    r = simulate(sc, Mode.ONE_SHOT, seed=0, max_time=0.05)
    assert abs(r.first_plan.thrust(r.first_plan.tf) - 6.0) < 1e-6
    with pytest.raises(ConfigError, match="scenario.alpha_nominal"):
        SimScenario(alpha_nominal=-2.0)


def test_the_scenarios_contact_velocity_is_the_default_planners() -> None:
    """``SimScenario.contact_velocity`` reaches the configuration ``simulate`` builds (as
    ``alpha_nominal`` does), ``SimConfig``'s contact speeds reach its scenarios, and a contact
    speed that leaves the pad or is not a number is refused by name."""
    from avp.errors import ConfigError
    from avp.sim.evaluate import SimConfig
    from avp.sim.run import _shared

    cv = avp.ContactVelocity(normal=-0.5, slope=-1.0)
    sc = SimScenario(contact_velocity=cv)
    assert _shared(sc, None)[1].contact_velocity is cv
    assert _shared(SimScenario(), None)[1].contact_velocity == avp.PlannerConfig().contact_velocity
    got = SimConfig(contact_normal=-0.6, contact_slope=-1.2).scenario(90.0, 4.5).contact_velocity
    assert (got.normal, got.slope) == (-0.6, -1.2)
    for field, bad in (("contact_normal", 0.0), ("contact_normal", 0.2), ("contact_slope", float("nan")),
                       ("contact_normal", True)):
        with pytest.raises(ConfigError, match=f"sim.{field}"):
            SimConfig(**{field: bad})
    with pytest.raises(ConfigError, match="scenario.contact_velocity"):
        SimScenario(contact_velocity=(-0.3, -2.0))


@pytest.mark.parametrize(("kwargs", "field"), [
    (dict(dt=0.0), "dt"),  # was a ZeroDivisionError
    (dict(dt=1e-9), "dt"),  # was accepted: 2e10 control steps
    (dict(dt=-0.001), "dt"),
    (dict(dt=0.01), "dt"),
    (dict(dt="0.002"), "dt"),
    (dict(seed=-1), "seed"),  # was numpy's ValueError
    (dict(seed="x"), "seed"),
    (dict(seed=1.5), "seed"),  # was truncated to 1
    (dict(seed=True), "seed"),
    (dict(max_time=-1.0), "max_time"),  # was accepted
    (dict(max_time=0.0), "max_time"),
    (dict(max_time=float("nan")), "max_time"),
    (dict(plan_drag="no"), "plan_drag"),  # was accepted, and true
    (dict(plan_drag=1), "plan_drag"),
])
def test_simulate_refuses_bad_run_settings_by_name(kwargs, field):
    with pytest.raises(avp.ConfigError) as info:
        simulate(SimScenario(), Mode.ONE_SHOT, **kwargs)
    assert info.value.field == field


def test_simulate_takes_run_settings_in_range():
    sc = WALL_45.ideal()
    r = simulate(sc, Mode.ONE_SHOT, seed=np.int64(3), dt=avp.sim.flight.DT_MIN, max_time=0.01, plan_drag=np.bool_(False))
    assert r.seed == 3 and r.path_t[-1] - r.t_plan < 0.05  # one 30 Hz period past max_time at most
    np.testing.assert_allclose(np.diff(r.path_t), 1e-4, rtol=1e-6)


@pytest.mark.parametrize(("kwargs", "field"), [
    (dict(incline=None), "scenario.incline"),  # these were TypeErrors
    (dict(distance=None), "scenario.distance"),
    (dict(distance="3"), "scenario.distance"),
    (dict(distance=[3.0]), "scenario.distance"),
    (dict(lateral=None), "scenario.lateral"),
    (dict(lateral="0"), "scenario.lateral"),
    (dict(height="x"), "scenario.height"),
    (dict(height=[1.0]), "scenario.height"),
    (dict(pad_height=None), "scenario.pad_height"),
    (dict(timeout=None), "scenario.timeout"),
    (dict(ground_z="0"), "scenario.ground_z"),
    (dict(distance=1e5), "scenario.distance"),  # broke the simulated camera's arithmetic
    (dict(lateral=1e300), "scenario.lateral"),  # gave NaN results
    (dict(lateral=-101.0), "scenario.lateral"),
    (dict(height=1e4), "scenario.height"),
    (dict(initial_frames=10**6), "scenario.initial_frames"),  # ran for minutes
    (dict(initial_frames=2.0), "scenario.initial_frames"),
    (dict(initial_frames=True), "scenario.initial_frames"),
    (dict(initial_frames=0), "scenario.initial_frames"),
])
def test_scenario_refuses_bad_geometry_by_name(kwargs, field):
    with pytest.raises(avp.ConfigError) as info:
        SimScenario(**kwargs)
    assert info.value.field == field


@pytest.mark.parametrize("name", ["camera", "vehicle", "gains", "odometry", "platform", "criteria", "perch_criteria"])
def test_scenario_refuses_settings_of_the_wrong_type(name):
    """A wrong object in a settings field was accepted and broke simulate() with an AttributeError."""
    with pytest.raises(avp.ConfigError, match="must be an avp.sim") as info:
        SimScenario(**{name: "x"})
    assert info.value.field == f"scenario.{name}"


def test_scenario_takes_geometry_in_range():
    sc = SimScenario(distance=100, lateral=-100.0, height=np.float32(100.0), initial_frames=np.int64(100),
                     odometry=None, platform=None)
    assert (sc.distance, sc.lateral, sc.height, sc.initial_frames) == (100.0, -100.0, 100.0, 100)
    assert isinstance(sc.distance, float) and type(sc.initial_frames) is int


@pytest.mark.parametrize(("kwargs", "field"), [
    (dict(modes=None), "sim.modes"),  # was a TypeError
    (dict(modes="avp"), "sim.modes"),
    (dict(modes=("avp", "x")), "sim.modes"),  # was reported on "mode"
    (dict(modes=(1,)), "sim.modes"),
    (dict(distances=None), "sim.distances"),  # was reported on sim.inclines_deg
    (dict(distances=()), "sim.distances"),
    (dict(distances=("a",)), "sim.distances"),
    (dict(distances=(-1.0,)), "sim.distances"),
    (dict(distances=(1e5,)), "sim.distances"),
    (dict(inclines_deg=None), "sim.inclines_deg"),
    (dict(inclines_deg=(200.0,)), "sim.inclines_deg"),
    (dict(inclines_deg=(float("nan"),)), "sim.inclines_deg"),
    (dict(n_trials=2.0), "sim.n_trials"),
    (dict(seed=-1), "sim.seed"),
    (dict(seed="0"), "sim.seed"),
    (dict(initial_frames=10**6), "sim.initial_frames"),
    (dict(camera_rate_hz=0.0), "sim.camera_rate_hz"),
    (dict(odometry_rate_hz=None), "sim.odometry_rate_hz"),
    (dict(camera_dropout=1.0), "sim.camera_dropout"),
    (dict(camera_bias_sign=2), "sim.camera_bias_sign"),
    (dict(filter_scale_error=-0.1), "sim.filter_scale_error"),
    (dict(filter_range_ratio=0.5), "sim.filter_range_ratio"),
    (dict(aim_normal="0"), "sim.aim_normal"),
    (dict(alpha_nominal=-1.0), "sim.alpha_nominal"),
])
def test_sim_config_is_validated_at_construction(kwargs, field):
    from avp.sim.evaluate import SimConfig

    with pytest.raises(avp.ConfigError) as info:
        SimConfig(**kwargs)
    assert info.value.field == field


def test_sim_config_takes_sequences_of_numbers():
    from avp.sim.evaluate import SimConfig

    c = SimConfig(modes=["avp"], inclines_deg=np.array([90, 45]), distances=[4.5], n_trials=np.int64(2))
    assert (c.modes, c.inclines_deg, c.distances, c.n_trials) == (("avp",), (90.0, 45.0), (4.5,), 2)
    assert c.scenario(c.inclines_deg[0], c.distances[0]).distance == 4.5
