"""The command-line grid shared by the closed-loop sweeps: trials, first seed, inclines and
stand-offs, defaulting to the realistic :class:`avp.sim.evaluate.SimConfig` grid."""

from __future__ import annotations

import argparse

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
