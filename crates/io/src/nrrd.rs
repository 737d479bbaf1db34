//! NRRD (`.nrrd`, detached `.nhdr`) and 3D Slicer segmentations (`.seg.nrrd`).
//!
//! Hand-written: the format is a text header of `field: value` lines and one data
//! block, and no maintained Rust crate reads it.

use std::io::Read;
use std::path::{Path, PathBuf};

use flate2::read::MultiGzDecoder;
use glam::{DMat3, DVec3};

use crate::error::IoError;
use crate::files::{checked_voxel_count, read_file};
use crate::loaded::LoadedVoxels;
use crate::material::Palette;
use crate::orient::place;
use crate::samples::{decode, Layout, Order};
use crate::samples::{DataType, Endian};

/// The largest label value a `.seg.nrrd` segment may name (the palette is indexed by
/// label).
const MAX_SEGMENT_LABEL: u32 = 1 << 16;

/// Reads a NRRD file (`.nrrd`, or a detached header `.nhdr` naming its data file), see
/// [`read_nrrd_bytes`].
pub fn read_nrrd(path: &Path) -> Result<LoadedVoxels, IoError> {
    read_nrrd_bytes(&read_file(path)?, path)
}

/// [`read_nrrd_bytes`] with nothing read but `bytes` (an upload): a detached header,
/// which names its data file, is refused.
pub(crate) fn read_nrrd_in_memory(bytes: &[u8], path: &Path) -> Result<LoadedVoxels, IoError> {
    if Header::parse(bytes, path)?.data_file.is_some() {
        return Err(IoError::unsupported(
            path,
            "a detached header names its data file: only the file itself is read here (attach the data)",
        ));
    }
    read_nrrd_bytes(bytes, path)
}

/// Reads a NRRD file held in `bytes` (`path` names it in errors, and locates a
/// detached data file).
///
/// **Header.** `NRRD000N` (versions 1 to 5), then `field: value` lines up to an empty
/// line: `dimension: 3`, `sizes`, `type` (8 to 64-bit integers, `float`, `double`),
/// `endian`, `encoding` (`raw`, `gzip`, `ascii`), optional `byte skip` and `line
/// skip`, and `data file` for a detached header (relative to the header's directory, and
/// confined to it: an absolute path, `..` or a link leading out of it is refused;
/// `LIST` and `%d` patterns of several files are not read). `byte skip: -1` (raw
/// encoding only) reads the last bytes of the data.
/// Voxel `[x, y, z]` is the `x + X (y + Y z)`-th value (NRRD's fastest axis first).
///
/// **Space.** `space directions` and `space origin` place the voxel centres (axis flips
/// and permutations applied; oblique rotations dropped, as for NIfTI), in the file's
/// own space (`right-anterior-superior`, `left-posterior-superior`...: coordinates
/// are not converted); without them, `spacings`. `space units` (all equal) are the
/// [`units`](LoadedVoxels::units).
///
/// **Segmentations.** 3D Slicer's `SegmentN_Name`, `SegmentN_LabelValue` and
/// `SegmentN_Color` key/value pairs (`.seg.nrrd`, one layer) become the
/// [`palette`](LoadedVoxels::palette): label value `l` gets the segment's colour and
/// a material named after the segment.
pub fn read_nrrd_bytes(bytes: &[u8], path: &Path) -> Result<LoadedVoxels, IoError> {
    let header = Header::parse(bytes, path)?;
    let [x, y, z] = header.sizes;
    let dtype = header.dtype;
    checked_voxel_count(path, [x, y, z], 2 * dtype.size() as u64 + 8)?;
    let layout =
        Layout { dims: [x, y, z].map(|d| d as usize), dtype, endian: header.endian, order: Order::XFastest };
    let expected = layout.dims.iter().product::<usize>() * dtype.size();
    let (owned, data_path);
    let data: &[u8] = match &header.data_file {
        Some(file) => {
            data_path = detached_data_file(path, file)?;
            owned = read_file(&data_path)?;
            &owned
        }
        None => {
            data_path = path.to_path_buf();
            &bytes[header.len..]
        }
    };
    let data = skip_lines(data, header.line_skip);
    let values = match header.encoding {
        Encoding::Raw => {
            let data = match header.byte_skip {
                -1 => data.get(data.len().saturating_sub(expected)..).unwrap_or(&[]),
                n => data.get(n as usize..).unwrap_or(&[]),
            };
            exact(&data_path, data, expected, header.data_file.is_some())?.to_vec()
        }
        Encoding::Gzip => {
            // The skipped bytes are inflated and dropped as they come, never held; the
            // data are inflated up to one byte past their declared size.
            let corrupt = |e: std::io::Error| IoError::format(&data_path, format!("corrupt gzip data: {e}"));
            let skip = u64::try_from(header.byte_skip.max(0)).unwrap_or(0);
            let mut decoder = MultiGzDecoder::new(data);
            let skipped =
                std::io::copy(&mut (&mut decoder).take(skip), &mut std::io::sink()).map_err(corrupt)?;
            if skipped < skip {
                return Err(IoError::format(
                    &data_path,
                    format!("truncated data: {skipped} bytes inflated of the {skip} to skip"),
                ));
            }
            let mut out = Vec::with_capacity(expected);
            decoder.take(expected as u64 + 1).read_to_end(&mut out).map_err(corrupt)?;
            exact(&data_path, &out, expected, true)?;
            out.truncate(expected);
            out
        }
        Encoding::Ascii => return ascii(&data_path, data, layout).and_then(|v| finish(v, &header, path)),
    };
    let voxels = decode(&data_path, &values, layout, None)?;
    finish(voxels, &header, path)
}

/// The detached data file `file` names, relative to the header's directory: it must
/// lie in that directory or below, after links are resolved (an absolute path, `..`
/// or a link that leaves it is refused: a header from elsewhere must not turn
/// `/etc/passwd` or `/proc/self/environ` into labels), and be a regular file.
fn detached_data_file(header: &Path, file: &Path) -> Result<PathBuf, IoError> {
    let dir = header.parent().unwrap_or(Path::new(""));
    let data_path = dir.join(file);
    let dir = if dir.as_os_str().is_empty() { Path::new(".") } else { dir };
    let outside = || {
        IoError::format(
            header,
            format!(
                "data file '{}' is outside the header's directory (detached data must lie beside the header; read other files as raw data, naming them and their layout)",
                file.display()
            ),
        )
    };
    if file.is_absolute() || file.components().any(|c| matches!(c, std::path::Component::ParentDir)) {
        return Err(outside());
    }
    let real_dir = dir.canonicalize().map_err(|e| IoError::io(dir, e))?;
    let real = data_path.canonicalize().map_err(|e| IoError::io(&data_path, e))?;
    if !real.starts_with(&real_dir) {
        return Err(outside());
    }
    crate::files::regular_file_len(&data_path)?;
    Ok(data_path)
}

/// Places the voxels and attaches units and segments.
fn finish(voxels: crate::grey::Voxels, header: &Header, path: &Path) -> Result<LoadedVoxels, IoError> {
    let (voxels, _) = place(voxels, header.directions, header.origin)
        .map_err(|e| IoError::format(path, format!("space directions: {e}")))?;
    Ok(LoadedVoxels { voxels, palette: header.palette.clone(), units: header.units.clone() })
}

/// `data` when it holds exactly `expected` bytes, else the error saying how not.
fn exact<'a>(path: &Path, data: &'a [u8], expected: usize, whole: bool) -> Result<&'a [u8], IoError> {
    match data.len().cmp(&expected) {
        std::cmp::Ordering::Less => {
            Err(IoError::format(path, format!("truncated data: {} bytes of {expected}", data.len())))
        }
        std::cmp::Ordering::Greater if whole => {
            Err(IoError::format(path, format!("more data than the header declares ({expected} bytes)")))
        }
        _ => Ok(&data[..expected]),
    }
}

/// `data` after its first `lines` lines (empty when it has fewer): stops at the end of
/// the data, whatever `line skip` the header declares.
fn skip_lines(mut data: &[u8], lines: usize) -> &[u8] {
    for _ in 0..lines {
        if data.is_empty() {
            break;
        }
        data = data.iter().position(|&b| b == b'\n').map_or(&[], |i| &data[i + 1..]);
    }
    data
}

/// ASCII data: whitespace-separated numbers, as many as voxels.
fn ascii(path: &Path, data: &[u8], layout: Layout) -> Result<crate::grey::Voxels, IoError> {
    let text =
        std::str::from_utf8(data).map_err(|_| IoError::format(path, "ascii data that are not text"))?;
    let count = layout.dims.iter().product::<usize>();
    let mut values = Vec::with_capacity(count * 8);
    let mut n = 0;
    for word in text.split_whitespace() {
        let v: f64 = word.parse().map_err(|_| IoError::format(path, format!("'{word}' is not a number")))?;
        n += 1;
        if n > count {
            return Err(IoError::format(path, format!("more than the {count} values the header declares")));
        }
        values.extend_from_slice(&v.to_le_bytes());
    }
    if n < count {
        return Err(IoError::format(path, format!("truncated data: {n} values of {count}")));
    }
    decode(path, &values, Layout { dtype: DataType::F64, endian: Endian::Little, ..layout }, None)
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Encoding {
    Raw,
    Gzip,
    Ascii,
}

/// What the header says.
#[derive(Debug)]
pub(crate) struct Header {
    /// Header bytes, up to and including the empty line.
    len: usize,
    sizes: [u64; 3],
    dtype: DataType,
    endian: Endian,
    encoding: Encoding,
    byte_skip: i64,
    line_skip: usize,
    pub(crate) data_file: Option<PathBuf>,
    /// Columns: the world steps of the three index axes.
    directions: DMat3,
    origin: DVec3,
    units: Option<String>,
    palette: Option<Palette>,
}

impl Header {
    pub(crate) fn parse(bytes: &[u8], path: &Path) -> Result<Header, IoError> {
        let not_nrrd = |m: String| IoError::format(path, format!("not a NRRD file: {m}"));
        let bad = |m: String| IoError::format(path, m);
        if !bytes.starts_with(b"NRRD000") || !bytes.get(7).is_some_and(|v| (b'1'..=b'5').contains(v)) {
            let start = String::from_utf8_lossy(&bytes[..bytes.len().min(8)]).escape_debug().to_string();
            return Err(not_nrrd(format!("no magic NRRD0001..NRRD0005 at the start ('{start}')")));
        }
        let mut fields: Vec<(String, String)> = Vec::new();
        let mut pairs: Vec<(String, String)> = Vec::new();
        let mut pos = 0;
        let mut ended = false;
        let mut first = true;
        while pos < bytes.len() {
            let end = bytes[pos..].iter().position(|&b| b == b'\n').map_or(bytes.len(), |i| pos + i);
            let line = &bytes[pos..end];
            pos = (end + 1).min(bytes.len());
            let line = line.strip_suffix(b"\r").unwrap_or(line);
            if first {
                first = false;
                continue;
            }
            if line.is_empty() {
                ended = true;
                break;
            }
            if line.starts_with(b"#") {
                continue;
            }
            let line = std::str::from_utf8(line).map_err(|_| not_nrrd("a header line is not text".into()))?;
            if let Some((k, v)) = line.split_once(":=") {
                pairs.push((k.to_string(), v.to_string()));
            } else if let Some((k, v)) = line.split_once(": ") {
                fields.push((k.trim().to_ascii_lowercase(), v.trim().to_string()));
            } else {
                return Err(not_nrrd(format!(
                    "header line '{}' is neither a field nor a key/value pair",
                    line.escape_debug()
                )));
            }
        }
        let field = |k: &str| get_field(&fields, k);
        let data_file = field("data file").or(field("datafile")).map(PathBuf::from);
        if !ended && data_file.is_none() {
            return Err(not_nrrd("the header has no empty line before the data".into()));
        }
        let required = |k: &str| field(k).ok_or_else(|| bad(format!("the header has no '{k}' field")));
        let dimension = required("dimension")?;
        if dimension != "3" {
            return Err(IoError::unsupported(path, format!("dimension {dimension} (3-D volumes are read)")));
        }
        let sizes: Vec<u64> = required("sizes")?
            .split_whitespace()
            .map(|s| s.parse::<u64>().ok().filter(|&n| n > 0))
            .collect::<Option<_>>()
            .filter(|v: &Vec<u64>| v.len() == 3)
            .ok_or_else(|| {
                bad(format!("sizes '{}' are not three positive integers", field("sizes").unwrap_or("")))
            })?;
        let type_name = required("type")?;
        let dtype = data_type(type_name).ok_or_else(|| {
            IoError::unsupported(path, format!("type '{type_name}' (integers, float and double are read)"))
        })?;
        let endian = match field("endian") {
            None | Some("little") => Endian::Little,
            Some("big") => Endian::Big,
            Some(other) => return Err(bad(format!("endian '{other}' is neither little nor big"))),
        };
        let encoding = match required("encoding")? {
            "raw" => Encoding::Raw,
            "gzip" | "gz" => Encoding::Gzip,
            "ascii" | "text" | "txt" => Encoding::Ascii,
            other => {
                return Err(IoError::unsupported(
                    path,
                    format!("encoding '{other}' (raw, gzip and ascii are read)"),
                ))
            }
        };
        let byte_skip = match field("byte skip").or(field("byteskip")) {
            None => 0,
            Some(s) => {
                s.parse::<i64>().ok().filter(|&n| n >= -1).ok_or_else(|| bad(format!("byte skip '{s}'")))?
            }
        };
        if byte_skip == -1 && encoding != Encoding::Raw {
            return Err(IoError::unsupported(path, "byte skip -1 with a compressed or ascii encoding"));
        }
        let line_skip = match field("line skip").or(field("lineskip")) {
            None => 0,
            Some(s) => s.parse::<usize>().map_err(|_| bad(format!("line skip '{s}'")))?,
        };
        if let Some(f) = &data_file {
            let name = f.to_string_lossy();
            if name.starts_with("LIST") || name.contains('%') || name.split_whitespace().count() > 1 {
                return Err(IoError::unsupported(
                    path,
                    format!("data file '{name}' (one data file is read)"),
                ));
            }
        }
        let (directions, origin) = placement(&fields, &bad)?;
        let units = match field("space units") {
            None => None,
            Some(u) => {
                let mut units: Vec<&str> = u.split_whitespace().map(|w| w.trim_matches('"')).collect();
                units.dedup();
                match units[..] {
                    [u] => Some(crate::files::printable(u)),
                    _ => {
                        return Err(IoError::unsupported(
                            path,
                            format!("space units {u} that differ by axis"),
                        ))
                    }
                }
            }
        };
        let palette = segments(&pairs, path)?;
        Ok(Header {
            len: pos,
            sizes: [sizes[0], sizes[1], sizes[2]],
            dtype,
            endian,
            encoding,
            byte_skip,
            line_skip,
            data_file,
            directions,
            origin,
            units,
            palette,
        })
    }
}

/// The index-to-world map of `space directions`/`space origin`, else of `spacings`.
fn placement(
    fields: &[(String, String)],
    bad: &dyn Fn(String) -> IoError,
) -> Result<(DMat3, DVec3), IoError> {
    let field = |k: &str| get_field(fields, k);
    let origin = match field("space origin") {
        Some(o) => vector(o).ok_or_else(|| bad(format!("space origin '{o}' is not a vector (x,y,z)")))?,
        None => DVec3::ZERO,
    };
    if let Some(d) = field("space directions") {
        let cols: Vec<DVec3> = d
            .split_whitespace()
            .map(vector)
            .collect::<Option<_>>()
            .filter(|c: &Vec<DVec3>| c.len() == 3)
            .ok_or_else(|| bad(format!("space directions '{d}' are not three vectors (x,y,z)")))?;
        return Ok((DMat3::from_cols(cols[0], cols[1], cols[2]), origin));
    }
    let spacing = match field("spacings") {
        Some(s) => {
            let v: Vec<f64> = s
                .split_whitespace()
                .map(|w| w.parse::<f64>().ok())
                .collect::<Option<_>>()
                .filter(|v: &Vec<f64>| v.len() == 3)
                .ok_or_else(|| bad(format!("spacings '{s}' are not three numbers")))?;
            DVec3::new(v[0], v[1], v[2])
        }
        None => DVec3::ONE,
    };
    Ok((DMat3::from_diagonal(spacing), origin))
}

/// The value of header field `key` (lower-case).
fn get_field<'a>(fields: &'a [(String, String)], key: &str) -> Option<&'a str> {
    fields.iter().find(|(f, _)| f == key).map(|(_, v)| v.as_str())
}

/// `(a,b,c)` as a vector.
fn vector(text: &str) -> Option<DVec3> {
    let inner = text.trim().strip_prefix('(')?.strip_suffix(')')?;
    let v: Vec<f64> = inner.split(',').map(|w| w.trim().parse::<f64>().ok()).collect::<Option<_>>()?;
    (v.len() == 3).then(|| DVec3::new(v[0], v[1], v[2]))
}

fn data_type(name: &str) -> Option<DataType> {
    Some(match name {
        "signed char" | "int8" | "int8_t" => DataType::I8,
        "uchar" | "unsigned char" | "uint8" | "uint8_t" => DataType::U8,
        "short" | "short int" | "signed short" | "signed short int" | "int16" | "int16_t" => DataType::I16,
        "ushort" | "unsigned short" | "unsigned short int" | "uint16" | "uint16_t" => DataType::U16,
        "int" | "signed int" | "int32" | "int32_t" => DataType::I32,
        "uint" | "unsigned int" | "uint32" | "uint32_t" => DataType::U32,
        "longlong"
        | "long long"
        | "long long int"
        | "signed long long"
        | "signed long long int"
        | "int64"
        | "int64_t" => DataType::I64,
        "ulonglong" | "unsigned long long" | "unsigned long long int" | "uint64" | "uint64_t" => {
            DataType::U64
        }
        "float" => DataType::F32,
        "double" => DataType::F64,
        _ => return None,
    })
}

/// The palette of 3D Slicer's segment key/value pairs, if any.
fn segments(pairs: &[(String, String)], path: &Path) -> Result<Option<Palette>, IoError> {
    let get = |k: usize, what: &str| {
        let key = format!("Segment{k}_{what}");
        pairs.iter().find(|(p, _)| *p == key).map(|(_, v)| v.trim())
    };
    let mut found: Vec<(u32, &str, [u8; 4])> = Vec::new();
    for k in 0.. {
        let Some(name) = get(k, "Name") else { break };
        if get(k, "Layer").is_some_and(|l| l != "0") {
            return Err(IoError::unsupported(path, "a segmentation of several layers (one is read)"));
        }
        let value = get(k, "LabelValue").unwrap_or("1");
        let label = value.parse::<u32>().ok().filter(|&l| l <= MAX_SEGMENT_LABEL).ok_or_else(|| {
            IoError::format(path, format!("segment {k} label value '{value}' (0 to {MAX_SEGMENT_LABEL})"))
        })?;
        let color = get(k, "Color")
            .and_then(|c| {
                let v: Vec<f64> =
                    c.split_whitespace().map(|w| w.parse::<f64>().ok()).collect::<Option<_>>()?;
                (v.len() == 3).then(|| [v[0], v[1], v[2]])
            })
            .map_or([200, 200, 200, 255], |[r, g, b]| {
                let byte = |c: f64| (c.clamp(0.0, 1.0) * 255.0).round() as u8;
                [byte(r), byte(g), byte(b), 255]
            });
        found.push((label, name, color));
    }
    let Some(max) = found.iter().map(|f| f.0).max() else { return Ok(None) };
    let mut palette = Palette::from_colors(vec![[200, 200, 200, 255]; max as usize + 1]);
    palette.colors[0][3] = 0;
    palette.materials[0].color[3] = 0;
    for (label, name, color) in found {
        palette.colors[label as usize] = color;
        palette.materials[label as usize].color = color;
        palette.set_name(label, name);
    }
    Ok(Some(palette))
}
