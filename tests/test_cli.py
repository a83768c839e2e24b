"""The command line: ``avp demo`` / ``simulate`` / ``campaign``, config files, JSON, exit codes."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

import avp
from avp.cli import (
    EXIT_FAILED,
    EXIT_RELAXED,
    EXIT_SOLVED,
    EXIT_USAGE,
    _ground_default,
    build_parser,
    demo_geometry,
    main,
    plan_exit_code,
    without_paper_notes,
)
from avp.configfile import load_settings

ROOT = Path(__file__).resolve().parent.parent


def test_demo_prints_summary_and_writes_png(tmp_path: Path, capsys) -> None:
    out = tmp_path / "demo.png"
    assert main(["demo", "--output", str(out)]) == EXIT_SOLVED
    text = capsys.readouterr().out
    for key in ("duration", "contact position", "attitude error", "contact velocity", "peak thrust", "solve time"):
        assert key in text
    assert out.stat().st_size > 10_000 and out.read_bytes()[:4] == b"\x89PNG"


def test_demo_flags_and_module_entry_point(tmp_path: Path) -> None:
    out = tmp_path / "floor.png"
    proc = subprocess.run(
        [sys.executable, "-m", "avp", "demo", "--incline-deg", "30", "--distance", "1.5",
         "--lateral", "0.3", "--solver", "proxqp", "--output", str(out)],
        capture_output=True, text=True, timeout=120, cwd=tmp_path,
    )
    assert proc.returncode == 0, proc.stderr
    assert "30 deg pad" in proc.stdout and out.exists()


def test_demo_bad_solver_is_a_clean_error(capsys) -> None:
    assert main(["demo", "--solver", "nope", "--no-plot"]) == EXIT_USAGE
    assert "not a qpsolvers back-end" in capsys.readouterr().err


def test_import_and_module_entry_from_the_clone_root() -> None:
    """After the README's editable install, the checkout's ``avp/`` is the installed package (it
    holds the compiled module), so running from the clone root works."""
    proc = subprocess.run([sys.executable, "-c", "import avp, avp._avp_rust; print(avp.__file__)"],
                          capture_output=True, text=True, timeout=60, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr
    assert Path(proc.stdout.strip()).resolve().parent == ROOT / "avp"


def test_version_flag(capsys) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0
    assert capsys.readouterr().out.strip() == f"avp {avp.__version__}"


def test_help_shows_defaults(capsys) -> None:
    with pytest.raises(SystemExit):
        main(["demo", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "(default: 3.5)" in text and "(default: perch_demo.png)" in text
    assert "along s2, m (default: 0.0)" in text  # a zero default is still shown
    assert f"default {avp.VehicleLimits().mass}" in text  # flags that default to the config say its value


# -- config file -> plan -> JSON round trip ---------------------------------------------------

CONFIG = """
[planner]
solver = "proxqp"
pre_impact = "cone"
[planner.limits]
mass = 0.6
thrust_max = 12.0
tilt_rate_max = 12.0
[planner.contact_velocity]
slope = "none"
[planner.fov]
n_points = 6
[planner.fov.camera]
half_fov = 0.6
[planner.bounds]
relaxations = ["free_slide"]
[replan]
latency = 0.03
"""


def test_config_file_sets_nested_knobs_and_flags_win(tmp_path: Path) -> None:
    path = tmp_path / "c.toml"
    path.write_text(CONFIG)
    s = load_settings(path, {"planner": {"limits": {"mass": 0.7}}})
    cfg = s.planner
    assert cfg.solver == "proxqp" and cfg.pre_impact is avp.PreImpactMode.CONE
    assert cfg.limits.mass == 0.7 and cfg.limits.thrust_max == 12.0 and cfg.limits.tilt_rate_max == 12.0
    assert cfg.contact_velocity.slope is None and cfg.contact_velocity.normal == avp.ContactVelocity().normal
    assert cfg.fov.n_points == 6 and cfg.fov.camera.half_fov == 0.6
    assert cfg.bounds.relaxations == (avp.Relaxation.FREE_SLIDE,)
    assert s.replan.latency == 0.03 and s.replan.freeze_horizon == avp.ReplanConfig().freeze_horizon


def test_config_file_to_plan_to_json_round_trip(tmp_path: Path, capsys) -> None:
    path = tmp_path / "c.toml"
    path.write_text(CONFIG)
    code = main(["demo", "--config", str(path), "--json", "--no-plot", "--mass", "0.55", "--distance", "3"])
    doc = json.loads(capsys.readouterr().out, parse_constant=lambda c: pytest.fail(f"non-JSON constant {c}"))
    assert code == doc["exit_code"] == EXIT_SOLVED and doc["status"] == "SOLVED"
    assert doc["config"]["planner"]["limits"]["mass"] == 0.55
    assert doc["config"]["planner"]["solver"] == "proxqp"
    assert doc["config"]["planner"]["limits"]["body_rate_max"] == "inf"  # strict JSON
    # the same plan in-process from the same file matches the JSON's trajectory (an iterative
    # back-end does not repeat itself to the last bit between calls, hence the tolerance)
    settings = load_settings(path, {"planner": {"limits": {"mass": 0.55}}},
                             defaults=_ground_default(avp.PlannerConfig))
    # the configuration echoed in the JSON builds the same configuration again
    from avp.configfile import from_mapping

    assert from_mapping(avp.PlannerConfig, doc["config"]["planner"], "planner") == settings.planner
    state, target, _ = demo_geometry(90.0, 3.0, 0.0, None)
    want = avp.plan_detailed(state, target, settings.planner).trajectory
    got = avp.Trajectory.from_json(json.dumps(doc["trajectory"]))
    assert np.allclose(got.coefficients, want.coefficients, rtol=1e-6, atol=1e-9)
    assert np.allclose(got.knots, want.knots, rtol=1e-9)
    assert doc["summary"]["contact_position_error_m"] < 1e-6


def test_the_line_table_sets_line_options(tmp_path: Path) -> None:
    from avp.line_planner import LineOptions

    path = tmp_path / "line.toml"
    path.write_text("[line]\nrecovery = false\nwedge_angle = 0.6\nflip_window = [0.6, 0.2]\n"
                    "recovery_point = [1.0, 2.0, 3.5]\n")
    opts = load_settings(path).line
    assert isinstance(opts, LineOptions)
    assert opts.recovery is False and opts.wedge_angle == 0.6 and opts.flip_window == (0.6, 0.2)
    np.testing.assert_array_equal(opts.recovery_point, [1.0, 2.0, 3.5])
    assert opts.guide_dt == LineOptions().guide_dt  # untouched knobs keep their defaults
    assert load_settings(None).line == LineOptions()


def test_avp_demo_on_a_line_flies_the_line_table(tmp_path: Path, capsys) -> None:
    """The [line] table reaches the line planner: without a recovery the JSON has none."""
    path = tmp_path / "line.toml"
    path.write_text("[line]\nrecovery = false\n")
    code = main(["demo", "--line-pitch-deg", "60", "--config", str(path), "--json", "--no-plot"])
    doc = json.loads(capsys.readouterr().out, parse_constant=lambda c: pytest.fail(f"non-JSON constant {c}"))
    assert code == EXIT_SOLVED and doc["summary"]["recovery_s"] is None
    from avp.configfile import from_mapping
    from avp.line_planner import LineOptions

    assert from_mapping(LineOptions, doc["config"]["line"], "line") == LineOptions(recovery=False)  # the options used
    main(["demo", "--line-pitch-deg", "60", "--json", "--no-plot"])
    assert json.loads(capsys.readouterr().out)["summary"]["recovery_s"] > 0.0


@pytest.mark.parametrize(("text", "field"), [
    ("[planner]\nnot_a_knob = 1\n", "planner.not_a_knob"),
    ("[planner.limits]\nmass = \"heavy\"\n", "planner.limits.mass"),
    ("[planner]\nn_segments = 2.5\n", "planner.n_segments"),
    ("[planner.fov]\nenabled = 1\n", "planner.fov.enabled"),
    ("[planner]\nn_segments = true\n", "planner.n_segments"),
    ("[planner]\npre_impact = \"sideways\"\n", "planner.pre_impact"),
    ("[planner.limits]\nmass = -1.0\n", "planner.limits.mass"),
    ("[plannr]\nsolver = \"daqp\"\n", "plannr"),
    ("[path]\nsolver = \"daqp\"\n", "path"),  # a table, not the file: not reported on --config
    ("[line]\nwedge = 0.6\n", "line.wedge"),
    ("[line]\nrecovery_point = [1.0, \"a\", 3.0]\n", "line.recovery_point"),
    ("[line]\nrecovery_point = [1.0, 2.0]\n", "line.recovery_point"),
    ("[line]\nwedge_angle = 4.0\n", "line.wedge_angle"),
    ("[line]\nflip_window = [0.1, 0.3]\n", "line.flip_window"),
])
def test_config_errors_name_the_key(tmp_path: Path, text: str, field: str, capsys) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(avp.ConfigError) as exc:
        load_settings(path)
    assert exc.value.field == field
    assert main(["demo", "--config", str(path), "--no-plot"]) == EXIT_USAGE
    assert field in capsys.readouterr().err
    assert main(["demo", "--config", str(path), "--json"]) == EXIT_USAGE
    doc = json.loads(capsys.readouterr().out)
    assert doc["exit_code"] == EXIT_USAGE and doc["field"] == field


@pytest.mark.parametrize("case", ["missing", "directory", "not TOML"])
def test_a_config_file_that_cannot_be_read_is_an_error_on_path_or_on_the_flag(case: str, tmp_path: Path,
                                                                                capsys) -> None:
    """From Python the error names ``load_settings``'s argument ``path`` (it named the CLI's
    ``--config``); ``avp demo`` and ``avp simulate`` report it on ``--config``."""
    path = {"missing": tmp_path / "none.toml", "directory": tmp_path, "not TOML": tmp_path / "bad.toml"}[case]
    if case == "not TOML":
        path.write_text("[planner]\nsolver = \n")
    with pytest.raises(avp.ConfigError) as exc:
        load_settings(path)
    assert exc.value.field == "path" and repr(str(path)) in exc.value.message
    for command in (["demo", "--no-plot"], ["simulate", "--trials", "1", "--no-plot"]):
        assert main([*command, "--config", str(path), "--json"]) == EXIT_USAGE
        doc = json.loads(capsys.readouterr().out)
        assert doc["field"] == "--config" and repr(str(path)) in doc["error"]


@pytest.mark.parametrize("path", [5, b"vehicle.toml", ["vehicle.toml"]])
def test_a_config_path_that_is_no_file_name_is_a_config_error(path) -> None:
    """Was Python's TypeError from pathlib."""
    with pytest.raises(avp.ConfigError) as exc:
        load_settings(path)
    assert exc.value.field == "path" and "str or pathlib.Path" in exc.value.message


# -- exit codes -------------------------------------------------------------------------------

def _result(status: str, relaxations=(), certified=True, has_traj=True):
    return SimpleNamespace(ok=has_traj, status=SimpleNamespace(name=status), relaxations=relaxations,
                           bounds=SimpleNamespace(certified=certified))


def test_exit_code_rules() -> None:
    assert plan_exit_code(_result("SOLVED")) == EXIT_SOLVED
    assert plan_exit_code(_result("SOLVED_WITHOUT_FOV")) == EXIT_SOLVED
    assert plan_exit_code(_result("SOLVED_RELAXED", ("free_slide",))) == EXIT_RELAXED
    assert plan_exit_code(_result("SOLVED_RELAXED")) == EXIT_RELAXED
    assert plan_exit_code(_result("SOLVED", ("free_slide",))) == EXIT_RELAXED  # before SOLVED_RELAXED existed
    assert plan_exit_code(_result("SOLVED", certified=False)) == EXIT_FAILED
    assert plan_exit_code(_result("BOUNDS_NOT_CERTIFIED", has_traj=False)) == EXIT_FAILED
    safety_failed = _result("SOLVED")
    safety_failed.safety = SimpleNamespace(certified=False)
    assert plan_exit_code(safety_failed) == EXIT_FAILED
    assert len({EXIT_SOLVED, EXIT_RELAXED, EXIT_FAILED, EXIT_USAGE}) == 4


def test_failed_plan_exits_nonzero_with_a_short_log(tmp_path: Path) -> None:
    """Limits no perch can meet: the demo exits 1, says why in a few lines, and (with -v only)
    prints the whole planner log."""
    args = ["demo", "--no-plot", "--tilt-rate-max", "0.05"]
    quiet = subprocess.run([sys.executable, "-m", "avp", *args], capture_output=True, text=True,
                           timeout=300, cwd=tmp_path)
    assert quiet.returncode == EXIT_FAILED, quiet.stderr
    assert "no certified plan" in quiet.stderr
    n_lines = len((quiet.stdout + quiet.stderr).splitlines())
    assert n_lines < 25
    loud = subprocess.run([sys.executable, "-m", "avp", *args, "-v"], capture_output=True, text=True,
                          timeout=300, cwd=tmp_path)
    assert loud.returncode == EXIT_FAILED
    assert len((loud.stdout + loud.stderr).splitlines()) > n_lines


def test_relaxed_plan_exits_3_and_says_what_was_relaxed(capsys) -> None:
    """A 3 m wall with a 3 rad/s tilt-rate limit certifies only after freeing the slide and
    using the cone band: solved, but relaxed."""
    code = main(["demo", "--no-plot", "--distance", "3", "--tilt-rate-max", "3", "--json"])
    doc = json.loads(capsys.readouterr().out)
    assert code == doc["exit_code"] == EXIT_RELAXED
    assert doc["label"] == "RELAXED" and doc["relaxations"] and doc["trajectory"] is not None
    assert main(["demo", "--no-plot", "--distance", "3", "--tilt-rate-max", "3", "-q"]) == EXIT_RELAXED
    assert "relaxations" in capsys.readouterr().err


def test_quiet_prints_nothing_on_success(capsys) -> None:
    assert main(["demo", "--no-plot", "-q"]) == EXIT_SOLVED
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err == ""


def test_ceiling_demo_starts_below_the_pad() -> None:
    for incline in (100.0, 135.0, 180.0):
        state, target, height = demo_geometry(incline, 3.5, 0.0, None)
        assert height < 0 and state.position[2] < target.point[2]
        assert float((state.position - target.point) @ target.s3) > 0  # outward side of the pad
        assert state.position[2] > 0  # above the demo's ground
    for incline in (0.0, 30.0, 90.0):
        state, target, _ = demo_geometry(incline, 3.5, 0.0, None)
        assert state.position[2] >= target.point[2]


def test_export_flag_writes_a_loadable_plan(tmp_path: Path) -> None:
    out = tmp_path / "plan.npz"
    assert main(["demo", "--no-plot", "-q", "--export", str(out)]) == EXIT_SOLVED
    traj = avp.Trajectory.from_npz(out)
    state, target, _ = demo_geometry(90.0, 3.5, 0.0, None)
    assert np.linalg.norm(traj(traj.tf) - target.point) < 1e-6
    assert np.allclose(traj(traj.t0), state.position, atol=1e-9)


def test_the_json_result_is_not_a_trajectory_file_and_says_where_its_plan_is(tmp_path: Path, capsys) -> None:
    """``avp demo --json > plan.json`` writes the result document, which ``Trajectory.from_json``
    refused as "not an avp.trajectory document"; the error now points at its ``trajectory``
    entry and at ``--export``, and that entry loads."""
    assert main(["demo", "--no-plot", "--json"]) == EXIT_SOLVED
    result = tmp_path / "result.json"
    result.write_text(capsys.readouterr().out)
    with pytest.raises(avp.ConfigError, match="result document of avp demo --json") as err:
        avp.Trajectory.from_json(result)
    assert err.value.field == "format" and "'trajectory'" in err.value.message and "--export" in err.value.message
    traj = avp.export.trajectory_from_dict(json.loads(result.read_text())["trajectory"])
    target = demo_geometry(90.0, 3.5, 0.0, None)[1]
    assert np.linalg.norm(traj(traj.tf) - target.point) < 1e-6


def test_export_rate_needs_export(capsys) -> None:
    assert main(["demo", "--no-plot", "--export-rate", "50"]) == EXIT_USAGE
    assert "--export-rate:" in capsys.readouterr().err


@pytest.mark.parametrize("output", [".", "..", "", "{tmp}", "{tmp}/", "{tmp}/new/", "{tmp}/sub"])
def test_demo_output_without_a_file_name_is_a_usage_error(output: str, tmp_path: Path, capsys, monkeypatch) -> None:
    """``--output .`` was a ValueError traceback from plotting.py ("has an empty name"); ``DIR/``
    wrote ``DIR.png`` beside the directory."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "sub.png").mkdir()  # "sub" would be written as sub.png: a directory
    out = output.format(tmp=tmp_path)
    assert main(["demo", "--output", out]) == EXIT_USAGE
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "--output:" in err and "file name" in err
    assert not list(tmp_path.parent.glob(f"{tmp_path.name}*.png")) and not (tmp_path / "new").exists()


@pytest.mark.parametrize("incline", ["inf", "1e400", "1e300", "-80.5", "nan", "80.5"])
def test_line_incline_out_of_range_is_a_usage_error(incline: str, capsys) -> None:
    """``inf`` and ``1e400`` were a math domain error's traceback; ``1e300`` was accepted. A
    negative incline mirrors the line (accepted, as before, within the same range)."""
    assert main(["demo", "--no-plot", "--line-pitch-deg", "0", f"--line-incline-deg={incline}"]) == EXIT_USAGE
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "--line-incline-deg:" in err and "[-80, 80] deg" in err


def test_a_negative_line_incline_mirrors_the_line(capsys) -> None:
    assert main(["demo", "--no-plot", "--line-pitch-deg", "20", "--line-incline-deg=-5"]) == 0


# -- simulate ---------------------------------------------------------------------------------

def test_progress_bar_only_on_a_terminal(monkeypatch, caplog) -> None:
    from avp import cli

    monkeypatch.setattr(sys.stderr, "isatty", lambda: False)
    with caplog.at_level("INFO", logger="avp.cli"):
        assert list(cli.progress(iter(range(20)), 20, "job")) == list(range(20))
    assert all("\r" not in r.getMessage() for r in caplog.records)
    assert [r.getMessage() for r in caplog.records][-1].startswith("job: 20/20")
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True)
    bar = cli.progress(iter(range(3)), 3, "job")
    assert type(bar).__name__ == "tqdm" and list(bar) == [0, 1, 2]


def test_paper_notes_are_removed_for_other_conditions() -> None:
    from avp.sim.evaluate import Comparison, Condition

    comp = Comparison([Condition(math.radians(45), 2.0)], [0])
    text = comp.report()
    assert "4.5 m one-shot" in text or "paper" in text  # the notes exist to be removed
    stripped = without_paper_notes(text)
    assert "Table V" not in stripped and "4.5 m one-shot" not in stripped and "AVP 60" not in stripped
    assert "Success rate" in stripped and "Interception error" in stripped


def test_simulate_json_for_a_45_degree_run(tmp_path: Path, capsys) -> None:
    code = main(["simulate", "--trials", "1", "--incline-deg", "45", "--distance", "2.0", "--no-plot",
                 "--json"])
    doc = json.loads(capsys.readouterr().out)
    assert code == EXIT_SOLVED
    assert {r["mode"] for r in doc["rows"]} == {"one_shot", "avp"}
    assert all(r["incline_deg"] == pytest.approx(45.0) and r["distance_m"] == 2.0 for r in doc["rows"])
    assert sum(s["trials"] for s in doc["summary"]) == 2


@pytest.mark.parametrize(("command", "flags", "flag"), [
    ("simulate", ["--distance", "1e5"], "--distance"),  # was a math domain error's traceback
    ("simulate", ["--lateral", "1e300"], "--lateral"),  # was exit 0 with a table of NaN
    ("simulate", ["--distance", "4.5", "-1"], "--distance"),  # the second condition: before any trial
    ("simulate", ["--height", "200"], "--height"),
    ("simulate", ["--incline-deg", "200"], "--incline-deg"),
    ("campaign", ["--distance", "1e5", "--backend", "serial"], "--distance"),
])
def test_swept_geometry_out_of_range_is_a_usage_error_on_its_flag(command, flags, flag, tmp_path: Path, capsys,
                                                                   monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)
    count = ["--trials", "1"] if command == "simulate" else ["--seeds", "1"]
    assert main([command, "--no-plot", *count, *flags]) == EXIT_USAGE
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and f"{flag}:" in err and "Traceback" not in err
    assert not list(tmp_path.iterdir())  # no trial ran, no results file


def test_simulate_report_has_no_wall_comparison_at_45_degrees(capsys) -> None:
    assert main(["simulate", "--trials", "1", "--incline-deg", "45", "--distance", "2.0", "--no-plot"]) == 0
    out = capsys.readouterr().out
    assert "Success rate" in out and "45 deg, 2 m" in out
    assert "4.5 m one-shot" not in out and "Table VI at 7.5" not in out


def test_parser_lists_the_three_commands() -> None:
    text = build_parser().format_help()
    for cmd in ("demo", "simulate", "campaign"):
        assert cmd in text


def test_simulate_flies_a_moving_platform_from_the_flags(tmp_path: Path, capsys) -> None:
    """--platform-* flags reach the simulated scenario (over a [scenario.platform] table of the
    file), and both modes fly a perch on the moving pad."""
    from avp.cli import _platform_overrides
    from avp.configfile import merge

    cfg = tmp_path / "c.toml"
    cfg.write_text("[scenario.platform]\nspeed = 9.0\nvertical_speed = 0.25\n")
    argv = ["simulate", "--trials", "1", "--incline-deg", "30", "--distance", "3", "--height", "0", "--no-plot",
            "--json", "--config", str(cfg), "--platform-speed", "1.5", "--platform-heading-deg", "10",
            "--platform-turn-rate", "0.1"]
    args = build_parser().parse_args(argv)
    platform = load_settings(args.config, merge({}, _platform_overrides(args))).scenario().platform
    assert (platform.speed, platform.turn_rate, platform.vertical_speed) == (1.5, 0.1, 0.25)
    assert platform.heading == pytest.approx(math.radians(10.0))
    code = main(argv)
    doc = json.loads(capsys.readouterr().out)
    assert code == EXIT_SOLVED
    assert {r["mode"] for r in doc["rows"]} == {"one_shot", "avp"}
    for r in doc["rows"]:
        assert r["outcome"] != "no initial detection" and not r["outcome"].startswith("no plan"), r["outcome"]
        assert r["initial_estimate_error_m"] < 0.3  # fitted from detections of the moving pad


def test_simulate_rejects_a_nan_platform_speed(capsys) -> None:
    code = main(["simulate", "--trials", "1", "--no-plot", "--json", "--platform-speed", "nan"])
    doc = json.loads(capsys.readouterr().out)
    assert code == EXIT_USAGE
    assert doc["field"] == "scenario.platform.speed"


@pytest.mark.parametrize("argv, field", [
    (["demo", "--config", "."], "--config"),  # a directory: was IsADirectoryError
    (["simulate", "--seed", "-1", "--trials", "1"], "--seed"),  # was numpy's ValueError
    (["campaign", "--seed", "-1"], "--seed"),
    (["simulate", "--gif", "run.txt", "--trials", "1"], "--gif"),  # was PIL's ValueError after the runs
])
def test_bad_cli_arguments_are_clean_errors(argv, field, capsys) -> None:
    assert main(argv) == EXIT_USAGE
    assert f"{field}:" in capsys.readouterr().err


@pytest.mark.parametrize("argv, field", [
    (["demo", "--no-plot", "--export", "{missing}/p.json"], "--export"),
    (["demo", "--no-plot", "--export", "{file}/p.npz"], "--export"),
    (["demo", "--output", "{file}/x.png"], "--output"),
    (["demo", "--output", "{file}/x"], "--output"),
    (["simulate", "--trials", "1", "--distance", "4.5", "--output-dir", "{file}/sub"], "--output-dir"),
    (["campaign", "--seeds", "1", "--distance", "4.5", "--modes", "avp", "--backend", "serial", "--no-plot",
      "--results", "{file}/r.csv"], "--results"),
])
def test_unusable_paths_are_usage_errors(argv, field, tmp_path: Path, capsys) -> None:
    """A path under a missing directory or under a regular file: exit 2 with one line naming the
    flag and the operating system's reason (was a traceback and exit 1)."""
    (tmp_path / "afile").write_text("")
    argv = [a.format(missing=tmp_path / "missing", file=tmp_path / "afile") for a in argv]
    assert main(argv) == EXIT_USAGE
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(f"avp: ERROR: {field}: cannot ") and "Traceback" not in err
    assert main([*argv, "--json"]) == EXIT_USAGE
    doc = json.loads(capsys.readouterr().out)
    assert doc["exit_code"] == EXIT_USAGE and doc["field"] == field


def test_an_os_error_that_names_no_file_is_not_bad_input(monkeypatch) -> None:
    """Only file-system errors on a path become usage errors; others propagate."""
    from avp import cli

    def broken(args):
        raise ConnectionError("the cluster went away")

    monkeypatch.setattr(cli, "demo", broken)
    with pytest.raises(ConnectionError):
        main(["demo"])


def test_demo_output_without_suffix_reports_the_png_it_writes(tmp_path: Path, capsys) -> None:
    assert main(["demo", "--output", str(tmp_path / "plot")]) == EXIT_SOLVED
    assert (tmp_path / "plot.png").is_file()
    captured = capsys.readouterr()
    assert str(tmp_path / "plot.png") in captured.out + captured.err


def test_demo_keeps_the_airframe_off_its_ground(capsys) -> None:
    """The demo's ground is z = 0 and its plans keep the centre of mass GROUND_CLEARANCE above it
    (with the limit at the ground itself a 150 deg overhang passed 5 mm above the floor)."""
    from avp.config import GROUND_CLEARANCE

    code = main(["demo", "--incline-deg", "150", "--json", "--no-plot"])
    doc = json.loads(capsys.readouterr().out)
    assert doc["config"]["planner"]["workspace"]["ground_z"] == GROUND_CLEARANCE
    if doc.get("trajectory") is not None:
        traj = avp.Trajectory.from_json(json.dumps(doc["trajectory"]))
        z = traj(traj.sample(1e-3))[:, 2]
        assert z.min() >= GROUND_CLEARANCE - 1e-6, (code, z.min())


@pytest.mark.parametrize("argv,flag,field", [
    (["--camera-half-fov-deg", "95"], "--camera-half-fov-deg", "half_fov"),
    (["--mass", "-1"], "--mass", "limits.mass"),
    (["--contact-normal", "0.5"], "--contact-normal", "contact_velocity.normal"),
])
def test_an_error_on_a_flag_names_the_flag(capsys, argv, flag, field) -> None:
    """A value given by a flag and refused as a configuration field is reported on the flag the
    user typed, with the field's message (``half_fov`` is checked in rad, the flag is in deg)."""
    assert main(["demo", "--no-plot", "--json", *argv]) == EXIT_USAGE
    doc = json.loads(capsys.readouterr().out)
    assert doc["field"] == flag and field in doc["error"] and argv[1] in doc["error"]


def test_an_error_on_the_demo_geometry_names_its_flags(capsys) -> None:
    assert main(["demo", "--no-plot", "--distance", "-3"]) == EXIT_USAGE
    assert "--distance -3" in capsys.readouterr().err


def test_a_file_in_the_output_dir_names_the_flag_and_other_files_are_not_bad_input(tmp_path, capsys, monkeypatch) -> None:
    """A file the command writes inside ``--output-dir`` that cannot be written is reported on
    ``--output-dir``; an ``OSError`` on a file no flag names is not bad input (re-raised)."""
    import avp.cli as cli

    out = tmp_path / "od"
    (out / "visibility.png").mkdir(parents=True)  # a directory where a plot goes
    assert main(["simulate", "--trials", "1", "--distance", "4.5", "--output-dir", str(out), "--json"]) == EXIT_USAGE
    assert json.loads(capsys.readouterr().out)["field"] == "--output-dir"

    def denied(args):
        raise PermissionError(13, "Permission denied", str(tmp_path / "cache" / "x.json"))

    monkeypatch.setattr(cli, "demo", denied)
    with pytest.raises(PermissionError):
        main(["demo", "--no-plot"])


def test_an_exact_path_flag_wins_over_the_directory_that_holds_it(tmp_path, capsys, monkeypatch) -> None:
    """A failing file that is one flag's own path names that flag, not the directory flag
    whose directory holds it; and a file deeper below ``--output-dir`` (a cache, not a file the
    command writes there) is not bad input."""
    import avp.cli as cli

    runs = tmp_path / "runs"
    (runs / "anim.gif").mkdir(parents=True)  # a directory where the animation goes
    argv = ["simulate", "--trials", "1", "--distance", "4.5", "--output-dir", str(runs), "--gif", str(runs / "anim.gif"),
            "--json", "--no-plot"]
    assert main(argv) == EXIT_USAGE
    assert json.loads(capsys.readouterr().out)["field"] == "--gif"

    def denied(args):
        raise PermissionError(13, "Permission denied", str(tmp_path / ".cache" / "matplotlib" / "x.json"))

    monkeypatch.setattr(cli, "simulate", denied)
    with pytest.raises(PermissionError):
        main(["simulate", "--output-dir", str(tmp_path)])


def test_an_export_rate_error_names_the_flag(tmp_path, capsys) -> None:
    out = tmp_path / "x.json"
    assert main(["demo", "--no-plot", "--json", "--export", str(out), "--export-rate", "0"]) == EXIT_USAGE
    assert json.loads(capsys.readouterr().out)["field"] == "--export-rate" and not out.exists()


@pytest.mark.parametrize("rate", ["0", "-5", "nan", "inf"])
def test_a_meaningless_export_rate_is_refused_before_planning(tmp_path, capsys, monkeypatch, rate) -> None:
    """The rate was checked only when the plan was written, after planning; a rate that is no
    positive number is a usage error on its flag before the planner runs."""
    import avp.planner as planner

    def never(*args, **kwargs):
        raise AssertionError("planned before the flags were checked")

    monkeypatch.setattr(planner, "plan_detailed", never)
    out = tmp_path / "x.json"
    assert main(["demo", "--no-plot", "--json", "--export", str(out), "--export-rate", rate]) == EXIT_USAGE
    assert json.loads(capsys.readouterr().out)["field"] == "--export-rate" and not out.exists()


@pytest.mark.parametrize("command,flag", [("simulate", "--gif"), ("simulate", "--output-dir"),
                                          ("campaign", "--results"), ("campaign", "--summary-plot")])
def test_an_unusable_output_path_stops_before_any_trial(tmp_path, capsys, monkeypatch, command, flag) -> None:
    """A path the command could not write was found after every trial had run; it is a usage
    error on its flag before the first one now."""
    import avp.campaign as campaign

    def no_trials(*args, **kwargs):
        raise AssertionError("a trial ran")

    monkeypatch.setattr(campaign, "execute", no_trials)
    monkeypatch.setattr(campaign, "run", no_trials)
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    paths = {"--gif": str(tmp_path / "anim.gif"), "--output-dir": str(tmp_path / "od"),
             "--results": str(tmp_path / "r.csv"), "--summary-plot": str(tmp_path / "s.png")}
    bad = {"--gif": str(blocker / "a.gif"), "--output-dir": str(blocker / "od"),
           "--results": str(blocker / "r.csv"), "--summary-plot": str(blocker / "s.png")}
    names = ("--gif", "--output-dir") if command == "simulate" else ("--results", "--summary-plot")
    argv = [command, "--json"] + [x for n in names for x in (n, bad[n] if n == flag else paths[n])]
    assert main(argv) == EXIT_USAGE
    assert json.loads(capsys.readouterr().out)["field"] == flag
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a_file"]  # the check created nothing


def test_a_refused_run_leaves_no_output_directory(tmp_path, capsys) -> None:
    """The output paths are checked without creating them: a run refused after the check (a
    start behind the pad) leaves no directory behind."""
    out = tmp_path / "new"
    assert main(["simulate", "--trials", "1", "--distance", "-1", "--output-dir", str(out)]) == EXIT_USAGE
    assert "--distance:" in capsys.readouterr().err and not out.exists()


def _no_planning(monkeypatch) -> None:
    """Planning, a line plan, a trial or a campaign fails the test."""
    import avp.campaign as campaign
    import avp.line_planner as line_planner
    import avp.planner as planner

    def never(*args, **kwargs):
        raise AssertionError("planned, or ran a trial")

    for module, name in ((planner, "plan_detailed"), (line_planner, "plan_line"), (campaign, "execute"),
                         (campaign, "run")):
        monkeypatch.setattr(module, name, never)


@pytest.mark.parametrize("argv, flag", [
    (["demo", "--output", "{missing}/p.png"], "--output"),  # created the directory, exit 0
    (["demo", "--output", "{missing}/p"], "--output"),
    (["demo", "--no-plot", "--export", "{missing}/p.json"], "--export"),  # exit 2 after planning
    (["demo", "--line-pitch-deg", "30", "--export", "{missing}/p.npz"], "--export"),
    (["simulate", "--trials", "1", "--output-dir", "{missing}/od"], "--output-dir"),
    (["simulate", "--trials", "1", "--no-plot", "--gif", "{missing}/a.gif"], "--gif"),
    (["campaign", "--seeds", "1", "--results", "{missing}/r.csv"], "--results"),
    (["campaign", "--seeds", "1", "--summary-plot", "{missing}/s.png"], "--summary-plot"),
])
def test_a_missing_directory_is_refused_before_planning_and_not_created(argv, flag, tmp_path, capsys,
                                                                        monkeypatch) -> None:
    """Every output path in a directory that does not exist is a usage error on its flag, before
    any planning or trial and without creating the directory (``--output-dir`` itself may be
    missing, its parent not)."""
    _no_planning(monkeypatch)
    monkeypatch.chdir(tmp_path)
    argv = [a.format(missing=tmp_path / "missing") for a in argv]
    assert main(argv) == EXIT_USAGE
    captured = capsys.readouterr()
    assert captured.err.startswith(f"avp: ERROR: {flag}: cannot write ") and captured.err.count("\n") == 1
    assert "does not exist" in captured.err and captured.out == ""  # no summary before the error
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("line", [[], ["--line-pitch-deg", "30"]])
@pytest.mark.parametrize("name", ["plan.txt", "plan", "plan.json.bak"])
def test_an_unknown_export_format_is_refused_before_planning(line, name, tmp_path, capsys, monkeypatch) -> None:
    """``--export plan.txt`` printed the whole summary and then exited 2."""
    _no_planning(monkeypatch)
    assert main(["demo", "--no-plot", *line, "--export", str(tmp_path / name)]) == EXIT_USAGE
    captured = capsys.readouterr()
    assert captured.err.startswith("avp: ERROR: --export: ") and ".json, .csv or .npz" in captured.err
    assert captured.out == "" and list(tmp_path.iterdir()) == []


def test_an_export_suffix_in_capitals_is_its_format(tmp_path, capsys) -> None:
    out = tmp_path / "PLAN.JSON"
    assert main(["demo", "--no-plot", "-q", "--export", str(out)]) == EXIT_SOLVED
    assert avp.Trajectory.from_json(out).duration > 0
