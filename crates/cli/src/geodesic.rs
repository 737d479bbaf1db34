//! `voxreg geodesic`: distances on the regularized (or digital) surface, written as a
//! PLY with a per-vertex `distance` and a colour ramp with iso-lines.

use anyhow::{Context, Result};
use glam::DVec3;
use voxreg_digisurf::DigitalSurface;
use voxreg_geodesic::{distances_from, GeodesicMesh};
use voxreg_io::{scalar_ramp, write_ply_with_vertex_field, Outputs, QuadMesh};

use crate::args::{GeodesicOptions, RegularizeArgs, SurfaceKind};

/// The distance written at vertices that no source reaches (other components).
const UNREACHED: f64 = -1.0;

/// Computes the distances of `opts` on `surface` (regularized to `proxy`) and stages the
/// mesh of `-o` in `outputs`; returns what was written, for the summary line.
pub(crate) fn write_distances(
    args: &RegularizeArgs,
    outputs: &mut Outputs,
    opts: &GeodesicOptions,
    surface: &DigitalSurface,
    proxy: &[DVec3],
) -> Result<String> {
    let digital = surface.positions();
    let pick = |kind: SurfaceKind| match kind {
        SurfaceKind::Proxy => proxy,
        SurfaceKind::Digital => digital.as_slice(),
    };
    let input = args.input.input.display();
    let metric = QuadMesh::from_surface(surface, pick(opts.metric));
    let mesh = GeodesicMesh::new(&metric.positions, &metric.quads)
        .with_context(|| format!("{input}: cannot measure distances on this surface"))?;
    let sources: Vec<_> = opts.from.iter().filter_map(|&p| mesh.nearest_point(p)).collect();
    let d = distances_from(&mesh, &sources, opts.method.method())
        .with_context(|| format!("{input}: cannot compute geodesic distances"))?;
    let largest = d.iter().copied().filter(|x| x.is_finite()).fold(0.0, f64::max);
    let spacing = opts.iso.unwrap_or(if largest > 0.0 { largest / 10.0 } else { 1.0 });
    let iso = mesh.iso_vertices(&d, spacing);
    let colours: Vec<[u8; 3]> = d
        .iter()
        .zip(&iso)
        .map(|(&x, &line)| {
            if !x.is_finite() {
                [128, 128, 128]
            } else {
                let c = scalar_ramp(if largest > 0.0 { x / largest } else { 0.0 });
                if line {
                    c.map(|v| (f64::from(v) * 0.3).round() as u8)
                } else {
                    c
                }
            }
        })
        .collect();
    let values: Vec<f64> = d.iter().map(|&x| if x.is_finite() { x } else { UNREACHED }).collect();
    let out = QuadMesh::from_surface(surface, pick(opts.on));
    outputs
        .write(&args.output, |path| write_ply_with_vertex_field(path, &out, "distance", &values, &colours))?;
    Ok(format!(
        "{} ({} source{}, largest distance {largest:.4}, iso-lines every {spacing:.4})",
        args.output.display(),
        sources.len(),
        if sources.len() == 1 { "" } else { "s" }
    ))
}
