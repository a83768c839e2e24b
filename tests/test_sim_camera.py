"""Camera of avp.sim.camera: FoV cone (7), 10 Hz frames, distance-dependent noise (Fig. 9)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import avp
from avp.frames import expm_so3, rotation_error_angle
from avp.sim import CameraParams, CameraSensor, OdometryNoise, RigidBodyState, noisy_odometry

WALL = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]]).T  # s1=e3, s2=e2, s3=-e1
ORIGIN = RigidBodyState(np.zeros(3))  # level, b1 = e1: the front camera looks along +x


def at_angle(deg, dist=3.0):
    a = np.deg2rad(deg)
    return np.array([np.cos(a), np.sin(a), 0.0]) * dist


def test_sees_in_front_not_behind_and_not_outside_the_cone():
    cam = CameraSensor()
    assert cam.visible(ORIGIN, at_angle(0), WALL)
    assert cam.visible(ORIGIN, at_angle(30), WALL)
    assert not cam.visible(ORIGIN, at_angle(40), WALL)
    assert not cam.visible(ORIGIN, at_angle(180), WALL)
    assert not cam.visible(ORIGIN, at_angle(0, dist=12.0), WALL)  # beyond max_range
    # the sensor's test is the planner's avp.Camera.sees (one FoV test), vectorised
    pts = np.array([at_angle(0), at_angle(180), at_angle(34)])
    np.testing.assert_array_equal(cam.params.camera.sees(np.zeros(3), np.eye(3), pts), [True, False, True])


def test_camera_turns_with_the_body_and_mounting():
    pitched_down = RigidBodyState(np.zeros(3), R_WB=expm_so3(np.array([0.0, np.pi / 2, 0.0])))
    below = np.array([0.0, 0.0, -2.0])
    assert CameraSensor().visible(pitched_down, below, WALL)  # b1 points down after +90 deg pitch
    assert not CameraSensor().visible(ORIGIN, below, WALL)
    down_cam = CameraParams(camera=avp.Camera(R_BC=np.diag([1.0, -1.0, -1.0]), range=10.0))  # optical axis along -b3
    assert CameraSensor(down_cam).visible(ORIGIN, below, WALL)


def test_incidence_limit_hides_a_pad_seen_from_behind():
    cam = CameraSensor(CameraParams(max_incidence=np.deg2rad(80)))
    assert cam.visible(ORIGIN, at_angle(0), WALL)  # s3 = -e1 faces the camera
    assert not cam.visible(ORIGIN, at_angle(0), WALL @ np.diag([-1.0, 1.0, -1.0]))


def test_frames_arrive_at_10_hz_only_while_visible():
    cam, rng = CameraSensor(), np.random.default_rng(0)
    meas = [cam.measure(k * 0.002, ORIGIN, at_angle(0), WALL, rng) for k in range(1000)]
    times = [m.t for m in meas if m is not None]
    assert len(times) == 20
    np.testing.assert_allclose(np.diff(times), 0.1, atol=1e-9)
    cam.reset()
    assert all(cam.measure(k * 0.002, ORIGIN, at_angle(90), WALL, rng) is None for k in range(1000))


def _errors(dist, n=1500, seed=1):
    cam, rng = CameraSensor(), np.random.default_rng(seed)
    target = at_angle(10, dist)
    pos, ang = [], []
    for k in range(n):
        m = cam.measure(0.1 * k, ORIGIN, target, WALL, rng)
        pos.append(m.p_W - target)
        ang.append(rotation_error_angle(m.R_WS, WALL))
    return np.array(pos), np.array(ang), cam.params


@pytest.mark.parametrize("dist", [1.5, 7.5])
def test_noise_matches_the_documented_model(dist):
    pos, ang, cp = _errors(dist)
    np.testing.assert_allclose(pos.std(axis=0), cp.sigma_position(dist), rtol=0.1)
    # a rotation vector with iid N(0, s^2) axes has E|delta| = s sqrt(8/pi)
    assert ang.mean() == pytest.approx(cp.sigma_angle(dist) * np.sqrt(8 / np.pi), rel=0.1)


def test_noise_grows_with_distance_like_fig_9():
    near, ang_near, _ = _errors(1.5)
    far, ang_far, _ = _errors(7.5)
    e_near, e_far = np.linalg.norm(near, axis=1).mean(), np.linalg.norm(far, axis=1).mean()
    assert 0.02 < e_near < 0.06  # a few cm at 1-2 m
    assert 0.2 < e_far < 0.6  # tens of cm at 7-8 m
    assert ang_far.mean() > 5 * ang_near.mean()


def test_measurement_uses_the_believed_vehicle_pose():
    cam = CameraSensor(CameraParams(sigma0_pos=0.0, sigma0_ang=0.0))
    believed = RigidBodyState(np.array([0.1, -0.2, 0.05]))
    m = cam.measure(0.0, ORIGIN, at_angle(0), WALL, np.random.default_rng(0), believed=believed)
    np.testing.assert_allclose(m.p_W, at_angle(0) + believed.p_W, atol=1e-12)
    np.testing.assert_allclose(m.R_WS, WALL, atol=1e-12)
    assert m.distance == pytest.approx(3.0)


def test_measurements_are_deterministic_per_seed():
    def run(seed):
        rng, cam = np.random.default_rng(seed), CameraSensor()
        odo = noisy_odometry(ORIGIN, OdometryNoise(), rng)
        return cam.measure(0.0, ORIGIN, at_angle(5), WALL, rng, believed=odo).p_W

    np.testing.assert_array_equal(run(3), run(3))
    assert not np.array_equal(run(3), run(4))


@settings(max_examples=60, deadline=None)
@given(st.floats(-1.5, 1.5), st.floats(-1.2, 1.2), st.floats(-0.4, 0.4))
def test_an_uptilted_front_camera_sees_what_the_level_one_sees_from_a_pitched_up_body(uptilt, pitch, yaw):
    """``Camera.front(uptilt)`` on a body ``R_WB`` is the level front camera on that body pitched
    nose up by ``uptilt`` (a rotation about ``b2`` by ``-uptilt``, independent of our mount's
    matrix algebra: checked through ``sees`` on random points), and its optical axis is
    ``cos(uptilt) b1 + sin(uptilt) b3``."""
    from avp.frames import expm_so3

    up, level = avp.Camera.front(uptilt), avp.Camera.front()
    np.testing.assert_allclose(up.axis_B, [np.cos(uptilt), 0.0, np.sin(uptilt)], atol=1e-15)
    R_WB = expm_so3(np.array([0.0, pitch, 0.0])) @ expm_so3(np.array([0.0, 0.0, yaw]))
    R_nose_up = R_WB @ expm_so3(np.array([0.0, -uptilt, 0.0]))
    pts = np.random.default_rng(0).normal(size=(400, 3)) * 3.0
    x = np.zeros(3)
    np.testing.assert_allclose(up.R_WC(R_WB), level.R_WC(R_nose_up), atol=1e-14)
    assert np.array_equal(up.sees(x, R_WB, pts), level.sees(x, R_nose_up, pts))


def test_camera_front_validation_and_default() -> None:
    assert avp.Camera.front() == avp.Camera()  # no tilt: the paper's front camera
    cam = avp.Camera.front(0.2, half_fov=0.5, range=10.0)
    assert (cam.half_fov, cam.range) == (0.5, 10.0)
    for bad in (float("nan"), 1.6, -2.0, "0.1", True):
        with pytest.raises(avp.ConfigError, match="camera.uptilt"):
            avp.Camera.front(bad)


def test_camera_front_refuses_its_own_mounting_and_unknown_settings() -> None:
    """``front`` sets ``R_BC`` itself: passing one is a ConfigError (not Python's "multiple values"
    TypeError), as is a keyword that is no Camera setting (not listing ``R_BC`` as one to use)."""
    with pytest.raises(avp.ConfigError, match=r"^camera.R_BC: is set by Camera.front"):
        avp.Camera.front(R_BC=np.eye(3))
    with pytest.raises(avp.ConfigError, match=r"^camera.half_angle: is not a Camera setting") as info:
        avp.Camera.front(0.1, half_angle=0.5)
    assert "'R_BC'" not in str(info.value) and "'half_fov'" in str(info.value)
    with pytest.raises(avp.ConfigError, match=r"^camera.range: "):
        avp.Camera.front(range="far")


def test_the_realistic_vehicles_camera_is_tilted_up_and_shared_with_the_planner() -> None:
    from avp.sim.evaluate import SimConfig
    from avp.sim.run import _shared

    sc = SimConfig().scenario(90.0, 4.5)
    cam = sc.camera.camera
    assert np.isclose(np.degrees(np.arcsin(cam.axis_B[2])), SimConfig().camera_uptilt_deg)
    assert _shared(sc, None)[1].fov.camera is cam  # one camera: the planner's rows see this mount
    from avp.sim import CameraParams

    # the tilt is the only change to the sensor's default camera (cone, range, image kept)
    assert SimConfig(camera_uptilt_deg=0.0).scenario(90.0, 4.5).camera.camera == CameraParams().camera
    for bad in (float("inf"), 75.0, "10", True):
        with pytest.raises(avp.ConfigError, match="sim.camera_uptilt_deg"):
            SimConfig(camera_uptilt_deg=bad)
