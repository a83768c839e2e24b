"""The simulator's pieces wired as a closed-loop runner will wire them: seeded determinism."""

from __future__ import annotations

import numpy as np

from avp.sim import (
    CameraSensor,
    FlatReference,
    OdometryNoise,
    RigidBodyState,
    TargetEstimator,
    fly,
    noisy_odometry,
)

WALL = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]]).T
TARGET = np.array([4.0, 0.0, 1.0])


def run(seed):
    rng = np.random.default_rng(seed)
    cam, est, odo = CameraSensor(), TargetEstimator(), OdometryNoise()

    def approach(t):  # 1 m/s towards the wall
        z = np.zeros(3)
        return FlatReference([t, 0.0, 1.0], [1.0, 0.0, 0.0], z, z, z)

    state, t = RigidBodyState(np.array([0.0, 0.0, 1.0]), v_W=[1.0, 0.0, 0.0]), 0.0
    for _ in range(10):  # one camera frame per stretch
        m = cam.measure(t, state, TARGET, WALL, rng, believed=noisy_odometry(state, odo, rng))
        if m is not None:
            est.update(m)
        res = fly(state, approach, t, 0.1, odometry=odo, rng=rng)
        state, t = res.state, res.t
    return state, est.estimate()


def test_same_seed_same_run_other_seed_other_run():
    (s1, e1), (s2, e2), (_, e3) = run(11), run(11), run(12)
    np.testing.assert_array_equal(s1.p_W, s2.p_W)
    np.testing.assert_array_equal(e1.p_W, e2.p_W)
    np.testing.assert_array_equal(e1.R_WS, e2.R_WS)
    assert not np.array_equal(e1.p_W, e3.p_W)
    assert e1.n_measurements == 10
    assert np.linalg.norm(e1.p_W - TARGET) < 0.3
    assert abs(s1.p_W[0] - 1.0) < 0.05  # followed the approach reference
