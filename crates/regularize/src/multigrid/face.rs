//! The face's operator `P^T D H D P` (the coordinates an active-set round leaves free):
//! its coarse rows, smoothers and levels, built anew or updated where the face changed.

use glam::{DVec3, Vec3A};
use rayon::prelude::*;

use super::coarse::{full_block, galerkin_from_rows, galerkin_row, Blocks, Bsr, Coarsest, Level};
use super::cycle::{FaceLevels, Vcycle};
use super::fine::fine_majorant;
use super::parts::{block, scale6, Accumulator, Aggregation, Block, Rows, FACE};
use crate::stencil::{Coefficients, Stencil};
use crate::vecops::sym_inverse;

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
///
/// [`galerkin_from_stencil`]: super::coarse::galerkin_from_stencil
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
pub(super) fn face_row_reads(stencil: &Stencil, changed: &[bool], i: usize) -> bool {
    changed[i]
        || stencil.faces(i).iter().any(|s| changed[s.prev as usize] || changed[s.next as usize])
        || stencil.fair_neighbours(i).iter().any(|&k| {
            changed[k as usize] || stencil.fair_neighbours(k as usize).iter().any(|&j| changed[j as usize])
        })
}

/// Below one changed vertex in this many, a face update finds the rows to recompute from
/// the changed vertices ([`rows_near`]) rather than by testing every row
/// ([`face_row_reads`]): a late active-set round changes a few hundred holds of millions.
pub(super) const SPARSE_CHANGES: usize = 256;

/// The aggregates holding a vertex within two edges of one of `changes` (ascending, each
/// once): every row whose [`face_row`] reads a changed vertex, since a row reads its
/// members, their faces' vertices (edge neighbours) and their fairness 2-rings (fairness
/// neighbours are edge neighbours, some cut by a mask), and edges go both ways. Where a
/// mask cuts fairness neighbours it may hold a few rows more, which recompute to the same
/// numbers.
pub(super) fn rows_near(stencil: &Stencil, agg: &Aggregation, changes: &[u32]) -> Vec<usize> {
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
///
/// [`l1_smoother`]: super::coarse::l1_smoother
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

impl Vcycle {
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
}
