//! `voxreg info`: the volume's dimensions and labels, and its digital surface's cells.

use std::fmt::Write as _;

use anyhow::Result;
use voxreg_io::vox_model_sizes;

use voxreg_regularize::{InputFacts, Preset};

use crate::args::InputArgs;
use crate::input::{read_source, voxel_art};
use crate::terminal::print_stdout;

/// `voxreg info`: the volume's dimensions and labels, and its digital surface's cells;
/// refused, as `regularize` is, when the regularization's estimate exceeds the budget.
pub(crate) fn info(args: &InputArgs) -> Result<()> {
    let mut out = String::new();
    let (volume, palette, units) = read_source(args)?;
    let preset = Preset::for_input(&InputFacts::voxel_art(voxel_art(args)));
    let map = args.region_map()?.unwrap_or_else(|| preset.params().regions);
    let [x, y, z] = volume.dims();
    let s = volume.spacing();
    writeln!(out, "file: {}", args.input.display()).ok();
    writeln!(out, "dimensions: {x} x {y} x {z} ({} voxels)", volume.len()).ok();
    match units {
        Some(u) => writeln!(out, "spacing: {} {} {} {u}", s.x, s.y, s.z).ok(),
        None => writeln!(out, "spacing: {} {} {}", s.x, s.y, s.z).ok(),
    };
    if voxel_art(args) {
        let bytes = voxreg_io::read_input_file(&args.input)?;
        let sizes = vox_model_sizes(&bytes, &args.input)?;
        writeln!(out, "models: {}", sizes.len()).ok();
        for (k, [x, y, z]) in sizes.iter().enumerate() {
            writeln!(out, "  {k}: {x} x {y} x {z}").ok();
        }
    }
    match volume.background() {
        Some(b) => writeln!(out, "background: {b}").ok(),
        None => writeln!(out, "background: none").ok(),
    };
    writeln!(out, "labels:").ok();
    for (label, count) in volume.label_counts() {
        // Names the file gives its labels (`.seg.nrrd` segments), not the generic ones.
        let name = palette.as_ref().and_then(|p| p.material(label)).map(|m| m.name.as_str());
        match name.filter(|&n| n != format!("color_{label}")) {
            Some(name) => writeln!(out, "  {label}: {count} voxels ({name})").ok(),
            None => writeln!(out, "  {label}: {count} voxels").ok(),
        };
    }
    // Under the budget `regularize` checks as it builds the surface: `info` on an input
    // that `regularize` refuses fails the same way, at the same point.
    let mut params = preset.params();
    params.regions = map.clone();
    let regularizer = volume.regularizer_within(
        args,
        &params,
        |_| 0,
        |n| format!("the regularization of its {n} surfels"),
    )?;
    let surface = regularizer.surface();
    let c = surface.counts();
    writeln!(out, "regions: {}", surface.regions().len()).ok();
    writeln!(out, "surfels: {}", c.surfels).ok();
    writeln!(out, "vertices: {}", c.vertices).ok();
    writeln!(out, "edges: {}", c.edges).ok();
    writeln!(out, "euler characteristic: {}", surface.euler_characteristic()).ok();
    writeln!(
        out,
        "components: {} ({} closed)",
        c.components,
        surface.components_closed().iter().filter(|&&b| b).count()
    )
    .ok();
    writeln!(out, "interfaces: {}", c.interfaces).ok();
    for iface in surface.interfaces() {
        let name = |r| {
            let labels = surface.regions().labels(r);
            labels.iter().map(u32::to_string).collect::<Vec<_>>().join("+")
        };
        writeln!(
            out,
            "  {} | {}: {} surfels",
            name(iface.regions[0]),
            name(iface.regions[1]),
            iface.surfels.len()
        )
        .ok();
    }
    writeln!(out, "boundary vertices: {}", c.boundary_vertices).ok();
    writeln!(out, "boundary edges: {}", c.boundary_edges).ok();
    writeln!(out, "junction edges: {}", c.junction_edges).ok();
    writeln!(out, "pinched edges: {}", c.pinched_edges).ok();
    writeln!(out, "pinched vertices: {}", c.pinched_vertices).ok();
    print_stdout(&out)
}
