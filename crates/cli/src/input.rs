//! Reading the input volume as the options say, and `voxreg info`.

use std::fmt::Write as _;

use anyhow::{bail, Context, Result};
use voxreg_digisurf::{DigitalSurface, LabelVolume, RegionMap};
use voxreg_io::{is_voxel_art, vox_model_sizes, Background, InputError, InputOptions, Palette};

use voxreg_regularize::{InputFacts, Preset};

use crate::args::InputArgs;
use crate::print_stdout;

/// Reads INPUT (raw with `--dims`, else by extension), applies `--spacing`, then
/// `--threshold` (or checks that grey levels are labels), `--labels` and the background
/// (`voxreg_io::read_input`), with the errors in the options' names.
/// Also returns the palette and the unit of the spacing, where the file has them.
pub(crate) fn read_input(args: &InputArgs) -> Result<(LabelVolume, Option<Palette>, Option<String>)> {
    let options = InputOptions {
        dims: args.dims,
        dtype: args.dtype,
        endian: args.endian,
        vox_model: args.model,
        spacing: args.spacing,
        threshold: args.threshold,
        keep_labels: args.labels.as_deref(),
        background: match (args.no_background, args.background) {
            (true, _) => Background::None,
            (false, Some(b)) => Background::Label(b),
            (false, None) => Background::File,
        },
    };
    let path = &args.input;
    match voxreg_io::read_input(path, &options) {
        Ok(input) => Ok((input.volume, input.palette, input.units)),
        Err(InputError::RawNeedsDims(_)) => {
            bail!("{}: raw data have no header: give --dims X,Y,Z and --dtype", path.display())
        }
        Err(InputError::ModelNeedsVox(_)) => {
            bail!("{}: --model applies to MagicaVoxel .vox files", path.display())
        }
        Err(InputError::Spacing { source, .. }) => {
            Err(anyhow::Error::new(source).context(format!("{}: --spacing", path.display())))
        }
        Err(InputError::NanThreshold) => bail!("--threshold: NaN is not a threshold"),
        Err(InputError::GreyNeedsThreshold { lo, hi, reason, .. }) => bail!(
            "{}: grey-level data needs --threshold T (values range from {lo} to {hi}; {reason})",
            path.display()
        ),
        Err(InputError::Io(e)) => Err(e.into()),
    }
}

/// Whether INPUT is voxel art (the voxel-art preset's input).
pub(crate) fn voxel_art(args: &InputArgs) -> bool {
    args.dims.is_none() && is_voxel_art(&args.input)
}

/// The digital surface of `volume`, or an error naming the file.
pub(crate) fn surface_of(args: &InputArgs, volume: &LabelVolume, map: &RegionMap) -> Result<DigitalSurface> {
    DigitalSurface::new(volume, map)
        .with_context(|| format!("{}: no surface to regularize", args.input.display()))
}

/// `voxreg info`: the volume's dimensions and labels, and its digital surface's cells.
pub(crate) fn info(args: &InputArgs) -> Result<()> {
    let mut out = String::new();
    let (volume, palette, units) = read_input(args)?;
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
        let bytes =
            std::fs::read(&args.input).with_context(|| format!("{}: cannot read", args.input.display()))?;
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
    let surface = surface_of(args, &volume, &map)?;
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
