//! Reading a volume of any supported format, by file extension.

use std::path::Path;

use voxreg_digisurf::LabelVolume;

use crate::{read_vol, read_vox, IoError};

/// The largest number of voxels a reader accepts: `2^31`.
///
/// A file declaring more is refused with [`IoError::TooLarge`] before anything is
/// allocated for it. (At the limit, a volume takes 8 GiB of `u32` labels.)
pub const MAX_VOXELS: u64 = 1 << 31;

/// A volume read from a file, with what the file says about its labels.
#[derive(Clone, Debug, PartialEq)]
pub struct LoadedVolume {
    /// The labeled voxels, spacing and origin.
    pub volume: LabelVolume,
    /// Colours as RGBA, indexed by label (`palette[label]`), for formats that have a
    /// palette (MagicaVoxel `.vox`: 256 entries, entry 0, the background, transparent);
    /// `None` for formats without (`.vol`).
    pub palette: Option<Vec<[u8; 4]>>,
}

/// Reads a labeled volume, choosing the format by the file's extension (case
/// insensitive):
///
/// - `.vol`: DGtal Vol, see [`read_vol`];
/// - `.vox`: MagicaVoxel, see [`read_vox`].
///
/// Fails with [`IoError::UnsupportedExtension`] for any other name, before opening it.
pub fn read_volume(path: &Path) -> Result<LoadedVolume, IoError> {
    match lowercase_extension(path).as_deref() {
        Some("vol") => Ok(LoadedVolume { volume: read_vol(path)?, palette: None }),
        Some("vox") => read_vox(path),
        _ => Err(IoError::UnsupportedExtension { path: path.to_path_buf(), expected: ".vol or .vox" }),
    }
}

/// The extension of `path`, lower-cased, if it has one.
pub(crate) fn lowercase_extension(path: &Path) -> Option<String> {
    path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase)
}

/// The number of voxels of `dims`, or [`IoError::TooLarge`] above [`MAX_VOXELS`]
/// (also when the product overflows).
pub(crate) fn checked_voxel_count(path: &Path, dims: [u64; 3]) -> Result<usize, IoError> {
    let count = dims.iter().map(|&d| u128::from(d)).product::<u128>();
    if count > u128::from(MAX_VOXELS) {
        return Err(IoError::TooLarge { path: path.to_path_buf(), dims, limit: MAX_VOXELS });
    }
    usize::try_from(count).map_err(|_| IoError::TooLarge {
        path: path.to_path_buf(),
        dims,
        limit: MAX_VOXELS,
    })
}

/// Reads a whole file into memory.
pub(crate) fn read_file(path: &Path) -> Result<Vec<u8>, IoError> {
    std::fs::read(path).map_err(|e| IoError::io(path, e))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unknown_extension_is_refused_before_opening() {
        for name in ["does/not/exist.nii", "no_extension", "weird.VOLUME"] {
            let err = read_volume(Path::new(name)).unwrap_err();
            assert!(matches!(err, IoError::UnsupportedExtension { .. }), "{err}");
            assert!(err.to_string().starts_with(name), "{err}");
        }
    }

    #[test]
    fn voxel_limit() {
        let p = Path::new("x.vol");
        assert_eq!(checked_voxel_count(p, [2, 3, 4]).unwrap(), 24);
        assert_eq!(checked_voxel_count(p, [1 << 11, 1 << 10, 1 << 10]).unwrap(), 1 << 31);
        assert!(matches!(checked_voxel_count(p, [1 << 11, 1 << 10, 1025]), Err(IoError::TooLarge { .. })));
        assert!(matches!(checked_voxel_count(p, [u64::MAX; 3]), Err(IoError::TooLarge { .. })));
    }

    #[test]
    fn missing_file_names_the_path() {
        let err = read_volume(Path::new("/nonexistent/dir/a.vol")).unwrap_err();
        assert!(matches!(err, IoError::Io { .. }));
        assert!(err.to_string().starts_with("/nonexistent/dir/a.vol: "), "{err}");
    }
}
