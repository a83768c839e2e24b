//! Polynomials in ascending powers: Horner evaluation of a value or any derivative.

/// Falling factorial `k (k-1) ... (k-r+1)` as f64 (1 when `r == 0`, 0 when `r > k`).
#[inline]
pub fn falling_factorial(k: usize, r: usize) -> f64 {
    if r > k {
        return 0.0;
    }
    let mut out = 1.0;
    for i in 0..r {
        out *= (k - i) as f64;
    }
    out
}

/// Value of `sum_k c[k] x^k` by Horner's rule.
#[inline]
pub fn eval(coeffs: &[f64], x: f64) -> f64 {
    coeffs.iter().rev().fold(0.0, |acc, &c| acc * x + c)
}

/// Value of the `order`-th derivative of `sum_k c[k] x^k` at `x`, by Horner's rule on the
/// differentiated coefficients `c[k] k!/(k-order)!` (no allocation).
#[inline]
pub fn eval_derivative(coeffs: &[f64], order: usize, x: f64) -> f64 {
    let n = coeffs.len();
    if order >= n {
        return 0.0;
    }
    let mut acc = 0.0;
    for k in (order..n).rev() {
        acc = acc * x + coeffs[k] * falling_factorial(k, order);
    }
    acc
}

/// Coefficients of the `order`-th derivative (ascending powers, length `max(n - order, 1)`).
pub fn derivative(coeffs: &[f64], order: usize) -> Vec<f64> {
    let n = coeffs.len();
    if order >= n {
        return vec![0.0];
    }
    (order..n)
        .map(|k| coeffs[k] * falling_factorial(k, order))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn horner_matches_power_sum() {
        let c = [1.0, -2.0, 0.5, 3.0];
        for &x in &[-1.5f64, 0.0, 0.3, 2.0] {
            let direct: f64 = c
                .iter()
                .enumerate()
                .map(|(k, ck)| ck * x.powi(k as i32))
                .sum();
            assert!((eval(&c, x) - direct).abs() < 1e-12);
        }
    }

    #[test]
    fn derivative_coefficients_and_direct_evaluation_agree() {
        let c = [0.2, 1.0, -3.0, 0.7, 2.5, -1.1];
        for order in 0..8 {
            let d = derivative(&c, order);
            for &x in &[-0.7, 0.0, 0.4, 1.3] {
                assert!((eval(&d, x) - eval_derivative(&c, order, x)).abs() < 1e-10);
            }
        }
        let d1 = derivative(&c, 1);
        for (got, want) in d1.iter().zip([1.0, -6.0, 2.1, 10.0, -5.5]) {
            assert!((got - want).abs() < 1e-12);
        }
    }

    #[test]
    fn falling_factorial_values() {
        assert_eq!(falling_factorial(7, 0), 1.0);
        assert_eq!(falling_factorial(7, 4), 840.0);
        assert_eq!(falling_factorial(3, 4), 0.0);
    }
}
