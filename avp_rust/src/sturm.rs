//! Sturm sequences and distinct-root counting (paper Appendix A, eq. (17)) with a floating-point
//! fast path that **knows when it is unsure**.
//!
//! The fast path encloses the *exact* Sturm sequence of the input polynomial in outward-rounded
//! interval arithmetic ([`Iv`]): every coefficient of every remainder is an interval that
//! provably contains the coefficient the exact (rational) computation would produce. A sign is
//! used only when its interval excludes zero. Whenever a leading coefficient, a final constant or
//! a sign evaluation is not certain the fast path returns `None` and [`sturm_count`] falls back
//! to exact big-integer arithmetic ([`crate::exact`]). See `docs/bounds.md` for the argument.
//!
//! Polynomials are in ascending powers; degree at most [`MAX_DEGREE`] on the public entry points.
use crate::error::{check_finite, Error, Result};
use crate::exact;
use crate::interval::{eval_iv, Iv};

/// Largest polynomial degree accepted by the public entry points.
pub const MAX_DEGREE: usize = 40;

/// Coefficients without trailing (highest-power) exact zeros.
pub fn trim(coeffs: &[f64]) -> &[f64] {
    let n = coeffs.iter().rposition(|&c| c != 0.0).map_or(0, |i| i + 1);
    &coeffs[..n]
}

/// A power of two `s` with `m * s` in `[0.5, 1)` (1 when `m` is zero or not finite).
#[inline]
fn pow2_normaliser(m: f64) -> f64 {
    if !(m.is_finite() && m > 0.0) {
        return 1.0;
    }
    let e = ((m.to_bits() >> 52) & 0x7ff) as i32 - 1022; // m in [2^(e-1), 2^e) for normal m
    let k = (-e).clamp(-1000, 1000);
    2f64.powi(k)
}

/// Scales an interval polynomial by a positive power of two so its largest magnitude is about
/// one. Positive factors do not change any sign, so the scaled sequence is still a Sturm
/// sequence of the same polynomial; the scaling keeps the chain away from overflow/underflow.
fn normalise(p: &mut [Iv]) {
    let m = p.iter().fold(0.0f64, |acc, c| acc.max(c.mag()));
    let s = pow2_normaliser(m);
    if s != 1.0 {
        for c in p.iter_mut() {
            *c = c.mul_f64(s);
        }
    }
}

/// Interval enclosure of the Sturm sequence `S_0 = p, S_1 = p', S_{i+1} = -rem(S_{i-1}, S_i)`
/// (each element scaled by a positive power of two), for a **regular** chain only: every
/// remainder must have a leading coefficient whose interval excludes zero (so its degree is
/// known to drop by exactly one) and the final constant must certainly be nonzero (so `p` is
/// squarefree). Returns `None` when any of that is not certain. `p` must be trimmed, degree >= 1.
pub fn sturm_chain_iv(p: &[f64]) -> Option<Vec<Vec<Iv>>> {
    let n = p.len().checked_sub(1)?;
    if n == 0 {
        return None;
    }
    let mut chain: Vec<Vec<Iv>> = Vec::with_capacity(n + 1);
    let mut s0: Vec<Iv> = p.iter().map(|&c| Iv::point(c)).collect();
    normalise(&mut s0);
    let mut s1: Vec<Iv> = p
        .iter()
        .enumerate()
        .skip(1)
        .map(|(k, &c)| Iv::point(c).mul_f64(k as f64))
        .collect();
    normalise(&mut s1);
    chain.push(s0);
    chain.push(s1);
    loop {
        let (a, b) = (&chain[chain.len() - 2], &chain[chain.len() - 1]);
        let m = a.len() - 1; // deg A; deg B = m - 1 (regular chain)
        let lb = b[m - 1];
        lb.sign().filter(|&s| s != 0)?;
        if m == 1 {
            break; // B is a certainly nonzero constant: the chain is complete
        }
        // A - q1 u B removes the u^m term exactly (by definition of the exact quotient).
        let q1 = a[m].div(lb);
        let mut ap: Vec<Iv> = a[..m].to_vec();
        for k in 1..m {
            ap[k] = ap[k].sub(q1.mul(b[k - 1]));
        }
        let q0 = ap[m - 1].div(lb);
        let mut r: Vec<Iv> = (0..m - 1).map(|k| ap[k].sub(q0.mul(b[k])).neg()).collect();
        // Degree of the remainder must be exactly m - 2 and, at the end, a nonzero constant.
        r.last()?.sign().filter(|&s| s != 0)?;
        normalise(&mut r);
        chain.push(r);
    }
    Some(chain)
}

/// Number of sign variations of the chain at `x`, or `None` when a sign is not certain. An
/// uncertain interior element is tolerated when its two neighbours have certain, opposite
/// signs: then the triple contributes exactly one variation whatever its sign (or zero).
pub fn variations_iv(chain: &[Vec<Iv>], x: f64) -> Option<usize> {
    let mut signs: Vec<Option<i8>> = chain.iter().map(|s| eval_iv(s, x).sign()).collect();
    let n = signs.len();
    for i in 0..n {
        if signs[i].is_none() {
            if i == 0 || i + 1 == n {
                return None;
            }
            match (signs[i - 1], signs[i + 1]) {
                (Some(l), Some(r)) if l * r == -1 => signs[i] = Some(l),
                _ => return None,
            }
        }
    }
    let mut count = 0;
    let mut last = 0i8;
    for s in signs.into_iter().flatten() {
        if s != 0 {
            if last != 0 && s != last {
                count += 1;
            }
            last = s;
        }
    }
    Some(count)
}

/// Fast path: number of distinct real roots of `p` in `[a, b]` (`a < b`), or `None` when the
/// floating-point enclosure cannot decide it (multiple roots, roots at an end, ill-conditioned
/// remainders). Never returns a wrong count.
pub fn count_roots_float(p: &[f64], a: f64, b: f64) -> Option<usize> {
    let p = trim(p);
    if p.is_empty() {
        return None; // zero polynomial
    }
    if p.len() == 1 {
        return Some(0);
    }
    let chain = sturm_chain_iv(p)?;
    // The ends must not be roots (certain nonzero signs of S_0).
    let s0 = &chain[0];
    eval_iv(s0, a).sign().filter(|&s| s != 0)?;
    eval_iv(s0, b).sign().filter(|&s| s != 0)?;
    let va = variations_iv(&chain, a)?;
    let vb = variations_iv(&chain, b)?;
    va.checked_sub(vb)
}

fn check_poly(coeffs: &[f64]) -> Result<()> {
    check_finite("coeffs", coeffs)?;
    if coeffs.is_empty() {
        return Err(Error::Shape {
            arg: "coeffs",
            detail: "needs at least one coefficient".into(),
        });
    }
    let deg = trim(coeffs).len().saturating_sub(1);
    if deg > MAX_DEGREE {
        return Err(Error::Invalid {
            arg: "coeffs",
            detail: format!("degree {deg} exceeds the supported maximum {MAX_DEGREE}"),
        });
    }
    Ok(())
}

/// Validates a polynomial for the public entry points: finite, nonempty, degree <= 40.
pub(crate) fn validate_poly(coeffs: &[f64]) -> Result<()> {
    check_poly(coeffs)
}

/// Validates an interval `[a, b]` with finite `a <= b`.
pub(crate) fn validate_interval(a: f64, b: f64) -> Result<()> {
    check_finite("a", &[a])?;
    check_finite("b", &[b])?;
    if a > b {
        return Err(Error::Invalid {
            arg: "b",
            detail: format!("interval end {b} is below its start {a}"),
        });
    }
    Ok(())
}

/// Exact number of distinct real roots of `sum_k coeffs[k] x^k` in the closed interval
/// `[a, b]` (ends included). Uses the interval fast path and falls back to exact big-integer
/// Sturm sequences whenever the fast path is unsure. Errors on non-finite input, `a > b`,
/// degree > 40 and the zero polynomial (infinitely many roots).
pub fn sturm_count(coeffs: &[f64], a: f64, b: f64) -> Result<usize> {
    check_poly(coeffs)?;
    validate_interval(a, b)?;
    let p = trim(coeffs);
    if p.is_empty() {
        return Err(Error::Invalid {
            arg: "coeffs",
            detail: "the zero polynomial has infinitely many roots".into(),
        });
    }
    if a < b {
        if let Some(n) = count_roots_float(p, a, b) {
            return Ok(n);
        }
    }
    Ok(exact::count_roots_f64(p, a, b))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::interval::{next_down, next_up};

    #[test]
    fn next_up_and_down_bracket() {
        for &x in &[0.0, -0.0, 1.0, -1.0, 1e-310, -1e-310, 3.5e300, f64::MAX] {
            assert!(next_up(x) > x);
            assert!(next_down(x) < x);
        }
        assert_eq!(next_up(f64::MAX), f64::INFINITY);
    }

    #[test]
    fn interval_ops_contain_exact_results() {
        let a = Iv::point(0.1);
        let b = Iv::point(0.2);
        let s = a.add(b);
        assert!(s.lo <= 0.30000000000000004 && s.hi >= 0.3);
        assert!(s.lo < s.hi);
        let p = Iv { lo: -1.0, hi: 2.0 }.mul(Iv { lo: -3.0, hi: 0.5 });
        assert!(p.lo <= -6.0 && p.hi >= 3.0);
        assert_eq!(Iv::point(1.0).div(Iv { lo: -1.0, hi: 1.0 }), Iv::ENTIRE);
        assert_eq!(Iv { lo: -1.0, hi: 1.0 }.sign(), None);
        assert_eq!(Iv::point(f64::INFINITY).mul(Iv::ZERO), Iv::ENTIRE);
    }

    #[test]
    fn paper_example_eq_18() {
        // H(t) = t^4 + t^3 - t - 1 has one root (t = 1) in [0, 2] (Appendix A).
        let h = [-1.0, -1.0, 0.0, 1.0, 1.0];
        assert_eq!(sturm_count(&h, 0.0, 2.0).unwrap(), 1);
        assert_eq!(count_roots_float(&h, 0.0, 2.0), Some(1));
        assert_eq!(sturm_count(&h, -2.0, 2.0).unwrap(), 2);
        // the root t = 1 at an end: the float path refuses, the exact path counts it
        assert_eq!(count_roots_float(&h, 1.0, 2.0), None);
        assert_eq!(sturm_count(&h, 1.0, 2.0).unwrap(), 1);
        assert_eq!(sturm_count(&h, 1.0, 1.0).unwrap(), 1);
        assert_eq!(sturm_count(&h, 1.5, 1.5).unwrap(), 0);
    }

    #[test]
    fn double_root_goes_exact() {
        // (x - 0.5)^2 (x + 3) = x^3 + 2x^2 - 2.75x + 0.75
        let p = [0.75, -2.75, 2.0, 1.0];
        assert_eq!(count_roots_float(&p, 0.0, 1.0), None);
        assert_eq!(sturm_count(&p, 0.0, 1.0).unwrap(), 1);
        assert_eq!(sturm_count(&p, -4.0, 1.0).unwrap(), 2);
    }

    #[test]
    fn rejects_bad_input() {
        assert!(sturm_count(&[], 0.0, 1.0).is_err());
        assert!(sturm_count(&[0.0, 0.0], 0.0, 1.0).is_err());
        assert!(sturm_count(&[1.0, f64::NAN], 0.0, 1.0).is_err());
        assert!(sturm_count(&[1.0, 1.0], 1.0, 0.0).is_err());
        assert!(sturm_count(&vec![1.0; 42], 0.0, 1.0).is_err());
        assert_eq!(sturm_count(&[2.0], 0.0, 1.0).unwrap(), 0);
        // trailing zeros do not count towards the degree
        let mut p = vec![0.0; 60];
        p[0] = -1.0;
        p[1] = 4.0;
        assert_eq!(sturm_count(&p, 0.0, 1.0).unwrap(), 1);
    }
}
