//! PyO3 wrapper of the rows appended to an eliminated QP (`crate::reduce`).
#![allow(clippy::useless_conversion)]
use numpy::{
    IntoPyArray, PyArray1, PyArray2, PyReadonlyArray1, PyReadonlyArray2, PyUntypedArrayMethods,
};
use pyo3::prelude::*;

use super::common::{columns, contiguous, matrix, to_py_err};
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
/// (or `None`). Returns the seven arrays, new; `m_rows` is `None` without a factor or when a new
/// row is not finite.
#[pyfunction(name = "append_rows")]
#[allow(clippy::too_many_arguments)]
fn append_rows_py<'py>(
    py: Python<'py>,
    g: PyReadonlyArray2<'py, f64>,
    lower: PyReadonlyArray1<'py, f64>,
    upper: PyReadonlyArray1<'py, f64>,
    g_z: PyReadonlyArray2<'py, f64>,
    lower_z: PyReadonlyArray1<'py, f64>,
    upper_z: PyReadonlyArray1<'py, f64>,
    m_rows: Option<PyReadonlyArray2<'py, f64>>,
    blocks: Vec<(
        PyReadonlyArray2<'py, f64>,
        PyReadonlyArray1<'py, f64>,
        PyReadonlyArray1<'py, f64>,
    )>,
    z_basis: PyReadonlyArray2<'py, f64>,
    c_p: PyReadonlyArray1<'py, f64>,
    r: Option<PyReadonlyArray2<'py, f64>>,
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
    let mut views = Vec::with_capacity(blocks.len());
    for (b, lo, hi) in &blocks {
        views.push(RowBlock {
            matrix: contiguous("blocks.matrix", b)?,
            lower: contiguous("blocks.lower", lo)?,
            upper: contiguous("blocks.upper", hi)?,
        });
    }
    let rows = QpRows::from_parts(
        contiguous("g", &g)?,
        contiguous("lower", &lower)?,
        contiguous("upper", &upper)?,
        contiguous("g_z", &g_z)?,
        contiguous("lower_z", &lower_z)?,
        contiguous("upper_z", &upper_z)?,
        m_rows
            .as_ref()
            .map(|a| contiguous("m_rows", a))
            .transpose()?,
    );
    let elim = Elimination {
        z: contiguous("z_basis", &z_basis)?,
        c_p: contiguous("c_p", &c_p)?,
        r: r.as_ref().map(|a| contiguous("r", a)).transpose()?,
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
