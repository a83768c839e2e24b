"""The command-line grid shared by the closed-loop sweeps: trials, first seed, inclines and
stand-offs, defaulting to the realistic :class:`avp.sim.evaluate.SimConfig` grid; the
replanner's step budget option they share with ``bench_replan.py``; and the grid, collector and
simulator options of the step benchmarks (``bench_replan.py``, ``bench_background.py``)."""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import gc
import math
from collections.abc import Iterator

from avp.replan import ReplanConfig
from avp.sim.evaluate import SimConfig
from avp.sim.run import SimScenario


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


def add_loop_options(ap: argparse.ArgumentParser, seeds: int) -> None:
    """The step benchmarks' grid (``--seeds``, ``--distances``, ``--inclines``), collector
    (``--gc-freeze``, ``--gc-between-steps``) and simulator (``--realistic``, ``--backend``)
    options; :func:`loop_scenario` builds a run's scenario from them."""
    ap.add_argument("--seeds", type=int, default=seeds)
    ap.add_argument("--distances", type=float, nargs="+", default=[1.5, 4.5, 7.5])
    ap.add_argument("--inclines", type=float, nargs="+", default=[90.0, 45.0], help="degrees")
    ap.add_argument("--gc-freeze", action="store_true",
                    help="gc.freeze() after the imports and a first run, as a real-time loop would after its setup")
    ap.add_argument("--gc-between-steps", action="store_true",
                    help="the cyclic garbage collector off inside each step and on again after it, so that a "
                         "collection that falls due runs between steps, as a real-time loop schedules it")
    ap.add_argument("--realistic", action="store_true",
                    help="the realistic simulator of the success sweeps (SimConfig().scenario: motor lag, "
                         "odometry drift, biased detections) instead of SimScenario's defaults")
    ap.add_argument("--backend", choices=["avp", "rotorpy"], default="avp",
                    help="the simulator that integrates the vehicle (rotorpy: its rotor drag model, which the "
                         "planner then knows, VehicleLimits.rotor_drag; needs avp[rotorpy])")


def loop_scenario(args: argparse.Namespace, incline_deg: float, distance: float) -> SimScenario:
    """The scenario of one run (:func:`add_loop_options`): the realistic one of the success
    sweeps or ``SimScenario``'s defaults, on ``--backend``."""
    sc = (SimConfig().scenario(incline_deg, distance) if args.realistic
          else SimScenario(distance=distance, incline=math.radians(incline_deg)))
    return dataclasses.replace(sc, backend=args.backend)


@contextlib.contextmanager
def collector_off(enabled: bool) -> Iterator[None]:
    """With ``enabled`` (``--gc-between-steps``) and the collector on, the collector off inside
    the block and on again after it: a collection that falls due runs at the next allocation,
    outside the block."""
    between = enabled and gc.isenabled()
    if between:
        gc.disable()
    try:
        yield
    finally:
        if between:
            gc.enable()
