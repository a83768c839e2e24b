"""Moving perch pads (Gao et al., "Adaptive Tracking and Perching for Quadrotor in Dynamic
Scenarios"): the platform model, the terminal map at the predicted pad, the moving-plane
clearance certificate, the arrival-time search and bad input."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp

import avp
from avp.errors import ConfigError
from avp.moving import MovingConfig, contact_errors, plan_moving, plan_moving_detailed
from avp.moving_clearance import certify_moving_clearance, clearance
from avp.platform import MotionModel, MovingTarget
from avp.qp.moving import MovingQpBuilder, TerminalYaw
from avp.solve import solve_perching_qp

LIMITS = avp.VehicleLimits(mass=1.0, thrust_min=5.0, thrust_max=17.0, tilt_rate_max=3.0)
"""Gao et al.'s limits (their Table III): mass-normalised thrust 5-17 m/s^2, rate 3 rad/s."""
CONFIG = avp.PlannerConfig(limits=LIMITS, alpha=5.5, pre_impact=avp.PreImpactMode.OFF)
QP_CONFIG = avp.PlannerConfig(limits=LIMITS, alpha=5.5, pre_impact=avp.PreImpactMode.OFF,
                              fov=avp.FovConfig(enabled=False), alpha_range=(5.6, 16.4))

speeds = st.floats(-4.0, 4.0)
turn_rates = st.floats(-0.5, 0.5)
angles = st.floats(-math.pi, math.pi)


def platform(incline: float, speed: float, turn_rate: float = 0.0, heading: float = 0.0,
             vertical: float = 0.0, model: MotionModel = MotionModel.CTRV) -> MovingTarget:
    return MovingTarget.on_platform([0.0, 0.0, 1.0], incline=incline, heading=heading, speed=speed,
                                    turn_rate=turn_rate, vertical_speed=vertical, model=model)


def behind(target: MovingTarget, distance: float = 3.0, height: float = 0.0) -> avp.State:
    """Start ``distance`` behind the pad along the heading, moving with the platform."""
    h = np.array([math.cos(target.heading), math.sin(target.heading), 0.0])
    return avp.State(position=target.point - distance * h + [0.0, 0.0, height], velocity=target.velocity,
                     yaw=target.heading)


# -- platform model ------------------------------------------------------------------------

@given(speed=speeds, turn=turn_rates, heading=angles, vertical=st.floats(-1, 1), dt=st.floats(-3.0, 5.0))
def test_ctrv_prediction_matches_integrating_the_model(speed, turn, heading, vertical, dt):
    """at(t) equals a numerical integration of d rho/dt = (v cos theta, v sin theta, v_v)."""
    tgt = platform(0.7, speed, turn, heading, vertical)
    sol = solve_ivp(lambda t, x: [speed * math.cos(x[3]), speed * math.sin(x[3]), vertical, turn],
                    (0.0, dt), [*tgt.point, heading], rtol=1e-11, atol=1e-12) if dt != 0 else None
    ref = sol.y[:3, -1] if sol is not None else tgt.point
    pad = tgt.at(dt)
    assert np.allclose(pad.point, ref, atol=1e-8)
    assert pad.heading == pytest.approx(heading + turn * dt)
    assert np.allclose(pad.velocity, [speed * math.cos(heading + turn * dt), speed * math.sin(heading + turn * dt), vertical])
    # the pad frame turns with the heading: s3 keeps its height and rotates about e3 by turn*dt
    assert np.allclose(pad.R_WS, avp.platform.rot_z(turn * dt) @ tgt.R_WS, atol=1e-12)
    assert pad.at(0.0).point == pytest.approx(tgt.point, abs=1e-9)


@given(speed=speeds, heading=angles, dt=st.floats(0.0, 5.0))
def test_constant_velocity_and_vanishing_turn_rate_agree(speed, heading, dt):
    cv = platform(0.3, speed, 0.2, heading, 0.1, model=MotionModel.CONSTANT_VELOCITY)  # turn rate ignored
    ctrv = platform(0.3, speed, 1e-12, heading, 0.1)
    assert np.allclose(cv.at(dt).point, cv.point + dt * cv.velocity, atol=1e-12)
    assert np.allclose(cv.at(dt).point, ctrv.at(dt).point, atol=1e-9)
    assert np.array_equal(cv.at(dt).R_WS, cv.R_WS)


def test_static_pads_are_unchanged():
    pad = avp.PerchTarget.from_incline([1.0, 2.0, 1.5], 0.8)
    assert pad.at(12.0) is pad
    still = MovingTarget.from_pad(pad)
    assert still.is_static
    assert np.array_equal(still.at(5.0).point, pad.point) and np.array_equal(still.at(5.0).R_WS, pad.R_WS)


# -- terminal map (fixed arrival time) ---------------------------------------------------

def solve_fixed(state, target, T, **kw):
    opts = dict(normal_speed=0.3, slip_max=1.0, slip_weight=1000.0, zero_jerk=True, yaw=TerminalYaw.HEADING,
                body_offset=0.0)
    opts.update(kw)
    builder = MovingQpBuilder(state, QP_CONFIG, **opts)
    pad = target.at(state.time + T)
    qp = builder.build(pad, T)
    out = solve_perching_qp(qp, QP_CONFIG)
    assert out.ok
    return qp.trajectory(out.c_hat, QP_CONFIG.g), pad


@settings(max_examples=25)
@given(incline=st.floats(0.0, 1.5), speed=speeds, turn=turn_rates, heading=angles, T=st.floats(1.5, 4.0),
       offset=st.floats(0.0, 0.1), t0=st.floats(-2.0, 2.0))
def test_terminal_conditions_on_random_platforms(incline, speed, turn, heading, T, offset, t0):
    """Gao et al.'s terminal map holds at the predicted pad whatever the platform does."""
    tgt = platform(incline, speed, turn, heading)
    state = behind(tgt.at(t0), 3.0, 0.5)
    state = avp.State(position=state.position, velocity=state.velocity, yaw=state.yaw, time=t0)
    traj, pad = solve_fixed(state, tgt, T, body_offset=offset)
    tf = traj.tf
    assert tf == pytest.approx(t0 + T)
    assert np.linalg.norm(traj(tf) - (pad.point + offset * pad.s3)) < 1e-9  # (43)
    f = traj(tf, 2) + [0, 0, QP_CONFIG.g]
    angle = math.atan2(np.linalg.norm(np.cross(f, pad.s3)), float(f @ pad.s3))
    assert angle < 1e-9  # (48)-(49)
    assert 5.6 - 1e-6 <= np.linalg.norm(f) <= 16.4 + 1e-6  # (50): thrust free inside the limits
    rel = traj(tf, 1) - pad.velocity
    assert float(rel @ pad.s3) == pytest.approx(-0.3, abs=1e-9)  # (45)-(46) normal push
    assert abs(float(rel @ pad.s1)) <= 1.0 + 1e-7 and abs(float(rel @ pad.s2)) <= 1.0 + 1e-7  # slip bound
    assert np.linalg.norm(traj(tf, 3)) < 1e-7  # zero jerk at contact
    yaw = float(traj.yaw(tf))
    assert math.cos(yaw - pad.heading) == pytest.approx(1.0, abs=1e-12)  # (44)


def test_zero_slip_bound_synchronises_the_full_velocity():
    tgt = platform(1.0, 2.0, 0.2)
    traj, pad = solve_fixed(behind(tgt), tgt, 3.0, slip_max=0.0)
    rel = traj(traj.tf, 1) - pad.velocity
    assert np.allclose(rel, -0.3 * pad.s3, atol=1e-9)


def test_slip_cost_pulls_the_slip_towards_zero():
    """The homogenised slip cost is Gao et al.'s |nu|^2: raising its weight cannot raise |nu|."""
    tgt = platform(0.5, 2.0, 0.2)
    slips = []
    for w in (0.0, 10.0, 1e4):
        traj, pad = solve_fixed(behind(tgt), tgt, 2.8, slip_weight=w)
        rel = traj(traj.tf, 1) - pad.velocity
        slips.append(math.hypot(rel @ pad.s1, rel @ pad.s2))
    assert slips[0] >= slips[1] - 1e-9 >= slips[2] - 2e-9
    assert slips[2] < 0.1 * max(slips[0], 1e-3)


@settings(max_examples=15)
@given(v=st.tuples(st.floats(-5, 5), st.floats(-5, 5), st.floats(-1, 1)))
def test_constant_velocity_platform_is_the_static_problem_in_its_frame(v):
    """Galilean invariance, an oracle we did not write: with a constant-velocity platform the
    optimum is the static plan in the platform frame plus ``v (t - t0)`` (snap, thrust and
    attitude only see the acceleration)."""
    heading = 0.4
    speed = math.hypot(v[0], v[1])
    heading = math.atan2(v[1], v[0]) if speed > 0 else heading
    tgt = MovingTarget.on_platform([0, 0, 1], incline=0.7, heading=heading, speed=speed, vertical_speed=v[2],
                                   model=MotionModel.CONSTANT_VELOCITY)
    state = avp.State(position=[-2.5, 0.4, 1.3], velocity=np.array([0.5, 0.0, 0.2]) + tgt.velocity, yaw=heading)
    T = 2.6
    moving, _ = solve_fixed(state, tgt, T)
    still = MovingTarget.from_pad(tgt.static(), heading=heading)
    rel_state = avp.State(position=state.position, velocity=state.velocity - tgt.velocity, yaw=heading)
    static, _ = solve_fixed(rel_state, still, T)
    t = np.linspace(0, T, 57)
    assert np.allclose(moving(t), static(t) + np.outer(t, tgt.velocity), atol=1e-7)
    assert np.allclose(moving(t, 2), static(t, 2), atol=1e-6)


def test_stationary_limit_equals_the_static_planner():
    """A pad that does not move, asked for the static planner's contact conditions, gives the
    static planner's trajectory (same QP): zero tangential velocity, no jerk row, yaw rule (13)."""
    pad = avp.PerchTarget.from_incline([0.0, 0.0, 1.0], 0.6)
    cfg = avp.PlannerConfig(limits=LIMITS, alpha=8.0, pre_impact=avp.PreImpactMode.OFF, fov=avp.FovConfig(enabled=False),
                            contact_velocity=avp.ContactVelocity(normal=-0.3, slope=0.0, lateral=0.0),
                            bounds=avp.BoundsPolicy(factors=(), relaxations=()))
    state = avp.State.hover([-3.0, 0.0, 1.0])
    static = avp.plan_detailed(state, pad, cfg, durations=[0.9, 0.9, 0.9])
    mcfg = MovingConfig(slip_max=0.0, zero_jerk=False, yaw=TerminalYaw.PAD, contact_thrust_margin=None)
    moving = plan_moving_detailed(state, MovingTarget.from_pad(pad), cfg, mcfg, duration=2.7)
    assert static.ok and moving.ok
    t = np.linspace(0.0, 2.7, 41)
    assert np.allclose(moving.trajectory.derivatives(t), static.trajectory.derivatives(t), atol=1e-7)


# -- moving-plane clearance ---------------------------------------------------------------

@pytest.mark.parametrize("incline,speed,turn", [(0.5, 2.0, 0.0), (1.0, 1.0, 0.2), (0.0, 6.0, 0.0), (1.5, 2.0, 0.2)])
def test_clearance_certificate_against_a_dense_grid(incline, speed, turn):
    tgt = platform(incline, speed, turn)
    state = behind(tgt, 3.0, 1.0 if incline < 0.3 else 0.0)
    res = plan_moving_detailed(state, tgt, CONFIG)
    assert res.ok and res.clearance is not None and res.clearance.certified
    traj = res.trajectory
    t = np.linspace(traj.t0, traj.tf, 20001)
    h = clearance(traj, tgt, t)
    assert h[:-1].min() > min(0.0, res.clearance.contact_residual_lower) - 1e-12
    assert abs(h[-1]) < 1e-9
    assert (res.clearance.taylor_order == 0) == (turn == 0.0)  # exact polynomial without a turn


@settings(max_examples=20)
@given(shift=st.floats(-0.05, 0.05), tilt=st.floats(-0.05, 0.05))
def test_clearance_certificate_is_sound(shift, tilt):
    """Against a pad displaced along its normal and tilted (so the plan may cross it), a
    'certified' verdict never coexists with a grid point below the plane."""
    tgt = platform(1.0, 2.0, 0.2)
    traj, _ = solve_fixed(behind(tgt), tgt, 3.0)
    R = tgt.R_WS @ np.array([[1, 0, 0], [0, math.cos(tilt), -math.sin(tilt)], [0, math.sin(tilt), math.cos(tilt)]])
    other = MovingTarget(point=tgt.point + shift * tgt.s3, R_WS=R, heading=tgt.heading, speed=tgt.speed,
                         turn_rate=tgt.turn_rate, time=tgt.time)
    rep = certify_moving_clearance(traj, other)
    h = clearance(traj, other, np.linspace(traj.t0, traj.tf, 4001))
    if rep.certified:
        assert h[:-1].min() > min(0.0, rep.contact_residual_lower) - 1e-12
    if h.min() < -1e-9:
        assert not rep.certified


def test_a_start_below_the_moving_roof_is_bad_input():
    """A start below the moving roof cannot keep the clearance from its first instant: a typed
    error on the start, as for a static pad (it was a clearance failure after the search);
    without the perch-plane clearance it is planned."""
    tgt = platform(0.0, 4.0, model=MotionModel.CONSTANT_VELOCITY)
    with pytest.raises(ConfigError) as exc:
        plan_moving_detailed(behind(tgt, 3.0, -0.5), tgt, CONFIG)
    assert exc.value.field == "state.position" and "behind the moving pad" in str(exc.value)
    free = replace(CONFIG, workspace=replace(CONFIG.workspace, perch_clearance=False))
    res = plan_moving_detailed(behind(tgt, 3.0, -0.5), tgt, free)
    assert res.clearance is None


# -- the search on Gao et al.'s grid --------------------------------------------------------

@pytest.mark.parametrize("name,tgt,height", [
    ("plane 1.0 rad at 2 m/s", platform(1.0, 2.0, model=MotionModel.CONSTANT_VELOCITY), 0.0),
    ("roof at 8.3 m/s", platform(0.0, 8.3, model=MotionModel.CONSTANT_VELOCITY), 1.5),
    ("CTRV 0.5 rad at 3 m/s", platform(0.5, 3.0, 0.2), 0.0),
])
def test_seed_grid_cases_are_certified_with_exact_contact(name, tgt, height):
    res = plan_moving_detailed(behind(tgt, 3.0, height), tgt, CONFIG)
    assert res.ok, res.log
    assert res.bounds is not None and res.bounds.certified
    err = contact_errors(res.trajectory, tgt, MovingConfig())
    assert err.position < 1e-3 and err.attitude < math.radians(0.5) and abs(err.normal_velocity) < 1e-3
    assert max(abs(x) for x in err.slip) <= 1.0 + 1e-6
    t = res.trajectory.sample(1e-3)
    f = res.trajectory.thrust(t)
    assert 5.0 < f.min() and f.max() < 17.0
    assert np.linalg.norm(res.trajectory.body_rates(t)[:, :2], axis=1).max() < 3.0


# -- bad input ---------------------------------------------------------------------------

def test_bad_input_is_a_config_error_naming_the_field():
    with pytest.raises(avp.ConfigError, match="target.speed"):
        platform(0.5, float("nan"))
    with pytest.raises(avp.ConfigError, match="target.turn_rate"):
        platform(0.5, 1.0, float("inf"))
    with pytest.raises(avp.ConfigError, match="moving.normal_speed"):
        MovingConfig(normal_speed=0.0)
    with pytest.raises(avp.ConfigError, match="moving.slip_max"):
        MovingConfig(slip_max=-1.0)
    with pytest.raises(avp.ConfigError, match="target"):
        plan_moving_detailed(avp.State.hover([0, 0, 1]), avp.PerchTarget.from_incline([1, 0, 1], 0.3), CONFIG)
    pad = platform(0.5, 1.0)
    for times in ([0.0, 1.0, "a"], [0.0, float("nan")], [True, False]):
        with pytest.raises(avp.ConfigError) as exc:  # ValueError / NaN predictions before
            pad.predict(times)
        assert exc.value.field == "times"
    points, _, _ = pad.predict([pad.time, pad.time + 1.0])
    np.testing.assert_allclose(points[1] - points[0], pad.velocity, atol=1e-12)  # 1 s at constant velocity


def test_a_fixed_duration_beyond_the_duration_limit_is_a_config_error():
    """``duration`` has the limit of ``avp.plan``'s durations: 1e300 overflowed, 1e6 solved to
    an INFEASIBLE result; the retime factors are nudges, in [0.1, 10]."""
    pad = MovingTarget.on_platform([0, 0, 1.0], incline=0.5, speed=2.0)
    start = avp.State(position=[-3.0, 0, 1.0], velocity=[2.0, 0, 0])
    for duration in (1e300, 1e6, 1.0001e4):
        with pytest.raises(ConfigError) as exc:
            plan_moving_detailed(start, pad, duration=duration)
        assert exc.value.field == "duration"
    for factors in ((1e300,), (1e6,), (0.0,), (0.01,), (1.03, float("nan"))):
        with pytest.raises(ConfigError) as exc:
            MovingConfig(retime=factors)
        assert exc.value.field == "moving.retime"
    assert MovingConfig(retime=(0.1, 10.0)).retime == (0.1, 10.0)


def test_max_solves_is_a_bounded_integer():
    """``max_solves`` is in [1, 1000] (:data:`avp.moving.MAX_SOLVES`): 10**9 was taken, a search
    that never certifies then running for days; a float or a bool is no count."""
    assert MovingConfig(max_solves=1000).max_solves == 1000
    assert MovingConfig(max_solves=np.int64(3)).max_solves == 3
    for bad in (0, 1001, 10**9, 7.0, True, "7", None):
        with pytest.raises(ConfigError, match=r"^moving.max_solves: must be an integer in \[1, 1000\]"):
            MovingConfig(max_solves=bad)


def test_negative_speed_is_a_reversing_platform():
    tgt = platform(0.5, -1.0, model=MotionModel.CONSTANT_VELOCITY)
    assert tgt.at(1.0).point[0] == pytest.approx(-1.0)
    h = np.array([1.0, 0.0, 0.0])
    res = plan_moving_detailed(avp.State(position=tgt.point - 3 * h, velocity=tgt.velocity), tgt, CONFIG)
    assert res.ok


def test_a_platform_outrunning_the_limits_is_an_honest_failure():
    """108 km/h away from a hovering vehicle 3 m behind, contact within 3 s: the pad is 93 m away
    by then, more than 0.5 * 13 m/s^2 * (3 s)^2 = 58 m of reach with the horizontal thrust."""
    tgt = platform(0.5, 30.0, model=MotionModel.CONSTANT_VELOCITY)
    state = avp.State.hover(tgt.point - [3.0, 0.0, 0.0])
    mcfg = MovingConfig(max_duration=3.0)
    res = plan_moving_detailed(state, tgt, CONFIG, mcfg)
    assert res.status is avp.PlanStatus.BOUNDS_NOT_CERTIFIED and res.trajectory is None
    assert all(c.duration <= 3.0 for c in res.candidates)
    with pytest.raises(avp.BoundsNotCertifiedError):
        plan_moving(state, tgt, CONFIG, mcfg)


@pytest.mark.parametrize("slip_weight,slip_max", [(1000.0, 1.0), (0.0, 1.0), (0.0, 0.0)])
def test_two_stage_elimination_matches_the_generic_one(slip_weight, slip_max):
    """The builder's cached null space gives the same optimum as PerchingQp's own elimination."""
    from dataclasses import replace
    tgt = platform(1.0, 2.0, 0.2)
    builder = MovingQpBuilder(behind(tgt), QP_CONFIG, 0.3, slip_max, slip_weight, True, TerminalYaw.HEADING, 0.0)
    qp = builder.build(tgt.at(3.0), 3.0)
    generic = replace(qp)
    assert "elimination" in qp.__dict__ and "elimination" not in generic.__dict__
    a, b = solve_perching_qp(qp, QP_CONFIG), solve_perching_qp(generic, QP_CONFIG)
    assert a.ok and b.ok
    assert np.allclose(a.c_hat, b.c_hat, atol=1e-7 * np.abs(b.c_hat).max())


# -- replanning ----------------------------------------------------------------------------

def test_replanner_follows_platform_estimates():
    """Replanning at 30 Hz from the committed plan with platform-state estimates: when the
    platform speeds up mid-flight (new estimate), the last committed plan meets the pad where the
    new motion puts it at contact (exact odometry, so anticipation (6) is exact)."""
    from avp.moving import MovingReplanner
    first = platform(0.5, 2.0, model=MotionModel.CONSTANT_VELOCITY)
    rp = MovingReplanner(first, CONFIG, avp.ReplanConfig(latency=0.02, freeze_horizon=0.25))
    s0 = behind(first)
    step = rp.step(0.0, s0, first)
    assert step.action is avp.ReplanAction.INITIAL_PLAN
    tf0 = step.trajectory.tf
    faster = None
    t = 1.0 / 30.0
    while t < tf0:
        traj = rp.trajectory
        odo = avp.State(position=traj(t), velocity=traj(t, 1), acceleration=traj(t, 2), jerk=traj(t, 3),
                        yaw=float(traj.yaw(t)), yaw_rate=float(traj.yaw(t, 1)), time=t)
        if faster is None and t > 0.4 * tf0:  # the platform accelerates to 2.5 m/s: new estimate
            now = first.at(t)
            faster = MovingTarget(point=now.point, R_WS=now.R_WS, heading=now.heading, speed=2.5, time=t,
                                  model=MotionModel.CONSTANT_VELOCITY)
        rp.step(t, odo, faster.at(t) if faster is not None else first.at(t))
        t += 1.0 / 30.0
    actions = {s.action for s in rp.history}
    assert avp.ReplanAction.REPLANNED in actions and avp.ReplanAction.FROZEN_NEAR_CONTACT in actions
    final = rp.trajectory
    assert final.tf == pytest.approx(tf0)  # replans keep the committed contact time
    err = contact_errors(final, faster, MovingConfig())
    assert err.position < 1e-3 and err.attitude < math.radians(0.5) and abs(err.normal_velocity) < 1e-3
    assert np.linalg.norm(final(final.tf) - first.at(final.tf).point) > 0.1  # it did follow the change


def _on_plan(traj, t: float) -> avp.State:
    d = traj.derivatives(t)
    return avp.State(position=d[0, :3], velocity=d[1, :3], acceleration=d[2, :3], jerk=d[3, :3],
                     yaw=float(d[0, 3]), yaw_rate=float(d[1, 3]), time=t)


@pytest.mark.parametrize("left", [0.6, 0.1])
def test_moving_replanner_says_cannot_reach_when_the_predicted_pad_is_out_of_reach(left):
    """An estimate that puts the pad 25+ m away at the committed contact time, 0.6 s before it
    (no certified plan closes that) or inside the freeze horizon: the step says CANNOT_REACH,
    the cue to abort, with the distance between the committed contact point and the pad the
    estimate predicts at contact (read off the platform model's vectorised prediction and the
    plan's end), and no budget (none applies to a moving pad)."""
    from avp.moving import MovingReplanner

    pad = platform(0.5, 2.5, 0.2)
    rc = avp.ReplanConfig(freeze_horizon=0.25)
    rp = MovingReplanner(pad, CONFIG, rc)
    assert rp.step(0.0, behind(pad)).action is avp.ReplanAction.INITIAL_PLAN
    plan = rp.trajectory
    t = plan.tf - left
    far = MovingTarget.on_platform([30.0, 10.0, 1.0], incline=0.5, speed=2.5, turn_rate=0.2, time=t)
    step = rp.step(t, _on_plan(plan, t), far)
    assert step.action is avp.ReplanAction.CANNOT_REACH and rp.cannot_reach, step.reason
    assert rp.trajectory is plan  # nothing committed
    predicted = far.predict([plan.tf])[0][0]
    committed = pad.predict([plan.tf])[0][0]
    assert step.target_error == pytest.approx(float(np.linalg.norm(predicted - committed)), rel=1e-9)
    assert step.target_error > 25.0 and math.isinf(step.reach_budget)
    assert np.linalg.norm(plan(plan.tf) - committed) < 0.5  # the plan ends at the committed pad


def test_moving_replanner_consistent_estimate_is_not_cannot_reach():
    """The same platform, estimated again mid-flight (its own prediction): the predicted pad at
    contact has not moved, so no step says CANNOT_REACH and the replans commit."""
    from avp.moving import MovingReplanner

    pad = platform(0.5, 2.5, 0.2)
    rp = MovingReplanner(pad, CONFIG, avp.ReplanConfig(freeze_horizon=0.25))
    rp.step(0.0, behind(pad))
    plan = rp.trajectory
    for t in np.arange(1, 8) / 30.0:
        step = rp.step(float(t), _on_plan(rp.trajectory, float(t)), pad.at(float(t)))
        assert step.action is avp.ReplanAction.REPLANNED, step.reason
        assert step.target_error < 1e-9
    assert rp.trajectory.tf == pytest.approx(plan.tf)
    # frozen near contact, the pad a few metres on from where it was at the start: compared at
    # the contact time, the estimate agrees with the committed contact point
    t = rp.trajectory.tf - 0.1
    step = rp.step(t, _on_plan(rp.trajectory, t), pad.at(t))
    assert step.action is avp.ReplanAction.FROZEN_NEAR_CONTACT and step.target_error < 1e-9, step.reason


def test_moving_start_at_rest_on_a_stopped_pad_is_a_typed_error():
    """config.min_distance as for a static pad: a start 2 cm from a pad that does not move, at
    rest relative to it, is a ConfigError naming target.point; the same start moving with a
    2 m/s platform, 2 cm behind its pad, too (relative rest); a start 2 m away is planned."""
    from avp.errors import ConfigError

    for pad in (platform(0.5, 0.0), platform(0.5, 2.0)):
        near = avp.State(position=pad.point - [0.02, 0.0, 0.0], velocity=pad.velocity)
        with pytest.raises(ConfigError, match="target.point"):
            plan_moving_detailed(near, pad, CONFIG)
    # a start one second after the estimate: the pad where it is then, 2 cm ahead (an error) or
    # 2 m ahead (planned), not where the estimate saw it
    pad = platform(0.5, 2.0)
    later = pad.at(1.0)
    for gap, fails in ((0.02, True), (2.0, False)):
        start = avp.State(position=later.point - [gap, 0.0, 0.0], velocity=later.velocity, time=1.0)
        if fails:
            with pytest.raises(ConfigError, match="target.point"):
                plan_moving_detailed(start, pad, CONFIG)
        else:
            assert plan_moving_detailed(start, pad, CONFIG).trajectory is not None
    pad = platform(0.5, 0.0)
    res = plan_moving_detailed(avp.State(position=pad.point - [2.0, 0.0, 0.0]), pad, CONFIG)
    assert res.trajectory is not None


def test_moving_planner_logs_the_settings_it_does_not_use():
    """Settings of a static perch the moving planner does not use (NOT_USED) are named in its
    log when they differ from the defaults, and leave the plan as it is."""
    from dataclasses import replace

    pad = platform(0.5, 1.0)
    start = behind(pad)
    plain = plan_moving_detailed(start, pad, CONFIG)
    assert not any(entry.startswith("config:") for entry in plain.log)
    changed = replace(CONFIG, flip=replace(CONFIG.flip, turn_rate=0.5),
                      bounds=replace(CONFIG.bounds, relaxations=()))
    res = plan_moving_detailed(start, pad, changed)
    notes = [entry for entry in res.log if entry.startswith("config:")]
    assert len(notes) == 1 and "flip.turn_rate" in notes[0] and "bounds.relaxations" in notes[0]
    assert np.array_equal(res.trajectory.coefficients, plain.trajectory.coefficients)


def test_static_workspace_regions_are_certified_on_moving_plans():
    """Without a ground the 1.5 rad perch swings metres below the pad. A ground 0.5 m below the
    pad gets QP rows and refinement around proven violations, as on a static pad: the plan is
    certified and stays above it on a dense grid. With the rows on 2 samples per segment and no
    refinement they do not keep the ground: an honest WORKSPACE_NOT_CERTIFIED naming it."""
    from dataclasses import replace
    tgt = platform(1.5, 2.0, 0.2)
    free = plan_moving_detailed(behind(tgt), tgt, CONFIG)
    assert free.ok and free.trajectory(free.trajectory.sample(1e-3))[:, 2].min() < 0.5
    res = plan_moving_detailed(behind(tgt), tgt, replace(CONFIG, workspace=avp.Workspace(ground_z=0.5)))
    assert res.ok and res.safety is not None and res.safety.certified
    assert res.trajectory(res.trajectory.sample(1e-4))[:, 2].min() >= 0.5 - 1e-9
    sparse = replace(CONFIG, workspace=avp.Workspace(ground_z=0.0, refinement_rounds=0, samples_per_segment=2))
    bad = plan_moving_detailed(behind(tgt), tgt, sparse)
    assert bad.status is avp.PlanStatus.WORKSPACE_NOT_CERTIFIED and bad.trajectory is None
    assert bad.safety is not None and "ground" in bad.safety.failed
    with pytest.raises(avp.WorkspaceNotCertifiedError):
        plan_moving(behind(tgt), tgt, sparse)


def test_the_static_planner_refuses_a_moving_pad():
    """avp.plan would freeze the pad at its current pose: a typed error points to plan_moving."""
    state = avp.State.hover([-3.0, 0.0, 1.0])
    with pytest.raises(avp.ConfigError, match="plan_moving"):
        avp.plan_detailed(state, platform(0.5, 2.0), CONFIG)
    still = MovingTarget.from_pad(avp.PerchTarget.from_incline([0.0, 0.0, 1.0], 0.5))
    assert avp.plan_detailed(state, still, CONFIG).ok  # a pad that does not move is a static pad


@pytest.mark.parametrize("turn", [0.8, 1.5, -2.0])
def test_fast_turns_cap_the_taylor_order_soundly(turn):
    """A fast or long turn needs more than the kernel's degree 40: the order is capped and the
    larger remainder keeps the verdict sound."""
    from avp.moving_clearance import MAX_TAYLOR_ORDER
    tgt = platform(0.5, 3.0, turn)
    traj, _ = solve_fixed(behind(tgt), tgt, 4.0)
    rep = certify_moving_clearance(traj, tgt)
    assert rep.taylor_order <= MAX_TAYLOR_ORDER
    h = clearance(traj, tgt, np.linspace(traj.t0, traj.tf, 20001))
    if rep.certified:
        assert h[:-1].min() > min(0.0, rep.contact_residual_lower) - 1e-12
    if h.min() < -1e-9:
        assert not rep.certified


def test_a_start_or_a_stopped_pad_outside_the_static_workspace_is_bad_input():
    """The static limits (ground, keep-out spheres, speed) are checked on the start, and on the
    contact point of a pad that does not move, as the static planner checks them: the same typed
    error on the same field as avp.plan for the pad's pose. They used to be searched for and
    reported as 'the limits may not allow catching this platform'."""
    ground = replace(CONFIG, workspace=avp.Workspace(ground_z=1.0))
    cases = [
        (avp.State(position=[-3.0, 0.0, 1.5]), MovingTarget.on_platform([0.0, 0.0, 0.5], incline=0.5, speed=0.0),
         ground, "target.point"),
        (avp.State(position=[-3.0, 0.0, 0.5]), MovingTarget.on_platform([0.0, 0.0, 1.5], incline=0.5, speed=1.0),
         ground, "state.position"),
        (avp.State(position=[-3.0, 0.0, 1.5]), MovingTarget.on_platform([0.0, 0.0, 1.5], incline=0.5, speed=1.0),
         replace(CONFIG, workspace=avp.Workspace(spheres=(avp.Sphere(center=(-3.0, 0.0, 1.4), radius=0.5),))),
         "state.position"),
        (avp.State(position=[-3.0, 0.0, 1.5], velocity=[3.0, 0.0, 0.0]),
         MovingTarget.on_platform([0.0, 0.0, 1.5], incline=0.5, speed=1.0),
         replace(CONFIG, workspace=avp.Workspace(max_speed=2.0)), "state.velocity"),
    ]
    for state, pad, config, field in cases:
        with pytest.raises(ConfigError) as exc:
            plan_moving_detailed(state, pad, config)
        assert exc.value.field == field, exc.value
        if pad.is_static and field != "state.velocity":  # the static planner on the same pose says the same
            with pytest.raises(ConfigError) as same:
                avp.plan(state, pad.static(), config)
            assert same.value.field == field


def test_a_moving_pad_outside_the_workspace_at_every_arrival_time_is_said_so():
    """A pad that moves below the ground: no arrival time can reach it whatever the limits. The
    status is WORKSPACE_NOT_CERTIFIED (not BOUNDS_NOT_CERTIFIED, which a replanner takes for a
    duration problem) and the log (and plan_moving's error) ends by saying so."""
    ground = replace(CONFIG, workspace=avp.Workspace(ground_z=1.0))
    pad = MovingTarget.on_platform([0.0, 0.0, 0.5], incline=0.5, speed=1.0)
    res = plan_moving_detailed(avp.State(position=[-3.0, 0.0, 1.5]), pad, ground)
    assert res.status is avp.PlanStatus.WORKSPACE_NOT_CERTIFIED and res.trajectory is None  # not the limits
    assert res.candidates
    for c in res.candidates:  # independent of the planner's regions: the pad's height at each arrival time
        at = pad.at(0.0, c.duration)
        assert at.point[2] + CONFIG.workspace.body_offset * at.s3[2] < 1.0
    assert "outside the workspace limit(s) ground at every arrival time tried" in res.log[-1]
    assert "may not allow catching" not in "\n".join(res.log)
    with pytest.raises(avp.WorkspaceNotCertifiedError) as exc:
        plan_moving(avp.State(position=[-3.0, 0.0, 1.5]), pad, ground)
    assert str(exc.value).endswith("check the pad's position and motion and the workspace limits")
    # above the ground the same pad is planned (the check does not fire on a reachable pad)
    up = MovingTarget.on_platform([0.0, 0.0, 1.5], incline=0.5, speed=1.0)
    assert plan_moving_detailed(avp.State(position=[-3.0, 0.0, 1.5]), up, ground).ok


def test_moving_plans_carry_their_provenance_into_exports():
    """A moving plan's trajectory carries its status and certificates, as avp.plan's (it had
    ``provenance`` None, so an export did not say it was certified)."""
    from avp.trajectory import Trajectory
    tgt = platform(1.5, 2.0, 0.2)
    res = plan_moving_detailed(behind(tgt), tgt, replace(CONFIG, workspace=avp.Workspace(ground_z=0.5)))
    assert res.ok and res.trajectory is not None and res.bounds is not None
    prov = res.trajectory.provenance
    assert prov is not None and prov.status == avp.PlanStatus.SOLVED.value and not prov.relaxed
    assert prov.bounds_certified == res.bounds.certified
    regions = [r for r in (res.clearance, res.safety) if r is not None]
    assert regions and prov.workspace_certified == all(r.certified for r in regions)
    assert Trajectory.from_json(res.trajectory.to_json()).provenance == prov


def test_plan_moving_takes_the_fixed_arrival_time_of_plan_moving_detailed():
    """``plan_moving`` is the raising form of ``plan_moving_detailed`` and takes its ``duration``
    (a TypeError before): the same plan, ending at the given arrival time."""
    tgt = platform(0.5, 2.0)
    detailed = plan_moving_detailed(behind(tgt), tgt, CONFIG, duration=2.5)
    assert detailed.ok and detailed.trajectory is not None
    traj = plan_moving(behind(tgt), tgt, CONFIG, duration=2.5)
    assert traj.duration == pytest.approx(2.5, abs=1e-12)
    np.testing.assert_array_equal(traj.coefficients, detailed.trajectory.coefficients)


def test_a_clearance_failing_only_at_contact_says_so():
    """A 9000 s arrival time: every segment of the clearance is proven, but the plan's rounding
    puts the contact point up to 2.5e-7 m behind the pad's plane, beyond the 1e-9 m tolerance.
    The log said only "NOT certified (within, within, within)"; it now says why, and a
    certified report does not."""
    pad = MovingTarget.on_platform([0.0, 0.0, 1.5], incline=0.5, speed=1.0)
    far = plan_moving_detailed(avp.State(position=[-3.0, 0.0, 1.5]), pad, avp.PlannerConfig(), duration=9000.0)
    rep = far.clearance
    assert far.status is avp.PlanStatus.WORKSPACE_NOT_CERTIFIED and rep is not None
    assert all(rep.segments) and rep.contact_residual_lower < -rep.contact_tol
    assert "behind the pad's plane, beyond the tolerance" in rep.summary()
    assert "behind the pad's plane" in far.log[-1]
    near = plan_moving_detailed(avp.State(position=[-3.0, 0.0, 1.5]), pad, avp.PlannerConfig(), duration=20.0)
    assert near.ok and near.clearance is not None and near.clearance.certified
    assert "behind the pad's plane" not in near.clearance.summary()
