//! Self-intersections of quad meshes: a uniform grid of face boxes, then exact-style
//! triangle-triangle tests (each quad split into two triangles).

use std::collections::HashMap;

use glam::DVec3;
use rayon::prelude::*;

/// A face whose box spans more grid cells than this is tested against every face instead
/// of being entered in the grid, so one huge face cannot blow the grid up.
const MAX_CELLS_PER_FACE: u64 = 64;

/// Each vertex's smallest-index twin at the same position (bit for bit), so that
/// duplicated vertices (a split pinch, a seam) count as shared.
fn welded(positions: &[DVec3]) -> Vec<u32> {
    let mut first: HashMap<[u64; 3], u32> = HashMap::with_capacity(positions.len());
    positions
        .iter()
        .enumerate()
        .map(|(i, p)| *first.entry(p.to_array().map(f64::to_bits)).or_insert(i as u32))
        .collect()
}

/// The pairs `(a, b)`, `a < b`, of quads of the mesh that intersect, sorted.
///
/// Each quad `[v0, v1, v2, v3]` is embedded as the triangles `(v0, v1, v2)` and
/// `(v0, v2, v3)` (so inside the convex hull of its vertices, rule (i) of the paper's
/// Proposition 2). Quads that share a vertex (adjacent across an edge or at a corner)
/// are never reported, whatever their geometry; vertices at the same position (bit for
/// bit) count as one, so duplicated pinch vertices are shared too. Two quads touching at
/// a point or along a segment without sharing a vertex are reported. Quads with an index
/// out of range or a non-finite position are ignored.
///
/// Cost: a grid of cells about the mean edge length; each quad is tested against the
/// quads whose boxes overlap its own, in parallel. Linear in the number of quads on
/// meshes with bounded local density (digital surfaces and their regularizations); a
/// quad whose box spans more than a few dozen cells is tested against every quad
/// instead, so memory stays linear whatever the geometry.
pub fn self_intersections(positions: &[DVec3], quads: &[[u32; 4]]) -> Vec<(usize, usize)> {
    let n = positions.len();
    let valid = |q: &[u32; 4]| q.iter().all(|&v| (v as usize) < n && positions[v as usize].is_finite());
    let weld = welded(positions);
    let canonical: Vec<[u32; 4]> =
        quads.iter().map(|q| if valid(q) { q.map(|v| weld[v as usize]) } else { *q }).collect();
    let boxes: Vec<Option<(DVec3, DVec3)>> = quads
        .par_iter()
        .map(|q| {
            valid(q).then(|| {
                let p = q.map(|v| positions[v as usize]);
                (p[0].min(p[1]).min(p[2]).min(p[3]), p[0].max(p[1]).max(p[2]).max(p[3]))
            })
        })
        .collect();
    let (mut lo, mut hi, mut size, mut count) = (DVec3::INFINITY, DVec3::NEG_INFINITY, 0.0, 0usize);
    for (a, b) in boxes.iter().flatten() {
        lo = lo.min(*a);
        hi = hi.max(*b);
        size += (*b - *a).max_element();
        count += 1;
    }
    if count < 2 || !lo.is_finite() || !hi.is_finite() {
        return Vec::new();
    }
    // Cells about twice the mean box size, and at most ~2^20 per axis.
    let extent = (hi - lo).max_element().max(f64::MIN_POSITIVE);
    let cell = (2.0 * size / count as f64).max(extent / (1 << 20) as f64).max(f64::MIN_POSITIVE);
    let cell_of = |p: DVec3| ((p - lo) / cell).floor().as_uvec3().min(glam::UVec3::splat((1 << 21) - 1));
    let key = |c: glam::UVec3| (u64::from(c.z) << 42) | (u64::from(c.y) << 21) | u64::from(c.x);
    let cells = |(a, b): (glam::UVec3, glam::UVec3)| {
        let d = (b - a).as_u64vec3() + glam::U64Vec3::ONE;
        d.x.saturating_mul(d.y).saturating_mul(d.z)
    };
    let all_ranges: Vec<Option<(glam::UVec3, glam::UVec3)>> =
        boxes.par_iter().map(|b| b.map(|(a, b)| (cell_of(a), cell_of(b)))).collect();
    // Faces too large for the grid: tested against every face below.
    let big: Vec<usize> =
        (0..quads.len()).filter(|&f| all_ranges[f].is_some_and(|r| cells(r) > MAX_CELLS_PER_FACE)).collect();
    let ranges: Vec<Option<(glam::UVec3, glam::UVec3)>> =
        all_ranges.iter().map(|r| r.filter(|r| cells(*r) <= MAX_CELLS_PER_FACE)).collect();
    let mut entries: Vec<(u64, u32)> = ranges
        .par_iter()
        .enumerate()
        .flat_map_iter(|(f, r)| {
            let mut out = Vec::new();
            if let Some((a, b)) = r {
                for z in a.z..=b.z {
                    for y in a.y..=b.y {
                        for x in a.x..=b.x {
                            out.push((key(glam::UVec3::new(x, y, z)), f as u32));
                        }
                    }
                }
            }
            out
        })
        .collect();
    entries.par_sort_unstable();
    let cell_faces = |k: u64| {
        let start = entries.partition_point(|e| e.0 < k);
        let end = entries.partition_point(|e| e.0 <= k);
        entries[start..end].iter().map(|e| e.1 as usize)
    };

    let mut pairs: Vec<(usize, usize)> = (0..quads.len())
        .into_par_iter()
        .flat_map_iter(|a| {
            let mut out = Vec::new();
            let (Some((ba_lo, ba_hi)), Some((ca, cb))) = (boxes[a], ranges[a]) else { return out };
            let qa = quads[a];
            for z in ca.z..=cb.z {
                for y in ca.y..=cb.y {
                    for x in ca.x..=cb.x {
                        let c = glam::UVec3::new(x, y, z);
                        for b in cell_faces(key(c)) {
                            if b <= a {
                                continue;
                            }
                            let Some((bb_lo, bb_hi)) = boxes[b] else { continue };
                            if ba_lo.cmpgt(bb_hi).any() || bb_lo.cmpgt(ba_hi).any() {
                                continue;
                            }
                            // Test each pair once: in the first cell both ranges share.
                            let (cc, _) = ranges[b].expect("a box has a range");
                            if ca.max(cc) != c {
                                continue;
                            }
                            let qb = quads[b];
                            if canonical[a].iter().any(|v| canonical[b].contains(v)) {
                                continue;
                            }
                            if quads_intersect(positions, qa, qb) {
                                out.push((a, b));
                            }
                        }
                    }
                }
            }
            out
        })
        .collect();
    // The large faces, against every other face with an overlapping box.
    let mut extra: Vec<(usize, usize)> = big
        .par_iter()
        .flat_map_iter(|&a| {
            let (lo_a, hi_a) = boxes[a].expect("a big face has a box");
            let (canonical, boxes, ranges) = (&canonical, &boxes, &ranges);
            (0..quads.len()).filter_map(move |b| {
                let (lo_b, hi_b) = boxes[b]?;
                let other_big = ranges[b].is_none();
                // A pair of two big faces is tested once, from the smaller index.
                if b == a || (other_big && b < a) || lo_a.cmpgt(hi_b).any() || lo_b.cmpgt(hi_a).any() {
                    return None;
                }
                if canonical[a].iter().any(|v| canonical[b].contains(v)) {
                    return None;
                }
                quads_intersect(positions, quads[a], quads[b]).then_some((a.min(b), a.max(b)))
            })
        })
        .collect();
    pairs.append(&mut extra);
    pairs.sort_unstable();
    pairs.dedup();
    pairs
}

fn triangles(positions: &[DVec3], q: [u32; 4]) -> [[DVec3; 3]; 2] {
    let p = q.map(|v| positions[v as usize]);
    [[p[0], p[1], p[2]], [p[0], p[2], p[3]]]
}

fn quads_intersect(positions: &[DVec3], a: [u32; 4], b: [u32; 4]) -> bool {
    let (ta, tb) = (triangles(positions, a), triangles(positions, b));
    ta.iter().any(|s| tb.iter().any(|t| triangles_intersect(s, t)))
}

/// Whether two closed triangles intersect (touching counts). Degenerate triangles are
/// handled as the segments or points they are.
pub fn triangles_intersect(a: &[DVec3; 3], b: &[DVec3; 3]) -> bool {
    let scale = a.iter().chain(b).map(|p| p.abs().max_element()).fold(1.0, f64::max);
    let eps = 1e-12 * scale;
    let lo = a[0].min(a[1]).min(a[2]).max(b[0].min(b[1]).min(b[2]));
    let hi = a[0].max(a[1]).max(a[2]).min(b[0].max(b[1]).max(b[2]));
    if (lo - hi).max_element() > eps {
        return false;
    }
    // Separating axis theorem: face normals, then edge-edge cross products; for coplanar
    // triangles, the in-plane edge normals.
    let na = (a[1] - a[0]).cross(a[2] - a[0]);
    let nb = (b[1] - b[0]).cross(b[2] - b[0]);
    let separated = |axis: DVec3| {
        let len = axis.length();
        if len <= 1e-300 {
            return false;
        }
        let axis = axis / len;
        let pa = a.map(|p| p.dot(axis));
        let pb = b.map(|p| p.dot(axis));
        let (amin, amax) = (pa[0].min(pa[1]).min(pa[2]), pa[0].max(pa[1]).max(pa[2]));
        let (bmin, bmax) = (pb[0].min(pb[1]).min(pb[2]), pb[0].max(pb[1]).max(pb[2]));
        amin > bmax + eps || bmin > amax + eps
    };
    if separated(na) || separated(nb) {
        return false;
    }
    let ea = [a[1] - a[0], a[2] - a[1], a[0] - a[2]];
    let eb = [b[1] - b[0], b[2] - b[1], b[0] - b[2]];
    for u in &ea {
        for v in &eb {
            if separated(u.cross(*v)) {
                return false;
            }
        }
    }
    // Coplanar (or degenerate) configurations: in-plane normals of the edges.
    let normal = if na.length_squared() >= nb.length_squared() { na } else { nb };
    if normal.length_squared() > 0.0 {
        for e in ea.iter().chain(&eb) {
            if separated(e.cross(normal)) {
                return false;
            }
        }
    } else {
        // Both degenerate (segments or points): separate along the edges and their
        // perpendiculars in every axis plane.
        for e in ea.iter().chain(&eb) {
            for k in [DVec3::X, DVec3::Y, DVec3::Z] {
                if separated(*e) || separated(e.cross(k)) {
                    return false;
                }
            }
        }
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tri(a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> [DVec3; 3] {
        [DVec3::from(a), DVec3::from(b), DVec3::from(c)]
    }

    #[test]
    fn triangle_pairs() {
        let t = tri([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]);
        // Crossing.
        assert!(triangles_intersect(&t, &tri([0.2, 0.2, -1.0], [0.2, 0.2, 1.0], [0.3, 0.3, 1.0])));
        // Above.
        assert!(!triangles_intersect(&t, &tri([0.2, 0.2, 0.1], [0.8, 0.1, 0.1], [0.1, 0.8, 0.2])));
        // Coplanar, overlapping and disjoint.
        assert!(triangles_intersect(&t, &tri([0.2, 0.2, 0.0], [2.0, 0.2, 0.0], [0.2, 2.0, 0.0])));
        assert!(!triangles_intersect(&t, &tri([1.0, 1.0, 0.0], [2.0, 1.0, 0.0], [1.0, 2.0, 0.0])));
        // Touching at an edge.
        assert!(triangles_intersect(&t, &tri([1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 0.5])));
        // Piercing through the middle with the plane of the other not separating.
        assert!(triangles_intersect(&t, &tri([0.25, -1.0, -0.5], [0.25, 2.0, -0.5], [0.25, 0.25, 0.5])));
    }

    #[test]
    fn quads_sharing_vertices_are_not_reported() {
        // Two unit squares folded onto each other along a shared edge.
        let p = vec![
            DVec3::new(0.0, 0.0, 0.0),
            DVec3::new(1.0, 0.0, 0.0),
            DVec3::new(1.0, 1.0, 0.0),
            DVec3::new(0.0, 1.0, 0.0),
            DVec3::new(0.0, 0.0, 0.0),
            DVec3::new(1.0, 0.0, 0.0),
        ];
        let quads = vec![[0, 1, 2, 3], [1, 0, 3, 2]];
        assert!(self_intersections(&p, &quads).is_empty());
        // Duplicated vertices at the same positions count as shared too.
        let mut p2 = p.clone();
        p2.push(DVec3::new(1.0, 1.0, 0.0));
        p2.push(DVec3::new(0.0, 1.0, 0.0));
        assert!(self_intersections(&p2, &[[0, 1, 2, 3], [5, 4, 7, 6]]).is_empty());
        // Overlapping squares that share no position do intersect.
        let shifted: Vec<DVec3> = p2[4..].iter().map(|v| *v + DVec3::new(0.5, 0.0, 0.0)).collect();
        let mut p3 = p2[..4].to_vec();
        p3.extend(shifted);
        assert_eq!(self_intersections(&p3, &[[0, 1, 2, 3], [5, 4, 7, 6]]), vec![(0, 1)]);
    }

    #[test]
    fn a_grid_of_crossing_quads() {
        // A horizontal strip of quads and a vertical one crossing it in its middle quad.
        let mut p = Vec::new();
        let mut quads = Vec::new();
        for i in 0..10 {
            let x = i as f64;
            let b = p.len() as u32;
            p.extend([
                DVec3::new(x, 0.0, 0.0),
                DVec3::new(x + 0.9, 0.0, 0.0),
                DVec3::new(x + 0.9, 1.0, 0.0),
                DVec3::new(x, 1.0, 0.0),
            ]);
            quads.push([b, b + 1, b + 2, b + 3]);
        }
        let b = p.len() as u32;
        p.extend([
            DVec3::new(4.5, 0.5, -1.0),
            DVec3::new(4.6, 0.5, -1.0),
            DVec3::new(4.6, 0.5, 1.0),
            DVec3::new(4.5, 0.5, 1.0),
        ]);
        quads.push([b, b + 1, b + 2, b + 3]);
        assert_eq!(self_intersections(&p, &quads), vec![(4, 10)]);
    }
}
