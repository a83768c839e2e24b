"""Sturm counts and bound certificates of the Rust core against exact sympy oracles.

Soundness is the point: ``certify_below`` / ``certify_spline`` must never answer WITHIN when
``F >= 0`` somewhere. Hypothesis profiles come from tests/conftest.py (``ci`` is derandomized).
"""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
import pytest
import sympy as sp
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from avp import _avp_rust
from avp.bounds import Bound, Certificate, certify_spline
from avp.errors import ConfigError

X = sp.Symbol("x")
WITHIN, VIOLATED, UNKNOWN, NOT_CHECKED = 0, 1, 2, 3


# ---------------------------------------------------------------- exact oracles


def _poly(coeffs) -> sp.Poly:
    """Exact sympy polynomial of float (or Fraction) coefficients, ascending powers."""
    terms = [sp.Rational(Fraction(c).numerator, Fraction(c).denominator) for c in coeffs]
    return sp.Poly(list(reversed(terms)), X)


def _rat(x: float) -> sp.Rational:
    f = Fraction(x)
    return sp.Rational(f.numerator, f.denominator)


def distinct_roots(coeffs, a: float, b: float) -> int:
    p = _poly(coeffs)
    if p.is_zero:
        raise ValueError("zero polynomial")
    if p.degree() <= 0:
        return 0
    return int(p.sqf_part().count_roots(_rat(a), _rat(b)))


def below_oracle(coeffs, a: float, b: float) -> bool:
    """Exact: F(t) < 0 for every t in [a, b] (Algorithm 1 with touching = violation)."""
    p = _poly(coeffs)
    if p.is_zero:
        return False
    if p.eval(_rat(a)) >= 0 or p.eval(_rat(b)) >= 0:
        return False
    return p.degree() <= 0 or p.sqf_part().count_roots(_rat(a), _rat(b)) == 0


def _exact_floats(fracs) -> list[float] | None:
    """The floats of exact Fractions, or None when one is not representable exactly."""
    out = [float(f) for f in fracs]
    return out if all(Fraction(v) == f for v, f in zip(out, fracs, strict=False)) else None


def _mul(p, q):
    out = [Fraction(0)] * (len(p) + len(q) - 1)
    for i, x in enumerate(p):
        for j, y in enumerate(q):
            out[i + j] += x * y
    return out


# ---------------------------------------------------------------- strategies

dyadic = st.builds(lambda m, e: m * 2.0**e, st.integers(-(2**20), 2**20), st.integers(-30, 30))
wide = st.one_of(
    dyadic,
    st.floats(min_value=-1e6, max_value=1e6, allow_nan=False, allow_infinity=False),
    st.builds(lambda m, e: m * 10.0**e, st.floats(-1, 1, allow_nan=False), st.integers(-12, 12)),
)
ends = st.tuples(st.integers(-8, 8), st.integers(1, 16)).map(lambda t: (t[0] / 4, t[0] / 4 + t[1] / 8))


small_dyadic = st.builds(lambda m, e: m * 2.0**e, st.integers(-(2**12), 2**12), st.integers(-10, 10))


@st.composite
def random_poly(draw, min_deg=4, max_deg=40):
    """Degree 4-40. Up to degree 16 the coefficients span ~1e-12..1e6 (wide scales, and
    optionally a tiny leading coefficient); above, they are small dyadics, because the sympy
    oracle needs minutes for degree-40 polynomials with 60-bit wide-range rationals."""
    deg = draw(st.integers(min_deg, max_deg))
    coeff = wide if deg <= 16 else small_dyadic
    c = draw(st.lists(coeff, min_size=deg + 1, max_size=deg + 1))
    if draw(st.booleans()):
        tiny = [1e-30, -1e-18, 2.0**-60] if deg <= 16 else [2.0**-40, -(2.0**-30)]
        c[-1] = draw(st.sampled_from(tiny))  # tiny leading coefficient
    assume(any(x != 0.0 for x in c))
    return c


@st.composite
def planted_poly(draw, a: float, b: float):
    """Small integer polynomial times planted structure: double roots, roots at the ends,
    tangencies at zero from below (F = -(x - r)^2 q with q > 0), or near-tangencies."""
    kind = draw(st.sampled_from(["double", "end", "tangent", "near_tangent"]))
    q = [Fraction(draw(st.integers(-9, 9))) for _ in range(draw(st.integers(1, 10)))]
    r = Fraction(draw(st.integers(int(a * 64) - 8, int(b * 64) + 8)), 64)
    if kind == "double":
        assume(any(q))
        p = _mul(_mul(q, [-r, Fraction(1)]), [-r, Fraction(1)])
    elif kind == "end":
        assume(any(q))
        p = _mul(q, [-Fraction(a if draw(st.booleans()) else b), Fraction(1)])
    else:
        # -(x - r)^2 s(x) with s = k (1 + x^2)^m > 0: touches zero at r from below
        s_poly = [Fraction(draw(st.integers(1, 9)))]
        for _ in range(draw(st.integers(0, 3))):
            s_poly = _mul(s_poly, [Fraction(1), Fraction(0), Fraction(1)])
        p = [-x for x in _mul(_mul([-r, Fraction(1)], [-r, Fraction(1)]), s_poly)]
        if kind == "near_tangent":
            p[0] -= Fraction(1, 2 ** draw(st.integers(20, 50)))
    floats = _exact_floats(p)
    assume(floats is not None and len(floats) <= 41)
    return floats


# ---------------------------------------------------------------- sturm_count


@settings(max_examples=40, deadline=None)
@given(c=random_poly(), ab=ends)
def test_sturm_count_matches_sympy_on_random_polynomials(c, ab):
    a, b = ab
    assert _avp_rust.sturm_count(np.array(c), a, b) == distinct_roots(c, a, b)


@settings(max_examples=80, deadline=None)
@given(data=st.data(), ab=ends)
def test_sturm_count_matches_sympy_on_planted_roots(data, ab):
    a, b = ab
    c = data.draw(planted_poly(a, b))
    assume(any(x != 0.0 for x in c))
    assert _avp_rust.sturm_count(np.array(c), a, b) == distinct_roots(c, a, b)


def test_sturm_count_paper_example_and_errors():
    h = np.array([-1.0, -1.0, 0.0, 1.0, 1.0])  # eq. (18): t^4 + t^3 - t - 1
    assert _avp_rust.sturm_count(h, 0.0, 2.0) == 1
    assert _avp_rust.sturm_count(h, -2.0, 2.0) == 2
    assert _avp_rust.sturm_count(h, 1.0, 1.0) == 1
    for bad, a, b in [
        (np.array([np.nan, 1.0]), 0.0, 1.0),
        (np.ones(42), 0.0, 1.0),
        (np.zeros(3), 0.0, 1.0),
        (np.array([1.0, 1.0]), 1.0, 0.0),
        (np.array([1.0, 1.0]), 0.0, math.inf),
    ]:
        with pytest.raises(ValueError):
            _avp_rust.sturm_count(bad, a, b)


# ---------------------------------------------------------------- certify_below


def _check_certificate(c, a, b):
    truth = below_oracle(c, a, b)
    code, t = _avp_rust.certify_below(np.array(c), a, b)
    assert code == (WITHIN if truth else VIOLATED)
    if code == VIOLATED:
        assert a <= t <= b
    fast, _ = _avp_rust.certify_below(np.array(c), a, b, exact=False)
    if truth:
        assert fast in (WITHIN, UNKNOWN)
    else:
        assert fast in (VIOLATED, UNKNOWN), "unsound WITHIN on the fast path"
    # dense sampling: a WITHIN verdict must not have a sample that is clearly >= 0
    if WITHIN in (code, fast):
        tt = np.linspace(a, b, 2001)
        vals = np.polynomial.polynomial.polyval(tt, np.array(c))
        scale = np.polynomial.polynomial.polyval(np.abs(tt), np.abs(np.array(c)))
        assert np.all(vals < 1e-9 * scale + 1e-300)
    return fast


@settings(max_examples=40, deadline=None)
@given(c=random_poly(max_deg=30), ab=ends, shift=st.sampled_from([0.0, 0.5, 1.0, 1.001]))
def test_certify_below_matches_exact_oracle_near_the_bound(c, ab, shift):
    a, b = ab
    # move the maximum of F close to zero so the interesting cases are common
    tt = np.linspace(a, b, 257)
    mx = float(np.max(np.polynomial.polynomial.polyval(tt, np.array(c))))
    assume(math.isfinite(mx))
    c = list(c)
    c[0] = c[0] - shift * mx
    assume(math.isfinite(c[0]))
    _check_certificate(c, a, b)


@settings(max_examples=80, deadline=None)
@given(data=st.data(), ab=ends)
def test_certify_below_planted_tangencies_and_end_roots(data, ab):
    a, b = ab
    c = data.draw(planted_poly(a, b))
    assume(any(x != 0.0 for x in c))
    _check_certificate(c, a, b)


def test_certify_below_touching_root_is_a_violation():
    touch = np.array([-0.25, 1.0, -1.0])  # -(t - 1/2)^2
    code, t = _avp_rust.certify_below(touch, 0.0, 1.0)
    assert code == VIOLATED and abs(t - 0.5) < 0.05
    assert _avp_rust.certify_below(touch, 0.0, 1.0, exact=False)[0] == UNKNOWN
    assert _avp_rust.certify_below(touch - [2.0**-40, 0, 0], 0.0, 1.0)[0] == WITHIN
    assert _avp_rust.certify_below(np.array([-1.0, 2.0]), 0.0, 0.5) == (VIOLATED, 0.5)


def test_fast_path_unknown_rate_is_recorded():
    """Unknown rate of the floating-point path (exact fallback off) on random polynomials whose
    maximum is within +-5 % of zero (a hard, near-tangent distribution)."""
    rng = np.random.default_rng(7)
    rates = {}
    for deg in (10, 20, 30):
        n = 400
        C = rng.standard_normal((n, deg + 1)) * np.exp(rng.uniform(-3, 3, (n, deg + 1)))
        vals = np.polynomial.polynomial.polyval(np.linspace(0, 1, 1001), C.T)
        mx = vals.max(axis=1)
        C[:, 0] -= mx + np.abs(mx) * rng.uniform(-0.05, 0.05, n)
        codes, _, fast = _avp_rust.certify_below_many(C, 0.0, 1.0, False)
        exact_codes, _, _ = _avp_rust.certify_below_many(C[codes != UNKNOWN], 0.0, 1.0, True)
        # whatever the fast path decided, the exact path agrees
        assert np.array_equal(codes[codes != UNKNOWN], exact_codes)
        assert np.array_equal(codes == UNKNOWN, ~fast)
        rates[deg] = float(np.mean(codes == UNKNOWN))
    print("fast-path unknown rate (max within 5 % of 0):", rates)
    assert all(r < 0.5 for r in rates.values())


@st.composite
def near_tangent_poly(draw):
    """Mixed-magnitude near-tangencies: ``scale * (-(x - r)^2 s(x) + eps)`` with ``s > 0`` a sum
    of squares with coefficients spanning ~2^-20..2^20 and ``eps = +-2^-k`` (k 10-60), rounded
    to floats (the oracle is exact on the rounded floats). The fast path is often unsure on
    these; the exact path decides them."""
    r = Fraction(draw(st.integers(1, 127)), 128)
    s = [Fraction(0)]
    for _ in range(draw(st.integers(1, 3))):
        f = [Fraction(draw(st.integers(-(2**8), 2**8))) * Fraction(2) ** draw(st.integers(-20, 20))
             for _ in range(draw(st.integers(1, 3)))]
        sq = _mul(f, f)
        s = [a + b for a, b in zip(s + [Fraction(0)] * (len(sq) - len(s)), sq + [Fraction(0)] * (len(s) - len(sq)), strict=True)]
    s[0] += Fraction(1, 2**20)  # strictly positive
    p = [-x for x in _mul(_mul([-r, Fraction(1)], [-r, Fraction(1)]), s)]
    eps = Fraction(draw(st.sampled_from([-1, 1])), 2 ** draw(st.integers(10, 60)))
    p[0] += eps * (abs(p[2]) + 1)
    scale = Fraction(2) ** draw(st.integers(-30, 30))
    return [float(x * scale) for x in p]


@settings(max_examples=60, deadline=None)
@given(c=near_tangent_poly(), ab=st.sampled_from([(0.0, 1.0), (0.25, 0.875), (-0.5, 0.75)]))
def test_exact_paths_and_budgets_match_sympy_on_near_tangent_polynomials(c, ab):
    """The Bernstein exact path, the previous Sturm path and every budget agree with the exact
    verdict: a budget may end in UNKNOWN, never in a wrong verdict."""
    a, b = ab
    truth = WITHIN if below_oracle(c, a, b) else VIOLATED
    row = np.array([c])
    assert _avp_rust.certify_below(np.array(c), a, b)[0] == truth
    assert _avp_rust.certify_below_many(row, a, b, True, method="sturm")[0][0] == truth
    codes, _, fast = _avp_rust.certify_below_many(row, a, b, True)
    assert codes[0] == truth
    for budget in (0.0, 1e-5, 1e-3):
        code, t = _avp_rust.certify_below(np.array(c), a, b, budget=budget)
        assert code in (truth, UNKNOWN)
        if fast[0]:
            assert code == truth  # the fast path never needs the budget
        if code == VIOLATED:
            assert a <= t <= b


def test_zero_budget_is_unknown_exactly_when_the_exact_path_is_needed():
    touch = np.array([-0.25, 1.0, -1.0])  # -(t - 1/2)^2: only the exact path decides it
    assert _avp_rust.certify_below(touch, 0.0, 1.0, budget=0.0)[0] == UNKNOWN
    assert _avp_rust.certify_below(touch, 0.0, 1.0, budget=math.inf)[0] == VIOLATED
    assert _avp_rust.certify_below(touch - [0.01, 0, 0], 0.0, 1.0, budget=0.0)[0] == WITHIN
    with pytest.raises(_avp_rust.KernelError) as exc:
        _avp_rust.certify_below(touch, 0.0, 1.0, budget=-1.0)
    assert exc.value.arg == "budget"
    with pytest.raises(_avp_rust.KernelError) as exc:
        _avp_rust.certify_below_many(touch[None, :], 0.0, 1.0, method="newton")
    assert exc.value.arg == "method"


def test_kernel_errors_carry_the_argument_name():
    with pytest.raises(_avp_rust.KernelError) as exc:
        _avp_rust.certify_below(np.array([np.nan, 1.0]), 0.0, 1.0)
    assert (exc.value.arg, exc.value.detail) == ("coeffs", "contains NaN or inf; pass finite values")
    assert str(exc.value) == "coeffs: contains NaN or inf; pass finite values"
    assert isinstance(exc.value, ValueError)
    with pytest.raises(_avp_rust.KernelError) as exc:
        _avp_rust.certify_below(np.array([1.0, 1.0]), 1.0, 0.0)
    assert exc.value.arg == "b"
    c, k = _hover()
    with pytest.raises(_avp_rust.KernelError) as exc:
        _avp_rust.certify_spline(c, k[::-1].copy(), np.full(5, 10.0))
    assert exc.value.arg == "knots"



def test_column_major_arrays_are_refused_not_misread():
    """NumPy calls a Fortran-ordered 2-D array contiguous, but the kernels index rows: its values
    would be read in the wrong order. Every wrapper refuses it with a KernelError naming it."""
    rng = np.random.default_rng(0)
    c = rng.normal(size=(2, 4, 6))
    k = np.array([0.0, 0.4, 1.0])
    t = np.linspace(0.0, 1.0, 5)
    with pytest.raises(_avp_rust.KernelError) as exc:
        _avp_rust.eval_spline(np.asfortranarray(c), k, t, [0])
    assert exc.value.arg == "coeffs" and "C-contiguous" in exc.value.detail
    x = np.asfortranarray(rng.normal(size=(4, 3)))
    with pytest.raises(_avp_rust.KernelError) as exc:
        _avp_rust.fov_gradient(x, np.zeros(4), np.zeros((4, 3)), np.ones(3), np.array([1.0, 0.0, 0.0]), 0.8, 9.81)
    assert exc.value.arg == "x"
    with pytest.raises(_avp_rust.KernelError) as exc:  # (3m, 1) has the length of (m, 3), not its shape
        _avp_rust.fov_gradient(np.zeros((12, 1)), np.zeros(4), np.zeros((4, 3)), np.ones(3),
                               np.array([1.0, 0.0, 0.0]), 0.8, 9.81)
    assert exc.value.arg == "x"
    # the same values in row-major order are accepted and equal the transposed reading's intent
    ok = _avp_rust.eval_spline(np.ascontiguousarray(np.asfortranarray(c)), k, t, [0])
    np.testing.assert_array_equal(ok, _avp_rust.eval_spline(c, k, t, [0]))


@pytest.mark.parametrize("axes", [1, 2, 3, 4])
def test_a_spline_with_too_few_axes_is_a_kernel_error_without_a_panic(axes, capfd):
    """Coefficients with fewer axes than a kernel reads (the regions and trackability need x, y,
    z; the actuator bounds x, y, z, yaw) are refused up front with a KernelError on ``coeffs``:
    the workspace certificates indexed the missing axes first, panicked (a message and backtrace
    hint on stderr) and raised an 'internal error' KernelError."""
    c = np.zeros((2, axes, 6))
    k = np.array([0.0, 0.5, 1.0])
    up = np.array([0.0, 0.0, 1.0])
    calls = {
        3: [lambda: _avp_rust.certify_halfspace(c, k, up, -1.0), lambda: _avp_rust.certify_halfspace(c, k, up, 0.0, 1),
            lambda: _avp_rust.certify_sphere_outside(c, k, up, 0.5), lambda: _avp_rust.certify_speed(c, k, 1.0),
            lambda: _avp_rust.trackability_rows(c, k, 10.0, 2.0)],
        4: [lambda: _avp_rust.certify_spline(c, k, np.full(5, 10.0)), lambda: _avp_rust.bound_polynomial(c, k, 0, 0, 10.0)],
    }
    for needed, kernels in calls.items():
        for call in kernels:
            if axes >= needed:
                call()  # takes it (the regions read the first three axes)
                continue
            with pytest.raises(_avp_rust.KernelError) as exc:
                call()
            assert exc.value.arg == "coeffs" and "axes" in exc.value.detail and "internal" not in exc.value.detail
    out, err = capfd.readouterr()
    assert err == "" and out == ""


# ---------------------------------------------------------------- certify_spline


def _spline_F(coeffs, knots, seg, bound, limit, g):
    """Exact checked polynomial of one bound on one segment, in u (sympy)."""
    u = X
    T = _rat(knots[seg + 1]) - _rat(knots[seg])
    ax = [sum(_rat(c) * (T * u) ** k for k, c in enumerate(coeffs[seg, i])) for i in range(4)]

    def d(p, r):  # time derivative: d/dt = (1/T) d/du
        return sp.expand(sp.diff(p, u, r) / T**r)

    acc = [d(ax[i], 2) for i in range(3)]
    acc[2] += _rat(g)
    jerk = [d(ax[i], 3) for i in range(3)]
    f2 = sum(x**2 for x in acc)
    j2 = sum(x**2 for x in jerk)
    psid2 = d(ax[3], 1) ** 2
    L = _rat(limit) ** 2
    F = {
        0: f2 - L,
        1: L - f2,
        2: j2 - L,
        3: j2 - L * f2,
        4: 3 * j2 + (4 * psid2 - L) * f2,
    }[bound]
    return sp.Poly(sp.expand(F), u)


def _oracle_poly_below(P: sp.Poly) -> bool:
    if P.is_zero:
        return False
    if P.eval(0) >= 0 or P.eval(1) >= 0:
        return False
    return P.degree() <= 0 or P.sqf_part().count_roots(0, 1) == 0


@st.composite
def small_spline(draw):
    S = draw(st.integers(1, 3))
    C = draw(st.integers(4, 8))
    vals = st.builds(lambda m, e: m * 2.0**e, st.integers(-40, 40), st.integers(-4, 1))
    c = np.array(draw(st.lists(vals, min_size=S * 4 * C, max_size=S * 4 * C))).reshape(S, 4, C)
    durs = draw(st.lists(st.sampled_from([0.25, 0.5, 0.75, 1.0, 0.3, 1.7]), min_size=S, max_size=S))
    knots = np.concatenate([[0.0], np.cumsum(durs)])
    return c, knots


@settings(max_examples=25, deadline=None)
@given(sk=small_spline(), data=st.data())
def test_certify_spline_matches_exact_oracle(sk, data):
    c, knots = sk
    g = 9.81
    t = np.linspace(knots[0], knots[-1], 801)
    ev = _avp_rust.eval_spline(c, knots, t, [1, 2, 3])
    fn = np.linalg.norm(ev[1, :, :3] + [0, 0, g], axis=1)
    jn = np.linalg.norm(ev[2, :, :3], axis=1)
    # limits close to the sampled extremes, so both verdicts happen
    pick = lambda v: float(v * data.draw(st.sampled_from([0.9, 1.0, 1.01, 1.5])))
    fmax = pick(fn.max())
    fmin = float(fn.min() * data.draw(st.sampled_from([0.5, 0.99, 1.0, 1.1])))
    rate = pick(jn.max()) if jn.max() > 0 else 1.0
    tilt = pick(float(np.max(jn / fn))) if np.max(jn) > 0 else 1.0
    body = pick(float(np.sqrt(np.max(3 * (jn / fn) ** 2 + 4 * ev[0, :, 3] ** 2)))) or 1.0
    limits = [fmax, fmin, rate, tilt, body]  # row order of BOUND_NAMES
    assume(all(math.isfinite(x) and x >= 0 for x in limits))
    codes, times = _avp_rust.certify_spline(c, knots, np.array(limits), g)
    fast_codes, _ = _avp_rust.certify_spline(c, knots, np.array(limits), g, False)
    for b in range(5):
        for s in range(c.shape[0]):
            truth = _oracle_poly_below(_spline_F(c, knots, s, b, limits[b], g))
            if b == 4:
                # body rate: WITHIN also needs a certified roll level, whose polynomial is never
                # weaker than the 45-degree one the oracle builds; otherwise VIOLATED/UNKNOWN
                assert truth or codes[b, s] != WITHIN, s
                assert truth or fast_codes[b, s] != WITHIN, s
            else:
                assert codes[b, s] == (WITHIN if truth else VIOLATED), (b, s)
                assert fast_codes[b, s] in ((WITHIN, UNKNOWN) if truth else (VIOLATED, UNKNOWN)), (b, s)
            if codes[b, s] == VIOLATED:
                assert knots[s] <= times[b, s] <= knots[s + 1]
    # physical cross-check by sampling: certified thrust max means no sample above the limit
    if np.all(codes[0] == WITHIN):
        assert fn.max() < fmax * (1 + 1e-12)
    if np.all(codes[1] == WITHIN):
        assert fn.min() > fmin * (1 - 1e-12)


def test_bound_polynomial_encloses_the_exact_one():
    rng = np.random.default_rng(3)
    c = rng.standard_normal((2, 4, 8))
    knots = np.array([0.0, 0.7, 1.9])
    for b in range(5):
        lo, hi = _avp_rust.bound_polynomial(c, knots, 1, b, 3.3)
        P = _spline_F(c, knots, 1, b, 3.3, 9.81)
        exact = [Fraction(int(x.p), int(x.q)) for x in reversed(P.all_coeffs())]
        assert all(Fraction(lo[k]) <= e <= Fraction(hi[k]) for k, e in enumerate(exact))
        assert len(exact) <= len(lo)


# ---------------------------------------------------------------- Python API


def _hover(S=2, C=8):
    c = np.zeros((S, 4, C))
    c[:, 2, 0] = 1.0
    return c, np.linspace(0.0, 1.0, S + 1)


def test_report_for_hover_and_a_violation():
    c, k = _hover()
    rep = certify_spline(c, k, thrust_min=5.0, thrust_max=15.0, thrust_rate_max=1.0, body_rate_max=2.0)
    assert rep.certified
    assert rep.verdicts[Bound.TILT_RATE] == (Certificate.NOT_CHECKED,) * 2
    assert rep.verdicts[Bound.THRUST_MAX] == (Certificate.WITHIN,) * 2
    assert rep.violations == []
    c[1, 2, 2] = 10.0  # z'' = 20 on the second segment: ||f|| = 29.81 > 15
    rep = certify_spline(c, k, thrust_min=5.0, thrust_max=15.0)
    assert not rep.certified
    (v,) = rep.violations
    assert v.bound is Bound.THRUST_MAX and v.segment == 1 and 0.5 <= v.t <= 1.0
    assert "thrust_max" in rep.summary() and "NOT certified" in rep.summary()


@pytest.mark.parametrize(
    "kwargs, field",
    [
        (dict(thrust_min=-1.0, thrust_max=10.0), "thrust_min"),
        (dict(thrust_min=1.0, thrust_max=float("nan")), "thrust_max"),
        (dict(thrust_min=11.0, thrust_max=10.0), "thrust_min"),
        (dict(thrust_min=1.0, thrust_max=10.0, g=float("inf")), "g"),
    ],
)
def test_config_errors_name_the_field(kwargs, field):
    c, k = _hover()
    with pytest.raises(ConfigError) as exc:
        certify_spline(c, k, **kwargs)
    assert exc.value.field == field


def test_budgeted_spline_certificate_is_unknown_never_wrong():
    c, k = _hover()
    # hovering: ||f|| = g exactly, so thrust_max = g touches: a violation only exact arithmetic sees
    exact = certify_spline(c, k, thrust_min=1.0, thrust_max=9.81, budget=math.inf)
    assert exact.verdicts[Bound.THRUST_MAX] == (Certificate.VIOLATED,) * 2
    spent = certify_spline(c, k, thrust_min=1.0, thrust_max=9.81, budget=0.0)
    assert spent.verdicts[Bound.THRUST_MAX] == (Certificate.UNKNOWN,) * 2
    assert spent.verdicts[Bound.THRUST_MIN] == (Certificate.WITHIN,) * 2
    assert not spent.certified and spent.unknown == [(Bound.THRUST_MAX, 0), (Bound.THRUST_MAX, 1)]
    with pytest.raises(ConfigError) as exc:
        certify_spline(c, k, thrust_min=1.0, thrust_max=9.81, budget=-1.0)
    assert exc.value.field == "budget"


def test_config_errors_on_shapes_and_degree():
    c, k = _hover()
    with pytest.raises(ConfigError):
        certify_spline(c[:, :3], k, thrust_min=1.0, thrust_max=20.0)
    with pytest.raises(ConfigError):
        certify_spline(c, k[:2], thrust_min=1.0, thrust_max=20.0)
    with pytest.raises(ConfigError) as exc:
        certify_spline(c, k[::-1].copy(), thrust_min=1.0, thrust_max=20.0)
    assert exc.value.field == "knots"
    big = np.zeros((1, 4, 13))
    with pytest.raises(ConfigError):
        certify_spline(big, k[:2], thrust_min=1.0, thrust_max=20.0, body_rate_max=3.0)
