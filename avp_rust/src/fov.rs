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
//!
//! Built on them: [`fov_linearise`] (the terms of the rows (8), the trust box (9)'s largest
//! decrease, the point policy and whether every row holds at its linearisation point, in the
//! order of operations of the NumPy code it replaced), [`fov_row_matrices`] (the dense rows
//! (8)-(9)), [`visibility_fractions`] (the visibility score of plans, cone only) and
//! [`spline_visibility`] (the same score of plans it evaluates itself, at their
//! [`attitude_points`]).
use crate::error::{check_finite, check_len, Error, Result};

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

/// The attitude (11), (13) at one point and the values its derivatives need: `b3 = f / |f|`
/// (`f = a + g e3`), `b1 = (b2_des x b3) / |.|`, `b2 = b3 x b1`, `|f|`, `|b2_des x b3|` and
/// `(sin psi, cos psi)`. The one home of this arithmetic for [`fov_point`] and [`fov_value`].
struct Attitude {
    b1: V3,
    b2: V3,
    b3: V3,
    f_norm: f64,
    v_norm: f64,
    sin_cos: (f64, f64),
}

#[inline]
fn attitude(psi: f64, a: V3, g: f64) -> Attitude {
    let f = [a[0], a[1], a[2] + g];
    let f_norm = norm(f);
    let b3 = scale(f, 1.0 / f_norm);
    let (sp, cp) = psi.sin_cos();
    let v = cross([-sp, cp, 0.0], b3);
    let v_norm = norm(v);
    let b1 = scale(v, 1.0 / v_norm);
    Attitude {
        b1,
        b2: cross(b3, b1),
        b3,
        f_norm,
        v_norm,
        sin_cos: (sp, cp),
    }
}

/// The optical axis `e_c = d1 b1 + d2 b2 + d3 b3` in W.
#[inline]
fn optical_axis(att: &Attitude, axis_b: V3) -> V3 {
    let [d1, d2, d3] = axis_b;
    let mut e_c = [0.0; 3];
    for (i, e) in e_c.iter_mut().enumerate() {
        *e = d1 * att.b1[i] + d2 * att.b2[i] + d3 * att.b3[i];
    }
    e_c
}

/// `h` of (7) and its gradient at one point (`axis_b`: optical axis in body coordinates).
pub fn fov_point(x: V3, psi: f64, a: V3, s: V3, axis_b: V3, cos_half: f64, g: f64) -> FovPoint {
    let n_d = [s[0] - x[0], s[1] - x[1], s[2] - x[2]];
    let dist = norm(n_d);
    let att = attitude(psi, a, g);
    let (b1, b3, fn_, vn) = (att.b1, att.b3, att.f_norm, att.v_norm);
    let j_b3 = normalisation_jacobian(b3, fn_);
    let (sp, cp) = att.sin_cos;
    let b2d = [-sp, cp, 0.0];
    let b2d_psi = [-cp, -sp, 0.0];
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
    let e_c = optical_axis(&att, axis_b);
    let mut de_psi = [0.0; 3];
    let mut de_a = [[0.0; 3]; 3];
    for i in 0..3 {
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
        check_len(arg, v.len(), n)?;
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

/// What to do with a point whose row (8) cannot hold inside its trust region (9)
/// (`avp.config.FovPointPolicy`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PointPolicy {
    /// Place the row as it is.
    Keep,
    /// Leave the point without a row.
    Skip,
    /// Ask for a fraction of the reachable decrease.
    Progress,
}

impl PointPolicy {
    /// The policy named `"keep"`, `"skip"` or `"progress"`.
    pub fn from_name(name: &str) -> Result<Self> {
        match name {
            "keep" => Ok(Self::Keep),
            "skip" => Ok(Self::Skip),
            "progress" => Ok(Self::Progress),
            _ => Err(Error::Invalid {
                arg: "policy",
                detail: format!("expected \"keep\", \"skip\" or \"progress\", got {name:?}"),
            }),
        }
    }
}

/// The FoV configuration a linearisation needs (`avp.camera.FovConfig`, with the camera's
/// `cos(half_fov)`): trust radii (9) in position, acceleration and yaw (each may be infinite),
/// the row margin, the reach and progress fractions and the point policy.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinearisationSettings {
    pub cos_half: f64,
    pub g: f64,
    pub trust: [f64; 3],
    pub margin: f64,
    pub reach_fraction: f64,
    pub progress_fraction: f64,
    pub policy: PointPolicy,
}

/// One point of the linearised FoV rows (8): `h0 = h / |n_d|` at the linearisation point, the
/// gradient over `|n_d|` (`gx`, `ga`, `gp`), the smallest `h / |n_d|` reachable inside the box
/// (9), the row's right-hand side, and whether a row is placed and asks for progress only.
/// A degenerate point (non-finite `h`, `d_a`, `d_psi`, or `|n_d| <= 1e-6`) has a zero gradient,
/// `h0 = inf` and no row.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FovRowTerms {
    pub h0: f64,
    pub reachable: f64,
    pub gx: V3,
    pub ga: V3,
    pub gp: f64,
    pub rhs: f64,
    pub placed: bool,
    pub progress: bool,
}

/// `g r` for `g >= 0` with `0 inf = 0` (an infinite trust radius on a zero gradient).
#[inline]
fn times_radius(g: f64, r: f64) -> f64 {
    if r.is_finite() {
        g * r
    } else if g > 0.0 {
        f64::INFINITY
    } else {
        0.0
    }
}

/// The row terms of one point from its gradient (the operations in the order of the former
/// NumPy code, so the rows are the same bits).
pub fn row_terms(
    p: &FovPoint,
    x0: V3,
    psi0: f64,
    a0: V3,
    st: &LinearisationSettings,
) -> FovRowTerms {
    let ok = p.h.is_finite()
        && p.d_a.iter().all(|v| v.is_finite())
        && p.d_psi.is_finite()
        && p.distance > 1e-6;
    let (dist, dx, da, dp, h) = if ok {
        (p.distance, p.d_x, p.d_a, p.d_psi, p.h)
    } else {
        (1.0, [0.0; 3], [0.0; 3], 0.0, f64::INFINITY)
    };
    let gx = [dx[0] / dist, dx[1] / dist, dx[2] / dist];
    let ga = [da[0] / dist, da[1] / dist, da[2] / dist];
    let gp = dp / dist;
    let h0 = h / dist;
    let abs_sum = |v: V3| v[0].abs() + v[1].abs() + v[2].abs();
    let decrease = times_radius(abs_sum(gx), st.trust[0])
        + times_radius(abs_sum(ga), st.trust[1])
        + times_radius(gp.abs(), st.trust[2]);
    let reachable = h0 - decrease;
    let lin0 = (gx[0] * x0[0] + gx[1] * x0[1] + gx[2] * x0[2])
        + (ga[0] * a0[0] + ga[1] * a0[1] + ga[2] * a0[2])
        + gp * psi0;
    let mut rhs = lin0 - h0 - st.margin;
    let hopeless = ok && (h0 - st.reach_fraction * decrease > -st.margin);
    let mut placed = ok;
    let mut progress = false;
    match st.policy {
        PointPolicy::Keep => {}
        PointPolicy::Skip => placed = ok && !hopeless,
        PointPolicy::Progress => {
            if hopeless {
                rhs = lin0 - st.progress_fraction * decrease;
            }
            progress = hopeless;
        }
    }
    FovRowTerms {
        h0,
        reachable,
        gx,
        ga,
        gp,
        rhs,
        placed,
        progress,
    }
}

/// The linearised FoV rows (8) of `m` points (`x0`, `a0` flattened `(m, 3)`, `psi0` `(m,)`)
/// and whether every placed row holds at the linearisation point itself (`h0 <= -margin` to
/// `1e-9 (1 + |rhs|)`, and no row asks for progress).
pub fn fov_linearise(
    x0: &[f64],
    psi0: &[f64],
    a0: &[f64],
    s: &[f64],
    axis_b: &[f64],
    st: &LinearisationSettings,
) -> Result<(Vec<FovRowTerms>, bool)> {
    if st.trust.iter().any(|r| r.is_nan() || *r < 0.0) {
        return Err(Error::Invalid {
            arg: "trust",
            detail: "every radius must be >= 0 (inf: no limit)".into(),
        });
    }
    for (arg, v) in [
        ("margin", st.margin),
        ("reach_fraction", st.reach_fraction),
        ("progress_fraction", st.progress_fraction),
    ] {
        if v.is_nan() || v < 0.0 {
            return Err(Error::Invalid {
                arg,
                detail: "must be >= 0".into(),
            });
        }
    }
    for (arg, v) in [
        ("margin", st.margin),
        ("reach_fraction", st.reach_fraction),
        ("progress_fraction", st.progress_fraction),
    ] {
        check_finite(arg, &[v])?;
    }
    let points = fov_gradient(x0, psi0, a0, s, axis_b, st.cos_half, st.g)?;
    let v3 = |v: &[f64], i: usize| [v[3 * i], v[3 * i + 1], v[3 * i + 2]];
    let terms: Vec<FovRowTerms> = points
        .iter()
        .enumerate()
        .map(|(i, p)| row_terms(p, v3(x0, i), psi0[i], v3(a0, i), st))
        .collect();
    let hold = !terms.iter().any(|t| t.placed && t.progress)
        && terms
            .iter()
            .filter(|t| t.placed)
            .all(|t| t.h0 + st.margin <= 1e-9 * (1.0 + t.rhs.abs()));
    Ok((terms, hold))
}

/// Largest row width (columns) and point count [`fov_row_matrices`] accepts: far above any
/// spline here (4 axes x 3 segments x 8 coefficients = 96), far below an allocation that fails.
pub const MAX_ROW_WIDTH: usize = 1 << 16;

/// Dense FoV row matrices of `k` placed points (`avp.qp.fov.fov_rows`), for a decision vector
/// laid out `(axis * n_segments + segment) * n_coeffs + j` over 4 axes (x, y, z, yaw):
/// row (8) of point `i` has `gx[i][a] p0[i] + ga[i][a] p2[i]` on axis `a`'s columns of its
/// segment and `gp[i] p0[i]` on the yaw columns; the trust-region (9) rows `3 i + a` have
/// `p0[i]` (position) or `p2[i]` (acceleration) on axis `a`, and yaw row `i` has `p0[i]`.
/// `p0`, `p2` are `(k, n_coeffs)` basis rows, `gx`, `ga` `(k, 3)`. Returns the four matrices
/// `(k, n)`, `(3k, n)`, `(3k, n)`, `(k, n)` flattened row-major, `n = 4 n_segments n_coeffs`.
#[allow(clippy::too_many_arguments, clippy::type_complexity)]
pub fn fov_row_matrices(
    n_segments: usize,
    n_coeffs: usize,
    seg: &[i64],
    p0: &[f64],
    p2: &[f64],
    gx: &[f64],
    ga: &[f64],
    gp: &[f64],
) -> Result<(Vec<f64>, Vec<f64>, Vec<f64>, Vec<f64>)> {
    let k = seg.len();
    for (arg, v, n) in [
        ("p0", p0, k * n_coeffs),
        ("p2", p2, k * n_coeffs),
        ("gx", gx, 3 * k),
        ("ga", ga, 3 * k),
        ("gp", gp, k),
    ] {
        check_len(arg, v.len(), n)?;
    }
    // the matrices hold 8 k n values: refuse sizes no spline of this library has (and overflow)
    let n = n_segments
        .checked_mul(n_coeffs)
        .and_then(|c| c.checked_mul(4))
        .filter(|&n| n <= MAX_ROW_WIDTH)
        .ok_or_else(|| Error::Invalid {
            arg: "n_segments",
            detail: format!(
                "{n_segments} segments of {n_coeffs} coefficients exceed {MAX_ROW_WIDTH} columns"
            ),
        })?;
    if k > MAX_ROW_WIDTH {
        return Err(Error::Invalid {
            arg: "seg",
            detail: format!("{k} points exceed {MAX_ROW_WIDTH}"),
        });
    }
    let segs: Vec<usize> = seg
        .iter()
        .map(|&s| usize::try_from(s).ok().filter(|&s| s < n_segments))
        .collect::<Option<_>>()
        .ok_or_else(|| Error::Invalid {
            arg: "seg",
            detail: format!("a segment outside 0..{n_segments}"),
        })?;
    let (mut row8, mut rx, mut ra, mut ryaw) = (
        vec![0.0; k * n],
        vec![0.0; 3 * k * n],
        vec![0.0; 3 * k * n],
        vec![0.0; k * n],
    );
    for (i, &s) in segs.iter().enumerate() {
        let (b0, b2) = (
            &p0[i * n_coeffs..][..n_coeffs],
            &p2[i * n_coeffs..][..n_coeffs],
        );
        let col = |axis: usize| (axis * n_segments + s) * n_coeffs;
        for axis in 0..3 {
            let (c, g_x, g_a) = (col(axis), gx[3 * i + axis], ga[3 * i + axis]);
            for j in 0..n_coeffs {
                row8[i * n + c + j] = g_x * b0[j] + g_a * b2[j];
            }
            rx[(3 * i + axis) * n + c..][..n_coeffs].copy_from_slice(b0);
            ra[(3 * i + axis) * n + c..][..n_coeffs].copy_from_slice(b2);
        }
        let c = col(3);
        for j in 0..n_coeffs {
            row8[i * n + c + j] = gp[i] * b0[j];
        }
        ryaw[i * n + c..][..n_coeffs].copy_from_slice(b0);
    }
    Ok((row8, rx, ra, ryaw))
}

/// `h` of (7) and `|n_d|` at one point, without the gradient: the same operations as
/// [`fov_point`] for these two values, so the sign of `h` is the same bit for bit.
pub fn fov_value(x: V3, psi: f64, a: V3, s: V3, axis_b: V3, cos_half: f64, g: f64) -> (f64, f64) {
    let n_d = [s[0] - x[0], s[1] - x[1], s[2] - x[2]];
    let dist = norm(n_d);
    let e_c = optical_axis(&attitude(psi, a, g), axis_b);
    (cos_half * dist - dot(n_d, e_c), dist)
}

/// Visibility of the point `s` from `k` plans on the same knots (`avp.metrics.visibility_many`,
/// cone (7) only). `flat` holds the plans' flat outputs at the increasing `times` `(n,)` as
/// `(2, n, k, 4)`: position and yaw (order 0), then the acceleration (order 2; its yaw entry
/// unused), the layout `avp._avp_rust.eval_spline` returns for orders `[0, 2]` on the plans'
/// stacked coefficients. Per plan: the trapezoid-weighted fraction of the time and of the path
/// length (chords between samples) with the point in view (`h <= 0`, `|n_d| > 1e-12`; a NaN
/// `h` is not in view), and the first sample time (of the first `n - 1`) out of view, NaN when
/// there is none. With a zero path length the path fraction is the time fraction.
#[allow(clippy::too_many_arguments)]
pub fn visibility_fractions(
    times: &[f64],
    flat: &[f64],
    k: usize,
    s: &[f64],
    axis_b: &[f64],
    cos_half: f64,
    g: f64,
) -> Result<Vec<(f64, f64, f64)>> {
    let n = times.len();
    for (arg, v, len) in [
        ("flat", flat, 2 * n * k * 4),
        ("s", s, 3),
        ("axis_B", axis_b, 3),
    ] {
        check_len(arg, v.len(), len)?;
    }
    if n < 2 {
        return Err(Error::Shape {
            arg: "times",
            detail: format!("need at least 2 samples, got {n}"),
        });
    }
    check_finite("s", s)?;
    check_finite("axis_B", axis_b)?;
    check_finite("cos_half", &[cos_half])?;
    check_finite("g", &[g])?;
    let (sv, d) = ([s[0], s[1], s[2]], [axis_b[0], axis_b[1], axis_b[2]]);
    let at = |order: usize, i: usize, j: usize| &flat[((order * n + i) * k + j) * 4..][..4];
    let pos = |i: usize, j: usize| {
        let p = at(0, i, j);
        [p[0], p[1], p[2]]
    };
    let mut total_t = 0.0;
    for i in 0..n - 1 {
        total_t += times[i + 1] - times[i];
    }
    let mut out = Vec::with_capacity(k);
    for j in 0..k {
        let seen = |i: usize| {
            let (p, a) = (at(0, i, j), at(1, i, j));
            let (h, dist) = fov_value(
                [p[0], p[1], p[2]],
                p[3],
                [a[0], a[1], a[2]],
                sv,
                d,
                cos_half,
                g,
            );
            if h <= 0.0 && dist > 1e-12 {
                1.0
            } else {
                0.0
            }
        };
        let (mut in_t, mut in_s, mut total_s, mut first_lost) = (0.0, 0.0, 0.0, f64::NAN);
        let mut f0 = seen(0);
        for i in 0..n - 1 {
            if f0 < 0.5 && first_lost.is_nan() {
                first_lost = times[i];
            }
            let f1 = seen(i + 1);
            let w = 0.5 * (f0 + f1);
            let (p, q) = (pos(i, j), pos(i + 1, j));
            let ds = norm([q[0] - p[0], q[1] - p[1], q[2] - p[2]]);
            in_t += w * (times[i + 1] - times[i]);
            in_s += w * ds;
            total_s += ds;
            f0 = f1;
        }
        let tf = if total_t > 0.0 { in_t / total_t } else { 0.0 };
        let pf = if total_s > 0.0 { in_s / total_s } else { tf };
        out.push((tf, pf, first_lost));
    }
    Ok(out)
}

/// The flat outputs of the plans in `spline` (axes x, y, z, yaw of each plan in turn) that set
/// the attitude, at its relative `times`: position and yaw (order 0), then the acceleration of
/// the thrust direction, `a + d v` with rotor drag `d > 0` (`avp.frames.drag_acceleration`; the
/// yaw entry is the yaw's second derivative, unused). Laid out `(2, n, axes)`, as
/// `avp._avp_rust.eval_spline` gives orders `[0, 2]`, whose values they are when `d = 0`.
pub fn attitude_points(
    spline: &crate::spline::SplineView<'_>,
    times: &[f64],
    rotor_drag: f64,
) -> Result<Vec<f64>> {
    if rotor_drag.is_nan() || rotor_drag < 0.0 || rotor_drag.is_infinite() {
        return Err(Error::Invalid {
            arg: "rotor_drag",
            detail: format!("must be finite and >= 0, got {rotor_drag}"),
        });
    }
    if rotor_drag == 0.0 {
        return crate::spline::evaluate(spline, times, &[0, 2]);
    }
    let block = times.len() * spline.n_axes();
    let mut pva = crate::spline::evaluate(spline, times, &[0, 1, 2])?;
    let (pv, acc) = pva.split_at_mut(2 * block);
    for (a4, v4) in acc.chunks_exact_mut(4).zip(pv[block..].chunks_exact(4)) {
        for c in 0..3 {
            a4[c] += rotor_drag * v4[c];
        }
    }
    pva.drain(block..2 * block);
    Ok(pva)
}

/// [`visibility_fractions`] of the `k = axes / 4` plans whose stacked coefficients `spline`
/// holds (axes x, y, z, yaw of each plan in turn, all on the same knots) at its relative
/// `times`, at their [`attitude_points`] (with rotor drag `d > 0` the thrust direction
/// `a + d v`), in one call.
pub fn spline_visibility(
    spline: &crate::spline::SplineView<'_>,
    times: &[f64],
    rotor_drag: f64,
    s: &[f64],
    axis_b: &[f64],
    cos_half: f64,
    g: f64,
) -> Result<Vec<(f64, f64, f64)>> {
    let axes = spline.n_axes();
    if axes % 4 != 0 {
        return Err(Error::Shape {
            arg: "coeffs",
            detail: format!("{axes} axes are not (x, y, z, yaw) of whole plans"),
        });
    }
    let flat = attitude_points(spline, times, rotor_drag)?;
    visibility_fractions(times, &flat, axes / 4, s, axis_b, cos_half, g)
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

    fn settings(policy: PointPolicy, trust: [f64; 3]) -> LinearisationSettings {
        LinearisationSettings {
            cos_half: 0.8,
            g: 9.81,
            trust,
            margin: 0.01,
            reach_fraction: 0.9,
            progress_fraction: 0.5,
            policy,
        }
    }

    #[test]
    fn visible_point_holds_and_hopeless_point_follows_the_policy() {
        // hovering 3 m in front of the pad, camera along b1 (x): visible, the row holds
        let axis = [1.0, 0.0, 0.0];
        let (x, a, s) = ([0.0, 0.0, 1.0], [0.0, 0.0, 0.0], [3.0, 0.0, 1.0]);
        let st = settings(PointPolicy::Skip, [0.05, 0.2, f64::INFINITY]);
        let (t, hold) = fov_linearise(&x, &[0.0], &a, &s, &axis, &st).unwrap();
        assert!(t[0].placed && !t[0].progress && t[0].h0 < -st.margin && hold);
        // the pad behind the vehicle: h0 = (cos + 1) |n_d| / |n_d| > 0, not reachable in a small box
        let behind = [-3.0, 0.0, 1.0];
        let tight = [0.05, 0.2, 0.1];
        for (policy, placed, progress) in [
            (PointPolicy::Skip, false, false),
            (PointPolicy::Keep, true, false),
            (PointPolicy::Progress, true, true),
        ] {
            let st = settings(policy, tight);
            let (t, hold) = fov_linearise(&x, &[0.0], &a, &behind, &axis, &st).unwrap();
            assert!((t[0].h0 - 1.8).abs() < 1e-12, "{}", t[0].h0);
            assert_eq!((t[0].placed, t[0].progress), (placed, progress));
            assert_eq!(hold, !placed, "{policy:?}");
            assert!(t[0].reachable < t[0].h0);
        }
    }

    #[test]
    fn degenerate_point_gets_no_row_and_infinite_radius_no_nan() {
        let axis = [1.0, 0.0, 0.0];
        let st = settings(PointPolicy::Keep, [f64::INFINITY; 3]);
        // at the target (|n_d| = 0) and one regular point with a zero yaw gradient
        let (t, _) = fov_linearise(
            &[3.0, 0.0, 1.0, 0.0, 0.0, 1.0],
            &[0.0, 0.0],
            &[0.0; 6],
            &[3.0, 0.0, 1.0],
            &axis,
            &st,
        )
        .unwrap();
        assert!(!t[0].placed && t[0].h0.is_infinite() && t[0].gx == [0.0; 3]);
        assert!(t[1].placed && !t[1].reachable.is_nan());
        let bad = LinearisationSettings { margin: -1.0, ..st };
        assert_eq!(
            fov_linearise(&[0.0; 3], &[0.0], &[0.0; 3], &[1.0; 3], &axis, &bad)
                .unwrap_err()
                .arg(),
            "margin"
        );
        assert_eq!(PointPolicy::from_name("all").unwrap_err().arg(), "policy");
    }

    #[test]
    fn row_matrices_place_each_point_in_its_segment() {
        // 2 segments, 3 coefficients: n = 24; one point in segment 1
        let (p0, p2) = ([1.0, 2.0, 3.0], [4.0, 5.0, 6.0]);
        let (r8, rx, ra, ry) = fov_row_matrices(
            2,
            3,
            &[1],
            &p0,
            &p2,
            &[1.0, 0.0, -1.0],
            &[0.5, 0.0, 0.0],
            &[2.0],
        )
        .unwrap();
        assert_eq!((r8.len(), rx.len(), ra.len(), ry.len()), (24, 72, 72, 24));
        // axis x, segment 1: columns 3..6
        assert_eq!(&r8[3..6], &[1.0 + 2.0, 2.0 + 2.5, 3.0 + 3.0]);
        assert_eq!(&r8[9..12], &[0.0; 3]); // y: zero gradient
        assert_eq!(&r8[15..18], &[-1.0, -2.0, -3.0]); // z
        assert_eq!(&r8[21..24], &[2.0, 4.0, 6.0]); // yaw
        assert_eq!(&rx[24 + 9..24 + 12], &p0); // row 1 (y) on y's columns
        assert_eq!(&ra[48 + 15..48 + 18], &p2); // row 2 (z)
        assert_eq!(&ry[21..24], &p0);
        assert_eq!(
            fov_row_matrices(2, 3, &[2], &p0, &p2, &[0.0; 3], &[0.0; 3], &[0.0])
                .unwrap_err()
                .arg(),
            "seg"
        );
        assert_eq!(
            fov_row_matrices(2, 3, &[0], &p0[..2], &p2, &[0.0; 3], &[0.0; 3], &[0.0])
                .unwrap_err()
                .arg(),
            "p0"
        );
        let zero3 = [0.0; 3];
        let huge = fov_row_matrices(1 << 40, 3, &[0], &p0, &p2, &zero3, &zero3, &[0.0]);
        assert_eq!(huge.unwrap_err().arg(), "n_segments"); // an error, not an allocation abort
        let negative = fov_row_matrices(2, 3, &[-1], &p0, &p2, &zero3, &zero3, &[0.0]);
        assert_eq!(negative.unwrap_err().arg(), "seg");
    }

    #[test]
    fn value_matches_the_gradient_kernel_and_fractions_count_the_view() {
        let (s, axis) = ([3.0, 0.0, 1.0], [1.0, 0.0, 0.0]);
        for (x, psi, a) in [
            ([0.0, 0.0, 1.0], 0.0, [0.0; 3]),
            ([0.5, -1.0, 2.0], 1.3, [2.0, -1.0, 0.5]),
        ] {
            let p = fov_point(x, psi, a, s, axis, 0.8, 9.81);
            assert_eq!(fov_value(x, psi, a, s, axis, 0.8, 9.81), (p.h, p.distance));
        }
        // one plan flying along x towards the pad, facing it for the first half, then yawed away
        let times: Vec<f64> = (0..5).map(|i| i as f64).collect();
        let yaws = [0.0, 0.0, 0.0, 3.0, 3.0];
        let mut flat = vec![0.0; 2 * 5 * 4]; // (2, n = 5, k = 1, 4); accelerations zero
        for i in 0..5 {
            flat[i * 4..i * 4 + 4].copy_from_slice(&[i as f64 * 0.1, 0.0, 1.0, yaws[i]]);
        }
        let r = visibility_fractions(&times, &flat, 1, &s, &axis, 0.8, 9.81).unwrap();
        // flags 1 1 1 0 0: trapezoid weights 1, 1, 0.5, 0 over four unit intervals
        assert_eq!(r[0].0, 2.5 / 4.0);
        assert!((r[0].1 - 2.5 / 4.0).abs() < 1e-15);
        assert_eq!(r[0].2, 3.0);
        assert_eq!(
            visibility_fractions(&times[..1], &flat[..8], 1, &s, &axis, 0.8, 9.81)
                .unwrap_err()
                .arg(),
            "times"
        );
    }

    #[test]
    fn spline_visibility_equals_the_fractions_of_its_evaluated_points() {
        // two plans of one segment on [0, 2] (degree 2), stacked: 8 axes
        let c = vec![
            0.0, 1.0, 0.0, 0.0, 0.0, 0.5, 1.0, 0.0, 0.0, 0.2, 0.0, 0.0, // plan 0
            0.0, 1.0, 0.2, 0.5, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.1, 0.0, // plan 1
        ];
        let knots = [0.0, 2.0];
        let view = crate::spline::SplineView::new(&c, (1, 8, 3), &knots).unwrap();
        let times: Vec<f64> = (0..=20).map(|i| 0.1 * i as f64).collect();
        let (s, axis) = ([3.0, 0.5, 1.0], [1.0, 0.0, 0.0]);
        for drag in [0.0, 0.4] {
            let got = spline_visibility(&view, &times, drag, &s, &axis, 0.7, 9.81).unwrap();
            let pva = crate::spline::evaluate(&view, &times, &[0, 1, 2]).unwrap();
            let block = times.len() * 8;
            let mut flat = pva[..block].to_vec();
            flat.extend(
                pva[2 * block..]
                    .iter()
                    .zip(&pva[block..2 * block])
                    .enumerate()
                    .map(|(i, (a, v))| if i % 4 < 3 { a + drag * v } else { *a }),
            );
            let want = visibility_fractions(&times, &flat, 2, &s, &axis, 0.7, 9.81).unwrap();
            assert_eq!(format!("{got:?}"), format!("{want:?}"));
        }
        let five = crate::spline::SplineView::new(&c[..15], (1, 5, 3), &knots).unwrap();
        let err = spline_visibility(&five, &times, 0.0, &s, &axis, 0.7, 9.81).unwrap_err();
        assert_eq!(err.arg(), "coeffs");
    }
}
