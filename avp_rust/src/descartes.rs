//! Exact root exclusion on `(0, 1)` by Bernstein subdivision (Descartes' rule of signs, the
//! Vincent–Collins–Akritas bisection), with a budget.
//!
//! This is the exact fallback of Algorithm 1 (Sec. V-C): given an integer polynomial `p` with
//! `p(0) < 0` and `p(1) < 0`, decide whether `p` has a real root in `(0, 1)` (then `p >= 0`
//! there: a violation, a touching root included) or none (then `p < 0` on `[0, 1]`). It
//! replaces the Sturm chain of [`crate::exact`] in the certificate: no remainder sequence is
//! built for squarefree input, only additions and shifts of big integers.
//!
//! * The Bernstein coefficients `b_j` of `p` on an interval bound the number of roots in the
//!   open interval by their sign variations `V`, with the same parity (Descartes' rule in the
//!   Bernstein basis). `V = 0`: no root; `V` odd: at least one root. Otherwise the interval is
//!   halved by de Casteljau's algorithm, in integers (every level doubles, common powers of two
//!   are removed), and the exact midpoint value is checked on the way.
//! * For a squarefree polynomial the bisection terminates (Vincent's theorem). Squarefreeness
//!   is tested modulo the prime `2^61 - 1` (a nonzero discriminant modulo a prime is nonzero);
//!   only when that test fails is the exact gcd with `p'` computed, by a subresultant
//!   pseudo-remainder sequence (no coefficient gcds), and `p` replaced by `p / gcd(p, p')`,
//!   which has the same roots.
//! * The work is bounded by a [`Budget`]: when it runs out the answer is [`Isolation::Unsure`],
//!   never a guess.
use std::time::{Duration, Instant};

use num_bigint::BigInt;
use num_integer::Integer;
use num_traits::{One, ToPrimitive, Zero};

use crate::exact::{primitive, sign, sign_variations, trim_int as trim, IntPoly};

/// A deadline for the exact path. `Budget::UNLIMITED` never runs out.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Budget {
    deadline: Option<Instant>,
    /// A zero budget runs out at the first check, deterministically (no clock read).
    zero: bool,
}

impl Budget {
    pub const UNLIMITED: Budget = Budget {
        deadline: None,
        zero: false,
    };

    /// A budget of `seconds` from now: `inf` (or NaN) is unlimited, `<= 0` is spent already.
    pub fn seconds(seconds: f64) -> Budget {
        if seconds.is_nan() || seconds == f64::INFINITY {
            return Budget::UNLIMITED;
        }
        if seconds <= 0.0 {
            return Budget {
                deadline: None,
                zero: true,
            };
        }
        let now = Instant::now();
        Budget {
            deadline: Duration::try_from_secs_f64(seconds)
                .ok()
                .and_then(|d| now.checked_add(d)),
            zero: false,
        }
    }

    /// True when the budget has run out.
    #[inline]
    pub fn spent(&self) -> bool {
        self.zero || self.deadline.is_some_and(|d| Instant::now() >= d)
    }
}

/// Outcome of [`root_in_unit`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Isolation {
    /// No real root in `(0, 1)`.
    NoRoot,
    /// A real root in `(0, 1)`; `u` estimates where (a bisection midpoint or the centre of an
    /// interval known to hold a root).
    Root { u: f64 },
    /// The budget ran out (or, never seen in practice, the bisection depth guard was reached).
    Unsure,
}

// ------------------------------------------------------------------ squarefreeness modulo a prime

const PRIME: u64 = (1 << 61) - 1;

#[inline]
fn mulmod(a: u64, b: u64) -> u64 {
    ((a as u128 * b as u128) % PRIME as u128) as u64
}

fn powmod(mut a: u64, mut e: u64) -> u64 {
    let mut r = 1u64;
    while e > 0 {
        if e & 1 == 1 {
            r = mulmod(r, a);
        }
        a = mulmod(a, a);
        e >>= 1;
    }
    r
}

fn reduce(c: &BigInt) -> u64 {
    c.mod_floor(&BigInt::from(PRIME)).to_u64().unwrap_or(0)
}

fn trim_mod(p: &mut Vec<u64>) {
    while p.last() == Some(&0) {
        p.pop();
    }
}

/// Degree of `gcd(a, b)` over GF(PRIME) (`None` when both are zero).
fn gcd_degree_mod(mut a: Vec<u64>, mut b: Vec<u64>) -> Option<usize> {
    trim_mod(&mut a);
    trim_mod(&mut b);
    while !b.is_empty() {
        // a <- a mod b
        let db = b.len() - 1;
        let inv = powmod(b[db], PRIME - 2);
        while a.len() > db {
            let top = a.len() - 1;
            let q = mulmod(a[top], inv);
            for (i, &bc) in b.iter().enumerate() {
                let k = i + top - db;
                a[k] = (a[k] + PRIME - mulmod(q, bc)) % PRIME;
            }
            a.pop();
            trim_mod(&mut a);
        }
        std::mem::swap(&mut a, &mut b);
    }
    a.len().checked_sub(1)
}

/// Sufficient test that `p` (degree >= 1) is squarefree: `gcd(p, p') = 1` modulo `2^61 - 1`
/// with the degree preserved. `false` means "not proven" (then compute the gcd exactly).
pub fn squarefree_mod_prime(p: &[BigInt]) -> bool {
    let n = p.len() - 1;
    let pm: Vec<u64> = p.iter().map(reduce).collect();
    if pm[n] == 0 {
        return false; // the reduction lost the degree: inconclusive
    }
    let dm: Vec<u64> = pm
        .iter()
        .enumerate()
        .skip(1)
        .map(|(k, &c)| mulmod(c, k as u64))
        .collect();
    gcd_degree_mod(pm, dm) == Some(0)
}

// ------------------------------------------------------------------ exact gcd (subresultants)

/// Pseudo-remainder `lc(b)^(deg a - deg b + 1) a mod b` (exact, deg a >= deg b >= 0).
fn prem(a: &[BigInt], b: &[BigInt]) -> IntPoly {
    let db = b.len() - 1;
    let lc = &b[db];
    let mut r: IntPoly = a.to_vec();
    let steps = a.len() - b.len() + 1;
    for s in 0..steps {
        let top = a.len() - 1 - s;
        let t = r[top].clone();
        for x in r[..top].iter_mut() {
            *x *= lc;
        }
        for (i, bc) in b.iter().enumerate().take(db) {
            r[i + top - db] -= &t * bc;
        }
        r.truncate(top); // r[top] is now lc * t - t * lc = 0
    }
    trim(r)
}

/// Primitive `gcd(a, b)` of two nonzero integer polynomials by the subresultant PRS (Collins,
/// Brown–Traub): the divisions by `g h^delta` are exact, so no coefficient gcd is taken until
/// the end. `None` when the budget runs out.
pub fn gcd_subresultant(a: &[BigInt], b: &[BigInt], budget: &Budget) -> Option<IntPoly> {
    let (mut a, mut b) = if a.len() >= b.len() {
        (primitive(a.to_vec()), primitive(b.to_vec()))
    } else {
        (primitive(b.to_vec()), primitive(a.to_vec()))
    };
    let mut g = BigInt::one();
    let mut h = BigInt::one();
    loop {
        if budget.spent() {
            return None;
        }
        let delta = (a.len() - b.len()) as u32;
        let r = prem(&a, &b);
        if r.is_empty() {
            return Some(primitive(b));
        }
        if r.len() == 1 {
            return Some(vec![BigInt::one()]);
        }
        let div = &g * num_traits::pow(h.clone(), delta as usize);
        a = b;
        b = r.into_iter().map(|c| c / &div).collect();
        g = a[a.len() - 1].clone();
        // h <- g^delta / h^(delta - 1)
        h = if delta == 0 {
            h
        } else {
            num_traits::pow(g.clone(), delta as usize) / num_traits::pow(h, delta as usize - 1)
        };
    }
}

/// `a / b` for integer polynomials with `b | a` exactly (both primitive: Gauss's lemma).
fn divide_exact(a: &[BigInt], b: &[BigInt]) -> IntPoly {
    let db = b.len() - 1;
    let mut r: IntPoly = a.to_vec();
    let mut q = vec![BigInt::zero(); a.len() - db];
    for k in (0..q.len()).rev() {
        let t = &r[k + db] / &b[db];
        for (i, bc) in b.iter().enumerate() {
            r[k + i] -= &t * bc;
        }
        q[k] = t;
    }
    primitive(q)
}

// ------------------------------------------------------------------ Bernstein bisection

fn binomial(n: usize, k: usize) -> BigInt {
    let mut r = BigInt::one();
    for i in 0..k {
        r = r * (n - i) / (i + 1);
    }
    r
}

/// Positive multiple of the Bernstein coefficients of `p` on `[0, 1]`, as integers:
/// `(1 + y)^n p(1 / (1 + y)) = sum_j C(n, j) b_j y^(n - j)` (a Taylor shift of the reversed
/// polynomial), then `b_j = (L / C(n, j)) (C(n, j) b_j) / L` with `L = lcm C(n, .)`.
pub fn bernstein_coefficients(p: &[BigInt]) -> IntPoly {
    let n = p.len() - 1;
    // reversed: r_k = p_{n-k}; Taylor shift r(y + 1) in place (Horner-like additions)
    let mut r: IntPoly = p.iter().rev().cloned().collect();
    for i in 0..n {
        for k in (i..n).rev() {
            let (lo, hi) = r.split_at_mut(k + 1);
            lo[k] += &hi[0];
        }
    }
    // r(y + 1) coefficients ascending in y: r[m] = C(n, n - m) b_{n - m}
    let binoms: Vec<BigInt> = (0..=n).map(|j| binomial(n, j)).collect();
    let l = binoms.iter().fold(BigInt::one(), |l, c| l.lcm(c));
    (0..=n).map(|j| &r[n - j] * (&l / &binoms[j])).collect()
}

fn variations(b: &[BigInt]) -> usize {
    sign_variations(b.iter().map(sign))
}

/// Divides every coefficient by the largest common power of two.
fn remove_twos(b: &mut [BigInt]) {
    let tz = b
        .iter()
        .filter_map(|c| c.trailing_zeros())
        .min()
        .unwrap_or(0);
    if tz > 0 {
        for c in b.iter_mut() {
            *c >>= tz as usize; // exact: every coefficient is divisible by 2^tz
        }
    }
}

/// Halves a Bernstein vector at `1/2` by de Casteljau in integers: returns the left and right
/// halves (positive multiples of their Bernstein coefficients) and the sign of the midpoint.
fn split(b: &[BigInt]) -> (IntPoly, IntPoly, i8) {
    let n = b.len() - 1;
    let mut w: IntPoly = b.to_vec();
    let mut left: IntPoly = vec![BigInt::zero(); n + 1];
    let mut right: IntPoly = vec![BigInt::zero(); n + 1];
    left[0] = &w[0] << n;
    right[n] = &w[n] << n;
    for k in 1..=n {
        for i in 0..=n - k {
            let (lo, hi) = w.split_at_mut(i + 1);
            lo[i] += &hi[0];
        }
        // level k holds 2^k times the de Casteljau points; bring both halves to scale 2^n
        left[k] = &w[0] << (n - k);
        right[n - k] = &w[n - k] << (n - k);
    }
    let mid = sign(&w[0]);
    remove_twos(&mut left);
    remove_twos(&mut right);
    (left, right, mid)
}

/// Largest bisection depth (a guard; squarefree input terminates long before it, since the
/// depth needed is about log2 of the inverse root separation).
const MAX_DEPTH: u32 = 4000;

/// Bisection on a squarefree polynomial given by its Bernstein vector on `[0, 1]`. With
/// `same_sign` the vector is a positive multiple of the caller's polynomial, so a positive
/// midpoint value is itself a violation.
fn bisect(b0: IntPoly, same_sign: bool, budget: &Budget) -> Isolation {
    // (coefficients, left end, depth): the interval [lo, lo + 2^-depth] (lo only estimates)
    let mut stack: Vec<(IntPoly, f64, u32)> = vec![(b0, 0.0, 0)];
    while let Some((b, lo, d)) = stack.pop() {
        let v = variations(&b);
        let half = 0.5f64.powi(d as i32 + 1);
        if v == 0 {
            continue;
        }
        if v % 2 == 1 {
            return Isolation::Root { u: lo + half };
        }
        if d >= MAX_DEPTH || budget.spent() {
            return Isolation::Unsure;
        }
        let (l, r, mid) = split(&b);
        if mid == 0 || (same_sign && mid > 0) {
            return Isolation::Root { u: lo + half };
        }
        stack.push((r, lo + half, d + 1));
        stack.push((l, lo, d + 1));
    }
    Isolation::NoRoot
}

/// Whether the integer polynomial `p` (degree >= 1, `p(0) != 0`, `p(1) != 0`) has a real root
/// in `(0, 1)`, exactly, within `budget`.
pub fn root_in_unit(p: &[BigInt], budget: &Budget) -> Isolation {
    let p = primitive(p.to_vec());
    if p.len() <= 1 {
        return Isolation::NoRoot;
    }
    // Cheap exits first: all Bernstein coefficients of one sign.
    let b = bernstein_coefficients(&p);
    let v = variations(&b);
    if v == 0 {
        return Isolation::NoRoot;
    }
    if v % 2 == 1 {
        return Isolation::Root { u: 0.5 };
    }
    if squarefree_mod_prime(&p) {
        return bisect(b, true, budget);
    }
    let dp: IntPoly = p
        .iter()
        .enumerate()
        .skip(1)
        .map(|(k, c)| c * BigInt::from(k))
        .collect();
    let Some(g) = gcd_subresultant(&p, &dp, budget) else {
        return Isolation::Unsure;
    };
    if g.len() <= 1 {
        return bisect(b, true, budget);
    }
    let q = divide_exact(&p, &g);
    if q.len() <= 1 {
        return Isolation::NoRoot;
    }
    bisect(bernstein_coefficients(&q), false, budget)
}

#[cfg(test)]
mod tests {
    use super::*;
    use num_traits::Signed;

    fn ints(v: &[i64]) -> IntPoly {
        v.iter().map(|&x| BigInt::from(x)).collect()
    }

    fn mul(a: &IntPoly, b: &IntPoly) -> IntPoly {
        let mut o = vec![BigInt::zero(); a.len() + b.len() - 1];
        for (i, x) in a.iter().enumerate() {
            for (j, y) in b.iter().enumerate() {
                o[i + j] += x * y;
            }
        }
        o
    }

    #[test]
    fn bernstein_coefficients_of_a_quadratic() {
        // p = -1 + 4u - 4u^2 = -(2u - 1)^2: Bernstein [-1, 1, -1] (times a positive factor)
        let b = bernstein_coefficients(&ints(&[-1, 4, -4]));
        let s: Vec<i8> = b.iter().map(|c| c.signum().to_i8().unwrap()).collect();
        assert_eq!(s, vec![-1, 1, -1]);
    }

    #[test]
    fn squarefree_test_and_gcd() {
        let p = ints(&[-1, 4, -4]); // -(2u - 1)^2
        assert!(!squarefree_mod_prime(&p));
        assert!(squarefree_mod_prime(&ints(&[-2, 4, -4])));
        let dp = ints(&[4, -8]);
        let g = gcd_subresultant(&p, &dp, &Budget::UNLIMITED).unwrap();
        assert_eq!(g.iter().map(|c| c.abs()).collect::<Vec<_>>(), ints(&[1, 2]));
        // gcd((u-1)^2 (u+3) (2u-1), (u-1)(2u-1)^3) = (u-1)(2u-1) up to sign
        let a = mul(
            &mul(&ints(&[-1, 1]), &ints(&[-1, 1])),
            &mul(&ints(&[3, 1]), &ints(&[-1, 2])),
        );
        let b = mul(
            &ints(&[-1, 1]),
            &mul(&ints(&[-1, 2]), &mul(&ints(&[-1, 2]), &ints(&[-1, 2]))),
        );
        let g = gcd_subresultant(&a, &b, &Budget::UNLIMITED).unwrap();
        let want = mul(&ints(&[-1, 1]), &ints(&[-1, 2]));
        assert!(g == want || g.iter().map(|c| -c).collect::<Vec<_>>() == want);
        assert_eq!(divide_exact(&a, &want).len(), 3);
    }

    #[test]
    fn halves_are_the_bernstein_coefficients_of_the_halved_polynomial() {
        // p(u) = 3 - 7u + 2u^2 + 5u^3 - u^4; left half p(x/2), right half p((x + 1)/2)
        let p = ints(&[3, -7, 2, 5, -1]);
        let n = p.len() - 1;
        let left_poly: IntPoly = p.iter().enumerate().map(|(k, c)| c << (n - k)).collect();
        let mut right_poly = left_poly.clone(); // Taylor shift by 1
        for i in 0..n {
            for k in (i..n).rev() {
                let (lo, hi) = right_poly.split_at_mut(k + 1);
                lo[k] += &hi[0];
            }
        }
        let (l, r, mid) = split(&bernstein_coefficients(&p));
        assert_eq!(primitive(l), primitive(bernstein_coefficients(&left_poly)));
        assert_eq!(primitive(r), primitive(bernstein_coefficients(&right_poly)));
        // p(1/2) = 3 - 3.5 + 0.5 + 0.625 - 0.0625 > 0
        assert_eq!(mid, 1);
    }

    #[test]
    fn isolation_verdicts() {
        // touching root at 1/2
        assert!(matches!(
            root_in_unit(&ints(&[-1, 4, -4]), &Budget::UNLIMITED),
            Isolation::Root { .. }
        ));
        // strictly negative
        assert_eq!(
            root_in_unit(&ints(&[-2, 4, -4]), &Budget::UNLIMITED),
            Isolation::NoRoot
        );
        // two close roots 1/2 +- 2^-20: -(u - 1/2)^2 + 2^-40, times 2^40
        let p = ints(&[1 - (1 << 38), 1 << 40, -(1 << 40)]);
        assert!(matches!(
            root_in_unit(&p, &Budget::UNLIMITED),
            Isolation::Root { .. }
        ));
        // near-tangent from below: -(u - 1/2)^2 - 2^-40
        let q = ints(&[-1 - (1 << 38), 1 << 40, -(1 << 40)]);
        assert_eq!(root_in_unit(&q, &Budget::UNLIMITED), Isolation::NoRoot);
        // a spent budget never guesses
        assert_eq!(root_in_unit(&q, &Budget::seconds(0.0)), Isolation::Unsure);
    }
}
