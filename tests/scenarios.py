"""Named planning scenarios (as qpsolvers' tests/problems.py): the paper's tables' grid of
inclines x stand-offs, starting at hover at the pad's height (1 m above it below 45 deg)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

import avp

INCLINES_DEG = (0, 30, 60, 90)
STANDOFFS = (1.5, 3.5, 7.5)
PAD = np.array([0.0, 0.0, 1.5])


@dataclass(frozen=True)
class Scenario:
    name: str
    state: avp.State
    target: avp.PerchTarget


def standard(incline_deg: float, standoff: float, heading: float = 0.0) -> Scenario:
    """Pad at ``PAD`` facing a vehicle ``standoff`` m away horizontally along ``heading``."""
    target = avp.PerchTarget.from_incline(PAD, math.radians(incline_deg), heading=heading)
    h = np.array([math.cos(heading), math.sin(heading), 0.0])
    height = 1.0 if incline_deg < 45 else 0.0
    start = PAD - standoff * h + np.array([0.0, 0.0, height])
    return Scenario(f"incline{incline_deg}-d{standoff}", avp.State.hover(start, yaw=heading), target)


def standard_grid() -> list[Scenario]:
    return [standard(i, d) for i in INCLINES_DEG for d in STANDOFFS]
