"""Rigid-body dynamics (1) of avp.sim.vehicle: equilibria, exact solutions, RK4 order, limits."""

from __future__ import annotations

import numpy as np
import pytest

from avp.errors import ConfigError
from avp.frames import GRAVITY
from avp.sim import RigidBodyState, VehicleParams, step
from avp.sim._so3 import expm_so3


def _fly_open_loop(state, thrust, moment, dt, duration, params):
    for _ in range(int(round(duration / dt))):
        state = step(state, thrust, moment, dt, params)
    return state


def test_hover_is_an_equilibrium():
    params = VehicleParams()
    s0 = RigidBodyState(p_W=[1.0, -2.0, 3.0], R_WB=expm_so3(np.array([0, 0, 0.7])))
    s = _fly_open_loop(s0, params.hover_thrust, np.zeros(3), 0.002, 2.0, params)
    np.testing.assert_allclose(s.p_W, s0.p_W, atol=1e-12)
    np.testing.assert_allclose(s.v_W, 0.0, atol=1e-12)
    np.testing.assert_allclose(s.R_WB, s0.R_WB, atol=1e-12)
    np.testing.assert_allclose(s.omega_B, 0.0, atol=1e-12)


def test_free_fall_matches_g():
    params = VehicleParams(thrust_min=0.0)
    s0 = RigidBodyState(p_W=[0.0, 0.0, 10.0], v_W=[1.0, 0.0, 0.0])
    s = _fly_open_loop(s0, 0.0, np.zeros(3), 0.002, 1.0, params)
    np.testing.assert_allclose(s.p_W, [1.0, 0.0, 10.0 - 0.5 * GRAVITY], atol=1e-10)
    np.testing.assert_allclose(s.v_W, [1.0, 0.0, -GRAVITY], atol=1e-10)


def test_thrust_is_clipped_to_the_limits():
    params = VehicleParams()  # 0.25 .. 8.5 N on 0.5 kg
    s0 = RigidBodyState(p_W=np.zeros(3))
    hi = step(s0, 100.0, np.zeros(3), 0.002, params)
    lo = step(s0, -5.0, np.zeros(3), 0.002, params)
    np.testing.assert_allclose(hi.v_W[2] / 0.002, 8.5 / 0.5 - GRAVITY, rtol=1e-9)
    np.testing.assert_allclose(lo.v_W[2] / 0.002, 0.25 / 0.5 - GRAVITY, rtol=1e-9)


def test_moment_is_clipped_per_axis():
    params = VehicleParams(moment_max=(0.5, 0.5, 0.1))
    s = step(RigidBodyState(p_W=np.zeros(3)), 4.9, np.array([10.0, -0.2, -3.0]), 0.001, params)
    expected = np.array([0.5, -0.2, -0.1]) / np.diag(params.J) * 0.001
    np.testing.assert_allclose(s.omega_B, expected, rtol=1e-4)  # gyroscopic term is O(dt^2)


def test_spin_about_a_principal_axis_is_exact():
    params = VehicleParams()
    w = np.array([0.0, 0.0, 5.0])
    s0 = RigidBodyState(p_W=np.zeros(3), omega_B=w)
    s = _fly_open_loop(s0, params.hover_thrust, np.zeros(3), 0.002, 1.0, params)
    np.testing.assert_allclose(s.omega_B, w, atol=1e-12)  # axis preserved
    np.testing.assert_allclose(s.R_WB, expm_so3(w * 1.0), atol=1e-9)


def _torque_free(dt):
    params = VehicleParams(thrust_min=0.0)
    s0 = RigidBodyState(p_W=np.zeros(3), omega_B=[4.0, 0.3, 2.0])  # not a principal axis
    return _fly_open_loop(s0, 0.0, np.zeros(3), dt, 1.0, params), params, s0


def test_rk4_is_fourth_order_and_conserves_energy_and_momentum():
    ref, params, s0 = _torque_free(0.002 / 16)
    errors = []
    for dt in (0.008, 0.004, 0.002):
        s, _, _ = _torque_free(dt)
        errors.append(np.linalg.norm(s.R_WB - ref.R_WB) + np.linalg.norm(s.omega_B - ref.omega_B))
    orders = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert np.all((orders > 3.6) & (orders < 4.4)), orders
    J = params.J
    s, _, _ = _torque_free(0.002)
    energy = lambda x: 0.5 * x.omega_B @ J @ x.omega_B
    momentum = lambda x: x.R_WB @ J @ x.omega_B
    assert abs(energy(s) - energy(s0)) < 1e-8 * energy(s0)
    np.testing.assert_allclose(momentum(s), momentum(s0), atol=1e-9)
    np.testing.assert_allclose(s.R_WB.T @ s.R_WB, np.eye(3), atol=1e-13)
    assert np.linalg.det(s.R_WB) == pytest.approx(1.0, abs=1e-13)


def test_bad_inputs_raise_config_error():
    with pytest.raises(ConfigError, match="params.mass"):
        VehicleParams(mass=-1.0)
    with pytest.raises(ConfigError, match="params.thrust_min"):
        VehicleParams(thrust_min=9.0, thrust_max=8.0)
    with pytest.raises(ConfigError, match="state.R_WB"):
        RigidBodyState(p_W=np.zeros(3), R_WB=2 * np.eye(3))
    with pytest.raises(ConfigError, match="dt"):
        step(RigidBodyState(p_W=np.zeros(3)), 4.9, np.zeros(3), 0.0)
