//! The field-of-view function `h` of the one-sided cone (7) and its analytic gradient, the
//! terms of the linearised rows (8), at a batch of points.
//!
//! `h(x, psi, a) = cos(half_fov) |n_d| - n_d . e_c` with `n_d = s - x` and the optical axis
//! `e_c = d1 b1 + d2 b2 + d3 b3` (`d = R_BC e3` in body coordinates), where the flatness map
//! (11), (13) gives `b3 = f / |f|` (`f = a + g e3`), `b1 = (b2_des x b3) / |.|`,
//! `b2 = b3 x b1` and `b2_des = (-sin psi, cos psi, 0)`. The derivatives follow the chain rule
//! through those three normalisations (`avp.qp.fov` documents the formulas). Degenerate points
//! (zero thrust, `b3 || b2_des`, `x = s`) give non-finite values, as in IEEE arithmetic; the
//! caller filters them.
use crate::error::{check_finite, Error, Result};

type V3 = [f64; 3];
type M3 = [[f64; 3]; 3];

#[inline]
fn cross(u: V3, v: V3) -> V3 {
    [
        u[1] * v[2] - u[2] * v[1],
        u[2] * v[0] - u[0] * v[2],
        u[0] * v[1] - u[1] * v[0],
    ]
}

#[inline]
fn dot(u: V3, v: V3) -> f64 {
    u[0] * v[0] + u[1] * v[1] + u[2] * v[2]
}

#[inline]
fn norm(u: V3) -> f64 {
    dot(u, u).sqrt()
}

#[inline]
fn scale(u: V3, s: f64) -> V3 {
    [u[0] * s, u[1] * s, u[2] * s]
}

/// `(I - u u^T) / n`: the Jacobian of `w / |w|` at `w` with `u = w / |w|`, `n = |w|`.
#[inline]
fn normalisation_jacobian(u: V3, n: f64) -> M3 {
    let mut m = [[0.0; 3]; 3];
    for (i, row) in m.iter_mut().enumerate() {
        for (j, x) in row.iter_mut().enumerate() {
            *x = ((i == j) as u8 as f64 - u[i] * u[j]) / n;
        }
    }
    m
}

#[inline]
fn matmul(a: &M3, b: &M3) -> M3 {
    let mut m = [[0.0; 3]; 3];
    for (i, row) in m.iter_mut().enumerate() {
        for (j, x) in row.iter_mut().enumerate() {
            *x = a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j];
        }
    }
    m
}

#[inline]
fn matvec(a: &M3, v: V3) -> V3 {
    [dot(a[0], v), dot(a[1], v), dot(a[2], v)]
}

/// `hat(w) M`: every column of `M` crossed with `w` from the left.
#[inline]
fn cross_mat(w: V3, m: &M3) -> M3 {
    let mut out = [[0.0; 3]; 3];
    for j in 0..3 {
        let c = cross(w, [m[0][j], m[1][j], m[2][j]]);
        for i in 0..3 {
            out[i][j] = c[i];
        }
    }
    out
}

/// `h`, `dh/dx` (3), `dh/dpsi`, `dh/da` (3) and `|n_d|` at one point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FovPoint {
    pub h: f64,
    pub d_x: V3,
    pub d_psi: f64,
    pub d_a: V3,
    pub distance: f64,
}

/// `h` of (7) and its gradient at one point (`axis_b`: optical axis in body coordinates).
pub fn fov_point(x: V3, psi: f64, a: V3, s: V3, axis_b: V3, cos_half: f64, g: f64) -> FovPoint {
    let n_d = [s[0] - x[0], s[1] - x[1], s[2] - x[2]];
    let dist = norm(n_d);
    let f = [a[0], a[1], a[2] + g];
    let fn_ = norm(f);
    let b3 = scale(f, 1.0 / fn_);
    let j_b3 = normalisation_jacobian(b3, fn_);
    let (sp, cp) = psi.sin_cos();
    let b2d = [-sp, cp, 0.0];
    let b2d_psi = [-cp, -sp, 0.0];
    let v = cross(b2d, b3);
    let vn = norm(v);
    let b1 = scale(v, 1.0 / vn);
    let b2 = cross(b3, b1);
    let p1 = normalisation_jacobian(b1, vn);
    let dv_a = cross_mat(b2d, &j_b3);
    let dv_psi = cross(b2d_psi, b3);
    let j_b1_a = matmul(&p1, &dv_a);
    let j_b1_psi = matvec(&p1, dv_psi);
    // b2 = b3 x b1: d b2 = hat(b3) d b1 - hat(b1) d b3
    let hb3 = cross_mat(b3, &j_b1_a);
    let hb1 = cross_mat(b1, &j_b3);
    let j_b2_psi = cross(b3, j_b1_psi);
    let [d1, d2, d3] = axis_b;
    let mut e_c = [0.0; 3];
    let mut de_psi = [0.0; 3];
    let mut de_a = [[0.0; 3]; 3];
    for i in 0..3 {
        e_c[i] = d1 * b1[i] + d2 * b2[i] + d3 * b3[i];
        de_psi[i] = d1 * j_b1_psi[i] + d2 * j_b2_psi[i];
        for j in 0..3 {
            de_a[i][j] = d1 * j_b1_a[i][j] + d2 * (hb3[i][j] - hb1[i][j]) + d3 * j_b3[i][j];
        }
    }
    let h = cos_half * dist - dot(n_d, e_c);
    let d_x = [
        e_c[0] - cos_half * (n_d[0] / dist),
        e_c[1] - cos_half * (n_d[1] / dist),
        e_c[2] - cos_half * (n_d[2] / dist),
    ];
    let d_psi = -dot(n_d, de_psi);
    let mut d_a = [0.0; 3];
    for (j, out) in d_a.iter_mut().enumerate() {
        *out = -(n_d[0] * de_a[0][j] + n_d[1] * de_a[1][j] + n_d[2] * de_a[2][j]);
    }
    FovPoint {
        h,
        d_x,
        d_psi,
        d_a,
        distance: dist,
    }
}

/// [`fov_point`] at `m` points: `x`, `a` flattened `(m, 3)`, `psi` `(m,)`.
#[allow(clippy::too_many_arguments)]
pub fn fov_gradient(
    x: &[f64],
    psi: &[f64],
    a: &[f64],
    s: &[f64],
    axis_b: &[f64],
    cos_half: f64,
    g: f64,
) -> Result<Vec<FovPoint>> {
    let m = psi.len();
    for (arg, v, n) in [
        ("x", x, 3 * m),
        ("a", a, 3 * m),
        ("s", s, 3),
        ("axis_B", axis_b, 3),
    ] {
        if v.len() != n {
            return Err(Error::Shape {
                arg,
                detail: format!("expected {n} values, got {}", v.len()),
            });
        }
    }
    check_finite("s", s)?;
    check_finite("axis_B", axis_b)?;
    check_finite("cos_half", &[cos_half])?;
    check_finite("g", &[g])?;
    let v3 = |v: &[f64], i: usize| [v[3 * i], v[3 * i + 1], v[3 * i + 2]];
    let (s, d) = (v3(s, 0), v3(axis_b, 0));
    Ok((0..m)
        .map(|i| fov_point(v3(x, i), psi[i], v3(a, i), s, d, cos_half, g))
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gradient_matches_central_differences() {
        let (x, psi, a, s) = ([0.3, -0.2, 1.0], 0.4, [0.5, -0.3, 0.2], [2.0, 0.5, 1.5]);
        let c = 0.8;
        let p = fov_point(x, psi, a, s, [1.0, 0.0, 0.0], c, 9.81);
        let hf = |x: V3, psi: f64, a: V3| fov_point(x, psi, a, s, [1.0, 0.0, 0.0], c, 9.81).h;
        let e = 1e-6;
        for k in 0..3 {
            let (mut xp, mut xm, mut ap, mut am) = (x, x, a, a);
            xp[k] += e;
            xm[k] -= e;
            ap[k] += e;
            am[k] -= e;
            assert!(((hf(xp, psi, a) - hf(xm, psi, a)) / (2.0 * e) - p.d_x[k]).abs() < 1e-7);
            assert!(((hf(x, psi, ap) - hf(x, psi, am)) / (2.0 * e) - p.d_a[k]).abs() < 1e-7);
        }
        assert!(((hf(x, psi + e, a) - hf(x, psi - e, a)) / (2.0 * e) - p.d_psi).abs() < 1e-7);
    }
}
