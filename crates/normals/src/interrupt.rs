//! A caller's request to stop a long computation early.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use crate::NormalError;

/// A flag that a caller raises, from any thread, to stop a long computation early: the
/// computation polls it between chunks of its work and returns an `Interrupted` error
/// ([`NormalError::Interrupted`], and `RegularizeError::Interrupted` in the front door)
/// soon after it is raised, leaving its reusable state (a solver, a cached field) as it
/// was or complete.
///
/// Why: an interactive front end replaces a run whose parameters the user changed while
/// it was still going; the new run should not wait for the old one's stages to end.
///
/// Clones share the flag. Once raised it stays raised: make a new one per run. The
/// default ([`Interrupt::never`]) is never raised and costs one branch per poll.
///
/// ```
/// use voxreg_normals::Interrupt;
///
/// let interrupt = Interrupt::new();
/// let handle = interrupt.clone(); // for another thread
/// assert!(!interrupt.is_raised());
/// handle.raise();
/// assert!(interrupt.is_raised());
/// assert!(!Interrupt::never().is_raised());
/// ```
#[derive(Clone, Debug, Default)]
pub struct Interrupt(Option<Arc<AtomicBool>>);

impl Interrupt {
    /// A flag not yet raised.
    pub fn new() -> Self {
        Interrupt(Some(Arc::new(AtomicBool::new(false))))
    }

    /// A flag that is never raised ([`Interrupt::raise`] does nothing).
    pub fn never() -> Self {
        Interrupt(None)
    }

    /// Raises the flag: the computations polling it (or any clone) stop.
    pub fn raise(&self) {
        if let Some(flag) = &self.0 {
            flag.store(true, Ordering::Relaxed);
        }
    }

    /// Whether the flag was raised.
    #[inline]
    pub fn is_raised(&self) -> bool {
        self.0.as_ref().is_some_and(|flag| flag.load(Ordering::Relaxed))
    }

    /// `Err(NormalError::Interrupted)` once the flag is raised.
    #[inline]
    pub fn check(&self) -> Result<(), NormalError> {
        if self.is_raised() {
            Err(NormalError::Interrupted)
        } else {
            Ok(())
        }
    }
}

#[cfg(test)]
mod tests {
    use voxreg_digisurf::{DigitalSurface, LabelVolume};

    use super::*;
    use crate::{
        AmbrosioTortorelli, AtParams, ConvolvedTrivial, IntegralInvariant, NormalEstimator, Refined, Trivial,
    };

    #[test]
    fn every_estimator_stops_at_a_raised_interrupt_and_ignores_one_not_raised() {
        let volume = LabelVolume::from_fn([12, 12, 12], |[x, y, z]| {
            let d = |c: usize| c as f64 - 5.5;
            u32::from(d(x).powi(2) + d(y).powi(2) + d(z).powi(2) <= 16.0)
        });
        let surface = DigitalSurface::from_volume(&volume).unwrap();
        let trivial = Trivial.estimate(&surface).unwrap();
        let positions = surface.positions();
        let estimators: Vec<Box<dyn NormalEstimator>> = vec![
            Box::new(Trivial),
            Box::new(ConvolvedTrivial { radius: None }),
            Box::new(IntegralInvariant { radius: None }),
            Box::new(AmbrosioTortorelli::new(
                AtParams::default(),
                Box::new(IntegralInvariant { radius: None }),
            )),
            Box::new(Refined {
                positions: &positions,
                previous: &trivial,
                radius: 3.0,
                feature_angle_deg: 30.0,
            }),
        ];
        let raised = Interrupt::new();
        raised.raise();
        for e in &estimators {
            assert_eq!(
                e.estimate_interruptible(&surface, &raised),
                Err(NormalError::Interrupted),
                "{}",
                e.name()
            );
            let field = e.estimate_interruptible(&surface, &Interrupt::new()).unwrap();
            assert_eq!(field, e.estimate(&surface).unwrap(), "{}", e.name());
        }
    }
}
