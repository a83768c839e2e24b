//! Algorithm 1 (global bound checking, Sec. V-C) made sound and tri-state.
//!
//! [`certify_below`] decides whether `F(t) < 0` for **every** `t` in `[a, b]`:
//! * [`Certificate::Within`]: proven, whatever the rounding (never said when `F >= 0` anywhere);
//! * [`Certificate::Violated`]: proven that `F(t) >= 0` somewhere (a root that only touches
//!   zero counts: conservative), with an estimate of where;
//! * [`Certificate::Unknown`]: the fast path could not decide and the exact fallback was
//!   disabled.
//!
//! Each interval is mapped to `u` in `[0, 1]` (`t = a + (b - a) u`). The mapped coefficients
//! are carried as an enclosure `lo_k <= G_k <= hi_k` (exact when no rounding happened). Because
//! `u^k >= 0` on `[0, 1]`, `lo(u) <= G(u) <= hi(u)` there, so "`hi < 0` on `[0, 1]`" proves
//! Within and "`lo(u) >= 0`" at one point proves Violated. The fast path tries, in order: the
//! ends (Algorithm 1, line 2), a Bernstein-coefficient upper bound, then the interval Sturm
//! count of [`crate::sturm`] (line 5). When undecided the exact fallback builds `G` with big
//! integers and runs Algorithm 1 exactly ([`crate::exact::certify_unit`]).
use crate::descartes::Budget;
use crate::error::Result;
use crate::exact::{self, IntPoly, UnitExact};
use crate::interval::{next_up, Iv};
use crate::sturm::{self, MAX_DEGREE};

/// Verdict of a bound certificate `F(t) < 0 on [a, b]`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Certificate {
    /// `F(t) < 0` for every `t` in the interval (proven).
    Within,
    /// `F(t) >= 0` somewhere (proven); `t` estimates where (the largest sampled value, or the
    /// violating end).
    Violated { t: f64 },
    /// Not decided (fast path unsure and exact fallback disabled or out of budget).
    Unknown,
}

impl Certificate {
    /// Integer code used across the FFI: 0 within, 1 violated, 2 unknown.
    pub fn code(&self) -> i8 {
        match self {
            Certificate::Within => 0,
            Certificate::Violated { .. } => 1,
            Certificate::Unknown => 2,
        }
    }

    /// Estimated time of the violation, NaN otherwise.
    pub fn time(&self) -> f64 {
        match self {
            Certificate::Violated { t } => *t,
            _ => f64::NAN,
        }
    }
}

/// Verdict on the unit interval, `u` coordinates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum UnitVerdict {
    Within,
    Violated(f64),
    Unsure,
}

const fn binomials() -> [[f64; MAX_DEGREE + 1]; MAX_DEGREE + 1] {
    let mut t = [[0.0; MAX_DEGREE + 1]; MAX_DEGREE + 1];
    let mut n = 0;
    while n <= MAX_DEGREE {
        t[n][0] = 1.0;
        let mut k = 1;
        while k <= n {
            // exact: every C(n, k) for n <= 40 is below 2^53
            t[n][k] = t[n - 1][k - 1] + if k < n { t[n - 1][k] } else { 0.0 };
            k += 1;
        }
        n += 1;
    }
    t
}

/// Pascal's triangle up to degree 40 (exact in f64).
static BINOM: [[f64; MAX_DEGREE + 1]; MAX_DEGREE + 1] = binomials();

/// Rigorous enclosure of `p(u)` for f64 coefficients and a point `u`.
#[inline]
pub fn eval_enclosure(p: &[f64], u: f64) -> Iv {
    if u == 0.0 {
        return Iv::point(p.first().copied().unwrap_or(0.0));
    }
    p.iter()
        .rev()
        .fold(Iv::ZERO, |acc, &c| acc.mul_f64(u).add(Iv::point(c)))
}

/// A rigorous upper bound of `max_{u in [0,1]} p(u)`: the largest Bernstein coefficient
/// `b_j = sum_{k<=j} C(j,k)/C(n,k) p_k` rounded upwards (convex-hull property). `+inf` when
/// the degree exceeds 40.
pub fn bernstein_upper(p: &[f64]) -> f64 {
    let n = match p.len().checked_sub(1) {
        Some(n) if n <= MAX_DEGREE => n,
        Some(_) => return f64::INFINITY,
        None => return 0.0,
    };
    let row = &BINOM[n];
    let mut d = [0.0f64; MAX_DEGREE + 1];
    for k in 0..=n {
        d[k] = next_up(p[k] / row[k]);
    }
    let mut best = f64::NEG_INFINITY;
    for (j, bj) in BINOM.iter().enumerate().take(n + 1) {
        let mut acc = 0.0f64;
        for k in 0..=j {
            acc = next_up(acc + next_up(bj[k] * d[k]));
        }
        if acc.is_nan() {
            return f64::INFINITY;
        }
        best = best.max(acc);
    }
    best
}

/// Depth of the Bernstein subdivision tried before the Sturm chain (at most `2^depth` pieces).
const SUBDIVISION_DEPTH: u32 = 4;

/// Proves `p(u) < 0` on `[a, b]` (a sub-interval of `[0, 1]`) by the Bernstein convex-hull bound
/// of `p` re-parametrised on `[a, b]`, halving pieces whose bound is not negative, `depth` times
/// at most. Sound: the re-parametrised coefficients are outward-rounded enclosures (their upper
/// polynomial bounds `p` on the piece, all powers of `u` being >= 0 there) and
/// [`bernstein_upper`] rounds upwards. `false` means "not proven", never "violated".
#[allow(clippy::neg_cmp_op_on_partial_ord)] // `!(x < 0.0)` is deliberately true for NaN
pub fn bernstein_subdivided_negative(p: &[f64], a: f64, b: f64, depth: u32) -> bool {
    let (_, hi) = unit_enclosure(p, a, b);
    if bernstein_upper(&hi) < 0.0 {
        return true;
    }
    if depth == 0 || !(eval_enclosure(&hi, 0.0).hi < 0.0) {
        return false;
    }
    let m = 0.5 * (a + b);
    bernstein_subdivided_negative(p, a, m, depth - 1)
        && bernstein_subdivided_negative(p, m, b, depth - 1)
}

/// `u` in `[0, 1]` of the largest of `samples + 1` equally spaced values of `p`.
pub fn argmax_sample(p: &[f64], samples: usize) -> f64 {
    let mut best = (f64::NEG_INFINITY, 0.0);
    for j in 0..=samples {
        let u = j as f64 / samples as f64;
        let v = crate::poly::eval(p, u);
        if v > best.0 {
            best = (v, u);
        }
    }
    best.1
}

const SAMPLES: usize = 64;
const COARSE: usize = 16;

/// Proves a violation by sampling: finds the largest float value of `lo` among `samples + 1`
/// points and re-evaluates it rigorously; `Some(u)` when `lo(u) >= 0` is certain there.
fn proven_violation(lo: &[f64], samples: usize) -> Option<f64> {
    let u = argmax_sample(lo, samples);
    (eval_enclosure(lo, u).lo >= 0.0).then_some(u)
}

/// Fast path on `[0, 1]` for an enclosure `lo_k <= G_k <= hi_k` (same length). Never claims
/// Within unless `hi(u) < 0` on `[0, 1]` is proven, never Violated unless `lo(u) >= 0` at a
/// point (or the exact input has a root inside) is proven.
#[allow(clippy::neg_cmp_op_on_partial_ord)] // `!(x < 0.0)` is deliberately true for NaN
pub fn certify_enclosure(lo: &[f64], hi: &[f64]) -> UnitVerdict {
    let (Some(&lo0), Some(&hi0)) = (lo.first(), hi.first()) else {
        return UnitVerdict::Violated(0.0); // empty = zero polynomial: F = 0 >= 0
    };
    // Algorithm 1, line 2: the ends.
    if lo0 >= 0.0 {
        return UnitVerdict::Violated(0.0);
    }
    if eval_enclosure(lo, 1.0).lo >= 0.0 {
        return UnitVerdict::Violated(1.0);
    }
    if !(hi0 < 0.0) || !(eval_enclosure(hi, 1.0).hi < 0.0) {
        return UnitVerdict::Unsure;
    }
    let hi_t = sturm::trim(hi);
    if hi_t.len() <= 1 || bernstein_upper(hi_t) < 0.0 {
        return UnitVerdict::Within;
    }
    // Cheap proof of a gross violation before anything more expensive.
    if let Some(u) = proven_violation(lo, COARSE) {
        return UnitVerdict::Violated(u);
    }
    // Bernstein subdivision: settles clear "within" cases whose chain would be ill-conditioned.
    if bernstein_subdivided_negative(hi_t, 0.0, 1.0, SUBDIVISION_DEPTH) {
        return UnitVerdict::Within;
    }
    // Algorithm 1, line 5: no root inside and negative ends => negative everywhere.
    let exact_input = lo == hi;
    match sturm::count_roots_float(hi_t, 0.0, 1.0) {
        Some(0) => return UnitVerdict::Within,
        Some(_) if exact_input => return UnitVerdict::Violated(argmax_sample(hi, SAMPLES)),
        _ => {}
    }
    match proven_violation(lo, SAMPLES) {
        Some(u) => UnitVerdict::Violated(u),
        None => UnitVerdict::Unsure,
    }
}

/// Which exact algorithm decides what the fast path cannot (the Sturm chain is the previous
/// path, kept for comparisons in `benchmarks/bench_bounds.py`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ExactMethod {
    /// Bernstein subdivision with Descartes' rule ([`crate::descartes`]), budgeted.
    Bernstein,
    /// Sturm chain of primitive pseudo-remainders ([`exact::certify_unit_sturm`]), unbudgeted.
    Sturm,
}

/// Exact Algorithm 1 on `[0, 1]` for an integer polynomial (a positive multiple of `G`);
/// `Unsure` only when `budget` runs out.
pub fn certify_unit_exact(p: &IntPoly, budget: &Budget) -> UnitVerdict {
    certify_unit_exact_with(p, budget, ExactMethod::Bernstein)
}

fn certify_unit_exact_with(p: &IntPoly, budget: &Budget, method: ExactMethod) -> UnitVerdict {
    let verdict = match method {
        ExactMethod::Bernstein => exact::certify_unit_budgeted(p, budget),
        ExactMethod::Sturm => Some(exact::certify_unit_sturm(p)),
    };
    match verdict {
        None => UnitVerdict::Unsure,
        Some(UnitExact::Within) => UnitVerdict::Within,
        Some(UnitExact::ViolatedAt0) => UnitVerdict::Violated(0.0),
        Some(UnitExact::ViolatedAt1) => UnitVerdict::Violated(1.0),
        Some(UnitExact::ViolatedInside) => {
            UnitVerdict::Violated(argmax_sample(&exact::to_f64_scaled(p), SAMPLES))
        }
    }
}

/// Enclosure of `G(u) = F(a + (b - a) u)` by interval Horner (exact when `[a, b] = [0, 1]`).
pub fn unit_enclosure(coeffs: &[f64], a: f64, b: f64) -> (Vec<f64>, Vec<f64>) {
    if a == 0.0 && b == 1.0 {
        return (coeffs.to_vec(), coeffs.to_vec());
    }
    let ia = Iv::point(a);
    let h = Iv::point(b).sub(ia);
    let mut acc: Vec<Iv> = Vec::with_capacity(coeffs.len());
    for &c in coeffs.iter().rev() {
        let mut next = vec![Iv::ZERO; acc.len() + 1];
        for (i, x) in acc.iter().enumerate() {
            next[i] = next[i].add(x.mul(ia));
            next[i + 1] = next[i + 1].add(x.mul(h));
        }
        next[0] = next[0].add(Iv::point(c));
        acc = next;
    }
    (
        acc.iter().map(|x| x.lo).collect(),
        acc.iter().map(|x| x.hi).collect(),
    )
}

/// A unit-interval verdict on `[a, b]` in time (`t = a + (b - a) u`).
pub fn to_time(v: UnitVerdict, a: f64, b: f64) -> Certificate {
    match v {
        UnitVerdict::Within => Certificate::Within,
        UnitVerdict::Violated(u) => Certificate::Violated {
            t: (a + (b - a) * u).clamp(a, b),
        },
        UnitVerdict::Unsure => Certificate::Unknown,
    }
}

/// Decides `F(t) = sum_k coeffs[k] t^k < 0` for all `t` in `[a, b]` (Algorithm 1, with a
/// touching root counted as a violation). With `exact = true` the answer is never Unknown.
/// Errors on non-finite input, `a > b` and degree > 40.
pub fn certify_below(coeffs: &[f64], a: f64, b: f64, exact: bool) -> Result<Certificate> {
    Ok(certify_below_traced(
        coeffs,
        a,
        b,
        exact,
        &Budget::UNLIMITED,
        ExactMethod::Bernstein,
    )?
    .0)
}

/// Like [`certify_below`], with a `budget` for the exact fallback (Unknown when it runs out),
/// a choice of exact `method`, and whether the fast path decided (for statistics).
pub fn certify_below_traced(
    coeffs: &[f64],
    a: f64,
    b: f64,
    exact: bool,
    budget: &Budget,
    method: ExactMethod,
) -> Result<(Certificate, bool)> {
    sturm::validate_poly(coeffs)?;
    sturm::validate_interval(a, b)?;
    let coeffs = sturm::trim(coeffs);
    if a == b {
        let p = exact::int_poly_from_f64(coeffs);
        let r = exact::rational(a);
        let v = exact::eval_hom(&p, r.numer(), r.denom());
        let cert = if num_traits::Signed::is_negative(&v) {
            Certificate::Within
        } else {
            Certificate::Violated { t: a }
        };
        return Ok((cert, true));
    }
    let (lo, hi) = unit_enclosure(coeffs, a, b);
    let fast = certify_enclosure(&lo, &hi);
    if fast != UnitVerdict::Unsure || !exact {
        return Ok((to_time(fast, a, b), fast != UnitVerdict::Unsure));
    }
    let p = exact::unit_shift(coeffs, a, b);
    Ok((
        to_time(certify_unit_exact_with(&p, budget, method), a, b),
        false,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bernstein_bound_is_an_upper_bound() {
        let p = [-1.0, 3.0, -2.5, 0.2];
        let ub = bernstein_upper(&p);
        for j in 0..=1000 {
            assert!(crate::poly::eval(&p, j as f64 / 1000.0) <= ub);
        }
        assert_eq!(BINOM[40][20], 137846528820.0);
    }

    #[test]
    fn subdivision_proves_negativity_the_global_hull_cannot() {
        // p(u) = -0.01 - (u - 0.5)^2 * 0 + 4 u (1 - u) - 1.02: max -0.02 at u = 0.5, yet the
        // Bernstein coefficients on [0, 1] are [-1.02, 0.98, -1.02] (hull reaches 0.98)
        let p = [-1.02, 4.0, -4.0];
        assert!(bernstein_upper(&p) > 0.0);
        assert!(bernstein_subdivided_negative(&p, 0.0, 1.0, 6));
        // and it never proves a polynomial that does reach zero
        let q = [-1.0, 4.0, -4.0]; // max exactly 0 at u = 0.5
        assert!(!bernstein_subdivided_negative(&q, 0.0, 1.0, 10));
    }

    #[test]
    fn verdicts_on_simple_cases() {
        // -(t - 0.5)^2 - 0.01 < 0 everywhere
        let inside = [-0.26, 1.0, -1.0];
        assert_eq!(
            certify_below(&inside, 0.0, 1.0, true).unwrap(),
            Certificate::Within
        );
        // -(t - 0.5)^2 touches zero at 0.5: violated (conservative)
        let touch = [-0.25, 1.0, -1.0];
        let c = certify_below(&touch, 0.0, 1.0, true).unwrap();
        match c {
            Certificate::Violated { t } => assert!((t - 0.5).abs() < 0.05),
            other => panic!("expected violation, got {other:?}"),
        }
        // the same polynomial is within on [0.6, 2]
        assert_eq!(
            certify_below(&touch, 0.6, 2.0, true).unwrap(),
            Certificate::Within
        );
        // a positive end
        assert_eq!(
            certify_below(&[-1.0, 2.0], 0.0, 1.0, true).unwrap(),
            Certificate::Violated { t: 1.0 }
        );
        // F = 0 at the end t = 0.5 exactly
        assert_eq!(
            certify_below(&[-1.0, 2.0], 0.0, 0.5, true).unwrap(),
            Certificate::Violated { t: 0.5 }
        );
        assert_eq!(
            certify_below(&[-1.0, 2.0], 0.25, 0.25, true).unwrap(),
            Certificate::Within
        );
        assert!(certify_below(&[0.0; 50], 0.0, 1.0, true).is_ok());
        assert!(certify_below(&[1.0; 50], 0.0, 1.0, true).is_err());
    }

    #[test]
    fn tangency_is_unsure_on_the_fast_path_and_violated_exactly() {
        let touch = [-0.25, 1.0, -1.0];
        // a double root makes the interval Sturm chain end in an uncertain constant
        assert_eq!(
            certify_below(&touch, 0.0, 1.0, false).unwrap(),
            Certificate::Unknown
        );
        // shifted interval: coefficients round, Sturm on hi is not enough
        let c = certify_below(&touch, 0.125, 0.875, false).unwrap();
        assert!(matches!(
            c,
            Certificate::Unknown | Certificate::Violated { .. }
        ));
        assert!(matches!(
            certify_below(&touch, 0.125, 0.875, true).unwrap(),
            Certificate::Violated { .. }
        ));
    }
}
