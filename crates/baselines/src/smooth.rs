//! Mesh smoothing: the mesh-denoising stand-in applied to marching-cubes surfaces.

use glam::DVec3;

use crate::Mesh;

/// Parameters of [`laplacian_smooth`].
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct LaplacianParams {
    /// Number of iterations. Default: `10`.
    pub iterations: usize,
    /// Step towards the neighbours' barycenter, in `(0, 1]`. Default: `0.5`.
    pub lambda: f64,
}

impl Default for LaplacianParams {
    fn default() -> Self {
        LaplacianParams { iterations: 10, lambda: 0.5 }
    }
}

/// Parameters of [`taubin_smooth`].
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct TaubinParams {
    /// Number of (shrink, inflate) step pairs. Default: `10`.
    pub iterations: usize,
    /// The shrinking step, positive. Default: `0.5`.
    pub lambda: f64,
    /// The inflating step, negative with `|mu| > lambda`. Default: `-0.53` (pass-band
    /// frequency `1/lambda + 1/mu = 0.113`).
    pub mu: f64,
}

impl Default for TaubinParams {
    fn default() -> Self {
        TaubinParams { iterations: 10, lambda: 0.5, mu: -0.53 }
    }
}

/// One umbrella step: `p_i += factor * (mean of the neighbours of i - p_i)`, all at once.
fn umbrella_step(positions: &mut [DVec3], neighbours: &[Vec<u32>], factor: f64, scratch: &mut Vec<DVec3>) {
    scratch.clear();
    scratch.extend(positions.iter().zip(neighbours).map(|(&p, n)| {
        if n.is_empty() {
            p
        } else {
            let b = n.iter().map(|&j| positions[j as usize]).sum::<DVec3>() / n.len() as f64;
            p + factor * (b - p)
        }
    }));
    positions.copy_from_slice(scratch);
}

/// Uniform Laplacian smoothing (the "umbrella" operator with equal weights), Jacobi
/// style. It smooths and shrinks: on a sphere of `N` vertices each step moves vertices
/// inward by about `lambda` times the local curvature times the squared edge length.
pub fn laplacian_smooth(mesh: &Mesh, params: &LaplacianParams) -> Mesh {
    let neighbours = mesh.vertex_neighbours();
    let mut out = mesh.clone();
    let mut scratch = Vec::new();
    for _ in 0..params.iterations {
        umbrella_step(&mut out.positions, &neighbours, params.lambda, &mut scratch);
    }
    out
}

/// Taubin's lambda/mu smoothing (*A signal processing approach to fair surface design*,
/// SIGGRAPH 1995): alternate umbrella steps of factor `lambda > 0` and `mu < -lambda`,
/// a low-pass filter that removes the staircase's high frequencies without the
/// shrinkage of [`laplacian_smooth`].
pub fn taubin_smooth(mesh: &Mesh, params: &TaubinParams) -> Mesh {
    let neighbours = mesh.vertex_neighbours();
    let mut out = mesh.clone();
    let mut scratch = Vec::new();
    for _ in 0..params.iterations {
        umbrella_step(&mut out.positions, &neighbours, params.lambda, &mut scratch);
        umbrella_step(&mut out.positions, &neighbours, params.mu, &mut scratch);
    }
    out
}
