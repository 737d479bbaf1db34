//! Simplification that keeps the partition (`voxreg_simplify`): of a regularized surface's
//! part, or of a mesh given as arrays; one level or a pyramid of levels.

use numpy::{PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use voxreg_io::{FaceGroup, Material, QuadMesh};
use voxreg_simplify::{
    simplify_levels_interruptible, Interrupt, Options, Simplified, SimplifyError, Stats, Target,
};

use crate::error::{Error, Result};
use crate::mesh::{colors_materials, labels_of, positions_of, quads_of, Arrays, PartSpec, Surface};
use crate::signals::interruptible;

/// A level's target as Python passes it: `(ratio or None, max_error)`.
pub(crate) type TargetTuple = (Option<f64>, f64);

fn targets_of(targets: &[TargetTuple]) -> Vec<Target> {
    targets.iter().map(|&(ratio, max_error)| Target { ratio, max_error }).collect()
}

fn error_of(e: &SimplifyError) -> Error {
    match e {
        SimplifyError::InvalidMesh(_) => Error::input(e.to_string()),
        SimplifyError::InvalidTarget(_) => Error::parameter(e.to_string()),
        // Only raised by `signals::interruptible`, which returns the signal's exception
        // instead.
        SimplifyError::Interrupted => Error::new(crate::error::Kind::Voxreg, e.to_string()),
    }
}

fn stats_dict<'py>(py: Python<'py>, s: &Stats) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("input_faces", s.input_faces)?;
    d.set_item("input_triangles", s.input_triangles)?;
    d.set_item("triangles_left", s.triangles_left)?;
    d.set_item("faces", s.faces)?;
    d.set_item("quads", s.quads)?;
    d.set_item("error_bound", s.error_bound)?;
    d.set_item("corners", s.corners)?;
    d.set_item("line_vertices", s.line_vertices)?;
    Ok(d)
}

/// The levels as Python takes them: a list of `(arrays dict, stats dict)`.
fn levels_list<'py>(py: Python<'py>, levels: Vec<(Arrays, Stats)>) -> PyResult<Bound<'py, PyList>> {
    let out = PyList::empty(py);
    for (arrays, stats) in levels {
        out.append((arrays.into_dict(py)?, stats_dict(py, &stats)?))?;
    }
    Ok(out)
}

fn run(mesh: &QuadMesh, targets: &[Target], interrupt: &Interrupt) -> Result<Vec<(Arrays, Stats)>> {
    let levels = simplify_levels_interruptible(mesh, targets, &Options::default(), interrupt)
        .map_err(|e| error_of(&e))?;
    Ok(levels.into_iter().map(|Simplified { mesh, stats }| (Arrays::of(&mesh), stats)).collect())
}

/// A regularized surface's part (as `Surface.mesh`) simplified to each of `targets`
/// (`(ratio or None, max_error)`) in turn, one collapse sequence: `[(arrays, stats)]`,
/// level `k` a simplification of level `k - 1`.
#[pyfunction]
#[pyo3(signature = (surface, targets, part=None))]
pub(crate) fn simplify_surface<'py>(
    py: Python<'py>,
    surface: PyRef<'py, Surface>,
    targets: Vec<TargetTuple>,
    part: Option<PartSpec>,
) -> PyResult<Bound<'py, PyList>> {
    let part = Surface::part(part)?;
    surface.check_part(part)?;
    let targets = targets_of(&targets);
    let surface: &Surface = &surface;
    let levels = interruptible(py, |interrupt| run(&surface.quad_mesh(part), &targets, interrupt))?;
    levels_list(py, levels)
}

/// A mesh given as arrays simplified to each of `targets` in turn: `[(arrays, stats)]`.
/// `groups`: per face a group number (faces of one group, labels and colour form one
/// patch; negative: none); `colors`: per face RGBA (one material per distinct colour).
#[pyfunction]
#[pyo3(signature = (vertices, quads, labels, targets, groups=None, colors=None))]
pub(crate) fn simplify_arrays<'py>(
    py: Python<'py>,
    vertices: PyReadonlyArray2<'py, f64>,
    quads: PyReadonlyArray2<'py, i64>,
    labels: PyReadonlyArray2<'py, u32>,
    targets: Vec<TargetTuple>,
    groups: Option<PyReadonlyArray1<'py, i64>>,
    colors: Option<PyReadonlyArray2<'py, u8>>,
) -> PyResult<Bound<'py, PyList>> {
    let positions = positions_of(&vertices)?;
    let quads = quads_of(&quads, positions.len())?;
    let face_labels = labels_of(&labels, quads.len())?;
    let mut mesh = QuadMesh { positions, quads, face_labels, ..Default::default() };
    if let Some(colors) = colors {
        let (materials, face_materials): (Vec<Material>, Vec<u32>) =
            colors_materials(&colors, mesh.quads.len())?;
        mesh.materials = materials;
        mesh.face_materials = face_materials;
    }
    if let Some(groups) = groups {
        let g = groups.as_array();
        if g.len() != mesh.quads.len() {
            return Err(Error::input(format!(
                "groups must have one entry per face ({}), got {}",
                mesh.quads.len(),
                g.len()
            ))
            .into());
        }
        let mut by_id: std::collections::BTreeMap<i64, Vec<u32>> = std::collections::BTreeMap::new();
        for (f, &id) in g.iter().enumerate() {
            if id >= 0 {
                by_id.entry(id).or_default().push(f as u32);
            }
        }
        mesh.groups =
            by_id.into_iter().map(|(id, faces)| FaceGroup { name: format!("g{id}"), faces }).collect();
    }
    let targets = targets_of(&targets);
    let levels = interruptible(py, |interrupt| run(&mesh, &targets, interrupt))?;
    levels_list(py, levels)
}

/// The targets of a pyramid of `levels` levels (`voxreg_simplify::pyramid_targets`):
/// level `k` keeps `factor^-k` of the faces within `max_error 2^(k-1)`, level 0 the input.
#[pyfunction]
pub(crate) fn pyramid_targets(levels: usize, factor: f64, max_error: f64) -> Vec<TargetTuple> {
    voxreg_simplify::pyramid_targets(levels, factor, max_error)
        .into_iter()
        .map(|t| (t.ratio, t.max_error))
        .collect()
}
