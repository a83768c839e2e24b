//! The acceptance checks of one QP solution (`avp.solve`): the largest relative violation of
//! the rows it was asked to meet, and the KKT residuals of a two-sided QP, the test of the
//! fallback (16) of Mao et al. Matrices are row-major slices.
//!
//! Each is a handful of dense products on a few hundred rows: computed in one pass here instead
//! of a dozen NumPy calls. The products are summed in four interleaved partial sums, so the
//! figures can differ from NumPy's (BLAS) in the last bits; they are compared with tolerances
//! only.
use crate::error::{check_len, Result};

/// `row . x` in four interleaved partial sums (independent chains the compiler can vectorise).
fn dot(row: &[f64], x: &[f64]) -> f64 {
    let n = row.len().min(x.len());
    let (row, x) = (&row[..n], &x[..n]);
    let mut acc = [0.0_f64; 4];
    let (rc, xc) = (row.chunks_exact(4), x.chunks_exact(4));
    let tail: f64 = rc
        .remainder()
        .iter()
        .zip(xc.remainder())
        .map(|(a, b)| a * b)
        .sum();
    for (r, v) in rc.zip(xc) {
        for k in 0..4 {
            acc[k] += r[k] * v[k];
        }
    }
    (acc[0] + acc[1]) + (acc[2] + acc[3]) + tail
}

/// `1 / max(1, |bound|)`, or 1 for an infinite bound (the scale of a row's violation).
fn inverse_scale(bound: f64) -> f64 {
    if bound.is_finite() {
        1.0 / bound.abs().max(1.0)
    } else {
        1.0
    }
}

/// `a` if it is larger than `b` or NaN (a NaN residual is never dropped), else `b`.
fn worse(a: f64, b: f64) -> f64 {
    if a.is_nan() || a > b {
        a
    } else {
        b
    }
}

/// The largest relative violation at `c` of `A c = b` and `lower <= G c <= upper`: the maximum
/// of 0, `|a_i c - b_i| / max(1, |b_i|)` over the equality rows and `(g_i c - upper_i) /
/// max(1, |upper_i|)`, `(lower_i - g_i c) / max(1, |lower_i|)` over the inequality rows (an
/// infinite bound scales by 1, so it is never violated by a finite product). NaN when a residual
/// is NaN. `a` is `(b.len(), c.len())`, `g` is `(lower.len(), c.len())`, both row-major.
pub fn max_violation(
    c: &[f64],
    a: &[f64],
    b: &[f64],
    g: &[f64],
    lower: &[f64],
    upper: &[f64],
) -> Result<f64> {
    let n = c.len();
    check_len("a", a.len(), b.len() * n)?;
    check_len("g", g.len(), lower.len() * n)?;
    check_len("upper", upper.len(), lower.len())?;
    let mut worst = 0.0_f64;
    if n == 0 {
        for &bi in b {
            worst = worse(bi.abs() * inverse_scale(bi), worst);
        }
        for (&lo, &hi) in lower.iter().zip(upper) {
            worst = worse(-hi * inverse_scale(hi), worst);
            worst = worse(lo * inverse_scale(lo), worst);
        }
        return Ok(worst);
    }
    for (row, &bi) in a.chunks_exact(n).zip(b) {
        worst = worse((dot(row, c) - bi).abs() * inverse_scale(bi), worst);
    }
    for ((row, &lo), &hi) in g.chunks_exact(n).zip(lower).zip(upper) {
        let r = dot(row, c);
        worst = worse((r - hi) * inverse_scale(hi), worst);
        worst = worse((lo - r) * inverse_scale(lo), worst);
    }
    Ok(worst)
}

/// KKT residuals of `min 1/2 x^T H x + q^T x` s.t. `lower <= G x <= upper` at `x` with signed
/// multipliers `lam` (`> 0`: upper bound active, `< 0`: lower): the dual residual `max_i |(H x +
/// q + G^T lam)_i|` (0 for an empty `x`) and the duality gap `|x^T H x + q^T x + sum_{lam_j > 0}
/// upper_j lam_j + sum_{lam_j < 0} lower_j lam_j|`. They equal those of the one-sided problem
/// `[G; -G] x <= [upper; -lower]` with multipliers `[lam^+; lam^-]`. NaN propagates, except from
/// a row of `G` whose multiplier is zero (it adds nothing, so its entries are not read).
pub fn kkt_residuals(
    h: &[f64],
    q: &[f64],
    g: &[f64],
    x: &[f64],
    lam: &[f64],
    lower: &[f64],
    upper: &[f64],
) -> Result<(f64, f64)> {
    let n = x.len();
    let m = lam.len();
    check_len("h", h.len(), n * n)?;
    check_len("q", q.len(), n)?;
    check_len("g", g.len(), m * n)?;
    check_len("lower", lower.len(), m)?;
    check_len("upper", upper.len(), m)?;
    let mut stationarity: Vec<f64> = if n == 0 {
        Vec::new()
    } else {
        h.chunks_exact(n).map(|row| dot(row, x)).collect()
    };
    let mut gap = dot(x, &stationarity) + dot(q, x);
    for (s, &qi) in stationarity.iter_mut().zip(q) {
        *s += qi;
    }
    for (j, &l) in lam.iter().enumerate() {
        if n > 0 && l != 0.0 {
            for (s, &gji) in stationarity.iter_mut().zip(&g[j * n..(j + 1) * n]) {
                *s += gji * l;
            }
        }
        if l > 0.0 {
            gap += upper[j] * l;
        } else if l < 0.0 {
            gap += lower[j] * l;
        } else if l.is_nan() {
            gap = f64::NAN;
        }
    }
    let dual = stationarity.iter().fold(0.0_f64, |w, &s| worse(s.abs(), w));
    Ok((dual, gap.abs()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn violation_is_relative_and_ignores_infinite_bounds() {
        // c = (1, 2); equality x0 + x1 = 3.5 (residual 0.5 over max(1, 3.5))
        let c = [1.0, 2.0];
        let a = [1.0, 1.0];
        let b = [3.5];
        // rows: x0 <= 0.5 (violated by 0.5), -inf <= x1 <= inf, 4 <= x0 + x1 (violated by 1 / 4)
        let g = [1.0, 0.0, 0.0, 1.0, 1.0, 1.0];
        let lo = [f64::NEG_INFINITY, f64::NEG_INFINITY, 4.0];
        let hi = [0.5, f64::INFINITY, f64::INFINITY];
        let v = max_violation(&c, &a, &b, &g, &lo, &hi).unwrap();
        assert_eq!(v, 0.5);
        let v = max_violation(&c, &a, &[3.0], &g[2..], &lo[1..], &hi[1..]).unwrap();
        assert_eq!(v, 0.25);
        let v = max_violation(&c, &[], &[], &g[2..4], &lo[1..2], &hi[1..2]).unwrap();
        assert_eq!(v, 0.0);
    }

    #[test]
    fn a_nan_residual_is_kept() {
        let v = max_violation(
            &[f64::MAX, f64::MAX],
            &[],
            &[],
            &[1.0, 1.0],
            &[0.0],
            &[f64::INFINITY],
        )
        .unwrap();
        assert!(v.is_nan());
    }

    #[test]
    fn shapes_are_checked_by_name() {
        let e = max_violation(&[1.0], &[1.0, 2.0], &[1.0], &[], &[], &[]).unwrap_err();
        assert_eq!(e.arg(), "a");
        let e =
            kkt_residuals(&[1.0], &[0.0], &[1.0], &[1.0], &[1.0, 2.0], &[0.0], &[0.0]).unwrap_err();
        assert_eq!(e.arg(), "g");
    }

    #[test]
    fn kkt_of_a_one_dimensional_qp() {
        // min 1/2 x^2 - 2 x s.t. x <= 1: x = 1, lam = 1 (upper active); gap = 1 - 2 + 1 = 0
        let (dual, gap) = kkt_residuals(
            &[1.0],
            &[-2.0],
            &[1.0],
            &[1.0],
            &[1.0],
            &[f64::NEG_INFINITY],
            &[1.0],
        )
        .unwrap();
        assert_eq!((dual, gap), (0.0, 0.0));
        // the same with the bound written as a lower one on -x
        let (dual, gap) = kkt_residuals(
            &[1.0],
            &[-2.0],
            &[-1.0],
            &[1.0],
            &[-1.0],
            &[-1.0],
            &[f64::INFINITY],
        )
        .unwrap();
        assert_eq!((dual, gap), (0.0, 0.0));
        let (dual, _) = kkt_residuals(&[], &[], &[], &[], &[0.5], &[0.0], &[1.0]).unwrap();
        assert_eq!(dual, 0.0);
    }
}
