//! Size preservation between refinement rounds: the re-centring of the attachment
//! targets ([`crate::Recentring`]), and what it reads from the surface alone
//! ([`RecentringInputs`]).

use glam::DVec3;
use rayon::prelude::*;
use voxreg_digisurf::{DigitalSurface, SurfelId, VertexId};
use voxreg_normals::{Interrupt, NormalField};

use crate::error::RegularizeError;

/// What the re-centring reads from the surface alone, kept across runs.
#[derive(Debug)]
pub(crate) struct RecentringInputs {
    /// Per vertex, whether the drift is measured there (outside digital plateaus and a
    /// block's cut sides).
    pub(crate) trusted: Vec<bool>,
    /// Per surfel, the weight of its centre as a sample ([`sample_weights`]; `None`: all 1).
    pub(crate) samples: Option<Vec<f64>>,
    /// The plateaus' attachment and alignment multipliers ([`plateau_weights`]; `None`:
    /// all 1).
    pub(crate) plateaus: Option<(Vec<f64>, Vec<f64>)>,
}

impl RecentringInputs {
    /// The inputs of `surface`, the vertices flagged in `untrusted` (a block's cut sides)
    /// left out of the drift's measurement.
    pub(crate) fn new(surface: &DigitalSurface, untrusted: Option<&[bool]>) -> Self {
        let informative = informative_vertices(surface);
        let plateaus = plateau_weights(surface, &informative);
        let mut trusted = informative;
        if let Some(untrusted) = untrusted {
            trusted.iter_mut().zip(untrusted).for_each(|(t, u)| *t &= !*u);
        }
        RecentringInputs { trusted, samples: sample_weights(surface), plateaus }
    }

    /// The targets' displacement for this round: minus the smoothed drift (standard
    /// deviation `sigma` voxels) of `positions` from the lattice, measured at the trusted
    /// vertices, with the sagitta of long quads lifted out by `lift_weight` (the
    /// anisotropy's blend, 0 on cubic voxels).
    pub(crate) fn drift(
        &self,
        surface: &DigitalSurface,
        positions: &[DVec3],
        field: &NormalField,
        lift_weight: f64,
        sigma: f64,
        interrupt: &Interrupt,
    ) -> Result<Vec<DVec3>, RegularizeError> {
        let lift = (lift_weight > 0.0).then(|| {
            let mut lift = sagitta_lift(surface, positions, field);
            lift.iter_mut().for_each(|l| *l *= lift_weight);
            lift
        });
        let (drift, sampled) =
            surfel_drift(surface, positions, &surface.positions(), self.samples.as_deref(), lift.as_deref());
        let weight: Vec<f64> =
            sampled.iter().zip(&self.trusted).map(|(w, &t)| if t { *w } else { 0.0 }).collect();
        trusted_drift(surface, &drift, &weight, sigma, interrupt)
    }
}

/// Low-pass filter of per-vertex displacements: lazy diffusion over the vertex graph,
/// `u_v <- (u_v + mean of u over v's neighbours) / 2`, repeated `k = 4 sigma^2` times,
/// which is a Gaussian of standard deviation `sigma` voxels on a flat grid (each step
/// adds a variance of 1/4 voxel^2 per axis). Diffusion follows the surface, so the
/// two sheets of a thin shape never mix; at junctions it runs across interfaces.
/// `interrupt` is polled before each step.
pub(crate) fn smoothed_displacements(
    surface: &DigitalSurface,
    displacements: &[DVec3],
    sigma: f64,
    interrupt: &Interrupt,
) -> Result<Vec<DVec3>, RegularizeError> {
    let steps = (4.0 * sigma * sigma).round() as usize;
    let mut u = displacements.to_vec();
    let mut next = vec![DVec3::ZERO; u.len()];
    for _ in 0..steps {
        interrupt.check()?;
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
    Ok(u)
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
pub(crate) fn informative_vertices(surface: &DigitalSurface) -> Vec<bool> {
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

/// The low-passed drift of [`smoothed_displacements`], measured at the vertices of
/// positive `weight` (normalized convolution: the smoothed weighted displacements over the
/// smoothed weights), so that a plateau's interior (weight 0) takes the drift of its rim.
/// Far from any weighted vertex (deep inside a large flat face), it falls back
/// continuously to the plain smoothed drift. An empty `weight`, or one that is the same
/// positive value everywhere, trusts every vertex equally: the plain smoothed drift.
/// `interrupt` is polled before each diffusion step.
pub(crate) fn trusted_drift(
    surface: &DigitalSurface,
    drift: &[DVec3],
    weight: &[f64],
    sigma: f64,
    interrupt: &Interrupt,
) -> Result<Vec<DVec3>, RegularizeError> {
    if weight.first().is_none_or(|&w0| w0 > 0.0 && weight.iter().all(|&w| w == w0)) {
        return smoothed_displacements(surface, drift, sigma, interrupt);
    }
    // The plain drift, the weighted drift and the weight diffused together: one pass
    // over the neighbour lists per step instead of three, each channel summed in the
    // same order as `smoothed_displacements` does (identical results).
    let steps = (4.0 * sigma * sigma).round() as usize;
    let mut u: Vec<Channels> = drift
        .iter()
        .zip(weight)
        .map(|(d, &w)| Channels { plain: *d, masked: if w > 0.0 { *d * w } else { DVec3::ZERO }, weight: w })
        .collect();
    let mut next = u.clone();
    for _ in 0..steps {
        interrupt.check()?;
        next.par_iter_mut().enumerate().for_each(|(v, out)| {
            let nb = surface.vertex_neighbours(VertexId(v as u32));
            let c = u[v];
            *out = if nb.is_empty() {
                c
            } else {
                let (mut plain, mut masked, mut weight) = (DVec3::ZERO, DVec3::ZERO, 0.0);
                for w in nb {
                    let o = &u[w.index()];
                    plain += o.plain;
                    masked += o.masked;
                    weight += o.weight;
                }
                let k = nb.len() as f64;
                Channels {
                    plain: 0.5 * (c.plain + plain / k),
                    masked: 0.5 * (c.masked + masked / k),
                    weight: 0.5 * (c.weight + weight / k),
                }
            };
        });
        std::mem::swap(&mut u, &mut next);
    }
    const EPS: f64 = 1e-3;
    Ok(u.iter().map(|c| (c.masked + EPS * c.plain) / (c.weight + EPS)).collect())
}

/// The three quantities [`trusted_drift`] diffuses.
#[derive(Copy, Clone)]
struct Channels {
    plain: DVec3,
    masked: DVec3,
    weight: f64,
}

/// Per surfel, the weight of its input centre as a sample of the surface in the
/// re-centring: `h_b h_c / h_a^2` for a surfel facing axis `a` (its area over the variance
/// of its centre's offset, which is uniform across the voxel step `h_a` along its axis:
/// Gauss digitization); `None` on cubic voxels, where every weight is 1.
///
/// Why: on thick slices a slice's walls (facing the fine axes) are `h_z / h_x` times
/// larger than its steps, and their centres are `h_z / h_x` times more precise along
/// their normal; with equal weights the steps' coarse offsets dominate the measured drift.
pub(crate) fn sample_weights(surface: &DigitalSurface) -> Option<Vec<f64>> {
    let h = surface.spacing();
    if h.min_element() == h.max_element() {
        return None;
    }
    let per_axis = [h.y * h.z / (h.x * h.x), h.x * h.z / (h.y * h.y), h.x * h.y / (h.z * h.z)];
    Some(surface.surfels().par_iter().map(|s| per_axis[s.axis as usize]).collect())
}

/// Per vertex, the mean over its quads of the displacement of the quad's centre from
/// `input` to `positions`, plus the quad's `lift` where given (see [`sagitta_lift`]),
/// weighted by the quads' `weights` where given ([`sample_weights`]); and per vertex the
/// mean weight of its quads (1 without weights). Quad centres, not vertices, because the
/// centre of a digital surfel is an unbiased sample of the surface (Gauss digitization:
/// the surface crosses the segment between the two voxel centres uniformly), while the
/// staircase's vertices are not (on a torus of minor radius 8 voxels they sit 0.027 voxel
/// inside on average).
pub(crate) fn surfel_drift(
    surface: &DigitalSurface,
    positions: &[DVec3],
    input: &[DVec3],
    weights: Option<&[f64]>,
    lift: Option<&[DVec3]>,
) -> (Vec<DVec3>, Vec<f64>) {
    let centre_moves: Vec<DVec3> = surface
        .surfels()
        .par_iter()
        .enumerate()
        .map(|(i, s)| {
            let m = s.vertices.iter().map(|v| positions[v.index()] - input[v.index()]).sum::<DVec3>() / 4.0;
            lift.map_or(m, |l| m + l[i])
        })
        .collect();
    (0..surface.num_vertices())
        .into_par_iter()
        .map(|v| {
            let sf = surface.vertex_surfels(VertexId(v as u32));
            let n = sf.len().max(1) as f64;
            match weights {
                None => (sf.iter().map(|s| centre_moves[s.index()]).sum::<DVec3>() / n, 1.0),
                Some(w) => {
                    let total: f64 = sf.iter().map(|s| w[s.index()]).sum();
                    let sum: DVec3 = sf.iter().map(|s| w[s.index()] * centre_moves[s.index()]).sum();
                    (if total > 0.0 { sum / total } else { DVec3::ZERO }, total / n)
                }
            }
        })
        .unzip()
}

/// Per surfel, the offset from its centre to the smooth surface through its vertices at
/// `positions`, along its normal in `field`: `(k_a |e_a|^2 + k_b |e_b|^2) / 8`, with `e_a`,
/// `e_b` the quad's mean edges and `k_a`, `k_b` the normal curvatures towards its
/// edge-adjacent quads of the same interface across them (`(n_g - n_f) . (c_g - c_f) /
/// |c_g - c_f|^2` from `field`'s normals and the quads' centres; neighbours past 30
/// degrees, across a feature, are left out). A quad whose vertices lie on a surface of
/// curvature `k` has its centre that far inside it (the sagitta of its diagonals).
///
/// Why: the re-centring matches the regularized quads' centres with the input's, so
/// their vertices end up a sagitta outside the surface; on thick slices the walls'
/// quads are long (the sagitta of a 1 x 2.5 quad on a sphere of radius 20 is 0.045 voxel,
/// against 0.0125 for a unit square) and the vertices of a convex shape sat that far out.
pub(crate) fn sagitta_lift(surface: &DigitalSurface, positions: &[DVec3], field: &NormalField) -> Vec<DVec3> {
    let normals = field.as_slice();
    let cos_max = 30f64.to_radians().cos();
    let centres: Vec<DVec3> = surface
        .surfels()
        .par_iter()
        .map(|s| s.vertices.iter().map(|v| positions[v.index()]).sum::<DVec3>() / 4.0)
        .collect();
    (0..surface.num_surfels())
        .into_par_iter()
        .map(|f| {
            let sf = surface.surfels()[f];
            let [a, b, c, d] = sf.vertices.map(|v| positions[v.index()]);
            let (ea, eb) = (0.5 * ((b - a) + (c - d)), 0.5 * ((d - a) + (c - b)));
            let nf = normals[f];
            // Curvature sums and counts towards the neighbours across `ea`'s ends and `eb`'s.
            let (mut k, mut count) = ([0.0; 2], [0.0; 2]);
            for e in surface.surfel_edges(SurfelId(f as u32)) {
                for &g in surface.edge_surfels(e) {
                    let g = g.index();
                    if g == f || surface.surfels()[g].interface != sf.interface {
                        continue;
                    }
                    let ng = normals[g] * normals[g].dot(nf).signum();
                    if ng.dot(nf) < cos_max {
                        continue;
                    }
                    let dc = centres[g] - centres[f];
                    let along = usize::from(dc.dot(eb).abs() * ea.length() > dc.dot(ea).abs() * eb.length());
                    k[along] += (ng - nf).dot(dc) / dc.length_squared().max(f64::MIN_POSITIVE);
                    count[along] += 1.0;
                }
            }
            let mean = |i: usize| if count[i] > 0.0 { Some(k[i] / count[i]) } else { None };
            let (ka, kb) = match (mean(0), mean(1)) {
                (Some(ka), Some(kb)) => (ka, kb),
                (Some(k), None) | (None, Some(k)) => (k, k),
                (None, None) => return DVec3::ZERO,
            };
            nf * ((ka * ea.length_squared() + kb * eb.length_squared()) / 8.0)
        })
        .collect()
}

/// The attachment (per vertex) and alignment (per surfel) multipliers of digital
/// plateaus on anisotropic voxels: `(h_min / h_a)^2` for the vertices inside a plateau
/// facing axis `a` (not [`informative_vertices`]) and for the quads whose four vertices
/// are, 1 elsewhere; `None` on cubic voxels (every multiplier 1).
///
/// Why: a plateau's level is a single sample of the surface, uncertain by the voxel step
/// along its axis; facing a coarse axis (the wide plateaus at the poles of a shape cut in
/// thick slices) the attachment pulled its interior flat onto that level, and the refined
/// normals read the flattened quads back (the poles of a sphere at spacing (1, 1, 2.5) sat
/// 0.2 voxel inside). Weighted by the inverse variance of the level, relative to the
/// finest axis, the plateau's interior is shaped by the fairness and the normals from its
/// informative rim.
pub(crate) fn plateau_weights(
    surface: &DigitalSurface,
    informative: &[bool],
) -> Option<(Vec<f64>, Vec<f64>)> {
    let h = surface.spacing();
    if h.min_element() == h.max_element() {
        return None;
    }
    let per_axis = [0, 1, 2].map(|a| (h.min_element() / h[a]).powi(2));
    let alpha = (0..surface.num_vertices())
        .into_par_iter()
        .map(|v| {
            let sf = surface.vertex_surfels(VertexId(v as u32));
            match sf.first() {
                Some(s) if !informative[v] => per_axis[surface.surfel(*s).axis as usize],
                _ => 1.0,
            }
        })
        .collect();
    let beta =
        surface
            .surfels()
            .par_iter()
            .map(|s| {
                if s.vertices.iter().all(|v| !informative[v.index()]) {
                    per_axis[s.axis as usize]
                } else {
                    1.0
                }
            })
            .collect();
    Some((alpha, beta))
}

#[cfg(test)]
mod tests {
    use voxreg_testkit::{digitize, Cuboid, Lcg, Sphere};

    use super::*;

    #[test]
    fn fused_trusted_drift_matches_three_separate_diffusions_bit_for_bit() {
        let surface = DigitalSurface::from_volume(&digitize(&Sphere { radius: 7.4 }, 1.0)).unwrap();
        let trusted = informative_vertices(&surface);
        assert!(trusted.iter().any(|&t| t) && trusted.iter().any(|&t| !t));
        let mut rng = Lcg::new(3);
        let drift: Vec<DVec3> = (0..surface.num_vertices()).map(|_| rng.vec3(-0.2, 0.2)).collect();
        // Trust as 0 / 1, and as weights of several values.
        let binary: Vec<f64> = trusted.iter().map(|&t| if t { 1.0 } else { 0.0 }).collect();
        let graded: Vec<f64> =
            trusted.iter().map(|&t| if t { 0.5 + rng.vec3(0.0, 1.0).x } else { 0.0 }).collect();
        let never = Interrupt::never();
        for weight in [binary, graded] {
            let masked: Vec<DVec3> = drift.iter().zip(&weight).map(|(d, w)| *d * *w).collect();
            let splat: Vec<DVec3> = weight.iter().map(|w| DVec3::splat(*w)).collect();
            let plain = smoothed_displacements(&surface, &drift, 3.0, &never).unwrap();
            let num = smoothed_displacements(&surface, &masked, 3.0, &never).unwrap();
            let den = smoothed_displacements(&surface, &splat, 3.0, &never).unwrap();
            let expected: Vec<DVec3> =
                num.iter().zip(&den).zip(&plain).map(|((n, w), p)| (*n + 1e-3 * *p) / (w.x + 1e-3)).collect();
            assert_eq!(trusted_drift(&surface, &drift, &weight, 3.0, &never).unwrap(), expected);
        }
    }

    #[test]
    fn the_sagitta_lift_of_quads_on_a_sphere() {
        // Vertices on a sphere of radius 12 sampled at (1, 1, 2.5), the exact normals as
        // the field: each quad's lift reaches from its centre back to the sphere, within
        // a tenth of the sagitta (the quads' edges are not exactly along the principal
        // directions, and the curvature is estimated from the neighbours).
        let sphere = Sphere { radius: 12.0 };
        let spacing = DVec3::new(1.0, 1.0, 2.5);
        let surface = DigitalSurface::from_volume(&voxreg_testkit::digitize_labels(
            &voxreg_testkit::Solid(&sphere),
            spacing,
        ))
        .unwrap();
        let on: Vec<DVec3> = surface.positions().iter().map(|p| p.normalize() * 12.0).collect();
        let centre =
            |s: &voxreg_digisurf::Surfel| s.vertices.iter().map(|v| on[v.index()]).sum::<DVec3>() / 4.0;
        let field = NormalField::new(surface.surfels().iter().map(|s| centre(s).normalize()).collect());
        let lift = sagitta_lift(&surface, &on, &field);
        let (mut before, mut after) = (0.0, 0.0);
        for (s, l) in surface.surfels().iter().zip(&lift) {
            let c = centre(s);
            before += 12.0 - c.length();
            after += (12.0 - (c + *l).length()).abs();
        }
        let n = surface.num_surfels() as f64;
        eprintln!("centres inside by {:.4} on average; lifted, off by {:.4}", before / n, after / n);
        assert!(before / n > 0.02 && after < 0.1 * before, "{} {}", before / n, after / n);
    }

    #[test]
    fn cubic_voxels_keep_unit_sample_and_plateau_weights() {
        let cubic = DigitalSurface::from_volume(&digitize(&Sphere { radius: 5.3 }, 0.7)).unwrap();
        assert!(sample_weights(&cubic).is_none());
        assert!(plateau_weights(&cubic, &informative_vertices(&cubic)).is_none());
        // Thick slices: walls weigh h_z / h_x, steps h_x^2 / h_z^2; the plateaus facing z
        // (h_x / h_z)^2, those facing x or y 1.
        let spacing = DVec3::new(1.0, 1.0, 2.5);
        let surface = DigitalSurface::from_volume(&voxreg_testkit::digitize_labels(
            &voxreg_testkit::Solid(&Sphere { radius: 9.0 }),
            spacing,
        ))
        .unwrap();
        let w = sample_weights(&surface).unwrap();
        for (s, w) in surface.surfels().iter().zip(&w) {
            assert_eq!(*w, if s.axis == 2 { 0.16 } else { 2.5 });
        }
        let informative = informative_vertices(&surface);
        let (alpha, beta) = plateau_weights(&surface, &informative).unwrap();
        let thin = (1.0f64 / 2.5).powi(2);
        assert!(alpha.contains(&thin) && beta.contains(&thin));
        for (v, a) in alpha.iter().enumerate() {
            let axis = surface.surfel(surface.vertex_surfels(VertexId(v as u32))[0]).axis;
            let expected = match (informative[v], axis) {
                (true, _) | (false, 0 | 1) => 1.0,
                (false, _) => thin,
            };
            assert_eq!(*a, expected);
        }
    }

    #[test]
    fn plateau_interiors_are_not_informative() {
        // A digitized cube: the vertices inside its faces are on digital plateaus, those
        // on its edges and corners are not.
        let cube = Cuboid { half: DVec3::splat(4.0) };
        let surface = DigitalSurface::from_volume(&digitize(&cube, 1.0)).unwrap();
        let informative = informative_vertices(&surface);
        for (v, p) in surface.positions().iter().enumerate() {
            let on_edge = p.abs().to_array().iter().filter(|c| (**c - 4.5).abs() < 1e-9).count() >= 2;
            assert_eq!(informative[v], on_edge, "vertex at {p}");
        }
    }
}
