"""Exports of a :class:`~avp.trajectory.Trajectory` for other tools, and loaders back.

Two forms:

- **coefficients** (exact): the knots and the ``(S, 4, N + 1)`` ascending-power coefficients of
  x, y, z, yaw per segment (local time ``t - t_i``), and ``g``. JSON and NPZ also store ``t0``
  and ``knots_rel`` (:attr:`~avp.trajectory.Trajectory.knots_rel`), which they read back in
  place of the absolute knots (which must agree with them to the clock's rounding: a document
  edited in one place only is refused): the segment durations stay exact at any clock value (CSV's
  ``t_start``, ``t_end`` are absolute, so at a clock value ``c`` they round a duration by up
  to ``ulp(c)``, 2.4e-7 s at UNIX time). JSON and NPZ also keep the
  trajectory's provenance (status, relaxations, certificates) when the planner recorded one. JSON writes floats with Python's
  shortest round-trip representation, NPZ stores the float64 arrays, CSV writes one row per
  segment and flat output with ``repr`` floats, so loading back gives bit-identical coefficients.
- **samples** at a rate (Hz): one row per time with the flat outputs and derivatives, the
  mass-normalised thrust (10), the attitude ``R_WB`` (11) as a quaternion ``(qw, qx, qy, qz)``
  and the body rates (22) in B. :func:`read_samples` loads them back as named arrays. Samples are
  always finite: a trajectory whose attitude is undefined at a sample time (zero thrust: a free
  fall) is refused with a :class:`~avp.errors.ConfigError` on ``trajectory`` naming that time.

:func:`write_csv` and :func:`write_npz` (``Trajectory.to_csv``, ``to_npz``) take a path and
return it as a :class:`~pathlib.Path`; :func:`write_json` (``Trajectory.to_json``) returns the
JSON text, with or without a path, and with one also writes that text (and a final newline)
there. A path that cannot be written or read (a missing directory, a file where a directory
should be, no permission) is a :class:`~avp.errors.ConfigError` on ``path`` (``source`` for
:func:`read_json`) that carries the operating system's message; so is a path that is no file
name (``None`` where a path is required, bytes, a number: give a ``str`` or a ``pathlib.Path``).
The ``Trajectory`` methods ``to_csv``, ``to_json``, ``to_npz``, ``from_csv``, ``from_json``,
``from_npz`` call these functions.
"""

from __future__ import annotations

import csv
import json
import math
import os
import zipfile
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from . import _validate as v
from ._typing import Array
from .errors import ConfigError

if TYPE_CHECKING:  # pragma: no cover
    from .trajectory import Trajectory

__all__ = [
    "FORMAT",
    "MAX_EXPORT_SAMPLES",
    "SAMPLE_COLUMNS",
    "read_samples",
    "sample_table",
    "trajectory_from_dict",
    "trajectory_to_dict",
]


FORMAT = "avp.trajectory"
VERSION = 1

SAMPLE_COLUMNS = (
    "t", "x", "y", "z", "yaw",
    "vx", "vy", "vz", "yaw_rate",
    "ax", "ay", "az", "yaw_acceleration",
    "jx", "jy", "jz", "sx", "sy", "sz",
    "thrust", "qw", "qx", "qy", "qz", "wx", "wy", "wz",
)
"""Columns of a sampled export: time (s); position (m), yaw (rad); velocity (m/s), yaw rate
(rad/s); acceleration (m/s^2), yaw acceleration (rad/s^2); jerk (m/s^3); snap (m/s^4);
mass-normalised thrust (m/s^2); attitude quaternion ``R_WB`` (scalar first); body rates (rad/s, B)."""


MAX_EXPORT_SAMPLES = 10**5
"""Most rows a sampled export holds (the ``rate`` times the duration, plus one). Measured per
10^5 rows of the 27 :data:`SAMPLE_COLUMNS`: JSON about 2 s, 220 MB of memory and a 60 MB file;
CSV 2.6 s, 65 MB, 56 MB; NPZ 0.2 s, 65 MB, 22 MB (time and memory grow linearly). A perch of a
few seconds at 10 kHz fits; a higher rate is refused before anything is sampled."""

_WRITE_HINT = "give a file name in an existing directory you can write to"
_READ_HINT = "give the path of an existing, readable file"


@contextmanager
def _file_errors(field: str, path: Any, verb: str, hint: str) -> Iterator[None]:
    """An :class:`OSError` of the block (``path`` missing, its directory missing or a file, no
    permission) as a :class:`ConfigError` on ``field`` that says what to do."""
    try:
        yield
    except OSError as exc:
        raise ConfigError(field, f"cannot {verb} {str(path)!r}: {exc.strerror or exc}; {hint}") from exc


def _path(path: Any, field: str = "path") -> Path:
    """``path`` (a ``str`` or an ``os.PathLike`` of one) as a :class:`Path`; anything else (``None``,
    bytes, a number) is a :class:`ConfigError` on ``field``."""
    if isinstance(path, (str, os.PathLike)):
        try:
            return Path(path)
        except TypeError:  # an os.PathLike of bytes
            pass
    raise ConfigError(field, f"expected a file name (str or pathlib.Path), got {type(path).__name__} {path!r:.60}")


def _indent(indent: Any) -> int | str | None:
    """``json.dumps``'s ``indent``: ``None`` (one line), a whole number of spaces (<= 0: newlines
    only) or a string of JSON whitespace; any other string would make text that is no JSON."""
    if indent is None or (isinstance(indent, str) and indent.strip(" \t\n\r") == ""):
        return indent
    if isinstance(indent, (int, np.integer)) and not isinstance(indent, (bool, np.bool_)):
        return int(indent)
    raise ConfigError("indent", f"expected None, a number of spaces or a string of spaces and tabs (JSON "
                                f"whitespace), got {indent!r:.60}")


def _times(traj: Trajectory, rate: float) -> Array:
    if not (isinstance(rate, (int, float)) and math.isfinite(rate) and rate > 0):
        raise ConfigError("rate", f"must be a positive sample rate in Hz, got {rate!r}")
    span = traj.duration * float(rate)  # steps before rounding; compared as a float (1e308 Hz overflows ceil)
    steps = max(1, math.ceil(span - 1e-9)) if span < MAX_EXPORT_SAMPLES else MAX_EXPORT_SAMPLES
    if steps + 1 > MAX_EXPORT_SAMPLES:
        top = (MAX_EXPORT_SAMPLES - 1) / traj.duration
        hint = f"{math.floor(top)}" if top >= 1.0 else f"{top * 0.999:.3g}"
        raise ConfigError("rate", f"would sample {span + 1:.3g} rows over {traj.duration:.4g} s at {rate:g} Hz; an "
                                  f"export holds at most {MAX_EXPORT_SAMPLES} (avp.export.MAX_EXPORT_SAMPLES): give a "
                                  f"rate of at most {hint} Hz, or export the exact coefficients (no rate)")
    try:
        return traj.sample(1.0 / float(rate))
    except ConfigError as exc:  # too many samples: the rate is what the caller set
        raise ConfigError("rate", f"{rate:g} Hz: {exc.message}") from exc


def sample_table(traj: Trajectory, rate: float, rotor_drag: float = 0.0) -> Array:
    """``(n, len(SAMPLE_COLUMNS))`` samples at ``rate`` Hz from ``t0`` to ``tf`` (both included);
    thrust, attitude and body rates with the vehicle's ``rotor_drag`` (1/s,
    ``VehicleLimits.rotor_drag``: the thrust ``a + g e3 + d v`` the planner certifies; 0: the
    drag-free map (11)).

    Every sample is finite: where the attitude is undefined, a thrust that vanishes (a free fall,
    ``a + g e3 = 0``), overflows, or lies along ``b2_des`` of (13) (a roll of +-90 deg), the samples are refused with a
    :class:`ConfigError` on ``trajectory`` naming the first such time (the coefficient export,
    without a rate, still holds the trajectory exactly)."""
    from scipy.spatial.transform import Rotation  # type: ignore[import-untyped]

    t = _times(traj, rate)
    with np.errstate(all="ignore"):  # an undefined attitude is NaN: refused below, at its time
        d = traj.derivatives(t)  # (5, n, 4)
        R = traj.attitude(t, rotor_drag=rotor_drag)
        thrust = traj.thrust(t, rotor_drag=rotor_drag)
        omega = traj.body_rates(t, rotor_drag=rotor_drag)
    _check_finite(t, d, thrust, R, omega)
    q_xyzw = Rotation.from_matrix(R).as_quat()
    return np.column_stack([
        t, d[0], d[1], d[2], d[3, :, :3], d[4, :, :3],
        thrust, q_xyzw[:, 3], q_xyzw[:, :3], omega,
    ])


def _check_finite(t: Array, d: Array, thrust: Array, R: Array, omega: Array) -> None:
    """A :class:`ConfigError` on ``trajectory`` at the first sample time with a value that is not
    finite, saying why (:func:`sample_table`)."""
    outputs = np.isfinite(d).all(axis=(0, 2)) & np.isfinite(thrust)
    ok = outputs & np.isfinite(R).all(axis=(1, 2)) & np.isfinite(omega).all(axis=1)
    if ok.all():
        return
    k = int(np.argmin(ok))
    if not outputs[k]:
        why = "the flat outputs or the thrust overflow (not finite)"
    elif thrust[k] == 0.0:
        why = "the thrust a + g e3 vanishes (free fall), so the attitude (11) and body rates are undefined"
    else:
        why = "the attitude (11), (13) is undefined (the thrust along b2_des: a roll of +-90 deg)"
    raise ConfigError("trajectory", f"cannot sample at t = {float(t[k])!r} s ({int(np.sum(~ok))} of {ok.size} "
                                    f"samples): {why}; export the exact coefficients (no rate), or sample a "
                                    "trajectory whose thrust stays finite and nonzero")


def trajectory_to_dict(traj: Trajectory, rate: float | None = None, rotor_drag: float = 0.0) -> dict[str, Any]:
    """JSON-ready dict: format tag, ``g``, knots, coefficients, the provenance if the trajectory
    has one, and with ``rate`` (Hz) a ``samples`` table ``{column: [values]}`` and the
    ``rotor_drag`` its thrust, attitude and body rates were computed with."""
    out: dict[str, Any] = {
        "format": FORMAT,
        "version": VERSION,
        "g": traj.g,
        "knots": traj.knots.tolist(),
        "t0": traj.t0,
        "knots_rel": traj.knots_rel.tolist(),
        "coefficients": traj.coefficients.tolist(),
    }
    prov = getattr(traj, "provenance", None)
    if prov is not None:
        from .configfile import to_mapping

        out["provenance"] = to_mapping(prov)
    if rate is not None:
        table = sample_table(traj, rate, rotor_drag)
        out["samples"] = {name: table[:, k].tolist() for k, name in enumerate(SAMPLE_COLUMNS)}
        out["samples_rotor_drag"] = float(rotor_drag)
    return out


def trajectory_from_dict(data: Mapping[str, Any]) -> Trajectory:
    """The trajectory of a :func:`trajectory_to_dict` dict (samples, if any, are ignored). The
    result document of ``avp ... --json`` is refused with a message that points at its
    ``trajectory`` entry and at ``--export``, which writes a loadable plan."""

    if isinstance(data, Mapping) and "format" not in data and "command" in data:
        raise ConfigError("format", _cli_result_message(data))
    if not isinstance(data, Mapping) or data.get("format") != FORMAT:
        raise ConfigError("format", f"not an {FORMAT} document (expected a 'format': '{FORMAT}' entry)")
    if data.get("version") != VERSION:
        raise ConfigError("version", f"unsupported version {data.get('version')!r}; this avp reads {VERSION}")
    for key in ("knots", "coefficients", "g"):
        if key not in data:
            raise ConfigError(key, "missing from the trajectory document")
    traj = _from_knots(data["coefficients"], data["knots"], data.get("t0"), data.get("knots_rel"), data["g"])
    _restore_provenance(traj, data.get("provenance"))
    return traj


def _cli_result_message(doc: Mapping[str, Any]) -> str:
    """Why the result document of ``avp COMMAND --json`` is no trajectory document, and what to load instead."""
    what = f"the result document of avp {doc['command']} --json, not an {FORMAT} document"
    if doc.get("trajectory") is not None:
        return (f"{what}: its plan is under 'trajectory' (load it with avp.export.trajectory_from_dict("
                "doc['trajectory'])); avp demo --export FILE.json writes a plan that Trajectory.from_json loads")
    if "trajectory" in doc:
        return f"{what}: it holds no plan ('trajectory' is null: the planner found none)"
    return f"{what}: it holds no plan; avp demo --export FILE.json writes one that Trajectory.from_json loads"


def _from_knots(coefficients: Any, knots: Any, t0: Any, knots_rel: Any, g: Any) -> Trajectory:
    """The trajectory on ``t0 + knots_rel`` when the document has them (exact durations), else
    on the absolute ``knots`` (documents written before they were stored)."""
    from .trajectory import Trajectory

    gravity = v.finite_float("g", g)
    if t0 is None or knots_rel is None:
        return Trajectory(coefficients, knots, g=gravity)
    traj = Trajectory.from_relative_knots(coefficients, knots_rel, t0=t0, g=gravity)
    # the absolute knots must be the same spline's (a document edited in one place only would
    # otherwise load on knots it does not show): equal to t0 + knots_rel up to the clock's rounding
    given = v.frozen_array("knots", knots, traj.knots.shape)
    gap = float(np.max(np.abs(given - traj.knots)))
    resolution = 4.0 * math.ulp(max(abs(traj.t0), abs(traj.tf), 1.0))
    if not gap <= resolution:
        raise ConfigError("knots", f"differ from t0 + knots_rel by up to {gap:.3g} s (the clock resolves "
                                   f"{resolution:.1g} s): an edited document must change both, or drop "
                                   "t0 and knots_rel to load on the knots alone")
    return traj


def _restore_provenance(traj: Trajectory, data: Any) -> None:
    """Set ``traj.provenance`` from its exported mapping (planners that record one)."""
    if data is None:
        return
    from . import trajectory as tr_mod
    from .configfile import from_mapping

    cls = getattr(tr_mod, "Provenance", None)
    if cls is not None:
        traj.provenance = from_mapping(cls, data, "provenance")


def write_json(traj: Trajectory, path: str | Path | None = None, rate: float | None = None,
               indent: int | None = None, rotor_drag: float = 0.0) -> str:
    """The JSON text of :func:`trajectory_to_dict`; also written to ``path`` if given."""
    target = _path(path) if path is not None else None
    text = json.dumps(trajectory_to_dict(traj, rate, rotor_drag), indent=_indent(indent), allow_nan=False)
    if target is not None:
        with _file_errors("path", path, "write", _WRITE_HINT):
            target.write_text(text + "\n")
    return text


def read_json(source: str | Path) -> Trajectory:
    """From a path, or from JSON text (a string starting with ``{``)."""
    if not isinstance(source, (str, Path)):
        raise ConfigError("source", f"expected a path or JSON text, got {type(source).__name__}")
    is_text = isinstance(source, str) and source.lstrip().startswith("{")
    with _file_errors("source", source, "read", _READ_HINT):
        text = str(source) if is_text else Path(source).read_text()
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ConfigError("json", f"not valid JSON: {exc}") from exc
    if not isinstance(data, dict):
        raise ConfigError("json", f"expected a JSON object (avp.export format), got {type(data).__name__}")
    return trajectory_from_dict(data)


def write_npz(traj: Trajectory, path: str | Path, rate: float | None = None, rotor_drag: float = 0.0) -> Path:
    """``coefficients``, ``knots``, ``t0``, ``knots_rel``, ``g`` and, with ``rate``, ``samples`` plus ``columns``."""
    p = _path(path)
    arrays: dict[str, Any] = {"format": np.array(FORMAT), "version": np.array(VERSION),
                              "coefficients": traj.coefficients, "knots": traj.knots, "t0": np.array(traj.t0),
                              "knots_rel": traj.knots_rel, "g": np.array(traj.g)}
    prov = getattr(traj, "provenance", None)
    if prov is not None:
        from .configfile import to_mapping

        arrays["provenance"] = np.array(json.dumps(to_mapping(prov)))
    if rate is not None:
        arrays["samples"] = sample_table(traj, rate, rotor_drag)
        arrays["columns"] = np.array(SAMPLE_COLUMNS)
        arrays["samples_rotor_drag"] = np.array(float(rotor_drag))
    with _file_errors("path", path, "write", _WRITE_HINT), p.open("wb") as fh:
        np.savez(fh, **arrays)  # a file object: numpy does not append ".npz" to the name
    return p


def read_npz(path: str | Path) -> Trajectory:

    _path(path)
    try:
        z = np.load(path, allow_pickle=False)
    except (OSError, ValueError, zipfile.BadZipFile) as exc:  # missing, unreadable, not an NPZ
        raise ConfigError("path", f"{str(path)!r} is not a readable {FORMAT} NPZ file: {exc}") from exc
    if not isinstance(z, np.lib.npyio.NpzFile):
        raise ConfigError("path", f"{str(path)!r} is a single array, not an {FORMAT} NPZ file")
    with z:
        if "format" not in z.files or str(z["format"]) != FORMAT:
            raise ConfigError("path", f"{str(path)!r} is not an {FORMAT} NPZ file")
        exact = "t0" in z.files and "knots_rel" in z.files
        traj = _from_knots(z["coefficients"], z["knots"], z["t0"] if exact else None,
                           z["knots_rel"] if exact else None, z["g"])
        if "provenance" in z.files:
            _restore_provenance(traj, json.loads(str(z["provenance"])))
        return traj


COEFFICIENT_HEADER = ("segment", "output", "t_start", "t_end", "g")


def write_csv(traj: Trajectory, path: str | Path, rate: float | None = None, rotor_drag: float = 0.0) -> Path:
    """With ``rate`` (Hz): one row per sample, columns :data:`SAMPLE_COLUMNS`. Without: one row per
    segment and flat output (``x, y, z, yaw``) with ``t_start, t_end, g, c0 ... cN`` (ascending
    powers of ``t - t_start``), which :func:`read_csv` turns back into the trajectory."""
    p = _path(path)
    table = sample_table(traj, rate, rotor_drag) if rate is not None else None  # a bad rate writes no file
    with _file_errors("path", path, "write", _WRITE_HINT), p.open("w", newline="") as fh:
        w = csv.writer(fh)
        if table is not None:
            w.writerow(SAMPLE_COLUMNS)
            for row in table:
                w.writerow([repr(float(x)) for x in row])
            return p
        w.writerow([*COEFFICIENT_HEADER, *(f"c{k}" for k in range(traj.degree + 1))])
        for s in range(traj.n_segments):
            for i, name in enumerate(("x", "y", "z", "yaw")):
                w.writerow([s, name, repr(float(traj.knots[s])), repr(float(traj.knots[s + 1])), repr(traj.g),
                            *(repr(float(c)) for c in traj.coefficients[s, i])])
    return p


def read_csv(path: str | Path) -> Trajectory:
    from .trajectory import Trajectory

    with _file_errors("path", path, "read", _READ_HINT), _path(path).open(newline="") as fh:
        rows = list(csv.reader(fh))
    if not rows or tuple(rows[0][: len(COEFFICIENT_HEADER)]) != COEFFICIENT_HEADER:
        raise ConfigError("path", f"{str(path)!r} is not a coefficient CSV (header {COEFFICIENT_HEADER}...); "
                                  "a sampled CSV has no polynomial: load it with avp.export.read_samples")
    body = rows[1:]
    n_seg = len(body) // 4
    if n_seg == 0 or len(body) != 4 * n_seg:
        raise ConfigError("path", f"{str(path)!r}: expected 4 rows (x, y, z, yaw) per segment, got {len(body)}")
    width = len(rows[0])
    for i, r in enumerate(body):
        if len(r) != width:
            raise ConfigError("path", f"{str(path)!r}: row {i + 2} has {len(r)} fields, the header {width}")
    try:
        coeffs = np.array([[float(x) for x in r[len(COEFFICIENT_HEADER):]] for r in body]).reshape(n_seg, 4, -1)
        knots = [float(body[4 * s][2]) for s in range(n_seg)] + [float(body[-1][3])]
        g = float(body[0][4])
    except ValueError as exc:
        raise ConfigError("path", f"{str(path)!r}: a field is not a number ({exc})") from exc
    return Trajectory(coeffs, knots, g=g)


def read_samples(path: str | Path) -> dict[str, Array]:
    """Sampled data of a CSV, JSON or NPZ export as ``{column: array}`` (:data:`SAMPLE_COLUMNS`)."""
    p = _path(path)
    suffix = p.suffix.lower()
    try:
        if suffix == ".npz":
            with _file_errors("path", p, "read", _READ_HINT):
                z = np.load(p, allow_pickle=False)
            with z:
                if "samples" not in z.files:
                    raise ConfigError("path", f"{str(p)!r} holds no samples (written without a rate)")
                return {str(c): z["samples"][:, k].copy() for k, c in enumerate(z["columns"])}
        if suffix == ".json":
            with _file_errors("path", p, "read", _READ_HINT):
                text = p.read_text()
            data = json.loads(text)
            if not isinstance(data, dict) or "samples" not in data:
                raise ConfigError("path", f"{str(p)!r} holds no samples (written without a rate)")
            return {k: np.asarray(val, dtype=float) for k, val in data["samples"].items()}
        with _file_errors("path", p, "read", _READ_HINT), p.open(newline="") as fh:
            rows = list(csv.reader(fh))
        if not rows or tuple(rows[0]) != SAMPLE_COLUMNS:
            raise ConfigError("path", f"{str(p)!r} is not a sampled CSV (header {SAMPLE_COLUMNS[:3]}...)")
        table = np.array([[float(x) for x in r] for r in rows[1:]], dtype=float).reshape(-1, len(SAMPLE_COLUMNS))
        return {name: table[:, k] for k, name in enumerate(SAMPLE_COLUMNS)}
    except (ValueError, KeyError, AttributeError, TypeError, zipfile.BadZipFile) as exc:  # a damaged file
        if isinstance(exc, ConfigError):
            raise
        raise ConfigError("path", f"{str(p)!r} is not a readable sample export ({type(exc).__name__}: {exc}); "
                                  "give a file written by to_csv/to_json/to_npz with a rate") from exc
