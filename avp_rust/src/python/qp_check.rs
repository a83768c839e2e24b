//! PyO3 wrappers of a QP solution's acceptance checks (`qp_check`).
#![allow(clippy::useless_conversion)]
use numpy::{PyReadonlyArray1, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;

use super::common::{columns, kernel_err, row_major, to_py_err, F1, F2};
use crate::error::guarded;
use crate::qp_check;

/// `vector` (named `arg`) has one entry per row of `m` (named `matrix`).
fn one_per_row(
    arg: &'static str,
    len: usize,
    matrix: &str,
    m: &PyReadonlyArray2<'_, f64>,
) -> PyResult<()> {
    let rows = m.shape()[0];
    if len == rows {
        Ok(())
    } else {
        Err(kernel_err(
            arg,
            format!("wrong shape: expected {rows} entries, one per row of {matrix}, got {len}"),
        ))
    }
}

/// Two-sided rows `lower <= g z <= upper` on `n` variables: `g` with `n` columns, one bound of
/// each side per row (the rows both kernels check).
fn two_sided_rows(
    g: &PyReadonlyArray2<'_, f64>,
    lower: &PyReadonlyArray1<'_, f64>,
    upper: &PyReadonlyArray1<'_, f64>,
    n: usize,
) -> PyResult<()> {
    columns("g", g, n)?;
    one_per_row("lower", lower.len(), "g", g)?;
    one_per_row("upper", upper.len(), "g", g)
}

/// Largest relative violation at `c` of `a c = b` and `lower <= g c <= upper` (0 at least;
/// NaN when a residual is NaN). The arrays are read by their values, of any layout and float
/// dtype (the planner's, without a conversion in Python).
#[pyfunction(name = "max_violation")]
fn max_violation_py(
    c: F1<'_>,
    a: F2<'_>,
    b: F1<'_>,
    g: F2<'_>,
    lower: F1<'_>,
    upper: F1<'_>,
) -> PyResult<f64> {
    let n = c.len();
    columns("a", &a, n)?;
    one_per_row("b", b.len(), "a", &a)?;
    two_sided_rows(&g, &lower, &upper, n)?;
    let (cs, a_s, bs) = (row_major(&c), row_major(&a), row_major(&b));
    let (gs, lo, hi) = (row_major(&g), row_major(&lower), row_major(&upper));
    guarded(|| qp_check::max_violation(&cs, &a_s, &bs, &gs, &lo, &hi)).map_err(to_py_err)
}

/// `(dual residual, duality gap)` of `min 1/2 x^T h x + q^T x` s.t. `lower <= g x <= upper` at
/// `x` with signed multipliers `lam`; arrays of any layout and float dtype.
#[pyfunction(name = "kkt_residuals")]
#[allow(clippy::too_many_arguments)]
fn kkt_residuals_py(
    h: F2<'_>,
    q: F1<'_>,
    g: F2<'_>,
    x: F1<'_>,
    lam: F1<'_>,
    lower: F1<'_>,
    upper: F1<'_>,
) -> PyResult<(f64, f64)> {
    let n = x.len();
    if h.shape() != [n, n] {
        return Err(kernel_err(
            "h",
            format!(
                "wrong shape: expected ({n}, {n}) for len(x) = {n}, got {:?}",
                h.shape()
            ),
        ));
    }
    one_per_row("lam", lam.len(), "g", &g)?;
    two_sided_rows(&g, &lower, &upper, n)?;
    let (hs, qs, gs, xs) = (row_major(&h), row_major(&q), row_major(&g), row_major(&x));
    let (ls, lo, hi) = (row_major(&lam), row_major(&lower), row_major(&upper));
    guarded(|| qp_check::kkt_residuals(&hs, &qs, &gs, &xs, &ls, &lo, &hi)).map_err(to_py_err)
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(max_violation_py, m)?)?;
    m.add_function(wrap_pyfunction!(kkt_residuals_py, m)?)?;
    Ok(())
}
