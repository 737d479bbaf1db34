//! Reading a volume of any supported format, by file extension.

use std::path::Path;

use crate::error::IoError;
#[cfg(test)]
use crate::files::checked_voxel_count;
use crate::files::{lowercase_extension, read_file};
use crate::grey::Voxels;
use crate::loaded::{LoadedVolume, LoadedVoxels};
use crate::longvol::read_longvol;
use crate::nifti::read_nifti;
use crate::npy::read_npy;
use crate::pgm3d::read_pgm3d;
use crate::vol::read_vol;
use crate::vti::read_vti;

/// Reads a labeled volume, choosing the format by the file's extension, as
/// [`read_voxels`] does.
///
/// Grey-level data (values that are not all integers in `0..=u32::MAX`) are refused
/// with [`IoError::Unsupported`]: read them with [`read_voxels`] and threshold them
/// ([`Voxels::threshold`]).
pub fn read_volume(path: &Path) -> Result<LoadedVolume, IoError> {
    let LoadedVoxels { voxels, palette, units } = read_voxels(path)?;
    let volume = voxels.into_labels().map_err(|e| {
        IoError::unsupported(
            path,
            format!("grey-level data, {e}: threshold them (read_voxels, Voxels::threshold)"),
        )
    })?;
    Ok(LoadedVolume { volume, palette, units })
}

/// The extensions [`read_voxels`] knows, for error messages.
const KNOWN_EXTENSIONS: &str =
    ".vol, .longvol, .pgm3d, .vox, .nii, .nii.gz, .vti, .npy, .tif, .tiff (or a directory or pattern of slices), .nrrd, .nhdr, .mrc, .map, .rec or a .zarr directory";

/// Reads the voxels of a file, labels or grey levels, choosing the format by the
/// file's extension (case insensitive):
///
/// - `.vol`: DGtal Vol, see [`read_vol`];
/// - `.longvol`: DGtal Longvol, see [`read_longvol`](crate::longvol::read_longvol);
/// - `.pgm3d`: DGtal PGM 3-D, see [`read_pgm3d`](crate::pgm3d::read_pgm3d);
/// - `.vox`: MagicaVoxel, see [`read_vox`](crate::vox::read_vox);
/// - `.nii`, `.nii.gz`: NIfTI-1, see [`read_nifti`](crate::nifti::read_nifti);
/// - `.vti`: VTK XML image data, see [`read_vti`](crate::vti::read_vti);
/// - `.npy`: NumPy array, see [`read_npy`](crate::npy::read_npy);
/// - `.tif`, `.tiff`: a TIFF stack, see [`read_tiff`](crate::tiff::read_tiff); a directory, or a
///   file name with `*` or `?`: the TIFF slices it holds or matches, stacked in name order
///   (see [`tiff_slices`](crate::tiff::tiff_slices));
/// - `.nrrd`, `.nhdr` (and `.seg.nrrd`): NRRD, see [`read_nrrd`](crate::nrrd::read_nrrd);
/// - `.mrc`, `.map`, `.rec`: MRC/CCP4 maps, see [`read_mrc`](crate::mrc::read_mrc);
/// - a `.zarr` directory, or any directory holding Zarr metadata (`zarr.json`, `.zarray`,
///   `.zgroup`, such as a level `image.ome.zarr/0`): a Zarr array or OME-Zarr image, see
///   [`read_zarr`](crate::zarr::read_zarr).
///
/// Fails with [`IoError::UnsupportedExtension`] for any other name, and with
/// [`IoError::Unsupported`] for `.raw` (which has no header: see
/// [`read_raw`](crate::raw::read_raw)), before opening the file.
pub fn read_voxels(path: &Path) -> Result<LoadedVoxels, IoError> {
    read_voxels_with(path, &ReadOptions::default())
}

/// Options of [`read_voxels_with`] for formats that hold several volumes.
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq)]
pub struct ReadOptions {
    /// `.vox`: read only this model (see [`VoxOptions::model`](crate::vox::VoxOptions::model)).
    pub vox_model: Option<usize>,
}

/// [`read_voxels`] with `options`.
pub fn read_voxels_with(path: &Path, options: &ReadOptions) -> Result<LoadedVoxels, IoError> {
    let plain = |voxels| Ok(LoadedVoxels { voxels, palette: None, units: None });
    let name = path.file_name().map(|n| n.to_string_lossy()).unwrap_or_default();
    if lowercase_extension(path).as_deref() == Some("zarr") || crate::zarr::is_zarr(path) {
        return crate::zarr::read_zarr(path);
    }
    if path.is_dir() || name.contains(['*', '?']) {
        return crate::tiff::read_tiff_slices(&crate::tiff::tiff_slices(path)?, path);
    }
    let is_nii_gz = path
        .file_name()
        .and_then(|n| n.to_str())
        .is_some_and(|n| n.to_ascii_lowercase().ends_with(".nii.gz"));
    let ext = if is_nii_gz { Some("nii".to_string()) } else { lowercase_extension(path) };
    match ext.as_deref() {
        Some("vol") => plain(Voxels::Labels(read_vol(path)?)),
        Some("longvol") => plain(read_longvol(path)?),
        Some("pgm3d") => plain(Voxels::Labels(read_pgm3d(path)?)),
        Some("vox") => {
            let vox = crate::vox::VoxOptions { model: options.vox_model };
            let LoadedVolume { volume, palette, .. } =
                crate::vox::read_vox_bytes_with(&read_file(path)?, path, &vox)?;
            Ok(LoadedVoxels { voxels: Voxels::Labels(volume), palette, units: None })
        }
        Some("nii") => plain(read_nifti(path)?),
        Some("vti") => plain(read_vti(path)?),
        Some("npy") => plain(read_npy(path)?),
        Some("tif" | "tiff") => crate::tiff::read_tiff(path),
        Some("nrrd" | "nhdr") => crate::nrrd::read_nrrd(path),
        Some("mrc" | "map" | "rec") => crate::mrc::read_mrc(path),
        Some("raw") => Err(IoError::unsupported(
            path,
            "raw voxel data have no header: give their dimensions and type (read_raw with a RawSpec)",
        )),
        _ => Err(IoError::UnsupportedExtension { path: path.to_path_buf(), expected: KNOWN_EXTENSIONS }),
    }
}

/// [`read_voxels_with`] of a file held in memory (an upload): `path` only names the file
/// (its extension picks the format) and nothing else is read. What names other files is
/// refused with [`IoError::Unsupported`]: a Zarr store, a directory or pattern of TIFF
/// slices, a NRRD detached header (`data file`).
pub fn read_voxels_bytes(bytes: &[u8], path: &Path, options: &ReadOptions) -> Result<LoadedVoxels, IoError> {
    let plain = |voxels| Ok(LoadedVoxels { voxels, palette: None, units: None });
    let name = path.file_name().map(|n| n.to_string_lossy()).unwrap_or_default();
    let is_nii_gz = name.to_ascii_lowercase().ends_with(".nii.gz");
    let ext = if is_nii_gz { Some("nii".to_string()) } else { lowercase_extension(path) };
    if ext.as_deref() == Some("zarr") || name.contains(['*', '?']) {
        return Err(IoError::unsupported(
            path,
            "a store or set of files: only a single file is read from memory",
        ));
    }
    match ext.as_deref() {
        Some("vol") => plain(Voxels::Labels(crate::vol::read_vol_bytes(bytes, path)?)),
        Some("longvol") => plain(crate::longvol::read_longvol_bytes(bytes, path)?),
        Some("pgm3d") => plain(Voxels::Labels(crate::pgm3d::read_pgm3d_bytes(bytes, path)?)),
        Some("vox") => {
            let vox = crate::vox::VoxOptions { model: options.vox_model };
            let LoadedVolume { volume, palette, .. } = crate::vox::read_vox_bytes_with(bytes, path, &vox)?;
            Ok(LoadedVoxels { voxels: Voxels::Labels(volume), palette, units: None })
        }
        Some("nii") => plain(crate::nifti::read_nifti_bytes(bytes, path)?),
        Some("vti") => plain(crate::vti::read_vti_bytes(bytes, path)?),
        Some("npy") => plain(crate::npy::read_npy_bytes(bytes, path)?),
        Some("tif" | "tiff") => crate::tiff::read_tiff_bytes(bytes, path),
        Some("nrrd" | "nhdr") => crate::nrrd::read_nrrd_in_memory(bytes, path),
        Some("mrc" | "map" | "rec") => crate::mrc::read_mrc_bytes(bytes, path),
        Some("raw") => Err(IoError::unsupported(
            path,
            "raw voxel data have no header: give their dimensions and type (read_raw_bytes with a RawSpec)",
        )),
        _ => Err(IoError::UnsupportedExtension { path: path.to_path_buf(), expected: KNOWN_EXTENSIONS }),
    }
}

/// Whether `path` names a format of voxel art (MagicaVoxel `.vox`): coloured voxels of
/// one object rather than a sampled shape, which voxreg regularizes with its voxel-art
/// preset (one solid region, clamped solve).
pub fn is_voxel_art(path: &Path) -> bool {
    lowercase_extension(path).as_deref() == Some("vox")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unknown_extension_is_refused_before_opening() {
        for name in ["does/not/exist.stl", "no_extension", "weird.VOLUME", "a.gz"] {
            let err = read_volume(Path::new(name)).unwrap_err();
            assert!(matches!(err, IoError::UnsupportedExtension { .. }), "{err}");
            assert!(err.to_string().starts_with(name), "{err}");
        }
    }

    #[test]
    fn voxel_limit() {
        let p = Path::new("x.vol");
        assert_eq!(checked_voxel_count(p, [2, 3, 4], 1).unwrap(), 24);
        assert_eq!(
            crate::limits::with_max_memory(u64::MAX, || checked_voxel_count(
                p,
                [1 << 11, 1 << 10, 1 << 10],
                1
            ))
            .unwrap(),
            1 << 31
        );
        assert!(matches!(checked_voxel_count(p, [1 << 11, 1 << 10, 1025], 1), Err(IoError::TooLarge { .. })));
        assert!(matches!(checked_voxel_count(p, [u64::MAX; 3], 1), Err(IoError::TooLarge { .. })));
        // 2^63 * 2^63 * 4 = 2^128: a product that wraps to 0.
        assert!(matches!(checked_voxel_count(p, [1 << 63, 1 << 63, 4], 1), Err(IoError::TooLarge { .. })));
    }

    #[test]
    fn dispatch_reads_every_bundled_format() {
        let data = |name: &str| Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../../data")).join(name);
        let cases: [(&str, [usize; 3]); 6] = [
            ("cat10.vol", [40; 3]),
            ("test.longvol", [16; 3]),
            ("cat10.pgm3d", [40; 3]),
            ("chr_army1.vox", [8, 7, 12]),
            ("lobsterCroped2.nii.gz", [101, 101, 41]),
            ("channels.vti", [250, 250, 100]),
        ];
        for (name, dims) in cases {
            let loaded = read_voxels(&data(name)).unwrap();
            assert_eq!(loaded.voxels.dims(), dims, "{name}");
            assert_eq!(loaded.palette.is_some(), name.ends_with(".vox"), "{name}");
            assert_eq!(read_volume(&data(name)).unwrap().volume.dims(), dims, "{name}");
        }
        let err = read_voxels(Path::new("/nonexistent/scan.RAW")).unwrap_err();
        assert!(matches!(err, IoError::Unsupported { .. }), "{err}");
        assert!(err.to_string().contains("read_raw"), "{err}");
    }

    #[test]
    fn read_volume_refuses_grey_levels() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("grey.npy");
        let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
        let header = "{'descr': '<f4', 'fortran_order': False, 'shape': (1, 1, 2), }\n";
        bytes.extend_from_slice(&(header.len() as u16).to_le_bytes());
        bytes.extend_from_slice(header.as_bytes());
        bytes.extend([1.0f32, 0.5].iter().flat_map(|v| v.to_le_bytes()));
        std::fs::write(&path, &bytes).unwrap();
        let err = read_volume(&path).unwrap_err();
        assert!(matches!(err, IoError::Unsupported { .. }), "{err}");
        assert!(err.to_string().contains("grey level 0.5 at voxel [0, 0, 1] is not a label"), "{err}");
        assert!(matches!(read_voxels(&path).unwrap().voxels, Voxels::Grey(_)));
    }

    #[test]
    fn missing_file_names_the_path() {
        let err = read_volume(Path::new("/nonexistent/dir/a.vol")).unwrap_err();
        assert!(matches!(err, IoError::Io { .. }));
        assert!(err.to_string().starts_with("/nonexistent/dir/a.vol: "), "{err}");
    }
}
