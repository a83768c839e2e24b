//! The FoV rows (8) and trust region (9) of one SQP step, linearised on a reference plan
//! (`avp.perception.linearise_on`): the reference's position, yaw and acceleration at the
//! points ([`crate::spline::evaluate`]), their row terms ([`crate::fov::fov_linearise`]), the
//! placed points' dense rows ([`crate::fov::fov_row_matrices`]) and the trust region's bounds,
//! in one call. Each part is the kernel the step used one call at a time, in the same order of
//! operations, so the rows are the same bits as `avp.qp.fov.fov_blocks` gives on the
//! evaluated points.
use crate::error::{check_len, Error, Result};
use crate::fov::{
    attitude_points, fov_linearise, fov_row_matrices, FovRowTerms, LinearisationSettings,
};
use crate::spline::SplineView;

/// The basis rows of the `m` points on the QP's spline (`avp.qp.fov._point_basis`): each
/// point's segment, its position basis `p0` and the basis `p2` of the rows' acceleration
/// variable, `(m, n_coeffs)` row-major.
pub struct PointBasis<'a> {
    pub n_segments: usize,
    pub seg: &'a [i64],
    pub p0: &'a [f64],
    pub p2: &'a [f64],
}

/// The rows of one linearisation: per point (`m`) the terms and the linearisation point, the
/// placed points' indices, and their blocks when asked for.
#[derive(Debug, Clone, PartialEq)]
pub struct StepRows {
    pub terms: Vec<FovRowTerms>,
    pub hold: bool,
    pub x0: Vec<f64>,
    pub psi0: Vec<f64>,
    pub a0: Vec<f64>,
    pub placed: Vec<usize>,
    pub blocks: Option<StepBlocks>,
}

/// Per placed point (`k`, in order) the row (8) `(k, n)`, and the trust region (9) in position
/// `(3k, n)`, acceleration `(3k, n)` and yaw `(k, n)` with their bounds (the linearisation point
/// minus and plus the radius).
#[derive(Debug, Clone, PartialEq)]
pub struct StepBlocks {
    pub row8: Vec<f64>,
    pub rx: Vec<f64>,
    pub ra: Vec<f64>,
    pub ryaw: Vec<f64>,
    pub x_bounds: (Vec<f64>, Vec<f64>),
    pub a_bounds: (Vec<f64>, Vec<f64>),
    pub yaw_bounds: (Vec<f64>, Vec<f64>),
}

/// The rows at the points `x0 (m, 3)`, `psi0 (m,)`, `a0 (m, 3)` (flattened row-major), with
/// their blocks when `build` (a caller that first asks whether the rows hold at the
/// linearisation point itself may never need them; `basis` is read only then).
#[allow(clippy::too_many_arguments)]
pub fn rows_at_points(
    x0: Vec<f64>,
    psi0: Vec<f64>,
    a0: Vec<f64>,
    s: &[f64],
    axis_b: &[f64],
    st: &LinearisationSettings,
    basis: &PointBasis<'_>,
    build: bool,
) -> Result<StepRows> {
    let m = psi0.len();
    check_len("x0", x0.len(), 3 * m)?;
    check_len("a0", a0.len(), 3 * m)?;
    if m == 0 {
        return Err(Error::Shape {
            arg: "psi0",
            detail: "no points: linearise at one point at least".into(),
        });
    }
    let (terms, hold) = fov_linearise(&x0, &psi0, &a0, s, axis_b, st)?;
    let placed: Vec<usize> = (0..m).filter(|&i| terms[i].placed).collect();
    if !build {
        return Ok(StepRows {
            terms,
            hold,
            x0,
            psi0,
            a0,
            placed,
            blocks: None,
        });
    }
    check_len("seg", basis.seg.len(), m)?;
    if basis.p0.len() % m != 0 {
        return Err(Error::Shape {
            arg: "p0",
            detail: format!(
                "{} values are not one basis row for each of {m} points",
                basis.p0.len()
            ),
        });
    }
    let n_coeffs = basis.p0.len() / m;
    check_len("p2", basis.p2.len(), m * n_coeffs)?;
    let gather = |v: &[f64], w: usize| -> Vec<f64> {
        placed
            .iter()
            .flat_map(|&i| v[i * w..][..w].iter().copied())
            .collect()
    };
    let seg: Vec<i64> = placed.iter().map(|&i| basis.seg[i]).collect();
    let gx: Vec<f64> = placed.iter().flat_map(|&i| terms[i].gx).collect();
    let ga: Vec<f64> = placed.iter().flat_map(|&i| terms[i].ga).collect();
    let gp: Vec<f64> = placed.iter().map(|&i| terms[i].gp).collect();
    let (row8, rx, ra, ryaw) = fov_row_matrices(
        basis.n_segments,
        n_coeffs,
        &seg,
        &gather(basis.p0, n_coeffs),
        &gather(basis.p2, n_coeffs),
        &gx,
        &ga,
        &gp,
    )?;
    let around = |v: Vec<f64>, r: f64| -> (Vec<f64>, Vec<f64>) {
        (
            v.iter().map(|z| z - r).collect(),
            v.iter().map(|z| z + r).collect(),
        )
    };
    let x_bounds = around(gather(&x0, 3), st.trust[0]);
    let a_bounds = around(gather(&a0, 3), st.trust[1]);
    let yaw_bounds = around(gather(&psi0, 1), st.trust[2]);
    Ok(StepRows {
        terms,
        hold,
        x0,
        psi0,
        a0,
        placed,
        blocks: Some(StepBlocks {
            row8,
            rx,
            ra,
            ryaw,
            x_bounds,
            a_bounds,
            yaw_bounds,
        }),
    })
}

/// The rows at the points of the `reference` spline (axes x, y, z, yaw) at its relative times
/// `tau`: its [`attitude_points`] (position and yaw, and the thrust direction's acceleration
/// `a + d v` with rotor drag `d > 0`).
#[allow(clippy::too_many_arguments)]
pub fn rows_on_spline(
    reference: &SplineView<'_>,
    tau: &[f64],
    rotor_drag: f64,
    s: &[f64],
    axis_b: &[f64],
    st: &LinearisationSettings,
    basis: &PointBasis<'_>,
    build: bool,
) -> Result<StepRows> {
    if reference.n_axes() != 4 {
        return Err(Error::Shape {
            arg: "coeffs",
            detail: format!("expected 4 axes (x, y, z, yaw), got {}", reference.n_axes()),
        });
    }
    let m = tau.len();
    // [order 0, then the thrust acceleration][time][axis]
    let d = attitude_points(reference, tau, rotor_drag)?;
    let mut x0 = Vec::with_capacity(3 * m);
    let mut a0 = Vec::with_capacity(3 * m);
    let mut psi0 = Vec::with_capacity(m);
    for (p, a) in d[..4 * m].chunks_exact(4).zip(d[4 * m..].chunks_exact(4)) {
        x0.extend_from_slice(&p[..3]);
        psi0.push(p[3]);
        a0.extend_from_slice(&a[..3]);
    }
    rows_at_points(x0, psi0, a0, s, axis_b, st, basis, build)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fov::PointPolicy;

    fn settings() -> LinearisationSettings {
        LinearisationSettings {
            cos_half: 0.8,
            g: 9.81,
            trust: [0.2, 1.0, f64::INFINITY],
            margin: 0.0,
            reach_fraction: 0.9,
            progress_fraction: 0.5,
            policy: PointPolicy::Keep,
        }
    }

    /// One segment of degree 2 on [0, 2]: x = 1 + t, y = 0.5 t^2, z = 2, yaw = 0.1 t.
    fn spline() -> (Vec<f64>, Vec<f64>) {
        let c = vec![1.0, 1.0, 0.0, 0.0, 0.0, 0.5, 2.0, 0.0, 0.0, 0.0, 0.1, 0.0];
        (c, vec![0.0, 2.0])
    }

    #[test]
    fn on_a_spline_equals_at_its_evaluated_points() {
        let (c, k) = spline();
        let view = SplineView::new(&c, (1, 4, 3), &k).unwrap();
        let tau = [0.5, 1.5];
        let basis_p0 = [1.0, 0.5, 0.25, 1.0, 1.5, 2.25];
        let basis_p2 = [0.0, 0.0, 2.0, 0.0, 0.0, 2.0];
        let basis = PointBasis {
            n_segments: 1,
            seg: &[0, 0],
            p0: &basis_p0,
            p2: &basis_p2,
        };
        let (s, axis) = ([5.0, 1.0, 2.0], [1.0, 0.0, 0.0]);
        for drag in [0.0, 0.3] {
            let on =
                rows_on_spline(&view, &tau, drag, &s, &axis, &settings(), &basis, true).unwrap();
            // the points by hand: x = (1 + t, 0.5 t^2, 2), v = (1, t, 0), a = (0, 1, 0), yaw 0.1 t
            let mut x0 = vec![];
            let mut a0 = vec![];
            for t in tau {
                x0.extend([1.0 + t, 0.5 * t * t, 2.0]);
                a0.extend([0.0 + drag * 1.0, 1.0 + drag * t, 0.0 + drag * 0.0]);
            }
            let psi0 = tau.iter().map(|t| 0.1 * t).collect();
            let at = rows_at_points(x0, psi0, a0, &s, &axis, &settings(), &basis, true).unwrap();
            assert_eq!(on, at);
            assert_eq!(on.placed, vec![0, 1]);
            let blocks = on.blocks.as_ref().unwrap();
            assert_eq!(blocks.x_bounds.0[0], 1.5 - 0.2);
            assert_eq!(blocks.yaw_bounds.1[1], f64::INFINITY);
            assert_eq!(blocks.row8.len(), 2 * 12);
            let terms_only =
                rows_on_spline(&view, &tau, drag, &s, &axis, &settings(), &basis, false).unwrap();
            assert_eq!(terms_only, StepRows { blocks: None, ..on });
        }
    }

    #[test]
    fn bad_inputs_name_their_argument() {
        let (c, k) = spline();
        let view = SplineView::new(&c, (1, 4, 3), &k).unwrap();
        let p = [1.0, 0.5, 0.25];
        let basis = PointBasis {
            n_segments: 1,
            seg: &[0],
            p0: &p,
            p2: &p,
        };
        let (s, axis) = ([5.0, 1.0, 2.0], [1.0, 0.0, 0.0]);
        let err =
            rows_on_spline(&view, &[0.5], -1.0, &s, &axis, &settings(), &basis, true).unwrap_err();
        assert_eq!(err.arg(), "rotor_drag");
        let short = PointBasis {
            n_segments: 1,
            seg: &[0, 0],
            p0: &p,
            p2: &p,
        };
        let err =
            rows_on_spline(&view, &[0.5], 0.0, &s, &axis, &settings(), &short, true).unwrap_err();
        assert_eq!(err.arg(), "seg");
        let three = SplineView::new(&c[..9], (1, 3, 3), &k).unwrap();
        let err =
            rows_on_spline(&three, &[0.5], 0.0, &s, &axis, &settings(), &basis, true).unwrap_err();
        assert_eq!(err.arg(), "coeffs");
    }
}
