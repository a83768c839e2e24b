"""Target estimator of avp.sim.estimator: inverse-variance fusion of camera detections."""

from __future__ import annotations

import numpy as np

from avp.frames import rotation_error_angle
from avp.sim import CameraParams, CameraSensor, RigidBodyState, TargetEstimator

WALL = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]]).T
TARGET = np.array([8.0, 0.0, 1.0])


def observe(estimator, cam, rng, x, n):
    """``n`` detections (one per frame) from a level vehicle at ``(x, 0, 1)``."""
    state = RigidBodyState(np.array([x, 0.0, 1.0]))
    t0 = 0.0 if estimator.n_measurements == 0 else estimator.estimate().t_last + 0.1
    for k in range(n):
        m = cam.measure(t0 + 0.1 * k, state, TARGET, WALL, rng)
        estimator.update(m)


def test_no_estimate_before_the_first_measurement():
    assert TargetEstimator().estimate() is None


def test_noise_free_measurements_give_the_exact_pose():
    est = TargetEstimator()
    exact = CameraSensor(CameraParams(sigma0_pos=1e-12, sigma0_ang=1e-12))
    observe(est, exact, np.random.default_rng(0), 2.0, 3)
    e = est.estimate()
    np.testing.assert_allclose(e.p_W, TARGET, atol=1e-9)
    np.testing.assert_allclose(e.R_WS, WALL, atol=1e-9)
    assert e.n_measurements == 3


def test_error_shrinks_with_more_close_measurements():
    rng = np.random.default_rng(42)
    far, close, ang_far, ang_close, sig_far, sig_close = [], [], [], [], [], []
    for _ in range(300):
        est, cam = TargetEstimator(), CameraSensor()
        observe(est, cam, rng, 2.0, 1)  # one detection from 6 m
        e = est.estimate()
        far.append(e.p_W - TARGET)
        ang_far.append(rotation_error_angle(e.R_WS, WALL))
        sig_far.append(e.sigma_pos)
        observe(est, cam, rng, 6.5, 10)  # ten more from 1.5 m
        e = est.estimate()
        close.append(e.p_W - TARGET)
        ang_close.append(rotation_error_angle(e.R_WS, WALL))
        sig_close.append(e.sigma_pos)
        assert abs(np.linalg.det(e.R_WS) - 1) < 1e-12
    far, close = np.array(far), np.array(close)
    assert np.linalg.norm(close, axis=1).mean() < 0.2 * np.linalg.norm(far, axis=1).mean()
    assert np.mean(ang_close) < 0.2 * np.mean(ang_far)
    # the reported std is calibrated against the empirical per-axis spread
    np.testing.assert_allclose(close.std(axis=0), sig_close[0], rtol=0.15)
    np.testing.assert_allclose(far.std(axis=0), sig_far[0], rtol=0.15)
