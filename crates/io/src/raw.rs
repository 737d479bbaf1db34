//! Raw voxel data: no header, the layout given by the caller.

use std::path::Path;

use glam::DVec3;

use crate::error::IoError;
use crate::files::{checked_voxel_count, read_file};
use crate::grey::Voxels;
use crate::samples::{check_data_len, data_len, decode, Layout, Order};
use crate::samples::{DataType, Endian};

/// The layout of a raw file, which has none of its own.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RawSpec {
    /// Number of voxels along x, y and z; each at least 1. No default.
    pub dims: [u64; 3],
    /// The type of each value. Default: [`DataType::U8`].
    pub dtype: DataType,
    /// The byte order of multi-byte values. Default: [`Endian::Little`].
    pub endian: Endian,
    /// Physical size of a voxel along x, y and z. Default: `1, 1, 1`.
    pub spacing: DVec3,
}

impl RawSpec {
    /// Unsigned bytes of dimensions `dims`, little endian, unit spacing.
    pub fn new(dims: [u64; 3]) -> Self {
        RawSpec { dims, dtype: DataType::U8, endian: Endian::Little, spacing: DVec3::ONE }
    }
}

/// Reads a raw file: the values of a `spec.dims` volume, `x` fastest, then `y`, then
/// `z`, with no header. See [`read_raw_bytes`].
pub fn read_raw(path: &Path, spec: &RawSpec) -> Result<Voxels, IoError> {
    // Refuse absurd dimensions before reading anything.
    checked_voxel_count(path, spec.dims, spec.dtype.size() as u64 + 8)?;
    read_raw_bytes(&read_file(path)?, path, spec)
}

/// Reads raw voxel data held in memory; `path` only names the file in errors.
///
/// The data must be exactly `dims[0] * dims[1] * dims[2]` values of `spec.dtype`: fewer
/// bytes is a truncated file, more a layout that does not match the file, both
/// [`IoError::Format`]. Values are labels when all are integers in `0..=u32::MAX`,
/// grey levels otherwise (see [`Voxels`]); a NaN is an error. Origin `0`.
pub fn read_raw_bytes(bytes: &[u8], path: &Path, spec: &RawSpec) -> Result<Voxels, IoError> {
    if spec.dims.contains(&0) {
        let [x, y, z] = spec.dims;
        return Err(IoError::format(path, format!("dimensions {x}x{y}x{z}: each must be at least 1")));
    }
    checked_voxel_count(path, spec.dims, spec.dtype.size() as u64 + 8)?;
    let layout = Layout {
        dims: spec.dims.map(|d| d as usize), // fits: each is at most the voxel count
        dtype: spec.dtype,
        endian: spec.endian,
        order: Order::XFastest,
    };
    let expected = data_len(&layout);
    check_data_len(path, bytes.len(), expected as usize, &layout)?;
    let voxels = decode(path, bytes, layout, None)?;
    voxels.with_spacing(spec.spacing).map_err(|source| IoError::Volume { path: path.to_path_buf(), source })
}

#[cfg(test)]
mod tests {
    use super::*;

    const P: &str = "scan.raw";

    fn spec(dims: [u64; 3], dtype: DataType) -> RawSpec {
        RawSpec { dtype, ..RawSpec::new(dims) }
    }

    fn message(bytes: &[u8], spec: &RawSpec) -> String {
        let text = read_raw_bytes(bytes, Path::new(P), spec).unwrap_err().to_string();
        assert!(text.starts_with("scan.raw: "), "{text}");
        text
    }

    #[test]
    fn reads_each_type() {
        let values = [0u32, 7, 65535];
        for dtype in DataType::ALL {
            let bytes: Vec<u8> = values
                .iter()
                .flat_map(|&v| {
                    let v = if dtype.size() == 1 { v.min(100) } else { v };
                    match dtype {
                        DataType::U8 | DataType::I8 => vec![v as u8],
                        DataType::U16 => (v as u16).to_le_bytes().to_vec(),
                        DataType::I16 => (v as u16 as i16).to_le_bytes().to_vec(),
                        DataType::U32 | DataType::I32 => v.to_le_bytes().to_vec(),
                        DataType::U64 | DataType::I64 => u64::from(v).to_le_bytes().to_vec(),
                        DataType::F32 => (v as f32).to_le_bytes().to_vec(),
                        DataType::F64 => f64::from(v).to_le_bytes().to_vec(),
                    }
                })
                .collect();
            let v = read_raw_bytes(&bytes, Path::new(P), &spec([3, 1, 1], dtype)).unwrap();
            match (dtype, v) {
                (DataType::I16, Voxels::Grey(g)) => assert_eq!(g.values()[[2, 0, 0]], -1.0),
                (_, Voxels::Labels(l)) => {
                    assert_eq!(l.label([1, 0, 0]), Some(7), "{dtype}");
                    let last = if dtype.size() == 1 { 100 } else { 65535 };
                    assert_eq!(l.label([2, 0, 0]), Some(last), "{dtype}");
                }
                (_, v) => panic!("{dtype}: {v:?}"),
            }
        }
    }

    #[test]
    fn big_endian_and_spacing() {
        let spec = RawSpec {
            endian: Endian::Big,
            spacing: DVec3::new(0.5, 1.0, 2.0),
            ..spec([1, 2, 1], DataType::U16)
        };
        let Voxels::Labels(v) = read_raw_bytes(&[1, 0, 0, 2], Path::new(P), &spec).unwrap() else { panic!() };
        assert_eq!(v.label([0, 0, 0]), Some(256));
        assert_eq!(v.label([0, 1, 0]), Some(2));
        assert_eq!(v.spacing(), DVec3::new(0.5, 1.0, 2.0));
        let bad = RawSpec { spacing: DVec3::new(0.0, 1.0, 1.0), ..spec };
        assert!(message(&[1, 0, 0, 2], &bad).contains("spacing must be finite and positive"));
    }

    #[test]
    fn errors() {
        let s = spec([2, 2, 2], DataType::U16);
        assert!(message(&[0; 15], &s).contains("truncated voxel data: 2x2x2 voxels of u16"));
        assert!(message(&[0; 17], &s).contains("dimensions do not match the data"));
        assert!(message(&[0; 16], &spec([0, 2, 2], DataType::U8)).contains("each must be at least 1"));
        let huge = read_raw_bytes(&[0; 16], Path::new(P), &spec([1 << 20, 1 << 20, 1], DataType::F64));
        assert!(matches!(huge, Err(IoError::TooLarge { .. })));
        let nan: Vec<u8> = [1.0f32, f32::NAN].iter().flat_map(|v| v.to_le_bytes()).collect();
        assert!(message(&nan, &spec([2, 1, 1], DataType::F32)).contains("grey level NaN at voxel [1, 0, 0]"));
        let missing = read_raw(Path::new("/nonexistent/scan.raw"), &s).unwrap_err();
        assert!(matches!(missing, IoError::Io { .. }));
    }
}
