//! Zarr v2 and v3 arrays, and OME-Zarr images (NGFF 0.4 and 0.5), through `zarrs`.
//!
//! `zarrs` reads the array metadata, the chunk grid and the codecs (blosc, gzip, zstd,
//! sharding, transpose, crc32c); this module finds the array (a plain array, or level 0
//! of an OME-Zarr image), reads the OME metadata (axes, units, scale, translation) itself,
//! checks the sizes against the memory budget before `zarrs` decodes anything, and
//! decodes the samples as every other reader does (`samples.rs`).

use std::path::Path;
use std::sync::Arc;

use glam::DVec3;
use serde_json::Value;
use zarrs::array::{Array, DataType as ZarrType};
use zarrs::storage::byte_range::{ByteRange, ByteRangeIterator};
use zarrs::storage::store::MemoryStore;
use zarrs::storage::{
    MaybeBytes, MaybeBytesIterator, ReadableStorageTraits, StorageError, StoreKey, WritableStorageTraits,
};

use crate::error::IoError;
use crate::files::checked_voxel_count;
use crate::loaded::LoadedVoxels;
use crate::samples::{decode, Layout, Order};
use crate::samples::{DataType, Endian};

/// Whether the directory `path` is a Zarr node: it holds `zarr.json` (v3), `.zarray` or
/// `.zgroup` (v2).
pub fn is_zarr(path: &Path) -> bool {
    path.is_dir() && ["zarr.json", ".zarray", ".zgroup"].iter().any(|m| path.join(m).is_file())
}

/// Reads a Zarr array, or level 0 of an OME-Zarr image, from the directory `path`.
///
/// **What.** `path` is a Zarr v2 or v3 array (a directory holding `.zarray` or a
/// `zarr.json` of `node_type` `array`), or an OME-Zarr image (a group whose attributes
/// hold NGFF `multiscales`, 0.4 on Zarr v2 or 0.5 on Zarr v3 under `ome`), of which the
/// first dataset, the full-resolution level, is read; or one level of such an image
/// (`image.ome.zarr/0`), which takes its scale from the image.
///
/// **Axes.** The array's last three axes are `z`, `y`, `x` (C order, `x` fastest, as
/// NumPy, zarr-python and the NGFF specification store images): element `a[z, y, x]` is
/// voxel `[x, y, z]`. Leading axes (time, channel) must have extent 1. With OME
/// metadata, the spatial axes are those of `type` `space`, which must be the last three.
///
/// **Spacing.** From the OME dataset's `scale` (times the image's own `scale`, if any)
/// and origin from its `translation`; units from the axes' `unit` (`micrometer` is
/// written `µm`, `nanometer` `nm`, `millimeter` `mm`, `angstrom` `Å`). Without OME
/// metadata, spacing 1, origin 0, no unit.
///
/// **Types.** `bool`, 8 to 64-bit integers, `float32`, `float64`; labels when every value
/// is an integer in `0..=u32::MAX`, grey levels otherwise. Other data types are
/// [`IoError::Unsupported`].
///
/// **Bad input.** Metadata that `zarrs` refuses, missing or malformed OME fields, and
/// undecodable chunks are [`IoError::Format`]; the volume and one decoded chunk are
/// checked against [`MAX_VOXELS`](crate::files::MAX_VOXELS) and the memory budget
/// ([`max_memory`](crate::limits::max_memory)) before any chunk is read.
pub fn read_zarr(path: &Path) -> Result<LoadedVoxels, IoError> {
    if !path.is_dir() {
        let source = std::io::Error::new(std::io::ErrorKind::NotFound, "not a Zarr directory");
        return Err(IoError::io(path, path.metadata().err().unwrap_or(source)));
    }
    let fs = |dir: &Path| {
        confine_store(dir)?;
        zarrs::filesystem::FilesystemStore::new(dir)
            .map(Arc::new)
            .map_err(|e| IoError::format(path, one_line(e)))
    };
    // A level of an OME-Zarr image: open the image, so that its metadata give the scale.
    if let (Some(parent), Some(name)) = (path.parent(), path.file_name().and_then(|n| n.to_str())) {
        let is_array = path.join(".zarray").is_file() || path.join("zarr.json").is_file();
        if is_array && is_zarr(parent) && StoreKey::new(name).is_ok() {
            let store = fs(parent)?;
            if let Some(Node::Group(attrs)) = node(&*store, "", path)? {
                if multiscales(&attrs).is_some() {
                    return read_store(store, Some(name), path);
                }
            }
        }
    }
    read_store(fs(path)?, None, path)
}

/// Reads a Zarr node held in memory (the fuzz target's entry point): `entries` are the
/// store's keys (`zarr.json`, `.zarray`, `.zattrs`, `0/zarr.json`, `c/0/0/0`, ...) and
/// their bytes, the node read is the store's root, as [`read_zarr`] reads a directory;
/// `path` only names the store in errors.
pub fn read_zarr_entries(entries: &[(&str, &[u8])], path: &Path) -> Result<LoadedVoxels, IoError> {
    let store = MemoryStore::new();
    for (key, bytes) in entries {
        let key = StoreKey::new(*key).map_err(|e| IoError::format(path, one_line(e)))?;
        store.set(&key, bytes.to_vec().into()).map_err(|e| IoError::format(path, one_line(e)))?;
    }
    read_store(Arc::new(store), None, path)
}

/// What a node's metadata say it is.
enum Node {
    /// An array.
    Array,
    /// A group, with its attributes.
    Group(Value),
}

/// The node at `prefix` (`""`: the root, else `name/`), from its metadata documents.
fn node<S: ReadableStorageTraits + ?Sized>(
    store: &S,
    prefix: &str,
    path: &Path,
) -> Result<Option<Node>, IoError> {
    let json = |name: &str| -> Result<Option<Value>, IoError> {
        let key = StoreKey::new(format!("{prefix}{name}")).map_err(|e| IoError::format(path, one_line(e)))?;
        match store.get(&key).map_err(|e| IoError::format(path, one_line(e)))? {
            None => Ok(None),
            Some(bytes) => serde_json::from_slice(&bytes)
                .map(Some)
                .map_err(|e| IoError::format(path, format!("{prefix}{name}: {e}"))),
        }
    };
    if let Some(meta) = json("zarr.json")? {
        return Ok(match meta.get("node_type").and_then(Value::as_str) {
            Some("group") => Some(Node::Group(meta.get("attributes").cloned().unwrap_or(Value::Null))),
            _ => Some(Node::Array),
        });
    }
    if json(".zarray")?.is_some() {
        return Ok(Some(Node::Array));
    }
    if json(".zgroup")?.is_some() {
        return Ok(Some(Node::Group(json(".zattrs")?.unwrap_or(Value::Null))));
    }
    Ok(None)
}

/// The first NGFF multiscale image of a group's attributes: 0.5 (`ome.multiscales`) or
/// 0.4 (`multiscales`).
fn multiscales(attrs: &Value) -> Option<&Value> {
    attrs.pointer("/ome/multiscales/0").or_else(|| attrs.pointer("/multiscales/0"))
}

/// Where the voxels of an OME-Zarr level sit: per array axis, its NGFF axis and its
/// scale and translation.
struct Placement {
    /// Per array axis: whether it is spatial, and its unit.
    axes: Vec<(bool, Option<String>)>,
    /// Per array axis.
    scale: Vec<f64>,
    /// Per array axis.
    translation: Vec<f64>,
}

/// Reads the store's root node, or `level` of the OME-Zarr image at its root.
fn read_store<S: ReadableStorageTraits + ?Sized + 'static>(
    store: Arc<S>,
    level: Option<&str>,
    path: &Path,
) -> Result<LoadedVoxels, IoError> {
    let (array_path, placement) = match node(&*store, "", path)? {
        None => return Err(IoError::format(path, "not a Zarr store: no zarr.json, .zarray or .zgroup")),
        Some(Node::Array) => ("/".to_string(), None),
        Some(Node::Group(attrs)) => {
            let Some(image) = multiscales(&attrs) else {
                return Err(IoError::unsupported(
                    path,
                    "a Zarr group without OME-Zarr multiscales: name one of its arrays",
                ));
            };
            let (dataset, placement) = ome_level(image, level, path)?;
            (format!("/{dataset}"), Some(placement))
        }
    };
    let array = Array::open(store.clone(), &array_path).map_err(|e| match array_path.as_str() {
        "/" => IoError::format(path, one_line(e)),
        dataset => IoError::format(path, format!("OME-Zarr dataset {}: {}", &dataset[1..], one_line(e))),
    })?;
    let shape = array.shape().to_vec();
    let n = shape.len();
    if let Some(p) = &placement {
        if p.axes.len() != n || p.scale.len() != n || p.translation.len() != n {
            return Err(IoError::format(
                path,
                format!("OME-Zarr metadata for {} axes, the array has {n}", p.axes.len()),
            ));
        }
        let spatial: Vec<bool> = p.axes.iter().map(|a| a.0).collect();
        if n < 3 || spatial[n - 3..] != [true; 3] || spatial[..n - 3].contains(&true) {
            return Err(IoError::unsupported(path, "OME-Zarr axes other than 3 spatial ones last"));
        }
    }
    if n < 3 {
        return Err(IoError::unsupported(path, format!("a {n}-dimensional array (3 are read)")));
    }
    if let Some(d) = shape[..n - 3].iter().position(|&s| s != 1) {
        return Err(IoError::unsupported(
            path,
            format!(
                "array of shape {shape:?}: axis {d} (before z, y, x) has extent {} (1 is read)",
                shape[d]
            ),
        ));
    }
    let dims = [shape[n - 1], shape[n - 2], shape[n - 3]];
    if dims.contains(&0) {
        return Err(IoError::format(path, format!("array of shape {shape:?} is empty")));
    }
    let (dtype, size) = data_type(array.data_type()).ok_or_else(|| {
        IoError::unsupported(
            path,
            format!("data type {} (bool, integers, float32, float64 are read)", array.data_type()),
        )
    })?;
    // The samples, decoded, plus the labels made of them.
    let count = checked_voxel_count(path, dims, size as u64 + 4)?;
    let chunk = array.chunk_shape(&vec![0; n]).map_err(|e| IoError::format(path, one_line(e)))?;
    // Saturating: a declared chunk shape can overflow even a u128.
    let chunk_elements = chunk.iter().fold(1u128, |a, c| a.saturating_mul(u128::from(c.get())));
    let what = format!("a chunk of {:?} elements", chunk.iter().map(|c| c.get()).collect::<Vec<_>>());
    // zarrs decodes chunks in parallel: about as many at once as there are threads.
    let threads = std::thread::available_parallelism().map_or(1, usize::from) as u128;
    let need =
        chunk_elements.saturating_mul(size as u128 * threads).saturating_add((count * (size + 4)) as u128);
    crate::limits::check_memory(path, &what, need)?;
    // Every chunk's decompression is checked against the chunk's size before zarrs
    // inflates it (its decoders inflate to the end, whatever the array declares).
    let chunk_bytes = u64::try_from(chunk_elements.saturating_mul(size as u128)).unwrap_or(u64::MAX);
    let (compressor, trailing) = outer_compressor(&*store, &array_path);
    let bounded = Bounded {
        inner: store,
        compressor,
        trailing,
        bound: chunk_bytes.saturating_add(chunk_bytes / 8).saturating_add(4096),
    };
    let array =
        Array::open(Arc::new(bounded), &array_path).map_err(|e| IoError::format(path, one_line(e)))?;
    // zarrs can panic on a corrupt shard index (a byte range past the chunk's end): that
    // is the file's fault, so it becomes the same one-line error as any other corruption.
    let retrieved = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        array
            .retrieve_array_subset(&array.subset_all())
            .and_then(|b| b.into_fixed().map(|b| b.into_owned()).map_err(Into::into))
            .map_err(|e| IoError::format(path, one_line(e)))
    }));
    let bytes = retrieved
        .unwrap_or_else(|_| Err(IoError::format(path, "corrupt chunk data (the decoder failed)")))?;
    let usize_dims = dims.map(|d| d as usize);
    let endian = if cfg!(target_endian = "big") { Endian::Big } else { Endian::Little };
    let layout = Layout { dims: usize_dims, dtype, endian, order: Order::XFastest };
    let voxels = decode(path, &bytes, layout, None)?;
    let Some(p) = placement else { return Ok(LoadedVoxels { voxels, palette: None, units: None }) };
    let xyz = |v: &[f64]| DVec3::new(v[n - 1], v[n - 2], v[n - 3]);
    let units: Vec<&Option<String>> = p.axes[n - 3..].iter().map(|a| &a.1).collect();
    if units.iter().any(|u| *u != units[0]) {
        return Err(IoError::unsupported(path, "OME-Zarr spatial axes in different units"));
    }
    let volume_error = |source| IoError::Volume { path: path.to_path_buf(), source };
    let voxels = voxels
        .with_spacing(xyz(&p.scale))
        .and_then(|v| v.with_origin(xyz(&p.translation)))
        .map_err(volume_error)?;
    Ok(LoadedVoxels { voxels, palette: None, units: units[0].clone() })
}

/// Refuses a store directory holding a link that leads out of it (after every link is
/// resolved), or a FIFO, device or socket: a chunk is read from the store's own files
/// only, and a chunk that is a FIFO would block the read. Broken links are left to the
/// reader (they read as missing chunks or fail).
fn confine_store(root: &Path) -> Result<(), IoError> {
    let real_root = root.canonicalize().map_err(|e| IoError::io(root, e))?;
    let mut dirs = vec![root.to_path_buf()];
    while let Some(dir) = dirs.pop() {
        for entry in std::fs::read_dir(&dir).map_err(|e| IoError::io(&dir, e))? {
            let entry = entry.map_err(|e| IoError::io(&dir, e))?;
            let entry_path = entry.path();
            let kind = entry.file_type().map_err(|e| IoError::io(&entry_path, e))?;
            if kind.is_dir() {
                dirs.push(entry_path);
                continue;
            }
            if kind.is_symlink() {
                let Ok(real) = entry_path.canonicalize() else { continue };
                if !real.starts_with(&real_root) {
                    return Err(IoError::format(
                        &entry_path,
                        format!(
                            "a link out of the Zarr store {} (to {}): a store is read from its own files",
                            root.display(),
                            real.display()
                        ),
                    ));
                }
                // A link to a directory inside the store: its entries are walked where
                // they are.
                if real.is_dir() {
                    continue;
                }
            }
            crate::files::regular_file_len(&entry_path)?;
        }
    }
    Ok(())
}

/// The compressors whose decompression [`Bounded`] checks.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Compressor {
    Gzip,
    Zlib,
    Zstd,
    Blosc,
}

/// The compressor decoded first from the array's chunks (the last bytes-to-bytes codec
/// of a v3 array, the compressor of a v2 one), and the bytes of checksums appended
/// after it (`crc32c`). `None` for an array whose chunks are not compressed that way
/// (sharding: its inner chunks are read by byte ranges).
fn outer_compressor<S: ReadableStorageTraits + ?Sized>(
    store: &S,
    array_path: &str,
) -> (Option<Compressor>, usize) {
    let prefix = array_path.trim_start_matches('/');
    let prefix = if prefix.is_empty() { String::new() } else { format!("{prefix}/") };
    let json = |name: &str| -> Option<Value> {
        let key = StoreKey::new(format!("{prefix}{name}")).ok()?;
        serde_json::from_slice(&store.get(&key).ok()??).ok()
    };
    let by_name = |name: &str| match name {
        "gzip" => Some(Compressor::Gzip),
        "zlib" | "numcodecs.zlib" => Some(Compressor::Zlib),
        "zstd" | "numcodecs.zstd" => Some(Compressor::Zstd),
        "blosc" | "numcodecs.blosc" => Some(Compressor::Blosc),
        _ => None,
    };
    if let Some(meta) = json("zarr.json") {
        let codecs = meta.get("codecs").and_then(Value::as_array).cloned().unwrap_or_default();
        let mut trailing = 0;
        for codec in codecs.iter().rev() {
            match codec.get("name").and_then(Value::as_str) {
                Some("crc32c") => trailing += 4,
                Some(name) => return (by_name(name), trailing),
                None => break,
            }
        }
        return (None, 0);
    }
    let meta = json(".zarray");
    (meta.as_ref().and_then(|m| m.pointer("/compressor/id")).and_then(Value::as_str).and_then(by_name), 0)
}

/// A store whose chunks are checked before they are decoded: a compressed chunk that
/// inflates (or declares it inflates) past `bound` bytes is an error, found by
/// inflating it into nothing, so that zarrs's decoders, which inflate to the end, never
/// hold more than the chunk's size.
struct Bounded<S: ?Sized> {
    inner: Arc<S>,
    compressor: Option<Compressor>,
    /// Checksum bytes after the compressed data.
    trailing: usize,
    /// The most bytes a chunk may inflate to.
    bound: u64,
}

impl<S: ReadableStorageTraits + ?Sized> Bounded<S> {
    fn check(&self, key: &StoreKey, bytes: &[u8]) -> Result<(), StorageError> {
        use std::io::Read as _;
        let Some(compressor) = self.compressor else { return Ok(()) };
        let name = key.as_str();
        let file = name.rsplit('/').next().unwrap_or(name);
        if matches!(file, "zarr.json" | ".zarray" | ".zattrs" | ".zgroup") {
            return Ok(());
        }
        let data = &bytes[..bytes.len().saturating_sub(self.trailing)];
        let too_large = || {
            StorageError::Other(format!(
                "chunk {name} inflates past the {} bytes a chunk of the array can hold",
                self.bound
            ))
        };
        let sink = &mut std::io::sink();
        let limit = self.bound.saturating_add(1);
        // A stream the decoder cannot read is left to zarrs, which reports it.
        let inflated = match compressor {
            Compressor::Gzip => std::io::copy(&mut flate2::read::GzDecoder::new(data).take(limit), sink).ok(),
            Compressor::Zlib => {
                std::io::copy(&mut flate2::read::ZlibDecoder::new(data).take(limit), sink).ok()
            }
            Compressor::Zstd => match zstd::bulk::Decompressor::upper_bound(data) {
                // zarrs inflates into a buffer of the declared size, no further.
                Some(declared) => Some(declared as u64),
                None => zstd::stream::read::Decoder::new(data)
                    .ok()
                    .and_then(|d| std::io::copy(&mut d.take(limit), sink).ok()),
            },
            // Blosc's header declares the inflated size, which its decoder allocates.
            Compressor::Blosc => {
                data.get(4..8).map(|b| u64::from(u32::from_le_bytes([b[0], b[1], b[2], b[3]])))
            }
        };
        match inflated {
            Some(n) if n > self.bound => Err(too_large()),
            _ => Ok(()),
        }
    }
}

impl<S: ReadableStorageTraits + ?Sized> ReadableStorageTraits for Bounded<S> {
    fn get(&self, key: &StoreKey) -> Result<MaybeBytes, StorageError> {
        let value = self.inner.get(key)?;
        if let Some(bytes) = &value {
            self.check(key, bytes)?;
        }
        Ok(value)
    }

    fn get_partial(&self, key: &StoreKey, byte_range: ByteRange) -> Result<MaybeBytes, StorageError> {
        match byte_range {
            ByteRange::FromStart(0, None) => self.get(key),
            range => self.inner.get_partial(key, range),
        }
    }

    fn get_partial_many<'a>(
        &'a self,
        key: &StoreKey,
        byte_ranges: ByteRangeIterator<'a>,
    ) -> Result<MaybeBytesIterator<'a>, StorageError> {
        self.inner.get_partial_many(key, byte_ranges)
    }

    fn size_key(&self, key: &StoreKey) -> Result<Option<u64>, StorageError> {
        self.inner.size_key(key)
    }

    fn supports_get_partial(&self) -> bool {
        self.inner.supports_get_partial()
    }
}

/// The dataset path and placement of `level` (its path; `None`: the first dataset) of an
/// NGFF multiscale image.
fn ome_level(image: &Value, level: Option<&str>, path: &Path) -> Result<(String, Placement), IoError> {
    let bad = |what: &str| IoError::format(path, format!("OME-Zarr multiscales: {what}"));
    let axes = image.get("axes").and_then(Value::as_array).ok_or_else(|| bad("no axes"))?;
    let axes = axes
        .iter()
        .map(|a| {
            let name = a.get("name").and_then(Value::as_str).unwrap_or("");
            let spatial = match a.get("type").and_then(Value::as_str) {
                Some(t) => t == "space",
                None => matches!(name, "x" | "y" | "z"),
            };
            (spatial, a.get("unit").and_then(Value::as_str).map(unit))
        })
        .collect::<Vec<_>>();
    let datasets = image.get("datasets").and_then(Value::as_array).ok_or_else(|| bad("no datasets"))?;
    let dataset = match level {
        None => datasets.first(),
        Some(l) => datasets.iter().find(|d| d.get("path").and_then(Value::as_str) == Some(l)),
    }
    .ok_or_else(|| bad(&format!("no dataset {}", level.unwrap_or("0"))))?;
    let dataset_path =
        dataset.get("path").and_then(Value::as_str).ok_or_else(|| bad("a dataset without a path"))?;
    let relative =
        !dataset_path.is_empty() && dataset_path.split('/').all(|c| !c.is_empty() && c != "." && c != "..");
    if !relative {
        return Err(bad(&format!("dataset path '{dataset_path}' is not a relative path inside the image")));
    }
    let n = axes.len();
    let mut scale = vec![1.0; n];
    let mut translation = vec![0.0; n];
    // The dataset's transformations, then the image's own (NGFF: applied after them).
    for transforms in [dataset.get("coordinateTransformations"), image.get("coordinateTransformations")]
        .into_iter()
        .flatten()
    {
        let transforms =
            transforms.as_array().ok_or_else(|| bad("coordinateTransformations is not a list"))?;
        for t in transforms {
            let values = || -> Result<Vec<f64>, IoError> {
                let kind = t.get("type").and_then(Value::as_str).unwrap_or("?");
                let v = t.get(kind).and_then(Value::as_array).ok_or_else(|| {
                    bad(&format!("a '{kind}' transformation without inline values (a path is not read)"))
                })?;
                let v: Option<Vec<f64>> = v.iter().map(Value::as_f64).collect();
                v.filter(|v| v.len() == n && v.iter().all(|x| x.is_finite()))
                    .ok_or_else(|| bad(&format!("'{kind}' needs {n} finite numbers")))
            };
            match t.get("type").and_then(Value::as_str) {
                Some("scale") => {
                    let s = values()?;
                    for i in 0..n {
                        scale[i] *= s[i];
                        translation[i] *= s[i];
                    }
                }
                Some("translation") => {
                    let s = values()?;
                    for i in 0..n {
                        translation[i] += s[i];
                    }
                }
                Some("identity") => {}
                other => {
                    return Err(IoError::unsupported(
                        path,
                        format!("OME-Zarr transformation '{}'", other.unwrap_or("without a type")),
                    ))
                }
            }
        }
    }
    Ok((dataset_path.to_string(), Placement { axes, scale, translation }))
}

/// An NGFF unit as voxreg writes units elsewhere (control characters escaped).
fn unit(name: &str) -> String {
    match name {
        "micrometer" | "micron" => "µm",
        "nanometer" => "nm",
        "millimeter" => "mm",
        "centimeter" => "cm",
        "meter" => "m",
        "angstrom" => "Å",
        other => return crate::files::printable(other),
    }
    .to_string()
}

/// The sample type of a Zarr data type, and its size in bytes; `None` for types that are
/// not read.
fn data_type(t: &ZarrType) -> Option<(DataType, usize)> {
    let dtype = match t {
        ZarrType::Bool | ZarrType::UInt8 => DataType::U8,
        ZarrType::Int8 => DataType::I8,
        ZarrType::UInt16 => DataType::U16,
        ZarrType::Int16 => DataType::I16,
        ZarrType::UInt32 => DataType::U32,
        ZarrType::Int32 => DataType::I32,
        ZarrType::UInt64 => DataType::U64,
        ZarrType::Int64 => DataType::I64,
        ZarrType::Float32 => DataType::F32,
        ZarrType::Float64 => DataType::F64,
        _ => return None,
    };
    Some((dtype, dtype.size()))
}

/// An error's message on one line.
fn one_line(e: impl std::fmt::Display) -> String {
    e.to_string().split_whitespace().collect::<Vec<_>>().join(" ")
}
