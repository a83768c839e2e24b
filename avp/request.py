"""Checks that a planning request makes physical sense before any QP is built.

Each rule raises :class:`~avp.errors.ConfigError` naming the field and saying what to change
(a start on or behind the pad's plane is rejected by :func:`avp.safety.check_endpoints`, the
perch-plane clearance region, with the other workspace limits):

* the requested contact velocity does not move into the pad (``v . s3 >= 0``): a contact needs
  ``ContactVelocity.normal < 0``;
* the contact attitude ``R_WS`` cannot be represented by the attitude construction (13)
  (:func:`avp.frames.contact_yaw`);
* the requested contact velocity is out of reach: ``|v(t_f) - v(0)| = |int a dt| <=
  (f_max + g) T`` because ``|a| <= |a + g e3| + g`` and the thrust (15) is at most ``f_max``,
  so a velocity change larger than ``(f_max + g) T_max``, with ``T_max`` the longest total
  duration the time search tries, is impossible for every trajectory the planner can return.
"""

from __future__ import annotations

import numpy as np

from .config import PlannerConfig
from .errors import ConfigError
from .frames import contact_yaw
from .types import PerchTarget, State

__all__ = ["check_request", "longest_total_time"]


def longest_total_time(config: PlannerConfig, total: float) -> float:
    """The longest total duration (s) the time search tries from ``total`` (Sec. V-C)."""
    factors = config.bounds.schedule() if config.bounds.certify else ()
    return total * max((1.0, *factors))


def check_request(state: State, target: PerchTarget, config: PlannerConfig, total: float) -> None:
    """Raises :class:`ConfigError` when the request makes no physical sense (module docs).

    ``total`` is the first total duration (s) the planner will try.
    """
    cv = config.contact_velocity
    if cv.normal is not None and cv.normal >= 0.0:
        raise ConfigError(
            "contact_velocity.normal",
            f"is {cv.normal} m/s: v . s3 >= 0 does not move into the pad (s3 points out of it), so "
            "the vehicle never arrives; use a negative value (paper: -0.3 m/s) or None to leave it free",
        )
    contact_yaw(target.R_WS)  # raises ConfigError("target.R_WS") for a singular contact attitude
    # The fixed components of v(t_f) in S against the start velocity; free ones can match it.
    names = ("slope", "lateral", "normal")
    gaps = [
        (abs(float(value) - float(state.velocity @ axis)), name)
        for name, axis, value in zip(names, target.R_WS.T, cv.components(target.incline), strict=True)
        if value is not None
    ]
    if not gaps:
        return
    dv = float(np.sqrt(sum(gap**2 for gap, _ in gaps)))
    t_max = longest_total_time(config, total)
    reach = (config.limits.accel_max + config.g) * t_max
    if dv > reach:
        worst = max(gaps)[1]
        raise ConfigError(
            f"contact_velocity.{worst}",
            f"asks the velocity to change by at least {dv:.4g} m/s between the start and contact, but "
            f"|v(t_f) - v(0)| <= (f_max + g) T_max = ({config.limits.accel_max:.4g} + {config.g:.4g}) "
            f"m/s^2 x {t_max:.4g} s = {reach:.4g} m/s for every plan the time search can return "
            "(|a| <= |a + g e3| + g, thrust (15) <= f_max); ask for a slower contact, raise "
            "limits.thrust_max or pass longer durations",
        )
