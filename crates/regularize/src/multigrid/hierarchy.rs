//! The voxel hierarchy (aggregation by lattice cell and connected component) and the
//! numeric setup of one energy's cycle on it.

use std::sync::Arc;
use std::time::Instant;

use glam::Vec3A;
use rayon::prelude::*;

use super::coarse::{galerkin_from_rows, galerkin_from_stencil, l1_smoother, Bsr, Coarsest, Level, Work};
use super::cycle::Vcycle;
use super::fine::{fine_majorant, inverse_blocks, FineNumbers};
use super::parts::{Aggregation, Rows};
use crate::error::RegularizeError;
use crate::stencil::{Coefficients, Stencil};
use voxreg_digisurf::union_find_root;
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

/// The voxel hierarchy of a surface: which vertices each coarse node groups.
#[derive(Clone, Debug)]
pub(crate) struct Hierarchy {
    /// Shared with the cycles built from it.
    pub(super) aggregations: Arc<[Aggregation]>,
    pub(super) params: MultigridParams,
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
    for i in 0..n {
        let ki = key(&cells[i]);
        neighbours.each(i, |j| {
            if (j as usize) > i && key(&cells[j as usize]) == ki {
                let (a, b) = (union_find_root(&mut root, i as u32), union_find_root(&mut root, j));
                if a != b {
                    root[a.max(b) as usize] = a.min(b);
                }
            }
        });
    }
    let mut order: Vec<(u64, u32)> =
        (0..n as u32).map(|i| (key(&cells[i as usize]), union_find_root(&mut root, i))).collect();
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
        super::tests::SETUPS.with(|c| c.set(c.get() + 1));
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
                last.smoother = l1_smoother(&finer, self.params.damping, std::mem::take(&mut last.smoother));
                last.matrix = Bsr::from_rows_reusing(finer, std::mem::take(&mut last.matrix));
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
        // Work vectors of the same hierarchy are reused as they are: every cycle writes
        // each entry before reading it. Only the fine level's `x` is made here; the other
        // vectors at their first use: the conjugate gradient lends its own
        // (`Vcycle::apply_in`).
        let n = stencil.len();
        let works = if spare_works.len() == levels.len() + 1 && spare_works[0].x.len() == n {
            spare_works
        } else {
            drop(spare_works);
            std::iter::once(Work { x: vec![Vec3A::ZERO; n], ..Default::default() })
                .chain(levels.iter().map(|_| Work::default()))
                .collect()
        };
        let fine = FineNumbers::new(stencil, coef, spare_fine);
        // The fine majorant (48 bytes a vertex) made only now, not held through the
        // coarse levels' construction (the setup's peak).
        let fine_smoother =
            inverse_blocks(&fine_majorant(stencil, coef), self.params.damping, spare_smoother);
        lap("fine smoother");
        Ok(Vcycle {
            fine,
            fine_smoother,
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
