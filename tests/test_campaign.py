"""Campaigns: grid x seeds of closed-loop trials, identical on every backend, resumable."""

from __future__ import annotations

import importlib.util
import json
import math
from pathlib import Path

import pytest

from avp import campaign
from avp.cli import main
from avp.errors import ConfigError

# Two short trials (a 1.5 m wall, both modes): about a second each.
TRIALS = campaign.grid([90.0], [1.5], [0.0], [None], ["one_shot", "avp"], [3])


@pytest.fixture(scope="module")
def serial_rows() -> dict[str, dict]:
    runner = campaign.Runner()
    return {t.trial_id: row for t, row in campaign.execute(runner, TRIALS, backend="serial")}


def test_grid_is_every_combination() -> None:
    g = campaign.grid([0.0, 90.0], [1.5, 3.0, 4.5], [0.0], [None, 1.0], ["avp"], range(4))
    assert len(g) == 2 * 3 * 2 * 4
    assert len({t.trial_id for t in g}) == len(g)
    assert {t.incline for t in g} == {0.0, math.pi / 2}
    with pytest.raises(ConfigError, match="modes"):
        campaign.grid([90.0], [1.5], [0.0], [None], ["sideways"], [0])


def test_rows_carry_every_parameter_and_outcome(serial_rows) -> None:
    for t in TRIALS:
        row = serial_rows[t.trial_id]
        assert tuple(row) == campaign.COLUMNS
        assert (row["incline_deg"], row["distance_m"], row["mode"], row["seed"]) == (90.0, 1.5, t.mode, 3)
        assert isinstance(row["success"], bool) and row["outcome"]
        if row["contact"]:
            assert abs(row["s1_m"]) < 1.0 and row["normal_speed_m_s"] > 0


def test_pool_gives_the_serial_rows(serial_rows) -> None:
    rows = dict((t.trial_id, row) for t, row in campaign.execute(campaign.Runner(), TRIALS, backend="pool", workers=2))
    assert rows.keys() == serial_rows.keys()
    for k, row in rows.items():
        assert campaign.rows_equal(row, serial_rows[k]), (row, serial_rows[k])


def test_a_trials_config_error_reaches_the_caller_from_the_pool() -> None:
    # The error is raised in a spawned worker (the aim is checked when the trial's scenario is
    # built) and must come back as itself, field and all: before ConfigError pickled by its two
    # arguments, unpickling it failed and the pool reported BrokenProcessPool instead.
    runner = campaign.Runner({"scenario": {"aim_normal": 0.04}})
    with pytest.raises(ConfigError) as serial:
        runner(TRIALS[0])
    with pytest.raises(ConfigError) as pooled:
        list(campaign.execute(runner, TRIALS[:1], backend="pool", workers=1))
    assert pooled.value.field == serial.value.field == "scenario.aim_normal"
    assert str(pooled.value) == str(serial.value)


@pytest.mark.skipif(importlib.util.find_spec("ray") is None, reason="ray is not installed (extra [ray])")
def test_ray_gives_the_serial_rows(serial_rows) -> None:
    import ray

    try:
        rows = dict((t.trial_id, row) for t, row in campaign.execute(campaign.Runner(), TRIALS, backend="ray",
                                                                       workers=2))
    finally:
        ray.shutdown()
    assert rows.keys() == serial_rows.keys()
    for k, row in rows.items():
        assert campaign.rows_equal(row, serial_rows[k]), (row, serial_rows[k])


def test_rows_equal_sees_a_changed_outcome(serial_rows) -> None:
    row = next(iter(serial_rows.values()))
    assert campaign.rows_equal(row, dict(row, trial_wall_s=row["trial_wall_s"] + 1))
    assert not campaign.rows_equal(row, dict(row, s2_m=1.0 + (row["s2_m"] if row["contact"] else 0.0)))


def test_results_resume_and_skip_done_rows(tmp_path: Path, serial_rows) -> None:
    path = tmp_path / "r.csv"
    first = campaign.run(TRIALS[:1], None, path, backend="serial")
    assert (first["ran"], first["skipped"]) == (1, 0)
    second = campaign.run(TRIALS, None, path, backend="serial")
    assert (second["ran"], second["skipped"]) == (1, 1)
    third = campaign.run(TRIALS, None, path, backend="serial")
    assert third["ran"] == 0
    rows = campaign.ResultStore(path).rows()
    assert sorted(r["trial_id"] for r in rows) == sorted(t.trial_id for t in TRIALS)
    for r in rows:  # parsed back from CSV: the same values as computed
        assert campaign.rows_equal(r, serial_rows[r["trial_id"]])
    # another configuration is another set of trials
    other = campaign.run(TRIALS[:1], {"replan": {"latency": 0.03}}, path, backend="serial")
    assert other["ran"] == 1


@pytest.mark.skipif(importlib.util.find_spec("pyarrow") is None, reason="pyarrow is not installed")
def test_parquet_results(tmp_path: Path, serial_rows) -> None:
    path = tmp_path / "r.parquet"
    campaign.run(TRIALS, None, path, backend="serial")
    rows = campaign.ResultStore(path).rows()
    assert len(rows) == 2 and all(campaign.rows_equal(r, serial_rows[r["trial_id"]]) for r in rows)
    assert campaign.run(TRIALS, None, path, backend="serial")["ran"] == 0


def test_summary_counts(serial_rows) -> None:
    summary = campaign.summarize(serial_rows.values())
    assert {s["mode"] for s in summary} == {"one_shot", "avp"}
    for s in summary:
        mine = [r for r in serial_rows.values() if r["mode"] == s["mode"]]
        assert s["trials"] == len(mine)
        assert s["success_rate"] == sum(r["success"] for r in mine) / len(mine)
    text = campaign.format_summary(summary)
    assert "one_shot" in text and "avp" in text


def test_campaign_command_with_config_and_json(tmp_path: Path, capsys) -> None:
    cfg = tmp_path / "c.toml"
    cfg.write_text("[scenario]\npad_half_size = 0.2\n[replan]\nlatency = 0.02\n")
    results = tmp_path / "c.csv"
    argv = ["campaign", "--config", str(cfg), "--distance", "1.5", "--seeds", "1", "--seed", "3",
            "--backend", "serial", "--results", str(results), "--summary-plot", str(tmp_path / "s.png"), "--json"]
    assert main(argv) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["ran"] == 2 and doc["skipped"] == 0 and sum(s["trials"] for s in doc["summary"]) == 2
    assert (tmp_path / "s.png").read_bytes()[:4] == b"\x89PNG"
    assert main(argv) == 0
    assert json.loads(capsys.readouterr().out)["ran"] == 0


def test_unknown_scenario_key_fails_before_any_trial(tmp_path: Path, capsys) -> None:
    cfg = tmp_path / "c.toml"
    cfg.write_text("[scenario]\npad_size = 0.2\n")
    assert main(["campaign", "--config", str(cfg), "--results", str(tmp_path / "r.csv"), "--no-plot"]) == 2
    assert "scenario.pad_size" in capsys.readouterr().err
    assert not (tmp_path / "r.csv").exists()


@pytest.mark.parametrize("command", ["campaign", "simulate"])
@pytest.mark.parametrize("key,flag", [("distance = 2.0", "--distance"), ("incline = 0.5", "--incline-deg")])
def test_scenario_keys_the_flags_sweep_are_refused_before_any_trial(tmp_path: Path, capsys, command, key, flag) -> None:
    """A ``[scenario]`` key that the command's flags set (defaults included) would be overridden
    silently: it is a usage error naming the key and the flag, before any trial."""
    cfg = tmp_path / "c.toml"
    cfg.write_text(f"[scenario]\n{key}\n")
    out = ["--results", str(tmp_path / "r.csv")] if command == "campaign" else ["--output-dir", str(tmp_path / "o")]
    assert main([command, "--config", str(cfg), "--no-plot", *out]) == 2
    err = capsys.readouterr().err
    assert f"scenario.{key.split()[0]}" in err and flag in err
    assert not (tmp_path / "r.csv").exists() and not (tmp_path / "o").exists()


def test_wilson_interval_against_the_closed_form() -> None:
    """Against an exact rational evaluation of the Wilson formula (z = 2 for exact squares)."""
    from fractions import Fraction

    for k, n in ((0, 5), (3, 10), (10, 10), (7, 50)):
        lo, hi = campaign.wilson_interval(k, n, z=2.0)
        p, z2 = Fraction(k, n), Fraction(4)
        den = 1 + z2 / n
        centre = (p + z2 / (2 * n)) / den
        rad2 = z2 * (p * (1 - p) / n + z2 / (4 * n * n)) / den**2
        assert (lo - float(centre)) ** 2 == pytest.approx(float(rad2), rel=1e-12, abs=1e-15) or lo == 0.0
        assert (hi - float(centre)) ** 2 == pytest.approx(float(rad2), rel=1e-12, abs=1e-15) or hi == 1.0
        assert 0.0 <= lo <= k / n <= hi <= 1.0


def test_runner_plans_above_the_simulated_ground_unless_configured() -> None:
    """The runner behind ``avp simulate|campaign`` builds its planner from the TOML data; as
    simulate()'s default it keeps GROUND_CLEARANCE above the world's ground. A 150 deg overhang
    2 m up needs a dive its ground does not allow: no plan. With the file's own ground far
    below, the plan dives and the world ends the run."""
    trial = campaign.grid([150.0], [3.0], [0.0], [None], ["one_shot"], [0])[0]
    scenario = {"pad_height": 2.0, "odometry": "none"}
    _, kept = campaign.Runner({"scenario": scenario}, keep_result=True)(trial)
    assert kept.outcome.startswith("no plan"), kept.outcome
    data = {"scenario": scenario, "planner": {"workspace": {"ground_z": -100.0}}}
    _, dived = campaign.Runner(data, keep_result=True)(trial)
    assert dived.outcome == "crash: ground", dived.outcome


def test_the_scenarios_contact_thrust_reaches_the_campaigns_planner(monkeypatch) -> None:
    """``[scenario] alpha_nominal`` is the planner's contact thrust in a campaign (as
    ``simulate``'s own configuration takes it), unless ``[planner]`` sets it."""
    import avp.sim.run

    seen: list[float] = []

    def fake_simulate(scenario, mode, *, seed, config, replan, plan_drag):
        seen.append(config.contact_alpha(scenario.incline))
        raise RuntimeError("stop")  # only the configuration is under test

    monkeypatch.setattr(avp.sim.run, "simulate", fake_simulate)
    trial = TRIALS[0]
    for data, want in (({"scenario": {"alpha_nominal": 6.0}}, 6.0),
                       ({"scenario": {"alpha_nominal": 6.0}, "planner": {"alpha_nominal": 5.0}}, 5.0),
                       ({}, 4.0)):
        with pytest.raises(RuntimeError, match="stop"):
            campaign.Runner(data)(trial)
        assert seen[-1] == want


def test_the_scenarios_contact_velocity_reaches_the_campaigns_planner(monkeypatch) -> None:
    """``[scenario.contact_velocity]`` is the planner's contact velocity in a campaign (as
    ``simulate``'s own configuration takes it), unless ``[planner.contact_velocity]`` sets it."""
    import avp.sim.run

    seen: list[tuple] = []

    def fake_simulate(scenario, mode, *, seed, config, replan, plan_drag):
        seen.append(config.contact_velocity.components(scenario.incline))
        raise RuntimeError("stop")  # only the configuration is under test

    monkeypatch.setattr(avp.sim.run, "simulate", fake_simulate)
    trial = TRIALS[0]  # a wall: the slide is the configured one
    scen = {"contact_velocity": {"normal": -0.4, "slope": -1.4}}
    for data, want in (({"scenario": scen}, (-1.4, 0.0, -0.4)),
                       ({"scenario": scen, "planner": {"contact_velocity": {"normal": -0.5}}}, (-2.0, 0.0, -0.5)),
                       ({}, (-2.0, 0.0, -0.3))):
        with pytest.raises(RuntimeError, match="stop"):
            campaign.Runner(data)(trial)
        assert seen[-1] == pytest.approx(want), data
