"""What the target estimate allows: the ideal perch on an estimate, an approximate bound for the closed loop.

A closed-loop perch can be no better than the estimate it steers to. This module judges, with
the simulator's own criteria (:func:`~avp.sim.contact.judge_perch`), an *ideal* vehicle that
reaches the estimated pad centre exactly at the plan's contact time ``t_f``, along a straight
line with the requested contact velocity (in the estimated pad frame) and its thrust along the
estimated normal: no tracking error, no actuator limits, no planning. It flies its believed
position, as the real vehicle does, so the odometry's drift it shares with the detections (both
are composed with the drifting pose) cancels. It uses the detections a
run delivered to its filter up to ``t_f - tau`` (``tau``: how long before contact the last
correction must be committed to be flown; the replanner's ``freeze_horizon`` is 0.25 s).

Two estimates are judged:

- ``filter``: the run's own user-side filter (:class:`~avp.sim.estimator.TargetEstimator` with
  the scenario's settings) re-fused from those detections;
- ``known_scale``: the detections with the camera's true per-run scale error removed, fused by
  inverse variance. No filter has that knowledge; it shows what the scale error costs.

The ideal vehicle reaches the estimate itself. A pad found too deep is hit early, and the
contact velocity's slide along ``s1`` carries that timing into the in-plane position (on a wall
at the paper's 0.3 m/s into the pad and 2 m/s down it, 1 cm too deep is about 6.7 cm too high).
One found too shallow is judged at ``t_f``, short of the plane. :meth:`EstimateLimit.judge`
can aim off the estimate, by a constant offset along the normal and along ``s1``. Over many
runs, the best constant aim (in hindsight) bounds what a closed loop reaches when its own errors
are independent of the estimate's: averaging over an independent error cannot beat the best
fixed shift. A replanner's errors are not fully independent of its estimate (it reacts to it),
so the bound is approximate, and a steady tracking lag can beat the ideal aimed at the estimate
itself (``@0``).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ..config import ContactVelocity
from ..errors import ConfigError
from ..frames import Array
from ..types import PerchTarget
from .contact import PerchCriteria, PerchOutcome, PerchPad, judge_perch
from .estimator import TargetEstimator
from .run import SimResult

__all__ = ["EstimateLimit", "estimate_before", "estimate_limit", "ideal_perch"]


def ideal_perch(estimate: PerchTarget, pad: PerchPad, v_S: Array, t_f: float,
                criteria: PerchCriteria | None = None, drift: Array | None = None) -> PerchOutcome:
    """Judge a vehicle that reaches ``estimate.point`` at ``t_f`` with velocity ``R_WS_est v_S``
    (``v_S = (v.s1, v.s2, v.s3)`` in the estimated frame) along a straight line, ``b3`` along
    the estimated normal, against the true ``pad``.

    ``drift`` (m): the odometry's drift at ``t_f`` (believed minus true position). The vehicle
    flies what it believes, so it truly arrives at ``estimate.point - drift``; detections
    composed with the same drifting pose carry it too, and the two cancel as they do in flight.

    The pose is judged at ``t_f``, or at the crossing of the true pad plane if that comes
    first, as :func:`~avp.sim.run.simulate` judges a run (``criteria``: default
    :class:`~avp.sim.contact.PerchCriteria`).
    """
    v_S = np.asarray(v_S, dtype=float)
    if v_S.shape != (3,) or not np.all(np.isfinite(v_S)):
        raise ConfigError("v_S", f"expected 3 finite numbers (m/s), got {v_S!r}")
    v_W = estimate.R_WS @ v_S
    end = estimate.point if drift is None else estimate.point - np.asarray(drift, dtype=float)
    d_f = pad.signed_distance(end)
    v_n = float(v_W @ pad.R_WS[:, 2])  # < 0: towards the pad
    t = float(t_f)
    if d_f < 0.0 and v_n < 0.0:
        t = t_f - d_f / v_n  # the crossing, before t_f (a path that never crosses is judged at t_f)
    p = end + v_W * (t - t_f)
    return judge_perch(t, p, estimate.R_WS, pad, criteria if criteria is not None else PerchCriteria())


def estimate_before(result: SimResult, tau: float, *, known_scale: bool = False) -> PerchTarget | None:
    """The target estimate from the detections ``result`` delivered up to ``t_f - tau`` (``t_f``
    the final plan's contact time), fused by the scenario's filter, or with the camera's true
    scale error removed and fused by inverse variance (``known_scale``). None without a plan or
    a detection by then."""
    sc = result.scenario
    if sc.platform is not None:
        raise ConfigError("result", "the estimate limit is defined for a static pad; this run's pad moves")
    if result.final_plan is None:
        return None
    t_cut = result.final_plan.tf - float(tau)
    ms = [m for m in result.measurements if m.t_delivered <= t_cut]
    if not ms:
        return None
    if known_scale:
        b = result.detector_scale
        est = TargetEstimator()
        for m in ms:
            if m.p_cam_W is None:
                raise ConfigError("result", "a detection without the camera position cannot be unscaled")
            est.update(dataclasses.replace(m, p_W=m.p_cam_W + (m.p_W - m.p_cam_W) / (1.0 + b)))
    else:
        est = sc.target_filter()
        for m in ms:
            est.update(m)
    e = est.estimate()
    assert e is not None
    return PerchTarget(point=e.p_W, R_WS=e.R_WS)


@dataclass(frozen=True, eq=False)
class EstimateLimit:
    """One run's estimates ``tau`` s before contact and the ideal perch on them (module docstring).

    ``filter`` / ``known_scale`` are the two estimates (None without a detection by then),
    ``normal_error`` their errors along the true normal (m, > 0: in front of the pad), net of
    the odometry drift at ``t_f`` (``drift``), which the vehicle shares with them. The pad,
    contact velocity ``v_S``, contact time ``t_f`` and criteria are the run's.
    """

    tau: float
    filter: PerchTarget | None
    known_scale: PerchTarget | None
    normal_error: tuple[float, float]
    pad: PerchPad
    v_S: Array
    t_f: float
    criteria: PerchCriteria
    drift: Array

    def judge(self, normal_offset: float = 0.0, slope_offset: float = 0.0) -> tuple[PerchOutcome | None, PerchOutcome | None]:
        """The ideal perch on ``(filter, known_scale)``, aimed ``normal_offset`` (m) in front of
        each estimate along its normal and ``slope_offset`` (m) along its ``s1`` (negative: down
        the slope; no ``sin(incline)`` factor). The best constant aim over many runs is the module's
        approximate bound. A scenario's aim (:class:`~avp.sim.run.SimScenario`) is
        ``judge(-aim_normal, -aim_slope sin(incline))`` on the unaimed estimate."""
        out: list[PerchOutcome | None] = []
        for e in (self.filter, self.known_scale):
            if e is None:
                out.append(None)
                continue
            aimed = PerchTarget(point=e.point + float(normal_offset) * e.s3 + float(slope_offset) * e.s1, R_WS=e.R_WS)
            out.append(ideal_perch(aimed, self.pad, self.v_S, self.t_f, self.criteria, self.drift))
        return out[0], out[1]


def estimate_limit(result: SimResult, taus: tuple[float, ...] = (0.6, 0.45, 0.25),
                   contact_velocity: ContactVelocity | None = None) -> tuple[EstimateLimit, ...]:
    """:class:`EstimateLimit` of ``result`` for each ``tau`` (s), with the planner's
    ``contact_velocity`` (default :class:`~avp.config.ContactVelocity`; a free component
    counts as 0). Empty without a final plan."""
    sc = result.scenario
    if result.final_plan is None:
        return ()
    cv = contact_velocity if contact_velocity is not None else ContactVelocity()
    v_S = np.array([0.0 if c is None else c for c in cv.components(sc.incline)])
    truth, pad = sc.target(), sc.pad()
    t_f = result.final_plan.tf
    drift = np.zeros(3)
    if result.path_drift is not None and result.path_drift.shape[0] == result.path_t.size and result.path_t.size:
        drift = result.path_drift[int(np.clip(np.searchsorted(result.path_t, t_f), 0, result.path_t.size - 1))]
    out = []
    for tau in taus:
        est = [estimate_before(result, tau, known_scale=known) for known in (False, True)]
        err = tuple(float("nan") if e is None else float((e.point - drift - truth.point) @ truth.s3) for e in est)
        out.append(EstimateLimit(tau=float(tau), filter=est[0], known_scale=est[1], normal_error=(err[0], err[1]),
                                 pad=pad, v_S=v_S, t_f=t_f, criteria=sc.perch_criteria, drift=drift))
    return tuple(out)
