"""Overhangs and ceilings, 95-180 deg: approached from below, the thrust turns
through the horizontal while it stays above thrust_min, every bound certified."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

import avp
from avp.qp.perching import flip_time

E3 = np.array([0.0, 0.0, 1.0])


def ceiling_case(incline_deg: float, below: float = 1.5, standoff: float = 3.0):
    target = avp.PerchTarget.from_incline([standoff, 0.0, 3.0], math.radians(incline_deg))
    return avp.State.hover([0.0, 0.0, 3.0 - below]), target


@pytest.mark.parametrize("incline_deg", [120.0, 150.0, 165.0, 180.0])
def test_overhangs_are_certified_without_relaxation(incline_deg) -> None:
    state, target = ceiling_case(incline_deg)
    config = avp.PlannerConfig()
    result = avp.plan_detailed(state, target, config)
    assert result.ok and not result.relaxations, result.log[-3:]
    traj = result.trajectory
    t = traj.sample(5e-4)
    f = traj(t, 2) + config.g * E3
    fn = np.linalg.norm(f, axis=1)
    lim = config.limits
    assert fn.min() > lim.accel_min and fn.max() < lim.accel_max
    w = traj.body_rates(t)
    assert np.linalg.norm(w[:, :2], axis=1).max() < lim.tilt_rate_max
    # from below: on the outward side of the pad's plane until contact
    side = (traj(t) - target.point) @ target.s3
    assert side[t < traj.tf - 1e-3].min() > 0.0
    # the thrust goes from up to down (s3) through the horizontal, along s1's horizontal part
    t_w = flip_time(target, config, traj.duration)
    assert t_w is not None
    f_w = traj(traj.t0 + t_w, 2) + config.g * E3
    u = target.s1 * [1.0, 1.0, 0.0] / np.linalg.norm(target.s1[:2])
    assert abs(f_w[2]) < 1e-6 and f_w @ u >= config.flip.horizontal_thrust(lim) - 1e-6
    assert f[0] @ E3 > 0.0 and f[-1] @ target.s3 > 0.9 * np.linalg.norm(f[-1])


def test_without_the_flip_rows_a_ceiling_is_not_certified() -> None:
    """The rows are what makes it work: the min-snap thrust otherwise passes through ~0."""
    state, target = ceiling_case(180.0)
    config = avp.PlannerConfig(flip=avp.OverhangFlip(enabled=False), bounds=avp.BoundsPolicy(relaxations=()))
    result = avp.plan_detailed(state, target, config)
    assert not result.ok
    bad = {v.bound for v in result.bounds.violations}
    assert avp.Bound.THRUST_MIN in bad or avp.Bound.TILT_RATE in bad


def test_walls_and_slopes_are_unchanged_by_the_overhang_rows() -> None:
    state = avp.State.hover([0.0, 0.0, 2.5])
    for incline in (0.0, 45.0, 90.0):
        target = avp.PerchTarget.from_incline([3.5, 0.0, 1.5], math.radians(incline))
        a = avp.plan_detailed(state, target).trajectory
        b = avp.plan_detailed(state, target, avp.PlannerConfig(flip=avp.OverhangFlip(enabled=False))).trajectory
        assert a is not None and np.array_equal(a.coefficients, b.coefficients)


def test_flip_settings_are_validated() -> None:
    with pytest.raises(avp.ConfigError) as exc:
        avp.PlannerConfig(flip=avp.OverhangFlip(thrust=25.0))
    assert exc.value.field == "flip.thrust"
    with pytest.raises(avp.ConfigError) as exc:
        avp.OverhangFlip(min_incline=0.5)
    assert exc.value.field == "flip.min_incline"


# A wall 7.5 m away as a noisy first detection sees it: the estimated normal tips 5.2 deg past
# vertical (an "overhang" of 95.2 deg) and yaws 0.6 deg (a closed-loop run of the simulator).
NOISY_WALL_R_WS = np.array([
    [-9.1112684901362179e-02, 4.6005222251508559e-04, -9.9584048270896097e-01],
    [-1.1408316953307741e-01, 9.9341144085710631e-01, 1.0896770324033109e-02],
    [9.8928434187515113e-01, 1.1460147261776436e-01, -9.0459899372526922e-02],
])


def test_a_barely_overhanging_estimate_is_solved_without_the_waypoint() -> None:
    """Just past ``min_incline`` the horizontal-thrust waypoint is a hindrance: with it no
    duration certifies and only relaxations gave a plan (measured before this fallback). The
    planner searches again without it before relaxing anything the request asked, so the result
    is SOLVED, with every certificate, and the log says the waypoint was dropped."""
    target = avp.PerchTarget(point=[7.9238, -0.0769, 1.7418], R_WS=NOISY_WALL_R_WS)
    assert math.degrees(target.incline) > 95.0
    state = avp.State(position=[0.0, 0.0, 1.5])
    res = avp.plan_detailed(state, target, avp.PlannerConfig())
    assert res.status is avp.PlanStatus.SOLVED
    assert res.relaxations == ()
    assert res.bounds is not None and res.bounds.certified
    assert res.safety is not None and res.safety.certified
    assert any("without the horizontal-thrust waypoint" in line for line in res.log)


def _band_at_contact(traj: avp.Trajectory, target: avp.PerchTarget, config: avp.PlannerConfig) -> tuple[np.ndarray, np.ndarray]:
    """``f . s3`` and the tilt of ``f = a + g e3 + d v`` from ``s3`` (rad) at the band's sample
    times ``t_f - t_k + j dt``, from the spline's own coefficients (not the planner's rows)."""
    kr, C = traj.knots_rel, traj.coefficients
    ts = kr[-1] - config.t_k + config.dt * np.arange(int(round(config.t_k / config.dt)))
    seg = np.clip(np.searchsorted(kr, ts, side="right") - 1, 0, traj.n_segments - 1)
    tau = ts - kr[seg]
    k = np.arange(C.shape[2])
    v = np.einsum("sak,sk->sa", C[seg, :3, 1:], k[1:] * tau[:, None] ** (k[1:] - 1))
    a = np.einsum("sak,sk->sa", C[seg, :3, 2:], k[2:] * (k[2:] - 1) * tau[:, None] ** (k[2:] - 2))
    f = a + config.limits.rotor_drag * v + [0.0, 0.0, config.g]
    fs = f @ target.s3
    return fs, np.arctan2(np.linalg.norm(np.cross(f, target.s3), axis=1), fs)


def test_the_search_without_the_waypoint_keeps_the_cone_band():
    """An overhang whose plan needs the search without the horizontal-thrust waypoint: the band
    asked (PAPER with ``cone_band``: the tilt cone) stays the cone. That search turned the flip
    off, which also dropped the cone for the box, and the plan, 1.4e-3 m/s^2 under the cone's
    ``alpha``, said SOLVED with nothing relaxed (found by an independent audit)."""
    state = avp.State.hover([1.014755075755966, 1.2843552588657738, 3.435395575028842], yaw=0.7335482938268485)
    target = avp.PerchTarget.from_incline([-1.7628476495686467, -0.8821583453555246, 3.868461153758506],
                                          math.radians(120), -3.1055475609748036)
    cfg = avp.PlannerConfig(
        limits=avp.VehicleLimits(mass=0.3, thrust_min=0.15, thrust_max=7.3575, tilt_rate_max=15.0,
                                 body_rate_max=8.84445913790563),
        workspace=avp.Workspace(body_offset=0.15, ground_z=2.0986216134041547, half_spaces=(
            avp.HalfSpace(point=[0, 0, 4.89144837907693], normal=[0, 0, -1]),
            avp.HalfSpace(point=[-1.2316798953997017, 1.3861960180239965, 3.6144283643936737],
                          normal=[0.6150288826707363, -0.7885045805071685, 0.0]))),
        contact_velocity=avp.ContactVelocity(normal=-0.1, slope=None, lateral=None))
    res = avp.plan_detailed(state, target, cfg)
    assert any("without the horizontal-thrust waypoint" in line for line in res.log)
    assert res.status is avp.PlanStatus.SOLVED and not res.relaxations
    fs, tilt = _band_at_contact(res.trajectory, target, cfg)
    alpha = cfg.contact_alpha(target.incline)
    assert fs.min() >= alpha - 1e-9 and fs.max() <= (1 + cfg.q) * alpha + 1e-9
    assert tilt.max() <= cfg.cone_half_angle + 1e-9


def test_the_cone_band_relaxation_is_not_tried_where_the_band_is_the_cone():
    """On an overhang (PAPER band with ``cone_band``: the cone already) CONE_BAND would repeat the
    previous stage's solves and report a relaxation that did not happen: it is skipped."""
    target = avp.PerchTarget.from_incline([1.9354943560314564, 0.0, 2.5], math.radians(171.14870853529328))
    cfg = avp.PlannerConfig(limits=avp.VehicleLimits(tilt_rate_max=5.1166322448628785))
    res = avp.plan_detailed(avp.State.hover([0.0, 0.0, 2.0]), target, cfg)
    assert any(line.startswith("relaxing") for line in res.log)  # the relaxations were reached
    assert avp.Relaxation.CONE_BAND not in res.relaxations
    assert not any("replaced by the tilt cone" in line for line in res.log)


def test_band_relaxations_are_not_tried_without_a_band():
    """With ``pre_impact=OFF`` CONE_BAND would add a band (a tighter problem labelled relaxed)
    and NO_BAND would change nothing: neither runs, nor is reported."""
    target = avp.PerchTarget.from_incline([1.9354943560314564, 0.0, 2.5], math.radians(171.14870853529328))
    cfg = avp.PlannerConfig(limits=avp.VehicleLimits(tilt_rate_max=5.1166322448628785), pre_impact=avp.PreImpactMode.OFF)
    res = avp.plan_detailed(avp.State.hover([0.0, 0.0, 2.0]), target, cfg)
    assert any(line.startswith("relaxing") for line in res.log)  # the relaxations were reached
    assert not {avp.Relaxation.CONE_BAND, avp.Relaxation.NO_BAND} & set(res.relaxations)


def _replan_state(traj: avp.Trajectory, fraction: float) -> avp.State:
    """The flat state of ``traj`` a ``fraction`` of the way along it (a replan's start)."""
    t = traj.t0 + fraction * traj.duration
    d = traj.derivatives(np.array([t]), [0, 1, 2, 3])[:, 0, :]
    return avp.State(position=d[0, :3], velocity=d[1, :3], acceleration=d[2, :3], jerk=d[3, :3],
                     yaw=float(d[0, 3]), yaw_rate=float(d[1, 3]), time=t)


def test_provenance_says_whether_the_plan_went_through_the_waypoint() -> None:
    """A ceiling plans through the waypoint; a wall has none; the barely overhanging estimate is
    solved without it; the flag is what the plan's thrust shows: horizontal at ``t_w`` or not."""
    state, target = ceiling_case(150.0)
    through = avp.plan_detailed(state, target, avp.PlannerConfig())
    assert through.ok and through.trajectory.provenance.overhang_waypoint is True
    wall = avp.plan_detailed(avp.State.hover([0.0, 0.0, 1.5]), avp.PerchTarget.from_incline([3.0, 0.0, 1.5], math.pi / 2))
    assert wall.ok and wall.trajectory.provenance.overhang_waypoint is False
    noisy = avp.plan_detailed(avp.State(position=[0.0, 0.0, 1.5]),
                              avp.PerchTarget(point=[7.9238, -0.0769, 1.7418], R_WS=NOISY_WALL_R_WS))
    assert noisy.ok and noisy.trajectory.provenance.overhang_waypoint is False
    cfg = avp.PlannerConfig()
    for res, tgt in ((through, target), (noisy, avp.PerchTarget(point=[7.9238, -0.0769, 1.7418], R_WS=NOISY_WALL_R_WS))):
        traj = res.trajectory
        t_w = flip_time(tgt, cfg, traj.duration)
        assert t_w is not None
        f_z = float(traj(traj.t0 + t_w, 2)[2] + cfg.g)
        assert (abs(f_z) < 1e-6) == traj.provenance.overhang_waypoint


def test_a_replan_of_a_plan_without_the_waypoint_does_not_search_with_it() -> None:
    """A wall whose estimate turns into an overhang mid-flight (past ``min_incline``): the
    committed plan has no waypoint, so the replan starts without it, one stage instead of a
    failed search with the waypoint first; from a committed plan through the waypoint, or with
    no provenance (a plan from elsewhere), the waypoint is tried first as before."""
    overhang = avp.PerchTarget(point=[7.9238, -0.0769, 1.7418], R_WS=NOISY_WALL_R_WS)
    wall = avp.PerchTarget.from_incline([7.9238, -0.0769, 1.7418], math.pi / 2)
    committed = avp.plan(avp.State(position=[0.0, 0.0, 1.5]), wall)
    assert committed.provenance.overhang_waypoint is False
    start = _replan_state(committed, 0.2)
    replan = avp.plan_detailed(start, overhang, previous=committed)
    assert replan.status is avp.PlanStatus.SOLVED and not replan.trajectory.provenance.overhang_waypoint
    assert any("committed plan has no horizontal-thrust waypoint" in line for line in replan.log)
    assert not any("searching again without" in line for line in replan.log)
    assert replan.duration_scale_steps == 0  # one attempt
    foreign = avp.Trajectory(committed.coefficients, committed.knots)  # no provenance
    again = avp.plan_detailed(start, overhang, previous=foreign)
    assert any("searching again without" in line for line in again.log)
    assert again.duration_scale_steps > replan.duration_scale_steps
    state, ceiling = ceiling_case(150.0)
    through = avp.plan(state, ceiling)
    assert through.provenance.overhang_waypoint
    onward = avp.plan_detailed(_replan_state(through, 0.2), ceiling, previous=through)
    assert onward.ok and onward.trajectory.provenance.overhang_waypoint
    assert not any("committed plan has no" in line for line in onward.log)


def test_a_replan_without_the_waypoint_still_tries_it_before_relaxing() -> None:
    """A committed wall plan and a pad re-estimated as a 150 deg overhang: without the waypoint
    no duration certifies, so the search goes on with it, and the replan is SOLVED with nothing
    relaxed, as a replan from a plan without provenance is (found by a review: the stage with
    the waypoint had been left out, and the replan relaxed the request)."""
    wall = avp.PerchTarget.from_incline([6.0, 0.0, 2.0], math.pi / 2)
    committed = avp.plan(avp.State.hover([0.0, 0.0, 1.5]), wall)
    start = _replan_state(committed, 0.15)
    overhang = avp.PerchTarget.from_incline([6.0, 0.0, 2.0], math.radians(150))
    replan = avp.plan_detailed(start, overhang, previous=committed)
    assert replan.status is avp.PlanStatus.SOLVED and replan.relaxations == ()
    assert replan.trajectory.provenance.overhang_waypoint is True
    assert any("searching again with the horizontal-thrust waypoint" in line for line in replan.log)
    foreign = avp.plan_detailed(start, overhang, previous=avp.Trajectory(committed.coefficients, committed.knots))
    assert foreign.status is avp.PlanStatus.SOLVED and foreign.relaxations == ()


def test_an_unknown_waypoint_provenance_tries_the_waypoint_first() -> None:
    """``overhang_waypoint=None`` (other planners, exports written before the field) is not read
    as "no waypoint": the replan starts with the waypoint, as without provenance."""
    overhang = avp.PerchTarget(point=[7.9238, -0.0769, 1.7418], R_WS=NOISY_WALL_R_WS)
    committed = avp.plan(avp.State(position=[0.0, 0.0, 1.5]),
                         avp.PerchTarget.from_incline([7.9238, -0.0769, 1.7418], math.pi / 2))
    unknown = avp.Trajectory(committed.coefficients, committed.knots)
    unknown.provenance = dataclasses.replace(committed.provenance, overhang_waypoint=None)
    replan = avp.plan_detailed(_replan_state(committed, 0.2), overhang, previous=unknown)
    assert any("searching again without" in line for line in replan.log)
    assert not any("committed plan has no" in line for line in replan.log)
    data = json.loads(committed.to_json())  # an export written before the field reads back as unknown
    assert data["provenance"].pop("overhang_waypoint") is False
    assert avp.Trajectory.from_json(json.dumps(data)).provenance.overhang_waypoint is None


def test_provenance_flags_are_truth_values() -> None:
    """``overhang_waypoint`` decides how a replan starts: a 0 or a string would read as unknown,
    so only True, False, None (and NumPy booleans, stored as Python's) are accepted."""
    assert avp.Provenance("solved", overhang_waypoint=np.False_).overhang_waypoint is False
    for bad in (0, 1, "no"):
        with pytest.raises(avp.ConfigError) as info:
            avp.Provenance("solved", overhang_waypoint=bad)
        assert info.value.field == "provenance.overhang_waypoint"
    with pytest.raises(avp.ConfigError) as info:
        avp.Provenance("solved", bounds_certified="yes")
    assert info.value.field == "provenance.bounds_certified"
