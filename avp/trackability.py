"""Sound trackability certificate: the snap of a plan stays below a limit (Sec. V-C, Alg. 1).

A vehicle tracks a flat-output reference only if it can deliver the reference's angular
acceleration, which the flatness map ties to the snap ``s = x''''`` (the paper's (30)-(36)). With
``b3 = f/|f|``, ``f = a + g e3``::

    b3'' = P s / |f| + P' j / |f| - P j (b3 . j) / |f|^2,   P = I - b3 b3^T,
    |b3''| <= |s| / |f| + 3 |j|^2 / |f|^2,

so a certified snap bound ``|s| < s_max`` together with the certified thrust floor
``|f| > f_min`` and tilt-rate bound ``|j| < w_max |f|`` (:mod:`avp.bounds`) gives
``|b3''| < s_max / f_min + 3 w_max^2``, and the tilt part of the angular acceleration satisfies
``|Omega'_{1,2}| <= |b3''| + |Omega_3| |Omega_{1,2}|``. (With rotor drag ``d`` the bounds of
:mod:`avp.bounds` are on ``f = a + g e3 + d v`` and ``f' = j + d a``, and ``f''`` is
``s + d j``: the same argument holds with ``|s| + d |j|`` for ``|s|``; this certificate stays on
the snap and the drag-free ``|a + g e3|``, a trackability margin, not a limit of the vehicle.)
The certificate itself is on the snap:

    F_i(u) = |s_i(T_i u)|^2 - s_max^2 < 0   for u in [0, 1], every segment i,

and, since the angular acceleration the flatness map asks for scales as ``|s| / |f|`` while the
moment a quadrotor can produce shrinks with its thrust (the rotors near their floor leave no room
for a differential), the thrust-relative form

    G_i(u) = |s_i(T_i u)|^2 - k^2 |a_i(T_i u) + g e3|^2 < 0,   i.e. |s| < k |f|,

in the normalised time ``u = (t - t_i) / T_i``. Soundness of the coefficients: the spline's
float coefficients and knots are read as exact rationals (every float is a dyadic rational
``m 2^e``), ``F_i``'s coefficients are computed exactly (a degree-``2(N-4)`` polynomial: a few
hundred operations), and each is rounded *upward* to the next float. The computation is the
Rust kernel ``avp._avp_rust.trackability_rows`` (big-integer mantissas with a binary exponent:
sums and products of dyadic rationals stay dyadic, so no division or gcd is needed); the
reference :class:`fractions.Fraction` computation (:func:`snap_polynomial`,
:func:`snap_thrust_polynomial`) gives the same floats bit for bit and is the fallback when a
coefficient leaves the normal float range. Because ``u^k >= 0`` on ``[0, 1]``,
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

__all__ = ["SnapReport", "certify_snap", "snap_polynomial", "snap_thrust_polynomial", "trackability_peaks",
           "trackability_rows"]


def _round_up(q: Fraction) -> float:
    """The smallest float ``>= q``."""
    x = float(q)  # round to nearest
    if Fraction(x) < q:
        x = math.nextafter(x, math.inf)
    return x


def _axis_derivative(c: np.ndarray, order: int, T: Fraction) -> list[Fraction]:
    """Exact ascending coefficients in ``u`` of ``d^order/dt^order`` of one axis, ``t = T u``."""
    n = c.shape[0] - 1
    return [Fraction(float(c[k + order])) * math.factorial(k + order) / math.factorial(k) * T**k
            for k in range(max(n - order + 1, 0))]


def _square_norm(rows: list[list[Fraction]]) -> list[Fraction]:
    """Exact coefficients of ``sum_axis p_axis(u)^2``."""
    size = max((2 * len(r) - 1 for r in rows if r), default=1)
    out = [Fraction(0)] * size
    for r in rows:
        for i, ri in enumerate(r):
            if ri == 0:
                continue
            for j, rj in enumerate(r):
                out[i + j] += ri * rj
    return out


def _duration(duration: float | Fraction) -> Fraction:
    return duration if isinstance(duration, Fraction) else Fraction(float(duration))


def snap_polynomial(coefficients: np.ndarray, duration: float | Fraction, snap_max: float) -> np.ndarray:
    """Upper-bounding float coefficients (ascending, in ``u``) of ``|s(T u)|^2 - s_max^2``.

    ``coefficients`` is one segment's ``(4, N + 1)`` (x, y, z, yaw; only x, y, z are used) in
    powers of ``t - t_i``; ``duration`` is ``T``. Every returned coefficient is ``>=`` the exact
    one (module docstring). Pass ``duration`` as a :class:`~fractions.Fraction` (the exact knot
    difference) to avoid rounding it.
    """
    c = np.asarray(coefficients, dtype=float)
    T = _duration(duration)
    total = _square_norm([_axis_derivative(c[a], 4, T) for a in range(3)])
    total[0] -= Fraction(float(snap_max)) ** 2
    return np.array([_round_up(q) for q in total], dtype=np.float64)


def snap_thrust_polynomial(coefficients: np.ndarray, duration: float | Fraction, ratio_max: float,
                           g: float) -> np.ndarray:
    """Upper-bounding float coefficients (ascending, in ``u``) of
    ``|s(T u)|^2 - k^2 |a(T u) + g e3|^2`` with ``k = ratio_max`` (1/s^2): negative on ``[0, 1]``
    iff ``|s| < k |f|``, the snap per unit of mass-normalised thrust (module docstring)."""
    c = np.asarray(coefficients, dtype=float)
    T = _duration(duration)
    snap = _square_norm([_axis_derivative(c[a], 4, T) for a in range(3)])
    acc = [_axis_derivative(c[a], 2, T) for a in range(3)]
    acc[2] = list(acc[2]) if acc[2] else [Fraction(0)]
    acc[2][0] += Fraction(float(g))
    thrust = _square_norm(acc)
    k2 = Fraction(float(ratio_max)) ** 2
    size = max(len(snap), len(thrust))
    total = [(snap[i] if i < len(snap) else 0) - k2 * (thrust[i] if i < len(thrust) else 0) for i in range(size)]
    return np.array([_round_up(Fraction(q)) for q in total], dtype=np.float64)


@dataclass(frozen=True, kw_only=True)
class SnapReport:
    """Per-segment verdicts of :func:`certify_snap`: ``|s| < snap_max`` (m/s^4) and
    ``|s| < snap_thrust_max |a + g e3|`` (1/s^2); a cell is WITHIN only if both are proven."""

    snap_max: float
    verdicts: tuple[Certificate, ...]
    times: tuple[float, ...]
    snap_thrust_max: float = math.inf

    @property
    def certified(self) -> bool:
        """Both bounds proven on every segment (always True when both are ``inf``)."""
        return all(v in (Certificate.WITHIN, Certificate.NOT_CHECKED) for v in self.verdicts)

    def summary(self) -> str:
        head = "certified" if self.certified else "NOT certified"
        cells = ", ".join(v.value for v in self.verdicts)
        return f"snap < {self.snap_max:g} m/s^4 and < {self.snap_thrust_max:g} |f|: {head} (per segment: {cells})"


def _limit(name: str, value: float) -> float:
    try:
        out = float(value)
    except (TypeError, ValueError):
        raise ConfigError(name, f"must be a number, got {value!r}") from None
    if math.isnan(out) or out <= 0:
        raise ConfigError(name, f"must be > 0 (or inf to skip), got {value!r}")
    return out


def trackability_rows(trajectory: Trajectory, snap_max: float, snap_thrust_max: float) -> np.ndarray:
    """Upper-bounding coefficients of every segment's polynomials, one row each (segment order;
    per segment :func:`snap_polynomial` if ``snap_max`` is finite, then
    :func:`snap_thrust_polynomial` if ``snap_thrust_max`` is finite), zero-padded.

    Computed exactly in Rust (``avp._avp_rust.trackability_rows``: dyadic big-integer
    arithmetic, the same upward rounding, bit for bit the :class:`~fractions.Fraction` result);
    a coefficient outside the normal float range falls back to the Fraction path. Limits as in
    :func:`certify_snap` (``> 0``, ``inf`` skips one; not both)."""
    snap_max = _limit("snap_max", snap_max)
    snap_thrust_max = _limit("snap_thrust_max", snap_thrust_max)
    if math.isinf(snap_max) and math.isinf(snap_thrust_max):
        raise ConfigError("snap_max", "both limits are inf: no polynomial to build (certify_snap reports NOT_CHECKED)")
    try:
        return _avp_rust.trackability_rows(trajectory.coefficients, trajectory.knots_rel, snap_max, snap_thrust_max,
                                           trajectory.g)
    except _avp_rust.KernelError:
        pass
    knots = trajectory.knots_rel  # the exact durations at any clock value
    rows = []
    for i in range(trajectory.n_segments):
        T = Fraction(float(knots[i + 1])) - Fraction(float(knots[i]))
        c = trajectory.coefficients[i]
        if math.isfinite(snap_max):
            rows.append(snap_polynomial(c, T, snap_max))
        if math.isfinite(snap_thrust_max):
            rows.append(snap_thrust_polynomial(c, T, snap_thrust_max, trajectory.g))
    width = max(len(r) for r in rows)
    polys = np.zeros((len(rows), width))
    for j, r in enumerate(rows):
        polys[j, :len(r)] = r
    return polys


def certify_snap(trajectory: Trajectory, snap_max: float, *, snap_thrust_max: float = math.inf,
                 exact: bool = True) -> SnapReport:
    """Prove ``|x(t)| < snap_max`` (m/s^4) and ``|x(t)| < snap_thrust_max |a + g e3|``
    on every segment of ``trajectory`` (module docstring). ``inf`` skips a bound; with both
    ``inf`` the verdicts are :attr:`Certificate.NOT_CHECKED`."""
    smax = _limit("snap_max", snap_max)
    kmax = _limit("snap_thrust_max", snap_thrust_max)
    n_seg = trajectory.n_segments
    if math.isinf(smax) and math.isinf(kmax):
        return SnapReport(snap_max=smax, verdicts=(Certificate.NOT_CHECKED,) * n_seg, times=(math.nan,) * n_seg, snap_thrust_max=kmax)
    knots = trajectory.knots
    polys = trackability_rows(trajectory, smax, kmax)
    codes, t, _ = _avp_rust.certify_below_many(np.ascontiguousarray(polys), 0.0, 1.0, exact)
    per = polys.shape[0] // n_seg
    codes_map = (Certificate.WITHIN, Certificate.VIOLATED, Certificate.UNKNOWN)
    verdicts, times = [], []
    for i in range(n_seg):
        cs = [codes_map[int(x)] for x in codes[i * per:(i + 1) * per]]
        ts = [float(x) for x in t[i * per:(i + 1) * per]]
        if Certificate.VIOLATED in cs:
            v, u = Certificate.VIOLATED, ts[cs.index(Certificate.VIOLATED)]
        elif Certificate.UNKNOWN in cs:
            v, u = Certificate.UNKNOWN, math.nan
        else:
            v, u = Certificate.WITHIN, math.nan
        verdicts.append(v)
        times.append(float(knots[i] + u * (knots[i + 1] - knots[i])) if np.isfinite(u) else math.nan)
    return SnapReport(snap_max=smax, verdicts=tuple(verdicts), times=tuple(times), snap_thrust_max=kmax)


def trackability_peaks(trajectory: Trajectory, samples: int = 400) -> tuple[float, float]:
    """Sampled peaks ``(max |s|, max |s| / |a + g e3|)`` of a plan (a measurement, not a proof:
    used to set limits relative to a plan, which the certificate then proves)."""
    t = np.linspace(trajectory.t0, trajectory.tf, samples)
    d = trajectory.derivatives(t, (2, 4))
    s = np.linalg.norm(d[1][:, :3], axis=-1)
    f = np.linalg.norm(d[0][:, :3] + np.array([0.0, 0.0, trajectory.g]), axis=-1)
    return float(s.max()), float(np.max(s / np.maximum(f, 1e-9)))
