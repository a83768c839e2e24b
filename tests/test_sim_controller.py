"""Geometric controller (2) of avp.sim.controller with the flatness feed-forward (22)."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.polynomial import polynomial as P

from avp import frames
from avp.errors import ConfigError
from avp.frames import expm_so3
from avp.sim import (
    ControllerGains,
    FlatReference,
    OdometryNoise,
    RigidBodyState,
    VehicleParams,
    angular_acceleration,
    control,
    fly,
)

T_MOVE = 2.0
P0 = np.array([0.0, 0.0, 1.0])
DISPLACEMENT = np.array([3.0, 1.0, 0.5])  # peak |a| ~ 6 m/s^2: ~34 deg of pitch/roll
YAW_END = 0.6
# 7th-order rest-to-rest profile on [0, 1]: zero velocity, acceleration and jerk at both ends.
_PROFILE = [np.array([0, 0, 0, 0, 35, -84, 70, -20.0])]
for _ in range(5):
    _PROFILE.append(P.polyder(_PROFILE[-1]))


def _profile(t, k):
    tau = min(max(t / T_MOVE, 0.0), 1.0)
    if k > 0 and not 0.0 < t < T_MOVE:
        return 0.0
    return P.polyval(tau, _PROFILE[k]) / T_MOVE**k


def move(t):
    """The 2 s rest-to-rest move with yaw, as a flat-output reference (held after the end)."""
    v = [_profile(t, k) for k in range(5)]
    return FlatReference(
        P0 + DISPLACEMENT * v[0], DISPLACEMENT * v[1], DISPLACEMENT * v[2], DISPLACEMENT * v[3],
        DISPLACEMENT * v[4], YAW_END * v[0], YAW_END * v[1], YAW_END * v[2],
    )


def tracking_errors(feedforward, params=None):
    """Controller alone: an ideal vehicle (instant thrust and moments) unless ``params``."""
    gains = ControllerGains(feedforward=feedforward)
    params = params if params is not None else VehicleParams.ideal()
    res = fly(RigidBodyState(P0), move, 0.0, 2.5, params, gains=gains, record=True)
    tr = res.trace
    refs = [move(t) for t in tr.t]
    p_ref = np.array([r.position for r in refs])
    acc, yaw = np.array([r.acceleration for r in refs]), np.array([r.yaw for r in refs])
    R_ref = frames.attitude(acc, yaw)
    pos = np.linalg.norm(tr.p_W - p_ref, axis=1).max()
    att = np.rad2deg(frames.rotation_error_angle(tr.R_WB, R_ref)).max()
    return pos, att, tr


def test_feedforward_matches_the_derivatives_of_the_reference_attitude():
    h = 1e-5
    for t in (0.3, 0.9, 1.6):
        W, dW = angular_acceleration(move(t), frames.GRAVITY)
        R = lambda r: frames.attitude(r.acceleration, r.yaw)
        Rdot = (R(move(t + h)) - R(move(t - h))) / (2 * h)
        Wfd = R(move(t)).T @ Rdot
        np.testing.assert_allclose(W, [Wfd[2, 1], Wfd[0, 2], Wfd[1, 0]], atol=1e-6)
        Wp, _ = angular_acceleration(move(t + h), frames.GRAVITY)
        Wm, _ = angular_acceleration(move(t - h), frames.GRAVITY)
        np.testing.assert_allclose(dW, (Wp - Wm) / (2 * h), atol=1e-4)
        assert np.linalg.norm(dW) > 0.5  # a non-trivial manoeuvre


def test_tracking_with_feedforward_is_accurate_and_without_it_is_not():
    pos_ff, att_ff, tr = tracking_errors(True)
    pos_no, att_no, _ = tracking_errors(False)
    params = VehicleParams.ideal()
    assert tr.thrust.max() < params.thrust_max and np.all(np.abs(tr.moment_B) < params.moment_max)
    assert np.rad2deg(np.arccos(tr.R_WB_des[:, 2, 2])).max() > 25  # a real pitch manoeuvre
    assert pos_ff < 2e-3 and att_ff < 0.2, (pos_ff, att_ff)  # measured 0.18 mm, 0.034 deg
    assert pos_no > 10 * pos_ff and att_no > 2.0, (pos_no, att_no)  # measured 62 mm, 8.3 deg


def test_motor_lag_degrades_tracking_but_feedforward_still_helps():
    _, att_ideal, _ = tracking_errors(True)
    pos_lag, att_lag, _ = tracking_errors(True, VehicleParams(motor_time_constant=0.02))
    pos_lag_no, att_lag_no, _ = tracking_errors(False, VehicleParams(motor_time_constant=0.02))
    assert att_lag > 3 * att_ideal  # 20 ms of lag is visible (measured 0.6 vs 0.034 deg)
    assert att_lag_no > 3 * att_lag and pos_lag_no > 5 * pos_lag


def test_hover_recovers_from_an_offset_and_a_tilt():
    s0 = RigidBodyState(P0 + [0.3, -0.2, 0.1], R_WB=expm_so3(np.deg2rad([15.0, -10.0, 30.0])))
    res = fly(s0, lambda t: FlatReference.hover(P0, yaw=0.2), 0.0, 3.0)
    assert np.linalg.norm(res.state.p_W - P0) < 1e-3
    R_des = frames.attitude(np.zeros(3), 0.2)
    assert frames.rotation_error_angle(res.state.R_WB, R_des) < np.deg2rad(0.1)


def test_thrust_limits_are_respected():
    params = VehicleParams()
    up = FlatReference(P0, np.zeros(3), [0.0, 0.0, 50.0], np.zeros(3), np.zeros(3))
    down = FlatReference(P0, np.zeros(3), [0.0, 0.0, -30.0], np.zeros(3), np.zeros(3))
    s = RigidBodyState(P0)
    assert control(s, up, params).thrust == pytest.approx(params.thrust_max)
    assert control(s, down, params).thrust == pytest.approx(params.thrust_min)


def test_free_fall_reference_is_handled_without_nan():
    ref = FlatReference(P0, np.zeros(3), [0.0, 0.0, -frames.GRAVITY], np.zeros(3), np.zeros(3))
    out = control(RigidBodyState(P0), ref, VehicleParams())
    assert np.all(np.isfinite(out.moment_B)) and np.isfinite(out.thrust)


def test_flight_with_odometry_noise_is_deterministic_per_seed():
    def run(seed):
        res = fly(RigidBodyState(P0), move, 0.0, 0.5, odometry=OdometryNoise(),
                  rng=np.random.default_rng(seed))
        return res.state.p_W

    np.testing.assert_array_equal(run(7), run(7))
    assert not np.array_equal(run(7), run(8))


def _perch_reference():
    """A 1 s 7th-order move onto a 90 deg wall at x = 1.5 m ending with ``a = 4 s3 - g e3``,
    0.3 m/s into the pad and 2 m/s down the slope (the design's contact condition)."""
    T = 1.0
    ends = [(1.5, 0.3, -4.0, 0.0), (0.0, 0.0, 0.0, 0.0), (0.0, -2.0, -frames.GRAVITY, 0.0)]
    rows = []
    for t in (0.0, T):
        for k in range(4):
            rows.append([np.prod(range(n - k + 1, n + 1)) * t ** (n - k) if n >= k else 0.0
                         for n in range(8)])
    coef = [np.linalg.solve(np.array(rows), np.r_[0, 0, 0, 0, e]) for e in ends]
    derivs = [[P.polyder(c, k) if k else c for k in range(5)] for c in coef]

    def ref(t):
        t = min(t, T)
        v = [np.array([P.polyval(t, d[k]) for d in derivs]) for k in range(5)]
        return FlatReference(*v)

    return ref


def test_a_wall_perch_is_flown_to_millimetres_only_with_feedforward():
    from avp.sim import PerchPad, detect_contact

    R_WS = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]]).T  # s3 = -e1
    pad = PerchPad([1.5, 0.0, 0.0], R_WS)

    def contact(feedforward):
        res = fly(RigidBodyState(np.zeros(3)), _perch_reference(), 0.0, 1.2, VehicleParams.ideal(),
                  gains=ControllerGains(feedforward=feedforward),
                  stop=lambda a, b, ta, tb: detect_contact(a, b, pad, ta, tb))
        return res.event

    c = contact(True)  # measured: 1.8 mm, 0.06 deg, 0.294 m/s into the pad
    assert c.success and np.linalg.norm(c.p_S) < 5e-3 and np.rad2deg(c.attitude_error) < 0.3
    assert c.normal_speed == pytest.approx(0.3, abs=0.02)
    np.testing.assert_allclose(c.v_tangential_S, [-2.0, 0.0], atol=0.05)
    c = contact(False)  # measured: 24 cm off, 12 deg, 1.65 m/s: a failed perch
    assert not c.success and np.rad2deg(c.attitude_error) > 5


@pytest.mark.parametrize("kwargs,field", [
    ({"k_x": -5.0}, "gains.k_x"), ({"k_x": "abc"}, "gains.k_x"), ({"k_v": [1.0, 2.0]}, "gains.k_v"),
    ({"k_R": [1.0, 0.0, 1.0]}, "gains.k_R"), ({"rotor_drag": [0.1]}, "gains.rotor_drag"),
    ({"rotor_drag": (-1e-3, -1e-3, 0.0)}, "gains.rotor_drag"), ({"k_omega": True}, "gains.k_omega"),
])
def test_bad_gains_are_typed_errors(kwargs, field) -> None:
    """Gains were taken as given: a negative one flew, a string crashed mid-run."""
    with pytest.raises(ConfigError) as exc:
        ControllerGains(**kwargs)
    assert exc.value.field == field


def test_gains_from_a_file_accept_none_and_diagonals(tmp_path) -> None:
    """``rotor_drag = "none"`` is None (the file's way to write it; it stayed a string and
    crashed the controller), and a diagonal gain comes back as a tuple."""
    from avp.configfile import load_settings

    path = tmp_path / "g.toml"
    path.write_text('[scenario.gains]\nrotor_drag = "none"\nk_v = [8.0, 8.0, 10.0]\n')
    gains = load_settings(path).scenario().gains
    assert gains.rotor_drag is None and gains.k_v == (8.0, 8.0, 10.0)
