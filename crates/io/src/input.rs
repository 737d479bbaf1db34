//! Reading an input volume as a front end's options describe it: raw data or a file by
//! extension, then the spacing, the threshold (or the check that grey levels are labels),
//! the labels kept and the background. The CLI and the Python package read through this
//! one function; each words the [`InputError`]s in its own option names.

use std::path::{Path, PathBuf};

use glam::DVec3;
use voxreg_digisurf::{Block, BlockVolume, LabelVolume, SurfaceError};

use crate::error::IoError;
use crate::grey::{NotALabel, Voxels};
use crate::material::Palette;
use crate::raw::{read_raw, RawSpec};
use crate::samples::{DataType, Endian};
use crate::volume::{is_voxel_art, read_voxels_with, ReadOptions};

/// What to do with the background label.
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq)]
pub enum Background {
    /// The file's (label `0` for formats that do not say).
    #[default]
    File,
    /// No background: every label is a material.
    None,
    /// This label.
    Label(u32),
}

/// How to read an input volume. `Default` reads the file by its extension, as it is.
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct InputOptions<'a> {
    /// Read raw data (no header, `x` fastest) of these dimensions. Default `None`.
    pub dims: Option<[u64; 3]>,
    /// Raw data: the sample type. Default `None` (`u8`).
    pub dtype: Option<DataType>,
    /// Raw data: the byte order. Default `None` (little-endian).
    pub endian: Option<Endian>,
    /// `.vox` input: read only this model. Default `None` (every model).
    pub vox_model: Option<usize>,
    /// The size of a voxel, for raw data or overriding the file's (whose unit then no
    /// longer applies). Default `None`.
    pub spacing: Option<DVec3>,
    /// Make a binary volume: label `1` where the value is `> threshold`, else `0`.
    /// Default `None` (grey levels must then be labels).
    pub threshold: Option<f64>,
    /// Keep only these labels; every other becomes the background label (the one given,
    /// else the file's, else `0`). Default `None`.
    pub keep_labels: Option<&'a [u32]>,
    /// The background. Default [`Background::File`].
    pub background: Background,
}

/// A volume read with [`read_input`].
#[derive(Clone, Debug)]
pub struct Input {
    /// The labels, spacing, origin and background.
    pub volume: LabelVolume,
    /// The file's colours and materials, where it has them.
    pub palette: Option<Palette>,
    /// The unit of the spacing, where the file gives one and no spacing was given.
    pub units: Option<String>,
}

/// Why [`read_input`] refused an input. Messages name the file, not the options: front
/// ends word the option-specific ones (the `RawNeedsDims`, `ModelNeedsVox`, `NanThreshold`
/// and `GreyNeedsThreshold` variants) in their own option names.
#[derive(Debug, thiserror::Error)]
pub enum InputError {
    /// The file could not be read.
    #[error(transparent)]
    Io(#[from] IoError),
    /// A `.raw` file and no dimensions.
    #[error("{}: raw data have no header: give the dimensions and sample type", .0.display())]
    RawNeedsDims(PathBuf),
    /// A model asked of a file that is not MagicaVoxel's.
    #[error("{}: a model applies to MagicaVoxel .vox files", .0.display())]
    ModelNeedsVox(PathBuf),
    /// The spacing given is not finite and positive.
    #[error("{}: spacing", .path.display())]
    Spacing {
        /// The file read.
        path: PathBuf,
        /// What is wrong with the spacing.
        #[source]
        source: SurfaceError,
    },
    /// A threshold of NaN.
    #[error("NaN is not a threshold")]
    NanThreshold,
    /// Grey levels that are not labels, and no threshold.
    #[error("{}: grey-level data needs a threshold (values range from {lo} to {hi}; {reason})", .path.display())]
    GreyNeedsThreshold {
        /// The file read.
        path: PathBuf,
        /// The smallest value.
        lo: f64,
        /// The largest value.
        hi: f64,
        /// The first value that is not a label.
        reason: NotALabel,
    },
}

/// Reads `path` as `options` say: raw data with `dims` (a `.raw` file needs them), else
/// by extension; then applies the spacing, the threshold (or checks that grey levels
/// are labels), the labels kept and the background. Spacings and origins whose vertex
/// coordinates a mesh cannot represent distinctly are refused ([`check_coordinates`]).
///
/// [`check_coordinates`]: crate::orient::check_coordinates
pub fn read_input(path: &Path, options: &InputOptions<'_>) -> Result<Input, InputError> {
    read_input_from(path, None, options)
}

/// [`read_input`] of a file held in memory (an upload to the viewer): `path` only names
/// it, and nothing else is read ([`read_voxels_bytes`](crate::volume::read_voxels_bytes)).
pub fn read_input_bytes(bytes: &[u8], path: &Path, options: &InputOptions<'_>) -> Result<Input, InputError> {
    read_input_from(path, Some(bytes), options)
}

fn read_input_from(
    path: &Path,
    bytes: Option<&[u8]>,
    options: &InputOptions<'_>,
) -> Result<Input, InputError> {
    let is_raw = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("raw"));
    let (voxels, palette, units) = match options.dims {
        Some(dims) => {
            let spec = RawSpec {
                dims,
                dtype: options.dtype.unwrap_or(DataType::U8),
                endian: options.endian.unwrap_or_default(),
                spacing: options.spacing.unwrap_or(DVec3::ONE),
            };
            let voxels = match bytes {
                Some(b) => crate::raw::read_raw_bytes(b, path, &spec)?,
                None => read_raw(path, &spec)?,
            };
            (voxels, None, None)
        }
        None if is_raw => return Err(InputError::RawNeedsDims(path.to_path_buf())),
        None => {
            if options.vox_model.is_some() && !is_voxel_art(path) {
                return Err(InputError::ModelNeedsVox(path.to_path_buf()));
            }
            let read = ReadOptions { vox_model: options.vox_model };
            let loaded = match bytes {
                Some(b) => crate::volume::read_voxels_bytes(b, path, &read)?,
                None => read_voxels_with(path, &read)?,
            };
            (loaded.voxels, loaded.palette, loaded.units)
        }
    };
    // A unit the file gives no longer applies to a spacing given by the caller.
    let units = if options.spacing.is_some() { None } else { units };
    let voxels = match options.spacing {
        Some(s) => voxels
            .with_spacing(s)
            .map_err(|source| InputError::Spacing { path: path.to_path_buf(), source })?,
        None => voxels,
    };
    crate::orient::check_coordinates(voxels.dims(), voxels.spacing(), voxels.origin())
        .map_err(|m| IoError::format(path, m))?;
    let mut volume = match (options.threshold, voxels) {
        (Some(t), _) if t.is_nan() => return Err(InputError::NanThreshold),
        (Some(t), voxels) => voxels.threshold(t),
        (None, Voxels::Labels(volume)) => volume,
        (None, Voxels::Grey(grey)) => match grey.to_labels() {
            Ok(volume) => volume,
            Err(reason) => {
                let (lo, hi) = grey.range().unwrap_or_default();
                return Err(InputError::GreyNeedsThreshold { path: path.to_path_buf(), lo, hi, reason });
            }
        },
    };
    if let Some(keep) = options.keep_labels {
        let background = match options.background {
            Background::Label(b) => b,
            _ => volume.background().unwrap_or(0),
        };
        volume.labels_mut().mapv_inplace(|l| if keep.contains(&l) { l } else { background });
    }
    match options.background {
        Background::File => {}
        Background::None => volume = volume.with_background(None),
        Background::Label(b) => volume = volume.with_background(Some(b)),
    }
    Ok(Input { volume, palette, units })
}

/// A MagicaVoxel scene read as blocks with [`read_sparse_input`].
#[derive(Clone, Debug)]
pub struct SparseInput {
    /// The scene's blocks, spacing, origin and background (label `0`).
    pub volume: BlockVolume,
    /// The file's colours and materials.
    pub palette: Palette,
}

/// Reads `path` as [`read_input`] does, into blocks built from the models' own boxes
/// ([`read_vox_scene_bytes`](crate::vox::read_vox_scene_bytes)), when it is a MagicaVoxel
/// scene whose blocks hold less than half of its bounding box (models far apart) and
/// the options leave empty space empty: no raw dimensions, no model picked, no
/// threshold, the file's background (label `0`). The spacing and the labels kept apply
/// as in [`read_input`]. `Ok(None)` otherwise (any other file, a dense scene): read it
/// with [`read_input`], whose volume's surface is the same.
pub fn read_sparse_input(
    path: &Path,
    bytes: Option<&[u8]>,
    options: &InputOptions<'_>,
) -> Result<Option<SparseInput>, InputError> {
    let applies = options.dims.is_none()
        && options.vox_model.is_none()
        && options.threshold.is_none()
        && matches!(options.background, Background::File | Background::Label(0))
        && is_voxel_art(path);
    if !applies {
        return Ok(None);
    }
    let owned;
    let bytes = match bytes {
        Some(b) => b,
        None => {
            owned = crate::files::read_input_file(path)?;
            &owned
        }
    };
    let scene = crate::vox::read_vox_scene_bytes(bytes, path, &crate::vox::VoxOptions::default())?;
    if !scene.is_sparse() {
        return Ok(None);
    }
    let mut volume = scene.volume;
    if let Some(s) = options.spacing {
        volume = volume
            .with_spacing(s)
            .map_err(|source| InputError::Spacing { path: path.to_path_buf(), source })?;
    }
    crate::orient::check_coordinates(volume.dims(), volume.spacing(), volume.origin())
        .map_err(|m| IoError::format(path, m))?;
    if let Some(keep) = options.keep_labels {
        let background = volume.background();
        let blocks = volume
            .blocks()
            .iter()
            .map(|b| Block {
                offset: b.offset,
                labels: b.labels.mapv(|l| if keep.contains(&l) { l } else { background }),
            })
            .collect();
        let (spacing, origin) = (volume.spacing(), volume.origin());
        volume = BlockVolume::new(volume.dims(), blocks, background)
            .and_then(|v| v.with_spacing(spacing))
            .and_then(|v| v.with_origin(origin))
            .map_err(|source| IoError::Volume { path: path.to_path_buf(), source })?;
    }
    Ok(Some(SparseInput { volume, palette: scene.palette }))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn npy(dir: &Path, name: &str, values: &[f32], dims: [usize; 3]) -> PathBuf {
        let path = dir.join(name);
        // A little-endian f32 .npy in Fortran order (x fastest), as the format allows.
        let header = format!(
            "{{'descr': '<f4', 'fortran_order': True, 'shape': ({}, {}, {}), }}",
            dims[0], dims[1], dims[2]
        );
        let mut h = header.into_bytes();
        while (10 + h.len() + 1) % 64 != 0 {
            h.push(b' ');
        }
        h.push(b'\n');
        let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
        bytes.extend((h.len() as u16).to_le_bytes());
        bytes.extend(h);
        for v in values {
            bytes.extend(v.to_le_bytes());
        }
        std::fs::write(&path, bytes).unwrap();
        path
    }

    #[test]
    fn options_apply_in_order() {
        let dir = tempfile::tempdir().unwrap();
        // x fastest: labels 0, 3, 5, 3 along x, 0.5 a grey level.
        let labels = npy(dir.path(), "l.npy", &[0.0, 3.0, 5.0, 3.0], [4, 1, 1]);
        let grey = npy(dir.path(), "g.npy", &[0.0, 0.5, 2.0, 1.0], [4, 1, 1]);
        let read = |path: &Path, o: InputOptions<'_>| read_input(path, &o);

        let plain = read(&labels, InputOptions::default()).unwrap();
        assert_eq!(plain.volume.labels().iter().copied().collect::<Vec<_>>(), [0, 3, 5, 3]);
        assert_eq!(plain.volume.background(), Some(0));

        // Kept labels: the others become the given background, which the volume then has.
        let o =
            InputOptions { keep_labels: Some(&[3]), background: Background::Label(7), ..Default::default() };
        let kept = read(&labels, o).unwrap().volume;
        assert_eq!(kept.labels().iter().copied().collect::<Vec<_>>(), [7, 3, 7, 3]);
        assert_eq!(kept.background(), Some(7));
        let o = InputOptions { keep_labels: Some(&[5]), background: Background::None, ..Default::default() };
        let kept = read(&labels, o).unwrap().volume;
        assert_eq!(kept.labels().iter().copied().collect::<Vec<_>>(), [0, 0, 5, 0]);
        assert_eq!(kept.background(), None);

        // Grey levels: refused without a threshold, naming the range; binary with one.
        match read(&grey, InputOptions::default()) {
            Err(InputError::GreyNeedsThreshold { lo, hi, .. }) => assert_eq!((lo, hi), (0.0, 2.0)),
            other => panic!("{other:?}"),
        }
        let t = read(&grey, InputOptions { threshold: Some(0.75), ..Default::default() }).unwrap();
        assert_eq!(t.volume.labels().iter().copied().collect::<Vec<_>>(), [0, 0, 1, 1]);
        assert!(matches!(
            read(&grey, InputOptions { threshold: Some(f64::NAN), ..Default::default() }),
            Err(InputError::NanThreshold)
        ));

        // Spacing overrides the file's; a bad one names the file.
        let s = DVec3::new(1.0, 2.0, 3.0);
        assert_eq!(
            read(&labels, InputOptions { spacing: Some(s), ..Default::default() }).unwrap().volume.spacing(),
            s
        );
        let bad = read(&labels, InputOptions { spacing: Some(DVec3::ZERO), ..Default::default() });
        assert!(matches!(&bad, Err(InputError::Spacing { path, .. }) if path == &labels), "{bad:?}");

        // Raw data need their dimensions; a model needs a .vox file.
        let raw = dir.path().join("v.raw");
        std::fs::write(&raw, [0u8, 1, 1, 0]).unwrap();
        assert!(matches!(read(&raw, InputOptions::default()), Err(InputError::RawNeedsDims(_))));
        let r = read(&raw, InputOptions { dims: Some([4, 1, 1]), ..Default::default() }).unwrap();
        assert_eq!(r.volume.labels().iter().copied().collect::<Vec<_>>(), [0, 1, 1, 0]);
        assert!(matches!(
            read(&labels, InputOptions { vox_model: Some(0), ..Default::default() }),
            Err(InputError::ModelNeedsVox(_))
        ));
        assert!(matches!(
            read(&dir.path().join("missing.npy"), InputOptions::default()),
            Err(InputError::Io(_))
        ));
    }
}
