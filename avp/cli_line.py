"""``avp demo`` and ``avp simulate`` on a line (``--line-pitch-deg``): the flags and the two
commands' line variants (:mod:`avp.cli` dispatches here when ``--line-pitch-deg`` is given).

The geometry: the vehicle hovers at ``(0, 0, 2.5)`` m; a 3 m straight line crosses the flight
direction at ``x = --line-distance``, ``--line-rise`` above the start (default 0.5 m up to a 90 deg
pitch, 1.2 m above: the vehicle hangs below it), inclined by ``--line-incline-deg`` (0 to 80 deg) along itself.
"""

from __future__ import annotations

import argparse
import logging
import math
from typing import Any

import numpy as np

from .errors import ConfigError

__all__ = ["add_line_flags", "line_demo", "line_geometry", "line_simulate"]

log = logging.getLogger("avp.cli")

LINE_START_HEIGHT = 2.5
"""Height (m) of the hover start of a line perch from the CLI."""


def add_line_flags(p: argparse.ArgumentParser) -> None:
    """The line flags of ``avp demo`` and ``avp simulate``."""
    g = p.add_argument_group("line perch (with --line-pitch-deg; docs/lines.md)")
    g.add_argument("--line-pitch-deg", type=float, default=None,
                   help="perch on a line at this final pitch about it: 0 on top, 180 hanging below")
    g.add_argument("--line-distance", type=float, default=2.5, help="horizontal distance to the line, m")
    g.add_argument("--line-rise", type=float, default=None,
                   help="line height above the start, m (default 0.5 up to 90 deg pitch, else 1.2)")
    g.add_argument("--line-incline-deg", type=float, default=0.0,
                   help="line inclination along itself, deg, in [0, 80]")
    g.add_argument("--line-yaw", choices=("across", "along", "free"), default="across",
                   help="yaw at contact: pitch axis along the line, heading along it, or free")
    g.add_argument("--line-free-grasp", action="store_true", help="let the planner choose the grasp point")


def line_geometry(args: argparse.Namespace) -> tuple[Any, Any]:
    """The CLI's hover start and :class:`~avp.line.LineTarget` (module docstring)."""
    from .line import MAX_INCLINE, LineTarget, LineYaw
    from .types import State

    pitch = float(args.line_pitch_deg)
    if not 0.0 <= pitch <= 180.0:
        raise ConfigError("--line-pitch-deg", f"must be in [0, 180] deg, got {pitch}")
    rise = args.line_rise if args.line_rise is not None else (0.5 if pitch <= 90.0 else 1.2)
    most = math.degrees(MAX_INCLINE)
    incline = float(args.line_incline_deg)
    if not abs(incline) <= most + 1e-9:  # NaN too
        raise ConfigError("--line-incline-deg", f"must be in [-{most:g}, {most:g}] deg (0: level; the sign only "
                                                f"mirrors the line; steeper lines have no defined pitch), got {incline}")
    half = 1.5 * math.tan(math.radians(incline))
    z = LINE_START_HEIGHT + rise
    kw: dict[str, Any] = {"pitch": math.radians(pitch), "yaw": LineYaw[args.line_yaw.upper()]}
    if args.line_free_grasp:
        kw["grasp"] = None
    line = LineTarget.segment([args.line_distance, -1.5, z - half], [args.line_distance, 1.5, z + half], **kw)
    return State.hover([0.0, 0.0, LINE_START_HEIGHT]), line


def _line_doc(line: Any) -> dict[str, Any]:
    return {"vertices": line.vertices.tolist(), "pitch_deg": math.degrees(line.pitch), "yaw": line.yaw.name.lower(),
            "grasp": line.grasp, "gripper_offset": line.gripper_offset}


def _bounds_doc(report: Any) -> dict[str, Any] | None:
    """A :class:`~avp.bounds.BoundReport` for the JSON: ``certified``, the bounds proven
    ``violated`` and those left ``undecided`` (:class:`~avp.bounds.Bound` values); ``None`` for no report."""
    if report is None:
        return None
    return {"certified": bool(report.certified),
            "violated": list(dict.fromkeys(v.bound.value for v in report.violations)),
            "undecided": list(dict.fromkeys(b.value for b, _ in report.unknown))}


def _bounds_line(name: str, doc: dict[str, Any]) -> str:
    """``"perch certified"`` or ``"recovery NOT certified (thrust_max violated)"``."""
    if doc["certified"]:
        return f"{name} certified"
    why = [f"{b} violated" for b in doc["violated"]] + [f"{b} undecided" for b in doc["undecided"]]
    return f"{name} NOT certified" + (f" ({', '.join(why)})" if why else "")


def line_demo(args: argparse.Namespace, config: Any, options: Any = None) -> tuple[int, dict[str, Any], Any]:
    """Plan one line perch and its recovery (``options``: the ``[line]`` table's
    :class:`~avp.line_planner.LineOptions`); log a summary. Returns the exit code, the JSON
    document (with the perch's and the recovery's coefficients, as the pad demo's has its
    trajectory's) and the perch trajectory (``None`` without one), which ``--export`` writes."""
    from .line_planner import plan_line

    state, line = line_geometry(args)
    result = plan_line(state, line, config, options)
    code = 0 if result.ok else 1
    log.info("avp demo: perch on a line at %g deg pitch, %g m away, %g m above the start",
             args.line_pitch_deg, args.line_distance, float(line.vertices[:, 2].mean()) - LINE_START_HEIGHT)
    log.info("  status          : %s", result.status.value)
    for entry in result.log:
        log.debug("    - %s", entry)
    summary: dict[str, Any] = {}
    bounds = {"perch": _bounds_doc(result.bounds), "recovery": _bounds_doc(result.recovery_bounds)}
    bounds_text = ", ".join(_bounds_line(name, doc) for name, doc in bounds.items() if doc is not None)
    perch = result.perch
    if perch is not None:
        tf, r, n = perch.tf, line.gripper_offset, result.contact.n
        b3 = perch.attitude(tf)[:, 2]
        summary = {
            "duration_s": perch.duration, "grasp_fraction": result.grasp,
            "gripper_error_m": line.distance(perch(tf) - r * n),
            "b3_error_deg": math.degrees(math.acos(max(-1.0, min(1.0, float(b3 @ n))))),
            "contact_speed_m_s": float(np.linalg.norm(perch(tf, 1))),
            "recovery_s": None if result.recovery is None else result.recovery.duration,
            "certificates": {c.name: bool(c.ok) for c in result.certificates},
        }
        log.info("  perch           : %.3f s, gripper %.2e mm from the line, b3 %.2e deg from the normal, "
                 "speed %.2e mm/s", perch.duration, summary["gripper_error_m"] * 1e3, summary["b3_error_deg"],
                 summary["contact_speed_m_s"] * 1e3)
        if result.recovery is not None:
            log.info("  recovery        : %.3f s to a hover", result.recovery.duration)
        bad = [c.name for c in result.violations]
        log.info("  actuator bounds : %s", bounds_text)
        log.info("  certificates    : %d/%d hold%s", len(result.certificates) - len(bad), len(result.certificates),
                 f" (failing: {', '.join(bad)})" if bad else "")
    log.info("  planning time   : %.1f ms (perch + recovery)", 1e3 * result.timings.get("total", math.nan))
    if not result.ok:
        failing = [_bounds_line(name, doc) for name, doc in bounds.items() if doc is not None and not doc["certified"]]
        log.warning("no certified line perch: %s%s", result.status.value,
                    f" (actuator bounds: {', '.join(failing)})" if failing else "")
    from .configfile import to_mapping
    from .export import trajectory_to_dict
    from .line_planner import LineOptions

    used = options if options is not None else LineOptions()
    reports = [b for b in bounds.values() if b is not None]
    doc = {"command": "demo", "exit_code": code, "status": result.status.name,
           "bounds_certified": all(b["certified"] for b in reports) if reports else None, "bounds": bounds,
           "line": _line_doc(line),
           "start": state.position.tolist(), "summary": summary, "log": list(result.log),
           "config": {"planner": to_mapping(config), "line": to_mapping(used)},
           "trajectory": None if perch is None else trajectory_to_dict(perch),
           "recovery_trajectory": None if result.recovery is None else trajectory_to_dict(result.recovery)}
    return code, doc, perch


def line_simulate(args: argparse.Namespace, config: Any, replan: Any = None, options: Any = None) -> dict[str, Any]:
    """Seeded closed-loop line perches in both modes (:func:`avp.sim.line_run.simulate_line`) with
    the ``[replan]`` and ``[line]`` tables' settings; logs a table and returns the JSON document."""
    from .sim.line_run import LineScenario, simulate_line
    from .sim.vehicle import VehicleParams

    state, line = line_geometry(args)
    vehicle = VehicleParams(limits=config.limits)
    scenario = LineScenario(line, state.position, None if config.workspace is None else config.workspace.ground_z,
                            vehicle=vehicle)
    rows = []
    log.info("closed-loop line perches: %g deg pitch, %d seeded trials per mode (success: %s)",
             args.line_pitch_deg, args.trials, scenario.criteria)
    log.info("| mode | success | gripper err cm median / max | b3 err deg median / max |")
    log.info("|---|---|---|---|")
    for mode in ("one_shot", "avp"):
        runs = [simulate_line(scenario, mode, seed=s, config=config, replan=replan, options=options)
                for s in range(args.seed, args.seed + args.trials)]
        flown = [r for r in runs if not r.outcome.startswith("no plan")]
        ok = sum(r.success for r in runs)
        grip = [100 * r.gripper_error for r in flown] or [math.nan]
        ang = [math.degrees(r.angle_error) for r in flown] or [math.nan]
        log.info("| %s | %d/%d | %.2f / %.2f | %.2f / %.2f |", mode, ok, len(runs), np.median(grip), max(grip),
                 np.median(ang), max(ang))
        rows += [{"mode": mode, "seed": r.seed, "outcome": r.outcome, "success": r.success,
                  "gripper_error_m": r.gripper_error, "b3_error_rad": r.angle_error, "speed_m_s": r.speed,
                  "clearance_m": r.clearance} for r in runs]
    return {"command": "simulate", "line": _line_doc(line), "rows": rows}

