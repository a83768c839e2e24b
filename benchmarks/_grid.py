"""The command-line grid shared by the closed-loop sweeps: trials, first seed, inclines and
stand-offs, defaulting to the realistic :class:`avp.sim.evaluate.SimConfig` grid; and the
replanner's step budget option they share with ``bench_replan.py``."""

from __future__ import annotations

import argparse

from avp.replan import ReplanConfig
from avp.sim.evaluate import SimConfig


def grid_parser(doc: str | None) -> argparse.ArgumentParser:
    """An argument parser with ``--trials``, ``--seed``, ``--inclines`` (deg), ``--distances`` (m)."""
    base = SimConfig()
    ap = argparse.ArgumentParser(description=(doc or "").splitlines()[0] if doc else None)
    ap.add_argument("--trials", type=int, default=base.n_trials)
    ap.add_argument("--seed", type=int, default=base.seed)
    ap.add_argument("--inclines", type=float, nargs="+", default=list(base.inclines_deg))
    ap.add_argument("--distances", type=float, nargs="+", default=list(base.distances))
    return ap


def add_vehicle_options(ap: argparse.ArgumentParser) -> None:
    """``--contact-normal`` and ``--contact-slope`` (m/s): the contact velocity the simulated
    user asks for (:attr:`avp.sim.evaluate.SimConfig.contact_normal` / ``contact_slope``);
    ``--camera-uptilt-deg``: its camera's mount (``SimConfig.camera_uptilt_deg``)."""
    base = SimConfig()
    ap.add_argument("--camera-uptilt-deg", type=float, default=base.camera_uptilt_deg,
                    help="SimConfig.camera_uptilt_deg: the front camera tilted up by this angle (deg; 0: level)")
    ap.add_argument("--contact-normal", type=float, default=base.contact_normal,
                    help="SimConfig.contact_normal: velocity into the pad at contact (m/s, < 0; the paper's -0.3)")
    ap.add_argument("--contact-slope", type=float, default=base.contact_slope,
                    help="SimConfig.contact_slope: velocity along s1 at contact on a wall (m/s, times sin(incline); "
                         "the paper's -2: down the slope)")


def add_timing_options(ap: argparse.ArgumentParser) -> None:
    """``--deadline-ms``: :attr:`avp.ReplanConfig.deadline` of AVP's steps, in ms;
    ``--adapt-latency``: :attr:`avp.ReplanConfig.adapt_latency`; ``--partial-min-correction``:
    :attr:`avp.ReplanConfig.partial_min_correction`; and ``--no-retime-backoff``:
    :attr:`avp.ReplanConfig.retime_backoff` off."""
    ap.add_argument("--deadline-ms", type=float, default=None,
                    help="ReplanConfig.deadline (ms) of AVP's steps: a solve starts only while it is predicted "
                         "to fit (decisions then depend on this machine's speed)")
    ap.add_argument("--adapt-latency", action="store_true",
                    help="ReplanConfig.adapt_latency: switch to a new plan no sooner than latency_margin times "
                         "the recent median planning call (decisions then depend on this machine's speed)")
    ap.add_argument("--partial-min-correction", type=float, default=0.0,
                    help="ReplanConfig.partial_min_correction (m, rad): in an anchored step, a partial fraction "
                         "is tried only when it moves the goal by more than this")
    ap.add_argument("--no-retime-backoff", action="store_true",
                    help="ReplanConfig.retime_backoff off: retimed retries at every step, also right after "
                         "a step whose retries all failed")


def replan_config(args: argparse.Namespace) -> ReplanConfig | None:
    """The replanning policy ``--deadline-ms``, ``--adapt-latency``, ``--partial-min-correction``
    and ``--no-retime-backoff`` ask for (``None``: the default policy)."""
    if args.deadline_ms is None and not args.adapt_latency and not args.no_retime_backoff \
            and not args.partial_min_correction:
        return None
    return ReplanConfig(deadline=None if args.deadline_ms is None else args.deadline_ms * 1e-3,
                        adapt_latency=bool(args.adapt_latency), retime_backoff=not args.no_retime_backoff,
                        partial_min_correction=args.partial_min_correction)
