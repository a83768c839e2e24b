//! Inequality rows added to a QP whose equalities are already eliminated
//! (`avp.qp.assemble.PerchingQp.with_inequalities`): their rows in the reduced variable `z`
//! (`c = c_p + Z z`) and in the least-distance variable `u = R z` (`R` the upper-triangular
//! Cholesky factor of the reduced Hessian), appended to the QP's existing rows.
//!
//! An SQP step of the FoV stage adds some fifty rows to a QP of a few dozen variables; in NumPy
//! that is a dozen calls (stacking, two products, a triangular solve, the concatenations), each
//! costing more than its arithmetic. Here it is one pass. Products are summed left to right and
//! the triangular solve is a plain forward substitution, so the figures can differ from BLAS's in
//! the last bits; they are compared with tolerances only.
use crate::error::{check_len, Error, Result};

/// One block of two-sided rows `lower <= matrix c <= upper`, `matrix` row-major with `n`
/// columns.
pub struct RowBlock<'a> {
    pub matrix: &'a [f64],
    pub lower: &'a [f64],
    pub upper: &'a [f64],
}

/// The elimination `c = c_p + Z z` (`z` row-major `(n, m)`) and, when the reduced Hessian has
/// one, its upper-triangular Cholesky factor `r` (row-major `(m, m)`, nonzero diagonal).
pub struct Elimination<'a> {
    pub z: &'a [f64],
    pub c_p: &'a [f64],
    pub r: Option<&'a [f64]>,
}

/// Rows of a QP in the coefficients `c` (`g`, `lower`, `upper`), in `z` (`g_z`, `lower_z`,
/// `upper_z`) and in `u = R z` (`m_rows`: `None` without a factor, or when a row is not finite:
/// a nearly singular factor), all row-major.
#[derive(Debug, Clone, PartialEq)]
pub struct QpRows {
    pub g: Vec<f64>,
    pub lower: Vec<f64>,
    pub upper: Vec<f64>,
    pub g_z: Vec<f64>,
    pub lower_z: Vec<f64>,
    pub upper_z: Vec<f64>,
    pub m_rows: Option<Vec<f64>>,
}

impl QpRows {
    /// A QP's rows so far, to append to (`m_rows`: `None` when it has no least-distance form),
    /// with room for `extra` more rows of `(n, m)` columns (in `c` and in `z`), so that appending
    /// them copies the rows so far once, not twice.
    #[allow(clippy::too_many_arguments)]
    pub fn with_room(
        extra: usize,
        (n, m): (usize, usize),
        g: &[f64],
        lower: &[f64],
        upper: &[f64],
        g_z: &[f64],
        lower_z: &[f64],
        upper_z: &[f64],
        m_rows: Option<&[f64]>,
    ) -> Self {
        let copy = |v: &[f64], more: usize| {
            let mut out = Vec::with_capacity(v.len() + more);
            out.extend_from_slice(v);
            out
        };
        QpRows {
            g: copy(g, extra * n),
            lower: copy(lower, extra),
            upper: copy(upper, extra),
            g_z: copy(g_z, extra * m),
            lower_z: copy(lower_z, extra),
            upper_z: copy(upper_z, extra),
            m_rows: m_rows.map(|v| copy(v, extra * m)),
        }
    }
}

/// Appends `blocks` to `rows` (a QP on `n = c_p.len()` coefficients and `m` reduced variables,
/// `Z` being `(n, m)`): `G` and the bounds as given; `G Z` and the bounds minus `G c_p`; and,
/// when `rows` has least-distance rows and `elim` a factor, `M = G Z R^-1` by forward
/// substitution (`M R = G Z`). New least-distance rows that are not all finite drop them
/// (`m_rows = None`: the back-end then takes the QP in `z`).
pub fn append_rows(
    mut rows: QpRows,
    blocks: &[RowBlock<'_>],
    elim: &Elimination<'_>,
) -> Result<QpRows> {
    let n = elim.c_p.len();
    if n == 0 {
        return Err(Error::Invalid {
            arg: "c_p",
            detail: "the QP has no coefficients".into(),
        });
    }
    if elim.z.len() % n != 0 {
        return Err(Error::Shape {
            arg: "z",
            detail: format!("{} values are not (n, m) rows for n = {n}", elim.z.len()),
        });
    }
    let m = elim.z.len() / n;
    let k0 = rows.lower.len();
    check_len("g", rows.g.len(), k0 * n)?;
    check_len("upper", rows.upper.len(), k0)?;
    check_len("g_z", rows.g_z.len(), k0 * m)?;
    check_len("lower_z", rows.lower_z.len(), k0)?;
    check_len("upper_z", rows.upper_z.len(), k0)?;
    if let Some(mr) = &rows.m_rows {
        check_len("m_rows", mr.len(), k0 * m)?;
    }
    if let Some(r) = elim.r {
        check_len("r", r.len(), m * m)?;
    }
    for b in blocks {
        let k = b.lower.len();
        check_len("blocks.matrix", b.matrix.len(), k * n)?;
        check_len("blocks.upper", b.upper.len(), k)?;
    }
    if elim.r.is_none() {
        rows.m_rows = None; // no factor: no least-distance rows for the new ones either
    }
    let k0z = rows.g_z.len();
    let mut gz = vec![0.0; m];
    for b in blocks {
        rows.g.extend_from_slice(b.matrix);
        rows.lower.extend_from_slice(b.lower);
        rows.upper.extend_from_slice(b.upper);
        for ((row, &lo), &hi) in b.matrix.chunks_exact(n).zip(b.lower).zip(b.upper) {
            gz.iter_mut().for_each(|v| *v = 0.0);
            let mut gc = 0.0;
            for (p, (&gp, &cp)) in row.iter().zip(elim.c_p).enumerate() {
                if gp != 0.0 {
                    gc += gp * cp;
                    for (acc, &zv) in gz.iter_mut().zip(&elim.z[p * m..(p + 1) * m]) {
                        *acc += gp * zv;
                    }
                }
            }
            rows.g_z.extend_from_slice(&gz);
            rows.lower_z.push(lo - gc);
            rows.upper_z.push(hi - gc);
        }
    }
    if let (Some(r), Some(mr)) = (elim.r, rows.m_rows.as_mut()) {
        let new = &rows.g_z[k0z..];
        let finite = forward_substitution(new, r, m, mr);
        if !finite {
            rows.m_rows = None;
        }
    }
    Ok(rows)
}

/// Appends to `out` the rows `M` (row-major, `k = gz.len() / m` of them) with `M R = gz`, `r`
/// upper triangular `(m, m)` row-major; whether they are all finite. All rows at once, column
/// by column (`u_j = w_j / R_jj`, then `w_l -= R_jl u_j` for `l > j`) on the transposed rows,
/// so each step is one pass over the `k` rows, not a chain of dependent operations.
fn forward_substitution(gz: &[f64], r: &[f64], m: usize, out: &mut Vec<f64>) -> bool {
    if m == 0 || gz.is_empty() {
        return true; // no variables (rows of no columns) or no rows
    }
    let k = gz.len() / m;
    let mut w = vec![0.0; m * k]; // column j of the rows at w[j k..(j + 1) k]
    for (i, row) in gz.chunks_exact(m).enumerate() {
        for (j, &v) in row.iter().enumerate() {
            w[j * k + i] = v;
        }
    }
    for j in 0..m {
        let (head, tail) = w.split_at_mut((j + 1) * k);
        let u = &mut head[j * k..];
        let d = r[j * m + j];
        u.iter_mut().for_each(|v| *v /= d);
        for (wl, &rjl) in tail.chunks_exact_mut(k).zip(&r[j * m + j + 1..(j + 1) * m]) {
            if rjl != 0.0 {
                for (a, &uj) in wl.iter_mut().zip(u.iter()) {
                    *a -= rjl * uj;
                }
            }
        }
    }
    let start = out.len();
    out.resize(start + k * m, 0.0);
    for (i, row) in out[start..].chunks_exact_mut(m).enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            *v = w[j * k + i];
        }
    }
    w.iter().all(|v| v.is_finite())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `M R` multiplied back: the forward substitution's oracle.
    fn times_r(mrow: &[f64], r: &[f64], m: usize) -> Vec<f64> {
        (0..m)
            .map(|j| (0..=j).map(|l| mrow[l] * r[l * m + j]).sum())
            .collect()
    }

    fn empty(with_m: bool) -> QpRows {
        QpRows::with_room(
            0,
            (0, 0),
            &[],
            &[],
            &[],
            &[],
            &[],
            &[],
            if with_m { Some(&[]) } else { None },
        )
    }

    #[test]
    fn rows_in_z_and_u_match_their_definitions() {
        // n = 3 coefficients, m = 2 reduced variables
        let z = [1.0, 0.5, -2.0, 1.0, 0.25, 3.0];
        let c_p = [0.5, -1.0, 2.0];
        let r = [2.0, -1.0, 0.0, 4.0];
        let elim = Elimination {
            z: &z,
            c_p: &c_p,
            r: Some(&r),
        };
        let g = [1.0, 2.0, 0.0, 0.0, -1.0, 3.0];
        let (lo, hi) = ([-1.0, f64::NEG_INFINITY], [1.0, 5.0]);
        let block = RowBlock {
            matrix: &g,
            lower: &lo,
            upper: &hi,
        };
        let out = append_rows(empty(true), &[block], &elim).unwrap();
        assert_eq!(out.g, g.to_vec());
        // G Z by hand: row 0 = [1 + 2 * -2, 0.5 + 2 * 1] = [-3, 2.5]; row 1 = [2 + 0.75, -1 + 9]
        assert_eq!(out.g_z, vec![-3.0, 2.5, 2.75, 8.0]);
        // G c_p: row 0 = 0.5 - 2 = -1.5; row 1 = 1 + 6 = 7
        assert_eq!(out.lower_z, vec![0.5, f64::NEG_INFINITY]);
        assert_eq!(out.upper_z, vec![2.5, -2.0]);
        let mr = out.m_rows.unwrap();
        for i in 0..2 {
            let back = times_r(&mr[2 * i..2 * i + 2], &r, 2);
            for (b, g) in back.iter().zip(&out.g_z[2 * i..2 * i + 2]) {
                assert!((b - g).abs() < 1e-14);
            }
        }
    }

    #[test]
    fn appends_after_the_existing_rows_and_keeps_them() {
        let z = [1.0, 0.0, 0.0, 1.0];
        let c_p = [0.0, 0.0];
        let r = [1.0, 0.0, 0.0, 1.0];
        let elim = Elimination {
            z: &z,
            c_p: &c_p,
            r: Some(&r),
        };
        let rows = QpRows::with_room(
            0,
            (0, 0),
            &[7.0, 8.0],
            &[-1.0],
            &[1.0],
            &[7.0, 8.0],
            &[-1.0],
            &[1.0],
            Some(&[7.0, 8.0]),
        );
        let g = [0.0, 2.0];
        let out = append_rows(
            rows,
            &[RowBlock {
                matrix: &g,
                lower: &[0.0],
                upper: &[3.0],
            }],
            &elim,
        )
        .unwrap();
        assert_eq!(out.g, vec![7.0, 8.0, 0.0, 2.0]);
        assert_eq!(out.m_rows.unwrap(), vec![7.0, 8.0, 0.0, 2.0]);
        assert_eq!(out.upper_z, vec![1.0, 3.0]);
    }

    #[test]
    fn a_singular_factor_drops_the_least_distance_rows() {
        let z = [1.0, 0.0, 0.0, 1.0];
        let c_p = [0.0, 0.0];
        let r = [1.0, 0.0, 0.0, 0.0];
        let elim = Elimination {
            z: &z,
            c_p: &c_p,
            r: Some(&r),
        };
        let g = [0.0, 2.0];
        let out = append_rows(
            empty(true),
            &[RowBlock {
                matrix: &g,
                lower: &[0.0],
                upper: &[3.0],
            }],
            &elim,
        )
        .unwrap();
        assert!(out.m_rows.is_none());
        assert_eq!(out.g_z, vec![0.0, 2.0]);
    }

    #[test]
    fn shapes_are_checked() {
        let z = [1.0, 0.0, 0.0, 1.0];
        let c_p = [0.0, 0.0];
        let elim = Elimination {
            z: &z,
            c_p: &c_p,
            r: None,
        };
        let g = [0.0, 2.0, 1.0];
        let err = append_rows(
            empty(false),
            &[RowBlock {
                matrix: &g,
                lower: &[0.0],
                upper: &[3.0],
            }],
            &elim,
        )
        .unwrap_err();
        assert_eq!(err.arg(), "blocks.matrix");
        let bad_z = [1.0, 0.0, 0.0];
        let elim = Elimination {
            z: &bad_z,
            c_p: &c_p,
            r: None,
        };
        assert_eq!(
            append_rows(empty(false), &[], &elim).unwrap_err().arg(),
            "z"
        );
    }

    #[test]
    fn no_new_rows_or_no_factor() {
        let z = [1.0, 0.0, 0.0, 1.0];
        let c_p = [0.0, 0.0];
        let r = [1.0, 0.0, 0.0, 1.0];
        let parent = || {
            QpRows::with_room(
                0,
                (0, 0),
                &[7.0, 8.0],
                &[-1.0],
                &[1.0],
                &[7.0, 8.0],
                &[-1.0],
                &[1.0],
                Some(&[7.0, 8.0]),
            )
        };
        let elim = Elimination {
            z: &z,
            c_p: &c_p,
            r: Some(&r),
        };
        let empty = RowBlock {
            matrix: &[],
            lower: &[],
            upper: &[],
        };
        let out = append_rows(parent(), &[empty], &elim).unwrap();
        assert_eq!(out.m_rows, Some(vec![7.0, 8.0]));
        let elim = Elimination {
            z: &z,
            c_p: &c_p,
            r: None,
        };
        let g = [0.0, 2.0];
        let block = RowBlock {
            matrix: &g,
            lower: &[0.0],
            upper: &[3.0],
        };
        assert!(append_rows(parent(), &[block], &elim)
            .unwrap()
            .m_rows
            .is_none());
    }

    #[test]
    fn equalities_that_fix_every_coefficient_leave_rows_of_no_columns() {
        // Z is (2, 0): only the bounds move, by G c_p
        let c_p = [1.0, 2.0];
        let elim = Elimination {
            z: &[],
            c_p: &c_p,
            r: Some(&[]),
        };
        let g = [1.0, 1.0, 0.0, 2.0];
        let block = RowBlock {
            matrix: &g,
            lower: &[0.0, f64::NEG_INFINITY],
            upper: &[5.0, 4.0],
        };
        let out = append_rows(empty(true), &[block], &elim).unwrap();
        assert!(out.g_z.is_empty());
        assert_eq!(out.lower_z, vec![-3.0, f64::NEG_INFINITY]);
        assert_eq!(out.upper_z, vec![2.0, 0.0]);
        assert_eq!(out.m_rows, Some(vec![]));
    }
}
