//! Outward-rounded interval arithmetic on binary64: [`Iv`], [`next_up`] / [`next_down`] and
//! interval Horner evaluation. Every operation rounds to nearest and then widens by one ulp on each
//! side, so a result contains the exact result of the operation on any members of the operands;
//! the fast paths of the certificates (`sturm`, `certify`, `bounds`, `regions`, `roll`) build on it.

/// Smallest f64 strictly greater than `x` (`x` itself for NaN and +inf). Same as the
/// `f64::next_up` of Rust 1.86, written out because the crate supports Rust 1.85.
#[inline]
pub fn next_up(x: f64) -> f64 {
    if x.is_nan() || x == f64::INFINITY {
        return x;
    }
    if x == 0.0 {
        return f64::from_bits(1);
    }
    let bits = x.to_bits();
    if x > 0.0 {
        f64::from_bits(bits + 1)
    } else {
        f64::from_bits(bits - 1)
    }
}

/// Largest f64 strictly smaller than `x` (`x` itself for NaN and -inf).
#[inline]
pub fn next_down(x: f64) -> f64 {
    -next_up(-x)
}

/// A closed interval `[lo, hi]` of reals with outward rounding: every operation rounds to
/// nearest and then widens by one ulp on each side, so the result contains the exact result of
/// the operation on any members of the operands. A NaN anywhere makes the interval the whole
/// line. Signs are read with [`Iv::sign`], which refuses to guess.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Iv {
    pub lo: f64,
    pub hi: f64,
}

// Named methods (not operator traits) keep every rounding step explicit at the call site.
#[allow(clippy::should_implement_trait)]
impl Iv {
    pub const ENTIRE: Iv = Iv {
        lo: f64::NEG_INFINITY,
        hi: f64::INFINITY,
    };
    pub const ZERO: Iv = Iv { lo: 0.0, hi: 0.0 };

    #[inline]
    pub fn point(x: f64) -> Iv {
        Iv { lo: x, hi: x }
    }

    #[inline]
    fn widen(lo: f64, hi: f64) -> Iv {
        if lo.is_nan() || hi.is_nan() {
            Iv::ENTIRE
        } else {
            Iv {
                lo: next_down(lo),
                hi: next_up(hi),
            }
        }
    }

    #[inline]
    pub fn add(self, o: Iv) -> Iv {
        Iv::widen(self.lo + o.lo, self.hi + o.hi)
    }

    #[inline]
    pub fn neg(self) -> Iv {
        Iv {
            lo: -self.hi,
            hi: -self.lo,
        }
    }

    #[inline]
    pub fn sub(self, o: Iv) -> Iv {
        self.add(o.neg())
    }

    #[inline]
    pub fn mul(self, o: Iv) -> Iv {
        let (a, b, c, d) = (
            self.lo * o.lo,
            self.lo * o.hi,
            self.hi * o.lo,
            self.hi * o.hi,
        );
        if (a + b + c + d).is_nan() {
            // 0 * inf or inf - inf: give up precision, keep soundness.
            return Iv::ENTIRE;
        }
        Iv::widen(a.min(b).min(c).min(d), a.max(b).max(c).max(d))
    }

    /// Product with an exact scalar (no widening when `x` is 0 or 1).
    #[inline]
    pub fn mul_f64(self, x: f64) -> Iv {
        if x == 1.0 {
            return self;
        }
        if x == 0.0 && self.lo.is_finite() && self.hi.is_finite() {
            return Iv::ZERO;
        }
        self.mul(Iv::point(x))
    }

    /// Quotient; the whole line when the divisor contains zero.
    #[inline]
    pub fn div(self, o: Iv) -> Iv {
        if !(o.lo > 0.0 || o.hi < 0.0) {
            return Iv::ENTIRE;
        }
        let (a, b, c, d) = (
            self.lo / o.lo,
            self.lo / o.hi,
            self.hi / o.lo,
            self.hi / o.hi,
        );
        if (a + b + c + d).is_nan() {
            return Iv::ENTIRE;
        }
        Iv::widen(a.min(b).min(c).min(d), a.max(b).max(c).max(d))
    }

    /// `Some(1)`, `Some(-1)` or `Some(0)` when the sign of every member is the same (`[0, 0]`
    /// is certainly zero), `None` otherwise (also for NaN).
    #[inline]
    pub fn sign(self) -> Option<i8> {
        if self.lo > 0.0 {
            Some(1)
        } else if self.hi < 0.0 {
            Some(-1)
        } else if self.lo == 0.0 && self.hi == 0.0 {
            Some(0)
        } else {
            None
        }
    }

    #[inline]
    pub fn mid(self) -> f64 {
        if self.lo.is_finite() && self.hi.is_finite() {
            0.5 * self.lo + 0.5 * self.hi
        } else {
            f64::NAN
        }
    }

    #[inline]
    pub fn mag(self) -> f64 {
        self.lo.abs().max(self.hi.abs())
    }
}

/// Enclosure of `p(x)` by Horner's rule in interval arithmetic.
#[inline]
pub fn eval_iv(p: &[Iv], x: f64) -> Iv {
    if x == 0.0 {
        return p.first().copied().unwrap_or(Iv::ZERO);
    }
    p.iter()
        .rev()
        .fold(Iv::ZERO, |acc, &c| acc.mul_f64(x).add(c))
}
