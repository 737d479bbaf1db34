//! The solve stage: the energy of a round (its normals and targets, the fairness masks,
//! the plateaus' weights and the weak alignment at creases) minimized by the run's
//! [`Solver`], from the start the round calls for.

use glam::DVec3;
use rayon::prelude::*;
use voxreg_digisurf::{DigitalSurface, SurfelId, VertexData};
use voxreg_normals::{FeatureRamp, Interrupt, NormalField};

use crate::energy::Energy;
use crate::error::RegularizeError;
use crate::info::SolveInfo;
use crate::params::Params;
use crate::progress::Progress;
use crate::request::{SolveRequest, SolveStart};
use crate::solver::Solver;
use crate::weights::{FairnessMask, Weights};

use super::recentre::RecentringInputs;

/// The solve stage of one run: the weights every round shares.
pub(crate) struct Solve<'a> {
    surface: &'a DigitalSurface,
    params: &'a Params,
    /// The fairness masks and the plateaus' multipliers (`None`: uniform).
    weights: Option<Weights>,
}

impl<'a> Solve<'a> {
    /// The stage on `surface` with `params`; `recentring` gives the plateaus' weights
    /// where the run re-centres.
    pub(crate) fn new(
        surface: &'a DigitalSurface,
        params: &'a Params,
        recentring: Option<&RecentringInputs>,
    ) -> Self {
        let texture = params.texture_aware.then(|| FairnessMask::texture_aware(surface));
        let junction = (params.junction_fairness && surface.interfaces().len() > 1)
            .then(|| FairnessMask::junction_curves(surface))
            .filter(|m| m.num_affected_vertices() > 0);
        let fairness = match (texture, junction) {
            (Some(t), Some(j)) => Some(t.and(&j)),
            (t, j) => t.or(j),
        };
        let (alpha, beta) = match recentring.and_then(|r| r.plateaus.as_ref()) {
            Some((a, b)) => (Some(a.clone().into()), Some(b.clone().into())),
            None => (None, None),
        };
        let weights = Weights { fairness, alpha, beta, ..Default::default() };
        let weights = (weights != Weights::default()).then_some(weights);
        Solve { surface, params, weights }
    }

    /// The weights every round shares (without the creases').
    pub(crate) fn weights(&self) -> Option<&Weights> {
        self.weights.as_ref()
    }

    /// Solve round `round` of the energy of `field` and `targets`.
    ///
    /// Refinement rounds start from the last solution `previous` (taken), or the round's
    /// `warm` start where given: the minimizer moves little when the normals and targets
    /// do, so the conjugate gradient needs fewer iterations to the same tolerance (the
    /// bounded solver's rounds start as its first does, so a cold run's results stay
    /// those its measurements describe). The solves before the last only feed the
    /// refinement: the fidelity mode's looser tolerance.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn round(
        &self,
        solver: &mut Solver,
        round: usize,
        field: &NormalField,
        targets: &VertexData<DVec3>,
        previous: &mut VertexData<DVec3>,
        warm: &[Vec<DVec3>],
        progress: &mut dyn FnMut(&Progress),
        interrupt: &Interrupt,
    ) -> Result<(Vec<DVec3>, SolveInfo), RegularizeError> {
        let (surface, params) = (self.surface, self.params);
        let refinement = params.refinement();
        interrupt.check()?;
        let creases = refinement.creases;
        let creased = (refinement.rounds > 0 && creases.alignment < 1.0).then(|| {
            let crease =
                crease_weights(surface, field, creases.angle_deg, creases.alignment, creases.dilation);
            let mut w = self.weights.clone().unwrap_or_default();
            w.beta = Some(match w.beta {
                Some(b) => b.iter().zip(&crease).map(|(b, c)| b * c).collect(),
                None => crease.into(),
            });
            w
        });
        interrupt.check()?;
        let energy = Energy::new(surface, field, targets, params.energy)?;
        let energy = match creased.as_ref().or(self.weights.as_ref()) {
            Some(w) => energy.with_weights(w)?,
            None => energy,
        };
        let last = round == refinement.rounds;
        let factor = match params.mode.fidelity() {
            Some(f) if !last => f.intermediate_tolerance,
            _ => 1.0,
        };
        let chained = round > 0 && !matches!(solver, Solver::Bounded(_));
        let start = match warm.get(round) {
            Some(start) => SolveStart::Given(start),
            None if chained => SolveStart::Owned(std::mem::take(previous).into_vec()),
            None => SolveStart::Input,
        };
        // A next round without a given start builds its own cycle: this one's memory
        // goes to the refinement first (the last solve's is kept for a next run).
        let keep_cycle = last || warm.get(round + 1).is_some();
        let request = SolveRequest {
            start,
            tolerance: Some(params.solver.cg.tolerance * factor),
            quick_start: warm.get(round).is_some(),
            keep_cycle,
            progress: Some(progress),
        };
        let (x, info) = solver.solve(&energy, request)?;
        if !info.relative_gradient().is_finite() || x.iter().any(|p| !p.is_finite()) {
            let h = surface.spacing();
            return Err(RegularizeError::NotFinite(format!(
                "solve {} gave non-finite positions or residuals (alpha {:e}, beta {:e}, gamma {:e}, \
                 voxel spacing {:e} {:e} {:e}): the weights or the spacing are out of range for \
                 double precision",
                round + 1,
                params.energy.alpha,
                params.energy.beta,
                params.energy.gamma,
                h.x,
                h.y,
                h.z
            )));
        }
        Ok((x, info))
    }
}

/// Per-surfel alignment multipliers: `weight` for the quads whose normal in `field` is
/// more than `feature_angle_deg` from the normal of an edge-adjacent quad of the same
/// interface (the quads on either side of a feature) and from their own surfel's axis,
/// and for the quads within `dilation` rings of them (sharing a vertex with a marked
/// quad, ring by ring); `1` for the others. Quads that keep their axis (the faces of an
/// axis-aligned box, whose edges run along the quads' edges) are not marked by the angle
/// test: they lie flat unsqueezed. The test is continuous: a quad within the feature rule's
/// ramp of both angles takes a weight between `weight` and 1 ([`straddling_degree`]), so
/// a small change of the field changes the weights little (a volume solved in chunks
/// must give the whole volume's weights to within as much).
pub(crate) fn crease_weights(
    surface: &DigitalSurface,
    field: &NormalField,
    feature_angle_deg: f64,
    weight: f64,
    dilation: usize,
) -> Vec<f64> {
    let mut degree = straddling_degree(surface, field, feature_angle_deg);
    for _ in 0..dilation {
        let mut touched = vec![0.0f64; surface.num_vertices()];
        for (s, &m) in degree.iter().enumerate().filter(|(_, &m)| m > 0.0) {
            surface.surfels()[s].vertices.iter().for_each(|v| touched[v.index()] = touched[v.index()].max(m));
        }
        degree = surface
            .surfels()
            .par_iter()
            .map(|s| s.vertices.iter().map(|v| touched[v.index()]).fold(0.0, f64::max))
            .collect();
    }
    degree
        .into_iter()
        .map(|m| match m {
            m if m >= 1.0 => weight,
            m if m <= 0.0 => 1.0,
            m => 1.0 - (1.0 - weight) * m,
        })
        .collect()
}

/// How much each quad is marked by [`crease_weights`]'s angle test, from 0 to 1: the
/// smaller of how far its normal is tilted from its surfel's axis and how far the most
/// tilted neighbour of its interface is from it, each through the feature rule's ramp
/// ([`FeatureRamp`], 1 past the angle plus half the ramp).
fn straddling_degree(surface: &DigitalSurface, field: &NormalField, feature_angle_deg: f64) -> Vec<f64> {
    let ramp = FeatureRamp::new(feature_angle_deg);
    let past = |c: f64| 1.0 - ramp.weight(c);
    let normals = field.as_slice();
    (0..surface.num_surfels())
        .into_par_iter()
        .map(|f| {
            let sf = surface.surfels()[f];
            // A quad in the plane of its own surfel lies flat without being squeezed.
            let tilted = past(normals[f].dot(sf.normal()));
            if tilted <= 0.0 {
                return 0.0;
            }
            let iface = sf.interface;
            let mut across = 0.0f64;
            for &e in surface.surfel_edges(SurfelId(f as u32)).iter() {
                for g in surface.edge_surfels(e) {
                    if surface.surfel(*g).interface == iface {
                        across = across.max(past(normals[g.index()].dot(normals[f])));
                    }
                }
            }
            tilted.min(across)
        })
        .collect()
}
