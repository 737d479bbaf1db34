//! One solve's request ([`SolveRequest`]): where it starts, to which tolerance, what it
//! keeps and reports. Every solver takes one ([`crate::Solver::solve`],
//! [`crate::CgSolver::solve`], [`crate::BoundedSolver::solve`]).

use glam::DVec3;

use crate::progress::Progress;

/// Where a solve's iterations start ([`SolveRequest::start`]).
#[derive(Debug, Default)]
pub enum SolveStart<'a> {
    /// The energy's input positions.
    #[default]
    Input,
    /// These positions, one per vertex (the bounded solver projects them into its boxes).
    Given(&'a [DVec3]),
    /// These positions, which the solver may take (the conjugate gradient iterates in
    /// them: one vector fewer held during the solve).
    Owned(Vec<DVec3>),
}

/// One solve of a solver ([`crate::Solver::solve`]): where it starts, to which
/// tolerance, and what it reports. `SolveRequest::default()` is a plain solve from the
/// input positions.
#[non_exhaustive]
#[derive(Default)]
pub struct SolveRequest<'a> {
    /// Where the iterations start. Default: [`SolveStart::Input`].
    pub start: SolveStart<'a>,
    /// The conjugate gradient's tolerance in voxels, for this solve and the next (the
    /// bounded solver keeps its own). Default: `None`, unchanged.
    pub tolerance: Option<f64>,
    /// Whether the conjugate gradient, from a given start, begins on the last solve's
    /// multigrid cycle, its fine level put on the new energy, and builds the energy's own
    /// cycle only after the first iteration, restarting from that iterate: the first
    /// iterate comes without waiting for the coarse levels' setup. Default: `false`.
    pub quick_start: bool,
    /// Whether the conjugate gradient keeps this solve's cycle for a next quick start;
    /// `false` frees its memory for what runs before the next solve. Default: `false`.
    pub keep_cycle: bool,
    /// Called after each iteration of the iterative solvers. Default: none.
    pub progress: Option<&'a mut dyn FnMut(&Progress)>,
}

impl std::fmt::Debug for SolveRequest<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SolveRequest")
            .field("start", &self.start)
            .field("tolerance", &self.tolerance)
            .field("quick_start", &self.quick_start)
            .field("keep_cycle", &self.keep_cycle)
            .field("progress", &self.progress.is_some())
            .finish()
    }
}

impl<'a> SolveRequest<'a> {
    /// A solve from `start` (the field `start`).
    pub fn from(start: SolveStart<'a>) -> Self {
        SolveRequest { start, ..Default::default() }
    }

    /// Reports each iteration to `progress` (the field `progress`).
    pub fn progress(mut self, progress: &'a mut dyn FnMut(&Progress)) -> Self {
        self.progress = Some(progress);
        self
    }

    /// Sets the field `quick_start`.
    pub fn quick_start(mut self, on: bool) -> Self {
        self.quick_start = on;
        self
    }

    /// Sets the field `keep_cycle`.
    pub fn keep_cycle(mut self, keep: bool) -> Self {
        self.keep_cycle = keep;
        self
    }

    /// Sets the field `tolerance`.
    pub fn tolerance(mut self, tolerance: f64) -> Self {
        self.tolerance = Some(tolerance);
        self
    }
}
