//! `regularize_block`: one block of a chunked volume (the `voxreg.dask` tasks), returning
//! what the block owns under global lattice ids.

use numpy::ndarray::{Array1, Array2};
use numpy::IntoPyArray;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use voxreg_regularize::{regularize_block as run_block, Block};

use crate::error::{no_panic, Error};
use crate::params;
use crate::run::{on_pool, report_json, threads_arg};
use crate::volume;

/// The core of `voxreg.dask`'s per-chunk task: `labels` are the voxels from global index
/// `start` on (the chunk with its halo), `owned` the chunk's half-open global ranges.
#[pyfunction]
#[pyo3(signature = (labels, spacing, origin, background, start, owned, global_dims, preset, options, threads))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn regularize_block<'py>(
    py: Python<'py>,
    labels: &Bound<'py, PyAny>,
    spacing: [f64; 3],
    origin: [f64; 3],
    background: Option<u32>,
    start: [usize; 3],
    owned: [[usize; 2]; 3],
    global_dims: [usize; 3],
    preset: &str,
    options: &Bound<'py, PyDict>,
    threads: i64,
) -> PyResult<Bound<'py, PyDict>> {
    let params = params::params(preset, options)?;
    let threads = threads_arg(threads)?;
    let labels = volume::labels_of(labels, voxreg_io::max_memory())?;
    let volume = volume::volume(labels.view(), spacing, origin, background)?;
    let block = Block { global_dims, start, owned };
    let mesh = py.detach(|| {
        on_pool(threads, || {
            no_panic(|| run_block(&volume, &block, &params).map_err(|e| Error::regularize("", &e)))
        })
    })??;
    let report = mesh.report.as_ref().map(report_json).transpose()?;
    let n = mesh.vertex_ids.len();
    let m = mesh.quads.len();
    let dict = PyDict::new(py);
    dict.set_item("vertex_ids", Array1::from(mesh.vertex_ids).into_pyarray(py))?;
    let positions: Vec<f64> = mesh.positions.iter().flat_map(|p| p.to_array()).collect();
    dict.set_item("positions", Array2::from_shape_vec((n, 3), positions).expect("rows").into_pyarray(py))?;
    dict.set_item("owns_vertex", Array1::from(mesh.owns_vertex).into_pyarray(py))?;
    let quads: Vec<u32> = mesh.quads.into_iter().flatten().collect();
    dict.set_item("quads", Array2::from_shape_vec((m, 4), quads).expect("rows").into_pyarray(py))?;
    let labels: Vec<u32> = mesh.labels.into_iter().flatten().collect();
    dict.set_item("labels", Array2::from_shape_vec((m, 2), labels).expect("rows").into_pyarray(py))?;
    dict.set_item("report_json", report)?;
    Ok(dict)
}
