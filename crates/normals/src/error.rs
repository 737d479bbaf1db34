//! The estimators' error.

/// What can go wrong when estimating normals.
#[derive(Debug, thiserror::Error, Clone, PartialEq)]
pub enum NormalError {
    /// A parameter is out of its valid range.
    #[error("invalid parameter: {0}")]
    InvalidParameter(String),
    /// A linear solve failed (e.g. a factorization of a matrix that is not positive
    /// definite).
    #[error("linear solver failed: {0}")]
    Solver(String),
    /// The caller raised the estimate's `Interrupt`.
    #[error("interrupted")]
    Interrupted,
}
