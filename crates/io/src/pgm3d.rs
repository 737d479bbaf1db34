//! DGtal `.pgm3d` volumes: the 3-D extension of PGM.
//!
//! The format: a magic, `P3D` (binary) or `P2-3D` (ASCII), then the width, height and
//! depth, then the maximum value, as whitespace-separated ASCII numbers with `#`
//! comments running to the end of a line; then the values, `x` fastest, then `y`, then
//! `z`: after a single whitespace byte, one byte each (two, big endian, when the
//! maximum value exceeds 255) for `P3D`; whitespace-separated decimal numbers for
//! `P2-3D`.

use std::path::Path;

use voxreg_digisurf::LabelVolume;

use crate::error::IoError;
use crate::files::{checked_voxel_count, read_file};

/// Reads a DGtal `.pgm3d` file (`P3D` binary or `P2-3D` ASCII) as a labeled volume.
/// See [`read_pgm3d_bytes`].
pub fn read_pgm3d(path: &Path) -> Result<LabelVolume, IoError> {
    read_pgm3d_bytes(&read_file(path)?, path)
}

/// Reads a DGtal `.pgm3d` file held in memory; `path` only names the file in errors.
///
/// Each voxel's label is its value; label `0` is the background, spacing `1`, origin
/// `0`. The maximum value must be at least 1 (at most 65535 for `P3D`) and only sets
/// the width of binary values; values above it are accepted, as DGtal writes them
/// (`cat10.pgm3d` declares `1` and holds `96`). One whitespace byte after the binary
/// data is allowed (DGtal writes a newline there). ASCII values must be integers in
/// `0..=u32::MAX`.
///
/// A missing or unknown magic, a malformed header, a zero dimension, and data shorter
/// (truncated) or longer (dimensions that do not match) than declared are
/// [`IoError::Format`] errors; dimensions above [`MAX_VOXELS`](crate::files::MAX_VOXELS) are
/// [`IoError::TooLarge`], checked before any allocation.
pub fn read_pgm3d_bytes(bytes: &[u8], path: &Path) -> Result<LabelVolume, IoError> {
    let not_pgm3d = |message: String| IoError::format(path, format!("not a DGtal .pgm3d file: {message}"));
    let mut tokens = Tokens { bytes, pos: 0 };
    let binary = match tokens.next() {
        Some(b"P3D") => true,
        Some(b"P2-3D") => false,
        Some(magic)
            if magic.len() <= 8
                && magic.starts_with(b"P")
                && magic.get(1).is_some_and(u8::is_ascii_digit) =>
        {
            return Err(IoError::unsupported(
                path,
                format!("magic '{}': only P3D (binary) and P2-3D (ASCII) are read", magic.escape_ascii()),
            ))
        }
        _ => {
            let start = &bytes[..bytes.len().min(8)];
            return Err(not_pgm3d(format!("no magic P3D or P2-3D (starts with '{}')", start.escape_ascii())));
        }
    };
    let mut header = [0u64; 4];
    for (value, name) in header.iter_mut().zip(["width", "height", "depth", "maximum value"]) {
        let Some(token) = tokens.next() else {
            return Err(not_pgm3d(format!("the header ends before its {name}")));
        };
        *value = parse_u64(token).ok_or_else(|| {
            not_pgm3d(format!("header {name}: '{}' is not a non-negative integer", token.escape_ascii()))
        })?;
    }
    let [x, y, z, max] = header;
    if [x, y, z].contains(&0) {
        return Err(IoError::format(path, format!("dimensions {x}x{y}x{z}: each must be at least 1")));
    }
    if max == 0 || (binary && max > 65535) {
        return Err(IoError::format(path, format!("maximum value {max}: must be in 1..=65535")));
    }
    let count = checked_voxel_count(path, [x, y, z], 2 + 4)?;
    let declared = || format!("{x}x{y}x{z} = {count} voxels declared");

    let labels: Vec<u32> = if binary {
        // A single whitespace byte ends the header.
        let mut data = bytes.get(tokens.pos + 1..).unwrap_or_default();
        let width = if max > 255 { 2 } else { 1 };
        let expected = count * width;
        // DGtal ends the data with a newline.
        if data.len() == expected + 1 && data[expected].is_ascii_whitespace() {
            data = &data[..expected];
        }
        if data.len() != expected {
            let what = if data.len() < expected {
                "truncated voxel data"
            } else {
                "dimensions do not match the data"
            };
            return Err(IoError::format(
                path,
                format!(
                    "{what}: {}, {} bytes each = {expected} bytes, {} found",
                    declared(),
                    width,
                    data.len()
                ),
            ));
        }
        if width == 1 {
            data.iter().map(|&b| u32::from(b)).collect()
        } else {
            data.chunks_exact(2).map(|b| u32::from(u16::from_be_bytes([b[0], b[1]]))).collect()
        }
    } else {
        // Each value takes at least two bytes: bound the allocation by the data.
        let mut labels = Vec::with_capacity(count.min(bytes.len() / 2 + 1));
        for token in tokens {
            if labels.len() == count {
                return Err(IoError::format(
                    path,
                    format!("dimensions do not match the data: {}, more values found", declared()),
                ));
            }
            let value = parse_u64(token).and_then(|v| u32::try_from(v).ok()).ok_or_else(|| {
                IoError::format(
                    path,
                    format!(
                        "value {}: '{}' is not an integer in 0..=4294967295",
                        labels.len(),
                        token.escape_ascii()
                    ),
                )
            })?;
            labels.push(value);
        }
        if labels.len() < count {
            return Err(IoError::format(
                path,
                format!("truncated voxel data: {}, {} values found", declared(), labels.len()),
            ));
        }
        labels
    };
    let dims = [x, y, z].map(|d| d as usize); // fits: each is at most the voxel count
    LabelVolume::from_x_fastest(dims, labels)
        .map_err(|source| IoError::Volume { path: path.to_path_buf(), source })
}

fn parse_u64(token: &[u8]) -> Option<u64> {
    std::str::from_utf8(token).ok()?.parse().ok()
}

/// Whitespace-separated tokens, skipping `#` comments to the end of the line.
struct Tokens<'a> {
    bytes: &'a [u8],
    /// Just past the last token returned.
    pos: usize,
}

impl<'a> Iterator for Tokens<'a> {
    type Item = &'a [u8];

    fn next(&mut self) -> Option<&'a [u8]> {
        loop {
            match self.bytes.get(self.pos)? {
                b if b.is_ascii_whitespace() => self.pos += 1,
                b'#' => {
                    let rest = &self.bytes[self.pos..];
                    self.pos += rest.iter().position(|&b| b == b'\n').unwrap_or(rest.len());
                }
                _ => break,
            }
        }
        let start = self.pos;
        let rest = &self.bytes[start..];
        self.pos += rest.iter().position(|&b| b.is_ascii_whitespace() || b == b'#').unwrap_or(rest.len());
        Some(&self.bytes[start..self.pos])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const P: &str = "v.pgm3d";

    fn read(bytes: &[u8]) -> Result<LabelVolume, IoError> {
        read_pgm3d_bytes(bytes, Path::new(P))
    }

    fn message(bytes: &[u8]) -> String {
        let text = read(bytes).unwrap_err().to_string();
        assert!(text.starts_with("v.pgm3d: "), "{text}");
        text
    }

    fn data(name: &str) -> Vec<u8> {
        std::fs::read(Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../../data")).join(name)).unwrap()
    }

    #[test]
    fn bundled_files() {
        let cat = read(&data("cat10.pgm3d")).unwrap();
        assert_eq!(cat.dims(), [40, 40, 40]);
        assert_eq!(cat.label_counts(), vec![(0, 55957), (96, 8043)]);
        // The same cat as cat10.vol, voxel for voxel.
        let vol =
            crate::vol::read_vol(Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../../data/cat10.vol")))
                .unwrap();
        assert_eq!(cat, vol);
        let ball = read(&data("ascii_ball.pgm3d")).unwrap();
        assert_eq!(ball.dims(), [9, 9, 9]);
        assert_eq!(ball.label_counts(), vec![(0, 472), (255, 257)]);
        assert_eq!(ball.label([4, 4, 4]), Some(255));
        assert_eq!(ball.label([0, 0, 0]), Some(0));
    }

    #[test]
    fn binary_and_ascii_with_comments() {
        let v = read(b"P3D\n# a comment\n2 1 2 # trailing\n255\n\x01\x02\x03\x04").unwrap();
        assert_eq!(v.label([1, 0, 0]), Some(2));
        assert_eq!(v.label([0, 0, 1]), Some(3));
        let wide = read(b"P3D 1 1 2 1000\n\x03\xe8\x00\x07").unwrap();
        assert_eq!(wide.label([0, 0, 0]), Some(1000));
        assert_eq!(wide.label([0, 0, 1]), Some(7));
        let ascii = read(b"P2-3D\n2 2 1\n# max\n70000\n1 2\n3 70000\n").unwrap();
        assert!(read(b"P3D\n1 1 1 255\n\x07\n").is_ok());
        assert_eq!(ascii.label([1, 1, 0]), Some(70000));
    }

    #[test]
    fn bad_input() {
        let cases: &[(&[u8], &str)] = &[
            (b"", "no magic P3D or P2-3D"),
            (b"P5\n1 1\n255\n\0", "unsupported: magic 'P5'"),
            (b"X: 1\n", "no magic"),
            (b"P3D\n2 2", "the header ends before its depth"),
            (b"P3D\n2 -2 2 255\n", "header height: '-2' is not a non-negative integer"),
            (b"P3D\n2 0 2 255\n", "dimensions 2x0x2: each must be at least 1"),
            (b"P3D\n1 1 1 0\n\0", "maximum value 0"),
            (b"P3D\n1 1 1 70000\n\0\0", "maximum value 70000"),
            (
                b"P3D\n2 1 1 255\n\0",
                "truncated voxel data: 2x1x1 = 2 voxels declared, 1 bytes each = 2 bytes, 1 found",
            ),
            (b"P3D\n2 1 1 255\n\0\0\0", "dimensions do not match the data"),
            (b"P3D\n2 1 1 255\n\0\0\n\n", "dimensions do not match the data"),
            (b"P3D\n1 1 1 256\n\0", "truncated voxel data"),
            (b"P2-3D\n2 1 1 255\n1", "truncated voxel data: 2x1x1 = 2 voxels declared, 1 values found"),
            (b"P2-3D\n2 1 1 255\n1 2 3", "dimensions do not match the data"),
            (b"P2-3D\n2 1 1 255\n1 -2", "value 1: '-2' is not an integer"),
            (b"P2-3D\n1 1 1 255\n4294967296", "value 0: '4294967296' is not an integer"),
        ];
        crate::testing::assert_refused(cases, message);
        let huge = read(b"P3D\n100000 100000 100000 255\n\0");
        assert!(matches!(huge, Err(IoError::TooLarge { .. })));
    }

    #[test]
    fn never_panics_on_prefixes_of_a_real_file() {
        let bytes = data("ascii_ball.pgm3d");
        for len in 0..bytes.len() {
            let _ = read(&bytes[..len]);
        }
    }
}
