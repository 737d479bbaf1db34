//! Per-element weights of the energy, and texture-aware fairness (paper, sec. 4.5).

use std::sync::Arc;

use rayon::prelude::*;
use voxreg_digisurf::{DigitalSurface, EdgeId, SurfelData, VertexData, VertexId};

use crate::error::RegularizeError;

/// Optional per-element weights, each multiplying the global weight of
/// [`EnergyParams`](crate::EnergyParams):
///
/// ```text
/// E = sum_i alpha w_alpha[i] |p_i - p^_i|^2
///   + sum_f beta w_beta[f] sum_{e in f} (e . n_f)^2
///   + sum_i gamma w_gamma[i] |p^_i - b^_i|^2
/// ```
///
/// and an optional [`FairnessMask`] choosing which neighbours enter each barycenter
/// `b^_i`. Every solver ([`crate::DirectSolver`], [`crate::CgSolver`],
/// [`crate::BoundedSolver`]) and [`crate::Energy`] use them consistently. Attach them with
/// [`crate::Energy::with_weights`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Weights {
    /// Per vertex: multiplies `alpha`. Positive and finite. Default: `None` (all 1).
    pub alpha: Option<VertexData<f64>>,
    /// Per surfel: multiplies `beta`. Non-negative and finite. Default: `None` (all 1).
    pub beta: Option<SurfelData<f64>>,
    /// Per vertex: multiplies `gamma`. Non-negative and finite. Default: `None` (all 1).
    pub gamma: Option<VertexData<f64>>,
    /// Which edge-neighbours each barycenter uses. Default: `None` (all of them).
    pub fairness: Option<FairnessMask>,
}

impl Weights {
    /// Checks lengths against `surface` and ranges (see the fields).
    pub fn validate(&self, surface: &DigitalSurface) -> Result<(), RegularizeError> {
        let check = |name: &str, w: Option<&[f64]>, len: usize, positive: bool| {
            let Some(w) = w else { return Ok(()) };
            if w.len() != len {
                return Err(RegularizeError::SizeMismatch(format!(
                    "{} {name} weights for {len} elements",
                    w.len()
                )));
            }
            let bad = w.iter().position(|&x| !x.is_finite() || x < 0.0 || (positive && x == 0.0));
            if let Some(i) = bad {
                let what = if positive { "positive" } else { "non-negative" };
                return Err(RegularizeError::InvalidParams(format!(
                    "{name} weight {i} is {}, must be {what} and finite",
                    w[i]
                )));
            }
            Ok(())
        };
        check("alpha", self.alpha.as_deref(), surface.num_vertices(), true)?;
        check("beta", self.beta.as_deref(), surface.num_surfels(), false)?;
        check("gamma", self.gamma.as_deref(), surface.num_vertices(), false)?;
        if let Some(m) = &self.fairness {
            if m.offsets.len() != surface.num_vertices() + 1
                || *m.offsets.last().unwrap_or(&0) as usize != m.keep.len()
            {
                return Err(RegularizeError::SizeMismatch("the fairness mask is not of this surface".into()));
            }
        }
        Ok(())
    }

    /// The smallest attachment multiplier (1 without per-vertex alphas).
    pub fn min_alpha(&self) -> f64 {
        match &self.alpha {
            Some(a) if !a.is_empty() => a.iter().copied().fold(f64::INFINITY, f64::min),
            _ => 1.0,
        }
    }
}

/// Which edge-neighbours enter each vertex's barycenter in the fairness term.
///
/// Built from a set of *cut* edges: the two ends of a cut edge leave each other out of
/// their barycenters (so the mask is symmetric, and the energy stays convex). A vertex
/// whose edges are all cut has no fairness term. Stored per vertex, aligned with
/// [`DigitalSurface::vertex_neighbours`].
///
/// Cloning one is cheap: the per-round weights of a run share it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FairnessMask {
    /// Where each vertex's flags start in `keep` (`u32`: a surface's neighbour slots, two
    /// per edge, number below `2^32`).
    offsets: Arc<[u32]>,
    keep: Arc<[bool]>,
}

impl FairnessMask {
    /// The mask that drops, from both ends' barycenters, every edge `e` with `cut[e]`.
    pub fn from_cut_edges(surface: &DigitalSurface, cut: &[bool]) -> Result<Self, RegularizeError> {
        if cut.len() != surface.num_edges() {
            return Err(RegularizeError::SizeMismatch(format!(
                "{} cut flags for {} edges",
                cut.len(),
                surface.num_edges()
            )));
        }
        let n = surface.num_vertices();
        let mut offsets = Vec::with_capacity(n + 1);
        offsets.push(0u32);
        for v in 0..n {
            let end = offsets[v] as usize + surface.vertex_neighbours(VertexId(v as u32)).len();
            offsets.push(u32::try_from(end).map_err(|_| {
                RegularizeError::OutOfMemory(format!("{end} neighbour slots, more than 2^32"))
            })?);
        }
        let mut keep = vec![true; offsets[n] as usize];
        for (e, edge) in surface.edges().iter().enumerate() {
            if !cut[e] {
                continue;
            }
            let [a, b] = edge.vertices;
            for (v, w) in [(a, b), (b, a)] {
                if let Ok(slot) = surface.vertex_neighbours(v).binary_search(&w) {
                    keep[offsets[v.index()] as usize + slot] = false;
                }
            }
        }
        Ok(FairnessMask { offsets: offsets.into(), keep: keep.into() })
    }

    /// Texture-aware fairness (paper, sec. 4.5 and Fig. 14): cuts the colour
    /// discontinuities of [`colour_discontinuities`], so that quad edges align with
    /// colour boundaries instead of zigzagging across them.
    pub fn texture_aware(surface: &DigitalSurface) -> Self {
        Self::from_cut_edges(surface, &colour_discontinuities(surface)).expect("one flag per edge")
    }

    /// Fairness along junction curves: cuts every edge between a junction vertex (one
    /// whose quads span three regions or more, [`junction_vertices`]) and a vertex that
    /// is not, so that a junction vertex's barycenter is that of its neighbours along the
    /// junction (a one-dimensional fairness along the curve), and its surfaces' vertices
    /// next to it are faired among themselves.
    ///
    /// Why: the barycenter of all the neighbours of a vertex where three interfaces meet
    /// lies inside the angle they make (on the split ball, a third of a voxel from the
    /// circle towards the cut disc), and pulls the junction off the curve.
    pub fn junction_curves(surface: &DigitalSurface) -> Self {
        let junction = junction_vertices(surface);
        let cut: Vec<bool> = surface
            .edges()
            .par_iter()
            .map(|e| junction[e.vertices[0].index()] != junction[e.vertices[1].index()])
            .collect();
        Self::from_cut_edges(surface, &cut).expect("one flag per edge")
    }

    /// The union of two masks' cuts: a neighbour is kept when both keep it.
    pub fn and(mut self, other: &FairnessMask) -> Self {
        self.keep = self.keep.iter().zip(other.keep.iter()).map(|(k, o)| *k && *o).collect();
        self
    }

    /// Whether the `slot`-th neighbour of `v` (in [`DigitalSurface::vertex_neighbours`]
    /// order) enters `v`'s barycenter.
    #[inline]
    pub fn keeps(&self, v: VertexId, slot: usize) -> bool {
        self.keep[self.offsets[v.index()] as usize + slot]
    }

    /// Number of vertices whose barycenter loses at least one neighbour.
    pub fn num_affected_vertices(&self) -> usize {
        self.offsets
            .windows(2)
            .filter(|w| self.keep[w[0] as usize..w[1] as usize].iter().any(|&k| !k))
            .count()
    }

    /// The neighbours of `v` that enter its barycenter.
    pub fn kept_neighbours<'s>(
        &'s self,
        surface: &'s DigitalSurface,
        v: VertexId,
    ) -> impl Iterator<Item = VertexId> + 's {
        let keep = &self.keep[self.offsets[v.index()] as usize..self.offsets[v.index() + 1] as usize];
        surface.vertex_neighbours(v).iter().zip(keep).filter(|(_, &k)| k).map(|(w, _)| *w)
    }
}

/// Per vertex, whether its quads span three regions or more (a vertex of a junction curve
/// or point).
pub fn junction_vertices(surface: &DigitalSurface) -> Vec<bool> {
    (0..surface.num_vertices())
        .into_par_iter()
        .map(|v| {
            // The first two distinct regions met; a third answers.
            let mut seen: [Option<_>; 2] = [None; 2];
            for s in surface.vertex_surfels(VertexId(v as u32)) {
                for r in surface.surfel(*s).regions {
                    match seen {
                        [None, _] => seen[0] = Some(r),
                        [Some(a), None] if a != r => seen[1] = Some(r),
                        [Some(a), Some(b)] if a != r && b != r => return true,
                        _ => {}
                    }
                }
            }
            false
        })
        .collect()
}

/// Per edge, whether it separates colours: its incident surfels do not all have the same
/// label on their inner side (`Surfel::labels[0]`, the solid's side of a solid/background
/// surfel, since the background region always comes last). For a MagicaVoxel model read
/// as one solid, these are the boundaries between palette colours.
pub fn colour_discontinuities(surface: &DigitalSurface) -> Vec<bool> {
    (0..surface.num_edges())
        .map(|e| {
            let surfels = surface.edge_surfels(EdgeId(e as u32));
            let first = surface.surfel(surfels[0]).labels[0];
            surfels.iter().any(|&s| surface.surfel(s).labels[0] != first)
        })
        .collect()
}
