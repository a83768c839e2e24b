//! PyO3 wrappers of the Sturm counts and bound certificates (`sturm`, `certify`, `bounds`).
//! Kernel errors become `KernelError` (a `ValueError` naming the argument); batch kernels
//! release the GIL. The optional `budget` (seconds, `inf` = none) bounds the exact fallback.
#![allow(clippy::useless_conversion)]
use numpy::ndarray::Array2;
use numpy::{
    IntoPyArray, PyArray1, PyArray2, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3,
    PyUntypedArrayMethods,
};
use pyo3::prelude::*;

use crate::error::guarded;

use super::common::{contiguous, kernel_err, matrix, spline_view, to_py_err};
use crate::bounds::{self, BoundKind, Limits, ALL_BOUNDS};
use crate::certify::{self, ExactMethod};
use crate::descartes::Budget;
use crate::sturm;
use crate::trackability;

/// Exact number of distinct real roots of `sum coeffs[k] x^k` in the closed interval `[a, b]`.
#[pyfunction(name = "sturm_count")]
fn sturm_count_py(
    py: Python<'_>,
    coeffs: PyReadonlyArray1<'_, f64>,
    a: f64,
    b: f64,
) -> PyResult<usize> {
    let c = contiguous("coeffs", &coeffs)?;
    py.detach(|| guarded(|| sturm::sturm_count(c, a, b)))
        .map_err(to_py_err)
}

fn budget_arg(budget: f64) -> PyResult<f64> {
    if budget.is_nan() || budget < 0.0 {
        return Err(kernel_err(
            "budget",
            format!("must be >= 0 seconds (inf for no budget), got {budget}"),
        ));
    }
    Ok(budget)
}

fn method_arg(method: &str) -> PyResult<ExactMethod> {
    match method {
        "bernstein" => Ok(ExactMethod::Bernstein),
        "sturm" => Ok(ExactMethod::Sturm),
        _ => Err(kernel_err(
            "method",
            format!("unknown exact method {method:?}; use \"bernstein\" or \"sturm\""),
        )),
    }
}

/// Algorithm 1: `(code, t)` with code 0 within (`F < 0` on `[a, b]`), 1 violated at about `t`,
/// 2 unknown (with `exact=False`, or when the exact fallback exceeds `budget` seconds).
#[pyfunction(name = "certify_below")]
#[pyo3(signature = (coeffs, a, b, exact = true, budget = f64::INFINITY))]
fn certify_below_py(
    py: Python<'_>,
    coeffs: PyReadonlyArray1<'_, f64>,
    a: f64,
    b: f64,
    exact: bool,
    budget: f64,
) -> PyResult<(i8, f64)> {
    let c = contiguous("coeffs", &coeffs)?;
    let budget = budget_arg(budget)?;
    let (cert, _) = py
        .detach(|| {
            guarded(|| {
                let budget = Budget::seconds(budget);
                certify::certify_below_traced(c, a, b, exact, &budget, ExactMethod::Bernstein)
            })
        })
        .map_err(to_py_err)?;
    Ok((cert.code(), cert.time()))
}

/// Algorithm 1 on every row of `coeffs` (shape `(n, C)`) over the same `[a, b]`. Returns
/// `(codes int8 (n,), t float64 (n,), fast bool (n,))`; `fast` tells whether the floating-point
/// path decided the row (for unknown-rate statistics). `budget` (seconds) applies to each row's
/// exact fallback separately; `method` picks the exact algorithm (`"bernstein"`, the default, or
/// the previous `"sturm"` chain, unbudgeted, kept for comparisons).
#[pyfunction(name = "certify_below_many")]
#[pyo3(signature = (coeffs, a, b, exact = true, budget = f64::INFINITY, method = "bernstein"))]
#[allow(clippy::type_complexity)]
fn certify_below_many_py<'py>(
    py: Python<'py>,
    coeffs: PyReadonlyArray2<'py, f64>,
    a: f64,
    b: f64,
    exact: bool,
    budget: f64,
    method: &str,
) -> PyResult<(
    Bound<'py, PyArray1<i8>>,
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<bool>>,
)> {
    let shape = coeffs.shape();
    let (n, m) = (shape[0], shape[1]);
    let c = contiguous("coeffs", &coeffs)?;
    let budget = budget_arg(budget)?;
    let method = method_arg(method)?;
    if m == 0 && n > 0 {
        return Err(kernel_err(
            "coeffs",
            "needs at least one coefficient per row",
        ));
    }
    let out = py
        .detach(|| {
            guarded(|| -> crate::Result<Vec<(certify::Certificate, bool)>> {
                if m == 0 {
                    return Ok(Vec::new());
                }
                c.chunks_exact(m)
                    .map(|row| {
                        let budget = Budget::seconds(budget);
                        certify::certify_below_traced(row, a, b, exact, &budget, method)
                    })
                    .collect()
            })
        })
        .map_err(to_py_err)?;
    let codes: Vec<i8> = out.iter().map(|(c, _)| c.code()).collect();
    let times: Vec<f64> = out.iter().map(|(c, _)| c.time()).collect();
    let fast: Vec<bool> = out.iter().map(|(_, f)| *f).collect();
    Ok((
        codes.into_pyarray(py),
        times.into_pyarray(py),
        fast.into_pyarray(py),
    ))
}

/// Certifies the actuator bounds of a flat-output spline (Sec. V-C, Appendix B).
///
/// `coeffs` shape `(S, 4, C)` (x, y, z, yaw; ascending powers of `t - knots[i]`), `knots`
/// shape `(S + 1,)`, `limits` = `[thrust_max, thrust_min, thrust_rate_max, tilt_rate_max,
/// body_rate_max]` (the row order) mass-normalised (`+inf` = not checked). Returns `(codes int8 (5, S),
/// t float64 (5, S))` with codes 0 within, 1 violated (at about `t`), 2 unknown (with `exact`,
/// only a body rate whose roll level is undecided, or a cell left when the exact fallbacks ran
/// out of `budget`), 3 not checked. `budget` (seconds, `inf` = none) bounds the exact fallbacks
/// of the whole call.
#[pyfunction(name = "certify_spline")]
#[pyo3(signature = (coeffs, knots, limits, g = 9.81, exact = true, budget = f64::INFINITY))]
#[allow(clippy::type_complexity)]
fn certify_spline_py<'py>(
    py: Python<'py>,
    coeffs: PyReadonlyArray3<'py, f64>,
    knots: PyReadonlyArray1<'py, f64>,
    limits: PyReadonlyArray1<'py, f64>,
    g: f64,
    exact: bool,
    budget: f64,
) -> PyResult<(Bound<'py, PyArray2<i8>>, Bound<'py, PyArray2<f64>>)> {
    let view = spline_view(&coeffs, &knots)?;
    let l = contiguous("limits", &limits)?;
    let limits = Limits::from_slice(l).map_err(to_py_err)?;
    let budget = budget_arg(budget)?;
    let verdicts = py
        .detach(|| {
            guarded(|| {
                let budget = Budget::seconds(budget);
                bounds::certify_spline_budgeted(&view, &limits, g, exact, &budget)
            })
        })
        .map_err(to_py_err)?;
    let n_seg = view.n_segments();
    let mut codes = Array2::<i8>::from_elem((ALL_BOUNDS.len(), n_seg), 3);
    let mut times = Array2::<f64>::from_elem((ALL_BOUNDS.len(), n_seg), f64::NAN);
    for v in &verdicts {
        if let Some(cert) = v.certificate {
            codes[[v.bound as usize, v.segment]] = cert.code();
            times[[v.bound as usize, v.segment]] = cert.time();
        }
    }
    Ok((codes.into_pyarray(py), times.into_pyarray(py)))
}

/// The checked polynomial of bound `bound` (row index 0..5) on segment `segment`, in
/// `u = (t - knots[i]) / (knots[i+1] - knots[i])`, as a rigorous coefficient enclosure
/// `(lo, hi)` (for tests and diagnostics).
#[pyfunction(name = "bound_polynomial")]
#[pyo3(signature = (coeffs, knots, segment, bound, limit, g = 9.81))]
#[allow(clippy::type_complexity, clippy::too_many_arguments)]
fn bound_polynomial_py<'py>(
    py: Python<'py>,
    coeffs: PyReadonlyArray3<'py, f64>,
    knots: PyReadonlyArray1<'py, f64>,
    segment: usize,
    bound: usize,
    limit: f64,
    g: f64,
) -> PyResult<(Bound<'py, PyArray1<f64>>, Bound<'py, PyArray1<f64>>)> {
    let view = spline_view(&coeffs, &knots)?;
    let shape = (view.n_segments(), view.n_axes(), view.n_coeffs());
    if shape.1 != 4 {
        return Err(kernel_err(
            "coeffs",
            format!("expected 4 axes (x, y, z, yaw), got {}", shape.1),
        ));
    }
    if segment >= shape.0 {
        return Err(kernel_err(
            "segment",
            format!("{segment} out of range for {} segments", shape.0),
        ));
    }
    let kind: BoundKind = *ALL_BOUNDS
        .get(bound)
        .ok_or_else(|| kernel_err("bound", format!("index {bound} out of range 0..5")))?;
    if !(limit.is_finite() && g.is_finite()) {
        let arg = if limit.is_finite() { "g" } else { "limit" };
        return Err(kernel_err(arg, "must be finite"));
    }
    let (lo, hi) = guarded(|| Ok(bounds::bound_enclosure(&view, segment, kind, limit, g)))
        .map_err(to_py_err)?;
    Ok((lo.into_pyarray(py), hi.into_pyarray(py)))
}

/// Exact, upward-rounded coefficients of the trackability polynomials (`avp.trackability`):
/// per segment of `coeffs` `(S, A >= 3, C)` and `knots` `(S + 1,)`, the row of
/// `|s|^2 - snap_max^2` if `snap_max` is finite, then the row of `|s|^2 - ratio_max^2 |a + g e3|^2`
/// if `ratio_max` is finite, ascending in `u = (t - t_i) / T_i`, zero-padded: float64
/// `(S * rows per segment, width)`. `KernelError` when a coefficient is outside the normal f64
/// range (the caller computes it otherwise).
#[pyfunction(name = "trackability_rows")]
#[pyo3(signature = (coeffs, knots, snap_max, ratio_max, g = 9.81))]
fn trackability_rows_py<'py>(
    py: Python<'py>,
    coeffs: PyReadonlyArray3<'py, f64>,
    knots: PyReadonlyArray1<'py, f64>,
    snap_max: f64,
    ratio_max: f64,
    g: f64,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let view = spline_view(&coeffs, &knots)?;
    let (rows, n, width) =
        guarded(|| trackability::trackability_rows(&view, snap_max, ratio_max, g))
            .map_err(to_py_err)?;
    matrix(py, n, width, rows)
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(sturm_count_py, m)?)?;
    m.add_function(wrap_pyfunction!(certify_below_py, m)?)?;
    m.add_function(wrap_pyfunction!(certify_below_many_py, m)?)?;
    m.add_function(wrap_pyfunction!(certify_spline_py, m)?)?;
    m.add_function(wrap_pyfunction!(bound_polynomial_py, m)?)?;
    m.add_function(wrap_pyfunction!(trackability_rows_py, m)?)?;
    m.add(
        "BOUND_NAMES",
        ALL_BOUNDS
            .iter()
            .map(|k| format!("{k:?}"))
            .collect::<Vec<_>>(),
    )?;
    Ok(())
}
