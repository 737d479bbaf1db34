//! Normals re-estimated from a regularized geometry (the refinement rounds).

use std::collections::VecDeque;

use glam::DVec3;
use rayon::prelude::*;
use voxreg_digisurf::{DigitalSurface, SurfelId};

use crate::{NormalError, NormalEstimator, NormalField};

/// Normals re-estimated from positions of the surface's vertices (typically a
/// regularized surface): for each surfel `f`, the normalized, tent-weighted average of
/// the area vectors `a_g` of the quads `g` at those positions
///
/// ```text
/// n'_f = normalize( sum_g (1 - |c_g - c_f| / r) a_g ),
/// ```
///
/// over the quads `g` of the interfaces that share a region with `f`'s (its own, and
/// those that continue it across a junction curve) reached from `f` through edge-adjacent
/// quads of such interfaces whose centres `c_g` stay within `radius` voxels of `c_f` and
/// whose normal is within `feature_angle_deg` of `previous`'s normal at `f` (the feature
/// rule: the two sides of a sharp edge, and interfaces meeting at an angle, never mix).
/// Orientation follows `previous`. A quad with no such neighbour keeps its normal from
/// `previous`.
///
/// Why: after one solve the quads follow the shape far better than the staircase, so
/// their own normals, averaged over a small disc, are a better field than any estimate
/// from the voxels alone.
#[derive(Clone, Copy, Debug)]
pub struct Refined<'a> {
    /// One position per vertex of the surface.
    pub positions: &'a [DVec3],
    /// The field being refined (orientation and the feature rule's reference).
    pub previous: &'a NormalField,
    /// Radius of the averaging disc, in voxels (of the largest spacing).
    pub radius: f64,
    /// The feature rule's angle in degrees.
    pub feature_angle_deg: f64,
}

impl NormalEstimator for Refined<'_> {
    fn name(&self) -> &'static str {
        "refined"
    }

    fn estimate(&self, surface: &DigitalSurface) -> Result<NormalField, NormalError> {
        if self.positions.len() != surface.num_vertices() || self.previous.len() != surface.num_surfels() {
            return Err(NormalError::InvalidParameter(format!(
                "refinement needs {} positions and {} normals, got {} and {}",
                surface.num_vertices(),
                surface.num_surfels(),
                self.positions.len(),
                self.previous.len()
            )));
        }
        if !(self.radius.is_finite() && self.radius > 0.0) {
            return Err(NormalError::InvalidParameter(format!(
                "the refinement radius must be positive and finite, got {}",
                self.radius
            )));
        }
        Ok(refined(surface, self.positions, self.previous, self.radius, self.feature_angle_deg))
    }
}

/// The vector area of surfel `s` at `positions` (half the cross product of its
/// diagonals), pointing like its oriented normal.
fn area_vector(surface: &DigitalSurface, positions: &[DVec3], s: usize) -> DVec3 {
    let [a, b, c, d] = surface.surfels()[s].vertices.map(|v| positions[v.index()]);
    0.5 * (c - a).cross(d - b)
}

/// For each surfel, the other surfels of its interface across each of its edges, in
/// the order of its edges and of each edge's surfels (compressed lists: surfel `g`'s are
/// `adjacent[starts[g]..starts[g + 1]]`). Built once per estimate so the disc searches
/// read one short list per quad instead of walking edges.
fn interface_adjacency(surface: &DigitalSurface) -> (Vec<u32>, Vec<u32>) {
    let lists: Vec<Vec<u32>> = (0..surface.num_surfels())
        .into_par_iter()
        .map(|g| {
            let regions = surface.surfels()[g].regions;
            let mut list = Vec::with_capacity(4);
            for e in surface.surfel_edges(SurfelId(g as u32)) {
                for &k in surface.edge_surfels(e) {
                    let other = surface.surfels()[k.index()].regions;
                    if k.index() != g && regions.iter().any(|r| other.contains(r)) {
                        list.push(k.0);
                    }
                }
            }
            list
        })
        .collect();
    let mut starts = Vec::with_capacity(lists.len() + 1);
    starts.push(0u32);
    let mut adjacent = Vec::with_capacity(lists.iter().map(Vec::len).sum());
    for l in &lists {
        adjacent.extend_from_slice(l);
        starts.push(adjacent.len() as u32);
    }
    (starts, adjacent)
}

fn refined(
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
    let lengths: Vec<f64> = areas.par_iter().map(|a| a.length()).collect();
    let (starts, adjacent) = interface_adjacency(surface);
    let surfels = surface.surfels();
    let normals = field.as_slice();
    let out: Vec<DVec3> = (0..n)
        .into_par_iter()
        .with_min_len(4096)
        .map_init(
            || (vec![false; n], Vec::new(), VecDeque::new()),
            |(seen, touched, queue), f| {
                let nf = normals[f];
                let cf = centres[f];
                let mut sum = DVec3::ZERO;
                let regions_f = surfels[f].regions;
                queue.push_back((f, 0.0));
                seen[f] = true;
                touched.push(f);
                while let Some((g, d)) = queue.pop_front() {
                    let a = areas[g];
                    let len = lengths[g];
                    let dot = if len > 0.0 { a.dot(nf) / len } else { 0.0 };
                    if dot.abs() < cos_max {
                        continue; // across a feature: neither counted nor crossed
                    }
                    sum += (1.0 - d / r) * a * dot.signum();
                    for &k in &adjacent[starts[g] as usize..starts[g + 1] as usize] {
                        let k = k as usize;
                        if !seen[k] && surfels[k].regions.iter().any(|r| regions_f.contains(r)) {
                            let dk = centres[k].distance(cf);
                            if dk < r {
                                seen[k] = true;
                                touched.push(k);
                                queue.push_back((k, dk));
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

#[cfg(test)]
mod tests {
    use voxreg_digisurf::SurfelId;
    use voxreg_testkit::{digitize, Lcg, Sphere, Torus};

    use super::*;

    /// The disc search as first written (edges walked per quad, distances recomputed): the
    /// reference the compressed-adjacency search must match (to rounding: the same terms).
    fn reference(
        surface: &DigitalSurface,
        positions: &[DVec3],
        field: &NormalField,
        radius: f64,
    ) -> Vec<DVec3> {
        let n = surface.num_surfels();
        let r = radius * surface.spacing().max_element();
        let cos_max = 30f64.to_radians().cos();
        let areas: Vec<DVec3> = (0..n).map(|s| area_vector(surface, positions, s)).collect();
        let centres: Vec<DVec3> = surface
            .surfels()
            .iter()
            .map(|s| s.vertices.iter().map(|v| positions[v.index()]).sum::<DVec3>() / 4.0)
            .collect();
        let mut seen = vec![false; n];
        (0..n)
            .map(|f| {
                let nf = field.as_slice()[f];
                let regions = surface.surfels()[f].regions;
                let mut sum = DVec3::ZERO;
                let mut queue = VecDeque::from([f]);
                let mut touched = vec![f];
                seen[f] = true;
                while let Some(g) = queue.pop_front() {
                    let d = centres[g].distance(centres[f]);
                    let a = areas[g];
                    let len = a.length();
                    let dot = if len > 0.0 { a.dot(nf) / len } else { 0.0 };
                    if dot.abs() < cos_max {
                        continue;
                    }
                    sum += (1.0 - d / r) * a * dot.signum();
                    for e in surface.surfel_edges(SurfelId(g as u32)) {
                        for &k in surface.edge_surfels(e) {
                            let k = k.index();
                            let other = surface.surfels()[k].regions;
                            if !seen[k]
                                && surface.surfels()[g].regions.iter().any(|r| other.contains(r))
                                && other.iter().any(|r| regions.contains(r))
                                && centres[k].distance(centres[f]) < r
                            {
                                seen[k] = true;
                                touched.push(k);
                                queue.push_back(k);
                            }
                        }
                    }
                }
                touched.into_iter().for_each(|k| seen[k] = false);
                let m = sum.normalize_or_zero();
                if m == DVec3::ZERO {
                    nf
                } else {
                    m
                }
            })
            .collect()
    }

    #[test]
    fn matches_the_reference_disc_search() {
        let mut rng = Lcg::new(7);
        for volume in
            [digitize(&Sphere { radius: 6.3 }, 1.0), digitize(&Torus { major: 6.0, minor: 2.5 }, 0.5)]
        {
            let surface = DigitalSurface::from_volume(&volume).unwrap();
            let positions: Vec<DVec3> =
                surface.positions().iter().map(|p| *p + 0.3 * rng.vec3(-1.0, 1.0)).collect();
            let field = NormalField::new(surface.surfels().iter().map(|s| s.normal()).collect());
            let fast =
                Refined { positions: &positions, previous: &field, radius: 3.0, feature_angle_deg: 30.0 }
                    .estimate(&surface)
                    .unwrap();
            let slow = reference(&surface, &positions, &field, 3.0);
            for (a, b) in fast.as_slice().iter().zip(&slow) {
                assert!((*a - *b).length() < 1e-13, "{a} vs {b}");
            }
        }
    }
}
