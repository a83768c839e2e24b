"""The SCALING time search (avp.time_search): the scaling law against explicitly time-scaled
splines, and the search's factors against its policy."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scenarios import standard, standard_grid

import avp
from avp.time_search import (
    MARGIN,
    SAMPLES_PER_SEGMENT,
    DurationSearch,
    predicted_factor,
    scaled_excess,
)

LIMITS = avp.VehicleLimits(mass=1.0, thrust_min=2.0, thrust_max=15.0, thrust_rate_max=40.0,
                           tilt_rate_max=4.0, body_rate_max=6.0)


def time_scaled(traj: avp.Trajectory, s: float) -> avp.Trajectory:
    """``q(t) = p(t0 + (t - t0) / s)``, built from the coefficients: the k-th ascending
    coefficient of each segment divided by ``s^k``, every knot interval times ``s``."""
    c = traj.coefficients / s ** np.arange(traj.coefficients.shape[2])
    return avp.Trajectory(c, traj.t0 + s * (traj.knots - traj.t0), g=traj.g)


@settings(max_examples=20, deadline=None)
@given(st.sampled_from(standard_grid()), st.floats(0.4, 3.0))
def test_scaling_law_matches_an_explicitly_scaled_spline(scenario, s) -> None:
    traj = avp.plan(scenario.state, scenario.target, avp.PlannerConfig(bounds=avp.BoundsPolicy(certify=False)))
    predicted = scaled_excess(traj, LIMITS, traj.g, np.array([s]))[0]
    direct = scaled_excess(time_scaled(traj, s), LIMITS, traj.g, np.ones(1))[0]
    assert predicted == pytest.approx(direct, rel=1e-9, abs=1e-9)


def test_excess_is_the_sampled_worst_ratio() -> None:
    """At s = 1 the excess is max(value / limit) - 1 over the bounds, recomputed here from the
    trajectory's own thrust and body rates (an independent path through avp.frames)."""
    sc = standard(60, 3.5)
    traj = avp.plan(sc.state, sc.target, avp.PlannerConfig(bounds=avp.BoundsPolicy(certify=False)))
    limits = avp.VehicleLimits(mass=1.0, thrust_min=2.0, thrust_max=15.0)  # thrust range only
    u = (np.arange(SAMPLES_PER_SEGMENT) + 0.5) / SAMPLES_PER_SEGMENT
    t = np.concatenate([a + u * (b - a) for a, b in zip(traj.knots[:-1], traj.knots[1:], strict=True)])
    f = traj.thrust(t)
    expected = max(f.max() / 15.0, 2.0 / f.min()) - 1.0
    assert scaled_excess(traj, limits, traj.g, np.ones(1))[0] == pytest.approx(expected, rel=1e-12)


def test_predicted_factor_meets_the_margin_and_stays_in_range() -> None:
    sc = standard(90, 3.5)
    traj = avp.plan(sc.state, sc.target, avp.PlannerConfig(bounds=avp.BoundsPolicy(certify=False)))
    tight = avp.VehicleLimits(mass=1.0, thrust_min=1.0, thrust_max=14.0, tilt_rate_max=2.0)
    assert scaled_excess(traj, tight, traj.g, np.ones(1))[0] > 0.0  # the plan violates them
    s = predicted_factor(traj, tight, traj.g, 0.5, 4.0)
    assert s is not None and 1.0 < s <= 4.0  # rates fall with a longer plan
    assert scaled_excess(time_scaled(traj, s), tight, traj.g, np.ones(1))[0] < -MARGIN + 1e-9
    assert predicted_factor(traj, tight, traj.g, 0.5, 1.0) is None  # nothing shorter works


@pytest.mark.parametrize("mode", list(avp.TimeSearch))
def test_search_factors_stay_in_the_policy_range_and_never_repeat(mode) -> None:
    policy = avp.BoundsPolicy(time_search=mode)
    sc = standard(90, 1.5)
    limits = avp.VehicleLimits(mass=1.0, thrust_min=5.0, thrust_max=17.0, tilt_rate_max=3.0)
    traj = avp.plan(sc.state, sc.target, avp.PlannerConfig(limits=limits, bounds=avp.BoundsPolicy(certify=False)))
    search = DurationSearch(policy, reach=True)
    factors = []
    for _ in range(40):
        k = search.next(traj, True, limits, traj.g)
        if k is None:
            break
        factors.append(k)
    assert len(factors) < 40
    lo, hi = min((1.0, *policy.schedule())), max((1.0, *policy.schedule()))
    assert all(lo - 1e-12 <= k <= hi + 1e-12 for k in factors)
    assert all(abs(math.log(a / b)) > 0.01 for i, a in enumerate([1.0, *factors]) for b in factors[i:])
    if mode is avp.TimeSearch.PAPER:
        assert all(k > 1.0 for k in factors)


def test_no_factors_means_no_search() -> None:
    search = DurationSearch(avp.BoundsPolicy(factors=(), max_steps=0))
    assert search.next(None, True, LIMITS, 9.81) is None


GAO = avp.VehicleLimits(mass=1.0, thrust_min=5.0, thrust_max=17.0, tilt_rate_max=3.0)


@pytest.mark.parametrize("incline", [60, 90])
def test_scaling_search_certifies_what_the_fixed_list_does_in_fewer_solves(incline) -> None:
    """Gao et al.'s tight limits: the default search returns a plan of the same status as the
    fixed factor list, certified, with fewer QP solves."""
    target = avp.PerchTarget.from_incline([3.0, 0.0, 1.5], math.radians(incline))
    state = avp.State.hover([0.0, 0.0, 1.5])
    cfg = avp.PlannerConfig(limits=GAO)
    fixed = avp.plan_detailed(state, target, replace(cfg, bounds=replace(cfg.bounds, time_search=avp.TimeSearch.BIDIRECTIONAL)))
    scaling = avp.plan_detailed(state, target, cfg)
    assert scaling.status is fixed.status and scaling.ok
    assert scaling.bounds is not None and scaling.bounds.certified
    assert scaling.duration_scale_steps <= fixed.duration_scale_steps


@pytest.mark.parametrize("search", list(avp.TimeSearch))
def test_the_documented_policy_keeps_given_durations(search) -> None:
    """``plan_detailed``'s docstring: ``BoundsPolicy(factors=(), max_steps=0, relaxations=())``
    keeps the given durations with every time search (PAPER grew them by ``growth`` with
    ``max_steps`` left at its default) even where a bound fails at them."""
    state = avp.State.hover([0.0, 0.0, 1.5])
    target = avp.PerchTarget.from_incline([3.5, 0.0, 1.5], math.pi / 2)
    cfg = avp.PlannerConfig(bounds=avp.BoundsPolicy(time_search=search, factors=(), max_steps=0, relaxations=()))
    result = avp.plan_detailed(state, target, cfg, durations=[0.4] * 3)
    assert result.trajectory is not None and not result.bounds.certified
    np.testing.assert_allclose(result.trajectory.durations, [0.4] * 3, rtol=0, atol=1e-12)
