//! Marching cubes with tables derived at first use from one face rule.

use std::collections::HashMap;
use std::sync::OnceLock;

use glam::DVec3;
use voxreg_digisurf::LabelVolume;

use crate::{Mesh, ScalarGrid};

/// Corner offset of cube corner `i`.
fn corner(i: usize) -> [i64; 3] {
    [(i & 1) as i64, (i >> 1 & 1) as i64, (i >> 2 & 1) as i64]
}

/// The 12 cube edges as (lower corner, axis), axis-major.
fn edges() -> [(usize, usize); 12] {
    let mut e = [(0, 0); 12];
    let mut n = 0;
    for axis in 0..3 {
        for c in 0..8 {
            if c >> axis & 1 == 0 {
                e[n] = (c, axis);
                n += 1;
            }
        }
    }
    e
}

/// The cube edge joining corners `a` and `b` (which differ in one bit).
fn edge_between(a: usize, b: usize) -> u8 {
    let (lo, axis) = (a.min(b), (a ^ b).trailing_zeros() as usize);
    edges().iter().position(|&e| e == (lo, axis)).expect("corners differ in one bit") as u8
}

/// The cube's faces, each as its 4 corners counter-clockwise around its outward normal.
fn faces() -> [[usize; 4]; 6] {
    let mut out = [[0; 4]; 6];
    for k in 0..3 {
        let (u, v) = ((k + 1) % 3, (k + 2) % 3);
        for side in 0..2 {
            let c = |a: usize, b: usize| side << k | a << u | b << v;
            // (0,0), (1,0), (1,1), (0,1) in (u, v) is counter-clockwise around +e_k.
            let ring = [c(0, 0), c(1, 0), c(1, 1), c(0, 1)];
            out[2 * k + side] = if side == 1 { ring } else { [ring[0], ring[3], ring[2], ring[1]] };
        }
    }
    out
}

fn midpoint(edge: u8) -> DVec3 {
    let (c, axis) = edges()[edge as usize];
    let mut p = DVec3::from_array(corner(c).map(|x| x as f64));
    p[axis] += 0.5;
    p
}

/// The loops of configuration `config` (bit `i` set: corner `i` inside), as cube edges,
/// counter-clockwise around the outward normal.
pub(crate) fn config_loops(config: u8) -> Vec<Vec<u8>> {
    let inside = |c: usize| config >> c & 1 == 1;
    let mut next = [u8::MAX; 12];
    for face in faces() {
        // Crossings in counter-clockwise order, with whether they enter.
        let crossings: Vec<(u8, bool)> = (0..4)
            .filter(|&i| inside(face[i]) != inside(face[(i + 1) % 4]))
            .map(|i| (edge_between(face[i], face[(i + 1) % 4]), inside(face[(i + 1) % 4])))
            .collect();
        for j in 0..crossings.len() {
            if crossings[j].1 {
                next[crossings[j].0 as usize] = crossings[(j + 1) % crossings.len()].0;
            }
        }
    }
    let mut seen = [false; 12];
    let mut loops = Vec::new();
    for start in 0..12u8 {
        if next[start as usize] == u8::MAX || seen[start as usize] {
            continue;
        }
        let mut lp = Vec::new();
        let mut e = start;
        while !seen[e as usize] {
            seen[e as usize] = true;
            lp.push(e);
            e = next[e as usize];
        }
        loops.push(lp);
    }
    loops
}

/// The triangulation of least total area of the polygon `pts` (indices into it).
fn min_area_triangulation(pts: &[DVec3]) -> Vec<[usize; 3]> {
    let n = pts.len();
    let area = |a: usize, b: usize, c: usize| (pts[b] - pts[a]).cross(pts[c] - pts[a]).length() / 2.0;
    // cost[i][j]: best triangulation of the sub-polygon i..=j; split[i][j]: its apex.
    let mut cost = vec![vec![0.0f64; n]; n];
    let mut split = vec![vec![0usize; n]; n];
    for len in 2..n {
        for i in 0..n - len {
            let j = i + len;
            cost[i][j] = f64::INFINITY;
            for k in i + 1..j {
                let c = cost[i][k] + cost[k][j] + area(i, k, j);
                if c < cost[i][j] - 1e-12 {
                    cost[i][j] = c;
                    split[i][j] = k;
                }
            }
        }
    }
    let mut tris = Vec::new();
    let mut stack = vec![(0, n - 1)];
    while let Some((i, j)) = stack.pop() {
        if j < i + 2 {
            continue;
        }
        let k = split[i][j];
        tris.push([i, k, j]);
        stack.push((i, k));
        stack.push((k, j));
    }
    tris
}

/// Triangles of each configuration, as triples of cube edges.
fn table() -> &'static [Vec<[u8; 3]>] {
    static TABLE: OnceLock<Vec<Vec<[u8; 3]>>> = OnceLock::new();
    TABLE.get_or_init(|| {
        (0..=255u8)
            .map(|config| {
                let mut tris = Vec::new();
                for lp in config_loops(config) {
                    let pts: Vec<DVec3> = lp.iter().map(|&e| midpoint(e)).collect();
                    for t in min_area_triangulation(&pts) {
                        tris.push(t.map(|i| lp[i]));
                    }
                }
                tris
            })
            .collect()
    })
}

/// The triangles of the iso-surface `value = iso` of `grid` (inside: `value >= iso`),
/// closed and oriented outward. Vertices are numbered in order of first use, cubes
/// visited `x` fastest: the output is deterministic.
///
/// **Cubes.** A cube has the 8 samples `m + {0,1}^3` as corners (corner `i` at offset
/// `(i & 1, i >> 1 & 1, i >> 2 & 1)`); a corner is inside when its value is `>= iso`.
/// Vertices lie on the cube edges whose corners differ, at the linear interpolation of
/// the iso-value (the midpoint for a 0/1 indicator).
///
/// **The table, derived, not copied.** For each of the 256 corner configurations the
/// polygons are built from the cube's six faces:
///
/// 1. Walk each face's corners counter-clockwise around the face's outward normal; a
///    crossed edge is *entering* (outside corner to inside corner) or *exiting*.
///    Entering and exiting crossings alternate around the face.
/// 2. Each entering crossing is joined by a segment to the next crossing, which exits.
///    This cuts every inside corner off on its own, so on an ambiguous face (two inside
///    corners on a diagonal) the inside corners are separated and the outside ones
///    joined: inside is 6-connected, outside 18-connected. The rule reads only the face,
///    so the two cubes sharing a face draw the same segments (in opposite directions),
///    which makes the surface closed and consistently oriented, whatever the data.
/// 3. Every crossed edge is entering in one of its two faces and exiting in the other, so
///    the segments chain into closed loops, counter-clockwise around the outward normal.
/// 4. Each loop (3 to 12 vertices) is triangulated without new vertices by the
///    triangulation of least total area, with the vertices at edge midpoints (dynamic
///    programming over the polygon; ties go to the first in a fixed order).
///
/// Step 2 is the whole ambiguity resolution: no face or body ambiguity remains (the
/// interior of a cube only joins what its faces joined). Values outside the grid are the
/// grid's exterior value, so a grid whose exterior is outside gives closed surfaces even
/// where the shape touches the grid's border.
pub fn marching_cubes(grid: &ScalarGrid, iso: f64) -> Mesh {
    let table = table();
    let cube_edges = edges();
    let dims = grid.dims();
    let mut ids: HashMap<[i64; 4], u32> = HashMap::new();
    let mut positions = Vec::new();
    let mut triangles = Vec::new();
    for z in -1..dims[2] as i64 {
        for y in -1..dims[1] as i64 {
            for x in -1..dims[0] as i64 {
                let at = |i: usize| {
                    let o = corner(i);
                    [x + o[0], y + o[1], z + o[2]]
                };
                let values: [f64; 8] = std::array::from_fn(|i| grid.get(at(i)));
                let config = (0..8).fold(0u8, |m, i| m | u8::from(values[i] >= iso) << i);
                if config == 0 || config == 255 {
                    continue;
                }
                for tri in &table[config as usize] {
                    let t = tri.map(|e| {
                        let (c, axis) = cube_edges[e as usize];
                        let a = at(c);
                        *ids.entry([a[0], a[1], a[2], axis as i64]).or_insert_with(|| {
                            let mut b = a;
                            b[axis] += 1;
                            let (va, vb) = (values[c], values[c | 1 << axis]);
                            let t = (iso - va) / (vb - va);
                            let t = if t.is_finite() { t.clamp(0.0, 1.0) } else { 0.5 };
                            positions.push(grid.position(a).lerp(grid.position(b), t));
                            (positions.len() - 1) as u32
                        })
                    });
                    triangles.push(t);
                }
            }
        }
    }
    Mesh::from_triangles(positions, &triangles)
}

/// Marching cubes on the indicator of `inside(label)` over `volume` at iso-value `0.5`:
/// the closed, outward-oriented triangle surface of the selected voxels, with vertices
/// at midpoints between voxel centres. For a multi-label volume, call it once per label
/// (`|l| l == k`) to get each label's own closed surface.
pub fn marching_cubes_volume(volume: &LabelVolume, inside: impl Fn(u32) -> bool) -> Mesh {
    marching_cubes(&ScalarGrid::indicator(volume, inside), 0.5)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn corner_configuration_is_one_outward_triangle() {
        let loops = config_loops(1);
        assert_eq!(loops.len(), 1);
        let p: Vec<DVec3> = loops[0].iter().map(|&e| midpoint(e)).collect();
        assert_eq!(p.len(), 3);
        // Counter-clockwise around the normal pointing away from the inside corner 0.
        assert!((p[1] - p[0]).cross(p[2] - p[0]).dot(DVec3::ONE) > 0.0);
    }

    #[test]
    fn complementary_configurations_mirror_except_on_ambiguities() {
        // Unambiguous configurations (no face with two diagonal inside corners and no
        // face with two diagonal outside corners) give the same loops, reversed, as their
        // complement.
        let ambiguous = |c: u8| {
            faces().iter().any(|f| {
                let i: Vec<bool> = f.iter().map(|&k| c >> k & 1 == 1).collect();
                i[0] == i[2] && i[1] == i[3] && i[0] != i[1]
            })
        };
        for config in 0..=255u8 {
            if ambiguous(config) {
                continue;
            }
            let mut a: Vec<Vec<u8>> = config_loops(config)
                .into_iter()
                .map(|mut l| {
                    l.sort_unstable();
                    l
                })
                .collect();
            let mut b: Vec<Vec<u8>> = config_loops(!config)
                .into_iter()
                .map(|mut l| {
                    l.sort_unstable();
                    l
                })
                .collect();
            a.sort();
            b.sort();
            assert_eq!(a, b, "config {config:#010b}");
        }
    }

    #[test]
    fn table_sizes() {
        let t = table();
        assert!(t[0].is_empty() && t[255].is_empty());
        // A loop of k vertices gives k - 2 triangles; at most 4 loops (4 isolated corners).
        for (c, tris) in t.iter().enumerate() {
            let loops = config_loops(c as u8);
            assert_eq!(tris.len(), loops.iter().map(|l| l.len() - 2).sum::<usize>());
            assert!(loops.len() <= 4);
        }
        // Two diagonal corners of a face: two separate triangles.
        assert_eq!(config_loops(0b0000_1001).len(), 2);
        // Two opposite corners of the cube: two triangles.
        assert_eq!(config_loops(0b1000_0001).len(), 2);
    }
}
