//! Metrics: accuracy against an analytic shape, and the quality of a mesh's faces.

use glam::{DMat3, DVec3};

use crate::linalg::sym_eigen;
use crate::{Implicit, Mesh, TriangleIndex};

/// Accuracy of a mesh against the true surface of an [`Implicit`] shape, in the mesh's
/// physical units and degrees ([`accuracy`]).
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct Accuracy {
    /// Mean over vertices of the distance to the true surface.
    pub distance_mean: f64,
    /// Maximum over vertices of the distance to the true surface.
    pub distance_max: f64,
    /// Mean over vertices of the *signed* distance (negative inside): the bias; negative
    /// means the mesh shrank.
    pub bias: f64,
    /// Area-weighted mean over faces of the angle between the face normal (Newell) and
    /// the true outward normal at the point of the surface nearest to the face centroid.
    pub normal_mean_deg: f64,
    /// Maximum of that angle over faces of positive area.
    pub normal_max_deg: f64,
}

/// Vertex distances and face-normal errors of `mesh` against `shape`. Orientation
/// counts: a face whose normal points inward has an error above 90 degrees.
pub fn accuracy(mesh: &Mesh, shape: &dyn Implicit) -> Accuracy {
    let mut acc = Accuracy::default();
    let used = used_vertices(mesh);
    let mut n = 0usize;
    for (p, _) in mesh.positions.iter().zip(&used).filter(|(_, &u)| u) {
        let d = shape.signed_distance(*p);
        acc.distance_mean += d.abs();
        acc.bias += d;
        acc.distance_max = acc.distance_max.max(d.abs());
        n += 1;
    }
    acc.distance_mean /= n.max(1) as f64;
    acc.bias /= n.max(1) as f64;
    let mut area = 0.0;
    for f in 0..mesh.num_faces() {
        let a = mesh.vector_area(f);
        let len = a.length();
        if len == 0.0 {
            continue;
        }
        let truth = shape.normal_near(mesh.centroid(f));
        let angle = (a / len).dot(truth).clamp(-1.0, 1.0).acos().to_degrees();
        acc.normal_mean_deg += len * angle;
        acc.normal_max_deg = acc.normal_max_deg.max(angle);
        area += len;
    }
    acc.normal_mean_deg /= if area > 0.0 { area } else { 1.0 };
    acc
}

fn used_vertices(mesh: &Mesh) -> Vec<bool> {
    let mut used = vec![false; mesh.positions.len()];
    mesh.faces().flatten().for_each(|&v| used[v as usize] = true);
    used
}

/// Mean and maximum of a set of distances.
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct DistanceStats {
    /// Mean.
    pub mean: f64,
    /// Maximum.
    pub max: f64,
}

impl DistanceStats {
    /// The mean and maximum of `values` (zeros for none).
    pub fn of(values: impl IntoIterator<Item = f64>) -> Self {
        let (mut sum, mut max, mut n) = (0.0, 0.0f64, 0usize);
        for v in values {
            sum += v;
            max = max.max(v);
            n += 1;
        }
        DistanceStats { mean: sum / n.max(1) as f64, max }
    }

    /// Both numbers multiplied by `factor` (e.g. `1 / h` for voxel units).
    pub fn scaled(self, factor: f64) -> Self {
        DistanceStats { mean: self.mean * factor, max: self.max * factor }
    }
}

/// Distance from each vertex of `mesh` used by a face to the surface indexed by `target`:
/// with `target` the input digital surface, Proposition 1 of the paper bounds the mean
/// by `C h` for the regularized surface.
pub fn distance_to(mesh: &Mesh, target: &TriangleIndex) -> DistanceStats {
    let used = used_vertices(mesh);
    DistanceStats::of(mesh.positions.iter().zip(&used).filter(|(_, &u)| u).map(|(&p, _)| target.distance(p)))
}

/// Per-vertex displacement `|a_i - b_i|` between two embeddings of the same vertices (for
/// the regularization: output against input, the left side of Proposition 1).
pub fn displacement(a: &[DVec3], b: &[DVec3]) -> DistanceStats {
    DistanceStats::of(a.iter().zip(b).map(|(p, q)| p.distance(*q)))
}

/// Parameters of [`quality`].
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct QualityParams {
    /// A face whose [`face_aspect_ratio`] exceeds this is degenerate. Default: `10`.
    pub degenerate_aspect: f64,
    /// A face whose area is below this fraction of the mean face area is degenerate.
    /// Default: `0.01`.
    pub degenerate_area: f64,
}

impl Default for QualityParams {
    fn default() -> Self {
        QualityParams { degenerate_aspect: 10.0, degenerate_area: 0.01 }
    }
}

/// The shape quality of a mesh's faces ([`quality`]). Areas are relative to the mean
/// face area, except [`Quality::area_mean`].
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct Quality {
    /// Number of faces.
    pub faces: usize,
    /// Mean of [`face_aspect_ratio`] over the faces (infinite ratios excluded).
    pub aspect_mean: f64,
    /// 95th percentile of the aspect ratio.
    pub aspect_p95: f64,
    /// Maximum aspect ratio (infinite for a face whose vertices are collinear).
    pub aspect_max: f64,
    /// Minimum over faces of [`face_scaled_jacobian`].
    pub jacobian_min: f64,
    /// Mean over faces of [`face_scaled_jacobian`].
    pub jacobian_mean: f64,
    /// Mean face area (physical units squared).
    pub area_mean: f64,
    /// Coefficient of variation of the face areas (standard deviation over mean).
    pub area_cv: f64,
    /// Smallest face area over the mean.
    pub area_min: f64,
    /// 5th percentile of the face areas over the mean.
    pub area_p05: f64,
    /// 95th percentile of the face areas over the mean.
    pub area_p95: f64,
    /// Largest face area over the mean.
    pub area_max: f64,
    /// Faces that are degenerate by [`QualityParams`].
    pub degenerate: usize,
    /// Faces with a corner of non-positive scaled Jacobian (folded or collapsed corners).
    pub inverted: usize,
}

/// The aspect ratio of face `f` as in Fig. 9 of the paper: `l1 / l2`, the largest
/// eigenvalue of the covariance matrix of the face's vertices over the second largest.
/// `1` for a square or an equilateral triangle, `3` for a right isosceles triangle,
/// infinite for collinear vertices.
pub fn face_aspect_ratio(mesh: &Mesh, f: usize) -> f64 {
    let c = mesh.centroid(f);
    let mut cov = DMat3::ZERO;
    for p in mesh.face_positions(f) {
        let d = p - c;
        cov += DMat3::from_cols(d * d.x, d * d.y, d * d.z);
    }
    let (l, _) = sym_eigen(cov);
    if l[1] <= 1e-14 * l[0].max(f64::MIN_POSITIVE) {
        f64::INFINITY
    } else {
        l[0] / l[1]
    }
}

/// The scaled Jacobian of face `f`: the minimum over its corners of the sine of the
/// corner angle, signed by the face normal (Newell), i.e. `(e1 x e2) . n / (|e1| |e2|)`
/// with `e1`, `e2` the edges to the next and previous vertices. Triangles are scaled by
/// `2 / sqrt(3)` so that an equilateral triangle scores `1`. `1` for a square, `0` or
/// less for a collapsed or folded corner.
pub fn face_scaled_jacobian(mesh: &Mesh, f: usize) -> f64 {
    let face = mesh.face(f);
    let n = mesh.vector_area(f).normalize_or_zero();
    let scale = if face.len() == 3 { 2.0 / 3f64.sqrt() } else { 1.0 };
    let k = face.len();
    let mut min = f64::INFINITY;
    for i in 0..k {
        let p = mesh.positions[face[i] as usize];
        let e1 = mesh.positions[face[(i + 1) % k] as usize] - p;
        let e2 = mesh.positions[face[(i + k - 1) % k] as usize] - p;
        let d = e1.length() * e2.length();
        let j = if d > 0.0 && n != DVec3::ZERO { e1.cross(e2).dot(n) / d * scale } else { 0.0 };
        min = min.min(j);
    }
    min
}

fn percentile(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return 0.0;
    }
    sorted[((sorted.len() - 1) as f64 * q).round() as usize]
}

/// Aspect ratios, scaled Jacobians and the area distribution of `mesh`'s faces.
pub fn quality(mesh: &Mesh, params: &QualityParams) -> Quality {
    let nf = mesh.num_faces();
    if nf == 0 {
        return Quality::default();
    }
    let areas: Vec<f64> = (0..nf).map(|f| mesh.vector_area(f).length()).collect();
    let aspects: Vec<f64> = (0..nf).map(|f| face_aspect_ratio(mesh, f)).collect();
    let jacobians: Vec<f64> = (0..nf).map(|f| face_scaled_jacobian(mesh, f)).collect();
    let area_mean = areas.iter().sum::<f64>() / nf as f64;
    let var = areas.iter().map(|a| (a - area_mean).powi(2)).sum::<f64>() / nf as f64;
    let rel = |a: f64| if area_mean > 0.0 { a / area_mean } else { 0.0 };
    let mut sorted_areas: Vec<f64> = areas.iter().map(|&a| rel(a)).collect();
    sorted_areas.sort_by(f64::total_cmp);
    let mut sorted_aspects = aspects.clone();
    sorted_aspects.sort_by(f64::total_cmp);
    let finite: Vec<f64> = aspects.iter().copied().filter(|a| a.is_finite()).collect();
    let degenerate = (0..nf)
        .filter(|&f| {
            aspects[f].is_nan()
                || aspects[f] > params.degenerate_aspect
                || rel(areas[f]) < params.degenerate_area
        })
        .count();
    Quality {
        faces: nf,
        aspect_mean: finite.iter().sum::<f64>() / finite.len().max(1) as f64,
        aspect_p95: percentile(&sorted_aspects, 0.95),
        aspect_max: sorted_aspects[nf - 1],
        jacobian_min: jacobians.iter().copied().fold(f64::INFINITY, f64::min),
        jacobian_mean: jacobians.iter().sum::<f64>() / nf as f64,
        area_mean,
        area_cv: if area_mean > 0.0 { var.sqrt() / area_mean } else { 0.0 },
        area_min: sorted_areas[0],
        area_p05: percentile(&sorted_areas, 0.05),
        area_p95: percentile(&sorted_areas, 0.95),
        area_max: sorted_areas[nf - 1],
        degenerate,
        inverted: jacobians.iter().filter(|&&j| j <= 0.0).count(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Ball;

    /// A UV sphere with its vertices exactly on the unit sphere: quads, and triangles at
    /// the poles.
    fn uv_sphere(n: usize) -> Mesh {
        let mut pos = vec![DVec3::Z, -DVec3::Z];
        for i in 1..n {
            let th = std::f64::consts::PI * i as f64 / n as f64;
            for j in 0..2 * n {
                let ph = std::f64::consts::PI * j as f64 / n as f64;
                pos.push(DVec3::new(th.sin() * ph.cos(), th.sin() * ph.sin(), th.cos()));
            }
        }
        let id = |i: usize, j: usize| (2 + (i - 1) * 2 * n + j % (2 * n)) as u32;
        let mut mesh = Mesh::new(pos);
        for j in 0..2 * n {
            mesh.push_face(&[0, id(1, j), id(1, j + 1)]);
            mesh.push_face(&[1, id(n - 1, j + 1), id(n - 1, j)]);
            for i in 1..n - 1 {
                mesh.push_face(&[id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
        }
        mesh
    }

    #[test]
    fn an_exact_sphere_mesh_has_near_zero_errors() {
        let ball = Ball { centre: DVec3::ZERO, radius: 1.0 };
        let coarse = accuracy(&uv_sphere(16), &ball);
        let fine = accuracy(&uv_sphere(64), &ball);
        assert!(fine.distance_max < 1e-12 && fine.bias.abs() < 1e-12);
        // Face normals of an inscribed polyhedron converge to the truth as O(edge length).
        assert!(fine.normal_mean_deg < 1.5 && fine.normal_max_deg < 3.0, "{fine:?}");
        assert!(fine.normal_mean_deg < coarse.normal_mean_deg / 3.0, "{coarse:?} {fine:?}");
    }

    #[test]
    fn a_shifted_sphere_has_the_shift_as_bias() {
        let ball = Ball { centre: DVec3::ZERO, radius: 1.0 };
        let mut mesh = uv_sphere(32);
        mesh.positions.iter_mut().for_each(|p| *p *= 0.9);
        let a = accuracy(&mesh, &ball);
        assert!(
            (a.bias + 0.1).abs() < 1e-12
                && (a.distance_mean - 0.1).abs() < 1e-12
                && (a.distance_max - 0.1).abs() < 1e-12
        );
        // Flipping every face makes every normal wrong.
        let mut flipped = Mesh::new(mesh.positions.clone());
        mesh.faces().for_each(|f| flipped.push_face(&f.iter().rev().copied().collect::<Vec<_>>()));
        assert!(accuracy(&flipped, &ball).normal_mean_deg > 170.0);
    }

    #[test]
    fn aspect_ratio_and_jacobian_of_known_faces() {
        let pos = vec![DVec3::ZERO, DVec3::X, DVec3::new(1.0, 1.0, 0.0), DVec3::Y, DVec3::new(2.0, 0.0, 0.0)];
        let mut m = Mesh::new(pos);
        m.push_face(&[0, 1, 2, 3]); // unit square
        m.push_face(&[0, 1, 3]); // right isosceles triangle
        m.push_face(&[0, 1, 4]); // collinear
        m.push_face(&[0, 4, 2, 3]); // trapezoid
        assert!((face_aspect_ratio(&m, 0) - 1.0).abs() < 1e-12);
        assert!((face_scaled_jacobian(&m, 0) - 1.0).abs() < 1e-12);
        assert!((face_aspect_ratio(&m, 1) - 3.0).abs() < 1e-12);
        assert!((face_scaled_jacobian(&m, 1) - 2.0 / 3f64.sqrt() * 0.5f64.sqrt()).abs() < 1e-12);
        assert!(face_aspect_ratio(&m, 2).is_infinite());
        assert_eq!(face_scaled_jacobian(&m, 2), 0.0);
        assert!((face_scaled_jacobian(&m, 3) - 0.5f64.sqrt()).abs() < 1e-12);
        let q = quality(&m, &QualityParams::default());
        assert_eq!(q.faces, 4);
        assert_eq!(q.degenerate, 1);
        assert_eq!(q.inverted, 1);
        assert!(q.aspect_max.is_infinite());
    }

    #[test]
    fn a_reflex_corner_is_inverted() {
        // An arrowhead: its corner at (0.5, 1) is reflex.
        let pos = vec![
            DVec3::ZERO,
            DVec3::new(2.0, 1.0, 0.0),
            DVec3::new(0.0, 2.0, 0.0),
            DVec3::new(0.5, 1.0, 0.0),
        ];
        let m = Mesh::from_quads(pos, &[[0, 1, 2, 3]]);
        assert!(face_scaled_jacobian(&m, 0) < 0.0);
        assert_eq!(quality(&m, &QualityParams::default()).inverted, 1);
    }
}
