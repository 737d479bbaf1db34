//! Dual contouring from Hermite data (Ju, Losasso, Schaefer and Warren, SIGGRAPH 2002).

use std::collections::HashMap;

use glam::{DMat3, DVec3};

use crate::linalg::sym_eigen;
use crate::{Mesh, ScalarGrid};

/// Parameters of [`dual_contour`].
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct DcParams {
    /// Singular values of the normal matrix below this fraction of the largest are
    /// dropped in the pseudo-inverse. Default: `0.1`.
    pub truncation: f64,
    /// Whether to clamp each vertex to its cube (not in the original method). Default:
    /// `false`.
    pub clamp_to_cube: bool,
}

impl Default for DcParams {
    fn default() -> Self {
        DcParams { truncation: 0.1, clamp_to_cube: false }
    }
}

/// `grid` with its values quantized to `bits` bits over `[-range, range]` (values
/// beyond are clamped): `2^bits` equal bins, each value replaced by its bin's centre. Zero
/// is a bin boundary, so the sign of every value, and thus the inside at iso-value `0`,
/// is kept. With `bits = 1` the values are `+-range / 2`: the binary map.
pub fn quantize(grid: &ScalarGrid, bits: u32, range: f64) -> ScalarGrid {
    let levels = (1u64 << bits.clamp(1, 52)) as f64;
    grid.map(|v| {
        let x = (v.clamp(-range, range) + range) / (2.0 * range) * levels;
        let bin = if v >= 0.0 {
            x.floor().clamp(levels / 2.0, levels - 1.0)
        } else {
            x.floor().clamp(0.0, levels / 2.0 - 1.0)
        };
        (bin + 0.5) / levels * 2.0 * range - range
    })
}

/// The gradient of `grid` at sample `p` by central differences (one-sided next to a
/// non-finite value).
fn gradient(grid: &ScalarGrid, p: [i64; 3]) -> DVec3 {
    let mut g = DVec3::ZERO;
    let v0 = grid.get(p);
    for k in 0..3 {
        let (mut a, mut b) = (p, p);
        a[k] -= 1;
        b[k] += 1;
        let (va, vb) = (grid.get(a), grid.get(b));
        g[k] = match (va.is_finite(), vb.is_finite(), v0.is_finite()) {
            (true, true, _) => (vb - va) / 2.0,
            (true, false, true) => v0 - va,
            (false, true, true) => vb - v0,
            _ => 0.0,
        } / grid.spacing()[k];
    }
    g
}

/// Hermite data of the crossed grid edge from sample `a` along `axis`: (crossing, unit
/// outward normal).
fn hermite(grid: &ScalarGrid, iso: f64, a: [i64; 3], axis: usize) -> (DVec3, DVec3) {
    let mut b = a;
    b[axis] += 1;
    let (va, vb) = (grid.get(a), grid.get(b));
    let t = (iso - va) / (vb - va);
    let t = if t.is_finite() { t.clamp(0.0, 1.0) } else { 0.5 };
    let s = grid.position(a).lerp(grid.position(b), t);
    let g = gradient(grid, a).lerp(gradient(grid, b), t);
    // Values grow inward, so the outward normal is -g; fall back to the edge direction.
    let mut fallback = DVec3::ZERO;
    fallback[axis] = if va >= iso { 1.0 } else { -1.0 };
    let n = (-g).try_normalize().unwrap_or(fallback);
    (s, n)
}

/// The dual contouring vertex of the cube with minimal sample `m`.
fn cube_vertex(grid: &ScalarGrid, iso: f64, m: [i64; 3], params: &DcParams) -> DVec3 {
    let mut points = Vec::with_capacity(12);
    for axis in 0..3 {
        let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
        for (du, dv) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
            let mut a = m;
            a[u] += du;
            a[v] += dv;
            let mut b = a;
            b[axis] += 1;
            if (grid.get(a) >= iso) != (grid.get(b) >= iso) {
                points.push(hermite(grid, iso, a, axis));
            }
        }
    }
    let c = points.iter().map(|(s, _)| *s).sum::<DVec3>() / points.len().max(1) as f64;
    let mut ata = DMat3::ZERO;
    let mut atb = DVec3::ZERO;
    for (s, n) in &points {
        ata += DMat3::from_cols(*n * n.x, *n * n.y, *n * n.z);
        atb += *n * n.dot(*s - c);
    }
    let (vals, vecs) = sym_eigen(ata);
    let mut x = c;
    for k in 0..3 {
        if vals[k] > params.truncation * params.truncation * vals[0] && vals[k] > 0.0 {
            x += vecs[k] * (vecs[k].dot(atb) / vals[k]);
        }
    }
    if params.clamp_to_cube {
        let lo = grid.position(m);
        x = x.clamp(lo, lo + grid.spacing());
    }
    x
}

/// The dual contouring surface of `value = iso` on `grid` (inside: `value >= iso`),
/// one quad per crossed grid edge.
///
/// **Hermite data.** On every grid edge whose samples straddle the iso-value: the crossing
/// `s_j` (linear interpolation of the values) and a unit normal `n_j` (minus the gradient
/// of the values by central differences at the two samples, interpolated like the
/// crossing). On a 0/1 indicator this is the paper's input of Fig. 7: positions at the
/// midpoints between inside and outside voxels, normals from the gradient of the binary
/// map. On an implicit function quantized to `b` bits ([`quantize`]) it is the input of
/// supplementary Figs. 3-4.
///
/// **Vertices.** One per grid cube with a crossing: the minimizer of the quadratic error
/// function `sum_j (n_j . (v - s_j))^2`, solved about the mass point `c` (the mean of the
/// `s_j`) with the pseudo-inverse of `sum_j n_j n_j^T` whose eigenvalues below
/// `truncation^2` times the largest are dropped (so flat and edge-like cubes put the
/// vertex at the mass point along the undetermined directions).
///
/// **Faces.** One quad per crossed grid edge, joining the vertices of its four cubes,
/// counter-clockwise around the direction from the inside sample to the outside one. The
/// surface is closed and consistently oriented; a cube where two sheets meet gives a
/// non-manifold vertex, as in the original method.
pub fn dual_contour(grid: &ScalarGrid, iso: f64, params: &DcParams) -> Mesh {
    let dims = grid.dims().map(|d| d as i64);
    let mut ids: HashMap<[i64; 3], u32> = HashMap::new();
    let mut positions = Vec::new();
    let mut quads = Vec::new();
    for z in -1..=dims[2] {
        for y in -1..=dims[1] {
            for x in -1..=dims[0] {
                let a = [x, y, z];
                let inside_a = grid.get(a) >= iso;
                for axis in 0..3 {
                    let mut b = a;
                    b[axis] += 1;
                    if inside_a == (grid.get(b) >= iso) {
                        continue;
                    }
                    let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
                    // Cubes around the edge, counter-clockwise around +e_axis.
                    let cubes = [(0, 0), (-1, 0), (-1, -1), (0, -1)].map(|(du, dv)| {
                        let mut m = a;
                        m[u] += du;
                        m[v] += dv;
                        *ids.entry(m).or_insert_with(|| {
                            positions.push(cube_vertex(grid, iso, m, params));
                            (positions.len() - 1) as u32
                        })
                    });
                    quads.push(if inside_a { cubes } else { [cubes[0], cubes[3], cubes[2], cubes[1]] });
                }
            }
        }
    }
    Mesh::from_quads(positions, &quads)
}
