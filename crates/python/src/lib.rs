//! The Rust core of the `voxreg` Python package (`voxreg._voxreg`).
//!
//! Thin bindings: every function takes and returns numpy arrays, plain Python values and
//! one opaque handle (`Surface`); the pure-Python package (`python/voxreg`) shapes them
//! into `voxreg.Mesh`, documents the public API and converts to pyvista and trimesh.
//! Computation runs with the GIL released, on a private rayon pool of the requested size.
//! No panic crosses into Python: each entry point catches them and raises `VoxregError`.

mod block;
mod error;
mod mesh;
mod params;
mod read;
mod run;
mod signals;
mod simplify;
mod volume;

use pyo3::prelude::*;

/// The extension module.
#[pymodule]
fn _voxreg(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(run::regularize, m)?)?;
    m.add_function(wrap_pyfunction!(read::read, m)?)?;
    m.add_function(wrap_pyfunction!(block::regularize_block, m)?)?;
    m.add_function(wrap_pyfunction!(mesh::check, m)?)?;
    m.add_function(wrap_pyfunction!(params::option_names, m)?)?;
    m.add_function(wrap_pyfunction!(params::preset_halo, m)?)?;
    m.add_function(wrap_pyfunction!(mesh::write_arrays, m)?)?;
    m.add_function(wrap_pyfunction!(simplify::simplify_arrays, m)?)?;
    m.add_function(wrap_pyfunction!(simplify::simplify_surface, m)?)?;
    m.add_function(wrap_pyfunction!(simplify::pyramid_targets, m)?)?;
    m.add_class::<mesh::Surface>()?;
    m.add_class::<mesh::PlyParts>()?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
