"""Plans on a large clock (a UNIX timestamp, ROS time) are the plans made at time 0, shifted.

A trajectory holds its start time ``t0`` and its knots relative to it (``knots_rel``), and the
certificates read those, so the clock's value cannot round the segment durations the planner
solved for. Before, absolute knots rounded them: replans from 1e9 s and moving pads from a day
failed their contact certificates. The oracle here is time invariance: the planning problem is
the same at any clock, so the answer must be too (bit for bit where no time is rounded)."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import avp
import avp.export
import avp.replan
from avp.bounds import certify_trajectory
from avp.line import LineTarget
from avp.line_certify import position_polys
from avp.line_planner import plan_line
from avp.line_replan import LineReplanner
from avp.moving import MovingConfig, MovingReplanner, contact_errors, plan_moving_detailed
from avp.moving_clearance import clearance
from avp.platform import MotionModel, MovingTarget
from avp.replan import Replanner
from avp.sim.run import sim_config
from avp.trackability import trackability_rows

ReplanAction = avp.ReplanAction
CLOCKS = [86_400.0, 1.7e9, 9.9e9]  # a day, UNIX time, near the time limit
WALL = avp.PerchTarget.from_incline([4.5, 0.0, 1.5], math.radians(90.0))
SLOPE = avp.PerchTarget.from_incline([3.0, 0.5, 0.3], math.radians(40.0))
MOVING_CFG = avp.PlannerConfig(limits=avp.VehicleLimits(mass=1.0, thrust_min=5.0, thrust_max=17.0, tilt_rate_max=3.0),
                               alpha=5.5, pre_impact=avp.PreImpactMode.OFF)


def _same_spline(a: avp.Trajectory, b: avp.Trajectory, shift: float) -> None:
    np.testing.assert_array_equal(a.coefficients, b.coefficients)
    np.testing.assert_array_equal(a.knots_rel, b.knots_rel)
    assert a.t0 == b.t0 + shift


@pytest.mark.parametrize("clock", CLOCKS)
@pytest.mark.parametrize("target", [WALL, SLOPE], ids=["wall", "slope"])
def test_a_pad_plan_is_the_same_at_any_clock(clock, target):
    ground = avp.PlannerConfig(workspace=avp.Workspace(ground_z=0.0))
    ref = avp.plan_detailed(avp.State.hover([0.0, 0.0, 1.5]), target, ground)
    res = avp.plan_detailed(avp.State.hover([0.0, 0.0, 1.5], time=clock), target, ground)
    assert ref.status is avp.PlanStatus.SOLVED and res.status is ref.status
    _same_spline(res.trajectory, ref.trajectory, clock)
    assert res.trajectory.provenance.workspace_certified
    # the contact is the spline's end, exactly (tf is evaluated there, not at tf - t0 rounded)
    np.testing.assert_array_equal(res.trajectory(res.trajectory.tf), ref.trajectory(ref.trajectory.tf))


@pytest.mark.parametrize("clock", CLOCKS)
@pytest.mark.parametrize("turn", [0.0, 0.2])
def test_a_moving_pad_plan_is_the_same_at_any_clock(clock, turn):
    """Before, a day's clock failed the moving-plane clearance (contact residual 1e-9 m) and
    UNIX time widened the enclosure to 2e-5 m."""
    def plan(t: float):
        pad = MovingTarget.on_platform([0.0, 0.0, 1.0], incline=0.5, speed=2.0, turn_rate=turn, time=t)
        start = avp.State(position=pad.point - [3.0, 0.0, -1.0], velocity=pad.velocity, time=t)
        return plan_moving_detailed(start, pad, MOVING_CFG), pad

    (ref, _), (res, pad) = plan(0.0), plan(clock)
    assert ref.status is avp.PlanStatus.SOLVED and res.status is ref.status
    _same_spline(res.trajectory, ref.trajectory, clock)
    assert res.clearance.contact_residual_lower == ref.clearance.contact_residual_lower
    assert res.clearance.certified
    assert contact_errors(res.trajectory, pad).position < 1e-9


@pytest.mark.parametrize("clock", CLOCKS)
def test_a_line_perch_and_its_recovery_are_the_same_at_any_clock(clock):
    line = LineTarget.segment([3.0, -1.5, 2.5], [3.0, 1.5, 2.5], pitch=math.radians(80.0))
    cfg = avp.PlannerConfig(limits=avp.VehicleLimits(mass=0.8, thrust_min=0.5, thrust_max=4 * 0.8 * 9.81),
                            workspace=avp.Workspace(ground_z=0.8))
    ref = plan_line(avp.State.hover([1.0, 0.0, 2.6]), line, cfg)
    res = plan_line(avp.State.hover([1.0, 0.0, 2.6], time=clock), line, cfg)
    assert ref.ok and res.ok and res.status is ref.status
    _same_spline(res.perch, ref.perch, clock)
    assert res.recovery is not None and ref.recovery is not None
    np.testing.assert_array_equal(res.recovery.knots_rel, ref.recovery.knots_rel)
    assert [c.verdict for c in res.certificates] == [c.verdict for c in ref.certificates]


def _fly(replanner: Replanner, t: float) -> avp.State:
    """Odometry of a vehicle that tracks the reference perfectly."""
    ref = replanner.reference(t)
    return avp.State(position=ref.position, velocity=ref.velocity, acceleration=ref.acceleration, jerk=ref.jerk,
                     yaw=float(ref.yaw), yaw_rate=float(ref.yaw_rate), time=t)


def _wall_loop(clock: float) -> tuple[list[avp.ReplanAction], avp.Trajectory]:
    """30 Hz replanning on a wall whose estimate wobbles by 5 cm (replans, holds, partial
    corrections and CANNOT_REACH all occur at clock 0)."""
    rp = Replanner(WALL, sim_config())
    rp.step(clock, avp.State.hover([0.0, 0.0, 1.5], time=clock))
    k, t = 0, clock
    while t < rp.trajectory.tf - 0.3:
        k += 1
        t = clock + k / 30
        moved = avp.PerchTarget(point=WALL.point + [0.0, 0.0, 0.05 * math.sin(7 * k / 30)], R_WS=WALL.R_WS)
        rp.step(t, _fly(rp, t), moved)
    return [s.action for s in rp.history], rp.trajectory


@pytest.mark.parametrize("clock", [1e9, 1.7e9])
def test_replanning_decides_the_same_at_any_clock(clock):
    """Before, from 1e9 s a third of these steps kept the previous plan: no replan kept its
    workspace certificate (the rounded knots moved the contact by 1e-8 m). The step times
    ``clock + k / 30`` are rounded to the clock (2.4e-7 s at UNIX time), so the plans differ by
    that much, and decide the same."""
    ref_actions, ref_traj = _wall_loop(0.0)
    actions, traj = _wall_loop(clock)
    assert ReplanAction.REPLANNED in ref_actions and ReplanAction.HELD in ref_actions
    assert actions == ref_actions
    assert abs(traj.tf - clock - ref_traj.tf) < 1e-5
    assert np.linalg.norm(traj(traj.tf) - ref_traj(ref_traj.tf)) < 1e-6


@pytest.mark.parametrize("clock", [86_400.0, 1.7e9])
def test_moving_replanning_decides_the_same_at_any_clock(clock):
    def loop(t0: float) -> tuple[list[avp.ReplanAction], float]:
        first = MovingTarget.on_platform([0.0, 0.0, 1.0], incline=0.5, speed=2.0, time=t0,
                                         model=MotionModel.CONSTANT_VELOCITY)
        rp = MovingReplanner(first, MOVING_CFG, avp.ReplanConfig(latency=0.02, freeze_horizon=0.25))
        rp.step(t0, avp.State(position=first.point - [3.0, 0.0, 0.0], velocity=first.velocity, time=t0), first)
        faster = None
        k = 1
        while (t := t0 + k / 30) < rp.trajectory.tf:
            if faster is None and k / 30 > 0.4 * rp.trajectory.duration:  # the platform speeds up
                now = first.at(t)
                faster = MovingTarget(point=now.point, R_WS=now.R_WS, heading=now.heading, speed=2.5, time=t,
                                      model=MotionModel.CONSTANT_VELOCITY)
            rp.step(t, _fly(rp, t), (faster or first).at(t))
            k += 1
        assert faster is not None
        return [s.action for s in rp.history], contact_errors(rp.trajectory, faster, MovingConfig()).position

    ref_actions, ref_err = loop(0.0)
    actions, err = loop(clock)
    assert ReplanAction.REPLANNED in ref_actions
    assert actions == ref_actions
    assert ref_err < 1e-3 and err < ref_err + 1e-6


def test_line_replanning_decides_the_same_at_any_clock():
    """30 Hz line replanning with 3 mm odometry noise and a 2 cm wobbling line estimate (this
    one already held before: the line certificates have no contact-residual tolerance at 1e-9 m)."""
    line = avp.LineTarget.segment([2.5, -1.5, 3.94], [2.5, 1.5, 4.46], pitch=math.radians(80))
    limits = avp.VehicleLimits(mass=0.8, thrust_min=0.5, thrust_max=4.0 * 0.8 * 9.81)

    def loop(clock: float) -> tuple[list[avp.ReplanAction], np.ndarray]:
        rp = LineReplanner(line, avp.PlannerConfig(limits=limits), avp.ReplanConfig())
        rp.step(clock, avp.State.hover([0.0, 0.0, 4.0], time=clock), line)
        rng = np.random.default_rng(7)
        k = 1
        while (t := clock + k / 30) < rp.trajectory.tf - 0.3:
            ref = rp.trajectory.flat_output(t)
            odo = avp.State(position=ref.position + rng.normal(0.0, 0.003, 3), velocity=ref.velocity,
                            acceleration=ref.acceleration, yaw=float(ref.yaw), time=t)
            rp.step(t, odo, dataclasses.replace(line, vertices=line.vertices + rng.normal(0.0, 0.02, 3)))
            k += 1
        return [s.action for s in rp.history], rp.trajectory(rp.trajectory.tf)

    (ref_actions, ref_end), (actions, end) = loop(0.0), loop(1.7e9)
    assert ReplanAction.REPLANNED in ref_actions and ReplanAction.KEPT_PREVIOUS in ref_actions
    assert actions == ref_actions
    assert np.linalg.norm(end - ref_end) < 1e-6


# -- the trajectory itself -------------------------------------------------------------------

@settings(max_examples=300, deadline=None)
@given(clock=st.floats(-9.99e9, 9.99e9), durations=st.lists(st.floats(1e-3, 10.0), min_size=1, max_size=5),
       u=st.lists(st.floats(0.0, 1.0), min_size=1, max_size=20), seed=st.integers(0, 2**32 - 1))
def test_evaluation_is_the_time_zero_spline_within_the_clock_resolution(clock, durations, u, seed):
    """``traj(t0 + tau)`` is the spline at a time within ``ulp(clock)`` of ``tau``, and at ``tf``
    exactly its end; the durations are the ones given, exactly."""
    rng = np.random.default_rng(seed)
    c = rng.normal(size=(len(durations), 4, 6))
    rel = np.concatenate(([0.0], np.cumsum(durations)))
    at0 = avp.Trajectory.from_relative_knots(c, rel)
    shifted = avp.Trajectory.from_relative_knots(c, rel, t0=clock)
    np.testing.assert_array_equal(shifted.durations, at0.durations)
    assert shifted.duration == at0.duration
    np.testing.assert_array_equal(shifted.derivatives(shifted.tf), at0.derivatives(at0.tf))
    tau = np.asarray(u) * at0.duration
    t = clock + tau  # rounded to the clock: within ulp(clock + tau) / 2 of the wanted time
    got, want = shifted.evaluate(t), at0.evaluate(tau)
    speed = np.abs(at0.evaluate(tau, 1)) + 1.0
    resolution = math.ulp(abs(clock) + at0.duration)
    tol = 2 * resolution * speed + 1e-12 * (np.abs(want) + 1.0)
    # the random segments do not join: within the clock's resolution of an interior knot the
    # rounded time may fall in the neighbouring segment
    away = np.all(np.abs(tau[:, None] - rel[None, 1:-1]) > 4 * resolution, axis=1) if rel.size > 2 else np.ones(tau.size, bool)
    assert np.all((np.abs(got - want) <= tol)[away])


@pytest.mark.parametrize("fmt", ["json", "npz"])
def test_exports_keep_the_durations_exact_on_a_large_clock(tmp_path, fmt):
    res = avp.plan_detailed(avp.State.hover([0.0, 0.0, 1.5], time=1.7e9), WALL)
    traj = res.trajectory
    path = tmp_path / f"plan.{fmt}"
    back = avp.Trajectory.from_json(traj.to_json(path)) if fmt == "json" else avp.Trajectory.from_npz(traj.to_npz(path))
    _same_spline(back, traj, 0.0)
    # the absolute knots alone round the durations at this clock: they are not what is read back
    assert not np.array_equal(np.diff(traj.knots), traj.durations)


def test_knots_closer_than_the_clock_resolves_are_a_typed_error():
    """Knots spanning 1e10 s, the last two one ulp of 5e9 s apart: relative to the first they
    round to the same time."""
    knots = [-5e9, 5e9, 5e9 + math.ulp(5e9)]
    with pytest.raises(avp.ConfigError, match="local clock"):
        avp.Trajectory(np.zeros((2, 4, 3)), knots)


# -- each consumer of the durations, on its own ----------------------------------------------

def _pair(clock: float) -> tuple[avp.Trajectory, avp.Trajectory]:
    """The wall plan at time 0 and the same plan at ``clock``."""
    at0 = avp.plan(avp.State.hover([0.0, 0.0, 1.5]), WALL)
    return at0, avp.plan(avp.State.hover([0.0, 0.0, 1.5], time=clock), WALL)


def test_anticipation_is_the_same_at_any_clock():
    """Anticipation (6) at ``clock + 0.25`` and ``clock + 0.5`` (exact at 1.7e9 s: multiples of
    its ulp, 2^-22 s): the state at time 0's offsets, bit for bit."""
    clock = 1.7e9
    at0, shifted = _pair(clock)
    odo0 = avp.State(position=[0.01, -0.02, 1.5], velocity=[0.5, 0.0, 0.1], time=0.25)
    a = avp.replan.anticipate(at0, odo0, 0.25, 0.5)
    b = avp.replan.anticipate(shifted, dataclasses.replace(odo0, time=clock + 0.25), clock + 0.25, clock + 0.5)
    for name in ("position", "velocity", "acceleration", "jerk"):
        np.testing.assert_array_equal(getattr(b, name), getattr(a, name))
    assert (b.yaw, b.yaw_rate, b.time) == (a.yaw, a.yaw_rate, clock + 0.5)


def test_the_snap_certificate_and_the_line_polynomials_read_the_exact_durations():
    at0, shifted = _pair(1.7e9)
    np.testing.assert_array_equal(trackability_rows(shifted, 600.0, 45.0), trackability_rows(at0, 600.0, 45.0))
    for i in range(at0.n_segments):
        for p, q in zip(position_polys(shifted, i), position_polys(at0, i), strict=True):
            assert (p.c, p.e) == (q.c, q.e)


def test_a_violation_time_is_on_the_plan_clock():
    """A thrust limit below the plan's peak: the certificate proves a violation, at the same
    time since the start on both clocks."""
    clock = 1.7e9
    at0, shifted = _pair(clock)
    tight = avp.VehicleLimits(mass=1.0, thrust_max=float(at0.thrust(at0.sample(1e-3)).max()) - 0.5)  # N = m/s^2
    r0 = certify_trajectory(at0, tight, at0.g)
    r1 = certify_trajectory(shifted, tight, shifted.g)
    assert r0.violations and r1.verdicts == r0.verdicts
    assert [clock + x.t for x in r0.violations] == [x.t for x in r1.violations]


def test_replanning_on_the_committed_knots_decides_the_same_at_any_clock():
    """``ReplanConfig.keep_knots``: a replan's segments lie on the committed plan's knots, found
    in time since its start (a switch time moved onto a knot, rounded to the clock, is that knot)."""
    def loop(clock: float) -> list[avp.ReplanAction]:
        rp = Replanner(WALL, sim_config(), avp.ReplanConfig(keep_knots=True))
        rp.step(clock, avp.State.hover([0.0, 0.0, 1.5], time=clock))
        k = 1
        while (t := clock + k / 30) < rp.trajectory.tf - 0.3:
            moved = avp.PerchTarget(point=WALL.point + [0.0, 0.0, 0.05 * math.sin(7 * k / 30)], R_WS=WALL.R_WS)
            rp.step(t, _fly(rp, t), moved)
            k += 1
        return [s.action for s in rp.history]

    ref = loop(0.0)
    assert ReplanAction.REPLANNED in ref
    assert loop(1.7e9) == ref


def test_relative_knots_are_checked_and_long_plans_round_trip():
    c = np.zeros((3, 4, 4))
    for bad, field in [("abc", "knots_rel"), ([0.0, "x", 1.0, 2.0], "knots_rel"), ([0.1, 1.0, 2.0, 3.0], "knots_rel"),
                       ([0.0, 2.0, 1.0, 3.0], "knots_rel"), ([0.0, 1.0, 2.0], "knots_rel")]:
        with pytest.raises(avp.ConfigError) as exc:
            avp.Trajectory.from_relative_knots(c, bad)
        assert exc.value.field == field
    with pytest.raises(avp.ConfigError) as exc:
        avp.Trajectory.from_relative_knots(c, [0.0, 1.0, 2.0, 3.0], t0=1e300)
    assert exc.value.field == "t0"
    # segments shorter than the clock resolves are kept exactly when given relative to t0
    fine = avp.Trajectory.from_relative_knots(c, [0.0, 1e-7, 1.0, 2.0], t0=1.7e9)
    assert fine.durations[0] == 1e-7
    long = avp.Trajectory(c, [0.0, 1.0, 2.0, 2e4])  # longer than a flight's durations: still a spline
    np.testing.assert_array_equal(avp.Trajectory.from_json(long.to_json()).knots_rel, long.knots_rel)


def test_exports_without_the_relative_knots_still_load_and_bad_ones_are_typed_errors(tmp_path):
    traj = avp.plan(avp.State.hover([0.0, 0.0, 1.5], time=100.0), WALL)
    doc = json.loads(traj.to_json())
    old = {k: val for k, val in doc.items() if k not in ("t0", "knots_rel")}  # written before they existed
    back = avp.export.trajectory_from_dict(old)
    np.testing.assert_array_equal(back.knots, traj.knots)
    np.testing.assert_array_equal(back.coefficients, traj.coefficients)
    with pytest.raises(avp.ConfigError) as exc:
        avp.export.trajectory_from_dict({**doc, "knots_rel": {"a": 1}})
    assert exc.value.field == "knots_rel"
    path = tmp_path / "bad.npz"
    np.savez(path, format=np.array(avp.export.FORMAT), version=np.array(avp.export.VERSION),
             coefficients=traj.coefficients, knots=traj.knots, t0=np.array([1.0, 2.0]),
             knots_rel=traj.knots_rel, g=np.array(traj.g))
    with pytest.raises(avp.ConfigError) as exc:
        avp.Trajectory.from_npz(path)
    assert exc.value.field == "t0"


def test_the_sampled_clearance_meets_the_pad_at_contact_on_a_large_clock():
    """:func:`avp.moving_clearance.clearance` evaluates the plan and the pad at the same time
    since the start: zero at contact at UNIX time too (it was -9e-8 m from the rounding of tf)."""
    pad = MovingTarget.on_platform([0.0, 0.0, 1.0], incline=0.5, speed=2.0, turn_rate=0.2, time=1.7e9)
    res = plan_moving_detailed(avp.State(position=pad.point - [3.0, 0.0, -1.0], velocity=pad.velocity, time=1.7e9),
                               pad, MOVING_CFG)
    traj = res.trajectory
    assert abs(clearance(traj, pad, [traj.tf])[0]) < 1e-12


def test_the_bound_certificate_gets_the_exact_durations(monkeypatch):
    """:func:`avp.bounds.certify_trajectory` hands the kernel the plan's own durations (the
    absolute knots at 1.7e9 s differ from them by 1e-8 s; its verdicts rarely show it)."""
    seen = []
    real = avp.bounds.certify_spline

    def spy(coeffs, knots, **kw):
        seen.append(np.array(knots))
        return real(coeffs, knots, **kw)

    monkeypatch.setattr(avp.bounds, "certify_spline", spy)
    _, shifted = _pair(1.7e9)
    assert not np.array_equal(np.diff(shifted.knots), shifted.durations)  # what rounding would give
    certify_trajectory(shifted, avp.VehicleLimits(), shifted.g)
    np.testing.assert_array_equal(np.diff(seen[-1]), shifted.durations)


def test_a_knot_rounded_to_the_clock_is_that_knot():
    """The replanner's kept knots after a switch time: a switch time that is a knot, rounded to
    the clock (1.6e-8 s early here), does not leave a 1e-8 s segment before it."""
    _, shifted = _pair(1.7e9)
    for i in range(1, shifted.n_segments):
        _, inner = avp.replan._knots_after(shifted, float(shifted.knots[i]))
        np.testing.assert_array_equal(inner, shifted.knots_rel[i + 1:-1])


@pytest.mark.parametrize("fmt", ["json", "npz"])
def test_a_document_whose_knots_disagree_with_its_relative_knots_is_refused(tmp_path, fmt):
    """JSON and NPZ read ``t0 + knots_rel``; a document whose absolute ``knots`` were edited
    alone (another spline than the one loaded) is a typed error on ``knots``, while the knots
    as written, rounded to the clock at UNIX time, load."""
    traj = avp.plan(avp.State.hover([0.0, 0.0, 1.5], time=1.7e9), WALL)
    doc = json.loads(traj.to_json())
    assert avp.export.trajectory_from_dict(doc).knots_rel.tolist() == traj.knots_rel.tolist()
    edited = list(doc["knots"])
    edited[1] += 0.05
    for bad in (edited, doc["knots"][:-1]):
        if fmt == "json":
            with pytest.raises(avp.ConfigError) as exc:
                avp.export.trajectory_from_dict({**doc, "knots": bad})
        else:
            path = tmp_path / "edited.npz"
            np.savez(path, format=np.array(avp.export.FORMAT), version=np.array(avp.export.VERSION),
                     coefficients=traj.coefficients, knots=np.array(bad), t0=np.array(traj.t0),
                     knots_rel=traj.knots_rel, g=np.array(traj.g))
            with pytest.raises(avp.ConfigError) as exc:
                avp.Trajectory.from_npz(path)
        assert exc.value.field == "knots"
