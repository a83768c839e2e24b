"""Planner-level bound certification (Sec. V-C): whatever the planner returns as solved meets
every vehicle limit on a dense grid, and the time search / relaxations are reported."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scenarios import standard, standard_grid

import avp

GRID = 1e-4  # s, the 0.1 ms sample grid


def assert_within_limits(traj: avp.Trajectory, limits: avp.VehicleLimits) -> None:
    t = traj.sample(GRID)
    f = traj.thrust(t)
    assert f.max() < limits.accel_max and f.min() > limits.accel_min
    w = traj.body_rates(t)
    if math.isfinite(limits.tilt_rate_max):
        assert np.linalg.norm(w[:, :2], axis=1).max() < limits.tilt_rate_max
    if math.isfinite(limits.thrust_rate_max):
        assert (limits.mass * np.linalg.norm(traj(t, 3), axis=1)).max() < limits.thrust_rate_max


TIGHT = avp.VehicleLimits(mass=0.5, thrust_min=0.5 * 2.0, thrust_max=0.5 * 13.0, thrust_rate_max=0.5 * 60.0, tilt_rate_max=4.0)


@pytest.mark.parametrize("scenario", standard_grid(), ids=lambda s: s.name)
def test_tight_limits_force_changes_and_the_result_meets_them(scenario) -> None:
    config = avp.PlannerConfig(limits=TIGHT)
    result = avp.plan_detailed(scenario.state, scenario.target, config)
    if result.ok:
        assert result.bounds is not None and result.bounds.certified
        assert_within_limits(result.trajectory, TIGHT)
    else:  # reported, with the uncertified trajectory and the report attached
        assert result.status is avp.PlanStatus.BOUNDS_NOT_CERTIFIED
        with pytest.raises(avp.BoundsNotCertifiedError) as exc:
            avp.plan(scenario.state, scenario.target, config)
        assert exc.value.result.bounds is not None and not exc.value.result.bounds.certified


def test_tight_limits_do_force_duration_changes_somewhere() -> None:
    """The scenario set above is not vacuous: the defaults violate TIGHT on some of them."""
    steps = [avp.plan_detailed(s.state, s.target, avp.PlannerConfig(limits=TIGHT)).duration_scale_steps
             for s in standard_grid()]
    assert max(steps) >= 1


@st.composite
def random_case(draw: st.DrawFn):
    incline = draw(st.floats(0.0, math.pi / 2))
    distance = draw(st.floats(1.5, 7.5))
    pad = np.array([0.0, 0.0, 2.0])
    target = avp.PerchTarget.from_incline(pad, incline)
    start = pad - np.array([distance, 0.0, 0.0]) + np.array([0.0, draw(st.floats(-1, 1)), draw(st.floats(-0.5, 1.0))])
    if (start - pad) @ target.s3 < 0.1:  # on or behind a low pad's plane: lift it above the pad
        start[2] = pad[2] + 0.1 + draw(st.floats(0.0, 1.0))
    limits = avp.VehicleLimits(
        mass=1.0, thrust_min=draw(st.floats(0.5, 3.5)), thrust_max=draw(st.floats(12.0, 20.0)),
        tilt_rate_max=draw(st.floats(3.0, 10.0)),
    )
    return avp.State.hover(start), target, limits


@settings(max_examples=25)
@given(random_case())
def test_random_scenarios_certified_plans_meet_bounds_on_dense_grid(case) -> None:
    state, target, limits = case
    result = avp.plan_detailed(state, target, avp.PlannerConfig(limits=limits))
    if result.ok:
        assert result.bounds.certified
        assert_within_limits(result.trajectory, limits)
    else:
        assert result.status in (avp.PlanStatus.BOUNDS_NOT_CERTIFIED, avp.PlanStatus.INFEASIBLE,
                                 avp.PlanStatus.WORKSPACE_NOT_CERTIFIED)


def test_a_flat_secant_in_the_time_search_does_not_overflow() -> None:
    """Found by the random scenarios above (unseeded run): a wall 1.5 m ahead with a 12 m/s^2
    thrust ceiling and 3 rad/s. The scaling search's secant was nearly flat and math.exp of its
    far-off root overflowed out of plan_detailed as an OverflowError; now the step is clamped to
    the search range and the result is an honest status."""
    state = avp.State.hover([-1.5, 0.0, 2.0])
    target = avp.PerchTarget.from_incline([0.0, 0.0, 2.0], math.pi / 2)
    limits = avp.VehicleLimits(mass=1.0, thrust_min=1.0, thrust_max=12.0, tilt_rate_max=3.0)
    result = avp.plan_detailed(state, target, avp.PlannerConfig(limits=limits))
    if result.ok:
        assert result.bounds.certified
        assert_within_limits(result.trajectory, limits)
    else:
        assert result.status in (avp.PlanStatus.BOUNDS_NOT_CERTIFIED, avp.PlanStatus.WORKSPACE_NOT_CERTIFIED)


GAO = avp.VehicleLimits(mass=1.0, thrust_min=5.0, thrust_max=17.0, tilt_rate_max=3.0)


def gao_case(incline_deg: float):
    target = avp.PerchTarget.from_incline([3.0, 0.0, 1.5], math.radians(incline_deg))
    return avp.State.hover([0.0, 0.0, 1.5]), target


def test_gao_90_deg_fails_with_the_paper_band_and_no_relaxation() -> None:
    """Reproduces Gao et al.'s claim: with band (14) active, no duration certifies at 90 deg."""
    state, target = gao_case(90)
    policy = avp.BoundsPolicy(time_search=avp.TimeSearch.BIDIRECTIONAL, relaxations=())
    config = avp.PlannerConfig(limits=GAO, alpha=5.5, bounds=policy)
    result = avp.plan_detailed(state, target, config)
    assert result.status is avp.PlanStatus.BOUNDS_NOT_CERTIFIED
    assert result.duration_scale_steps == len(config.bounds.schedule())
    # the default (SCALING) search reaches the same verdict in fewer solves
    scaling = avp.plan_detailed(state, target, avp.PlannerConfig(limits=GAO, alpha=5.5, bounds=avp.BoundsPolicy(relaxations=())))
    assert scaling.status is avp.PlanStatus.BOUNDS_NOT_CERTIFIED
    assert scaling.duration_scale_steps < result.duration_scale_steps


@pytest.mark.parametrize("incline", [30, 60, 90])
def test_gao_setting_is_certified_with_relaxations(incline) -> None:
    state, target = gao_case(incline)
    config = avp.PlannerConfig(limits=GAO, alpha=5.5)
    result = avp.plan_detailed(state, target, config)
    assert result.ok, result.log
    assert_within_limits(result.trajectory, GAO)
    # planar manoeuvre: the full body rate equals the tilt rate, so |w| <= 3 rad/s holds too
    w = result.trajectory.body_rates(result.trajectory.sample(GRID))
    assert np.linalg.norm(w, axis=1).max() < 3.0
    if incline == 90:
        assert result.relaxations, "the 90 deg case needs a relaxation (the band blocks it)"


def test_paper_time_search_only_lengthens() -> None:
    sc = standard(90, 3.5)
    limits = avp.VehicleLimits(mass=0.5, thrust_max=0.5 * 13.0, tilt_rate_max=4.0)
    policy = avp.BoundsPolicy(time_search=avp.TimeSearch.PAPER, relaxations=())
    result = avp.plan_detailed(sc.state, sc.target, avp.PlannerConfig(limits=limits, bounds=policy))
    first = avp.plan_detailed(sc.state, sc.target, avp.PlannerConfig(limits=limits, bounds=avp.BoundsPolicy(certify=False)))
    if result.trajectory is not None:
        assert result.trajectory.duration >= first.trajectory.duration - 1e-12
    assert all(f > 1 for f in policy.schedule())


def test_alpha_outside_thrust_limits_is_a_config_error() -> None:
    with pytest.raises(avp.ConfigError) as exc:
        avp.PlannerConfig(limits=GAO, alpha=4.0)
    assert exc.value.field == "config.alpha"
