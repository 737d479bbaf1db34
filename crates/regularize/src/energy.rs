//! The regularization energy: value per term and exact gradient, matrix-free.

use glam::DVec3;
use rayon::prelude::*;
use voxreg_digisurf::{DigitalSurface, VertexId};
use voxreg_normals::NormalField;

use crate::RegularizeError;

/// Weights of the three terms of the energy (eq. 2 of the paper).
#[derive(Copy, Clone, Debug, PartialEq)]
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
    /// Checks that `alpha > 0`, `beta >= 0`, `gamma >= 0`, all finite.
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
        Ok(())
    }
}

/// The value of each term of the energy, weights included.
#[derive(Copy, Clone, Debug, Default, PartialEq)]
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
#[derive(Clone, Copy, Debug)]
pub struct Energy<'a> {
    surface: &'a DigitalSurface,
    normals: &'a [DVec3],
    input: &'a [DVec3],
    params: EnergyParams,
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
        Ok(Energy { surface, normals: normals.as_slice(), input, params })
    }

    /// The weights.
    pub fn params(&self) -> EnergyParams {
        self.params
    }

    /// The input (attachment) positions.
    pub fn input(&self) -> &'a [DVec3] {
        self.input
    }

    /// The surface.
    pub fn surface(&self) -> &'a DigitalSurface {
        self.surface
    }

    /// The prescribed normals.
    pub fn normals(&self) -> &'a [DVec3] {
        self.normals
    }

    fn barycenter_residual(&self, p: &[DVec3], v: usize) -> DVec3 {
        let vid = VertexId(v as u32);
        if self.surface.is_boundary_vertex(vid) {
            return DVec3::ZERO;
        }
        let nb = self.surface.vertex_neighbours(vid);
        let sum: DVec3 = nb.iter().map(|w| p[w.index()]).sum();
        p[v] - sum / nb.len() as f64
    }

    /// The value of each term at positions `p`.
    pub fn terms(&self, p: &[DVec3]) -> EnergyTerms {
        let EnergyParams { alpha, beta, gamma } = self.params;
        let attachment =
            alpha * p.par_iter().zip(self.input).map(|(a, b)| (*a - *b).length_squared()).sum::<f64>();
        let alignment = beta
            * self
                .surface
                .surfels()
                .par_iter()
                .zip(self.normals)
                .map(|(s, n)| {
                    (0..4)
                        .map(|i| {
                            let e = p[s.vertices[i].index()] - p[s.vertices[(i + 1) % 4].index()];
                            e.dot(*n).powi(2)
                        })
                        .sum::<f64>()
                })
                .sum::<f64>();
        let fairness = gamma
            * (0..p.len())
                .into_par_iter()
                .map(|v| self.barycenter_residual(p, v).length_squared())
                .sum::<f64>();
        EnergyTerms { attachment, alignment, fairness, total: attachment + alignment + fairness }
    }

    /// The exact gradient `dE/dp^` at positions `p`, one 3-vector per vertex.
    pub fn gradient(&self, p: &[DVec3]) -> Vec<DVec3> {
        let EnergyParams { alpha, beta, gamma } = self.params;
        let s = self.surface;
        let residual: Vec<DVec3> =
            (0..p.len()).into_par_iter().map(|v| self.barycenter_residual(p, v)).collect();
        (0..p.len())
            .into_par_iter()
            .map(|v| {
                let vid = VertexId(v as u32);
                let mut g = 2.0 * alpha * (p[v] - self.input[v]);
                // Alignment: the two edges of each incident face that touch v.
                for f in s.vertex_surfels(vid) {
                    let sf = s.surfel(*f);
                    let n = self.normals[f.index()];
                    let i = sf.vertices.iter().position(|&w| w == vid).unwrap_or(0);
                    for j in [(i + 1) % 4, (i + 3) % 4] {
                        let d = (p[v] - p[sf.vertices[j].index()]).dot(n);
                        g += 2.0 * beta * d * n;
                    }
                }
                // Fairness: v's own residual, and v's share in its neighbours' barycenters.
                g += 2.0 * gamma * residual[v];
                for w in s.vertex_neighbours(vid) {
                    if !s.is_boundary_vertex(*w) {
                        let deg = s.vertex_neighbours(*w).len() as f64;
                        g -= 2.0 * gamma * residual[w.index()] / deg;
                    }
                }
                g
            })
            .collect()
    }

    /// Euclidean norm of the gradient at `p` (all 3n components).
    pub fn gradient_norm(&self, p: &[DVec3]) -> f64 {
        self.gradient(p).iter().map(|g| g.length_squared()).sum::<f64>().sqrt()
    }
}
