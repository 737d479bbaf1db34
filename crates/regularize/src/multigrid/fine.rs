//! The surface's own level in the cycle: its operator's numbers in `f32`, its
//! block-diagonal majorant and smoother.

use glam::Vec3A;
use rayon::prelude::*;

use super::parts::{block, refill, scale6, Block};
use crate::stencil::{Coefficients, Stencil, CHUNK};
use crate::vecops::sym_inverse;

/// The damped inverses of the majorant blocks `m` (the fine level's smoother), in the
/// arrays of `old` when it has their number.
pub(super) fn inverse_blocks(m: &[[f64; 6]], damping: f64, old: Vec<Block>) -> Vec<Block> {
    refill(old, m.par_iter().map(|d| block(&scale6(&sym_inverse(d), damping))))
}

/// The fine operator's numbers in `f32`, for the cycle's fine residuals: the whole cycle
/// runs in `f32` SIMD (it only preconditions: CG's products and residuals stay `f64`).
#[derive(Debug, Default)]
pub(super) struct FineNumbers {
    alpha: Vec<f32>,
    fair: Vec<f32>,
    /// `sqrt(beta_f) n_f` per face, as [`Coefficients::face_normals`].
    face_normals: Vec<Vec3A>,
}

impl FineNumbers {
    /// The numbers of `coef`, in the arrays of `old` where their sizes match.
    pub(super) fn new(stencil: &Stencil, coef: &Coefficients<'_>, old: FineNumbers) -> Self {
        let FineNumbers { alpha, fair, face_normals } = old;
        FineNumbers {
            alpha: refill(alpha, (0..stencil.len()).into_par_iter().map(|i| coef.alpha.get(i) as f32)),
            fair: refill(fair, coef.fair.par_iter().map(|&c| c as f32)),
            face_normals: refill(face_normals, coef.face_normals.par_iter().map(|m| m.as_vec3a())),
        }
    }

    pub(super) fn bytes(&self) -> usize {
        4 * (self.alpha.len() + self.fair.len()) + 16 * self.face_normals.len()
    }

    /// `y = b - H x` in `f32`, in the two passes of the `f64` product (`t` is scratch),
    /// masked by `face` when given; `b(i)` is the right-hand side's entry `i`.
    pub(super) fn residual(
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
    pub(super) fn residual_map<T: Send>(
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
