"""Closed-loop perching on a moving platform (avp.sim.platform)."""

from __future__ import annotations

import math

import numpy as np
import pytest

import avp
from avp.platform import MotionModel, MovingTarget
from avp.sim.platform import MovingSimScenario, PlatformNoise, noisy_platform, simulate_moving

LIMITS = avp.VehicleLimits(mass=1.0, thrust_min=5.0, thrust_max=17.0, tilt_rate_max=3.0)
CONFIG = avp.PlannerConfig(limits=LIMITS, alpha=5.5, pre_impact=avp.PreImpactMode.OFF)


def test_noiseless_perch_on_a_moving_plane_meets_the_pad_as_planned():
    """Perfect odometry and platform state: the vehicle meets the moving pad near its centre, with
    the planned relative normal speed (0.3 m/s) and b3 close to s3."""
    tgt = MovingTarget.on_platform([0.0, 0.0, 1.0], incline=0.5, speed=2.0, model=MotionModel.CONSTANT_VELOCITY)
    res = simulate_moving(MovingSimScenario(tgt, odometry=None, platform_noise=None), seed=0, config=CONFIG)
    assert res.success, res.outcome
    c = res.contact
    assert res.error < 0.03
    assert c.normal_speed == pytest.approx(0.3, abs=0.1)
    assert c.attitude_error < math.radians(3.0)
    assert res.speed_max > 2.0 and res.target_speed == 2.0


def test_platform_estimates_are_unbiased_noise_around_the_truth():
    tgt = MovingTarget.on_platform([1.0, 2.0, 1.0], incline=0.5, heading=0.3, speed=2.0, turn_rate=0.2)
    rng = np.random.default_rng(3)
    est = [noisy_platform(tgt, PlatformNoise(), rng) for _ in range(2000)]
    pts = np.array([e.point for e in est])
    assert np.allclose(pts.mean(axis=0), tgt.point, atol=0.005)
    assert pts.std(axis=0) == pytest.approx([0.03] * 3, rel=0.1)
    assert np.mean([e.heading for e in est]) == pytest.approx(0.3, abs=0.002)
    assert noisy_platform(tgt, None, rng) is tgt


def test_bad_scenarios_are_config_errors():
    with pytest.raises(avp.ConfigError, match="scenario.target"):
        MovingSimScenario(avp.PerchTarget.from_incline([0, 0, 1], 0.5))  # type: ignore[arg-type]
    tgt = MovingTarget.on_platform([0.0, 0.0, 1.0], speed=1.0)
    with pytest.raises(avp.ConfigError, match="scenario.behind"):
        MovingSimScenario(tgt, behind=float("nan"))
    with pytest.raises(avp.ConfigError, match="platform_noise.sigma_velocity"):
        PlatformNoise(sigma_velocity=-1.0)


def test_platform_filter_reduces_the_noise_and_tracks_the_motion():
    """Fixed-gain fusion of 30 Hz measurements of a CTRV platform: unbiased, and its error is
    well below the single-measurement noise once it has settled."""
    from avp.sim.platform import PlatformFilter
    tgt = MovingTarget.on_platform([0.0, 0.0, 1.0], incline=0.5, speed=3.0, turn_rate=0.2)
    rng = np.random.default_rng(7)
    filt = PlatformFilter(0.2)
    errors = []
    for k in range(300):
        t = k / 30.0
        fused = filt.update(noisy_platform(tgt.at(t), PlatformNoise(), rng))
        errors.append(fused.point - tgt.at(t).point)
    err = np.array(errors[60:])
    assert np.abs(err.mean(axis=0)).max() < 0.01
    assert err.std(axis=0).max() < 0.6 * PlatformNoise().sigma_position
    with pytest.raises(avp.ConfigError, match="filter_gain"):
        PlatformFilter(0.0)
