//! A certified bound on the roll of the attitude construction (13), the assumption behind the
//! body-rate certificate (Sec. V-C, assumption (25)).
//!
//! The construction `b2_des = [-sin ψ, cos ψ, 0]`, `b1 = (b2_des × b3)/‖·‖`, `b2 = b3 × b1` is
//! `R_WB = Rz(ψ) Ry(θ) Rx(φ)` with `cos φ >= 0`, and `sin φ = -b2_des · b3`, so
//!
//! `sin² φ < S` on a segment  ⇔  `G(t) = (b2_des(ψ(t)) · f(t))² − S ‖f(t)‖² < 0` there
//!
//! (with `f = a + g e3`; `G < 0` also proves `‖f‖ > 0`). `G` is not a polynomial (`ψ` enters
//! through `sin`, `cos`), so the segment is cut into pieces. On a piece with a reference yaw
//! `ψ_m` and `Δ >= max |ψ(t) − ψ_m|` (a rigorous Bernstein bound of the yaw polynomial minus
//! `ψ_m`), the unit vector `c(ψ) = b2_des(ψ)` moves by at most `Δ` (it is 1-Lipschitz in `ψ`),
//! so with the float vector `c̃ ≈ c(ψ_m)` (error below [`TRIG_EPS`]):
//!
//! `|c(ψ(t)) · f| <= |c̃ · f| + (Δ + ε) ‖f‖`,
//!
//! and `sin² φ < S` follows from the **polynomial** inequality
//! `P(t) = (c̃ · f)² − r² ‖f‖² < 0` with `r = √S − Δ − ε > 0` (rounded down), which the
//! certificate of [`crate::certify`] proves on the piece. Pieces that fail are halved, down to
//! [`MAX_DEPTH`]. A violation `sin² φ > S` is proven by evaluating `sin² φ` at a piece's
//! midpoint in floating point with a relative margin of `1e-9` (far above its rounding error).
use crate::certify::{bernstein_upper, certify_enclosure, unit_enclosure, UnitVerdict};
use crate::interval::{eval_iv, next_down, Iv};

/// `sin²` of the roll levels tried, increasing: `1 − 2^-k`, i.e. 45°, 60°, 69.3°, 75.5°. Each is
/// exact in binary, and so are the body-rate constants it gives (see [`body_rate_constants`]).
pub const ROLL_LEVELS: [f64; 4] = [0.5, 0.75, 0.875, 0.9375];

/// Upper bound on the error of `(-sin ψ, cos ψ)` computed in f64 for `|ψ| < 1e6` (a few ulp).
pub const TRIG_EPS: f64 = 1e-12;

/// Largest number of halvings of a segment (at most `2^MAX_DEPTH` pieces).
pub const MAX_DEPTH: u32 = 9;

/// Relative margin of the floating-point proof of a violation `sin² φ > S`.
const VIOLATION_MARGIN: f64 = 1e-9;

/// `(A, B)` with `‖ω‖² <= A ‖j‖²/‖f‖² + B ψ̇²` when `sin² φ <= S`: `A = (1+S)/(1−S)`,
/// `B = 2/(1−S)` (docs/bounds.md); `(3, 4)`, `(7, 8)`, `(15, 16)`, `(31, 32)` for the levels.
pub fn body_rate_constants(s: f64) -> (f64, f64) {
    ((1.0 + s) / (1.0 - s), 2.0 / (1.0 - s))
}

/// Verdict of `sin² φ < S` on one segment (`u` coordinates).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RollVerdict {
    /// `sin² φ < S` on the whole segment (proven).
    Within,
    /// `sin² φ > S` at `u` (proven up to the floating-point margin).
    Violated(f64),
    /// Neither proven within [`MAX_DEPTH`] halvings.
    Unsure,
}

/// The flat outputs one segment's roll depends on, as interval polynomials in `u in [0, 1]`.
pub struct RollInput<'a> {
    /// `f = a + g e3` per axis (physical derivatives at `t = t_i + T u`).
    pub f: [&'a [Iv]; 3],
    /// The yaw `ψ(t_i + T u)`.
    pub psi: &'a [Iv],
}

fn his(p: &[Iv]) -> Vec<f64> {
    p.iter().map(|x| x.hi).collect()
}

fn sq(p: &[Iv]) -> Vec<Iv> {
    let mut out = vec![Iv::ZERO; 2 * p.len() - 1];
    for (i, x) in p.iter().enumerate() {
        for (j, y) in p.iter().enumerate() {
            out[i + j] = out[i + j].add(x.mul(*y));
        }
    }
    out
}

/// Rigorous upper bound of `max_{u in [a, b]} p(u)` for an interval polynomial (upper ends).
fn max_on(p_hi: &[f64], a: f64, b: f64) -> f64 {
    let (_, hi) = unit_enclosure(p_hi, a, b);
    bernstein_upper(&hi)
}

/// Proves `sin² φ < s` on `[0, 1]` (see the module docs).
pub fn roll_below(input: &RollInput<'_>, s: f64) -> RollVerdict {
    // ‖f‖² once for the whole segment.
    let f2 = input
        .f
        .iter()
        .map(|p| sq(p))
        .fold(vec![Iv::ZERO], |acc, p| {
            let n = acc.len().max(p.len());
            (0..n)
                .map(|k| {
                    acc.get(k)
                        .copied()
                        .unwrap_or(Iv::ZERO)
                        .add(p.get(k).copied().unwrap_or(Iv::ZERO))
                })
                .collect()
        });
    let sqrt_s = next_down(s.sqrt()); // sqrt is correctly rounded: one step down is below √S
    piece(input, &f2, s, sqrt_s, 0.0, 1.0, MAX_DEPTH)
}

fn piece(
    input: &RollInput<'_>,
    f2: &[Iv],
    s: f64,
    sqrt_s: f64,
    a: f64,
    b: f64,
    depth: u32,
) -> RollVerdict {
    let um = 0.5 * (a + b);
    let psi_m = eval_iv(input.psi, um).mid();
    let fm: Vec<f64> = input.f.iter().map(|p| eval_iv(p, um).mid()).collect();
    if !(psi_m.is_finite() && fm.iter().all(|x| x.is_finite())) {
        return RollVerdict::Unsure;
    }
    let (cx, cy) = (-psi_m.sin(), psi_m.cos());
    let dot = cx * fm[0] + cy * fm[1];
    let norm2 = fm[0] * fm[0] + fm[1] * fm[1] + fm[2] * fm[2];
    if dot * dot > s * norm2 * (1.0 + VIOLATION_MARGIN) + f64::MIN_POSITIVE {
        return RollVerdict::Violated(um);
    }
    // Δ >= max |ψ − ψ_m| on [a, b].
    let mut q = input.psi.to_vec();
    q[0] = q[0].sub(Iv::point(psi_m));
    let up = max_on(&his(&q), a, b);
    let neg_lo: Vec<f64> = q.iter().map(|x| -x.lo).collect();
    let down = max_on(&neg_lo, a, b);
    let delta = up.max(down).max(0.0);
    // r = √S − Δ − ε, rounded down.
    let r = next_down(next_down(sqrt_s - delta) - TRIG_EPS);
    if r > 0.0 && r.is_finite() {
        let (icx, icy) = (Iv::point(cx), Iv::point(cy));
        let n = input.f[0].len().max(input.f[1].len());
        let d: Vec<Iv> = (0..n)
            .map(|k| {
                let x = input.f[0].get(k).copied().unwrap_or(Iv::ZERO);
                let y = input.f[1].get(k).copied().unwrap_or(Iv::ZERO);
                icx.mul(x).add(icy.mul(y))
            })
            .collect();
        let d2 = sq(&d);
        let r2 = Iv::point(r).mul(Iv::point(r));
        let m = d2.len().max(f2.len());
        // P = (c̃·f)² − r² ‖f‖²; its upper polynomial bounds P on [0, 1] (u^k >= 0).
        let p_hi: Vec<f64> = (0..m)
            .map(|k| {
                let x = d2.get(k).copied().unwrap_or(Iv::ZERO);
                let y = f2.get(k).copied().unwrap_or(Iv::ZERO);
                x.sub(r2.mul(y)).hi
            })
            .collect();
        let (lo, hi) = unit_enclosure(&p_hi, a, b);
        if certify_enclosure(&lo, &hi) == UnitVerdict::Within {
            return RollVerdict::Within;
        }
    }
    if depth == 0 {
        return RollVerdict::Unsure;
    }
    match piece(input, f2, s, sqrt_s, a, um, depth - 1) {
        RollVerdict::Within => piece(input, f2, s, sqrt_s, um, b, depth - 1),
        other => other,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pts(c: &[f64]) -> Vec<Iv> {
        c.iter().map(|&x| Iv::point(x)).collect()
    }

    fn verdict(fx: &[f64], fy: &[f64], fz: &[f64], psi: &[f64], s: f64) -> RollVerdict {
        let (fx, fy, fz, psi) = (pts(fx), pts(fy), pts(fz), pts(psi));
        roll_below(
            &RollInput {
                f: [&fx, &fy, &fz],
                psi: &psi,
            },
            s,
        )
    }

    #[test]
    fn constant_roll_is_decided_on_both_sides() {
        // yaw 0: b2_des = e2; f = (0, -sin φ, cos φ) g has roll φ exactly.
        for (deg, s, within) in [
            (30.0f64, 0.5, true),
            (44.0, 0.5, true),
            (46.0, 0.5, false),
            (59.0, 0.75, true),
            (61.0, 0.75, false),
        ] {
            let p = deg.to_radians();
            let v = verdict(&[0.0], &[-9.81 * p.sin()], &[9.81 * p.cos()], &[0.0], s);
            assert_eq!(v == RollVerdict::Within, within, "{deg} deg: {v:?}");
            if !within {
                assert!(matches!(v, RollVerdict::Violated(_)), "{deg}: {v:?}");
            }
        }
    }

    #[test]
    fn spinning_yaw_under_a_constant_tilt() {
        // f tilted 40 deg towards +x; yaw turns 3 rad over the segment: the roll
        // sin φ = -b2_des·b3 = sin ψ sin 40° reaches sin 40° (40 deg) at ψ = pi/2.
        let t = 40f64.to_radians();
        let f = [9.81 * t.sin(), 0.0, 9.81 * t.cos()];
        assert_eq!(
            verdict(&[f[0]], &[f[1]], &[f[2]], &[0.0, 3.0], 0.5),
            RollVerdict::Within
        );
        // tilted 50 deg: the roll passes 45 deg
        let t = 50f64.to_radians();
        let f = [9.81 * t.sin(), 0.0, 9.81 * t.cos()];
        assert!(matches!(
            verdict(&[f[0]], &[f[1]], &[f[2]], &[0.0, 3.0], 0.5),
            RollVerdict::Violated(u) if (0.3..0.7).contains(&u)
        ));
    }

    #[test]
    fn free_fall_is_never_within() {
        // f = 0 somewhere: sin φ undefined, G = 0 there.
        let v = verdict(&[0.0], &[0.0], &[-9.81, 19.62], &[0.0], 0.9375);
        assert_ne!(v, RollVerdict::Within);
    }

    #[test]
    fn constants_match_the_levels() {
        let expect = [(3.0, 4.0), (7.0, 8.0), (15.0, 16.0), (31.0, 32.0)];
        for (s, e) in ROLL_LEVELS.iter().zip(expect) {
            assert_eq!(body_rate_constants(*s), e);
        }
    }
}
