//! Exact, upward-rounded coefficients of the trackability polynomials of `avp.trackability`.
//!
//! Per segment `i` of duration `T_i` (the exact difference of its knots), in the normalised
//! time `u = (t - t_i) / T_i`:
//!
//! * `F_i(u) = |s_i(T_i u)|^2 - s_max^2` (snap bound), and
//! * `G_i(u) = |s_i(T_i u)|^2 - k^2 |a_i(T_i u) + g e3|^2` (snap per unit of thrust),
//!
//! with `s` the fourth and `a` the second derivative of the x, y, z axes. Every input (spline
//! coefficients, knots, limits, `g`) is a finite f64, hence a dyadic rational `m 2^e`; sums and
//! products of dyadic rationals are dyadic, so the coefficients are computed **exactly** as
//! big-integer mantissas with a binary exponent (no division, no gcd), then each is rounded
//! **upward** to the smallest f64 not below it. Because `u^k >= 0` on `[0, 1]`, the rounded
//! polynomial bounds the exact one from above there: proving it negative proves the bound. The
//! result is bit for bit the one of the reference `fractions.Fraction` computation of
//! `avp.trackability.snap_polynomial` / `snap_thrust_polynomial`.
use num_bigint::{BigInt, Sign};
use num_traits::{ToPrimitive, Zero};

use crate::error::{Error, Result};
use crate::exact::decode;
use crate::spline::SplineView;

/// The exact value `m 2^e`.
#[derive(Debug, Clone, PartialEq)]
struct Dyadic {
    m: BigInt,
    e: i64,
}

impl Dyadic {
    fn zero() -> Self {
        Dyadic {
            m: BigInt::zero(),
            e: 0,
        }
    }

    fn from_f64(x: f64) -> Self {
        let (m, e) = decode(x);
        Dyadic {
            m: BigInt::from(m),
            e: i64::from(e),
        }
    }

    fn mul(&self, o: &Dyadic) -> Dyadic {
        Dyadic {
            m: &self.m * &o.m,
            e: self.e + o.e,
        }
    }

    fn add_assign(&mut self, o: &Dyadic) {
        if o.m.is_zero() {
            return;
        }
        if self.m.is_zero() {
            *self = o.clone();
            return;
        }
        if self.e <= o.e {
            self.m += &o.m << ((o.e - self.e) as usize);
        } else {
            self.m = (&self.m << ((self.e - o.e) as usize)) + &o.m;
            self.e = o.e;
        }
    }

    fn neg(&self) -> Dyadic {
        Dyadic {
            m: -&self.m,
            e: self.e,
        }
    }
}

/// `2^k` for `k` in the normal exponent range.
fn pow2(k: i64) -> f64 {
    debug_assert!((-1022..=1023).contains(&k));
    f64::from_bits(((k + 1023) as u64) << 52)
}

/// The smallest f64 `>= m 2^e`; `None` outside the normal range (the caller falls back).
fn round_up(d: &Dyadic) -> Option<f64> {
    if d.m.is_zero() {
        return Some(0.0);
    }
    let negative = d.m.sign() == Sign::Minus;
    let a = d.m.magnitude();
    let bits = i64::try_from(a.bits()).ok()?;
    let (mut q, exp, inexact) = if bits > 53 {
        let shift = bits - 53;
        let inexact = a.trailing_zeros().is_some_and(|z| (z as i64) < shift);
        ((a >> (shift as usize)).to_u64()?, d.e + shift, inexact)
    } else {
        (a.to_u64()?, d.e, false)
    };
    if inexact && !negative {
        q += 1; // at most 2^53: still exact as an f64
    }
    // |value| = q 2^exp, 1 <= q <= 2^53, in [2^top, 2^(top + 1)): exact and normal when
    // top is in the normal exponent range.
    let top = exp + i64::from(64 - q.leading_zeros()) - 1;
    if !(-1022..=1023).contains(&top) {
        return None;
    }
    let magnitude = (q as f64 * pow2(exp - top)) * pow2(top);
    Some(if negative { -magnitude } else { magnitude })
}

/// Exact coefficients `d_k = c[k + order] (k + order)! / k!` of the `order`-th derivative of
/// one axis polynomial in `t`; at `t = T u` its coefficient of `u^k` is `d_k T^k`.
fn axis_derivative(c: &[f64], order: usize) -> Vec<Dyadic> {
    let n = c.len();
    if n <= order {
        return Vec::new();
    }
    (0..n - order)
        .map(|k| {
            // (k + order)! / k!
            let falling: u64 = ((k + 1)..=(k + order)).map(|j| j as u64).product();
            let mut term = Dyadic::from_f64(c[k + order]);
            term.m *= falling;
            term
        })
        .collect()
}

/// `v[m] * t^m` for every `m`, exactly: a square norm of polynomials whose coefficients of
/// `u^k` are `d_k T^k` has the coefficient `T^m sum_{i+j=m} d_i d_j` of `u^m`, so the powers of
/// `T` are applied once per coefficient instead of inside every product.
fn scale_by_powers(v: &mut [Dyadic], t: &Dyadic) {
    let mut power = Dyadic {
        m: BigInt::from(1),
        e: 0,
    };
    for (m, coefficient) in v.iter_mut().enumerate() {
        if m > 0 {
            power = power.mul(t);
        }
        if !coefficient.m.is_zero() && m > 0 {
            *coefficient = coefficient.mul(&power);
        }
    }
}

/// Exact coefficients of `sum_axis p_axis(u)^2` (length `2 max_len - 1`, at least 1).
///
/// The coefficients are first brought to one exponent (the smallest), so every product has the
/// same exponent and the sums are plain integer sums; `p_i p_j` is formed once for `i < j`.
fn square_norm(rows: &[Vec<Dyadic>]) -> Vec<Dyadic> {
    let size = rows
        .iter()
        .filter(|r| !r.is_empty())
        .map(|r| 2 * r.len() - 1)
        .max()
        .unwrap_or(1);
    let e = rows
        .iter()
        .flatten()
        .filter(|d| !d.m.is_zero())
        .map(|d| d.e)
        .min()
        .unwrap_or(0);
    let mut out = vec![BigInt::zero(); size];
    for r in rows {
        let m: Vec<BigInt> = r
            .iter()
            .map(|d| {
                if d.m.is_zero() {
                    BigInt::zero()
                } else {
                    &d.m << ((d.e - e) as usize)
                }
            })
            .collect();
        for (i, mi) in m.iter().enumerate() {
            if mi.is_zero() {
                continue;
            }
            out[2 * i] += mi * mi;
            for (j, mj) in m.iter().enumerate().skip(i + 1) {
                if !mj.is_zero() {
                    out[i + j] += (mi * mj) << 1usize;
                }
            }
        }
    }
    out.into_iter().map(|m| Dyadic { m, e: 2 * e }).collect()
}

fn rounded(total: &[Dyadic], width: usize, out: &mut Vec<f64>) -> Result<()> {
    for d in total {
        out.push(round_up(d).ok_or_else(|| Error::Invalid {
            arg: "coeffs",
            detail: "a trackability coefficient is outside the normal f64 range".into(),
        })?);
    }
    out.extend(std::iter::repeat_n(0.0, width - total.len()));
    Ok(())
}

/// Upper-bounding coefficients of the trackability polynomials of every segment.
///
/// Rows in segment order; per segment the snap row `F_i` if `snap_max` is finite, then the
/// thrust-relative row `G_i` if `ratio_max` is finite. Returns `(rows, n_rows, width)` with the
/// rows flattened and zero-padded to `width`. Only the first three axes of `spline` are used.
/// Fails (`Invalid`) when a coefficient falls outside the normal f64 range, and on non-finite
/// or non-positive limits.
pub fn trackability_rows(
    spline: &SplineView<'_>,
    snap_max: f64,
    ratio_max: f64,
    g: f64,
) -> Result<(Vec<f64>, usize, usize)> {
    if spline.n_axes() < 3 {
        return Err(Error::Shape {
            arg: "coeffs",
            detail: format!("needs at least 3 axes (x, y, z), got {}", spline.n_axes()),
        });
    }
    for (arg, v) in [("snap_max", snap_max), ("ratio_max", ratio_max)] {
        if v.is_nan() || v <= 0.0 {
            return Err(Error::Invalid {
                arg,
                detail: format!("must be > 0 (inf to skip), got {v}"),
            });
        }
    }
    if !g.is_finite() {
        return Err(Error::NonFinite { arg: "g" });
    }
    let (with_snap, with_ratio) = (snap_max.is_finite(), ratio_max.is_finite());
    let n_c = spline.n_coeffs();
    let len_of = |order: usize| {
        if n_c > order {
            2 * (n_c - order) - 1
        } else {
            1
        }
    };
    let width = match (with_snap, with_ratio) {
        (_, true) => len_of(4).max(len_of(2)),
        (true, false) => len_of(4),
        (false, false) => 0,
    };
    let per = usize::from(with_snap) + usize::from(with_ratio);
    let n_rows = spline.n_segments() * per;
    let mut out = Vec::with_capacity(n_rows * width);
    let knots = spline.knots();
    let s2 = Dyadic::from_f64(snap_max);
    let s2 = s2.mul(&s2).neg();
    let k2 = Dyadic::from_f64(ratio_max);
    let k2 = k2.mul(&k2).neg();
    for seg in 0..spline.n_segments() {
        let mut t = Dyadic::from_f64(knots[seg + 1]);
        t.add_assign(&Dyadic::from_f64(knots[seg]).neg());
        // sums of products without the powers of T (scale_by_powers applies them)
        let snap_axes: Vec<Vec<Dyadic>> = (0..3)
            .map(|a| axis_derivative(spline.poly(seg, a), 4))
            .collect();
        let snap = square_norm(&snap_axes);
        if with_snap {
            let mut total = snap.clone();
            scale_by_powers(&mut total, &t);
            total[0].add_assign(&s2);
            rounded(&total, width, &mut out)?;
        }
        if with_ratio {
            let mut acc: Vec<Vec<Dyadic>> = (0..3)
                .map(|a| axis_derivative(spline.poly(seg, a), 2))
                .collect();
            if acc[2].is_empty() {
                acc[2].push(Dyadic::zero());
            }
            acc[2][0].add_assign(&Dyadic::from_f64(g));
            let thrust = square_norm(&acc);
            let mut total = vec![Dyadic::zero(); snap.len().max(thrust.len())];
            for (i, s) in snap.iter().enumerate() {
                total[i].add_assign(s);
            }
            for (i, f) in thrust.iter().enumerate() {
                total[i].add_assign(&f.mul(&k2));
            }
            scale_by_powers(&mut total, &t);
            rounded(&total, width, &mut out)?;
        }
    }
    Ok((out, n_rows, width))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dy(m: i64, e: i64) -> Dyadic {
        Dyadic {
            m: BigInt::from(m),
            e,
        }
    }

    #[test]
    fn round_up_is_the_smallest_float_not_below() {
        // exact values come back unchanged
        for x in [0.0, 1.0, -2.5, 1e-300, 3.0e300, 0.1] {
            assert_eq!(round_up(&Dyadic::from_f64(x)), Some(x));
        }
        // 1 + 2^-60 lies strictly between 1 and next_up(1)
        let v = Dyadic {
            m: (BigInt::from(1) << 60usize) + 1,
            e: -60,
        };
        assert_eq!(round_up(&v), Some(1.0 + f64::EPSILON));
        assert_eq!(round_up(&v.neg()), Some(-1.0));
        // 0.1 * 3 exactly, versus its float neighbours
        let p = Dyadic::from_f64(0.1).mul(&dy(3, 0));
        let r = round_up(&p).unwrap();
        let exact_is_above = |f: f64| {
            let mut diff = p.clone();
            diff.add_assign(&Dyadic::from_f64(f).neg());
            diff.m.sign() == Sign::Plus
        };
        assert!(!exact_is_above(r));
        assert!(exact_is_above(crate::interval::next_down(r)));
        // out of the normal range: no answer
        assert_eq!(round_up(&dy(3, -1100)), None);
        assert_eq!(round_up(&dy(3, 1100)), None);
    }

    #[test]
    fn constant_snap_of_a_quartic() {
        // x(t) = t^4 on one segment of length 0.5: s = 24, |s|^2 - 10^2 = 476
        let mut c = vec![0.0; 3 * 6];
        c[4] = 1.0;
        let knots = [0.25, 0.75];
        let view = SplineView::new(&c, (1, 3, 6), &knots).unwrap();
        let (rows, n, w) = trackability_rows(&view, 10.0, f64::INFINITY, 9.81).unwrap();
        assert_eq!((n, w), (1, 3));
        assert_eq!(rows, vec![476.0, 0.0, 0.0]);
        // with the thrust ratio: a = 12 t^2 -> 12 (T u)^2 = 3 u^2 in u; f_z = 9.81
        let (rows, n, w) = trackability_rows(&view, f64::INFINITY, 2.0, 9.81).unwrap();
        assert_eq!((n, w), (1, 7));
        // 576 - 4 (9.81^2 + 9 u^4): x carries a, z carries g (no cross term)
        assert_eq!(&rows[1..], &[0.0, 0.0, 0.0, -36.0, 0.0, 0.0]);
        let f = 576.0 - 4.0 * 9.81 * 9.81;
        assert!(rows[0] >= f && rows[0] <= f + 1e-12);
    }

    #[test]
    fn bad_limits_are_errors() {
        let c = vec![0.0; 3 * 6];
        let knots = [0.0, 1.0];
        let view = SplineView::new(&c, (1, 3, 6), &knots).unwrap();
        assert!(trackability_rows(&view, -1.0, 1.0, 9.81).is_err());
        assert!(trackability_rows(&view, 1.0, f64::NAN, 9.81).is_err());
        assert!(trackability_rows(&view, 1.0, 1.0, f64::INFINITY).is_err());
    }
}
