//! The surface's own level in the cycle: its operator's numbers in `f32`, its
//! block-diagonal majorant and smoother.

use std::sync::Arc;

use glam::{DVec3, Vec3A};
use rayon::prelude::*;

use super::parts::{block, refill, scale6, Block, Stored};
use crate::stencil::{Coefficients, PerItem, Stencil, CHUNK};
use crate::vecops::sym_inverse;

/// The damped inverses of the majorant blocks `m` (the fine level's smoother), in the
/// arrays of `old` when it has their number.
pub(super) fn inverse_blocks(m: &[[f64; 6]], damping: f64, old: Vec<Block>) -> Vec<Block> {
    refill(old, m.par_iter().map(|d| block(&scale6(&sym_inverse(d), damping))))
}

/// The fine operator's numbers, for the cycle's fine residuals: the whole cycle runs in
/// `f32` SIMD (it only preconditions: CG's products and residuals stay `f64`). The
/// fairness weights and face normals are the solve's own ([`Coefficients`], shared, read
/// in `f32` where used: the same numbers as an `f32` copy, without its 20 bytes a vertex).
#[derive(Debug)]
pub(super) struct FineNumbers {
    /// `alpha_i` in `f32`: one value for all (`Err`), or one per vertex.
    alpha: Result<Vec<f32>, f32>,
    fair: Arc<[f64]>,
    /// `sqrt(beta_f) n_f` per face, [`Coefficients::face_normals`].
    face_normals: Arc<[DVec3]>,
}

impl Default for FineNumbers {
    fn default() -> Self {
        FineNumbers { alpha: Err(0.0), fair: Arc::new([]), face_normals: Arc::new([]) }
    }
}

impl FineNumbers {
    /// The numbers of `coef`, the per-vertex `alpha` in the array of `old` where its size
    /// matches.
    pub(super) fn new(stencil: &Stencil, coef: &Coefficients<'_>, old: FineNumbers) -> Self {
        let alpha = match coef.alpha {
            PerItem::Uniform(a) => Err(a as f32),
            PerItem::Scaled(..) => Ok(refill(
                old.alpha.unwrap_or_default(),
                (0..stencil.len()).into_par_iter().map(|i| coef.alpha.get(i) as f32),
            )),
        };
        FineNumbers { alpha, fair: Arc::clone(&coef.fair), face_normals: Arc::clone(&coef.face_normals) }
    }

    /// Bytes of the numbers the fine residual reads.
    pub(super) fn bytes(&self) -> usize {
        self.alpha.as_ref().map_or(0, |a| 4 * a.len()) + 8 * self.fair.len() + 24 * self.face_normals.len()
    }

    /// Bytes held by the cycle alone (the shared numbers not counted).
    pub(super) fn own_bytes(&self) -> usize {
        self.alpha.as_ref().map_or(0, |a| 4 * a.len())
    }

    /// Lets go of the shared numbers (before the next solve's are made: the old ones are
    /// not held beside them).
    pub(super) fn release_shared(&mut self) {
        self.fair = Arc::new([]);
        self.face_normals = Arc::new([]);
    }

    #[inline(always)]
    fn alpha(&self, i: usize) -> f32 {
        match &self.alpha {
            Ok(a) => a[i],
            Err(a) => *a,
        }
    }

    /// `y_i = f(i, (b - H x)_i)` in `f32`, in the two passes of the `f64` product (`t`
    /// is scratch), masked by `face` when given; `b(i)` is the right-hand side's entry
    /// `i`. What is done with each residual (a smoothing step, the cycle's output) is
    /// done in the pass that computes it, without writing the residual and reading it
    /// back; `|_, r| Y::put(r)` stores the residual itself.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn residual_map<Y: Send, T: Stored>(
        &self,
        stencil: &Stencil,
        x: &[Vec3A],
        b: &(impl Fn(usize) -> Vec3A + Sync),
        y: &mut [Y],
        t: &mut [T],
        face: Option<&[Vec3A]>,
        f: impl Fn(usize, Vec3A) -> Y + Sync,
    ) {
        t.par_chunks_mut(CHUNK).enumerate().for_each(|(k, out)| {
            let base = k * CHUNK;
            for (o, ti) in out.iter_mut().enumerate() {
                let i = base + o;
                let ci = self.fair[i] as f32;
                *ti = T::put(if ci == 0.0 {
                    Vec3A::ZERO
                } else {
                    let nb = stencil.fair_neighbours(i);
                    let sum: Vec3A = nb.iter().map(|&j| x[j as usize]).sum();
                    ci * (x[i] - sum / nb.len() as f32)
                });
            }
        });
        let t = &*t;
        let slots = stencil.face_slots();
        y.par_chunks_mut(CHUNK).enumerate().for_each(|(k, out)| {
            let base = k * CHUNK;
            for (o, yi) in out.iter_mut().enumerate() {
                let i = base + o;
                let xi = x[i];
                let mut acc = self.alpha(i) * xi;
                let range = stencil.face_range(i);
                for s in &slots[range] {
                    let m = self.face_normals[s.face as usize].as_vec3a();
                    acc += (2.0 * xi - x[s.prev as usize] - x[s.next as usize]).dot(m) * m;
                }
                let nb = stencil.fair_neighbours(i);
                let sum: Vec3A = nb.iter().map(|&j| t[j as usize].get()).sum();
                *yi = f(i, masked(face, i, b(i) - (acc + nb.len() as f32 * t[i].get() - sum)));
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
pub(super) fn fine_majorant(stencil: &Stencil, coef: &Coefficients<'_>) -> Vec<[f64; 6]> {
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
            stencil.add_alignment_block(coef, i, 4.0, &mut d);
            d
        })
        .collect()
}

/// `v * face[i]` coordinate-wise (`v` without a face): the cycle's masks, applied where
/// each value is written rather than in passes of their own.
#[inline(always)]
pub(super) fn masked(face: Option<&[Vec3A]>, i: usize, v: Vec3A) -> Vec3A {
    match face {
        Some(f) => v * f[i],
        None => v,
    }
}
