//! `regularize`: a numpy label volume through the library's front door, with the GIL
//! released, a private thread pool and a throttled progress callback.

use std::any::Any;
use std::panic::{catch_unwind, resume_unwind, AssertUnwindSafe};
use std::sync::Arc;
use std::time::{Duration, Instant};

use numpy::PyReadonlyArray2;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyString};
use voxreg_io::{Material, Palette};
use voxreg_regularize::{Budgeted, Event, Output, Regularizer, Report, Run, Stage};

use crate::error::{panic_error, Error, Result};
use crate::mesh::{Part, Surface};
use crate::params;
use crate::volume;

/// The shortest interval between two progress calls (a stage change always calls).
pub(crate) const THROTTLE: Duration = Duration::from_millis(50);

/// The unwinding payload that aborts a run whose progress callback raised.
struct Cancelled;

/// A material as the Python layer passes it: name, RGBA, metallic, roughness, emission,
/// transparency.
type MaterialTuple = (String, [u8; 4], f32, f32, f32, f32);

fn palette_arg(
    colors: Option<PyReadonlyArray2<'_, u8>>,
    materials: Option<Vec<MaterialTuple>>,
    names: Option<std::collections::BTreeMap<u32, String>>,
) -> Result<Option<Palette>> {
    let Some(colors) = colors else { return Ok(None) };
    let names: std::collections::BTreeMap<u32, String> =
        names.unwrap_or_default().into_iter().filter(|(_, n)| !n.trim().is_empty()).collect();
    let view = colors.as_array();
    if view.ncols() != 4 {
        return Err(Error::parameter(format!(
            "palette colours must be an (n, 4) RGBA array, got {:?}",
            view.shape()
        )));
    }
    let colors: Vec<[u8; 4]> = view.rows().into_iter().map(|r| [r[0], r[1], r[2], r[3]]).collect();
    Ok(Some(match materials {
        None => {
            // Materials named after the labels, as the readers name them.
            let mut palette = Palette::from_colors(colors);
            for (&label, name) in &names {
                palette.set_name(label, name);
            }
            palette
        }
        Some(m) => {
            if m.len() != colors.len() {
                return Err(Error::parameter(format!(
                    "{} palette materials for {} colours",
                    m.len(),
                    colors.len()
                )));
            }
            let materials = m
                .into_iter()
                .map(|(name, color, metallic, roughness, emission, transparency)| Material {
                    name,
                    color,
                    metallic,
                    roughness,
                    emission,
                    transparency,
                })
                .collect();
            Palette { colors, materials, names }
        }
    }))
}

/// The most threads a private pool may have: more only costs their start-up.
pub(crate) const MAX_THREADS: i64 = 1024;

pub(crate) fn threads_arg(threads: i64) -> Result<usize> {
    match usize::try_from(threads) {
        Ok(n) if threads <= MAX_THREADS => Ok(n),
        Ok(_) => Err(Error::parameter(format!(
            "threads must be at most {MAX_THREADS} (0: every core), got {threads}"
        ))),
        Err(_) => Err(Error::parameter(format!(
            "threads must be a non-negative integer (0: every core), got {threads}"
        ))),
    }
}

/// Runs `f` on a private pool of `threads` threads (0: rayon's default, every core).
pub(crate) fn on_pool<T: Send>(threads: usize, f: impl FnOnce() -> T + Send) -> Result<T> {
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().map_err(|e| {
        Error::new(crate::error::Kind::Voxreg, format!("cannot start {threads} threads: {e}"))
    })?;
    Ok(pool.install(f))
}

/// The core of `voxreg.regularize` (documented there).
#[pyfunction]
#[pyo3(signature = (
    labels, spacing, origin, background, preset, options, threads, progress, palette_colors,
    palette_materials, max_memory, palette_names=None
))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn regularize<'py>(
    py: Python<'py>,
    labels: &Bound<'py, PyAny>,
    spacing: [f64; 3],
    origin: [f64; 3],
    background: Option<u32>,
    preset: &str,
    options: &Bound<'py, PyDict>,
    threads: i64,
    progress: Option<Py<PyAny>>,
    palette_colors: Option<PyReadonlyArray2<'py, u8>>,
    palette_materials: Option<Vec<MaterialTuple>>,
    max_memory: Option<&Bound<'py, PyAny>>,
    palette_names: Option<std::collections::BTreeMap<u32, String>>,
) -> PyResult<Bound<'py, PyDict>> {
    let params = params::params(preset, options)?;
    let threads = threads_arg(threads)?;
    let palette = palette_arg(palette_colors, palette_materials, palette_names)?;
    // Never above what the address-space and cgroup limits leave the process.
    let limit = max_memory_arg(max_memory)?;
    let limit = voxreg_io::environment_limit().map_or(limit, |e| e.min(limit));
    // Borrowed (uint32) or converted with the GIL held.
    let labels = volume::labels_of(labels, limit)?;
    let volume = volume::volume(labels.view(), spacing, origin, background)?;

    let mut callback_error: Option<PyErr> = None;
    let outcome = {
        let mut last: Option<(Stage, Instant)> = None;
        let params = &params;
        let callback_error = &mut callback_error;
        let progress = progress.as_ref();
        let mut report = move |e: &Event| {
            let Some(callback) = progress else { return };
            let now = Instant::now();
            if last.is_some_and(|(stage, t)| stage == e.stage && now.duration_since(t) < THROTTLE) {
                return;
            }
            last = Some((e.stage, now));
            let label = e.stage.label(params);
            if let Err(err) = Python::attach(|py| callback.bind(py).call1((label, e.fraction)).map(drop)) {
                *callback_error = Some(err);
                resume_unwind(Box::new(Cancelled));
            }
        };
        let volume = &volume;
        // On a thread of its own while this one runs Python's signal handlers: Ctrl-C
        // raises the run's interrupt.
        crate::signals::interruptible(py, move |interrupt| {
            on_pool(threads, move || {
                catch_unwind(AssertUnwindSafe(|| -> Result<Output> {
                    // Refused before the surface is built, as the CLI refuses it.
                    let need = |s: u64| voxreg_regularize::estimated_bytes(s, params);
                    let mut regularizer =
                        match Regularizer::from_volume_within_budget(volume, &params.regions, limit, need)
                            .map_err(|e| Error::regularize("labels: no surface to regularize: ", &e))?
                        {
                            Budgeted::Fits(r) => *r,
                            Budgeted::TooLarge { surfels, bytes } => {
                                let what = format!("the regularization of its {surfels} surfels");
                                return Err(volume::over_budget(&what, bytes, limit));
                            }
                        };
                    regularizer.set_keep_normals(false);
                    regularizer.set_interrupt(interrupt.clone());
                    regularizer
                        .run(Run::new(params).progress(&mut report))
                        .map_err(|e| Error::regularize("", &e))
                }))
            })
        })?
    };
    let out = match outcome {
        Ok(result) => result?,
        Err(payload) => return Err(aborted(payload, callback_error)),
    };
    if let Some(callback) = &progress {
        callback.bind(py).call1(("done", 1.0))?;
    }
    drop(labels);
    finish(py, out, palette)
}

/// `max_memory=`: bytes, a size such as `"4G"`, or `None` for the library's budget (half
/// the physical memory, or less where the environment limits the process).
fn max_memory_arg(max_memory: Option<&Bound<'_, PyAny>>) -> Result<u64> {
    let Some(m) = max_memory else { return Ok(voxreg_io::max_memory()) };
    let bad = || {
        Error::parameter(format!(
            "max_memory must be a positive number of bytes or a size such as '4G', got {m}"
        ))
    };
    if let Ok(s) = m.cast::<PyString>() {
        return voxreg_io::parse_size(&s.to_string()).ok_or_else(bad);
    }
    match m.extract::<u64>() {
        Ok(n) if n > 0 => Ok(n),
        _ => Err(bad()),
    }
}

/// The error of a run that unwound: the callback's exception, or a panic's `VoxregError`.
fn aborted(payload: Box<dyn Any + Send>, callback_error: Option<PyErr>) -> PyErr {
    match (payload.is::<Cancelled>(), callback_error) {
        (true, Some(err)) => err,
        _ => panic_error(payload).into(),
    }
}

/// A run's report as the JSON string the Python layer parses.
pub(crate) fn report_json(report: &Report) -> Result<String> {
    serde_json::to_string(report).map_err(|e| Error::new(crate::error::Kind::Voxreg, e.to_string()))
}

/// The result dict: the whole mesh's arrays, the report (JSON), the CLI's summary line and
/// the surface handle for sub-meshes and writing.
fn finish<'py>(py: Python<'py>, out: Output, palette: Option<Palette>) -> PyResult<Bound<'py, PyDict>> {
    let r = &out.report;
    let summary = r.summary();
    let report = report_json(r)?;
    let converged = r.converged();
    let surface =
        Surface { surface: Arc::clone(&out.surface), positions: Arc::new(out.positions.into_vec()), palette };
    let arrays = py.detach(|| crate::error::no_panic(|| Ok(surface.arrays(Part::All))))?;
    let dict = arrays.into_dict(py)?;
    dict.set_item("report_json", report)?;
    dict.set_item("summary", summary)?;
    dict.set_item("converged", converged)?;
    dict.set_item("surface", Bound::new(py, surface)?)?;
    Ok(dict)
}
