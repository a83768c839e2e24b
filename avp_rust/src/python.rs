//! Thin PyO3 wrappers: convert NumPy arrays to slices, call a kernel, convert back. Every
//! kernel error becomes [`KernelError`] (a `ValueError` with `.arg` and `.detail`); kernels
//! return `Result` and do not panic on input paths.
#![allow(clippy::useless_conversion)]
use numpy::{
    IntoPyArray, PyArray1, PyArray2, PyArray3, PyReadonlyArray1, PyReadonlyArray2,
    PyReadonlyArray3, PyUntypedArrayMethods,
};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use crate::error::{guarded, Error};
use crate::spline::{self, SplineView};

pyo3::create_exception!(
    _avp_rust,
    KernelError,
    PyValueError,
    "A kernel rejected an argument: `.arg` names it, `.detail` says why and what to do."
);

/// A [`KernelError`] naming the offending argument (message `"{arg}: {detail}"`).
pub(crate) fn kernel_err(arg: &str, detail: impl Into<String>) -> PyErr {
    let detail = detail.into();
    Python::attach(|py| {
        let err = KernelError::new_err(format!("{arg}: {detail}"));
        let value = err.value(py);
        match value
            .setattr("arg", arg)
            .and_then(|()| value.setattr("detail", detail))
        {
            Ok(()) => err,
            Err(e) => e,
        }
    })
}

pub(crate) fn to_py_err(e: Error) -> PyErr {
    kernel_err(e.arg(), e.detail())
}

pub(crate) fn contiguous<'a>(
    arg: &'static str,
    slice: std::result::Result<&'a [f64], numpy::NotContiguousError>,
) -> PyResult<&'a [f64]> {
    slice.map_err(|_| kernel_err(arg, "must be a C-contiguous float64 array"))
}

/// Borrows a `(segments, axes, coeffs)` array and its knots as a validated [`SplineView`].
pub(crate) fn spline_view<'a>(
    coeffs: &'a PyReadonlyArray3<'_, f64>,
    knots: &'a PyReadonlyArray1<'_, f64>,
) -> PyResult<SplineView<'a>> {
    let shape = coeffs.shape();
    let shape = (shape[0], shape[1], shape[2]);
    let c = contiguous("coeffs", coeffs.as_slice())?;
    let k = contiguous("knots", knots.as_slice())?;
    SplineView::new(c, shape, k).map_err(to_py_err)
}

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
    let t = contiguous("times", times.as_slice())?;
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
    let o = contiguous("odometry", odometry.as_slice())?;
    let out =
        guarded(|| crate::anticipation::anticipate(&view, o, t_rp, t_ex)).map_err(to_py_err)?;
    let arr = numpy::ndarray::Array2::from_shape_vec((crate::anticipation::ORDERS, n_axes), out)
        .map_err(|e| kernel_err("kernel", format!("internal shape error: {e}")))?;
    Ok(arr.into_pyarray(py))
}

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

#[pymodule]
pub fn _avp_rust(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("KernelError", m.py().get_type::<KernelError>())?;
    m.add_function(wrap_pyfunction!(eval_spline_py, m)?)?;
    m.add_function(wrap_pyfunction!(anticipate_py, m)?)?;
    m.add_function(wrap_pyfunction!(fov_gradient_py, m)?)?;
    crate::python_bounds::register(m)?;
    crate::python_regions::register(m)?;
    Ok(())
}
