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


# -- the camera's attitude with drag: FoV rows (8)-(9) and the visibility score -------------------


def _off_axis_cosine(x, psi, acc, s, camera, g=9.81, scale=None):
    """cos(half_fov) - cos(angle between the optical axis and the target): h/|n_d| of (7),
    from the attitude of the thrust acc + g e3 (sampled geometry, not the FoV kernel); with
    ``scale``, h divided by that distance instead (the rows divide by |n_d| at z0)."""
    R = avp.frames.attitude(acc, psi, g)
    axis = camera.axis(R)
    n = s - x
    dist = float(np.linalg.norm(n))
    return (math.cos(camera.half_fov) * dist - float(axis @ n)) / (dist if scale is None else scale)


@pytest.mark.parametrize("drag", [0.2, 0.45])
def test_fov_rows_take_the_camera_attitude_of_the_drag_aware_thrust(drag):
    """With d the FoV rows are linearised in a + d v: at the linearisation point they equal the
    off-axis cosine of the thrust a + g e3 + d v's attitude, and along a small step of the
    decision vector they predict it to second order (a basis without d b1 would be off to first
    order in the velocity change)."""
    from avp.perception import linearise_on
    from avp.qp.assemble import build_perching_qp

    cfg = _config(drag, fov=avp.FovConfig(point_policy=avp.FovPointPolicy.KEEP))
    state = avp.State.hover([0.0, 0.0, 1.0])
    target = avp.PerchTarget.from_incline([4.0, 0.0, 1.0], math.pi / 2)
    ref = avp.plan_detailed(state, target, dataclasses.replace(cfg, fov=avp.FovConfig(enabled=False)))
    qp = build_perching_qp(state, target, cfg, ref.durations)
    lin = linearise_on(qp, ref.trajectory, target, cfg)
    rows = lin.blocks[0]
    assert rows.name == "fov rows (8)" and lin.placed.sum() >= 6  # the last point: at the pad
    cam = cfg.fov.camera
    t_abs = state.time + lin.times[lin.placed]

    dist0 = np.linalg.norm(target.point - ref.trajectory.derivatives(t_abs, (0,))[0, :, :3], axis=1)

    def h_true(traj):
        d = traj.derivatives(t_abs, (0, 1, 2))
        return np.array([_off_axis_cosine(d[0, i, :3], d[0, i, 3], d[2, i, :3] + drag * d[1, i, :3],
                                          target.point, cam, scale=dist0[i]) for i in range(t_abs.size)])

    c0 = ref.qp.c_hat
    h0 = h_true(ref.trajectory)
    np.testing.assert_allclose(rows.matrix @ c0 - rows.upper, h0, atol=1e-9)
    # the trust region (9) in a bounds a + d v: centred on it at the reference
    d1 = ref.trajectory.derivatives(t_abs, (1, 2))
    box = next(b for b in lin.blocks if b.name == "fov trust region (9) a")
    np.testing.assert_allclose(box.matrix @ c0, (d1[1, :, :3] + drag * d1[0, :, :3]).reshape(-1), atol=1e-9)
    np.testing.assert_allclose(0.5 * (box.lower + box.upper), box.matrix @ c0, atol=1e-9)
    d = ref.trajectory.derivatives(t_abs, (0, 2))
    drag_free = np.array([_off_axis_cosine(d[0, i, :3], d[0, i, 3], d[1, i, :3], target.point, cam)
                          for i in range(t_abs.size)])
    assert np.max(np.abs(drag_free - h0)) > 1e-3  # the drag moves the camera: the test can tell
    # the same points and a0 = a + d v, but a basis without d b1 (the rows of a drag-free model)
    from avp.qp.fov import fov_blocks

    dd = ref.trajectory.derivatives(state.time + lin.times, (0, 1, 2))
    wrong = fov_blocks(qp.layout, qp.knots_rel, lin.times, dd[0, :, :3], dd[0, :, 3],
                       dd[2, :, :3] + drag * dd[1, :, :3], target.point, cfg.fov, cfg.g).blocks[0]
    rng = np.random.default_rng(int(100 * drag))
    dc = rng.normal(size=c0.size)
    dc *= np.linalg.norm(c0) / np.linalg.norm(dc)

    def errors(block):
        out = []
        for eps in (2e-3, 1e-3, 5e-4):
            c = c0 + eps * dc
            out.append(np.max(np.abs(block.matrix @ c - block.upper - h_true(qp.trajectory(c, cfg.g)))))
        return out

    right, bad = errors(rows), errors(wrong)
    assert right[1] / right[2] > 3.0 and right[0] / right[1] > 3.0  # second order: halving eps quarters it
    assert bad[2] > 10 * right[2] and bad[1] / bad[2] < 2.5  # first order without d b1


def test_visibility_with_drag_uses_the_drag_aware_attitude():
    """visibility(..., rotor_drag=d) counts the samples whose thrust a + g e3 + d v's attitude
    sees the pad (dense sampling against Camera.sees), and differs from the drag-free score on a
    plan that runs the pad near the edge of the cone."""
    from avp.metrics import visibility, visibility_many

    state = avp.State.hover([0.0, 0.0, 1.0])
    target = avp.PerchTarget.from_incline([6.0, 0.0, 1.0], math.pi / 2)
    tr = avp.plan(state, target, avp.PlannerConfig(fov=avp.FovConfig(enabled=False)))
    cam = avp.Camera()
    for drag in (0.0, 0.3, 0.6):
        v = visibility(tr, target, cam, dt=1e-3, rotor_drag=drag)
        t = tr.sample(1e-3)
        d = tr.derivatives(t, (0, 1, 2))
        R = avp.frames.attitude(d[2, :, :3] + drag * d[1, :, :3], d[0, :, 3])
        seen = cam.sees(d[0, :, :3], R, target.point).astype(float)
        w = 0.5 * (seen[1:] + seen[:-1])
        want = float(np.sum(w * np.diff(t)) / (t[-1] - t[0]))
        chords = np.linalg.norm(np.diff(d[0, :, :3], axis=0), axis=1)
        assert v.time_fraction == pytest.approx(want, abs=1e-9)
        assert v.path_fraction == pytest.approx(float(w @ chords / chords.sum()), abs=1e-9)
        lost = np.flatnonzero(seen[:-1] < 0.5)
        assert v.first_loss == (None if lost.size == 0 else pytest.approx(float(t[lost[0]])))
    assert visibility(tr, target, cam, rotor_drag=0.6).time_fraction != visibility(tr, target, cam).time_fraction
    # several plans in one pass (the SQP's score) equal one at a time
    other = avp.plan(state, avp.PerchTarget.from_incline([6.0, 0.5, 1.2], math.pi / 2),
                     avp.PlannerConfig(fov=avp.FovConfig(enabled=False)))
    other = avp.Trajectory(other.coefficients, tr.knots) if other.n_segments == tr.n_segments else tr
    many = visibility_many((tr, other), target, cam, dt=1e-2, rotor_drag=0.4)
    assert many == [visibility(x, target, cam, dt=1e-2, rotor_drag=0.4) for x in (tr, other)]
    with pytest.raises(ConfigError, match="rotor_drag"):
        visibility(tr, target, cam, rotor_drag=-0.1)


def test_a_bool_is_not_a_drag():
    with pytest.raises(ConfigError, match="limits.rotor_drag"):
        avp.VehicleLimits(rotor_drag=True)
    from avp.metrics import visibility

    target = avp.PerchTarget.from_incline([4.0, 0.0, 1.5], math.pi / 2)
    tr = avp.plan(avp.State.hover([0.0, 0.0, 1.5]), target, avp.PlannerConfig(fov=avp.FovConfig(enabled=False)))
    with pytest.raises(ConfigError, match="limits.rotor_drag"):
        visibility(tr, target, rotor_drag=True)


# -- the line perch (avp.plan_line) with drag ----------------------------------------------------


def _line(pitch_deg: float, speed: float = 0.0) -> avp.LineTarget:
    c, half = np.array([3.0, 0.0, 3.0]), np.array([0.0, 1.5, 0.0])
    return avp.LineTarget.segment(c - half, c + half, pitch=math.radians(pitch_deg), contact_speed=speed)


def _line_config(drag: float) -> avp.PlannerConfig:
    limits = avp.VehicleLimits(mass=0.8, thrust_min=0.5, thrust_max=4 * 0.8 * 9.81, rotor_drag=drag)
    return avp.PlannerConfig(limits=limits, workspace=avp.Workspace(ground_z=0.5))


@settings(max_examples=10, deadline=None)
@given(st.sampled_from([0.0, 30.0, 60.0, 80.0, 120.0]), st.sampled_from([0.0, 0.4]), st.floats(0.1, 0.6),
       st.floats(-0.4, 0.4))
def test_line_contact_thrust_and_rest_rates_with_drag(pitch_deg, speed, drag, dz):
    """With drag d the thrust f = a + g e3 + d v of a line perch is along n at contact, within
    the contact thrust range, and at rest: f' = j + d a = 0 (no body rotation, no thrust rate),
    so the jerk itself is -d a (it was 0 before drag was modelled: the vehicle arrived turning at
    0.2-0.6 rad/s with d = 0.3). Read off the spline, not the QP rows."""
    from avp.line_planner import LineOptions, _thrust_range

    line, cfg = _line(pitch_deg, speed), _line_config(drag)
    start = np.array([1.0, 0.3, 3.0 + dz - (1.2 if pitch_deg > 90.0 else 0.0)])
    res = avp.plan_line(avp.State.hover(start), line, cfg, LineOptions(recovery=False))
    tr = res.perch
    assert tr is not None, res.log
    n = res.contact.n
    a, v, j = tr(tr.tf, 2), tr(tr.tf, 1), tr(tr.tf, 3)
    f = a + np.array([0.0, 0.0, cfg.g]) + drag * v
    assert _angle(f, n) < 1e-6
    lo, hi = _thrust_range(res.contact, cfg, LineOptions())
    assert lo - 1e-6 <= float(f @ n) <= hi + 1e-6
    assert np.linalg.norm(j + drag * a) < 1e-6 * max(1.0, float(np.linalg.norm(a)))
    # the unit thrust axis does not turn at contact: a one-sided difference of f/|f| is O(h)
    h = 1e-4
    f_before = tr(tr.tf - h, 2) + np.array([0.0, 0.0, cfg.g]) + drag * tr(tr.tf - h, 1)
    turn = np.linalg.norm(f / np.linalg.norm(f) - f_before / np.linalg.norm(f_before)) / h
    assert turn < 1e-2


def test_line_flip_rows_bound_the_drag_aware_thrust():
    """Upside down (pitch 120 deg) the flip rows hold on f = a + g e3 + d v at their samples:
    up before the window, across inside it (at least flip_thrust), along n after it."""
    from avp.line_planner import LineOptions, _guide_times

    drag, opts = 0.4, LineOptions(recovery=False)
    cfg = _line_config(drag)
    res = avp.plan_line(avp.State.hover([1.0, 0.3, 1.8]), _line(120.0), cfg, opts)
    tr = res.perch
    assert tr is not None, res.log
    tf = tr.duration
    t = _guide_times(tf, opts.guide_dt / 2.0, include_end=True)
    t1, t2 = tf - opts.flip_window[0], tf - opts.flip_window[1]
    f = tr(tr.t0 + t, 2) + np.array([0.0, 0.0, cfg.g]) + drag * tr(tr.t0 + t, 1)
    c = res.contact
    for sel, direction in ((t <= t1, np.array([0.0, 0.0, 1.0])), ((t >= t1) & (t <= t2), c.w), (t >= t2, c.n)):
        assert sel.any()
        assert np.all(f[sel] @ direction >= opts.flip_thrust - 1e-6)


@pytest.mark.parametrize("search", [True, False])
def test_line_recovery_with_drag_continues_the_perch(search):
    """The perch run backwards is no recovery with drag (it ends with jerk -d a, which the
    reverse flips): the QP recovery, continuous up to snap with the perch, is used instead, at
    its allocated time first. Without a duration search (bounds.certify off) that one recovery
    is all there is: here its bounds fail, and the result says so (it has a recovery, and it is
    not SOLVED)."""
    drag = 0.3
    cfg = _line_config(drag)
    if not search:
        cfg = dataclasses.replace(cfg, bounds=dataclasses.replace(cfg.bounds, certify=False))
    res = avp.plan_line(avp.State.hover([1.0, 0.3, 1.8]), _line(120.0), cfg)
    assert any("not with rotor drag" in line for line in res.log)
    assert any(line.startswith("recovery x1 ") for line in res.log)  # the QP recovery at its allocated time
    if not search:
        assert res.recovery is not None and res.status is avp.LineStatus.NOT_CERTIFIED
        assert res.recovery_bounds is not None and not res.recovery_bounds.certified
        return
    assert res.ok, res.log
    p, r = res.perch, res.recovery
    end, begin = p.derivatives(p.tf), r.derivatives(r.t0)
    assert np.all(np.abs(end - begin) / np.maximum(1.0, np.abs(end)) < 1e-6)
    assert np.linalg.norm(end[3, :3] + drag * end[2, :3]) < 1e-6 * max(1.0, float(np.linalg.norm(end[2, :3])))


@settings(max_examples=200, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), drag=st.floats(0.01, 1.0), degree=st.integers(1, 9))
def test_the_drag_thrust_spline_is_the_thrust_with_drag(seed, drag, degree):
    """``q = p + d int p``: ``q''`` and ``q'''`` are ``a + d v`` and ``j + d a`` of ``p``, checked in
    exact rational arithmetic on the coefficients (three roundings per coefficient of ``q``:
    ``d / k``, the product and the sum, so within 2 eps of the terms' magnitudes)."""
    from fractions import Fraction

    from avp.bounds import drag_thrust_spline

    rng = np.random.default_rng(seed)
    c = rng.normal(size=(2, 4, degree + 1)) * 10.0 ** rng.uniform(-2, 2, size=(2, 4, degree + 1))
    q = drag_thrust_spline(c, drag)
    assert q.shape == (2, 4, degree + 2)
    np.testing.assert_array_equal(q[:, 3, : degree + 1], c[:, 3])  # yaw as is
    d = Fraction(drag)
    for s in range(2):
        for ax in range(3):
            p = [Fraction(x) for x in c[s, ax]]
            terms = [((p[k] if k <= degree else 0), (d * p[k - 1] / k if k else 0)) for k in range(degree + 2)]
            for k, (got, (own, drag_term)) in enumerate(zip(q[s, ax], terms, strict=True)):
                err = abs(Fraction(got) - own - drag_term)
                assert err <= (abs(own) + abs(drag_term)) * Fraction(2.0**-51), (s, ax, k)


def test_a_solved_plan_keeps_the_limits_on_the_thrust_the_rotors_make():
    """An overhang with rotor drag ``d = 0.3 /s``: the certificate bounds the thrust
    ``a + g e3 + d v`` and its turn (``j + d a``), sampled densely here. With the limits
    certified on the drag-free ``a + g e3`` this plan said SOLVED and turned at 1.057 x the
    tilt-rate limit (found by an independent audit, and by a search over 150 such perches)."""
    limits = avp.VehicleLimits(tilt_rate_max=6.348282557827985, rotor_drag=0.3)
    target = avp.PerchTarget.from_incline([1.828458037016572, 0.0, 2.5], math.radians(122.7753264445449))
    res = avp.plan_detailed(avp.State.hover([0.0, 0.0, 2.0]), target, avp.PlannerConfig(limits=limits))
    assert res.trajectory is not None
    traj = res.trajectory
    t = np.linspace(traj.t0, traj.tf, 20001)
    D = traj.derivatives(t, (1, 2, 3))
    f = D[1][:, :3] + 0.3 * D[0][:, :3] + [0.0, 0.0, traj.g]
    f_dot = D[2][:, :3] + 0.3 * D[1][:, :3]
    norm = np.linalg.norm(f, axis=1)
    tilt_rate = np.linalg.norm(np.cross(f, f_dot), axis=1) / norm**2
    if res.ok:
        assert tilt_rate.max() <= limits.tilt_rate_max * (1 + 1e-9)
        assert limits.accel_min * (1 - 1e-9) <= norm.min() and norm.max() <= limits.accel_max * (1 + 1e-9)
    else:  # not certified: then it is not SOLVED either
        assert res.status is not avp.PlanStatus.SOLVED


def test_reports_of_a_plan_with_drag_use_the_thrust_the_certificate_bounds():
    """The failure message and the trajectory's flatness read-offs with ``rotor_drag`` measure
    ``a + g e3 + d v`` (before: the drag-free thrust, so a plan whose tilt rate was proven over
    the limit was reported under it, and the CLI printed b3 16 deg off s3 on a SOLVED plan)."""
    limits = avp.VehicleLimits(tilt_rate_max=3.5, rotor_drag=0.6)
    cfg = avp.PlannerConfig(limits=limits, bounds=avp.BoundsPolicy(relaxations=()))
    res = avp.plan_detailed(avp.State.hover([0.0, 0.0, 2.0]), avp.PerchTarget.from_incline([2.0, 0.0, 2.3], math.pi / 2), cfg)
    assert res.status is avp.PlanStatus.BOUNDS_NOT_CERTIFIED
    assert any(x.bound.value == "tilt_rate" for x in res.bounds.violations)
    line = next(x for x in res.log if "tilt rate up to" in x)
    assert float(line.split("tilt rate up to ")[1].split(" ")[0]) > limits.tilt_rate_max
    ok = avp.plan_detailed(avp.State.hover([0.0, 0.0, 1.5]), avp.PerchTarget.from_incline([3.5, 0.0, 1.5], math.pi / 2),
                           avp.PlannerConfig(limits=avp.VehicleLimits(rotor_drag=0.6)))
    traj = ok.trajectory
    b3 = traj.attitude(traj.tf, rotor_drag=0.6)[:, 2]
    assert float(b3 @ avp.PerchTarget.from_incline([3.5, 0.0, 1.5], math.pi / 2).s3) > 1 - 1e-12
    t = traj.sample(0.01)
    D = traj.derivatives(t, (1, 2))
    np.testing.assert_allclose(traj.thrust(t, rotor_drag=0.6),
                               np.linalg.norm(D[1][:, :3] + 0.6 * D[0][:, :3] + [0.0, 0.0, traj.g], axis=1), rtol=1e-14)
