//! What every wrapper family shares: the [`KernelError`] exception, error conversion and the
//! NumPy-array-to-slice helpers. The families (`spline`, `fov`, `bounds`, `regions`) import only
//! from here, never from each other.
use numpy::{PyReadonlyArray1, PyReadonlyArray3, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use crate::error::Error;
use crate::spline::SplineView;

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
