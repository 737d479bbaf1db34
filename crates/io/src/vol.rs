//! DGtal `.vol` volumes.
//!
//! The format: an ASCII header of `Key: value` lines, ended by a line holding a single
//! `.`, then one byte per voxel with `x` fastest, then `y`, then `z`. Version 2 stores
//! the bytes raw; version 3 compresses them with zlib.

use std::io::Read;
use std::path::Path;

use flate2::read::ZlibDecoder;
use voxreg_digisurf::LabelVolume;

use crate::error::IoError;
use crate::files::{checked_voxel_count, read_file};

/// At most this many header lines before the `.` line (as DGtal).
const MAX_HEADER_LINES: usize = 64;
/// At most this many bytes in a header line.
const MAX_LINE_LEN: usize = 256;

/// Reads a DGtal `.vol` file (versions 2 and 3) as a labeled volume.
///
/// Each voxel's label is its byte value; label `0` is the background, spacing is `1`
/// and the origin `0` (the `Center-*` fields are ignored). See [`read_vol_bytes`] for
/// what is accepted.
pub fn read_vol(path: &Path) -> Result<LabelVolume, IoError> {
    read_vol_bytes(&read_file(path)?, path)
}

/// Reads a DGtal `.vol` file held in memory; `path` only names the file in errors.
///
/// Header fields read:
///
/// - `X`, `Y`, `Z` (or `Dim: x y z`): the dimensions, each at least 1 and together at
///   most [`MAX_VOXELS`](crate::files::MAX_VOXELS) voxels, checked before any allocation;
/// - `Version`: `2` (raw bytes) or `3` (zlib); files without it (the older layout with
///   a binary size header) are refused with [`IoError::Unsupported`];
/// - `Voxel-Size`: must be `1` (one byte per voxel) when present.
///
/// Other fields (`Int-Endian`, `Voxel-Endian`, `Alpha-Color`, `Center-X`, ...) are
/// ignored; a byte has no endianness. The voxel data must hold exactly `X * Y * Z` bytes
/// (after decompression for version 3): fewer is a truncated file, more a header whose
/// dimensions do not match the data, and both are [`IoError::Format`] errors.
pub fn read_vol_bytes(bytes: &[u8], path: &Path) -> Result<LabelVolume, IoError> {
    let (header, data_start) = parse_header(bytes, path, ".vol")?;
    let dims = header.dims(path)?;
    if let Some(size) = header.get("Voxel-Size") {
        if size != "1" {
            return Err(IoError::unsupported(
                path,
                format!("Voxel-Size {size}: only one byte per voxel (Voxel-Size: 1) is read"),
            ));
        }
    }
    let compressed = header.compressed(path)?;
    let count = checked_voxel_count(path, dims, 1 + 4)?;
    let data = &bytes[data_start..];
    let describe = || format!("{}x{}x{} = {count} voxels declared", dims[0], dims[1], dims[2]);

    let labels: Vec<u32> = if compressed {
        let voxels = inflate_at_most(data, count, path)?;
        check_len(path, voxels.len(), count, &describe, " after decompression")?;
        voxels.into_iter().map(u32::from).collect()
    } else {
        check_len(path, data.len(), count, &describe, "")?;
        data.iter().copied().map(u32::from).collect()
    };
    let dims = dims.map(|d| d as usize); // fits: each is at most the voxel count
    LabelVolume::from_x_fastest(dims, labels)
        .map_err(|source| IoError::Volume { path: path.to_path_buf(), source })
}

fn check_len(
    path: &Path,
    found: usize,
    count: usize,
    describe: &dyn Fn() -> String,
    when: &str,
) -> Result<(), IoError> {
    if found < count {
        Err(IoError::format(path, format!("truncated voxel data: {}, {found} bytes found{when}", describe())))
    } else if found > count {
        Err(IoError::format(
            path,
            format!("dimensions do not match the data: {}, more bytes found{when}", describe()),
        ))
    } else {
        Ok(())
    }
}

/// The header's `(key, value)` fields, in file order.
pub(crate) struct Header {
    fields: Vec<(String, String)>,
}

impl Header {
    /// The value of the first field named `key`, trimmed.
    pub(crate) fn get(&self, key: &str) -> Option<&str> {
        self.fields.iter().find(|(k, _)| k == key).map(|(_, v)| v.as_str())
    }

    /// Whether the voxel data is zlib-compressed: `Version` 3, or 2 for raw data; other
    /// versions are refused.
    pub(crate) fn compressed(&self, path: &Path) -> Result<bool, IoError> {
        match self.get("Version") {
            Some("2") => Ok(false),
            Some("3") => Ok(true),
            Some(v) => Err(IoError::unsupported(
                path,
                format!("Version {v}: only versions 2 (raw) and 3 (zlib) are read"),
            )),
            None => Err(IoError::unsupported(
                path,
                "no Version field: the pre-version-2 layout (binary size header) is not read",
            )),
        }
    }

    pub(crate) fn dims(&self, path: &Path) -> Result<[u64; 3], IoError> {
        let parse = |key: &str, text: &str| {
            text.parse::<u64>().map_err(|_| {
                IoError::format(path, format!("header field {key}: '{text}' is not a non-negative integer"))
            })
        };
        let xyz = ["X", "Y", "Z"].map(|k| self.get(k));
        let dims = if let [Some(x), Some(y), Some(z)] = xyz {
            [parse("X", x)?, parse("Y", y)?, parse("Z", z)?]
        } else if let Some(dim) = self.get("Dim") {
            let parts: Vec<&str> = dim.split_whitespace().collect();
            let [x, y, z] = parts[..] else {
                return Err(IoError::format(
                    path,
                    format!("header field Dim: '{dim}' is not three integers"),
                ));
            };
            [parse("Dim", x)?, parse("Dim", y)?, parse("Dim", z)?]
        } else {
            let missing: Vec<&str> =
                ["X", "Y", "Z"].into_iter().zip(xyz).filter(|(_, v)| v.is_none()).map(|(k, _)| k).collect();
            return Err(IoError::format(
                path,
                format!("missing dimensions: no header field {} (nor Dim)", missing.join(", ")),
            ));
        };
        if dims.contains(&0) {
            return Err(IoError::format(
                path,
                format!("dimensions {}x{}x{}: each must be at least 1", dims[0], dims[1], dims[2]),
            ));
        }
        Ok(dims)
    }
}

/// Inflates zlib `data` declared to hold `expected` bytes, reading at most one byte more:
/// a zlib bomb or a header that understates the data is caught without inflating
/// everything (the caller compares the length with `expected`).
pub(crate) fn inflate_at_most(data: &[u8], expected: usize, path: &Path) -> Result<Vec<u8>, IoError> {
    let mut out = Vec::with_capacity(expected.min(1 << 24));
    ZlibDecoder::new(data)
        .take(expected as u64 + 1)
        .read_to_end(&mut out)
        .map_err(|e| IoError::format(path, format!("corrupt or truncated zlib voxel data: {e}")))?;
    Ok(out)
}

/// Splits the header off `bytes`: its fields and the offset of the voxel data. `format`
/// (`.vol`, `.longvol`) names the format in errors.
pub(crate) fn parse_header(bytes: &[u8], path: &Path, format: &str) -> Result<(Header, usize), IoError> {
    let not_vol = |message: String| IoError::format(path, format!("not a DGtal {format} file: {message}"));
    if bytes.is_empty() {
        return Err(not_vol("the file is empty".into()));
    }
    let mut fields = Vec::new();
    let mut pos = 0;
    for line_no in 1..=MAX_HEADER_LINES + 1 {
        let rest = &bytes[pos..];
        let Some(len) = rest.iter().take(MAX_LINE_LEN + 1).position(|&b| b == b'\n') else {
            return Err(if rest.len() > MAX_LINE_LEN {
                not_vol(format!("header line {line_no} is longer than {MAX_LINE_LEN} bytes"))
            } else {
                not_vol("the header ends before its end line '.'".into())
            });
        };
        let line = rest[..len].strip_suffix(b"\r").unwrap_or(&rest[..len]);
        pos += len + 1;
        if line == b"." {
            return Ok((Header { fields }, pos));
        }
        if line_no > MAX_HEADER_LINES {
            break;
        }
        let text = std::str::from_utf8(line)
            .map_err(|_| not_vol(format!("header line {line_no} is not text: {}", line.escape_ascii())))?;
        let Some((key, value)) = text.split_once(':').filter(|(k, _)| !k.trim().is_empty()) else {
            return Err(not_vol(format!(
                "header line {line_no} is not 'Key: value': '{}'",
                text.escape_debug()
            )));
        };
        fields.push((key.trim().to_owned(), value.trim().to_owned()));
    }
    Err(not_vol(format!("no header end line '.' within {MAX_HEADER_LINES} lines")))
}

#[cfg(test)]
mod tests {
    use std::io::Write;

    use flate2::write::ZlibEncoder;
    use flate2::Compression;

    use super::*;

    const P: &str = "test.vol";

    fn vol(header: &str, data: &[u8], version3: bool) -> Vec<u8> {
        let mut bytes = header.as_bytes().to_vec();
        if version3 {
            let mut enc = ZlibEncoder::new(Vec::new(), Compression::default());
            enc.write_all(data).unwrap();
            bytes.extend(enc.finish().unwrap());
        } else {
            bytes.extend_from_slice(data);
        }
        bytes
    }

    fn read(bytes: &[u8]) -> Result<LabelVolume, IoError> {
        read_vol_bytes(bytes, Path::new(P))
    }

    fn message(bytes: &[u8]) -> String {
        let err = read(bytes).unwrap_err();
        let text = err.to_string();
        assert!(text.starts_with("test.vol: "), "error does not name the file: {text}");
        text
    }

    const HEADER: &str = "Center-X: 1\nCenter-Y: 1\nCenter-Z: 0\nX: 3\nY: 2\nZ: 2\nVoxel-Size: 1\n\
                          Alpha-Color: 0\nVoxel-Endian: 0\nInt-Endian: 0123\nVersion: 3\n.\n";

    #[test]
    fn reads_version_3_x_fastest() {
        let data: Vec<u8> = (0..12).collect();
        let v = read(&vol(HEADER, &data, true)).unwrap();
        assert_eq!(v.dims(), [3, 2, 2]);
        assert_eq!(v.label([1, 0, 0]), Some(1));
        assert_eq!(v.label([0, 1, 0]), Some(3));
        assert_eq!(v.label([0, 0, 1]), Some(6));
        assert_eq!(v.label([2, 1, 1]), Some(11));
        assert_eq!(v.background(), Some(0));
        assert_eq!(v.spacing(), glam::DVec3::ONE);
        assert_eq!(v.origin(), glam::DVec3::ZERO);
    }

    #[test]
    fn reads_version_2_raw_dim_field_and_crlf() {
        let header = "Dim: 2 1 3\r\nVersion: 2\r\n.\r\n";
        let v = read(&vol(header, &[0, 255, 7, 0, 0, 9], false)).unwrap();
        assert_eq!(v.dims(), [2, 1, 3]);
        assert_eq!(v.label([1, 0, 0]), Some(255));
        assert_eq!(v.label([1, 0, 2]), Some(9));
    }

    #[test]
    fn truncated_data() {
        let data: Vec<u8> = (0..12).collect();
        let full = vol(HEADER, &data, true);
        for cut in [1, 4, full.len() - HEADER.len() - 1] {
            let text = message(&full[..full.len() - cut]);
            assert!(text.contains("truncated"), "cut {cut}: {text}");
        }
        let raw = vol(&HEADER.replace("Version: 3", "Version: 2"), &data[..11], false);
        assert!(message(&raw).contains("truncated voxel data: 3x2x2 = 12 voxels declared, 11 bytes found"));
    }

    #[test]
    fn dims_do_not_match_data() {
        let text = message(&vol(HEADER, &[1; 13], true));
        assert!(text.contains("dimensions do not match the data"), "{text}");
        let raw = vol("X: 1\nY: 1\nZ: 1\nVersion: 2\n.\n", &[1, 2], false);
        assert!(message(&raw).contains("dimensions do not match the data"));
    }

    #[test]
    fn corrupt_zlib() {
        let mut bytes = HEADER.as_bytes().to_vec();
        bytes.extend_from_slice(b"this is not zlib at all");
        assert!(message(&bytes).contains("corrupt or truncated zlib voxel data"));
    }

    #[test]
    fn absurd_dims_refused_before_allocating() {
        let header = "X: 100000\nY: 100000\nZ: 100000\nVoxel-Size: 1\nVersion: 3\n.\n";
        let err = read(&vol(header, &[0; 16], true)).unwrap_err();
        assert!(matches!(err, IoError::TooLarge { dims: [100000, 100000, 100000], .. }), "{err}");
        assert_eq!(
            err.to_string(),
            "test.vol: volume of 100000x100000x100000 voxels exceeds the limit of 2147483648 voxels"
        );
        let huge = "X: 18446744073709551615\nY: 18446744073709551615\nZ: 2\nVersion: 2\n.\n";
        assert!(matches!(read(huge.as_bytes()), Err(IoError::TooLarge { .. })));
    }

    #[test]
    fn bad_headers() {
        let cases: &[(&[u8], &str)] = &[
            (b"", "the file is empty"),
            (b"VOX \x96\0\0\0MAIN", "the header ends before its end line"),
            (b"VOX \x96\0\0\0MAIN\n.\n", "header line 1 is not text"),
            (b"hello world\n.\n", "header line 1 is not 'Key: value'"),
            (b": 3\n.\n", "header line 1 is not 'Key: value'"),
            (&[b'a'; 300], "header line 1 is longer than 256 bytes"),
            (b"X: 1\nY: 1\nZ: 1\nVersion: 2\n", "the header ends before its end line"),
            (b"X: 1\nZ: 1\nVersion: 2\n.\n", "no header field Y (nor Dim)"),
            (b"X: -1\nY: 1\nZ: 1\nVersion: 2\n.\n", "header field X: '-1' is not a non-negative integer"),
            (b"X: 0\nY: 1\nZ: 1\nVersion: 2\n.\n", "dimensions 0x1x1: each must be at least 1"),
            (b"Dim: 1 2\nVersion: 2\n.\n", "header field Dim: '1 2' is not three integers"),
            (b"X: 1\nY: 1\nZ: 1\nVersion: 4\n.\n", "unsupported: Version 4"),
            (b"X: 1\nY: 1\nZ: 1\n.\n", "unsupported: no Version field"),
            (b"X: 1\nY: 1\nZ: 1\nVoxel-Size: 4\nVersion: 2\n.\n\0\0\0\0", "unsupported: Voxel-Size 4"),
        ];
        crate::testing::assert_refused(cases, message);
        let many = "Comment: x\n".repeat(MAX_HEADER_LINES + 1) + ".\n";
        assert!(message(many.as_bytes()).contains("no header end line '.' within 64 lines"));
    }

    #[test]
    fn never_panics_on_prefixes_of_a_real_file() {
        let bytes = std::fs::read(concat!(env!("CARGO_MANIFEST_DIR"), "/../../data/cat10.vol")).unwrap();
        for len in 0..bytes.len() {
            assert!(read(&bytes[..len]).is_err(), "prefix of {len} bytes was accepted");
        }
        assert!(read(&bytes).is_ok());
    }
}
