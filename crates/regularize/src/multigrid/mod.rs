//! Aggregation multigrid over the voxel hierarchy: the preconditioner of [`crate::CgSolver`].
//!
//! Level 0 is the surface itself, with the matrix-free operator. Level `l` groups the
//! vertices whose lattice corners fall in one cell of `2^l` voxels and are connected
//! through the surface inside it (the two sides of a thin sheet, or two labels' surfaces
//! that meet only outside the cell, are separate nodes: one translation for both was a
//! poor coarse space there, and cost multi-label surfaces a third more iterations,
//! `docs/design/connected-aggregates.md`); its operator is the
//! Galerkin product `P^T H P` for the piecewise-constant prolongation `P` (each coarse
//! node moves its fine vertices by one translation: the energy's near-kernel, since
//! translations only pay the small attachment term). Coarse operators are 3x3-block
//! sparse rows, stored in `f32`, and the whole cycle runs in `f32` SIMD vectors, the
//! surface's own residuals included (it only preconditions: the answer's accuracy is set
//! by CG's `f64` products and residuals; see `docs/design/solver-choice.md`). The
//! coarsest level (at most `coarsest_nodes` nodes; the
//! surface itself when it is that small) is factored by sparse Cholesky. The cycle is a
//! symmetric V-cycle whose smoother steps along `M^-1 r` for a block-diagonal majorant
//! `M >= H` (a block l1-Jacobi that leaves tangential directions undamped), convergent
//! for any damping in `(0, 2)` without eigenvalue estimates: a fixed symmetric positive
//! definite preconditioner. Its iteration counts on smooth fields are nearly independent
//! of the surface's size (`docs/performance.md`).

mod coarse;
mod cycle;
mod face;
mod fine;
mod hierarchy;
mod parts;
#[cfg(test)]
pub(crate) mod tests;

pub(crate) use cycle::Vcycle;
pub(crate) use hierarchy::Hierarchy;
pub use hierarchy::MultigridParams;
