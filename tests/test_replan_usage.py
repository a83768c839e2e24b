"""The replanners under the irregular use of a real flight stack (found by an audit of the API):
a plan handed in, a pad turned about its normal or flipped, a moving planner that retimes, line
estimates that change more than their vertices, bad times, an estimate on another clock, and a
yaw that odometry wraps."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

import avp
from avp.moving import MovingReplanner, plan_moving_detailed
from avp.platform import MovingTarget
from avp.replan import ReplanAction

WALL = avp.PerchTarget.from_incline([4.5, 0.0, 1.5], math.pi / 2)
START = avp.State.hover([0.0, 0.0, 1.5])
MOVING_CFG = avp.PlannerConfig(limits=avp.VehicleLimits(mass=1.0, thrust_min=5.0, thrust_max=17.0, tilt_rate_max=3.0),
                               alpha=5.5, pre_impact=avp.PreImpactMode.OFF)


def _fly(rp: avp.Replanner, t: float) -> avp.State:
    """Odometry of a vehicle that tracks the reference perfectly."""
    f = rp.reference(t)
    return avp.State(position=f.position, velocity=f.velocity, acceleration=f.acceleration, jerk=f.jerk,
                     yaw=float(f.yaw), yaw_rate=float(f.yaw_rate), time=t)


def test_a_plan_handed_in_sets_the_snap_limits_as_a_first_plan_does():
    """Replans certify snap against the first plan's peaks; a plan given to the constructor is
    that first plan (before, the defaults stayed, and a short perch, whose own peak is above
    them, could not replan at all)."""
    near = avp.PerchTarget.from_incline([1.5, 0.0, 1.5], math.pi / 2)
    own = avp.Replanner(near)
    own.step(0.0, START)
    given = avp.Replanner(near, trajectory=own.trajectory)
    assert given.snap_limits == own.snap_limits
    assert given.snap_limits[1] > avp.ReplanConfig().snap_thrust_max  # the perch's own peak is above the default
    moved = avp.PerchTarget(point=near.point + [0.0, 0.0, 0.01], R_WS=near.R_WS)
    actions = [rp.step(0.2, _fly(rp, 0.2), moved).action for rp in (own, given)]
    assert actions[0] is actions[1] is ReplanAction.REPLANNED


def test_a_level_pad_estimated_from_noisy_normals_holds_its_contact_yaw():
    """A floor pad re-estimated from a plane fit (``from_normal``, 1 mrad of normal noise): the
    frame's rotation about the normal is arbitrary, and is not a change. An attempt to replan on
    it (the frame's full rotation) replanned every step and swung the contact yaw by 170 deg."""
    pad = avp.PerchTarget.from_normal([3.0, 0.0, 0.5], [0.0, 0.0, 1.0])
    rng = np.random.default_rng(0)
    rp = avp.Replanner(pad)
    rp.step(0.0, START)
    yaw0 = float(rp.trajectory.yaw(rp.trajectory.tf))
    steps = [rp.step(t, _fly(rp, t), avp.PerchTarget.from_normal(pad.point, [0.0, 0.0, 1.0] + 1e-3 * rng.normal(size=3)))
             for t in np.arange(1, 40) / 30]
    assert all(s.action in (ReplanAction.HELD, ReplanAction.FROZEN_NEAR_CONTACT) for s in steps)
    assert float(rp.trajectory.yaw(rp.trajectory.tf)) == yaw0


def test_a_flipped_normal_is_not_blended():
    """An estimate of the wall with its normal reversed: no partial correction (a blend of the
    two frames is the committed frame below half the correction, degenerate at half). Before,
    every step committed a "50 %" plan to the unchanged target."""
    flipped = avp.PerchTarget.from_normal(WALL.point, -WALL.s3)
    rp = avp.Replanner(WALL)
    rp.step(0.0, START)
    steps = [rp.step(t, _fly(rp, t), flipped) for t in (0.5, 0.55, 0.6)]
    assert all(s.action is not ReplanAction.PARTIAL and s.fraction in (0.0, 1.0) for s in steps)
    assert all(s.n_solves <= 1 + len(avp.ReplanConfig().retime_retries) for s in steps)
    # flipped and moved beyond the reach budget late in the flight: nothing to try, the cue
    late = avp.Replanner(WALL)
    late.step(0.0, START)
    away = avp.PerchTarget.from_normal(WALL.point + [0.0, 0.5, 0.0], -WALL.s3)
    step = late.step(1.9, _fly(late, 1.9), away)
    assert step.action is ReplanAction.CANNOT_REACH and step.n_solves == 0 and step.reach_budget < 0.5
    assert "no partial correction" in step.reason


def test_a_moving_replan_that_moves_the_contact_time_says_so():
    """The moving planner nudges the time left by ``MovingConfig.retime`` when the nominal one
    does not certify; the step reports the factor (it said 1.0 and "ok")."""
    pad = MovingTarget.on_platform([0.0, 0.0, 1.0], incline=0.5, speed=2.0)
    rp = MovingReplanner(pad, MOVING_CFG)
    rp.step(0.0, avp.State(position=[-3.0, 0.0, 1.0], velocity=[2.0, 0.0, 0.0]), pad)
    moved = 0
    for t in np.arange(1, 70) / 30:
        now = pad.at(t)
        est = now if t < 0.8 else MovingTarget(point=now.point, R_WS=now.R_WS, heading=now.heading, speed=1.0, time=t)
        before = rp.trajectory.tf
        step = rp.step(t, _fly(rp, t), est)
        if step.committed and step.t_ex < before:
            nominal = before - step.t_ex
            assert step.time_factor == pytest.approx(rp.trajectory.duration / nominal, rel=1e-12)
            if abs(rp.trajectory.tf - before) > 1e-9:
                moved += 1
                assert step.time_factor != 1.0 and "time left x" in step.reason
    assert moved >= 1


@pytest.mark.parametrize("field, value", [("grasp", 0.25), ("pitch", math.radians(30))])
def test_a_line_estimate_with_a_new_grasp_or_pitch_is_not_held(field, value):
    limits = avp.VehicleLimits(mass=0.8, thrust_min=0.5, thrust_max=4.0 * 0.8 * 9.81)
    line = avp.LineTarget.segment([2.5, -1.5, 3.94], [2.5, 1.5, 4.46], pitch=math.radians(80), gripper_offset=0.15)
    rp = avp.LineReplanner(line, avp.PlannerConfig(limits=limits))
    rp.step(0.0, avp.State.hover([0.0, 0.0, 4.0]))
    estimate = dataclasses.replace(line, **{field: value})
    first = rp.step(1 / 30, _fly(rp, 1 / 30), estimate)
    assert first.action is ReplanAction.REPLANNED
    assert getattr(rp.committed_target, field) == value


def test_bad_times_are_typed_errors_and_do_not_lock_the_replanner():
    rp = avp.Replanner(WALL)
    rp.step(0.0, START)
    for bad in (None, "0.5", [0.5, 0.6], True, math.nan):
        with pytest.raises(avp.ConfigError) as exc:
            rp.reference(bad)
        assert exc.value.field == "t"
    with pytest.raises(avp.ConfigError) as exc:  # a millisecond timestamp by mistake
        rp.step(1.7e12, START)
    assert exc.value.field == "t"
    assert rp.step(0.1, _fly(rp, 0.1)).action is not ReplanAction.NO_PLAN  # not locked out


def test_a_moving_estimate_on_another_clock_is_a_typed_error():
    """A platform estimate stamped in UNIX time against a loop in seconds since take-off puts the
    pad 3.4e9 m away at the state's time: a ConfigError naming the estimate's time (it was an
    "infeasible" plan, or CANNOT_REACH mid-flight)."""
    pad = MovingTarget.on_platform([0.0, 0.0, 1.0], incline=0.5, speed=2.0, time=1.7e9)
    start = avp.State(position=[-3.0, 0.0, 1.0], velocity=[2.0, 0.0, 0.0])
    with pytest.raises(avp.ConfigError) as exc:
        plan_moving_detailed(start, pad, MOVING_CFG)
    assert exc.value.field == "target.time"
    rp = MovingReplanner(MovingTarget.on_platform([0.0, 0.0, 1.0], incline=0.5, speed=2.0), MOVING_CFG)
    with pytest.raises(avp.ConfigError) as exc:
        rp.step(0.0, start, pad)
    assert exc.value.field == "target_estimate.time"


def test_a_wrapped_odometry_yaw_continues_the_plan_yaw():
    """A perch heading to -x flies at yaw pi; odometry reports it wrapped to (-pi, pi]. A step that
    re-anchors on odometry takes the yaw on the plan's branch: the reference yaw is continuous
    at the switch (it jumped by 2 pi)."""
    target = avp.PerchTarget.from_incline([-4.5, 0.0, 1.5], math.pi / 2, heading=math.pi)
    rp = avp.Replanner(target)
    rp.step(0.0, avp.State.hover([0.0, 0.0, 1.5], yaw=math.pi))
    f = rp.reference(0.5)
    wrapped = (float(f.yaw) + math.pi) % (2 * math.pi) - math.pi
    assert abs(wrapped - float(f.yaw)) > math.pi  # the case: odometry is on the other branch
    off = avp.State(position=f.position + [0.0, 0.3, 0.0], velocity=f.velocity + [0.0, 0.6, 0.0],
                    acceleration=f.acceleration, jerk=f.jerk, yaw=wrapped, yaw_rate=float(f.yaw_rate), time=0.5)
    step = rp.step(0.5, off, None)
    assert step.committed and not step.anchored
    before, after = rp.reference(step.t_ex - 1e-4), rp.reference(step.t_ex + 1e-4)
    assert abs(float(after.yaw) - float(before.yaw)) < 0.01


def test_an_estimate_turned_beyond_reach_says_cannot_reach():
    """The wall re-estimated as a 60 deg slope late in the flight: no certified plan turns the
    contact by 30 deg, and the step says so (it said KEPT_PREVIOUS with a target error of 0 m:
    the cue counted distance only)."""
    slope = avp.PerchTarget.from_incline(WALL.point, math.radians(60))
    rp = avp.Replanner(WALL)
    rp.step(0.0, START)
    steps = [rp.step(t, _fly(rp, t), slope) for t in np.arange(48, 75) / 30]
    uncorrected = [s for s in steps if not s.committed]
    assert uncorrected and all(s.action is ReplanAction.CANNOT_REACH for s in uncorrected)
    assert all(s.target_angle == pytest.approx(math.radians(30), abs=1e-9) for s in uncorrected)
    assert all("30.0 deg" in s.reason for s in uncorrected)
    # a turn within the tolerance is not the cue
    within = avp.Replanner(WALL, replan=avp.ReplanConfig(reach_angle_tolerance=math.radians(40)))
    within.step(0.0, START)
    assert all(within.step(t, _fly(within, t), slope).action is not ReplanAction.CANNOT_REACH
               for t in np.arange(48, 75) / 30)


def test_the_time_factor_of_a_committed_fraction_is_its_own():
    """With ``retime_normal`` each fraction has its own nominal time left; the smallest one,
    committed after the fractions between failed, reports 1 (it reported the last fraction's
    ratio, 0.96, and "the nominal time failed a certificate")."""
    rp = avp.Replanner(WALL, replan=avp.ReplanConfig(retime_normal=True, retime_retries=()))
    rp.step(0.0, START)
    deeper = avp.PerchTarget(point=WALL.point - 0.2 * WALL.s3, R_WS=WALL.R_WS)
    real = rp._plan

    def only_the_smallest(state, target, durations, previous, config, deadline=None):
        if abs(float(np.linalg.norm(target.point - WALL.point)) / 0.2 - 0.125) > 1e-6:
            return None, 0.0, "forced failure"
        return real(state, target, durations, previous, config, deadline)

    rp._plan = only_the_smallest
    step = rp.step(0.5, _fly(rp, 0.5), deeper)
    assert step.committed and step.fraction == 0.125  # a partial commit (labelled CANNOT_REACH: 17.5 cm left)
    assert step.time_factor == pytest.approx(1.0, abs=1e-12) and "time left x" not in step.reason


def test_a_line_estimate_within_the_tolerances_is_held():
    """Fields other than the vertices compare within ``target_tolerance`` (a radius re-measured
    to 1e-7 m, a side vector recomputed each step): the step holds."""
    limits = avp.VehicleLimits(mass=0.8, thrust_min=0.5, thrust_max=4.0 * 0.8 * 9.81)
    line = avp.LineTarget.segment([2.5, -1.5, 3.94], [2.5, 1.5, 4.46], pitch=math.radians(80), gripper_offset=0.15,
                                  side=[-1.0, 0.0, 0.0])
    rp = avp.LineReplanner(line, avp.PlannerConfig(limits=limits))
    rp.step(0.0, avp.State.hover([0.0, 0.0, 4.0]))
    again = dataclasses.replace(line, radius=line.radius + 1e-7, side=[-1.0, 1e-4, 0.0])
    assert rp.step(1 / 30, _fly(rp, 1 / 30), again).action is ReplanAction.HELD


def test_bad_clocks_of_a_moving_replanner_are_typed_errors():
    pad = MovingTarget.on_platform([0.0, 0.0, 1.0], incline=0.5, speed=2.0)
    start = avp.State(position=[-3.0, 0.0, 1.0], velocity=[2.0, 0.0, 0.0])
    with pytest.raises(avp.ConfigError) as exc:  # a millisecond timestamp: the step's own clock
        MovingReplanner(pad, MOVING_CFG).step(1.7e12, start, pad)
    assert exc.value.field == "t"
    unix = dataclasses.replace(pad, time=1.7e9)  # the constructor's estimate on another clock
    with pytest.raises(avp.ConfigError) as exc:
        MovingReplanner(unix, MOVING_CFG).step(0.0, start)
    assert exc.value.field == "target.time"
    rp = avp.Replanner(WALL)
    rp.step(0.0, START)
    with pytest.raises(avp.ConfigError) as exc:
        rp.reference(10**400)  # OverflowError before
    assert exc.value.field == "t"


def test_a_step_before_the_committed_plan_starts_is_never_cannot_reach() -> None:
    """With a latency longer than the step period, a step before the new plan's switch time
    keeps it without trying anything: no CANNOT_REACH (no plan was tried), whatever the estimate
    (it was relabelled CANNOT_REACH with n_solves 0 and a 10 m budget); the next step replans."""
    pad = avp.PerchTarget.from_incline([3.5, 0.0, 1.5], math.pi / 2)

    def shifted(dy: float) -> avp.PerchTarget:
        return avp.PerchTarget(point=pad.point + [0.0, dy, 0.0], R_WS=pad.R_WS)

    rp = avp.Replanner(pad, replan=avp.ReplanConfig(latency=0.1))
    steps = []
    for t, est in [(0.0, None), (1 / 30, shifted(0.01)), (2 / 30, shifted(0.10)), (3 / 30, None), (4 / 30, None)]:
        ref = rp.reference(t) if t > 0 else None
        odo = avp.State.hover([0.0, 0.0, 1.5]) if ref is None else avp.State(
            position=ref.position, velocity=ref.velocity, acceleration=ref.acceleration, time=t)
        steps.append(rp.step(t, odo, est))
    waiting = [s for s in steps if "has not started" in s.reason]
    assert waiting and all(s.action is ReplanAction.KEPT_PREVIOUS and s.n_solves == 0 for s in waiting)
    assert any(s.target_error > 0.05 for s in waiting)  # the estimate was beyond reach_tolerance
    assert steps[-1].action in (ReplanAction.REPLANNED, ReplanAction.PARTIAL)


def _perched() -> avp.Replanner:
    rp = avp.Replanner(WALL)
    rp.step(0.0, START)
    return rp


def test_a_vehicle_far_off_the_plan_says_off_track_whatever_the_pad():
    """A vehicle 0.6 m beside its reference whose replans from odometry fail flies on with a
    plan that does not start where it is: the steps say so (``off_track``, the tracking error,
    the reason), though the pad estimate is exact and ``CANNOT_REACH`` stays silent (it is
    about the pad). Found by a review: the reasons spoke only of certificates."""
    rp = _perched()
    tf = rp.trajectory.tf
    offset = np.array([0.0, 0.6, 0.0])
    steps = []
    for t in (0.6 * tf, 0.62 * tf, tf - 0.05):
        f = rp.reference(t)
        steps.append(rp.step(t, avp.State(position=f.position + offset, velocity=f.velocity), None))
    kept = [s for s in steps if s.action is not ReplanAction.REPLANNED and s.action is not ReplanAction.PARTIAL]
    assert kept, "a plan from 0.6 m off certified: the scenario no longer tests a kept plan"
    for s in kept:
        assert s.off_track and s.reason.startswith("off track: odometry 0.600 m")
        assert s.tracking_error == pytest.approx(0.6, abs=1e-9)
    for s in steps:
        if s.action in (ReplanAction.REPLANNED, ReplanAction.PARTIAL):
            assert not s.off_track and "planned from odometry" in s.reason


def test_a_tracked_plan_is_never_off_track_and_tracking_is_not_measured_past_contact():
    rp = _perched()
    tf = rp.trajectory.tf
    steps = [rp.step(t, _fly(rp, min(t, tf)), WALL) for t in np.arange(1, 90) / 30]
    assert any(s.t > tf for s in steps)
    for s in steps:
        assert not s.off_track
        if s.t <= tf:
            assert s.tracking_error == pytest.approx(0.0, abs=1e-9)
        else:  # the perch is over: the contact state held is not a reference to be off
            assert math.isnan(s.tracking_error) and math.isnan(s.tracking_velocity_error)


def test_plan_at_is_the_plan_the_reference_comes_from():
    rp = _perched()
    first = rp.trajectory
    moved = avp.PerchTarget(point=WALL.point + [0.0, 0.0, 0.01], R_WS=WALL.R_WS)
    s = rp.step(0.3, _fly(rp, 0.3), moved)
    assert s.committed and rp.trajectory is not first and rp.trajectory.t0 > 0.3
    before, after = 0.5 * (0.3 + rp.trajectory.t0), rp.trajectory.t0 + 0.1
    assert rp.plan_at(before) is first and rp.plan_at(after) is rp.trajectory
    for t in (before, after):
        np.testing.assert_array_equal(rp.reference(t).position, rp.plan_at(t)(t))
    with pytest.raises(avp.ConfigError, match="no plan committed"):
        avp.Replanner(WALL).plan_at(0.0)


def test_a_plan_handed_in_for_another_pad_is_refused():
    """The replanner takes a plan handed in as ending at its target: one that ends 1 m away was
    held ("estimate moved 0.0000 m") all the way to the wrong contact."""
    plan = avp.plan(START, WALL)
    elsewhere = avp.PerchTarget.from_incline(WALL.point + [0.0, 1.0, 0.0], math.pi / 2)
    with pytest.raises(avp.ConfigError, match=r"trajectory.*ends 1\.000 m from its contact point"):
        avp.Replanner(elsewhere, trajectory=plan)
    rp = avp.Replanner(WALL, trajectory=plan)  # the pad it was made for, then the newer estimate
    s = rp.step(0.2, _fly(rp, 0.2), elsewhere)
    assert s.action is ReplanAction.REPLANNED
    np.testing.assert_allclose(rp.trajectory(rp.trajectory.tf), elsewhere.point, atol=1e-9)


def test_the_reasons_say_the_turn_and_the_time_to_contact():
    """A partial correction of a turned normal said "0.000 m requested"; a frozen step gave the
    time from t_ex as the time to contact."""
    rp = _perched()
    tf = rp.trajectory.tf
    turned = avp.PerchTarget.from_incline(WALL.point, math.radians(80.0))
    s = rp.step(1.5, _fly(rp, 1.5), turned)  # late: only a part of the turn certifies
    assert s.action is ReplanAction.PARTIAL and 0.0 < s.fraction < 1.0
    assert "(0.000 m and 10.0 deg requested" in s.reason
    t = tf - 0.05
    f = rp.step(t, _fly(rp, t), None)
    assert f.action in (ReplanAction.FROZEN_NEAR_CONTACT, ReplanAction.CANNOT_REACH)
    assert f"contact in {rp.trajectory.tf - t:.3f} s" in f.reason


def test_a_partial_commit_from_odometry_reported_as_cannot_reach_is_not_off_track():
    """A step that commits half a 1 m correction from odometry 0.2 m off says ``CANNOT_REACH``
    (the rest is out of reach); the plan it committed starts at the vehicle, so it is not off
    track (a review found both said, the tracking text twice)."""
    truth = avp.PerchTarget.from_incline([3.5, 0.0, 1.5], math.pi / 2)
    rp = avp.Replanner(truth, replan=avp.ReplanConfig(latency=0.02, deadline=None))
    rp.step(0.0, START, truth)
    f = rp.reference(0.8)
    s = rp.step(0.8, avp.State(position=f.position + [0.0, 0.2, 0.0], velocity=f.velocity),
                avp.PerchTarget(point=truth.point + [0.0, 1.0, 0.0], R_WS=truth.R_WS))
    assert s.action is ReplanAction.CANNOT_REACH and s.committed and not s.anchored
    assert not s.off_track and s.reason.count("from the reference") == 1


def test_steps_before_a_plan_from_odometry_starts_are_not_off_track():
    """Until the plan just committed from odometry takes over (its ``t0``), the vehicle is still
    off the previous plan: that is not a plan flown on from elsewhere."""
    rp = avp.Replanner(WALL, replan=avp.ReplanConfig(latency=0.1, deadline=None))
    rp.step(0.0, START)
    first = rp.trajectory
    off = np.array([0.0, 0.3, 0.0])
    s = rp.step(0.5, avp.State(position=first(0.5) + off, velocity=first(0.5, 1)), WALL)
    assert s.committed and not s.anchored and rp.trajectory.t0 > 0.55
    s2 = rp.step(0.55, avp.State(position=first(0.55) + off, velocity=first(0.55, 1)), WALL)
    assert s2.action is ReplanAction.KEPT_PREVIOUS and not s2.off_track
    assert s2.tracking_error == pytest.approx(0.3, abs=1e-9)  # measured, against the plan flown


def test_a_plan_handed_in_with_a_body_offset_ends_at_its_contact_point():
    """The centre of mass of a plan with ``workspace.body_offset`` ends that far off the pad
    along its normal: still the plan made for the pad (a review found it refused)."""
    cfg = avp.PlannerConfig(workspace=avp.Workspace(body_offset=0.1))
    plan = avp.plan(START, WALL, cfg)
    assert np.linalg.norm(plan(plan.tf) - WALL.point) == pytest.approx(0.1, abs=1e-9)
    avp.Replanner(WALL, cfg, trajectory=plan)
    with pytest.raises(avp.ConfigError, match="trajectory"):
        avp.Replanner(WALL, trajectory=plan)  # without the offset the contact point is elsewhere
