//! A caller's request to stop a long computation early.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use crate::error::NormalError;

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
