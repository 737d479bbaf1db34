//! The sparse operator of the energy (eq. 28), assembled straight into
//! compressed-column form.

use faer::sparse::{SparseColMat, SymbolicSparseColMat};
use glam::{DMat3, DVec3};
use rayon::prelude::*;
use voxreg_digisurf::{DigitalSurface, VertexId};

use crate::energy::Energy;
use crate::error::RegularizeError;

/// The sparsity pattern of the operator: for each vertex, the sorted vertices within two
/// edge-hops (the fairness term couples a vertex with its neighbours' neighbours).
///
/// Depends on the complex only: compute it once and reuse it when weights or normals
/// change. Entries are 3x3 blocks, stored as a full symmetric `3n x 3n` matrix in
/// compressed-column form, vertex `i` owning rows and columns `3i..3i+3`.
#[derive(Clone, Debug)]
pub struct OperatorPattern {
    /// Block column `j` holds block rows `ring[ring_offsets[j]..ring_offsets[j + 1]]`.
    ring_offsets: Vec<usize>,
    ring: Vec<u32>,
    symbolic: SymbolicSparseColMat<usize>,
}

impl OperatorPattern {
    /// The pattern of the operator of `surface`.
    pub fn new(surface: &DigitalSurface) -> Result<Self, RegularizeError> {
        let n = surface.num_vertices();
        let rings: Vec<Vec<u32>> = (0..n)
            .into_par_iter()
            .map(|j| {
                let vj = VertexId(j as u32);
                let mut r = vec![j as u32];
                for &w in surface.vertex_neighbours(vj) {
                    r.push(w.0);
                    r.extend(surface.vertex_neighbours(w).iter().map(|x| x.0));
                }
                r.sort_unstable();
                r.dedup();
                r
            })
            .collect();
        let mut ring_offsets = Vec::with_capacity(n + 1);
        ring_offsets.push(0);
        for r in &rings {
            ring_offsets.push(ring_offsets.last().unwrap() + r.len());
        }
        let ring: Vec<u32> = rings.into_iter().flatten().collect();

        let dim = 3 * n;
        let nnz = 9 * ring.len();
        let mut col_ptr = Vec::with_capacity(dim + 1);
        let mut row_idx = Vec::new();
        row_idx
            .try_reserve_exact(nnz)
            .map_err(|_| RegularizeError::OutOfMemory("operator pattern".into()))?;
        col_ptr.push(0usize);
        for j in 0..n {
            let block = &ring[ring_offsets[j]..ring_offsets[j + 1]];
            for _c in 0..3 {
                for &k in block {
                    let k = 3 * k as usize;
                    row_idx.extend([k, k + 1, k + 2]);
                }
                col_ptr.push(row_idx.len());
            }
        }
        let symbolic = SymbolicSparseColMat::new_checked(dim, dim, col_ptr, None, row_idx);
        Ok(OperatorPattern { ring_offsets, ring, symbolic })
    }

    /// The matrix dimension, `3n`.
    pub fn dim(&self) -> usize {
        self.symbolic.nrows()
    }

    /// Number of stored entries (both triangles).
    pub fn nnz(&self) -> usize {
        9 * self.ring.len()
    }

    /// The compressed-column structure.
    pub fn symbolic(&self) -> &SymbolicSparseColMat<usize> {
        &self.symbolic
    }

    /// A fill-reducing ordering of the `3n` unknowns: approximate minimum degree on the
    /// `n`-vertex block graph (9 times fewer entries than the scalar pattern), each vertex
    /// expanded to its 3 consecutive coordinates. Returns `(forward, inverse)`.
    pub fn block_amd_ordering(&self) -> Result<(Vec<usize>, Vec<usize>), RegularizeError> {
        use faer::dyn_stack::{MemBuffer, MemStack};
        use faer::sparse::linalg::amd;
        let n = self.ring_offsets.len() - 1;
        let row_idx: Vec<usize> = self.ring.iter().map(|&k| k as usize).collect();
        let graph = SymbolicSparseColMat::new_checked(n, n, self.ring_offsets.clone(), None, row_idx);
        let mut perm = vec![0usize; n];
        let mut perm_inv = vec![0usize; n];
        let mut mem = MemBuffer::try_new(amd::order_scratch::<usize>(n, self.ring.len()))
            .map_err(|_| RegularizeError::OutOfMemory("ordering workspace".into()))?;
        amd::order(
            &mut perm,
            &mut perm_inv,
            graph.as_ref(),
            amd::Control::default(),
            MemStack::new(&mut mem),
        )
        .map_err(|e| RegularizeError::Factorization(format!("ordering failed: {e:?}")))?;
        let fwd: Vec<usize> = perm.iter().flat_map(|&p| [3 * p, 3 * p + 1, 3 * p + 2]).collect();
        let mut inv = vec![0usize; 3 * n];
        for (i, &p) in fwd.iter().enumerate() {
            inv[p] = i;
        }
        Ok((fwd, inv))
    }

    fn block_rows(&self, j: usize) -> &[u32] {
        &self.ring[self.ring_offsets[j]..self.ring_offsets[j + 1]]
    }
}

/// The operator `H` of the energy as a sparse symmetric positive definite matrix:
/// `E(p^) = p^T H p^ - 2 alpha p^T p + alpha |p|^2`, so `grad E = 2 (H p^ - alpha p)`
/// and the minimizer solves `H p* = alpha p` (eq. 28 of the supplementary material):
///
/// ```text
/// H = alpha I + beta D^T U^T U D + gamma (I - B)^T (I - B)
/// ```
///
/// with `D` the edge-difference operator, `U` the per-face projections on the normals
/// and `B` the barycenter operator (its rows zero on rim vertices).
#[derive(Clone, Debug)]
pub struct Operator {
    matrix: SparseColMat<usize, f64>,
}

impl Operator {
    /// Assembles the operator of `energy` on `pattern` (which must come from the same
    /// surface). Column-parallel; each 3x3 block is written in place, no triplets.
    pub fn assemble(pattern: &OperatorPattern, energy: &Energy<'_>) -> Self {
        let surface = energy.surface();
        let normals = energy.normals();
        let n = surface.num_vertices();
        let mut values = vec![0.0f64; pattern.nnz()];
        // Split the values into one chunk per block column (3 scalar columns).
        let mut chunks: Vec<&mut [f64]> = Vec::with_capacity(n);
        let mut rest: &mut [f64] = &mut values;
        for j in 0..n {
            let (head, tail) = rest.split_at_mut(9 * pattern.block_rows(j).len());
            chunks.push(head);
            rest = tail;
        }
        chunks.into_par_iter().enumerate().for_each(|(j, chunk)| {
            let rows = pattern.block_rows(j);
            let m = rows.len();
            let mut add = |k: usize, block: DMat3| {
                let t = rows.binary_search(&(k as u32)).expect("operator pattern misses a coupling");
                for c in 0..3 {
                    for r in 0..3 {
                        chunk[c * 3 * m + 3 * t + r] += block.col(c)[r];
                    }
                }
            };
            let vj = VertexId(j as u32);
            add(j, DMat3::from_diagonal(DVec3::splat(energy.alpha_at(j))));
            // Alignment: beta * n n^T on the diagonal, minus it for the edge's other end.
            for f in surface.vertex_surfels(vj) {
                let sf = surface.surfel(*f);
                let nf = normals[f.index()];
                let nn = energy.beta_at(f.index()) * DMat3::from_cols(nf * nf.x, nf * nf.y, nf * nf.z);
                let i = sf.vertices.iter().position(|&w| w == vj).unwrap_or(0);
                for w in [sf.vertices[(i + 1) % 4], sf.vertices[(i + 3) % 4]] {
                    add(j, nn);
                    add(w.index(), -nn);
                }
            }
            // Fairness: sum over rows r_i of (I - B) whose support holds j: row j itself and
            // the rows of the vertices whose barycenter holds j (the mask is symmetric, so
            // those are j's own barycenter neighbours).
            let mut fair = |i: VertexId| {
                let Some(nb) = energy.fairness_neighbours(i) else { return };
                let gamma = energy.gamma_at(i.index());
                let w = 1.0 / nb.len() as f64;
                let rij = if i == vj { 1.0 } else { -w };
                add(i.index(), DMat3::from_diagonal(DVec3::splat(gamma * rij)));
                for k in &nb {
                    add(k.index(), DMat3::from_diagonal(DVec3::splat(-gamma * w * rij)));
                }
            };
            fair(vj);
            let own: Vec<VertexId> = match energy.weights().and_then(|w| w.fairness.as_ref()) {
                Some(mask) => mask.kept_neighbours(surface, vj).collect(),
                None => surface.vertex_neighbours(vj).to_vec(),
            };
            for i in own {
                fair(i);
            }
        });
        Operator { matrix: SparseColMat::new(pattern.symbolic().clone(), values) }
    }

    /// The matrix (both triangles stored).
    pub fn matrix(&self) -> &SparseColMat<usize, f64> {
        &self.matrix
    }

    /// `y = H x` for `x`, `y` of length `3n`, coordinates of vertex `i` at `3i..3i+3`.
    pub fn apply(&self, x: &[f64]) -> Vec<f64> {
        let m = self.matrix.as_ref();
        let n = m.ncols();
        let col_ptr = m.symbolic().col_ptr();
        let row_idx = m.symbolic().row_idx();
        let val = m.val();
        // Symmetric: row i of H is column i, so y_i = sum over column i.
        (0..n)
            .into_par_iter()
            .map(|i| (col_ptr[i]..col_ptr[i + 1]).map(|p| val[p] * x[row_idx[p]]).sum())
            .collect()
    }
}
