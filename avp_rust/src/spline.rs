//! Piecewise-polynomial splines: coefficients `(segments, axes, coeffs)` in ascending powers of
//! local time `tau = t - knots[i]`, evaluated for any derivative order over a batch of times.
use crate::error::{check_finite, Error, Result};
use crate::poly;

/// A borrowed view of a spline, validated once.
#[derive(Debug, Clone, Copy)]
pub struct SplineView<'a> {
    coeffs: &'a [f64],
    knots: &'a [f64],
    n_segments: usize,
    n_axes: usize,
    n_coeffs: usize,
}

impl<'a> SplineView<'a> {
    /// Checks shapes (`coeffs.len() == S * A * C`, `knots.len() == S + 1`), finiteness, and
    /// strictly increasing knots.
    pub fn new(coeffs: &'a [f64], shape: (usize, usize, usize), knots: &'a [f64]) -> Result<Self> {
        let (n_segments, n_axes, n_coeffs) = shape;
        if n_segments == 0 || n_axes == 0 || n_coeffs == 0 {
            return Err(Error::Shape {
                arg: "coeffs",
                detail: format!("got shape {shape:?}; every dimension must be at least 1"),
            });
        }
        if coeffs.len() != n_segments * n_axes * n_coeffs {
            return Err(Error::Shape {
                arg: "coeffs",
                detail: format!("{} values do not fill shape {shape:?}", coeffs.len()),
            });
        }
        if knots.len() != n_segments + 1 {
            return Err(Error::Shape {
                arg: "knots",
                detail: format!(
                    "expected {} knots for {n_segments} segments, got {}",
                    n_segments + 1,
                    knots.len()
                ),
            });
        }
        check_finite("coeffs", coeffs)?;
        check_finite("knots", knots)?;
        if knots.windows(2).any(|w| w[1] <= w[0]) {
            return Err(Error::Invalid {
                arg: "knots",
                detail: "must be strictly increasing".into(),
            });
        }
        Ok(Self {
            coeffs,
            knots,
            n_segments,
            n_axes,
            n_coeffs,
        })
    }

    pub fn n_segments(&self) -> usize {
        self.n_segments
    }
    pub fn n_axes(&self) -> usize {
        self.n_axes
    }
    pub fn n_coeffs(&self) -> usize {
        self.n_coeffs
    }
    pub fn knots(&self) -> &'a [f64] {
        self.knots
    }

    /// Coefficients of one segment and axis.
    #[inline]
    pub fn poly(&self, segment: usize, axis: usize) -> &'a [f64] {
        let start = (segment * self.n_axes + axis) * self.n_coeffs;
        &self.coeffs[start..start + self.n_coeffs]
    }

    /// Segment that owns time `t`: right-continuous at interior knots, the first segment for
    /// `t < t0` and the last for `t >= tf` (polynomial extrapolation outside the domain).
    #[inline]
    pub fn segment_of(&self, t: f64) -> usize {
        let interior = &self.knots[1..self.n_segments];
        interior.partition_point(|&k| k <= t)
    }

    /// `order`-th derivative of every axis at `t`, written into `out[..n_axes]`.
    #[inline]
    pub fn eval_into(&self, t: f64, order: usize, out: &mut [f64]) {
        let seg = self.segment_of(t);
        let tau = t - self.knots[seg];
        for (axis, o) in out.iter_mut().enumerate().take(self.n_axes) {
            *o = poly::eval_derivative(self.poly(seg, axis), order, tau);
        }
    }
}

/// Evaluates the spline at every time for every derivative order.
///
/// Returns a flat vector laid out `[order][time][axis]` (shape `(orders, times, axes)`).
///
/// Per order, the differentiated coefficients `c[k] k!/(k-order)!` of every segment and axis are
/// formed once (the same products [`poly::eval_derivative`] forms at each time, so the values
/// are the same bits) and each time costs one Horner pass per axis.
pub fn evaluate(spline: &SplineView<'_>, times: &[f64], orders: &[usize]) -> Result<Vec<f64>> {
    check_finite("times", times)?;
    let (n_s, a, n_c) = (spline.n_segments(), spline.n_axes(), spline.n_coeffs());
    let mut out = vec![0.0; orders.len() * times.len() * a];
    if a == 0 {
        return Ok(out); // no axis: nothing to evaluate
    }
    // the differentiated coefficients laid out [segment][power][axis]: at one time, the Horner
    // passes of four axes at a time run side by side (independent chains, the same operations in
    // the same order per axis as one pass at a time, so the same bits)
    let mut diff = vec![0.0; n_s * n_c * a];
    for (oi, &order) in orders.iter().enumerate() {
        let len = n_c.saturating_sub(order); // differentiated coefficients per polynomial
        for seg in 0..n_s {
            for axis in 0..a {
                let c = spline.poly(seg, axis);
                for j in 0..len {
                    diff[(seg * n_c + j) * a + axis] =
                        c[j + order] * poly::falling_factorial(j + order, order);
                }
            }
        }
        for (ti, &t) in times.iter().enumerate() {
            let seg = spline.segment_of(t);
            let tau = t - spline.knots()[seg];
            let row = &mut out[(oi * times.len() + ti) * a..][..a]; // zeros: Horner's start
            let block = &diff[seg * n_c * a..][..len * a];
            let mut groups = row.chunks_exact_mut(4);
            for (g, o4) in (&mut groups).enumerate() {
                let mut acc = [0.0f64; 4];
                for d in block.chunks_exact(a).rev() {
                    let d4 = &d[4 * g..4 * g + 4];
                    for q in 0..4 {
                        acc[q] = acc[q] * tau + d4[q];
                    }
                }
                o4.copy_from_slice(&acc);
            }
            let done = a - groups.into_remainder().len();
            for axis in done..a {
                let mut acc = 0.0;
                for d in block.chunks_exact(a).rev() {
                    acc = acc * tau + d[axis];
                }
                row[axis] = acc;
            }
        }
    }
    Ok(out)
}

/// A decision vector `c` of normalised coefficients, laid out axis-major (`axes x segments x
/// powers`, the QP's layout), as spline coefficients `(segments, axes, powers)` in powers of
/// `t - t_i`: `c[a, i, k] * scale[i, k]` (`scale[i, k] = T_i^-k`, row-major `(segments,
/// powers)`), one product per entry; and whether they are all finite.
pub fn physical_coefficients(
    c: &[f64],
    scale: &[f64],
    n_coeffs: usize,
) -> Result<(Vec<f64>, bool)> {
    if n_coeffs == 0 || scale.len() % n_coeffs != 0 {
        return Err(Error::Shape {
            arg: "scale",
            detail: format!("{} values are not (segments, {n_coeffs}) rows", scale.len()),
        });
    }
    let block = scale.len(); // segments x powers: one axis of c
    if block == 0 {
        return Err(Error::Shape {
            arg: "scale",
            detail: "no segment: a spline has one at least".into(),
        });
    }
    if c.is_empty() || c.len() % block != 0 {
        return Err(Error::Shape {
            arg: "c_hat",
            detail: format!(
                "{} values are not whole axes of {block} coefficients",
                c.len()
            ),
        });
    }
    let axes = c.len() / block;
    let mut out = vec![0.0; c.len()];
    for (i, (row_scale, out_seg)) in scale
        .chunks_exact(n_coeffs)
        .zip(out.chunks_exact_mut(axes * n_coeffs))
        .enumerate()
    {
        for (a, o) in out_seg.chunks_exact_mut(n_coeffs).enumerate() {
            let src = &c[a * block + i * n_coeffs..][..n_coeffs];
            for ((v, &x), &f) in o.iter_mut().zip(src).zip(row_scale) {
                *v = x * f;
            }
        }
    }
    let finite = out.iter().all(|v| v.is_finite());
    Ok((out, finite))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn two_segment() -> (Vec<f64>, Vec<f64>) {
        // axis 0: p1 = 1 + t, p2 = 2 + t ; axis 1: p1 = t^2, p2 = 1 + 2 tau + tau^2
        let coeffs = vec![1.0, 1.0, 0.0, 0.0, 0.0, 1.0, 2.0, 1.0, 0.0, 1.0, 2.0, 1.0];
        (coeffs, vec![0.0, 1.0, 3.0])
    }

    #[test]
    fn physical_coefficients_reorder_and_scale() {
        // 2 axes, 2 segments, 2 powers: c[a, i, k] = 10 a + 2 i + k
        let c = [0.0, 1.0, 2.0, 3.0, 10.0, 11.0, 12.0, 13.0];
        let scale = [1.0, 2.0, 1.0, 0.5];
        let (out, finite) = physical_coefficients(&c, &scale, 2).unwrap();
        assert!(finite);
        assert_eq!(out, vec![0.0, 2.0, 10.0, 22.0, 2.0, 1.5, 12.0, 6.5]);
        let (_, finite) = physical_coefficients(&[f64::MAX, 0.0], &[1.0, 4.0], 2).unwrap();
        assert!(finite);
        let (_, finite) = physical_coefficients(&[1.0, f64::MAX], &[1.0, 4.0], 2).unwrap();
        assert!(!finite); // the product overflows
        assert_eq!(
            physical_coefficients(&c, &scale[..3], 2).unwrap_err().arg(),
            "scale"
        );
        assert_eq!(
            physical_coefficients(&c[..7], &scale, 2).unwrap_err().arg(),
            "c_hat"
        );
        assert_eq!(
            physical_coefficients(&c, &[], 2).unwrap_err().arg(),
            "scale"
        );
        assert_eq!(
            physical_coefficients(&[], &scale, 2).unwrap_err().arg(),
            "c_hat"
        );
    }

    #[test]
    fn picks_segments_and_evaluates_derivatives() {
        let (c, k) = two_segment();
        let s = SplineView::new(&c, (2, 2, 3), &k).unwrap();
        assert_eq!(s.segment_of(-1.0), 0);
        assert_eq!(s.segment_of(0.5), 0);
        assert_eq!(s.segment_of(1.0), 1);
        assert_eq!(s.segment_of(5.0), 1);
        let v = evaluate(&s, &[0.5, 2.0], &[0, 1, 2]).unwrap();
        assert_eq!(
            v,
            vec![1.5, 0.25, 3.0, 4.0, 1.0, 1.0, 1.0, 4.0, 0.0, 2.0, 0.0, 2.0]
        );
    }

    #[test]
    fn rejects_bad_input() {
        let (c, k) = two_segment();
        assert!(matches!(
            SplineView::new(&c, (2, 2, 4), &k),
            Err(Error::Shape { arg: "coeffs", .. })
        ));
        assert!(matches!(
            SplineView::new(&c, (2, 2, 3), &k[..2]),
            Err(Error::Shape { arg: "knots", .. })
        ));
        assert!(matches!(
            SplineView::new(&c, (2, 2, 3), &[0.0, 1.0, 1.0]),
            Err(Error::Invalid { arg: "knots", .. })
        ));
        let mut bad = c.clone();
        bad[3] = f64::NAN;
        assert!(matches!(
            SplineView::new(&bad, (2, 2, 3), &k),
            Err(Error::NonFinite { arg: "coeffs" })
        ));
        let s = SplineView::new(&c, (2, 2, 3), &k).unwrap();
        assert!(evaluate(&s, &[f64::INFINITY], &[0]).is_err());
    }

    #[test]
    fn batch_evaluation_equals_pointwise_horner_bit_for_bit() {
        // a deterministic pseudo-random spline: 3 segments, 4 axes, degree 9
        let mut state = 0x2545_f491_4f6c_dd1d_u64;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64 * 20.0 - 10.0
        };
        let c: Vec<f64> = (0..3 * 4 * 10).map(|_| next()).collect();
        let k = vec![0.0, 0.37, 1.1, 1.5];
        let s = SplineView::new(&c, (3, 4, 10), &k).unwrap();
        let times: Vec<f64> = (0..97)
            .map(|i| -0.1 + 1.7 * i as f64 / 96.0)
            .chain([0.37, 1.1, 1.5])
            .collect();
        let orders = [0, 1, 2, 3, 4, 9, 10, 12];
        let out = evaluate(&s, &times, &orders).unwrap();
        let mut one = [0.0; 4];
        for (oi, &order) in orders.iter().enumerate() {
            for (ti, &t) in times.iter().enumerate() {
                s.eval_into(t, order, &mut one);
                let got = &out[(oi * times.len() + ti) * 4..][..4];
                for axis in 0..4 {
                    assert_eq!(
                        got[axis].to_bits(),
                        one[axis].to_bits(),
                        "order {order}, t {t}, axis {axis}"
                    );
                }
            }
        }
    }
}
