//! The sparse SPD systems of AT and their two solvers: faer's sparse Cholesky (symbolic
//! analysis once, numeric factorization per solve) and Jacobi-preconditioned conjugate
//! gradients (warm-started, with the Cholesky solve as fallback).

use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::sparse::linalg::cholesky::{
    factorize_symbolic_cholesky, CholeskySymbolicParams, SymbolicCholesky, SymmetricOrdering,
};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMat};
use faer::{Conj, MatMut, Side};
use rayon::prelude::*;

use crate::error::NormalError;

/// Rows per parallel task in the matrix-vector products.
const ROWS_PER_TASK: usize = 8192;

/// What one solve cost.
#[derive(Copy, Clone, Debug, Default)]
pub(super) struct SolveStats {
    pub(super) cg_iterations: usize,
    pub(super) factorizations: usize,
    pub(super) factor_seconds: f64,
    pub(super) solve_seconds: f64,
}

/// A symmetric positive definite `n x n` matrix with a fixed pattern: a diagonal plus
/// given off-diagonal pairs, stored twice (lower compressed columns for Cholesky, full
/// compressed rows for the matrix-vector products of CG), with both solvers' state.
pub(super) struct SpdSystem {
    n: usize,
    /// Lower triangle, compressed columns; each column starts with its diagonal.
    lower: SymbolicSparseColMat<usize>,
    /// Slot of each off-diagonal pair's entry in `values`.
    pair_slot: Vec<usize>,
    /// Numeric values of the lower triangle.
    values: Vec<f64>,
    /// Full pattern, compressed rows: `row_ptr`, column indices and, for each entry, its
    /// slot in `values`.
    row_ptr: Vec<usize>,
    col_idx: Vec<u32>,
    from_lower: Vec<u32>,
    full_values: Vec<f64>,
    inv_diag: Vec<f64>,
    /// Symbolic Cholesky, computed on the first direct solve.
    symbolic: Option<SymbolicCholesky<usize>>,
    factor: Vec<f64>,
}

impl std::fmt::Debug for SpdSystem {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SpdSystem")
            .field("n", &self.n)
            .field("nnz_lower", &self.values.len())
            .field("analysed", &self.symbolic.is_some())
            .finish()
    }
}

impl SpdSystem {
    /// The pattern of an `n x n` matrix coupling the given pairs `(i, j)`, `i != j`, each
    /// at most once.
    pub(super) fn new(n: usize, pairs: impl ExactSizeIterator<Item = [u32; 2]>) -> Self {
        let mut keyed: Vec<(u32, u32, u32)> =
            pairs.enumerate().map(|(p, [a, b])| (a.min(b), a.max(b), p as u32)).collect();
        keyed.par_sort_unstable();
        let mut col_ptr = Vec::with_capacity(n + 1);
        let mut row_idx = Vec::with_capacity(n + keyed.len());
        let mut pair_slot = vec![0usize; keyed.len()];
        let mut k = 0;
        col_ptr.push(0);
        for j in 0..n {
            row_idx.push(j);
            while k < keyed.len() && keyed[k].0 as usize == j {
                pair_slot[keyed[k].2 as usize] = row_idx.len();
                row_idx.push(keyed[k].1 as usize);
                k += 1;
            }
            col_ptr.push(row_idx.len());
        }
        // Full rows: row i holds its diagonal and every partner, sorted by column.
        let mut degree = vec![1usize; n];
        for &(a, b, _) in &keyed {
            degree[a as usize] += 1;
            degree[b as usize] += 1;
        }
        let mut row_ptr = Vec::with_capacity(n + 1);
        row_ptr.push(0);
        for d in &degree {
            row_ptr.push(row_ptr.last().unwrap() + d);
        }
        let mut entries: Vec<Vec<(u32, u32)>> = degree.iter().map(|&d| Vec::with_capacity(d)).collect();
        for j in 0..n {
            entries[j].push((j as u32, col_ptr[j] as u32));
            for slot in col_ptr[j] + 1..col_ptr[j + 1] {
                let i = row_idx[slot];
                entries[j].push((i as u32, slot as u32));
                entries[i].push((j as u32, slot as u32));
            }
        }
        let mut col_idx = Vec::with_capacity(row_ptr[n]);
        let mut from_lower = Vec::with_capacity(row_ptr[n]);
        for mut row in entries {
            row.sort_unstable();
            for (c, slot) in row {
                col_idx.push(c);
                from_lower.push(slot);
            }
        }
        let nnz = row_idx.len();
        SpdSystem {
            n,
            lower: SymbolicSparseColMat::new_checked(n, n, col_ptr, None, row_idx),
            pair_slot,
            values: vec![0.0; nnz],
            row_ptr,
            full_values: vec![0.0; col_idx.len()],
            col_idx,
            from_lower,
            inv_diag: vec![0.0; n],
            symbolic: None,
            factor: Vec::new(),
        }
    }

    /// The numeric values to assemble: `(diagonal slots, pair slots, values)`; the diagonal
    /// of column `j` is at `lower.col_ptr()[j]`.
    pub(super) fn values_mut(&mut self) -> (&[usize], &[usize], &mut [f64]) {
        (&self.lower.col_ptr()[..self.n], &self.pair_slot, &mut self.values)
    }

    /// Solves `A x = b` for `K` right-hand sides (interleaved per row), to a relative
    /// residual `tolerance` per column with CG from the initial guess in `x`, or directly
    /// when `tolerance` is `None` or CG has not converged in `max_iterations`.
    pub(super) fn solve<const K: usize>(
        &mut self,
        b: &[[f64; K]],
        x: &mut [[f64; K]],
        tolerance: Option<f64>,
        max_iterations: usize,
        par: faer::Par,
    ) -> Result<SolveStats, NormalError> {
        let mut stats = SolveStats::default();
        if let Some(tol) = tolerance {
            let t = std::time::Instant::now();
            let (converged, iterations) = self.cg(b, x, tol, max_iterations);
            stats.cg_iterations = iterations;
            stats.solve_seconds = t.elapsed().as_secs_f64();
            if converged {
                return Ok(stats);
            }
        }
        self.direct(b, x, par, &mut stats)?;
        Ok(stats)
    }

    fn direct<const K: usize>(
        &mut self,
        b: &[[f64; K]],
        x: &mut [[f64; K]],
        par: faer::Par,
        stats: &mut SolveStats,
    ) -> Result<(), NormalError> {
        let t = std::time::Instant::now();
        if self.symbolic.is_none() {
            let symbolic = factorize_symbolic_cholesky(
                self.lower.as_ref(),
                Side::Lower,
                SymmetricOrdering::Amd,
                CholeskySymbolicParams::default(),
            )
            .map_err(|e| NormalError::Solver(format!("symbolic Cholesky analysis failed: {e:?}")))?;
            self.factor = vec![0.0; symbolic.len_val()];
            self.symbolic = Some(symbolic);
        }
        let symbolic = self.symbolic.as_ref().expect("analysed above");
        // Sequential solves: they are memory-bound, and faer's parallel supernodal solve was
        // slower (see docs/design/at-linear-solver.md).
        let mut mem = MemBuffer::try_new(StackReq::any_of(&[
            symbolic.factorize_numeric_llt_scratch::<f64>(par, Default::default()),
            symbolic.solve_in_place_scratch::<f64>(K, faer::Par::Seq),
        ]))
        .map_err(|_| NormalError::Solver("out of memory for the Cholesky workspace".into()))?;
        let llt = symbolic
            .factorize_numeric_llt::<f64>(
                &mut self.factor,
                SparseColMatRef::new(self.lower.as_ref(), &self.values),
                Side::Lower,
                LltRegularization::default(),
                par,
                MemStack::new(&mut mem),
                Default::default(),
            )
            .map_err(|e| NormalError::Solver(format!("numeric Cholesky failed: {e:?}")))?;
        stats.factorizations += 1;
        stats.factor_seconds += t.elapsed().as_secs_f64();
        let t = std::time::Instant::now();
        let n = self.n;
        let mut rhs = vec![0.0; n * K];
        for (i, row) in b.iter().enumerate() {
            for c in 0..K {
                rhs[c * n + i] = row[c];
            }
        }
        llt.solve_in_place_with_conj(
            Conj::No,
            MatMut::from_column_major_slice_mut(&mut rhs, n, K),
            faer::Par::Seq,
            MemStack::new(&mut mem),
        );
        for (i, row) in x.iter_mut().enumerate() {
            for c in 0..K {
                row[c] = rhs[c * n + i];
            }
        }
        stats.solve_seconds += t.elapsed().as_secs_f64();
        Ok(())
    }

    /// Copies the lower values into the full rows and inverts the diagonal.
    fn sync_full(&mut self) {
        let (values, from_lower) = (&self.values, &self.from_lower);
        self.full_values.par_iter_mut().zip(from_lower).for_each(|(v, &s)| *v = values[s as usize]);
        let col_ptr = &self.lower.col_ptr()[..self.n];
        self.inv_diag.par_iter_mut().zip(col_ptr).for_each(|(d, &s)| *d = 1.0 / values[s]);
    }

    /// `y = A x`, rows in parallel.
    fn apply<const K: usize>(&self, x: &[[f64; K]], y: &mut [[f64; K]]) {
        let (row_ptr, col_idx, vals) = (&self.row_ptr, &self.col_idx, &self.full_values);
        y.par_chunks_mut(ROWS_PER_TASK).enumerate().for_each(|(t, chunk)| {
            let rows = &row_ptr[t * ROWS_PER_TASK..t * ROWS_PER_TASK + chunk.len() + 1];
            for (out, w) in chunk.iter_mut().zip(rows.windows(2)) {
                let mut acc = [0.0; K];
                for (a, &j) in vals[w[0]..w[1]].iter().zip(&col_idx[w[0]..w[1]]) {
                    let xj = &x[j as usize];
                    for c in 0..K {
                        acc[c] += a * xj[c];
                    }
                }
                *out = acc;
            }
        });
    }

    /// Jacobi-preconditioned CG on the `K` columns in lockstep, in the Chronopoulos-Gear
    /// form: one matrix-vector product and two passes over the vectors per iteration, with
    /// all inner products of an iteration reduced together. Returns whether every column
    /// reached `||b - A x|| <= tol ||b||`, and the iterations run.
    fn cg<const K: usize>(
        &mut self,
        b: &[[f64; K]],
        x: &mut [[f64; K]],
        tol: f64,
        max_iterations: usize,
    ) -> (bool, usize) {
        self.sync_full();
        let n = self.n;
        let zero = vec![[0.0; K]; n];
        let (mut r, mut u, mut w, mut p, mut s) =
            (zero.clone(), zero.clone(), zero.clone(), zero.clone(), zero);
        // r = b - A x, u = D^-1 r; sums |b|^2, |r|^2, r.u.
        self.apply(x, &mut w);
        let inv_diag = &self.inv_diag;
        let [b2, mut r2, mut gamma] = r
            .par_chunks_mut(ROWS_PER_TASK)
            .zip(u.par_chunks_mut(ROWS_PER_TASK))
            .enumerate()
            .map(|(t, (rc, uc))| {
                let o = t * ROWS_PER_TASK;
                let mut sums = [[0.0; K]; 3];
                for (k, (ri, ui)) in rc.iter_mut().zip(uc.iter_mut()).enumerate() {
                    let (bi, wi, d) = (&b[o + k], &w[o + k], inv_diag[o + k]);
                    for c in 0..K {
                        ri[c] = bi[c] - wi[c];
                        ui[c] = d * ri[c];
                        sums[0][c] += bi[c] * bi[c];
                        sums[1][c] += ri[c] * ri[c];
                        sums[2][c] += ri[c] * ui[c];
                    }
                }
                sums
            })
            .collect::<Vec<_>>()
            .into_iter()
            .fold([[0.0; K]; 3], add_sums);
        let limit: [f64; K] = std::array::from_fn(|c| tol * tol * b2[c]);
        let mut alpha = [0.0; K];
        let mut beta = [0.0; K];
        let mut iterations = 0;
        loop {
            if (0..K).all(|c| r2[c] <= limit[c]) {
                return (true, iterations);
            }
            if iterations == max_iterations || !(0..K).all(|c| r2[c].is_finite()) {
                return (false, iterations);
            }
            // w = A u and delta = w.u.
            let delta = self.apply_dot(&u, &mut w);
            for c in 0..K {
                // A column solved exactly (gamma = 0) or broken down (alpha = 0) stays put.
                let stalled = iterations > 0 && alpha[c] == 0.0;
                let denominator =
                    delta[c] - if iterations == 0 { 0.0 } else { beta[c] * gamma[c] / alpha[c] };
                alpha[c] = if !stalled && denominator > 0.0 && gamma[c] > 0.0 {
                    gamma[c] / denominator
                } else {
                    0.0
                };
            }
            iterations += 1;
            // p = u + beta p, s = w + beta s, x += alpha p, r -= alpha s, u = D^-1 r;
            // sums |r|^2 and r.u.
            let [new_r2, new_gamma, _] = x
                .par_chunks_mut(ROWS_PER_TASK)
                .zip(r.par_chunks_mut(ROWS_PER_TASK))
                .zip(u.par_chunks_mut(ROWS_PER_TASK))
                .zip(p.par_chunks_mut(ROWS_PER_TASK).zip(s.par_chunks_mut(ROWS_PER_TASK)))
                .enumerate()
                .map(|(t, (((xc, rc), uc), (pc, sc)))| {
                    let o = t * ROWS_PER_TASK;
                    let mut sums = [[0.0; K]; 3];
                    for k in 0..xc.len() {
                        let (wi, d) = (&w[o + k], inv_diag[o + k]);
                        for c in 0..K {
                            pc[k][c] = uc[k][c] + beta[c] * pc[k][c];
                            sc[k][c] = wi[c] + beta[c] * sc[k][c];
                            xc[k][c] += alpha[c] * pc[k][c];
                            rc[k][c] -= alpha[c] * sc[k][c];
                            uc[k][c] = d * rc[k][c];
                            sums[0][c] += rc[k][c] * rc[k][c];
                            sums[1][c] += rc[k][c] * uc[k][c];
                        }
                    }
                    sums
                })
                .collect::<Vec<_>>()
                .into_iter()
                .fold([[0.0; K]; 3], add_sums);
            beta = std::array::from_fn(|c| if gamma[c] > 0.0 { new_gamma[c] / gamma[c] } else { 0.0 });
            (r2, gamma) = (new_r2, new_gamma);
        }
    }

    /// `y = A x` and the column sums of `x * y`, rows in parallel.
    fn apply_dot<const K: usize>(&self, x: &[[f64; K]], y: &mut [[f64; K]]) -> [f64; K] {
        let (row_ptr, col_idx, vals) = (&self.row_ptr, &self.col_idx, &self.full_values);
        y.par_chunks_mut(ROWS_PER_TASK)
            .enumerate()
            .map(|(t, chunk)| {
                let o = t * ROWS_PER_TASK;
                let rows = &row_ptr[o..o + chunk.len() + 1];
                let mut dot = [0.0; K];
                for (k, (out, w)) in chunk.iter_mut().zip(rows.windows(2)).enumerate() {
                    let mut acc = [0.0; K];
                    for (a, &j) in vals[w[0]..w[1]].iter().zip(&col_idx[w[0]..w[1]]) {
                        let xj = &x[j as usize];
                        for c in 0..K {
                            acc[c] += a * xj[c];
                        }
                    }
                    for c in 0..K {
                        dot[c] += acc[c] * x[o + k][c];
                    }
                    *out = acc;
                }
                dot
            })
            .collect::<Vec<_>>()
            .into_iter()
            .fold([0.0; K], |a, b| std::array::from_fn(|c| a[c] + b[c]))
    }
}

fn add_sums<const K: usize>(a: [[f64; K]; 3], b: [[f64; K]; 3]) -> [[f64; K]; 3] {
    std::array::from_fn(|i| std::array::from_fn(|c| a[i][c] + b[i][c]))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 2D grid Laplacian plus a diagonal shift: CG and Cholesky agree.
    #[test]
    fn cg_matches_cholesky_on_a_grid() {
        let side = 60usize;
        let n = side * side;
        let mut pairs = Vec::new();
        for y in 0..side {
            for x in 0..side {
                let i = (x + side * y) as u32;
                if x + 1 < side {
                    pairs.push([i, i + 1]);
                }
                if y + 1 < side {
                    pairs.push([i, i + side as u32]);
                }
            }
        }
        let mut sys = SpdSystem::new(n, pairs.iter().copied());
        let (diag, pair_slot, values) = sys.values_mut();
        let diag = diag.to_vec();
        for &d in &diag {
            values[d] = 0.1;
        }
        for (p, &slot) in pairs.iter().zip(pair_slot) {
            values[diag[p[0] as usize]] += 1.0;
            values[diag[p[1] as usize]] += 1.0;
            values[slot] = -1.0;
        }
        let b: Vec<[f64; 3]> = (0..n).map(|i| [(i % 7) as f64, 1.0, (i % 3) as f64 - 1.0]).collect();
        let mut x_cg = vec![[0.0; 3]; n];
        let stats = sys.solve(&b, &mut x_cg, Some(1e-10), 10_000, faer::Par::Seq).unwrap();
        assert!(stats.cg_iterations > 0 && stats.factorizations == 0);
        let mut x_direct = vec![[0.0; 3]; n];
        let stats = sys.solve(&b, &mut x_direct, None, 0, faer::Par::Seq).unwrap();
        assert_eq!(stats.factorizations, 1);
        // CG that cannot converge in 2 iterations falls back to Cholesky.
        let mut x_fallback = vec![[0.0; 3]; n];
        let stats = sys.solve(&b, &mut x_fallback, Some(1e-10), 2, faer::Par::Seq).unwrap();
        assert_eq!((stats.cg_iterations, stats.factorizations), (2, 1));
        assert_eq!(x_fallback, x_direct);
        let err = x_cg
            .iter()
            .zip(&x_direct)
            .flat_map(|(a, b)| (0..3).map(move |c| (a[c] - b[c]).abs()))
            .fold(0.0, f64::max);
        assert!(err < 1e-6, "{err}");
    }
}
