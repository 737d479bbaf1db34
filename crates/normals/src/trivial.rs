//! The trivial estimator.

use rayon::prelude::*;
use voxreg_digisurf::DigitalSurface;

use crate::error::NormalError;
use crate::estimator::NormalEstimator;
use crate::field::NormalField;
use crate::interrupt::Interrupt;

/// The trivial normal: each surfel's axis, oriented from its lower region to its
/// higher one (outward for a solid surrounded by background).
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq)]
pub struct Trivial;

impl NormalEstimator for Trivial {
    fn name(&self) -> &'static str {
        "trivial"
    }

    fn estimate_interruptible(
        &self,
        surface: &DigitalSurface,
        interrupt: &Interrupt,
    ) -> Result<NormalField, NormalError> {
        interrupt.check()?;
        Ok(NormalField::new(surface.surfels().par_iter().map(|s| s.normal()).collect()))
    }
}
