//! PyO3 wrappers of the workspace certificates (`regions`): one function per region kind, so
//! the boundary is typed by name, not by a row order. Kernel errors become `KernelError` (a
//! `ValueError` with `.arg` and `.detail`); the kernels release the GIL.
#![allow(clippy::useless_conversion)]
use numpy::{IntoPyArray, PyArray1, PyReadonlyArray1, PyReadonlyArray3};
use pyo3::prelude::*;

use super::common::{contiguous, kernel_err, spline_view, to_py_err};
use crate::error::guarded;
use crate::regions::{self, Region, RegionVerdict};

type Verdicts<'py> = (Bound<'py, PyArray1<i8>>, Bound<'py, PyArray1<f64>>, f64);

fn vec3(arg: &'static str, v: &PyReadonlyArray1<'_, f64>) -> PyResult<[f64; 3]> {
    let s = contiguous(arg, v)?;
    <[f64; 3]>::try_from(s).map_err(|_| {
        kernel_err(
            arg,
            format!("wrong shape: expected 3 values, got {}", s.len()),
        )
    })
}

fn run<'py>(
    py: Python<'py>,
    coeffs: PyReadonlyArray3<'py, f64>,
    knots: PyReadonlyArray1<'py, f64>,
    region: Region,
    touch_order: usize,
    exact: bool,
) -> PyResult<Verdicts<'py>> {
    let view = spline_view(&coeffs, &knots)?;
    let out: Vec<RegionVerdict> = py
        .detach(|| guarded(|| regions::certify_region(&view, &region, touch_order, exact)))
        .map_err(to_py_err)?;
    let codes: Vec<i8> = out.iter().map(|v| v.certificate.code()).collect();
    let times: Vec<f64> = out.iter().map(|v| v.certificate.time()).collect();
    let residual = out.iter().map(|v| v.residual).fold(0.0, f64::max);
    Ok((codes.into_pyarray(py), times.into_pyarray(py), residual))
}

/// `normal . p(t) > offset` on every segment of a `(S, A >= 3, C)` spline (x, y, z first). With `touch_order = k >= 1`
/// the last segment touches the plane at its end (contact): the quotient after dividing out a
/// `k`-fold root at `t_f` is certified and `residual` bounds how far beyond the plane the
/// position can be (m). Returns `(codes int8 (S,), t (S,), residual)`; codes 0 within,
/// 1 violated (near `t`), 2 unknown (only with `exact=False`).
#[pyfunction(name = "certify_halfspace")]
#[pyo3(signature = (coeffs, knots, normal, offset, touch_order = 0, exact = true))]
fn certify_halfspace_py<'py>(
    py: Python<'py>,
    coeffs: PyReadonlyArray3<'py, f64>,
    knots: PyReadonlyArray1<'py, f64>,
    normal: PyReadonlyArray1<'py, f64>,
    offset: f64,
    touch_order: usize,
    exact: bool,
) -> PyResult<Verdicts<'py>> {
    let normal = vec3("normal", &normal)?;
    run(
        py,
        coeffs,
        knots,
        Region::HalfSpace { normal, offset },
        touch_order,
        exact,
    )
}

/// `|p(t) - center| > radius` on every segment; returns `(codes, t, 0.0)` as `certify_halfspace`.
#[pyfunction(name = "certify_sphere_outside")]
#[pyo3(signature = (coeffs, knots, center, radius, exact = true))]
fn certify_sphere_outside_py<'py>(
    py: Python<'py>,
    coeffs: PyReadonlyArray3<'py, f64>,
    knots: PyReadonlyArray1<'py, f64>,
    center: PyReadonlyArray1<'py, f64>,
    radius: f64,
    exact: bool,
) -> PyResult<Verdicts<'py>> {
    let center = vec3("center", &center)?;
    run(
        py,
        coeffs,
        knots,
        Region::SphereOutside { center, radius },
        0,
        exact,
    )
}

/// `|v(t)| < v_max` on every segment; returns `(codes, t, 0.0)` as `certify_halfspace`.
#[pyfunction(name = "certify_speed")]
#[pyo3(signature = (coeffs, knots, v_max, exact = true))]
fn certify_speed_py<'py>(
    py: Python<'py>,
    coeffs: PyReadonlyArray3<'py, f64>,
    knots: PyReadonlyArray1<'py, f64>,
    v_max: f64,
    exact: bool,
) -> PyResult<Verdicts<'py>> {
    run(py, coeffs, knots, Region::SpeedBelow { v_max }, 0, exact)
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(certify_halfspace_py, m)?)?;
    m.add_function(wrap_pyfunction!(certify_sphere_outside_py, m)?)?;
    m.add_function(wrap_pyfunction!(certify_speed_py, m)?)?;
    Ok(())
}
