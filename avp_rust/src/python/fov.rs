//! PyO3 wrappers of the field-of-view kernels (7)-(9): `h` and its gradient, the linearised
//! rows' terms, the dense rows, the visibility fractions of plans (`crate::fov`) and the rows of
//! one SQP step on a reference plan (`crate::fov_step`).
#![allow(clippy::useless_conversion)]
use numpy::{
    IntoPyArray, PyArray1, PyArray2, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3,
    PyUntypedArrayMethods,
};
use pyo3::prelude::*;

use super::common::{contiguous, kernel_err, matrix, spline_view, to_py_err};
use crate::error::guarded;

/// Rejects a 2-D array whose rows are not 3-vectors (a `(3m, 1)` array has the right length
/// but is not `(m, 3)`).
fn rows_of_three(arg: &'static str, a: &PyReadonlyArray2<'_, f64>) -> PyResult<()> {
    match a.shape()[1] {
        3 => Ok(()),
        c => Err(kernel_err(
            arg,
            format!("wrong shape: expected (m, 3), got (m, {c})"),
        )),
    }
}

/// The settings of a linearisation from the wrappers' arguments (`policy` by name).
fn linearisation_settings(
    cos_half: f64,
    g: f64,
    trust: (f64, f64, f64),
    margin: f64,
    reach_fraction: f64,
    progress_fraction: f64,
    policy: &str,
) -> PyResult<crate::fov::LinearisationSettings> {
    Ok(crate::fov::LinearisationSettings {
        cos_half,
        g,
        trust: [trust.0, trust.1, trust.2],
        margin,
        reach_fraction,
        progress_fraction,
        policy: crate::fov::PointPolicy::from_name(policy).map_err(to_py_err)?,
    })
}

/// The number of coefficients of the basis rows `p0` and `p2`, which have the same shape.
fn basis_width(p0: &PyReadonlyArray2<'_, f64>, p2: &PyReadonlyArray2<'_, f64>) -> PyResult<usize> {
    if p2.shape() != p0.shape() {
        return Err(kernel_err(
            "p2",
            format!(
                "wrong shape: expected {:?} as p0, got {:?}",
                p0.shape(),
                p2.shape()
            ),
        ));
    }
    Ok(p0.shape()[1])
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
    rows_of_three("x", &x)?;
    rows_of_three("a", &a)?;
    let xs = contiguous("x", &x)?;
    let ps = contiguous("psi", &psi)?;
    let as_ = contiguous("a", &a)?;
    let ss = contiguous("s", &s)?;
    let ds = contiguous("axis_B", &axis_B)?;
    let pts = guarded(|| crate::fov::fov_gradient(xs, ps, as_, ss, ds, cos_half, g))
        .map_err(to_py_err)?;
    let m = pts.len();
    let h: Vec<f64> = pts.iter().map(|p| p.h).collect();
    let dpsi: Vec<f64> = pts.iter().map(|p| p.d_psi).collect();
    let dist: Vec<f64> = pts.iter().map(|p| p.distance).collect();
    let dx: Vec<f64> = pts.iter().flat_map(|p| p.d_x).collect();
    let da: Vec<f64> = pts.iter().flat_map(|p| p.d_a).collect();
    Ok((
        h.into_pyarray(py),
        matrix(py, m, 3, dx)?,
        dpsi.into_pyarray(py),
        matrix(py, m, 3, da)?,
        dist.into_pyarray(py),
    ))
}

/// The linearised FoV rows (8) at `m` points (`avp.qp.fov.fov_blocks`): `x0 (m, 3)`,
/// `psi0 (m,)`, `a0 (m, 3)`, target `s (3,)`, optical axis `axis_B (3,)`; `trust` the box (9)
/// radii in position, acceleration and yaw (each may be inf); `policy` `"keep"`, `"skip"` or
/// `"progress"`. Returns `(h0 (m,), reachable (m,), gx (m, 3), ga (m, 3), gp (m,), rhs (m,),
/// placed (m,) bool, progress (m,) bool, hold)`.
#[pyfunction(name = "fov_linearise")]
#[allow(clippy::type_complexity, clippy::too_many_arguments, non_snake_case)]
fn fov_linearise_py<'py>(
    py: Python<'py>,
    x0: PyReadonlyArray2<'py, f64>,
    psi0: PyReadonlyArray1<'py, f64>,
    a0: PyReadonlyArray2<'py, f64>,
    s: PyReadonlyArray1<'py, f64>,
    axis_B: PyReadonlyArray1<'py, f64>,
    cos_half: f64,
    g: f64,
    trust: (f64, f64, f64),
    margin: f64,
    reach_fraction: f64,
    progress_fraction: f64,
    policy: &str,
) -> PyResult<(
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<bool>>,
    Bound<'py, PyArray1<bool>>,
    bool,
)> {
    rows_of_three("x0", &x0)?;
    rows_of_three("a0", &a0)?;
    let xs = contiguous("x0", &x0)?;
    let ps = contiguous("psi0", &psi0)?;
    let as_ = contiguous("a0", &a0)?;
    let ss = contiguous("s", &s)?;
    let ds = contiguous("axis_B", &axis_B)?;
    let settings = linearisation_settings(
        cos_half,
        g,
        trust,
        margin,
        reach_fraction,
        progress_fraction,
        policy,
    )?;
    let (terms, hold) =
        guarded(|| crate::fov::fov_linearise(xs, ps, as_, ss, ds, &settings)).map_err(to_py_err)?;
    let m = terms.len();
    let col = |f: fn(&crate::fov::FovRowTerms) -> f64| terms.iter().map(f).collect::<Vec<f64>>();
    let flag = |f: fn(&crate::fov::FovRowTerms) -> bool| terms.iter().map(f).collect::<Vec<bool>>();
    let gx: Vec<f64> = terms.iter().flat_map(|t| t.gx).collect();
    let ga: Vec<f64> = terms.iter().flat_map(|t| t.ga).collect();
    Ok((
        col(|t| t.h0).into_pyarray(py),
        col(|t| t.reachable).into_pyarray(py),
        matrix(py, m, 3, gx)?,
        matrix(py, m, 3, ga)?,
        col(|t| t.gp).into_pyarray(py),
        col(|t| t.rhs).into_pyarray(py),
        flag(|t| t.placed).into_pyarray(py),
        flag(|t| t.progress).into_pyarray(py),
        hold,
    ))
}

/// Dense FoV row matrices (`avp.qp.fov.fov_rows`): rows (8) `(k, n)`, trust region (9) in
/// position `(3k, n)`, in acceleration `(3k, n)` and in yaw `(k, n)`, `n = 4 n_segments n_coeffs`,
/// from the points' segments `seg (k,)`, basis rows `p0`, `p2` `(k, n_coeffs)` and the
/// gradients `gx`, `ga` `(k, 3)`, `gp (k,)`.
#[pyfunction(name = "fov_row_matrices")]
#[allow(clippy::type_complexity, clippy::too_many_arguments)]
fn fov_row_matrices_py<'py>(
    py: Python<'py>,
    n_segments: usize,
    seg: PyReadonlyArray1<'py, i64>,
    p0: PyReadonlyArray2<'py, f64>,
    p2: PyReadonlyArray2<'py, f64>,
    gx: PyReadonlyArray2<'py, f64>,
    ga: PyReadonlyArray2<'py, f64>,
    gp: PyReadonlyArray1<'py, f64>,
) -> PyResult<(
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray2<f64>>,
)> {
    rows_of_three("gx", &gx)?;
    rows_of_three("ga", &ga)?;
    let n_coeffs = basis_width(&p0, &p2)?;
    let segs = contiguous("seg", &seg)?;
    let (p0s, p2s) = (contiguous("p0", &p0)?, contiguous("p2", &p2)?);
    let (gxs, gas, gps) = (
        contiguous("gx", &gx)?,
        contiguous("ga", &ga)?,
        contiguous("gp", &gp)?,
    );
    let (r8, rx, ra, ry) = guarded(|| {
        crate::fov::fov_row_matrices(n_segments, n_coeffs, segs, p0s, p2s, gxs, gas, gps)
    })
    .map_err(to_py_err)?;
    let (k, n) = (segs.len(), 4 * n_segments * n_coeffs);
    Ok((
        matrix(py, k, n, r8)?,
        matrix(py, 3 * k, n, rx)?,
        matrix(py, 3 * k, n, ra)?,
        matrix(py, k, n, ry)?,
    ))
}

/// The visibility fractions (`crate::fov::visibility_fractions`) of the plans whose stacked
/// coefficients `coeffs (S, 4k, C)` on `knots (S + 1,)` hold, at their relative `times (n,)`,
/// evaluated in the kernel (with rotor drag `d > 0` in the thrust direction `a + d v`).
/// Returns `(time_fraction (k,), path_fraction (k,), first_lost (k,))`.
#[pyfunction(name = "spline_visibility")]
#[allow(clippy::type_complexity, clippy::too_many_arguments, non_snake_case)]
fn spline_visibility_py<'py>(
    py: Python<'py>,
    coeffs: PyReadonlyArray3<'py, f64>,
    knots: PyReadonlyArray1<'py, f64>,
    times: PyReadonlyArray1<'py, f64>,
    rotor_drag: f64,
    s: PyReadonlyArray1<'py, f64>,
    axis_B: PyReadonlyArray1<'py, f64>,
    cos_half: f64,
    g: f64,
) -> PyResult<(
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<f64>>,
)> {
    let view = spline_view(&coeffs, &knots)?;
    let ts = contiguous("times", &times)?;
    let (ss, ds) = (contiguous("s", &s)?, contiguous("axis_B", &axis_B)?);
    let out = guarded(|| crate::fov::spline_visibility(&view, ts, rotor_drag, ss, ds, cos_half, g))
        .map_err(to_py_err)?;
    let col =
        |f: fn(&(f64, f64, f64)) -> f64| out.iter().map(f).collect::<Vec<f64>>().into_pyarray(py);
    Ok((col(|r| r.0), col(|r| r.1), col(|r| r.2)))
}

type StepBlocksOut<'py> = (
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<f64>>,
);

type StepOut<'py> = (
    (
        Bound<'py, PyArray1<f64>>,
        Bound<'py, PyArray1<f64>>,
        Bound<'py, PyArray1<bool>>,
        Bound<'py, PyArray1<bool>>,
        bool,
    ),
    (
        Bound<'py, PyArray2<f64>>,
        Bound<'py, PyArray2<f64>>,
        Bound<'py, PyArray1<f64>>,
        Bound<'py, PyArray1<f64>>,
        Bound<'py, PyArray2<f64>>,
        Bound<'py, PyArray2<f64>>,
        Bound<'py, PyArray1<f64>>,
    ),
    Option<StepBlocksOut<'py>>,
);

/// The rows of one SQP step linearised on the reference spline `coeffs (S, 4, C)`, `knots
/// (S + 1,)` at its relative times `tau (m,)` (`avp.perception.linearise_on`): the reference's
/// points (acceleration `a + rotor_drag v`), their row terms as `fov_linearise` gives them, and
/// the placed points' rows as `fov_row_matrices` gives them, on the QP's point basis `seg (m,)`,
/// `p0`, `p2 (m, n_coeffs)` of `n_segments` segments. Returns three tuples: per point `(h0,
/// reachable, placed, progress, hold)`; per placed point (`k`) the row inputs `(gx (k, 3), ga
/// (k, 3), gp, rhs, x0 (k, 3), a0 (k, 3), psi0)`; and the blocks `(row8 (k, n), rx (3k, n), x_lo,
/// x_hi, ra (3k, n), a_lo, a_hi, ryaw (k, n), yaw_lo, yaw_hi)`, the trust region's bounds being
/// the point minus and plus its radius, or `None` unless `build_rows`.
#[pyfunction(name = "fov_step_rows")]
#[allow(clippy::too_many_arguments, non_snake_case)]
fn fov_step_rows_py<'py>(
    py: Python<'py>,
    coeffs: PyReadonlyArray3<'py, f64>,
    knots: PyReadonlyArray1<'py, f64>,
    tau: PyReadonlyArray1<'py, f64>,
    rotor_drag: f64,
    s: PyReadonlyArray1<'py, f64>,
    axis_B: PyReadonlyArray1<'py, f64>,
    cos_half: f64,
    g: f64,
    trust: (f64, f64, f64),
    margin: f64,
    reach_fraction: f64,
    progress_fraction: f64,
    policy: &str,
    n_segments: usize,
    seg: PyReadonlyArray1<'py, i64>,
    p0: PyReadonlyArray2<'py, f64>,
    p2: PyReadonlyArray2<'py, f64>,
    build_rows: bool,
) -> PyResult<StepOut<'py>> {
    let view = spline_view(&coeffs, &knots)?;
    let ts = contiguous("tau", &tau)?;
    let (ss, ds) = (contiguous("s", &s)?, contiguous("axis_B", &axis_B)?);
    let settings = linearisation_settings(
        cos_half,
        g,
        trust,
        margin,
        reach_fraction,
        progress_fraction,
        policy,
    )?;
    let n_coeffs = basis_width(&p0, &p2)?;
    let basis = crate::fov_step::PointBasis {
        n_segments,
        seg: contiguous("seg", &seg)?,
        p0: contiguous("p0", &p0)?,
        p2: contiguous("p2", &p2)?,
    };
    let out = guarded(|| {
        crate::fov_step::rows_on_spline(
            &view, ts, rotor_drag, ss, ds, &settings, &basis, build_rows,
        )
    })
    .map_err(to_py_err)?;
    let (k, n) = (out.placed.len(), 4 * n_segments * n_coeffs);
    let terms = &out.terms;
    let per_point = |f: fn(&crate::fov::FovRowTerms) -> f64| {
        terms.iter().map(f).collect::<Vec<f64>>().into_pyarray(py)
    };
    let flag = |f: fn(&crate::fov::FovRowTerms) -> bool| {
        terms.iter().map(f).collect::<Vec<bool>>().into_pyarray(py)
    };
    let placed = &out.placed;
    let per_placed = |f: fn(&crate::fov::FovRowTerms) -> f64| {
        placed.iter().map(|&i| f(&terms[i])).collect::<Vec<f64>>()
    };
    let triples = |f: fn(&crate::fov::FovRowTerms) -> [f64; 3]| {
        placed
            .iter()
            .flat_map(|&i| f(&terms[i]))
            .collect::<Vec<f64>>()
    };
    let of_points = |v: &[f64], w: usize| {
        placed
            .iter()
            .flat_map(|&i| v[i * w..][..w].iter().copied())
            .collect::<Vec<f64>>()
    };
    let point = (
        per_point(|t| t.h0),
        per_point(|t| t.reachable),
        flag(|t| t.placed),
        flag(|t| t.progress),
        out.hold,
    );
    let inputs = (
        matrix(py, k, 3, triples(|t| t.gx))?,
        matrix(py, k, 3, triples(|t| t.ga))?,
        per_placed(|t| t.gp).into_pyarray(py),
        per_placed(|t| t.rhs).into_pyarray(py),
        matrix(py, k, 3, of_points(&out.x0, 3))?,
        matrix(py, k, 3, of_points(&out.a0, 3))?,
        of_points(&out.psi0, 1).into_pyarray(py),
    );
    let blocks = match out.blocks {
        None => None,
        Some(b) => {
            let ((x_lo, x_hi), (a_lo, a_hi), (y_lo, y_hi)) = (b.x_bounds, b.a_bounds, b.yaw_bounds);
            Some((
                matrix(py, k, n, b.row8)?,
                matrix(py, 3 * k, n, b.rx)?,
                x_lo.into_pyarray(py),
                x_hi.into_pyarray(py),
                matrix(py, 3 * k, n, b.ra)?,
                a_lo.into_pyarray(py),
                a_hi.into_pyarray(py),
                matrix(py, k, n, b.ryaw)?,
                y_lo.into_pyarray(py),
                y_hi.into_pyarray(py),
            ))
        }
    };
    Ok((point, inputs, blocks))
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(fov_gradient_py, m)?)?;
    m.add_function(wrap_pyfunction!(fov_linearise_py, m)?)?;
    m.add_function(wrap_pyfunction!(fov_row_matrices_py, m)?)?;
    m.add_function(wrap_pyfunction!(fov_step_rows_py, m)?)?;
    m.add_function(wrap_pyfunction!(spline_visibility_py, m)?)?;
    Ok(())
}
