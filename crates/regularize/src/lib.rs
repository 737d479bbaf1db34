//! The quadratic regularization energy of digital surfaces, its solvers, and voxreg's
//! front door.
//!
//! Given a [`DigitalSurface`](voxreg_digisurf::DigitalSurface) (quads with input positions
//! `p`) and a normal field (one direction `n_f` per quad), the regularized positions
//! minimize the convex quadratic [`Energy`] of the papers (eq. 2 of
//! `multilabel-interfaces-tvcg`):
//!
//! ```text
//! E(P^) = alpha * sum_i |p_i - p^_i|^2                  (attachment)
//!       + beta  * sum_f sum_{edges e of f} (e . n_f)^2   (alignment)
//!       + gamma * sum_i |p^_i - b^_i|^2                  (fairness)
//! ```
//!
//! # The front door
//!
//! - [`regularize`]: a labelled volume in, regularized positions and a [`Report`] out
//!   ([`Output`]).
//! - [`Regularizer`]: the same, reusable: it keeps the surface, the solver's analysis and
//!   the initial normals across runs (parameter sweeps, interactive use). An
//!   [`Interrupt`] raised from another thread ([`Regularizer::set_interrupt`]) stops a run
//!   early with [`RegularizeError::Interrupted`] (an interactive front end replacing it).
//! - [`Preset`] and [`Overrides`]: the one place where a front end's options become
//!   [`Params`] ([`Overrides::resolve`]), shared by the command line, the viewer and Python.
//! - [`Params`], with three presets: [`Params::default`] (the fidelity pipeline: solve,
//!   then refine the normals from the result and solve again, re-centring the targets),
//!   [`Params::papers`] (the papers' single solve) and [`Params::voxel_art`] (one solve
//!   clamped to the voxels' boxes: never self-intersecting).
//!
//! # The layers below
//!
//! - [`Energy`]: value per term and exact gradient, matrix-free, with optional
//!   per-element [`Weights`] (texture-aware fairness: [`FairnessMask`]); [`Operator`] and
//!   [`OperatorPattern`]: the same quadratic form as a sparse matrix (eq. 28), its
//!   symbolic pattern built once per surface.
//! - Solvers, each with its `Params` and `Info`, chosen by [`Solver`] ([`SolverParams`]):
//!   [`DirectSolver`] (sparse Cholesky, exact), [`CgSolver`] (matrix-free conjugate
//!   gradient with a multigrid preconditioner over the voxel hierarchy, stopping at a
//!   tolerance in voxels) and [`BoundedSolver`] (the same CG inside per-vertex boxes, the
//!   clamping of the paper's sec. 3.4, which rules out self-intersections).
//!
//! # Example
//!
//! ```
//! use voxreg_digisurf::LabelVolume;
//! use voxreg_regularize::{regularize, Params};
//!
//! // A digital ball of radius 4.
//! let volume = LabelVolume::from_fn([11, 11, 11], |[x, y, z]| {
//!     let d = |c: usize| c as f64 - 5.0;
//!     u32::from(d(x).powi(2) + d(y).powi(2) + d(z).powi(2) <= 16.0)
//! });
//! let out = regularize(&volume, &Params::default())?;
//! assert_eq!(out.positions.len(), out.surface.num_vertices()); // one quad per voxel face
//! assert!(out.report.energy.after.total < out.report.energy.before.total);
//! assert!(out.report.converged());
//! // Every vertex stays within a voxel of the staircase.
//! let input = out.surface.positions();
//! assert!(out.positions.iter().zip(&input).all(|(x, p)| x.distance(*p) < 1.0));
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! # Features
//!
//! None.

mod assemble;
mod block;
mod bounded;
mod boxqp;
mod cg;
mod clamping;
mod direct;
mod energy;
mod faces;
mod info;
mod iterative;
mod multigrid;
mod options;
mod params;
mod pipeline;
mod regularizer;
mod report;
mod solver;
mod stencil;
mod unfold;
mod vecops;
mod weights;

pub use assemble::{Operator, OperatorPattern};
pub use block::{lattice_id, regularize_block, Block, BlockMesh, CUT_MARGIN, MIN_HALO};
pub use bounded::{BoundedParams, BoundedSolver};
pub use cg::{CgParams, CgSolver, StoppingRule};
pub use direct::DirectSolver;
pub use energy::{Energy, EnergyParams, EnergyTerms, MAX_STIFFNESS_RATIO};
pub use info::{BoundedInfo, CgInfo, DirectInfo, SolveInfo, SolveTimings};
pub use iterative::Preconditioner;
pub use multigrid::MultigridParams;
pub use options::{Clamp, InputFacts, Overrides, Preset, Regions};
pub use params::{EstimatedNormals, Estimator, NormalsParams, Params};
pub use regularizer::{
    estimated_bytes, regularize, Event, Output, Regularizer, Run, Stage, BYTES_FIXED, BYTES_PER_SURFEL,
    BYTES_PER_SURFEL_CLAMPED,
};
pub use report::{EnergyReport, NormalsReport, Report, StageTimes};
pub use solver::{
    estimate_factor_nnz, ClampOverride, OverrideError, SolveRequest, SolveStart, Solver, SolverChoice,
    SolverParams,
};
pub use stencil::MatrixFreeOperator;
/// The flag that stops a run early ([`Regularizer::set_interrupt`]), from
/// `voxreg-normals`, whose estimators poll it too.
pub use voxreg_normals::Interrupt;
pub use weights::{colour_discontinuities, junction_vertices, FairnessMask, Weights};

use glam::DVec3;
use voxreg_digisurf::SurfaceError;
use voxreg_normals::NormalError;

/// What can go wrong when regularizing.
#[derive(Debug, thiserror::Error, Clone, PartialEq)]
pub enum RegularizeError {
    /// The volume has no surface to regularize, or its regions are invalid.
    #[error(transparent)]
    Surface(#[from] SurfaceError),
    /// The normal estimator failed or was given invalid parameters.
    #[error(transparent)]
    Normals(NormalError),
    /// A weight is out of range.
    #[error("invalid parameters: {0}")]
    InvalidParams(String),
    /// A front end's option is out of range or conflicts with another
    /// ([`Overrides::resolve`]): `"{option} {message}"`, e.g. `alpha must be finite and
    /// positive, got 0`.
    #[error("{option} {message}")]
    InvalidOption {
        /// The option, as [`Overrides`] names it (`sharpen_threshold`).
        option: &'static str,
        /// What is wrong, starting with a verb.
        message: String,
    },
    /// Arrays do not match the surface (normals per surfel, positions per vertex).
    #[error("size mismatch: {0}")]
    SizeMismatch(String),
    /// The factorization failed (e.g. the system is not positive definite).
    #[error("factorization failed: {0}")]
    Factorization(String),
    /// Not enough memory for a solver's data.
    #[error("out of memory: {0}")]
    OutOfMemory(String),
    /// The computation left the finite numbers (weights or spacings whose scale the
    /// double-precision arithmetic cannot hold): never reported as converged.
    #[error("numerical failure: {0}")]
    NotFinite(String),
    /// The run's [`Interrupt`] was raised ([`Regularizer::set_interrupt`]): it stopped
    /// before its end, and returned nothing.
    #[error("interrupted")]
    Interrupted,
}

impl From<NormalError> for RegularizeError {
    /// [`NormalError::Interrupted`] becomes [`RegularizeError::Interrupted`]; the others
    /// are wrapped.
    fn from(e: NormalError) -> Self {
        match e {
            NormalError::Interrupted => RegularizeError::Interrupted,
            e => RegularizeError::Normals(e),
        }
    }
}

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
    /// The current estimate of that distance in voxels (see [`StoppingRule::Estimate`]).
    pub error_estimate: f64,
    /// The current iterate minus the solve's input positions ([`Energy::input`], the
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
