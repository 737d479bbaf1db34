//! The pipeline as named stages, which [`crate::Regularizer`] runs in order:
//!
//! 1. [`normals`]: the initial normal field (given, estimated, or kept from the last run);
//! 2. for each round `0..=rounds` of the mode's [`crate::Refinement`]: [`refine`] (from
//!    round 1: the normals re-estimated from the last solve, the targets re-centred in the
//!    fidelity mode, [`recentre`]) and [`solve`] (the round's energy minimized);
//! 3. [`finish`]: the fold-free post-condition and the energies.
//!
//! Each stage reads the parameters of its own: the [`crate::Mode`] decides which exist.

use glam::DVec3;

use crate::params::Params;
use crate::progress::Progress;

mod finish;
mod normals;
mod recentre;
mod refine;
mod solve;

pub(crate) use finish::finish;
pub(crate) use normals::initial_normals;
pub(crate) use recentre::RecentringInputs;
pub(crate) use refine::Refine;
pub(crate) use solve::Solve;

/// A stage of the front door's work, for progress displays.
#[derive(Copy, Clone, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Stage {
    /// Estimating the initial normal field.
    Normals,
    /// Solve number `round` (0 is the first; `1..=refine` follow refinements).
    Solve {
        /// The round.
        round: usize,
    },
    /// Refining the normals and re-centring the targets before solve `round`.
    Refine {
        /// The round of the solve that follows.
        round: usize,
    },
}

impl Stage {
    /// A short label: `"normals"`, `"solve 2/4"`, `"refine 1/3"`.
    pub fn label(&self, params: &Params) -> String {
        match self {
            Stage::Normals => "normals".into(),
            Stage::Solve { round } => format!("solve {}/{}", round + 1, params.refinement().rounds + 1),
            Stage::Refine { round } => format!("refine {round}/{}", params.refinement().rounds),
        }
    }
}

/// What a progress callback receives.
#[derive(Copy, Clone, Debug)]
pub struct Event<'a> {
    /// The stage under way.
    pub stage: Stage,
    /// An estimate of the fraction of the whole run done, in `[0, 1]` (stages are
    /// weighted equally; iterations advance it within a solve).
    pub fraction: f64,
    /// The latest iteration of an iterative solver, within [`Stage::Solve`].
    pub iteration: Option<&'a Progress<'a>>,
    /// With `iteration`: the solve's input positions (its attachment targets), which
    /// the iterate is displaced from; see [`Event::iterate`].
    pub input: Option<&'a [DVec3]>,
}

impl Event<'_> {
    /// The current iterate of the solve under way, one position per vertex: `input +
    /// displacement` (`None` between iterations, and for the direct solver).
    pub fn iterate(&self) -> Option<Vec<DVec3>> {
        let (p, input) = (self.iteration?, self.input?);
        Some(input.iter().zip(p.displacement).map(|(x, d)| *x + *d).collect())
    }
}
