//! What the pipeline does between solves: weak alignment at creases, and re-centring of
//! the attachment targets (size preservation).

use glam::DVec3;
use rayon::prelude::*;
use voxreg_digisurf::{DigitalSurface, SurfelId, VertexId};
use voxreg_normals::{Interrupt, NormalField};

use crate::RegularizeError;

/// Per-surfel alignment multipliers: `weight` for the quads whose normal in `field` is
/// more than `feature_angle_deg` from the normal of an edge-adjacent quad of the same
/// interface (the quads on either side of a feature) and from their own surfel's axis,
/// and for the quads within `dilation` rings of them (sharing a vertex with a marked
/// quad, ring by ring); `1` for the others. Quads that keep their axis (the faces of an
/// axis-aligned box, whose edges run along the quads' edges) are not marked by the angle
/// test: they lie flat unsqueezed.
pub(crate) fn crease_weights(
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

/// The low-passed drift of [`smoothed_displacements`], measured only at the `trusted`
/// vertices (normalized convolution: the smoothed trusted displacements over the smoothed
/// indicator of trust), so that a plateau's interior takes the drift of its rim. Far from
/// any trusted vertex (deep inside a large flat face), it falls back continuously to the
/// plain smoothed drift. An empty `trusted` trusts every vertex. `interrupt` is polled
/// before each diffusion step.
pub(crate) fn trusted_drift(
    surface: &DigitalSurface,
    drift: &[DVec3],
    trusted: &[bool],
    sigma: f64,
    interrupt: &Interrupt,
) -> Result<Vec<DVec3>, RegularizeError> {
    if trusted.is_empty() || trusted.iter().all(|&t| t) {
        return smoothed_displacements(surface, drift, sigma, interrupt);
    }
    // The plain drift, the masked drift and the trust indicator diffused together: one
    // pass over the neighbour lists per step instead of three, each channel summed in the
    // same order as `smoothed_displacements` does (identical results).
    let steps = (4.0 * sigma * sigma).round() as usize;
    let mut u: Vec<Channels> = drift
        .iter()
        .zip(trusted)
        .map(|(d, &t)| Channels {
            plain: *d,
            masked: if t { *d } else { DVec3::ZERO },
            weight: if t { 1.0 } else { 0.0 },
        })
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

/// Per vertex, the mean over its quads of the displacement of the quad's centre from
/// `input` to `positions`. Quad centres, not vertices, because the centre of a digital
/// surfel is an unbiased sample of the surface (Gauss digitization: the surface crosses
/// the segment between the two voxel centres uniformly), while the staircase's vertices
/// are not (on a torus of minor radius 8 voxels they sit 0.027 voxel inside on average).
pub(crate) fn surfel_drift(surface: &DigitalSurface, positions: &[DVec3], input: &[DVec3]) -> Vec<DVec3> {
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
        let masked: Vec<DVec3> =
            drift.iter().zip(&trusted).map(|(d, &t)| if t { *d } else { DVec3::ZERO }).collect();
        let weight: Vec<DVec3> = trusted.iter().map(|&t| DVec3::splat(if t { 1.0 } else { 0.0 })).collect();
        let never = Interrupt::never();
        let plain = smoothed_displacements(&surface, &drift, 3.0, &never).unwrap();
        let num = smoothed_displacements(&surface, &masked, 3.0, &never).unwrap();
        let den = smoothed_displacements(&surface, &weight, 3.0, &never).unwrap();
        let expected: Vec<DVec3> =
            num.iter().zip(&den).zip(&plain).map(|((n, w), p)| (*n + 1e-3 * *p) / (w.x + 1e-3)).collect();
        assert_eq!(trusted_drift(&surface, &drift, &trusted, 3.0, &never).unwrap(), expected);
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
