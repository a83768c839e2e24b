//! Numeric kernels of `avp` (active visual perching).
//!
//! Pure functions on plain slices: spline evaluation ([`spline`]), polynomial algebra ([`poly`]),
//! Sturm sequences and bound certificates (`sturm`, `certify`, `exact`), workspace
//! certificates (`regions`), the FoV rows (`fov`) and those of one SQP step on a reference plan
//! (`fov_step`), the anticipation step (6) of the replanner (`anticipation`), the
//! time search's scaling law (`time_scaling`), the acceptance checks of a QP solution
//! (`qp_check`) and the rows appended to an eliminated QP (`reduce`). The PyO3 wrappers live
//! in `python` behind the `python` feature, so `cargo test` runs without linking libpython.
//!
//! Conventions: polynomial coefficients are stored in **ascending** powers (the constant
//! coefficient comes first); spline coefficients have shape `(segments, axes, coeffs)` in
//! physical units with per-segment local time `tau = t - t_i`.
#![deny(unsafe_code)]
#![warn(clippy::all)]

pub mod anticipation;
pub mod bounds;
pub mod certify;
pub mod descartes;
pub mod error;
pub mod exact;
pub mod fov;
pub mod fov_step;
pub mod interval;
pub mod poly;
pub mod qp_check;
pub mod reduce;
pub mod regions;
pub mod roll;
pub mod spline;
pub mod sturm;
pub mod time_scaling;
pub mod trackability;

#[cfg(feature = "python")]
mod python;

pub use error::{Error, Result};
