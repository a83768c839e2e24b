"""Sound global bound certificates of a flat-output spline (Sec. V-C, Algorithm 1, Appendix B).

Every checked quantity is a polynomial ``F`` per segment that must be negative on the whole
segment; the Rust core (``avp._avp_rust.certify_spline``) proves ``F < 0`` (:attr:`Certificate.
WITHIN`) or ``F >= 0`` somewhere (:attr:`Certificate.VIOLATED`, a root that only touches zero
counts as a violation), using a floating-point fast path with rigorous error bounds and an exact
big-integer Sturm fallback, so a ``WITHIN`` verdict is never wrong. All limits are
**mass-normalised** (thrust / mass in m/s^2, thrust rate / mass in m/s^3, rates in rad/s); the
planner converts from newtons. See ``docs/bounds.md`` for the derivations and error analysis.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from . import _avp_rust, _validate
from .errors import ConfigError

if TYPE_CHECKING:
    from .config import VehicleLimits
    from .trajectory import Trajectory

__all__ = ["EXACT_BUDGET", "Bound", "BoundReport", "Certificate", "Violation", "certify_spline", "certify_trajectory",
           "check_body_rate_degree", "drag_thrust_spline"]

EXACT_BUDGET = 0.01
"""Default time budget (s, wall clock) of the exact fallback per :func:`certify_spline` call.
Measured with ``benchmarks/bench_bounds.py``: the planner's own polynomials never needed the
exact path on the standard scenarios; on adversarial near-tangent, mixed-magnitude polynomials
(degree 10-40) the exact path (Bernstein subdivision) takes a median of ~0.3 ms and at most
~0.8 ms of CPU time (the previous Sturm path: median ~16 ms, max ~75 ms CPU), so 10 ms leaves
room for a loaded machine; a cell still undecided then is UNKNOWN, never a wrong verdict. ``inf``
restores the unbounded, never-UNKNOWN behaviour."""


class Certificate(Enum):
    """Verdict of one bound on one segment (Algorithm 1, made tri-state and sound)."""

    WITHIN = "within"
    """``F(t) < 0`` on the whole segment: proven."""
    VIOLATED = "violated"
    """``F(t) >= 0`` somewhere on the segment: proven (touching counts)."""
    UNKNOWN = "unknown"
    """Not decided: the exact fallback was disabled or ran out of its time budget."""
    NOT_CHECKED = "not checked"
    """The limit is ``inf``: the bound was skipped."""


_CODES = (Certificate.WITHIN, Certificate.VIOLATED, Certificate.UNKNOWN, Certificate.NOT_CHECKED)
_DECIDED_WITHIN = {Certificate.WITHIN: True, Certificate.VIOLATED: False, Certificate.UNKNOWN: False,
                   Certificate.NOT_CHECKED: True}
"""Whether a verdict lets a report be certified (WITHIN, or a bound not checked)."""


class Bound(Enum):
    """The checked bounds, in the row order of the kernel output."""

    THRUST_MAX = "thrust_max"
    """``||a + g e3|| < f_max``, eq. (15)."""
    THRUST_MIN = "thrust_min"
    """``||a + g e3|| > f_min``, eq. (15)."""
    THRUST_RATE = "thrust_rate"
    """``||j|| < fdot_max``, sufficient for ``|d||f||/dt| < fdot_max``, eqs. (19)-(21)."""
    TILT_RATE = "tilt_rate"
    """``||j||^2 - w_max^2 ||f||^2 < 0``, sufficient for ``w1^2 + w2^2 < w_max^2``, eq. (22)."""
    BODY_RATE = "body_rate"
    """``A||j||^2 + (B psidot^2 - w_max^2)||f||^2 < 0`` with the roll ``sin^2 phi < S`` of the
    construction (13) certified per segment (levels 45, 60, 69.3, 75.5 deg; ``(A, B) = (3, 4)``
    at the paper's assumption (25)): sufficient for ``||w|| < w_max`` at every attitude; replaces
    the paper's (26)-(29). UNKNOWN when the roll level is not decided (docs/bounds.md)."""


_BOUNDS = tuple(Bound)


@dataclass(frozen=True)
class Violation:
    """One proven violation: the bound, the segment and an estimate of the time (s)."""

    bound: Bound
    segment: int
    t: float

    def __str__(self) -> str:
        return f"{self.bound.value} violated on segment {self.segment} near t = {self.t:.4g} s"


@dataclass(frozen=True, kw_only=True)
class BoundReport:
    """Per bound and per segment verdicts of :func:`certify_spline`.

    Attributes
    ----------
    verdicts:
        ``verdicts[bound][segment]`` is a :class:`Certificate`.
    times:
        ``times[bound][segment]``: estimated absolute time (s) of a violation, NaN otherwise.
    limits:
        The mass-normalised limits checked (``inf`` = not checked).
    """

    verdicts: dict[Bound, tuple[Certificate, ...]]
    times: dict[Bound, tuple[float, ...]]
    limits: dict[Bound, float]

    @property
    def n_segments(self) -> int:
        return len(next(iter(self.verdicts.values()), ()))

    @property
    def certified(self) -> bool:
        """True when every checked bound is WITHIN on every segment."""
        return all(_DECIDED_WITHIN[v] for verdicts in self.verdicts.values() for v in verdicts)

    @property
    def violations(self) -> list[Violation]:
        """Every proven violation, bound by bound, in segment order."""
        return [
            Violation(bound, seg, self.times[bound][seg])
            for bound, verdicts in self.verdicts.items()
            for seg, v in enumerate(verdicts)
            if v is Certificate.VIOLATED
        ]

    @property
    def unknown(self) -> list[tuple[Bound, int]]:
        """``(bound, segment)`` pairs left undecided."""
        return [
            (bound, seg)
            for bound, verdicts in self.verdicts.items()
            for seg, v in enumerate(verdicts)
            if v is Certificate.UNKNOWN
        ]

    def summary(self) -> str:
        """A readable multi-line summary."""
        head = "certified" if self.certified else "NOT certified"
        lines = [f"bound certificate over {self.n_segments} segment(s): {head}"]
        for bound, verdicts in self.verdicts.items():
            if all(v is Certificate.NOT_CHECKED for v in verdicts):
                lines.append(f"  {bound.value:<12} not checked")
                continue
            cells = ", ".join(v.value for v in verdicts)
            lines.append(f"  {bound.value:<12} limit {self.limits[bound]:.6g}: {cells}")
        lines.extend(f"  - {v}" for v in self.violations)
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.summary()


def _limit(name: str, value: float) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ConfigError(name, f"must be a number, got {value!r}") from None
    if math.isnan(v) or v < 0.0:
        raise ConfigError(name, f"must be >= 0 (or inf to skip the bound), got {value!r}")
    return v


def certify_spline(
    coeffs: npt.ArrayLike,
    knots: npt.ArrayLike,
    *,
    thrust_min: float,
    thrust_max: float,
    thrust_rate_max: float = math.inf,
    tilt_rate_max: float = math.inf,
    body_rate_max: float = math.inf,
    g: float = 9.81,
    exact: bool = True,
    budget: float = EXACT_BUDGET,
) -> BoundReport:
    """Certifies the actuator bounds of a flat-output spline on every segment (Algorithm 1).

    Parameters
    ----------
    coeffs:
        Shape ``(segments, 4, C)``: axes x, y, z (m) and yaw (rad), ascending powers of
        ``t - knots[i]``.
    knots:
        Shape ``(segments + 1,)``, strictly increasing times (s).
    thrust_min, thrust_max:
        Mass-normalised thrust limits (m/s^2) of eq. (15): ``f_min < ||a + g e3|| < f_max``.
        ``thrust_min = 0`` still checks ``||f|| > 0``; ``inf`` skips a bound.
    thrust_rate_max:
        Limit on ``||j||`` (m/s^3), sufficient for the thrust rate, eq. (21).
    tilt_rate_max:
        Limit on ``sqrt(w1^2 + w2^2)`` (rad/s) through ``||j||^2 < w^2 ||f||^2``, eq. (22).
    body_rate_max:
        Limit on ``||w||`` (rad/s) including the yaw rate, after (24)-(29): the roll level
        ``sin^2 phi < S`` is certified first, then ``A||j||^2 + (B psidot^2 - w^2)||f||^2 < 0``
        (``(A, B) = (3, 4)`` for ``|phi| < pi/4``, assumption (25)); see docs/bounds.md.
    g:
        Gravity (m/s^2), positive.
    exact:
        ``True`` or ``False``: fall back to exact arithmetic when the floating-point path is unsure (default). With
        ``False`` undecided cells are :attr:`Certificate.UNKNOWN`. The body rate's roll level
        has no exact path: a segment whose roll is not decided is UNKNOWN either way.
    budget:
        Seconds the exact fallbacks of this call may take together (default
        :data:`EXACT_BUDGET`; ``inf``: no limit, never UNKNOWN with ``exact=True``). Cells still
        undecided when it runs out are :attr:`Certificate.UNKNOWN`: never a wrong WITHIN, never
        a needless VIOLATED. It is checked between steps of the exact path, so a call can
        overrun it by one step (a few ms at degree 40). The fast path alone decides realistic
        trajectories; the budget bounds the rare near-tangent case (``docs/bounds.md``).

    Returns
    -------
    BoundReport
        ``report.certified`` is True only if every checked bound is proven on every segment.

    Raises
    ------
    ConfigError
        Bad shapes, NaN/inf coefficients, non-increasing knots, negative or NaN limits,
        ``thrust_min > thrust_max``, a ``g`` that is not a positive number, an ``exact`` that is not
        a bool, or a spline whose checked polynomials exceed degree 40.
    """
    limits = {
        Bound.THRUST_MIN: _limit("thrust_min", thrust_min),
        Bound.THRUST_MAX: _limit("thrust_max", thrust_max),
        Bound.THRUST_RATE: _limit("thrust_rate_max", thrust_rate_max),
        Bound.TILT_RATE: _limit("tilt_rate_max", tilt_rate_max),
        Bound.BODY_RATE: _limit("body_rate_max", body_rate_max),
    }
    if math.isfinite(limits[Bound.THRUST_MIN]) and limits[Bound.THRUST_MIN] > limits[Bound.THRUST_MAX]:
        raise ConfigError("thrust_min", f"{thrust_min} exceeds thrust_max {thrust_max}")
    g = _validate.positive_float("g", g)  # gravity along -e3: the thrust construction needs it > 0
    exact = _validate.boolean("exact", exact)
    try:
        budget = float(budget)
    except (TypeError, ValueError):
        raise ConfigError("budget", f"must be a number of seconds, got {budget!r}") from None
    if math.isnan(budget) or budget < 0.0:
        raise ConfigError("budget", f"must be >= 0 s (inf for no limit), got {budget!r}")
    c = np.ascontiguousarray(coeffs, dtype=np.float64)
    k = np.ascontiguousarray(knots, dtype=np.float64)
    if c.ndim != 3 or c.shape[1] != 4:
        raise ConfigError("coeffs", f"expected shape (segments, 4, C), got {c.shape}")
    if k.ndim != 1 or k.shape[0] != c.shape[0] + 1:
        raise ConfigError("knots", f"expected shape ({c.shape[0] + 1},), got {k.shape}")
    # The kernel's limits vector and its output rows share one order: Bound (= BOUND_NAMES).
    row = np.array([limits[b] for b in _BOUNDS], dtype=np.float64)
    try:
        codes, times = _avp_rust.certify_spline(c, k, row, g, exact, budget)
    except _avp_rust.KernelError as exc:
        raise ConfigError(exc.arg, exc.detail) from exc
    verdicts = {b: tuple(map(_CODES.__getitem__, cells)) for b, cells in zip(_BOUNDS, codes.tolist(), strict=True)}
    tmap = {b: tuple(cells) for b, cells in zip(_BOUNDS, times.tolist(), strict=True)}
    return BoundReport(verdicts=verdicts, times=tmap, limits=limits)


def drag_thrust_spline(coeffs: npt.ArrayLike, drag: float) -> np.ndarray:
    """Coefficients ``(S, 4, C + 1)`` of ``q = p + d int p`` per segment (x, y, z; yaw as is):
    ``q'' + g e3 = a + g e3 + d v`` is the thrust with linear rotor drag ``d``
    (:class:`~avp.config.VehicleLimits` ``rotor_drag``) and ``q''' = j + d a`` its rate, so
    :func:`certify_spline` on ``q`` certifies the limits on the thrust the rotors make.
    ``q_k = p_k + d p_(k-1) / k`` in floating point (three roundings per coefficient, at the
    level of the QP solution's own; the certificate takes ``q``'s floats as the truth)."""
    c = np.asarray(coeffs, dtype=np.float64)
    out = np.zeros((c.shape[0], 4, c.shape[2] + 1))
    out[:, :, : c.shape[2]] = c
    k = np.arange(1, c.shape[2] + 1, dtype=np.float64)
    out[:, :3, 1:] += (drag / k) * c[:, :3, :]
    return out


def check_body_rate_degree(degree: int, limits: VehicleLimits) -> None:
    """Raise :class:`ConfigError` on ``config.degree`` when a body-rate limit cannot be certified
    at ``degree``: the kernel's body-rate polynomial has degree ``4 C - 10`` for ``C``
    coefficients per axis (one more with rotor drag, :func:`drag_thrust_spline`), at most 40."""
    if not math.isfinite(limits.body_rate_max):
        return
    top = 10 if limits.rotor_drag else 11
    if degree > top:
        raise ConfigError("config.degree", f"{degree} is above {top}, the highest whose body-rate certificate "
                          "(limits.body_rate_max" + (" with limits.rotor_drag" if top == 10 else "")
                          + ") stays within the kernel's degree 40: lower the degree or set body_rate_max = inf")


def certify_trajectory(traj: Trajectory, limits: VehicleLimits, g: float, *, exact: bool = True) -> BoundReport:
    """:func:`certify_spline` of a plan against a vehicle's limits, mass-normalised (thrust and
    its rate per unit mass, eqs. (15), (21)-(22) and the body rate), on the plan's exact segment
    durations (:attr:`Trajectory.knots_rel <avp.trajectory.Trajectory.knots_rel>`, so a large
    clock value does not round them); violation times are on the plan's clock. With
    ``limits.rotor_drag`` the limits are certified on the thrust ``a + g e3 + d v`` that the
    rotors make (:func:`drag_thrust_spline`), not on the drag-free ``a + g e3``."""
    check_body_rate_degree(traj.degree, limits)
    drag = limits.rotor_drag
    report = certify_spline(
        drag_thrust_spline(traj.coefficients, drag) if drag else traj.coefficients, traj.knots_rel,
        thrust_min=limits.accel_min, thrust_max=limits.accel_max,
        thrust_rate_max=limits.thrust_rate_max / limits.mass, tilt_rate_max=limits.tilt_rate_max,
        body_rate_max=limits.body_rate_max, g=g, exact=exact,
    )
    if traj.t0 == 0.0:
        return report
    times = {b: tuple(traj.t0 + t for t in cells) for b, cells in report.times.items()}
    return BoundReport(verdicts=report.verdicts, times=times, limits=report.limits)
