//! Anticipation step (6) of active replanning.
//!
//! A new plan computed from odometry taken at `t_rp` only takes over at `t_ex = t_rp + latency`.
//! Its start state is the odometry plus what the committed plan says happens in between:
//! `x0^(k) = x_n^(k) + P^(k)(t_ex) - P^(k)(t_rp)` for `k = 0..=4`, for x, y, z and yaw alike.
use crate::error::{check_finite, Error, Result};
use crate::spline::SplineView;

/// Number of derivative orders anticipated (position..snap).
pub const ORDERS: usize = 5;

/// Anticipated flat state at `t_ex`, laid out `[order][axis]` (`ORDERS x n_axes`).
///
/// `odometry` is laid out the same way (`x_n^(k)` for each axis). Both times must lie in the
/// committed plan's domain and `t_ex >= t_rp`.
pub fn anticipate(
    plan: &SplineView<'_>,
    odometry: &[f64],
    t_rp: f64,
    t_ex: f64,
) -> Result<Vec<f64>> {
    let a = plan.n_axes();
    if odometry.len() != ORDERS * a {
        return Err(Error::Shape {
            arg: "odometry",
            detail: format!(
                "expected {ORDERS} x {a} values (orders 0..4 x axes), got {}",
                odometry.len()
            ),
        });
    }
    check_finite("odometry", odometry)?;
    check_finite("t_rp", &[t_rp])?;
    check_finite("t_ex", &[t_ex])?;
    let knots = plan.knots();
    let (t0, tf) = (knots[0], knots[knots.len() - 1]);
    if t_rp < t0 || t_ex > tf {
        return Err(Error::Invalid {
            arg: "t_ex",
            detail: format!(
                "t_rp = {t_rp} and t_ex = {t_ex} must lie in the committed plan [{t0}, {tf}]"
            ),
        });
    }
    if t_ex < t_rp {
        return Err(Error::Invalid {
            arg: "t_ex",
            detail: format!("t_ex = {t_ex} is before t_rp = {t_rp}"),
        });
    }
    let mut out = odometry.to_vec();
    let mut at_ex = vec![0.0; a];
    let mut at_rp = vec![0.0; a];
    for k in 0..ORDERS {
        plan.eval_into(t_ex, k, &mut at_ex);
        plan.eval_into(t_rp, k, &mut at_rp);
        for axis in 0..a {
            out[k * a + axis] += at_ex[axis] - at_rp[axis];
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn anticipation_adds_the_plans_displacement() {
        // one axis: p(t) = t^3 on [0, 2]
        let c = [0.0, 0.0, 0.0, 1.0];
        let k = [0.0, 2.0];
        let s = SplineView::new(&c, (1, 1, 4), &k).unwrap();
        let odo = [0.1, 0.2, 0.3, 0.4, 0.5];
        let out = anticipate(&s, &odo, 0.5, 1.0).unwrap();
        let want = [
            0.1 + 1.0 - 0.125,
            0.2 + 3.0 - 0.75,
            0.3 + 6.0 - 3.0,
            0.4 + 6.0 - 6.0,
            0.5 + 0.0 - 0.0,
        ];
        for (o, w) in out.iter().zip(want) {
            assert!((o - w).abs() < 1e-12);
        }
    }

    #[test]
    fn rejects_times_outside_the_plan_and_bad_shapes() {
        let c = [0.0, 1.0];
        let k = [0.0, 1.0];
        let s = SplineView::new(&c, (1, 1, 2), &k).unwrap();
        let odo = [0.0; 5];
        assert!(anticipate(&s, &odo, 0.5, 1.5).is_err());
        assert!(anticipate(&s, &odo, 0.6, 0.5).is_err());
        assert!(anticipate(&s, &odo[..4], 0.1, 0.2).is_err());
        assert!(anticipate(&s, &[f64::NAN; 5], 0.1, 0.2).is_err());
    }
}
