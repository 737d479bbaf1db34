//! Normal estimators on digital surfaces.
//!
//! A [`NormalField`] holds one unit direction per surfel of a
//! [`DigitalSurface`](voxreg_digisurf::DigitalSurface). Estimators implement the small
//! [`NormalEstimator`] trait so callers (the CLI, xtask) can loop over them:
//!
//! - [`Trivial`]: the surfel's own axis, oriented from its lower region to its higher one.
//!
//! More estimators (integral invariant, anisotropic) plug in behind the same trait.
//! The regularization energy only uses each normal's *direction*: orientation is
//! kept for display and export.
//!
//! # Example
//!
//! ```
//! use voxreg_digisurf::{DigitalSurface, LabelVolume};
//! use voxreg_normals::{NormalEstimator, Trivial};
//!
//! let volume = LabelVolume::from_fn([3, 3, 3], |p| u32::from(p == [1, 1, 1]));
//! let surface = DigitalSurface::from_volume(&volume)?;
//! let normals = Trivial.estimate(&surface)?;
//! assert_eq!(normals.len(), 6);
//! // Normals of a solid point outward: the +x face of the voxel has normal +x.
//! let s = surface.surfels().iter().position(|s| s.axis == 0 && s.cell[0] == 2).unwrap();
//! assert_eq!(normals.as_slice()[s], glam::DVec3::X);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod field;
mod trivial;

pub use field::NormalField;
pub use trivial::Trivial;

use voxreg_digisurf::DigitalSurface;

/// What can go wrong when estimating normals.
#[derive(Debug, thiserror::Error, Clone, PartialEq)]
pub enum NormalError {
    /// A parameter is out of its valid range.
    #[error("invalid parameter: {0}")]
    InvalidParameter(String),
}

/// A way of estimating one normal per surfel.
pub trait NormalEstimator {
    /// A short name (`"trivial"`, `"ii"`, ...), used in reports.
    fn name(&self) -> &'static str;

    /// The normal field of `surface`: one unit vector per surfel, in surfel order.
    fn estimate(&self, surface: &DigitalSurface) -> Result<NormalField, NormalError>;
}
