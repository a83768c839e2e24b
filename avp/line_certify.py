"""Certificates of a line perch: clearance from the line, minimum height, wedge corridor.

Each checked quantity is a polynomial per spline segment that must stay negative; the Rust
kernel ``avp._avp_rust.certify_below`` proves it (see ``docs/bounds.md`` for its contract).
The polynomials are built **exactly** from the f64 inputs (spline coefficients, knots, line end
points, offsets): every f64 is a dyadic rational ``m 2^-e``, so the arithmetic below runs on
Python integers with a shared power-of-two exponent and has no rounding at all. Only the final
coefficients are rounded, **upwards**, to f64; in the normalised time ``u in [0, 1]`` every power
``u^k`` is >= 0, so the rounded polynomial bounds the exact one from above and proving it
negative proves the exact one negative. ``docs/lines.md`` has the derivations.

Clearance (the CoM never closer to the line than the gripper offset ``r`` before contact). For a
piece ``A -> B`` with ``v = B - A`` and ``e(t) = p(t) - A``, the squared distance to the
**infinite** line through the piece is ``|e x v|^2 / |v|^2``; its distance to the segment is
never smaller, so the certificate also holds for the segment. The checked polynomial is
``F = r^2 |v|^2 - |e x v|^2`` (degree ``2N``). At contact the CoM is at distance ``r`` with zero
normal speed, so ``F`` has a (numerically) double root at ``t_f``: with ``s = u - 1`` we write
exactly ``F = G_0 + G_1 s + s^2 Q(u)`` and prove ``Q < 0`` on ``[0, 1]`` (``Q(1) = F''/2 < 0`` is
the sign of the approach: the CoM decelerates towards the line). Then ``F(u) < G_0 + |G_1|`` on
``[0, 1)``: ``dist^2 > r^2 - slack`` with ``slack = (max(G_0, 0) + |G_1|) / |v|^2`` computed
exactly (the contact residual of the QP's equalities, ~1e-12 m^2), reported with the verdict.
A contact with a normal speed has a simple root (``m = 1``: ``F = G_0 + s Q``, ``Q > 0``); a start
perched on the line has a root of order 4 at ``u = 0`` (position to jerk pinned, the snap must
point away from the line).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from math import comb

import numpy as np

from . import _avp_rust
from ._typing import Array
from .bounds import Certificate
from .trajectory import Trajectory

__all__ = ["DyadicPoly", "LineCertificate", "PolyCheck", "run_checks"]

_CODES = (Certificate.WITHIN, Certificate.VIOLATED, Certificate.UNKNOWN, Certificate.NOT_CHECKED)


def _split(x: float) -> tuple[int, int]:
    """``x = n / 2^e`` exactly (``e >= 0``)."""
    n, d = float(x).as_integer_ratio()
    return n, d.bit_length() - 1


class DyadicPoly:
    """Exact polynomial ``sum_k c[k] u^k / 2^e`` with integer ``c`` (ascending powers)."""

    __slots__ = ("c", "e")

    def __init__(self, c: list[int], e: int) -> None:
        self.c = c
        self.e = e

    @classmethod
    def const(cls, x: float) -> DyadicPoly:
        n, e = _split(x)
        return cls([n], e)

    @classmethod
    def from_floats(cls, xs: Sequence[float]) -> DyadicPoly:
        parts = [_split(x) for x in xs]
        e = max(p[1] for p in parts)
        return cls([n << (e - k) for n, k in parts], e)

    @classmethod
    def segment(cls, coeffs: Sequence[float], t0: float, t1: float) -> DyadicPoly:
        """``sum c_k (t - t0)^k`` in ``u = (t - t0)/T``, ``T = t1 - t0`` exactly: ``c_k T^k u^k``."""
        tn1, te1 = _split(t1)
        tn0, te0 = _split(t0)
        te = max(te0, te1)
        tn = (tn1 << (te - te1)) - (tn0 << (te - te0))
        parts = []
        for k, ck in enumerate(coeffs):
            n, e = _split(ck)
            parts.append((n * tn**k, e + k * te))
        e = max(p[1] for p in parts)
        return cls([n << (e - k) for n, k in parts], e)

    def _aligned(self, e: int) -> list[int]:
        s = e - self.e
        return [x << s for x in self.c]

    def __add__(self, other: DyadicPoly) -> DyadicPoly:
        e = max(self.e, other.e)
        a, b = self._aligned(e), other._aligned(e)
        if len(a) < len(b):
            a, b = b, a
        out = list(a)
        for i, x in enumerate(b):
            out[i] += x
        return DyadicPoly(out, e)

    def __neg__(self) -> DyadicPoly:
        return DyadicPoly([-x for x in self.c], self.e)

    def __sub__(self, other: DyadicPoly) -> DyadicPoly:
        return self + (-other)

    def __mul__(self, other: DyadicPoly) -> DyadicPoly:
        # Schoolbook: at these sizes (<= 15 coefficients of ~400 bits) it measured 2x faster than
        # a Kronecker-substitution product (one big-integer multiply plus unpacking).
        out = [0] * (len(self.c) + len(other.c) - 1)
        for i, x in enumerate(self.c):
            if x:
                for j, y in enumerate(other.c):
                    out[i + j] += x * y
        return DyadicPoly(out, self.e + other.e)

    def shift(self, a: int) -> DyadicPoly:
        """Coefficients of ``P(s + a)`` in ``s`` (integer ``a``), exact."""
        n = len(self.c)
        out = [0] * n
        for k, ck in enumerate(self.c):
            if ck:
                for j in range(k + 1):
                    out[j] += ck * comb(k, j) * a ** (k - j)
        return DyadicPoly(out, self.e)

    def tail(self, m: int) -> DyadicPoly:
        """``(P - sum_{k<m} c_k u^k) / u^m``."""
        return DyadicPoly(self.c[m:] or [0], self.e)

    def head_slack(self, m: int) -> float:
        """f64 upper bound of ``max(c_0, 0) + sum_{1<=k<m} |c_k|`` (bounds ``sum_{k<m} c_k x^k`` on ``|x| <= 1``)."""
        total = max(self.c[0], 0) + sum(abs(x) for x in self.c[1:m])
        return _round_up(total, self.e)

    def value_at(self, u: float) -> float:
        return float(sum(x * u**k for k, x in enumerate(self.c)) / 2.0**self.e)

    def upper_floats(self) -> Array:
        """Coefficients rounded upwards to f64 (each >= the exact one)."""
        return np.array([_round_up(x, self.e) for x in self.c], dtype=np.float64)


def _round_up(n: int, e: int) -> float:
    """Smallest-or-next f64 >= ``n / 2^e`` (int true division is correctly rounded)."""
    den = 1 << e
    f = n / den
    fn, fd = f.as_integer_ratio()
    if fn * den < n * fd:
        f = math.nextafter(f, math.inf)
    return f


@dataclass(frozen=True)
class LineCertificate:
    """Verdict of one checked quantity on one segment.

    ``slack`` (in the checked quantity's units, see :class:`PolyCheck`) is what the exact
    contact residual adds to the statement: the quantity is ``< slack`` on the interval (0 when
    there is no contact root on the segment).
    """

    name: str
    trajectory: str
    segment: int
    verdict: Certificate
    t: float
    slack: float

    @property
    def ok(self) -> bool:
        return self.verdict is Certificate.WITHIN

    def __str__(self) -> str:
        at = f" near t = {self.t:.4g} s" if math.isfinite(self.t) else ""
        return f"{self.name} on {self.trajectory} segment {self.segment}: {self.verdict.value}{at}"


@dataclass(frozen=True)
class PolyCheck:
    """``F < 0`` on ``[a, b]`` (normalised time of ``segment``), with an optional root of
    order ``m`` divided out at ``u = root_at`` (0 or 1); ``scale`` turns the slack into the
    reported unit (e.g. ``1 / |v|^2`` for squared distances)."""

    name: str
    trajectory: str
    segment: int
    poly: DyadicPoly
    a: float = 0.0
    b: float = 1.0
    root_at: int | None = None
    order: int = 0
    scale: float = 1.0


def _checked(chk: PolyCheck) -> tuple[Array, float]:
    """The polynomial handed to the kernel (upper-rounded) and the slack."""
    F = chk.poly
    if chk.root_at is None or chk.order == 0:
        return F.upper_floats(), 0.0
    m = chk.order
    if chk.root_at == 0:
        return F.tail(m).upper_floats(), math.nextafter(F.head_slack(m) * chk.scale, math.inf)
    G = F.shift(1)  # coefficients in s = u - 1
    slack = math.nextafter(G.head_slack(m) * chk.scale, math.inf)
    Q = G.tail(m).shift(-1)  # back to powers of u
    if m % 2 == 1:  # (u - 1)^m <= 0 on [0, 1]: need Q > 0
        Q = -Q
    return Q.upper_floats(), slack


def run_checks(checks: Sequence[PolyCheck], traj_knots: dict[str, Array]) -> list[LineCertificate]:
    """Run every check through the Rust kernel (batched where the interval is ``[0, 1]``)."""
    polys = [_checked(c) for c in checks]
    out: list[LineCertificate | None] = [None] * len(checks)
    full = [i for i, c in enumerate(checks) if c.a == 0.0 and c.b == 1.0]
    if full:
        width = max(polys[i][0].size for i in full)
        M = np.zeros((len(full), width))
        for r, i in enumerate(full):
            M[r, : polys[i][0].size] = polys[i][0]
        codes, ts, _fast = _avp_rust.certify_below_many(M, 0.0, 1.0)
        for r, i in enumerate(full):
            out[i] = _certificate(checks[i], int(codes[r]), float(ts[r]), polys[i][1], traj_knots)
    for i, c in enumerate(checks):
        if out[i] is None:
            code, t = _avp_rust.certify_below(polys[i][0], c.a, c.b)
            out[i] = _certificate(c, int(code), float(t), polys[i][1], traj_knots)
    return [x for x in out if x is not None]


def _certificate(chk: PolyCheck, code: int, u: float, slack: float, knots: dict[str, Array]) -> LineCertificate:
    verdict = _CODES[code]
    t = math.nan
    if verdict is Certificate.VIOLATED and math.isfinite(u):
        k = knots[chk.trajectory]
        t = float(k[chk.segment] + u * (k[chk.segment + 1] - k[chk.segment]))
    return LineCertificate(chk.name, chk.trajectory, chk.segment, verdict, t, slack)


# -- the checked polynomials ------------------------------------------------------------------

def position_polys(traj: Trajectory, segment: int) -> list[DyadicPoly]:
    """Exact x, y, z of ``segment`` in its normalised time (on the plan's exact durations,
    :attr:`~avp.trajectory.Trajectory.knots_rel`)."""
    c = traj.coefficients[segment]
    t0, t1 = float(traj.knots_rel[segment]), float(traj.knots_rel[segment + 1])
    return [DyadicPoly.segment(c[a].tolist(), t0, t1) for a in range(3)]


def clearance_poly(pos: list[DyadicPoly], A: Array, B: Array, r: float) -> tuple[DyadicPoly, float]:
    """``r^2 |v|^2 - |(p - A) x v|^2`` exactly, and ``1/|v|^2`` (rounded up) for the slack."""
    a = [DyadicPoly.const(float(x)) for x in A]
    v = [DyadicPoly.const(float(B[i])) - a[i] for i in range(3)]
    e = [pos[i] - a[i] for i in range(3)]
    # |e x v|^2 = |e|^2 |v|^2 - (e . v)^2 (Lagrange's identity): 4 products of polynomials
    vv = v[0] * v[0] + v[1] * v[1] + v[2] * v[2]
    ev = e[0] * v[0] + e[1] * v[1] + e[2] * v[2]
    ee = e[0] * e[0] + e[1] * e[1] + e[2] * e[2]
    rr = DyadicPoly.const(r) * DyadicPoly.const(r)
    F = (rr - ee) * vv + ev * ev
    vv_f = _round_down_pos(vv.c[0], vv.e)
    return F, math.nextafter(1.0 / vv_f, math.inf)


def _round_down_pos(n: int, e: int) -> float:
    f = n / (1 << e)
    fn, fd = f.as_integer_ratio()
    if fn * (1 << e) > n * fd:
        f = math.nextafter(f, 0.0)
    return f


def halfplane_poly(pos: list[DyadicPoly], point: Array, normal: Array, margin: float = 0.0) -> DyadicPoly:
    """``margin - normal . (p - point)`` exactly (negative = strictly on the ``normal`` side)."""
    out = DyadicPoly.const(margin)
    for i in range(3):
        out = out - DyadicPoly.const(float(normal[i])) * (pos[i] - DyadicPoly.const(float(point[i])))
    return out


def sphere_poly(pos: list[DyadicPoly], center: Array, r: float) -> DyadicPoly:
    """``r^2 - |p - center|^2`` exactly (negative = outside the ball)."""
    e = [pos[i] - DyadicPoly.const(float(center[i])) for i in range(3)]
    rr = DyadicPoly.const(r) * DyadicPoly.const(r)
    return rr - (e[0] * e[0] + e[1] * e[1] + e[2] * e[2])


def capsule_certificate(pos: list[DyadicPoly], A: Array, B: Array, r: float, name: str, trajectory: str,
                        segment: int, knots: Array, lambdas: Sequence[float] = (0.25, 1.0, 4.0, 16.0)) -> LineCertificate:
    """Clearance from the **segment** ``A -> B`` (not its infinite line), a sufficient test.

    With ``sigma = e . v / |v|^2`` the distance to the segment is the distance to the line where
    ``0 <= sigma <= 1`` and to an end point elsewhere. Proven: ``r^2 - |p - A|^2 < 0`` and
    ``r^2 - |p - B|^2 < 0`` (the end points), and for one ``lambda >= 0``
    ``H = F + lambda s < 0`` with ``F`` the line polynomial of :func:`clearance_poly` and
    ``s = (e . v)(|v|^2 - e . v) = |v|^4 sigma (1 - sigma)``: where ``s >= 0`` (inside the slab)
    ``F < -lambda s <= 0`` (an S-procedure with a constant multiplier). A failed end point is a
    proven violation; otherwise failing every ``lambda`` is UNKNOWN (not proven either way).
    """
    ends = [PolyCheck(name, trajectory, segment, sphere_poly(pos, P, r)) for P in (A, B)]
    a = [DyadicPoly.const(float(x)) for x in A]
    v = [DyadicPoly.const(float(B[i])) - a[i] for i in range(3)]
    e = [pos[i] - a[i] for i in range(3)]
    ev = e[0] * v[0] + e[1] * v[1] + e[2] * v[2]
    vv = v[0] * v[0] + v[1] * v[1] + v[2] * v[2]
    s = ev * (vv - ev)
    F, _ = clearance_poly(pos, A, B, r)
    certs = run_checks(ends, {trajectory: knots})
    bad = [c for c in certs if not c.ok]
    if bad:
        return bad[0]
    slab = run_checks([PolyCheck(name, trajectory, segment, F + DyadicPoly.const(lam) * s) for lam in lambdas],
                      {trajectory: knots})
    if any(c.ok for c in slab):
        return next(c for c in slab if c.ok)
    return LineCertificate(name, trajectory, segment, Certificate.UNKNOWN, math.nan, 0.0)
