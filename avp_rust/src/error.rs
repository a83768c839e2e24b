//! The crate's one error type. Kernels return `Result` and never panic on input paths; the
//! Python wrappers map every variant to `avp._avp_rust.KernelError` (a `ValueError`) carrying
//! the offending argument as `.arg` and the reason as `.detail` (message: `"{arg}: {detail}"`).
use std::fmt;

#[derive(Debug, Clone, PartialEq)]
pub enum Error {
    /// An argument has the wrong shape or length.
    Shape { arg: &'static str, detail: String },
    /// An argument holds NaN or an infinity.
    NonFinite { arg: &'static str },
    /// An argument violates a documented precondition.
    Invalid { arg: &'static str, detail: String },
}

pub type Result<T> = std::result::Result<T, Error>;

impl Error {
    /// Name of the offending argument.
    pub fn arg(&self) -> &'static str {
        match self {
            Error::Shape { arg, .. } | Error::NonFinite { arg } | Error::Invalid { arg, .. } => arg,
        }
    }

    /// What is wrong and what to do, without the argument name.
    pub fn detail(&self) -> String {
        match self {
            Error::Shape { detail, .. } => format!("wrong shape: {detail}"),
            Error::NonFinite { .. } => "contains NaN or inf; pass finite values".into(),
            Error::Invalid { detail, .. } => detail.clone(),
        }
    }
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}", self.arg(), self.detail())
    }
}

impl std::error::Error for Error {}

/// Runs a kernel and turns a panic (a bug, never an input path by design) into an error, so the
/// Python wrappers raise `ValueError` instead of PyO3's `PanicException` (a `BaseException`
/// that would get past a replanner's `except Exception`).
pub fn guarded<T>(kernel: impl FnOnce() -> Result<T>) -> Result<T> {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(kernel)).unwrap_or_else(|payload| {
        let what = payload
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| payload.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "unknown panic".into());
        Err(Error::Invalid {
            arg: "kernel",
            detail: format!("internal error (please report): {what}"),
        })
    })
}

/// Fails with [`Error::NonFinite`] when any value is NaN or infinite.
/// A [`Error::Shape`] naming `arg` unless it holds exactly `expected` values.
pub fn check_len(arg: &'static str, len: usize, expected: usize) -> Result<()> {
    if len == expected {
        Ok(())
    } else {
        Err(Error::Shape {
            arg,
            detail: format!("expected {expected} values, got {len}"),
        })
    }
}

pub fn check_finite(arg: &'static str, values: &[f64]) -> Result<()> {
    if values.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(Error::NonFinite { arg })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn guarded_turns_a_panic_into_an_error() {
        let r: Result<()> = guarded(|| panic!("boom"));
        assert!(matches!(r, Err(Error::Invalid { arg: "kernel", .. })));
        assert_eq!(guarded(|| Ok(3)), Ok(3));
    }
}
