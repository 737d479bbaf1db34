//! `read`: every format the CLI reads, as the CLI reads it (`crates/cli/src/input.rs`),
//! into a numpy label array and a dict of what the file says about it.

use std::path::PathBuf;

use glam::DVec3;
use numpy::ndarray::Array2;
use numpy::IntoPyArray;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use voxreg_io::{is_voxel_art, read_raw, read_voxels, DataType, Endian, Palette, RawSpec, Voxels};

use crate::error::{no_panic, Error, Result};

/// What the Rust side of `read` returns before the GIL is taken again.
struct Loaded {
    volume: voxreg_digisurf::LabelVolume,
    palette: Option<Palette>,
}

#[allow(clippy::too_many_arguments)]
fn load(
    path: &std::path::Path,
    threshold: Option<f64>,
    dims: Option<[u64; 3]>,
    dtype: Option<DataType>,
    endian: Option<Endian>,
    spacing: Option<DVec3>,
    keep: Option<&[u32]>,
    background: Option<u32>,
) -> Result<Loaded> {
    let is_raw = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("raw"));
    let (voxels, palette) = match dims {
        Some(dims) => {
            let spec = RawSpec {
                dims,
                dtype: dtype.unwrap_or(DataType::U8),
                endian: endian.unwrap_or_default(),
                spacing: spacing.unwrap_or(DVec3::ONE),
            };
            (read_raw(path, &spec).map_err(|e| Error::io(&e))?, None)
        }
        None if is_raw => {
            return Err(Error::input(format!(
                "{}: raw data have no header: give dims=(X, Y, Z) and dtype",
                path.display()
            )))
        }
        None => {
            let loaded = read_voxels(path).map_err(|e| Error::io(&e))?;
            (loaded.voxels, loaded.palette)
        }
    };
    let voxels = match spacing {
        Some(s) => voxels
            .with_spacing(s)
            .map_err(|e| Error::parameter(format!("{}: spacing: {e}", path.display())))?,
        None => voxels,
    };
    let mut volume = match (threshold, voxels) {
        (Some(t), _) if t.is_nan() => return Err(Error::parameter("threshold: NaN is not a threshold")),
        (Some(t), voxels) => voxels.threshold(t),
        (None, Voxels::Labels(volume)) => volume,
        (None, Voxels::Grey(grey)) => match grey.to_labels() {
            Ok(volume) => volume,
            Err(e) => {
                let (lo, hi) = grey.range().unwrap_or_default();
                return Err(Error::input(format!(
                    "{}: grey-level data needs threshold=T (values range from {lo} to {hi}; {e})",
                    path.display()
                )));
            }
        },
    };
    if let Some(keep) = keep {
        let bg = background.or(volume.background()).unwrap_or(0);
        volume.labels_mut().mapv_inplace(|l| if keep.contains(&l) { l } else { bg });
    }
    if let Some(b) = background {
        volume = volume.with_background(Some(b));
    }
    Ok(Loaded { volume, palette })
}

/// The palette as `{"colors": (n, 4) uint8, "materials": [dict]}`.
pub(crate) fn palette_dict<'py>(py: Python<'py>, palette: &Palette) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    let flat: Vec<u8> = palette.colors.iter().flatten().copied().collect();
    let colors = Array2::from_shape_vec((palette.colors.len(), 4), flat).expect("RGBA rows");
    d.set_item("colors", colors.into_pyarray(py))?;
    let materials = PyList::empty(py);
    for m in &palette.materials {
        let md = PyDict::new(py);
        md.set_item("name", &m.name)?;
        md.set_item("color", m.color)?;
        md.set_item("metallic", m.metallic)?;
        md.set_item("roughness", m.roughness)?;
        md.set_item("emission", m.emission)?;
        md.set_item("transparency", m.transparency)?;
        materials.append(md)?;
    }
    d.set_item("materials", materials)?;
    Ok(d)
}

/// The core of `voxreg.read` (documented there).
#[pyfunction]
#[pyo3(signature = (path, threshold=None, dims=None, dtype=None, endian=None, spacing=None, keep_labels=None, background=None))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn read<'py>(
    py: Python<'py>,
    path: PathBuf,
    threshold: Option<f64>,
    dims: Option<[u64; 3]>,
    dtype: Option<String>,
    endian: Option<String>,
    spacing: Option<[f64; 3]>,
    keep_labels: Option<Vec<u32>>,
    background: Option<u32>,
) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyDict>)> {
    if dims.is_none() && (dtype.is_some() || endian.is_some()) {
        return Err(Error::parameter("dtype and endian describe raw data: give dims=(X, Y, Z) too").into());
    }
    if threshold.is_some() && keep_labels.is_some() {
        return Err(Error::parameter("threshold and keep_labels exclude each other").into());
    }
    let dtype = dtype
        .map(|d| d.parse::<DataType>())
        .transpose()
        .map_err(|e| Error::parameter(format!("dtype: {e}")))?;
    let endian = endian
        .map(|d| d.parse::<Endian>())
        .transpose()
        .map_err(|e| Error::parameter(format!("endian: {e}")))?;
    let spacing = match spacing.map(DVec3::from_array) {
        Some(s) if !(s.is_finite() && s.min_element() > 0.0) => {
            return Err(Error::parameter(format!(
                "spacing: voxel sizes must be finite and positive, got {s}"
            ))
            .into())
        }
        s => s,
    };
    let loaded = py.detach(|| {
        no_panic(|| load(&path, threshold, dims, dtype, endian, spacing, keep_labels.as_deref(), background))
    })?;
    let mut loaded = loaded;
    let v = &loaded.volume;
    let info = PyDict::new(py);
    info.set_item("spacing", v.spacing().to_array())?;
    info.set_item("origin", v.origin().to_array())?;
    info.set_item("background", v.background())?;
    match &loaded.palette {
        Some(p) => info.set_item("palette", palette_dict(py, p)?)?,
        None => info.set_item("palette", py.None())?,
    }
    let preset = if dims.is_none() && is_voxel_art(&path) { "voxel_art" } else { "default" };
    info.set_item("preset", preset)?;
    // Moved, not copied, into numpy.
    let labels = crate::volume::to_numpy(py, std::mem::take(loaded.volume.labels_mut()));
    Ok((labels, info))
}
