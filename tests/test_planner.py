"""Planner properties on the paper's standard scenarios and on random ones (hypothesis)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import qpsolvers
from hypothesis import given
from hypothesis import strategies as st
from scenarios import Scenario, standard, standard_grid

import avp
from avp.qp.perching import band_times, terminal_acceleration

SOLVERS = [
    pytest.param(s, marks=pytest.mark.skipif(s not in qpsolvers.available_solvers, reason=f"{s} not installed"))
    for s in ("daqp", "proxqp", "osqp")
]

POS_TOL = 1e-3  # m
ANGLE_TOL = math.radians(0.5)
VEL_TOL = 1e-3  # m/s


def check_contact(
    traj: avp.Trajectory, target: avp.PerchTarget, config: avp.PlannerConfig, relaxed: tuple = ()
) -> None:
    """Terminal constraints: position, b3 = s3 (12), requested velocity components in S (the
    slide only if it was not relaxed), contact thrust alpha (unless it became a variable)."""
    tf = traj.tf
    assert np.linalg.norm(traj(tf) - target.point) < POS_TOL
    b3 = traj.attitude(tf)[:, 2]
    assert math.acos(min(1.0, float(b3 @ target.s3))) < ANGLE_TOL
    if avp.Relaxation.ALPHA_RANGE not in relaxed:
        assert abs(traj.thrust(tf) - config.contact_alpha(target.incline)) < 1e-6
    v_S = target.to_target_frame(traj(tf, 1))
    wanted = list(config.contact_velocity.components(target.incline))
    if avp.Relaxation.FREE_SLIDE in relaxed:
        wanted[0] = None
    for got, want in zip(v_S, wanted, strict=True):
        if want is not None:
            assert abs(got - want) < VEL_TOL


def check_continuity(traj: avp.Trajectory, max_order: int = 4) -> None:
    """Left and right limits agree up to snap at every interior knot."""
    c = traj.coefficients
    for i, T in enumerate(traj.durations[:-1]):
        for r in range(max_order + 1):
            left = np.array([np.polynomial.polynomial.polyval(T, np.polynomial.polynomial.polyder(c[i, a], r) if r else c[i, a]) for a in range(4)])
            right = traj.evaluate(traj.knots[i + 1], r)
            assert np.allclose(left, right, rtol=1e-7, atol=1e-7 * max(1.0, np.abs(left).max())), (i, r)


def check_band(traj: avp.Trajectory, target: avp.PerchTarget, config: avp.PlannerConfig) -> None:
    """Band (14) at its sample times, with the configured width floor."""
    c0 = terminal_acceleration(target, config.contact_alpha(target.incline), config.g)
    lo = np.minimum(c0, (1 + config.q) * c0)
    hi = np.maximum(c0, (1 + config.q) * c0)
    pad = np.maximum(0.0, config.band_min_width - (hi - lo)) / 2
    times = traj.t0 + band_times(config, traj.duration)
    a = traj(times, 2)
    assert np.all(a >= lo - pad - 1e-6) and np.all(a <= hi + pad + 1e-6)


@pytest.mark.parametrize("solver", SOLVERS)
@pytest.mark.parametrize("scenario", standard_grid(), ids=lambda s: s.name)
def test_standard_scenarios_meet_perching_constraints(scenario: Scenario, solver: str) -> None:
    config = avp.PlannerConfig(solver=solver)
    result = avp.plan_detailed(scenario.state, scenario.target, config)
    # The FoV rows may be incompatible (16) and dropped (at 1.5 m on the floor and the 60 deg slope,
    # with the contact thrust g cos(incline); OSQP also at its iteration cap): still a perch, and
    # the status says so. Nothing is relaxed on the standard grid.
    assert result.status in {avp.PlanStatus.SOLVED, avp.PlanStatus.SOLVED_WITHOUT_FOV}, result.log
    assert result.relaxations == () and result.safety is not None and result.safety.certified
    assert result.bounds is not None and result.bounds.certified
    traj = result.trajectory
    assert traj is not None and np.isclose(traj.t0, scenario.state.time)
    check_contact(traj, scenario.target, config)
    check_continuity(traj)
    check_band(traj, scenario.target, config)
    # on the outward side of the pad's plane until contact (0.5 ms grid)
    ts = np.arange(traj.t0, traj.tf, 5e-4)
    assert np.all((traj(ts) - scenario.target.point) @ scenario.target.s3 > 0.0)
    # starts where the vehicle is
    assert np.allclose(traj.derivatives(traj.t0, (0, 1, 2, 3))[:, :3], scenario.state.derivatives(), atol=1e-9)


@pytest.mark.parametrize("mode", list(avp.PreImpactMode))
def test_pre_impact_modes_keep_thrust_axis_near_normal(mode: avp.PreImpactMode) -> None:
    """In the last t_k the thrust axis is within the cone (CONE) or the box (PAPER) of s3."""
    sc = standard(60, 3.5)
    config = avp.PlannerConfig(pre_impact=mode)
    traj = avp.plan(sc.state, sc.target, config)
    check_contact(traj, sc.target, config)
    times = traj.t0 + band_times(config, traj.duration)
    f = traj(times, 2) + np.array([0, 0, config.g])
    if mode is avp.PreImpactMode.CONE:
        alpha = config.contact_alpha(sc.target.incline)
        along = f @ sc.target.s3
        assert np.all(along >= alpha - 1e-6) and np.all(along <= (1 + config.q) * alpha + 1e-6)
        tilt = np.arccos(np.clip(along / np.linalg.norm(f, axis=1), -1, 1))
        assert np.all(tilt <= config.cone_half_angle + 1e-6)
    elif mode is avp.PreImpactMode.PAPER:
        check_band(traj, sc.target, config)


def test_paper_mode_zero_width_band_pins_component() -> None:
    """band_min_width = 0 reproduces the paper's equality rows where c0 has a zero component."""
    sc = standard(90, 3.5)
    config = avp.PlannerConfig(band_min_width=0.0)
    traj = avp.plan(sc.state, sc.target, config)
    times = traj.t0 + band_times(config, traj.duration)
    assert np.allclose(traj(times, 2)[:, 1], 0.0, atol=1e-6)  # c0_y = 0 on this wall


def test_user_durations_are_used() -> None:
    sc = standard(90, 3.5)
    traj = avp.plan(sc.state, sc.target, durations=[0.5, 0.6, 0.7])
    assert np.allclose(traj.durations, [0.5, 0.6, 0.7])


def snap_cost(traj: avp.Trajectory) -> float:
    """Cost (4) of the position, by the trapezoid rule on a fine grid."""
    t = traj.sample(1e-4)
    return float(np.trapezoid(np.sum(traj(t, 4) ** 2, axis=1), t))


def test_free_velocity_components_are_not_constrained() -> None:
    """Freeing components moves the contact velocity off the fixed value and cannot raise the
    minimum-snap cost (same durations, no FoV rows, no bound search)."""
    sc = standard(90, 3.5)
    plain = dict(fov=avp.FovConfig(enabled=False), bounds=avp.BoundsPolicy(certify=False))
    config = avp.PlannerConfig(contact_velocity=avp.ContactVelocity(normal=-0.3, slope=None, lateral=None), **plain)
    traj = avp.plan(sc.state, sc.target, config)
    check_contact(traj, sc.target, config)
    fixed = avp.plan(sc.state, sc.target, avp.PlannerConfig(**plain))
    assert np.allclose(traj.durations, fixed.durations)
    v_free = sc.target.to_target_frame(traj(traj.tf, 1))
    assert abs(v_free[0] - (-2.0)) > 1e-3  # the slide is chosen by the optimiser, not pinned
    assert snap_cost(traj) <= snap_cost(fixed) * (1 + 1e-6)


@st.composite
def random_problem(draw: st.DrawFn) -> tuple[avp.State, avp.PerchTarget]:
    incline = draw(st.floats(0.0, math.pi / 2))
    heading = draw(st.floats(-math.pi, math.pi))
    distance = draw(st.floats(1.0, 8.0))
    lateral = draw(st.floats(-1.0, 1.0))
    height = draw(st.floats(-1.0, 1.5))
    pad = np.array([0.0, 0.0, 2.0])
    target = avp.PerchTarget.from_incline(pad, incline, heading)
    h = np.array([math.cos(heading), math.sin(heading), 0.0])
    start = pad - distance * h + lateral * target.s2 + np.array([0.0, 0.0, height])
    moving = draw(st.booleans())
    vel = np.zeros(3)
    if moving:
        direction = draw(st.tuples(*[st.floats(-1, 1)] * 3)).__iter__()
        d = np.array(list(direction))
        if np.linalg.norm(d) > 1e-3:
            vel = draw(st.floats(0.0, 2.0)) * d / np.linalg.norm(d)
    yaw = heading + draw(st.floats(-0.8, 0.8))
    return avp.State(position=start, velocity=vel, yaw=yaw), target


@given(random_problem())
def test_random_problems_meet_every_equality(problem: tuple[avp.State, avp.PerchTarget]) -> None:
    state, target = problem
    config = avp.PlannerConfig()
    try:
        result = avp.plan_detailed(state, target, config)
    except avp.ConfigError as exc:  # the documented rejections: target at the start, start behind the pad
        behind = float((state.position - target.point) @ target.s3) <= 1e-9
        assert exc.field == "target.point" or (exc.field == "state.position" and behind), exc
        return
    if result.trajectory is None:  # a documented, reported outcome, never a crash
        assert result.status in (avp.PlanStatus.INFEASIBLE, avp.PlanStatus.SOLVER_FAILED)
        return
    # solved, or not certified with the last (uncertified) trajectory: equalities hold
    assert result.ok or result.status in (avp.PlanStatus.BOUNDS_NOT_CERTIFIED, avp.PlanStatus.WORKSPACE_NOT_CERTIFIED)
    traj = result.trajectory
    assert np.all(np.isfinite(traj.coefficients))
    check_contact(traj, target, config, result.relaxations)
    check_continuity(traj)
    d0 = traj.derivatives(traj.t0, (0, 1, 2, 3))
    assert np.allclose(d0[:, :3], state.derivatives(), atol=1e-8)
    assert abs(d0[0, 3] - state.yaw) < 1e-9 and abs(d0[1, 3] - state.yaw_rate) < 1e-9
    # terminal yaw (13): R_WB(tf) equals R_WS, not only b3 = s3
    assert avp.frames.rotation_error_angle(traj.attitude(traj.tf), target.R_WS) < ANGLE_TOL


def test_alpha_nominal_sets_the_contact_thrust_on_steep_pads_only() -> None:
    """``alpha_nominal`` is the contact thrust on steep pads; flatter pads keep ``g cos(incline)``
    when that is larger, and a plan meets it at contact."""
    cfg = avp.PlannerConfig(alpha_nominal=6.0)
    assert avp.PlannerConfig().alpha_nominal == avp.config.ALPHA_NOMINAL == 4.0
    assert cfg.contact_alpha(math.radians(90.0)) == 6.0
    assert cfg.contact_alpha(math.radians(60.0)) == 6.0  # g cos 60 deg = 4.9 is below it
    assert cfg.contact_alpha(math.radians(45.0)) == pytest.approx(cfg.g * math.cos(math.radians(45.0)))
    target = avp.PerchTarget.from_incline([3.5, 0.0, 1.5], math.radians(90.0))
    traj = avp.plan(avp.State.hover([0.0, 0.0, 1.5]), target, cfg)
    assert abs(traj.thrust(traj.tf) - 6.0) < 1e-6
    for bad in (0.0, -1.0, math.nan):
        with pytest.raises(avp.ConfigError, match="config.alpha_nominal"):
            avp.PlannerConfig(alpha_nominal=bad)


# Gao et al.'s tight limits (benchmarks/bench_gao_perch.py): a near rest-to-rest 60 deg perch
# needs a time search (two failing durations, then a certified one, then the FoV re-solve).
GAO_LIMITS = avp.VehicleLimits(mass=1.0, thrust_min=5.0, thrust_max=17.0, tilt_rate_max=3.0)


def _searching_request():
    cfg = avp.PlannerConfig(limits=GAO_LIMITS, alpha=5.5,
                            contact_velocity=avp.ContactVelocity(normal=-0.05, slope=0.0, lateral=0.0))
    return avp.State.hover([0.0, 0.0, 1.5]), avp.PerchTarget.from_incline([3.0, 0.0, 1.5], math.radians(60.0)), cfg


def test_a_deadline_that_leaves_no_time_ends_the_plan_out_of_time():
    """A deadline shorter than any attempt: the first attempt runs, then nothing else fits, and
    the result says so (not ok: its trajectory, the uncertified attempt, is no plan), where the
    plan without a deadline searches on to a certified one."""
    state, target, cfg = _searching_request()
    full = avp.plan_detailed(state, target, cfg)
    assert full.status is avp.PlanStatus.SOLVED and full.duration_scale_steps >= 2
    cut = avp.plan_detailed(state, target, cfg, deadline=1e-9)
    assert cut.status is avp.PlanStatus.OUT_OF_TIME and not cut.ok and not cut.status.has_trajectory
    assert cut.duration_scale_steps == 0 and cut.log[-1].startswith("deadline")
    assert cut.trajectory is None or not cut.trajectory.provenance.bounds_certified


@pytest.mark.parametrize("bad", [0.0, -1.0, float("nan"), float("inf"), "soon", []])
def test_a_meaningless_deadline_is_a_config_error(bad):
    state, target, cfg = _searching_request()
    with pytest.raises(avp.ConfigError, match="deadline"):
        avp.plan_detailed(state, target, cfg, deadline=bad)


@pytest.mark.parametrize("certify", [True, False])
def test_refinement_cut_short_by_the_deadline_is_out_of_time_not_a_workspace_verdict(certify):
    """A speed limit the first solve breaks needs refinement rounds to certify (without a
    deadline the plan is SOLVED). With no time left for a round, the attempt is returned
    uncertified, and the plan ends OUT_OF_TIME, not WORKSPACE_NOT_CERTIFIED (which would claim
    that no plan keeps the limit)."""
    state = avp.State.hover([0.0, 0.0, 1.5])
    target = avp.PerchTarget.from_incline([3.5, 0.0, 1.5], math.radians(90))
    first = avp.plan(state, target)
    limit = 0.93 * float(np.linalg.norm(first(np.linspace(first.t0, first.tf, 400), 1), axis=1).max())
    cfg = avp.PlannerConfig(workspace=avp.Workspace(max_speed=limit),
                            bounds=avp.BoundsPolicy(certify=certify))
    full = avp.plan_detailed(state, target, cfg)
    assert full.ok and any("workspace: " in line for line in full.log)  # it took a refinement round
    cut = avp.plan_detailed(state, target, cfg, deadline=1e-9)
    assert cut.status is avp.PlanStatus.OUT_OF_TIME and not cut.ok
    assert any(line.startswith("deadline: no time for refinement round 1") for line in cut.log)


def test_a_generous_deadline_changes_nothing():
    state, target, cfg = _searching_request()
    full = avp.plan_detailed(state, target, cfg)
    timed = avp.plan_detailed(state, target, cfg, deadline=60.0)
    assert timed.status is full.status and timed.duration_scale_steps == full.duration_scale_steps
    assert np.array_equal(timed.trajectory.coefficients, full.trajectory.coefficients)
    assert np.array_equal(timed.trajectory.knots, full.trajectory.knots)


@pytest.mark.parametrize(("deadline", "want"), [(2.5, avp.PlanStatus.OUT_OF_TIME),
                                                (3.5, avp.PlanStatus.SOLVED_WITHOUT_FOV),
                                                (4.0, avp.PlanStatus.SOLVED)])
def test_an_attempt_starts_only_while_it_is_predicted_to_fit_the_deadline(monkeypatch, deadline, want):
    """Each attempt (one duration of the search, or the FoV re-solve) made to take 1 s on a clock
    that otherwise stands still: the search needs three attempts and then the FoV re-solve, so a
    2.5 s deadline stops it after two, 3.5 s keeps the certified FoV-free plan (and says why),
    and 4 s runs it all. The same durations and plan where one is returned."""
    import types

    import avp.attempt
    import avp.planner as planner

    state, target, cfg = _searching_request()
    full = avp.plan_detailed(state, target, cfg)
    clock = [0.0]
    real_solve_at = planner.solve_at

    def slow_solve_at(*args, **kw):
        clock[0] += 1.0
        return real_solve_at(*args, **kw)

    fake_time = types.SimpleNamespace(perf_counter=lambda: clock[0])
    monkeypatch.setattr(planner, "time", fake_time)
    monkeypatch.setattr(avp.attempt, "time", fake_time)  # the refinement rounds' budget: the same clock
    monkeypatch.setattr(planner, "solve_at", slow_solve_at)
    r = avp.plan_detailed(state, target, cfg, deadline=deadline)
    assert r.status is want
    assert clock[0] <= deadline  # no attempt was started that the prediction said would overrun
    if want is avp.PlanStatus.OUT_OF_TIME:
        assert clock[0] == 2.0
        return
    assert np.array_equal(r.trajectory.coefficients, full.trajectory.coefficients)
    assert r.fov_dropped is (want is avp.PlanStatus.SOLVED_WITHOUT_FOV)
    if r.fov_dropped:
        assert "FoV rows not added back: no time for the re-solve" in r.log


def test_plan_result_repr_is_one_readable_line() -> None:
    """The repr says the status, the plan, its durations and certificates in one line, without
    dumping the QP's arrays (it was 10 kB of coefficients)."""
    target = avp.PerchTarget.from_incline(np.array([0.0, 0.0, 1.5]), math.radians(90))
    result = avp.plan_detailed(avp.State.hover([-4.0, 0.0, 1.5]), target)
    text = repr(result)
    assert "\n" not in text and len(text) < 400
    assert text.startswith("PlanResult(status=SOLVED, trajectory=Trajectory(") and "(bounds certified;" in text
    assert "array(" not in text and "c_hat" not in text
    # a relaxed plan after a time search: still one short line, the relaxations said once
    tight = avp.PlannerConfig(limits=avp.VehicleLimits(mass=1.0, thrust_min=5.0, thrust_max=17.0, tilt_rate_max=3.0))
    relaxed = avp.plan_detailed(avp.State.hover([0.0, 0.0, 1.5]),
                                avp.PerchTarget.from_incline([3.0, 0.0, 1.5], math.radians(90)), tight)
    text = repr(relaxed)
    assert relaxed.relaxations and relaxed.duration_scale_steps > 0
    assert "\n" not in text and len(text) < 400 and text.count("FREE_SLIDE") == 1
    assert f"attempts={relaxed.duration_scale_steps + 1}" in text


@pytest.mark.parametrize("order", [0, 1, 2])
def test_a_continuity_below_jerk_is_refused(order: int) -> None:
    """Below jerk, the attitude or the body rates jump at a knot while the certificates, which
    bound them within each segment, hold: continuity_order 0 gave a wall plan a velocity jump of
    8.4 m/s and an attitude jump of 161 deg, reported SOLVED with certified bounds."""
    with pytest.raises(avp.ConfigError) as exc:
        avp.PlannerConfig(continuity_order=order)
    assert exc.value.field == "config.continuity_order"


def test_the_lowest_continuity_keeps_attitude_and_body_rates_continuous() -> None:
    """With the smallest continuity allowed (jerk) the plan is continuous to jerk at every knot
    (left limits from the coefficients, numpy's polynomials) and so are its attitude and body
    rates, (11) and (22)."""
    config = avp.PlannerConfig(continuity_order=3)
    target = avp.PerchTarget.from_incline([3.5, 0.0, 1.5], math.pi / 2)
    result = avp.plan_detailed(avp.State.hover([0.0, 0.0, 1.5]), target, config)
    assert result.status is avp.PlanStatus.SOLVED and result.bounds.certified
    traj = result.trajectory
    check_continuity(traj, max_order=3)
    for k in traj.knots[1:-1]:
        eps = 1e-7
        R = traj.attitude(np.array([k - eps, k + eps]))
        w = traj.body_rates(np.array([k - eps, k + eps]))
        assert np.degrees(np.arccos(np.clip((np.trace(R[0].T @ R[1]) - 1) / 2, -1, 1))) < 1e-3
        assert np.linalg.norm(w[1] - w[0]) < 1e-3


@pytest.mark.parametrize("thrust_max", [3.0, 0.5 * avp.PlannerConfig().g])
def test_a_vehicle_that_cannot_hover_is_refused(thrust_max: float) -> None:
    """Thrust at most the weight (0.5 kg): no hover, no climb; it was planned, searched and
    reported as uncertified bounds instead of refused."""
    with pytest.raises(avp.ConfigError) as exc:
        avp.PlannerConfig(limits=avp.VehicleLimits(thrust_max=thrust_max))
    assert exc.value.field == "limits.thrust_max"
    assert avp.PlannerConfig(limits=avp.VehicleLimits(thrust_max=0.5 * avp.PlannerConfig().g * 1.01)).limits.thrust_max > 0


def test_a_derived_stage_configuration_is_the_relaxed_configuration() -> None:
    """The stage configurations are cached per configuration object: each equals the one
    ``_relaxed`` builds for that object and that pad, the alpha range follows the pad's incline,
    and an equal but distinct configuration gets its own entry."""
    from avp import planner

    cfg = avp.PlannerConfig()
    steep, flat = avp.PerchTarget.from_incline([3.0, 0.0, 1.5], math.radians(90)), \
        avp.PerchTarget.from_incline([3.0, 0.0, 1.5], math.radians(30))
    for relaxation in avp.Relaxation:
        for target in (steep, flat):
            got = planner._relax(cfg, relaxation, target)
            assert got == planner._relaxed(cfg, relaxation, target)
            assert planner._relax(cfg, relaxation, target) is got  # built once
    assert planner._relax(cfg, avp.Relaxation.ALPHA_RANGE, steep).alpha_range \
        != planner._relax(cfg, avp.Relaxation.ALPHA_RANGE, flat).alpha_range
    twin = avp.PlannerConfig()
    assert planner._without_fov(twin) is not planner._without_fov(cfg)
    assert planner._without_fov(twin) == planner._without_fov(cfg) and not planner._without_fov(cfg).fov.enabled
    waypoint_off = planner._without_waypoint(avp.PlannerConfig(flip=avp.OverhangFlip(cone_band=True)))
    assert not waypoint_off.flip.enabled and waypoint_off.pre_impact is avp.PreImpactMode.CONE
