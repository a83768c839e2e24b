//! PyO3 wrappers of a QP solution's acceptance checks (`qp_check`).
#![allow(clippy::useless_conversion)]
use numpy::{
    AllowTypeChange, PyArrayLike1, PyArrayLike2, PyReadonlyArray1, PyReadonlyArray2,
    PyUntypedArrayMethods,
};
use pyo3::prelude::*;

use super::common::{columns, kernel_err, row_major, to_py_err};
use crate::error::guarded;
use crate::qp_check;

/// A float array of any layout or dtype (converted to `float64` when it is not): the judges
/// read the planner's arrays as they are, without a conversion call in Python for each.
type F1<'py> = PyArrayLike1<'py, f64, AllowTypeChange>;
/// A float matrix of any layout or dtype.
type F2<'py> = PyArrayLike2<'py, f64, AllowTypeChange>;

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
