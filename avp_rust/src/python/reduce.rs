//! PyO3 wrapper of the rows appended to an eliminated QP (`crate::reduce`).
#![allow(clippy::useless_conversion)]
use numpy::{IntoPyArray, PyArray1, PyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;

use super::common::{columns, matrix, row_major, to_py_err, F1, F2};
use crate::error::guarded;
use crate::reduce::{append_rows, Elimination, QpRows, RowBlock};

type Rows<'py> = (
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<f64>>,
    Option<Bound<'py, PyArray2<f64>>>,
);

/// The QP's rows `(g, lower, upper)` in the coefficients, `(g_z, lower_z, upper_z)` in `z` and
/// `m_rows` in `u = R z` (or `None`), with the rows of `blocks` (`(matrix, lower, upper)`
/// triples) appended: `c = c_p + z_basis z`, `r` the reduced Hessian's upper Cholesky factor
/// (or `None`). Any layout (a Fortran-ordered factor) and float dtype is read by its values.
/// Returns the seven arrays, new; `m_rows` is `None` without a factor or when a new row is not
/// finite.
#[pyfunction(name = "append_rows")]
#[allow(clippy::too_many_arguments)]
fn append_rows_py<'py>(
    py: Python<'py>,
    g: F2<'py>,
    lower: F1<'py>,
    upper: F1<'py>,
    g_z: F2<'py>,
    lower_z: F1<'py>,
    upper_z: F1<'py>,
    m_rows: Option<F2<'py>>,
    blocks: Vec<(F2<'py>, F1<'py>, F1<'py>)>,
    z_basis: F2<'py>,
    c_p: F1<'py>,
    r: Option<F2<'py>>,
) -> PyResult<Rows<'py>> {
    let (n, m) = (z_basis.shape()[0], z_basis.shape()[1]);
    columns("g", &g, n)?;
    columns("g_z", &g_z, m)?;
    if let Some(mr) = &m_rows {
        columns("m_rows", mr, m)?;
    }
    if let Some(rr) = &r {
        columns("r", rr, m)?;
    }
    for (b, _, _) in &blocks {
        columns("blocks.matrix", b, n)?;
    }
    let block_values: Vec<_> = blocks
        .iter()
        .map(|(b, lo, hi)| (row_major(b), row_major(lo), row_major(hi)))
        .collect();
    let views: Vec<RowBlock<'_>> = block_values
        .iter()
        .map(|(b, lo, hi)| RowBlock {
            matrix: b,
            lower: lo,
            upper: hi,
        })
        .collect();
    let m_values = m_rows.as_ref().map(|a| row_major(a));
    let extra = blocks.iter().map(|(_, lo, _)| lo.len()).sum();
    let rows = QpRows::with_room(
        extra,
        (n, m),
        &row_major(&g),
        &row_major(&lower),
        &row_major(&upper),
        &row_major(&g_z),
        &row_major(&lower_z),
        &row_major(&upper_z),
        m_values.as_deref(),
    );
    let (z_values, c_values) = (row_major(&z_basis), row_major(&c_p));
    let r_values = r.as_ref().map(|a| row_major(a));
    let elim = Elimination {
        z: &z_values,
        c_p: &c_values,
        r: r_values.as_deref(),
    };
    let out = guarded(|| append_rows(rows, &views, &elim)).map_err(to_py_err)?;
    let k = out.lower.len();
    let m_out = match out.m_rows {
        Some(v) => Some(matrix(py, k, m, v)?),
        None => None,
    };
    Ok((
        matrix(py, k, n, out.g)?,
        out.lower.into_pyarray(py),
        out.upper.into_pyarray(py),
        matrix(py, k, m, out.g_z)?,
        out.lower_z.into_pyarray(py),
        out.upper_z.into_pyarray(py),
        m_out,
    ))
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(append_rows_py, m)?)?;
    Ok(())
}
