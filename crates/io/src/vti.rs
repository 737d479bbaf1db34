//! VTK XML image data (`.vti`), as written by VTK, ParaView and pyvista.
//!
//! The format: an XML document `<VTKFile type="ImageData">` holding an `<ImageData>`
//! (`WholeExtent`, `Origin`, `Spacing`, `Direction`) with one or more `<Piece>`s, each
//! with `<PointData>` and `<CellData>` holding `<DataArray>`s. An array's values are
//! inline ASCII (`format="ascii"`), inline base64 (`format="binary"`), or in the
//! `<AppendedData>` section at the end of the file (`format="appended"`, at byte
//! `offset`), raw or base64. Binary data start with a header of `UInt32` or `UInt64`
//! words (`header_type`): the byte count, or, when compressed, the number of blocks,
//! the block size, the size of the last block and each block's compressed size.

use std::path::Path;

use glam::{DMat3, DVec3};
use roxmltree::{Document, Node};

use crate::error::IoError;
use crate::files::{checked_voxel_count, read_file};
use crate::grey::Voxels;
use crate::orient::place;
use crate::samples::{decode, Layout, Order};
use crate::samples::{DataType, Endian};

mod binary;
#[cfg(test)]
mod tests;

use binary::{read_binary, Base64, Raw};

/// Reads a VTK XML image data file (`.vti`). See [`read_vti_bytes`].
pub fn read_vti(path: &Path) -> Result<Voxels, IoError> {
    read_vti_bytes(&read_file(path)?, path)
}

/// Reads a VTK XML image data file held in memory; `path` only names the file in
/// errors.
///
/// **Which array.** The active scalars of the cell data (its `Scalars` attribute), else
/// those of the point data, else the first cell-data array, else the first point-data
/// array. It must have one component, of type `Int8` ... `UInt64`, `Float32` or
/// `Float64`. Values are labels (background `0`) when all are integers in
/// `0..=u32::MAX`, grey levels otherwise; a NaN is an error.
///
/// **Space.** Cell data: one voxel per cell, the centre of cell `i` at
/// `Origin + (extent start + i + 0.5) * Spacing` (a flat axis of one point has one
/// cell, centred on it). Point data: one voxel per point, centred on it. A `Direction`
/// that only permutes and flips the axes, and negative spacings, are applied exactly
/// (the volume is re-stored to follow the world axes); an oblique `Direction` is
/// dropped, keeping spacing and origin.
///
/// **Encodings.** `ascii`, `binary` (base64) and `appended` (`raw` or `base64`), in
/// either `byte_order`, with `UInt32` or `UInt64` headers, uncompressed or compressed by
/// `vtkZLibDataCompressor` (LZ4 and LZMA are [`IoError::Unsupported`]). Several pieces
/// are assembled into the whole extent; together they must hold at least as many values
/// as the whole extent has voxels.
///
/// **Refused.** Malformed XML, another root than `VTKFile`, missing or malformed
/// extents, a piece outside the whole extent, arrays whose size does not match the
/// extent (truncated or longer data), bad base64 or zlib data are
/// [`IoError::Format`]; other dataset types, multi-component arrays and other types
/// are [`IoError::Unsupported`]; extents above [`MAX_VOXELS`](crate::files::MAX_VOXELS) are
/// [`IoError::TooLarge`], checked before any allocation.
pub fn read_vti_bytes(bytes: &[u8], path: &Path) -> Result<Voxels, IoError> {
    let malformed = |message: String| IoError::format(path, message);
    let (xml, appended) = split_appended(bytes).map_err(malformed)?;
    let doc =
        Document::parse(&xml).map_err(|e| malformed(format!("not a VTK XML file: malformed XML: {e}")))?;
    let root = doc.root_element();
    if !root.has_tag_name("VTKFile") {
        return Err(malformed(format!(
            "not a VTK XML file: the root element is <{}>",
            root.tag_name().name()
        )));
    }
    match root.attribute("type") {
        Some("ImageData") => {}
        Some(other) => {
            return Err(IoError::unsupported(
                path,
                format!("VTK dataset type {other} (only ImageData is read)"),
            ))
        }
        None => return Err(malformed("<VTKFile> has no type attribute".into())),
    }
    let endian = match root.attribute("byte_order").unwrap_or("LittleEndian") {
        "LittleEndian" => Endian::Little,
        "BigEndian" => Endian::Big,
        other => return Err(malformed(format!("unknown byte_order '{other}'"))),
    };
    let word = match root.attribute("header_type").unwrap_or("UInt32") {
        "UInt32" => 4,
        "UInt64" => 8,
        other => {
            return Err(IoError::unsupported(
                path,
                format!("header_type {other} (UInt32 and UInt64 are read)"),
            ))
        }
    };
    let compressed = match root.attribute("compressor") {
        None | Some("") => false,
        Some("vtkZLibDataCompressor") => true,
        Some(other) => {
            return Err(IoError::unsupported(
                path,
                format!("compressor {other} (only vtkZLibDataCompressor is read)"),
            ))
        }
    };
    let codec = Codec { endian, word, compressed };

    let image = child(root, "ImageData").ok_or_else(|| malformed("no <ImageData> element".into()))?;
    let whole = parse_extent(image.attribute("WholeExtent"), "WholeExtent").map_err(malformed)?;
    let origin = parse_floats::<3>(image.attribute("Origin"), "Origin", [0.0; 3]).map_err(malformed)?;
    let spacing = parse_floats::<3>(image.attribute("Spacing"), "Spacing", [1.0; 3]).map_err(malformed)?;
    let identity = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];
    let direction =
        parse_floats::<9>(image.attribute("Direction"), "Direction", identity).map_err(malformed)?;

    let pieces: Vec<Node> = image.children().filter(|n| n.has_tag_name("Piece")).collect();
    let first = pieces.first().ok_or_else(|| malformed("no <Piece> in <ImageData>".into()))?;
    let (section, name, index) =
        choose_array(*first).ok_or_else(|| malformed("no <DataArray> in the first <Piece>".into()))?;
    let cells = section == "CellData";
    let dims = whole.map(|(lo, hi)| extent_len(lo, hi, cells));
    let count = checked_voxel_count(path, dims, 8 + 8 + 8)?;
    let dims = dims.map(|d| d as usize); // fits: each is at most the voxel count

    let mut dtype = None;
    let mut assembled: Option<Vec<u8>> = None;
    let mut covered = 0usize;
    // Which voxels the pieces have filled, one bit each, once there are several pieces.
    let mut filled: Vec<u64> = Vec::new();
    let mut boxes: Vec<([usize; 3], [usize; 3])> = Vec::new();
    for (k, piece) in pieces.iter().enumerate() {
        let where_ = format!("piece {k}");
        let extent = match piece.attribute("Extent") {
            Some(_) => parse_extent(piece.attribute("Extent"), "Extent")
                .map_err(|e| malformed(format!("{where_}: {e}")))?,
            None => whole,
        };
        if (0..3).any(|a| extent[a].0 < whole[a].0 || extent[a].1 > whole[a].1) {
            return Err(malformed(format!("{where_}: its Extent lies outside the WholeExtent")));
        }
        let pdims = extent.map(|(lo, hi)| extent_len(lo, hi, cells) as usize);
        let offset = [0, 1, 2].map(|a| (extent[a].0 - whole[a].0) as usize);
        if (0..3).any(|a| offset[a] + pdims[a] > dims[a]) {
            return Err(malformed(format!("{where_}: its Extent lies outside the WholeExtent")));
        }
        let pcount = pdims.iter().product::<usize>(); // at most the whole count
        let array = find_array(*piece, section, name, index).ok_or_else(|| {
            malformed(format!("{where_}: no {section} array {}", name.unwrap_or("(unnamed)")))
        })?;
        let (t, data) = read_array(array, pcount, codec, appended.as_ref())
            .map_err(|e| {
                malformed(format!(
                    "{where_}, {section} array '{}': {e}",
                    array.attribute("Name").unwrap_or("")
                ))
            })?
            .map_err(|e| IoError::unsupported(path, e))?;
        if dtype.is_some_and(|d| d != t) {
            return Err(malformed(format!("{where_}: the array's type differs from the first piece's")));
        }
        dtype = Some(t);
        // Cell-data pieces tile the extent; point-data pieces share their boundary points
        // (VTK writes them in both), so only cells are refused for overlapping.
        if cells {
            if let Some(j) = boxes
                .iter()
                .position(|&(o, d)| (0..3).all(|a| offset[a] < o[a] + d[a] && o[a] < offset[a] + pdims[a]))
            {
                return Err(malformed(format!("{where_}: its Extent overlaps that of piece {j}")));
            }
            boxes.push((offset, pdims));
        }
        covered += pcount;
        if pdims == dims {
            assembled = Some(data);
        } else {
            let buffer = assembled.get_or_insert_with(Vec::new);
            if buffer.is_empty() {
                // Allocate the whole volume only once a piece's data exist (bounded
                // by the data actually decoded, see the coverage check below).
                if pcount.saturating_mul(pieces.len()) < count {
                    return Err(malformed(format!(
                        "{} pieces of at most {pcount} voxels cannot cover the {count} voxels of the WholeExtent",
                        pieces.len()
                    )));
                }
                buffer.resize(count * t.size(), 0);
                filled = vec![0; count.div_ceil(64)];
            }
            copy_piece(buffer, &data, dims, pdims, offset, t.size());
            mark_piece(&mut filled, dims, pdims, offset);
        }
    }
    if covered < count {
        return Err(malformed(format!(
            "the pieces hold {covered} values for the {count} voxels of the WholeExtent"
        )));
    }
    if let Some(hole) = first_unfilled(&filled, count) {
        let (x, y, z) = (hole % dims[0], hole / dims[0] % dims[1], hole / dims[0] / dims[1]);
        return Err(malformed(format!("no piece covers voxel [{x}, {y}, {z}] of the WholeExtent")));
    }
    let (Some(dtype), Some(data)) = (dtype, assembled) else {
        return Err(malformed("no data".into()));
    };
    let layout = Layout { dims, dtype, endian: Endian::Little, order: Order::XFastest };
    let voxels = decode(path, &data, layout, None)?;

    // Index-to-world: world = Origin + Direction * ((start + i + half) * Spacing).
    let d = |r: usize, c: usize| direction[3 * r + c];
    let dir = DMat3::from_cols(
        DVec3::new(d(0, 0), d(1, 0), d(2, 0)),
        DVec3::new(d(0, 1), d(1, 1), d(2, 1)),
        DVec3::new(d(0, 2), d(1, 2), d(2, 2)),
    );
    let spacing = DVec3::from_array(spacing);
    let half = |a: usize| if cells && whole[a].1 > whole[a].0 { 0.5 } else { 0.0 };
    let start =
        DVec3::new(whole[0].0 as f64 + half(0), whole[1].0 as f64 + half(1), whole[2].0 as f64 + half(2));
    let matrix = dir * DMat3::from_diagonal(spacing);
    let translation = DVec3::from_array(origin) + dir * (start * spacing);
    let (voxels, _) = place(voxels, matrix, translation)
        .map_err(|source| IoError::Volume { path: path.to_path_buf(), source })?;
    Ok(voxels)
}

/// Number of voxels along an axis of extent `lo..=hi`: points, or cells (one for a flat
/// axis).
fn extent_len(lo: i64, hi: i64, cells: bool) -> u64 {
    let points = (hi - lo) as u64 + 1;
    if cells {
        (points - 1).max(1)
    } else {
        points
    }
}

/// Copies the values of a piece of dimensions `pdims` into the whole volume's buffer at
/// voxel `offset` (`x` fastest, `size` bytes per value).
fn copy_piece(
    buffer: &mut [u8],
    data: &[u8],
    dims: [usize; 3],
    pdims: [usize; 3],
    offset: [usize; 3],
    size: usize,
) {
    let row = pdims[0] * size;
    for z in 0..pdims[2] {
        for y in 0..pdims[1] {
            let src = (z * pdims[1] + y) * row;
            let dst = (((offset[2] + z) * dims[1] + offset[1] + y) * dims[0] + offset[0]) * size;
            buffer[dst..dst + row].copy_from_slice(&data[src..src + row]);
        }
    }
}

/// Marks the voxels of a piece in the bit set `filled` (empty: a single piece, nothing
/// to mark).
fn mark_piece(filled: &mut [u64], dims: [usize; 3], pdims: [usize; 3], offset: [usize; 3]) {
    if filled.is_empty() {
        return;
    }
    for z in 0..pdims[2] {
        for y in 0..pdims[1] {
            let row = ((offset[2] + z) * dims[1] + offset[1] + y) * dims[0] + offset[0];
            for i in row..row + pdims[0] {
                filled[i / 64] |= 1 << (i % 64);
            }
        }
    }
}

/// The first of `count` voxels not marked in `filled` (none when `filled` is empty).
fn first_unfilled(filled: &[u64], count: usize) -> Option<usize> {
    let (k, word) = filled.iter().enumerate().find(|&(k, &w)| {
        let bits = (count - 64 * k).min(64);
        let full = if bits == 64 { u64::MAX } else { (1u64 << bits) - 1 };
        w & full != full
    })?;
    Some(64 * k + (!word).trailing_zeros() as usize)
}

/// Splits off the `<AppendedData>` section: the XML before it (closed so that it
/// parses) and the data after its `_` marker, which may be raw binary.
fn split_appended(bytes: &[u8]) -> Result<(String, Option<Appended>), String> {
    const TAG: &[u8] = b"<AppendedData";
    let Some(start) = find(bytes, TAG) else {
        let text =
            std::str::from_utf8(bytes).map_err(|_| "not a VTK XML file: not UTF-8 text".to_string())?;
        return Ok((text.to_owned(), None));
    };
    let head =
        std::str::from_utf8(&bytes[..start]).map_err(|_| "not a VTK XML file: not UTF-8 text".to_string())?;
    let tag_len = bytes[start..].iter().position(|&b| b == b'>').ok_or("unterminated <AppendedData> tag")?;
    let tag =
        std::str::from_utf8(&bytes[start..start + tag_len]).map_err(|_| "malformed <AppendedData> tag")?;
    let tag = tag.strip_suffix('/').unwrap_or(tag);
    let encoding = if tag.contains("encoding=\"raw\"") || tag.contains("encoding='raw'") {
        Encoding::Raw
    } else if tag.contains("encoding=\"base64\"") || tag.contains("encoding='base64'") {
        Encoding::Base64
    } else {
        return Err("<AppendedData> has no encoding \"raw\" or \"base64\"".into());
    };
    let after = &bytes[start + tag_len + 1..];
    let data = match after.iter().position(|&b| b == b'_') {
        Some(u) if after[..u].iter().all(u8::is_ascii_whitespace) => &after[u + 1..],
        _ => return Err("<AppendedData> does not start with '_'".into()),
    };
    let data = match encoding {
        Encoding::Raw => data.to_vec(),
        // Base64 text runs to the closing tag; whitespace is dropped.
        Encoding::Base64 => {
            let end = data.iter().position(|&b| b == b'<').unwrap_or(data.len());
            data[..end].iter().copied().filter(|b| !b.is_ascii_whitespace()).collect()
        }
    };
    // Close the document: the appended section is a child of <VTKFile>.
    let xml = format!("{head}<AppendedData/></VTKFile>");
    Ok((xml, Some(Appended { encoding, data })))
}

fn find(haystack: &[u8], needle: &[u8]) -> Option<usize> {
    haystack.windows(needle.len()).position(|w| w == needle)
}

#[derive(Clone, Copy, PartialEq, Eq)]
enum Encoding {
    Raw,
    Base64,
}

/// The `<AppendedData>` section's data, after the `_`.
struct Appended {
    encoding: Encoding,
    data: Vec<u8>,
}

/// How binary data are framed.
#[derive(Clone, Copy)]
struct Codec {
    endian: Endian,
    /// Bytes per header word: 4 or 8.
    word: usize,
    compressed: bool,
}

fn child<'a, 'i>(node: Node<'a, 'i>, name: &str) -> Option<Node<'a, 'i>> {
    node.children().find(|n| n.has_tag_name(name))
}

fn data_arrays<'a, 'i>(section: Node<'a, 'i>) -> impl Iterator<Item = Node<'a, 'i>> {
    section.children().filter(|n| n.has_tag_name("DataArray"))
}

/// The array to read, from the first piece: its section, its name (if any) and its
/// position among the section's arrays.
fn choose_array<'a>(piece: Node<'a, '_>) -> Option<(&'static str, Option<&'a str>, usize)> {
    for section in ["CellData", "PointData"] {
        if let Some(s) = child(piece, section) {
            if let Some(active) = s.attribute("Scalars") {
                if let Some(i) = data_arrays(s).position(|a| a.attribute("Name") == Some(active)) {
                    return Some((section, Some(active), i));
                }
            }
        }
    }
    for section in ["CellData", "PointData"] {
        if let Some(a) = child(piece, section).and_then(|s| data_arrays(s).next()) {
            return Some((section, a.attribute("Name"), 0));
        }
    }
    None
}

/// The array of another piece: by name, or by position when unnamed.
fn find_array<'a, 'i>(
    piece: Node<'a, 'i>,
    section: &str,
    name: Option<&str>,
    index: usize,
) -> Option<Node<'a, 'i>> {
    let s = child(piece, section)?;
    match name {
        Some(name) => data_arrays(s).find(|a| a.attribute("Name") == Some(name)),
        None => data_arrays(s).nth(index),
    }
}

fn parse_extent(text: Option<&str>, what: &str) -> Result<[(i64, i64); 3], String> {
    let text = text.ok_or_else(|| format!("no {what}"))?;
    let values: Vec<i64> = text
        .split_ascii_whitespace()
        .map(|t| t.parse::<i64>().map_err(|_| format!("{what} '{text}' is not six integers")))
        .collect::<Result<_, _>>()?;
    let [x0, x1, y0, y1, z0, z1] = values[..] else {
        return Err(format!("{what} '{text}' is not six integers"));
    };
    let extent = [(x0, x1), (y0, y1), (z0, z1)];
    // Bounded so that lengths cannot overflow (the voxel limit comes later).
    if extent.iter().any(|&(lo, hi)| lo > hi || lo.unsigned_abs() > 1 << 40 || hi.unsigned_abs() > 1 << 40) {
        return Err(format!("{what} '{text}': empty or out-of-range extent"));
    }
    Ok(extent)
}

fn parse_floats<const N: usize>(
    text: Option<&str>,
    what: &str,
    default: [f64; N],
) -> Result<[f64; N], String> {
    let Some(text) = text else { return Ok(default) };
    let values: Vec<f64> = text
        .split_ascii_whitespace()
        .map(|t| t.parse::<f64>().ok().filter(|v| v.is_finite()))
        .collect::<Option<_>>()
        .ok_or_else(|| format!("{what} '{text}' is not {N} finite numbers"))?;
    values.try_into().map_err(|_| format!("{what} '{text}' is not {N} finite numbers"))
}

fn data_type(name: &str) -> Option<DataType> {
    Some(match name {
        "Int8" | "Char" => DataType::I8,
        "UInt8" | "UnsignedChar" => DataType::U8,
        "Int16" | "Short" => DataType::I16,
        "UInt16" | "UnsignedShort" => DataType::U16,
        "Int32" | "Int" => DataType::I32,
        "UInt32" | "UnsignedInt" => DataType::U32,
        "Int64" | "IdType" => DataType::I64,
        "UInt64" => DataType::U64,
        "Float32" | "Float" => DataType::F32,
        "Float64" | "Double" => DataType::F64,
        _ => return None,
    })
}

/// Reads one `<DataArray>` of `count` values: its type and its bytes, little endian.
/// The outer error is a malformed file, the inner an unsupported feature.
fn read_array(
    array: Node,
    count: usize,
    codec: Codec,
    appended: Option<&Appended>,
) -> Result<Result<(DataType, Vec<u8>), String>, String> {
    let type_name = array.attribute("type").ok_or("no type attribute")?;
    let Some(dtype) = data_type(type_name) else {
        return Ok(Err(format!("DataArray type {type_name}")));
    };
    let components = array.attribute("NumberOfComponents").unwrap_or("1");
    if components != "1" {
        return Ok(Err(format!("NumberOfComponents {components} (only scalar arrays are read)")));
    }
    if let Some(tuples) = array.attribute("NumberOfTuples") {
        if tuples.parse::<u64>().ok() != Some(count as u64) {
            return Err(format!("NumberOfTuples {tuples} for an extent of {count} voxels"));
        }
    }
    let size = dtype.size();
    let expected = count * size; // at most MAX_VOXELS * 8
    let mut data = match array.attribute("format").unwrap_or("ascii") {
        "ascii" => {
            let data = parse_ascii(array.text().unwrap_or(""), dtype, count)?;
            return Ok(Ok((dtype, data)));
        }
        "binary" => {
            let text: Vec<u8> =
                array.text().unwrap_or("").bytes().filter(|b| !b.is_ascii_whitespace()).collect();
            read_binary(&mut Base64 { text: &text, buf: Vec::new() }, codec, expected)?
        }
        "appended" => {
            let appended = appended.ok_or("format appended, but no <AppendedData>")?;
            let offset = array.attribute("offset").ok_or("format appended, but no offset")?;
            let offset =
                offset.parse::<usize>().map_err(|_| format!("offset '{offset}' is not a byte offset"))?;
            let data = appended
                .data
                .get(offset..)
                .ok_or_else(|| format!("offset {offset} is past the appended data"))?;
            match appended.encoding {
                Encoding::Raw => read_binary(&mut Raw { data }, codec, expected)?,
                Encoding::Base64 => {
                    read_binary(&mut Base64 { text: data, buf: Vec::new() }, codec, expected)?
                }
            }
        }
        other => return Err(format!("unknown format '{other}'")),
    };
    if codec.endian == Endian::Big && size > 1 {
        data.chunks_exact_mut(size).for_each(<[u8]>::reverse);
    }
    Ok(Ok((dtype, data)))
}

/// Parses ASCII values into little-endian bytes.
fn parse_ascii(text: &str, dtype: DataType, count: usize) -> Result<Vec<u8>, String> {
    let mut out = Vec::with_capacity((count * dtype.size()).min(text.len() * dtype.size()));
    let mut n = 0;
    for token in text.split_ascii_whitespace() {
        if n == count {
            return Err(format!("dimensions do not match the data: more than {count} values"));
        }
        let bad = || format!("value {n}: '{}' is not a {dtype}", token.escape_debug());
        match dtype {
            DataType::U8 => out.push(token.parse::<u8>().map_err(|_| bad())?),
            DataType::I8 => out.extend(token.parse::<i8>().map_err(|_| bad())?.to_le_bytes()),
            DataType::U16 => out.extend(token.parse::<u16>().map_err(|_| bad())?.to_le_bytes()),
            DataType::I16 => out.extend(token.parse::<i16>().map_err(|_| bad())?.to_le_bytes()),
            DataType::U32 => out.extend(token.parse::<u32>().map_err(|_| bad())?.to_le_bytes()),
            DataType::I32 => out.extend(token.parse::<i32>().map_err(|_| bad())?.to_le_bytes()),
            DataType::U64 => out.extend(token.parse::<u64>().map_err(|_| bad())?.to_le_bytes()),
            DataType::I64 => out.extend(token.parse::<i64>().map_err(|_| bad())?.to_le_bytes()),
            DataType::F32 => out.extend(token.parse::<f32>().map_err(|_| bad())?.to_le_bytes()),
            DataType::F64 => out.extend(token.parse::<f64>().map_err(|_| bad())?.to_le_bytes()),
        }
        n += 1;
    }
    if n < count {
        return Err(format!("truncated data: {n} values for {count} voxels"));
    }
    Ok(out)
}
