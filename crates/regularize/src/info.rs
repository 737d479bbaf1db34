//! What each solver reports about a solve.

use serde::Serialize;

/// The preconditioner of the iterative solvers ([`crate::CgSolver`],
/// [`crate::BoundedSolver`]).
#[derive(Copy, Clone, Debug, PartialEq, Eq, Default, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Preconditioner {
    /// None: plain conjugate gradient or steepest descent.
    Identity,
    /// The scalar diagonal of `H`.
    Jacobi,
    /// The 3x3 diagonal blocks of `H` (couples the coordinates through the normals).
    BlockJacobi,
    /// One symmetric V-cycle of aggregation multigrid over the voxel hierarchy (see
    /// [`crate::MultigridParams`]): several times fewer iterations than the others.
    #[default]
    Multigrid,
}

impl Preconditioner {
    /// A short name for reports: `"identity"`, `"jacobi"`, `"block-jacobi"`, `"multigrid"`.
    pub fn name(&self) -> &'static str {
        match self {
            Preconditioner::Identity => "identity",
            Preconditioner::Jacobi => "jacobi",
            Preconditioner::BlockJacobi => "block-jacobi",
            Preconditioner::Multigrid => "multigrid",
        }
    }
}

/// Seconds spent in each step of a solve.
///
/// `structure` and `symbolic` are spent once per surface (the first solve of a reused
/// solver pays them; later solves report `0`).
#[derive(Copy, Clone, Debug, Default, PartialEq, Serialize)]
pub struct SolveTimings {
    /// The operator's sparsity pattern or connectivity, and the multigrid hierarchy.
    pub structure: f64,
    /// Fill-reducing ordering and symbolic factorization (direct solver only).
    pub symbolic: f64,
    /// Numeric assembly: coefficients, coarse operators.
    pub assemble: f64,
    /// Numeric factorization: the whole operator (direct) or the coarsest multigrid level.
    pub factor: f64,
    /// Triangular solves and refinement, or the iterations.
    pub solve: f64,
}

impl SolveTimings {
    /// The sum of every step.
    pub fn total(&self) -> f64 {
        self.structure + self.symbolic + self.assemble + self.factor + self.solve
    }
}

/// What [`crate::DirectSolver`] reports.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct DirectInfo {
    /// Iterative refinement steps after the first triangular solve.
    pub refinement_steps: usize,
    /// Certificate: `|grad E(p*)| / |grad E(p)|` at the result relative to the input.
    pub relative_gradient: f64,
    /// Entries of the Cholesky factor.
    pub factor_nnz: usize,
    /// Bytes of the factor and the pattern.
    pub memory_bytes: usize,
    /// Seconds per step.
    pub seconds: SolveTimings,
}

/// What [`crate::CgSolver`] reports.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CgInfo {
    /// Iterations.
    pub iterations: usize,
    /// Of those, the first ones preconditioned by the previous solve's multigrid cycle (a
    /// quick start of a warm re-solve, [`crate::Run::warm`](crate::Run::warm()); 0 otherwise).
    pub quick_start_iterations: usize,
    /// Products by the operator `H` (matrix-free).
    pub operator_applications: usize,
    /// Certificate: `|grad E(p*)| / |grad E(p)|` at the result relative to the input.
    pub relative_gradient: f64,
    /// A guaranteed bound, in voxels, on the distance of every vertex to the exact
    /// minimizer: `|grad E|_2 / (2 alpha_min h)` (see [`crate::CgParams::tolerance`]).
    pub error_bound: f64,
    /// The estimated distance, in voxels, of the farthest vertex to the exact minimizer
    /// (see [`crate::StoppingRule::Estimate`]).
    pub error_estimate: f64,
    /// Whether the stopping rule was met.
    pub converged: bool,
    /// The preconditioner.
    pub preconditioner: Preconditioner,
    /// Bytes of the solver's data (connectivity, coarse levels, vectors).
    pub memory_bytes: usize,
    /// A model of the bytes one iteration moves between memory and the cores (every array
    /// read or written once per pass), to compare the time per iteration with the memory
    /// bandwidth.
    pub bytes_per_iteration: usize,
    /// Seconds per step.
    pub seconds: SolveTimings,
}

/// What [`crate::BoundedSolver`] reports.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct BoundedInfo {
    /// MPRGP's iterations, after the active-set rounds (`0` when the rounds settled:
    /// their iterate is then the minimizer in the boxes).
    pub iterations: usize,
    /// Products by the operator `H`, every phase included.
    pub operator_applications: usize,
    /// Of [`BoundedInfo::operator_applications`], those of the unconstrained start
    /// (`0` without boxes or with [`crate::BoundedParams::conjugate`] off).
    pub start_applications: usize,
    /// Active-set rounds run ([`crate::BoundedParams::active_set_rounds`]).
    pub active_set_rounds: usize,
    /// Of [`BoundedInfo::operator_applications`], those of the active-set rounds.
    pub active_set_applications: usize,
    /// The active-set rounds' conjugate gradient iterations, all rounds together.
    pub active_set_iterations: usize,
    /// Certificate: the norm of the projected gradient at the result relative to the
    /// gradient at the input.
    pub relative_gradient: f64,
    /// Without boxes, the guaranteed bound of [`CgInfo::error_bound`]; `None` with boxes
    /// (the minimizer over the boxes is another one).
    pub error_bound: Option<f64>,
    /// The estimated remaining movement of the farthest vertex, in voxels.
    pub error_estimate: f64,
    /// Whether the stopping rule was met.
    pub converged: bool,
    /// The box margin in voxels, when clamping.
    pub clamp: Option<f64>,
    /// Vertices held on the boundary of their box at the end (`0` without boxes).
    pub clamped_vertices: usize,
    /// The preconditioner.
    pub preconditioner: Preconditioner,
    /// Bytes of the solver's data.
    pub memory_bytes: usize,
    /// The memory-traffic model of [`CgInfo::bytes_per_iteration`].
    pub bytes_per_iteration: usize,
    /// Seconds per step.
    pub seconds: SolveTimings,
}

/// What [`crate::SweepsSolver`] reports.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SweepsInfo {
    /// Sweeps done (each one product by the operator).
    pub iterations: usize,
    /// `|b - H x|` before the last sweep relative to its value at the start.
    pub relative_gradient: f64,
    /// The largest move of a vertex in the last sweep, in voxels (of the finest spacing).
    pub last_move: f64,
    /// Bytes of the solver's data (connectivity, block inverses, vectors).
    pub memory_bytes: usize,
    /// Seconds per step.
    pub seconds: SolveTimings,
}

/// What a solver reports about its solve: the report of the solver that ran.
#[derive(Clone, Debug, PartialEq, Serialize)]
#[serde(tag = "solver", rename_all = "snake_case")]
pub enum SolveInfo {
    /// Sparse Cholesky.
    Direct(DirectInfo),
    /// Preconditioned conjugate gradient.
    Cg(CgInfo),
    /// Bound-constrained preconditioned conjugate gradient.
    Bounded(BoundedInfo),
    /// Damped block-Jacobi sweeps (a fixed count: always "converged").
    Sweeps(SweepsInfo),
}

impl SolveInfo {
    /// `"direct"`, `"cg"`, `"bounded"` or `"sweeps"`.
    pub fn name(&self) -> &'static str {
        match self {
            SolveInfo::Direct(_) => "direct",
            SolveInfo::Cg(_) => "cg",
            SolveInfo::Bounded(_) => "bounded",
            SolveInfo::Sweeps(_) => "sweeps",
        }
    }

    /// The certificate `|grad E(p*)| / |grad E(p)|` (projected for the bounded solver).
    pub fn relative_gradient(&self) -> f64 {
        match self {
            SolveInfo::Direct(i) => i.relative_gradient,
            SolveInfo::Cg(i) => i.relative_gradient,
            SolveInfo::Bounded(i) => i.relative_gradient,
            SolveInfo::Sweeps(i) => i.relative_gradient,
        }
    }

    /// Whether the solve met its stopping rule (always for the direct solver).
    pub fn converged(&self) -> bool {
        match self {
            SolveInfo::Direct(_) => true,
            SolveInfo::Cg(i) => i.converged,
            SolveInfo::Bounded(i) => i.converged,
            SolveInfo::Sweeps(_) => true,
        }
    }

    /// Iterations of the iterative solvers (for the clamped one, its active-set rounds'
    /// and MPRGP's, without the unconstrained start); for the direct solver, `1` plus its
    /// refinement steps.
    pub fn iterations(&self) -> usize {
        match self {
            SolveInfo::Direct(i) => 1 + i.refinement_steps,
            SolveInfo::Cg(i) => i.iterations,
            SolveInfo::Bounded(i) => i.active_set_iterations + i.iterations,
            SolveInfo::Sweeps(i) => i.iterations,
        }
    }

    /// The estimated distance to the minimizer in voxels (`None` for the direct solver,
    /// exact up to rounding, and for the sweeps, which stop early on purpose).
    pub fn error_estimate(&self) -> Option<f64> {
        match self {
            SolveInfo::Direct(_) => None,
            SolveInfo::Cg(i) => Some(i.error_estimate),
            SolveInfo::Bounded(i) => Some(i.error_estimate),
            SolveInfo::Sweeps(_) => None,
        }
    }

    /// Seconds per step.
    pub fn seconds(&self) -> &SolveTimings {
        match self {
            SolveInfo::Direct(i) => &i.seconds,
            SolveInfo::Cg(i) => &i.seconds,
            SolveInfo::Bounded(i) => &i.seconds,
            SolveInfo::Sweeps(i) => &i.seconds,
        }
    }

    /// Bytes of the solver's data.
    pub fn memory_bytes(&self) -> usize {
        match self {
            SolveInfo::Direct(i) => i.memory_bytes,
            SolveInfo::Cg(i) => i.memory_bytes,
            SolveInfo::Bounded(i) => i.memory_bytes,
            SolveInfo::Sweeps(i) => i.memory_bytes,
        }
    }
}
