"""The documentation is self-contained and the configuration page matches the code."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import pytest

import avp
from avp import configfile

ROOT = Path(__file__).resolve().parent.parent


def test_configuration_page_is_in_sync() -> None:
    page = (ROOT / "docs" / "configuration.md").read_text()
    assert page == configfile.configuration_markdown(), (
        "docs/configuration.md is stale: regenerate it with "
        "python -c \"import avp.configfile as c; print(c.configuration_markdown(), end='')\" > docs/configuration.md")


def _knobs(cls: type, prefix: str) -> list[str]:
    import typing

    out = []
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        tp = hints[f.name]
        if isinstance(tp, type) and dataclasses.is_dataclass(tp):
            out += _knobs(tp, f"{prefix}.{f.name}")
        else:
            out.append(f"{prefix}.{f.name}")
    return out


def test_every_knob_is_listed_with_unit_default_and_meaning() -> None:
    """Independently of the generator: every field of every nested configuration dataclass
    appears as a row of its table, with four non-empty cells."""
    page = configfile.configuration_markdown()
    sections = dict(re.findall(r"## `\[([^\]]+)\]`[^\n]*\n(.*?)(?=\n## |\Z)", page, flags=re.S))
    for name, cls in (("planner", avp.PlannerConfig), ("replan", avp.ReplanConfig)):
        for knob in _knobs(cls, name):
            table, key = knob.rsplit(".", 1)
            rows = [r for r in sections[table].splitlines() if r.startswith(f"| `{key}` |")]
            assert len(rows) == 1, knob
            cells = [c.strip() for c in rows[0].strip("|").split(" | ")]
            assert len(cells) == 4 and all(cells), knob


def test_every_listed_knob_can_be_set_from_a_file(tmp_path: Path) -> None:
    """A TOML file with each knob set to its default value builds the default configuration."""
    planner = configfile.to_mapping(avp.PlannerConfig())
    replan = configfile.to_mapping(avp.ReplanConfig())

    def toml(table: str, data: dict) -> list[str]:
        scalars = {k: v for k, v in data.items() if not isinstance(v, dict)}
        lines = [f"[{table}]"] + [f"{k} = {_toml_value(v)}" for k, v in scalars.items()]
        for k, v in data.items():
            if isinstance(v, dict):
                lines += toml(f"{table}.{k}", v)
        return lines

    path = tmp_path / "all.toml"
    path.write_text("\n".join(toml("planner", planner) + toml("replan", replan)) + "\n")
    s = configfile.load_settings(path)
    assert s.planner == avp.PlannerConfig() and s.replan == avp.ReplanConfig()


def _toml_value(v) -> str:
    if v is None:
        return '"none"'
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return "inf" if v == float("inf") else repr(v)
    if isinstance(v, str):
        return f'"{v}"'
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    return str(v)


FORBIDDEN = re.compile(
    r"DESIGN\.md|\bseed[ -]?00\d|\bissue \d|\bthe (seed|issue)'s\b|/work/|/root/|\.\./shared", re.I
)


@pytest.mark.parametrize("folder", ["avp", "docs", "examples", "benchmarks", "tests", "README.md"])
def test_no_references_outside_the_repository(folder: str) -> None:
    paths = [ROOT / folder] if folder.endswith(".md") else sorted((ROOT / folder).rglob("*"))
    bad = []
    for p in paths:
        if p.suffix not in (".py", ".md", ".toml", ".pyi") or p.name == "test_docs.py":
            continue
        for n, line in enumerate(p.read_text().splitlines(), 1):
            if FORBIDDEN.search(line):
                bad.append(f"{p.relative_to(ROOT)}:{n}: {line.strip()}")
    assert not bad, "\n".join(bad)


def test_the_page_example_loads(tmp_path: Path) -> None:
    page = configfile.configuration_markdown()
    example = page.split("```toml\n", 1)[1].split("```", 1)[0]
    path = tmp_path / "example.toml"
    path.write_text(example)
    cfg = configfile.load_settings(path).planner
    assert cfg.solver == "proxqp" and cfg.limits.mass == 0.7 and cfg.contact_velocity.slope is None
    (ceiling,) = cfg.workspace.half_spaces
    assert ceiling.normal.tolist() == [0.0, 0.0, -1.0] and ceiling.offset == -3.0


def test_the_page_python_example_runs(tmp_path: Path, monkeypatch) -> None:
    """The page's Python snippet, run on its TOML example saved as ``vehicle.toml``."""
    page = configfile.configuration_markdown()
    toml = page.split("```toml\n", 1)[1].split("```", 1)[0]
    code = page.split("```python\n", 1)[1].split("```", 1)[0]
    (tmp_path / "vehicle.toml").write_text(toml)
    monkeypatch.chdir(tmp_path)
    names: dict = {}
    exec(compile(code, "docs/configuration.md", "exec"), names)
    settings, heavier = names["settings"], names["heavier"]
    assert settings.planner.limits.mass == 0.7 and settings.replan.latency == 0.03
    assert heavier.planner.limits.mass == 0.8 and heavier.planner.limits.thrust_max == 13.7
    assert isinstance(names["traj"], avp.Trajectory) and names["replanner"].config == settings.planner
