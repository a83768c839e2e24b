//! The scaling law of the time search (Mao et al., Sec. V-C; `avp.time_search`).
//!
//! A plan `p(t)` time-scaled by `s` (`q(t) = p(t / s)`) has its `r`-th derivative scaled by
//! `s^-r`. From one sampling of the plan (acceleration, jerk and yaw rate at the midpoints of
//! `per_segment` equal parts of every segment), [`scaled_excess`] gives, for every factor, the
//! worst relative excess `max(value / limit) - 1` over the thrust range (15), the thrust rate
//! (21), the tilt rate (22) and the body rate (24) of the scaled plan.
//!
//! The arithmetic is NumPy's, operation by operation (`avp.time_search` computed it with NumPy
//! before this kernel): `|a/s^2 + g e3|^2 = (|a|^2 s2) s2 + (2 g a_z) s2 + g^2` with
//! `s2 = s^-2` given by the caller, `|j/s^3|^2 = |j|^2 ((s2 s2) s2)`, the squared norms summed
//! left to right, NaN propagated as NumPy's `maximum` and `max` propagate it. The same inputs
//! give the same bits, so the time search takes the same steps.
use crate::error::{check_finite, Error, Result};
use crate::spline::{evaluate, SplineView};

/// The limits of [`scaled_excess`], mass-normalised where the planner normalises them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScalingLimits {
    /// Largest mass-normalised thrust (m/s^2), positive and finite.
    pub accel_max: f64,
    /// Smallest mass-normalised thrust (m/s^2); `0` leaves the lower bound out.
    pub accel_min: f64,
    /// Vehicle mass (kg), for the thrust rate (N/s).
    pub mass: f64,
    /// Largest thrust rate (N/s); `inf`: not checked.
    pub thrust_rate_max: f64,
    /// Largest tilt rate (rad/s); `inf`: not checked.
    pub tilt_rate_max: f64,
    /// Largest body rate (rad/s); `inf`: not checked.
    pub body_rate_max: f64,
}

impl ScalingLimits {
    fn check(&self) -> Result<()> {
        let bad = |arg: &'static str, detail: &str| {
            Err(Error::Invalid {
                arg,
                detail: detail.into(),
            })
        };
        if !(self.accel_max.is_finite() && self.accel_max > 0.0) {
            return bad("accel_max", "must be positive and finite (m/s^2)");
        }
        if !(self.accel_min.is_finite() && self.accel_min >= 0.0 && self.accel_min < self.accel_max)
        {
            return bad(
                "accel_min",
                "must be finite, at least 0 and below accel_max (m/s^2)",
            );
        }
        if !(self.mass.is_finite() && self.mass > 0.0) {
            return bad("mass", "must be positive and finite (kg)");
        }
        for (arg, rate) in [
            ("thrust_rate_max", self.thrust_rate_max),
            ("tilt_rate_max", self.tilt_rate_max),
            ("body_rate_max", self.body_rate_max),
        ] {
            if rate.is_nan() || rate <= 0.0 {
                return bad(arg, "must be positive (inf: not checked)");
            }
        }
        Ok(())
    }
}

/// NumPy's `maximum`: NaN when either is NaN (`f64::max` would drop the NaN).
#[inline]
fn nan_max(a: f64, b: f64) -> f64 {
    if a.is_nan() || b.is_nan() {
        f64::NAN
    } else {
        a.max(b)
    }
}

/// The roll-level constants of the body-rate bound (25): `|w|^2 <= A tilt^2 + B yaw_rate^2`.
const BODY_RATE_A: f64 = 3.0;
const BODY_RATE_B: f64 = 4.0;

/// The most samples per segment (`avp.time_search.MAX_SAMPLES_PER_SEGMENT`).
pub const MAX_PER_SEGMENT: usize = 100_000;

/// Smallest squared thrust the ratios divide by.
const MIN_THRUST_SQUARED: f64 = 1e-24;

/// Per sample: `|a|^2`, `a_z`, `|j|^2` and the yaw rate.
struct Samples {
    a2: Vec<f64>,
    a_z: Vec<f64>,
    j2: Vec<f64>,
    yaw_rate: Vec<f64>,
}

/// Samples at the midpoints of `per_segment` equal parts of every segment (segment-major).
fn samples(spline: &SplineView<'_>, per_segment: usize) -> Result<Samples> {
    if spline.n_axes() != 4 {
        return Err(Error::Shape {
            arg: "coeffs",
            detail: format!("expected 4 axes (x, y, z, yaw), got {}", spline.n_axes()),
        });
    }
    let knots = spline.knots();
    let per = per_segment as f64;
    let mut t = Vec::with_capacity(spline.n_segments() * per_segment);
    for w in knots.windows(2) {
        for m in 0..per_segment {
            t.push(w[0] + ((m as f64 + 0.5) / per) * (w[1] - w[0]));
        }
    }
    let n = t.len();
    let d = evaluate(spline, &t, &[1, 2, 3])?; // [order][time][axis]
    let at = |order: usize, i: usize, axis: usize| d[(order * n + i) * 4 + axis];
    let norm2 = |order: usize, i: usize| {
        let (x, y, z) = (at(order, i, 0), at(order, i, 1), at(order, i, 2));
        x * x + y * y + z * z
    };
    Ok(Samples {
        a2: (0..n).map(|i| norm2(1, i)).collect(),
        a_z: (0..n).map(|i| at(1, i, 2)).collect(),
        j2: (0..n).map(|i| norm2(2, i)).collect(),
        yaw_rate: (0..n).map(|i| at(0, i, 3)).collect(),
    })
}

/// `excess[k]`: the worst relative excess of the spline time-scaled by `s_k`, where
/// `s2[k] = s_k^-2`, on `per_segment` midpoint samples per segment (negative: every sample
/// within every limit). See the module documentation for the arithmetic.
pub fn scaled_excess(
    spline: &SplineView<'_>,
    per_segment: usize,
    s2: &[f64],
    g: f64,
    limits: &ScalingLimits,
) -> Result<Vec<f64>> {
    if per_segment == 0 || per_segment > MAX_PER_SEGMENT {
        return Err(Error::Invalid {
            arg: "per_segment",
            detail: format!("must be in [1, {MAX_PER_SEGMENT}], got {per_segment}"),
        });
    }
    check_finite("s2", s2)?;
    if s2.iter().any(|&v| v <= 0.0) {
        return Err(Error::Invalid {
            arg: "s2",
            detail: "the squared inverse scale factors must be positive".into(),
        });
    }
    if !g.is_finite() {
        return Err(Error::NonFinite { arg: "g" });
    }
    limits.check()?;
    let smp = samples(spline, per_segment)?;
    let two_g = 2.0 * g;
    let g2 = g * g;
    let rates = limits.thrust_rate_max.is_finite()
        || limits.tilt_rate_max.is_finite()
        || limits.body_rate_max.is_finite();
    let mut out = Vec::with_capacity(s2.len());
    for &s in s2 {
        let (mut f2_max, mut f2_min) = (f64::NEG_INFINITY, f64::INFINITY);
        let (mut jj_max, mut tilt2_max, mut w2_max) =
            (f64::NEG_INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY);
        // NaN anywhere in a quantity makes NumPy's maximum of it NaN: flagged here, the maxima
        // themselves taken without NaN (a flagged quantity's maximum is not used)
        let (mut nan_f2, mut nan_jj, mut nan_tilt2, mut nan_w2) = (false, false, false, false);
        let s6 = s * s * s;
        for i in 0..smp.a2.len() {
            let raw = smp.a2[i] * s * s + two_g * smp.a_z[i] * s + g2;
            nan_f2 |= raw.is_nan();
            let f2 = raw.max(MIN_THRUST_SQUARED);
            f2_max = f2_max.max(f2);
            f2_min = f2_min.min(f2);
            if rates {
                let jj = smp.j2[i] * s6;
                let tilt2 = jj / f2;
                let y = smp.yaw_rate[i];
                let w2 = BODY_RATE_A * tilt2 + BODY_RATE_B * (y * y) * s;
                nan_jj |= jj.is_nan();
                nan_tilt2 |= tilt2.is_nan();
                nan_w2 |= w2.is_nan();
                jj_max = jj_max.max(jj);
                tilt2_max = tilt2_max.max(tilt2);
                w2_max = w2_max.max(w2);
            }
        }
        // a NaN f2 is NaN in NumPy's tilt and body rates too (here it was replaced by 1e-24)
        let nan = nan_f2
            || (limits.thrust_rate_max.is_finite() && nan_jj)
            || (limits.tilt_rate_max.is_finite() && nan_tilt2)
            || (limits.body_rate_max.is_finite() && nan_w2);
        if nan {
            out.push(f64::NAN);
            continue;
        }
        let mut worst = f2_max.sqrt() / limits.accel_max;
        if limits.accel_min > 0.0 {
            worst = nan_max(worst, limits.accel_min / f2_min.sqrt());
        }
        if limits.thrust_rate_max.is_finite() {
            worst = nan_max(worst, jj_max.sqrt() * limits.mass / limits.thrust_rate_max);
        }
        if limits.tilt_rate_max.is_finite() {
            worst = nan_max(worst, tilt2_max.sqrt() / limits.tilt_rate_max);
        }
        if limits.body_rate_max.is_finite() {
            worst = nan_max(worst, w2_max.sqrt() / limits.body_rate_max);
        }
        out.push(worst - 1.0);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    const LIMITS: ScalingLimits = ScalingLimits {
        accel_max: 20.0,
        accel_min: 5.0,
        mass: 1.0,
        thrust_rate_max: f64::INFINITY,
        tilt_rate_max: 3.0,
        body_rate_max: f64::INFINITY,
    };

    /// One segment of one second: x = t^3 (a_x = 6 t, j_x = 6), the other axes at rest.
    fn cubic() -> (Vec<f64>, Vec<f64>) {
        let mut c = vec![0.0; 4 * 4];
        c[3] = 1.0;
        (c, vec![0.0, 1.0])
    }

    #[test]
    fn the_excess_at_scale_one_is_the_worst_sampled_ratio() {
        let (c, k) = cubic();
        let view = SplineView::new(&c, (1, 4, 4), &k).unwrap();
        let g = 9.81;
        let out = scaled_excess(&view, 2, &[1.0], g, &LIMITS).unwrap();
        // midpoints 0.25, 0.75: |f| = sqrt((6 t)^2 + g^2), tilt = 6 / |f|
        let f = |t: f64| ((6.0 * t) * (6.0 * t) + g * g).sqrt();
        let expected = [f(0.75) / 20.0, 5.0 / f(0.25), 6.0 / f(0.25) / 3.0]
            .into_iter()
            .fold(f64::NEG_INFINITY, f64::max)
            - 1.0;
        assert!(
            (out[0] - expected).abs() < 1e-15,
            "{} vs {expected}",
            out[0]
        );
    }

    #[test]
    fn slower_plans_have_smaller_rates() {
        let (c, k) = cubic();
        let view = SplineView::new(&c, (1, 4, 4), &k).unwrap();
        let limits = ScalingLimits {
            accel_min: 0.0,
            ..LIMITS
        };
        let s2: Vec<f64> = [1.0f64, 2.0, 4.0].iter().map(|s| s.powi(-2)).collect();
        let out = scaled_excess(&view, 8, &s2, 9.81, &limits).unwrap();
        assert!(out[0] > out[1] && out[1] > out[2], "{out:?}");
    }

    #[test]
    fn a_nan_sample_makes_the_excess_nan_as_in_numpy() {
        // a_z = -1e307 and |a|^2 = inf: |f|^2 = inf - inf = NaN at every scale
        let mut c = vec![0.0; 4 * 3];
        c[8] = -0.5e307; // z = -0.5e307 t^2 (axis 2, coefficient 2): a_z = -1e307
        let k = vec![0.0, 1.0];
        let view = SplineView::new(&c, (1, 4, 3), &k).unwrap();
        let limits = ScalingLimits {
            accel_min: 0.0,
            ..LIMITS
        };
        let out = scaled_excess(&view, 2, &[1.0], 9.81, &limits).unwrap();
        assert!(out[0].is_nan(), "{out:?}");
    }

    #[test]
    fn bad_arguments_are_named() {
        let (c, k) = cubic();
        let view = SplineView::new(&c, (1, 4, 4), &k).unwrap();
        let err = |per: usize, s2: &[f64], limits: ScalingLimits| {
            scaled_excess(&view, per, s2, 9.81, &limits)
                .unwrap_err()
                .arg()
        };
        assert_eq!(err(0, &[1.0], LIMITS), "per_segment");
        assert_eq!(err(MAX_PER_SEGMENT + 1, &[1.0], LIMITS), "per_segment");
        assert_eq!(err(2, &[0.0], LIMITS), "s2");
        assert_eq!(err(2, &[f64::NAN], LIMITS), "s2");
        let no_thrust = ScalingLimits {
            accel_max: f64::INFINITY,
            ..LIMITS
        };
        assert_eq!(err(2, &[1.0], no_thrust), "accel_max");
        let no_tilt = ScalingLimits {
            tilt_rate_max: 0.0,
            ..LIMITS
        };
        assert_eq!(err(2, &[1.0], no_tilt), "tilt_rate_max");
        let three = vec![0.0; 3 * 4];
        let view3 = SplineView::new(&three, (1, 3, 4), &k).unwrap();
        let e = scaled_excess(&view3, 2, &[1.0], 9.81, &LIMITS).unwrap_err();
        assert_eq!(e.arg(), "coeffs");
    }
}
