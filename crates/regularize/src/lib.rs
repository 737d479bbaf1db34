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
//!   clamped to the voxels' boxes: never self-intersecting). What differs between the
//!   fidelity and the clamped pipeline is a type, [`Mode`]: [`Fidelity`] owns the
//!   re-centring and the intermediate tolerance, [`Clamped`] the boxes, both a
//!   [`Refinement`].
//! - The pipeline runs as named stages (normals, then per round refine and solve, then
//!   finish), each in its own module, looped by the [`Regularizer`]; progress reports
//!   name them ([`Stage`], [`Event`]).
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
mod error;
mod faces;
mod info;
mod iterative;
mod mode;
mod multigrid;
mod options;
mod params;
mod progress;
mod regularizer;
mod report;
mod request;
mod solver;
mod stages;
mod stencil;
mod sweeps;
mod unfold;
mod vecops;
mod weights;

pub use assemble::{Operator, OperatorPattern};
pub use block::{lattice_id, regularize_block, Block, BlockMesh, CUT_MARGIN, MIN_HALO};
pub use bounded::{BoundedParams, BoundedSolver};
pub use cg::{CgParams, CgSolver, StoppingRule};
pub use direct::DirectSolver;
pub use energy::{Energy, EnergyParams, EnergyTerms, MAX_STIFFNESS_RATIO};
pub use error::RegularizeError;
pub use info::{BoundedInfo, CgInfo, DirectInfo, Preconditioner, SolveInfo, SolveTimings, SweepsInfo};
pub use mode::{Clamped, Creases, Fidelity, Mode, Recentring, Refinement};
pub use multigrid::MultigridParams;
pub use options::{Clamp, InputFacts, Overrides, Preset, Regions};
pub use params::{EstimatedNormals, Estimator, NormalsParams, Params};
pub use progress::Progress;
pub use regularizer::{
    estimated_bytes, max_surfels_within, regularize, Budgeted, Output, Regularizer, Run, BYTES_FIXED,
    BYTES_PER_SURFEL, BYTES_PER_SURFEL_CLAMPED, BYTES_PER_SURFEL_SWEEPS,
};
pub use report::{EnergyReport, NormalsReport, Report, StageTimes};
pub use request::{SolveRequest, SolveStart};
pub use solver::{estimate_factor_nnz, ClampOverride, OverrideError, Solver, SolverChoice, SolverParams};
pub use stages::{Event, Stage};
pub use stencil::MatrixFreeOperator;
pub use sweeps::{SweepsParams, SweepsSolver};
/// The flag that stops a run early ([`Regularizer::set_interrupt`]), from
/// `voxreg-normals`, whose estimators poll it too.
pub use voxreg_normals::Interrupt;
pub use weights::{colour_discontinuities, junction_vertices, FairnessMask, Weights};
