"""Requests that make no physical sense are ConfigErrors naming the field (issue 8, item 6)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import avp
from avp.request import longest_total_time
from avp.timing import initial_durations

WALL = avp.PerchTarget.from_incline([3.5, 0.0, 1.5], math.radians(90))  # s3 = -x
START = avp.State.hover([0.0, 0.0, 1.5])


def field_of(state, target, config=None) -> str:
    with pytest.raises(avp.ConfigError) as exc:
        avp.plan_detailed(state, target, config)
    return exc.value.field


@pytest.mark.parametrize("incline_deg", [0.0, 45.0, 90.0, 150.0, 180.0])
def test_a_start_behind_the_pad_plane_is_rejected(incline_deg) -> None:
    target = avp.PerchTarget.from_incline([3.0, 0.0, 2.0], math.radians(incline_deg))
    behind = target.point - 0.5 * target.s3 + 0.7 * target.s1  # off the pad, on its back side
    assert field_of(avp.State.hover(behind), target) == "state.position"
    in_front = target.point + 0.5 * target.s3 + 0.7 * target.s1
    avp.plan_detailed(avp.State.hover(in_front), target)  # no error on the outward side


def test_the_floor_case_of_the_issue_from_below_the_floor() -> None:
    floor = avp.PerchTarget.from_incline([2.0, 0.0, 0.0], 0.0)
    assert field_of(avp.State.hover([0.0, 0.0, -0.3]), floor) == "state.position"


@pytest.mark.parametrize("normal", [0.0, -0.0, 0.3, 2.0])
def test_a_contact_velocity_that_does_not_enter_the_pad_is_rejected(normal) -> None:
    cfg = avp.PlannerConfig(contact_velocity=avp.ContactVelocity(normal=normal))
    assert field_of(START, WALL, cfg) == "contact_velocity.normal"


def test_a_free_normal_velocity_is_not_a_request() -> None:
    cfg = avp.PlannerConfig(contact_velocity=avp.ContactVelocity(normal=None))
    avp.plan_detailed(START, WALL, cfg)


def test_an_unreachable_contact_speed_names_the_component_and_the_bound() -> None:
    cfg = avp.PlannerConfig(contact_velocity=avp.ContactVelocity(slope=-500.0))
    with pytest.raises(avp.ConfigError) as exc:
        avp.plan_detailed(START, WALL, cfg)
    assert exc.value.field == "contact_velocity.slope"
    assert "f_max + g" in str(exc.value) and "T_max" in str(exc.value)


@settings(max_examples=15, deadline=None)
@given(slope=st.floats(-60.0, 0.0), lateral=st.floats(-20.0, 20.0), speed=st.floats(0.0, 5.0),
       incline=st.floats(0.3, math.pi / 2))
def test_the_speed_rule_is_a_necessary_condition(slope, lateral, speed, incline) -> None:
    """Whatever the planner returns obeys |v(tf) - v(0)| <= (f_max + g) T <= (f_max + g) T_max,
    measured on the plan (sampled thrust), so the rule never rejects a reachable request."""
    target = avp.PerchTarget.from_incline([3.5, 0.0, 1.5], incline)
    state = avp.State(position=[0.0, 0.0, 1.5], velocity=[speed, 0.0, 0.0])
    cfg = avp.PlannerConfig(contact_velocity=avp.ContactVelocity(slope=slope, lateral=lateral),
                            bounds=avp.BoundsPolicy(relaxations=()))
    try:
        result = avp.plan_detailed(state, target, cfg)
    except avp.ConfigError as exc:
        assert exc.field.startswith("contact_velocity.")
        return
    traj = result.trajectory
    if traj is None:
        return
    t = traj.sample(1e-3)
    dv = float(np.linalg.norm(traj(traj.tf, 1) - state.velocity))
    acc = np.linalg.norm(traj(t, 2), axis=1)
    assert dv <= np.trapezoid(acc, t) + 1e-6  # |int a| <= int |a|
    # the premise of the rule: no plan is longer than T_max of the first allocation
    assert traj.duration <= longest_total_time(cfg, float(initial_durations(state, target, cfg).sum())) + 1e-9
    if result.ok:  # certified thrust: the rule's bound holds on the returned plan
        assert dv <= (cfg.limits.accel_max + cfg.g) * traj.duration


def test_a_contact_attitude_the_flatness_map_cannot_represent() -> None:
    target = avp.PerchTarget.from_normal([0.0, 3.5, 1.5], [0.0, -1.0, 0.0], up_slope=[1.0, 0.0, 0.0])
    assert field_of(START, target) == "target.R_WS"
