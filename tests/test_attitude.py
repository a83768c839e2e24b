"""The body-rate certificate at every attitude and the contact attitude (13).

Every check compares with an independent computation of the attitude: ``oracles.attitude_zyx``
builds ``R_WB = Rz(yaw) Ry(pitch) Rx(roll)`` from Euler angles with scipy and the body rate is
its numerical derivative ``|log(R_k^T R_{k+1})| / dt`` on a 0.5 ms grid (not the kernel's
polynomial, not ``avp.frames.body_rates``).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, example, given, settings
from hypothesis import strategies as st
from oracles import attitude_zyx, body_rate_norm_numeric, roll_zyx

import avp
from avp import _avp_rust, frames
from avp.bounds import Bound, Certificate, certify_spline

G = 9.81
WITHIN = Certificate.WITHIN


def segment_max(traj: avp.Trajectory, dt: float = 5e-4) -> np.ndarray:
    """Largest sampled true ``|omega|`` per segment (oracle), each segment on its own (a
    difference across a knot would see a jump of a discontinuous test spline)."""
    c, k = traj.coefficients, traj.knots
    return np.array([body_rate_norm_numeric(avp.Trajectory(c[s:s + 1], k[s:s + 2]), dt)[1].max()
                     for s in range(traj.n_segments)])


def test_the_oracle_agrees_with_the_flatness_map_away_from_the_singularity() -> None:
    """The oracle measures what it should: on a plan with yaw motion it matches (22) + (13)."""
    state = avp.State(position=[0.0, 0.0, 1.5], velocity=[0.0, 2.0, 0.5], yaw=1.0, yaw_rate=2.0)
    traj = avp.plan(state, avp.PerchTarget.from_incline([3.5, 0.0, 1.5], math.radians(60)))
    t, w = body_rate_norm_numeric(traj)
    ref = np.linalg.norm(traj.body_rates(t), axis=1)
    assert np.max(np.abs(w - ref)) < 1e-3 * max(1.0, ref.max())
    tt = traj.sample(0.01)
    assert np.allclose(attitude_zyx(traj(tt, 2), traj.yaw(tt)), traj.attitude(tt), atol=1e-9)


# ------------------------------------------------------------------ the kernel on its own


@st.composite
def rolling_spline(draw: st.DrawFn):
    """1-2 degree-7 segments whose thrust tilts up to ~80 deg sideways and whose yaw turns at up
    to ~10 rad/s: large roll in the construction (13), the case the 45 deg assumption missed."""
    S = draw(st.integers(1, 2))
    c = np.zeros((S, 4, 8))
    small = st.floats(-1.0, 1.0)
    for s in range(S):
        tilt = draw(st.floats(0.0, 1.4))  # rad, the tilt of a + g e3 at tau = 0
        az = draw(st.floats(-8.0, 8.0))
        mag = (G + az) * math.tan(tilt) if G + az > 1.0 else 0.0
        d = draw(st.floats(-math.pi, math.pi))
        c[s, 0, 2] = 0.5 * mag * math.cos(d)
        c[s, 1, 2] = 0.5 * mag * math.sin(d)
        c[s, 2, 2] = 0.5 * az
        for ax in range(3):  # jerk and snap terms
            c[s, ax, 3] = draw(small) * 4.0
            c[s, ax, 4] = draw(small) * 4.0
        c[s, 3, 0] = draw(st.floats(-math.pi, math.pi))
        c[s, 3, 1] = draw(st.floats(-10.0, 10.0))
        c[s, 3, 2] = draw(small) * 5.0
    durs = draw(st.lists(st.sampled_from([0.2, 0.35, 0.5]), min_size=S, max_size=S))
    return c, np.concatenate([[0.0], np.cumsum(durs)])


@settings(max_examples=40, deadline=None)
@given(sk=rolling_spline(), factor=st.sampled_from([0.8, 1.0, 1.5, 2.5, 4.0, 8.0]))
def test_a_certified_body_rate_holds_on_every_segment(sk, factor) -> None:
    c, knots = sk
    traj = avp.Trajectory(c, knots)
    t = traj.sample(5e-4)
    f = traj(t, 2) + [0.0, 0.0, G]
    assume(np.linalg.norm(f, axis=1).min() > 0.5)  # the oracle needs a thrust direction
    true_max = segment_max(traj)
    limit = float(true_max.max() * factor)
    report = certify_spline(c, knots, thrust_min=0.0, thrust_max=math.inf, body_rate_max=limit)
    roll = np.abs(roll_zyx(traj(t, 2), traj.yaw(t)))
    seg = np.clip(np.searchsorted(knots, t, side="right") - 1, 0, len(knots) - 2)
    for s, verdict in enumerate(report.verdicts[Bound.BODY_RATE]):
        if verdict is WITHIN:
            assert true_max[s] < limit, (s, true_max[s], limit)
            assert roll[seg == s].max() < frames.MAX_CONTACT_ROLL  # the top certified level
        else:
            assert verdict in (Certificate.VIOLATED, Certificate.UNKNOWN)


def _planted_tilt(tilt_deg: float, yaw_rate: float) -> tuple[np.ndarray, np.ndarray]:
    """Constant thrust tilted ``tilt_deg`` towards -y (|f| = 15 m/s^2), yaw turning at
    ``yaw_rate`` around 0: the roll is about ``tilt_deg`` and ``w3 = yaw_rate / cos(roll)``."""
    fmag = 15.0
    th = math.radians(tilt_deg)
    c = np.zeros((1, 4, 8))
    c[0, 1, 2] = 0.5 * (-fmag * math.sin(th))
    c[0, 2, 2] = 0.5 * (fmag * math.cos(th) - G)
    c[0, 3, 0] = -0.1 * yaw_rate
    c[0, 3, 1] = yaw_rate
    return c, np.array([0.0, 0.2])


def test_the_45_degree_inequality_is_unsound_at_75_degrees_and_the_kernel_refuses() -> None:
    """The bug this certificate fixes: at 75 deg roll ``3|j|^2 + (4 psidot^2 - w^2)|f|^2 < 0`` holds while
    the true rate exceeds ``w``. The certificate now proves the roll level first."""
    c, knots = _planted_tilt(75.0, 1.0)
    traj = avp.Trajectory(c, knots)
    true = segment_max(traj)[0]
    limit = 2.5  # true |w| ~ 1/cos(75 deg) = 3.9 rad/s
    assert true > limit
    _lo, hi = _avp_rust.bound_polynomial(c, knots, 0, 4, limit)  # the 45-degree polynomial
    assert _avp_rust.certify_below(np.asarray(hi), 0.0, 1.0)[0] == 0  # ... is negative: unsound
    report = certify_spline(c, knots, thrust_min=1.0, thrust_max=30.0, body_rate_max=limit)
    assert report.verdicts[Bound.BODY_RATE] != (WITHIN,)
    # and a true limit well above the rate is certified at the 75.5 deg level (A, B) = (31, 32)
    report = certify_spline(c, knots, thrust_min=1.0, thrust_max=30.0, body_rate_max=6.0)
    assert report.verdicts[Bound.BODY_RATE] == (WITHIN,)


def test_a_roll_beyond_the_top_level_is_violated() -> None:
    c, knots = _planted_tilt(80.0, 0.1)
    report = certify_spline(c, knots, thrust_min=1.0, thrust_max=30.0, body_rate_max=100.0)
    assert report.verdicts[Bound.BODY_RATE] == (Certificate.VIOLATED,)


# ------------------------------------------------------------------ returned plans


@st.composite
def hard_request(draw: st.DrawFn):
    """Inclines 0-180 deg, pads with a custom up-slope (contact roll, vertical s2), starts moving
    at up to 5 m/s in any direction, any yaw, yaw rates up to 5 rad/s."""
    heading = draw(st.floats(-math.pi, math.pi))
    h = np.array([math.cos(heading), math.sin(heading), 0.0])
    distance = draw(st.floats(1.5, 6.0))
    start = np.array([0.0, 0.0, 2.0])
    pad = start + distance * h + np.array([0.0, 0.0, draw(st.floats(-1.0, 1.0))])
    incline = draw(st.floats(0.0, math.pi))
    normal = math.cos(incline) * np.array([0.0, 0.0, 1.0]) - math.sin(incline) * h
    if draw(st.booleans()):
        target = avp.PerchTarget.from_incline(pad, incline, heading)
    else:
        up = np.array(draw(st.tuples(*[st.floats(-1.0, 1.0)] * 3)))
        assume(np.linalg.norm(np.cross(up, normal)) > 0.1)
        target = avp.PerchTarget.from_normal(pad, normal, up_slope=up)
    assume((start - pad) @ target.s3 > 0.2)
    v = np.array(draw(st.tuples(*[st.floats(-1.0, 1.0)] * 3)))
    v = draw(st.floats(0.0, 5.0)) * v / max(np.linalg.norm(v), 1e-9)
    state = avp.State(position=start, velocity=v, yaw=draw(st.floats(-math.pi, math.pi)),
                      yaw_rate=draw(st.floats(-5.0, 5.0)))
    return state, target


LIMITS = avp.VehicleLimits(body_rate_max=14.0)


def _contact_roll(R_WS: np.ndarray) -> float:
    """|roll| (rad) of R_WS as ``Rz Ry Rx`` with cos(roll) >= 0: the textbook ZYX extraction
    ``tan(roll) = R[2, 1] / R[2, 2]`` (third row ``[-s_th, c_th s_phi, c_th c_phi]``); 0 at the
    gimbal lock ``|pitch| = 90 deg`` where the yaw absorbs it."""
    r21, r22 = float(R_WS[2, 1]), float(R_WS[2, 2])
    return 0.0 if math.hypot(r21, r22) < 1e-12 else math.atan2(abs(r21), abs(r22))


VERTICAL_S2 = avp.PerchTarget.from_normal([0.0, 3.5, 1.5], [0.0, -1.0, 0.0], up_slope=[1.0, 0.0, 0.0])
CEILING = avp.PerchTarget.from_incline([3.0, 0.0, 3.0], math.pi)
FAST = avp.State(position=[0.0, 0.0, 0.5], velocity=[3.0, -3.0, 2.0], yaw=2.0, yaw_rate=-5.0)


@settings(max_examples=12, deadline=None)
@given(hard_request())
@example((avp.State.hover([0.0, 0.0, 1.5]), VERTICAL_S2))
@example((avp.State.hover([0.0, 0.0, 1.5], yaw=1.0), CEILING))
@example((FAST, CEILING))
@example((FAST, avp.PerchTarget.from_incline([3.0, 0.0, 1.0], math.radians(60))))
def test_certified_plans_keep_the_true_body_rate_below_the_limit(request) -> None:
    state, target = request
    config = avp.PlannerConfig(limits=LIMITS)
    result = avp.plan_detailed(state, target, config)
    if not (result.ok and result.bounds is not None and result.bounds.certified):
        return
    traj = result.trajectory
    assert segment_max(traj).max() < LIMITS.body_rate_max
    R_f = traj.attitude(traj.tf)
    assert float(R_f[:, 2] @ target.s3) > 1.0 - 1e-9  # the thrust axis along the normal, always
    error = frames.rotation_error_angle(R_f, target.R_WS)
    if _contact_roll(target.R_WS) <= frames.MAX_CONTACT_ROLL - 1e-9:
        assert error < 1e-6
    else:  # documented fallback: the rotation about s3 is off by contact_frame_error
        assert abs(error - frames.contact_frame_error(target.R_WS)) < 1e-6


# ------------------------------------------------------------------ the contact attitude


@settings(max_examples=200, deadline=None)
@given(normal=st.tuples(*[st.floats(-1.0, 1.0)] * 3), up=st.tuples(*[st.floats(-1.0, 1.0)] * 3),
       alpha=st.floats(1.0, 15.0))
@example(normal=(0.75, 1.192092896e-07, 1.192092896e-07), up=(0.0, 1.0, 0.0), alpha=1.0)  # a nearly vertical s2
@example(normal=(1.0, 0.5, 0.0), up=(0.0, 5.960464477539063e-08, 1.0), alpha=3.0)  # an error angle near 0
def test_contact_yaw_reproduces_R_WS_or_says_why_not(normal, up, alpha) -> None:
    n, u = np.array(normal), np.array(up)
    assume(np.linalg.norm(n) > 0.1 and np.linalg.norm(np.cross(u, n)) > 0.1 * np.linalg.norm(n))
    target = avp.PerchTarget.from_normal([0.0, 0.0, 0.0], n, up_slope=u)
    roll = _contact_roll(target.R_WS)
    psi, _ = frames.contact_yaw(target.R_WS)
    a_f = alpha * target.s3 - G * np.array([0.0, 0.0, 1.0])  # (12)
    if roll > frames.MAX_CONTACT_ROLL:  # not representable: b3 = s3, b2 horizontal and closest to s2
        R = frames.attitude(a_f, psi)
        b2_des = np.array([-math.sin(psi), math.cos(psi), 0.0])  # horizontal by construction (13)
        assert np.allclose(R[:, 2], target.s3, atol=1e-9) and abs(float(R[:, 0] @ b2_des)) < 1e-9
        h = target.s2 * np.array([1.0, 1.0, 0.0])
        if np.linalg.norm(h) > 1e-6:  # b2_des is the horizontal direction of s2
            assert np.allclose(b2_des, h / np.linalg.norm(h), atol=1e-9)
        # Both sides build b1 = unit(b2_des x b3) from b3 = unit(a_f + g e3): the sum cancels g to
        # a rounding of about eps g, and the cross product divides it by |b2_des x s3|, which
        # vanishes as the roll nears 90 deg (a vertical s2). contact_frame_error uses 4 m/s^2 of
        # thrust and this test alpha, so the two agree to that forward error, not to 1e-9 flat.
        cond = float(np.linalg.norm(np.cross(b2_des, target.s3)))
        tol = 1e-9 + 8 * np.finfo(float).eps * (1.0 + G / alpha) / max(cond, 1e-300)
        assert abs(frames.contact_frame_error(target.R_WS) - frames.rotation_error_angle(R, target.R_WS)) < tol
        return
    assert np.allclose(frames.attitude(a_f, psi), target.R_WS, atol=1e-9)
    assert np.allclose(attitude_zyx(a_f[None], np.array([psi]))[0], target.R_WS, atol=1e-9)


def test_a_vertical_s2_keeps_b3_on_the_normal_and_says_how_far_the_frame_is_off() -> None:
    """A pad with a horizontal normal and a vertical s2: no atan2(0, 0), no spin; b3 = s3 at
    contact, the frame 90 deg off about s3, and the log says so."""
    target = avp.PerchTarget.from_normal([0.0, 3.5, 1.5], [0.0, -1.0, 0.0], up_slope=[1.0, 0.0, 0.0])
    result = avp.plan_detailed(avp.State.hover([0.0, 0.0, 1.5]), target)
    assert result.ok and result.bounds is not None and result.bounds.certified
    traj = result.trajectory
    R_f = traj.attitude(traj.tf)
    assert float(R_f[:, 2] @ target.s3) > 1.0 - 1e-12
    assert abs(math.degrees(frames.contact_frame_error(target.R_WS)) - 90.0) < 1e-6
    assert any("differs from R_WS by 90.00 deg" in line for line in result.log)
    ts = np.linspace(traj.t0, traj.tf, 4001)
    assert np.linalg.norm(traj.body_rates(ts), axis=-1).max() < 10.0  # no singular spin


def test_a_skewed_up_slope_ends_exactly_in_R_WS() -> None:
    """s1 and s2 both off the horizontal: the old b2_des || s2 rule missed R_WS by 19.5 deg."""
    target = avp.PerchTarget.from_normal([0.0, 3.5, 1.5], [1.0, 0.0, 1.0], up_slope=[0.0, 1.0, 1.0])
    assert abs(target.s1[2]) > 0.1 and abs(target.s2[2]) > 0.1
    traj = avp.plan(avp.State.hover([1.0, 0.0, 2.5]), target, allow_relaxed=True)
    assert frames.rotation_error_angle(traj.attitude(traj.tf), target.R_WS) < 1e-6


@pytest.mark.parametrize("heading", [0.0, 1.0, -2.5])
def test_the_ceiling_frame_is_continuous_at_180_degrees(heading) -> None:
    near = avp.PerchTarget.from_incline([3.0, 0.0, 3.0], math.radians(179.999), heading)
    at = avp.PerchTarget.from_incline([3.0, 0.0, 3.0], math.pi, heading)
    assert np.max(np.abs(near.R_WS - at.R_WS)) < 1e-4
    h = np.array([math.cos(heading), math.sin(heading), 0.0])
    assert np.allclose(at.s1, -h) and np.allclose(at.s3, [0.0, 0.0, -1.0])
    # and the plans agree: no half turn of yaw at exactly 180 deg
    state = avp.State.hover([3.0 - 2.0 * math.cos(heading), -2.0 * math.sin(heading), 1.5], yaw=heading)
    cfg = avp.PlannerConfig(bounds=avp.BoundsPolicy(certify=False))
    a = avp.plan_detailed(state, near, cfg).trajectory
    b = avp.plan_detailed(state, at, cfg).trajectory
    t = a.sample(0.01)
    assert np.max(np.abs(a.evaluate(t) - b.evaluate(t))) < 1e-3
    assert abs(b.yaw(b.tf) - heading) < 1e-6


@pytest.mark.parametrize("incline_deg", [0.0, 30.0, 90.0, 150.0, 180.0])
def test_from_incline_matches_from_normal_off_the_level_pads(incline_deg) -> None:
    inc = math.radians(incline_deg)
    a = avp.PerchTarget.from_incline([0.0, 0.0, 0.0], inc, 0.4)
    if 0.0 < incline_deg < 180.0:
        b = avp.PerchTarget.from_normal([0.0, 0.0, 0.0], a.s3)
        assert np.allclose(a.R_WS, b.R_WS, atol=1e-12)
    assert np.allclose(a.s2, [-math.sin(0.4), math.cos(0.4), 0.0])  # s2 = e3 x h, horizontal


@settings(max_examples=200, deadline=None)
@given(angle=st.floats(0.0, math.pi), axis=st.tuples(*[st.floats(-1.0, 1.0)] * 3),
       base=st.tuples(*[st.floats(-3.0, 3.0)] * 3))
def test_rotation_error_angle_is_accurate_near_zero_and_pi(angle, axis, base) -> None:
    """The angle between ``R`` and ``R exp(angle a)`` is ``angle`` to rounding, also where
    ``arccos`` of the trace loses half the digits (about 1e-8 rad near 0 and pi)."""
    a = np.array(axis)
    assume(np.linalg.norm(a) > 0.1)
    a /= np.linalg.norm(a)
    R0 = frames.expm_so3(np.array(base))
    R1 = R0 @ frames.expm_so3(angle * a)
    assert abs(float(frames.rotation_error_angle(R0, R1)) - angle) < 1e-13 + 1e-12 * angle


@settings(max_examples=40, deadline=None)
@given(normal=st.tuples(*[st.floats(-1.0, 1.0)] * 3), up=st.tuples(*[st.floats(-1.0, 1.0)] * 3),
       v_S=st.tuples(*[st.floats(-3.0, 3.0)] * 3), g=st.sampled_from([9.81, 3.71]))
def test_a_pads_cached_contact_quantities_equal_the_functions(normal, up, v_S, g) -> None:
    """The pad's frame error, world contact velocity and terminal yaw are computed once per pad
    (every QP of a plan uses them); each equals its function of ``R_WS`` bit for bit, also on a
    second call, and the cached velocity is read-only with ``R_WS^T v_W = v_S``."""
    n = np.array(normal)
    assume(np.linalg.norm(n) > 0.1)
    u = np.array(up)
    assume(np.linalg.norm(u) > 0.1 and np.linalg.norm(np.cross(n, u)) > 0.1 * np.linalg.norm(u) * np.linalg.norm(n))
    target = avp.PerchTarget.from_normal([0.0, 0.0, 1.0], n, up_slope=u)
    for _ in range(2):
        assert target._frame_error(g) == frames.contact_frame_error(target.R_WS, g)
        assert target._contact_yaw == frames.contact_yaw(target.R_WS)[0]
        v_W = target._velocity_W(v_S)
        assert v_W.tobytes() == np.linalg.solve(target.R_WS.T, np.array(v_S)).tobytes()
        assert not v_W.flags.writeable
        np.testing.assert_allclose(target.R_WS.T @ v_W, v_S, atol=1e-12)


def test_the_cached_contact_velocity_tells_minus_zero_from_zero() -> None:
    """Keyed by the exact bits of ``v_S``: a request with ``-0.0`` gets its own solve, whose
    zero's sign can differ from the one of ``0.0``."""
    target = avp.PerchTarget.from_incline([0.0, 0.0, 1.0], 1.0)
    plus, minus = (-2.0, 0.0, -0.3), (-2.0, -0.0, -0.3)
    solved = [np.linalg.solve(target.R_WS.T, np.array(v)).tobytes() for v in (plus, minus)]
    if solved[0] == solved[1]:  # plus == minus as tuples; here LAPACK keeps the zero's sign
        pytest.skip("this LAPACK build drops the sign of zero in this solve")
    for first, second in ((0, 1), (1, 0)):
        fresh = avp.PerchTarget(point=target.point, R_WS=target.R_WS)
        fresh._velocity_W((plus, minus)[first])
        assert fresh._velocity_W((plus, minus)[second]).tobytes() == solved[second]


def test_a_moving_pads_later_pose_does_not_inherit_its_cached_quantities() -> None:
    """``MovingTarget.at`` turns the pad frame with the platform's yaw rate: the pose's contact
    yaw, frame error and world velocity are its own frame's, whatever the first pose cached."""
    pad = avp.MovingTarget.on_platform([2.0, 0.0, 1.0], incline=math.radians(60.0), speed=0.5, turn_rate=0.8)
    v_S = (2.0, 0.0, -0.3)
    _ = pad.incline, pad._contact_yaw, pad._frame_error(9.81), pad._velocity_W(v_S)  # fill the caches
    later = pad.at(pad.time + 1.0)
    assert not np.allclose(later.R_WS, pad.R_WS)
    assert not {"incline", "_contact_yaw", "_frame_errors", "_velocities_W"} & set(later.__dict__)
    assert later.incline == pytest.approx(math.acos(later.R_WS[2, 2]))
    assert later._contact_yaw == frames.contact_yaw(later.R_WS)[0]
    assert later._frame_error(9.81) == frames.contact_frame_error(later.R_WS, 9.81)
    assert later._velocity_W(v_S).tobytes() == np.linalg.solve(later.R_WS.T, np.array(v_S)).tobytes()
    # and the first pose's caches are still its own
    assert pad._velocity_W(v_S).tobytes() == np.linalg.solve(pad.R_WS.T, np.array(v_S)).tobytes()
