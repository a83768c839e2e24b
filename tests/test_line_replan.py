"""Line perches in closed loop: :class:`avp.LineReplanner`, :func:`avp.sim.line_run.simulate_line`
and ``avp demo`` / ``avp simulate`` with ``--line-pitch-deg``."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import avp
from avp.cli import EXIT_FAILED, EXIT_SOLVED, EXIT_USAGE, main
from avp.config import PlannerConfig, ReplanConfig, VehicleLimits, Workspace
from avp.errors import ConfigError
from avp.line_replan import LineReplanner, line_change
from avp.replan import ReplanAction, Replanner
from avp.sim.line_run import LineDetector, LineScenario, simulate_line
from avp.sim.vehicle import VehicleParams

G = 9.81
LIM = VehicleLimits(mass=0.8, thrust_min=0.5, thrust_max=4.0 * 0.8 * G)  # Paneque et al.: T/W 4:1
LINE80 = avp.LineTarget.segment([2.5, -1.5, 4.2 - 0.26], [2.5, 1.5, 4.2 + 0.26], pitch=math.radians(80),
                                gripper_offset=0.15)
START = np.array([0.0, 0.0, 4.0])


def _vehicle() -> VehicleParams:
    return VehicleParams(limits=LIM, inertia=tuple(1.6 * np.asarray(VehicleParams().inertia, dtype=float)))


def _shifted(line: avp.LineTarget, offset: np.ndarray) -> avp.LineTarget:
    return dataclasses.replace(line, vertices=line.vertices + offset)


def test_closed_loop_line_perch_perfect_world_and_noisy_replanning() -> None:
    sc = LineScenario(LINE80, START, vehicle=_vehicle())
    # perfect detections and odometry, realistic rotors: one-shot tracking alone reaches the line
    ideal = dataclasses.replace(sc, detector=LineDetector(sigma=0.0, sigma_per_metre=0.0), odometry=None)
    one = simulate_line(ideal, "one_shot", seed=0)
    assert one.success, one.outcome
    assert one.gripper_error < 0.01 and one.estimate_error == 0.0
    # noisy world: replanning on the fused estimate succeeds on each seed
    for seed in (0, 1):
        run = simulate_line(sc, "avp", seed=seed)
        assert run.success, (seed, run.outcome)
        # independent of the criterion code: the true CoM ends within r + 3 cm of the true line and
        # never entered the clearance radius by more than 2 cm before contact
        assert LINE80.distance(run.path_p[-1]) <= LINE80.gripper_offset + 0.03
        before = run.path_t < run.final_plan.tf - 0.05
        assert min(LINE80.distance(p) for p in run.path_p[before]) >= LINE80.gripper_offset - 0.02
        # replanning did commit, and only certified plans
        committed = [s for s in run.steps if s.committed]
        assert len(committed) >= 2
        assert all(s.result is not None and s.result.ok for s in committed)


def test_line_replanner_never_raises_and_commits_only_certified_plans() -> None:
    cfg = PlannerConfig(limits=LIM)
    rp = LineReplanner(LINE80, cfg, ReplanConfig())
    first = rp.step(0.0, avp.State.hover(START), LINE80)
    assert first.action is ReplanAction.INITIAL_PLAN and rp.recovery is not None
    tf = rp.trajectory.tf
    rng = np.random.default_rng(7)
    offsets = [rng.normal(0.0, 0.03, 3) for _ in range(8)] + [np.array([0.0, 0.0, 2.0]), np.array([-2.5, 0.0, -0.2])]
    t = 0.0
    for off in offsets:
        t += 1.0 / 30.0
        before = rp.trajectory
        ref = before.flat_output(t)
        odo = avp.State(position=ref.position + rng.normal(0.0, 0.005, 3), velocity=ref.velocity,
                        acceleration=ref.acceleration, yaw=float(ref.yaw), time=t)
        estimate = _shifted(LINE80, off)  # the last one passes through the vehicle: plan_line refuses it
        step = rp.step(t, odo, estimate)  # never raises
        if step.committed:
            res = step.result
            assert res is not None and res.ok and res.bounds.certified and not res.violations
            traj = rp.trajectory
            assert traj.tf == pytest.approx(tf, abs=1e-9)  # the committed contact time is kept
            grip = traj(traj.tf) - estimate.gripper_offset * res.contact.n
            assert estimate.distance(grip) < 1e-3  # on the line it planned for
            assert rp.recovery is res.recovery
        else:
            assert rp.trajectory is before
    actions = {s.action for s in rp.history}
    assert ReplanAction.REPLANNED in actions
    # the line 2 m up and the one through the vehicle: nothing certified, the plan kept, the
    # committed grasp point metres from the estimate (CANNOT_REACH)
    assert [s.action for s in rp.history[-2:]] == [ReplanAction.CANNOT_REACH] * 2
    assert min(s.target_error for s in rp.history[-2:]) > 1.0
    assert "ConfigError" in rp.history[-1].reason  # the line through the vehicle, reported


def test_line_replanner_bad_input() -> None:
    pad = avp.PerchTarget.from_incline([2.0, 0.0, 1.5], math.pi / 2)
    with pytest.raises(ConfigError, match="LineTarget"):
        LineReplanner(pad)  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="PerchTarget"):
        Replanner(LINE80)  # type: ignore[arg-type]
    rp = LineReplanner(LINE80, PlannerConfig(limits=LIM))
    with pytest.raises(ConfigError, match="target_estimate"):
        rp.step(0.0, avp.State.hover(START), pad)  # type: ignore[arg-type]


@settings(max_examples=40, deadline=None)
@given(st.lists(st.floats(-2.0, 2.0), min_size=3, max_size=3), st.floats(0.0, 1.5))
def test_line_change_of_a_translation_and_a_rotation(u: list[float], angle: float) -> None:
    off = np.array(u)
    shift, turn = line_change(LINE80, _shifted(LINE80, off))
    assert shift == pytest.approx(float(np.linalg.norm(off)), abs=1e-12) and turn == pytest.approx(0.0, abs=1e-6)
    # a rotation by ``angle`` about z through the first vertex: the turn is the angle between the
    # directions (computed here from the vertices), the shift that of the second vertex
    c, s = math.cos(angle), math.sin(angle)
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    v0 = LINE80.vertices[0]
    rotated = dataclasses.replace(LINE80, vertices=(LINE80.vertices - v0) @ R.T + v0)
    d0, d1 = np.diff(LINE80.vertices, axis=0)[0], np.diff(rotated.vertices, axis=0)[0]
    want = math.acos(float(d0 @ d1) / float(np.linalg.norm(d0) * np.linalg.norm(d1)))
    shift_r, turn_r = line_change(LINE80, rotated)
    assert turn_r == pytest.approx(want, abs=1e-6)
    assert shift_r == pytest.approx(float(np.linalg.norm(rotated.vertices[1] - LINE80.vertices[1])), abs=1e-12)


def test_cli_demo_and_simulate_on_a_line(capsys) -> None:
    assert main(["demo", "--line-pitch-deg", "80", "--json", "--no-plot"]) == EXIT_SOLVED
    doc = json.loads(capsys.readouterr().out)
    assert doc["status"] == "SOLVED" and doc["exit_code"] == EXIT_SOLVED
    s = doc["summary"]
    assert s["gripper_error_m"] < 1e-3 and s["b3_error_deg"] < 0.5 and s["contact_speed_m_s"] < 1e-3
    assert s["recovery_s"] > 0 and all(s["certificates"].values())
    # the JSON's line and start plan the same perch in-process
    line = avp.LineTarget(vertices=np.array(doc["line"]["vertices"]), pitch=math.radians(doc["line"]["pitch_deg"]),
                          gripper_offset=doc["line"]["gripper_offset"])
    res = avp.plan_line(avp.State.hover(doc["start"]), line, PlannerConfig(workspace=Workspace(ground_z=0.0)))
    assert res.ok and res.perch.duration == pytest.approx(s["duration_s"], rel=1e-9)

    assert main(["simulate", "--line-pitch-deg", "20", "--trials", "1", "--json", "--no-plot"]) == EXIT_SOLVED
    rows = json.loads(capsys.readouterr().out)["rows"]
    assert [r["mode"] for r in rows] == ["one_shot", "avp"]
    assert rows[1]["success"] and rows[1]["gripper_error_m"] < 0.03

    assert main(["demo", "--line-pitch-deg", "200", "--no-plot"]) == EXIT_USAGE


def test_cli_line_demo_exports_and_prints_its_trajectory(tmp_path, capsys) -> None:
    """``--export`` / ``--export-rate`` write the line's perch as the pad demo writes its plan (with
    the configured rotor drag), and ``--json`` carries its coefficients (both were ignored)."""
    config = tmp_path / "drag.toml"
    config.write_text("[planner.limits]\nrotor_drag = 0.2\n")
    out = tmp_path / "perch.json"
    argv = ["demo", "--line-pitch-deg", "60", "--config", str(config), "--export", str(out), "--export-rate", "50"]
    code = main([*argv, "--json"])
    doc = json.loads(capsys.readouterr().out)
    assert code == doc["exit_code"] and doc["export"] == str(out)
    perch = avp.export.trajectory_from_dict(doc["trajectory"])
    assert perch.duration == pytest.approx(doc["summary"]["duration_s"], rel=1e-12)
    assert avp.export.trajectory_from_dict(doc["recovery_trajectory"]).duration == pytest.approx(
        doc["summary"]["recovery_s"], rel=1e-12)
    written = json.loads(out.read_text())
    assert written["coefficients"] == doc["trajectory"]["coefficients"] and written["samples_rotor_drag"] == 0.2
    table = avp.export.sample_table(perch, 50, rotor_drag=0.2)  # the drag-aware thrust of the certificates
    assert written["samples"]["thrust"] == table[:, avp.export.SAMPLE_COLUMNS.index("thrust")].tolist()


@pytest.mark.parametrize("extra, field", [
    (["--output", "line.png"], "--output"),  # avp.plotting needs a pad
    (["--incline-deg", "90"], "--incline-deg"),  # the pad's geometry, even at its default value
    (["--distance", "3.5"], "--distance"),
    (["--lateral", "0.2"], "--lateral"),
    (["--height", "1"], "--height"),
    (["--export-rate", "50"], "--export-rate"),  # without --export
])
def test_cli_line_demo_refuses_flags_it_would_ignore(extra, field, capsys) -> None:
    assert main(["demo", "--line-pitch-deg", "60", "--json", *extra]) == EXIT_USAGE
    assert json.loads(capsys.readouterr().out)["field"] == field


def test_cli_line_demo_reports_the_actuator_bounds(capsys) -> None:
    """Hanging below the line at the default thrust limit, neither the perch nor its recovery
    keeps thrust_max certified: the summary and the JSON say so (the summary said the line
    certificates hold and nothing of the bounds; the JSON had no bounds_certified)."""
    assert main(["demo", "--line-pitch-deg", "180"]) == EXIT_FAILED
    captured = capsys.readouterr()
    assert "actuator bounds : perch NOT certified (thrust_max violated), recovery NOT certified" in captured.out
    assert "thrust_max violated" in captured.err  # the warning -q keeps
    assert main(["demo", "--line-pitch-deg", "180", "--json"]) == EXIT_FAILED
    doc = json.loads(capsys.readouterr().out)
    assert doc["bounds_certified"] is False
    assert doc["bounds"]["perch"] == {"certified": False, "violated": ["thrust_max"], "undecided": []}
    assert main(["demo", "--line-pitch-deg", "60", "--json"]) == EXIT_SOLVED
    doc = json.loads(capsys.readouterr().out)
    assert doc["bounds_certified"] is True and doc["bounds"]["recovery"]["certified"] is True


def _line_distance(line: avp.LineTarget, p: np.ndarray) -> float:
    """Distance from ``p`` to the polyline, written here from the geometry (not LineTarget's)."""
    best = math.inf
    for A, B in zip(line.vertices[:-1], line.vertices[1:], strict=True):
        lam = float(np.clip((p - A) @ (B - A) / ((B - A) @ (B - A)), 0.0, 1.0))
        best = min(best, float(np.linalg.norm(p - (A + lam * (B - A)))))
    return best


def test_line_replanner_says_cannot_reach_when_the_gripper_would_miss_the_line() -> None:
    """Late in the flight an estimate 0.3 m beside the committed line cannot be reached: the step
    keeps the plan and says CANNOT_REACH, with target_error the committed grasp point's distance
    to the estimated line. The same line moved 0.3 m along itself is still grasped by the
    committed plan: whatever the step does, it is no CANNOT_REACH."""
    cfg = PlannerConfig(limits=LIM)
    rc = ReplanConfig()

    def first_plan() -> tuple[LineReplanner, avp.LinePlanResult]:
        rp = LineReplanner(LINE80, cfg, rc)
        rp.step(0.0, avp.State.hover(START), LINE80)
        assert rp.last_result is not None
        return rp, rp.last_result

    rp, _ = first_plan()
    t_late = rp.trajectory.tf - max(rc.freeze_horizon, cfg.t_k) - 0.1
    d = LINE80.vertices[1] - LINE80.vertices[0]
    d = d / np.linalg.norm(d)
    across = np.cross(d, [0.0, 0.0, 1.0])
    for offset, missed in ((0.3 * across, True), (0.3 * d, False)):
        rp, first = first_plan()
        t = t_late
        committed = rp.trajectory
        ref = committed.flat_output(t)
        odo = avp.State(position=ref.position, velocity=ref.velocity, acceleration=ref.acceleration,
                        yaw=float(ref.yaw), time=t)
        estimate = _shifted(LINE80, offset)
        step = rp.step(t, odo, estimate)
        if not step.committed:
            grasp = committed(committed.tf) - LINE80.gripper_offset * first.contact.n
            assert step.target_error == pytest.approx(_line_distance(estimate, grasp), abs=1e-6)
            assert step.target_angle == pytest.approx(0.0, abs=1e-9)  # a translated line
        if missed:
            assert step.action is ReplanAction.CANNOT_REACH and rp.cannot_reach, step.reason
            assert step.target_error == pytest.approx(0.3, abs=0.01)
            assert "from the estimate" in step.reason
        else:
            assert step.action is not ReplanAction.CANNOT_REACH, step.reason
            assert step.target_error < 0.01


@pytest.mark.parametrize("flag", [["--distance", "3"], ["--incline-deg", "45"], ["--platform-speed", "1"]])
def test_cli_line_simulate_refuses_the_pad_trials_flags(capsys, flag) -> None:
    """``avp simulate --line-pitch-deg`` flew the line whatever the pad flags said; one given
    with another value than its default is a usage error naming it."""
    assert main(["simulate", "--line-pitch-deg", "20", "--trials", "1", "--no-plot", *flag]) == EXIT_USAGE
    assert flag[0] in capsys.readouterr().err


def test_cli_line_simulate_refuses_a_scenario_table_it_does_not_read(tmp_path, capsys) -> None:
    cfg = tmp_path / "s.toml"
    cfg.write_text('[scenario]\nbackend = "rotorpy"\n')  # as --simulator rotorpy, which is refused
    assert main(["simulate", "--line-pitch-deg", "20", "--trials", "1", "--no-plot", "--config", str(cfg)]) == EXIT_USAGE
    assert "scenario.backend" in capsys.readouterr().err
    cfg.write_text("[scenario]\nincline = 0.5\n")
    assert main(["simulate", "--line-pitch-deg", "20", "--trials", "1", "--no-plot", "--config", str(cfg)]) == EXIT_USAGE
    assert "scenario.incline" in capsys.readouterr().err
    assert main(["simulate", "--line-pitch-deg", "20", "--trials", "1", "--backend", "pool"]) == EXIT_USAGE
    assert "--backend" in capsys.readouterr().err
