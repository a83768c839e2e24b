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


def _numpy_excess(traj: avp.Trajectory, limits: avp.VehicleLimits, g: float, scales: np.ndarray,
                  per_segment: int) -> np.ndarray:
    """The scaling law in NumPy, as ``avp.time_search`` computed it before its Rust kernel:
    the spline evaluator at midpoints of the plan's relative knots (on the drag thrust's spline
    with rotor drag), then the formula of the module's docs."""
    from avp import _avp_rust
    from avp.bounds import drag_thrust_spline

    k = traj.knots_rel
    u = (np.arange(per_segment) + 0.5) / per_segment
    t = (k[:-1, None] + u[None, :] * (k[1:] - k[:-1])[:, None]).reshape(-1)
    coeffs = drag_thrust_spline(traj.coefficients, limits.rotor_drag) if limits.rotor_drag else traj.coefficients
    d = _avp_rust.eval_spline(coeffs, k, t, [1, 2, 3]).reshape(3, t.size, 4)
    a, j, yaw_rate = d[1, :, :3], d[2, :, :3], d[0, :, 3]
    a2, a_z, j2 = (a * a).sum(axis=1), a[:, 2].copy(), (j * j).sum(axis=1)
    s2 = scales[:, None] ** -2.0
    f2 = np.maximum(a2[None, :] * s2 * s2 + (2.0 * g) * a_z[None, :] * s2 + g * g, 1e-24)
    ratios = [np.sqrt(f2.max(axis=1)) / limits.accel_max]
    if limits.accel_min > 0.0:
        ratios.append(limits.accel_min / np.sqrt(f2.min(axis=1)))
    jj = j2[None, :] * (s2 * s2 * s2)
    tilt2 = jj / f2
    if math.isfinite(limits.thrust_rate_max):
        ratios.append(np.sqrt(jj.max(axis=1)) * limits.mass / limits.thrust_rate_max)
    if math.isfinite(limits.tilt_rate_max):
        ratios.append(np.sqrt(tilt2.max(axis=1)) / limits.tilt_rate_max)
    if math.isfinite(limits.body_rate_max):
        w2 = 3.0 * tilt2 + 4.0 * (yaw_rate[None, :] ** 2) * s2
        ratios.append(np.sqrt(w2.max(axis=1)) / limits.body_rate_max)
    return np.max(ratios, axis=0) - 1.0


@settings(max_examples=200, deadline=None)
@given(st.integers(1, 4), st.integers(4, 10), st.integers(0, 2**32 - 1), st.integers(1, 20),
       st.sampled_from([math.inf, 40.0]), st.sampled_from([math.inf, 3.0]), st.sampled_from([math.inf, 6.0]),
       st.floats(0.0, 4.0), st.sampled_from([0.0, 0.35]), st.sampled_from([9.81, 3.71, 0.0]),
       st.sampled_from([(-3.0, 2.0), (150.0, 160.0)]))
def test_the_kernel_computes_numpys_bits(segments, coeffs, seed, per_segment, thrust_rate, tilt_rate,
                                         body_rate, thrust_min, drag, g, magnitude) -> None:
    """The Rust kernel against the NumPy formula, value for value (``==``, NaN equal to NaN):
    the time search takes the same steps it took when the formula was NumPy, on any spline
    (starting at any time; absurd coefficients whose squares overflow included), limits,
    rotor drag and gravity."""
    rng = np.random.default_rng(seed)
    c = rng.normal(size=(segments, 4, coeffs)) * 10.0 ** rng.uniform(*magnitude, size=(1, 1, coeffs))
    knots = float(rng.uniform(-5.0, 50.0)) + np.concatenate([[0.0], np.cumsum(rng.uniform(0.05, 3.0, size=segments))])
    traj = avp.Trajectory(c, knots, g=g) if g else avp.Trajectory(c, knots)
    limits = avp.VehicleLimits(mass=float(rng.uniform(0.2, 4.0)), thrust_min=thrust_min, thrust_max=30.0,
                               thrust_rate_max=thrust_rate, tilt_rate_max=tilt_rate, body_rate_max=body_rate,
                               rotor_drag=drag)
    scales = np.concatenate([[1.0], rng.uniform(0.25, 4.0, size=5)])
    with np.errstate(over="ignore", invalid="ignore"):
        expected = _numpy_excess(traj, limits, g, scales, per_segment)
    got = scaled_excess(traj, limits, g, scales, per_segment=per_segment)
    assert np.array_equal(got, expected, equal_nan=True), (got, expected)


def test_the_tilt_rate_term_is_the_jerk_over_the_thrust() -> None:
    """At s = 1 with only a tilt-rate limit (and a thrust range that cannot bind), the excess is
    ``max |j| / |a + g e3|`` over the samples divided by the limit, minus 1: recomputed from the
    trajectory's jerk and thrust, not from the kernel's samples."""
    sc = standard(90, 3.5)
    traj = avp.plan(sc.state, sc.target, avp.PlannerConfig(bounds=avp.BoundsPolicy(certify=False)))
    limits = avp.VehicleLimits(mass=1.0, thrust_min=0.0, thrust_max=1e4, tilt_rate_max=0.5)
    u = (np.arange(SAMPLES_PER_SEGMENT) + 0.5) / SAMPLES_PER_SEGMENT
    t = np.concatenate([a + u * (b - a) for a, b in zip(traj.knots[:-1], traj.knots[1:], strict=True)])
    jerk = np.linalg.norm(traj.derivatives(t, [3])[0, :, :3], axis=1)
    expected = float((jerk / traj.thrust(t)).max()) / 0.5 - 1.0
    assert scaled_excess(traj, limits, traj.g, np.ones(1))[0] == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize(("kwargs", "arg"), [
    (dict(per_segment=0), "per_segment"),
    (dict(s2=np.array([0.0])), "s2"),
    (dict(s2=np.array([np.nan])), "s2"),
    (dict(per_segment=-1), "per_segment"),
    (dict(per_segment=100_001), "per_segment"),
    (dict(g=math.nan), "g"),
    (dict(accel_max=math.inf), "accel_max"),
    (dict(accel_min=30.0), "accel_min"),
    (dict(mass=0.0), "mass"),
    (dict(tilt_rate_max=-1.0), "tilt_rate_max"),
    (dict(coeffs=np.zeros((1, 3, 4))), "coeffs"),
    (dict(knots=np.array([0.0, 0.0])), "knots"),
])
def test_the_kernel_names_a_bad_argument(kwargs, arg) -> None:
    from avp import _avp_rust

    call = dict(coeffs=np.zeros((1, 4, 4)), knots=np.array([0.0, 1.0]), per_segment=2, s2=np.ones(1), g=9.81,
                accel_max=20.0, accel_min=0.0, mass=1.0, thrust_rate_max=math.inf, tilt_rate_max=math.inf,
                body_rate_max=math.inf)
    call.update(kwargs)
    with pytest.raises(_avp_rust.KernelError) as info:
        _avp_rust.scaled_excess(**call)
    assert info.value.arg == arg


@pytest.mark.parametrize(("kwargs", "field"), [
    (dict(per_segment=0), "per_segment"),
    (dict(per_segment=-3), "per_segment"),
    (dict(per_segment=2.0), "per_segment"),
    (dict(scales=np.array([1.0, 0.0])), "scales"),
    (dict(scales=np.array([np.inf])), "scales"),
    (dict(scales=np.array([1e200])), "scales"),  # s^-2 underflows to 0
    (dict(scales=np.array([1e-160])), "scales"),  # s^-2 overflows
    (dict(scales="fast"), "scales"),
    (dict(g=float("nan")), "g"),
])
def test_scaled_excess_names_a_bad_argument(kwargs, field) -> None:
    sc = standard(60, 3.5)
    traj = avp.plan(sc.state, sc.target, avp.PlannerConfig(bounds=avp.BoundsPolicy(certify=False)))
    call = dict(traj=traj, limits=LIMITS, g=traj.g, scales=np.ones(1), per_segment=4)
    call.update(kwargs)
    with pytest.raises(avp.ConfigError) as info:
        scaled_excess(**call)
    assert info.value.field == field
