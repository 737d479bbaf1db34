//! What the pipeline does between solves: weak alignment at creases, and re-centring of
//! the attachment targets (size preservation).

use glam::{DVec3, Vec3};
use rayon::prelude::*;
use voxreg_digisurf::{DigitalSurface, Surfel, SurfelId, VertexId};
use voxreg_normals::{FeatureRamp, Interrupt, NormalField};

use crate::error::RegularizeError;
use crate::faces::FaceIndex;

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

/// The scale below which a quad's normal changes are not treated as an oscillation by
/// [`relaxed_normals`], squared: 1e-4 (a hundredth of a radian, about 0.6 degree).
const OSCILLATION_SCALE2: f64 = 1e-4;

/// The refined normals of a round, relaxed where they swing back: each quad moves from
/// its normal `n` of the last round by `t d` instead of the whole change
/// `d = estimate - n`, with `t = 1 / (1 + c)` and
/// `c = max(0, -d . p) / (|p|^2 + s^2)`, where `p` is the change the quad took in the
/// round before (`previous`, updated here to the change taken now) and `s` a hundredth of
/// a radian. A quad whose normal keeps turning the same way, or barely moved, takes the
/// estimate (`c = 0`); one that undoes its last change (`d = -p`, an oscillation between
/// two normals) takes about half of it, the midpoint that the iteration would otherwise
/// circle around. `t` is a continuous function of the normals, so a small change of the
/// positions changes the result little (chunks must agree with the whole volume).
///
/// Why: on thin sheets of real segmentations the rounds do not settle on their own: some
/// quads' normals alternate between two directions, and the alternation amplifies a
/// difference of the positions (a solver tolerance, a chunk's cut) round after round.
pub(crate) fn relaxed_normals(
    field: &NormalField,
    estimate: NormalField,
    previous: &mut Option<Vec<Vec3>>,
) -> NormalField {
    let (n, e) = (field.as_slice(), estimate.as_slice());
    let change =
        |relaxed: &[DVec3]| Some(relaxed.par_iter().zip(n).map(|(r, n)| (*r - *n).as_vec3()).collect());
    let relaxed: Vec<DVec3> = match previous.as_deref() {
        None => {
            *previous = change(e);
            return estimate;
        }
        Some(p) => n
            .par_iter()
            .zip(e)
            .zip(p)
            .map(|((n, e), p)| {
                let (d, p) = (*e - *n, p.as_dvec3());
                let c = (-d.dot(p)).max(0.0) / (p.length_squared() + OSCILLATION_SCALE2);
                let m = (*n + d / (1.0 + c)).normalize_or_zero();
                if m == DVec3::ZERO {
                    *e
                } else {
                    m
                }
            })
            .collect(),
    };
    *previous = change(&relaxed);
    NormalField::new(relaxed)
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

/// Full width, in voxels of the finest spacing, of the thin-sheet rule's ramp (see
/// [`thin_sheets`]): a quad's share falls from 1 at `thickness - 0.5` to 0 at
/// `thickness + 0.5`.
const SHEET_RAMP: f64 = 1.0;

/// The angles, in degrees, between a sheet's two sides (their outward normals, one
/// reversed) within which they count as parallel in full and past which not at all
/// (see [`thin_sheets`]).
const SHEET_PARALLEL_DEG: [f64; 2] = [30.0, 50.0];

/// The quads of thin sheets, as `(surfel, share)` with `share` in `(0, 1]`: for each quad
/// and each of its two regions, the distance from the quad's centre through that region
/// along `field`'s normal to the region's other side (marched voxel by voxel, in voxels of
/// the finest spacing), where that side faces the opposite way (its outward normal in
/// `field` within [`SHEET_PARALLEL_DEG`] of the march). The share is 1 for a sheet
/// thinner than `thickness - 0.5`, 0 from `thickness + 0.5` on, linear between, and
/// weighed by how parallel the sides are; the thinner region counts. A quad whose
/// normal in `field` does not enter a region through the quad skips that region.
///
/// Why: a region one or two voxels thick between two others (a membrane between two
/// compartments of a segmentation) is a long sheet whose tilt only the weak attachment
/// holds; refined normals read that tilt back and the next solve amplifies it, so the
/// rounds do not settle there and a difference of thousandths of a voxel (a solver's
/// tolerance, a chunk's cut) grows to tenths. Measured on the initial field (from the
/// voxels alone), the rule does not depend on the positions; the wedges at the rim of a
/// thick region (sides not parallel) are not sheets.
pub(crate) fn thin_sheets(surface: &DigitalSurface, field: &NormalField, thickness: f64) -> Vec<(u32, f64)> {
    if thickness <= 0.0 {
        return Vec::new();
    }
    let reach = thickness + 0.5 * SHEET_RAMP;
    let dims = surface.dims().map(|d| d as i64);
    let faces = FaceIndex::new(surface);
    let h = surface.spacing();
    let unit = h.min_element();
    let [par_one, par_zero] = SHEET_PARALLEL_DEG.map(|a| a.to_radians().cos());
    let normals = field.as_slice();
    // From quad `s` into its region `side` along `dir`: the distance to the region's far
    // side and how parallel that side is; `None` past `reach` or out of the domain.
    let march = |s: &Surfel, side: usize, dir: DVec3| -> Option<(f64, f64)> {
        let a = s.axis as usize;
        let mut p = DVec3::from_array(s.cell.map(|c| c as f64 + 0.5));
        p[a] = s.cell[a] as f64;
        // Lattice steps per voxel of the finest spacing.
        let u = dir * unit / h;
        let mut v = s.voxels()[side];
        let mut next = [f64::INFINITY; 3];
        let mut delta = [f64::INFINITY; 3];
        for k in 0..3 {
            if u[k] != 0.0 {
                let bound = if u[k] > 0.0 { (v[k] + 1) as f64 } else { v[k] as f64 };
                next[k] = ((bound - p[k]) / u[k]).max(0.0);
                delta[k] = 1.0 / u[k].abs();
            }
        }
        // The quad's own face is behind the start.
        next[a] = delta[a];
        loop {
            let k = (0..3).min_by(|&i, &j| next[i].total_cmp(&next[j])).expect("three axes");
            let t = next[k];
            if t >= reach {
                return None;
            }
            let mut cell = v;
            if u[k] > 0.0 {
                cell[k] += 1;
            }
            if let Some(g) = faces.get(k, cell) {
                let far = &surface.surfels()[g as usize];
                let n = normals[g as usize];
                let outward = if far.regions[0] == s.regions[side] { n } else { -n };
                let parallel = ((dir.dot(outward) - par_zero) / (par_one - par_zero)).clamp(0.0, 1.0);
                return Some((t, parallel));
            }
            v[k] += if u[k] > 0.0 { 1 } else { -1 };
            if v[k] < -1 || v[k] > dims[k] {
                return None;
            }
            next[k] += delta[k];
        }
    };
    surface
        .surfels()
        .par_iter()
        .zip(normals.par_iter())
        .enumerate()
        .filter_map(|(i, (s, n))| {
            let oriented = s.normal();
            let share = (0..2)
                .filter_map(|side| {
                    // Into the inner voxel against the normal, into the outer one along it.
                    let dir = if side == 0 { -*n } else { *n };
                    let entering = if side == 0 { -dir.dot(oriented) } else { dir.dot(oriented) };
                    if entering <= 1e-6 {
                        return None;
                    }
                    let (t, parallel) = march(s, side, dir)?;
                    let thin = ((thickness + 0.5 * SHEET_RAMP - t) / SHEET_RAMP).clamp(0.0, 1.0);
                    Some(thin * parallel)
                })
                .fold(0.0, f64::max);
            (share > 0.0).then_some((i as u32, share))
        })
        .collect()
}

/// `estimate` moved towards the normals `held` (one per quad of a thin sheet, with its
/// share from [`thin_sheets`]): by each quad's share, all the way at share 1.
pub(crate) fn hold_thin_sheets(estimate: NormalField, held: &[(u32, DVec3, f64)]) -> NormalField {
    if held.is_empty() {
        return estimate;
    }
    let mut normals = estimate.as_slice().to_vec();
    for &(s, n, share) in held {
        let e = &mut normals[s as usize];
        let m = (share * n + (1.0 - share) * *e).normalize_or_zero();
        *e = if m == DVec3::ZERO { n } else { m };
    }
    NormalField::new(normals)
}

#[cfg(test)]
mod tests {
    use voxreg_normals::NormalEstimator;
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

    #[test]
    fn relaxed_normals_halve_an_oscillation_and_keep_a_steady_turn() {
        let unit = |x: f64, y: f64| DVec3::new(x, y, 1.0).normalize();
        let n0 = NormalField::new(vec![unit(0.0, 0.0), unit(0.0, 0.0), unit(0.0, 0.0)]);
        let n1 = NormalField::new(vec![unit(0.2, 0.0), unit(0.2, 0.0), unit(1e-4, 0.0)]);
        // The first round has no previous change: the estimate as it is.
        let mut previous = None;
        let r1 = relaxed_normals(&n0, n1.clone(), &mut previous);
        assert_eq!(r1.as_slice(), n1.as_slice());
        // Then: quad 0 swings back to where it was, quad 1 keeps turning the same way,
        // quad 2 swings back by a change far below the oscillation scale.
        let e2 = NormalField::new(vec![unit(0.0, 0.0), unit(0.4, 0.0), unit(0.0, 0.0)]);
        let r2 = relaxed_normals(&r1, e2.clone(), &mut previous);
        let (r, e) = (r2.as_slice(), e2.as_slice());
        let mid = (n1.as_slice()[0] + e[0]).normalize();
        assert!(r[0].angle_between(mid) < 0.01, "{} from the midpoint", r[0].angle_between(mid));
        assert_eq!(r[1], e[1]);
        assert!(r[2].angle_between(e[2]) < 1e-6);
        for m in r {
            assert!((m.length() - 1.0).abs() < 1e-12);
        }
        // The change taken is what the next round compares with.
        let p = previous.unwrap();
        assert!((p[1].as_dvec3() - (e[1] - n1.as_slice()[1])).length() < 1e-7);
    }

    #[test]
    fn relaxed_normals_are_continuous_in_the_estimate() {
        // The estimate's change crosses from turning on (d . p > 0) to swinging back
        // (d . p < 0) at k = 0: a tiny change of the estimate moves the result by about as
        // much, not by a jump (a rule switching at d . p = 0 would jump by degrees here).
        let n = DVec3::new(0.0, 0.0, 1.0);
        let mut last = None;
        for k in -5..=5 {
            let e = DVec3::new(1e-6 * k as f64, 0.3, 1.0).normalize();
            let mut previous = Some(vec![Vec3::new(0.1, 0.0, 0.0)]);
            let r = relaxed_normals(&NormalField::new(vec![n]), NormalField::new(vec![e]), &mut previous);
            let m = r.as_slice()[0];
            if let Some(l) = last {
                assert!(m.angle_between(l) < 1e-5, "step {k}: {}", m.angle_between(l));
            }
            last = Some(m);
        }
    }

    /// A sheet of label 2, `thickness` voxels thick along z, sloping one in three along x,
    /// between label 1 below and label 3 above, in a 40 x 24 x 28 box; and its integral
    /// invariant normals.
    fn sloping_sheet(thickness: f64) -> (DigitalSurface, NormalField) {
        let volume = voxreg_digisurf::LabelVolume::from_fn([40, 24, 28], |[x, _, z]| {
            let h = z as f64 + 0.5 - 8.0 - (x as f64 + 0.5) / 3.0;
            if h < 0.0 {
                1
            } else if h < thickness {
                2
            } else {
                3
            }
        });
        let surface = DigitalSurface::from_volume(&volume).unwrap();
        let field = voxreg_normals::IntegralInvariant { radius: None }.estimate(&surface).unwrap();
        (surface, field)
    }

    /// The sheet's own quads (between labels 1 and 2 or 2 and 3), away from the box.
    fn sheet_quads(surface: &DigitalSurface) -> Vec<usize> {
        (0..surface.num_surfels())
            .filter(|&i| {
                let s = &surface.surfels()[i];
                let inside = (6..34).contains(&s.cell[0]) && (6..18).contains(&s.cell[1]);
                inside && s.labels.contains(&2) && s.labels.iter().all(|&l| l != 0)
            })
            .collect()
    }

    #[test]
    fn thin_sheets_are_the_quads_of_sheets_one_or_two_voxels_thick() {
        // Thickness along z, the shares' range on the sheet's quads.
        for (thickness, least, most) in [(1.0, 1.0, 1.0), (1.8, 0.5, 1.0), (4.0, 0.0, 0.0)] {
            let (surface, field) = sloping_sheet(thickness);
            let shares: std::collections::HashMap<u32, f64> =
                thin_sheets(&surface, &field, 2.5).into_iter().collect();
            let quads = sheet_quads(&surface);
            assert!(quads.len() > 200);
            for f in quads {
                let share = shares.get(&(f as u32)).copied().unwrap_or(0.0);
                assert!(share >= least && share <= most, "thickness {thickness}, quad {f}: {share}");
            }
        }
        // A ball is thick everywhere along its normals, the rim of a shallow cap included
        // (its two sides are not parallel); 0 turns the rule off.
        let ball = DigitalSurface::from_volume(&digitize(&Sphere { radius: 9.3 }, 1.0)).unwrap();
        let field = voxreg_normals::IntegralInvariant { radius: None }.estimate(&ball).unwrap();
        assert!(thin_sheets(&ball, &field, 2.5).is_empty());
        let (surface, field) = sloping_sheet(1.0);
        assert!(thin_sheets(&surface, &field, 0.0).is_empty());
    }

    #[test]
    fn held_normals_move_the_estimate_by_their_share() {
        let (a, b) = (DVec3::X, DVec3::Y);
        let estimate = NormalField::new(vec![a, a, a]);
        let held = hold_thin_sheets(estimate, &[(0, b, 1.0), (2, b, 0.5)]);
        let [full, none, half] = [0, 1, 2].map(|i| held.as_slice()[i]);
        assert!(full.distance(b) < 1e-15 && none.distance(a) < 1e-15);
        assert!((half.angle_between(a) - half.angle_between(b)).abs() < 1e-12 && half.angle_between(a) > 0.7);
    }

    #[test]
    fn thin_sheets_keep_the_first_rounds_normals() {
        let (surface, _) = sloping_sheet(1.0);
        let run = |refine: usize, sheet_thickness: f64| {
            let params = crate::Params { refine, sheet_thickness, ..crate::Params::default() };
            crate::Regularizer::new(surface.clone()).run(&params).unwrap().normals
        };
        let quads = sheet_quads(&surface);
        let turn = |a: &NormalField, b: &NormalField| {
            quads.iter().map(|&f| a.as_slice()[f].angle_between(b.as_slice()[f])).fold(0.0, f64::max)
        };
        let first = run(1, 2.5);
        assert!(turn(&first, &run(3, 2.5)) < 1e-9);
        // Refined in every round, the same quads turn on.
        let free = turn(&run(1, 0.0), &run(3, 0.0));
        assert!(free > 1e-4, "{free}");
    }
}
