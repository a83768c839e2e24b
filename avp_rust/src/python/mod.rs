//! Thin PyO3 wrappers, one module per kernel family (`spline`, `fov`, `bounds`, `regions`,
//! `time_scaling`, `qp_check`, `reduce`), sharing only [`common`]: convert NumPy arrays to
//! slices, call a kernel, convert back. Every kernel error becomes `KernelError` (a `ValueError`
//! with `.arg` and `.detail`); kernels return `Result` and do not panic on input paths.
use pyo3::prelude::*;

mod bounds;
mod common;
mod fov;
mod qp_check;
mod reduce;
mod regions;
mod spline;
mod time_scaling;

#[pymodule]
pub fn _avp_rust(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("KernelError", m.py().get_type::<common::KernelError>())?;
    spline::register(m)?;
    fov::register(m)?;
    bounds::register(m)?;
    regions::register(m)?;
    time_scaling::register(m)?;
    qp_check::register(m)?;
    reduce::register(m)?;
    Ok(())
}
