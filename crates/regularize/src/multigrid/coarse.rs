//! The coarse operators of the whole energy: Galerkin products, their `f32` block rows,
//! smoothers, and the coarsest level's Cholesky factor.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::sparse::linalg::cholesky::{
    factorize_symbolic_cholesky, CholeskySymbolicParams, LltRef, SymbolicCholesky, SymmetricOrdering,
};
use faer::sparse::{SparseColMat, SymbolicSparseColMat};
use faer::{Conj, MatMut, Side};
use glam::Vec3A;
use rayon::prelude::*;

use super::parts::{
    block, block_mul, full_mul, refill, scale6, Accumulator, Aggregation, Block, Full, Rows, Stored, FACE,
};
use crate::error::RegularizeError;
use crate::stencil::{Coefficients, Stencil, CHUNK};
use crate::vecops::sym_inverse;

impl Accumulator<10> {
    fn add_scalar(&mut self, col: u32, v: f64) {
        self.entry(col)[9] += v;
    }

    /// Adds `s` times the outer product `nn` (column-major).
    fn add_outer(&mut self, col: u32, s: f64, nn: &[f64; 9]) {
        let e = self.entry(col);
        for t in 0..9 {
            e[t] += s * nn[t];
        }
    }
}

/// `P^T H P` of the matrix-free fine operator, one coarse row per aggregate.
pub(super) fn galerkin_from_stencil(stencil: &Stencil, coef: &Coefficients<'_>, agg: &Aggregation) -> Rows {
    let nc = agg.len();
    let parent = &agg.parent;
    Rows::build(nc, nc, |acc, a| {
        let me = a as u32;
        for &i in agg.members(a) {
            let i = i as usize;
            acc.add_scalar(me, coef.alpha.get(i));
            for s in stencil.faces(i) {
                let n = coef.normals[s.face as usize];
                let b = coef.beta.get(s.face as usize);
                let nn = [
                    n.x * n.x,
                    n.y * n.x,
                    n.z * n.x,
                    n.x * n.y,
                    n.y * n.y,
                    n.z * n.y,
                    n.x * n.z,
                    n.y * n.z,
                    n.z * n.z,
                ];
                acc.add_outer(me, 2.0 * b, &nn);
                acc.add_outer(parent[s.prev as usize], -b, &nn);
                acc.add_outer(parent[s.next as usize], -b, &nn);
            }
            // Fairness rows k holding i: k = i (coefficient 1) and the rows of i's
            // barycenter neighbours (coefficient -1/|S_k|).
            let mut row_k = |k: usize, coeff: f64| {
                let ck = coef.fair[k];
                if ck == 0.0 {
                    return;
                }
                let nbk = stencil.fair_neighbours(k);
                let gk = ck * nbk.len() as f64;
                let w = gk * coeff;
                acc.add_scalar(parent[k], w);
                let share = -w / nbk.len() as f64;
                for &j in nbk {
                    acc.add_scalar(parent[j as usize], share);
                }
            };
            row_k(i, 1.0);
            for &k in stencil.fair_neighbours(i) {
                let dk = stencil.fair_neighbours(k as usize).len();
                if dk > 0 {
                    row_k(k as usize, -1.0 / dk as f64);
                }
            }
        }
    })
}

/// `P^T A P` of an assembled level.
pub(super) fn galerkin_from_rows<const W: usize>(rows: &Rows<W>, agg: &Aggregation) -> Rows<W> {
    let nc = agg.len();
    Rows::build(nc, nc, |acc, a| galerkin_row(acc, rows, agg, a))
}

/// Row `a` of `P^T A P`: the rows of aggregate `a`'s members, summed by aggregate.
pub(super) fn galerkin_row<const W: usize>(
    acc: &mut Accumulator<W>,
    rows: &Rows<W>,
    agg: &Aggregation,
    a: usize,
) {
    for &i in agg.members(a) {
        for (j, block) in rows.row(i as usize) {
            let e = acc.entry(agg.parent[j as usize]);
            for t in 0..W {
                e[t] += block[t];
            }
        }
    }
}

/// The inverse blocks of a block-diagonal majorant `M >= A` of an assembled level,
/// damped: `M_I = A_II + sum_{J != I} (-N_IJ + |s_IJ| I)` for off-diagonal blocks
/// `N_IJ + s_IJ I` with `N_IJ <= 0` (alignment) — since `[[0, B], [B, 0]] <= diag(C, C)`
/// whenever `C >= +-B`.
pub(super) fn l1_smoother(rows: &Rows, damping: f64, old: Vec<Block>) -> Vec<Block> {
    refill(
        old,
        (0..rows.len()).into_par_iter().map(|i| {
            let mut d = [0.0; 6];
            for (j, b) in rows.row(i) {
                let sym = [b[0], b[4], b[8], 0.5 * (b[3] + b[1]), 0.5 * (b[6] + b[2]), 0.5 * (b[7] + b[5])];
                let (sign, s) = if j as usize == i { (1.0, b[9]) } else { (-1.0, b[9].abs()) };
                for t in 0..6 {
                    d[t] += sign * sym[t];
                }
                for t in 0..3 {
                    d[t] += s;
                }
            }
            block(&scale6(&sym_inverse(&d), damping))
        }),
    )
}

/// A 3x3-block sparse row matrix in `f32`, its products in SIMD `f32` (it only
/// preconditions).
#[derive(Clone, Debug, Default)]
pub(crate) struct Bsr {
    pub(super) offsets: Vec<u32>,
    pub(super) cols: Vec<u32>,
    pub(super) blocks: Blocks,
}

/// A level's blocks: symmetric ([`Block`], 24 bytes) for the whole operator, whose
/// blocks are sums of `n n^T` and multiples of the identity, or general ([`Full`], 36
/// bytes) for a face's operator, whose masks differ at a block's two ends.
#[derive(Clone, Debug)]
pub(super) enum Blocks {
    Sym(Vec<Block>),
    Full(Vec<Full>),
}

impl Default for Blocks {
    fn default() -> Self {
        Blocks::Sym(Vec::new())
    }
}

impl Bsr {
    /// The blocks of a level: the alignment part (`b[..9]`) plus the diagonal part, one
    /// value for the three coordinates (the whole operator's rows, `W = 10`, symmetric
    /// blocks) or one per coordinate (a face's rows, `W = FACE`, from `b[9]`).
    pub(super) fn from_rows<const W: usize>(rows: &Rows<W>) -> Self {
        let offsets = rows.offsets.iter().map(|&o| o as u32).collect();
        let cols = rows.cols.clone();
        let blocks = if W == 10 {
            Blocks::Sym(rows.vals.map(|b| sym_block(full_block(b))))
        } else {
            Blocks::Full(rows.vals.map(full_block))
        };
        Bsr { offsets, cols, blocks }
    }

    /// [`Bsr::from_rows`] of the whole operator's rows (`W = 10`), taken: in the arrays of
    /// `old` when it has their pattern (the last solve's level: the pattern depends on the
    /// surface and hierarchy, seldom on the numbers), else with the rows' columns; each
    /// part of the rows' numbers freed once converted, so that the level's blocks and its
    /// rows' numbers are never held in full together (the setup's peak).
    pub(super) fn from_rows_reusing(rows: Rows<10>, old: Bsr) -> Self {
        let same = old.offsets.len() == rows.offsets.len()
            && old.cols == rows.cols
            && old.offsets.iter().zip(&rows.offsets).all(|(&a, &b)| a as usize == b);
        let Rows { offsets, cols, vals } = rows;
        let (offsets, cols, mut blocks) = match old.blocks {
            Blocks::Sym(blocks) if same && blocks.len() == vals.len() => {
                drop((offsets, cols));
                (old.offsets, old.cols, blocks)
            }
            _ => (offsets.iter().map(|&o| o as u32).collect(), cols, vec![Block::default(); vals.len()]),
        };
        vals.map_into_freeing(&mut blocks, |b| sym_block(full_block(b)));
        Bsr { offsets, cols, blocks: Blocks::Sym(blocks) }
    }

    /// Bytes read by one product.
    pub(crate) fn bytes(&self) -> usize {
        let blocks = match &self.blocks {
            Blocks::Sym(b) => 24 * b.len(),
            Blocks::Full(b) => 36 * b.len(),
        };
        4 * self.offsets.len() + 4 * self.cols.len() + blocks
    }

    /// `y = b - A x`.
    pub(super) fn residual<S: Stored>(&self, x: &[S], b: &[S], y: &mut [S]) {
        match &self.blocks {
            Blocks::Sym(blocks) => self.residual_with(blocks, block_mul, x, b, y),
            Blocks::Full(blocks) => self.residual_with(blocks, full_mul, x, b, y),
        }
    }

    #[inline(always)]
    fn residual_with<B: Sync, S: Stored>(
        &self,
        blocks: &[B],
        mul: impl Fn(&B, Vec3A) -> Vec3A + Sync,
        x: &[S],
        b: &[S],
        y: &mut [S],
    ) {
        y.par_chunks_mut(CHUNK).enumerate().for_each(|(k, out)| {
            let base = k * CHUNK;
            for (o, yi) in out.iter_mut().enumerate() {
                let i = base + o;
                let (start, end) = (self.offsets[i] as usize, self.offsets[i + 1] as usize);
                let mut acc = Vec3A::ZERO;
                for (m, &c) in blocks[start..end].iter().zip(&self.cols[start..end]) {
                    acc += mul(m, x[c as usize].get());
                }
                *yi = S::put(b[i].get() - acc);
            }
        });
    }
}

/// A level's block from its row entry: the alignment part (`b[..9]`) plus the diagonal
/// part, one value for the three coordinates (`W = 10`) or one per coordinate (`W = FACE`).
pub(super) fn full_block<const W: usize>(b: &[f32; W]) -> Full {
    let mut m = [0.0f32; 9];
    m.copy_from_slice(&b[..9]);
    for (k, t) in [0, 4, 8].into_iter().enumerate() {
        m[t] += b[if W == 10 { 9 } else { 9 + k }];
    }
    m
}

/// A whole-operator block in symmetric storage: the same numbers as the full block's (its
/// entries are exactly symmetric: each is accumulated from the same products in the same
/// order), so the products are the same to the bit.
fn sym_block(m: Full) -> Block {
    debug_assert!(m[1] == m[3] && m[2] == m[6] && m[5] == m[7], "an asymmetric block");
    // [xx, yy, xz, yz, zz, xy], the layout of `Block`.
    [m[0], m[4], m[6], m[7], m[8], m[3]]
}

/// Sparse Cholesky of the coarsest level.
pub(super) struct Coarsest {
    symbolic: SymbolicCholesky<usize>,
    pub(super) factor: Vec<f64>,
    n: usize,
}

impl std::fmt::Debug for Coarsest {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Coarsest").field("n", &self.n).finish()
    }
}

impl Coarsest {
    pub(super) fn new(rows: &Rows) -> Result<Self, RegularizeError> {
        Self::from_blocks(rows, |b, r, c| b[3 * c + r] + if r == c { b[9] } else { 0.0 })
    }

    /// The factor of a face's coarsest level, with the identity on the coordinates no
    /// free vertex moves.
    pub(super) fn face(rows: &Rows<FACE>) -> Result<Self, RegularizeError> {
        Self::from_blocks(rows, |b, r, c| b[3 * c + r] + if r == c { b[9 + r] } else { 0.0 })
    }

    /// `entry(block, r, c)`: the entry `(r, c)` of a block (symmetric: block `(j, i)` is
    /// block `(i, j)` transposed). A zero diagonal entry becomes `1` (a coordinate no
    /// free vertex moves, on a face; never on the whole operator).
    fn from_blocks<const W: usize>(
        rows: &Rows<W>,
        entry: impl Fn(&[f64; W], usize, usize) -> f64,
    ) -> Result<Self, RegularizeError> {
        let n = rows.len();
        let dim = 3 * n;
        // Full symmetric CSC: block row i is block column i transposed.
        let mut col_ptr = Vec::with_capacity(dim + 1);
        let mut row_idx = Vec::new();
        let mut values = Vec::new();
        col_ptr.push(0usize);
        for i in 0..n {
            for c in 0..3 {
                for (j, block) in rows.row(i) {
                    for r in 0..3 {
                        // Column 3i + c, row 3j + r: entry (3j + r, 3i + c) = A_ji[r][c]
                        // = A_ij[c][r] (symmetry).
                        row_idx.push(3 * j as usize + r);
                        let v = entry(&block, c, r);
                        values.push(if v == 0.0 && j as usize == i && r == c { 1.0 } else { v });
                    }
                }
                col_ptr.push(row_idx.len());
            }
        }
        let symbolic = SymbolicSparseColMat::new_checked(dim, dim, col_ptr, None, row_idx);
        let matrix = SparseColMat::new(symbolic, values);
        let chol = factorize_symbolic_cholesky(
            matrix.symbolic(),
            Side::Lower,
            SymmetricOrdering::Amd,
            CholeskySymbolicParams::default(),
        )
        .map_err(|e| RegularizeError::Factorization(format!("coarse symbolic analysis failed: {e:?}")))?;
        let mut factor = vec![0.0; chol.len_val()];
        let par = faer::Par::Seq;
        let mut mem = MemBuffer::try_new(chol.factorize_numeric_llt_scratch::<f64>(par, Default::default()))
            .map_err(|_| RegularizeError::OutOfMemory("coarse Cholesky workspace".into()))?;
        chol.factorize_numeric_llt::<f64>(
            &mut factor,
            matrix.as_ref(),
            Side::Lower,
            LltRegularization::default(),
            par,
            MemStack::new(&mut mem),
            Default::default(),
        )
        .map_err(|e| RegularizeError::Factorization(format!("coarse Cholesky failed: {e:?}")))?;
        Ok(Coarsest { symbolic: chol, factor, n })
    }

    pub(super) fn solve<S: Stored>(&self, b: &[S], x: &mut [S]) {
        let mut rhs: Vec<f64> = b.iter().flat_map(|v| v.get().as_dvec3().to_array()).collect();
        let par = faer::Par::Seq;
        let mut mem = MemBuffer::new(self.symbolic.solve_in_place_scratch::<f64>(1, par));
        LltRef::new(&self.symbolic, &self.factor).solve_in_place_with_conj(
            Conj::No,
            MatMut::from_column_major_slice_mut(&mut rhs, 3 * self.n, 1),
            par,
            MemStack::new(&mut mem),
        );
        for (xi, v) in x.iter_mut().zip(rhs.chunks_exact(3)) {
            *xi = S::put(Vec3A::new(v[0] as f32, v[1] as f32, v[2] as f32));
        }
    }
}

#[derive(Debug, Default)]
pub(super) struct Level {
    /// The operator (empty on the coarsest level, which is factored instead).
    pub(super) matrix: Bsr,
    pub(super) smoother: Vec<Block>,
    pub(super) n: usize,
}

/// A level's work vectors, the cycle's own: the fine level's `x` made with the cycle,
/// the others at their first use (the conjugate gradient lends its own vectors instead,
/// [`super::Vcycle::apply_in`]).
#[derive(Debug, Default)]
pub(super) struct Work {
    pub(super) r: Vec<Vec3A>,
    pub(super) x: Vec<Vec3A>,
    pub(super) t: Vec<Vec3A>,
}

/// A coarse level's work vectors for one cycle: the cycle's own ([`Work`]) or slices of
/// vectors lent by its caller (`S` how the values are stored, [`Stored`]).
pub(super) struct WorkMut<'a, S> {
    pub(super) r: &'a mut [S],
    pub(super) x: &'a mut [S],
    pub(super) t: &'a mut [S],
}
