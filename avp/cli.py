"""Command line: ``avp demo`` (one perch, summary, plot), ``avp simulate`` (seeded closed-loop
trials, one-shot planning vs AVP) and ``avp campaign`` (a grid x seeds of trials on a process
pool or Ray, resumable results, summary).

``avp --help`` and ``avp COMMAND --help`` list the flags with their defaults. Every planner,
vehicle, camera, replanner and line-perch knob can be set from a TOML file (``--config``, see
``docs/configuration.md``); the common ones also from flags, which win over the file. Degrees
appear only here (``--incline-deg``, ``--camera-half-fov-deg``); everything else is SI.

Exit codes (:data:`EXIT_CODES`): 0 a plan that meets every constraint and certificate, 3 a plan
that needed a relaxation, 1 no certified plan, 2 bad input (usage, configuration, or a path of
:data:`PATH_FLAGS` that cannot be written or read; :func:`main` reports each as one error line).
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import os
import re
import signal
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .cli_line import add_line_flags, line_demo, line_simulate
from .config import GROUND_CLEARANCE
from .configfile import Settings, load_settings, merge, to_mapping
from .errors import AvpError, ConfigError
from .export import trajectory_to_dict

__all__ = ["EXIT_CODES", "EXIT_FAILED", "EXIT_RELAXED", "EXIT_SOLVED", "EXIT_USAGE", "main", "plan_exit_code"]

EXIT_SOLVED = 0
EXIT_FAILED = 1
EXIT_USAGE = 2
EXIT_RELAXED = 3
EXIT_CODES = {
    EXIT_SOLVED: "solved: every constraint and certificate met",
    EXIT_FAILED: "no certified plan (infeasible, solver failure, or a certificate failed)",
    EXIT_USAGE: "bad input: usage or configuration error, or a path that cannot be written or read",
    EXIT_RELAXED: "solved after relaxing a soft constraint (slide, band or contact thrust range)",
}

EXECUTION_BACKENDS = ("auto", "serial", "pool", "ray")
"""``--backend`` values: where the trials run."""
SIMULATORS = ("avp", "rotorpy")
"""``--simulator`` values (:class:`avp.sim.backend.Backend`); ``--backend`` takes them too."""

PLOT_HINT = "matplotlib is not installed: pip install \"avp[plot]\" (or pip install matplotlib) for plots"

log = logging.getLogger("avp.cli")


# -- exit codes -------------------------------------------------------------------------------

def plan_exit_code(result: Any) -> int:
    """:data:`EXIT_SOLVED`, :data:`EXIT_RELAXED` or :data:`EXIT_FAILED` for a
    :class:`~avp.planner.PlanResult`. A plan is relaxed when its status is ``SOLVED_RELAXED`` or,
    with planners that report relaxations only in ``result.relaxations``, when that is non-empty;
    it fails when it has no trajectory or a certificate (bounds, workspace) is not met."""
    if not result.ok:
        return EXIT_FAILED
    bounds = getattr(result, "bounds", None)
    if bounds is not None and not bounds.certified:
        return EXIT_FAILED
    safety = getattr(result, "safety", None)
    if safety is not None and not getattr(safety, "certified", True):
        return EXIT_FAILED
    if result.status.name == "SOLVED_RELAXED" or tuple(getattr(result, "relaxations", ())):
        return EXIT_RELAXED
    return EXIT_SOLVED


def plan_label(result: Any) -> str:
    """``"SOLVED"``, ``"RELAXED"`` or ``"FAILED"``: how a plot and the summary mark the plan."""
    return {EXIT_SOLVED: "SOLVED", EXIT_RELAXED: "RELAXED"}.get(plan_exit_code(result), "FAILED")


# -- logging and progress ---------------------------------------------------------------------

class _Below(logging.Filter):
    def __init__(self, level: int) -> None:
        super().__init__()
        self.level = level

    def filter(self, record: logging.LogRecord) -> bool:
        return record.levelno < self.level


def _setup_logging(verbose: int, quiet: bool, machine_output: bool) -> None:
    """Messages of the ``avp`` loggers: INFO and DEBUG to stdout (the human summary), WARNING and
    above to stderr. ``-q``: warnings only; ``-v``: also debug lines (the planner's log). With
    ``--json`` stdout carries only the JSON document."""
    level = logging.WARNING if quiet or machine_output else (logging.DEBUG if verbose else logging.INFO)
    logger = logging.getLogger("avp")
    for h in list(logger.handlers):
        if getattr(h, "_avp_cli", False):
            logger.removeHandler(h)
    out = logging.StreamHandler(sys.stdout)
    out.addFilter(_Below(logging.WARNING))
    err = logging.StreamHandler(sys.stderr)
    err.setLevel(logging.WARNING)
    err.setFormatter(logging.Formatter("avp: %(levelname)s: %(message)s"))
    for h in (out, err):
        h._avp_cli = True  # type: ignore[attr-defined]
        logger.addHandler(h)
    logger.setLevel(level)
    logger.propagate = False


def progress(iterable: Any, total: int, desc: str) -> Any:
    """``tqdm`` progress bar on stderr when stderr is a terminal; otherwise the items unchanged
    (no ``\\r`` updates in log files) with a log line every tenth of the work."""
    if sys.stderr.isatty():
        try:
            from tqdm import tqdm  # type: ignore[import-untyped]
        except ImportError:  # pragma: no cover - tqdm is a dependency
            pass
        else:
            return tqdm(iterable, total=total, desc=desc, unit="trial", leave=False)
    return _logged(iterable, total, desc)


def _logged(iterable: Any, total: int, desc: str) -> Any:
    step = max(1, math.ceil(total / 10))
    t0 = time.perf_counter()
    for k, item in enumerate(iterable, 1):
        yield item
        if k % step == 0 or k == total:
            log.info("%s: %d/%d (%.0f s)", desc, k, total, time.perf_counter() - t0)


# -- flags shared by the commands -------------------------------------------------------------

class _HelpFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """Shows ``(default: X)`` except for flags whose default is ``None`` (their help says what
    ``None`` means) or ``False``."""

    def _get_help_string(self, action: argparse.Action) -> str:
        if action.default is None or action.default is False or action.default is argparse.SUPPRESS:
            return action.help or ""
        return super()._get_help_string(action) or ""


def _free_float(text: str) -> float | str:
    if text.strip().lower() in ("free", "none"):
        return "none"
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number or 'free', got {text!r}") from None


def _common_parser() -> argparse.ArgumentParser:
    from .camera import Camera
    from .config import ContactVelocity, PlannerConfig, VehicleLimits

    lim, cv, cam = VehicleLimits(), ContactVelocity(), Camera()
    p = argparse.ArgumentParser(add_help=False)
    g = p.add_argument_group("output")
    g.add_argument("-v", "--verbose", action="count", default=0,
                   help="more detail: the planner's log and debug messages")
    g.add_argument("-q", "--quiet", action="store_true", help="warnings and errors only")
    g.add_argument("--json", action="store_true", help="print one JSON document on stdout instead of the summary")
    c = p.add_argument_group("configuration (flags win over --config)")
    c.add_argument("--config", metavar="FILE.toml",
                   help="TOML file with [planner], [replan], [line], [scenario] tables (docs/configuration.md)")
    c.add_argument("--solver", help=f"qpsolvers back-end: daqp, proxqp, osqp... (default {PlannerConfig.solver})")
    c.add_argument("--mass", type=float, help=f"vehicle mass, kg (default {lim.mass})")
    c.add_argument("--thrust-min", type=float, help=f"minimum thrust, N (default {lim.thrust_min:g})")
    c.add_argument("--thrust-max", type=float, help=f"maximum thrust, N (default {lim.thrust_max:g})")
    c.add_argument("--thrust-rate-max", type=float, help=f"thrust rate limit, N/s (default {lim.thrust_rate_max})")
    c.add_argument("--tilt-rate-max", type=float, help=f"tilt rate limit, rad/s (default {lim.tilt_rate_max:g})")
    c.add_argument("--body-rate-max", type=float, help=f"body rate limit, rad/s (default {lim.body_rate_max})")
    alpha = (f"max({PlannerConfig.alpha_nominal:g}, g cos(incline))" if PlannerConfig.alpha is None
             else f"{PlannerConfig.alpha:g}")
    c.add_argument("--alpha", type=float, help=f"mass-normalised thrust at contact, m/s^2 (default {alpha})")
    c.add_argument("--contact-normal", type=_free_float, metavar="V|free",
                   help=f"v.s3 at contact, m/s, negative into the pad (default {cv.normal:g})")
    c.add_argument("--contact-slope", type=_free_float, metavar="V|free",
                   help=f"v.s1 at contact, m/s, negative down the slope (default {cv.slope:g}, times sin(incline))")
    c.add_argument("--contact-lateral", type=_free_float, metavar="V|free",
                   help=f"v.s2 at contact, m/s (default {cv.lateral:g})")
    c.add_argument("--camera-half-fov-deg", type=float,
                   help=f"half-angle of the camera cone, deg (default {math.degrees(cam.half_fov):g})")
    c.add_argument("--no-fov", action="store_true", help="plan without the field-of-view rows")
    return p


def _flag_overrides(args: argparse.Namespace) -> dict[str, Any]:
    """The flags given, as a mapping with the nesting of the configuration file."""
    planner: dict[str, Any] = {}
    limits = {k: getattr(args, k) for k in ("mass", "thrust_min", "thrust_max", "thrust_rate_max",
                                             "tilt_rate_max", "body_rate_max") if getattr(args, k) is not None}
    contact = {k: getattr(args, f"contact_{k}") for k in ("normal", "slope", "lateral")
               if getattr(args, f"contact_{k}") is not None}
    if args.solver is not None:
        planner["solver"] = args.solver
    if args.alpha is not None:
        planner["alpha"] = args.alpha
    if limits:
        planner["limits"] = limits
    if contact:
        planner["contact_velocity"] = contact
    fov: dict[str, Any] = {}
    if args.no_fov:
        fov["enabled"] = False
    if args.camera_half_fov_deg is not None:
        fov["camera"] = {"half_fov": math.radians(args.camera_half_fov_deg)}
    if fov:
        planner["fov"] = fov
    return {"planner": planner} if planner else {}


def _settings(args: argparse.Namespace, defaults: dict[str, Any] | None = None,
              overrides: dict[str, Any] | None = None) -> Settings:
    """:func:`~avp.configfile.load_settings` of ``--config`` with the flags (``overrides``, by
    default the common ones: :func:`_flag_overrides`) over it; an error on the file itself
    (missing, unreadable, not TOML: a ``ConfigError`` on ``path``) is reported on ``--config``."""
    try:
        return load_settings(args.config, _flag_overrides(args) if overrides is None else overrides, defaults)
    except ConfigError as exc:
        if exc.field == "path" and exc.__cause__ is not None:  # read_toml's (not a [path] table's)
            raise ConfigError("--config", exc.message) from exc
        raise


def _emit_json(doc: Any) -> None:
    """Strict JSON on stdout: NaN becomes ``null``, infinities the strings ``"inf"`` / ``"-inf"``
    (as the configuration file writes them)."""
    sys.stdout.write(json.dumps(_finite(doc), indent=2, allow_nan=False, default=_json_default) + "\n")


def _finite(obj: Any) -> Any:
    if isinstance(obj, float) and not math.isfinite(obj):
        return None if math.isnan(obj) else ("inf" if obj > 0 else "-inf")
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite(v) for v in obj]
    return obj


def _json_default(obj: Any) -> Any:
    if isinstance(obj, (np.floating, np.integer, np.bool_)):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    return to_mapping(obj) if hasattr(obj, "__dataclass_fields__") else str(obj)


# -- avp demo ---------------------------------------------------------------------------------

DEMO_PAD_HEIGHT = 1.5
"""Height (m) of the demo's pad centre, or of its start when the start is below the pad."""
DEMO_GROUND_Z = 0.0
"""Height (m) of the demo's ground; the planner keeps the centre of mass
:data:`avp.config.GROUND_CLEARANCE` above it (:func:`_ground_default`)."""


def demo_geometry(incline_deg: float, distance: float, lateral: float, height: float | None) -> tuple[Any, Any, float]:
    """The demo's start state, pad and start height above the pad (m).

    Default height above the pad: +1 m for inclines below 45 deg, 0 up to 90 deg, and -1 m (below the
    pad) for ceilings and overhangs above 90 deg, whose outward side faces down. The lower of
    start and pad is at :data:`DEMO_PAD_HEIGHT`, the ground is at z = 0."""
    from .types import PerchTarget, State

    if not 0.0 <= incline_deg <= 180.0:
        raise ConfigError("--incline-deg", f"must be in [0, 180] deg, got {incline_deg}")
    if height is None:
        height = 1.0 if incline_deg < 45.0 else (0.0 if incline_deg <= 90.0 else -1.0)
    pad = np.array([distance, 0.0, DEMO_PAD_HEIGHT + max(0.0, -height)])
    target = PerchTarget.from_incline(pad, math.radians(incline_deg), heading=0.0)
    start = pad + np.array([-distance, 0.0, height]) + lateral * target.s2
    return State.hover(start), target, height


DEMO_DEFAULTS: dict[str, Any] = {"incline_deg": 90.0, "distance": 3.5, "lateral": 0.0, "output": "perch_demo.png"}
"""The pad demo's geometry and plot path when their flags are not given."""

PAD_GEOMETRY = ("incline_deg", "distance", "lateral", "height")
"""``avp demo`` flags (``args`` attributes) that place the pad and the start (:func:`demo_geometry`)."""

PAD_FLAGS = (*PAD_GEOMETRY, "output")
"""``avp demo`` flags of a pad perch only: a line perch refuses them."""


def _demo_parser(sub: Any, common: argparse.ArgumentParser) -> None:
    p = sub.add_parser("demo", parents=[common], formatter_class=_HelpFormatter,
                       help="plan one perch, print a summary, write a PNG",
                       description="Plan one perch from hover, print a summary (or --json), plot it. "
                                   f"The ground is at z = {DEMO_GROUND_Z:g}: the planner keeps the centre of mass "
                                   f"{GROUND_CLEARANCE:g} m above it (the simulator's margin for the airframe and "
                                   "tracking) when it supports "
                                   "workspace limits (unless the config file sets workspace.ground_z).")
    # the pad flags default to None so that a line perch can tell them given (PAD_FLAGS); the
    # pad demo fills in DEMO_DEFAULTS, which the help shows
    d = DEMO_DEFAULTS
    p.add_argument("--incline-deg", type=float, default=None,
                   help=f"pad incline: 0 floor, 90 wall, 180 ceiling (default: {d['incline_deg']})")
    p.add_argument("--distance", type=float, default=None,
                   help=f"horizontal stand-off from the pad, m (default: {d['distance']})")
    p.add_argument("--lateral", type=float, default=None,
                   help=f"lateral offset of the start along s2, m (default: {d['lateral']})")
    p.add_argument("--height", type=float, default=None,
                   help="start height above the pad, m (default: +1 for inclines below 45 deg, 0 up to "
                        "90 deg, -1 i.e. below the pad above 90 deg)")
    p.add_argument("--output", default=None, help=f"PNG path for the plot of a pad perch (default: {d['output']})")
    p.add_argument("--no-plot", action="store_true", help="skip the plot (a line perch has none)")
    p.add_argument("--export", metavar="FILE", help="write the plan (a line's perch) to FILE (.json, .csv or .npz by suffix)")
    p.add_argument("--export-rate", type=float, metavar="HZ",
                   help="with --export: sample the export at HZ (default: exact coefficients only)")
    add_line_flags(p)


def _check_demo_flags(args: argparse.Namespace) -> None:
    """Refuse flags the demo would ignore, and output paths it could not write (before planning:
    :func:`_export_format`, :func:`_check_outputs`); fill in :data:`DEMO_DEFAULTS` for a pad perch."""
    if args.export_rate is not None and args.export is None:
        raise ConfigError("--export-rate", "samples the --export file: give --export FILE too, or drop it")
    if args.export_rate is not None and not (math.isfinite(args.export_rate) and args.export_rate > 0):
        raise ConfigError("--export-rate", f"must be a positive sample rate in Hz, got {args.export_rate:g}")
    if args.export is not None:
        _export_format(args.export)
        _check_outputs(args, ("export",))
    if args.line_pitch_deg is None:
        for name, value in DEMO_DEFAULTS.items():
            if getattr(args, name) is None:
                setattr(args, name, value)
        if not args.no_plot:
            _check_plot_path(args.output)
            _check_outputs(args, ("output",))
        return
    given = _given(args, PAD_FLAGS)  # their defaults are None: given at all
    if "--output" in given:
        raise ConfigError("--output", "avp.plotting draws pad perches only, a line perch has no plot: drop --output "
                                      "(--export FILE writes the plan, --json prints it)")
    _refuse_for_a_line(given, "places the pad demo's start")


def _check_plot_path(output: str) -> None:
    """``--output`` names a file, before any planning: not empty, not ``.`` or ``..``, not ending
    in a path separator, not an existing directory, also with the ``.png`` that
    :func:`avp.plotting.plot_plan` adds to a name without a suffix; else a :class:`ConfigError`
    on ``--output``."""
    path = Path(output)
    written = path if path.suffix else path.with_suffix(".png") if path.name not in ("", ".", "..") else path
    if (not output or output.endswith(("/", os.sep)) or (os.altsep and output.endswith(os.altsep))
            or path.name in ("", ".", "..") or path.is_dir() or written.is_dir()):
        raise ConfigError("--output", f"needs a file name for the plot, got {output!r} (a directory or an empty "
                                      f"path); give a PNG file name, e.g. "
                                      f"{str(Path(output or '.') / DEMO_DEFAULTS['output'])!r}")


def _refuse_for_a_line(given: list[str], what: str) -> None:
    """A :class:`ConfigError` on the first of the pad flags ``given`` to a line perch, which ``what``
    (its use for a pad) a line perch does not need; nothing when none was given."""
    if given:
        also = f" (and {', '.join(given[1:])})" if len(given) > 1 else ""
        raise ConfigError(given[0], f"{what}, which a line perch does not use: drop it{also}; "
                                    "--line-distance, --line-rise, --line-incline-deg place the line")


def _ground_default(planner_cls: type) -> dict[str, Any]:
    """``{"planner": {"workspace": {"ground_z": GROUND_CLEARANCE}}}`` when the planner has
    workspace limits: the demo's ground is at z = 0, and its centre of mass is kept
    :data:`avp.config.GROUND_CLEARANCE` above it, as the simulator keeps it (a limit at the
    ground itself let plans pass 5 mm above it, with the airframe below)."""
    import dataclasses

    names = {f.name for f in dataclasses.fields(planner_cls)}
    return {"planner": {"workspace": {"ground_z": DEMO_GROUND_Z + GROUND_CLEARANCE}}} if "workspace" in names else {}


def demo(args: argparse.Namespace) -> int:
    from .config import PlannerConfig
    from .frames import rotation_error_angle
    from .planner import plan_detailed

    _check_demo_flags(args)
    settings = _settings(args, defaults=_ground_default(PlannerConfig))
    config = settings.planner
    if args.line_pitch_deg is not None:  # a line perch (avp/cli_line.py)
        code, doc, perch = line_demo(args, config, settings.line)
        exported = _export_plan(args, perch, config)
        if args.json:
            _emit_json({**doc, "export": None if exported is None else str(exported)})
        return code
    state, target, height = demo_geometry(args.incline_deg, args.distance, args.lateral, args.height)
    t0 = time.perf_counter()
    result = plan_detailed(state, target, config)
    first_call = time.perf_counter() - t0
    repeat = plan_detailed(state, target, config)  # steady state: caches and imports warm
    code = plan_exit_code(result)
    label = plan_label(result)
    ground = getattr(getattr(config, "workspace", None), "ground_z", None)
    log.info("avp demo: perch on a %g deg pad, %g m away (lateral %g m, height %g m), solver %s%s",
             args.incline_deg, args.distance, args.lateral, height, config.solver,
             "" if ground is None else f", centre of mass kept above z = {ground:g} m")
    log.info("  status          : %s (%s)", result.status.value, label)
    if result.relaxations:
        log.info("  relaxations     : %s", ", ".join(r.name.lower() for r in result.relaxations))
    for line in result.log:
        log.debug("    - %s", line)
    traj = result.trajectory
    summary: dict[str, Any] = {}
    if traj is not None:
        tf = traj.tf
        drag = config.limits.rotor_drag  # the thrust the planner certifies: a + g e3 + d v
        R_tf = traj.attitude(tf, rotor_drag=drag)
        b3 = R_tf[:, 2]
        v_S = target.to_target_frame(traj(tf, 1))
        want = config.contact_velocity.components(target.incline)
        ts = traj.sample(1e-3)
        thrust = traj.thrust(ts, rotor_drag=drag)
        rates = np.linalg.norm(traj.body_rates(ts, rotor_drag=drag), axis=-1)
        summary = {
            "duration_s": traj.duration, "n_segments": traj.n_segments, "degree": traj.degree,
            "contact_position_m": traj(tf).tolist(),
            "contact_position_error_m": float(np.linalg.norm(traj(tf) - target.point)),
            "b3_error_deg": math.degrees(math.acos(max(-1.0, min(1.0, float(b3 @ target.s3))))),
            "frame_error_deg": math.degrees(float(rotation_error_angle(R_tf, target.R_WS))),
            "contact_velocity_S": v_S.tolist(),
            "contact_velocity_error_m_s": max((abs(v_S[i] - w) for i, w in enumerate(want) if w is not None), default=0.0),
            "thrust_max_m_s2": float(thrust.max()), "thrust_min_m_s2": float(thrust.min()),
            "body_rate_max_rad_s": float(rates.max()),
            "min_height_m": float(traj(ts)[:, 2].min()),
        }
        log.info("  duration        : %.3f s (%d segments, degree %d)", traj.duration, traj.n_segments, traj.degree)
        log.info("  contact position: %s m (error %.2e mm)", np.round(traj(tf), 4).tolist(),
                 summary["contact_position_error_m"] * 1e3)
        log.info("  attitude error  : b3 vs s3 %.2e deg, R_WB vs R_WS %.2e deg", summary["b3_error_deg"],
                 summary["frame_error_deg"])
        log.info("  contact velocity: v_S = %s m/s (error %.2e mm/s)", np.round(v_S, 4).tolist(),
                 summary["contact_velocity_error_m_s"] * 1e3)
        log.info("  peak thrust     : %.2f m/s^2 (%.2f N at %g kg), min %.2f m/s^2; peak body rate %.2f rad/s; "
                 "lowest point z = %.2f m", thrust.max(), thrust.max() * config.limits.mass, config.limits.mass,
                 thrust.min(), rates.max(), summary["min_height_m"])
    tm = repeat.timings
    log.info("  solve time      : %.2f ms (build %.2f, QP %.2f, certificate %.2f); first call %.1f ms with one-time setup",
             tm.total * 1e3, tm.build * 1e3, tm.solve * 1e3, tm.certify * 1e3, first_call * 1e3)
    if code == EXIT_FAILED:
        shown = result.log[-3:]
        log.warning("no certified plan: %s%s", result.status.value,
                    "".join(f"\n    - {line}" for line in shown)
                    + (f"\n    ({len(result.log) - len(shown)} earlier planner log lines with -v)"
                       if len(result.log) > len(shown) and args.verbose == 0 else ""))
    elif code == EXIT_RELAXED:
        log.warning("the plan needed relaxations: %s", ", ".join(r.name.lower() for r in result.relaxations) or
                    result.status.value)
    exported = _export_plan(args, traj, config)
    plot = None
    if not args.no_plot and traj is not None:
        # the ground drawn is the world's (z = 0) under the default limit GROUND_CLEARANCE above it
        world = DEMO_GROUND_Z if ground is None or ground == DEMO_GROUND_Z + GROUND_CLEARANCE else ground
        plot = _plot_demo(result, target, config, args, world)
    if args.json:
        _emit_json({
            "command": "demo", "exit_code": code, "label": label, "status": result.status.name,
            "status_text": result.status.value,
            "relaxations": [r.name.lower() for r in result.relaxations],
            "bounds_certified": None if result.bounds is None else bool(result.bounds.certified),
            "workspace_certified": _workspace_certified(result),
            "start": {"position": state.position.tolist(), "yaw": state.yaw},
            "target": {"point": target.point.tolist(), "R_WS": target.R_WS.tolist(), "incline_deg": args.incline_deg},
            "summary": summary, "log": list(result.log),
            "timings_ms": {"build": tm.build * 1e3, "solve": tm.solve * 1e3, "certify": tm.certify * 1e3,
                           "total": tm.total * 1e3, "first_call": first_call * 1e3},
            "config": {"planner": to_mapping(config)},
            "trajectory": None if traj is None else trajectory_to_dict(traj),
            "plot": None if plot is None else str(plot), "export": None if exported is None else str(exported),
        })
    return code


def _workspace_certified(result: Any) -> bool | None:
    safety = getattr(result, "safety", None)
    return None if safety is None else bool(getattr(safety, "certified", False))


def _export_plan(args: argparse.Namespace, traj: Any, config: Any) -> Path | None:
    """``--export``: write the demo's trajectory (a pad perch, or a line's perch) sampled at
    ``--export-rate`` with the vehicle's rotor drag, log the path and return it (``None`` without
    the flag or a trajectory)."""
    if not args.export or traj is None:
        return None
    exported = _export(traj, Path(args.export), args.export_rate, config.limits.rotor_drag)
    log.info("  export          : %s", exported)
    return exported


EXPORT_FORMATS = (".json", ".csv", ".npz")
"""``--export`` file name suffixes (any case): the format the plan is written in."""


def _export_format(path: str | Path) -> str:
    """The format (lower-case suffix, one of :data:`EXPORT_FORMATS`) of an ``--export`` path;
    any other suffix, or none, is a :class:`ConfigError` on ``--export``."""
    suffix = Path(path).suffix.lower()
    if suffix not in EXPORT_FORMATS:
        what = f"unknown format {suffix!r}" if suffix else "no format suffix"
        raise ConfigError("--export", f"{what} in {str(path)!r}: use a file name ending in "
                                      f"{', '.join(EXPORT_FORMATS[:-1])} or {EXPORT_FORMATS[-1]}")
    return suffix


def _export(traj: Any, path: Path, rate: float | None, rotor_drag: float = 0.0) -> Path:
    suffix = _export_format(path)
    if suffix == ".json":
        traj.to_json(path, rate=rate, indent=1, rotor_drag=rotor_drag)
    elif suffix == ".csv":
        traj.to_csv(path, rate=rate, rotor_drag=rotor_drag)
    else:
        traj.to_npz(path, rate=rate, rotor_drag=rotor_drag)
    return path


def _plot_demo(result: Any, target: Any, config: Any, args: argparse.Namespace, ground: float) -> Path | None:
    try:
        from . import plotting
    except ImportError:  # pragma: no cover - plotting imports matplotlib lazily
        log.warning(PLOT_HINT)
        return None
    try:
        out = plotting.plot_plan(result, target, args.output, config=config, ground_z=ground,
                                 title=f"{args.incline_deg:g} deg pad, {args.distance:g} m", label=plan_label(result))
    except plotting.MatplotlibMissingError:
        log.warning(PLOT_HINT)
        return None
    log.info("  plot            : %s", out)
    return out


# -- avp simulate -----------------------------------------------------------------------------

def _sweep_flags(p: argparse.ArgumentParser, distances: Sequence[float]) -> None:
    p.add_argument("--incline-deg", type=float, nargs="+", default=[90.0], help="pad incline(s), deg")
    p.add_argument("--distance", type=float, nargs="+", default=list(distances), help="stand-off(s), m")
    p.add_argument("--lateral", type=float, nargs="+", default=[0.0], help="start offset(s) along s2, m")
    p.add_argument("--height", type=_free_float, nargs="+", default=["none"], metavar="H|none",
                   help="start height(s) above the pad, m; none: +1 (above the pad) for inclines below 45 deg, "
                        "else 0")
    p.add_argument("--seed", type=int, default=0, help="first seed")
    p.add_argument("--backend", choices=(*EXECUTION_BACKENDS, *SIMULATORS), default="serial",
                   help="where trials run: serial, a local process pool, or Ray (auto: Ray if installed, else the "
                        "pool); or, short for --simulator, avp / rotorpy")
    p.add_argument("--simulator", choices=SIMULATORS, default=None,
                   help="what integrates the vehicle: avp's model (default) or rotorpy's Multirotor "
                        "(pip install \"avp[rotorpy]\"; avp's controller feeds rotorpy's rotor drag forward)")
    p.add_argument("--workers", type=int, default=None, help="parallel workers (default: the CPU count)")
    p.add_argument("--address", default=None,
                   help="Ray cluster address (e.g. ray://head:10001 or auto); default: a local Ray instance")


def _simulator_settings(args: argparse.Namespace) -> dict[str, Any]:
    """Resolve ``--backend avp|rotorpy`` (short for ``--simulator``; the trials then run
    serially, or on ``auto`` for ``avp campaign``) and return the simulator's ``defaults``
    mapping, ``{"scenario": {"backend": ...}}`` (``{}`` without the flag)."""
    if args.backend in SIMULATORS:
        if args.simulator is not None and args.simulator != args.backend:
            raise ConfigError("--backend", f"{args.backend!r} contradicts --simulator {args.simulator!r}")
        args.simulator = args.backend
        args.backend = "auto" if args.command == "campaign" else "serial"
    if args.simulator is None:
        return {}
    if args.simulator == "rotorpy":
        from .sim.backend import require_rotorpy

        require_rotorpy("--simulator")
    return {"scenario": {"backend": args.simulator}}


def _simulate_parser(sub: Any, common: argparse.ArgumentParser) -> None:
    p = sub.add_parser("simulate", parents=[common], formatter_class=_HelpFormatter,
                       help="closed-loop trials: one-shot planning vs AVP replanning",
                       description="Seeded closed-loop trials of every condition in both modes, with "
                                   "the paired tables of success, interception and anticipation error. "
                                   "The simulated world has a ground at z = 0 (a run below it ends as "
                                   "'crash: ground'); the planner keeps avp.config.GROUND_CLEARANCE above it unless the config "
                                   "file sets [planner.workspace] ground_z (line perches: no ground unless set).")
    p.add_argument("--trials", type=int, default=5, help="seeded trials per condition and mode")
    _sweep_flags(p, (4.5, 7.5))
    p.add_argument("--output-dir", default="avp_simulation",
                   help="directory for the plots (created if missing; its parent must exist)")
    p.add_argument("--no-plot", action="store_true", help="skip the plots")
    p.add_argument("--gif", metavar="FILE.gif", help="animate the first AVP trial of the first condition")
    add_line_flags(p)
    m = p.add_argument_group("moving platform (the pad rides a platform; [scenario.platform] in --config)")
    m.add_argument("--platform-speed", type=float, metavar="M/S", help="platform speed, m/s (default: a static pad)")
    m.add_argument("--platform-heading-deg", type=float, metavar="DEG",
                   help="direction of travel from +x, deg; 0: away from the start (default 0)")
    m.add_argument("--platform-turn-rate", type=float, metavar="RAD/S", help="CTRV turn rate, rad/s (default 0)")


def _platform_overrides(args: argparse.Namespace) -> dict[str, Any]:
    """The ``--platform-*`` flags as ``{"scenario": {"platform": {...}}}`` (empty without any)."""
    heading = None if args.platform_heading_deg is None else math.radians(args.platform_heading_deg)
    table = {k: float(v) for k, v in (("speed", args.platform_speed), ("heading", heading),
                                      ("turn_rate", args.platform_turn_rate)) if v is not None}
    return {"scenario": {"platform": table}} if table else {}


PAPER_NOTE = re.compile(r"\s*\((?:cf\. )?paper Table [^()]*\)|;\s*paper: [^\n]*")
"""The paper's numbers quoted in the tables' headers (a 90 deg wall, no offsets)."""


def without_paper_notes(text: str) -> str:
    """The report without the paper's figures, for conditions the paper did not fly."""
    return PAPER_NOTE.sub("", text)


SWEEP_KEYS = {"incline": "--incline-deg", "distance": "--distance", "lateral": "--lateral", "height": "--height"}
"""``[scenario]`` keys that ``avp simulate`` and ``avp campaign`` set from their flags (the sweep)."""


def _refuse_swept_keys(settings: Settings) -> None:
    """A ``--config`` whose ``[scenario]`` table sets a key the command sweeps by its flags is a
    ``ConfigError`` (the flags' values, defaults included, would override it silently)."""
    table = settings.data.get("scenario", {})
    for key, flag in SWEEP_KEYS.items():
        if key in table:
            raise ConfigError(f"scenario.{key}", f"is set by the flag {flag} in this command (its default "
                                                 "included); remove it from the --config file and pass the flag")


LINE_UNUSED = ("incline_deg", "distance", "lateral", "height", "output_dir", "gif", "platform_speed",
               "platform_heading_deg", "platform_turn_rate", "backend", "workers", "address")
"""``avp simulate`` flags (``args`` attributes) of the pad trials, which line trials do not use."""


def _check_conditions(settings: Settings, trials: Sequence[Any]) -> None:
    """Build the scenario of every condition of ``trials`` before running any, so that a swept
    value out of range (``--distance 1e5``) is a usage error now, not in the middle of the run,
    on its flag with the value as the flag gave it (a ``--config`` file cannot set these keys:
    :func:`_refuse_swept_keys`)."""
    seen = set()
    for t in trials:
        key = (t.incline, t.distance, t.lateral, t.height)
        if key not in seen:
            seen.add(key)
            try:
                settings.scenario(incline=t.incline, distance=t.distance, lateral=t.lateral, height=t.height)
            except ConfigError as exc:  # on its flag, with the value as the flag gave it
                name = exc.field.removeprefix("scenario.")
                flag = SWEEP_KEYS.get(name)
                if flag is None:
                    raise
                value = math.degrees(t.incline) if name == "incline" else getattr(t, name)
                shown = f"{value:g}" if isinstance(value, (int, float)) else repr(value)
                raise ConfigError(flag, f"{shown} gives {exc.field}: {exc.message}") from exc


def _check_outputs(args: argparse.Namespace, names: Sequence[str]) -> None:
    """Before any planning or trial, without creating anything: the output flags ``names``
    (``args`` attributes) can be written where they point, else a :class:`ConfigError` on the
    flag. The directory that holds the path exists, is a directory and is writable: the CLI
    creates no directory but a missing :data:`DIRECTORY_FLAGS` path itself (``--output-dir``),
    never its parents; a file flag does not name a directory, a directory flag not a file."""
    for name in names:
        value = getattr(args, name, None)
        if value is None:
            continue
        flag = "--" + name.replace("_", "-")
        path = Path(value).absolute()
        is_dir = name in DIRECTORY_FLAGS
        if path.exists() and path.is_dir() != is_dir:
            what = "a file, not a directory; give a directory" if is_dir else "a directory; give a file name"
            raise ConfigError(flag, f"cannot write {value!r}: it is {what}")
        holder = path if is_dir and path.exists() else path.parent
        if holder.exists() and not holder.is_dir():
            raise ConfigError(flag, f"cannot write {value!r}: {str(holder)!r} is a file, not a directory; give a "
                                    "path in an existing directory")
        if not holder.exists():
            create = f"avp creates {flag} itself, not its parents" if is_dir else "avp creates no directories"
            raise ConfigError(flag, f"cannot write {value!r}: the directory {str(holder)!r} does not exist ({create}); "
                                    "create it first or give a path in an existing directory")
        if not os.access(holder, os.W_OK):
            raise ConfigError(flag, f"cannot write {value!r}: no permission to write in {str(holder)!r}; give a "
                                    "path in a directory you can write to")


def _given(args: argparse.Namespace, names: Sequence[str]) -> list[str]:
    """The flags among ``names`` given with a value other than their default."""
    defaults = build_parser().parse_args([args.command])
    return ["--" + n.replace("_", "-") for n in names if getattr(args, n, None) != getattr(defaults, n, None)]


def simulate(args: argparse.Namespace) -> int:
    from . import campaign
    from .sim.evaluate import Comparison, Condition

    if args.trials < 1:
        raise ConfigError("--trials", f"must be >= 1, got {args.trials}")
    if args.seed < 0:
        raise ConfigError("--seed", f"must be >= 0 (a random generator seed), got {args.seed}")
    settings = _settings(args, _simulator_settings(args), merge(_flag_overrides(args), _platform_overrides(args)))
    if args.line_pitch_deg is not None:  # closed-loop line perches (avp/cli_line.py)
        if args.simulator not in (None, "avp"):
            raise ConfigError("--simulator", "line perches fly on avp's simulator only; drop --simulator/--backend rotorpy")
        # after _simulator_settings: --backend avp is the default back-end
        _refuse_for_a_line(_given(args, LINE_UNUSED), "sets up the pad trials")
        table = settings.data.get("scenario", {})
        if table.get("backend", "avp") != "avp":  # a file's [scenario] backend, as --simulator above
            raise ConfigError("scenario.backend", f"line perches fly on avp's simulator only, not {table['backend']!r}; "
                                                  "remove it from the --config file for a line run")
        unused = sorted(k for k in table if k != "backend")
        if unused:
            raise ConfigError(f"scenario.{unused[0]}", "the line trials do not read the --config file's [scenario] "
                                                      "table (the pad trials' world): remove it for a line run")
        doc = line_simulate(args, settings.planner, settings.replan, settings.line)
        if args.json:
            _emit_json(doc)
        return EXIT_SOLVED
    if args.gif and not str(args.gif).lower().endswith(".gif"):
        raise ConfigError("--gif", f"the animation is a GIF: give a path ending in .gif, got {args.gif!r}")
    _refuse_swept_keys(settings)
    _check_outputs(args, ("gif",) if args.no_plot else ("output_dir", "gif"))
    trials = campaign.grid(args.incline_deg, args.distance, args.lateral, _heights(args.height),
                           ("one_shot", "avp"), range(args.seed, args.seed + args.trials))
    _check_conditions(settings, trials)
    runner = campaign.Runner(settings.data, keep_result=True)
    comp = Comparison([], [args.seed + k for k in range(args.trials)])
    t0 = time.perf_counter()
    rows = []
    outputs = campaign.execute(runner, trials, backend=args.backend, workers=args.workers, address=args.address)
    for trial, (row, sim) in progress(outputs, len(trials), "simulate"):
        cond = Condition(trial.incline, trial.distance, trial.lateral, trial.height)
        if cond not in comp.conditions:
            comp.conditions.append(cond)
        comp.results.setdefault((cond, sim.mode), []).append(sim)
        rows.append(row)
    comp.wall_time = time.perf_counter() - t0
    order = {c: k for k, c in enumerate(Condition(t.incline, t.distance, t.lateral, t.height) for t in trials)}
    comp.conditions.sort(key=order.__getitem__)
    for runs in comp.results.values():
        runs.sort(key=lambda r: r.seed)
    paper = "platform" not in settings.data.get("scenario", {}) and all(
        abs(c.incline - math.pi / 2) < 1e-9 and c.lateral == 0 and c.height is None for c in comp.conditions)
    report = comp.report() if paper else without_paper_notes(comp.report())
    if not args.json:
        log.info("%s", report)
    if not args.no_plot:
        try:
            for path in comp.plot(args.output_dir):
                log.info("plot: %s", path)
        except ImportError:
            log.warning(PLOT_HINT)
    if args.gif:
        from .sim.run import Mode

        runs = comp.runs(comp.conditions[0], Mode.AVP)
        try:
            from .plotting import animate_run

            log.info("animation: %s", animate_run(runs[0], args.gif))
        except ImportError:
            log.warning(PLOT_HINT)
    if args.json:  # after the plots: an unusable --output-dir or --gif leaves only the error's document
        _emit_json({"command": "simulate", "rows": sorted(rows, key=lambda r: r["trial_id"]),
                    "summary": campaign.summarize(rows), "wall_time_s": comp.wall_time})
    return EXIT_SOLVED


def _heights(values: Sequence[Any]) -> list[float | None]:
    return [None if v == "none" else float(v) for v in values]


# -- avp campaign -----------------------------------------------------------------------------

def _campaign_parser(sub: Any, common: argparse.ArgumentParser) -> None:
    p = sub.add_parser("campaign", parents=[common], formatter_class=_HelpFormatter,
                       help="Monte Carlo campaign: a grid x seeds of closed-loop trials on a pool or Ray",
                       description="Runs every grid cell x mode x seed as one closed-loop trial, on Ray "
                                   "(local, or a cluster with --address) or a local process pool, and "
                                   "appends one row per trial to the results file. Re-running with the "
                                   "same results file skips the trials already there (same grid cell, "
                                   "seed, mode and configuration), so an interrupted campaign resumes.")
    p.add_argument("--seeds", type=int, default=10, help="seeds per grid cell and mode")
    _sweep_flags(p, (1.5, 3.5, 4.5, 7.5))
    p.set_defaults(backend="auto")
    p.add_argument("--modes", nargs="+", choices=("one_shot", "avp"), default=["one_shot", "avp"], help="planning modes")
    p.add_argument("--results", default="avp_campaign.csv", help="results file, .csv or .parquet (needs pyarrow)")
    p.add_argument("--summary-plot", default="avp_campaign.png", help="PNG of the success rates")
    p.add_argument("--no-plot", action="store_true", help="skip the plot")


def run_campaign(args: argparse.Namespace) -> int:
    from . import campaign

    if args.seeds < 1:
        raise ConfigError("--seeds", f"must be >= 1, got {args.seeds}")
    if args.seed < 0:
        raise ConfigError("--seed", f"must be >= 0 (a random generator seed), got {args.seed}")
    settings = _settings(args, _simulator_settings(args))
    _refuse_swept_keys(settings)
    _check_outputs(args, ("results",) if args.no_plot else ("results", "summary_plot"))
    trials = campaign.grid(args.incline_deg, args.distance, args.lateral, _heights(args.height), args.modes,
                           range(args.seed, args.seed + args.seeds))
    _check_conditions(settings, trials)
    stats = campaign.run(trials, settings.data, args.results, backend=args.backend, workers=args.workers,
                         address=args.address, progress=progress)
    rows = campaign.ResultStore(args.results).rows()
    config_id = campaign.config_id(settings.data)
    rows = [r for r in rows if r["config_id"] == config_id]
    summary = campaign.summarize(rows)
    plot = None
    if not args.no_plot and rows:
        try:
            plot = campaign.plot_summary(summary, args.summary_plot)
        except ImportError:
            log.warning(PLOT_HINT)
    if args.json:
        _emit_json({"command": "campaign", "results": str(args.results), **stats, "summary": summary,
                    "plot": None if plot is None else str(plot)})
    else:
        log.info("%s", campaign.format_summary(summary))
        log.info("%d trials run, %d already in %s (skipped); backend %s; %.1f trials/min",
                 stats["ran"], stats["skipped"], args.results, stats["backend"], stats["trials_per_minute"])
        if plot is not None:
            log.info("plot: %s", plot)
    return EXIT_SOLVED


# -- entry point ------------------------------------------------------------------------------

PATH_FLAGS = ("config", "export", "output", "output_dir", "gif", "results", "summary_plot")
"""The flags (``args`` attributes) that name a file or directory the command reads or writes."""
DIRECTORY_FLAGS = ("output_dir",)
"""The flags of :data:`PATH_FLAGS` that name a directory the command writes its files in."""


FIELD_FLAGS = {
    "fov.camera.half_fov": "camera_half_fov_deg", "alpha": "alpha", "solver": "solver", "rate": "export_rate",
    **{f"limits.{k}": k for k in ("mass", "thrust_min", "thrust_max", "thrust_rate_max", "tilt_rate_max",
                                  "body_rate_max")},
    **{f"contact_velocity.{k}": f"contact_{k}" for k in ("normal", "slope", "lateral")},
}
"""Configuration fields (without the ``planner.`` table) and the flag (``args`` attribute) that sets
each: an error on the field names the flag the user typed (:func:`_with_flag`)."""

GEOMETRY_FIELDS = ("state.position", "target.point")
"""Fields of the demo's start and pad, which its geometry flags place (:func:`demo_geometry`)."""


def _with_flag(args: argparse.Namespace, error: AvpError) -> AvpError:
    """``error`` on a field set by a flag the user gave, as an error on that flag that keeps the
    field's message (``--camera-half-fov-deg 95`` is checked as ``half_fov`` in rad); a demo's
    start or pad error names the geometry flags. Any other error as it is."""
    if not isinstance(error, ConfigError):
        return error
    field = error.field.removeprefix("planner.")
    name = FIELD_FLAGS.get(field)
    if name is not None and getattr(args, name, None) is not None:
        flag = "--" + name.replace("_", "-")
        return ConfigError(flag, f"{getattr(args, name)!r} gives {error.field}: {error.message}")
    if field in GEOMETRY_FIELDS and args.command == "demo" and getattr(args, "line_pitch_deg", None) is None:
        place = " ".join(f"--{n.replace('_', '-')} {getattr(args, n):g}" for n in PAD_GEOMETRY
                         if getattr(args, n, None) is not None)
        return ConfigError(error.field, f"{error.message} (the demo's geometry: {place})")
    return error


def _path_error(args: argparse.Namespace, exc: Exception) -> AvpError | None:
    """The usage error :func:`main` reports for ``exc``: an :class:`AvpError` as it is, except that
    a :class:`ConfigError` raised from an :class:`OSError` (the export writers') and a bare
    ``OSError`` on a file (a plot, the results file, the animation) name the flag whose path it
    is; ``None`` for an ``OSError`` that is not about a file (not bad input: re-raised)."""
    os_error = exc if isinstance(exc, OSError) else exc.__cause__
    if not isinstance(os_error, OSError) or not isinstance(os_error.filename, (str, bytes, os.PathLike)):
        return exc if isinstance(exc, AvpError) else None
    flag = _path_flag(args, os_error.filename)
    if isinstance(exc, ConfigError):
        return ConfigError(flag, exc.message) if flag is not None else exc
    if flag is None:  # a file the user did not name (a cache, a library's): not bad input
        return None
    reason = os_error.strerror or str(os_error)
    if isinstance(os_error, FileExistsError) and not os.path.isdir(os_error.filename):
        reason = "a file is in the way of a directory"  # mkdir of a path's parent that is a file
    return ConfigError(flag, f"cannot open or create {str(os_error.filename)!r}: {reason}; give a "
                             "path in an existing directory you can write to")


def _path_flag(args: argparse.Namespace, filename: Any) -> str | None:
    """The flag of :data:`PATH_FLAGS` whose path is ``filename``, lies below it (``filename`` is
    a directory on its way), is it without the suffix the command adds (``--output plot``), or
    holds it (a file the command writes in ``--output-dir``)."""
    failed = Path(os.fsdecode(filename)).absolute()
    paths = [(name, Path(getattr(args, name)).absolute()) for name in PATH_FLAGS if getattr(args, name, None) is not None]
    for name, given in paths:  # a flag's own path first
        if failed == given or failed in given.parents or failed.with_suffix("") == given:
            return "--" + name.replace("_", "-")
    for name, given in paths:  # then a file the command writes directly in a directory flag's path
        if name in DIRECTORY_FLAGS and failed.parent == given:
            return "--" + name.replace("_", "-")
    return None


def _version() -> str:
    try:
        from . import __version__

        return __version__
    except ImportError:  # pragma: no cover
        from importlib.metadata import version

        return version("avp")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="avp", formatter_class=_HelpFormatter,
        description="Active visual perching planner. Exit codes: "
                    + "; ".join(f"{k} {v}" for k, v in sorted(EXIT_CODES.items())) + ".")
    parser.add_argument("--version", action="version", version=f"avp {_version()}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="{demo,simulate,campaign}")
    common = _common_parser()
    _demo_parser(sub, common)
    _simulate_parser(sub, common)
    _campaign_parser(sub, common)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if argv is None and hasattr(signal, "SIGPIPE"):  # `avp demo | head`: end quietly, as Unix tools do
        signal.signal(signal.SIGPIPE, signal.SIG_DFL)
    _setup_logging(args.verbose, args.quiet, args.json)
    try:
        if args.command == "demo":
            return demo(args)
        if args.command == "simulate":
            return simulate(args)
        if args.command == "campaign":
            return run_campaign(args)
    except (AvpError, OSError) as exc:
        error = _path_error(args, exc)
        if error is None:
            raise
        error = _with_flag(args, error)
        log.error("%s", error)
        if args.json:
            _emit_json({"command": args.command, "exit_code": EXIT_USAGE, "error": str(error),
                        "field": getattr(error, "field", None)})
        return EXIT_USAGE
    except KeyboardInterrupt:  # pragma: no cover - interactive
        log.error("interrupted")
        return 130
    return EXIT_USAGE  # pragma: no cover


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
