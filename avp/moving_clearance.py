"""Certified clearance from a moving perch plane until contact.

The vehicle must stay on the outward side of the pad's plane, which moves and (for a turning
platform) rotates: ``h(t) = (p(t) - rho(t)) . s3(t) - l > 0`` on ``[t_0, t_f)`` and
``h(t_f) = 0`` at contact (``l`` the landing-gear offset). For a constant-velocity platform
``h`` is a polynomial per segment; for CTRV it contains ``cos`` and ``sin`` of
``theta(t) = theta_f - omega (t_f - t)``.

Method (a polynomial enclosure, "Taylor model"): in the time to contact ``sigma = t_f - t >= 0``
every factor is written as a polynomial with **interval coefficients** ``[m_k - r_k, m_k + r_k]``;
because ``sigma^k >= 0`` such a polynomial encloses every value between
``sum (m_k - r_k) sigma^k`` and ``sum (m_k + r_k) sigma^k``.

* trajectory segments ``p_i(tau)``, ``tau = D_i - sigma`` (``D_i = t_f - t_i``): Horner's rule in
  interval coefficients;
* ``cos``/``sin`` of ``theta_f - omega sigma``: Taylor polynomials of order ``K`` about contact
  with the Lagrange remainder ``|omega sigma|^(K+1) / (K+1)!`` added as the radius of the
  ``sigma^(K+1)`` coefficient, and the pad trajectory
  ``rho(t_f - sigma) = rho_f - int_0^sigma v_pad`` integrated term by term (remainder
  ``|omega|^(K+1) sigma^(K+2) / (K+2)!``); ``K`` is the smallest order whose remainder at the
  largest ``sigma`` is below ``1e-13`` (``K = 0``, no remainder, for a non-turning platform);
* every floating-point operation adds a rigorous rounding radius (``gamma_n`` bounds of
  Higham, Accuracy and Stability of Numerical Algorithms, Sec. 3.1, doubled), and the values
  that come from floating-point functions (``cos``, ``sin``, the predicted ``rho_f``, ``s3_f``) get
  a radius of a few ulps.

The lower polynomial ``L(sigma) = sum (m_k - r_k) sigma^k <= h`` is then certified by the Rust
kernel ``avp._avp_rust.certify_below`` (Sturm, exact fallback; ``docs/bounds.md``):

* segments away from contact: ``-L < 0`` on ``[t_f - t_(i+1), t_f - t_i]``;
* the contact segment: ``h(t_f) = 0`` is a root, divided out exactly by shifting coefficients
  (in ``sigma`` the root is at 0): ``L(sigma) = L_0 + sigma Q(sigma)``, and ``-Q < 0`` on
  ``[0, T_S]`` proves ``h > L_0`` for ``t < t_f``. ``L_0`` is a lower bound of the contact
  residual ``h(t_f)`` (rounding level, about 1e-15 m): the certificate states
  ``h(t) > min(0, L_0)`` on ``[t_0, t_f)``, and the planner requires ``L_0 > -contact_tol``.

``Q(0)`` is the normal approach speed ``v_n``, so a pad approached with ``v_n = 0`` (a tangency
at contact) cannot be certified: the planner requires ``normal_speed > 0``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from . import _avp_rust
from ._typing import Array
from .platform import MovingTarget
from .safety import RESIDUAL_TOL
from .trajectory import Trajectory

__all__ = ["ClearanceReport", "certify_moving_clearance", "clearance"]


EPS = 2.0**-52
TINY = 2.0**-1000
"""Absolute radius floor for underflow (far below any meaningful clearance)."""
REMAINDER_TOL = 1e-13
"""Largest Taylor remainder (relative to the speeds and the normal) accepted when choosing ``K``."""


@dataclass(frozen=True)
class _IPoly:
    """Polynomial in ``sigma >= 0`` with interval coefficients ``mid +- rad`` (ascending)."""

    mid: Array
    rad: Array

    @staticmethod
    def const(value: float, rad: float = 0.0) -> _IPoly:
        return _IPoly(np.array([value]), np.array([rad]))

    def __add__(self, other: _IPoly) -> _IPoly:
        n = max(self.mid.size, other.mid.size)
        m = np.zeros(n)
        r = np.zeros(n)
        m[: self.mid.size] += self.mid
        m[: other.mid.size] += other.mid
        r[: self.rad.size] += self.rad
        r[: other.rad.size] += other.rad
        return _IPoly(m, (r + EPS * np.abs(m)) * (1 + 4 * EPS) + TINY)

    def __neg__(self) -> _IPoly:
        return _IPoly(-self.mid, self.rad)

    def __sub__(self, other: _IPoly) -> _IPoly:
        return self + (-other)

    def __mul__(self, other: _IPoly) -> _IPoly:
        m1, r1, m2, r2 = self.mid, self.rad, other.mid, other.rad
        n = min(m1.size, m2.size)
        gamma = 2.0 * (n + 1) * EPS
        a1, a2 = np.abs(m1), np.abs(m2)
        rad = np.convolve(a1, r2) + np.convolve(r1, a2) + np.convolve(r1, r2) + gamma * np.convolve(a1, a2)
        return _IPoly(np.convolve(m1, m2), rad * (1 + 4 * (n + 3) * EPS) + TINY)

    def scaled(self, c: float, c_rad: float = 0.0) -> _IPoly:
        """``self`` times the scalar ``c +- c_rad``."""
        m = c * self.mid
        rad = abs(c) * self.rad + c_rad * (np.abs(self.mid) + self.rad) + EPS * np.abs(m)
        return _IPoly(m, rad * (1 + 4 * EPS) + TINY)

    def lower(self) -> Array:
        """Coefficients of a polynomial ``<= self`` for every ``sigma >= 0``."""
        return np.nextafter(self.mid - self.rad * (1 + 4 * EPS), -np.inf)


MAX_TAYLOR_ORDER = 18
"""Cap on ``K``: the clearance polynomial has degree ``2K + 3`` at most, and the Rust kernel takes
degree <= 40. Beyond the cap the (rigorous) remainder is simply larger, so a very long or fast
turn is certified conservatively (or not at all), never wrongly."""


def _taylor_order(omega: float, sigma_max: float) -> int:
    """Smallest ``K`` with ``|omega sigma_max|^(K+1) / (K+1)! <= REMAINDER_TOL`` (0 if no turn),
    at most :data:`MAX_TAYLOR_ORDER`."""
    x = abs(omega) * sigma_max
    if x == 0.0:
        return 0
    K, term = 0, x
    while term > REMAINDER_TOL and K < MAX_TAYLOR_ORDER:
        K += 1
        term *= x / (K + 1)
    return K


def _trig_series(phase: float, phase_rad: float, omega: float, K: int) -> tuple[_IPoly, _IPoly]:
    """``cos`` and ``sin`` of ``phase - omega sigma`` as interval polynomials of order ``K`` with
    the Lagrange remainder in the ``sigma^(K+1)`` radius; ``phase_rad`` bounds the error of the
    floating-point ``phase`` (and of ``math.cos``/``math.sin``, 1 ulp)."""
    c0, s0 = math.cos(phase), math.sin(phase)
    err = phase_rad + 2 * EPS
    # d^k/dsigma^k cos(phase - w sigma) = (-w)^k cos(phase + k pi/2); same for sin.
    cyc_c = (c0, -s0, -c0, s0)
    cyc_s = (s0, c0, -s0, -c0)
    cm, sm, rr = np.zeros(K + 2), np.zeros(K + 2), np.zeros(K + 2)
    fact = 1.0
    for k in range(K + 1):
        if k:
            fact *= k
        scale = (-omega) ** k / fact
        cm[k] = cyc_c[k % 4] * scale
        sm[k] = cyc_s[k % 4] * scale
        rr[k] = err * abs(scale) + 4 * (k + 1) * EPS * abs(scale) + TINY
    rr[K + 1] = abs(omega) ** (K + 1) / (fact * (K + 1)) * (1 + 8 * (K + 2) * EPS) if omega != 0.0 else 0.0
    return _IPoly(cm, rr.copy()), _IPoly(sm, rr.copy())


def _integrate(p: _IPoly) -> _IPoly:
    """``int_0^sigma p(s) ds`` (valid for the enclosure because ``|int R| <= int |R|``)."""
    k = np.arange(1, p.mid.size + 1, dtype=float)
    m = np.concatenate([[0.0], p.mid / k])
    r = np.concatenate([[0.0], p.rad / k * (1 + 4 * EPS) + EPS * np.abs(p.mid / k)])
    return _IPoly(m, r + TINY)


def _pad_enclosures(pad_f: MovingTarget, span: float, sigma_max: float
                    ) -> tuple[list[_IPoly], _IPoly | None, _IPoly | None, int]:
    """``rho(t_f - sigma)`` per axis, the rotation ``cos``/``sin`` of ``omega sigma`` that turns
    ``s3_f`` back to ``s3(t_f - sigma)`` (``None`` for a non-turning platform: ``s3`` is constant),
    and the Taylor order used. ``pad_f`` was predicted from the estimate's time ``t_ref`` over
    ``dt = (t_0 - t_ref) + (t_f - t_0)`` (:meth:`MovingTarget.at`); ``span = |t_0 - t_ref| +
    (t_f - t_0) >= |dt|`` (s) bounds both roundings. They grow with that span, not with the
    clock's value (the difference of two times is rounded relative to itself)."""
    omega = pad_f.omega
    K = _taylor_order(omega, sigma_max)
    theta = pad_f.heading
    phase_rad = 4 * EPS * (abs(theta) + abs(omega) * span) + 2 * EPS
    cos_h, sin_h = _trig_series(theta, phase_rad, omega, K)
    reach = span + sigma_max
    scale_rho = 16 * EPS * (float(np.max(np.abs(pad_f.point))) + (abs(pad_f.speed) + abs(pad_f.vertical_speed)) * reach) + TINY
    drift = [_integrate(cos_h).scaled(pad_f.speed), _integrate(sin_h).scaled(pad_f.speed),
             _IPoly(np.array([0.0, pad_f.vertical_speed]), np.array([0.0, EPS * abs(pad_f.vertical_speed)]))]
    rho = [_IPoly.const(float(pad_f.point[a]), scale_rho) - drift[a] for a in range(3)]
    if omega == 0.0:
        return rho, None, None, K
    # s3(t_f - sigma) = R_z(-omega sigma) s3_f: cos/sin of (0 - omega sigma), exact phase 0.
    cos_w, sin_w = _trig_series(0.0, 0.0, omega, K)
    return rho, cos_w, sin_w, K


def _normal_component(
    v: list[_IPoly], s3_f: Array, s3_rad: float, cos_w: _IPoly | None, sin_w: _IPoly | None
) -> _IPoly:
    """``v . s3(t_f - sigma)`` with ``s3 = (cos a - sin b, sin a + cos b, c)`` (``cos``, ``sin``
    of ``-omega sigma``, ``(a, b, c) = s3_f +- s3_rad``):
    ``cos (a v_x + b v_y) + sin (a v_y - b v_x) + c v_z``."""
    a, b, c = (float(x) for x in s3_f)
    r = s3_rad
    u = v[0].scaled(a, r) + v[1].scaled(b, r)
    out = v[2].scaled(c, r)
    if cos_w is None or sin_w is None:
        return u + out
    w = v[1].scaled(a, r) - v[0].scaled(b, r)
    return cos_w * u + sin_w * w + out


@lru_cache(maxsize=8)
def _binomials(n: int) -> Array:
    """``B[j, k] = C(k, j)`` for ``j, k < n`` (exact integers in float64, read-only)."""
    B = np.array([[math.comb(k, j) for k in range(n)] for j in range(n)], dtype=float)
    B.setflags(write=False)
    return B


def _segments_in_sigma(coeffs: Array, D: float) -> list[_IPoly]:
    """``p_a(tau)`` with ``tau = D - sigma`` for the three position axes of one segment
    (``coeffs`` shape ``(axes, n)``): the coefficient of ``sigma^j`` is
    ``sum_k c_k C(k, j) D^(k-j) (-1)^j``, a dot product of ``n`` terms whose factors carry at most
    ``2n`` roundings (the power and ``D`` itself), hence radius ``(4n + 4) eps sum |terms|``."""
    n = coeffs.shape[1]
    k = np.arange(n)
    expo = k[None, :] - k[:, None]  # k - j
    Dp = np.where(expo >= 0, float(D) ** np.maximum(expo, 0), 0.0)
    M = _binomials(n) * Dp * np.where(k % 2 == 0, 1.0, -1.0)[:, None]
    mid = coeffs[:3] @ M.T
    rad = (np.abs(coeffs[:3]) @ np.abs(M).T) * ((4 * n + 4) * EPS) + TINY
    return [_IPoly(mid[a], rad[a]) for a in range(3)]


@dataclass(frozen=True, kw_only=True)
class ClearanceReport:
    """Verdict of :func:`certify_moving_clearance`.

    Attributes
    ----------
    certified:
        ``h(t) > min(0, contact_residual_lower)`` proven on ``[t_0, t_f)`` for every segment,
        and ``contact_residual_lower >= -contact_tol``.
    segments:
        Per segment: True if proven.
    violation_time:
        Estimated time (s) of a violation (NaN if none was found).
    contact_residual_lower, contact_residual_upper:
        Enclosure of ``h(t_f)`` (m): the contact residual of the stored polynomials.
    taylor_order:
        ``K`` of the trigonometric expansions (0 for a non-turning platform: exact polynomial).
    contact_tol:
        How far (m) the contact residual may reach behind the pad's plane.
    """

    certified: bool
    segments: tuple[bool, ...]
    violation_time: float
    contact_residual_lower: float
    contact_residual_upper: float
    taylor_order: int
    contact_tol: float = RESIDUAL_TOL

    def summary(self) -> str:
        verdict = "certified" if self.certified else "NOT certified"
        cells = ", ".join("within" if s else "violated" for s in self.segments)
        extra = "" if math.isnan(self.violation_time) else f"; violation near t = {self.violation_time:.4g} s"
        if all(self.segments) and self.contact_residual_lower < -self.contact_tol:  # every segment within: the end
            extra += (f"; the contact point may end {-self.contact_residual_lower:.2e} m behind the pad's plane, "
                      f"beyond the tolerance {self.contact_tol:.0e} m (the plan's rounding at contact; a shorter "
                      "arrival time pins it closer)")
        return (f"moving-plane clearance: {verdict} ({cells}); contact residual in "
                f"[{self.contact_residual_lower:.2e}, {self.contact_residual_upper:.2e}] m; "
                f"Taylor order {self.taylor_order}{extra}")


def clearance(traj: Trajectory, target: MovingTarget, times: Array, body_offset: float = 0.0) -> Array:
    """``h(t) = (p(t) - rho(t)) . s3(t) - l`` at ``times`` (floating point, for checks and plots;
    the plan and the pad at the same time since the plan's start, as the certificate has them)."""
    tau, _ = traj._times(np.atleast_1d(np.asarray(times, dtype=float)))
    points, _, s3 = target._predict((traj.t0 - target.time) + tau)
    return np.einsum("ij,ij->i", traj._derivatives_rel(tau, [0])[0, :, :3] - points, s3) - body_offset


def certify_moving_clearance(
    traj: Trajectory, target: MovingTarget, body_offset: float = 0.0, contact_tol: float = RESIDUAL_TOL
) -> ClearanceReport:
    """Prove ``(p(t) - rho(t)) . s3(t) - l > 0`` on ``[t_0, t_f)`` (module docstring)."""
    knots = traj.knots_rel  # sigma = t_f - t in the plan's own (exact) durations
    tf = float(knots[-1])
    pad_f = target.at(traj.t0, tf)
    # |dt| with dt = (t0 - time) + tf as at() computes it, plus the rounding of t0 - time (exact
    # when they are close; not when the estimate's time is far from t0, and then the sum may
    # cancel while its rounding stays)
    span = abs(traj.t0 - target.time) + tf
    rho, cos_w, sin_w, K = _pad_enclosures(pad_f, span, tf)
    coeffs = traj.coefficients
    # s3_f = R_z(omega dt) s3(t_ref) in floating point: a few ulps plus the rounding of the angle.
    s3_rad = 8 * EPS * (1.0 + abs(pad_f.omega) * span)
    rho_s3 = _normal_component(rho, pad_f.s3, s3_rad, cos_w, sin_w) + _IPoly.const(body_offset)
    verdicts: list[bool] = []
    t_bad = math.nan
    r_lo = r_hi = math.nan
    for i in range(coeffs.shape[0]):
        D = tf - float(knots[i])
        h = _normal_component(_segments_in_sigma(coeffs[i], D), pad_f.s3, s3_rad, cos_w, sin_w) - rho_s3
        lo = h.lower()
        sig_lo, sig_hi = tf - float(knots[i + 1]), D
        if i == coeffs.shape[0] - 1:
            r_lo = float(lo[0])
            r_hi = float(np.nextafter(h.mid[0] + h.rad[0] * (1 + 4 * EPS), np.inf))
            F = -lo[1:] if lo.size > 1 else np.array([1.0])
            sig_lo = 0.0
        else:
            F = -lo
        code, t_sig = _avp_rust.certify_below(np.ascontiguousarray(F), sig_lo, sig_hi)
        verdicts.append(code == 0)
        if code != 0 and math.isnan(t_bad):
            t_bad = traj.t0 + (tf - float(t_sig))
    ok = all(verdicts) and r_lo >= -contact_tol
    return ClearanceReport(certified=ok, segments=tuple(verdicts), violation_time=t_bad, contact_residual_lower=r_lo,
                           contact_residual_upper=r_hi, taylor_order=K, contact_tol=float(contact_tol))
