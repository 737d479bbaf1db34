//! What can go wrong when regularizing: the crate's one error type, at the bottom of the
//! crate so that every module names it without going through the crate root.

use voxreg_digisurf::SurfaceError;
use voxreg_normals::NormalError;

/// What can go wrong when regularizing.
#[derive(Debug, thiserror::Error, Clone, PartialEq)]
pub enum RegularizeError {
    /// The volume has no surface to regularize, or its regions are invalid.
    #[error(transparent)]
    Surface(#[from] SurfaceError),
    /// The normal estimator failed or was given invalid parameters.
    #[error(transparent)]
    Normals(NormalError),
    /// A weight is out of range.
    #[error("invalid parameters: {0}")]
    InvalidParams(String),
    /// A front end's option is out of range or conflicts with another
    /// ([`Overrides::resolve`](crate::Overrides::resolve)): `"{option} {message}"`, e.g. `alpha must be finite and
    /// positive, got 0`.
    #[error("{option} {message}")]
    InvalidOption {
        /// The option, as [`Overrides`](crate::Overrides) names it (`sharpen_threshold`).
        option: &'static str,
        /// What is wrong, starting with a verb.
        message: String,
    },
    /// Arrays do not match the surface (normals per surfel, positions per vertex).
    #[error("size mismatch: {0}")]
    SizeMismatch(String),
    /// The factorization failed (e.g. the system is not positive definite).
    #[error("factorization failed: {0}")]
    Factorization(String),
    /// Not enough memory for a solver's data.
    #[error("out of memory: {0}")]
    OutOfMemory(String),
    /// The computation left the finite numbers (weights or spacings whose scale the
    /// double-precision arithmetic cannot hold): never reported as converged.
    #[error("numerical failure: {0}")]
    NotFinite(String),
    /// The run's [`Interrupt`](voxreg_normals::Interrupt) was raised ([`Regularizer::set_interrupt`](crate::Regularizer::set_interrupt)): it stopped
    /// before its end, and returned nothing.
    #[error("interrupted")]
    Interrupted,
}

impl From<NormalError> for RegularizeError {
    /// [`NormalError::Interrupted`] becomes [`RegularizeError::Interrupted`]; the others
    /// are wrapped.
    fn from(e: NormalError) -> Self {
        match e {
            NormalError::Interrupted => RegularizeError::Interrupted,
            e => RegularizeError::Normals(e),
        }
    }
}
