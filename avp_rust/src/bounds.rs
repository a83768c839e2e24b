//! Actuator bounds of a flat-output spline as polynomials, certified per segment
//! (Sec. V-C, Algorithm 1, Appendix B).
//!
//! The spline has 4 axes `(x, y, z, yaw)`; everything is **mass-normalised**: `f = a + g e3`
//! (m/s^2), `j` the jerk (m/s^3), `psidot` the yaw rate (rad/s). Per segment `i`, with
//! `T = t_{i+1} - t_i` and `t = t_i + T u`, each checked quantity is a polynomial `F(u)` that
//! must be negative on `u in [0, 1]`:
//!
//! | bound | `F` | paper |
//! |---|---|---|
//! | [`BoundKind::ThrustMax`] | `‖f‖² − f_max²` | (15) |
//! | [`BoundKind::ThrustMin`] | `f_min² − ‖f‖²` | (15) |
//! | [`BoundKind::ThrustRate`] | `‖j‖² − ḟ_max²` (since `ḟ = b3·j`, `|ḟ| ≤ ‖j‖`) | (19)-(21) |
//! | [`BoundKind::TiltRate`] | `‖j‖² − w_max² ‖f‖²` (`ω1²+ω2² ≤ ‖j‖²/‖f‖²`) | (22) |
//! | [`BoundKind::BodyRate`] | `A‖j‖² + (Bψ̇² − w_max²) ‖f‖²` (`‖ω‖² ≤ A‖j‖²/‖f‖² + Bψ̇²` while `sin²φ ≤ S`) | (24)-(29) |
//!
//! The body-rate inequality needs a bound on the roll `φ` of the attitude construction (13):
//! it is **certified** per segment by [`crate::roll`] for the levels `S` of
//! [`crate::roll::ROLL_LEVELS`] (45° .. 75.5°), and the smallest proven level gives `(A, B)`
//! (`(3, 4)` at the paper's 45°, assumption (25)). A segment whose roll is proven above the
//! largest level is Violated; one whose roll is not decided is Unknown.
//!
//! The polynomials are built twice with the same generic code ([`Scalar`]): in outward-rounded
//! interval arithmetic for the fast path (so `lo_k <= F_k <= hi_k` holds for the exact
//! coefficients `F_k`), and, only when the fast path is unsure, in exact rational arithmetic.
//! Derivations and the error analysis are in `docs/bounds.md`.
use num_bigint::BigInt;
use num_rational::BigRational;
use num_traits::Zero;

use crate::certify::{certify_enclosure, certify_unit_exact, to_time, Certificate, UnitVerdict};
use crate::descartes::Budget;
use crate::error::{Error, Result};
use crate::exact;
use crate::interval::Iv;
use crate::poly::falling_factorial;
use crate::roll::{self, RollInput, RollVerdict};
use crate::spline::SplineView;
use crate::sturm::MAX_DEGREE;

/// The checked bounds, in the order of the batch output rows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum BoundKind {
    /// `‖a + g e3‖ < f_max`, eq. (15).
    ThrustMax = 0,
    /// `‖a + g e3‖ > f_min`, eq. (15).
    ThrustMin = 1,
    /// `‖j‖ < fdot_max`, a sufficient condition for the thrust rate, eq. (21).
    ThrustRate = 2,
    /// `‖j‖ < w_max ‖a + g e3‖`, sufficient for `ω1² + ω2² < w_max²`, eq. (22).
    TiltRate = 3,
    /// `A‖j‖² + Bψ̇²‖f‖² < w_max²‖f‖²` and a certified roll bound `sin²φ < S`, together
    /// sufficient for `‖ω‖ < w_max`, (24)-(29); `(A, B) = (3, 4)` for `S = 1/2` (25).
    BodyRate = 4,
}

/// Every bound, in row order.
pub const ALL_BOUNDS: [BoundKind; 5] = [
    BoundKind::ThrustMax,
    BoundKind::ThrustMin,
    BoundKind::ThrustRate,
    BoundKind::TiltRate,
    BoundKind::BodyRate,
];

/// Mass-normalised limits; `+inf` means "not checked".
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    /// Minimum `‖f‖` in m/s^2 (`tau_min / m`).
    pub thrust_min: f64,
    /// Maximum `‖f‖` in m/s^2 (`tau_max / m`).
    pub thrust_max: f64,
    /// Maximum `‖j‖` in m/s^3 (`taudot_max / m`).
    pub thrust_rate_max: f64,
    /// Maximum `sqrt(ω1² + ω2²)` in rad/s.
    pub tilt_rate_max: f64,
    /// Maximum `‖ω‖` in rad/s.
    pub body_rate_max: f64,
}

impl Limits {
    /// From `[thrust_max, thrust_min, thrust_rate_max, tilt_rate_max, body_rate_max]` (the row
    /// order of [`ALL_BOUNDS`]).
    /// Each value must be `>= 0` or `+inf` (not checked).
    pub fn from_slice(v: &[f64]) -> Result<Self> {
        if v.len() != ALL_BOUNDS.len() {
            return Err(Error::Shape {
                arg: "limits",
                detail: format!("expected 5 values, got {}", v.len()),
            });
        }
        if v.iter().any(|x| x.is_nan()) {
            return Err(Error::NonFinite { arg: "limits" });
        }
        if let Some(bad) = v.iter().find(|&&x| x < 0.0) {
            return Err(Error::Invalid {
                arg: "limits",
                detail: format!("limit {bad} is negative; use +inf to skip a bound"),
            });
        }
        Ok(Self {
            thrust_max: v[0],
            thrust_min: v[1],
            thrust_rate_max: v[2],
            tilt_rate_max: v[3],
            body_rate_max: v[4],
        })
    }

    /// The limit of one bound (`+inf` = not checked).
    pub fn get(&self, kind: BoundKind) -> f64 {
        match kind {
            BoundKind::ThrustMax => self.thrust_max,
            BoundKind::ThrustMin => self.thrust_min,
            BoundKind::ThrustRate => self.thrust_rate_max,
            BoundKind::TiltRate => self.tilt_rate_max,
            BoundKind::BodyRate => self.body_rate_max,
        }
    }

    pub fn checked(&self, kind: BoundKind) -> bool {
        self.get(kind).is_finite()
    }
}

/// Verdict for one bound on one segment; `certificate` is `None` when the bound is not checked.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoundVerdict {
    pub bound: BoundKind,
    pub segment: usize,
    pub certificate: Option<Certificate>,
}

/// Coefficient arithmetic shared by the interval (fast) and rational (exact) builds.
pub trait Scalar: Clone {
    fn from_f64(x: f64) -> Self;
    fn zero() -> Self;
    fn add(&self, o: &Self) -> Self;
    fn sub(&self, o: &Self) -> Self;
    fn mul(&self, o: &Self) -> Self;
}

impl Scalar for Iv {
    fn from_f64(x: f64) -> Self {
        Iv::point(x)
    }
    fn zero() -> Self {
        Iv::ZERO
    }
    fn add(&self, o: &Self) -> Self {
        Iv::add(*self, *o)
    }
    fn sub(&self, o: &Self) -> Self {
        Iv::sub(*self, *o)
    }
    fn mul(&self, o: &Self) -> Self {
        Iv::mul(*self, *o)
    }
}

impl Scalar for BigRational {
    fn from_f64(x: f64) -> Self {
        exact::rational(x)
    }
    fn zero() -> Self {
        BigRational::from_integer(BigInt::zero())
    }
    fn add(&self, o: &Self) -> Self {
        self + o
    }
    fn sub(&self, o: &Self) -> Self {
        self - o
    }
    fn mul(&self, o: &Self) -> Self {
        self * o
    }
}

pub(crate) fn padd<S: Scalar>(a: &[S], b: &[S]) -> Vec<S> {
    let n = a.len().max(b.len());
    (0..n)
        .map(|k| match (a.get(k), b.get(k)) {
            (Some(x), Some(y)) => x.add(y),
            (Some(x), None) | (None, Some(x)) => x.clone(),
            (None, None) => S::zero(),
        })
        .collect()
}

pub(crate) fn pmul<S: Scalar>(a: &[S], b: &[S]) -> Vec<S> {
    if a.is_empty() || b.is_empty() {
        return vec![S::zero()];
    }
    let mut out = vec![S::zero(); a.len() + b.len() - 1];
    for (i, x) in a.iter().enumerate() {
        for (j, y) in b.iter().enumerate() {
            out[i + j] = out[i + j].add(&x.mul(y));
        }
    }
    out
}

pub(crate) fn pscale<S: Scalar>(a: &[S], s: &S) -> Vec<S> {
    a.iter().map(|x| x.mul(s)).collect()
}

/// `c - p` for a constant `c`.
pub(crate) fn const_minus<S: Scalar>(c: &S, p: &[S]) -> Vec<S> {
    let mut out: Vec<S> = p.iter().map(|x| S::zero().sub(x)).collect();
    out[0] = c.add(&out[0]);
    out
}

/// `p - c` for a constant `c`.
pub(crate) fn minus_const<S: Scalar>(p: &[S], c: &S) -> Vec<S> {
    let mut out = p.to_vec();
    out[0] = out[0].sub(c);
    out
}

/// Squared norm `sum_i v_i²` of a vector of polynomials.
pub(crate) fn sq_norm<S: Scalar>(v: &[Vec<S>]) -> Vec<S> {
    v.iter()
        .fold(vec![S::zero()], |acc, p| padd(&acc, &pmul(p, p)))
}

/// Coefficients in `u` of the `order`-th time derivative of `sum c_k tau^k` at `tau = T u`:
/// `d^r p/dtau^r (T u) = sum_m (m+r)!/m! c_{m+r} T^m u^m` (the physical derivative, no `1/T`).
pub(crate) fn scaled_derivative<S: Scalar>(c: &[f64], order: usize, h: &S) -> Vec<S> {
    if order >= c.len() {
        return vec![S::zero()];
    }
    let mut hp = S::from_f64(1.0);
    let mut out = Vec::with_capacity(c.len() - order);
    for m in 0..c.len() - order {
        let k = m + order;
        out.push(
            S::from_f64(falling_factorial(k, order))
                .mul(&S::from_f64(c[k]))
                .mul(&hp),
        );
        hp = hp.mul(h);
    }
    out
}

/// The squared norms one segment needs, as polynomials in `u`: `‖a + g e3‖²`, `‖j‖²`, `ψ̇²`.
struct SegmentPolys<S> {
    f2: Vec<S>,
    j2: Vec<S>,
    psid2: Vec<S>,
    /// `f = a + g e3` per axis and the yaw, for the roll certificate.
    f: Vec<Vec<S>>,
    psi: Vec<S>,
}

fn segment_polys<S: Scalar>(view: &SplineView<'_>, seg: usize, g: f64) -> SegmentPolys<S> {
    let knots = view.knots();
    let h = S::from_f64(knots[seg + 1]).sub(&S::from_f64(knots[seg]));
    let mut acc: Vec<Vec<S>> = (0..3)
        .map(|ax| scaled_derivative(view.poly(seg, ax), 2, &h))
        .collect();
    acc[2][0] = acc[2][0].add(&S::from_f64(g)); // f = a + g e3
    let jerk: Vec<Vec<S>> = (0..3)
        .map(|ax| scaled_derivative(view.poly(seg, ax), 3, &h))
        .collect();
    let psid = scaled_derivative(view.poly(seg, 3), 1, &h);
    SegmentPolys {
        f2: sq_norm(&acc),
        j2: sq_norm(&jerk),
        psid2: pmul(&psid, &psid),
        psi: scaled_derivative(view.poly(seg, 3), 0, &h),
        f: acc,
    }
}

/// The checked polynomial `F` of one bound (negative everywhere iff the bound holds); for the
/// body rate, at the roll level `sin²φ <= roll_s2` (see [`roll::body_rate_constants`]).
fn bound_poly<S: Scalar>(kind: BoundKind, p: &SegmentPolys<S>, limit: f64, roll_s2: f64) -> Vec<S> {
    let l = S::from_f64(limit);
    let l2 = l.mul(&l);
    match kind {
        // (15): ‖f‖² - f_max²
        BoundKind::ThrustMax => minus_const(&p.f2, &l2),
        // (15): f_min² - ‖f‖²
        BoundKind::ThrustMin => const_minus(&l2, &p.f2),
        // (21): ‖j‖² - fdot_max²
        BoundKind::ThrustRate => minus_const(&p.j2, &l2),
        // (22): ‖j‖² - w² ‖f‖²
        BoundKind::TiltRate => padd(&p.j2, &pscale(&p.f2, &S::zero().sub(&l2))),
        // (24)-(29), sin²φ <= S: A ‖j‖² + (B ψ̇² - w²) ‖f‖² (A = 3, B = 4 at |φ| <= pi/4)
        BoundKind::BodyRate => {
            let (a, b) = roll::body_rate_constants(roll_s2);
            let factor = minus_const(&pscale(&p.psid2, &S::from_f64(b)), &l2);
            padd(&pscale(&p.j2, &S::from_f64(a)), &pmul(&factor, &p.f2))
        }
    }
}

/// Degree of the checked polynomial of `kind` for `n_coeffs` spline coefficients per axis.
pub fn bound_degree(kind: BoundKind, n_coeffs: usize) -> usize {
    let d = |order: usize| n_coeffs.saturating_sub(order + 1);
    match kind {
        BoundKind::ThrustMax | BoundKind::ThrustMin => 2 * d(2),
        BoundKind::ThrustRate => 2 * d(3),
        BoundKind::TiltRate => 2 * d(3).max(d(2)),
        BoundKind::BodyRate => (2 * d(3)).max(2 * d(1) + 2 * d(2)),
    }
}

/// The checked polynomial of one bound on one segment, in `u` on `[0, 1]`, as an interval
/// enclosure `(lo, hi)` of the exact coefficients (the body rate at the 45° roll level).
pub fn bound_enclosure(
    view: &SplineView<'_>,
    seg: usize,
    kind: BoundKind,
    limit: f64,
    g: f64,
) -> (Vec<f64>, Vec<f64>) {
    let polys = segment_polys::<Iv>(view, seg, g);
    let f = bound_poly(kind, &polys, limit, roll::ROLL_LEVELS[0]);
    (
        f.iter().map(|x| x.lo).collect(),
        f.iter().map(|x| x.hi).collect(),
    )
}

fn validate(view: &SplineView<'_>, limits: &Limits, g: f64) -> Result<()> {
    if view.n_axes() != 4 {
        return Err(Error::Shape {
            arg: "coeffs",
            detail: format!("expected 4 axes (x, y, z, yaw), got {}", view.n_axes()),
        });
    }
    if !g.is_finite() {
        return Err(Error::NonFinite { arg: "g" });
    }
    for kind in ALL_BOUNDS {
        let deg = bound_degree(kind, view.n_coeffs());
        if limits.checked(kind) && deg > MAX_DEGREE {
            return Err(Error::Invalid {
                arg: "coeffs",
                detail: format!(
                    "{kind:?} needs a degree-{deg} polynomial for {} coefficients per axis; at most {MAX_DEGREE} is supported",
                    view.n_coeffs()
                ),
            });
        }
    }
    Ok(())
}

/// The smallest level `S` of [`roll::ROLL_LEVELS`] with `sin²φ < S` proven on the segment, or
/// the body-rate verdict when there is none: Violated where the roll is proven above the
/// largest level, Unsure (reported Unknown) when it is not decided.
fn certified_roll_level(p: &SegmentPolys<Iv>) -> std::result::Result<f64, UnitVerdict> {
    let input = RollInput {
        f: [&p.f[0], &p.f[1], &p.f[2]],
        psi: &p.psi,
    };
    let mut last = UnitVerdict::Unsure;
    for s2 in roll::ROLL_LEVELS {
        match roll::roll_below(&input, s2) {
            RollVerdict::Within => return Ok(s2),
            RollVerdict::Violated(u) => last = UnitVerdict::Violated(u),
            RollVerdict::Unsure => last = UnitVerdict::Unsure,
        }
    }
    Err(last)
}

/// Certifies every checked bound on every segment (Algorithm 1 per bound and segment).
///
/// Output order is bound-major (`ALL_BOUNDS` x segments). With `exact = true` every checked
/// polynomial verdict is Within or Violated: undecided fast-path cases are rebuilt and
/// decided in exact rational arithmetic. The body rate's roll certificate has no exact
/// fallback: a segment whose roll is neither proven below 75.5° nor above it is Unknown. Violation times are absolute (`t_i + T u`).
pub fn certify_spline(
    view: &SplineView<'_>,
    limits: &Limits,
    g: f64,
    exact: bool,
) -> Result<Vec<BoundVerdict>> {
    certify_spline_budgeted(view, limits, g, exact, &Budget::UNLIMITED)
}

/// [`certify_spline`] whose exact fallbacks share one `budget` (for the whole call): cells the
/// fast path leaves undecided when the budget has run out are Unknown, never guessed.
pub fn certify_spline_budgeted(
    view: &SplineView<'_>,
    limits: &Limits,
    g: f64,
    exact: bool,
    budget: &Budget,
) -> Result<Vec<BoundVerdict>> {
    validate(view, limits, g)?;
    let n_seg = view.n_segments();
    let mut verdicts: Vec<BoundVerdict> = Vec::with_capacity(ALL_BOUNDS.len() * n_seg);
    for kind in ALL_BOUNDS {
        for segment in 0..n_seg {
            verdicts.push(BoundVerdict {
                bound: kind,
                segment,
                certificate: None,
            });
        }
    }
    if !ALL_BOUNDS.iter().any(|&k| limits.checked(k)) {
        return Ok(verdicts);
    }
    let knots = view.knots();
    for seg in 0..n_seg {
        let fast = segment_polys::<Iv>(view, seg, g);
        let mut exact_polys: Option<SegmentPolys<BigRational>> = None;
        let (t0, t1) = (knots[seg], knots[seg + 1]);
        for (row, &kind) in ALL_BOUNDS.iter().enumerate() {
            if !limits.checked(kind) {
                continue;
            }
            let limit = limits.get(kind);
            let mut roll_s2 = roll::ROLL_LEVELS[0];
            if kind == BoundKind::BodyRate {
                match certified_roll_level(&fast) {
                    Ok(s2) => roll_s2 = s2,
                    Err(v) => {
                        verdicts[row * n_seg + seg].certificate = Some(to_time(v, t0, t1));
                        continue;
                    }
                }
            }
            let f = bound_poly(kind, &fast, limit, roll_s2);
            let lo: Vec<f64> = f.iter().map(|x| x.lo).collect();
            let hi: Vec<f64> = f.iter().map(|x| x.hi).collect();
            let mut v = certify_enclosure(&lo, &hi);
            if v == UnitVerdict::Unsure && exact && !budget.spent() {
                let ep =
                    exact_polys.get_or_insert_with(|| segment_polys::<BigRational>(view, seg, g));
                let fe = bound_poly(kind, ep, limit, roll_s2);
                v = certify_unit_exact(&exact::int_poly_from_rational(&fe), budget);
            }
            verdicts[row * n_seg + seg].certificate = Some(to_time(v, t0, t1));
        }
    }
    Ok(verdicts)
}

#[cfg(test)]
mod tests {
    use super::*;

    const INF: f64 = f64::INFINITY;

    /// One segment on [t0, t0 + T] with the given per-axis coefficients (padded to C).
    fn spline(axes: [&[f64]; 4], c: usize) -> Vec<f64> {
        let mut out = vec![0.0; 4 * c];
        for (ax, p) in axes.iter().enumerate() {
            out[ax * c..ax * c + p.len()].copy_from_slice(p);
        }
        out
    }

    fn limits(v: [f64; 5]) -> Limits {
        Limits::from_slice(&v).unwrap()
    }

    fn verdict(c: &[f64], knots: &[f64], l: Limits, kind: BoundKind) -> Certificate {
        let view = SplineView::new(
            c,
            (knots.len() - 1, 4, c.len() / 4 / (knots.len() - 1)),
            knots,
        )
        .unwrap();
        let v = certify_spline(&view, &l, 9.81, true).unwrap();
        v.iter()
            .find(|b| b.bound == kind)
            .unwrap()
            .certificate
            .unwrap()
    }

    #[test]
    fn hover_thrust_is_g() {
        // hovering: a = 0, so ‖f‖ = g exactly
        let c = spline([&[1.0], &[2.0], &[3.0], &[0.0]], 8);
        let k = [0.0, 1.5];
        assert_eq!(
            verdict(
                &c,
                &k,
                limits([9.82, 0.0, INF, INF, INF]),
                BoundKind::ThrustMax
            ),
            Certificate::Within
        );
        // the limit exactly at g: touching is a violation
        assert!(matches!(
            verdict(
                &c,
                &k,
                limits([9.81, 0.0, INF, INF, INF]),
                BoundKind::ThrustMax
            ),
            Certificate::Violated { .. }
        ));
        assert!(matches!(
            verdict(
                &c,
                &k,
                limits([INF, 9.81, INF, INF, INF]),
                BoundKind::ThrustMin
            ),
            Certificate::Violated { .. }
        ));
        assert_eq!(
            verdict(
                &c,
                &k,
                limits([INF, 9.80, INF, INF, INF]),
                BoundKind::ThrustMin
            ),
            Certificate::Within
        );
    }

    #[test]
    fn acceleration_ramp_with_known_maximum() {
        // z(t) = t^3: a_z = 6 t, ‖f‖ = 9.81 + 6 t on [2, 3] (local tau in [0, 1]: a_z = 12 + 6 tau + ...)
        // use the local polynomial of (2 + tau)^3 = 8 + 12 tau + 6 tau^2 + tau^3
        let c = spline([&[0.0], &[0.0], &[8.0, 12.0, 6.0, 1.0], &[0.0]], 6);
        let k = [2.0, 3.0];
        // max ‖f‖ = 9.81 + 18 = 27.81 at t = 3
        assert_eq!(
            verdict(
                &c,
                &k,
                limits([27.82, 0.0, INF, INF, INF]),
                BoundKind::ThrustMax
            ),
            Certificate::Within
        );
        match verdict(
            &c,
            &k,
            limits([27.0, 0.0, INF, INF, INF]),
            BoundKind::ThrustMax,
        ) {
            Certificate::Violated { t } => assert_eq!(t, 3.0),
            other => panic!("{other:?}"),
        }
        // jerk is 6 everywhere: rate bound 6 is touched -> violated, 6.001 within
        assert!(matches!(
            verdict(
                &c,
                &k,
                limits([INF, 0.0, 6.0, INF, INF]),
                BoundKind::ThrustRate
            ),
            Certificate::Violated { .. }
        ));
        assert_eq!(
            verdict(
                &c,
                &k,
                limits([INF, 0.0, 6.001, INF, INF]),
                BoundKind::ThrustRate
            ),
            Certificate::Within
        );
        // tilt: ‖j‖/‖f‖ = 6 / (9.81 + 6 t) <= 6 / 21.81 = 0.2751 on [2, 3]
        assert_eq!(
            verdict(
                &c,
                &k,
                limits([INF, 0.0, INF, 0.276, INF]),
                BoundKind::TiltRate
            ),
            Certificate::Within
        );
        assert!(
            matches!(verdict(&c, &k, limits([INF, 0.0, INF, 0.27, INF]), BoundKind::TiltRate), Certificate::Violated { t } if (t - 2.0).abs() < 0.05)
        );
    }

    #[test]
    fn body_rate_includes_yaw_rate() {
        // hover with constant yaw rate 0.5 rad/s: bound 3*0 + 4*0.25 = 1 -> |w| bound 1 rad/s
        let c = spline([&[0.0], &[0.0], &[0.0], &[0.0, 0.5]], 8);
        let k = [0.0, 2.0];
        assert_eq!(
            verdict(
                &c,
                &k,
                limits([INF, 0.0, INF, INF, 1.001]),
                BoundKind::BodyRate
            ),
            Certificate::Within
        );
        assert!(matches!(
            verdict(
                &c,
                &k,
                limits([INF, 0.0, INF, INF, 1.0]),
                BoundKind::BodyRate
            ),
            Certificate::Violated { .. }
        ));
    }

    #[test]
    fn body_rate_at_large_roll_uses_the_certified_level() {
        // |f| = 15 tilted 75 deg towards -y, yaw turning at 1 rad/s around 0: roll ~75 deg and
        // the true |w| = w3 ~ 1/cos(75 deg) = 3.86 rad/s. The 45-degree inequality
        // (3, 4) would accept w = 2.5; the certified level (31, 32) needs w^2 > 32.
        let th = 75f64.to_radians();
        let ay = -15.0 * th.sin();
        let az = 15.0 * th.cos() - 9.81;
        let c = spline(
            [
                &[0.0],
                &[0.0, 0.0, 0.5 * ay],
                &[0.0, 0.0, 0.5 * az],
                &[-0.1, 1.0],
            ],
            8,
        );
        let k = [0.0, 0.2];
        let body = |w: f64| verdict(&c, &k, limits([INF, 1.0, INF, INF, w]), BoundKind::BodyRate);
        assert!(matches!(body(2.5), Certificate::Violated { .. }));
        assert!(matches!(body(5.6), Certificate::Violated { .. }));
        assert_eq!(body(5.7), Certificate::Within); // sqrt(32) = 5.657
                                                    // 80 deg: beyond the top level, whatever the limit
        let th = 80f64.to_radians();
        let c = spline(
            [
                &[0.0],
                &[0.0, 0.0, -7.5 * th.sin()],
                &[0.0, 0.0, 7.5 * th.cos() - 4.905],
                &[0.0, 0.1],
            ],
            8,
        );
        assert!(matches!(
            verdict(
                &c,
                &k,
                limits([INF, 1.0, INF, INF, 1e3]),
                BoundKind::BodyRate
            ),
            Certificate::Violated { .. }
        ));
    }

    #[test]
    fn not_checked_and_errors() {
        let c = spline([&[0.0], &[0.0], &[0.0], &[0.0]], 8);
        let view = SplineView::new(&c, (1, 4, 8), &[0.0, 1.0]).unwrap();
        let v = certify_spline(&view, &limits([INF; 5]), 9.81, true).unwrap();
        assert_eq!(v.len(), 5);
        assert!(v.iter().all(|b| b.certificate.is_none()));
        assert!(Limits::from_slice(&[1.0; 4]).is_err());
        assert!(Limits::from_slice(&[1.0, -1.0, 1.0, 1.0, 1.0]).is_err());
        assert!(Limits::from_slice(&[1.0, f64::NAN, 1.0, 1.0, 1.0]).is_err());
        assert!(certify_spline(&view, &limits([INF; 5]), f64::NAN, true).is_err());
        let c13 = vec![0.0; 4 * 13];
        let view = SplineView::new(&c13, (1, 4, 13), &[0.0, 1.0]).unwrap();
        assert!(certify_spline(&view, &limits([INF, 1.0, INF, INF, 5.0]), 9.81, true).is_err());
        assert!(certify_spline(&view, &limits([30.0, 1.0, INF, INF, INF]), 9.81, true).is_ok());
        let c3 = vec![0.0; 3 * 8];
        let view = SplineView::new(&c3, (1, 3, 8), &[0.0, 1.0]).unwrap();
        assert!(certify_spline(&view, &limits([30.0, 1.0, INF, INF, INF]), 9.81, true).is_err());
    }
}
