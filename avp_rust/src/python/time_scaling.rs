//! PyO3 wrapper of the time search's scaling law (`time_scaling`).
#![allow(clippy::useless_conversion)]
use numpy::{IntoPyArray, PyArray1, PyReadonlyArray1, PyReadonlyArray3};
use pyo3::prelude::*;

use super::common::{contiguous, kernel_err, spline_view, to_py_err};
use crate::error::guarded;
use crate::time_scaling::{self, ScalingLimits};

/// Worst relative excess over the limits of the spline time-scaled by each factor `s`, given
/// `s2 = s^-2`, on `per_segment` midpoint samples per segment. Returns shape `(len(s2),)`.
#[pyfunction(name = "scaled_excess")]
#[allow(clippy::too_many_arguments)]
#[pyo3(signature = (coeffs, knots, per_segment, s2, g, *, accel_max, accel_min, mass,
                    thrust_rate_max, tilt_rate_max, body_rate_max))]
fn scaled_excess_py<'py>(
    py: Python<'py>,
    coeffs: PyReadonlyArray3<'py, f64>,
    knots: PyReadonlyArray1<'py, f64>,
    per_segment: i64,
    s2: PyReadonlyArray1<'py, f64>,
    g: f64,
    accel_max: f64,
    accel_min: f64,
    mass: f64,
    thrust_rate_max: f64,
    tilt_rate_max: f64,
    body_rate_max: f64,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let per_segment = usize::try_from(per_segment).map_err(|_| {
        kernel_err(
            "per_segment",
            format!("must be at least 1, got {per_segment}"),
        )
    })?;
    let view = spline_view(&coeffs, &knots)?;
    let s2 = contiguous("s2", &s2)?;
    let limits = ScalingLimits {
        accel_max,
        accel_min,
        mass,
        thrust_rate_max,
        tilt_rate_max,
        body_rate_max,
    };
    let out = guarded(|| time_scaling::scaled_excess(&view, per_segment, s2, g, &limits))
        .map_err(to_py_err)?;
    Ok(out.into_pyarray(py))
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(scaled_excess_py, m)?)?;
    Ok(())
}
