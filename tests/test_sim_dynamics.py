"""Rigid-body dynamics (1) of avp.sim.vehicle: equilibria, exact solutions, RK4 order, limits."""

from __future__ import annotations

import numpy as np
import pytest

from avp.config import VehicleLimits
from avp.errors import ConfigError
from avp.frames import GRAVITY, expm_so3
from avp.sim import RigidBodyState, VehicleParams, step


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
    params = VehicleParams.ideal(VehicleLimits(thrust_min=0.0))
    s0 = RigidBodyState(p_W=[0.0, 0.0, 10.0], v_W=[1.0, 0.0, 0.0])
    s = _fly_open_loop(s0, 0.0, np.zeros(3), 0.002, 1.0, params)
    np.testing.assert_allclose(s.p_W, [1.0, 0.0, 10.0 - 0.5 * GRAVITY], atol=1e-10)
    np.testing.assert_allclose(s.v_W, [1.0, 0.0, -GRAVITY], atol=1e-10)


def test_thrust_is_clipped_to_the_limits():
    limits = VehicleLimits()  # the planner's: 0.25 .. 9.81 N on 0.5 kg
    for params in (VehicleParams.ideal(limits), VehicleParams(limits=limits, motor_time_constant=0.0)):
        s0 = RigidBodyState(p_W=np.zeros(3))
        hi = step(s0, 100.0, np.zeros(3), 0.002, params)
        lo = step(s0, -5.0, np.zeros(3), 0.002, params)
        np.testing.assert_allclose(hi.v_W[2] / 0.002, limits.thrust_max / limits.mass - GRAVITY, rtol=1e-9)
        np.testing.assert_allclose(lo.v_W[2] / 0.002, limits.thrust_min / limits.mass - GRAVITY, rtol=1e-9)


def test_moment_is_clipped_per_axis():
    params = VehicleParams.ideal()
    mm = params.moment_max
    s = step(RigidBodyState(p_W=np.zeros(3)), 4.9, np.array([10.0, -0.2 * mm[1], -3.0]), 0.001, params)
    expected = np.array([mm[0], -0.2 * mm[1], -mm[2]]) / np.diag(params.J) * 0.001
    np.testing.assert_allclose(s.omega_B, expected, rtol=1e-4)  # gyroscopic term is O(dt^2)


def test_spin_about_a_principal_axis_is_exact():
    params = VehicleParams()
    w = np.array([0.0, 0.0, 5.0])
    s0 = RigidBodyState(p_W=np.zeros(3), omega_B=w)
    s = _fly_open_loop(s0, params.hover_thrust, np.zeros(3), 0.002, 1.0, params)
    np.testing.assert_allclose(s.omega_B, w, atol=1e-12)  # axis preserved
    np.testing.assert_allclose(s.R_WB, expm_so3(w * 1.0), atol=1e-9)


def _torque_free(dt):
    params = VehicleParams.ideal(VehicleLimits(thrust_min=0.0))
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
    with pytest.raises(ConfigError, match="vehicle.inertia"):
        VehicleParams(inertia=(-1.0, 1.0, 1.0))
    with pytest.raises(ConfigError, match="vehicle.motor_time_constant"):
        VehicleParams(motor_time_constant=-0.01)
    with pytest.raises(ConfigError, match="vehicle.limits"):
        VehicleParams(limits="heavy")
    with pytest.raises(ConfigError, match="state.R_WB"):
        RigidBodyState(p_W=np.zeros(3), R_WB=2 * np.eye(3))
    with pytest.raises(ConfigError, match="dt"):
        step(RigidBodyState(p_W=np.zeros(3)), 4.9, np.zeros(3), 0.0)


def test_vehicle_is_built_from_the_planners_limits():
    limits = VehicleLimits(mass=0.8, thrust_max=14.0)
    params = VehicleParams(limits=limits)
    assert params.limits is limits
    assert (params.mass, params.thrust_max) == (0.8, 14.0)
    assert params.rotor_thrust_limits == (limits.thrust_min / 4, 14.0 / 4)


@pytest.mark.parametrize("seed", range(5))
def test_mixer_reproduces_feasible_wrenches_and_respects_rotor_limits(seed):
    params = VehicleParams()
    rng = np.random.default_rng(seed)
    lo, hi = params.rotor_thrust_limits
    T = rng.uniform(lo, hi, 4)  # a feasible allocation: its wrench must come back exactly
    tau, M = params.wrench(T)
    np.testing.assert_allclose(params.mix(tau, M), T, rtol=1e-12, atol=1e-12)
    # an infeasible request: every rotor stays in its range, roll/pitch keep their sign
    big = params.mix(params.hover_thrust, np.array([5.0, -3.0, 1.0]))
    assert np.all(big >= lo - 1e-15) and np.all(big <= hi + 1e-15)
    _, M_out = params.wrench(big)
    assert M_out[0] > 0 and M_out[1] < 0


def test_motor_lag_is_first_order_with_the_documented_time_constant():
    params = VehicleParams(motor_time_constant=0.02)
    s = RigidBodyState(p_W=np.zeros(3))
    cmd = 1.5 * params.hover_thrust
    w0 = params.rotor_speed(np.array(params.hover_thrust / 4))
    w_cmd = params.rotor_speed(np.array(cmd / 4))
    for _ in range(10):  # 20 ms = one time constant
        s = step(s, cmd, np.zeros(3), 0.002, params)
    expected = w_cmd + (w0 - w_cmd) * np.exp(-1.0)
    np.testing.assert_allclose(s.rotor_speeds, expected, rtol=1e-12)
    v_instant = (cmd / params.mass - GRAVITY) * 0.02  # climb rate after 20 ms without lag
    assert 0.2 * v_instant < s.v_W[2] < 0.6 * v_instant  # e^-1 of the step still missing at the end


def test_rotor_floor_is_the_motors_idle_not_a_higher_planner_floor():
    """The planner may certify a thrust floor above the motors' idle to keep authority for
    feedback; the simulated rotors still reach down to idle. The default vehicle's floor is
    unchanged (its planner floor is below idle)."""
    default = VehicleParams()
    assert default.thrust_floor == default.thrust_min
    assert default.rotor_thrust_limits[0] == default.thrust_min / 4.0
    gao = VehicleParams(limits=VehicleLimits(mass=1.0, thrust_min=5.0, thrust_max=17.0, tilt_rate_max=3.0))
    assert gao.thrust_min == 5.0  # the planner's floor, as certified
    assert gao.thrust_floor == pytest.approx(0.05 * 17.0)
    assert gao.rotor_thrust_limits == pytest.approx((0.05 * 17.0 / 4.0, 17.0 / 4.0))
    assert gao.clip_thrust(1.0) == 1.0 and gao.clip_thrust(0.1) == pytest.approx(0.85)
    lo, hi = gao.rotor_thrust_limits
    T = gao.mix(1.0, np.zeros(3))
    assert np.all(T >= lo - 1e-12) and np.all(T <= hi + 1e-12) and np.isclose(T.sum(), 1.0)
    for bad in (-0.1, 1.0, float("nan")):
        with pytest.raises(ConfigError, match="rotor_idle_fraction"):
            VehicleParams(rotor_idle_fraction=bad)


@pytest.mark.parametrize("inertia", ["abc", [1e-3, "a", 2e-3], None, {"x": 1.0}, True, [True, True, True]])
def test_inertia_that_is_not_numbers_is_a_config_error(inertia):
    """``inertia="abc"`` was NumPy's ValueError."""
    with pytest.raises(ConfigError) as info:
        VehicleParams(inertia=inertia)
    assert info.value.field == "vehicle.inertia"
