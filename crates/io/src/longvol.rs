//! DGtal `.longvol` volumes: `.vol` with 64-bit voxels.
//!
//! The format: the `.vol` header (`Key: value` lines ended by a line holding a single
//! `.`), then eight bytes per voxel, little endian (as DGtal's `LongvolReader` reads
//! them), `x` fastest, then `y`, then `z`. Version 2 stores them raw, version 3
//! compresses them with zlib.

use std::path::Path;

use crate::error::IoError;
use crate::files::{checked_voxel_count, read_file};
use crate::grey::Voxels;
use crate::samples::{check_data_len, data_len, decode, Layout, Order};
use crate::samples::{DataType, Endian};
use crate::vol::{inflate_at_most, parse_header};

/// Reads a DGtal `.longvol` file (versions 2 and 3). See [`read_longvol_bytes`].
pub fn read_longvol(path: &Path) -> Result<Voxels, IoError> {
    read_longvol_bytes(&read_file(path)?, path)
}

/// Reads a DGtal `.longvol` file held in memory; `path` only names the file in errors.
///
/// Header fields read: `X`, `Y`, `Z` (or `Dim`), each at least 1, together at most
/// [`MAX_VOXELS`](crate::files::MAX_VOXELS) voxels (checked before any allocation), and
/// `Version`: `2` (raw) or `3` (zlib); files without it (the older layout with a binary
/// size header) are [`IoError::Unsupported`]. Other fields are ignored, `Lvoxel-Size`
/// included: DGtal writes `4` there and eight bytes per voxel.
///
/// Values are labels (background `0`, spacing `1`, origin `0`) when all fit a `u32`,
/// grey levels otherwise. Voxel data shorter (truncated) or longer (dimensions that do
/// not match) than declared, after decompression for version 3, and corrupt zlib data
/// are [`IoError::Format`] errors.
pub fn read_longvol_bytes(bytes: &[u8], path: &Path) -> Result<Voxels, IoError> {
    let (header, data_start) = parse_header(bytes, path, ".longvol")?;
    let dims = header.dims(path)?;
    let compressed = header.compressed(path)?;
    checked_voxel_count(path, dims, 8 + 8)?;
    let layout = Layout {
        dims: dims.map(|d| d as usize), // fits: each is at most the voxel count
        dtype: DataType::U64,
        endian: Endian::Little,
        order: Order::XFastest,
    };
    let expected = data_len(&layout);
    let data = &bytes[data_start..];
    if compressed {
        let voxels = inflate_at_most(data, expected as usize, path)?;
        check_data_len(path, voxels.len(), expected as usize, &layout)?;
        decode(path, &voxels, layout, None)
    } else {
        check_data_len(path, data.len(), expected as usize, &layout)?;
        decode(path, data, layout, None)
    }
}

#[cfg(test)]
mod tests {
    use std::io::Write;

    use flate2::write::ZlibEncoder;
    use flate2::Compression;

    use super::*;

    const P: &str = "l.longvol";

    fn read(bytes: &[u8]) -> Result<Voxels, IoError> {
        read_longvol_bytes(bytes, Path::new(P))
    }

    fn message(bytes: &[u8]) -> String {
        let text = read(bytes).unwrap_err().to_string();
        assert!(text.starts_with("l.longvol: "), "{text}");
        text
    }

    fn longvol(version: u8, values: &[u64]) -> Vec<u8> {
        longvol_x(values.len(), version, values)
    }

    fn longvol_x(x: usize, version: u8, values: &[u64]) -> Vec<u8> {
        let mut bytes = format!("X: {x}\nY: 1\nZ: 1\nLvoxel-Size: 4\nVersion: {version}\n.\n").into_bytes();
        let data: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        if version == 3 {
            let mut enc = ZlibEncoder::new(Vec::new(), Compression::default());
            enc.write_all(&data).unwrap();
            bytes.extend(enc.finish().unwrap());
        } else {
            bytes.extend(data);
        }
        bytes
    }

    #[test]
    fn bundled_test_file() {
        let bytes = std::fs::read(concat!(env!("CARGO_MANIFEST_DIR"), "/../../data/test.longvol")).unwrap();
        let Voxels::Labels(v) = read(&bytes).unwrap() else { panic!("labels expected") };
        assert_eq!(v.dims(), [16, 16, 16]);
        // One voxel of value 0xb27d, at byte 15288 of the data: index 1911.
        assert_eq!(v.label_counts(), vec![(0, 4095), (0xb27d, 1)]);
        assert_eq!(v.label([1911 % 16, (1911 / 16) % 16, 1911 / 256]), Some(0xb27d));
        for len in 0..bytes.len() {
            assert!(read(&bytes[..len]).is_err(), "prefix of {len} bytes was accepted");
        }
    }

    #[test]
    fn versions_and_wide_values() {
        for version in [2, 3] {
            let Voxels::Labels(v) = read(&longvol(version, &[0, 5, u64::from(u32::MAX)])).unwrap() else {
                panic!("labels expected")
            };
            assert_eq!(v.label([2, 0, 0]), Some(u32::MAX));
            let Voxels::Grey(g) = read(&longvol(version, &[0, 1 << 33])).unwrap() else {
                panic!("grey expected")
            };
            assert_eq!(g.values()[[1, 0, 0]], (1u64 << 33) as f64);
        }
    }

    #[test]
    fn bad_input() {
        let mut short = longvol(2, &[1, 2]);
        short.pop();
        assert!(message(&short).contains("truncated voxel data: 2x1x1 voxels of u64"));
        let mut long = longvol(2, &[1, 2]);
        long.push(0);
        assert!(message(&long).contains("dimensions do not match the data"));
        assert!(message(&longvol_x(2, 3, &[1, 2, 3])).contains("dimensions do not match the data"));
        assert!(message(&longvol_x(4, 3, &[1, 2, 3])).contains("truncated voxel data"));
        let mut corrupt = b"X: 1\nY: 1\nZ: 1\nVersion: 3\n.\n".to_vec();
        corrupt.extend_from_slice(b"not zlib");
        assert!(message(&corrupt).contains("corrupt or truncated zlib voxel data"));
        assert!(message(b"X: 1\nY: 1\nZ: 1\n.\n").contains("unsupported: no Version field"));
        assert!(message(b"X: 1\nY: 1\nZ: 1\nVersion: 1\n.\n").contains("unsupported: Version 1"));
        assert!(message(b"P3D\n1 1 1 255\n\0").contains("not a DGtal .longvol file"));
        let huge = read(b"X: 100000\nY: 100000\nZ: 100000\nVersion: 2\n.\n");
        assert!(matches!(huge, Err(IoError::TooLarge { .. })));
    }
}
