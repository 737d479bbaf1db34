//! The full regularization pipeline: solve, then refine the normals from the regularized
//! geometry and re-centre the attachment targets, and solve again.

use std::collections::VecDeque;

use glam::DVec3;
use rayon::prelude::*;
use voxreg_digisurf::{DigitalSurface, SurfelId, VertexId};
use voxreg_normals::NormalField;

use crate::{Energy, EnergyParams, Progress, RegularizeError, SolveInfo, Solver, SolverParams, Weights};

/// Parameters of [`run_pipeline`].
///
/// The defaults were chosen by measurement against analytic shapes (sphere, torus,
/// goursat; see the README's accuracy table): a stronger attachment than the papers'
/// (`alpha = 1e-2` instead of `1e-3`), three refinement rounds and re-centring.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct PipelineParams {
    /// The energy's weights. Default: `alpha = 1e-2, beta = 1, gamma = 0.1`
    /// ([`PipelineParams::ENERGY`]).
    pub energy: EnergyParams,
    /// Refinement rounds: after each solve, the normal field is re-estimated from the
    /// regularized quads ([`refined_normals`]) and the energy solved again. Default: `3`.
    pub refine: usize,
    /// Radius, in voxels, of the neighbourhood whose regularized quad normals are
    /// averaged into a refined normal. Default: `3`.
    pub refine_radius: f64,
    /// Feature rule of the refinement: a quad only enters the average if its regularized
    /// normal is within this angle (degrees) of the normal being refined, so that the two
    /// sides of a sharp edge never mix. Default: `30`.
    pub feature_angle_deg: f64,
    /// Size preservation (re-centring): before each refinement solve, the attachment
    /// targets move by minus the smoothed displacement of the last solve, measured where
    /// the digital surface is informative ([`informative_vertices`]: outside digital
    /// plateaus) and smoothed by [`smoothed_displacements`], which cancels the inward
    /// drift of thin curved shapes.
    /// Ignored when the solver clamps (its boxes are centred on the targets, which must
    /// stay at the input for Proposition 2 to hold). Default: `true`.
    pub preserve_size: bool,
    /// Standard deviation, in voxels, of the smoothing of displacements used by the
    /// re-centring. Default: `3`.
    pub recentre_sigma: f64,
    /// Alignment weight (a multiplier of `beta`) of the quads near a feature: those whose
    /// normal is more than `crease_angle_deg` from an edge-neighbour's on the same
    /// interface and from their own axis, and the quads within `crease_dilation` vertex
    /// rings of them ([`crease_weights`]). The alignment of a quad straddling a crease pins
    /// its vertices to the planes of both sides at once, i.e. to the crease line, which
    /// collapses the quads whose four vertices all touch the other side into slivers; a
    /// weak alignment lets them fold across the crease instead. Applied in every solve
    /// when the pipeline refines (`refine > 0`; the first solve's features come from the
    /// input normal field, the others' from the refined one); a single solve
    /// (`refine = 0`, the default for `.vox` input) keeps the papers' uniform weight.
    /// `1` keeps the uniform weight everywhere. Default: `0.015`.
    pub crease_alignment: f64,
    /// Feature rule of [`crease_weights`]: the angle (degrees) between the normals of two
    /// edge-adjacent quads, and between a quad's normal and its axis, above which a quad
    /// straddles a feature. Default: `20`.
    pub crease_angle_deg: f64,
    /// How many rings of quads (sharing a vertex) around the quads straddling a feature
    /// also get the weak alignment: the quads next to a crease line lean on it too.
    /// Default: `1`.
    pub crease_dilation: usize,
    /// The solver. Default: [`SolverParams::default`].
    pub solver: SolverParams,
}

impl PipelineParams {
    /// The energy weights of the pipeline's default: `alpha = 1e-2, beta = 1, gamma = 0.1`.
    pub const ENERGY: EnergyParams = EnergyParams { alpha: 1e-2, beta: 1.0, gamma: 0.1 };

    /// The papers' behaviour: their weights (`alpha = 1e-3`), one solve, no refinement, no
    /// re-centring.
    pub fn papers() -> Self {
        PipelineParams {
            energy: EnergyParams::default(),
            refine: 0,
            preserve_size: false,
            crease_alignment: 1.0,
            ..Default::default()
        }
    }

    /// Checks every field's range.
    pub fn validate(&self) -> Result<(), RegularizeError> {
        self.energy.validate()?;
        let positive = |x: f64| x.is_finite() && x > 0.0;
        if !positive(self.refine_radius) || !positive(self.recentre_sigma) {
            return Err(RegularizeError::InvalidParams(format!(
                "the refinement radius and the re-centring sigma must be positive and finite, got {} and {}",
                self.refine_radius, self.recentre_sigma
            )));
        }
        if !(self.crease_alignment >= 0.0 && self.crease_alignment <= 1.0) {
            return Err(RegularizeError::InvalidParams(format!(
                "the crease alignment weight must be in [0, 1], got {}",
                self.crease_alignment
            )));
        }
        for (what, a) in [("feature", self.feature_angle_deg), ("crease", self.crease_angle_deg)] {
            if !(a > 0.0 && a <= 180.0) {
                return Err(RegularizeError::InvalidParams(format!(
                    "the {what} angle must be in (0, 180] degrees, got {a}"
                )));
            }
        }
        Ok(())
    }
}

impl Default for PipelineParams {
    fn default() -> Self {
        PipelineParams {
            energy: Self::ENERGY,
            refine: 3,
            refine_radius: 3.0,
            feature_angle_deg: 30.0,
            preserve_size: true,
            recentre_sigma: 3.0,
            crease_alignment: 0.015,
            crease_angle_deg: 20.0,
            crease_dilation: 1,
            solver: SolverParams::default(),
        }
    }
}

/// What [`run_pipeline`] returns.
#[derive(Clone, Debug)]
pub struct PipelineOutput {
    /// The regularized positions, one per vertex.
    pub positions: Vec<DVec3>,
    /// The normal field of the last solve (the input field when `refine = 0`).
    pub normals: NormalField,
    /// The attachment targets of the last solve (the input positions unless re-centred).
    pub targets: Vec<DVec3>,
    /// The solver's report for each solve, in order (`1 + refine` of them).
    pub solves: Vec<SolveInfo>,
    /// Seconds spent refining normals and re-centring targets (all rounds).
    pub refine_seconds: f64,
}

/// Regularizes `surface` starting from the normal field `normals`: one solve of the
/// energy, then `params.refine` rounds of (refine normals, re-centre targets, solve),
/// reusing one [`Solver`] (its analysis is done once). `weights` apply to every solve;
/// `progress` receives the iterative solvers' iterations.
///
/// The last round's energy is the one to report (`Energy::new(surface, &out.normals,
/// &out.targets, params.energy)`).
pub fn run_pipeline(
    surface: &DigitalSurface,
    normals: &NormalField,
    weights: Option<&Weights>,
    params: &PipelineParams,
    progress: &mut dyn FnMut(&Progress),
) -> Result<PipelineOutput, RegularizeError> {
    params.validate()?;
    let mut solver = Solver::new(surface, &params.solver)?;
    let input = surface.positions();
    let mut targets = input.clone();
    let mut field = normals.clone();
    let mut solves = Vec::with_capacity(params.refine + 1);
    let mut refine_seconds = 0.0;
    let clamps = matches!(&solver, Solver::Gd(s) if s.params().clamp.is_some());
    let mut positions = Vec::new();
    let trusted = if params.preserve_size && !clamps && params.refine > 0 {
        informative_vertices(surface)
    } else {
        Vec::new()
    };
    for round in 0..=params.refine {
        if round > 0 {
            let t = std::time::Instant::now();
            field =
                refined_normals(surface, &positions, &field, params.refine_radius, params.feature_angle_deg);
            if params.preserve_size && !clamps {
                let drift = trusted_drift(
                    surface,
                    &surfel_drift(surface, &positions, &input),
                    &trusted,
                    params.recentre_sigma,
                );
                targets.iter_mut().zip(&drift).for_each(|(t, d)| *t -= *d);
            }
            refine_seconds += t.elapsed().as_secs_f64();
        }
        let creased = (params.refine > 0 && params.crease_alignment < 1.0).then(|| {
            let crease = crease_weights(
                surface,
                &field,
                params.crease_angle_deg,
                params.crease_alignment,
                params.crease_dilation,
            );
            let mut w = weights.cloned().unwrap_or_default();
            w.beta = Some(match w.beta {
                Some(b) => b.iter().zip(&crease).map(|(b, c)| b * c).collect(),
                None => crease,
            });
            w
        });
        let energy = Energy::new(surface, &field, &targets, params.energy)?;
        let energy = match creased.as_ref().or(weights) {
            Some(w) => energy.with_weights(w)?,
            None => energy,
        };
        let (x, info) = solver.solve_with(&energy, progress)?;
        tracing::debug!(round, solver = info.solver, iterations = info.iterations, "pipeline solve");
        positions = x;
        solves.push(info);
    }
    Ok(PipelineOutput { positions, normals: field, targets, solves, refine_seconds })
}

/// The vector area of surfel `s` at `positions` (half the cross product of its
/// diagonals), pointing like its oriented normal.
fn area_vector(surface: &DigitalSurface, positions: &[DVec3], s: usize) -> DVec3 {
    let [a, b, c, d] = surface.surfels()[s].vertices.map(|v| positions[v.index()]);
    0.5 * (c - a).cross(d - b)
}

/// Normals re-estimated from the regularized geometry: for each surfel `f`, the
/// normalized, tent-weighted average of the area vectors of the regularized quads `g`
///
/// ```text
/// n'_f = normalize( sum_g (1 - |c_g - c_f| / r) a_g ),
/// ```
///
/// over the quads `g` of `f`'s interface (same region pair) reached from `f` through
/// edge-adjacent quads whose centres `c_g` stay within `radius` voxels of `c_f` and whose
/// regularized normal is within `feature_angle_deg` of `field`'s normal at `f` (the
/// feature rule: the two sides of a sharp edge never mix). Orientation follows `field`.
/// A quad with no such neighbour keeps its normal from `field`.
pub fn refined_normals(
    surface: &DigitalSurface,
    positions: &[DVec3],
    field: &NormalField,
    radius: f64,
    feature_angle_deg: f64,
) -> NormalField {
    let n = surface.num_surfels();
    let h = surface.spacing().max_element();
    let r = radius * h;
    let cos_max = feature_angle_deg.to_radians().cos();
    let areas: Vec<DVec3> = (0..n).into_par_iter().map(|s| area_vector(surface, positions, s)).collect();
    let centres: Vec<DVec3> = surface
        .surfels()
        .par_iter()
        .map(|s| s.vertices.iter().map(|v| positions[v.index()]).sum::<DVec3>() / 4.0)
        .collect();
    let normals = field.as_slice();
    let out: Vec<DVec3> = (0..n)
        .into_par_iter()
        .map_init(
            || (vec![false; n], Vec::new(), VecDeque::new()),
            |(seen, touched, queue), f| {
                let nf = normals[f];
                let iface = surface.surfels()[f].interface;
                let mut sum = DVec3::ZERO;
                queue.push_back(f);
                seen[f] = true;
                touched.push(f);
                while let Some(g) = queue.pop_front() {
                    let d = centres[g].distance(centres[f]);
                    let a = areas[g];
                    let len = a.length();
                    let dot = if len > 0.0 { a.dot(nf) / len } else { 0.0 };
                    if dot.abs() < cos_max {
                        continue; // across a feature: neither counted nor crossed
                    }
                    sum += (1.0 - d / r) * a * dot.signum();
                    for e in surface.surfel_edges(SurfelId(g as u32)) {
                        for &k in surface.edge_surfels(e) {
                            let k = k.index();
                            if !seen[k]
                                && surface.surfels()[k].interface == iface
                                && centres[k].distance(centres[f]) < r
                            {
                                seen[k] = true;
                                touched.push(k);
                                queue.push_back(k);
                            }
                        }
                    }
                }
                touched.drain(..).for_each(|k| seen[k] = false);
                let m = sum.normalize_or_zero();
                if m == DVec3::ZERO {
                    nf
                } else {
                    m
                }
            },
        )
        .collect();
    NormalField::new(out)
}

/// Per-surfel alignment multipliers: `weight` for the quads whose normal in `field` is
/// more than `feature_angle_deg` from the normal of an edge-adjacent quad of the same
/// interface (the quads on either side of a feature) and from their own surfel's axis,
/// and for the quads within `dilation` rings of them (sharing a vertex with a marked
/// quad, ring by ring); `1` for the others. Quads that keep their axis (the faces of an
/// axis-aligned box, whose edges run along the quads' edges) are not marked by the angle
/// test: they lie flat unsqueezed.
pub fn crease_weights(
    surface: &DigitalSurface,
    field: &NormalField,
    feature_angle_deg: f64,
    weight: f64,
    dilation: usize,
) -> Vec<f64> {
    let mut marked = straddling_quads(surface, field, feature_angle_deg);
    for _ in 0..dilation {
        let mut touched = vec![false; surface.num_vertices()];
        for (s, _) in marked.iter().enumerate().filter(|(_, &m)| m) {
            surface.surfels()[s].vertices.iter().for_each(|v| touched[v.index()] = true);
        }
        marked =
            surface.surfels().par_iter().map(|s| s.vertices.iter().any(|v| touched[v.index()])).collect();
    }
    marked.into_iter().map(|m| if m { weight } else { 1.0 }).collect()
}

/// The quads of [`crease_weights`]'s angle test.
fn straddling_quads(surface: &DigitalSurface, field: &NormalField, feature_angle_deg: f64) -> Vec<bool> {
    let cos_max = feature_angle_deg.to_radians().cos();
    let normals = field.as_slice();
    (0..surface.num_surfels())
        .into_par_iter()
        .map(|f| {
            let sf = surface.surfels()[f];
            // A quad in the plane of its own surfel lies flat without being squeezed.
            let tilted = normals[f].dot(sf.normal()) < cos_max;
            let iface = sf.interface;
            tilted
                && surface.surfel_edges(SurfelId(f as u32)).iter().any(|&e| {
                    surface.edge_surfels(e).iter().any(|g| {
                        surface.surfel(*g).interface == iface && normals[g.index()].dot(normals[f]) < cos_max
                    })
                })
        })
        .collect()
}

/// Low-pass filter of per-vertex displacements: lazy diffusion over the vertex graph,
/// `u_v <- (u_v + mean of u over v's neighbours) / 2`, repeated `k = 4 sigma^2` times,
/// which is a Gaussian of standard deviation `sigma` voxels on a flat grid (each step
/// adds a variance of 1/4 voxel^2 per axis). Diffusion follows the surface, so the
/// two sheets of a thin shape never mix; at junctions it runs across interfaces.
pub fn smoothed_displacements(surface: &DigitalSurface, displacements: &[DVec3], sigma: f64) -> Vec<DVec3> {
    let steps = (4.0 * sigma * sigma).round() as usize;
    let mut u = displacements.to_vec();
    let mut next = vec![DVec3::ZERO; u.len()];
    for _ in 0..steps {
        next.par_iter_mut().enumerate().for_each(|(v, out)| {
            let nb = surface.vertex_neighbours(VertexId(v as u32));
            let mean = if nb.is_empty() {
                u[v]
            } else {
                nb.iter().map(|w| u[w.index()]).sum::<DVec3>() / nb.len() as f64
            };
            *out = 0.5 * (u[v] + mean);
        });
        std::mem::swap(&mut u, &mut next);
    }
    u
}

/// Whether each vertex's staircase position is informative about where the true surface
/// lies: `false` inside a *digital plateau*, i.e. when the vertex's four surfels all have
/// the same oriented normal (the digital surface is exactly flat around it), `true`
/// otherwise (staircase steps and corners, junctions, open borders).
///
/// Why: where a surface faces a grid axis, the digital surface is one flat plateau whose
/// level is a single sample for the whole plateau, not many independent ones. On a curved
/// surface it is biased: the true surface is a dome spanning the voxel layer from its
/// rim to its top, so the plateau sits below the dome's mean when the top just misses
/// the next layer of voxel centres, and above it when it just reaches it (the sphere's
/// poles and the torus's tube top at integer radii lose up to 0.17 voxel on average over
/// the plateau). The steps at the plateau's rim are unbiased samples of the surface.
pub fn informative_vertices(surface: &DigitalSurface) -> Vec<bool> {
    (0..surface.num_vertices())
        .into_par_iter()
        .map(|v| {
            let v = VertexId(v as u32);
            let sf = surface.vertex_surfels(v);
            let n0 = sf.first().map(|s| surface.surfel(*s).normal());
            let plateau = sf.len() == 4
                && !surface.is_boundary_vertex(v)
                && sf.iter().all(|s| Some(surface.surfel(*s).normal()) == n0);
            !plateau
        })
        .collect()
}

/// The low-passed drift of [`smoothed_displacements`], measured only at the `trusted`
/// vertices (normalized convolution: the smoothed trusted displacements over the smoothed
/// indicator of trust), so that a plateau's interior takes the drift of its rim. Far from
/// any trusted vertex (deep inside a large flat face), it falls back continuously to the
/// plain smoothed drift. An empty `trusted` trusts every vertex.
fn trusted_drift(surface: &DigitalSurface, drift: &[DVec3], trusted: &[bool], sigma: f64) -> Vec<DVec3> {
    if trusted.is_empty() || trusted.iter().all(|&t| t) {
        return smoothed_displacements(surface, drift, sigma);
    }
    // Three channels for the masked drift, and the trust indicator in a fourth pass.
    let masked: Vec<DVec3> =
        drift.iter().zip(trusted).map(|(d, &t)| if t { *d } else { DVec3::ZERO }).collect();
    let weight: Vec<DVec3> = trusted.iter().map(|&t| DVec3::splat(if t { 1.0 } else { 0.0 })).collect();
    let plain = smoothed_displacements(surface, drift, sigma);
    let num = smoothed_displacements(surface, &masked, sigma);
    let den = smoothed_displacements(surface, &weight, sigma);
    const EPS: f64 = 1e-3;
    num.iter().zip(&den).zip(&plain).map(|((n, w), p)| (*n + EPS * *p) / (w.x + EPS)).collect()
}

/// Per vertex, the mean over its quads of the displacement of the quad's centre from
/// `input` to `positions`. Quad centres, not vertices, because the centre of a digital
/// surfel is an unbiased sample of the surface (Gauss digitization: the surface crosses
/// the segment between the two voxel centres uniformly), while the staircase's vertices
/// are not (on a torus of minor radius 8 voxels they sit 0.027 voxel inside on average).
fn surfel_drift(surface: &DigitalSurface, positions: &[DVec3], input: &[DVec3]) -> Vec<DVec3> {
    let centre_moves: Vec<DVec3> = surface
        .surfels()
        .par_iter()
        .map(|s| s.vertices.iter().map(|v| positions[v.index()] - input[v.index()]).sum::<DVec3>() / 4.0)
        .collect();
    (0..surface.num_vertices())
        .into_par_iter()
        .map(|v| {
            let sf = surface.vertex_surfels(VertexId(v as u32));
            sf.iter().map(|s| centre_moves[s.index()]).sum::<DVec3>() / sf.len().max(1) as f64
        })
        .collect()
}
