"""The robust replanner: anchoring, hold, reach budget, CANNOT_REACH, certified commits,
no exception for solver failures; the trackability certificate; one vehicle and one camera."""

from __future__ import annotations

import dataclasses
import math
import types
from fractions import Fraction

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import avp
import avp.replan
from avp.bounds import Certificate
from avp.planner import PlanStatus
from avp.replan import ReplanAction, ReplanConfig, Replanner
from avp.sim.evaluate import SimConfig, wilson_interval
from avp.sim.run import Mode, SimScenario, sim_config, simulate
from avp.trackability import (
    certify_snap,
    snap_polynomial,
    snap_thrust_polynomial,
    trackability_rows,
)
from avp.trajectory import Trajectory

WALL = avp.PerchTarget.from_incline([4.5, 0.0, 1.5], math.radians(90.0))
START = avp.State.hover([0.0, 0.0, 1.5])
# biased detections only (no other noise): a +3 % range scale error, seed-independent
BIASED = SimConfig(perfect_odometry=True, camera_noise_scale=0.0, camera_latency=0.0, camera_dropout=0.0,
                   camera_normal_tilt_deg=0.0, camera_bias_sign=1.0)


def _fly_reference(replanner, t):
    """Odometry of a vehicle that tracks the reference perfectly."""
    ref = replanner.reference(t)
    return avp.State(position=ref.position, velocity=ref.velocity, acceleration=ref.acceleration,
                     jerk=ref.jerk, yaw=float(ref.yaw), yaw_rate=float(ref.yaw_rate), time=t)


# -- one vehicle, one camera ------------------------------------------------------------------------


def test_planner_and_simulator_share_vehicle_and_camera():
    sc = SimScenario(distance=4.5)
    cfg = sim_config(limits=sc.vehicle.limits, camera=sc.camera.camera)
    assert cfg.limits is sc.vehicle.limits and cfg.fov.camera is sc.camera.camera
    # with an explicit planner config the simulator flies *its* limits and camera
    mine = dataclasses.replace(avp.PlannerConfig(), limits=avp.VehicleLimits(thrust_max=8.0))
    r = simulate(dataclasses.replace(sc, timeout=0.01), Mode.ONE_SHOT, seed=0, config=mine, max_time=0.05)
    assert r.vehicle.limits is mine.limits and r.camera.camera is mine.fov.camera
    assert r.vehicle.thrust_max == 8.0 and r.vehicle.rotor_thrust_limits[1] == 2.0
    # the sensor's FoV test is the planner's Camera.sees (no second copy)
    assert not hasattr(avp.sim.camera, "in_fov")


# -- closed loop ----------------------------------------------------------------------------------


def test_avp_beats_one_shot_on_a_biased_estimate():
    sc = BIASED.scenario(90.0, 4.5)
    one, act = simulate(sc, Mode.ONE_SHOT, seed=0), simulate(sc, Mode.AVP, seed=0)
    # one-shot flies to the first estimate, 3 % x 4.5 m = 13.5 cm behind the wall: it hits early
    assert not one.success
    assert act.success, act.outcome
    assert np.linalg.norm(act.perch.error_S) < 0.5 * np.linalg.norm(one.perch.error_S)
    assert any(s.committed and s.action is not ReplanAction.INITIAL_PLAN for s in act.steps)


def test_perfect_estimate_avp_matches_one_shot():
    sc = SimConfig().perfect_estimate().scenario(90.0, 4.5)  # 20 ms motor lag, mixer
    one, act = simulate(sc, Mode.ONE_SHOT, seed=0), simulate(sc, Mode.AVP, seed=0)
    assert one.success and act.success
    # nothing to correct and tracking is good: every step holds the committed plan
    assert {s.action for s in act.steps[1:]} <= {ReplanAction.HELD, ReplanAction.FROZEN_NEAR_CONTACT}
    np.testing.assert_array_equal(act.path_p, one.path_p)


def test_every_committed_plan_is_certified_including_trackability():
    # without the filter's scale fit the estimate converges only as the range shrinks, so the
    # replanner commits a correction again and again (with it, noise-free detections give the
    # exact pad after the first approach steps and one correction suffices)
    unfitted = dataclasses.replace(BIASED, filter_estimate_scale=False)
    r = simulate(unfitted.scenario(90.0, 7.5), Mode.AVP, seed=0)
    committed = [s for s in r.steps if s.committed]
    assert len(committed) > 3
    limits = None
    for s in committed:
        assert s.result is not None and s.result.ok and s.result.bounds.certified
        assert not s.result.relaxations
        if s.action is ReplanAction.INITIAL_PLAN:
            continue
        assert s.snap is not None and s.snap.certified
        limits = (s.snap.snap_max, s.snap.snap_thrust_max)
        # independent check on a dense grid: the certified bounds really hold
        tr = s.trajectory
        t = np.linspace(tr.t0, tr.tf, 3000)
        d = tr.derivatives(t, (2, 4))
        snap = np.linalg.norm(d[1][:, :3], axis=1)
        f = np.linalg.norm(d[0][:, :3] + [0.0, 0.0, tr.g], axis=1)
        assert snap.max() < limits[0] and np.max(snap / f) < limits[1]
    assert limits is not None


# -- the replanner driven directly ---------------------------------------------------------------


@pytest.mark.parametrize("error", [ValueError("bad matrix"), np.linalg.LinAlgError("singular"),
                                   avp.SolverError("injected"), RuntimeError("boom"), "status"])
def test_replanner_never_raises_for_planning_failures(monkeypatch, error):
    real = avp.replan.plan_detailed
    calls = {"n": 0}

    def flaky(*args, **kwargs):
        calls["n"] += 1
        if calls["n"] > 1 and calls["n"] % 2 == 0:  # the first plan succeeds, then every other call fails
            if error == "status":
                return dataclasses.replace(real(*args, **kwargs), status=PlanStatus.SOLVER_FAILED, trajectory=None)
            raise error
        return real(*args, **kwargs)

    monkeypatch.setattr(avp.replan, "plan_detailed", flaky)
    rp = Replanner(WALL, sim_config())
    t, steps = 0.0, []
    rp.step(t, START)
    while t < rp.trajectory.tf - 0.3:
        t += 1 / 30
        moved = avp.PerchTarget(point=WALL.point + [0.0, 0.0, 0.02 * math.sin(7 * t)], R_WS=WALL.R_WS)
        steps.append(rp.step(t, _fly_reference(rp, t), moved))  # must not raise
    want = PlanStatus.SOLVER_FAILED.value if error == "status" else type(error).__name__
    failed_first = [s for s in steps if s.n_solves >= 1 and s.fraction != 1.0 and s.solved]
    assert failed_first, [s.action for s in steps]
    assert any(want in s.reason or s.action is ReplanAction.PARTIAL for s in failed_first)
    assert all(s.trajectory is not None for s in steps)


def test_noisy_odometry_is_not_fed_into_the_reference():
    rp = Replanner(WALL, sim_config())
    rp.step(0.0, START)
    first = rp.trajectory
    rng = np.random.default_rng(0)
    for k in range(1, 20):
        t = k / 30
        good = _fly_reference(rp, t)
        noisy = dataclasses.replace(good, position=good.position + rng.normal(0, 0.003, 3),
                                    velocity=good.velocity + rng.normal(0, 0.01, 3))
        s = rp.step(t, noisy, WALL)
        assert s.action is ReplanAction.HELD and s.anchored and not s.solved
    assert rp.trajectory is first
    # a real divergence (30 cm) re-anchors on odometry
    t = 20 / 30
    off = _fly_reference(rp, t)
    off = dataclasses.replace(off, position=off.position + [0.0, 0.0, 0.3])
    s = rp.step(t, off, WALL)
    assert not s.anchored and s.solved


def test_a_late_jump_of_the_estimate_is_reported_as_cannot_reach():
    rp = Replanner(WALL, sim_config())
    rp.step(0.0, START)
    tf = rp.trajectory.tf
    t = tf - 0.67
    jumped = avp.PerchTarget(point=WALL.point + [0.0, 1.0, 0.0], R_WS=WALL.R_WS)
    steps = []
    while t < tf:
        steps.append(rp.step(t, _fly_reference(rp, t), jumped))
        t += 1 / 30
    last = steps[-1]
    assert last.action is ReplanAction.CANNOT_REACH and rp.cannot_reach
    assert 0.5 < last.target_error <= 1.0 + 1e-9
    assert "1.000 m and 0.0 deg from the estimate" in last.reason
    assert last.reach_budget < 0.5  # the numbers say why: the budget has collapsed


class _FakeClock:
    """A wall clock that stands still except where a test advances it."""

    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


def _slow_solves(monkeypatch) -> _FakeClock:
    """Replace the replanner's clock (solve times, deadline) by one the test advances."""
    clock = _FakeClock()
    monkeypatch.setattr(avp.replan, "_clock", clock)
    return clock


def _fraction_probe(monkeypatch, certifies, replan=None, elapsed=None):
    """A replanner after its first plan whose certificate is replaced by ``certifies(fraction)``
    (and, with ``elapsed``, each planning call reported to take that long, s, on a clock that
    otherwise stands still; a list gives each call its own); returns it and the list of
    fractions it solved for."""
    rp = Replanner(WALL, sim_config(), replan)
    rp.step(0.0, START)
    tried: list[float] = []
    real_plan = rp._plan
    clock = _slow_solves(monkeypatch) if elapsed is not None else None
    times = iter(elapsed) if isinstance(elapsed, list) else None

    def plan(state, target, *args, deadline=None):
        tried.append(float(np.linalg.norm(target.point - WALL.point) / 0.04))
        if clock is None:
            return real_plan(state, target, *args, deadline=deadline)
        result, _, error = real_plan(state, target, *args)  # the fake budget is not the planner's seconds
        took = next(times) if times is not None else elapsed
        clock.now += took
        return result, took, error

    def certified(result, trackability=True):
        ok = certifies(tried[-1])
        return ok, "ok" if ok else "injected: not certified", None, False  # not a certificate: no retries

    monkeypatch.setattr(rp, "_plan", plan)
    monkeypatch.setattr(rp, "_certified", certified)
    return rp, tried


MOVED = avp.PerchTarget(point=WALL.point + [0.0, 0.04, 0.0], R_WS=WALL.R_WS)


@pytest.mark.parametrize(("certifying", "want_fraction", "want_solves"),
                         [((1.0, 0.5, 0.25, 0.125), 1.0, 1), ((0.5, 0.25, 0.125), 0.5, 3),
                          ((0.25, 0.125), 0.25, 4), ((0.125,), 0.125, 4), ((), 0.0, 2),
                          ((0.5,), 0.0, 2)])  # not monotone: 1/2 would certify, 1/8 does not
def test_fractions_are_tried_full_then_smallest_then_largest_between(monkeypatch, certifying, want_fraction,
                                                                     want_solves):
    """Order (1, 1/8, 1/2, 1/4): a step that cannot correct at all costs two solves; when 1/8
    certifies, the largest fraction that certifies is committed."""
    rp, tried = _fraction_probe(monkeypatch, lambda f: any(abs(f - c) < 1e-9 for c in certifying))
    first = rp.trajectory
    t = 0.4
    s = rp.step(t, _fly_reference(rp, t), MOVED)
    assert s.n_solves == want_solves == len(tried)
    assert tried == pytest.approx([1.0, 0.125, 0.5, 0.25][:want_solves])
    assert s.fraction == pytest.approx(want_fraction)
    if want_fraction == 0.0:
        assert s.action is ReplanAction.KEPT_PREVIOUS and rp.trajectory is first
    else:
        assert s.action is (ReplanAction.REPLANNED if want_fraction == 1.0 else ReplanAction.PARTIAL)
        assert rp.trajectory is not first and rp.trajectory is s.trajectory
        assert np.linalg.norm(rp.committed_target.point - WALL.point) == pytest.approx(0.04 * want_fraction)


@pytest.mark.parametrize(("minimum", "want_tried", "want_fraction", "not_tried"),
                         [(0.0, [1.0, 0.125, 0.5, 0.25], 0.25, 0),  # the default: every fraction
                          (0.006, [1.0, 0.25, 0.5], 0.25, 1),  # 1/8 moves the goal by 5 mm: left out
                          (0.015, [1.0, 0.5], 0.0, 2),  # 1/4 (10 mm) too: 1/2 is the only fraction
                          (0.02, [1.0], 0.0, 3)])  # 1/2 moves it by exactly 20 mm: not more than the minimum
def test_partial_min_correction_leaves_out_the_fractions_that_move_the_goal_too_little(
        monkeypatch, minimum, want_tried, want_fraction, not_tried):
    """An anchored step tries only the fractions that move the goal (by 40 mm here) by more than
    ``partial_min_correction``, in the usual order (full, smallest, the ones between; 1/4 and 1/8
    certify), and a step that commits nothing says how many it left out."""
    rp, tried = _fraction_probe(monkeypatch, lambda f: f <= 0.25, ReplanConfig(partial_min_correction=minimum))
    t = 0.4
    s = rp.step(t, _fly_reference(rp, t), MOVED)
    assert s.anchored
    assert tried == pytest.approx(want_tried) and s.n_solves == len(want_tried)
    assert s.fraction == pytest.approx(want_fraction)
    if want_fraction:
        assert s.action is ReplanAction.PARTIAL
    else:
        assert s.action is ReplanAction.KEPT_PREVIOUS
        assert f"{not_tried} partial correction(s) not tried (at most partial_min_correction" in s.reason


def test_a_step_the_deadline_ends_says_which_fractions_partial_min_correction_left_out(monkeypatch):
    """With a deadline that leaves room for one solve, the step ends before its smallest fraction
    (1/4 here, 1/8 being left out): its reason says both."""
    rp, tried = _fraction_probe(monkeypatch, lambda f: False,
                                ReplanConfig(partial_min_correction=0.006, deadline=1.5), elapsed=1.0)
    t = 0.4
    s = rp.step(t, _fly_reference(rp, t), MOVED)
    assert tried == pytest.approx([1.0])
    assert s.action is ReplanAction.KEPT_PREVIOUS
    assert "no time for 25 % of the correction" in s.reason
    assert "1 partial correction(s) not tried (at most partial_min_correction 0.006)" in s.reason


def test_partial_min_correction_does_not_apply_to_a_step_that_re_anchors(monkeypatch):
    """A step whose odometry left the committed reference re-anchors on it, and its plan corrects
    the tracking too: it tries every fraction whatever ``partial_min_correction`` says."""
    rp, tried = _fraction_probe(monkeypatch, lambda f: False, ReplanConfig(partial_min_correction=1.0))
    t = 0.4
    odo = _fly_reference(rp, t)
    odo = dataclasses.replace(odo, position=odo.position + [0.0, 0.0, 0.2])  # 0.2 m > anchor_position
    s = rp.step(t, odo, MOVED)
    assert not s.anchored
    assert tried == pytest.approx([1.0, 0.125])  # full, then the smallest (which fails: no others)
    assert "partial_min_correction" not in s.reason


def test_partial_min_correction_is_checked():
    with pytest.raises(avp.ConfigError, match="replan.partial_min_correction"):
        ReplanConfig(partial_min_correction=-0.001)
    with pytest.raises(avp.ConfigError, match="replan.partial_min_correction"):
        ReplanConfig(partial_min_correction=math.nan)


def test_a_deadline_commits_the_certified_smallest_correction(monkeypatch):
    """With a deadline that leaves no room for a third solve, the 1/8 correction already
    certified is committed (not thrown away for a KEPT_PREVIOUS); a first solve that overruns
    ends the step, and its plan is committed if it certifies, else nothing is."""
    t = 0.4
    rp, tried = _fraction_probe(monkeypatch, lambda f: f < 0.2, ReplanConfig(deadline=0.5), elapsed=1.0)
    s = rp.step(t, _fly_reference(rp, t), MOVED)
    assert tried == pytest.approx([1.0])  # the first solve already overran: nothing at hand
    assert s.action is ReplanAction.KEPT_PREVIOUS and "too late" in s.reason

    rp, tried = _fraction_probe(monkeypatch, lambda f: True, ReplanConfig(deadline=0.5), elapsed=1.0)
    s = rp.step(t, _fly_reference(rp, t), MOVED)
    assert tried == pytest.approx([1.0])  # overran and certified: committed, however late
    assert s.action is ReplanAction.REPLANNED and rp.trajectory is s.trajectory
    assert "past the deadline of 500.0 ms" in s.reason

    rp, tried = _fraction_probe(monkeypatch, lambda f: f < 0.2, ReplanConfig(deadline=2.5), elapsed=1.0)
    s = rp.step(t, _fly_reference(rp, t), MOVED)
    assert tried == pytest.approx([1.0, 0.125])  # a third solve would end past 2.5 s: not started
    assert s.action is ReplanAction.PARTIAL and s.fraction == pytest.approx(0.125) and s.n_solves == 2


@pytest.mark.parametrize(("deadline", "want_tried", "want_action"),
                         [(1.5, [1.0], ReplanAction.KEPT_PREVIOUS),  # no time even for 1/8
                          (2.0, [1.0, 0.125], ReplanAction.PARTIAL),  # exactly two solves fit
                          (3.99, [1.0, 0.125, 0.5], ReplanAction.PARTIAL),
                          (4.0, [1.0, 0.125, 0.5, 0.25], ReplanAction.PARTIAL)])
def test_a_deadline_starts_only_the_solves_predicted_to_fit(monkeypatch, deadline, want_tried, want_action):
    """Every solve takes 1 s and only 1/8 certifies: a solve starts only while the step's
    solves so far plus one more (as slow as the first) fit the deadline, so the step never
    overruns it, and it commits the certified 1/8 when nothing more fits."""
    t = 0.4
    rp, tried = _fraction_probe(monkeypatch, lambda f: f < 0.2, ReplanConfig(deadline=deadline), elapsed=1.0)
    first = rp.trajectory
    s = rp.step(t, _fly_reference(rp, t), MOVED)
    assert tried == pytest.approx(want_tried)
    assert s.n_solves == len(want_tried) and s.solve_time == pytest.approx(len(want_tried))
    assert s.solve_time <= deadline
    assert s.action is want_action
    if want_action is ReplanAction.KEPT_PREVIOUS:
        assert rp.trajectory is first and "no time for 12.5 % of the correction after 1 solve(s)" in s.reason
    else:
        assert s.fraction == pytest.approx(0.125) and rp.trajectory is s.trajectory is not first


@pytest.mark.parametrize(("certifies_below", "want_fraction"), [(0.6, 0.5), (0.2, 0.125)])
def test_a_solve_slower_than_predicted_ends_the_step(monkeypatch, certifies_below, want_fraction):
    """The third solve (1/2) takes 3 s where the first took 1: it starts (1 + 1 + 1 <= 3.5 s
    was predicted) but ends past the deadline, so no further solve (1/4) starts. Its plan is
    committed when it certifies (the time is spent; throwing it away saves none, and on a slow
    onboard computer it cost perches: docs/simulation.md); otherwise the 1/8 correction
    certified before it is."""
    t = 0.4
    rp, tried = _fraction_probe(monkeypatch, lambda f: f < certifies_below, ReplanConfig(deadline=3.5),
                                elapsed=[1.0, 1.0, 3.0])
    s = rp.step(t, _fly_reference(rp, t), MOVED)
    assert tried == pytest.approx([1.0, 0.125, 0.5])
    assert s.action is ReplanAction.PARTIAL and s.fraction == pytest.approx(want_fraction) and s.n_solves == 3
    assert s.solve_time == pytest.approx(5.0) and rp.trajectory is s.trajectory
    assert ("past the deadline of 3500.0 ms" in s.reason) == (want_fraction == 0.5)


def test_the_planning_call_gets_the_time_left(monkeypatch):
    """Each planning call of a step is handed what is left of the deadline (s), so that
    plan_detailed stops its own search in time; without a deadline, none."""
    for deadline in (None, 0.5):
        rp = Replanner(WALL, sim_config(), ReplanConfig(deadline=deadline))
        rp.step(0.0, START)
        seen: list[float | None] = []
        real = rp._solve

        def solve(*args, seen=seen, real=real, **kw):
            seen.append(kw.get("deadline"))
            return real(*args, **kw)

        monkeypatch.setattr(rp, "_solve", solve)
        rp.step(0.4, _fly_reference(rp, 0.4), MOVED)
        assert seen
        if deadline is None:
            assert seen == [None] * len(seen)
        else:
            assert all(0.0 < x <= deadline for x in seen)


def _replan_to_committed_target(keep_knots: bool, t: float):
    """A replanner without FoV rows after its first plan, tracking it perfectly; at ``t`` one
    planning call to the committed target from the anchored start at the switch time."""
    cfg = dataclasses.replace(sim_config(), fov=avp.FovConfig(enabled=False))
    rp = Replanner(WALL, cfg, ReplanConfig(keep_knots=keep_knots))
    rp.step(0.0, START)
    committed = rp.trajectory
    t_ex = rp._switch_time(committed, t + rp.latency)
    start = avp.replan._plan_state(committed, t_ex)
    durations = rp._durations(committed, t_ex, committed.tf - t_ex)
    result, _, error = rp._plan(start, rp.committed_target, durations, committed, rp._replan_config)
    assert error is None and result.ok
    ts = np.linspace(t_ex, committed.tf, 400)
    gap = np.max(np.abs(result.trajectory.derivatives(ts, (0,))[0] - committed.derivatives(ts, (0,))[0]))
    return committed, result.trajectory, t_ex, gap


def test_a_replan_on_the_committed_knots_stays_on_the_committed_plan():
    """keep_knots: the committed remainder is a spline of the replan's layout, so a replan to the
    committed target (no correction) stays within 0.5 mm of the committed plan; on equal pieces
    it moves by about a centimetre. (Not where a piece is halved to make up the segments:
    continuity stops at snap, so the halves may leave the committed polynomial.)"""
    committed, same, t_ex, gap = _replan_to_committed_target(True, 0.3)
    for k in committed.knots[committed.knots > t_ex]:
        assert np.min(np.abs(same.knots - k)) < 1e-9
    assert gap < 5e-4
    *_, gap_equal = _replan_to_committed_target(False, 0.3)
    assert gap_equal > 5e-3


@settings(max_examples=300, deadline=None)
@given(st.lists(st.floats(0.01, 2.0), min_size=1, max_size=6), st.floats(0.0, 1.0), st.integers(1, 5),
       st.floats(0.5, 1.5))
def test_replan_durations_keep_every_committed_knot(pieces, where, n, stretch):
    """Any committed layout, switch time and segment count: n positive durations summing to the
    requested total, every committed knot after the switch time kept (scaled with the total),
    and no first piece shorter than keep_knots_min of an equal share before the next knot."""
    knots = np.concatenate([[0.0], np.cumsum(pieces)])
    committed = Trajectory(np.zeros((len(pieces), 4, 8)), knots)
    rp = Replanner.__new__(Replanner)
    rp.replan = ReplanConfig(keep_knots=True)
    rp.config = dataclasses.replace(avp.PlannerConfig(), n_segments=n)
    t = float(knots[-1]) * where * 0.999
    t_ex = rp._switch_time(committed, t)
    assert t <= t_ex < knots[-1]
    remaining = knots[-1] - t_ex
    total = remaining * stretch
    d = rp._durations(committed, t_ex, total)
    assert d.shape == (n,) and np.all(d > 0) and math.isclose(float(d.sum()), total, rel_tol=1e-12)
    after = knots[(knots > t_ex) & (knots < knots[-1])]
    if after.size < n:  # all of them fit: each is a boundary of the new layout
        bounds = t_ex + np.cumsum(d) / stretch
        for k in after:
            assert np.min(np.abs(bounds - k)) < 1e-9 * (1 + k)
    if t_ex == t and after.size:  # not moved: the first piece is long enough
        assert after[0] - t_ex > rp.replan.keep_knots_min * remaining / n


def test_reach_budget_limits_how_far_one_step_moves_the_contact_point():
    rc = ReplanConfig(reach_acceleration=1.0)
    rp = Replanner(WALL, sim_config(), rc)
    rp.step(0.0, START)
    t = 0.5
    far = avp.PerchTarget(point=WALL.point + [0.0, 0.0, 2.0], R_WS=WALL.R_WS)
    s = rp.step(t, _fly_reference(rp, t), far)
    moved = np.linalg.norm(rp.committed_target.point - WALL.point)
    assert moved <= s.reach_budget + 1e-9 < 2.0
    assert s.action in (ReplanAction.PARTIAL, ReplanAction.CANNOT_REACH)


def test_replan_config_rejects_bad_knobs():
    for bad in (-0.1, 0.0, 0.6, float("nan")):
        with pytest.raises(avp.ConfigError, match="replan.keep_knots_min"):
            ReplanConfig(keep_knots_min=bad)
    with pytest.raises(avp.ConfigError, match="replan.partial_fractions"):
        ReplanConfig(partial_fractions=(1.0, 1.5))
    with pytest.raises(avp.ConfigError, match="strictly decreasing"):
        ReplanConfig(partial_fractions=(0.125, 0.25, 1.0))
    with pytest.raises(avp.ConfigError, match="strictly decreasing"):
        ReplanConfig(partial_fractions=(1.0, 0.5, 0.5))
    with pytest.raises(avp.ConfigError, match="replan.snap_thrust_max"):
        ReplanConfig(snap_thrust_max=-1.0)
    with pytest.raises(avp.ConfigError, match="replan.anchor_position"):
        ReplanConfig(anchor_position=float("nan"))
    for bad in ((1.0,), (0.97, 3.0), (0.4,), (float("nan"),), "0.97", 0.97, (True,), (0.97, 0.97), {0.97: 1},
                (0.97, -1.03)):
        with pytest.raises(avp.ConfigError, match=r"replan.retime_retries"):
            ReplanConfig(retime_retries=bad)
    with pytest.raises(avp.ConfigError, match=r"replan.retime_retries\[1\].*\(\) turns the retries off"):
        ReplanConfig(retime_retries=(0.97, 2.5))
    assert ReplanConfig(retime_retries=[0.9, 1.1]).retime_retries == (0.9, 1.1)
    for bad_time in (-0.1, float("nan"), True, None):
        with pytest.raises(avp.ConfigError, match="replan.retime_min_time"):
            ReplanConfig(retime_min_time=bad_time)


# -- trackability certificate ----------------------------------------------------------------------


def _exact_sq_norm_derivative(c, order, T):
    """Independent oracle: exact coefficients in u of |d^order x / dt^order|^2 via Fraction
    polynomial differentiation written out directly."""
    out = {}
    for axis in range(3):
        poly = [Fraction(float(x)) for x in c[axis]]
        for _ in range(order):
            poly = [k * poly[k] for k in range(1, len(poly))]
        poly = [poly[k] * T**k for k in range(len(poly))]
        for i, a in enumerate(poly):
            for j, b in enumerate(poly):
                out[i + j] = out.get(i + j, Fraction(0)) + a * b
    return [out.get(k, Fraction(0)) for k in range(max(out) + 1)]


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**31), duration=st.floats(0.1, 2.0), limit=st.floats(1.0, 500.0))
def test_snap_polynomial_coefficients_bound_the_exact_ones_by_one_ulp(seed, duration, limit):
    c = np.random.default_rng(seed).normal(scale=10.0, size=(4, 8))
    T = Fraction(duration)
    got = snap_polynomial(c, T, limit)
    exact = _exact_sq_norm_derivative(c, 4, T)
    exact[0] -= Fraction(limit) ** 2
    assert len(got) == len(exact)
    for g, e in zip(got, exact, strict=True):
        assert Fraction(g) >= e  # rounded upward: sound
        assert g <= math.nextafter(float(e), math.inf)  # and tight
    k = 30.0
    got_k = snap_thrust_polynomial(c, T, k, 9.81)
    acc_sq = _exact_sq_norm_derivative(c, 2, T)
    # |a + g e3|^2 = |a|^2 + 2 g a_z + g^2
    az = [Fraction(float(c[2, k2])) * k2 * (k2 - 1) * T ** (k2 - 2) for k2 in range(2, 8)]
    thrust = list(acc_sq) + [Fraction(0)] * 8
    for i, a in enumerate(az):
        thrust[i] += 2 * Fraction(9.81) * a
    thrust[0] += Fraction(9.81) ** 2
    snap = _exact_sq_norm_derivative(c, 4, T)
    for i, g in enumerate(got_k):
        e = (snap[i] if i < len(snap) else 0) - Fraction(k) ** 2 * thrust[i]
        assert Fraction(g) >= e


def _fraction_rows(tr, snap_max, ratio_max):
    """The reference rows: the Fraction computation of avp.trackability, segment by segment."""
    rows = []
    for i in range(tr.n_segments):
        T = Fraction(float(tr.knots[i + 1])) - Fraction(float(tr.knots[i]))
        if math.isfinite(snap_max):
            rows.append(snap_polynomial(tr.coefficients[i], T, snap_max))
        if math.isfinite(ratio_max):
            rows.append(snap_thrust_polynomial(tr.coefficients[i], T, ratio_max, tr.g))
    out = np.zeros((len(rows), max(len(r) for r in rows)))
    for j, r in enumerate(rows):
        out[j, :len(r)] = r
    return out


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**31), n_seg=st.integers(1, 4), n_coeffs=st.integers(3, 12),
       decades=st.floats(0.0, 8.0), t0=st.floats(-50.0, 50.0),
       limits=st.sampled_from([(300.0, 40.0), (math.inf, 12.5), (1e3 / 3, math.inf), (0.7, 1e-3)]))
def test_rust_trackability_rows_are_the_fraction_rows_bit_for_bit(seed, n_seg, n_coeffs, decades, t0, limits):
    rng = np.random.default_rng(seed)
    c = rng.normal(size=(n_seg, 4, n_coeffs)) * 10.0 ** rng.uniform(-decades, decades, size=(n_seg, 4, n_coeffs))
    knots = t0 + np.cumsum(np.r_[0.0, rng.uniform(1e-3, 3.0, size=n_seg)])
    tr = Trajectory(c, knots)
    got = avp._avp_rust.trackability_rows(tr.coefficients, tr.knots, *limits, tr.g)
    ref = _fraction_rows(tr, *limits)
    assert got.shape == ref.shape
    assert np.array_equal(got, ref) and np.array_equal(np.signbit(got), np.signbit(ref))


def test_trackability_rows_fall_back_to_fractions_outside_the_float_range():
    c = np.zeros((1, 4, 8))
    c[0, 0, 6] = 1e200  # its snap squared overflows a float: the kernel refuses, Fraction decides
    tr = Trajectory(c, np.array([0.0, 1.0]))
    with pytest.raises(avp._avp_rust.KernelError, match="normal f64 range"):
        avp._avp_rust.trackability_rows(tr.coefficients, tr.knots, 10.0, math.inf, tr.g)
    with pytest.raises(OverflowError):  # the Fraction path's own answer, as before the kernel
        trackability_rows(tr, 10.0, math.inf)
    with pytest.raises(avp.ConfigError, match="snap_thrust_max"):
        trackability_rows(tr, 10.0, -1.0)
    with pytest.raises(avp.ConfigError, match="snap_max"):
        trackability_rows(tr, math.inf, math.inf)
    tiny = Trajectory(c * 1e-180, np.array([0.0, 1.0]))  # |s|^2 ~ 1e-355: subnormal, the kernel refuses
    assert np.array_equal(trackability_rows(tiny, math.inf, 2.0), _fraction_rows(tiny, math.inf, 2.0))


def test_snap_certificate_agrees_with_dense_sampling():
    tr = avp.plan(START, WALL, sim_config())
    t = np.linspace(tr.t0, tr.tf, 20000)
    d = tr.derivatives(t, (2, 4))
    s = np.linalg.norm(d[1][:, :3], axis=1)
    ratio = s / np.linalg.norm(d[0][:, :3] + [0, 0, tr.g], axis=1)
    assert certify_snap(tr, 1.01 * s.max()).certified
    assert not certify_snap(tr, 0.99 * s.max()).certified
    assert certify_snap(tr, math.inf, snap_thrust_max=1.01 * ratio.max()).certified
    low = certify_snap(tr, math.inf, snap_thrust_max=0.99 * ratio.max())
    assert Certificate.VIOLATED in low.verdicts
    assert all(v is Certificate.NOT_CHECKED for v in certify_snap(tr, math.inf).verdicts)
    with pytest.raises(avp.ConfigError, match="snap_max"):
        certify_snap(tr, -1.0)


def test_wilson_interval_matches_the_closed_form():
    lo, hi = wilson_interval(90, 100)
    assert lo == pytest.approx(0.8256, abs=1e-4) and hi == pytest.approx(0.9448, abs=1e-4)
    assert wilson_interval(0, 10)[0] == 0.0 and wilson_interval(10, 10)[1] == pytest.approx(1.0)


def test_without_keep_knots_a_replan_splits_the_time_left_equally():
    """The default layout: n_segments equal pieces of the time left, the switch at t_ex."""
    knots = np.array([0.0, 0.4, 1.3, 2.0])
    committed = Trajectory(np.zeros((3, 4, 8)), knots)
    rp = Replanner.__new__(Replanner)
    rp.replan = ReplanConfig()
    rp.config = avp.PlannerConfig()
    assert rp._switch_time(committed, 0.39) == 0.39
    np.testing.assert_array_equal(rp._durations(committed, 0.39, 1.61), np.full(3, 1.61 / 3))


def test_keep_knots_waits_for_a_near_knot_even_when_pieces_are_merged():
    """A committed plan with more pieces left than n_segments (a plan handed in by the user):
    the switch still waits for a knot 1 ms away, so no 1 ms first segment is laid out."""
    knots = np.array([0.0, 1.0, 1.3, 1.4, 1.5])
    committed = Trajectory(np.zeros((4, 4, 8)), knots)
    rp = Replanner.__new__(Replanner)
    rp.replan = ReplanConfig(keep_knots=True)
    rp.config = avp.PlannerConfig()
    t_ex = rp._switch_time(committed, 0.999)
    assert t_ex == 1.0
    np.testing.assert_allclose(rp._durations(committed, t_ex, 0.5), [0.3, 0.1, 0.1])


def test_a_retimed_commit_is_certified_and_its_nominal_time_was_not(monkeypatch):
    """``retime_retries``: in a realistic closed loop (avp's model, a wall at 4.5 m) a full
    correction that failed a certificate at the nominal time left is committed at a scaled one.
    The step's planning calls show it: the first, at the nominal time, fails the bounds or the
    trackability certificate (re-checked here), the committed one has the durations of the
    reported factor, and its snap limits hold on a dense grid. Without the retries no commit is
    retimed, and the flight, the same until then, does not commit that correction in full."""
    calls: list[tuple[int, tuple]] = []

    class Recording(Replanner):
        def _plan(self, state, target, durations, previous, config, deadline=None):
            calls.append((len(self.history), (state, target, durations, previous, config)))
            return super()._plan(state, target, durations, previous, config, deadline)

    monkeypatch.setattr(avp.sim.run, "Replanner", Recording)
    sc = SimConfig().scenario(90.0, 4.5)
    r = simulate(sc, Mode.AVP, seed=3)
    retimed = [(i, s) for i, s in enumerate(r.steps) if s.time_factor != 1.0]
    assert retimed
    rc = ReplanConfig()
    for i, s in retimed:
        assert s.action is ReplanAction.REPLANNED and s.fraction == 1.0
        assert any(math.isclose(s.time_factor, f, rel_tol=1e-9) for f in rc.retime_retries)
        assert "time left x" in s.reason
        mine = [a for k, a in calls if k == i]
        assert 2 <= len(mine) == s.n_solves <= 1 + len(rc.retime_retries)
        nominal, last = mine[0], mine[-1]
        assert math.isclose(float(np.sum(last[2])), s.time_factor * float(np.sum(nominal[2])), rel_tol=1e-9)
        assert last[1] is nominal[1]  # the same goal, the full correction
        state, target, durations, previous, config = nominal
        again = avp.plan_detailed(state, target, config, durations=durations, previous=previous, warm_start=previous)
        failed_bounds = (again.status is PlanStatus.BOUNDS_NOT_CERTIFIED or again.bounds is None
                         or not again.bounds.certified)
        limits = (s.snap.snap_max, s.snap.snap_thrust_max)
        failed_snap = again.ok and not certify_snap(again.trajectory, limits[0], snap_thrust_max=limits[1]).certified
        assert failed_bounds or failed_snap
        tr = s.trajectory
        assert s.snap.certified and s.result.bounds.certified
        t = np.linspace(tr.t0, tr.tf, 4000)
        d = tr.derivatives(t, (2, 4))
        snap = np.linalg.norm(d[1][:, :3], axis=1)
        f = np.linalg.norm(d[0][:, :3] + [0.0, 0.0, tr.g], axis=1)
        assert snap.max() < limits[0] and np.max(snap / f) < limits[1]
    plain = simulate(sc, Mode.AVP, seed=3, replan=ReplanConfig(retime_retries=()))
    assert all(s.time_factor == 1.0 for s in plain.steps)
    first = retimed[0][0]  # the same flight up to the first retimed step, which plain cannot commit in full
    assert [s.action for s in plain.steps[:first]] == [s.action for s in r.steps[:first]]
    assert plain.steps[first].fraction < 1.0 and plain.steps[first].n_solves >= 2


def _failing_full_corrections(rc, monkeypatch, elapsed=None, static=True):
    """A replanner after its first plan whose full corrections all fail only the trackability
    certificate (the other fractions are certified as usual), recording the time left of every
    planning call; ``elapsed`` replaces the measured solve time."""
    rp = Replanner(WALL, sim_config(), rc)
    rp.step(0.0, START)
    calls: list[tuple[object, float]] = []
    plan, certified = rp._plan, rp._certified
    clock = _slow_solves(monkeypatch) if elapsed is not None else None

    def fake_plan(state, target, durations, previous, config, deadline=None):
        # with the fake clock, the budget is in fake seconds: the planner gets none
        result, took, error = plan(state, target, durations, previous, config, deadline if clock is None else None)
        calls.append((target, float(np.sum(durations))))
        if clock is None:
            return result, took, error
        clock.now += elapsed
        return result, elapsed, error

    def fake_certified(result, trackability=True):
        ok, why, snap, only = certified(result, trackability)
        if calls and calls[-1][0] is rp.target and ok:
            return False, "snap 1e9 > limit (forced)", snap, True
        return ok, why, snap, only

    monkeypatch.setattr(rp, "_plan", fake_plan)
    monkeypatch.setattr(rp, "_certified", fake_certified)
    if not static:
        monkeypatch.setattr(Replanner, "_static_pad", property(lambda self: False))
    return rp, calls


def _moved_wall_step(rp, t=0.5, dz=0.02):
    moved = avp.PerchTarget(point=WALL.point + [0.0, 0.0, dz], R_WS=WALL.R_WS)
    return rp.step(t, _fly_reference(rp, t), moved)


def test_failed_retries_report_the_nominal_plan_and_fall_back_to_the_fractions(monkeypatch):
    """A full correction that fails only a certificate is retried at every factor in turn, then
    the fractions follow; a step that commits no full correction reports the nominal time's plan,
    ``time_factor`` 1 and which retries were made."""
    rc = ReplanConfig()
    rp, calls = _failing_full_corrections(rc, monkeypatch)
    s = _moved_wall_step(rp)
    nominal = calls[0][1]
    full = [T for target, T in calls if target is rp.target]
    np.testing.assert_allclose(full, [nominal * f for f in (1.0, *rc.retime_retries)], rtol=1e-12)
    assert len(calls) > len(full)  # the fractions were tried after the retries
    assert s.time_factor == 1.0 and s.fraction < 1.0
    if s.action is ReplanAction.KEPT_PREVIOUS:  # no fraction certified either
        assert math.isclose(float(np.sum(s.result.trajectory.durations)), nominal, rel_tol=1e-12)
    assert s.action in (ReplanAction.PARTIAL, ReplanAction.KEPT_PREVIOUS, ReplanAction.CANNOT_REACH)


def _nothing_certifies(rp):
    """``rp._certified`` with every certified plan turned into one that fails only a certificate."""
    original = Replanner._certified.__get__(rp)

    def certified(result, trackability=True):
        ok, why, snap, only = original(result, trackability)
        return (False, "snap 1e9 > limit (forced)", snap, True) if ok else (ok, why, snap, only)
    return certified


def _full_calls(rp, calls, t, dz):
    """One step with the estimate moved by ``dz``; its full-correction planning calls' totals."""
    before = len(calls)
    s = _moved_wall_step(rp, t=t, dz=dz)
    return s, [T for target, T in calls[before:] if target is rp.target]


NOT_RETIMED = "the full correction was not retimed"


@pytest.mark.parametrize("backoff", [True, False])
def test_retries_back_off_after_they_all_failed_until_a_plan_is_committed(monkeypatch, backoff):
    """``retime_backoff``: after a step whose retries all failed and that committed nothing, the
    next steps solve the full correction at the nominal time only (and say so) while nothing is
    committed; after a commit (here a partial one), a failing full correction is retried again.
    Off: every step retries."""
    rc = ReplanConfig(retime_backoff=backoff)
    rp, calls = _failing_full_corrections(rc, monkeypatch)
    n_retried = 1 + len(rc.retime_retries)
    partial_ok = rp._certified  # full corrections fail a certificate, the fractions certify
    monkeypatch.setattr(rp, "_certified", _nothing_certifies(rp))
    s1, full1 = _full_calls(rp, calls, 0.5, 0.02)
    assert s1.action in (ReplanAction.KEPT_PREVIOUS, ReplanAction.CANNOT_REACH) and len(full1) == n_retried
    assert NOT_RETIMED not in s1.reason
    s2, full2 = _full_calls(rp, calls, 0.55, 0.03)
    assert s2.action in (ReplanAction.KEPT_PREVIOUS, ReplanAction.CANNOT_REACH)
    assert len(full2) == (1 if backoff else n_retried)
    assert (NOT_RETIMED in s2.reason) is backoff
    monkeypatch.setattr(rp, "_certified", partial_ok)
    s3, full3 = _full_calls(rp, calls, 0.6, 0.035)  # still no retries, but a fraction is committed
    assert s3.action is ReplanAction.PARTIAL and len(full3) == (1 if backoff else n_retried)
    assert (NOT_RETIMED in s3.reason) is backoff
    s4, full4 = _full_calls(rp, calls, 0.65, 0.045)  # something was committed: the retries are back
    assert len(full4) == n_retried and NOT_RETIMED not in s4.reason


def test_a_commit_in_the_same_step_ends_the_backoff(monkeypatch):
    """Retries that all fail followed by a committed fraction in the same step do not start the
    backoff: the committed plan changed, so the next step's problem is another one."""
    rp, calls = _failing_full_corrections(ReplanConfig(), monkeypatch)
    n_retried = 1 + len(rp.replan.retime_retries)
    s1, full1 = _full_calls(rp, calls, 0.5, 0.02)
    assert s1.action is ReplanAction.PARTIAL and len(full1) == n_retried
    s2, full2 = _full_calls(rp, calls, 0.55, 0.03)
    assert len(full2) == n_retried and NOT_RETIMED not in s2.reason


def test_retries_cut_by_the_deadline_do_not_start_the_backoff(monkeypatch):
    """With a deadline that leaves room for one retry only (solves of 1 ms, 3.5 ms), the retries
    did not all run: the next step retries again rather than backing off."""
    rp, calls = _failing_full_corrections(ReplanConfig(deadline=3.5e-3), monkeypatch, elapsed=1e-3)
    monkeypatch.setattr(rp, "_certified", _nothing_certifies(rp))
    s1, full1 = _full_calls(rp, calls, 0.5, 0.02)
    assert len(full1) == 2 and s1.fraction == 0.0
    s2, full2 = _full_calls(rp, calls, 0.55, 0.03)
    assert len(full2) == 2 and NOT_RETIMED not in s2.reason


def test_no_retries_for_a_plan_that_failed_other_than_a_certificate(monkeypatch):
    rp = Replanner(WALL, sim_config(), ReplanConfig())
    rp.step(0.0, START)
    plan = rp._plan
    full_calls: list[float] = []

    def infeasible_full(state, target, durations, previous, config, deadline=None):
        result, took, error = plan(state, target, durations, previous, config, deadline)
        if target is rp.target:
            full_calls.append(float(np.sum(durations)))
            return dataclasses.replace(result, status=PlanStatus.INFEASIBLE), took, error
        return result, took, error

    monkeypatch.setattr(rp, "_plan", infeasible_full)
    s = _moved_wall_step(rp)
    assert len(full_calls) == 1 and s.time_factor == 1.0 and s.fraction < 1.0


def test_certified_says_which_failures_a_retry_may_fix():
    """Only a solved, unrelaxed plan that failed its bounds or trackability certificate is
    retried; relaxed, infeasible and workspace-uncertified plans are not."""
    rp = Replanner(WALL, sim_config(), ReplanConfig())
    first = rp.step(0.0, START).result
    assert first is not None and first.ok and not first.relaxations
    ok, _, _, only = rp._certified(first)
    assert ok and not only
    uncertified = types.SimpleNamespace(certified=False)  # a bound report that did not certify
    assert rp._certified(dataclasses.replace(first, bounds=uncertified))[1:4:2] == ("actuator bounds not certified", True)
    bnc = dataclasses.replace(first, status=PlanStatus.BOUNDS_NOT_CERTIFIED, bounds=uncertified)
    assert rp._certified(bnc)[3] is True
    relaxed = dataclasses.replace(first, relaxations=("terminal velocity",))
    assert rp._certified(relaxed)[0] is False and rp._certified(relaxed)[3] is False
    assert rp._certified(dataclasses.replace(relaxed, status=PlanStatus.BOUNDS_NOT_CERTIFIED))[3] is False
    assert rp._certified(dataclasses.replace(relaxed, bounds=uncertified))[3] is False
    for status in (PlanStatus.INFEASIBLE, PlanStatus.WORKSPACE_NOT_CERTIFIED, PlanStatus.SOLVER_FAILED):
        assert rp._certified(dataclasses.replace(first, status=status))[3] is False
    rp.snap_limits = (1e-6, 1e-6)  # no plan meets these
    ok, why, snap, only = rp._certified(first)
    assert "snap" in why or "trackab" in why
    assert not ok and only and snap is not None and not snap.certified


def test_retries_only_for_a_static_pad_and_not_late(monkeypatch):
    """A subclass with its own target model keeps the committed contact time (no retries), and
    with less than ``retime_min_time`` left no retry is made."""
    rp, calls = _failing_full_corrections(ReplanConfig(), monkeypatch, static=False)
    _moved_wall_step(rp)
    assert len({round(T, 12) for _, T in calls}) == 1
    monkeypatch.undo()
    remaining = None
    rc = ReplanConfig(retime_min_time=50.0)  # more than any time left
    rp, calls = _failing_full_corrections(rc, monkeypatch)
    s = _moved_wall_step(rp)
    remaining = s.trajectory.tf - s.t_ex if s.trajectory is not None else None
    assert remaining is not None and remaining < rc.retime_min_time
    assert len([T for target, T in calls if target is rp.target]) == 1


def test_retries_leave_room_for_the_smallest_fraction_within_the_deadline(monkeypatch):
    """With a deadline, a retry starts only while it and the smallest fraction fit: with every
    solve taking 1 ms and a 3.5 ms deadline, the nominal time and one retry are solved, then the
    smallest fraction, which is committed since no further solve fits."""
    rc = ReplanConfig(deadline=3.5e-3)
    rp, calls = _failing_full_corrections(rc, monkeypatch, elapsed=1e-3)
    s = _moved_wall_step(rp)
    full = [T for target, T in calls if target is rp.target]
    assert len(full) == 2 and math.isclose(full[1], full[0] * rc.retime_retries[0], rel_tol=1e-12)
    assert s.action is ReplanAction.PARTIAL
    assert math.isclose(s.fraction, rc.partial_fractions[-1], rel_tol=1e-12)


RESUMED = "began with the partial corrections"


@pytest.mark.parametrize("deadline", [1.5, None])
def test_a_step_cut_before_its_fractions_leaves_them_to_the_next(monkeypatch, deadline):
    """Solves of 1 s and a 1.5 s deadline: one solve per step. The full correction fails, so the
    next solving step begins with the smallest fraction (which certifies and is committed), not
    with the full correction again; the step after that begins with the full correction. Without
    a deadline every step tries them all, full first."""
    rp, tried = _fraction_probe(monkeypatch, lambda f: f < 0.2, ReplanConfig(deadline=deadline), elapsed=1.0)
    s1 = rp.step(0.4, _fly_reference(rp, 0.4), MOVED)
    n1 = len(tried)
    s2 = rp.step(0.45, _fly_reference(rp, 0.45), MOVED)
    n2 = len(tried)
    s3 = rp.step(0.5, _fly_reference(rp, 0.5), MOVED)
    if deadline is None:
        assert tried[:n1] == pytest.approx([1.0, 0.125, 0.5, 0.25]) and s1.action is ReplanAction.PARTIAL
        assert tried[n1] == pytest.approx(1.0) and RESUMED not in s2.reason + s3.reason
        return
    assert tried[:n1] == pytest.approx([1.0]) and s1.action is ReplanAction.KEPT_PREVIOUS
    assert "no time for 12.5 %" in s1.reason and RESUMED not in s1.reason
    assert tried[n1:n2] == pytest.approx([0.125]) and RESUMED in s2.reason
    assert s2.action is ReplanAction.PARTIAL and s2.fraction == pytest.approx(0.125)
    assert rp.trajectory is s2.trajectory
    assert tried[n2] == pytest.approx(1.0) and RESUMED not in s3.reason  # from the start again


def test_a_step_whose_smallest_fraction_ran_leaves_nothing_to_the_next(monkeypatch):
    """A deadline that cuts a step after its smallest fraction was tried (and failed) carries
    nothing over: the next step begins with the full correction."""
    rp, tried = _fraction_probe(monkeypatch, lambda f: False, ReplanConfig(deadline=2.5), elapsed=1.0)
    rp.step(0.4, _fly_reference(rp, 0.4), MOVED)
    assert tried == pytest.approx([1.0, 0.125])
    s2 = rp.step(0.45, _fly_reference(rp, 0.45), MOVED)
    assert tried[2:] == pytest.approx([1.0, 0.125]) and RESUMED not in s2.reason


def test_retries_cut_by_the_deadline_are_made_at_the_next_steps(monkeypatch):
    """Full corrections that fail only a certificate, solves of 1 ms, a 1.5 ms deadline: the
    nominal time, then each retimed retry, then the fractions, one per step, each step going on
    where the one before was cut; once every retry ran and failed (over several steps) and
    nothing was committed, the next full correction is not retimed (``retime_backoff``)."""
    rc = ReplanConfig(deadline=1.5e-3)
    rp, calls = _failing_full_corrections(rc, monkeypatch, elapsed=1e-3)
    monkeypatch.setattr(rp, "_certified", _nothing_certifies(rp))
    steps, full, other = [], [], []
    for i in range(5):
        before = len(calls)
        steps.append(_moved_wall_step(rp, t=0.5 + 0.05 * i, dz=0.02 + 0.001 * i))
        new = calls[before:]
        assert len(new) == 1 and steps[-1].n_solves == 1  # one solve fits each step
        full.append([T for target, T in new if target is rp.target])
        other.append([T for target, T in new if target is not rp.target])
    nominal = [None if not f else f[0] for f in full]
    # step 0: the nominal time; steps 1, 2: the retries; step 3: the fractions; step 4: from the start
    assert full[0] and full[1] and full[2] and not full[3] and other[3] and full[4]
    assert "began with the retimed retry x0.97" in steps[1].reason
    assert "began with the retimed retry x1.03" in steps[2].reason
    assert RESUMED in steps[3].reason
    assert NOT_RETIMED in steps[4].reason  # every retry ran (over two steps) and failed
    left = [rp.trajectory.tf - s.t_ex for s in steps]  # nothing was committed: the first plan's
    for i, factor in enumerate((1.0, *rc.retime_retries)):  # the normal correction is 0 on a wall
        assert nominal[i] == pytest.approx(factor * left[i], rel=1e-9)


def test_retries_that_overrun_the_deadline_over_several_steps_start_the_backoff(monkeypatch):
    """Solves slower than the whole deadline (2 ms against 1.5 ms): each step makes one, ends past
    the deadline, and the next goes on from there. Once the last retry due has run and failed,
    ``retime_backoff`` holds as after one step that ran them all."""
    rc = ReplanConfig(deadline=1.5e-3)
    rp, _calls = _failing_full_corrections(rc, monkeypatch, elapsed=2e-3)
    monkeypatch.setattr(rp, "_certified", _nothing_certifies(rp))
    steps = [_moved_wall_step(rp, t=0.5 + 0.05 * i, dz=0.02 + 0.001 * i) for i in range(6)]
    assert [s.n_solves for s in steps] == [1] * 6 and all("too late" in s.reason for s in steps)
    assert "began with the retimed retry x0.97" in steps[1].reason
    assert "began with the retimed retry x1.03" in steps[2].reason
    assert RESUMED in steps[3].reason
    assert NOT_RETIMED in steps[4].reason  # the nominal time only: no retry is due after it
    assert RESUMED in steps[5].reason and "retimed retry" not in steps[5].reason


def test_a_resumed_retry_that_fails_otherwise_leaves_the_next_retry(monkeypatch):
    """The nominal time failed only a certificate at the step before; the retry this step goes on
    with fails for another reason (here: forced). The correction stays retryable, so the next
    step makes the retry still due, as one step without a deadline would have."""
    rc = ReplanConfig(deadline=1.5e-3)
    rp, calls = _failing_full_corrections(rc, monkeypatch, elapsed=1e-3)
    fails_certificate = _nothing_certifies(rp)
    n_full = [0]

    def certified(result, trackability=True):
        if calls[-1][0] is rp.target:
            n_full[0] += 1
            if n_full[0] == 2:  # the first retry
                return False, "forced: not a certificate", None, False
        return fails_certificate(result, trackability)

    monkeypatch.setattr(rp, "_certified", certified)
    steps = [_moved_wall_step(rp, t=0.5 + 0.05 * i, dz=0.02 + 0.001 * i) for i in range(3)]
    assert "began with the retimed retry x0.97" in steps[1].reason
    assert "forced: not a certificate" in steps[1].reason  # the retry failed otherwise
    assert "began with the retimed retry x1.03" in steps[2].reason


def test_retries_are_carried_over_with_no_fraction_to_try(monkeypatch):
    """``partial_fractions=(1,)``: with one solve per step, the retimed retries the deadline cut
    are made at the next steps (a retry does not wait for room for a fraction that does not
    exist), and once they have all failed ``retime_backoff`` holds."""
    rc = ReplanConfig(deadline=1.5e-3, partial_fractions=(1.0,))
    rp, calls = _failing_full_corrections(rc, monkeypatch, elapsed=1e-3)
    monkeypatch.setattr(rp, "_certified", _nothing_certifies(rp))
    steps = [_moved_wall_step(rp, t=0.5 + 0.05 * i, dz=0.02 + 0.001 * i) for i in range(4)]
    assert [s.n_solves for s in steps] == [1] * 4 and len(calls) == 4
    assert "the deadline left the retimed retries still due to the next step" in steps[0].reason
    assert "began with the retimed retry x0.97" in steps[1].reason
    assert "began with the retimed retry x1.03" in steps[2].reason
    assert NOT_RETIMED in steps[3].reason


def test_a_resumed_retry_that_certifies_says_where_the_step_began(monkeypatch):
    """One solve per step; the nominal time fails a certificate and the retimed retries certify:
    the next step commits the first retry, and its reason says the step began there."""
    rc = ReplanConfig(deadline=1.5e-3)
    rp, calls = _failing_full_corrections(rc, monkeypatch, elapsed=1e-3)
    nominal_fails = rp._certified
    n_full = [0]

    def certified(result, trackability=True):
        if calls[-1][0] is rp.target:
            n_full[0] += 1
            if n_full[0] > 1:  # the retries: as the planner certified them
                return Replanner._certified(rp, result, trackability)
        return nominal_fails(result, trackability)

    monkeypatch.setattr(rp, "_certified", certified)
    s0 = _moved_wall_step(rp, t=0.5)
    s1 = _moved_wall_step(rp, t=0.55)
    assert s0.action in (ReplanAction.KEPT_PREVIOUS, ReplanAction.CANNOT_REACH) and s0.n_solves == 1
    assert s1.action is ReplanAction.REPLANNED and s1.time_factor == pytest.approx(0.97)
    assert "began with the retimed retry x0.97" in s1.reason


def test_what_a_cut_step_left_is_dropped_when_held_or_without_a_deadline(monkeypatch):
    """A held step (the estimate back at the committed target) drops where a cut step left off,
    and so does a replanner whose deadline was switched off: the next correction begins with the
    full correction at the nominal time."""
    for switch_off in (False, True):
        rc = ReplanConfig(deadline=1.5e-3)
        rp, calls = _failing_full_corrections(rc, monkeypatch, elapsed=1e-3)
        monkeypatch.setattr(rp, "_certified", _nothing_certifies(rp))
        s0 = _moved_wall_step(rp, t=0.5)
        assert s0.n_solves == 1 and rp._resume == 1
        if switch_off:
            rp.replan = ReplanConfig()
        else:
            held = rp.step(0.55, _fly_reference(rp, 0.55), WALL)
            assert held.action is ReplanAction.HELD
        before = len(calls)
        s2 = _moved_wall_step(rp, t=0.6)
        full = [T for target, T in calls[before:] if target is rp.target]
        assert "began with" not in s2.reason
        assert full[0] == pytest.approx(rp.trajectory.tf - s2.t_ex, rel=1e-9)  # the nominal time first
        monkeypatch.undo()


def test_two_fractions_are_carried_over_too(monkeypatch):
    """With ``partial_fractions=(1, 1/2)`` and one solve per step, the step after a cut one begins
    with the half correction."""
    rc = ReplanConfig(deadline=1.5, partial_fractions=(1.0, 0.5))
    rp, tried = _fraction_probe(monkeypatch, lambda f: f < 0.6, rc, elapsed=1.0)
    s0 = rp.step(0.4, _fly_reference(rp, 0.4), MOVED)
    s1 = rp.step(0.45, _fly_reference(rp, 0.45), MOVED)
    assert tried == pytest.approx([1.0, 0.5]) and s0.action is ReplanAction.KEPT_PREVIOUS
    assert s1.action is ReplanAction.PARTIAL and s1.fraction == pytest.approx(0.5) and RESUMED in s1.reason


def test_step_refuses_time_going_back_and_keeps_its_state():
    """A step earlier than the previous one (a clock reset, mixed clocks) is bad input: a typed
    error naming ``t``, and the replanner's plan and history are as before; the same time again
    is a step like any other."""
    rp = Replanner(WALL, sim_config())
    rp.step(0.0, START)
    rp.step(0.2, _fly_reference(rp, 0.2))
    plan, n = rp.trajectory, len(rp.history)
    with pytest.raises(avp.ConfigError, match=r"^t: went back from 0.2 s to 0.1 s.*new Replanner"):
        rp.step(0.1, _fly_reference(rp, 0.1))
    assert rp.trajectory is plan and len(rp.history) == n
    again = rp.step(0.2, _fly_reference(rp, 0.2))
    assert again.t == 0.2 and len(rp.history) == n + 1
