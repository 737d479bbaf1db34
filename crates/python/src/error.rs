//! The Python exceptions: `voxreg.VoxregError` and its subclasses, defined in the pure-Python
//! package (`voxreg._errors`) so they can also derive from `ValueError` and `OSError`.

use pyo3::exceptions::PyRuntimeError;
use pyo3::prelude::*;
use pyo3::types::PyType;
use voxreg_regularize::RegularizeError;

/// The exception class an error maps to.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub(crate) enum Kind {
    /// `VoxregError`: a failure of the computation itself (factorization, memory, a bug).
    Voxreg,
    /// `InputError`: the labels or the file's contents cannot be regularized.
    Input,
    /// `ParameterError`: a parameter is out of range or unknown.
    Parameter,
    /// `IoError`: a file cannot be read or written.
    Io,
}

/// An error on its way to Python.
#[derive(Debug)]
pub(crate) struct Error {
    kind: Kind,
    message: String,
}

pub(crate) type Result<T> = std::result::Result<T, Error>;

impl Error {
    pub(crate) fn new(kind: Kind, message: impl Into<String>) -> Self {
        Error { kind, message: message.into() }
    }

    pub(crate) fn input(message: impl Into<String>) -> Self {
        Self::new(Kind::Input, message)
    }

    pub(crate) fn parameter(message: impl Into<String>) -> Self {
        Self::new(Kind::Parameter, message)
    }

    /// A library error, its message prefixed with `context` (as the CLI prefixes the file).
    pub(crate) fn regularize(context: &str, e: &RegularizeError) -> Self {
        let kind = match e {
            RegularizeError::Surface(_) | RegularizeError::SizeMismatch(_) => Kind::Input,
            RegularizeError::Normals(_)
            | RegularizeError::InvalidParams(_)
            | RegularizeError::InvalidOption { .. }
            | RegularizeError::NotFinite(_) => Kind::Parameter,
            // Raised on Ctrl-C, whose KeyboardInterrupt is returned instead.
            RegularizeError::Factorization(_)
            | RegularizeError::OutOfMemory(_)
            | RegularizeError::Interrupted => Kind::Voxreg,
        };
        Self::new(kind, format!("{context}{e}"))
    }

    pub(crate) fn io(e: &voxreg_io::IoError) -> Self {
        Self::new(Kind::Io, e.to_string())
    }
}

impl From<Error> for PyErr {
    fn from(e: Error) -> PyErr {
        let name = match e.kind {
            Kind::Voxreg => "VoxregError",
            Kind::Input => "InputError",
            Kind::Parameter => "ParameterError",
            Kind::Io => "IoError",
        };
        Python::attach(|py| {
            let class = py
                .import("voxreg._errors")
                .and_then(|m| m.getattr(name))
                .and_then(|c| Ok(c.cast_into::<PyType>()?));
            match class {
                Ok(class) => PyErr::from_type(class, e.message),
                // The package is broken; still say what went wrong.
                Err(_) => PyRuntimeError::new_err(e.message),
            }
        })
    }
}

/// Runs `f`, turning a panic into a `VoxregError` (no panic may cross into Python).
pub(crate) fn no_panic<T>(f: impl FnOnce() -> Result<T>) -> Result<T> {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(f))
        .unwrap_or_else(|payload| Err(panic_error(payload)))
}

/// The `VoxregError` of a caught panic.
pub(crate) fn panic_error(payload: Box<dyn std::any::Any + Send>) -> Error {
    let what = payload
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| payload.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "unknown panic".into());
    Error::new(Kind::Voxreg, format!("internal error (please report it): {what}"))
}
