//! The crate's one error type. Kernels return `Result` and never panic on input paths; the
//! Python wrappers map every variant to `avp._avp_rust.KernelError` (a `ValueError`) carrying
//! the offending argument as `.arg` and the reason as `.detail` (message: `"{arg}: {detail}"`).
use std::cell::{Cell, RefCell};
use std::fmt;
use std::sync::Once;

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

std::thread_local! {
    /// This thread is inside [`guarded`]: a panic becomes the kernel's error, not stderr output.
    static GUARDED: Cell<bool> = const { Cell::new(false) };
    /// Where the last guarded panic on this thread happened (`file:line:column`).
    static PANIC_AT: RefCell<Option<String>> = const { RefCell::new(None) };
}

/// Installs, once, a panic hook that stays silent inside [`guarded`] (recording the location
/// for the error) and defers to the previous hook elsewhere. In the Python extension (a cdylib
/// with its own `std`) the hook is the extension's alone; linked as an rlib into a program, it
/// wraps that program's hook, which still sees every panic outside [`guarded`].
fn install_quiet_hook() {
    static HOOK: Once = Once::new();
    HOOK.call_once(|| {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if GUARDED.with(Cell::get) {
                PANIC_AT.with(|at| *at.borrow_mut() = info.location().map(|l| l.to_string()));
            } else {
                previous(info);
            }
        }));
    });
}

/// Runs a kernel and turns a panic (a bug, never an input path by design) into an error, so the
/// Python wrappers raise `ValueError` instead of PyO3's `PanicException` (a `BaseException`
/// that would get past a replanner's `except Exception`). The panic prints nothing (no message
/// or backtrace on stderr): its message and location are in the error's detail.
pub fn guarded<T>(kernel: impl FnOnce() -> Result<T>) -> Result<T> {
    install_quiet_hook();
    let outer = GUARDED.with(|g| g.replace(true));
    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(kernel));
    GUARDED.with(|g| g.set(outer));
    result.unwrap_or_else(|payload| {
        let what = payload
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| payload.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "unknown panic".into());
        let at = PANIC_AT
            .with(|at| at.borrow_mut().take())
            .map(|l| format!(" at {l}"))
            .unwrap_or_default();
        Err(Error::Invalid {
            arg: "kernel",
            detail: format!("internal error (please report): {what}{at}"),
        })
    })
}

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

/// Fails with [`Error::NonFinite`] when any value is NaN or infinite.
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
        match r {
            Err(Error::Invalid {
                arg: "kernel",
                detail,
            }) => {
                assert!(detail.contains("boom at src/error.rs:"), "{detail}")
            }
            other => panic!("expected the kernel's error, got {other:?}"),
        }
        assert_eq!(guarded(|| Ok(3)), Ok(3));
        // nested: the inner panic is the inner call's error; the outer call still guards
        let r: Result<Result<()>> = guarded(|| Ok(guarded(|| panic!("inner"))));
        assert!(matches!(r, Ok(Err(Error::Invalid { arg: "kernel", .. }))));
        let r: Result<()> = guarded(|| {
            let _ = guarded(|| -> Result<()> { panic!("inner") });
            panic!("outer")
        });
        assert!(matches!(r, Err(Error::Invalid { detail, .. }) if detail.contains("outer at ")));
    }
}
