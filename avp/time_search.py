"""The time search (Sec. V-C): which total duration the planner tries next when a bound fails.

A plan ``p(t)`` time-scaled by ``s`` (``q(t) = p(t / s)``, every duration times ``s``) has its
``r``-th derivative scaled by ``s^-r``: acceleration by ``s^-2``, jerk by ``s^-3``, yaw rate by
``s^-1``. The mass-normalised thrust ``f = a + g e3``, the tilt-rate quantity ``|j| / |f|`` of
(22), the thrust-rate quantity ``|j|`` of (21) and the body-rate quantity of (24)-(29) of the
scaled plan are therefore known for every ``s`` from one sampling of the plan
(:func:`scaled_excess`). The SCALING search (:class:`~avp.config.TimeSearch`) moves the total
duration to the factor closest to the current one at which the scaled plan meets every bound
with a margin (:func:`predicted_factor`), re-solves there and certifies again.

The re-solved plan is not exactly the scaled one: the contact velocity, the contact thrust and
the pre-impact band are fixed in physical units, so they do not scale. The next steps are
therefore a secant on the measured excess (:class:`DurationSearch`); when the secant barely
improves (:data:`STALL`), the remaining violation is held by those fixed conditions rather than
by the time scale, and the search of that relaxation stage ends (the planner then relaxes, see
:class:`~avp.config.Relaxation`). Certificates stay as they were: the prediction only chooses
the next duration; every returned plan is certified.
"""

from __future__ import annotations

import math

import numpy as np

from . import _avp_rust
from . import _validate as v
from ._typing import Array
from .bounds import drag_thrust_spline
from .config import BoundsPolicy, TimeSearch, VehicleLimits
from .errors import ConfigError
from .trajectory import Trajectory

__all__ = ["MARGIN", "STALL", "DurationSearch", "predicted_factor", "scaled_excess"]

SCALES = np.exp(np.linspace(math.log(0.25), math.log(4.0), 97))
"""Relative time-scale factors considered by :func:`predicted_factor` (3 % apart)."""

MARGIN = 0.1
"""Relative margin the predicted plan keeps from every limit. The re-solved plan keeps less
(its contact conditions do not scale), and a plan that ends up touching a limit sends the
certificate to its slow exact path: 0.03 gave plans at 99.98 % of the Gao tilt-rate limit and
2.5 ms certificates; 0.1 certifies on the fast path (``benchmarks/bench_gao_perch.py``)."""

STALL = 0.9
"""The secant step must be predicted to bring the best worst-relative-excess below this
fraction of itself inside the factor range, or the stage's search ends (after the reach step
of :class:`DurationSearch`)."""

SAMPLES_PER_SEGMENT = 16
"""Samples per segment of the plan whose scaling is predicted (midpoints)."""

MAX_SAMPLES_PER_SEGMENT = 100_000
"""The most samples per segment :func:`scaled_excess` takes (the kernel's own bound)."""

_ONE = np.ones(1)
_ONE.setflags(write=False)  # handed to the kernel as s^-2 at scale 1 too (the planner)


def _excess(traj: Trajectory, limits: VehicleLimits, g: float, s2: Array,
            per_segment: int = SAMPLES_PER_SEGMENT) -> Array:
    """:func:`scaled_excess` by the Rust kernel (``time_scaling.rs``): it samples ``|a|^2``,
    ``a_z``, ``|j|^2`` and the yaw rate at ``per_segment`` midpoints of equal parts of every
    segment (with rotor drag ``a + d v`` and ``j + d a``, the thrust the certificate bounds,
    :func:`avp.bounds.drag_thrust_spline`) and, per scale ``s``, takes ``|a/s^2 + g e3|^2 =
    |a|^2 s^-4 + 2 g a_z s^-2 + g^2`` and ``|j/s^3|^2 = |j|^2 s^-6`` against the limits, in
    NumPy's arithmetic. ``s2`` is ``scales ** -2.0`` computed by the caller in NumPy (the same
    bits as when all of it was NumPy)."""
    drag = limits.rotor_drag
    coeffs = drag_thrust_spline(traj.coefficients, drag) if drag else traj.coefficients
    return _avp_rust.scaled_excess(
        coeffs, traj.knots_rel, per_segment, s2, g, accel_max=limits.accel_max,
        accel_min=limits.accel_min, mass=limits.mass, thrust_rate_max=limits.thrust_rate_max,
        tilt_rate_max=limits.tilt_rate_max, body_rate_max=limits.body_rate_max)


def scaled_excess(traj: Trajectory, limits: VehicleLimits, g: float, scales: Array = SCALES,
                  per_segment: int = SAMPLES_PER_SEGMENT) -> Array:
    """``excess[k]``: worst relative excess, ``max(value / limit) - 1`` over the checked bounds
    (thrust range (15), thrust rate (21), tilt rate (22), body rate (24)), of ``traj``
    time-scaled by ``scales[k]``, on ``per_segment`` samples per segment (negative: every
    sample within). A positive excess at scale 1 is a proven violation of the certified
    polynomial at a sample (the tilt and body rates as the certificate bounds them; with rotor
    drag on the drag thrust, whose time scaling the other scales take as drag-free: a
    prediction, not a proof). Bad arguments raise :class:`~avp.errors.ConfigError` naming them
    (``per_segment`` an integer in ``[1, MAX_SAMPLES_PER_SEGMENT]``, ``scales`` finite and
    positive with a finite, nonzero ``s^-2``, ``g`` finite). A sample whose arithmetic overflows
    (absurd coefficients, extreme scales) gives NaN, as NumPy's arithmetic does."""
    per_segment = v.integer("per_segment", per_segment, 1, MAX_SAMPLES_PER_SEGMENT)
    s = v.float_array("scales", scales, "time-scale factors").reshape(-1)
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        s2 = s ** -2.0
    if not (np.isfinite(s).all() and (s > 0.0).all() and np.isfinite(s2).all() and (s2 > 0.0).all()):
        raise ConfigError("scales", "time-scale factors must be finite and positive, with s^-2 a finite, "
                                    "nonzero float (s between about 1e-154 and 4e161)")
    return _excess(traj, limits, v.finite_float("g", g), s2, per_segment)


def predicted_factor(traj: Trajectory, limits: VehicleLimits, g: float, lo: float, hi: float) -> float | None:
    """The relative time-scale factor in ``[lo, hi]`` closest to 1 (in ratio) at which ``traj``,
    scaled, meets every bound with :data:`MARGIN` on the samples; ``None`` when there is none."""
    return _predict_with_excess(traj, limits, g, lo, hi)[0]


def _predict_with_excess(traj: Trajectory, limits: VehicleLimits, g: float,
                         lo: float, hi: float) -> tuple[float | None, float]:
    """:func:`predicted_factor` and the excess at scale 1, from one call of the kernel (each
    scale's excess is computed on its own: the same values as separate calls)."""
    scales = SCALES[(SCALES >= lo) & (SCALES <= hi)]
    excess = _excess(traj, limits, g, np.concatenate((_ONE, scales)) ** -2.0)
    at_one = float(excess[0])
    if scales.size == 0:
        return None, at_one
    ok = scales[excess[1:] < -MARGIN]
    if ok.size == 0:
        return None, at_one
    return float(ok[np.argmin(np.abs(np.log(ok)))]), at_one


class DurationSearch:
    """The total-duration factors of one relaxation stage, chosen one at a time.

    Call :meth:`next` after each attempt; it returns the next factor of the initial durations,
    or ``None`` when the stage's search is over. PAPER and BIDIRECTIONAL walk
    ``policy.schedule()``. SCALING predicts: its first step from the scaling law of the plan
    (:func:`predicted_factor`, which also fixes the direction, longer or shorter), the next ones
    by a secant on the measured excess against the log of the factor through the two best plans,
    in that direction only, and it stops when the secant line does not bring the best excess
    below :data:`STALL` of itself inside the factor range. With ``reach`` (the first stage,
    before anything is relaxed) it then tries the end of the range in that direction once: the
    measured excess can stay flat over small changes and fall later, when the fixed contact
    conditions weigh less. After a QP without a solution it tries the longest and the shortest
    total once each; after a plan whose bounds hold but whose workspace does not it walks
    ``policy.schedule()``.
    """

    def __init__(self, policy: BoundsPolicy, *, reach: bool = False) -> None:
        self.policy = policy
        self.reach = reach
        self.fixed = policy.schedule() if policy.certify else ()
        self.lo = min((1.0, *self.fixed))
        self.hi = max((1.0, *self.fixed))
        self.tried = [1.0]
        self.predicted = 0
        self.direction = 0  # +1 longer, -1 shorter: the scaling law's first step
        self.measured: list[tuple[float, float]] = []  # (log factor, sampled excess)

    @property
    def current(self) -> float:
        return self.tried[-1]

    def _untried(self, k: float) -> bool:
        return all(abs(math.log(k / t)) > 0.01 for t in self.tried)

    def _next_fixed(self) -> float | None:
        for k in self.fixed:
            if self._untried(k):
                self.tried.append(k)
                return k
        return None

    def next(self, traj: Trajectory | None, bounds_failed: bool, limits: VehicleLimits, g: float) -> float | None:
        """The next factor after an attempt that gave ``traj`` (``None``: no solution) whose
        bound certificate failed (``bounds_failed``) or held (the workspace did not)."""
        if not self.fixed:
            return None
        if self.policy.time_search is not TimeSearch.SCALING or not bounds_failed:
            return self._next_fixed()
        if traj is None:  # no solution: the longest and the shortest total once each, then stop
            return next((self._step(k) for k in (self.hi, self.lo) if self._untried(k)), None)
        if self.predicted >= self.policy.max_steps:
            return None
        current = self.current
        if not self.measured:  # the scaling law of this plan
            s, excess = _predict_with_excess(traj, limits, g, self.lo / current, self.hi / current)
            self.measured.append((math.log(current), excess))
            if s is None:
                return None
            if abs(math.log(s)) < 0.02:  # the samples miss what the certificate found: nudge
                s = 1.03 if s >= 1.0 else 1.0 / 1.03
            self.direction = 1 if s > 1.0 else -1
            return self._step(current * s)
        self.measured.append((math.log(current), float(_excess(traj, limits, g, _ONE)[0])))  # 1^-2 = 1
        k = self._secant()
        return k if k is not None else self._reach()

    def _secant(self) -> float | None:
        """Secant on the measured excess against log(factor), through the two best points."""
        (x1, e1), (x2, e2) = sorted(self.measured, key=lambda m: m[1])[:2]
        if x1 == x2 or e1 == e2:
            return None
        slope = (e2 - e1) / (x2 - x1)
        x = x1 + (-MARGIN - e1) / slope
        if (x - x1) * self.direction <= 0.0:
            return None  # back against the scaling law
        # clamped in log space: a nearly flat secant puts x far beyond the range (exp overflows)
        k = math.exp(min(max(x, math.log(self.lo)), math.log(self.hi)))
        if e1 > 0.0 and e1 + slope * (math.log(k) - x1) > STALL * e1:
            return None  # the line barely improves inside the range: held by fixed conditions
        return self._step(k)

    def _reach(self) -> float | None:
        if not self.reach or self.direction == 0:
            return None
        end = self.hi if self.direction > 0 else self.lo
        return self._step(end)

    def _step(self, k: float) -> float | None:
        k = min(max(k, self.lo), self.hi)
        if not self._untried(k):
            return None
        self.predicted += 1
        self.tried.append(k)
        return k
