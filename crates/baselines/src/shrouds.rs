//! Shrouds: one vertex per surfel on its dual edge, slice curvature minimization.

use glam::DVec3;
use voxreg_digisurf::{DigitalSurface, EdgeId, EdgeKind, SurfelId, VertexId};

use crate::{BaselineError, Mesh};

/// Parameters of [`shrouds`].
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct ShroudsParams {
    /// Margin `eps` keeping each vertex strictly inside its dual edge: `t` in
    /// `[eps, 1 - eps]`. Default: `0.05`.
    pub eps: f64,
    /// Fraction of the optimal step taken at each update, in `(0, 1]`. Default: `0.5`.
    pub damping: f64,
    /// Maximum number of sweeps over the vertices. Default: `200`.
    pub max_iterations: usize,
    /// Stop when no parameter `t` moved by more than this in a sweep. Default: `1e-4`.
    pub tolerance: f64,
}

impl Default for ShroudsParams {
    fn default() -> Self {
        ShroudsParams { eps: 0.05, damping: 0.5, max_iterations: 200, tolerance: 1e-4 }
    }
}

/// What [`shrouds`] reports.
#[derive(Clone, Debug, PartialEq)]
pub struct ShroudsInfo {
    /// Sweeps done.
    pub iterations: usize,
    /// The largest change of a parameter `t` in the last sweep.
    pub last_step: f64,
    /// The curvature energy at the start (all `t = 1/2`).
    pub energy_before: f64,
    /// The curvature energy at the end.
    pub energy_after: f64,
    /// The final parameter `t` of each surfel's vertex.
    pub parameters: Vec<f64>,
}

/// Per surfel: the inner voxel centre, the dual edge vector, its axis, and its two
/// neighbours in the slice perpendicular to each other axis `b` (`slices[s][b]`).
struct Setup {
    origin: Vec<DVec3>,
    dir: Vec<DVec3>,
    axis: Vec<u8>,
    slices: Vec<[[u32; 2]; 3]>,
}

/// The two slice axes of a surfel perpendicular to `axis`.
fn slice_axes(axis: u8) -> [usize; 2] {
    [(axis as usize + 1) % 3, (axis as usize + 2) % 3]
}

fn setup(surface: &DigitalSurface) -> Result<Setup, BaselineError> {
    if surface.has_open_border() {
        return Err(BaselineError::Unsupported(
            "shrouds needs closed surfaces (the volume has no background)".into(),
        ));
    }
    let spacing = surface.spacing();
    let mut origin = Vec::with_capacity(surface.num_surfels());
    let mut dir = Vec::with_capacity(surface.num_surfels());
    let mut slices = Vec::with_capacity(surface.num_surfels());
    let mut axis = Vec::with_capacity(surface.num_surfels());
    for (s, sf) in surface.surfels().iter().enumerate() {
        let centre = sf.vertices.iter().map(|&v| surface.vertex_position(v)).sum::<DVec3>() / 4.0;
        let d = sf.normal() * spacing[sf.axis as usize];
        origin.push(centre - d / 2.0);
        dir.push(d);
        let mut slot = [[u32::MAX; 2]; 3];
        for e in surface.surfel_edges(SurfelId(s as u32)) {
            let other = across(surface, SurfelId(s as u32), e)?;
            // The edge's axis b names the slice (perpendicular to b).
            let b = surface.edges()[e.index()].axis as usize;
            let j = usize::from(slot[b][0] != u32::MAX);
            slot[b][j] = other.0;
        }
        slices.push(slot);
        axis.push(sf.axis);
    }
    Ok(Setup { origin, dir, axis, slices })
}

/// The curvature vector of vertex `i` in slice `k` with lengths `len` (to its two
/// neighbours), its weight and the coefficient of `x_i` in it.
fn curvature(x: &[DVec3], i: usize, nbrs: [u32; 2], len: [f64; 2]) -> (DVec3, f64, f64) {
    let (lm, ln) = (len[0].max(1e-12), len[1].max(1e-12));
    let cm = 2.0 / ((lm + ln) * lm);
    let cn = 2.0 / ((lm + ln) * ln);
    let k = cm * (x[nbrs[0] as usize] - x[i]) + cn * (x[nbrs[1] as usize] - x[i]);
    (k, (lm + ln) / 2.0, -(cm + cn))
}

fn lengths(x: &[DVec3], setup: &Setup) -> Vec<[[f64; 2]; 3]> {
    (0..x.len())
        .map(|i| {
            let mut l = [[0.0; 2]; 3];
            for b in slice_axes(setup.axis[i]) {
                l[b] = setup.slices[i][b].map(|j| x[i].distance(x[j as usize]));
            }
            l
        })
        .collect()
}

/// The terms of the energy that depend on `x_i`, with lengths from the positions: the
/// curvature of `i` and of its neighbours in both slices.
fn local_energy(x: &[DVec3], i: usize, setup: &Setup) -> f64 {
    let term = |j: usize, k: usize| {
        let nb = setup.slices[j][k];
        let len = nb.map(|m| x[j].distance(x[m as usize]));
        let (kv, w, _) = curvature(x, j, nb, len);
        w * kv.length_squared()
    };
    slice_axes(setup.axis[i])
        .into_iter()
        .map(|k| term(i, k) + setup.slices[i][k].iter().map(|&j| term(j as usize, k)).sum::<f64>())
        .sum()
}

fn energy(x: &[DVec3], setup: &Setup, len: &[[[f64; 2]; 3]]) -> f64 {
    let slices = &setup.slices;
    (0..x.len())
        .map(|i| {
            slice_axes(setup.axis[i])
                .into_iter()
                .map(|k| {
                    let (kv, w, _) = curvature(x, i, slices[i][k], len[i][k]);
                    w * kv.length_squared()
                })
                .sum::<f64>()
        })
        .sum()
}

/// The Shrouds surface of a closed digital surface: one vertex per surfel, one polygon
/// per fan of surfels around a surface vertex. Vertex `i` of the mesh is surfel `i`'s.
///
/// Shrouds (Williams et al., *Shrouds: optimal separating surfaces for enumerated
/// volumes*, VisSym 2003) as described in section 1 of the supplementary material, with
/// the choices made here where that description is vague.
///
/// **Vertices and faces.** One vertex per surfel, on the surfel's *dual edge*, the segment
/// from its inner voxel centre `a` to its outer voxel centre `b`:
/// `x(t) = (1 - t) a + t b`, `t` in `[eps, 1 - eps]`, starting at the surfel centre
/// (`t = 1/2`). Faces are dual to the digital surface's vertices: one polygon (3 to 6
/// sides) per lattice corner, through its surfels in cyclic order, oriented outward.
///
/// **Slices.** A surfel perpendicular to axis `a` lies in the two axis slices
/// perpendicular to the other axes `b`; in the slice perpendicular to `b`, its
/// neighbours along the slice's contour are the surfels across its two edges parallel to
/// `b`. So every vertex has two neighbours `m`, `n` in each of its two slices.
///
/// **Energy (our choice).** The supplementary linearizes the Euler-Lagrange equation of
/// the continuous squared curvature and leaves several terms unspecified. We minimize the
/// discrete squared curvature of every slice contour instead:
///
/// ```text
/// E = sum_i sum_{slices of i} w_i |k_i|^2,   k_i = 2 / (l_m + l_n) * ((x_n - x_i) / l_n - (x_i - x_m) / l_m),
///                                          w_i = (l_m + l_n) / 2,
/// ```
///
/// with `l_m`, `l_n` the lengths to the neighbours. As in the supplementary, the process
/// alternates two steps: estimate the parameterization (the lengths, then frozen), and
/// move each vertex along its dual edge towards the exact minimizer of `E` in its own `t`
/// (its curvature and that of its four neighbours), damped by `damping`, clamped to
/// `[eps, 1 - eps]`, visiting vertices in surfel order (Gauss-Seidel). Since the true
/// energy's lengths move with the vertex, a step is halved until the true local energy
/// does not increase: the energy decreases monotonically. It stops after
/// `max_iterations` sweeps or when no `t` moves by more than `tolerance`.
/// (Why this energy: see docs/design/shrouds-energy.md.)
///
/// **Closed surfaces only**, as in the paper: a volume with background and two regions.
/// Edges must have two surfels, or four at an edge pinch, where the two diagonal voxels
/// are kept apart (each surfel continues with the other surfel of its own voxel, as the
/// marching cubes face rule does); a pinched vertex gets one polygon per fan. Junctions
/// between three or more regions give [`BaselineError::Unsupported`].
pub fn shrouds(
    surface: &DigitalSurface,
    params: &ShroudsParams,
) -> Result<(Mesh, ShroudsInfo), BaselineError> {
    if !(params.eps >= 0.0 && params.eps < 0.5 && params.damping > 0.0 && params.damping <= 1.0) {
        return Err(BaselineError::InvalidInput(format!("bad shrouds parameters {params:?}")));
    }
    let setup = setup(surface)?;
    let (origin, dir, slices) = (&setup.origin, &setup.dir, &setup.slices);
    let faces = dual_faces(surface)?;
    let n = origin.len();
    let mut t = vec![0.5; n];
    let mut x: Vec<DVec3> = (0..n).map(|i| origin[i] + dir[i] * t[i]).collect();
    let energy_before = energy(&x, &setup, &lengths(&x, &setup));
    let (mut iterations, mut last_step) = (0, 0.0);
    while iterations < params.max_iterations {
        let len = lengths(&x, &setup);
        last_step = 0.0f64;
        for i in 0..n {
            // E restricted to t_i is quadratic: sum over the curvature terms containing
            // x_i of w |k + c d dt|^2.
            let (mut num, mut den) = (0.0, 0.0);
            for k in slice_axes(setup.axis[i]) {
                let (kv, w, c) = curvature(&x, i, slices[i][k], len[i][k]);
                let g = c * dir[i];
                num += w * kv.dot(g);
                den += w * g.length_squared();
                for &j in &slices[i][k] {
                    let j = j as usize;
                    // i is j's neighbour in the same slice.
                    let (kj, wj, _) = curvature(&x, j, slices[j][k], len[j][k]);
                    let pos = usize::from(slices[j][k][1] as usize == i);
                    let (lm, ln) = (len[j][k][0].max(1e-12), len[j][k][1].max(1e-12));
                    let cj = 2.0 / ((lm + ln) * [lm, ln][pos]);
                    let g = cj * dir[i];
                    num += wj * kj.dot(g);
                    den += wj * g.length_squared();
                }
            }
            if den <= 0.0 {
                continue;
            }
            // The step of the frozen-length quadratic, damped and clamped; halved until
            // the true local energy (lengths updated) does not increase.
            let target = (t[i] - num / den).clamp(params.eps, 1.0 - params.eps);
            let before = local_energy(&x, i, &setup);
            let old = t[i];
            let mut step = params.damping * (target - old);
            for _ in 0..8 {
                x[i] = origin[i] + dir[i] * (old + step);
                if local_energy(&x, i, &setup) <= before {
                    break;
                }
                step /= 2.0;
            }
            if local_energy(&x, i, &setup) > before {
                step = 0.0;
            }
            t[i] = old + step;
            x[i] = origin[i] + dir[i] * t[i];
            last_step = last_step.max(step.abs());
        }
        iterations += 1;
        if last_step <= params.tolerance {
            break;
        }
    }
    let energy_after = energy(&x, &setup, &lengths(&x, &setup));
    let mut mesh = Mesh::new(x);
    faces.iter().for_each(|f| mesh.push_face(f));
    Ok((mesh, ShroudsInfo { iterations, last_step, energy_before, energy_after, parameters: t }))
}

/// One polygon per surface vertex through its surfels, counter-clockwise around the
/// outward normal: from surfel `s`, the next is the one across the edge from the vertex
/// to its predecessor in `s`.
/// The surfel across edge `e` from surfel `s`: the other one on a manifold edge; on an
/// edge pinch (two diagonal voxels of a region touching along `e`), the other surfel of
/// the same inner voxel, so that the two voxels are kept apart (inside 6-connected, as in
/// [`marching_cubes`](crate::marching_cubes)).
fn across(surface: &DigitalSurface, s: SurfelId, e: EdgeId) -> Result<SurfelId, BaselineError> {
    let incident = surface.edge_surfels(e);
    match (incident.len(), surface.edges()[e.index()].kind) {
        (2, _) => Ok(if incident[0] == s { incident[1] } else { incident[0] }),
        (4, EdgeKind::Pinch) => {
            let inner = surface.surfel(s).voxels()[0];
            incident
                .iter()
                .copied()
                .find(|&o| o != s && surface.surfel(o).voxels()[0] == inner)
                .ok_or_else(|| BaselineError::Unsupported("an edge pinch without a pair".into()))
        }
        (n, kind) => Err(BaselineError::Unsupported(format!(
            "shrouds needs a closed surface between two regions; an edge has {n} surfels ({kind:?})"
        ))),
    }
}

/// One polygon per fan of surfels around each surface vertex (one fan, or several at a
/// pinch), counter-clockwise around the outward normal: from surfel `s`, the next is the
/// one across the edge from the vertex to its predecessor in `s`.
fn dual_faces(surface: &DigitalSurface) -> Result<Vec<Vec<u32>>, BaselineError> {
    let mut faces = Vec::with_capacity(surface.num_vertices());
    for v in 0..surface.num_vertices() {
        let vid = VertexId(v as u32);
        let around = surface.vertex_surfels(vid);
        let mut used = vec![false; around.len()];
        for first in 0..around.len() {
            if used[first] {
                continue;
            }
            let mut face = Vec::with_capacity(around.len());
            let mut s = around[first];
            loop {
                let k = around.iter().position(|&o| o == s).expect("fans stay around the vertex");
                if used[k] {
                    break;
                }
                used[k] = true;
                face.push(s.0);
                let i = surface
                    .surfel(s)
                    .vertices
                    .iter()
                    .position(|&w| w == vid)
                    .expect("surfel around its vertex");
                s = across(surface, s, surface.surfel_edges(s)[(i + 3) % 4])?;
            }
            if s != around[first] || face.len() < 3 {
                return Err(BaselineError::Unsupported(
                    "the surfels around a vertex do not close into fans".into(),
                ));
            }
            faces.push(face);
        }
    }
    Ok(faces)
}
