//! Geometric (workspace) certificates of a flat-output spline: clearance from a plane, from a
//! sphere, and a speed limit, each proven per segment with the same sound machinery as the
//! actuator bounds ([`crate::bounds`]).
//!
//! Every region is a polynomial `F(u)` on `u in [0, 1]` per segment (`t = t_i + T u`) that must
//! be negative:
//!
//! | region | `F` | holds when |
//! |---|---|---|
//! | [`Region::HalfSpace`] | `d − n·p` | the position stays on the side `n` points to, `n·p > d` |
//! | [`Region::SphereOutside`] | `r² − ‖p − c‖²` | the position stays outside the ball |
//! | [`Region::SpeedBelow`] | `‖v‖² − v_max²` | the speed stays below `v_max` |
//!
//! **Touching at the end.** A perch plane is reached at contact: `F(1) = 0` by construction
//! (up to rounding), so `F < 0` on the closed segment is false and not what is meant. With
//! `touch_order = k >= 1` the last segment is certified as follows: `G(w) = F(1 − w)` (Taylor
//! shift), `G(w) = sum_{j<k} G_j w^j + w^k Q(w)`; the kernel proves `Q(w) < 0` on `w in [0, 1]`
//! and returns the rigorous residual `eps = sum_{j<k} max(G_j, 0)` (an upper bound of the exact
//! `G_j`). Then `F(u) < eps` on the segment and `F(u) < 0` wherever `w^k |Q| > eps`: the
//! position never goes further than `eps` (about 1e-15 m for a contact met to rounding) beyond
//! the plane, and approaches it with a strictly positive order-`k` rate (`k = 1`: a normal
//! velocity into the plane at contact, `Q(0) = -T n·v(t_f)`). `docs/bounds.md` has the proof.
use num_rational::BigRational;

use crate::bounds::{const_minus, minus_const, padd, pscale, scaled_derivative, sq_norm, Scalar};
use crate::certify::{certify_enclosure, certify_unit_exact, Certificate, UnitVerdict};
use crate::descartes::Budget;
use crate::error::{check_finite, Error, Result};
use crate::exact;
use crate::interval::Iv;
use crate::spline::SplineView;
use crate::sturm::MAX_DEGREE;

/// A workspace region the position (or velocity) must stay in.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Region {
    /// `n·p(t) > d`.
    HalfSpace { normal: [f64; 3], offset: f64 },
    /// `‖p(t) − c‖ > r`.
    SphereOutside { center: [f64; 3], radius: f64 },
    /// `‖v(t)‖ < v_max`.
    SpeedBelow { v_max: f64 },
}

impl Region {
    fn validate(&self) -> Result<()> {
        match *self {
            Region::HalfSpace { normal, offset } => {
                check_finite("normal", &normal)?;
                check_finite("offset", &[offset])?;
                let n2: f64 = normal.iter().map(|x| x * x).sum();
                if n2 == 0.0 {
                    return Err(Error::Invalid {
                        arg: "normal",
                        detail: "is the zero vector; pass the plane's normal".into(),
                    });
                }
            }
            Region::SphereOutside { center, radius } => {
                check_finite("center", &center)?;
                check_finite("radius", &[radius])?;
                if radius < 0.0 {
                    return Err(Error::Invalid {
                        arg: "radius",
                        detail: format!("must be >= 0, got {radius}"),
                    });
                }
            }
            Region::SpeedBelow { v_max } => {
                if v_max.is_nan() || v_max < 0.0 || v_max.is_infinite() {
                    return Err(Error::Invalid {
                        arg: "v_max",
                        detail: format!("must be finite and >= 0, got {v_max}"),
                    });
                }
            }
        }
        Ok(())
    }

    /// Degree of `F` for `n_coeffs` coefficients per axis.
    fn degree(&self, n_coeffs: usize) -> usize {
        let d = n_coeffs.saturating_sub(1);
        match self {
            Region::HalfSpace { .. } => d,
            Region::SphereOutside { .. } => 2 * d,
            Region::SpeedBelow { .. } => 2 * d.saturating_sub(1),
        }
    }

    /// `F(u)` on segment `seg` (negative iff the region holds), in the scalar type `S`.
    fn poly<S: Scalar>(&self, view: &SplineView<'_>, seg: usize) -> Vec<S> {
        let knots = view.knots();
        let h = S::from_f64(knots[seg + 1]).sub(&S::from_f64(knots[seg]));
        let axis = |order: usize, ax: usize| scaled_derivative::<S>(view.poly(seg, ax), order, &h);
        match *self {
            Region::HalfSpace { normal, offset } => {
                // d - n.p
                let np = (0..3).fold(vec![S::zero()], |acc, ax| {
                    padd(&acc, &pscale(&axis(0, ax), &S::from_f64(normal[ax])))
                });
                const_minus(&S::from_f64(offset), &np)
            }
            Region::SphereOutside { center, radius } => {
                // r^2 - |p - c|^2
                let rel: Vec<Vec<S>> = (0..3)
                    .map(|ax| minus_const(&axis(0, ax), &S::from_f64(center[ax])))
                    .collect();
                let r = S::from_f64(radius);
                const_minus(&r.mul(&r), &sq_norm(&rel))
            }
            Region::SpeedBelow { v_max } => {
                let vel: Vec<Vec<S>> = (0..3).map(|ax| axis(1, ax)).collect();
                let v = S::from_f64(v_max);
                minus_const(&sq_norm(&vel), &v.mul(&v))
            }
        }
    }
}

/// Verdict on one segment; `residual` is the contact residual `eps` (only on a touching last
/// segment, 0 elsewhere).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RegionVerdict {
    pub certificate: Certificate,
    pub residual: f64,
}

/// `G(w) = F(1 − w)`: `G_j = (−1)^j sum_{k>=j} C(k, j) F_k` (exact binomials up to degree 40).
fn reflect<S: Scalar>(f: &[S]) -> Vec<S> {
    let n = f.len();
    (0..n)
        .map(|j| {
            let mut acc = S::zero();
            let mut binom = 1.0_f64; // C(k, j) for k = j
            for (k, fk) in f.iter().enumerate().skip(j) {
                if k > j {
                    binom = binom * k as f64 / (k - j) as f64;
                }
                acc = acc.add(&fk.mul(&S::from_f64(binom.round())));
            }
            if j % 2 == 1 {
                S::zero().sub(&acc)
            } else {
                acc
            }
        })
        .collect()
}

fn bounds_of(p: &[Iv]) -> (Vec<f64>, Vec<f64>) {
    (
        p.iter().map(|x| x.lo).collect(),
        p.iter().map(|x| x.hi).collect(),
    )
}

/// Certifies `region` on every segment of the spline. With `touch_order >= 1` the last segment
/// is treated as touching the boundary at its end (see the module docs). With `exact = true`
/// no verdict is Unknown.
pub fn certify_region(
    view: &SplineView<'_>,
    region: &Region,
    touch_order: usize,
    exact: bool,
) -> Result<Vec<RegionVerdict>> {
    if view.n_axes() < 3 {
        return Err(Error::Shape {
            arg: "coeffs",
            detail: format!("needs at least 3 axes (x, y, z), got {}", view.n_axes()),
        });
    }
    region.validate()?;
    let deg = region.degree(view.n_coeffs());
    if deg > MAX_DEGREE {
        return Err(Error::Invalid {
            arg: "coeffs",
            detail: format!(
                "the region needs a degree-{deg} polynomial; at most {MAX_DEGREE} is supported"
            ),
        });
    }
    if touch_order > deg {
        return Err(Error::Invalid {
            arg: "touch_order",
            detail: format!("{touch_order} exceeds the polynomial degree {deg}"),
        });
    }
    let knots = view.knots();
    let n_seg = view.n_segments();
    let mut out = Vec::with_capacity(n_seg);
    for seg in 0..n_seg {
        let (t0, t1) = (knots[seg], knots[seg + 1]);
        let touching = touch_order > 0 && seg + 1 == n_seg;
        let f = region.poly::<Iv>(view, seg);
        let (verdict, residual, reflected) = if touching {
            let g = reflect(&f);
            let residual: f64 = g[..touch_order].iter().map(|x| x.hi.max(0.0)).sum();
            let (lo, hi) = bounds_of(&g[touch_order..]);
            (certify_enclosure(&lo, &hi), residual, true)
        } else {
            let (lo, hi) = bounds_of(&f);
            (certify_enclosure(&lo, &hi), 0.0, false)
        };
        let verdict = if verdict == UnitVerdict::Unsure && exact {
            let fe = region.poly::<BigRational>(view, seg);
            let q = if reflected {
                reflect(&fe)[touch_order..].to_vec()
            } else {
                fe
            };
            certify_unit_exact(&exact::int_poly_from_rational(&q), &Budget::UNLIMITED)
        } else {
            verdict
        };
        let certificate = match verdict {
            UnitVerdict::Within => Certificate::Within,
            UnitVerdict::Violated(x) => {
                let u = if reflected { 1.0 - x } else { x };
                Certificate::Violated {
                    t: (t0 + (t1 - t0) * u).clamp(t0, t1),
                }
            }
            UnitVerdict::Unsure => Certificate::Unknown,
        };
        out.push(RegionVerdict {
            certificate,
            residual,
        });
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn one_segment(x: &[f64], y: &[f64], z: &[f64], knots: &[f64]) -> (Vec<f64>, usize) {
        let c = x.len().max(y.len()).max(z.len());
        let mut out = vec![0.0; 4 * c];
        for (ax, p) in [x, y, z].iter().enumerate() {
            out[ax * c..ax * c + p.len()].copy_from_slice(p);
        }
        assert_eq!(knots.len(), 2);
        (out, c)
    }

    fn verdicts(
        coeffs: &[f64],
        c: usize,
        knots: &[f64],
        r: Region,
        k: usize,
    ) -> Vec<RegionVerdict> {
        let view = SplineView::new(coeffs, (knots.len() - 1, 4, c), knots).unwrap();
        certify_region(&view, &r, k, true).unwrap()
    }

    #[test]
    fn reflect_is_the_taylor_shift_to_the_end() {
        let f = [1.0, -2.0, 3.0, 0.5];
        let g = reflect::<BigRational>(&f.iter().map(|&x| exact::rational(x)).collect::<Vec<_>>());
        for j in 0..=10 {
            let w = j as f64 / 10.0;
            let gw: f64 = g
                .iter()
                .enumerate()
                .map(|(k, x)| num_traits::ToPrimitive::to_f64(x).unwrap() * w.powi(k as i32))
                .sum();
            assert!((gw - crate::poly::eval(&f, 1.0 - w)).abs() < 1e-12);
        }
    }

    #[test]
    fn approach_to_a_plane_touching_at_the_end() {
        // z(t) = 1 - t on [0, 1]: above z = 0 until contact at t = 1, moving down at 1 m/s
        let (c, n) = one_segment(&[0.0], &[0.0], &[1.0, -1.0], &[0.0, 1.0]);
        let ground = Region::HalfSpace {
            normal: [0.0, 0.0, 1.0],
            offset: 0.0,
        };
        let v = verdicts(&c, n, &[0.0, 1.0], ground, 1);
        assert_eq!(v[0].certificate, Certificate::Within);
        // rounding level: one ulp widening per interval operation on unit-size coefficients
        assert!(
            v[0].residual > 0.0 && v[0].residual <= 32.0 * f64::EPSILON,
            "residual {}",
            v[0].residual
        );
        // without the touch treatment the closed segment touches zero: violated at the end
        let v = verdicts(&c, n, &[0.0, 1.0], ground, 0);
        assert!(matches!(v[0].certificate, Certificate::Violated { .. }));
    }

    #[test]
    fn a_dip_below_the_plane_before_contact_is_violated() {
        // z(t) = (1 - t)(1 - 3t) = 1 - 4t + 3t^2: below zero on (1/3, 1), contact at t = 1
        let (c, n) = one_segment(&[0.0], &[0.0], &[1.0, -4.0, 3.0], &[0.0, 1.0]);
        let ground = Region::HalfSpace {
            normal: [0.0, 0.0, 1.0],
            offset: 0.0,
        };
        let v = verdicts(&c, n, &[0.0, 1.0], ground, 1);
        match v[0].certificate {
            Certificate::Violated { t } => assert!(t > 1.0 / 3.0 - 1e-9 && t <= 1.0),
            other => panic!("expected violated, got {other:?}"),
        }
    }

    #[test]
    fn sphere_and_speed() {
        // x(t) = 2t on [0, 1]: passes through the unit ball at (1, 0, 0), speed 2
        let (c, n) = one_segment(&[0.0, 2.0], &[0.0], &[0.0], &[0.0, 1.0]);
        let ball = Region::SphereOutside {
            center: [1.0, 0.0, 0.0],
            radius: 0.5,
        };
        assert!(matches!(
            verdicts(&c, n, &[0.0, 1.0], ball, 0)[0].certificate,
            Certificate::Violated { .. }
        ));
        let off = Region::SphereOutside {
            center: [1.0, 1.0, 0.0],
            radius: 0.5,
        };
        assert_eq!(
            verdicts(&c, n, &[0.0, 1.0], off, 0)[0].certificate,
            Certificate::Within
        );
        let fast = Region::SpeedBelow { v_max: 2.5 };
        assert_eq!(
            verdicts(&c, n, &[0.0, 1.0], fast, 0)[0].certificate,
            Certificate::Within
        );
        let slow = Region::SpeedBelow { v_max: 2.0 }; // touching counts as violated
        assert!(matches!(
            verdicts(&c, n, &[0.0, 1.0], slow, 0)[0].certificate,
            Certificate::Violated { .. }
        ));
    }

    #[test]
    fn bad_regions_are_errors() {
        let (c, n) = one_segment(&[0.0, 1.0], &[0.0], &[0.0], &[0.0, 1.0]);
        let view = SplineView::new(&c, (1, 4, n), &[0.0, 1.0]).unwrap();
        let zero = Region::HalfSpace {
            normal: [0.0; 3],
            offset: 0.0,
        };
        assert!(certify_region(&view, &zero, 0, true).is_err());
        let nan = Region::SphereOutside {
            center: [f64::NAN, 0.0, 0.0],
            radius: 1.0,
        };
        assert!(certify_region(&view, &nan, 0, true).is_err());
        let neg = Region::SpeedBelow { v_max: -1.0 };
        assert!(certify_region(&view, &neg, 0, true).is_err());
        let plane = Region::HalfSpace {
            normal: [0.0, 0.0, 1.0],
            offset: 0.0,
        };
        assert!(certify_region(&view, &plane, 5, true).is_err());
    }

    #[test]
    fn fewer_than_three_axes_is_a_shape_error_not_a_panic() {
        let c = [0.0, 1.0, 0.0, 1.0];
        for axes in [1, 2] {
            let view = SplineView::new(&c[..2 * axes], (1, axes, 2), &[0.0, 1.0]).unwrap();
            for r in [
                Region::HalfSpace {
                    normal: [0.0, 0.0, 1.0],
                    offset: 0.0,
                },
                Region::SphereOutside {
                    center: [0.0; 3],
                    radius: 1.0,
                },
                Region::SpeedBelow { v_max: 1.0 },
            ] {
                match certify_region(&view, &r, 0, true) {
                    Err(Error::Shape {
                        arg: "coeffs",
                        detail,
                    }) => {
                        assert!(detail.contains("at least 3 axes"), "{detail}")
                    }
                    other => panic!("expected a shape error on coeffs, got {other:?}"),
                }
            }
        }
    }
}
