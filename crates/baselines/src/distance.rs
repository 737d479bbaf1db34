//! Point-to-surface distance queries on a triangulated mesh.

use glam::DVec3;

use crate::Mesh;

/// A uniform-grid index over the triangles of a mesh (faces fanned from their first
/// vertex) for exact point-to-surface distances.
///
/// Each triangle is listed in every cell its bounding box overlaps; a query visits rings
/// of cells around the point's cell until no unvisited cell can hold a nearer triangle.
/// Queries near the surface (the use here: a few cells away) cost a few dozen
/// point-triangle distances.
#[derive(Clone, Debug)]
pub struct TriangleIndex {
    triangles: Vec<[DVec3; 3]>,
    lo: DVec3,
    cell: f64,
    dims: [usize; 3],
    starts: Vec<u32>,
    items: Vec<u32>,
}

impl TriangleIndex {
    /// Indexes the triangles of `mesh`'s faces.
    pub fn new(mesh: &Mesh) -> Self {
        let triangles: Vec<[DVec3; 3]> =
            mesh.fan_triangles().map(|(t, _)| t.map(|v| mesh.positions[v as usize])).collect();
        let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
        let mut edge_sum = 0.0;
        for t in &triangles {
            for p in t {
                lo = lo.min(*p);
                hi = hi.max(*p);
            }
            edge_sum += t[0].distance(t[1]) + t[1].distance(t[2]) + t[2].distance(t[0]);
        }
        if triangles.is_empty() {
            return TriangleIndex {
                triangles,
                lo: DVec3::ZERO,
                cell: 1.0,
                dims: [1; 3],
                starts: vec![0, 0],
                items: vec![],
            };
        }
        // Cells of about two mean edge lengths, at most ~64^3 of them.
        let extent = (hi - lo).max(DVec3::splat(1e-12));
        let cell =
            (2.0 * edge_sum / (3 * triangles.len()) as f64).max(extent.max_element() / 64.0).max(1e-12);
        let dims = ((extent / cell).floor() + 1.0).to_array().map(|d| d as usize);
        let mut counts = vec![0u32; dims[0] * dims[1] * dims[2] + 1];
        let index = TriangleIndex { triangles, lo, cell, dims, starts: Vec::new(), items: Vec::new() };
        let ranges: Vec<([usize; 3], [usize; 3])> = index
            .triangles
            .iter()
            .map(|t| (index.cell_of(t[0].min(t[1]).min(t[2])), index.cell_of(t[0].max(t[1]).max(t[2]))))
            .collect();
        let for_cells = |(a, b): ([usize; 3], [usize; 3]), f: &mut dyn FnMut(usize)| {
            for z in a[2]..=b[2] {
                for y in a[1]..=b[1] {
                    for x in a[0]..=b[0] {
                        f(x + dims[0] * (y + dims[1] * z));
                    }
                }
            }
        };
        for &r in &ranges {
            for_cells(r, &mut |c| counts[c + 1] += 1);
        }
        for c in 1..counts.len() {
            counts[c] += counts[c - 1];
        }
        let mut fill = counts.clone();
        let mut items = vec![0u32; counts[counts.len() - 1] as usize];
        for (t, &r) in ranges.iter().enumerate() {
            for_cells(r, &mut |c| {
                items[fill[c] as usize] = t as u32;
                fill[c] += 1;
            });
        }
        TriangleIndex { starts: counts, items, ..index }
    }

    fn cell_of(&self, p: DVec3) -> [usize; 3] {
        let c = ((p - self.lo) / self.cell).floor();
        [0, 1, 2].map(|k| (c[k].max(0.0) as usize).min(self.dims[k] - 1))
    }

    /// Number of indexed triangles.
    pub fn num_triangles(&self) -> usize {
        self.triangles.len()
    }

    /// The distance from `p` to the nearest indexed triangle (infinite for an empty mesh).
    pub fn distance(&self, p: DVec3) -> f64 {
        self.nearest(p).map_or(f64::INFINITY, |q| p.distance(q))
    }

    /// The point of the indexed surface nearest to `p`, if any.
    pub fn nearest(&self, p: DVec3) -> Option<DVec3> {
        if self.triangles.is_empty() {
            return None;
        }
        let c = self.cell_of(p);
        let [nx, ny, nz] = self.dims;
        let max_ring = nx.max(ny).max(nz);
        let mut best = (f64::INFINITY, p);
        for r in 0..=max_ring {
            let ri = r as i64;
            for dz in -ri..=ri {
                for dy in -ri..=ri {
                    for dx in -ri..=ri {
                        if dx.abs().max(dy.abs()).max(dz.abs()) != ri {
                            continue;
                        }
                        let (x, y, z) = (c[0] as i64 + dx, c[1] as i64 + dy, c[2] as i64 + dz);
                        if x < 0 || y < 0 || z < 0 || x >= nx as i64 || y >= ny as i64 || z >= nz as i64 {
                            continue;
                        }
                        let cell = x as usize + nx * (y as usize + ny * z as usize);
                        for &t in &self.items[self.starts[cell] as usize..self.starts[cell + 1] as usize] {
                            let q = closest_on_triangle(p, &self.triangles[t as usize]);
                            let d = p.distance_squared(q);
                            if d < best.0 {
                                best = (d, q);
                            }
                        }
                    }
                }
            }
            // Cells of ring r + 1 and beyond are at least r cells away from p.
            if best.0.sqrt() <= r as f64 * self.cell {
                break;
            }
        }
        Some(best.1)
    }
}

/// The point of triangle `t` nearest to `p` (Ericson, *Real-Time Collision Detection*,
/// 5.1.5).
pub(crate) fn closest_on_triangle(p: DVec3, t: &[DVec3; 3]) -> DVec3 {
    let [a, b, c] = *t;
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return a + ab * (d1 / (d1 - d3));
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return a + ac * (d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
    }
    let denom = va + vb + vc;
    if denom == 0.0 {
        // Degenerate triangle: the nearest of its edges.
        let seg = |u: DVec3, v: DVec3| {
            let d = v - u;
            let l = d.length_squared();
            if l == 0.0 {
                u
            } else {
                u + d * ((p - u).dot(d) / l).clamp(0.0, 1.0)
            }
        };
        return [seg(a, b), seg(b, c), seg(c, a)]
            .into_iter()
            .min_by(|x, y| p.distance_squared(*x).total_cmp(&p.distance_squared(*y)))
            .unwrap_or(a);
    }
    a + ab * (vb / denom) + ac * (vc / denom)
}

#[cfg(test)]
mod tests {
    use super::*;
    use voxreg_testkit::Lcg;

    #[test]
    fn closest_points_on_a_triangle() {
        let t = [DVec3::ZERO, DVec3::X, DVec3::Y];
        assert!(
            closest_on_triangle(DVec3::new(0.2, 0.2, 3.0), &t).distance(DVec3::new(0.2, 0.2, 0.0)) < 1e-15
        );
        assert_eq!(closest_on_triangle(DVec3::new(-1.0, -1.0, 0.0), &t), DVec3::ZERO);
        assert_eq!(closest_on_triangle(DVec3::new(0.5, -2.0, 1.0), &t), DVec3::new(0.5, 0.0, 0.0));
        assert_eq!(closest_on_triangle(DVec3::new(1.0, 1.0, 0.0), &t), DVec3::new(0.5, 0.5, 0.0));
    }

    #[test]
    fn index_agrees_with_brute_force() {
        // A bumpy grid surface, queried at scattered points near and far.
        let n = 12;
        let pos: Vec<DVec3> = (0..n * n)
            .map(|i| {
                let (x, y) = ((i % n) as f64, (i / n) as f64);
                DVec3::new(x, y, (x * 0.7).sin() + (y * 0.4).cos())
            })
            .collect();
        let mut mesh = Mesh::new(pos);
        for y in 0..n - 1 {
            for x in 0..n - 1 {
                let v = (x + n * y) as u32;
                mesh.push_face(&[v, v + 1, v + 1 + n as u32, v + n as u32]);
            }
        }
        let index = TriangleIndex::new(&mesh);
        let tris: Vec<[DVec3; 3]> =
            mesh.fan_triangles().map(|(t, _)| t.map(|v| mesh.positions[v as usize])).collect();
        let mut rng = Lcg::new(12345);
        for _ in 0..300 {
            let p = DVec3::new(rng.range(-2.0, 14.0), rng.range(-2.0, 14.0), rng.range(-5.0, 5.0));
            let brute =
                tris.iter().map(|t| p.distance(closest_on_triangle(p, t))).fold(f64::INFINITY, f64::min);
            assert!((index.distance(p) - brute).abs() < 1e-12, "{p}");
        }
    }
}
