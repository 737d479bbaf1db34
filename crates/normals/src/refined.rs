//! Normals re-estimated from a regularized geometry (the refinement rounds).

use std::collections::VecDeque;

use glam::{DMat3, DVec3};
use rayon::prelude::*;
use voxreg_digisurf::{DigitalSurface, SurfelId, VertexId};

use crate::eigen::symmetric_eigen;
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
/// Away from junctions the average is a first-order fit evaluated at `c_f` (the mean
/// normal plus the fitted slope of the quad normals times `c_f - mean centre`), not the
/// plain mean, which is the normal at the disc's weighted centre; next to a junction the
/// plain mean is kept (the fit, extrapolated from quads bent by the other interfaces,
/// feeds back through the rounds; see docs/design/junctions.md).
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

/// Per surfel, whether one of its vertices is on a junction (its quads span three regions
/// or more).
fn junction_surfels(surface: &DigitalSurface) -> Vec<bool> {
    let junction: Vec<bool> = (0..surface.num_vertices())
        .into_par_iter()
        .map(|v| {
            let mut regions =
                surface.vertex_surfels(VertexId(v as u32)).iter().flat_map(|s| surface.surfel(*s).regions);
            let first = regions.next();
            let second = regions.find(|r| Some(*r) != first);
            second.is_some_and(|b| regions.any(|r| Some(r) != first && r != b))
        })
        .collect();
    surface.surfels().par_iter().map(|s| s.vertices.iter().any(|v| junction[v.index()])).collect()
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
    let at_junction = junction_surfels(surface);
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
                let mut fit = FirstOrder::default();
                let mut near_junction = false;
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
                    near_junction |= at_junction[g];
                    sum += (1.0 - d / r) * a * dot.signum();
                    if len > 0.0 {
                        fit.add((1.0 - d / r) * len, a / len * dot.signum(), centres[g] - cf);
                    }
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
                let m = if near_junction { sum } else { fit.at_origin(r).unwrap_or(sum) }.normalize_or_zero();
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

/// A weighted first-order fit of unit normals `u` against positions `c` (relative to the
/// quad being estimated): `u(c) ~ u_mean + J (c - c_mean)`, evaluated at `c = 0`.
///
/// Why: the plain weighted mean is the normal at the disc's weighted centre, not at the
/// quad's. Where the disc is one-sided (next to a junction curve, a feature, or an open
/// rim, where only one side's quads count) the two are a voxel or more apart, and on a
/// curved interface the mean is tilted by that distance over the radius of curvature
/// (three degrees on a sphere of radius 20, which pulls a junction a tenth of a voxel off
/// its curve). The first-order term removes that tilt; on a symmetric disc the centres
/// nearly coincide and it changes little.
#[derive(Default)]
struct FirstOrder {
    w: f64,
    wu: DVec3,
    wc: DVec3,
    wcc: DMat3,
    wuc: DMat3,
}

impl FirstOrder {
    fn add(&mut self, w: f64, u: DVec3, c: DVec3) {
        self.w += w;
        self.wu += w * u;
        self.wc += w * c;
        self.wcc += outer(w * c, c);
        self.wuc += outer(w * u, c);
    }

    /// The fitted normal at the origin (not normalized), `None` without weight. The
    /// positions' covariance is inverted only along directions where the disc spans at
    /// least a tenth of the radius `r` (so a thin strip of quads gives no slope across it),
    /// and the correction is kept below a quarter of the mean normal.
    fn at_origin(&self, r: f64) -> Option<DVec3> {
        if self.w <= 0.0 {
            return None;
        }
        let mean_u = self.wu / self.w;
        let mean_c = self.wc / self.w;
        let ccov = self.wcc / self.w - outer(mean_c, mean_c);
        let ucov = self.wuc / self.w - outer(mean_u, mean_c);
        let (values, vectors) = symmetric_eigen(ccov);
        let floor = (0.1 * r).powi(2);
        // J (0 - mean_c) = ucov C^+ (-mean_c).
        let mut solved = DVec3::ZERO;
        for (l, e) in values.iter().zip(vectors) {
            if *l > floor {
                solved += e * (e.dot(-mean_c) / l);
            }
        }
        let mut correction = ucov * solved;
        let cap = 0.25 * mean_u.length();
        if correction.length() > cap {
            correction *= cap / correction.length();
        }
        Some(mean_u + correction)
    }
}

fn outer(a: DVec3, b: DVec3) -> DMat3 {
    DMat3::from_cols(a * b.x, a * b.y, a * b.z)
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
        let at_junction = junction_surfels(surface);
        let mut seen = vec![false; n];
        (0..n)
            .map(|f| {
                let nf = field.as_slice()[f];
                let regions = surface.surfels()[f].regions;
                let mut sum = DVec3::ZERO;
                let mut fit = FirstOrder::default();
                let mut near_junction = false;
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
                    near_junction |= at_junction[g];
                    sum += (1.0 - d / r) * a * dot.signum();
                    if len > 0.0 {
                        fit.add((1.0 - d / r) * len, a / len * dot.signum(), centres[g] - centres[f]);
                    }
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
                let m = if near_junction { sum } else { fit.at_origin(r).unwrap_or(sum) }.normalize_or_zero();
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
