//! What an iterative solver reports after each iteration, at the bottom of the crate.

use glam::DVec3;

/// What an iterative solver reports after each iteration (for progress bars, and for
/// viewers that show the surface converge).
#[derive(Copy, Clone, PartialEq)]
pub struct Progress<'a> {
    /// Iterations done.
    pub iteration: usize,
    /// The energy at the current iterate.
    pub energy: f64,
    /// `|grad E|_2` at the current iterate (for the clamped descent: of the projected
    /// gradient).
    pub gradient_norm: f64,
    /// `gradient_norm` relative to its value at the input positions.
    pub relative_gradient: f64,
    /// The current guaranteed error bound in voxels (`gradient_norm / (2 alpha_min h)`),
    /// which the iterative solvers drive below their tolerance.
    pub error_bound: f64,
    /// The current estimate of that distance in voxels (see [`StoppingRule::Estimate`](crate::StoppingRule::Estimate)).
    pub error_estimate: f64,
    /// The current iterate minus the solve's input positions ([`Energy::input`](crate::Energy::input), the
    /// attachment targets), one per vertex: the iterate is `input[i] + displacement[i]`.
    pub displacement: &'a [DVec3],
}

impl std::fmt::Debug for Progress<'_> {
    // The displacement has one entry per vertex: show its length, not its values.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Progress")
            .field("iteration", &self.iteration)
            .field("energy", &self.energy)
            .field("gradient_norm", &self.gradient_norm)
            .field("relative_gradient", &self.relative_gradient)
            .field("error_bound", &self.error_bound)
            .field("error_estimate", &self.error_estimate)
            .field("displacement", &format_args!("[{} vectors]", self.displacement.len()))
            .finish()
    }
}
