"""Exports of a Trajectory (CSV / JSON / NPZ) and loaders back; the rotorpy example."""

from __future__ import annotations

import importlib.util
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import avp
from avp import export
from avp.errors import ConfigError

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


@pytest.fixture(scope="module")
def traj() -> avp.Trajectory:
    return avp.plan(avp.State.hover([0.0, 0.0, 1.5]), avp.PerchTarget.from_incline([3.5, 0.0, 1.5], math.pi / 2))


def _random_traj(seed: int, n_seg: int, degree: int) -> avp.Trajectory:
    rng = np.random.default_rng(seed)
    c = rng.normal(size=(n_seg, 4, degree + 1)) * 10.0 ** rng.integers(-8, 4, size=(n_seg, 4, degree + 1))
    knots = np.concatenate([[rng.uniform(-5, 5)], rng.uniform(1e-3, 2.0, n_seg)]).cumsum()
    return avp.Trajectory(c, knots, g=float(rng.uniform(9.7, 9.9)))


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 5), st.integers(1, 12), st.sampled_from(["json", "npz", "csv"]))
def test_coefficient_round_trip_is_exact(tmp_path_factory, seed: int, n_seg: int, degree: int, fmt: str) -> None:
    tr = _random_traj(seed, n_seg, degree)
    path = tmp_path_factory.mktemp("rt") / f"t.{fmt}"
    getattr(tr, f"to_{fmt}")(path)
    back = getattr(avp.Trajectory, f"from_{fmt}")(path)
    assert back.coefficients.tobytes() == tr.coefficients.tobytes()
    assert back.knots.tobytes() == tr.knots.tobytes() and back.g == tr.g


@pytest.mark.parametrize("fmt", ["json", "npz"])
def test_provenance_travels_with_the_plan(traj: avp.Trajectory, tmp_path: Path, fmt: str) -> None:
    if getattr(traj, "provenance", None) is None:
        pytest.skip("this planner records no provenance")
    path = tmp_path / f"p.{fmt}"
    getattr(traj, f"to_{fmt}")(path)
    back = getattr(avp.Trajectory, f"from_{fmt}")(path)
    assert back.provenance == traj.provenance and repr(back) == repr(traj)


def test_json_text_round_trip(traj: avp.Trajectory) -> None:
    text = traj.to_json()
    back = avp.Trajectory.from_json(text)
    assert np.array_equal(back.coefficients, traj.coefficients) and np.array_equal(back.knots, traj.knots)
    assert json.loads(text)["format"] == export.FORMAT


@pytest.mark.parametrize("doc, says", [
    ({"command": "demo", "exit_code": 1, "trajectory": None}, "holds no plan ('trajectory' is null"),
    ({"command": "simulate", "rows": []}, "holds no plan; avp demo --export"),
])
def test_a_cli_result_without_a_plan_says_so(doc: dict, says: str) -> None:
    with pytest.raises(ConfigError, match="not an avp.trajectory document") as err:
        avp.Trajectory.from_json(json.dumps(doc))
    assert err.value.field == "format" and says in err.value.message
    assert f"avp {doc['command']} --json" in err.value.message


def test_writers_return_what_the_module_docstring_says(traj: avp.Trajectory, tmp_path: Path) -> None:
    """``to_csv`` and ``to_npz`` return the path as a ``Path``; ``to_json`` returns the JSON text
    also when it writes a file (the docstring said that every writer returns its path)."""
    for fmt in ("csv", "npz"):
        given = str(tmp_path / f"p.{fmt}")
        assert getattr(traj, f"to_{fmt}")(given) == Path(given)
    path = tmp_path / "p.json"
    text = traj.to_json(path)
    assert text == traj.to_json() and path.read_text() == text + "\n"
    assert export.__doc__ is not None and "Every writer takes a path and returns it" not in export.__doc__


@pytest.mark.parametrize("fmt", ["json", "npz", "csv"])
def test_samples_match_the_trajectory(traj: avp.Trajectory, tmp_path: Path, fmt: str) -> None:
    """Sampled exports against independent evaluations: flat outputs from the polynomial with
    numpy (not the Rust kernel), the attitude's b3 from the thrust vector, quaternion unit norm."""
    path = tmp_path / f"s.{fmt}"
    getattr(traj, f"to_{fmt}")(path, rate=250.0)
    s = export.read_samples(path)
    assert set(s) == set(export.SAMPLE_COLUMNS)
    t = s["t"]
    assert t[0] == traj.t0 and t[-1] == traj.tf and np.allclose(np.diff(t)[:-1], 1 / 250.0, atol=1e-12)
    seg = np.clip(np.searchsorted(traj.knots, t, side="right") - 1, 0, traj.n_segments - 1)
    tau = t - traj.knots[seg]
    for axis, (pos, vel) in enumerate((("x", "vx"), ("y", "vy"), ("z", "vz"), ("yaw", "yaw_rate"))):
        c = traj.coefficients[seg, axis]  # (n, N + 1), ascending
        powers = tau[:, None] ** np.arange(c.shape[1])
        assert np.allclose(s[pos], np.sum(c * powers, axis=1), rtol=0, atol=1e-12 * (1 + np.abs(s[pos]).max()))
        dc = c[:, 1:] * np.arange(1, c.shape[1])
        dv = np.sum(dc * tau[:, None] ** np.arange(dc.shape[1]), axis=1)
        assert np.allclose(s[vel], dv, rtol=0, atol=1e-12 * (1 + np.abs(dv).max()))
    q = np.column_stack([s["qw"], s["qx"], s["qy"], s["qz"]])
    assert np.allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-12)
    w, x, y, z = q.T
    b3 = np.column_stack([2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)])
    f = np.column_stack([s["ax"], s["ay"], s["az"] + traj.g])
    assert np.allclose(b3, f / np.linalg.norm(f, axis=1)[:, None], atol=1e-9)
    assert np.allclose(s["thrust"], np.linalg.norm(f, axis=1), atol=1e-12 * 20)
    assert np.allclose(np.column_stack([s["wx"], s["wy"], s["wz"]]), traj.body_rates(t), atol=1e-12)


def test_sampled_csv_is_not_a_polynomial(traj: avp.Trajectory, tmp_path: Path) -> None:
    path = tmp_path / "s.csv"
    traj.to_csv(path, rate=50)
    with pytest.raises(ConfigError, match="read_samples"):
        avp.Trajectory.from_csv(path)


@pytest.mark.parametrize("bad", [0.0, -5.0, math.inf, math.nan])
def test_bad_rate_is_a_config_error(traj: avp.Trajectory, tmp_path: Path, bad: float) -> None:
    with pytest.raises(ConfigError, match="rate"):
        traj.to_npz(tmp_path / "x.npz", rate=bad)
    with pytest.raises(ConfigError, match="rate"):
        traj.to_csv(tmp_path / "x.csv", rate=bad)
    assert not (tmp_path / "x.csv").exists()  # no empty file left behind


@pytest.mark.parametrize("fmt", ["json", "npz", "csv"])
def test_a_rate_beyond_the_export_cap_is_refused_with_the_highest_rate(traj: avp.Trajectory, tmp_path: Path,
                                                                        fmt: str) -> None:
    """The cap was Trajectory.sample's 10^7 rows (a 2 s perch at 100 kHz took 6 s and 1 GB for a
    137 MB JSON); an export holds MAX_EXPORT_SAMPLES rows and the error gives the highest rate."""
    path = tmp_path / f"x.{fmt}"
    with pytest.raises(ConfigError, match="at most 100000 .*give a rate of at most") as exc:
        getattr(traj, f"to_{fmt}")(path, rate=1e5)
    assert exc.value.field == "rate" and not path.exists()
    top = float(str(exc.value).split("rate of at most ")[1].split(" Hz")[0])
    assert len(export.sample_table(traj, top)) <= export.MAX_EXPORT_SAMPLES == 10**5
    with pytest.raises(ConfigError, match="rate"):
        export.sample_table(traj, top * 1.001)


@pytest.mark.parametrize("fmt", ["json", "npz", "csv"])
def test_unwritable_path_is_a_config_error(traj: avp.Trajectory, tmp_path: Path, fmt: str) -> None:
    """A missing directory or a file where a directory should be: a ConfigError on ``path`` with
    the operating system's reason, not a raw OSError."""
    (tmp_path / "afile").write_text("")
    for where, reason in ((tmp_path / "missing" / f"x.{fmt}", "No such file"),
                          (tmp_path / "afile" / f"x.{fmt}", "Not a directory")):
        with pytest.raises(ConfigError, match=f"cannot write .*{reason}") as exc:
            getattr(traj, f"to_{fmt}")(where)
        assert exc.value.field == "path" and isinstance(exc.value.__cause__, OSError)


@pytest.mark.parametrize(("fmt", "field"), [("json", "source"), ("npz", "path"), ("csv", "path")])
def test_missing_file_is_a_config_error(tmp_path: Path, fmt: str, field: str) -> None:
    with pytest.raises(ConfigError, match="No such file") as exc:
        getattr(avp.Trajectory, f"from_{fmt}")(tmp_path / f"missing.{fmt}")
    assert exc.value.field == field
    with pytest.raises(ConfigError, match="cannot read") as exc:
        export.read_samples(tmp_path / f"missing.{fmt}")
    assert exc.value.field == "path"


@pytest.mark.parametrize("call", [lambda tr: tr.to_npz(None), lambda tr: tr.to_csv(None), lambda tr: tr.to_json(123),
                                  lambda tr: tr.to_npz(b"x.npz"), lambda tr: tr.to_csv(b"x.csv", rate=10.0),
                                  lambda tr: avp.Trajectory.from_npz(None), lambda tr: avp.Trajectory.from_csv(None),
                                  lambda tr: export.read_samples(None), lambda tr: export.read_samples(b"x.csv")])
def test_a_path_that_is_no_file_name_is_a_config_error(traj: avp.Trajectory, call) -> None:
    """``None``, bytes or a number as a path raised TypeError (``from_json(None)`` already was a
    ConfigError on ``source``)."""
    with pytest.raises(ConfigError, match="str or pathlib.Path") as exc:
        call(traj)
    assert exc.value.field == "path"


@pytest.mark.parametrize("bad", ["x", "  x", True, 1.5, [2]])
def test_an_indent_that_makes_no_json_is_a_config_error(traj: avp.Trajectory, bad) -> None:
    """``to_json(indent="x")`` wrote text that ``from_json`` cannot read."""
    with pytest.raises(ConfigError) as exc:
        traj.to_json(indent=bad)
    assert exc.value.field == "indent"
    for good in (None, 0, 2, np.int64(4), "\t", "  "):
        assert avp.Trajectory.from_json(traj.to_json(indent=good)).duration == traj.duration


def _spline(acceleration: list[float], scale: float = 1.0) -> avp.Trajectory:
    """One segment of constant ``acceleration`` (from rest at (0, 0, 10)), all coefficients
    times ``scale``."""
    c = np.zeros((1, 4, 8))
    c[0, 2, 0] = 10.0
    c[0, :3, 2] = np.asarray(acceleration) / 2.0
    return avp.Trajectory(c * scale if scale != 1.0 else c, [0.0, 1.0])


@pytest.mark.parametrize(("traj_of", "why"), [
    (lambda: _spline([0.0, 0.0, -avp.frames.GRAVITY]), "vanishes"),  # free fall
    (lambda: _spline([0.0, 3.0, -avp.frames.GRAVITY]), "along b2_des"),  # b3 = y at yaw 0: no b1
    (lambda: avp.Trajectory(np.full((1, 4, 8), 1e300), [0.0, 1.0]), "overflow"),
])
@pytest.mark.parametrize("fmt", ["json", "npz", "csv"])
def test_samples_where_the_attitude_is_undefined_are_a_config_error(tmp_path: Path, traj_of, why: str,
                                                                    fmt: str) -> None:
    """A valid spline whose thrust vanishes (or overflows) had NaN attitudes, which scipy's
    Rotation.from_matrix refused with LinAlgError: a ConfigError on ``trajectory`` at the time."""
    traj = traj_of()
    path = tmp_path / f"x.{fmt}"
    with pytest.raises(ConfigError, match=f"t = 0.0 s .*{why}.*no rate") as exc:
        getattr(traj, f"to_{fmt}")(path, rate=10.0)
    assert exc.value.field == "trajectory" and not path.exists()
    getattr(traj, f"to_{fmt}")(path)  # the coefficients export it exactly
    assert np.array_equal(getattr(avp.Trajectory, f"from_{fmt}")(path).coefficients, traj.coefficients)


def test_foreign_json_is_rejected() -> None:
    with pytest.raises(ConfigError, match="format"):
        avp.Trajectory.from_json('{"knots": [0, 1], "coefficients": [[[0], [0], [0], [0]]]}')


def test_rotorpy_example_flies_or_says_how_to_install(tmp_path: Path) -> None:
    proc = subprocess.run([sys.executable, str(EXAMPLES / "fly_in_rotorpy.py")], capture_output=True,
                          text=True, timeout=300, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    if importlib.util.find_spec("rotorpy") is None:
        assert 'pip install "avp[rotorpy]"' in proc.stdout
        return
    line = proc.stdout.strip().splitlines()[-1]
    assert line.startswith("rotorpy flew")
    pos_cm = float(line.split("position error ")[1].split(" cm")[0])
    tilt = float(line.split("b3 vs s3 ")[1].split(" deg")[0])
    # an independent simulator and controller reach the pad with the plan (45 deg: 1.0 cm and
    # 8.5 deg measured; rotorpy's controller lags the attitude, see the example's docstring)
    assert pos_cm < 5.0 and tilt < 15.0


def test_rotorpy_example_without_rotorpy_exits_cleanly(tmp_path: Path) -> None:
    code = ("import sys, runpy; sys.modules['rotorpy'] = None; sys.argv = ['fly_in_rotorpy.py'];"
            f"runpy.run_path({str(EXAMPLES / 'fly_in_rotorpy.py')!r}, run_name='__main__')")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert 'pip install "avp[rotorpy]"' in proc.stdout


def test_sampled_exports_carry_the_drag_thrust_when_asked() -> None:
    """With ``rotor_drag`` the exported thrust, attitude and body rates are those of the thrust
    ``a + g e3 + d v`` the planner certifies: at contact ``b3`` is the pad normal (the drag-free
    samples put it 16 deg off on this wall); without it nothing changes."""
    target = avp.PerchTarget.from_incline([3.5, 0.0, 1.5], math.pi / 2)
    res = avp.plan_detailed(avp.State.hover([0.0, 0.0, 1.5]), target,
                            avp.PlannerConfig(limits=avp.VehicleLimits(rotor_drag=0.6)))
    traj = res.trajectory
    data = json.loads(traj.to_json(rate=100.0, rotor_drag=0.6))
    assert data["samples_rotor_drag"] == 0.6
    cols = {k: np.asarray(v) for k, v in data["samples"].items()}
    t = cols["t"]
    D = traj.derivatives(t, (1, 2))
    f = D[1][:, :3] + 0.6 * D[0][:, :3] + [0.0, 0.0, traj.g]
    np.testing.assert_allclose(cols["thrust"], np.linalg.norm(f, axis=1), rtol=1e-13)
    q = np.column_stack([cols["qx"], cols["qy"], cols["qz"], cols["qw"]])
    from scipy.spatial.transform import Rotation

    b3 = Rotation.from_quat(q[-1]).as_matrix()[:, 2]
    assert float(b3 @ target.s3) > 1 - 1e-12
    plain = export.sample_table(traj, 100.0)
    np.testing.assert_array_equal(plain[:, export.SAMPLE_COLUMNS.index("thrust")], traj.thrust(t))


@pytest.mark.parametrize("name,content", [("bad.json", "{not json"), ("bad.csv", None), ("bad.npz", "not a zip"),
                                          ("list.json", "[1, 2]")])
def test_a_damaged_sample_file_is_a_config_error(traj: avp.Trajectory, tmp_path: Path, name, content) -> None:
    """Invalid JSON, a non-numeric CSV cell or a corrupt NPZ raised raw JSONDecodeError /
    ValueError; each is a ConfigError on ``path`` now."""
    from avp.export import SAMPLE_COLUMNS, read_samples

    path = tmp_path / name
    if content is None:  # the right header, a cell that is no number
        path.write_text(",".join(SAMPLE_COLUMNS) + "\n" + ",".join(["x"] * len(SAMPLE_COLUMNS)) + "\n")
    else:
        path.write_text(content)
    with pytest.raises(ConfigError) as exc:
        read_samples(path)
    assert exc.value.field == "path"


def test_an_upper_case_suffix_reads_as_its_format(traj: avp.Trajectory, tmp_path: Path) -> None:
    from avp.export import read_samples

    traj.to_npz(tmp_path / "s.NPZ", rate=50.0)
    assert read_samples(tmp_path / "s.NPZ")["t"].size > 2
