//! PyO3 wrappers of the spline kernels: evaluation, the anticipation step (6) and a decision
//! vector's spline coefficients.
#![allow(clippy::useless_conversion)]
use numpy::{
    IntoPyArray, PyArray2, PyArray3, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3,
    PyUntypedArrayMethods,
};
use pyo3::prelude::*;

use super::common::{contiguous, kernel_err, matrix, row_major, spline_view, to_py_err, F1, F2};
use crate::error::guarded;
use crate::spline;

/// Evaluates a spline at `times` for each derivative order in `orders`.
///
/// `coeffs` has shape `(segments, axes, coeffs)` (ascending powers of `t - knots[i]`),
/// `knots` shape `(segments + 1,)`. Returns shape `(len(orders), len(times), axes)`.
#[pyfunction(name = "eval_spline")]
fn eval_spline_py<'py>(
    py: Python<'py>,
    coeffs: PyReadonlyArray3<'py, f64>,
    knots: PyReadonlyArray1<'py, f64>,
    times: PyReadonlyArray1<'py, f64>,
    orders: Vec<usize>,
) -> PyResult<Bound<'py, PyArray3<f64>>> {
    let view = spline_view(&coeffs, &knots)?;
    let t = contiguous("times", &times)?;
    if let Some(&bad) = orders.iter().find(|&&o| o > 64) {
        return Err(kernel_err(
            "orders",
            format!("derivative order {bad} is too large (at most 64)"),
        ));
    }
    let n_times = t.len();
    let n_orders = orders.len();
    let out = py
        .detach(|| guarded(|| spline::evaluate(&view, t, &orders)))
        .map_err(to_py_err)?;
    let arr = numpy::ndarray::Array3::from_shape_vec((n_orders, n_times, view.n_axes()), out)
        .map_err(|e| kernel_err("kernel", format!("internal shape error: {e}")))?;
    Ok(arr.into_pyarray(py))
}

/// Anticipated flat state (6) at `t_ex` from odometry at `t_rp` and the committed plan.
///
/// `odometry` has shape `(5, axes)` (orders 0..4); returns the same shape.
#[pyfunction(name = "anticipate")]
fn anticipate_py<'py>(
    py: Python<'py>,
    coeffs: PyReadonlyArray3<'py, f64>,
    knots: PyReadonlyArray1<'py, f64>,
    odometry: PyReadonlyArray2<'py, f64>,
    t_rp: f64,
    t_ex: f64,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let view = spline_view(&coeffs, &knots)?;
    let n_axes = view.n_axes();
    let odo_shape = odometry.shape().to_vec();
    if odo_shape != [crate::anticipation::ORDERS, n_axes] {
        return Err(kernel_err(
            "odometry",
            format!(
                "expected shape ({}, {}), got {:?}",
                crate::anticipation::ORDERS,
                n_axes,
                odo_shape
            ),
        ));
    }
    let o = contiguous("odometry", &odometry)?;
    let out =
        guarded(|| crate::anticipation::anticipate(&view, o, t_rp, t_ex)).map_err(to_py_err)?;
    matrix(py, crate::anticipation::ORDERS, n_axes, out)
}

/// A decision vector's spline coefficients `(segments, axes, powers)` and whether they are all
/// finite (`crate::spline::physical_coefficients`); `c_hat` and `scale` of any layout and float
/// dtype.
#[pyfunction(name = "physical_coefficients")]
fn physical_coefficients_py<'py>(
    py: Python<'py>,
    c_hat: F1<'py>,
    scale: F2<'py>,
) -> PyResult<(Bound<'py, PyArray3<f64>>, bool)> {
    let (segments, powers) = (scale.shape()[0], scale.shape()[1]);
    let (c, f) = (row_major(&c_hat), row_major(&scale));
    let (out, finite) =
        guarded(|| spline::physical_coefficients(&c, &f, powers)).map_err(to_py_err)?;
    let axes = out.len() / (segments * powers).max(1);
    let arr = numpy::ndarray::Array3::from_shape_vec((segments, axes, powers), out)
        .map_err(|e| kernel_err("kernel", format!("internal shape error: {e}")))?;
    Ok((arr.into_pyarray(py), finite))
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(eval_spline_py, m)?)?;
    m.add_function(wrap_pyfunction!(anticipate_py, m)?)?;
    m.add_function(wrap_pyfunction!(physical_coefficients_py, m)?)?;
    Ok(())
}
