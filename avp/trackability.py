"""Sound trackability certificate: the snap of a plan stays below a limit (Sec. V-C, Alg. 1).

A vehicle tracks a flat-output reference only if it can deliver the reference's angular
acceleration, which the flatness map ties to the snap ``s = x''''`` (the paper's (30)-(36)). With
``b3 = f/|f|``, ``f = a + g e3``::

    b3'' = P s / |f| + P' j / |f| - P j (b3 . j) / |f|^2,   P = I - b3 b3^T,
    |b3''| <= |s| / |f| + 3 |j|^2 / |f|^2,

so a certified snap bound ``|s| < s_max`` together with the certified thrust floor
``|f| > f_min`` and tilt-rate bound ``|j| < w_max |f|`` (:mod:`avp.bounds`) gives
``|b3''| < s_max / f_min + 3 w_max^2``, and the tilt part of the angular acceleration satisfies
``|Omega'_{1,2}| <= |b3''| + |Omega_3| |Omega_{1,2}|``. The certificate itself is on the snap:

    F_i(u) = |s_i(T_i u)|^2 - s_max^2 < 0   for u in [0, 1], every segment i,

in the normalised time ``u = (t - t_i) / T_i``. Soundness of the coefficients: the spline's
float coefficients and knots are read as exact rationals, ``F_i``'s coefficients are computed
exactly with :class:`fractions.Fraction` (a degree-``2(N-4)`` polynomial: a few hundred
operations), and each is rounded *upward* to the next float. Because ``u^k >= 0`` on ``[0, 1]``,
the rounded polynomial is ``>= F_i`` pointwise, so proving it negative proves ``F_i < 0``. The
proof is the Rust kernel ``avp._avp_rust.certify_below_many`` (floating-point fast path with
rigorous error bounds and an exact fallback, ``docs/bounds.md``): a ``WITHIN`` verdict is never
wrong. A ``VIOLATED`` verdict on the rounded polynomial is reported as such (its rounding is at
most one ulp per coefficient; the kernel's estimated time shows where).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from fractions import Fraction

import numpy as np

from . import _avp_rust
from .bounds import Certificate
from .errors import ConfigError
from .trajectory import Trajectory

__all__ = ["SnapReport", "certify_snap", "snap_polynomial"]


def _round_up(q: Fraction) -> float:
    """The smallest float ``>= q``."""
    x = float(q)  # round to nearest
    if Fraction(x) < q:
        x = math.nextafter(x, math.inf)
    return x


def snap_polynomial(coefficients: np.ndarray, duration: float | Fraction, snap_max: float) -> np.ndarray:
    """Upper-bounding float coefficients (ascending, in ``u``) of ``|s(T u)|^2 - s_max^2``.

    ``coefficients`` is one segment's ``(4, N + 1)`` (x, y, z, yaw; only x, y, z are used) in
    powers of ``t - t_i``; ``duration`` is ``T``. Every returned coefficient is ``>=`` the exact
    one (module docstring). Pass ``duration`` as a :class:`~fractions.Fraction` (the exact knot
    difference) to avoid rounding it.
    """
    c = np.asarray(coefficients, dtype=float)
    n = c.shape[1] - 1
    if n < 4:
        return np.array([_round_up(-Fraction(float(snap_max)) ** 2)])
    T = duration if isinstance(duration, Fraction) else Fraction(float(duration))
    total = [Fraction(0)] * (2 * (n - 4) + 1)
    for axis in range(3):
        # s(T u) = sum_k c_{k+4} (k+4)!/k! T^{k+4} ... in t: s(t) = sum_k c_{k+4} (k+4)!/k! t^k
        s = [Fraction(float(c[axis, k + 4])) * math.factorial(k + 4) / math.factorial(k) * T**k
             for k in range(n - 3)]
        for i, si in enumerate(s):
            if si == 0:
                continue
            for j, sj in enumerate(s):
                total[i + j] += si * sj
    total[0] -= Fraction(float(snap_max)) ** 2
    return np.array([_round_up(q) for q in total], dtype=np.float64)


@dataclass(frozen=True)
class SnapReport:
    """Per-segment verdicts of :func:`certify_snap` (``snap_max`` in m/s^4)."""

    snap_max: float
    verdicts: tuple[Certificate, ...]
    times: tuple[float, ...]

    @property
    def certified(self) -> bool:
        """``|snap| < snap_max`` proven on every segment (always True for ``inf``)."""
        return all(v in (Certificate.WITHIN, Certificate.NOT_CHECKED) for v in self.verdicts)

    def summary(self) -> str:
        head = "certified" if self.certified else "NOT certified"
        cells = ", ".join(v.value for v in self.verdicts)
        return f"snap < {self.snap_max:g} m/s^4: {head} ({cells})"


def certify_snap(trajectory: Trajectory, snap_max: float, *, exact: bool = True) -> SnapReport:
    """Prove ``|x''''(t)| < snap_max`` (m/s^4) on every segment of ``trajectory`` (module
    docstring). ``inf`` skips the check (verdicts :attr:`Certificate.NOT_CHECKED`)."""
    try:
        smax = float(snap_max)
    except (TypeError, ValueError):
        raise ConfigError("snap_max", f"must be a number, got {snap_max!r}") from None
    if math.isnan(smax) or smax <= 0:
        raise ConfigError("snap_max", f"must be > 0 m/s^4 (or inf to skip), got {snap_max!r}")
    n_seg = trajectory.n_segments
    if math.isinf(smax):
        return SnapReport(smax, (Certificate.NOT_CHECKED,) * n_seg, (math.nan,) * n_seg)
    knots = trajectory.knots
    polys = np.ascontiguousarray(np.stack([
        snap_polynomial(trajectory.coefficients[i], Fraction(float(knots[i + 1])) - Fraction(float(knots[i])), smax)
        for i in range(n_seg)
    ]))
    codes, t, _ = _avp_rust.certify_below_many(polys, 0.0, 1.0, exact)
    codes_map = (Certificate.WITHIN, Certificate.VIOLATED, Certificate.UNKNOWN)
    times = tuple(
        float(knots[i] + ti * (knots[i + 1] - knots[i])) if np.isfinite(ti) else math.nan
        for i, ti in enumerate(t)
    )
    return SnapReport(smax, tuple(codes_map[int(c)] for c in codes), times)
