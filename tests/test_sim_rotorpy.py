"""The rotorpy back-end of the simulator (avp.sim.backend): rotorpy's Multirotor integrates the
vehicle, avp's closed loop and feed-forward controller drive it. Tests that need rotorpy skip
without it; the ones about its absence run everywhere."""

from __future__ import annotations

import dataclasses
import math
import subprocess
import sys

import numpy as np
import pytest

from avp.errors import ConfigError
from avp.sim.backend import (
    HUMMINGBIRD_AERO,
    ROTORPY_ROTOR_DRAG,
    Backend,
    RotorpyPlant,
    plant,
    rotorpy_gains,
    rotorpy_params,
)
from avp.sim.controller import ControllerGains, FlatReference, drag_acceleration
from avp.sim.evaluate import SimConfig
from avp.sim.flight import fly
from avp.sim.run import SimScenario, simulate
from avp.sim.vehicle import RigidBodyState, VehicleParams

NO_AERO = {k: 0.0 for k in HUMMINGBIRD_AERO}


def _block_rotorpy(monkeypatch: pytest.MonkeyPatch) -> None:
    for name in ("rotorpy", "rotorpy.vehicles", "rotorpy.vehicles.multirotor"):
        monkeypatch.setitem(sys.modules, name, None)  # import rotorpy... raises ImportError


# -- without rotorpy -------------------------------------------------------------------------

def test_missing_rotorpy_is_a_typed_config_error(monkeypatch: pytest.MonkeyPatch) -> None:
    _block_rotorpy(monkeypatch)
    with pytest.raises(ConfigError) as exc:
        SimScenario(backend="rotorpy")
    assert exc.value.field == "scenario.backend" and 'pip install "avp[rotorpy]"' in str(exc.value)
    with pytest.raises(ConfigError, match=r'pip install "avp\[rotorpy\]"'):
        plant(Backend.ROTORPY, VehicleParams())


def test_cli_without_rotorpy_exits_with_usage_error(monkeypatch: pytest.MonkeyPatch,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    from avp.cli import EXIT_USAGE, main

    _block_rotorpy(monkeypatch)
    code = main(["simulate", "--backend", "rotorpy", "--trials", "1", "--no-plot", "--json"])
    assert code == EXIT_USAGE
    out = capsys.readouterr().out
    assert '"field": "--simulator"' in out and "avp[rotorpy]" in out


def test_default_backend_runs_without_rotorpy(monkeypatch: pytest.MonkeyPatch) -> None:
    _block_rotorpy(monkeypatch)
    sc = SimScenario(incline=math.radians(45.0), distance=3.5).without_noise()
    assert sc.backend is Backend.AVP
    r = simulate(sc, "one_shot", seed=0)
    assert r.success, r.outcome


def test_the_simulator_does_not_import_rotorpy() -> None:
    code = ("import sys, avp.sim.run, avp.sim.evaluate, avp.cli; "
            "print(sorted(k for k in sys.modules if k.split('.')[0] == 'rotorpy'))")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True)
    assert proc.stdout.strip() == "[]"


def test_backend_names_are_checked() -> None:
    assert Backend.parse("RotorPy") is Backend.ROTORPY and Backend.parse("avp") is Backend.AVP
    with pytest.raises(ConfigError) as exc:
        SimScenario(backend="gazebo")
    assert exc.value.field == "scenario.backend"
    with pytest.raises(ConfigError) as exc2:
        SimConfig(backend="gazebo")
    assert exc2.value.field == "sim.backend"


def test_cli_backend_and_simulator_must_agree(capsys: pytest.CaptureFixture[str]) -> None:
    from avp.cli import EXIT_USAGE, main

    assert main(["simulate", "--backend", "rotorpy", "--simulator", "avp", "--trials", "1", "--no-plot"]) == EXIT_USAGE


# -- with rotorpy ----------------------------------------------------------------------------

@pytest.fixture(scope="module")
def rotorpy() -> object:
    return pytest.importorskip("rotorpy.vehicles.multirotor")


def test_rotorpy_vehicle_is_the_planner_vehicle(rotorpy: object) -> None:
    """Mass, inertia and collective thrust limits are the planner's; rotorpy's own allocation
    matrix, built from the derived rotor positions and spins, is avp's mixer's."""
    veh = VehicleParams()
    p = RotorpyPlant(veh)
    mr = p.multirotor
    assert mr.mass == veh.limits.mass
    np.testing.assert_allclose(mr.inertia, veh.J)
    assert 4 * mr.k_eta * mr.rotor_speed_max**2 == pytest.approx(veh.limits.thrust_max, rel=1e-12)
    assert 4 * mr.k_eta * mr.rotor_speed_min**2 == pytest.approx(veh.limits.thrust_min, rel=1e-12)
    np.testing.assert_allclose(mr.f_to_TM, veh.allocation, atol=1e-15)
    assert mr.tau_m == veh.motor_time_constant
    with pytest.raises(ConfigError) as exc:
        rotorpy_params(VehicleParams(g=9.80665))
    assert exc.value.field == "scenario.vehicle.g"


def _agile(t: float) -> FlatReference:
    """A smooth reference with large tilt and body rates (lateral sine, 1 Hz)."""
    w = 2 * math.pi
    a = 1.5
    return FlatReference([a * math.sin(w * t), 0.3 * t, 0.2 * math.sin(w * t)],
                         [a * w * math.cos(w * t), 0.3, 0.2 * w * math.cos(w * t)],
                         [-a * w**2 * math.sin(w * t), 0.0, -0.2 * w**2 * math.sin(w * t)],
                         [-a * w**3 * math.cos(w * t), 0.0, -0.2 * w**3 * math.cos(w * t)],
                         [a * w**4 * math.sin(w * t), 0.0, 0.2 * w**4 * math.sin(w * t)], 0.3 * t, 0.3, 0.0)


@pytest.mark.parametrize(("lag", "tol"), [(0.0, 1e-5), (0.02, 2e-4)])
def test_rotorpy_without_aero_reproduces_avp_model(rotorpy: object, lag: float, tol: float) -> None:
    """Two integrators written independently (avp's RK4 on R, rotorpy's RK45 on a quaternion),
    the same vehicle, mixer and motor lag, no drag: the same 0.4 s, 3 m agile flight to 10 um
    with instant rotors; to 0.2 mm with the 20 ms lag, which avp discretises (the thrust of the
    mid-step rotor speeds held over the step) and rotorpy integrates with the state."""
    veh = VehicleParams(motor_time_constant=lag)
    start = RigidBodyState(_agile(0.0).position, _agile(0.0).velocity)
    a = fly(start, _agile, 0.0, 0.4, veh, record=True)
    b = fly(start, _agile, 0.0, 0.4, veh, record=True, plant=RotorpyPlant(veh, aero=NO_AERO))
    assert a.trace is not None and b.trace is not None
    assert np.max(np.linalg.norm(a.trace.omega_B, axis=1)) > 5.0  # the attitude loop is exercised
    assert np.max(np.abs(a.trace.p_W - b.trace.p_W)) < tol
    assert np.max(np.abs(a.trace.R_WB - b.trace.R_WB)) < 10 * tol


def _climb(t: float, c: float = 20.0) -> FlatReference:
    """Straight up from hover with constant jerk ``c`` (m/s^3): the thrust ramps at ``m c``."""
    return FlatReference([0.0, 0.0, c * t**3 / 6], [0.0, 0.0, c * t**2 / 2], [0.0, 0.0, c * t], [0.0, 0.0, c],
                         [0.0, 0.0, 0.0], 0.0, 0.0, 0.0)


def test_thrust_lead_cancels_rotorpy_motor_lag(rotorpy: object) -> None:
    """rotorpy integrates its own first-order rotor-speed lag (20 ms). Led by ``tau_m m j . b3``
    (``ControllerGains.lag_feedforward``), the thrust its rotors deliver on a 20 m/s^3 thrust
    ramp is the reference's to 0.005 N and the vehicle stays within 1 mm; without the lead the
    ramp leaves it 5+ mm behind (the feedback alone makes up the thrust only with an error)."""
    veh = VehicleParams()
    assert veh.motor_time_constant == 0.02
    out = {}
    for lead in (True, False):
        res = fly(RigidBodyState(np.zeros(3), np.zeros(3)), _climb, 0.0, 0.3, veh,
                  ControllerGains(lag_feedforward=lead), plant=RotorpyPlant(veh, aero=NO_AERO))
        assert res.state.rotor_speeds is not None
        thrust = veh.thrust_coefficient * float(np.sum(res.state.rotor_speeds**2))
        ref = _climb(res.t)
        out[lead] = (thrust - veh.mass * (veh.g + ref.acceleration[2]), res.state.p_W[2] - ref.position[2])
    assert abs(out[True][0]) < 0.005 and abs(out[True][1]) < 1e-3
    assert out[False][1] < -5e-3


def test_hover_recovers_and_holds_in_rotorpy(rotorpy: object) -> None:
    veh = VehicleParams()
    ref = FlatReference.hover([0.0, 0.0, 1.5])
    R0 = np.array([[math.cos(0.3), 0.0, math.sin(0.3)], [0.0, 1.0, 0.0], [-math.sin(0.3), 0.0, math.cos(0.3)]])
    start = RigidBodyState([0.1, -0.05, 1.4], [0.2, 0.0, 0.0], R0, [0.0, 1.0, 0.0])
    res = fly(start, lambda t: ref, 0.0, 2.0, veh, record=True, plant=plant("rotorpy", veh))
    assert res.trace is not None
    late = res.trace.t > 1.5
    assert np.max(np.linalg.norm(res.trace.p_W[late] - ref.position, axis=1)) < 5e-3
    R = res.state.R_WB
    assert R[2, 2] > math.cos(math.radians(0.5))  # level
    assert abs(math.atan2(R[1, 0], R[0, 0])) < 1e-2  # heading kept


def test_drag_feedforward_cancels_rotorpy_rotor_drag(rotorpy: object) -> None:
    """drag_acceleration against rotorpy's own wrench: at hover rotor speeds, no rotation, the
    force rotorpy's rotor drag puts on the body is -m times the feed-forward."""
    veh = VehicleParams()
    aero = {**NO_AERO, "k_d": HUMMINGBIRD_AERO["k_d"], "k_z": HUMMINGBIRD_AERO["k_z"]}
    mr = RotorpyPlant(veh, aero=aero).multirotor
    c, s = math.cos(0.7), math.sin(0.7)
    R = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    v_W = np.array([3.0, -1.0, 0.5])
    w_hover = math.sqrt(veh.hover_thrust / 4 / veh.thrust_coefficient)
    F_B, _ = mr.compute_body_wrench(np.zeros(3), np.full(4, w_hover), R.T @ v_W)
    drag_B = F_B - np.array([0.0, 0.0, veh.hover_thrust])
    ff = drag_acceleration(R, v_W, FlatReference.hover(np.zeros(3)), veh, ROTORPY_ROTOR_DRAG)
    np.testing.assert_allclose(drag_B, -veh.mass * (R.T @ ff), rtol=1e-9, atol=1e-12)


def test_perfect_estimate_perch_in_rotorpy(rotorpy: object) -> None:
    """A seeded perfect-estimate perch on a 45 deg slope flown by rotorpy's vehicle (drag on)
    with avp's feed-forward controller meets the success criterion with the drag fed forward;
    without it rotor drag leaves the vehicle short of the pad plane at the contact time."""
    sc = SimScenario(incline=math.radians(45.0), distance=4.5, backend="rotorpy").without_noise()
    fed = simulate(sc, "one_shot", seed=0)  # gains.rotor_drag None: rotorpy's drag fed forward
    assert fed.success, fed.outcome
    assert fed.scenario.gains == rotorpy_gains()
    assert fed.vehicle is not None and fed.first_plan is not None
    assert fed.vehicle.limits is fed.scenario.vehicle.limits  # the vehicle rotorpy flew is the certified one
    bare = simulate(dataclasses.replace(sc, gains=ControllerGains(rotor_drag=(0.0, 0.0, 0.0))), "one_shot", seed=0)
    assert bare.perch is not None and fed.perch is not None
    assert bare.perch.error_S[2] > 0.02 > abs(fed.perch.error_S[2])  # on the free side of the plane


@pytest.mark.parametrize(("argv", "execution"), [
    (["simulate", "--backend", "rotorpy"], "serial"),
    (["campaign", "--backend", "rotorpy"], "auto"),
    (["simulate", "--simulator", "rotorpy", "--backend", "pool"], "pool"),
])
def test_cli_selects_rotorpy_with_drag_feedforward(rotorpy: object, argv: list[str], execution: str) -> None:
    from avp.cli import _simulator_settings, build_parser
    from avp.configfile import load_settings

    args = build_parser().parse_args(argv)
    sc = load_settings(None, {}, _simulator_settings(args)).scenario()
    assert args.backend == execution and args.simulator == "rotorpy"
    assert sc.backend is Backend.ROTORPY and sc.gains.rotor_drag is None  # simulate() fills in rotorpy's drag


@pytest.mark.parametrize("backend", ["avp", "rotorpy"])
def test_perfect_estimate_avp_matches_one_shot_on_each_backend(backend: str) -> None:
    """SimConfig's perfect-estimate point on a wall: both modes perch and AVP is not worse."""
    if backend == "rotorpy":
        pytest.importorskip("rotorpy.vehicles.multirotor")
    sc = dataclasses.replace(SimConfig(), backend=backend).perfect_estimate().scenario(90.0, 4.5)
    assert sc.backend is Backend.parse(backend)
    one, avp_ = (simulate(sc, mode, seed=1) for mode in ("one_shot", "avp"))
    assert one.success and avp_.success, (one.outcome, avp_.outcome)
    assert one.perch is not None and avp_.perch is not None
    assert np.linalg.norm(avp_.perch.error_S) <= np.linalg.norm(one.perch.error_S) + 1e-3


def test_drag_aware_contact_condition_on_rotorpys_wall(rotorpy: object) -> None:
    """A perfect-estimate perch on a wall flown by rotorpy (rotor drag fed forward): the default
    planner knows the drag at the contact thrust (limits.rotor_drag) and plans the thrust, not
    the acceleration, along the normal. Judged by rotorpy's attitude at the contact time: 0.7 deg
    (seed 0), where the drag-free plan of the same perch arrives 9 deg tilted by the drag on the
    2 m/s slide, 1 deg inside the 10 deg criterion, so any estimate error tips it over."""
    from avp.sim.run import sim_config

    sc = SimScenario(incline=math.pi / 2, distance=4.5, backend="rotorpy").without_noise()
    aware = simulate(sc, "one_shot", seed=0)
    limits = aware.scenario.vehicle.limits
    assert 0.2 < limits.rotor_drag < 0.4 and aware.vehicle is not None and aware.vehicle.limits is limits
    own = sim_config(limits=sc.vehicle.limits, camera=sc.camera.camera, ground_z=0.3)
    free = simulate(sc, "one_shot", seed=0, config=own, plan_drag=False)
    assert free.scenario.vehicle.limits.rotor_drag == 0.0
    # a configuration of the user's that sets no drag gets the back-end's, as simulate's own
    given = simulate(sc, "one_shot", seed=0, config=own, max_time=0.05)
    assert given.scenario.vehicle.limits.rotor_drag == limits.rotor_drag
    assert aware.perch is not None and free.perch is not None
    att_aware, att_free = (math.degrees(r.perch.attitude_error) for r in (aware, free))
    assert att_aware < 4.0 and att_free > att_aware + 4.0, (att_aware, att_free)


def test_campaign_runner_gives_the_planner_rotorpys_drag_unless_configured(rotorpy: object) -> None:
    """``avp simulate|campaign --backend rotorpy`` build their planner configuration from the TOML
    data: the runner still hands the planner the drag it flies (limits.rotor_drag), unless
    ``[planner.limits] rotor_drag`` is set, which is kept (0 for an ablation)."""
    from avp import campaign

    trial = campaign.grid([90.0], [4.5], [0.0], [None], ["one_shot"], [0])[0]
    _, aware = campaign.Runner({"scenario": {"backend": "rotorpy"}}, keep_result=True)(trial)
    assert 0.2 < aware.scenario.vehicle.limits.rotor_drag < 0.4
    data = {"scenario": {"backend": "rotorpy"}, "planner": {"limits": {"rotor_drag": 0.0}}}
    _, ablated = campaign.Runner(data, keep_result=True)(trial)
    assert ablated.scenario.vehicle.limits.rotor_drag == 0.0
