//! PyO3 wrapper of the field-of-view kernel (7): `h` and its gradient.
#![allow(clippy::useless_conversion)]
use numpy::{IntoPyArray, PyArray1, PyArray2, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;

use super::common::{contiguous, kernel_err, to_py_err};
use crate::error::guarded;

/// `h` of the FoV cone (7) and its gradient at `m` points: `x (m, 3)`, `psi (m,)`, `a (m, 3)`,
/// target `s (3,)`, optical axis `axis_B (3,)`. Returns `(h (m,), d_x (m, 3), d_psi (m,),
/// d_a (m, 3), distance (m,))`.
#[pyfunction(name = "fov_gradient")]
#[allow(clippy::type_complexity, clippy::too_many_arguments, non_snake_case)]
fn fov_gradient_py<'py>(
    py: Python<'py>,
    x: PyReadonlyArray2<'py, f64>,
    psi: PyReadonlyArray1<'py, f64>,
    a: PyReadonlyArray2<'py, f64>,
    s: PyReadonlyArray1<'py, f64>,
    axis_B: PyReadonlyArray1<'py, f64>,
    cos_half: f64,
    g: f64,
) -> PyResult<(
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray1<f64>>,
)> {
    let xs = contiguous("x", x.as_slice())?;
    let ps = contiguous("psi", psi.as_slice())?;
    let as_ = contiguous("a", a.as_slice())?;
    let ss = contiguous("s", s.as_slice())?;
    let ds = contiguous("axis_B", axis_B.as_slice())?;
    let pts = guarded(|| crate::fov::fov_gradient(xs, ps, as_, ss, ds, cos_half, g))
        .map_err(to_py_err)?;
    let m = pts.len();
    let h: Vec<f64> = pts.iter().map(|p| p.h).collect();
    let dpsi: Vec<f64> = pts.iter().map(|p| p.d_psi).collect();
    let dist: Vec<f64> = pts.iter().map(|p| p.distance).collect();
    let dx: Vec<f64> = pts.iter().flat_map(|p| p.d_x).collect();
    let da: Vec<f64> = pts.iter().flat_map(|p| p.d_a).collect();
    let shape = |v: Vec<f64>| {
        numpy::ndarray::Array2::from_shape_vec((m, 3), v)
            .map_err(|e| kernel_err("kernel", format!("internal shape error: {e}")))
    };
    Ok((
        h.into_pyarray(py),
        shape(dx)?.into_pyarray(py),
        dpsi.into_pyarray(py),
        shape(da)?.into_pyarray(py),
        dist.into_pyarray(py),
    ))
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(fov_gradient_py, m)?)?;
    Ok(())
}
