//! Reading the input volume as the options say.

use anyhow::{Context, Result};
use glam::DVec3;
use voxreg_digisurf::{BlockVolume, LabelVolume};
use voxreg_io::{is_voxel_art, Background, InputError, InputOptions, Palette};
use voxreg_regularize::{Budgeted, Params, Regularizer};

use crate::args::InputArgs;

/// Reads INPUT (raw with `--dims`, else by extension), applies `--spacing`, then
/// `--threshold` (or checks that grey levels are labels), `--labels` and the background
/// (`voxreg_io::read_input`), with the errors in the options' names.
/// Also returns the palette and the unit of the spacing, where the file has them.
pub(crate) fn read_input(args: &InputArgs) -> Result<(LabelVolume, Option<Palette>, Option<String>)> {
    match voxreg_io::read_input(&args.input, &options(args)) {
        Ok(input) => Ok((input.volume, input.palette, input.units)),
        Err(e) => Err(input_error(args, e)),
    }
}

/// The options of `args` as `voxreg_io` takes them.
pub(crate) fn options(args: &InputArgs) -> InputOptions<'_> {
    InputOptions {
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
    }
}

/// An [`InputError`] in the options' names.
pub(crate) fn input_error(args: &InputArgs, e: InputError) -> anyhow::Error {
    let path = &args.input;
    match e {
        InputError::RawNeedsDims(_) => {
            anyhow::anyhow!("{}: raw data have no header: give --dims X,Y,Z and --dtype", path.display())
        }
        InputError::ModelNeedsVox(_) => {
            anyhow::anyhow!("{}: --model applies to MagicaVoxel .vox files", path.display())
        }
        InputError::Spacing { source, .. } => {
            anyhow::Error::new(source).context(format!("{}: --spacing", path.display()))
        }
        InputError::NanThreshold => anyhow::anyhow!("--threshold: NaN is not a threshold"),
        InputError::GreyNeedsThreshold { lo, hi, reason, .. } => anyhow::anyhow!(
            "{}: grey-level data needs --threshold T (values range from {lo} to {hi}; {reason})",
            path.display()
        ),
        InputError::Io(e) => e.into(),
    }
}

/// An input volume: dense, or (a MagicaVoxel scene of models far apart) blocks in a
/// lattice of empty space, whose surface is that of the volume made dense.
pub(crate) enum Source {
    /// Every voxel stored.
    Dense(LabelVolume),
    /// The models' own boxes (`voxreg_io::read_sparse_input`).
    Blocks(BlockVolume),
}

/// Reads INPUT as [`read_input`] does, as blocks where it is a MagicaVoxel scene of
/// models far apart (`voxreg_io::read_sparse_input`): the memory and time of its
/// models' boxes, not of their bounding box.
pub(crate) fn read_source(args: &InputArgs) -> Result<(Source, Option<Palette>, Option<String>)> {
    match voxreg_io::read_sparse_input(&args.input, None, &options(args)) {
        Ok(Some(scene)) => Ok((Source::Blocks(scene.volume), Some(scene.palette), None)),
        Ok(None) => read_input(args).map(|(v, p, u)| (Source::Dense(v), p, u)),
        Err(e) => Err(input_error(args, e)),
    }
}

impl Source {
    /// Number of voxels along x, y and z.
    pub(crate) fn dims(&self) -> [usize; 3] {
        match self {
            Source::Dense(v) => v.dims(),
            Source::Blocks(v) => v.dims(),
        }
    }

    /// Number of voxels (the empty space between blocks included).
    pub(crate) fn len(&self) -> u128 {
        match self {
            Source::Dense(v) => v.len() as u128,
            Source::Blocks(v) => v.len(),
        }
    }

    /// Physical size of a voxel.
    pub(crate) fn spacing(&self) -> DVec3 {
        match self {
            Source::Dense(v) => v.spacing(),
            Source::Blocks(v) => v.spacing(),
        }
    }

    /// The background label, if any.
    pub(crate) fn background(&self) -> Option<u32> {
        match self {
            Source::Dense(v) => v.background(),
            Source::Blocks(v) => Some(v.background()),
        }
    }

    /// The distinct labels with their voxel counts, sorted by label.
    pub(crate) fn label_counts(&self) -> Vec<(u32, u64)> {
        match self {
            Source::Dense(v) => v.label_counts(),
            Source::Blocks(v) => v.label_counts(),
        }
    }

    /// The largest label.
    pub(crate) fn max_label(&self) -> Option<u32> {
        match self {
            Source::Dense(v) => v.max_label(),
            Source::Blocks(v) => Some(v.max_label()),
        }
    }

    /// A regularizer of `params.regions`' surface, refused before the surface is built
    /// when a run of `params` on it, and `extra(surfels)` more bytes, would exceed the
    /// memory budget (`voxreg_io::max_memory`); `what(count)` names what needs the memory
    /// ("the regularization of its {count} surfels"). A dense volume's extraction counts
    /// its surfels as it finds them and stops past the most that fit (one pass over the
    /// voxels; `Regularizer::from_volume_within_budget`); blocks are counted first
    /// (`Regularizer::from_blocks_within_budget`).
    pub(crate) fn regularizer_within(
        &self,
        args: &InputArgs,
        params: &Params,
        extra: impl Fn(u64) -> u64,
        what: impl Fn(&str) -> String,
    ) -> Result<Regularizer> {
        let path = &args.input;
        let no_surface = || format!("{}: no surface to regularize", path.display());
        let need = |s: u64| voxreg_regularize::estimated_bytes(s, params).saturating_add(extra(s));
        let limit = voxreg_io::max_memory();
        let budgeted = match self {
            Source::Dense(v) => Regularizer::from_volume_within_budget(v, &params.regions, limit, need),
            Source::Blocks(v) => Regularizer::from_blocks_within_budget(v, &params.regions, limit, need),
        }
        .with_context(no_surface)?;
        match budgeted {
            Budgeted::Fits(r) => Ok(*r),
            Budgeted::TooLarge { surfels, bytes } => Err(voxreg_io::IoError::OverBudget {
                path: path.clone(),
                what: what(&surfels.to_string()),
                bytes,
                limit,
            }
            .into()),
        }
    }
}

/// Whether INPUT is voxel art (the voxel-art preset's input).
pub(crate) fn voxel_art(args: &InputArgs) -> bool {
    args.dims.is_none() && is_voxel_art(&args.input)
}
