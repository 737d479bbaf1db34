//! The regularization energy: value per term and exact gradient, matrix-free.

use glam::DVec3;
use rayon::prelude::*;
use voxreg_digisurf::{DigitalSurface, VertexId};
use voxreg_normals::NormalField;

use crate::error::RegularizeError;
use crate::vecops::ordered_sum;
use crate::weights::Weights;

/// Weights of the three terms of the energy (eq. 2 of the paper).
#[derive(Copy, Clone, Debug, PartialEq, serde::Serialize)]
pub struct EnergyParams {
    /// Attachment weight: keeps vertices near their input positions. Must be positive.
    /// Default: `1e-3`.
    pub alpha: f64,
    /// Alignment weight: makes quad edges orthogonal to the normal field. Default: `1`.
    pub beta: f64,
    /// Fairness weight: pulls vertices towards their neighbours' barycenter. Default: `0.1`.
    pub gamma: f64,
}

impl Default for EnergyParams {
    fn default() -> Self {
        EnergyParams { alpha: 1e-3, beta: 1.0, gamma: 0.1 }
    }
}

impl EnergyParams {
    /// Checks that `alpha > 0`, `beta >= 0`, `gamma >= 0`, all finite, and that
    /// `max(beta, gamma) <= MAX_STIFFNESS_RATIO * alpha`.
    pub fn validate(&self) -> Result<(), RegularizeError> {
        let ok = |x: f64| x.is_finite() && x >= 0.0;
        if !(ok(self.alpha) && self.alpha > 0.0) {
            return Err(RegularizeError::InvalidParams(format!(
                "alpha must be positive and finite (it makes the energy strictly convex), got {}",
                self.alpha
            )));
        }
        if !ok(self.beta) || !ok(self.gamma) {
            return Err(RegularizeError::InvalidParams(format!(
                "beta and gamma must be non-negative and finite, got {} and {}",
                self.beta, self.gamma
            )));
        }
        // The system's eigenvalues lie between alpha and about alpha + 4 beta + 64 gamma
        // (the fairness term is a squared Laplacian): past this ratio no factorization or
        // iteration in double precision resolves the smallest ones.
        let stiffest = self.beta.max(self.gamma);
        if stiffest > MAX_STIFFNESS_RATIO * self.alpha {
            return Err(RegularizeError::InvalidParams(format!(
                "alpha {:e} is too small against beta {:e} and gamma {:e}: the system would be \
                 numerically singular (alpha must be at least {:e} times the larger)",
                self.alpha,
                self.beta,
                self.gamma,
                1.0 / MAX_STIFFNESS_RATIO
            )));
        }
        Ok(())
    }
}

/// The largest `max(beta, gamma) / alpha` accepted by [`EnergyParams::validate`].
pub const MAX_STIFFNESS_RATIO: f64 = 1e10;

/// The value of each term of the energy, weights included.
#[derive(Copy, Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct EnergyTerms {
    /// `alpha * sum_i |p_i - p^_i|^2`.
    pub attachment: f64,
    /// `beta * sum_f sum_{e in f} (e . n_f)^2`.
    pub alignment: f64,
    /// `gamma * sum_i |p^_i - b^_i|^2` over non-boundary vertices.
    pub fairness: f64,
    /// The sum of the three terms.
    pub total: f64,
}

/// The energy of the papers (eq. 2 of `multilabel-interfaces-tvcg`):
///
/// ```text
/// E(P^) = alpha * sum_i |p_i - p^_i|^2
///       + beta  * sum_f sum_{edges e of f} (e . n_f)^2
///       + gamma * sum_{i not on a rim} |p^_i - b^_i|^2
/// ```
///
/// where `p_i` are the input positions, `n_f` the prescribed face normals (their
/// orientation does not matter) and `b^_i` the barycenter of all edge-neighbours of
/// vertex `i`, across interfaces too (paper, section 3.5). An edge shared by several
/// faces counts once per face. Evaluation and gradient are matrix-free and parallel;
/// [`crate::Operator`] holds the same quadratic form as a sparse matrix (eq. 28).
///
/// Optional per-element [`Weights`] (attached by [`Energy::with_weights`]) multiply the
/// three weights per vertex or per surfel and may leave some neighbours out of the
/// barycenters (texture-aware fairness).
#[derive(Clone, Copy, Debug)]
pub struct Energy<'a> {
    surface: &'a DigitalSurface,
    normals: &'a [DVec3],
    input: &'a [DVec3],
    params: EnergyParams,
    weights: Option<&'a Weights>,
}

impl<'a> Energy<'a> {
    /// The energy of `surface` with prescribed `normals` (one per surfel), attached to the
    /// `input` positions (one per vertex).
    pub fn new(
        surface: &'a DigitalSurface,
        normals: &'a NormalField,
        input: &'a [DVec3],
        params: EnergyParams,
    ) -> Result<Self, RegularizeError> {
        params.validate()?;
        if normals.len() != surface.num_surfels() {
            return Err(RegularizeError::SizeMismatch(format!(
                "{} normals for {} surfels",
                normals.len(),
                surface.num_surfels()
            )));
        }
        if input.len() != surface.num_vertices() {
            return Err(RegularizeError::SizeMismatch(format!(
                "{} positions for {} vertices",
                input.len(),
                surface.num_vertices()
            )));
        }
        Ok(Energy { surface, normals: normals.as_slice(), input, params, weights: None })
    }

    /// The same energy with per-element `weights` (checked against the surface).
    pub fn with_weights(mut self, weights: &'a Weights) -> Result<Self, RegularizeError> {
        weights.validate(self.surface)?;
        self.weights = Some(weights);
        Ok(self)
    }

    /// The per-element weights, if any.
    pub fn weights(&self) -> Option<&'a Weights> {
        self.weights
    }

    /// The attachment weight of vertex `v`: `alpha` times its multiplier.
    #[inline]
    pub fn alpha_at(&self, v: usize) -> f64 {
        let w = self.weights.and_then(|w| w.alpha.as_ref()).map_or(1.0, |a| a[v]);
        self.params.alpha * w
    }

    /// The alignment weight of surfel `f`: `beta` times its multiplier.
    #[inline]
    pub fn beta_at(&self, f: usize) -> f64 {
        let w = self.weights.and_then(|w| w.beta.as_ref()).map_or(1.0, |b| b[f]);
        self.params.beta * w
    }

    /// The fairness weight of vertex `v`: `gamma` times its multiplier.
    #[inline]
    pub fn gamma_at(&self, v: usize) -> f64 {
        let w = self.weights.and_then(|w| w.gamma.as_ref()).map_or(1.0, |g| g[v]);
        self.params.gamma * w
    }

    /// The smallest attachment weight over the vertices: a lower bound of the operator's
    /// eigenvalues, used by the iterative solvers' error bound.
    pub fn min_alpha(&self) -> f64 {
        self.params.alpha * self.weights.map_or(1.0, Weights::min_alpha)
    }

    /// The neighbours of `v` that enter its barycenter `b^_v`, or `None` when `v` has no
    /// fairness term (a rim vertex, or all its neighbours masked out).
    pub fn fairness_neighbours(&self, v: VertexId) -> Option<Vec<VertexId>> {
        if self.surface.is_boundary_vertex(v) {
            return None;
        }
        let nb: Vec<VertexId> = match self.weights.and_then(|w| w.fairness.as_ref()) {
            Some(mask) => mask.kept_neighbours(self.surface, v).collect(),
            None => self.surface.vertex_neighbours(v).to_vec(),
        };
        (!nb.is_empty()).then_some(nb)
    }

    /// Calls `f` on each neighbour of `v` entering `v`'s barycenter (boundary vertices
    /// included: the mask, not the rim, decides), and returns their number.
    #[inline]
    fn for_kept_neighbours(&self, v: VertexId, mut f: impl FnMut(VertexId)) -> usize {
        let nb = self.surface.vertex_neighbours(v);
        match self.weights.and_then(|w| w.fairness.as_ref()) {
            Some(mask) => {
                let mut count = 0;
                for (slot, &w) in nb.iter().enumerate() {
                    if mask.keeps(v, slot) {
                        f(w);
                        count += 1;
                    }
                }
                count
            }
            None => {
                nb.iter().for_each(|&w| f(w));
                nb.len()
            }
        }
    }

    /// Number of neighbours in `v`'s barycenter, 0 when `v` has no fairness term.
    #[inline]
    fn fairness_degree(&self, v: VertexId) -> usize {
        if self.surface.is_boundary_vertex(v) {
            return 0;
        }
        self.for_kept_neighbours(v, |_| ())
    }

    /// The weights.
    pub fn params(&self) -> EnergyParams {
        self.params
    }

    /// The input (attachment) positions.
    pub fn input(&self) -> &'a [DVec3] {
        self.input
    }

    /// Fails unless `start` holds one position per vertex (a solver's start).
    pub(crate) fn check_start(&self, start: &[DVec3]) -> Result<(), RegularizeError> {
        if start.len() == self.input.len() {
            return Ok(());
        }
        Err(RegularizeError::SizeMismatch(format!(
            "{} start positions for {} vertices",
            start.len(),
            self.input.len()
        )))
    }

    /// The surface.
    pub fn surface(&self) -> &'a DigitalSurface {
        self.surface
    }

    /// The prescribed normals.
    pub fn normals(&self) -> &'a [DVec3] {
        self.normals
    }

    /// `p_v - b^_v`, zero when `v` has no fairness term.
    fn barycenter_residual(&self, p: &[DVec3], v: usize) -> DVec3 {
        let vid = VertexId(v as u32);
        if self.surface.is_boundary_vertex(vid) {
            return DVec3::ZERO;
        }
        let mut sum = DVec3::ZERO;
        let count = self.for_kept_neighbours(vid, |w| sum += p[w.index()]);
        if count == 0 {
            return DVec3::ZERO;
        }
        p[v] - sum / count as f64
    }

    /// The value of each term at positions `p`.
    pub fn terms(&self, p: &[DVec3]) -> EnergyTerms {
        let attachment = ordered_sum(p.len(), |i| self.alpha_at(i) * (p[i] - self.input[i]).length_squared());
        let surfels = self.surface.surfels();
        let alignment = ordered_sum(surfels.len(), |f| {
            let s = &surfels[f];
            let n = self.normals[f];
            self.beta_at(f)
                * (0..4)
                    .map(|i| {
                        let e = p[s.vertices[i].index()] - p[s.vertices[(i + 1) % 4].index()];
                        e.dot(n).powi(2)
                    })
                    .sum::<f64>()
        });
        let fairness =
            ordered_sum(p.len(), |v| self.gamma_at(v) * self.barycenter_residual(p, v).length_squared());
        EnergyTerms { attachment, alignment, fairness, total: attachment + alignment + fairness }
    }

    /// The exact gradient `dE/dp^` at positions `p`, one 3-vector per vertex.
    pub fn gradient(&self, p: &[DVec3]) -> Vec<DVec3> {
        let s = self.surface;
        // gamma_w (p_w - b^_w) / |S_w|: what w's fairness term sends to each of its neighbours.
        let scaled: Vec<(DVec3, DVec3)> = (0..p.len())
            .into_par_iter()
            .map(|v| {
                let r = self.gamma_at(v) * self.barycenter_residual(p, v);
                let deg = self.fairness_degree(VertexId(v as u32));
                (r, if deg == 0 { DVec3::ZERO } else { r / deg as f64 })
            })
            .collect();
        (0..p.len())
            .into_par_iter()
            .map(|v| {
                let vid = VertexId(v as u32);
                let mut g = 2.0 * self.alpha_at(v) * (p[v] - self.input[v]);
                // Alignment: the two edges of each incident face that touch v.
                for f in s.vertex_surfels(vid) {
                    let sf = s.surfel(*f);
                    let n = self.normals[f.index()];
                    let beta = self.beta_at(f.index());
                    let i = sf.vertices.iter().position(|&w| w == vid).unwrap_or(0);
                    for j in [(i + 1) % 4, (i + 3) % 4] {
                        let d = (p[v] - p[sf.vertices[j].index()]).dot(n);
                        g += 2.0 * beta * d * n;
                    }
                }
                // Fairness: v's own residual, and v's share in its neighbours' barycenters
                // (the mask is symmetric: v is in w's barycenter iff w is in v's).
                g += 2.0 * scaled[v].0;
                self.for_kept_neighbours(vid, |w| g -= 2.0 * scaled[w.index()].1);
                g
            })
            .collect()
    }

    /// Euclidean norm of the gradient at `p` (all 3n components).
    pub fn gradient_norm(&self, p: &[DVec3]) -> f64 {
        self.gradient(p).iter().map(|g| g.length_squared()).sum::<f64>().sqrt()
    }
}
