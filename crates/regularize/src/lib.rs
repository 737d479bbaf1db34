//! The quadratic regularization energy of digital surfaces, and its solvers.
//!
//! Given a [`DigitalSurface`] (quads with input positions `p`) and a
//! [`NormalField`] (one direction `n_f` per quad), the regularized positions minimize
//! the convex quadratic [`Energy`] of the papers:
//!
//! ```text
//! E(P^) = alpha * sum_i |p_i - p^_i|^2                  (attachment)
//!       + beta  * sum_f sum_{edges e of f} (e . n_f)^2   (alignment)
//!       + gamma * sum_i |p^_i - b^_i|^2                  (fairness)
//! ```
//!
//! with defaults `alpha = 1e-3, beta = 1, gamma = 0.1` ([`EnergyParams`]). Entry points:
//!
//! - [`regularize`]: the one-shot form (exact solve).
//! - [`Solver`] ([`SolverParams`], [`SolverChoice`]): picks one of the solvers below;
//!   `Auto` factors small surfaces exactly and iterates on the others.
//! - [`DirectSolver`]: exact sparse Cholesky (faer) that keeps its symbolic analysis
//!   for repeated solves on the same surface. Fast to a few thousand vertices; its factor
//!   grows like `n^1.27` (1.6 GB at 120k vertices).
//! - [`CgSolver`] ([`CgParams`]): matrix-free conjugate gradient with a multigrid
//!   preconditioner over the voxel hierarchy ([`MultigridParams`], [`Preconditioner`]),
//!   stopping at a tolerance in voxels ([`StoppingRule`]): memory linear in the surface,
//!   about 20 iterations on smooth normal fields (2 s for 367k quads on 2 cores).
//! - [`DescentSolver`] ([`DescentParams`]): gradient descent with the exact gradient and
//!   optimal steps, optionally *clamped* so that every vertex stays in a cube around its
//!   input position (paper, sec. 3.4), which rules out self-intersections
//!   ([`self_intersections`] checks meshes).
//! - [`Energy`]: value per term and exact gradient, matrix-free, with optional
//!   per-element [`Weights`] and texture-aware fairness ([`FairnessMask`]); [`Operator`]
//!   and [`OperatorPattern`]: the same quadratic form as a sparse matrix (eq. 28).
//!
//! Iterative solvers report each iteration ([`Progress`]: energy, gradient norm, error
//! estimate) for progress bars, and every solver returns a [`SolveInfo`] certificate: the
//! gradient norm at the result relative to the input's, and for the iterative ones a
//! guaranteed and an estimated distance to the exact minimizer.
//!
//! # Example
//!
//! ```
//! use voxreg_digisurf::{DigitalSurface, LabelVolume};
//! use voxreg_normals::{NormalEstimator, Trivial};
//! use voxreg_regularize::{regularize, CgParams, CgSolver, Energy, EnergyParams};
//!
//! // A digital ball of radius 4.
//! let volume = LabelVolume::from_fn([11, 11, 11], |[x, y, z]| {
//!     let d = |c: usize| c as f64 - 5.0;
//!     u32::from(d(x).powi(2) + d(y).powi(2) + d(z).powi(2) <= 16.0)
//! });
//! let surface = DigitalSurface::from_volume(&volume)?;
//! let normals = Trivial.estimate(&surface)?;
//! let result = regularize(&surface, &normals, EnergyParams::default())?;
//! assert!(result.after.total < result.before.total);
//! assert!(result.info.relative_gradient <= 1e-9);
//!
//! // The same minimizer by multigrid CG, to 1e-3 voxel.
//! let input = surface.positions();
//! let energy = Energy::new(&surface, &normals, &input, EnergyParams::default())?;
//! let (x, info) = CgSolver::new(&surface, CgParams::default())?.solve(&energy)?;
//! assert!(info.converged && x.iter().zip(&result.positions).all(|(a, b)| a.distance(*b) < 1e-3));
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! # Features
//!
//! None.

mod assemble;
mod boxqp;
mod cg;
mod descent;
mod direct;
mod energy;
mod intersections;
mod iterative;
mod multigrid;
mod pipeline;
mod solver;
mod stencil;
mod vecops;
mod weights;

pub use assemble::{Operator, OperatorPattern};
pub use cg::{CgParams, CgSolver, StoppingRule};
pub use descent::{DescentParams, DescentSolver};
pub use direct::DirectSolver;
pub use energy::{Energy, EnergyParams, EnergyTerms};
pub use intersections::{self_intersections, triangles_intersect};
pub use iterative::Preconditioner;
pub use multigrid::MultigridParams;
pub use pipeline::{
    crease_weights, informative_vertices, refined_normals, run_pipeline, smoothed_displacements,
    PipelineOutput, PipelineParams,
};
pub use solver::{estimate_factor_nnz, Solver, SolverChoice, SolverParams};
pub use weights::{colour_discontinuities, FairnessMask, Weights};

use glam::DVec3;
use voxreg_digisurf::DigitalSurface;
use voxreg_normals::NormalField;

/// What can go wrong when regularizing.
#[derive(Debug, thiserror::Error, Clone, PartialEq, Eq)]
pub enum RegularizeError {
    /// A weight is out of range.
    #[error("invalid parameters: {0}")]
    InvalidParams(String),
    /// Arrays do not match the surface (normals per surfel, positions per vertex).
    #[error("size mismatch: {0}")]
    SizeMismatch(String),
    /// The factorization failed (e.g. the system is not positive definite).
    #[error("factorization failed: {0}")]
    Factorization(String),
    /// Not enough memory for a solver's data.
    #[error("out of memory: {0}")]
    OutOfMemory(String),
}

/// What a solver reports about its solve.
#[derive(Clone, Debug, PartialEq)]
pub struct SolveInfo {
    /// The solver: `"direct"`, `"cg"` or `"gd"`.
    pub solver: &'static str,
    /// Iterations (for the direct solver: 1 + refinement steps).
    pub iterations: usize,
    /// Certificate: `|grad E(p*)| / |grad E(p)|`, the gradient norm at the result
    /// relative to the one at the input positions (0 when the input is optimal). For the
    /// clamped descent, the norm of the projected gradient (see [`DescentSolver`]).
    pub relative_gradient: f64,
    /// Entries of the Cholesky factor, for the direct solver.
    pub factor_nnz: Option<usize>,
    /// Seconds spent building the operator's sparsity pattern or connectivity (once per
    /// surface).
    pub pattern_seconds: f64,
    /// Seconds of symbolic analysis: fill-reducing ordering and symbolic factorization
    /// (once per surface).
    pub symbolic_seconds: f64,
    /// Seconds of numeric assembly (for CG: coefficients and coarse operators).
    pub assemble_seconds: f64,
    /// Seconds of numeric factorization (for CG: of the coarsest multigrid level).
    pub factor_seconds: f64,
    /// Seconds of triangular solves and refinement, or of the iterations.
    pub solve_seconds: f64,
    /// For the iterative solvers: a guaranteed bound, in voxels, on the distance of every
    /// vertex to the exact minimizer, `|grad E|_2 / (2 alpha_min h)` (see
    /// [`CgParams::tolerance`]); `None` for the direct solver (exact up to rounding) and
    /// the clamped descent (whose minimizer is another one).
    pub error_bound: Option<f64>,
    /// For the iterative solvers: the estimated distance, in voxels, of the farthest vertex
    /// to the exact minimizer (see [`StoppingRule::Estimate`]).
    pub error_estimate: Option<f64>,
    /// Whether the stopping rule was met (always true for the direct solver).
    pub converged: bool,
    /// The preconditioner of CG (`"jacobi"`, `"block-jacobi"`, `"multigrid"`).
    pub preconditioner: Option<&'static str>,
    /// Products by the operator `H` (matrix-free), for the iterative solvers.
    pub operator_applications: usize,
    /// For the clamped descent: vertices held on the boundary of their cube at the end.
    pub clamped_vertices: Option<usize>,
    /// Bytes of the solver's data (factor, or connectivity, coarse levels and vectors).
    pub memory_bytes: usize,
    /// For the iterative solvers: a model of the bytes one iteration moves between memory
    /// and the cores (every array read or written once per pass), to compare the time
    /// per iteration with the memory bandwidth.
    pub bytes_per_iteration: Option<usize>,
}

/// What an iterative solver reports after each iteration (for progress bars).
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Progress {
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
    /// The current estimate of that distance in voxels (see [`StoppingRule::Estimate`]).
    pub error_estimate: f64,
}

/// The result of [`regularize`].
#[derive(Clone, Debug)]
pub struct Regularization {
    /// Optimal positions, one per vertex.
    pub positions: Vec<DVec3>,
    /// Energy terms at the input positions.
    pub before: EnergyTerms,
    /// Energy terms at the optimal positions.
    pub after: EnergyTerms,
    /// Solver report.
    pub info: SolveInfo,
}

/// Regularizes `surface` with `normals` by an exact direct solve, starting from the
/// surface's own vertex positions.
pub fn regularize(
    surface: &DigitalSurface,
    normals: &NormalField,
    params: EnergyParams,
) -> Result<Regularization, RegularizeError> {
    let input = surface.positions();
    let energy = Energy::new(surface, normals, &input, params)?;
    let mut solver = DirectSolver::new(surface)?;
    let (positions, info) = solver.solve(&energy)?;
    Ok(Regularization { before: energy.terms(&input), after: energy.terms(&positions), positions, info })
}
