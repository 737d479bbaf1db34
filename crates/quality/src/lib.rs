//! Mesh quality checks for quad meshes, shared by `voxreg check`, the tests and xtask.
//!
//! A quad `[v0, v1, v2, v3]` is embedded as the triangles `(v0, v1, v2)` and
//! `(v0, v2, v3)`, as voxreg's writers triangulate it. Four defects are counted
//! ([`check`], [`MeshReport`]):
//!
//! - [`self_intersections`]: pairs of faces that meet anywhere but along the edges and
//!   at the corners they share (piercing, folded onto or overlapping a neighbour,
//!   repeated), decided exactly (the papers' Proposition 2 rules them out for clamped
//!   results);
//! - [`invalid_faces`]: faces with a non-finite position or a corner out of range;
//! - [`folded_quads`]: quads bent over their diagonal, their two triangles' normals more
//!   than 90 degrees apart;
//! - [`folded_pairs`]: edge-adjacent quads folded onto each other, their normals more
//!   than 120 degrees apart (across edges that exactly two quads share; at junction and
//!   pinched edges the pairing is ambiguous and left out).
//!
//! Measurements describe how a mesh made from voxels treats them:
//! [`mean_adjacent_angle_deg`] (smoothness: the mean angle between edge-adjacent quads),
//! [`angle_report`] (the same on and off thin voxels, and the angle kept at the voxels'
//! [`hard_edges`]) and [`solid_report`] (which voxel centres of an [`Occupancy`] end up
//! inside, and how deep the thin ones are).
//!
//! # Example
//!
//! ```
//! use glam::DVec3;
//! use voxreg_quality::check;
//!
//! // Two unit squares sharing an edge, the second folded back onto the first.
//! let p = [[0., 0., 0.], [1., 0., 0.], [1., 1., 0.], [0., 1., 0.], [0.1, 0.1, 0.01], [0.1, 0.9, 0.01]];
//! let positions: Vec<DVec3> = p.iter().map(|&a| DVec3::from_array(a)).collect();
//! let quads = [[0, 1, 2, 3], [1, 4, 5, 2]];
//! let report = check(&positions, &quads);
//! assert_eq!(report.folded_pairs, 1);
//! assert_eq!(report.folded_quads, 0);
//! assert!(!report.is_clean());
//! ```
//!
//! # Features
//!
//! None.

mod exact;
mod intersections;
mod solid;

use glam::DVec3;
use rayon::prelude::*;

pub use exact::triangles_meet_off_shared;
pub use intersections::{invalid_faces, self_intersections, triangles_intersect};
pub use solid::{point_triangle_distance, solid_report, Occupancy, SolidReport};

/// What [`check`] counts.
#[derive(Clone, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct MeshReport {
    /// Quads.
    pub faces: usize,
    /// Pairs of faces that intersect ([`self_intersections`]: anywhere but where they
    /// share corners; repeated faces included).
    pub intersecting_pairs: usize,
    /// Faces with a non-finite position or a corner out of range ([`invalid_faces`]).
    pub invalid_faces: usize,
    /// Quads whose two triangles are more than 90 degrees apart.
    pub folded_quads: usize,
    /// Pairs of edge-adjacent quads more than 120 degrees apart.
    pub folded_pairs: usize,
    /// The first intersecting pair, for messages.
    pub first_intersection: Option<(usize, usize)>,
}

impl MeshReport {
    /// No intersection, no invalid face and no fold.
    pub fn is_clean(&self) -> bool {
        self.intersecting_pairs == 0
            && self.invalid_faces == 0
            && self.folded_quads == 0
            && self.folded_pairs == 0
    }
}

/// Every check of this crate on one mesh.
pub fn check(positions: &[DVec3], quads: &[[u32; 4]]) -> MeshReport {
    let pairs = self_intersections(positions, quads);
    MeshReport {
        faces: quads.len(),
        intersecting_pairs: pairs.len(),
        invalid_faces: invalid_faces(positions, quads).len(),
        folded_quads: folded_quads(positions, quads).len(),
        folded_pairs: folded_pairs(positions, quads).len(),
        first_intersection: pairs.first().copied(),
    }
}

/// The normals (unnormalized) of a quad's two triangles `(v0, v1, v2)` and `(v0, v2, v3)`.
fn triangle_normals(p: [DVec3; 4]) -> [DVec3; 2] {
    [(p[1] - p[0]).cross(p[2] - p[0]), (p[2] - p[0]).cross(p[3] - p[0])]
}

fn corners(positions: &[DVec3], q: &[u32; 4]) -> Option<[DVec3; 4]> {
    let n = positions.len();
    q.iter().all(|&v| (v as usize) < n).then(|| q.map(|v| positions[v as usize]))
}

/// The quads bent over their diagonal `v0 v2`: the normals of their two triangles more
/// than 90 degrees apart (a negative dot product). Degenerate triangles do not count.
pub fn folded_quads(positions: &[DVec3], quads: &[[u32; 4]]) -> Vec<usize> {
    quads
        .par_iter()
        .enumerate()
        .filter_map(|(f, q)| {
            let [a, b] = triangle_normals(corners(positions, q)?);
            (a.dot(b) < 0.0).then_some(f)
        })
        .collect()
}

/// The vector area of a quad (half the cross product of its diagonals).
pub(crate) fn vector_area(p: [DVec3; 4]) -> DVec3 {
    0.5 * (p[2] - p[0]).cross(p[3] - p[1])
}

/// The pairs of quads sharing an edge that no other quad shares, with their vector
/// areas, the second one flipped when the pair runs the shared edge in the same direction
/// (so that orientations agree), sorted by pair. Degenerate quads are left out.
fn adjacent_pairs(positions: &[DVec3], quads: &[[u32; 4]]) -> Vec<((usize, usize), DVec3, DVec3)> {
    let mut out = adjacent_pairs_unsorted(positions, quads);
    out.par_sort_unstable_by_key(|x| x.0);
    out
}

/// [`adjacent_pairs`] in the order of their shared edges.
fn adjacent_pairs_unsorted(positions: &[DVec3], quads: &[[u32; 4]]) -> Vec<((usize, usize), DVec3, DVec3)> {
    let out: Vec<((usize, usize), DVec3, DVec3)> = shared_edges(positions, quads)
        .into_par_iter()
        .filter_map(|e| oriented_pair(positions, quads, e))
        .collect();
    out
}

/// The two quads of shared edge `(f, i, g, j)` with their vector areas, the second one
/// flipped when the pair runs the edge in the same direction; `None` when either is
/// degenerate.
fn oriented_pair(
    positions: &[DVec3],
    quads: &[[u32; 4]],
    (f, i, g, j): (usize, usize, usize, usize),
) -> Option<((usize, usize), DVec3, DVec3)> {
    // The edge runs the same way in both quads: one of them is flipped.
    let forward = |f: usize, i: usize| quads[f][i] < quads[f][(i + 1) % 4];
    let same = forward(f, i) == forward(g, j);
    let nf = vector_area(corners(positions, &quads[f])?);
    let mut ng = vector_area(corners(positions, &quads[g])?);
    if same {
        ng = -ng;
    }
    (nf.length() > 0.0 && ng.length() > 0.0).then_some(((f.min(g), f.max(g)), nf, ng))
}

/// The edges exactly two different quads share, as `(f, i, g, j)`: edge `i` of quad `f`
/// (from corner `i` to `i + 1`) is edge `j` of quad `g`, `f < g`, in the order of the
/// edges' corner pairs.
fn shared_edges(positions: &[DVec3], quads: &[[u32; 4]]) -> Vec<(usize, usize, usize, usize)> {
    // Every quad's edges as (undirected edge, quad, slot), sorted by edge then quad: a run
    // of two entries of two quads is a shared edge; longer runs are edges shared by more
    // than two. A sort, not a map of edges: linear memory, no allocation per edge. Four
    // slots a quad, written in place; the edges a quad does not have (a repeated corner,
    // a corner out of range) get the key `u64::MAX`, sorted last and cut off.
    const NONE: (u64, u32, u8) = (u64::MAX, u32::MAX, u8::MAX);
    let mut edges = vec![NONE; 4 * quads.len()];
    edges.par_chunks_mut(4).zip(quads.par_iter()).enumerate().for_each(|(f, (e, q))| {
        let ok = corners(positions, q).is_some();
        for i in 0..4 {
            let (a, b) = (q[i], q[(i + 1) % 4]);
            if ok && a != b {
                e[i] = ((u64::from(a.min(b)) << 32) | u64::from(a.max(b)), f as u32, i as u8);
            }
        }
    });
    edges.par_sort_unstable();
    edges.truncate(edges.partition_point(|e| e.0 != u64::MAX));
    let starts: Vec<usize> =
        (0..edges.len()).into_par_iter().filter(|&i| i == 0 || edges[i - 1].0 != edges[i].0).collect();
    starts
        .par_iter()
        .enumerate()
        .filter_map(|(k, &start)| {
            let end = starts.get(k + 1).copied().unwrap_or(edges.len());
            if end - start != 2 {
                return None;
            }
            let [(_, f, i), (_, g, j)] = [edges[start], edges[start + 1]];
            (f != g).then_some((f as usize, usize::from(i), g as usize, usize::from(j)))
        })
        .collect()
}

/// The pairs `(a, b)`, `a < b`, of quads sharing an edge that no other quad shares, whose
/// vector areas are more than 120 degrees apart once orientations agree (a pair that
/// runs the shared edge in the same direction is oriented oppositely: one normal is
/// flipped first). Sorted.
pub fn folded_pairs(positions: &[DVec3], quads: &[[u32; 4]]) -> Vec<(usize, usize)> {
    folded_pairs_of(positions, quads, &shared_edges(positions, quads))
}

/// [`folded_pairs`] among the given shared edges `(f, i, g, j)`: edge `i` of quad `f`
/// (from corner `i` to `i + 1`) is edge `j` of quad `g`, and no other quad has it. For a
/// caller that knows its mesh's edges (a digital surface does): the same test without
/// the sort that finds them.
pub fn folded_pairs_of(
    positions: &[DVec3],
    quads: &[[u32; 4]],
    shared: &[(usize, usize, usize, usize)],
) -> Vec<(usize, usize)> {
    let cos_max = (120f64).to_radians().cos();
    // Filtered before sorting: the folded pairs are few.
    let mut out: Vec<(usize, usize)> = shared
        .par_iter()
        .filter_map(|&e| oriented_pair(positions, quads, e))
        .filter(|(_, nf, ng)| nf.dot(*ng) < cos_max * nf.length() * ng.length())
        .map(|x| x.0)
        .collect();
    out.sort_unstable();
    out.dedup();
    out
}

/// The mean angle, in degrees, between the normals (vector areas) of quads sharing an
/// edge that no other quad shares: `90 * 2/3`-ish on a staircase, lower when smoother,
/// `0` on a plane (and without such pairs).
pub fn mean_adjacent_angle_deg(positions: &[DVec3], quads: &[[u32; 4]]) -> f64 {
    let pairs = adjacent_angles_deg(positions, quads);
    if pairs.is_empty() {
        return 0.0;
    }
    let sum: f64 = pairs.iter().map(|p| p.1).sum();
    sum / pairs.len() as f64
}

/// The pairs `(a, b)`, `a < b`, of quads sharing an edge that no other quad shares, with
/// the angle in degrees between their normals (vector areas): the terms of
/// [`mean_adjacent_angle_deg`], sorted by pair.
pub fn adjacent_angles_deg(positions: &[DVec3], quads: &[[u32; 4]]) -> Vec<((usize, usize), f64)> {
    adjacent_pairs(positions, quads)
        .into_iter()
        .map(|(p, a, b)| (p, a.angle_between(b).to_degrees()))
        .collect()
}

/// How smooth a mesh made from voxels is, and how sharp it keeps its box edges; angles
/// in degrees ([`angle_report`]).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct AngleReport {
    /// [`mean_adjacent_angle_deg`].
    pub mean: f64,
    /// The mean over the pairs with a quad on a thin voxel, and their count.
    pub thin: (f64, usize),
    /// The mean over the other pairs, and their count.
    pub elsewhere: (f64, usize),
    /// The mean at the staircase's [`hard_edges`] (90 degrees in the voxels), and their
    /// count.
    pub hard_edges: (f64, usize),
}

/// [`AngleReport`] of the mesh (`positions`, `quads`) made from the staircase
/// (`staircase`, the same quads), `thin[f]` saying whether quad `f` lies on a thin voxel
/// ([`Occupancy::thin_quads`]).
pub fn angle_report(
    staircase: &[DVec3],
    positions: &[DVec3],
    quads: &[[u32; 4]],
    thin: &[bool],
) -> AngleReport {
    let angles = adjacent_angles_deg(positions, quads);
    let mean = |it: &mut dyn Iterator<Item = f64>| {
        let (sum, n) = it.fold((0.0, 0usize), |(s, n), a| (s + a, n + 1));
        (if n > 0 { sum / n as f64 } else { 0.0 }, n)
    };
    let on_thin = |(a, b): (usize, usize)| {
        thin.get(a).copied().unwrap_or(false) || thin.get(b).copied().unwrap_or(false)
    };
    let hard = hard_edges(staircase, quads);
    AngleReport {
        mean: mean(&mut angles.iter().map(|x| x.1)).0,
        thin: mean(&mut angles.iter().filter(|x| on_thin(x.0)).map(|x| x.1)),
        elsewhere: mean(&mut angles.iter().filter(|x| !on_thin(x.0)).map(|x| x.1)),
        hard_edges: mean(
            &mut hard
                .iter()
                .filter_map(|p| angles.binary_search_by_key(p, |x| x.0).ok())
                .map(|k| angles[k].1),
        ),
    }
}

/// The deliberate hard edges of a voxel model: the pairs `(a, b)`, `a < b`, of quads
/// sharing an edge that meet at a right angle in `input` (the staircase), where the crease
/// runs straight for at least three edges and both faces are flat at least two quads
/// across it: each quad's neighbours across its other three edges lie in its own plane.
/// A box's edges are hard edges; a staircase's steps, one quad wide, are not. Sorted.
pub fn hard_edges(input: &[DVec3], quads: &[[u32; 4]]) -> Vec<(usize, usize)> {
    let unit = |q: &[u32; 4]| corners(input, q).map(|c| vector_area(c).normalize_or_zero());
    let normals: Vec<Option<DVec3>> = quads.iter().map(unit).collect();
    let shared = shared_edges(input, quads);
    // `across[f][slot]`: the other quad of that edge, where exactly two quads share it.
    let mut across = vec![[u32::MAX; 4]; quads.len()];
    for &(f, i, g, j) in &shared {
        across[f][i] = g as u32;
        across[g][j] = f as u32;
    }
    let flat = |f: usize, slot: usize| {
        let Some(n) = normals[f] else { return false };
        (1..4).all(|k| {
            let g = across[f][(slot + k) % 4];
            g != u32::MAX && normals[g as usize].is_some_and(|m| n.dot(m) > 1.0 - 1e-9)
        })
    };
    let mut out: Vec<(usize, usize)> = shared
        .into_iter()
        .filter_map(|(f, i, g, j)| {
            let (nf, ng) = (normals[f]?, normals[g]?);
            (nf.dot(ng).abs() < 1e-9 && flat(f, i) && flat(g, j)).then(|| (f.min(g), f.max(g)))
        })
        .collect();
    out.sort_unstable();
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(n: u32) -> (Vec<DVec3>, Vec<[u32; 4]>) {
        let mut p = Vec::new();
        for y in 0..=n {
            for x in 0..=n {
                p.push(DVec3::new(f64::from(x), f64::from(y), 0.0));
            }
        }
        let id = |x: u32, y: u32| y * (n + 1) + x;
        let mut q = Vec::new();
        for y in 0..n {
            for x in 0..n {
                q.push([id(x, y), id(x + 1, y), id(x + 1, y + 1), id(x, y + 1)]);
            }
        }
        (p, q)
    }

    #[test]
    fn a_flat_grid_is_clean() {
        let (p, q) = grid(4);
        assert!(check(&p, &q).is_clean());
    }

    #[test]
    fn a_quad_folded_over_its_diagonal_is_found() {
        let (mut p, q) = grid(3);
        // Pull one corner of the middle quad across its diagonal v0 v2.
        let [v0, _, _, v3] = q[4];
        p[v3 as usize] = p[v0 as usize] + DVec3::new(0.8, 0.2, 0.0);
        let folded = folded_quads(&p, &q);
        assert!(folded.contains(&4), "{folded:?}");
    }

    #[test]
    fn adjacent_quads_folded_onto_each_other_are_found() {
        let (mut p, q) = grid(2);
        // Fold the right column back over the left one, hinged on x = 1.
        for v in p.iter_mut() {
            if v.x > 1.5 {
                *v = DVec3::new(0.2, v.y, 0.05);
            }
        }
        let pairs = folded_pairs(&p, &q);
        assert_eq!(pairs, vec![(0, 1), (2, 3)]);
        // A right-angle crease is not a fold.
        let (mut p, q) = grid(2);
        for v in p.iter_mut() {
            if v.x > 1.5 {
                *v = DVec3::new(1.0, v.y, 1.0);
            }
        }
        assert!(folded_pairs(&p, &q).is_empty());
    }

    #[test]
    fn duplicated_vertices_at_one_position_count_as_shared() {
        // Two quads meeting at one corner, the corner duplicated: no intersection.
        let p: Vec<DVec3> = [
            [0., 0., 0.],
            [1., 0., 0.],
            [1., 1., 0.],
            [0., 1., 0.],
            [1., 1., 0.],
            [2., 1., 0.],
            [2., 2., 0.],
            [1., 2., 0.],
        ]
        .iter()
        .map(|&a| DVec3::from_array(a))
        .collect();
        let q = [[0, 1, 2, 3], [4, 5, 6, 7]];
        assert!(self_intersections(&p, &q).is_empty());
    }

    #[test]
    fn one_huge_face_does_not_blow_up_the_grid() {
        let (mut p, mut q) = grid(40);
        let base = p.len() as u32;
        for c in [[-1e6, -1e6, 0.5], [1e6, -1e6, 0.5], [1e6, 1e6, 0.5], [-1e6, 1e6, 0.5]] {
            p.push(DVec3::from_array(c));
        }
        q.push([base, base + 1, base + 2, base + 3]);
        assert!(self_intersections(&p, &q).is_empty());
        // Lowered onto the grid, it crosses every quad.
        for v in &mut p[base as usize..] {
            v.z = 0.0;
        }
        assert_eq!(self_intersections(&p, &q).len(), 40 * 40);
    }

    /// The boundary quads of a set of solid voxels, outward, with shared corners.
    fn voxel_surface(solid: impl Fn([i32; 3]) -> bool, n: i32) -> (Vec<DVec3>, Vec<[u32; 4]>) {
        let mut ids = std::collections::HashMap::new();
        let mut p = Vec::new();
        let mut id = |c: [i32; 3]| {
            *ids.entry(c).or_insert_with(|| {
                p.push(DVec3::new(f64::from(c[0]), f64::from(c[1]), f64::from(c[2])));
                (p.len() - 1) as u32
            })
        };
        let mut q = Vec::new();
        for x in -1..=n {
            for y in -1..=n {
                for z in -1..=n {
                    let v = [x, y, z];
                    if !solid(v) {
                        continue;
                    }
                    for a in 0..3 {
                        for side in [0, 1] {
                            let mut w = v;
                            w[a] += 2 * side - 1;
                            if solid(w) {
                                continue;
                            }
                            let (b, c) = ((a + 1) % 3, (a + 2) % 3);
                            let corner = |db: i32, dc: i32| {
                                let mut k = v;
                                k[a] += side;
                                k[b] += db;
                                k[c] += dc;
                                k
                            };
                            let mut quad = [corner(0, 0), corner(1, 0), corner(1, 1), corner(0, 1)];
                            if side == 0 {
                                quad.reverse();
                            }
                            q.push(quad.map(&mut id));
                        }
                    }
                }
            }
        }
        (p, q)
    }

    #[test]
    fn a_box_has_hard_edges_and_a_staircase_has_none() {
        // A 4 x 4 x 4 box: each of its 12 edges has 4 crease segments, of which the
        // two at the corners have a side neighbour on the third face.
        let inside = |v: [i32; 3], n: i32| v.iter().all(|&c| (0..n).contains(&c));
        let (p, q) = voxel_surface(|v| inside(v, 4), 4);
        assert_eq!(hard_edges(&p, &q).len(), 12 * 2);
        // A slab cut by a 45-degree plane into one-voxel steps: the steps' creases are
        // not hard edges; the five box edges away from the steps are, but for the
        // segments at their ends (4 each).
        let (p, q) = voxel_surface(|v| inside(v, 6) && v[0] <= v[1], 6);
        let hard = hard_edges(&p, &q);
        assert_eq!(hard.len(), 5 * 4);
        let centre = |f: usize| q[f].iter().map(|&v| p[v as usize]).sum::<DVec3>() / 4.0;
        let on_a_step = |f: usize| {
            let c = centre(f);
            (c.z > 0.0 && c.z < 6.0) && c.x > 0.0 && c.y < 6.0
        };
        assert!(hard.iter().all(|&(a, b)| !on_a_step(a) && !on_a_step(b)));
    }

    #[test]
    fn a_clamped_mesh_gives_back_its_staircase_and_its_thin_quads() {
        // A 4 x 4 x 1 plate: every voxel thin (empty above and below).
        let (p, q) = voxel_surface(|v| (0..4).contains(&v[0]) && (0..4).contains(&v[1]) && v[2] == 0, 4);
        let occ = Occupancy::from_fn([4, 4, 1], DVec3::splat(0.5), DVec3::ONE, |_| true);
        // Voxel corners sit at integers here (centres at origin + index).
        let moved: Vec<DVec3> = p
            .iter()
            .enumerate()
            .map(|(i, &v)| v + 0.45 * DVec3::new((i as f64 * 0.7).sin(), (i as f64 * 1.3).cos(), 0.3))
            .collect();
        assert_eq!(occ.staircase_of(&moved, &q), Some(p.clone()));
        assert!(occ.thin_quads(&p, &q).iter().all(|&t| t));
        let report = angle_report(&p, &moved, &q, &occ.thin_quads(&p, &q));
        assert_eq!(report.elsewhere.1, 0);
        assert_eq!(report.thin.1 + report.elsewhere.1, adjacent_angles_deg(&moved, &q).len());
        // A vertex past half a voxel from its corner: no staircase.
        let mut far = moved;
        far[0].x = p[0].x + 0.6;
        assert_eq!(occ.staircase_of(&far, &q), None);
        // A thick box: no thin quad.
        let (p, q) = voxel_surface(|v| v.iter().all(|&c| (0..3).contains(&c)), 3);
        let occ = Occupancy::from_fn([3, 3, 3], DVec3::splat(0.5), DVec3::ONE, |_| true);
        assert!(occ.thin_quads(&p, &q).iter().all(|&t| !t));
    }
}
