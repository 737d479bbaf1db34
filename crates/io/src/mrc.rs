//! MRC / CCP4 maps (`.mrc`, `.map`, `.rec`): cryo-EM and tomography volumes.
//!
//! Hand-written: the format is one fixed 1024-byte header and a data block, and no
//! maintained Rust crate reads it without pulling in an image stack.

use std::path::Path;

use glam::{DMat3, DVec3};

use crate::error::IoError;
use crate::files::{checked_voxel_count, read_file};
use crate::loaded::LoadedVoxels;
use crate::orient::place;
use crate::samples::{check_data_len, data_len, decode, Layout, Order};
use crate::samples::{DataType, Endian};

/// The fixed header's length.
const HEADER_LEN: usize = 1024;

/// Reads an MRC file (`.mrc`, `.map`, `.rec`), see [`read_mrc_bytes`].
pub fn read_mrc(path: &Path) -> Result<LoadedVoxels, IoError> {
    read_mrc_bytes(&read_file(path)?, path)
}

/// Reads an MRC2014 (or older CCP4-style) file held in `bytes`; `path` names it in
/// errors.
///
/// Modes 0 (8-bit signed), 1 (16-bit signed) and 6 (16-bit unsigned) are labels;
/// mode 2 (32-bit float) grey levels. The byte order is the machine stamp's (`0x44`
/// little-endian, `0x11` big-endian). Values run columns fastest, then rows, then
/// sections; `MAPC`/`MAPR`/`MAPS` say which axis each is (permutations applied), after
/// the `NSYMBT` bytes of extended header. Spacing: the cell length over the sampling
/// (`CELLA / MX`...) in ångström (units `Å`), unit spacing without a cell; origin:
/// `ORIGIN`, or the start indices times the spacing when `ORIGIN` is zero. A cell or an
/// origin that is NaN, infinite or negative (the cell) is an [`IoError::Format`], not
/// replaced.
pub fn read_mrc_bytes(bytes: &[u8], path: &Path) -> Result<LoadedVoxels, IoError> {
    let Some(header) = bytes.get(..HEADER_LEN) else {
        return Err(IoError::format(
            path,
            format!("not an MRC file: {} bytes, shorter than its 1024-byte header", bytes.len()),
        ));
    };
    let endian = match header[212] {
        0x11 => Endian::Big,
        _ => Endian::Little,
    };
    let word = |i: usize| {
        let b: [u8; 4] = header[4 * i..4 * i + 4].try_into().unwrap_or_default();
        match endian {
            Endian::Little => i32::from_le_bytes(b),
            Endian::Big => i32::from_be_bytes(b),
        }
    };
    let float = |i: usize| f64::from(f32::from_bits(word(i) as u32));
    if &header[208..212] != b"MAP " && !(1..=3).contains(&word(16)) {
        return Err(IoError::format(path, "not an MRC file: no 'MAP ' stamp and no axis map"));
    }
    let dims = [word(0), word(1), word(2)];
    if dims.iter().any(|&d| d <= 0) {
        return Err(IoError::format(
            path,
            format!("dimensions {}x{}x{} are not positive", dims[0], dims[1], dims[2]),
        ));
    }
    let mode = word(3);
    let dtype = match mode {
        0 => DataType::I8,
        1 => DataType::I16,
        2 => DataType::F32,
        6 => DataType::U16,
        other => {
            return Err(IoError::unsupported(path, format!("mode {other} (modes 0, 1, 2 and 6 are read)")))
        }
    };
    let dims = dims.map(|d| d as u64);
    checked_voxel_count(path, dims, dtype.size() as u64 + 8)?;
    // Index axis k (column, row, section) is world axis map[k].
    let map = [word(16), word(17), word(18)];
    let map = if map == [0, 0, 0] { [1, 2, 3] } else { map };
    let mut sorted = map;
    sorted.sort_unstable();
    if sorted != [1, 2, 3] {
        return Err(IoError::format(path, format!("axis map {map:?} is not a permutation of 1, 2, 3")));
    }
    let sampling = [word(7), word(8), word(9)];
    let cell = [float(10), float(11), float(12)];
    // A zero cell (or sampling) is MRC's "unset": spacing 1. A cell that is not a size
    // is a corrupt header, not a spacing to replace silently.
    if cell.iter().any(|c| !c.is_finite() || *c < 0.0) {
        return Err(IoError::format(
            path,
            format!("cell {} x {} x {} is not a size (finite, not negative)", cell[0], cell[1], cell[2]),
        ));
    }
    let has_cell = (0..3).all(|a| sampling[a] > 0 && cell[a].is_finite() && cell[a] > 0.0);
    let step = if has_cell {
        DVec3::from_array(std::array::from_fn(|a| cell[a] / f64::from(sampling[a])))
    } else {
        DVec3::ONE
    };
    let mut matrix = DMat3::ZERO;
    for k in 0..3 {
        let a = (map[k] - 1) as usize;
        matrix.col_mut(k)[a] = step[a];
    }
    let origin_field = DVec3::new(float(49), float(50), float(51));
    if !origin_field.is_finite() {
        return Err(IoError::format(path, format!("origin {origin_field} is not finite")));
    }
    let origin = if origin_field != DVec3::ZERO {
        origin_field
    } else {
        let start = [word(4), word(5), word(6)];
        (0..3).map(|k| matrix.col(k) * f64::from(start[k])).sum()
    };
    let extended = usize::try_from(word(23))
        .map_err(|_| IoError::format(path, format!("extended header length {}", word(23))))?;
    let Some(data) = bytes.get(HEADER_LEN.saturating_add(extended)..) else {
        return Err(IoError::format(
            path,
            format!("the file ends inside its {extended}-byte extended header"),
        ));
    };
    let layout = Layout { dims: dims.map(|d| d as usize), dtype, endian, order: Order::XFastest };
    check_data_len(path, data.len(), data_len(&layout) as usize, &layout)?;
    let voxels = decode(path, data, layout, None)?;
    let (voxels, _) =
        place(voxels, matrix, origin).map_err(|e| IoError::format(path, format!("placement: {e}")))?;
    let units = has_cell.then(|| "Å".to_string());
    Ok(LoadedVoxels { voxels, palette: None, units })
}
