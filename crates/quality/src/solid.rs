//! Where a closed mesh puts the voxels it came from: inside or outside, and how deep.
//!
//! The measurements of voxel art's targets, one definition for the tests, `voxreg check`
//! and xtask. Distances are in voxels (positions are mapped to voxel coordinates first).

use std::collections::HashMap;

use glam::DVec3;
use rayon::prelude::*;

/// A binary voxel grid placed in space: voxel `(i, j, k)` has its centre at
/// `origin + (i, j, k) * spacing`; voxels outside `dims` are empty.
#[derive(Clone, Debug)]
pub struct Occupancy {
    /// Voxels along x, y and z.
    pub dims: [usize; 3],
    /// Whether each voxel is solid, x fastest (`i + dims[0] * (j + dims[1] * k)`).
    pub solid: Vec<bool>,
    /// The centre of voxel `(0, 0, 0)`.
    pub origin: DVec3,
    /// The voxel size along each axis.
    pub spacing: DVec3,
}

impl Occupancy {
    /// The grid of `dims` voxels whose voxel `[i, j, k]` is solid when `f([i, j, k])`.
    pub fn from_fn(
        dims: [usize; 3],
        origin: DVec3,
        spacing: DVec3,
        mut f: impl FnMut([usize; 3]) -> bool,
    ) -> Self {
        let mut solid = Vec::with_capacity(dims.iter().product());
        for k in 0..dims[2] {
            for j in 0..dims[1] {
                for i in 0..dims[0] {
                    solid.push(f([i, j, k]));
                }
            }
        }
        Occupancy { dims, solid, origin, spacing }
    }

    /// Whether voxel `v` (possibly outside the grid) is solid.
    pub fn get(&self, v: [i64; 3]) -> bool {
        let d = self.dims.map(|d| d as i64);
        if (0..3).any(|a| v[a] < 0 || v[a] >= d[a]) {
            return false;
        }
        self.solid[(v[0] + d[0] * (v[1] + d[1] * v[2])) as usize]
    }

    /// Whether solid voxel `v` is thin: both its neighbours along some axis are empty.
    pub fn is_thin(&self, v: [i64; 3]) -> bool {
        self.get(v)
            && (0..3).any(|a| {
                let (mut lo, mut hi) = (v, v);
                lo[a] -= 1;
                hi[a] += 1;
                !self.get(lo) && !self.get(hi)
            })
    }

    /// For each quad of a staircase (`staircase`: voxel faces, corners on the lattice of
    /// voxel corners), whether a voxel on either side of it is thin.
    pub fn thin_quads(&self, staircase: &[DVec3], quads: &[[u32; 4]]) -> Vec<bool> {
        quads
            .iter()
            .map(|q| {
                let c = q.iter().map(|&v| staircase[v as usize]).sum::<DVec3>() / 4.0;
                let n = super::vector_area(q.map(|v| staircase[v as usize])).normalize_or_zero();
                [-0.5, 0.5].iter().any(|&side| {
                    let v = ((c + side * n * self.spacing - self.origin) / self.spacing).round();
                    self.is_thin([v.x as i64, v.y as i64, v.z as i64])
                })
            })
            .collect()
    }

    /// The staircase a clamped mesh came from: each vertex moved back to the nearest
    /// voxel corner. `None` unless every quad is then a voxel face (an axis-aligned square
    /// of the voxel's size), as for meshes whose vertices stayed within half a voxel of
    /// their corners (the voxel-art preset's).
    pub fn staircase_of(&self, positions: &[DVec3], quads: &[[u32; 4]]) -> Option<Vec<DVec3>> {
        let corner = |p: DVec3| {
            let k = ((p - self.origin) / self.spacing + 0.5).round();
            self.origin + (k - 0.5) * self.spacing
        };
        let stair: Vec<DVec3> = positions.iter().map(|&p| corner(p)).collect();
        let faces = quads.iter().all(|q| {
            let c = q.map(|v| stair.get(v as usize).copied().unwrap_or(DVec3::NAN));
            let edges = [c[1] - c[0], c[2] - c[1], c[3] - c[2], c[0] - c[3]];
            let axis = |e: DVec3| (0..3).filter(|&a| e[a] != 0.0).count() == 1;
            let n = super::vector_area(c);
            edges.iter().all(|&e| axis(e)) && (0..3).filter(|&a| n[a] != 0.0).count() == 1
        });
        faces.then_some(stair)
    }

    /// Whether voxel `v` has a 6-neighbour of the other state (so a face of the surface).
    fn on_surface(&self, v: [i64; 3]) -> bool {
        let s = self.get(v);
        (0..6).any(|k| {
            let mut w = v;
            w[k / 2] += if k % 2 == 0 { -1 } else { 1 };
            self.get(w) != s
        })
    }
}

/// What [`solid_report`] measures, distances in voxels.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct SolidReport {
    /// Solid voxels with an empty 6-neighbour.
    pub solid_surface_voxels: usize,
    /// Of those, the ones whose centre the mesh leaves outside.
    pub solid_outside: usize,
    /// Empty voxels (within one voxel of the grid) with a solid 6-neighbour.
    pub empty_surface_voxels: usize,
    /// Of those, the ones whose centre the mesh puts inside.
    pub empty_inside: usize,
    /// Thin voxels (see [`Occupancy::is_thin`]).
    pub thin_voxels: usize,
    /// Thin voxels whose centre is less than `0.25` voxel inside (or outside).
    pub thin_shallow: usize,
    /// The smallest depth of a thin voxel's centre: its distance to the mesh, negative when
    /// outside, at most `1` (depths are searched within one voxel). `1` without thin voxels.
    pub thin_min_depth: f64,
}

/// The triangles `(v0, v1, v2)`, `(v0, v2, v3)` of every valid quad, in voxel coordinates.
fn triangles(occ: &Occupancy, positions: &[DVec3], quads: &[[u32; 4]]) -> Vec<[DVec3; 3]> {
    let n = positions.len();
    let to_voxel = |p: DVec3| (p - occ.origin) / occ.spacing;
    quads
        .iter()
        .filter(|q| q.iter().all(|&v| (v as usize) < n && positions[v as usize].is_finite()))
        .flat_map(|q| {
            let p = q.map(|v| to_voxel(positions[v as usize]));
            [[p[0], p[1], p[2]], [p[0], p[2], p[3]]]
        })
        .collect()
}

/// Unit-cell buckets of triangles: by their (y, z) box for rays along x, and by their 3D
/// box for distances.
struct Buckets {
    tris: Vec<[DVec3; 3]>,
    yz: HashMap<[i64; 2], Vec<u32>>,
    xyz: HashMap<[i64; 3], Vec<u32>>,
}

impl Buckets {
    fn new(tris: Vec<[DVec3; 3]>) -> Buckets {
        let (mut yz, mut xyz) = (HashMap::<[i64; 2], Vec<u32>>::new(), HashMap::<[i64; 3], Vec<u32>>::new());
        for (t, p) in tris.iter().enumerate() {
            let lo = p[0].min(p[1]).min(p[2]).floor().as_i64vec3();
            let hi = p[0].max(p[1]).max(p[2]).floor().as_i64vec3();
            if (hi - lo).max_element() > 4 {
                continue; // far from a regularized voxel surface; not measured
            }
            for z in lo.z..=hi.z {
                for y in lo.y..=hi.y {
                    yz.entry([y, z]).or_default().push(t as u32);
                    for x in lo.x..=hi.x {
                        xyz.entry([x, y, z]).or_default().push(t as u32);
                    }
                }
            }
        }
        Buckets { tris, yz, xyz }
    }

    /// Whether `p` is inside: the parity of the crossings of a ray along +x, started a
    /// hair off the lattice so that it meets no edge or vertex of an unmoved face.
    fn inside(&self, p: DVec3) -> bool {
        let p = p + DVec3::new(0.0, 1.234_567e-7, 2.345_678e-7);
        let key = [p.y.floor() as i64, p.z.floor() as i64];
        let Some(list) = self.yz.get(&key) else { return false };
        let mut crossings = 0usize;
        for &t in list {
            let [a, b, c] = self.tris[t as usize];
            // Barycentric coordinates of (p.y, p.z) in the projected triangle.
            let d = (b.y - a.y) * (c.z - a.z) - (c.y - a.y) * (b.z - a.z);
            if d == 0.0 {
                continue;
            }
            let u = ((p.y - a.y) * (c.z - a.z) - (c.y - a.y) * (p.z - a.z)) / d;
            let v = ((b.y - a.y) * (p.z - a.z) - (p.y - a.y) * (b.z - a.z)) / d;
            if u < 0.0 || v < 0.0 || u + v > 1.0 {
                continue;
            }
            let x = a.x + u * (b.x - a.x) + v * (c.x - a.x);
            if x > p.x {
                crossings += 1;
            }
        }
        crossings % 2 == 1
    }

    /// The distance from `p` to the nearest triangle, at most `1`.
    fn distance(&self, p: DVec3) -> f64 {
        let c = p.floor().as_i64vec3();
        let mut best = 1.0f64;
        for z in c.z - 1..=c.z + 1 {
            for y in c.y - 1..=c.y + 1 {
                for x in c.x - 1..=c.x + 1 {
                    for &t in self.xyz.get(&[x, y, z]).map_or(&[][..], |v| &v[..]) {
                        best = best.min(point_triangle_distance(p, self.tris[t as usize]));
                    }
                }
            }
        }
        best
    }
}

/// The Euclidean distance from `p` to the triangle `t` (Ericson, Real-Time Collision
/// Detection, 5.1.5).
pub fn point_triangle_distance(p: DVec3, t: [DVec3; 3]) -> f64 {
    let [a, b, c] = t;
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return ap.length();
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return bp.length();
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return (p - (a + v * ab)).length();
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return cp.length();
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return (p - (a + w * ac)).length();
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return (p - (b + w * (c - b))).length();
    }
    let denom = va + vb + vc;
    if denom == 0.0 {
        // Degenerate triangle: the nearest of its edges.
        let seg = |a: DVec3, b: DVec3| {
            let d = b - a;
            let l = d.length_squared();
            let s = if l > 0.0 { ((p - a).dot(d) / l).clamp(0.0, 1.0) } else { 0.0 };
            (p - (a + s * d)).length()
        };
        return seg(a, b).min(seg(b, c)).min(seg(a, c));
    }
    let (v, w) = (vb / denom, vc / denom);
    (p - (a + ab * v + ac * w)).length()
}

/// Measures where the closed quad mesh (`positions`, `quads`, triangulated as everywhere
/// in this crate) puts the voxel centres of `occ` next to its surface: solid ones should be
/// inside, empty ones outside, and thin ones at least `0.25` voxel deep.
///
/// Inside is the parity of the crossings of a ray along +x; depths are distances to the
/// nearest triangle searched within one voxel. Cost: linear in voxels and quads.
pub fn solid_report(occ: &Occupancy, positions: &[DVec3], quads: &[[u32; 4]]) -> SolidReport {
    let buckets = Buckets::new(triangles(occ, positions, quads));
    let d = occ.dims.map(|d| d as i64);
    let voxels: Vec<[i64; 3]> = (-1..=d[2])
        .flat_map(|z| (-1..=d[1]).flat_map(move |y| (-1..=d[0]).map(move |x| [x, y, z])))
        .collect();
    let per: Vec<SolidReport> = voxels
        .par_chunks(4096)
        .map(|chunk| {
            let mut r = SolidReport { thin_min_depth: 1.0, ..Default::default() };
            for &v in chunk {
                if !occ.on_surface(v) {
                    continue;
                }
                let p = DVec3::new(v[0] as f64, v[1] as f64, v[2] as f64);
                let inside = buckets.inside(p);
                if occ.get(v) {
                    r.solid_surface_voxels += 1;
                    r.solid_outside += usize::from(!inside);
                    if occ.is_thin(v) {
                        r.thin_voxels += 1;
                        let depth = if inside { buckets.distance(p) } else { -buckets.distance(p) };
                        r.thin_shallow += usize::from(depth < 0.25);
                        r.thin_min_depth = r.thin_min_depth.min(depth);
                    }
                } else {
                    r.empty_surface_voxels += 1;
                    r.empty_inside += usize::from(inside);
                }
            }
            r
        })
        .collect();
    per.into_iter().fold(SolidReport { thin_min_depth: 1.0, ..Default::default() }, |a, b| SolidReport {
        solid_surface_voxels: a.solid_surface_voxels + b.solid_surface_voxels,
        solid_outside: a.solid_outside + b.solid_outside,
        empty_surface_voxels: a.empty_surface_voxels + b.empty_surface_voxels,
        empty_inside: a.empty_inside + b.empty_inside,
        thin_voxels: a.thin_voxels + b.thin_voxels,
        thin_shallow: a.thin_shallow + b.thin_shallow,
        thin_min_depth: a.thin_min_depth.min(b.thin_min_depth),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The staircase of `occ`: one quad per face between a solid and an empty voxel,
    /// oriented outwards, vertices shared by lattice corner.
    fn staircase(occ: &Occupancy) -> (Vec<DVec3>, Vec<[u32; 4]>) {
        let mut ids: HashMap<[i64; 3], u32> = HashMap::new();
        let mut positions = Vec::new();
        let mut quads = Vec::new();
        let d = occ.dims.map(|d| d as i64);
        let mut id = |c: [i64; 3]| {
            *ids.entry(c).or_insert_with(|| {
                positions.push(DVec3::new(c[0] as f64, c[1] as f64, c[2] as f64) - 0.5);
                (positions.len() - 1) as u32
            })
        };
        for z in -1..=d[2] {
            for y in -1..=d[1] {
                for x in -1..=d[0] {
                    let v = [x, y, z];
                    if !occ.get(v) {
                        continue;
                    }
                    for a in 0..3 {
                        for s in [-1i64, 1] {
                            let mut w = v;
                            w[a] += s;
                            if occ.get(w) {
                                continue;
                            }
                            let (b, c) = ((a + 1) % 3, (a + 2) % 3);
                            let mut base = v;
                            if s > 0 {
                                base[a] += 1;
                            }
                            let corner = |db: i64, dc: i64| {
                                let mut k = base;
                                k[b] += db;
                                k[c] += dc;
                                k
                            };
                            let mut q = [corner(0, 0), corner(1, 0), corner(1, 1), corner(0, 1)];
                            if s < 0 {
                                q.reverse();
                            }
                            quads.push(q.map(&mut id));
                        }
                    }
                }
            }
        }
        (positions, quads)
    }

    fn plate() -> Occupancy {
        // A 1 x 4 x 4 plate with one voxel sticking out: every plate voxel is thin along x.
        let dims = [3, 4, 4];
        let mut solid = vec![false; 3 * 4 * 4];
        for z in 0..4 {
            for y in 0..4 {
                solid[1 + 3 * (y + 4 * z)] = true;
            }
        }
        solid[2 + 3 * (1 + 4)] = true; // voxel (2, 1, 1)
        Occupancy { dims, solid, origin: DVec3::ZERO, spacing: DVec3::ONE }
    }

    #[test]
    fn the_staircase_keeps_every_centre_half_a_voxel_deep() {
        let occ = plate();
        let (p, q) = staircase(&occ);
        let r = solid_report(&occ, &p, &q);
        assert_eq!(r.solid_surface_voxels, 17);
        assert_eq!((r.solid_outside, r.empty_inside, r.thin_shallow), (0, 0, 0));
        assert_eq!(r.thin_voxels, 16 - 1 + 1);
        assert!((r.thin_min_depth - 0.5).abs() < 1e-12, "{r:?}");
    }

    #[test]
    fn a_squeezed_plate_is_shallow_and_a_shifted_one_leaves_centres_outside() {
        let occ = plate();
        let (p, q) = staircase(&occ);
        // Squeeze the plate (x in [0.5, 1.5]) to 0.2 voxel thick around its mid-plane.
        let squeezed: Vec<DVec3> = p
            .iter()
            .map(|v| if v.x < 2.0 { DVec3::new(1.0 + (v.x - 1.0) * 0.2, v.y, v.z) } else { *v })
            .collect();
        let r = solid_report(&occ, &squeezed, &q);
        assert!(r.thin_shallow >= 15 && r.thin_min_depth < 0.11, "{r:?}");
        assert_eq!(r.solid_outside, 0);
        // Shifted by 0.6 voxel along x, the plate's centres are all outside and the empty
        // ones on the +x side inside.
        let shifted: Vec<DVec3> = p.iter().map(|v| *v + DVec3::new(0.6, 0.0, 0.0)).collect();
        let r = solid_report(&occ, &shifted, &q);
        assert!(r.solid_outside >= 15 && r.empty_inside >= 15, "{r:?}");
        assert!(r.thin_min_depth < 0.0);
    }

    #[test]
    fn point_triangle_distances_match_the_obvious_cases() {
        let t = [DVec3::ZERO, DVec3::X, DVec3::Y];
        assert!((point_triangle_distance(DVec3::new(0.2, 0.2, 0.5), t) - 0.5).abs() < 1e-12);
        assert!((point_triangle_distance(DVec3::new(-1.0, 0.0, 0.0), t) - 1.0).abs() < 1e-12);
        assert!((point_triangle_distance(DVec3::new(1.0, 1.0, 0.0), t) - 0.5f64.sqrt()).abs() < 1e-12);
    }
}
