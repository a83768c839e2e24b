"""Rotor drag in the perching constraints (VehicleLimits.rotor_drag): at contact the thrust
``a + g e3 + d v`` (Faessler et al.'s flatness with drag), not the acceleration, is along s3."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import avp
from avp.errors import ConfigError


def _config(drag: float, **kw) -> avp.PlannerConfig:
    base = avp.PlannerConfig(**kw)
    return dataclasses.replace(base, limits=dataclasses.replace(base.limits, rotor_drag=drag))


def _angle(u, w) -> float:
    return math.degrees(math.atan2(np.linalg.norm(np.cross(u, w)), float(u @ w)))


@settings(max_examples=12, deadline=None)
@given(st.floats(30.0, 90.0), st.floats(2.0, 6.0), st.floats(0.1, 0.6))
def test_contact_thrust_with_drag_is_along_the_normal(incline_deg, distance, drag):
    """Random slopes and walls: with drag d the plan's a + g e3 + d v is along s3 at contact (the
    drag-free thrust a + g e3 is not: the 2 m/s slide tilts it by atan(d |v_t| / alpha))."""
    target = avp.PerchTarget.from_incline([distance, 0.0, 1.5], math.radians(incline_deg))
    start = avp.State.hover([0.0, 0.0, 1.5 if incline_deg > 45.0 else 2.5])
    res = avp.plan_detailed(start, target, _config(drag))
    assert res.status is avp.PlanStatus.SOLVED, res.log[-3:]
    tr = res.trajectory
    a, v = tr(tr.tf, 2), tr(tr.tf, 1)
    f = a + np.array([0.0, 0.0, avp.PlannerConfig().g])
    assert _angle(f + drag * v, target.s3) < 1e-6
    v_t = v - (v @ target.s3) * target.s3
    expected = math.degrees(math.atan2(drag * np.linalg.norm(v_t), float(f @ target.s3)))
    assert _angle(f, target.s3) == pytest.approx(expected, rel=1e-6, abs=1e-9)


def test_zero_drag_is_the_drag_free_planner():
    target = avp.PerchTarget.from_incline([4.5, 0.0, 1.5], math.pi / 2)
    start = avp.State.hover([0.0, 0.0, 1.5])
    a = avp.plan_detailed(start, target, avp.PlannerConfig())
    b = avp.plan_detailed(start, target, _config(0.0))
    assert np.array_equal(a.trajectory.coefficients, b.trajectory.coefficients)


def test_moving_contact_thrust_with_drag_is_along_the_normal():
    from avp.moving import contact_errors, plan_moving_detailed
    from avp.platform import MovingTarget

    limits = avp.VehicleLimits(mass=1.0, thrust_min=5.0, thrust_max=17.0, tilt_rate_max=3.0, rotor_drag=0.3)
    cfg = avp.PlannerConfig(limits=limits, alpha=5.5, pre_impact=avp.PreImpactMode.OFF)
    pad = MovingTarget.on_platform([0.0, 0.0, 1.0], incline=0.5, speed=2.0, turn_rate=0.2)
    start = avp.State(position=[-3.0, 0.0, 1.0], velocity=pad.velocity)
    res = plan_moving_detailed(start, pad, cfg)
    assert res.ok and res.contact is not None and res.contact.attitude < 1e-8
    drag_free = contact_errors(res.trajectory, pad)
    assert drag_free.attitude > math.radians(0.5)  # the drag-free thrust is off the normal


def test_planar_drag_is_the_controllers_drag_in_the_rotor_plane():
    """The planner's d (avp.sim.controller.planar_drag) against the controller's drag model
    (drag_acceleration) with b3 = s3 of a wall: the in-plane drag is d v_t, the normal part uses
    the other coefficient."""
    from avp.sim.controller import FlatReference, drag_acceleration, planar_drag
    from avp.sim.vehicle import VehicleParams

    params = VehicleParams()
    k = (1.19e-4, 1.19e-4, 2.32e-4)
    alpha = 4.0
    target = avp.PerchTarget.from_incline([1.0, 0.0, 1.0], math.pi / 2)
    R = target.R_WS  # b3 = s3
    a_ref = alpha * target.s3 - np.array([0.0, 0.0, params.g])
    z = np.zeros(3)
    ref = FlatReference(z, z, a_ref, z, z)
    v = -2.0 * target.s1 - 0.3 * target.s3
    acc = drag_acceleration(R, v, ref, params, k)
    d = planar_drag(params, k, alpha)
    v_t = v - (v @ target.s3) * target.s3
    np.testing.assert_allclose(acc - (acc @ target.s3) * target.s3, d * v_t, rtol=1e-12, atol=1e-15)
    assert 0.2 < d < 0.4  # rotorpy's Hummingbird at 4 m/s^2: about 0.29 /s
    with pytest.raises(ConfigError, match="rotor_drag"):
        planar_drag(params, (1e-4, 2e-4, 1e-4), alpha)


def test_bad_rotor_drag_is_a_typed_error():
    for bad in (-0.1, math.nan, math.inf):
        with pytest.raises(ConfigError, match="limits.rotor_drag"):
            avp.VehicleLimits(rotor_drag=bad)
