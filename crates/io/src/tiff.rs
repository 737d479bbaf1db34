//! TIFF stacks: a multi-page file, or single-page slices, through the `tiff` crate.

use std::io::Cursor;
use std::path::{Path, PathBuf};

use glam::DVec3;
use tiff::decoder::{Decoder, DecodingResult, Limits};
use tiff::tags::Tag;
use tiff::ColorType;

use crate::error::IoError;
use crate::files::{checked_voxel_count, read_file};
use crate::loaded::LoadedVoxels;
use crate::samples::{decode, Layout, Order};
use crate::samples::{DataType, Endian};

/// Reads a TIFF stack: a multi-page `.tif`/`.tiff` file, see [`read_tiff_bytes`].
pub fn read_tiff(path: &Path) -> Result<LoadedVoxels, IoError> {
    read_tiff_bytes(&read_file(path)?, path)
}

/// Reads a multi-page TIFF file held in `bytes` (`path` names it in errors).
///
/// Voxel `[x, y, z]` is the pixel of column `x`, row `y` of page `z` (tifffile's
/// `imread(path)[z, y, x]`). Every page must be one-sample greyscale of the same size
/// and type: 8, 16 or 32-bit unsigned or signed integers (labels), or 32/64-bit floats
/// (grey levels); raw, LZW, deflate or PackBits compressed, in strips or tiles.
///
/// **Spacing and units.** From OME-TIFF metadata (the OME-XML of the first page's
/// `ImageDescription`: `PhysicalSizeX/Y/Z` and their units, `µm` by default; one
/// channel and one time point), else from ImageJ's (`ImageDescription` starting
/// `ImageJ=`: `unit=` and `spacing=`, the z step, with x and y the inverse of the
/// `XResolution`/`YResolution` tags), else unit spacing and no unit.
pub fn read_tiff_bytes(bytes: &[u8], path: &Path) -> Result<LoadedVoxels, IoError> {
    let mut stack = Stack::new(path);
    stack.add_file(bytes, path, true)?;
    stack.finish()
}

/// Reads single-page TIFF slices, slice `z` the `z`-th of `paths`, as one volume (see
/// [`read_tiff_bytes`]; spacing and units from the first slice). `path` (the directory
/// or pattern the slices came from) names the volume in errors about it as a whole.
pub fn read_tiff_slices(paths: &[PathBuf], path: &Path) -> Result<LoadedVoxels, IoError> {
    if paths.is_empty() {
        return Err(IoError::format(path, "no .tif or .tiff slices"));
    }
    let mut stack = Stack::new(path);
    for (z, slice) in paths.iter().enumerate() {
        stack.add_file(&read_file(slice)?, slice, z == 0)?;
    }
    stack.finish()
}

/// The `.tif`/`.tiff` files of a directory, or those matching a file-name pattern
/// (`*` any run of characters, `?` one character, e.g. `scan/slice_*.tif`), sorted by
/// name: the slices [`read_tiff_slices`] stacks.
pub fn tiff_slices(path: &Path) -> Result<Vec<PathBuf>, IoError> {
    let (dir, pattern) = if path.is_dir() {
        (path.to_path_buf(), None)
    } else {
        let dir = path.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
        (dir.to_path_buf(), path.file_name().map(|n| n.to_string_lossy().into_owned()))
    };
    let entries = std::fs::read_dir(&dir).map_err(|e| IoError::io(&dir, e))?;
    let mut files = Vec::new();
    for entry in entries {
        let entry = entry.map_err(|e| IoError::io(&dir, e))?;
        let name = entry.file_name().to_string_lossy().into_owned();
        let lower = name.to_ascii_lowercase();
        let selected = match &pattern {
            Some(p) => wildcard_match(p.as_bytes(), name.as_bytes()),
            None => (lower.ends_with(".tif") || lower.ends_with(".tiff")) && !name.starts_with('.'),
        };
        if selected && entry.path().is_file() {
            files.push(entry.path());
        }
    }
    files.sort();
    if files.is_empty() {
        return Err(IoError::format(path, "no .tif or .tiff slices match"));
    }
    Ok(files)
}

/// Whether `name` matches `pattern` (`*`: any run, `?`: any one byte).
pub(crate) fn wildcard_match(pattern: &[u8], name: &[u8]) -> bool {
    let (mut p, mut n, mut star, mut mark) = (0, 0, None, 0);
    while n < name.len() {
        if p < pattern.len() && (pattern[p] == b'?' || pattern[p] == name[n]) {
            p += 1;
            n += 1;
        } else if p < pattern.len() && pattern[p] == b'*' {
            star = Some(p);
            mark = n;
            p += 1;
        } else if let Some(s) = star {
            p = s + 1;
            mark += 1;
            n = mark;
        } else {
            return false;
        }
    }
    pattern[p..].iter().all(|&c| c == b'*')
}

/// Pages read so far, all of one size and type.
struct Stack<'a> {
    path: &'a Path,
    /// Width, height and type of the first page.
    page: Option<(u32, u32, DataType)>,
    pages: u64,
    data: Vec<u8>,
    spacing: DVec3,
    units: Option<String>,
}

impl<'a> Stack<'a> {
    fn new(path: &'a Path) -> Self {
        Stack { path, page: None, pages: 0, data: Vec::new(), spacing: DVec3::ONE, units: None }
    }

    /// Appends every page of one file, after checking that the pages (and those of the
    /// files to come, as far as `self` knows) fit the budget; `first`: take the spacing
    /// from this file's metadata.
    fn add_file(&mut self, bytes: &[u8], file: &Path, first: bool) -> Result<(), IoError> {
        let err = |e: tiff::TiffError| tiff_error(file, e);
        let mut limits = Limits::default();
        limits.decoding_buffer_size = usize::try_from(crate::limits::max_memory()).unwrap_or(usize::MAX);
        let mut decoder = Decoder::new(Cursor::new(bytes)).map_err(err)?.with_limits(limits);
        let mut pages = 1u64;
        while decoder.more_images() {
            decoder.next_image().map_err(err)?;
            pages += 1;
        }
        decoder.seek_to_image(0).map_err(err)?;
        let (w, h) = decoder.dimensions().map_err(err)?;
        let dtype = page_type(&mut decoder, file)?;
        let (pw, ph, ptype) = *self.page.get_or_insert((w, h, dtype));
        if (w, h, dtype) != (pw, ph, ptype) {
            return Err(IoError::format(
                file,
                format!("a {w}x{h} page of {dtype}, after {pw}x{ph} pages of {ptype}"),
            ));
        }
        let total = self.pages + pages;
        let dims = [u64::from(w), u64::from(h), total];
        checked_voxel_count(self.path, dims, 2 * dtype.size() as u64 + 8)?;
        if first {
            (self.spacing, self.units) = metadata(&mut decoder, file, pages)?;
        }
        let page_len = w as usize * h as usize * dtype.size();
        self.data.reserve(page_len * pages as usize);
        for k in 0..pages {
            if k > 0 {
                decoder.next_image().map_err(err)?;
                let (kw, kh) = decoder.dimensions().map_err(err)?;
                let ktype = page_type(&mut decoder, file)?;
                if (kw, kh, ktype) != (w, h, dtype) {
                    return Err(IoError::format(
                        file,
                        format!("page {k} is {kw}x{kh} of {ktype}, page 0 {w}x{h} of {dtype}"),
                    ));
                }
            }
            let start = self.data.len();
            push_le(&mut self.data, decoder.read_image().map_err(err)?);
            if self.data.len() - start != page_len {
                return Err(IoError::format(
                    file,
                    format!("page {k} decodes to the wrong number of samples"),
                ));
            }
        }
        self.pages = total;
        Ok(())
    }

    fn finish(self) -> Result<LoadedVoxels, IoError> {
        let Some((w, h, dtype)) = self.page else {
            return Err(IoError::format(self.path, "no pages"));
        };
        let layout = Layout {
            dims: [w as usize, h as usize, self.pages as usize],
            dtype,
            endian: Endian::Little,
            order: Order::XFastest,
        };
        let voxels = decode(self.path, &self.data, layout, None)?
            .with_spacing(self.spacing)
            .map_err(|e| IoError::format(self.path, format!("spacing {}: {e}", self.spacing)))?;
        let units = self.units.as_deref().map(crate::files::printable);
        Ok(LoadedVoxels { voxels, palette: None, units })
    }
}

/// The sample type of the current page: one greyscale sample of 8, 16, 32 or 64 bits.
fn page_type(decoder: &mut Decoder<Cursor<&[u8]>>, file: &Path) -> Result<DataType, IoError> {
    let bits = match decoder.colortype().map_err(|e| tiff_error(file, e))? {
        ColorType::Gray(bits) => bits,
        other => {
            return Err(IoError::unsupported(
                file,
                format!("{other:?} pixels (one greyscale sample per pixel is read)"),
            ))
        }
    };
    let format = decoder.find_tag_unsigned::<u16>(Tag::SampleFormat).map_err(|e| tiff_error(file, e))?;
    let dtype = match (format.unwrap_or(1), bits) {
        (1, 8) => DataType::U8,
        (1, 16) => DataType::U16,
        (1, 32) => DataType::U32,
        (1, 64) => DataType::U64,
        (2, 8) => DataType::I8,
        (2, 16) => DataType::I16,
        (2, 32) => DataType::I32,
        (2, 64) => DataType::I64,
        (3, 32) => DataType::F32,
        (3, 64) => DataType::F64,
        (f, b) => {
            return Err(IoError::unsupported(
                file,
                format!(
                    "{b}-bit samples of format {f} (8 to 64-bit integers, 32 and 64-bit floats are read)"
                ),
            ))
        }
    };
    Ok(dtype)
}

/// Appends the decoded samples as little-endian bytes.
fn push_le(out: &mut Vec<u8>, result: DecodingResult) {
    macro_rules! push {
        ($v:expr) => {
            for s in $v {
                out.extend_from_slice(&s.to_le_bytes());
            }
        };
    }
    match result {
        DecodingResult::U8(v) => out.extend_from_slice(&v),
        DecodingResult::I8(v) => push!(v),
        DecodingResult::U16(v) => push!(v),
        DecodingResult::I16(v) => push!(v),
        DecodingResult::U32(v) => push!(v),
        DecodingResult::I32(v) => push!(v),
        DecodingResult::U64(v) => push!(v),
        DecodingResult::I64(v) => push!(v),
        DecodingResult::F32(v) => push!(v),
        DecodingResult::F64(v) => push!(v),
        // Half floats are refused by `page_type` (16-bit samples of format 3).
        DecodingResult::F16(_) => {}
    }
}

/// Spacing and unit from the OME-XML or ImageJ description of the first page.
fn metadata(
    decoder: &mut Decoder<Cursor<&[u8]>>,
    file: &Path,
    pages: u64,
) -> Result<(DVec3, Option<String>), IoError> {
    let description = match decoder.find_tag(Tag::ImageDescription) {
        Ok(Some(v)) => v.into_string().unwrap_or_default(),
        Ok(None) | Err(_) => String::new(),
    };
    if description.trim_start().starts_with("<?xml") || description.contains("<OME") {
        return ome_metadata(&description, file, pages);
    }
    if let Some(imagej) = description.strip_prefix("ImageJ=") {
        let value = |key: &str| {
            imagej.lines().find_map(|l| l.strip_prefix(key).and_then(|r| r.strip_prefix('='))).map(str::trim)
        };
        for key in ["channels", "frames"] {
            if let Some(n) = value(key).filter(|&n| n != "1") {
                return Err(IoError::unsupported(
                    file,
                    format!("an ImageJ hyperstack of {n} {key} (one is read)"),
                ));
            }
        }
        let mut inverse = |tag| match decoder.find_tag(tag) {
            Ok(Some(tiff::decoder::ifd::Value::Rational(n, d))) if n > 0 && d > 0 => {
                f64::from(d) / f64::from(n)
            }
            _ => 1.0,
        };
        let (sx, sy) = (inverse(Tag::XResolution), inverse(Tag::YResolution));
        let sz = value("spacing").and_then(|s| s.parse::<f64>().ok()).unwrap_or(1.0);
        let unit = value("unit").map(|u| u.replace("\\u00B5", "µ"));
        let unit = unit.map(|u| if u == "micron" { "µm".to_string() } else { u });
        return Ok((DVec3::new(sx, sy, sz), unit));
    }
    Ok((DVec3::ONE, None))
}

/// `PhysicalSize*` of the first `Pixels` element of an OME-XML description.
fn ome_metadata(xml: &str, file: &Path, pages: u64) -> Result<(DVec3, Option<String>), IoError> {
    let doc = roxmltree::Document::parse(xml)
        .map_err(|e| IoError::format(file, format!("OME-XML description: {e}")))?;
    let Some(pixels) = doc.descendants().find(|n| n.tag_name().name() == "Pixels") else {
        return Err(IoError::format(file, "OME-XML description without a Pixels element"));
    };
    let size = |k: &str| pixels.attribute(k).and_then(|v| v.parse::<u64>().ok()).unwrap_or(1);
    if size("SizeC") * size("SizeT") != 1 {
        return Err(IoError::unsupported(
            file,
            format!(
                "OME-TIFF of {} channels and {} time points (one of each is read)",
                size("SizeC"),
                size("SizeT")
            ),
        ));
    }
    if size("SizeZ") != pages {
        return Err(IoError::unsupported(
            file,
            format!("OME-TIFF with SizeZ {} in {pages} pages (one image per file is read)", size("SizeZ")),
        ));
    }
    let mut spacing = [1.0; 3];
    let mut units = Vec::new();
    for (k, axis) in ["X", "Y", "Z"].into_iter().enumerate() {
        if let Some(s) = pixels.attribute(format!("PhysicalSize{axis}").as_str()) {
            spacing[k] = s.parse::<f64>().map_err(|_| {
                IoError::format(file, format!("OME-XML PhysicalSize{axis} '{s}' is not a number"))
            })?;
            units.push(
                pixels.attribute(format!("PhysicalSize{axis}Unit").as_str()).unwrap_or("µm").to_string(),
            );
        }
    }
    units.dedup();
    let unit = match &units[..] {
        [] => None,
        [u] => Some(u.clone()),
        _ => return Err(IoError::unsupported(file, format!("OME-XML sizes in different units {units:?}"))),
    };
    Ok((DVec3::from_array(spacing), unit))
}

/// A `tiff` crate error as an error naming the file.
fn tiff_error(file: &Path, e: tiff::TiffError) -> IoError {
    match e {
        tiff::TiffError::UnsupportedError(e) => IoError::unsupported(file, format!("TIFF: {e}")),
        tiff::TiffError::IoError(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => {
            IoError::format(file, "not a TIFF file, or truncated: the data end early")
        }
        other => IoError::format(file, format!("not a readable TIFF file: {other}")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wildcards() {
        assert!(wildcard_match(b"slice_*.tif", b"slice_001.tif"));
        assert!(wildcard_match(b"s?.tif", b"s1.tif"));
        assert!(!wildcard_match(b"s?.tif", b"s12.tif"));
        assert!(wildcard_match(b"*", b""));
        assert!(!wildcard_match(b"*.tif", b"a.tiff"));
        assert!(wildcard_match(b"*a*b", b"xxaxxb"));
    }
}
