//! Self-intersections of quad meshes: a uniform grid of face boxes, then exact
//! triangle-triangle tests (each quad split into two triangles; see [`crate::exact`]).

use std::collections::HashMap;

use glam::DVec3;
use rayon::prelude::*;

use crate::exact;

/// A face whose box spans more grid cells than this is tested against every face instead
/// of being entered in the grid, so one huge face cannot blow the grid up.
const MAX_CELLS_PER_FACE: u64 = 64;

/// Each vertex's smallest-index twin at the same position, so that duplicated vertices
/// (a split pinch, a seam) count as shared. `-0.0` and `0.0` are one position.
fn welded(positions: &[DVec3]) -> Vec<u32> {
    let mut first: HashMap<[u64; 3], u32> = HashMap::with_capacity(positions.len());
    positions
        .iter()
        .enumerate()
        .map(|(i, p)| *first.entry((*p + DVec3::ZERO).to_array().map(f64::to_bits)).or_insert(i as u32))
        .collect()
}

/// The faces with a corner index out of range or a position that is not finite (NaN or
/// infinite): no geometry to check, a defect of their own.
pub fn invalid_faces(positions: &[DVec3], quads: &[[u32; 4]]) -> Vec<usize> {
    let n = positions.len();
    quads
        .par_iter()
        .enumerate()
        .filter(|(_, q)| !q.iter().all(|&v| (v as usize) < n && positions[v as usize].is_finite()))
        .map(|(f, _)| f)
        .collect()
}

/// The pairs `(a, b)`, `a < b`, of faces of the mesh that intersect, sorted. Exact: every
/// test is decided by exact orientation predicates on the `f64` positions.
///
/// Each quad `[v0, v1, v2, v3]` is embedded as the triangles `(v0, v1, v2)` and
/// `(v0, v2, v3)` (so inside the convex hull of its vertices, rule (i) of the paper's
/// Proposition 2; a triangle is a quad repeating a corner). Vertices at the same position
/// count as one (a split pinch, a seam). Two faces intersect when a triangle of one and a
/// triangle of the other meet anywhere outside the segments between the positions they
/// share: faces sharing an edge may touch along it, faces sharing a corner at it, and
/// faces sharing nothing not at all. (Where a shared corner lies inside a triangle of the
/// other face that does not have it as a corner, a folded face, that triangle is first
/// fanned around it.) So a face piercing its neighbour, folded onto it or
/// overlapping it in their common plane is reported, as is a face touching another
/// without sharing a corner.
///
/// A face with the same corners (after welding, in any order) as an earlier face is
/// reported once, paired with the first such face, and not tested again: thousands of
/// stacked copies of one face make as many pairs, not their square. Faces with an index
/// out of range or a non-finite position are left out here and counted by
/// [`invalid_faces`].
///
/// Cost: a grid of cells about the mean edge length; each quad is tested against the
/// quads whose boxes overlap its own, in parallel. Linear in the number of quads on
/// meshes with bounded local density (digital surfaces and their regularizations); a
/// quad whose box spans more than a few dozen cells is tested against every quad
/// instead, so memory stays linear whatever the geometry.
pub fn self_intersections(positions: &[DVec3], quads: &[[u32; 4]]) -> Vec<(usize, usize)> {
    let n = positions.len();
    let finite = |q: &[u32; 4]| q.iter().all(|&v| (v as usize) < n && positions[v as usize].is_finite());
    let weld = welded(positions);
    let canonical: Vec<[u32; 4]> =
        quads.iter().map(|q| if finite(q) { q.map(|v| weld[v as usize]) } else { *q }).collect();
    // Repeated faces: paired with their first copy, then left out of the geometry.
    let mut first_copy: HashMap<[u32; 4], usize> = HashMap::new();
    let mut duplicates: Vec<(usize, usize)> = Vec::new();
    let mut repeated = vec![false; quads.len()];
    for (f, q) in canonical.iter().enumerate() {
        if !finite(&quads[f]) {
            continue;
        }
        let mut key = *q;
        key.sort_unstable();
        match first_copy.entry(key) {
            std::collections::hash_map::Entry::Occupied(e) => {
                duplicates.push((*e.get(), f));
                repeated[f] = true;
            }
            std::collections::hash_map::Entry::Vacant(e) => {
                e.insert(f);
            }
        }
    }
    let live = |f: usize| !repeated[f] && finite(&quads[f]);
    let boxes: Vec<Option<(DVec3, DVec3)>> = (0..quads.len())
        .into_par_iter()
        .map(|f| {
            let q = &quads[f];
            live(f).then(|| {
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
        return duplicates;
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
                            if quads_intersect(positions, canonical[a], canonical[b]) {
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
                quads_intersect(positions, canonical[a], canonical[b]).then_some((a.min(b), a.max(b)))
            })
        })
        .collect();
    pairs.append(&mut extra);
    pairs.append(&mut duplicates);
    pairs.sort_unstable();
    pairs.dedup();
    pairs
}

/// The two triangles of a quad of welded corner ids, each corner with its position.
fn triangles(positions: &[DVec3], q: [u32; 4]) -> [[(u32, DVec3); 3]; 2] {
    let c = q.map(|v| (v, positions[v as usize]));
    [[c[0], c[1], c[2]], [c[0], c[2], c[3]]]
}

/// Whether two faces (welded corner ids) intersect, as [`self_intersections`] defines it.
fn quads_intersect(positions: &[DVec3], a: [u32; 4], b: [u32; 4]) -> bool {
    let shared: Vec<u32> = a.iter().filter(|v| b.contains(v)).copied().collect();
    let (ta, tb) = (triangles(positions, a), triangles(positions, b));
    ta.iter().any(|s| tb.iter().any(|t| exact::pieces_meet(*s, *t, &shared)))
}

/// Whether two closed triangles intersect (touching counts), exactly. Degenerate
/// triangles are handled as the segments or points they are.
pub fn triangles_intersect(a: &[DVec3; 3], b: &[DVec3; 3]) -> bool {
    exact::simplices_meet(&exact::reduce(a), &exact::reduce(b))
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

    fn pts(a: &[[f64; 3]]) -> Vec<DVec3> {
        a.iter().map(|&p| DVec3::from_array(p)).collect()
    }

    #[test]
    fn neighbours_may_touch_only_where_they_share() {
        // Two unit squares side by side, sharing an edge (and, as copies, its positions).
        let p = pts(&[[0., 0., 0.], [1., 0., 0.], [1., 1., 0.], [0., 1., 0.], [2., 0., 0.], [2., 1., 0.]]);
        assert!(self_intersections(&p, &[[0, 1, 2, 3], [1, 4, 5, 2]]).is_empty());
        let mut copies = p.clone();
        copies.extend(pts(&[[1., 0., 0.], [1., 1., 0.]]));
        assert!(self_intersections(&copies, &[[0, 1, 2, 3], [6, 4, 5, 7]]).is_empty());
        // Folded back onto the first over the shared edge: they overlap.
        let mut folded = p.clone();
        folded[4] = DVec3::new(0.2, 0.0, 0.0);
        folded[5] = DVec3::new(0.2, 1.0, 0.0);
        assert_eq!(self_intersections(&folded, &[[0, 1, 2, 3], [1, 4, 5, 2]]), vec![(0, 1)]);
        // The same square twice (in either orientation).
        assert_eq!(self_intersections(&p, &[[0, 1, 2, 3], [3, 2, 1, 0]]), vec![(0, 1)]);
        // Overlapping squares that share no position.
        let shifted = pts(&[[0.5, 0., 0.], [1.5, 0., 0.], [1.5, 1., 0.], [0.5, 1., 0.]]);
        let mut p3 = p[..4].to_vec();
        p3.extend(shifted);
        assert_eq!(self_intersections(&p3, &[[0, 1, 2, 3], [4, 5, 6, 7]]), vec![(0, 1)]);
    }

    #[test]
    fn a_triangle_piercing_a_neighbour_through_a_shared_corner() {
        // Triangles (quads repeating a corner) sharing the vertex 0; the second passes
        // through the first's interior.
        let p = pts(&[[0., 0., 0.], [4., 0., 0.], [0., 4., 0.], [2., 1., -1.], [1., 2., 1.]]);
        let quads = [[0, 1, 2, 2], [0, 3, 4, 4]];
        assert_eq!(self_intersections(&p, &quads), vec![(0, 1)]);
        // The same with the shared corner as two copies of one position.
        let mut q = p.clone();
        q.push(DVec3::ZERO);
        assert_eq!(self_intersections(&q, &[[0, 1, 2, 2], [5, 3, 4, 4]]), vec![(0, 1)]);
        // Tilted away, it touches only at the corner.
        let mut away = p.clone();
        away[3] = DVec3::new(-1., -1., -1.);
        away[4] = DVec3::new(-1., -2., 1.);
        assert!(self_intersections(&away, &quads).is_empty());
    }

    #[test]
    fn a_shared_corner_inside_a_folded_neighbours_triangle_is_still_shared() {
        // B, flat in y = 0, folded: its corner q lies inside its triangle (p, b1, b2). A
        // hinges on the edge p q that both share: they touch along it only.
        let p = pts(&[[0., 0., 0.], [4., 0., 0.], [4., 0., 4.], [2., 0., 1.], [0., -1., 0.], [2., -1., 1.]]);
        let (b, a) = ([0, 1, 2, 3], [4, 0, 3, 5]);
        assert!(self_intersections(&p, &[a, b]).is_empty());
        // Tilted into B's plane past the edge, A overlaps it.
        let mut flat = p.clone();
        flat[4] = DVec3::new(3.0, 0.0, 0.5);
        flat[5] = DVec3::new(3.5, 0.0, 1.5);
        assert_eq!(self_intersections(&flat, &[a, b]), vec![(0, 1)]);
    }

    #[test]
    fn stacked_copies_of_one_triangle_are_each_reported() {
        let n = 20_000;
        let mut p = Vec::new();
        let mut quads = Vec::new();
        for i in 0..n {
            let b = 3 * i;
            p.extend(pts(&[[0., 0., 0.], [1., 0., 0.], [0., 1., 0.]]));
            quads.push([b, b + 1, b + 2, b + 2]);
        }
        let pairs = self_intersections(&p, &quads);
        assert_eq!(pairs.len(), n as usize - 1);
        assert!(pairs.iter().all(|&(a, _)| a == 0));
    }

    #[test]
    fn faces_without_geometry_are_invalid() {
        let p = pts(&[[f64::NAN; 3], [f64::NAN; 3], [f64::NAN; 3], [f64::NAN; 3], [0., 0., f64::INFINITY]]);
        assert_eq!(invalid_faces(&p, &[[0, 1, 2, 3], [0, 1, 4, 4], [0, 1, 2, 9]]), vec![0, 1, 2]);
        assert!(invalid_faces(&pts(&[[0.; 3]]), &[[0, 0, 0, 0]]).is_empty());
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
