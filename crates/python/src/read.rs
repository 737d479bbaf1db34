//! `read`: every format the CLI reads, as the CLI reads it (`crates/cli/src/input.rs`),
//! into a numpy label array and a dict of what the file says about it.

use std::path::PathBuf;

use glam::DVec3;
use numpy::ndarray::Array2;
use numpy::IntoPyArray;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use voxreg_io::{is_voxel_art, read_input, Background, DataType, Endian, InputError, InputOptions, Palette};

use crate::error::{no_panic, Error, Result};

/// What the Rust side of `read` returns before the GIL is taken again.
struct Loaded {
    volume: voxreg_digisurf::LabelVolume,
    palette: Option<Palette>,
}

/// Reads as the CLI reads (`voxreg_io::read_input`), with the errors in the keywords' names.
fn load(path: &std::path::Path, options: &InputOptions<'_>) -> Result<Loaded> {
    match read_input(path, options) {
        Ok(input) => Ok(Loaded { volume: input.volume, palette: input.palette }),
        Err(InputError::RawNeedsDims(_)) => Err(Error::input(format!(
            "{}: raw data have no header: give dims=(X, Y, Z) and dtype",
            path.display()
        ))),
        Err(InputError::Spacing { source, .. }) => {
            Err(Error::parameter(format!("{}: spacing: {source}", path.display())))
        }
        Err(InputError::NanThreshold) => Err(Error::parameter("threshold: NaN is not a threshold")),
        Err(InputError::GreyNeedsThreshold { lo, hi, reason, .. }) => Err(Error::input(format!(
            "{}: grey-level data needs threshold=T (values range from {lo} to {hi}; {reason})",
            path.display()
        ))),
        Err(InputError::Io(e)) => Err(Error::io(&e)),
        Err(e @ InputError::ModelNeedsVox(_)) => Err(Error::parameter(e.to_string())),
    }
}

/// The palette as `{"colors": (n, 4) uint8, "materials": [dict], "names": {label: name}}`.
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
    let names = PyDict::new(py);
    for (label, name) in &palette.names {
        names.set_item(label, name)?;
    }
    d.set_item("names", names)?;
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
    let options = InputOptions {
        dims,
        dtype,
        endian,
        vox_model: None,
        spacing,
        threshold,
        keep_labels: keep_labels.as_deref(),
        background: background.map_or(Background::File, Background::Label),
    };
    let loaded = py.detach(|| no_panic(|| load(&path, &options)))?;
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
