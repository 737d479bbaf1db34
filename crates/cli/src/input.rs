//! Reading the input volume as the options say.

use anyhow::{bail, Context, Result};
use voxreg_digisurf::{DigitalSurface, LabelVolume, RegionMap};
use voxreg_io::{is_voxel_art, Background, InputError, InputOptions, Palette};

use crate::args::InputArgs;

/// Reads INPUT (raw with `--dims`, else by extension), applies `--spacing`, then
/// `--threshold` (or checks that grey levels are labels), `--labels` and the background
/// (`voxreg_io::read_input`), with the errors in the options' names.
/// Also returns the palette and the unit of the spacing, where the file has them.
pub(crate) fn read_input(args: &InputArgs) -> Result<(LabelVolume, Option<Palette>, Option<String>)> {
    read_input_from(args, None)
}

/// [`read_input`] of INPUT's contents held in memory (a file dropped on the viewer's
/// page): nothing else is read (`voxreg_io::read_input_bytes`).
pub(crate) fn read_input_from(
    args: &InputArgs,
    bytes: Option<&[u8]>,
) -> Result<(LabelVolume, Option<Palette>, Option<String>)> {
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
    let read = match bytes {
        Some(b) => voxreg_io::read_input_bytes(b, path, &options),
        None => voxreg_io::read_input(path, &options),
    };
    match read {
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
