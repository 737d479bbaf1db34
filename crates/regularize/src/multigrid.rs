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

use std::sync::Arc;
use std::time::Instant;

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::sparse::linalg::cholesky::{
    factorize_symbolic_cholesky, CholeskySymbolicParams, LltRef, SymbolicCholesky, SymmetricOrdering,
};
use faer::sparse::{SparseColMat, SymbolicSparseColMat};
use faer::{Conj, MatMut, Side};
use glam::{DVec3, Vec3A};
use rayon::prelude::*;

use crate::error::RegularizeError;
use crate::stencil::{Coefficients, Stencil, CHUNK};
use crate::vecops::sym_inverse;
use voxreg_normals::Interrupt;

/// Settings of the multigrid preconditioner.
#[derive(Copy, Clone, Debug, PartialEq, serde::Serialize)]
pub struct MultigridParams {
    /// Stop coarsening at a level of at most this many nodes, and factor it exactly.
    /// Default: `150` (smaller coarsest levels cost less to factor and to solve each
    /// cycle; in an A/B run 150 was 12%, 10% and 7% faster than 800 on spheres of 20k,
    /// 100k and 367k quads, with the same iteration counts within one).
    pub coarsest_nodes: usize,
    /// At most this many levels, the surface included. Default: `16`.
    pub max_levels: usize,
    /// Smoothing sweeps before and after the coarse correction on the surface itself
    /// (each costs one matrix-free product by `H`). Default: `1`.
    pub smoothing_steps: usize,
    /// Smoothing sweeps before and after each coarse correction on the coarse levels,
    /// whose products are several times cheaper than the surface's. Default: `1`.
    pub coarse_smoothing_steps: usize,
    /// Damping of the smoother: the step along `M^-1 r`, `M >= H` a block-diagonal
    /// majorant, convergent for any damping in `(0, 2)`. Default: `1.8`.
    pub damping: f64,
}

impl Default for MultigridParams {
    fn default() -> Self {
        MultigridParams {
            coarsest_nodes: 150,
            max_levels: 16,
            smoothing_steps: 1,
            coarse_smoothing_steps: 1,
            damping: 1.8,
        }
    }
}

/// The aggregation of one level into the next: structure only.
#[derive(Clone, Debug)]
struct Aggregation {
    /// For each node of the finer level, its aggregate (a node of the coarser level).
    parent: Vec<u32>,
    /// Members of each aggregate: `members[offsets[a]..offsets[a + 1]]`.
    offsets: Vec<u32>,
    members: Vec<u32>,
}

impl Aggregation {
    fn len(&self) -> usize {
        self.offsets.len() - 1
    }

    fn members(&self, a: usize) -> &[u32] {
        &self.members[self.offsets[a] as usize..self.offsets[a + 1] as usize]
    }
}

/// The voxel hierarchy of a surface: which vertices each coarse node groups.
#[derive(Clone, Debug)]
pub(crate) struct Hierarchy {
    /// Shared with the cycles built from it.
    aggregations: Arc<[Aggregation]>,
    params: MultigridParams,
}

/// Groups nodes by `cell >> 1` and, within a cell, by connected component of
/// `neighbours`: the two sides of a sheet thinner than the cell, or two parts of a surface
/// that meet only outside it, move independently and get a translation each. Returns the
/// aggregation (numbered in lexicographic (z, y, x) cell order, then by the smallest
/// member), the coarse cells and the coarse adjacency (aggregates joined by an edge, as
/// offsets and neighbour lists).
fn aggregate(
    cells: &[[u32; 3]],
    neighbours: &Adjacency<'_>,
) -> (Aggregation, Vec<[u32; 3]>, Vec<u32>, Vec<u32>) {
    let key = |c: &[u32; 3]| ((c[2] as u64 >> 1) << 42) | ((c[1] as u64 >> 1) << 21) | (c[0] as u64 >> 1);
    let n = cells.len();
    // Union-find within each cell, the smaller index the root: deterministic components.
    let mut root: Vec<u32> = (0..n as u32).collect();
    fn find(root: &mut [u32], mut i: u32) -> u32 {
        while root[i as usize] != i {
            let up = root[root[i as usize] as usize];
            root[i as usize] = up;
            i = up;
        }
        i
    }
    for i in 0..n {
        let ki = key(&cells[i]);
        neighbours.each(i, |j| {
            if (j as usize) > i && key(&cells[j as usize]) == ki {
                let (a, b) = (find(&mut root, i as u32), find(&mut root, j));
                if a != b {
                    root[a.max(b) as usize] = a.min(b);
                }
            }
        });
    }
    let mut order: Vec<(u64, u32)> =
        (0..n as u32).map(|i| (key(&cells[i as usize]), find(&mut root, i))).collect();
    drop(root);
    // Sorting (cell, component) pairs with each node's index: the members of an aggregate
    // in increasing order, aggregates by cell, then by their smallest member.
    let mut sorted: Vec<u32> = (0..n as u32).collect();
    sorted.par_sort_unstable_by_key(|&i| (order[i as usize], i));
    let mut parent = vec![0u32; n];
    let mut offsets = vec![0u32];
    let mut coarse = Vec::new();
    for group in sorted.chunk_by(|&a, &b| order[a as usize] == order[b as usize]) {
        let a = coarse.len() as u32;
        let c = cells[group[0] as usize];
        coarse.push([c[0] >> 1, c[1] >> 1, c[2] >> 1]);
        for &i in group {
            parent[i as usize] = a;
        }
        offsets.push(offsets.last().copied().unwrap_or(0) + group.len() as u32);
    }
    order.clear();
    order.shrink_to_fit();
    let agg = Aggregation { parent, offsets, members: sorted };
    // The coarse adjacency: aggregates joined by an edge, each list sorted.
    let lists: Vec<Vec<u32>> = (0..agg.len())
        .into_par_iter()
        .map(|a| {
            let mut out = Vec::new();
            for &i in agg.members(a) {
                neighbours.each(i as usize, |j| {
                    let b = agg.parent[j as usize];
                    if b as usize != a {
                        out.push(b);
                    }
                });
            }
            out.sort_unstable();
            out.dedup();
            out
        })
        .collect();
    let mut coarse_offsets = Vec::with_capacity(lists.len() + 1);
    coarse_offsets.push(0u32);
    for l in &lists {
        coarse_offsets.push(coarse_offsets.last().copied().unwrap_or(0) + l.len() as u32);
    }
    let coarse_nbrs: Vec<u32> = lists.into_iter().flatten().collect();
    (agg, coarse, coarse_offsets, coarse_nbrs)
}

/// Each node's neighbours: the surface's (across its quads' edges, from the stencil) or a
/// coarse level's (compressed lists).
enum Adjacency<'a> {
    Surface(&'a Stencil),
    Lists { offsets: Vec<u32>, nbrs: Vec<u32> },
}

impl Adjacency<'_> {
    fn each(&self, i: usize, mut f: impl FnMut(u32)) {
        match self {
            Adjacency::Surface(stencil) => {
                for s in &stencil.face_slots()[stencil.face_range(i)] {
                    f(s.prev);
                    f(s.next);
                }
            }
            Adjacency::Lists { offsets, nbrs } => {
                nbrs[offsets[i] as usize..offsets[i + 1] as usize].iter().for_each(|&j| f(j))
            }
        }
    }
}

impl Hierarchy {
    /// The hierarchy of a surface whose vertices are `stencil`'s, at lattice corners
    /// `corners` ([`crate::stencil::lattice_corners`]).
    pub(crate) fn new(stencil: &Stencil, corners: Vec<[u32; 3]>, params: &MultigridParams) -> Self {
        let mut aggregations = Vec::new();
        let mut cells = corners;
        let mut adjacency = Adjacency::Surface(stencil);
        while cells.len() > params.coarsest_nodes.max(1) && aggregations.len() + 1 < params.max_levels.max(1)
        {
            let (agg, coarse, offsets, nbrs) = aggregate(&cells, &adjacency);
            adjacency = Adjacency::Lists { offsets, nbrs };
            if coarse.len() * 10 > cells.len() * 9 {
                break; // no longer coarsening
            }
            aggregations.push(agg);
            cells = coarse;
        }
        if aggregations.is_empty() {
            // A small surface: factor its own operator (the identity aggregation), which
            // makes the preconditioner exact up to the `f32` rounding of the factor's input.
            let n = cells.len() as u32;
            aggregations.push(Aggregation {
                parent: (0..n).collect(),
                offsets: (0..=n).collect(),
                members: (0..n).collect(),
            });
        }
        Hierarchy { aggregations: aggregations.into(), params: *params }
    }

    /// Number of levels, the surface included.
    pub(crate) fn levels(&self) -> usize {
        self.aggregations.len() + 1
    }

    /// The coarse operators, smoothers and coarsest factorization of one energy;
    /// [`RegularizeError::Interrupted`] if `interrupt` is raised before a level. The
    /// arrays of `old` (a cycle built on this hierarchy, the last solve's) are refilled
    /// where their sizes and patterns match instead of allocated: the same cycle, without
    /// faulting in fresh memory for the levels' blocks, smoothers and work vectors at
    /// every solve of a refinement loop.
    pub(crate) fn numeric(
        &self,
        stencil: &Stencil,
        coef: &Coefficients<'_>,
        interrupt: &Interrupt,
        old: Option<Box<Vcycle>>,
    ) -> Result<Vcycle, RegularizeError> {
        #[cfg(test)]
        tests::SETUPS.with(|c| c.set(c.get() + 1));
        // The old cycle's arrays (its face's levels and coarsest factor dropped here).
        let (mut spare_levels, spare_works, spare_smoother, spare_fine) =
            match old.filter(|v| Arc::ptr_eq(&v.aggregations, &self.aggregations)) {
                Some(v) => {
                    let Vcycle { levels, works, fine_smoother, fine, .. } = *v;
                    (levels, works, fine_smoother, fine)
                }
                None => Default::default(),
            };
        spare_levels.reverse();
        let clock = Instant::now();
        let lap = |what: &str| {
            tracing::trace!(stage = what, ms = clock.elapsed().as_secs_f64() * 1e3, "multigrid setup");
        };
        let fine_smoother = fine_majorant(stencil, coef);
        lap("fine majorant");
        let mut levels = Vec::with_capacity(self.aggregations.len());
        let mut rows: Option<Rows> = None;
        for (l, agg) in self.aggregations.iter().enumerate() {
            interrupt.check()?;
            let coarse_rows = match &rows {
                None => galerkin_from_stencil(stencil, coef, agg),
                Some(finer) => galerkin_from_rows(finer, agg),
            };
            let _ = l;
            if let Some(finer) = rows.take() {
                let last: &mut Level = levels.last_mut().expect("a previous level");
                last.matrix = Bsr::from_rows_reusing(&finer, std::mem::take(&mut last.matrix));
                last.smoother = l1_smoother(&finer, self.params.damping, std::mem::take(&mut last.smoother));
            }
            rows = Some(coarse_rows);
            lap(&format!(
                "galerkin level {} ({} nodes, {:.1} blocks/row)",
                l + 1,
                agg.len(),
                rows.as_ref().map_or(0, |r| r.nnz()) as f64 / agg.len() as f64
            ));
            // The last solve's level `l`, its arrays refilled once the rows are built.
            let mut level = spare_levels.pop().unwrap_or_default();
            level.n = agg.len();
            levels.push(level);
        }
        interrupt.check()?;
        let t = Instant::now();
        let coarsest = match rows {
            Some(rows) => {
                let last = levels.last_mut().expect("a coarse level");
                last.smoother = Vec::new();
                Some(Coarsest::new(&rows)?)
            }
            None => None,
        };
        let factor_seconds = t.elapsed().as_secs_f64();
        lap("coarsest factor");
        // Work vectors of the same sizes are reused as they are: every cycle writes each
        // entry before reading it.
        let sizes: Vec<usize> = std::iter::once(stencil.len()).chain(levels.iter().map(|l| l.n)).collect();
        let works = if spare_works.iter().map(|w| w.x.len()).eq(sizes.iter().copied()) {
            spare_works
        } else {
            drop(spare_works);
            let work =
                |n: usize| Work { r: vec![Vec3A::ZERO; n], x: vec![Vec3A::ZERO; n], t: vec![Vec3A::ZERO; n] };
            sizes.iter().map(|&n| work(n)).collect()
        };
        let fine = FineNumbers::new(stencil, coef, spare_fine);
        Ok(Vcycle {
            fine,
            fine_smoother: inverse_blocks(&fine_smoother, self.params.damping, spare_smoother),
            face_smoother: Vec::new(),
            face_levels: None,
            majorant: Vec::new(),
            damping: self.params.damping,
            levels,
            aggregations: Arc::clone(&self.aggregations),
            coarsest,
            works,
            steps: self.params.smoothing_steps.max(1),
            coarse_steps: self.params.coarse_smoothing_steps.max(1),
            factor_seconds,
        })
    }
}

fn scale6(m: &[f64; 6], s: f64) -> [f64; 6] {
    m.map(|x| x * s)
}

/// The damped inverses of the majorant blocks `m` (the fine level's smoother), in the
/// arrays of `old` when it has their number.
fn inverse_blocks(m: &[[f64; 6]], damping: f64, old: Vec<Block>) -> Vec<Block> {
    refill(old, m.par_iter().map(|d| block(&scale6(&sym_inverse(d), damping))))
}

/// The items of `items` in `buf` when it has their number (written in place, no new
/// memory to fault in), else collected anew.
fn refill<T: Send>(mut buf: Vec<T>, items: impl IndexedParallelIterator<Item = T>) -> Vec<T> {
    if buf.len() == items.len() {
        buf.par_iter_mut().zip(items).for_each(|(b, x)| *b = x);
        buf
    } else {
        drop(buf);
        items.collect()
    }
}

/// A symmetric 3x3 block `[xx, yy, zz, xy, xz, yz]` in `f32`: 24 bytes, half of three
/// SIMD columns (the smoothers are streamed once per sweep, so their size is their cost).
type Block = [f32; 6];

fn block(m: &[f64; 6]) -> Block {
    narrow(m)
}

/// `m` in `f32`, its entries below `f32::EPSILON^2` times the largest set to zero.
///
/// They are rounding residue (a voxel face's normal has components like `1e-17`, whose
/// products reach `1e-34`) and change no product beyond `f32` rounding, but their
/// products with the cycle's vectors fall below `f32::MIN_POSITIVE`, and subnormal
/// arithmetic is many times slower than normal arithmetic on common processors.
#[inline]
fn narrow<const N: usize>(m: &[f64; N]) -> [f32; N] {
    let cut = m.iter().fold(0.0f64, |a, x| a.max(x.abs())) * f64::from(f32::EPSILON * f32::EPSILON);
    m.map(|x| if x.abs() < cut { 0.0 } else { x as f32 })
}

#[inline(always)]
fn block_mul(m: &Block, v: Vec3A) -> Vec3A {
    let [a, d, f, b, c, e] = *m;
    Vec3A::new(a, b, c) * v.x + Vec3A::new(b, d, e) * v.y + Vec3A::new(c, e, f) * v.z
}

/// A general 3x3 block, its columns one after the other, in `f32` (36 bytes: no SIMD
/// padding).
type Full = [f32; 9];

#[inline(always)]
fn full_mul(m: &Full, v: Vec3A) -> Vec3A {
    Vec3A::new(m[0], m[1], m[2]) * v.x
        + Vec3A::new(m[3], m[4], m[5]) * v.y
        + Vec3A::new(m[6], m[7], m[8]) * v.z
}

/// The fine operator's numbers in `f32`, for the cycle's fine residuals: the whole cycle
/// runs in `f32` SIMD (it only preconditions: CG's products and residuals stay `f64`).
#[derive(Debug, Default)]
struct FineNumbers {
    alpha: Vec<f32>,
    fair: Vec<f32>,
    /// `sqrt(beta_f) n_f` per face, as [`Coefficients::face_normals`].
    face_normals: Vec<Vec3A>,
}

impl FineNumbers {
    /// The numbers of `coef`, in the arrays of `old` where their sizes match.
    fn new(stencil: &Stencil, coef: &Coefficients<'_>, old: FineNumbers) -> Self {
        let FineNumbers { alpha, fair, face_normals } = old;
        FineNumbers {
            alpha: refill(alpha, (0..stencil.len()).into_par_iter().map(|i| coef.alpha.get(i) as f32)),
            fair: refill(fair, coef.fair.par_iter().map(|&c| c as f32)),
            face_normals: refill(face_normals, coef.face_normals.par_iter().map(|m| m.as_vec3a())),
        }
    }

    fn bytes(&self) -> usize {
        4 * (self.alpha.len() + self.fair.len()) + 16 * self.face_normals.len()
    }

    /// `y = b - H x` in `f32`, in the two passes of the `f64` product (`t` is scratch),
    /// masked by `face` when given; `b(i)` is the right-hand side's entry `i`.
    fn residual(
        &self,
        stencil: &Stencil,
        x: &[Vec3A],
        b: &(impl Fn(usize) -> Vec3A + Sync),
        y: &mut [Vec3A],
        t: &mut [Vec3A],
        face: Option<&[Vec3A]>,
    ) {
        self.residual_map(stencil, x, b, y, t, face, |_, r| r);
    }

    /// [`FineNumbers::residual`] with `y_i = f(i, (b - H x)_i)`: what is done with each
    /// residual (a smoothing step, the cycle's output) done in the pass that computes it,
    /// without writing the residual and reading it back.
    #[allow(clippy::too_many_arguments)]
    fn residual_map<T: Send>(
        &self,
        stencil: &Stencil,
        x: &[Vec3A],
        b: &(impl Fn(usize) -> Vec3A + Sync),
        y: &mut [T],
        t: &mut [Vec3A],
        face: Option<&[Vec3A]>,
        f: impl Fn(usize, Vec3A) -> T + Sync,
    ) {
        t.par_chunks_mut(CHUNK).enumerate().for_each(|(k, out)| {
            let base = k * CHUNK;
            for (o, ti) in out.iter_mut().enumerate() {
                let i = base + o;
                let ci = self.fair[i];
                *ti = if ci == 0.0 {
                    Vec3A::ZERO
                } else {
                    let nb = stencil.fair_neighbours(i);
                    let sum: Vec3A = nb.iter().map(|&j| x[j as usize]).sum();
                    ci * (x[i] - sum / nb.len() as f32)
                };
            }
        });
        let t = &*t;
        let slots = stencil.face_slots();
        y.par_chunks_mut(CHUNK).enumerate().for_each(|(k, out)| {
            let base = k * CHUNK;
            for (o, yi) in out.iter_mut().enumerate() {
                let i = base + o;
                let xi = x[i];
                let mut acc = self.alpha[i] * xi;
                let range = stencil.face_range(i);
                for s in &slots[range] {
                    let m = self.face_normals[s.face as usize];
                    acc += (2.0 * xi - x[s.prev as usize] - x[s.next as usize]).dot(m) * m;
                }
                let nb = stencil.fair_neighbours(i);
                let sum: Vec3A = nb.iter().map(|&j| t[j as usize]).sum();
                *yi = f(i, masked(face, i, b(i) - (acc + nb.len() as f32 * t[i] - sum)));
            }
        });
    }
}

/// A block-diagonal majorant `M >= H` of the fine operator (a block l1-Jacobi): each
/// edge term `beta n n^T (x_i - x_j)^2` is at most twice `beta n n^T` at both ends, and
/// each fairness row `gamma_k (rho_k . x)^2 <= gamma_k |rho_k|_1 sum_j |rho_kj| x_j^2`. So
/// `M = alpha I + 4 sum_f beta_f n_f n_f^T + 2 (gamma_i + sum_{k in S_i} gamma_k / |S_k|) I`,
/// which keeps the smoother convergent without any eigenvalue estimate while leaving the
/// tangential directions (where alignment has no stiffness) undamped.
fn fine_majorant(stencil: &Stencil, coef: &Coefficients<'_>) -> Vec<[f64; 6]> {
    (0..stencil.len())
        .into_par_iter()
        .map(|i| {
            let nb = stencil.fair_neighbours(i);
            let mut fair = coef.fair[i] * nb.len() as f64;
            for &k in nb {
                fair += coef.fair[k as usize];
            }
            let a = coef.alpha.get(i) + 2.0 * fair;
            let mut d = [a, a, a, 0.0, 0.0, 0.0];
            for s in stencil.faces(i) {
                let n = coef.normals[s.face as usize];
                let b = 4.0 * coef.beta.get(s.face as usize);
                d[0] += b * n.x * n.x;
                d[1] += b * n.y * n.y;
                d[2] += b * n.z * n.z;
                d[3] += b * n.x * n.y;
                d[4] += b * n.x * n.z;
                d[5] += b * n.y * n.z;
            }
            d
        })
        .collect()
}

/// The rows of an operator under construction, flat: sorted columns and blocks of `W`
/// numbers. For the whole operator (`W = 10`) each block is the sum of an alignment part
/// (a 3x3 block, column-major, entries `0..9`: positive semi-definite on the diagonal,
/// negative semi-definite off it) and a multiple of the identity (entry `9`: attachment
/// and fairness), kept apart so that the smoother's majorant needs no eigenvalues; for a
/// face's operator, see [`FACE`].
#[derive(Debug)]
struct Rows<const W: usize = 10> {
    offsets: Vec<usize>,
    cols: Vec<u32>,
    /// Accumulated in `f64`, stored in `f32`: they only precondition. Kept in the parts
    /// they were built in (each a range of whole rows), never joined.
    vals: Parts<[f32; W]>,
}

/// A sequence stored as the consecutive parts it was built in, each a range of whole
/// rows: joining them would copy the level's numbers into fresh memory, which the system
/// must fault in page by page.
#[derive(Debug, Default)]
struct Parts<T> {
    parts: Vec<Vec<T>>,
    /// Where each part starts in the sequence, and its length last.
    starts: Vec<usize>,
}

impl<T> Parts<T> {
    fn new(parts: Vec<Vec<T>>) -> Self {
        let mut starts = Vec::with_capacity(parts.len() + 1);
        starts.push(0);
        for p in &parts {
            starts.push(starts.last().unwrap() + p.len());
        }
        Parts { parts, starts }
    }

    fn len(&self) -> usize {
        *self.starts.last().unwrap_or(&0)
    }

    /// The part holding entry `k`.
    fn part_of(&self, k: usize) -> usize {
        self.starts.partition_point(|&s| s <= k) - 1
    }

    /// Entries `r`, which lie in one part (a row's).
    fn slice(&self, r: std::ops::Range<usize>) -> &[T] {
        if r.is_empty() {
            return &[];
        }
        let p = self.part_of(r.start);
        let s = self.starts[p];
        &self.parts[p][r.start - s..r.end - s]
    }

    fn iter(&self) -> impl Iterator<Item = &T> {
        self.parts.iter().flatten()
    }

    /// `out[k] = f(&self[k])` for every entry, in parallel part by part.
    fn map_into<U: Send>(&self, out: &mut [U], f: impl Fn(&T) -> U + Sync)
    where
        T: Sync,
    {
        let mut pieces = Vec::with_capacity(self.parts.len());
        let mut rest = out;
        for p in &self.parts {
            let (here, tail) = rest.split_at_mut(p.len());
            pieces.push((p, here));
            rest = tail;
        }
        pieces.into_par_iter().for_each(|(p, out)| {
            out.par_chunks_mut(CHUNK).zip(p.par_chunks(CHUNK)).for_each(|(o, v)| {
                o.iter_mut().zip(v).for_each(|(o, v)| *o = f(v));
            })
        });
    }

    /// `f(&self[k])` for every entry, in a new vector.
    fn map<U: Send + Default + Clone>(&self, f: impl Fn(&T) -> U + Sync) -> Vec<U>
    where
        T: Sync,
    {
        let mut out = vec![U::default(); self.len()];
        self.map_into(&mut out, f);
        out
    }
}

impl<T: PartialEq> PartialEq for Parts<T> {
    fn eq(&self, other: &Self) -> bool {
        self.len() == other.len() && self.iter().eq(other.iter())
    }
}

impl<const W: usize> Rows<W> {
    fn len(&self) -> usize {
        self.offsets.len() - 1
    }

    /// Rows `dirty` (ascending) computed anew by `f` (as [`Rows::build`] does, so to the
    /// bit), in place and in parallel; `false` if a row's columns differ (its pattern is
    /// not this one's: the rows are then partly rewritten, and the caller builds anew).
    fn recompute(&mut self, dirty: &[usize], f: impl Fn(&mut Accumulator<W>, usize) + Sync) -> bool {
        let n = self.len();
        let Rows { offsets, cols, vals } = self;
        // Each dirty row's values, a slice of its own (in its part).
        let mut rows: Vec<(usize, &mut [[f32; W]])> = Vec::with_capacity(dirty.len());
        let mut dirty = dirty.iter().copied().peekable();
        for (p, part) in vals.parts.iter_mut().enumerate() {
            let (start, end) = (vals.starts[p], vals.starts[p + 1]);
            let (mut rest, mut at): (&mut [[f32; W]], usize) = (part, start);
            while let Some(&a) = dirty.peek() {
                if offsets[a] >= end && offsets[a + 1] > offsets[a] {
                    break;
                }
                dirty.next();
                debug_assert!(offsets[a] >= at, "dirty rows ascending");
                let (_, tail) = std::mem::take(&mut rest).split_at_mut(offsets[a] - at);
                let (row, tail) = tail.split_at_mut(offsets[a + 1] - offsets[a]);
                rows.push((a, row));
                (rest, at) = (tail, offsets[a + 1]);
            }
        }
        let (offsets, cols) = (&*offsets, &*cols);
        rows.into_par_iter()
            .map_init(
                || Accumulator { slot: vec![u32::MAX; n], row: Vec::with_capacity(64) },
                |acc, (a, out)| {
                    f(acc, a);
                    acc.flush_checked(&cols[offsets[a]..offsets[a + 1]], out)
                },
            )
            .all(|same| same)
    }

    fn nnz(&self) -> usize {
        self.cols.len()
    }

    fn bytes(&self) -> usize {
        8 * self.offsets.len() + (4 + 4 * W) * self.cols.len()
    }

    fn row(&self, i: usize) -> impl Iterator<Item = (u32, [f64; W])> + '_ {
        let r = self.offsets[i]..self.offsets[i + 1];
        self.cols[r.clone()].iter().zip(self.vals.slice(r)).map(|(c, v)| (*c, v.map(f64::from)))
    }

    /// Builds `n` rows with `f(accumulator, row)`, columns in `0..cols`, in parallel
    /// chunks of rows (one marker array and one output buffer per chunk).
    fn build(n: usize, cols: usize, f: impl Fn(&mut Accumulator<W>, usize) + Sync) -> Rows<W> {
        type Part<const W: usize> = (Vec<usize>, Vec<u32>, Vec<[f32; W]>);
        // A few parts per thread, each a large block that the level keeps (its numbers
        // are never joined): freed with the level, a large block goes back to the system,
        // where many small ones would stay in the allocator's heaps.
        let rows = n.div_ceil(4 * rayon::current_num_threads().max(1)).max(1024);
        // One marker array per worker, not per chunk of rows: `cols` entries each, so a
        // fresh one per chunk would cost time quadratic in the level's size.
        let parts: Vec<Part<W>> = (0..n.div_ceil(rows))
            .into_par_iter()
            .map_init(
                || Accumulator { slot: vec![u32::MAX; cols], row: Vec::with_capacity(64) },
                |acc, c| {
                    let mut part: Part<W> = (Vec::with_capacity(rows), Vec::new(), Vec::new());
                    for i in c * rows..((c + 1) * rows).min(n) {
                        f(acc, i);
                        part.0.push(acc.row.len());
                        acc.flush_into(&mut part.1, &mut part.2);
                    }
                    // Grown by doubling: at their size, since the numbers stay in the
                    // level and the columns are joined below.
                    part.1.shrink_to_fit();
                    part.2.shrink_to_fit();
                    part
                },
            )
            .collect();
        let total = parts.iter().map(|p| p.1.len()).sum();
        let mut offsets = Vec::with_capacity(n + 1);
        offsets.push(0);
        // The columns (4 bytes an entry) joined; the numbers stay in their parts.
        let mut all_cols = Vec::with_capacity(total);
        let mut vals = Vec::with_capacity(parts.len());
        for (lens, c, v) in parts {
            for l in lens {
                offsets.push(offsets.last().unwrap() + l);
            }
            all_cols.extend(c);
            vals.push(v);
        }
        Rows { offsets, cols: all_cols, vals: Parts::new(vals) }
    }
}

/// Row accumulator with a dense marker.
struct Accumulator<const W: usize = 10> {
    slot: Vec<u32>,
    row: Vec<(u32, [f64; W])>,
}

impl<const W: usize> Accumulator<W> {
    #[inline]
    fn entry(&mut self, col: u32) -> &mut [f64; W] {
        let s = &mut self.slot[col as usize];
        if *s == u32::MAX {
            *s = self.row.len() as u32;
            self.row.push((col, [0.0; W]));
        }
        &mut self.row[*s as usize].1
    }

    /// Writes the row, sorted by column, to `out` if its columns are `cols`; clears it.
    fn flush_checked(&mut self, cols: &[u32], out: &mut [[f32; W]]) -> bool {
        for (c, _) in &self.row {
            self.slot[*c as usize] = u32::MAX;
        }
        self.row.sort_unstable_by_key(|e| e.0);
        let same = self.row.len() == cols.len() && self.row.iter().zip(cols).all(|(e, c)| e.0 == *c);
        if same {
            for (o, e) in out.iter_mut().zip(&self.row) {
                *o = narrow(&e.1);
            }
        }
        self.row.clear();
        same
    }

    /// Appends the row, sorted by column, to `cols` and `vals`, and clears it.
    fn flush_into(&mut self, cols: &mut Vec<u32>, vals: &mut Vec<[f32; W]>) {
        for (c, _) in &self.row {
            self.slot[*c as usize] = u32::MAX;
        }
        self.row.sort_unstable_by_key(|e| e.0);
        cols.extend(self.row.iter().map(|e| e.0));
        vals.extend(self.row.iter().map(|e| narrow(&e.1)));
        self.row.clear();
    }
}

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
fn galerkin_from_stencil(stencil: &Stencil, coef: &Coefficients<'_>, agg: &Aggregation) -> Rows {
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
fn galerkin_from_rows<const W: usize>(rows: &Rows<W>, agg: &Aggregation) -> Rows<W> {
    let nc = agg.len();
    Rows::build(nc, nc, |acc, a| galerkin_row(acc, rows, agg, a))
}

/// Row `a` of `P^T A P`: the rows of aggregate `a`'s members, summed by aggregate.
fn galerkin_row<const W: usize>(acc: &mut Accumulator<W>, rows: &Rows<W>, agg: &Aggregation, a: usize) {
    for &i in agg.members(a) {
        for (j, block) in rows.row(i as usize) {
            let e = acc.entry(agg.parent[j as usize]);
            for t in 0..W {
                e[t] += block[t];
            }
        }
    }
}

/// The numbers of a block of a face's operator `P^T D H D P` (`D` the 0/1 diagonal of the
/// face's free coordinates): entries `0..9`, the alignment part, a general 3x3 block
/// (column-major); `9..12`, the diagonal part (attachment and fairness, masked at both
/// ends: no longer a multiple of the identity); `12..18`, a symmetric `[xx, yy, zz, xy,
/// xz, yz]` block bounding what the alignment part adds to its row's majorant off the
/// diagonal: the sum of `b (D_i n)(D_i n)^T` over the fine couplings it aggregates, since
/// `[[0, -b u v^T], [-b v u^T, 0]] <= diag(b u u^T, b v v^T)`. (Masking breaks the sign
/// structure the whole operator's blocks have; this carries the bound instead.)
const FACE: usize = 18;

impl Accumulator<FACE> {
    fn add_diag(&mut self, col: u32, d: DVec3) {
        let e = self.entry(col);
        e[9] += d.x;
        e[10] += d.y;
        e[11] += d.z;
    }

    /// Adds `s u v^T` to the alignment part and `g u u^T` to the majorant part.
    fn add_coupling(&mut self, col: u32, s: f64, u: DVec3, v: DVec3, g: f64) {
        let e = self.entry(col);
        for c in 0..3 {
            for r in 0..3 {
                e[3 * c + r] += s * u[r] * v[c];
            }
        }
        if g != 0.0 {
            let m = [u.x * u.x, u.y * u.y, u.z * u.z, u.x * u.y, u.x * u.z, u.y * u.z];
            for t in 0..6 {
                e[12 + t] += g * m[t];
            }
        }
    }
}

/// `P^T D H D P` of the matrix-free fine operator, `D = diag(face)`: the rows of
/// [`galerkin_from_stencil`], each contribution masked at its row's and its column's
/// vertex.
fn galerkin_face_from_stencil(
    stencil: &Stencil,
    coef: &Coefficients<'_>,
    agg: &Aggregation,
    face: &[Vec3A],
) -> Rows<FACE> {
    Rows::build(agg.len(), agg.len(), |acc, a| face_row(acc, stencil, coef, agg, face, a))
}

/// Row `a` of [`galerkin_face_from_stencil`]. It reads the face at the members of
/// aggregate `a`, their faces' vertices and their fairness 2-rings ([`face_row_reads`]);
/// which entries it creates does not depend on the face.
fn face_row(
    acc: &mut Accumulator<FACE>,
    stencil: &Stencil,
    coef: &Coefficients<'_>,
    agg: &Aggregation,
    face: &[Vec3A],
    a: usize,
) {
    let parent = &agg.parent;
    let f = |i: usize| face[i].as_dvec3();
    let me = a as u32;
    for &i in agg.members(a) {
        let i = i as usize;
        let fi = f(i);
        acc.add_diag(me, coef.alpha.get(i) * fi);
        for s in stencil.faces(i) {
            let n = coef.normals[s.face as usize];
            let b = coef.beta.get(s.face as usize);
            let m = n * fi;
            acc.add_coupling(me, 2.0 * b, m, m, 0.0);
            for j in [s.prev, s.next] {
                acc.add_coupling(parent[j as usize], -b, m, n * f(j as usize), b);
            }
        }
        let mut row_k = |k: usize, coeff: f64| {
            let ck = coef.fair[k];
            if ck == 0.0 {
                return;
            }
            let nbk = stencil.fair_neighbours(k);
            let w = ck * nbk.len() as f64 * coeff;
            acc.add_diag(parent[k], w * fi * f(k));
            let share = -w / nbk.len() as f64;
            for &j in nbk {
                acc.add_diag(parent[j as usize], share * fi * f(j as usize));
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
}

/// Whether [`face_row`]'s contributions of vertex `i` read a vertex where `changed` is
/// set: `i` itself, the other vertices of its faces, its fairness neighbours and theirs.
fn face_row_reads(stencil: &Stencil, changed: &[bool], i: usize) -> bool {
    changed[i]
        || stencil.faces(i).iter().any(|s| changed[s.prev as usize] || changed[s.next as usize])
        || stencil.fair_neighbours(i).iter().any(|&k| {
            changed[k as usize] || stencil.fair_neighbours(k as usize).iter().any(|&j| changed[j as usize])
        })
}

/// Below one changed vertex in this many, a face update finds the rows to recompute from
/// the changed vertices ([`rows_near`]) rather than by testing every row
/// ([`face_row_reads`]): a late active-set round changes a few hundred holds of millions.
const SPARSE_CHANGES: usize = 256;

/// The aggregates holding a vertex within two edges of one of `changes` (ascending, each
/// once): every row whose [`face_row`] reads a changed vertex, since a row reads its
/// members, their faces' vertices (edge neighbours) and their fairness 2-rings (fairness
/// neighbours are edge neighbours, some cut by a mask), and edges go both ways. Where a
/// mask cuts fairness neighbours it may hold a few rows more, which recompute to the same
/// numbers.
fn rows_near(stencil: &Stencil, agg: &Aggregation, changes: &[u32]) -> Vec<usize> {
    let parent = &agg.parent;
    let mut rows: Vec<u32> = changes
        .par_iter()
        .flat_map_iter(|&c| {
            let c = c as usize;
            let mut out = vec![parent[c]];
            for s in stencil.faces(c) {
                for v in [s.prev as usize, s.next as usize] {
                    out.push(parent[v]);
                    for t in stencil.faces(v) {
                        out.push(parent[t.prev as usize]);
                        out.push(parent[t.next as usize]);
                    }
                }
            }
            out
        })
        .collect();
    rows.par_sort_unstable();
    rows.dedup();
    rows.into_iter().map(|a| a as usize).collect()
}

/// [`l1_smoother`] of a face's level: `M_I = A_II + sum_{J != I} (G_IJ + |d_IJ|)` (`G` the
/// majorant part, `d` the diagonal part of [`FACE`]); a coordinate that no free vertex
/// moves (a zero row) gets the identity.
fn l1_face_smoother(rows: &Rows<FACE>, damping: f64) -> Vec<Block> {
    (0..rows.len()).into_par_iter().map(|i| l1_face_block(rows, i, damping)).collect()
}

/// Row `i`'s block of [`l1_face_smoother`].
fn l1_face_block(rows: &Rows<FACE>, i: usize, damping: f64) -> Block {
    let mut d = [0.0; 6];
    for (j, b) in rows.row(i) {
        if j as usize == i {
            let sym = [b[0], b[4], b[8], 0.5 * (b[3] + b[1]), 0.5 * (b[6] + b[2]), 0.5 * (b[7] + b[5])];
            for t in 0..6 {
                d[t] += sym[t];
            }
            for t in 0..3 {
                d[t] += b[9 + t];
            }
        } else {
            for t in 0..6 {
                d[t] += b[12 + t];
            }
            for t in 0..3 {
                d[t] += b[9 + t].abs();
            }
        }
    }
    for t in 0..3 {
        if d[t] == 0.0 {
            d[t] = 1.0;
        }
    }
    block(&scale6(&sym_inverse(&d), damping))
}

/// The coarse levels of a face's operator ([`Vcycle::set_face`]).
#[derive(Debug)]
struct FaceLevels {
    levels: Vec<Level>,
    coarsest: Option<Coarsest>,
    /// Every coarse level's rows (the first coarse level's first), and the face they
    /// were built for, to update them for the next face
    /// ([`Vcycle::updated_face_hierarchy`]).
    rows: Vec<Rows<FACE>>,
    face: Vec<Vec3A>,
}

/// The inverse blocks of a block-diagonal majorant `M >= A` of an assembled level,
/// damped: `M_I = A_II + sum_{J != I} (-N_IJ + |s_IJ| I)` for off-diagonal blocks
/// `N_IJ + s_IJ I` with `N_IJ <= 0` (alignment) — since `[[0, B], [B, 0]] <= diag(C, C)`
/// whenever `C >= +-B`.
fn l1_smoother(rows: &Rows, damping: f64, old: Vec<Block>) -> Vec<Block> {
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
    offsets: Vec<u32>,
    cols: Vec<u32>,
    blocks: Blocks,
}

/// A level's blocks: symmetric ([`Block`], 24 bytes) for the whole operator, whose
/// blocks are sums of `n n^T` and multiples of the identity, or general ([`Full`], 36
/// bytes) for a face's operator, whose masks differ at a block's two ends.
#[derive(Clone, Debug)]
enum Blocks {
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
    fn from_rows<const W: usize>(rows: &Rows<W>) -> Self {
        let offsets = rows.offsets.iter().map(|&o| o as u32).collect();
        let cols = rows.cols.clone();
        let blocks = if W == 10 {
            Blocks::Sym(rows.vals.map(|b| sym_block(full_block(b))))
        } else {
            Blocks::Full(rows.vals.map(full_block))
        };
        Bsr { offsets, cols, blocks }
    }

    /// [`Bsr::from_rows`] of the whole operator's rows (`W = 10`), in the arrays of `old`
    /// when it has their pattern (the last solve's level: the pattern depends on the
    /// surface and hierarchy, seldom on the numbers).
    fn from_rows_reusing(rows: &Rows<10>, old: Bsr) -> Self {
        let same = old.offsets.len() == rows.offsets.len()
            && old.cols == rows.cols
            && old.offsets.iter().zip(&rows.offsets).all(|(&a, &b)| a as usize == b);
        match old.blocks {
            Blocks::Sym(mut blocks) if same && blocks.len() == rows.vals.len() => {
                rows.vals.map_into(&mut blocks, |b| sym_block(full_block(b)));
                Bsr { offsets: old.offsets, cols: old.cols, blocks: Blocks::Sym(blocks) }
            }
            _ => Self::from_rows(rows),
        }
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
    fn residual(&self, x: &[Vec3A], b: &[Vec3A], y: &mut [Vec3A]) {
        match &self.blocks {
            Blocks::Sym(blocks) => self.residual_with(blocks, block_mul, x, b, y),
            Blocks::Full(blocks) => self.residual_with(blocks, full_mul, x, b, y),
        }
    }

    #[inline(always)]
    fn residual_with<B: Sync>(
        &self,
        blocks: &[B],
        mul: impl Fn(&B, Vec3A) -> Vec3A + Sync,
        x: &[Vec3A],
        b: &[Vec3A],
        y: &mut [Vec3A],
    ) {
        y.par_chunks_mut(CHUNK).enumerate().for_each(|(k, out)| {
            let base = k * CHUNK;
            for (o, yi) in out.iter_mut().enumerate() {
                let i = base + o;
                let (start, end) = (self.offsets[i] as usize, self.offsets[i + 1] as usize);
                let mut acc = Vec3A::ZERO;
                for (m, &c) in blocks[start..end].iter().zip(&self.cols[start..end]) {
                    acc += mul(m, x[c as usize]);
                }
                *yi = b[i] - acc;
            }
        });
    }
}

/// A level's block from its row entry: the alignment part (`b[..9]`) plus the diagonal
/// part, one value for the three coordinates (`W = 10`) or one per coordinate (`W = FACE`).
fn full_block<const W: usize>(b: &[f32; W]) -> Full {
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
    [m[0], m[4], m[8], m[3], m[6], m[7]]
}

/// Sparse Cholesky of the coarsest level.
struct Coarsest {
    symbolic: SymbolicCholesky<usize>,
    factor: Vec<f64>,
    n: usize,
}

impl std::fmt::Debug for Coarsest {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Coarsest").field("n", &self.n).finish()
    }
}

impl Coarsest {
    fn new(rows: &Rows) -> Result<Self, RegularizeError> {
        Self::from_blocks(rows, |b, r, c| b[3 * c + r] + if r == c { b[9] } else { 0.0 })
    }

    /// The factor of a face's coarsest level, with the identity on the coordinates no
    /// free vertex moves.
    fn face(rows: &Rows<FACE>) -> Result<Self, RegularizeError> {
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

    fn solve(&self, b: &[Vec3A], x: &mut [Vec3A]) {
        let mut rhs: Vec<f64> = b.iter().flat_map(|v| v.as_dvec3().to_array()).collect();
        let par = faer::Par::Seq;
        let mut mem = MemBuffer::new(self.symbolic.solve_in_place_scratch::<f64>(1, par));
        LltRef::new(&self.symbolic, &self.factor).solve_in_place_with_conj(
            Conj::No,
            MatMut::from_column_major_slice_mut(&mut rhs, 3 * self.n, 1),
            par,
            MemStack::new(&mut mem),
        );
        for (xi, v) in x.iter_mut().zip(rhs.chunks_exact(3)) {
            *xi = Vec3A::new(v[0] as f32, v[1] as f32, v[2] as f32);
        }
    }
}

#[derive(Debug, Default)]
struct Level {
    /// The operator (empty on the coarsest level, which is factored instead).
    matrix: Bsr,
    smoother: Vec<Block>,
    n: usize,
}

impl Level {
    /// Rows `dirty` of a face's level (general blocks) and their smoother blocks, from
    /// `rows` (the same pattern). When they are a quarter of the rows or more, every row is
    /// converted, in parallel: the others come out as they were.
    fn set_face_rows(&mut self, rows: &Rows<FACE>, dirty: &[usize], damping: f64) {
        let Blocks::Full(blocks) = &mut self.matrix.blocks else {
            unreachable!("a face's level has general blocks")
        };
        if 4 * dirty.len() >= rows.len() {
            rows.vals.map_into(blocks, full_block);
            self.smoother.par_iter_mut().enumerate().for_each(|(i, b)| *b = l1_face_block(rows, i, damping));
            return;
        }
        for &i in dirty {
            let r = rows.offsets[i]..rows.offsets[i + 1];
            for (b, v) in blocks[r.clone()].iter_mut().zip(rows.vals.slice(r)) {
                *b = full_block(v);
            }
            self.smoother[i] = l1_face_block(rows, i, damping);
        }
    }
}

#[derive(Debug)]
struct Work {
    r: Vec<Vec3A>,
    x: Vec<Vec3A>,
    t: Vec<Vec3A>,
}

/// One energy's multigrid preconditioner: `z = V(r)`.
#[derive(Debug)]
pub(crate) struct Vcycle {
    fine: FineNumbers,
    fine_smoother: Vec<Block>,
    /// The smoother of the face operator ([`Vcycle::set_face`]).
    face_smoother: Vec<Block>,
    /// The face operator's own coarse levels ([`Vcycle::set_face`]).
    face_levels: Option<FaceLevels>,
    /// The fine majorant's blocks, for the face smoothers: computed by the first
    /// [`Vcycle::set_face`] (48 bytes a vertex that unconstrained solves never hold).
    majorant: Vec<[f64; 6]>,
    damping: f64,
    levels: Vec<Level>,
    aggregations: Arc<[Aggregation]>,
    coarsest: Option<Coarsest>,
    works: Vec<Work>,
    steps: usize,
    coarse_steps: usize,
    /// Seconds spent factoring the coarsest level.
    pub(crate) factor_seconds: f64,
}

/// The fine smoother's block of a vertex on a face: the damped inverse of its majorant
/// `m` on the free coordinates (`face` 1), the identity on the held ones.
fn face_smoother_block(m: &[f64; 6], face: Vec3A, damping: f64) -> Block {
    let keep = [face.x != 0.0, face.y != 0.0, face.z != 0.0];
    // [xx, yy, zz, xy, xz, yz]
    let pairs = [(0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)];
    let mut b = [0.0; 6];
    for (k, &(i, j)) in pairs.iter().enumerate() {
        b[k] = if keep[i] && keep[j] {
            m[k]
        } else if i == j {
            1.0
        } else {
            0.0
        };
    }
    block(&scale6(&sym_inverse(&b), damping))
}

/// `x = m r` (or `x += m r` with `add`), masked by `face` when given.
fn smooth(m: &[Block], r: &[Vec3A], x: &mut [Vec3A], add: bool, face: Option<&[Vec3A]>) {
    x.par_chunks_mut(CHUNK).zip(r.par_chunks(CHUNK)).zip(m.par_chunks(CHUNK)).enumerate().for_each(
        |(k, ((x, r), m))| {
            for i in 0..x.len() {
                let d = block_mul(&m[i], r[i]);
                x[i] = masked(face, k * CHUNK + i, if add { x[i] + d } else { d });
            }
        },
    );
}

/// `v * face[i]` coordinate-wise (`v` without a face): the cycle's masks, applied where
/// each value is written rather than in passes of their own.
#[inline(always)]
fn masked(face: Option<&[Vec3A]>, i: usize, v: Vec3A) -> Vec3A {
    match face {
        Some(f) => v * f[i],
        None => v,
    }
}

fn restrict(agg: &Aggregation, fine: &[Vec3A], coarse: &mut [Vec3A]) {
    coarse.par_chunks_mut(CHUNK).enumerate().for_each(|(k, out)| {
        for (o, c) in out.iter_mut().enumerate() {
            *c = agg.members(k * CHUNK + o).iter().map(|&i| fine[i as usize]).sum();
        }
    });
}

/// `fine += P coarse`, masked by `face` when given.
fn prolong_add(parent: &[u32], coarse: &[Vec3A], fine: &mut [Vec3A], face: Option<&[Vec3A]>) {
    fine.par_chunks_mut(CHUNK).zip(parent.par_chunks(CHUNK)).enumerate().for_each(|(k, (f, p))| {
        for i in 0..f.len() {
            f[i] = masked(face, k * CHUNK + i, f[i] + coarse[p[i] as usize]);
        }
    });
}

impl Vcycle {
    /// Bytes of the coarse levels, smoothers and work vectors.
    pub(crate) fn memory_bytes(&self) -> usize {
        let agg: usize =
            self.aggregations.iter().map(|a| 4 * (a.parent.len() + a.members.len() + a.offsets.len())).sum();
        let levels: usize = self.levels.iter().map(|l| l.matrix.bytes() + 24 * l.n).sum();
        let works: usize = self.works.iter().map(|w| 16 * (w.r.len() + w.x.len() + w.t.len())).sum();
        let coarsest = self.coarsest.as_ref().map_or(0, |c| 8 * c.factor.len());
        let face = self.face_levels.as_ref().map_or(0, |f| {
            let levels: usize = f.levels.iter().map(|l| l.matrix.bytes() + 24 * l.n).sum();
            levels
                + f.coarsest.as_ref().map_or(0, |c| 8 * c.factor.len())
                + f.rows.iter().map(Rows::bytes).sum::<usize>()
                + 16 * f.face.len()
        });
        face + 24 * (self.fine_smoother.len() + self.face_smoother.len())
            + 48 * self.majorant.len()
            + self.fine.bytes()
            + agg
            + levels
            + works
            + coarsest
    }

    /// Puts the fine level on the operator of `coef` (its numbers, majorant and smoother)
    /// and keeps the coarse levels, which stay those of the energy the cycle was built
    /// for: the cycle of a quick start ([`crate::iterative::Setup::prepare`]), O(n) instead
    /// of a setup. Still a fixed symmetric positive definite preconditioner of the new
    /// operator `A`: with the smoother `S = damping M^-1`, `M >= A` and damping below 2,
    /// the cycle is `2S - SAS + (I - SA) P C P^T (I - AS)`, where `2S - SAS` is positive
    /// definite and `C` (the old levels' own symmetric cycle) positive semi-definite; how
    /// close the old levels are to the new operator's only sets the rate.
    pub(crate) fn refresh_fine(&mut self, stencil: &Stencil, coef: &Coefficients<'_>) {
        self.fine_smoother = inverse_blocks(
            &fine_majorant(stencil, coef),
            self.damping,
            std::mem::take(&mut self.fine_smoother),
        );
        self.fine = FineNumbers::new(stencil, coef, std::mem::take(&mut self.fine));
        self.forget_face();
    }

    /// Drops the face's levels, smoother and majorant ([`Vcycle::set_face`]): once the
    /// active-set rounds are over, or the operator's numbers changed.
    pub(crate) fn forget_face(&mut self) {
        self.face_levels = None;
        self.face_smoother = Vec::new();
        self.majorant = Vec::new();
    }

    /// Bytes moved by one cycle (`connectivity`: bytes of the stencil's connectivity).
    pub(crate) fn traffic(&self, connectivity: usize, n: usize) -> usize {
        let (s, cs) = (self.steps, self.coarse_steps);
        // Fine, in f32: products (connectivity, numbers, 5 vectors), smoothing (r, M, z),
        // residual updates, conversions in and out, restriction, prolongation.
        let product = connectivity + self.fine.bytes() + 5 * 16 * n;
        let fine = 2 * s * product + 2 * s * 56 * n + 2 * s * 48 * n + 2 * 40 * n + 40 * n;
        let coarse: usize =
            self.levels.iter().map(|l| 2 * cs * (l.matrix.bytes() + 3 * 16 * l.n) + 10 * 16 * l.n).sum();
        let coarsest = self.coarsest.as_ref().map_or(0, |c| 2 * 8 * c.factor.len());
        fine + coarse + coarsest
    }

    /// `z = V(r)`: one symmetric V-cycle, in `f32`.
    pub(crate) fn apply(&mut self, stencil: &Stencil, r: &[DVec3], z: &mut [DVec3]) {
        self.apply_on_face(stencil, r, z, None);
    }

    /// Prepares [`Vcycle::apply_on_face`] for `face`: the fine smoother of the face's
    /// operator, each vertex's majorant block with the held coordinates' rows and columns
    /// replaced by the identity, inverted (the whole block's inverse, masked, would be
    /// the face block of `M^-1`, larger than `M_FF^-1`: no longer a convergent smoother),
    /// and the face's own Galerkin coarse operators `P^T D H D P` (`D = diag(face)`) with
    /// their smoothers and coarsest factor, so that the coarse correction is the face
    /// operator's, not the whole one's (which moves held coordinates' neighbourhoods as if
    /// they were free). Costs about one multigrid setup.
    ///
    /// With `update`, levels built for another face of the same operator (the previous
    /// round of the active-set iteration) are updated where the face changed
    /// ([`Vcycle::updated_face_hierarchy`]) instead of built anew.
    pub(crate) fn set_face(
        &mut self,
        stencil: &Stencil,
        coef: &Coefficients<'_>,
        face: &[Vec3A],
        update: bool,
    ) {
        // The former face's levels go first: one face hierarchy in memory at a time.
        let built = self.face_levels.take();
        let damping = self.damping;
        if self.majorant.len() != stencil.len() {
            self.majorant = fine_majorant(stencil, coef);
        }
        // Where the face changed since the last one, when updating: the fine smoother's
        // blocks and the coarse levels' rows follow those coordinates only.
        let changed: Option<Vec<bool>> = built
            .as_ref()
            .filter(|b| update && b.face.len() == face.len() && self.face_smoother.len() == face.len())
            .map(|b| b.face.par_iter().zip(face).map(|(a, b)| a != b).collect());
        match &changed {
            Some(changed) => {
                self.face_smoother
                    .par_iter_mut()
                    .zip(self.majorant.par_iter().zip(face.par_iter().zip(changed)))
                    .for_each(|(s, (m, (f, &c)))| {
                        if c {
                            *s = face_smoother_block(m, *f, damping);
                        }
                    });
            }
            None => {
                self.face_smoother = self
                    .majorant
                    .par_iter()
                    .zip(face.par_iter())
                    .map(|(m, f)| face_smoother_block(m, *f, damping))
                    .collect();
            }
        }
        self.face_levels = match (built, changed) {
            (Some(b), Some(changed)) => self.updated_face_hierarchy(stencil, coef, face, &changed, b),
            _ => None,
        }
        .or_else(|| self.face_hierarchy(stencil, coef, face));
    }

    /// The coarse levels of the face's operator; `None` when its coarsest level does not
    /// factor (the cycle then falls back to the whole operator's coarse levels) or the
    /// surface is its own coarsest level.
    fn face_hierarchy(
        &self,
        stencil: &Stencil,
        coef: &Coefficients<'_>,
        face: &[Vec3A],
    ) -> Option<FaceLevels> {
        let first = self.aggregations.first()?;
        let rows = galerkin_face_from_stencil(stencil, coef, first, face);
        self.face_levels_from(rows, face.to_vec())
    }

    /// The face's levels from its first coarse level's rows.
    fn face_levels_from(&self, rows: Rows<FACE>, face: Vec<Vec3A>) -> Option<FaceLevels> {
        let mut all = vec![rows];
        for agg in &self.aggregations[1..] {
            let coarse = galerkin_from_rows(all.last().expect("a finer level"), agg);
            all.push(coarse);
        }
        // Every level but the coarsest (factored) is smoothed and multiplied.
        let levels = all
            .iter()
            .enumerate()
            .map(|(k, r)| {
                if k + 1 < all.len() {
                    Level {
                        matrix: Bsr::from_rows(r),
                        smoother: l1_face_smoother(r, self.damping),
                        n: r.len(),
                    }
                } else {
                    Level { matrix: Bsr::default(), smoother: Vec::new(), n: r.len() }
                }
            })
            .collect();
        let coarsest = Coarsest::face(all.last().expect("a coarse level")).ok()?;
        Some(FaceLevels { levels, coarsest: Some(coarsest), rows: all, face })
    }

    /// The face's levels for `face`, updated from `built` (those of another face of the
    /// same operator): only the rows of the first coarse level that read a vertex whose
    /// free coordinates changed are recomputed ([`face_row_reads`]), then on each coarser
    /// level the rows of the aggregates holding a recomputed row, with their blocks and
    /// smoother blocks. The same levels as [`Vcycle::face_hierarchy`], at a cost
    /// that follows the number of changed vertices instead of the surface's size. `None`
    /// where the change is too large to gain (half the vertices or more) or a
    /// row's pattern differs (it cannot: which entries a row has does not depend on the
    /// face); the caller builds them anew.
    fn updated_face_hierarchy(
        &self,
        stencil: &Stencil,
        coef: &Coefficients<'_>,
        face: &[Vec3A],
        changed: &[bool],
        built: FaceLevels,
    ) -> Option<FaceLevels> {
        let agg = self.aggregations.first()?;
        let changes: Vec<u32> =
            (0..changed.len()).into_par_iter().filter(|&i| changed[i]).map(|i| i as u32).collect();
        if 2 * changes.len() >= face.len() {
            return None;
        }
        let mut dirty: Vec<usize> = if changes.len() * SPARSE_CHANGES < face.len() {
            rows_near(stencil, agg, &changes)
        } else {
            (0..agg.len())
                .into_par_iter()
                .filter(|&a| agg.members(a).iter().any(|&i| face_row_reads(stencil, changed, i as usize)))
                .collect()
        };
        let FaceLevels { mut levels, mut rows, face: mut kept, .. } = built;
        if rows.len() != levels.len()
            || !rows[0].recompute(&dirty, |acc, a| face_row(acc, stencil, coef, agg, face, a))
        {
            return None;
        }
        for k in 0..rows.len() - 1 {
            let level = &mut levels[k];
            level.set_face_rows(&rows[k], &dirty, self.damping);
            let coarser = &self.aggregations[k + 1];
            let mut next: Vec<usize> = dirty.iter().map(|&i| coarser.parent[i] as usize).collect();
            next.sort_unstable();
            next.dedup();
            let (finer, rest) = rows.split_at_mut(k + 1);
            let finer = &finer[k];
            if !rest[0].recompute(&next, |acc, a| galerkin_row(acc, finer, coarser, a)) {
                return None;
            }
            dirty = next;
        }
        let coarsest = Coarsest::face(rows.last().expect("a coarse level")).ok()?;
        kept.copy_from_slice(face);
        Some(FaceLevels { levels, coarsest: Some(coarsest), rows, face: kept })
    }

    /// [`Vcycle::apply`] for the operator restricted to a face (the coordinates where
    /// `face` is 1; it is 0 on the others, held fixed): every fine-level smoothing,
    /// residual, restriction and prolongation is masked, so the fine level smooths the
    /// face's own operator `D H D` (`D = diag(face)`) and the coarse correction only moves
    /// free coordinates. Symmetric positive definite on the face, like the V-cycle; a much
    /// better preconditioner there than the whole operator's cycle masked afterwards,
    /// whose smoother moves held coordinates that the mask then discards.
    pub(crate) fn apply_on_face(
        &mut self,
        stencil: &Stencil,
        r: &[DVec3],
        z: &mut [DVec3],
        face: Option<&[Vec3A]>,
    ) {
        let steps = self.steps;
        let mut works = std::mem::take(&mut self.works);
        let (fine, rest) = works.split_at_mut(1);
        let w = &mut fine[0];
        let face_smoother = std::mem::take(&mut self.face_smoother);
        let smoother = if face.is_some() && face_smoother.len() == w.x.len() {
            &face_smoother
        } else {
            &self.fine_smoother
        };
        // Fine level: the right-hand side in `f32`, read from `r` where used (not stored),
        // and the pre-smoothing from zero, then the residual restricted.
        let b = |i: usize| masked(face, i, r[i].as_vec3a());
        w.x.par_chunks_mut(CHUNK).zip(smoother.par_chunks(CHUNK)).enumerate().for_each(|(k, (x, m))| {
            for i in 0..x.len() {
                let j = k * CHUNK + i;
                x[i] = masked(face, j, block_mul(&m[i], b(j)));
            }
        });
        if self.levels.is_empty() {
            z.par_chunks_mut(CHUNK).zip(w.x.par_chunks(CHUNK)).for_each(|(z, x)| {
                for (z, x) in z.iter_mut().zip(x) {
                    *z = x.as_dvec3();
                }
            });
        } else {
            for s in 0..steps {
                self.fine.residual(stencil, &w.x, &b, &mut w.r, &mut w.t, face);
                if s + 1 < steps {
                    smooth(smoother, &w.r, &mut w.x, true, face);
                }
            }
            restrict(&self.aggregations[0], &w.r, &mut rest[0].r);
            match (face, &self.face_levels) {
                (Some(_), Some(f)) => self.coarse_cycle(&f.levels, f.coarsest.as_ref(), 0, rest),
                _ => self.coarse_cycle(&self.levels, self.coarsest.as_ref(), 0, rest),
            }
            prolong_add(&self.aggregations[0].parent, &rest[0].x, &mut w.x, face);
            for _ in 1..steps {
                self.fine.residual(stencil, &w.x, &b, &mut w.r, &mut w.t, face);
                smooth(smoother, &w.r, &mut w.x, true, face);
            }
            // The last post-smoothing step and the output in `f64`, in the residual's pass.
            let Work { x, t, .. } = w;
            let x = &*x;
            self.fine.residual_map(stencil, x, &b, z, t, face, |i, r| {
                masked(face, i, x[i] + block_mul(&smoother[i], r)).as_dvec3()
            });
        }
        self.face_smoother = face_smoother;
        self.works = works;
    }

    /// Solves approximately on coarse level `l + 1` (`works[l]`): `x = V(r)`.
    fn coarse_cycle(&self, levels: &[Level], coarsest: Option<&Coarsest>, l: usize, works: &mut [Work]) {
        let last = l + 1 == levels.len();
        if last {
            let w = &mut works[0];
            coarsest.expect("factored").solve(&w.r, &mut w.x);
            return;
        }
        let steps = self.coarse_steps;
        let (here, rest) = works.split_at_mut(1);
        let w = &mut here[0];
        let level = &levels[l];
        smooth(&level.smoother, &w.r, &mut w.x, false, None);
        for s in 0..steps {
            level.matrix.residual(&w.x, &w.r, &mut w.t);
            if s + 1 < steps {
                smooth(&level.smoother, &w.t, &mut w.x, true, None);
            }
        }
        restrict(&self.aggregations[l + 1], &w.t, &mut rest[0].r);
        self.coarse_cycle(levels, coarsest, l + 1, rest);
        let level = &levels[l];
        let (here, rest) = works.split_at_mut(1);
        let w = &mut here[0];
        prolong_add(&self.aggregations[l + 1].parent, &rest[0].x, &mut w.x, None);
        for _ in 0..steps {
            level.matrix.residual(&w.x, &w.r, &mut w.t);
            smooth(&level.smoother, &w.t, &mut w.x, true, None);
        }
    }
}

#[cfg(test)]
pub(crate) mod tests {
    thread_local! {
        /// Multigrid setups ([`super::Hierarchy::numeric`]) run on this thread, for the
        /// tests that bound the work before a quick start's first iterate.
        pub(crate) static SETUPS: std::cell::Cell<usize> = const { std::cell::Cell::new(0) };
    }

    /// The setups run on this thread so far.
    pub(crate) fn setups() -> usize {
        SETUPS.with(|c| c.get())
    }

    use glam::{DVec3, Vec3A};
    use voxreg_digisurf::DigitalSurface;
    use voxreg_testkit::{digitize, true_normals, Lcg, Torus};

    use super::*;
    use crate::energy::{Energy, EnergyParams};
    use crate::stencil::Stencil;

    /// Rows built in several parts (some rows empty) read back and recomputed in place
    /// across the parts' boundaries as if they were one array.
    #[test]
    fn rows_in_parts_read_and_recompute_as_one_array() {
        let n = 9000;
        // Row i: columns i, i + 7 and i * 3 (mod n), except every 13th row, empty;
        // numbers from the row, the column and `s`.
        let f = |s: f64| {
            move |acc: &mut Accumulator<2>, i: usize| {
                if i % 13 != 0 {
                    for c in [i, (i + 7) % n, (i * 3) % n] {
                        let e = acc.entry(c as u32);
                        e[0] += s * i as f64 + c as f64;
                        e[1] += 1.0;
                    }
                }
            }
        };
        let mut rows = Rows::<2>::build(n, n, f(1.0));
        assert!(rows.vals.parts.len() > 2, "{} parts", rows.vals.parts.len());
        let fresh = Rows::<2>::build(n, n, f(2.0));
        // Every third row, and the rows at the parts' edges, recomputed with `s = 2`.
        let mut dirty: Vec<usize> = (0..n).step_by(3).collect();
        for &k in &rows.vals.starts {
            let row = rows.offsets.partition_point(|&o| o <= k).saturating_sub(1).min(n - 1);
            dirty.extend([row.saturating_sub(1), row, (row + 1).min(n - 1)]);
        }
        dirty.sort_unstable();
        dirty.dedup();
        assert!(rows.recompute(&dirty, f(2.0)));
        let old = Rows::<2>::build(n, n, f(1.0));
        for i in 0..n {
            let want: Vec<_> =
                if dirty.binary_search(&i).is_ok() { fresh.row(i) } else { old.row(i) }.collect();
            assert_eq!(rows.row(i).collect::<Vec<_>>(), want, "row {i}");
        }
        // Another pattern is refused.
        let shifted = |acc: &mut Accumulator<2>, i: usize| {
            acc.entry(((i + 1) % n) as u32)[0] += 1.0;
        };
        assert!(!rows.recompute(&[1, 5000], shifted));
        // The blocks of a level read the parts in order.
        let flat: Vec<[f32; 2]> = fresh.vals.iter().copied().collect();
        assert_eq!(fresh.vals.map(|v| *v), flat);
        assert_eq!(flat.len(), fresh.nnz());
    }

    /// A face holding a random fifth of the coordinates.
    fn random_face(n: usize, rng: &mut Lcg) -> Vec<Vec3A> {
        (0..n)
            .map(|_| {
                let v = rng.vec3(0.0, 1.0);
                Vec3A::new(f32::from(v.x > 0.2), f32::from(v.y > 0.2), f32::from(v.z > 0.2))
            })
            .collect()
    }

    /// Runs `test` on the default energy of a digitized torus (its true normals, each
    /// moved by up to `noise` per coordinate and normalized when `noise > 0`): the
    /// stencil, the coefficients and a hierarchy of at least three levels, with a random
    /// generator seeded with `seed`.
    fn on_torus(noise: f64, seed: u64, test: impl FnOnce(&Stencil, &Coefficients<'_>, &Hierarchy, &mut Lcg)) {
        let torus = Torus { major: 8.0, minor: 3.0 };
        let s = DigitalSurface::from_volume(&digitize(&torus, 1.0)).unwrap();
        let mut rng = Lcg::new(seed);
        let mut normals = true_normals(&s, &torus);
        if noise > 0.0 {
            normals.iter_mut().for_each(|n| *n = (*n + rng.vec3(-noise, noise)).normalize());
        }
        let normals = voxreg_normals::NormalField::new(normals);
        let input = s.positions();
        let e = Energy::new(&s, &normals, &input, EnergyParams::default()).unwrap();
        let st = Stencil::new(&s, None).unwrap();
        let c = st.coefficients(&e);
        let h = Hierarchy::new(
            &st,
            crate::stencil::lattice_corners(&s),
            &MultigridParams { coarsest_nodes: 20, ..Default::default() },
        );
        assert!(h.levels() > 2);
        test(&st, &c, &h, &mut rng);
    }

    /// The whole operator's coarse blocks are stored as symmetric blocks: they must be
    /// exactly symmetric at every level, and their products those of the full blocks to
    /// the bit.
    #[test]
    fn whole_operator_blocks_are_exactly_symmetric() {
        // Noisy normals: no symmetry from the shape itself.
        on_torus(0.3, 5, |st, c, h, rng| {
            let mut rows = galerkin_from_stencil(st, c, &h.aggregations[0]);
            for agg in &h.aggregations[1..] {
                assert!(rows.vals.iter().all(|b| b[1] == b[3] && b[2] == b[6] && b[5] == b[7]));
                let sym = Bsr::from_rows(&rows);
                assert!(matches!(sym.blocks, Blocks::Sym(_)));
                let full =
                    Bsr { blocks: Blocks::Full(rows.vals.iter().map(full_block).collect()), ..sym.clone() };
                let x: Vec<Vec3A> = (0..rows.len()).map(|_| rng.vec3(-1.0, 1.0).as_vec3a()).collect();
                let b: Vec<Vec3A> = (0..rows.len()).map(|_| rng.vec3(-1.0, 1.0).as_vec3a()).collect();
                let (mut ys, mut yf) = (vec![Vec3A::ZERO; rows.len()], vec![Vec3A::ZERO; rows.len()]);
                sym.residual(&x, &b, &mut ys);
                full.residual(&x, &b, &mut yf);
                assert_eq!(ys, yf);
                assert_eq!(full.bytes() - sym.bytes(), 12 * rows.vals.len());
                rows = galerkin_from_rows(&rows, agg);
            }
        });
    }

    /// A cycle built in the arrays of another energy's cycle (the last solve's, in a
    /// refinement loop) is the cycle built anew, to the bit; a cycle of another hierarchy
    /// lends nothing.
    #[test]
    fn a_cycle_built_in_another_ones_arrays_is_the_same() {
        on_torus(0.2, 7, |st, c, h, rng| {
            let other = Coefficients {
                normals: c.normals,
                alpha: c.alpha,
                beta: c.beta,
                fair: c.fair.iter().map(|f| 3.0 * f).collect(),
                face_normals: c.face_normals.iter().map(|m| 0.5 * *m).collect(),
            };
            // The same levels, but another hierarchy's.
            let elsewhere =
                Hierarchy { aggregations: h.aggregations.iter().cloned().collect(), params: h.params };
            let r: Vec<DVec3> = (0..st.len()).map(|_| rng.vec3(-1.0, 1.0)).collect();
            let mut fresh = h.numeric(st, c, &Interrupt::never(), None).unwrap();
            let mut zf = vec![DVec3::ZERO; st.len()];
            fresh.apply(st, &r, &mut zf);
            for old in [
                h.numeric(st, &other, &Interrupt::never(), None),
                elsewhere.numeric(st, &other, &Interrupt::never(), None),
            ] {
                let mut reused = h.numeric(st, c, &Interrupt::never(), Some(Box::new(old.unwrap()))).unwrap();
                assert_eq!(reused.levels.len(), fresh.levels.len());
                for (a, b) in reused.levels.iter().zip(&fresh.levels) {
                    assert_eq!((a.n, &a.smoother, a.matrix.bytes()), (b.n, &b.smoother, b.matrix.bytes()));
                }
                let mut z = vec![DVec3::ZERO; st.len()];
                reused.apply(st, &r, &mut z);
                assert_eq!(z, zf);
            }
        });
    }

    /// The rows found from the changed vertices are those that read one, and a superset
    /// of them where a fairness mask cuts neighbours.
    #[test]
    fn rows_near_the_changes_are_the_rows_that_read_them() {
        let torus = Torus { major: 8.0, minor: 3.0 };
        let s = DigitalSurface::from_volume(&digitize(&torus, 1.0)).unwrap();
        let mut rng = Lcg::new(11);
        let cut: Vec<bool> = (0..s.num_edges()).map(|_| rng.next_f64() < 0.2).collect();
        let mask = crate::FairnessMask::from_cut_edges(&s, &cut).unwrap();
        for m in [None, Some(&mask)] {
            let st = Stencil::new(&s, m).unwrap();
            let params = MultigridParams { coarsest_nodes: 20, ..Default::default() };
            let h = Hierarchy::new(&st, crate::stencil::lattice_corners(&s), &params);
            let agg = &h.aggregations[0];
            for count in [1, 7, 60] {
                let mut changed = vec![false; st.len()];
                for _ in 0..count {
                    changed[rng.below(st.len() as u32) as usize] = true;
                }
                let changes: Vec<u32> = (0..st.len() as u32).filter(|&i| changed[i as usize]).collect();
                let near = rows_near(&st, agg, &changes);
                let read: Vec<usize> = (0..agg.len())
                    .filter(|&a| agg.members(a).iter().any(|&i| face_row_reads(&st, &changed, i as usize)))
                    .collect();
                assert!(!read.is_empty());
                match m {
                    None => assert_eq!(near, read),
                    Some(_) => {
                        assert!(read.iter().all(|a| near.binary_search(a).is_ok()));
                        assert!(near.len() < 2 * read.len(), "{} rows near, {} read", near.len(), read.len());
                    }
                }
            }
        }
    }

    #[test]
    fn updated_face_levels_are_those_built_anew() {
        on_torus(0.0, 3, |st, c, h, rng| {
            let first = random_face(st.len(), rng);
            // The next face: the first one with one vertex, a few (the rows to rewrite found
            // from the changes, or by testing every row), or a third of them changed
            // (updates: a few rows rewritten one by one, or most rows, all rewritten in
            // parallel), then one with most of them changed (built anew).
            let flipped = |step: usize| {
                let mut next = first.clone();
                for i in (0..st.len()).step_by(step) {
                    next[i] = Vec3A::new(1.0, 0.0, 1.0) - next[i] * Vec3A::new(1.0, 0.0, 1.0);
                }
                next
            };
            let (one, two, few, third) =
                (flipped(st.len()), flipped(st.len().div_ceil(2)), flipped(37), flipped(3));
            // One and two changes: below the share where the rows are found from the changes.
            assert!(2 * SPARSE_CHANGES < st.len() && st.len() / 37 * SPARSE_CHANGES > st.len());
            let many = random_face(st.len(), rng);
            let r: Vec<DVec3> = (0..st.len()).map(|_| rng.vec3(-1.0, 1.0)).collect();
            for next in [one, two, few, third, many] {
                let mut updated = h.numeric(st, c, &Interrupt::never(), None).unwrap();
                updated.set_face(st, c, &first, false);
                updated.set_face(st, c, &next, true);
                let mut fresh = h.numeric(st, c, &Interrupt::never(), None).unwrap();
                fresh.set_face(st, c, &next, false);
                let (a, b) = (updated.face_levels.as_ref().unwrap(), fresh.face_levels.as_ref().unwrap());
                assert_eq!(a.rows.len(), b.rows.len());
                for (ra, rb) in a.rows.iter().zip(&b.rows) {
                    assert_eq!(ra.cols, rb.cols);
                    assert_eq!(ra.vals, rb.vals);
                }
                for (la, lb) in a.levels.iter().zip(&b.levels) {
                    assert_eq!(la.smoother, lb.smoother);
                    assert_eq!(la.matrix.bytes(), lb.matrix.bytes());
                }
                let (mut za, mut zb) = (vec![DVec3::ZERO; st.len()], vec![DVec3::ZERO; st.len()]);
                updated.apply_on_face(st, &r, &mut za, Some(&next));
                fresh.apply_on_face(st, &r, &mut zb, Some(&next));
                assert_eq!(za, zb);
            }
        });
    }
}
