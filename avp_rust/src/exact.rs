//! Exact fallback: Sturm sequences over the integers.
//!
//! Every finite f64 is a dyadic rational `m 2^e`, so a polynomial with f64 coefficients (and
//! f64 interval ends) converts **exactly** to an integer polynomial times a positive power of
//! two. The Sturm sequence is then a primitive pseudo-remainder sequence with **positive**
//! multipliers (`|lc|^k`, positive contents), which keeps the sign pattern of the true
//! `S_{i+1} = -rem(S_{i-1}, S_i)` sequence (paper eq. (17)) while the integers stay small.
//! Signs at rational points come from homogenised Horner evaluation, so nothing rounds.
//!
//! The certificate ([`certify_unit_budgeted`]) no longer builds a Sturm chain: it decides the
//! inside of `[0, 1]` by exact Bernstein subdivision ([`crate::descartes`]), under a budget.
//! The chain stays for root counting ([`count_roots`]) and as [`certify_unit_sturm`].
use num_bigint::BigInt;
use num_integer::Integer;
use num_rational::BigRational;
use num_traits::{One, Signed, ToPrimitive, Zero};

use crate::descartes::{self, Budget, Isolation};

/// Integer polynomial, ascending powers, no trailing zeros (the zero polynomial is empty).
pub type IntPoly = Vec<BigInt>;

/// `x = mantissa * 2^exponent` exactly (x finite).
pub fn decode(x: f64) -> (i64, i32) {
    let bits = x.to_bits();
    let sign: i64 = if bits >> 63 == 0 { 1 } else { -1 };
    let exp_bits = ((bits >> 52) & 0x7ff) as i32;
    let frac = (bits & ((1u64 << 52) - 1)) as i64;
    if exp_bits == 0 {
        (sign * frac, -1074)
    } else {
        (sign * (frac | (1i64 << 52)), exp_bits - 1075)
    }
}

/// The exact rational value of a finite f64.
pub fn rational(x: f64) -> BigRational {
    let (m, e) = decode(x);
    if e >= 0 {
        BigRational::from_integer(BigInt::from(m) << (e as usize))
    } else {
        BigRational::new(BigInt::from(m), BigInt::one() << ((-e) as usize))
    }
}

pub(crate) fn trim_int(mut p: IntPoly) -> IntPoly {
    while p.last().is_some_and(|c| c.is_zero()) {
        p.pop();
    }
    p
}

/// Divides by the (positive) gcd of the coefficients.
pub(crate) fn primitive(p: IntPoly) -> IntPoly {
    let p = trim_int(p);
    let g = p.iter().fold(BigInt::zero(), |g, c| g.gcd(c));
    if g.is_zero() || g.is_one() {
        return p;
    }
    p.into_iter().map(|c| c / &g).collect()
}

/// A positive multiple of `sum coeffs[k] x^k` with integer coefficients (exact).
pub fn int_poly_from_f64(coeffs: &[f64]) -> IntPoly {
    let dec: Vec<(i64, i32)> = coeffs.iter().map(|&c| decode(c)).collect();
    let emin = dec
        .iter()
        .filter(|d| d.0 != 0)
        .map(|d| d.1)
        .min()
        .unwrap_or(0);
    primitive(
        dec.iter()
            .map(|&(m, e)| BigInt::from(m) << ((e - emin) as usize))
            .collect(),
    )
}

/// A positive multiple of a rational polynomial with integer coefficients (exact).
pub fn int_poly_from_rational(coeffs: &[BigRational]) -> IntPoly {
    let l = coeffs.iter().fold(BigInt::one(), |l, c| l.lcm(c.denom()));
    primitive(
        coeffs
            .iter()
            .map(|c| c.numer() * (&l / c.denom()))
            .collect(),
    )
}

/// `den^n p(num / den)` (same sign as `p(num/den)` for `den > 0`), by homogenised Horner.
pub fn eval_hom(p: &[BigInt], num: &BigInt, den: &BigInt) -> BigInt {
    let Some((top, rest)) = p.split_last() else {
        return BigInt::zero();
    };
    let mut acc = top.clone();
    let mut dpow = BigInt::one();
    for c in rest.iter().rev() {
        dpow *= den;
        acc = acc * num + c * &dpow;
    }
    acc
}

/// `p / (den x - num)` for a root `num/den` in lowest terms (exact by Gauss's lemma).
fn deflate(p: &[BigInt], num: &BigInt, den: &BigInt) -> IntPoly {
    let n = p.len() - 1;
    let mut r = vec![BigInt::zero(); n];
    r[n - 1] = &p[n] / den;
    for k in (1..n).rev() {
        r[k - 1] = (&p[k] + num * &r[k]) / den;
    }
    primitive(r)
}

fn derivative(p: &[BigInt]) -> IntPoly {
    primitive(
        p.iter()
            .enumerate()
            .skip(1)
            .map(|(k, c)| c * BigInt::from(k))
            .collect(),
    )
}

/// `c (A - Q B)` with some `c > 0`: pseudo-remainder with positive multipliers.
fn prem_positive(a: &[BigInt], b: &[BigInt]) -> IntPoly {
    let d = b.len() - 1;
    let lc = &b[d];
    let alc = lc.abs();
    let slc = lc.signum();
    let mut r: IntPoly = a.to_vec();
    while r.len() > d {
        let top = r.len() - 1;
        let t = &r[top] * &slc;
        for x in r.iter_mut() {
            *x *= &alc;
        }
        for (i, bc) in b.iter().enumerate() {
            r[i + top - d] -= &t * bc;
        }
        r.pop(); // the top coefficient is now exactly zero
        r = trim_int(r);
    }
    r
}

/// Sturm sequence `p, p', -rem, ...` up to the gcd of `p` and `p'` (each element a positive
/// multiple of the classical one). `p` must have degree >= 1.
pub fn sturm_chain(p: &[BigInt]) -> Vec<IntPoly> {
    let mut chain = vec![primitive(p.to_vec()), derivative(p)];
    loop {
        let n = chain.len();
        if chain[n - 1].len() <= 1 {
            break;
        }
        let r = prem_positive(&chain[n - 2], &chain[n - 1]);
        if r.is_empty() {
            break;
        }
        chain.push(primitive(r.into_iter().map(|c| -c).collect()));
    }
    chain
}

/// Sign of a big integer as `-1`, `0` or `1`.
pub(crate) fn sign(c: &BigInt) -> i8 {
    if c.is_positive() {
        1
    } else if c.is_negative() {
        -1
    } else {
        0
    }
}

/// Sign variations of a sequence of signs, zeros skipped (Sturm's and Descartes' rules).
pub(crate) fn sign_variations(signs: impl IntoIterator<Item = i8>) -> usize {
    let mut count = 0;
    let mut last = 0i8;
    for s in signs {
        if s != 0 {
            if last != 0 && s != last {
                count += 1;
            }
            last = s;
        }
    }
    count
}

fn variations(chain: &[IntPoly], num: &BigInt, den: &BigInt) -> usize {
    sign_variations(chain.iter().map(|s| sign(&eval_hom(s, num, den))))
}

/// Number of distinct real roots of `p` in the closed interval `[a, b]`, exactly. Roots at the
/// ends are counted and divided out first (Sturm's theorem needs ends that are not roots).
pub fn count_roots(p: &[BigInt], a: &BigRational, b: &BigRational) -> usize {
    let mut p = trim_int(p.to_vec());
    if p.is_empty() || a > b {
        return 0;
    }
    if a == b {
        return usize::from(eval_hom(&p, a.numer(), a.denom()).is_zero());
    }
    let mut extra = 0;
    for e in [a, b] {
        if p.len() > 1 && eval_hom(&p, e.numer(), e.denom()).is_zero() {
            extra += 1;
            while p.len() > 1 && eval_hom(&p, e.numer(), e.denom()).is_zero() {
                p = deflate(&p, e.numer(), e.denom());
            }
        }
    }
    if p.len() <= 1 {
        return extra;
    }
    let chain = sturm_chain(&p);
    let va = variations(&chain, a.numer(), a.denom());
    let vb = variations(&chain, b.numer(), b.denom());
    extra + va.saturating_sub(vb)
}

/// Exact distinct-root count of an f64 polynomial on `[a, b]` (f64 ends, exact conversion).
pub fn count_roots_f64(coeffs: &[f64], a: f64, b: f64) -> usize {
    count_roots(&int_poly_from_f64(coeffs), &rational(a), &rational(b))
}

/// A positive multiple of `G(u) = F(a + (b - a) u)` with integer coefficients, exactly.
pub fn unit_shift(coeffs: &[f64], a: f64, b: f64) -> IntPoly {
    // Common dyadic scale: a = A 2^s, h = b - a = H 2^s (exact rationals).
    let ra = rational(a);
    let rh = rational(b) - &ra;
    let l = ra.denom().lcm(rh.denom());
    let big_a = ra.numer() * (&l / ra.denom());
    let big_h = rh.numer() * (&l / rh.denom());
    // x = (A + H u) / l ; l^n F(x) = sum C_k (A + H u)^k l^(n-k)
    let c = int_poly_from_f64(coeffs);
    let Some((top, rest)) = c.split_last() else {
        return Vec::new();
    };
    let mut acc: IntPoly = vec![top.clone()];
    let mut lpow = BigInt::one();
    for ck in rest.iter().rev() {
        lpow *= &l;
        // acc = acc * (A + H u) + ck * l^(n-k)
        let mut next = vec![BigInt::zero(); acc.len() + 1];
        for (i, x) in acc.iter().enumerate() {
            next[i] += x * &big_a;
            next[i + 1] += x * &big_h;
        }
        next[0] += ck * &lpow;
        acc = next;
    }
    primitive(acc)
}

/// Exact verdict of `p(u) < 0` on `[0, 1]`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum UnitExact {
    /// `p(u) < 0` for every `u` in `[0, 1]`.
    Within,
    /// `p(0) >= 0`.
    ViolatedAt0,
    /// `p(1) >= 0`.
    ViolatedAt1,
    /// `p` has a root inside `(0, 1)`, so `p >= 0` there (a touching root counts).
    ViolatedInside,
}

/// The ends of Algorithm 1 (line 2) exactly: `Err(verdict)` when an end decides, `Ok(p)` (the
/// trimmed polynomial, degree >= 1, negative at both ends) when the inside must be checked.
fn unit_ends(p: &[BigInt]) -> std::result::Result<IntPoly, UnitExact> {
    let p = trim_int(p.to_vec());
    let Some(p0) = p.first() else {
        return Err(UnitExact::ViolatedAt0); // F == 0
    };
    if !p0.is_negative() {
        return Err(UnitExact::ViolatedAt0);
    }
    let p1: BigInt = p.iter().sum();
    if !p1.is_negative() {
        return Err(UnitExact::ViolatedAt1);
    }
    if p.len() == 1 {
        return Err(UnitExact::Within);
    }
    Ok(p)
}

/// Decides `p(u) < 0 for all u in [0, 1]` exactly (Algorithm 1 with `F = p`), by Bernstein
/// subdivision ([`crate::descartes`]); `None` when `budget` runs out first.
pub fn certify_unit_budgeted(p: &[BigInt], budget: &Budget) -> Option<UnitExact> {
    let p = match unit_ends(p) {
        Ok(p) => p,
        Err(v) => return Some(v),
    };
    match descartes::root_in_unit(&p, budget) {
        Isolation::NoRoot => Some(UnitExact::Within),
        Isolation::Root { .. } => Some(UnitExact::ViolatedInside),
        Isolation::Unsure if *budget == Budget::UNLIMITED => Some(certify_unit_sturm(&p)),
        Isolation::Unsure => None,
    }
}

/// Decides `p(u) < 0 for all u in [0, 1]` exactly, without a budget (never undecided).
pub fn certify_unit(p: &[BigInt]) -> UnitExact {
    certify_unit_budgeted(p, &Budget::UNLIMITED).unwrap_or_else(|| certify_unit_sturm(p))
}

/// The previous exact path, kept for comparisons: Algorithm 1 with a Sturm chain of primitive
/// pseudo-remainders (a coefficient gcd per element).
pub fn certify_unit_sturm(p: &[BigInt]) -> UnitExact {
    let p = match unit_ends(p) {
        Ok(p) => p,
        Err(v) => return v,
    };
    let chain = sturm_chain(&p);
    let (zero, one) = (BigInt::zero(), BigInt::one());
    let v0 = variations(&chain, &zero, &one);
    let v1 = variations(&chain, &one, &one);
    if v0 > v1 {
        UnitExact::ViolatedInside
    } else {
        UnitExact::Within
    }
}

/// Nearest f64 coefficients of a positive multiple of `p` (scaled by a power of two so the
/// largest is about one), for locating a violation by sampling.
pub fn to_f64_scaled(p: &[BigInt]) -> Vec<f64> {
    let bits = p.iter().map(|c| c.bits()).max().unwrap_or(0);
    let shift = bits.saturating_sub(60);
    p.iter()
        .map(|c| {
            let v = (c >> shift).to_f64().unwrap_or(0.0);
            v / 2f64.powi((bits - shift) as i32) // bits - shift <= 60
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ints(v: &[i64]) -> IntPoly {
        v.iter().map(|&x| BigInt::from(x)).collect()
    }

    #[test]
    fn decode_is_exact() {
        for &x in &[0.1, -3.75, 1e-310, 5e300, 0.0, -0.0, 1.0] {
            let (m, e) = decode(x);
            assert_eq!(
                m as f64 * 2f64.powi(e.max(-1000)) * 2f64.powi((e - e.max(-1000)).min(0)),
                x
            );
            assert_eq!(rational(x).to_f64().unwrap(), x);
        }
        assert_eq!(rational(0.5), BigRational::new(1.into(), 2.into()));
    }

    #[test]
    fn counts_distinct_roots_with_multiplicity_and_ends() {
        // (x - 1)^3 (x + 2)^2 (x - 1/2)
        let p = ints(&[-1, 3, -3, 1]);
        let q = ints(&[4, 4, 1]);
        let r = ints(&[-1, 2]);
        let mul = |a: &IntPoly, b: &IntPoly| {
            let mut o = vec![BigInt::zero(); a.len() + b.len() - 1];
            for (i, x) in a.iter().enumerate() {
                for (j, y) in b.iter().enumerate() {
                    o[i + j] += x * y;
                }
            }
            o
        };
        let f = mul(&mul(&p, &q), &r);
        let rq = |n: i64, d: i64| BigRational::new(n.into(), d.into());
        assert_eq!(count_roots(&f, &rq(-3, 1), &rq(3, 1)), 3);
        assert_eq!(count_roots(&f, &rq(1, 2), &rq(1, 1)), 2);
        assert_eq!(count_roots(&f, &rq(-2, 1), &rq(1, 2)), 2);
        assert_eq!(count_roots(&f, &rq(0, 1), &rq(1, 3)), 0);
        assert_eq!(count_roots(&f, &rq(1, 1), &rq(1, 1)), 1);
    }

    #[test]
    fn unit_shift_matches_substitution() {
        // F(x) = x^2 - 2 on [1, 2]: G(u) = (1 + u)^2 - 2 = -1 + 2u + u^2
        let g = unit_shift(&[-2.0, 0.0, 1.0], 1.0, 2.0);
        assert_eq!(g, ints(&[-1, 2, 1]));
        assert_eq!(certify_unit(&g), UnitExact::ViolatedAt1);
        assert_eq!(certify_unit(&ints(&[-1, 0, 1])), UnitExact::ViolatedAt1);
        // -(u - 1/2)^2 touches zero inside
        assert_eq!(certify_unit(&ints(&[-1, 4, -4])), UnitExact::ViolatedInside);
        assert_eq!(certify_unit(&ints(&[-2, 4, -4])), UnitExact::Within);
        assert_eq!(certify_unit(&[]), UnitExact::ViolatedAt0);
    }
}
