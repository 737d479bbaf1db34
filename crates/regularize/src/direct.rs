//! The exact direct solve: sparse Cholesky (faer), symbolic analysis kept for reuse.

use std::time::Instant;

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::perm::PermRef;
use faer::sparse::linalg::cholesky::{
    factorize_symbolic_cholesky, CholeskySymbolicParams, LltRef, SymbolicCholesky, SymmetricOrdering,
};
use faer::{Conj, MatMut, Side};
use glam::DVec3;

use crate::assemble::{Operator, OperatorPattern};
use crate::energy::Energy;
use crate::error::RegularizeError;
use crate::info::{DirectInfo, SolveTimings};

/// A direct solver for the energy's linear system, reusable across solves on the same
/// surface.
///
/// [`DirectSolver::new`] analyses the operator's sparsity pattern once (fill-reducing
/// ordering and symbolic Cholesky); each [`DirectSolver::solve`] only assembles the
/// numeric values, factors and solves. Use one solver for parameter sweeps, normal
/// refinement rounds or interactive edits of the weights.
#[derive(Debug)]
pub struct DirectSolver {
    pattern: OperatorPattern,
    symbolic: SymbolicCholesky<usize>,
    factor: Vec<f64>,
    pattern_seconds: f64,
    symbolic_seconds: f64,
}

impl DirectSolver {
    /// The solver of energies on `surface`: builds its operator pattern
    /// ([`OperatorPattern::new`]) and analyses it ([`DirectSolver::new`]).
    pub fn for_surface(surface: &voxreg_digisurf::DigitalSurface) -> Result<Self, RegularizeError> {
        let t = Instant::now();
        let pattern = OperatorPattern::new(surface)?;
        let mut solver = Self::new(pattern)?;
        solver.pattern_seconds = t.elapsed().as_secs_f64() - solver.symbolic_seconds;
        Ok(solver)
    }

    /// Analyses the operator's sparsity `pattern` (fill-reducing ordering, symbolic
    /// Cholesky): no numeric work yet.
    pub fn new(pattern: OperatorPattern) -> Result<Self, RegularizeError> {
        let pattern_seconds = 0.0;
        let t = Instant::now();
        let (fwd, inv) = pattern.block_amd_ordering()?;
        let perm = PermRef::new_checked(&fwd, &inv, pattern.dim());
        let symbolic = factorize_symbolic_cholesky(
            pattern.symbolic().as_ref(),
            Side::Lower,
            SymmetricOrdering::Custom(perm),
            CholeskySymbolicParams::default(),
        )
        .map_err(|e| RegularizeError::Factorization(format!("symbolic analysis failed: {e:?}")))?;
        Ok(DirectSolver {
            pattern,
            symbolic,
            factor: Vec::new(),
            pattern_seconds,
            symbolic_seconds: t.elapsed().as_secs_f64(),
        })
    }

    /// Number of stored entries of the Cholesky factor (known after [`DirectSolver::new`]):
    /// the factor takes `8 *` this many bytes.
    pub fn factor_nnz(&self) -> usize {
        self.symbolic.len_val()
    }

    /// The operator pattern.
    pub fn pattern(&self) -> &OperatorPattern {
        &self.pattern
    }

    /// Minimizes `energy` exactly; returns the optimal positions and a certificate.
    ///
    /// Solves for the displacement from the input positions, `H u = -grad E(p) / 2`
    /// (translation-invariant and small, so rounding stays relative to the voxel size),
    /// then refines with the matrix-free gradient until the relative gradient norm
    /// `|grad E(p*)| / |grad E(p)|` is below `1e-12` (at most 3 refinement steps).
    pub fn solve(&mut self, energy: &Energy<'_>) -> Result<(Vec<DVec3>, DirectInfo), RegularizeError> {
        let input = energy.input();
        if input.len() * 3 != self.pattern.dim() {
            return Err(RegularizeError::SizeMismatch("the energy is not on this solver's surface".into()));
        }
        let t = Instant::now();
        let operator = Operator::assemble(&self.pattern, energy);
        let assemble_seconds = t.elapsed().as_secs_f64();

        let t = Instant::now();
        self.factor.clear();
        self.factor.try_reserve_exact(self.symbolic.len_val()).map_err(|_| {
            RegularizeError::OutOfMemory(format!("Cholesky factor of {} entries", self.factor_nnz()))
        })?;
        self.factor.resize(self.symbolic.len_val(), 0.0);
        // A fixed split of the work, whatever the thread count, so that the factor has the
        // same bits at every thread count.
        let par = faer::Par::rayon(4);
        let mut mem =
            MemBuffer::try_new(self.symbolic.factorize_numeric_llt_scratch::<f64>(par, Default::default()))
                .map_err(|_| RegularizeError::OutOfMemory("Cholesky workspace".into()))?;
        self.symbolic
            .factorize_numeric_llt::<f64>(
                &mut self.factor,
                operator.matrix().as_ref(),
                Side::Lower,
                LltRegularization::default(),
                par,
                MemStack::new(&mut mem),
                Default::default(),
            )
            .map_err(|e| RegularizeError::Factorization(format!("numeric Cholesky failed: {e:?}")))?;
        let factor_seconds = t.elapsed().as_secs_f64();

        let t = Instant::now();
        let llt = LltRef::new(&self.symbolic, &self.factor);
        let mut solve_mem = MemBuffer::try_new(self.symbolic.solve_in_place_scratch::<f64>(1, par))
            .map_err(|_| RegularizeError::OutOfMemory("solve workspace".into()))?;
        let g0 = energy.gradient(input);
        let g0_norm = norm(&g0);
        let mut x: Vec<DVec3> = input.to_vec();
        let mut g = g0;
        let mut refinements = 0;
        let mut relative = 1.0;
        for step in 0..4 {
            // Newton step on the quadratic: H dx = -g / 2.
            let mut rhs: Vec<f64> = g.iter().flat_map(|v| (-0.5 * *v).to_array()).collect();
            llt.solve_in_place_with_conj(
                Conj::No,
                MatMut::from_column_major_slice_mut(&mut rhs, self.pattern.dim(), 1),
                par,
                MemStack::new(&mut solve_mem),
            );
            for (xi, d) in x.iter_mut().zip(rhs.chunks_exact(3)) {
                *xi += DVec3::new(d[0], d[1], d[2]);
            }
            g = energy.gradient(&x);
            relative = if g0_norm > 0.0 { norm(&g) / g0_norm } else { 0.0 };
            refinements = step;
            if relative <= 1e-12 {
                break;
            }
        }
        let solve_seconds = t.elapsed().as_secs_f64();
        tracing::debug!(relative, refinements, "direct solve done");
        Ok((
            x,
            DirectInfo {
                refinement_steps: refinements,
                relative_gradient: relative,
                factor_nnz: self.factor_nnz(),
                memory_bytes: 8 * self.factor.len() + 16 * self.pattern.nnz() / 9,
                seconds: SolveTimings {
                    structure: self.pattern_seconds,
                    symbolic: self.symbolic_seconds,
                    assemble: assemble_seconds,
                    factor: factor_seconds,
                    solve: solve_seconds,
                },
            },
        ))
    }
}

fn norm(v: &[DVec3]) -> f64 {
    v.iter().map(|x| x.length_squared()).sum::<f64>().sqrt()
}
