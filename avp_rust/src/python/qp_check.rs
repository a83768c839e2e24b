//! PyO3 wrappers of a QP solution's acceptance checks (`qp_check`).
#![allow(clippy::useless_conversion)]
use numpy::{PyReadonlyArray1, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;

use super::common::{columns, contiguous, kernel_err, to_py_err};
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

/// The row-major slices of two-sided rows `lower <= g z <= upper` on `n` variables: `g` with
/// `n` columns, one bound of each side per row (the rows both kernels check).
fn two_sided_rows<'a>(
    g: &'a PyReadonlyArray2<'_, f64>,
    lower: &'a PyReadonlyArray1<'_, f64>,
    upper: &'a PyReadonlyArray1<'_, f64>,
    n: usize,
) -> PyResult<(&'a [f64], &'a [f64], &'a [f64])> {
    columns("g", g, n)?;
    one_per_row("lower", lower.len(), "g", g)?;
    one_per_row("upper", upper.len(), "g", g)?;
    Ok((
        contiguous("g", g)?,
        contiguous("lower", lower)?,
        contiguous("upper", upper)?,
    ))
}

/// Largest relative violation at `c` of `a c = b` and `lower <= g c <= upper` (0 at least;
/// NaN when a residual is NaN).
#[pyfunction(name = "max_violation")]
fn max_violation_py(
    c: PyReadonlyArray1<'_, f64>,
    a: PyReadonlyArray2<'_, f64>,
    b: PyReadonlyArray1<'_, f64>,
    g: PyReadonlyArray2<'_, f64>,
    lower: PyReadonlyArray1<'_, f64>,
    upper: PyReadonlyArray1<'_, f64>,
) -> PyResult<f64> {
    let cs = contiguous("c", &c)?;
    columns("a", &a, cs.len())?;
    one_per_row("b", b.len(), "a", &a)?;
    let (gs, lo, hi) = two_sided_rows(&g, &lower, &upper, cs.len())?;
    let (a_s, bs) = (contiguous("a", &a)?, contiguous("b", &b)?);
    guarded(|| qp_check::max_violation(cs, a_s, bs, gs, lo, hi)).map_err(to_py_err)
}

/// `(dual residual, duality gap)` of `min 1/2 x^T h x + q^T x` s.t. `lower <= g x <= upper` at
/// `x` with signed multipliers `lam`.
#[pyfunction(name = "kkt_residuals")]
#[allow(clippy::too_many_arguments)]
fn kkt_residuals_py(
    h: PyReadonlyArray2<'_, f64>,
    q: PyReadonlyArray1<'_, f64>,
    g: PyReadonlyArray2<'_, f64>,
    x: PyReadonlyArray1<'_, f64>,
    lam: PyReadonlyArray1<'_, f64>,
    lower: PyReadonlyArray1<'_, f64>,
    upper: PyReadonlyArray1<'_, f64>,
) -> PyResult<(f64, f64)> {
    let xs = contiguous("x", &x)?;
    if h.shape() != [xs.len(), xs.len()] {
        return Err(kernel_err(
            "h",
            format!(
                "wrong shape: expected ({n}, {n}) for len(x) = {n}, got {:?}",
                h.shape(),
                n = xs.len()
            ),
        ));
    }
    one_per_row("lam", lam.len(), "g", &g)?;
    let (gs, lo, hi) = two_sided_rows(&g, &lower, &upper, xs.len())?;
    let (hs, qs, ls) = (
        contiguous("h", &h)?,
        contiguous("q", &q)?,
        contiguous("lam", &lam)?,
    );
    guarded(|| qp_check::kkt_residuals(hs, qs, gs, xs, ls, lo, hi)).map_err(to_py_err)
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(max_violation_py, m)?)?;
    m.add_function(wrap_pyfunction!(kkt_residuals_py, m)?)?;
    Ok(())
}
