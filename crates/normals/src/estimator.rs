//! The trait every estimator implements.

use voxreg_digisurf::DigitalSurface;

use crate::error::NormalError;
use crate::field::NormalField;
use crate::interrupt::Interrupt;

/// A way of estimating one normal per surfel.
pub trait NormalEstimator {
    /// A short name (`"trivial"`, `"ii"`, ...), used in reports.
    fn name(&self) -> &'static str;

    /// The normal field of `surface`: one unit vector per surfel, in surfel order
    /// ([`NormalEstimator::estimate_interruptible`] never interrupted).
    fn estimate(&self, surface: &DigitalSurface) -> Result<NormalField, NormalError> {
        self.estimate_interruptible(surface, &Interrupt::never())
    }

    /// [`NormalEstimator::estimate`], returning [`NormalError::Interrupted`] soon after
    /// `interrupt` is raised (from another thread) instead of finishing. The estimators
    /// of this crate poll it inside their loops over surfels or iterations (the trivial
    /// one, which has none, before starting).
    fn estimate_interruptible(
        &self,
        surface: &DigitalSurface,
        interrupt: &Interrupt,
    ) -> Result<NormalField, NormalError>;
}
