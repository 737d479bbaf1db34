//! Simplification that keeps the partition (`voxreg_simplify`): of a regularized surface's
//! part, or of a mesh given as arrays; one level or a pyramid of levels.

use numpy::{PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use std::time::Instant;
use voxreg_io::{FaceGroup, Material, QuadMesh};

use voxreg_simplify::{
    simplify_levels_reporting, Interrupt, Options, Progress, Simplified, SimplifyError, Stage, Stats, Target,
};

use crate::error::{Error, Result};
use crate::mesh::{colors_materials, labels_of, positions_of, quads_of, Arrays, PartSpec, Surface};
use crate::run::THROTTLE;
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

/// The stage as the callback gets it: `setup`, or `collapses`, `flips`, `pairing` with
/// `level K/N` before it when there are several levels.
fn stage_label(p: &Progress) -> String {
    if p.stage == Stage::Setup || p.levels == 1 {
        p.stage.label().to_string()
    } else {
        format!("level {}/{}: {}", p.level + 1, p.levels, p.stage.label())
    }
}

/// Simplifies on the calling (worker) thread, calling `progress(stage, fraction)` with the
/// GIL at most every 50 ms and at every stage change; an exception it raises is kept in
/// `failed` and stops the run through `interrupt`.
fn run(
    mesh: &QuadMesh,
    targets: &[Target],
    interrupt: &Interrupt,
    progress: Option<&Py<PyAny>>,
    failed: &mut Option<PyErr>,
) -> Result<Vec<(Arrays, Stats)>> {
    let mut last: Option<(String, Instant)> = None;
    let mut report = |p: &Progress| {
        let Some(callback) = progress else { return };
        if failed.is_some() {
            return;
        }
        let label = stage_label(p);
        let now = Instant::now();
        let same = last.as_ref().is_some_and(|(l, t)| *l == label && now.duration_since(*t) < THROTTLE);
        if same && p.fraction < 1.0 {
            return;
        }
        let fraction = p.overall();
        if let Err(e) = Python::attach(|py| callback.bind(py).call1((label.as_str(), fraction)).map(drop)) {
            *failed = Some(e);
            interrupt.raise();
        }
        last = Some((label, now));
    };
    let levels = simplify_levels_reporting(mesh, targets, &Options::default(), interrupt, &mut report)
        .map_err(|e| error_of(&e))?;
    Ok(levels.into_iter().map(|Simplified { mesh, stats }| (Arrays::of(&mesh), stats)).collect())
}

/// Runs `work` with Ctrl-C and the progress callback wired: the callback's exception
/// first, then the run's error; `("done", 1.0)` after a run that completed.
fn with_progress<T: Send>(
    py: Python<'_>,
    progress: Option<Py<PyAny>>,
    work: impl FnOnce(&Interrupt, Option<&Py<PyAny>>, &mut Option<PyErr>) -> Result<T> + Send,
) -> PyResult<T> {
    let mut failed: Option<PyErr> = None;
    let outcome = {
        let failed = &mut failed;
        let progress = progress.as_ref();
        interruptible(py, move |interrupt| work(interrupt, progress, failed))
    };
    if let Some(e) = failed {
        return Err(e);
    }
    let out = outcome?;
    if let Some(callback) = &progress {
        callback.bind(py).call1(("done", 1.0))?;
    }
    Ok(out)
}

/// A regularized surface's part (as `Surface.mesh`) simplified to each of `targets`
/// (`(ratio or None, max_error)`) in turn, one collapse sequence: `[(arrays, stats)]`,
/// level `k` a simplification of level `k - 1`.
#[pyfunction]
#[pyo3(signature = (surface, targets, part=None, progress=None))]
pub(crate) fn simplify_surface<'py>(
    py: Python<'py>,
    surface: PyRef<'py, Surface>,
    targets: Vec<TargetTuple>,
    part: Option<PartSpec>,
    progress: Option<Py<PyAny>>,
) -> PyResult<Bound<'py, PyList>> {
    let part = Surface::part(part)?;
    surface.check_part(part)?;
    let targets = targets_of(&targets);
    let surface: &Surface = &surface;
    let levels = with_progress(py, progress, |interrupt, progress, failed| {
        run(&surface.quad_mesh(part), &targets, interrupt, progress, failed)
    })?;
    levels_list(py, levels)
}

/// A mesh given as arrays simplified to each of `targets` in turn: `[(arrays, stats)]`.
/// `groups`: per face a group number (faces of one group, labels and colour form one
/// patch; negative: none); `colors`: per face RGBA (one material per distinct colour).
#[pyfunction]
#[pyo3(signature = (vertices, quads, labels, targets, groups=None, colors=None, progress=None))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn simplify_arrays<'py>(
    py: Python<'py>,
    vertices: PyReadonlyArray2<'py, f64>,
    quads: PyReadonlyArray2<'py, i64>,
    labels: PyReadonlyArray2<'py, u32>,
    targets: Vec<TargetTuple>,
    groups: Option<PyReadonlyArray1<'py, i64>>,
    colors: Option<PyReadonlyArray2<'py, u8>>,
    progress: Option<Py<PyAny>>,
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
    let levels = with_progress(py, progress, |interrupt, progress, failed| {
        run(&mesh, &targets, interrupt, progress, failed)
    })?;
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
