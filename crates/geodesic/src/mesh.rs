//! The triangle mesh every method works on: polygons fanned into triangles, edges and
//! their triangles, the vertices that can bend a geodesic.

use glam::DVec3;

use crate::exact::Snapped;
use crate::GeodesicError;

/// A point on the surface: barycentric coordinates on one of [`GeodesicMesh::triangles`]
/// (weights of its three corners, summing to 1).
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct SurfacePoint {
    /// Index into [`GeodesicMesh::triangles`].
    pub triangle: u32,
    /// Weights of the triangle's corners, in its corner order.
    pub barycentric: [f64; 3],
}

/// Barycentric coordinates of the point of triangle `abc` nearest to `p` (Ericson,
/// Real-Time Collision Detection, 5.1.5: the Voronoi regions of the corners, sides and
/// face in turn).
fn closest_on_triangle(p: DVec3, a: DVec3, b: DVec3, c: DVec3) -> [f64; 3] {
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return [1.0, 0.0, 0.0];
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return [0.0, 1.0, 0.0];
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return [1.0 - v, v, 0.0];
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return [0.0, 0.0, 1.0];
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return [1.0 - w, 0.0, w];
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return [0.0, 1.0 - w, w];
    }
    let denom = va + vb + vc;
    if denom.is_nan() || denom == 0.0 {
        // A degenerate triangle: its nearest corner.
        let d = [a, b, c].map(|q| q.distance_squared(p));
        let i = (0..3).min_by(|&i, &j| d[i].total_cmp(&d[j])).unwrap_or(0);
        let mut out = [0.0; 3];
        out[i] = 1.0;
        return out;
    }
    let (v, w) = (vb / denom, vc / denom);
    [1.0 - v - w, v, w]
}

/// A triangle mesh built from positions and polygons (triangles, quads, or any
/// polygon), with the connectivity the geodesic methods need.
///
/// Quads are split along their shorter diagonal, other polygons fanned from their first
/// vertex; every triangle remembers its polygon, so per-polygon results map back onto the
/// input. Edges may be shared by any number of triangles (boundaries and the non-manifold
/// edges of multi-label interfaces are allowed).
#[derive(Clone, Debug)]
pub struct GeodesicMesh {
    pub(crate) positions: Vec<DVec3>,
    pub(crate) triangles: Vec<[u32; 3]>,
    pub(crate) polygons: Vec<Vec<u32>>,
    /// Edge of each triangle side `k`: between corners `k` and `k + 1`.
    pub(crate) triangle_edges: Vec<[u32; 3]>,
    /// Triangles on each edge, compressed: `edge_triangles[edge_offsets[e]..edge_offsets[e + 1]]`.
    pub(crate) edge_offsets: Vec<u32>,
    pub(crate) edge_triangles: Vec<u32>,
    /// Triangles around each vertex, compressed like the edges'.
    pub(crate) vertex_offsets: Vec<u32>,
    pub(crate) vertex_triangles: Vec<u32>,
    /// Vertices through which a shortest path may turn: saddles (angle sum at least
    /// 2 pi), and vertices on boundary or non-manifold edges.
    pub(crate) bends: Vec<bool>,
    /// Connected component of each vertex (through triangles).
    pub(crate) component: Vec<u32>,
    pub(crate) num_components: usize,
}

impl GeodesicMesh {
    /// Builds the mesh of `positions` and `polygons` (vertex indices, at least 3 distinct
    /// per polygon). Refused if an index is out of range, a polygon has fewer than 3
    /// vertices or repeats one, or a position is not finite.
    pub fn new<P: AsRef<[u32]>>(positions: &[DVec3], polygons: &[P]) -> Result<Self, GeodesicError> {
        let n = positions.len();
        if n > u32::MAX as usize {
            return Err(GeodesicError::InvalidMesh(format!("{n} vertices: at most 2^32 - 1")));
        }
        if let Some(i) = positions.iter().position(|p| !p.is_finite()) {
            return Err(GeodesicError::InvalidMesh(format!("vertex {i} at {} is not finite", positions[i])));
        }
        let mut triangles = Vec::new();
        let mut kept = Vec::with_capacity(polygons.len());
        for (f, poly) in polygons.iter().enumerate() {
            let poly = poly.as_ref();
            if poly.len() < 3 {
                return Err(GeodesicError::InvalidMesh(format!("face {f} has {} vertices", poly.len())));
            }
            if let Some(&v) = poly.iter().find(|&&v| v as usize >= n) {
                return Err(GeodesicError::InvalidMesh(format!("face {f} names vertex {v} of {n}")));
            }
            for (i, v) in poly.iter().enumerate() {
                if poly[i + 1..].contains(v) {
                    return Err(GeodesicError::InvalidMesh(format!("face {f} repeats vertex {v}")));
                }
            }
            let p = |i: usize| positions[poly[i] as usize];
            if poly.len() == 4 && p(0).distance_squared(p(2)) > p(1).distance_squared(p(3)) {
                triangles.push([poly[1], poly[2], poly[3]]);
                triangles.push([poly[1], poly[3], poly[0]]);
            } else {
                for i in 1..poly.len() - 1 {
                    triangles.push([poly[0], poly[i], poly[i + 1]]);
                }
            }
            kept.push(poly.to_vec());
        }

        // Edges: sort the triangle sides by their vertex pair.
        let mut sides: Vec<(u32, u32, u32)> = Vec::with_capacity(3 * triangles.len());
        for (t, tri) in triangles.iter().enumerate() {
            for k in 0..3 {
                let (a, b) = (tri[k], tri[(k + 1) % 3]);
                sides.push((a.min(b), a.max(b), (3 * t + k) as u32));
            }
        }
        sides.sort_unstable();
        let mut triangle_edges = vec![[0u32; 3]; triangles.len()];
        let mut edge_offsets = vec![0u32];
        let mut edge_triangles = Vec::with_capacity(sides.len());
        let mut i = 0;
        while i < sides.len() {
            let e = (edge_offsets.len() - 1) as u32;
            let mut j = i;
            while j < sides.len() && sides[j].0 == sides[i].0 && sides[j].1 == sides[i].1 {
                let side = sides[j].2 as usize;
                triangle_edges[side / 3][side % 3] = e;
                edge_triangles.push((side / 3) as u32);
                j += 1;
            }
            edge_offsets.push(edge_triangles.len() as u32);
            i = j;
        }

        let mut counts = vec![0u32; n + 1];
        for tri in &triangles {
            for &v in tri {
                counts[v as usize + 1] += 1;
            }
        }
        for v in 0..n {
            counts[v + 1] += counts[v];
        }
        let vertex_offsets = counts.clone();
        let mut vertex_triangles = vec![0u32; triangles.len() * 3];
        for (t, tri) in triangles.iter().enumerate() {
            for &v in tri {
                vertex_triangles[counts[v as usize] as usize] = t as u32;
                counts[v as usize] += 1;
            }
        }

        let mut angle = vec![0.0f64; n];
        let mut bends = vec![false; n];
        for tri in &triangles {
            for k in 0..3 {
                let (a, b, c) = (tri[k], tri[(k + 1) % 3], tri[(k + 2) % 3]);
                let (pa, pb, pc) = (positions[a as usize], positions[b as usize], positions[c as usize]);
                angle[a as usize] += (pb - pa).angle_between(pc - pa);
            }
        }
        for e in 0..edge_offsets.len() - 1 {
            if edge_offsets[e + 1] - edge_offsets[e] != 2 {
                let t = edge_triangles[edge_offsets[e] as usize] as usize;
                let k =
                    triangle_edges[t].iter().position(|&x| x as usize == e).expect("edge of its triangle");
                bends[triangles[t][k] as usize] = true;
                bends[triangles[t][(k + 1) % 3] as usize] = true;
            }
        }
        for v in 0..n {
            bends[v] |= angle[v] >= 2.0 * std::f64::consts::PI - 1e-9;
        }

        // Components by union-find over the triangles.
        let mut parent: Vec<u32> = (0..n as u32).collect();
        fn find(parent: &mut [u32], mut v: u32) -> u32 {
            while parent[v as usize] != v {
                parent[v as usize] = parent[parent[v as usize] as usize];
                v = parent[v as usize];
            }
            v
        }
        for tri in &triangles {
            let r0 = find(&mut parent, tri[0]);
            for &v in &tri[1..] {
                let r = find(&mut parent, v);
                parent[r as usize] = r0;
            }
        }
        let mut component = vec![u32::MAX; n];
        let mut root_component = vec![u32::MAX; n];
        let mut num_components = 0;
        for v in 0..n {
            let r = find(&mut parent, v as u32) as usize;
            if root_component[r] == u32::MAX {
                root_component[r] = num_components as u32;
                num_components += 1;
            }
            component[v] = root_component[r];
        }

        Ok(GeodesicMesh {
            positions: positions.to_vec(),
            triangles,
            polygons: kept,
            triangle_edges,
            edge_offsets,
            edge_triangles,
            vertex_offsets,
            vertex_triangles,
            bends,
            component,
            num_components,
        })
    }

    /// Number of vertices.
    pub fn num_vertices(&self) -> usize {
        self.positions.len()
    }

    /// The triangles (indices into the positions), in polygon order.
    pub fn triangles(&self) -> &[[u32; 3]] {
        &self.triangles
    }

    /// The vertex nearest to `point` (the first of equals), or `None` for a mesh without
    /// vertices.
    pub fn nearest_vertex(&self, point: DVec3) -> Option<u32> {
        let mut best: Option<(f64, u32)> = None;
        for (v, p) in self.positions.iter().enumerate() {
            let d = p.distance_squared(point);
            if best.is_none_or(|(b, _)| d < b) {
                best = Some((d, v as u32));
            }
        }
        best.map(|(_, v)| v)
    }

    /// The point of the surface nearest to `point` (the first of equals), or `None` for
    /// a mesh without triangles.
    pub fn nearest_point(&self, point: DVec3) -> Option<SurfacePoint> {
        let mut best: Option<(f64, SurfacePoint)> = None;
        for (t, tri) in self.triangles.iter().enumerate() {
            let [a, b, c] = tri.map(|v| self.pos(v));
            let barycentric = closest_on_triangle(point, a, b, c);
            let q = barycentric[0] * a + barycentric[1] * b + barycentric[2] * c;
            let d = q.distance_squared(point);
            if best.is_none_or(|(e, _)| d < e) {
                best = Some((d, SurfacePoint { triangle: t as u32, barycentric }));
            }
        }
        best.map(|(_, p)| p)
    }

    /// Per-polygon values from per-vertex `distances`: the mean over each polygon's
    /// corners (infinite where a corner is unreached).
    pub fn polygon_values(&self, distances: &[f64]) -> Vec<f64> {
        self.polygons
            .iter()
            .map(|p| p.iter().map(|&v| distances[v as usize]).sum::<f64>() / p.len() as f64)
            .collect()
    }

    /// Mean edge length `h` (of the triangles' sides).
    pub fn mean_edge_length(&self) -> f64 {
        let mut sum = 0.0;
        let mut count = 0usize;
        for tri in &self.triangles {
            for k in 0..3 {
                sum += self.pos(tri[k]).distance(self.pos(tri[(k + 1) % 3]));
                count += 1;
            }
        }
        if count == 0 {
            0.0
        } else {
            sum / count as f64
        }
    }

    /// The same triangles with vertices and triangles renumbered along a Morton
    /// (Z-order) curve of their positions (centroids for triangles), ties in input
    /// order, and the maps from this mesh's vertex and triangle indices to the copy's.
    ///
    /// Why: window propagation visits the surface front by front, and in this order the
    /// data of nearby triangles and vertices share cache lines and pages, where the
    /// input order (a voxel scan) scatters every front over the whole mesh.
    pub(crate) fn spatially_ordered(&self) -> Result<(GeodesicMesh, Vec<u32>, Vec<u32>), GeodesicError> {
        let (lo, hi) = self
            .positions
            .iter()
            .fold((DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)), |(a, b), &p| {
                (a.min(p), b.max(p))
            });
        let scale = (hi - lo).max(DVec3::splat(f64::MIN_POSITIVE));
        // 16 bits per axis, interleaved.
        let morton = |p: DVec3| -> u64 {
            let u = ((p - lo) / scale * 65535.0).clamp(DVec3::ZERO, DVec3::splat(65535.0)).as_uvec3();
            let mut key = 0u64;
            for bit in 0..16 {
                for (axis, c) in [u.x, u.y, u.z].into_iter().enumerate() {
                    key |= u64::from((c >> bit) & 1) << (3 * bit + axis);
                }
            }
            key
        };
        let mut order: Vec<u32> = (0..self.positions.len() as u32).collect();
        order.sort_by_cached_key(|&v| morton(self.pos(v)));
        let mut vertex_ids = vec![0u32; order.len()];
        for (new, &v) in order.iter().enumerate() {
            vertex_ids[v as usize] = new as u32;
        }
        let positions: Vec<DVec3> = order.iter().map(|&v| self.pos(v)).collect();
        let mut tri_order: Vec<u32> = (0..self.triangles.len() as u32).collect();
        tri_order.sort_by_cached_key(|&t| {
            morton(self.triangles[t as usize].iter().map(|&v| self.pos(v)).sum::<DVec3>() / 3.0)
        });
        let mut triangle_ids = vec![0u32; tri_order.len()];
        for (new, &t) in tri_order.iter().enumerate() {
            triangle_ids[t as usize] = new as u32;
        }
        let triangles: Vec<[u32; 3]> =
            tri_order.iter().map(|&t| self.triangles[t as usize].map(|v| vertex_ids[v as usize])).collect();
        Ok((GeodesicMesh::new(&positions, &triangles)?, vertex_ids, triangle_ids))
    }

    /// The position of vertex `v`.
    pub fn position(&self, v: u32) -> DVec3 {
        self.positions[v as usize]
    }

    pub(crate) fn pos(&self, v: u32) -> DVec3 {
        self.positions[v as usize]
    }

    pub(crate) fn edge_tris(&self, e: u32) -> &[u32] {
        &self.edge_triangles
            [self.edge_offsets[e as usize] as usize..self.edge_offsets[e as usize + 1] as usize]
    }

    pub(crate) fn vertex_tris(&self, v: u32) -> &[u32] {
        &self.vertex_triangles
            [self.vertex_offsets[v as usize] as usize..self.vertex_offsets[v as usize + 1] as usize]
    }

    /// The position of a surface point.
    pub fn point_position(&self, p: SurfacePoint) -> DVec3 {
        let tri = self.triangles[p.triangle as usize];
        let sum: f64 = p.barycentric.iter().sum();
        (0..3).map(|i| p.barycentric[i] / sum * self.pos(tri[i])).sum()
    }

    /// Checks `points` (at least one, on a triangle of the mesh, barycentric coordinates
    /// finite, not negative, not all zero).
    pub(crate) fn check_points(&self, points: &[SurfacePoint]) -> Result<(), GeodesicError> {
        if points.is_empty() {
            return Err(GeodesicError::NoSource);
        }
        for p in points {
            if p.triangle as usize >= self.triangles.len() {
                return Err(GeodesicError::InvalidSource(format!(
                    "triangle {} of {}",
                    p.triangle,
                    self.triangles.len()
                )));
            }
            let b = p.barycentric;
            if b.iter().any(|x| !x.is_finite() || *x < -1e-9) || b.iter().sum::<f64>() <= 0.0 {
                return Err(GeodesicError::InvalidSource(format!("barycentric coordinates {b:?}")));
            }
        }
        Ok(())
    }

    /// Places a surface point: the vertex it is on, or the triangles it is on (its own,
    /// or all those on the edge it lies on) and its position, within `1e-9` in
    /// barycentric coordinates.
    pub(crate) fn snap(&self, p: SurfacePoint) -> Snapped {
        const SNAP: f64 = 1e-9;
        let tri = self.triangles[p.triangle as usize];
        let sum: f64 = p.barycentric.iter().sum();
        let b = p.barycentric.map(|x| (x / sum).max(0.0));
        if let Some(i) = (0..3).find(|&i| b[i] >= 1.0 - SNAP) {
            return Snapped::Vertex(tri[i]);
        }
        if let Some(i) = (0..3).find(|&i| b[i] <= SNAP) {
            // On the side from corner i + 1 to corner i + 2 (side i + 1).
            let (j, k) = ((i + 1) % 3, (i + 2) % 3);
            let w = b[j] / (b[j] + b[k]);
            let point = w * self.pos(tri[j]) + (1.0 - w) * self.pos(tri[k]);
            let edge = self.triangle_edges[p.triangle as usize][j];
            return Snapped::Point(self.edge_tris(edge).to_vec(), point);
        }
        Snapped::Point(vec![p.triangle], (0..3).map(|i| b[i] * self.pos(tri[i])).sum())
    }

    /// Checks `sources` (vertex indices, at least one, in range).
    pub(crate) fn check_sources(&self, sources: &[u32]) -> Result<(), GeodesicError> {
        if sources.is_empty() {
            return Err(GeodesicError::NoSource);
        }
        if let Some(&s) = sources.iter().find(|&&s| s as usize >= self.positions.len()) {
            return Err(GeodesicError::InvalidSource(format!("vertex {s} of {}", self.positions.len())));
        }
        Ok(())
    }
}

/// Iso-lines of a per-vertex field, for display: level sets `value = k spacing`,
/// `k = 1, 2, ...`.
impl GeodesicMesh {
    /// Per vertex: whether it is the endpoint nearer to a level of some edge crossing it
    /// (one vertex wide lines, for per-vertex colours). Infinite values cross nothing.
    pub fn iso_vertices(&self, values: &[f64], spacing: f64) -> Vec<bool> {
        let mut on = vec![false; self.num_vertices()];
        let level = |x: f64| (x / spacing).floor();
        for tri in &self.triangles {
            for k in 0..3 {
                let (a, b) = (tri[k] as usize, tri[(k + 1) % 3] as usize);
                let (va, vb) = (values[a], values[b]);
                if !(va.is_finite() && vb.is_finite()) || level(va) == level(vb) {
                    continue;
                }
                // The level between them, nearer to which endpoint.
                let l = level(va.max(vb)) * spacing;
                on[if (va - l).abs() <= (vb - l).abs() { a } else { b }] = true;
            }
        }
        on
    }

    /// Per input polygon: whether a level set crosses it (its corners' values straddle a
    /// multiple of `spacing`), for per-face colours.
    pub fn iso_polygons(&self, values: &[f64], spacing: f64) -> Vec<bool> {
        self.polygons
            .iter()
            .map(|p| {
                let levels = p
                    .iter()
                    .map(|&v| values[v as usize])
                    .filter(|x| x.is_finite())
                    .map(|x| (x / spacing).floor());
                let (lo, hi) =
                    levels.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), l| (lo.min(l), hi.max(l)));
                hi > lo
            })
            .collect()
    }
}
