//! What every wrapper family shares: the [`KernelError`] exception, error conversion and the
//! NumPy-array helpers. The families (`spline`, `fov`, `bounds`, `regions`, `time_scaling`,
//! `qp_check`, `reduce`) import only from here, never from each other.
use std::borrow::Cow;

use numpy::ndarray::Dimension;
use numpy::{
    AllowTypeChange, Element, IntoPyArray, PyArray2, PyArrayLike1, PyArrayLike2, PyReadonlyArray,
    PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3, PyUntypedArrayMethods,
};
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

/// The array's data as a row-major slice. A column-major (Fortran-ordered) array is rejected:
/// NumPy's `as_slice` accepts it, but the kernels index rows, so its values would be read in the
/// wrong order.
pub(crate) fn contiguous<'a, T: Element, D: Dimension>(
    arg: &'static str,
    arr: &'a PyReadonlyArray<'_, T, D>,
) -> PyResult<&'a [T]> {
    let bad = || {
        kernel_err(
            arg,
            "must be a C-contiguous (row-major) array; pass np.ascontiguousarray(...)",
        )
    };
    if !arr.is_c_contiguous() {
        return Err(bad());
    }
    arr.as_slice().map_err(|_| bad())
}

/// `m` (named `arg`) has `n` columns, or no rows (an empty `(0, k)` stack of rows fits any
/// width).
pub(crate) fn columns(arg: &'static str, m: &PyReadonlyArray2<'_, f64>, n: usize) -> PyResult<()> {
    let shape = m.shape();
    if shape[1] == n || shape[0] == 0 {
        Ok(())
    } else {
        Err(kernel_err(
            arg,
            format!("wrong shape: expected {n} columns, got {:?}", shape),
        ))
    }
}

/// A float array of any layout or dtype (converted to `float64` when it is not), read by its
/// values ([`row_major`]): the kernels that take the planner's arrays as they are, without a
/// conversion call in Python for each.
pub(crate) type F1<'py> = PyArrayLike1<'py, f64, AllowTypeChange>;
/// A float matrix of any layout or dtype.
pub(crate) type F2<'py> = PyArrayLike2<'py, f64, AllowTypeChange>;

/// The values of `arr` in row-major order: its own buffer when it is C-contiguous, a copy
/// otherwise (a Fortran-ordered factor, a strided view).
pub(crate) fn row_major<'a, D: Dimension>(arr: &'a PyReadonlyArray<'_, f64, D>) -> Cow<'a, [f64]> {
    match arr.as_slice() {
        Ok(s) if arr.is_c_contiguous() => Cow::Borrowed(s),
        Ok(s) if arr.ndim() == 2 => {
            // a Fortran-ordered matrix (the elimination's basis and factor): its columns, one
            // after another, transposed by plain loops (ndarray's general iterator is slower)
            let (rows, cols) = (arr.shape()[0], arr.shape()[1]);
            let mut out = vec![0.0; s.len()];
            for (j, column) in s.chunks_exact(rows.max(1)).enumerate() {
                for (i, &v) in column.iter().enumerate() {
                    out[i * cols + j] = v;
                }
            }
            Cow::Owned(out)
        }
        _ => Cow::Owned(arr.as_array().iter().copied().collect()),
    }
}

/// A kernel's row-major output `v` as a `(rows, cols)` NumPy array.
pub(crate) fn matrix<'py>(
    py: Python<'py>,
    rows: usize,
    cols: usize,
    v: Vec<f64>,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    numpy::ndarray::Array2::from_shape_vec((rows, cols), v)
        .map(|a| a.into_pyarray(py))
        .map_err(|e| kernel_err("kernel", format!("internal shape error: {e}")))
}

/// Borrows a `(segments, axes, coeffs)` array and its knots as a validated [`SplineView`].
pub(crate) fn spline_view<'a>(
    coeffs: &'a PyReadonlyArray3<'_, f64>,
    knots: &'a PyReadonlyArray1<'_, f64>,
) -> PyResult<SplineView<'a>> {
    let shape = coeffs.shape();
    let shape = (shape[0], shape[1], shape[2]);
    let c = contiguous("coeffs", coeffs)?;
    let k = contiguous("knots", knots)?;
    SplineView::new(c, shape, k).map_err(to_py_err)
}
