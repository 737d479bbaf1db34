//! The solve worker: one thread owns the current input and its [`Regularizer`] (surface,
//! solver analysis, normals), runs the jobs the page sends, and publishes what the page
//! polls and streams (the latest iterate, the final result, errors) in [`State`].

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, Sender};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::time::{Duration, Instant};
use voxreg_simplify::Simplified;

use glam::DVec3;
use voxreg_digisurf::{Block, BlockVolume, RegionMap, SurfaceError};
use voxreg_io::{Palette, QuadMesh};
use voxreg_regularize::{Budgeted, Interrupt, Output, Params, RegularizeError, Regularizer, Run, Stage};

use crate::model::{f32_bytes, Model};
use crate::model::{Loaded, Volume};
use crate::tuning::Tuning;

/// The least time between two streamed iterates (the first of a run is sent at once).
const FRAME_INTERVAL: Duration = Duration::from_millis(60);

/// A job for the worker.
pub(crate) enum Job {
    /// Show a new input; the reply says whether its surface could be built.
    Open(Box<Loaded>, Option<Sender<Result<(), String>>>, u64),
    /// Re-solve the current input with these parameters.
    Solve(Tuning, u64),
    /// Remove or add a voxel at a face of the surface shown, and re-solve.
    Edit(Edit, u64),
}

/// A voxel edit from the page: at face `face` of surface `model` (the state's
/// `model_id`), remove the voxel behind the face (it takes the label of the one in front)
/// or, with `add`, give the voxel in front the label of the one behind. Behind is along
/// `toward` (the click's ray), or without it the face's inner side (seen against its
/// normal).
#[derive(Clone, Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct Edit {
    pub(crate) model: u64,
    pub(crate) face: usize,
    #[serde(default)]
    pub(crate) add: bool,
    #[serde(default)]
    pub(crate) toward: Option<[f64; 3]>,
    /// The panel's parameters for the re-solve (default: the last solve's).
    #[serde(default)]
    pub(crate) tuning: Option<Tuning>,
}

/// The last result of the current input, for downloads and the side panel.
#[derive(Debug)]
pub(crate) struct Finished {
    pub(crate) positions: Vec<DVec3>,
    pub(crate) normals: Vec<u8>,
    pub(crate) features: Option<Vec<u8>>,
    pub(crate) report: serde_json::Value,
    pub(crate) summary: String,
}

/// The pyramid of one result, or why it could not be computed.
#[derive(Debug)]
pub(crate) struct Levels {
    /// The frame of the result simplified ([`State::frame`] when it was published).
    pub(crate) frame: u64,
    /// The levels of the pyramid, level 0 first.
    pub(crate) result: Result<Vec<Simplified>, String>,
    /// Milliseconds the simplification took.
    pub(crate) ms: f64,
}

impl Levels {
    /// The levels, if they simplify the result shown in `state`.
    pub(crate) fn of(state: &State) -> Option<&[Simplified]> {
        let levels = state.levels.as_ref().filter(|l| l.frame == state.frame && state.frame_final)?;
        levels.result.as_deref().ok()
    }
}

/// What the page sees; `version` grows on every change (the event stream sends each).
#[derive(Debug, Default)]
pub(crate) struct State {
    pub(crate) version: u64,
    /// Grows with each new surface (a new input, or regions changed with the preset).
    pub(crate) model_id: u64,
    pub(crate) name: String,
    pub(crate) model: Option<Arc<Model>>,
    pub(crate) surface: Option<Arc<voxreg_digisurf::DigitalSurface>>,
    pub(crate) palette: Option<Palette>,
    pub(crate) tuning: Option<Tuning>,
    /// The latest positions (an iterate, or the final result), little-endian `f32`.
    pub(crate) positions: Option<Arc<Vec<u8>>>,
    /// Grows with every new `positions`.
    pub(crate) frame: u64,
    /// The job whose run produced `positions` (the number [`Shared::next_job`] gave it).
    pub(crate) job: u64,
    pub(crate) frame_final: bool,
    pub(crate) stage: String,
    pub(crate) iteration: Option<usize>,
    pub(crate) busy: bool,
    pub(crate) error: Option<String>,
    /// Milliseconds from the job's request to its first streamed iterate, and to its end.
    pub(crate) first_frame_ms: Option<f64>,
    pub(crate) total_ms: Option<f64>,
    /// The last finished run's solver iterations (all its solves), and whether its first
    /// solve started from the previous result (the iterative solvers).
    pub(crate) iterations: Option<usize>,
    pub(crate) warm: bool,
    pub(crate) finished: Option<Arc<Finished>>,
    /// Runs stopped because a newer job replaced them.
    pub(crate) superseded: u64,
    /// Whether the surface comes from a voxel edit of the previous one (the page keeps
    /// its view), and the milliseconds the edit's new surface took to build.
    pub(crate) edited: bool,
    pub(crate) edit_ms: Option<f64>,
    /// The level of detail the page chose (0: the full surface).
    pub(crate) level: usize,
    /// The levels of detail of a result, once computed (dropped when a new run starts).
    pub(crate) levels: Option<Arc<Levels>>,
    /// Whether the levels' thread is simplifying a result.
    pub(crate) levels_busy: bool,
    /// How far that simplification is, from 0 to 1 (`voxreg_simplify::Progress::overall`,
    /// updated at each whole percent).
    pub(crate) levels_progress: f64,
    /// Simplifications stopped because a newer result (or the viewer's end) replaced the
    /// one they simplified.
    pub(crate) levels_stopped: u64,
    pub(crate) shutdown: bool,
}

/// The state and the condition the event streams wait on.
#[derive(Debug, Default)]
pub(crate) struct Shared {
    state: Mutex<State>,
    pub(crate) changed: Condvar,
    /// Counts the jobs queued: a run whose job is older than the latest is interrupted
    /// (the job that replaced it runs next).
    jobs: AtomicU64,
    /// The latest job and when its request came (a job's times count from there, the
    /// wait for the run it replaces included).
    arrival: Mutex<Option<(u64, Instant)>>,
    /// The running job and the interrupt its run polls, raised when a newer job comes.
    running: Mutex<Option<(u64, Interrupt)>>,
    /// The frame the levels' thread is simplifying and the interrupt its simplification
    /// polls, raised by a new job, a run's start, a new frame or the viewer's end.
    levels_running: Mutex<Option<(u64, Interrupt)>>,
}

impl Shared {
    /// Numbers a new job, and interrupts the running one (it stops within a chunk of its
    /// current stage: an iteration, a multigrid level, a surfel of the normals).
    pub(crate) fn next_job(&self) -> u64 {
        let mut arrival = self.arrival.lock().unwrap_or_else(|e| e.into_inner());
        let job = self.jobs.fetch_add(1, Ordering::SeqCst) + 1;
        *arrival = Some((job, Instant::now()));
        drop(arrival);
        if let Some((_, interrupt)) = &*self.running.lock().unwrap_or_else(|e| e.into_inner()) {
            interrupt.raise();
        }
        // The result being simplified is about to be replaced.
        if let Some((_, interrupt)) = &*self.levels_running.lock().unwrap_or_else(|e| e.into_inner()) {
            interrupt.raise();
        }
        job
    }

    /// Registers the levels' simplification of the frame shown in `state` (locked by the
    /// caller, so that no later change of frame is missed); its interrupt.
    pub(crate) fn start_levels(&self, state: &State) -> Interrupt {
        let interrupt = Interrupt::new();
        *self.levels_running.lock().unwrap_or_else(|e| e.into_inner()) =
            Some((state.frame, interrupt.clone()));
        interrupt
    }

    /// Forgets the levels' simplification once it returned.
    pub(crate) fn end_levels(&self) {
        *self.levels_running.lock().unwrap_or_else(|e| e.into_inner()) = None;
    }

    /// The interrupt of job `job`'s run, raised already if a newer job came.
    fn start(&self, job: u64) -> Interrupt {
        let interrupt = Interrupt::new();
        *self.running.lock().unwrap_or_else(|e| e.into_inner()) = Some((job, interrupt.clone()));
        // A job numbered between this one's and the registration raised no interrupt.
        if self.superseded(job) {
            interrupt.raise();
        }
        interrupt
    }

    /// When job `job`'s request came, if it is the latest.
    fn arrival(&self, job: u64) -> Option<Instant> {
        let arrival = self.arrival.lock().unwrap_or_else(|e| e.into_inner());
        arrival.filter(|(j, _)| *j == job).map(|(_, t)| t)
    }

    fn superseded(&self, job: u64) -> bool {
        self.jobs.load(Ordering::SeqCst) > job
    }

    /// The state; a panic elsewhere never makes it unreachable.
    pub(crate) fn lock(&self) -> MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Applies `f` to the state, bumps its version and wakes the event streams.
    pub(crate) fn update(&self, f: impl FnOnce(&mut State)) {
        let mut s = self.lock();
        f(&mut s);
        // A simplification of a frame no longer shown, or about to be replaced by a run
        // that started, stops.
        if let Some((frame, interrupt)) = &*self.levels_running.lock().unwrap_or_else(|e| e.into_inner()) {
            if s.shutdown || s.busy || s.frame != *frame {
                interrupt.raise();
            }
        }
        s.version += 1;
        drop(s);
        self.changed.notify_all();
    }
}

/// The worker's own data for the current input.
struct Current {
    loaded: Loaded,
    regularizer: Regularizer,
    regions: voxreg_digisurf::RegionMap,
    /// The last finished run's solutions on this surface, one per solve round (each
    /// round's last iterate): the next run's starting guesses ([`Run::warm`](voxreg_regularize::Run::warm()));
    /// empty on a new surface.
    last: Vec<Vec<DVec3>>,
    /// The last solve's parameters (a voxel edit re-solves with them).
    tuned: Option<(Tuning, Params)>,
}

/// Runs jobs until the channel closes; a panicking job becomes an error on the page.
pub(crate) fn worker(shared: Arc<Shared>, jobs: Receiver<Job>) {
    let mut current: Option<Current> = None;
    while let Ok(mut job) = jobs.recv() {
        // Only the latest re-solve matters: skip those a newer one replaced.
        while let Job::Solve(..) = job {
            match jobs.try_recv() {
                Ok(next) => job = next,
                Err(_) => break,
            }
        }
        let id = match &job {
            Job::Open(_, _, id) | Job::Solve(_, id) | Job::Edit(_, id) => *id,
        };
        let t = shared.arrival(id).unwrap_or_else(Instant::now);
        let interrupt = shared.start(id);
        // On a thread of rayon's pool, so that the solve's parallel passes do not each
        // wake a worker from outside it.
        let result = catch_unwind(AssertUnwindSafe(|| {
            rayon::scope(|_| run(&shared, &mut current, job, t, &interrupt))
        }));
        if let Err(panic) = result {
            let message = panic_message(&*panic);
            current = None;
            shared.update(|s| {
                s.busy = false;
                s.error = Some(format!("internal error: {message}"));
            });
        }
    }
}

/// A panic payload's message.
pub(crate) fn panic_message(panic: &(dyn std::any::Any + Send)) -> String {
    match (panic.downcast_ref::<&str>(), panic.downcast_ref::<String>()) {
        (Some(s), _) => s.to_string(),
        (_, Some(s)) => s.clone(),
        _ => "a panic".to_string(),
    }
}

fn run(shared: &Shared, current: &mut Option<Current>, job: Job, t: Instant, interrupt: &Interrupt) {
    match job {
        Job::Open(loaded, reply, job) => {
            let loaded = *loaded;
            let params =
                match (Tuning { preset: loaded.preset, overrides: loaded.overrides.clone() }).resolve() {
                    Ok(p) => p,
                    Err(e) => {
                        let message = format!("{}: {e}", loaded.name);
                        shared.update(|s| s.error = Some(message.clone()));
                        if let Some(reply) = reply {
                            let _ = reply.send(Err(message));
                        }
                        return;
                    }
                };
            let tuning = Tuning::of(loaded.preset, &loaded.overrides, &params);
            shared.update(|s| {
                s.busy = true;
                s.stage = "digital surface".into();
            });
            match build(&loaded.volume, &params.regions, &loaded.name) {
                Ok(regularizer) => {
                    // A new input is shown whole first.
                    shared.update(|s| s.level = 0);
                    let regions = params.regions.clone();
                    *current = Some(Current { loaded, regularizer, regions, last: Vec::new(), tuned: None });
                    let c = current.as_mut().expect("set above");
                    publish_model(shared, c, None);
                    if let Some(reply) = reply {
                        let _ = reply.send(Ok(()));
                    }
                    solve(shared, c, tuning, params, t, job, interrupt);
                }
                Err(message) => {
                    shared.update(|s| {
                        s.busy = false;
                        s.error = Some(message.clone());
                    });
                    if let Some(reply) = reply {
                        let _ = reply.send(Err(message));
                    }
                }
            }
        }
        Job::Solve(tuning, job) => {
            let Some(c) = current.as_mut() else {
                shared.update(|s| s.error = Some("no input to solve: open a file".into()));
                return;
            };
            let tuning = tuning.merged(c.loaded.preset, &c.loaded.overrides);
            let params = match tuning.resolve() {
                Ok(p) => p,
                Err(e) => {
                    shared.update(|s| s.error = Some(e));
                    return;
                }
            };
            if params.regions != c.regions {
                // The preset groups labels differently: a new surface.
                match build(&c.loaded.volume, &params.regions, &c.loaded.name) {
                    Ok(r) => {
                        c.regularizer = r;
                        c.regions = params.regions.clone();
                        c.last.clear();
                        publish_model(shared, c, None);
                    }
                    Err(message) => {
                        shared.update(|s| s.error = Some(message));
                        return;
                    }
                }
            }
            solve(shared, c, tuning, params, t, job, interrupt);
        }
        Job::Edit(edit, job) => {
            let Some(c) = current.as_mut() else {
                shared.update(|s| s.error = Some("no input to edit: open a file".into()));
                return;
            };
            let tuned = match edit.tuning.clone() {
                Some(tuning) => {
                    let tuning = tuning.merged(c.loaded.preset, &c.loaded.overrides);
                    tuning.resolve().map(|p| (tuning, p))
                }
                None => match c.tuned.clone() {
                    Some(tp) => Ok(tp),
                    None => {
                        let tuning =
                            Tuning { preset: c.loaded.preset, overrides: c.loaded.overrides.clone() };
                        tuning.resolve().map(|p| (Tuning::of(c.loaded.preset, &c.loaded.overrides, &p), p))
                    }
                },
            };
            let (tuning, params) = match tuned {
                Ok(tp) if tp.1.regions == c.regions => tp,
                Ok(_) => {
                    let message = "the preset groups the labels otherwise: solve with it before editing";
                    shared.update(|s| s.error = Some(message.into()));
                    return;
                }
                Err(e) => {
                    shared.update(|s| s.error = Some(e));
                    return;
                }
            };
            if let Err(message) = apply_edit(shared, c, &edit) {
                shared.update(|s| s.error = Some(message));
                return;
            }
            shared.update(|s| s.edit_ms = Some(t.elapsed().as_secs_f64() * 1e3));
            solve(shared, c, tuning, params, t, job, interrupt);
        }
    }
}

/// Changes the voxel of `edit`, rebuilds the surface, and maps the last run's solutions
/// onto it by lattice corner (a new vertex starts at its corner), so that the re-solve
/// starts from the shape shown; a refused edit leaves everything as it was.
fn apply_edit(shared: &Shared, c: &mut Current, edit: &Edit) -> Result<(), String> {
    let shown = shared.lock().model_id;
    if edit.model != shown {
        return Err("the surface changed since that click: click again".into());
    }
    let old = Arc::clone(c.regularizer.surface());
    let Some(face) = old.surfels().get(edit.face) else {
        return Err(format!("no face {} on this surface of {} faces", edit.face, old.num_surfels()));
    };
    // [behind, in front], voxels and labels: [inner, outer] unless the ray crosses the face
    // from the outer side (the inner voxel is on the negative side unless it is flipped).
    let (mut voxels, mut labels) = (face.voxels(), face.labels);
    let axis = usize::from(face.axis);
    if edit.toward.is_some_and(|t| t[axis] != 0.0 && (t[axis] > 0.0) != face.flipped) {
        voxels.swap(0, 1);
        labels.swap(0, 1);
    }
    let (voxel, label) = if edit.add { (voxels[1], labels[0]) } else { (voxels[0], labels[1]) };
    let dims = c.loaded.volume.dims();
    let index =
        (0..3).map(|k| usize::try_from(voxel[k]).ok().filter(|&i| i < dims[k])).collect::<Option<Vec<_>>>();
    let Some(index) = index else {
        return Err(format!(
            "the voxel ({}, {}, {}) is outside the volume ({} x {} x {}): only voxels inside it can change",
            voxel[0], voxel[1], voxel[2], dims[0], dims[1], dims[2]
        ));
    };
    let at = [index[0], index[1], index[2]];
    let regularizer = match &mut c.loaded.volume {
        Volume::Dense(volume) => {
            let before = volume.labels()[at];
            volume.labels_mut()[at] = label;
            let built = build(&c.loaded.volume, &c.regions, &c.loaded.name);
            if built.is_err() {
                if let Volume::Dense(volume) = &mut c.loaded.volume {
                    volume.labels_mut()[at] = before;
                }
            }
            built?
        }
        Volume::Blocks(volume) => {
            let edited =
                Volume::Blocks(with_label(volume, at, label).map_err(|e| format!("{}: {e}", c.loaded.name))?);
            let built = build(&edited, &c.regions, &c.loaded.name)?;
            c.loaded.volume = edited;
            built
        }
    };
    let new = Arc::clone(regularizer.surface());
    let mut by_corner = std::collections::HashMap::with_capacity(old.num_vertices());
    for v in 0..old.num_vertices() {
        by_corner.entry(old.vertex_corner(voxreg_digisurf::VertexId(v as u32))).or_insert(v);
    }
    let staircase = new.positions();
    let map: Vec<Option<usize>> = (0..new.num_vertices())
        .map(|v| by_corner.get(&new.vertex_corner(voxreg_digisurf::VertexId(v as u32))).copied())
        .collect();
    let mapped = |x: &[DVec3]| -> Vec<DVec3> {
        map.iter().zip(staircase.iter()).map(|(m, p)| m.map_or(*p, |i| x[i])).collect()
    };
    c.last = c.last.iter().map(|x| mapped(x)).collect();
    let shown = shared.lock().finished.as_ref().map(|f| mapped(&f.positions));
    c.regularizer = regularizer;
    publish_model(shared, c, shown.as_deref());
    Ok(())
}

/// Peak memory per surfel of a viewer session: a clamped run's (the page may turn clamping
/// on at any time) and what the session keeps across runs (the solver's last cycle for a
/// quick start, the initial normals, the shown and streamed positions). Not measured
/// apart: the figure the command line's clamped runs had before theirs was measured
/// lower, above [`voxreg_regularize::BYTES_PER_SURFEL_CLAMPED`].
const SESSION_BYTES_PER_SURFEL: u64 = 2_700;

/// The regularizer of `volume`, refused up front (as the CLI does) when a session on it
/// would not fit the memory limit; the error is the page's one-line message. Blocks are
/// built as blocks ([`Regularizer::from_blocks`]): the memory of the models' boxes.
fn build(volume: &Volume, regions: &RegionMap, name: &str) -> Result<Regularizer, String> {
    let need = |surfels: u64| {
        surfels.saturating_mul(SESSION_BYTES_PER_SURFEL).saturating_add(voxreg_regularize::BYTES_FIXED)
    };
    let limit = voxreg_io::max_memory();
    // A dense volume: one pass over the voxels, the extraction's (a refused one is counted).
    let budgeted = match volume {
        Volume::Dense(v) => Regularizer::from_volume_within_budget(v, regions, limit, need),
        Volume::Blocks(v) => Regularizer::from_blocks_within_budget(v, regions, limit, need),
    }
    .map_err(|e| format!("{name}: {e}"))?;
    match budgeted {
        Budgeted::Fits(r) => Ok(*r),
        Budgeted::TooLarge { surfels, bytes } => {
            let path = std::path::PathBuf::from(name);
            let what = format!("the regularization of its {surfels} surfels");
            Err(voxreg_io::IoError::OverBudget { path, what, bytes, limit }.to_string())
        }
    }
}

/// `volume` with voxel `at` set to `label`: inside a block, that block's voxel; outside
/// every block, a new one-voxel block, merged with the blocks it touches (and so on) into
/// their bounding box, so that the blocks stay one voxel apart. The voxels stay those of
/// the volume made dense with `at` set.
fn with_label(volume: &BlockVolume, at: [usize; 3], label: u32) -> Result<BlockVolume, SurfaceError> {
    let mut blocks = volume.blocks().to_vec();
    let inside = |b: &Block| {
        let (lo, hi) = b.bounds();
        (0..3).all(|k| lo[k] <= at[k] && at[k] < hi[k])
    };
    if let Some(b) = blocks.iter_mut().find(|b| inside(b)) {
        let o = b.offset;
        b.labels[[at[0] - o[0], at[1] - o[1], at[2] - o[2]]] = label;
    } else if label != volume.background() {
        let mut new = Block { offset: at, labels: ndarray::Array3::from_elem((1, 1, 1), label) };
        loop {
            let (lo, hi) = new.bounds();
            let touching: Vec<usize> = (0..blocks.len())
                .filter(|&i| {
                    let (blo, bhi) = blocks[i].bounds();
                    (0..3).all(|k| blo[k] <= hi[k] && lo[k] <= bhi[k])
                })
                .collect();
            if touching.is_empty() {
                break;
            }
            let (mut mlo, mut mhi) = (lo, hi);
            for &i in &touching {
                let (blo, bhi) = blocks[i].bounds();
                for k in 0..3 {
                    mlo[k] = mlo[k].min(blo[k]);
                    mhi[k] = mhi[k].max(bhi[k]);
                }
            }
            let shape = (mhi[0] - mlo[0], mhi[1] - mlo[1], mhi[2] - mlo[2]);
            let mut labels = ndarray::Array3::from_elem(shape, volume.background());
            let mut parts = vec![new];
            for &i in touching.iter().rev() {
                parts.push(blocks.swap_remove(i));
            }
            for part in &parts {
                let (plo, phi) = part.bounds();
                let mut view = labels.view_mut();
                for k in 0..3 {
                    view.slice_axis_inplace(
                        ndarray::Axis(k),
                        ndarray::Slice::from(plo[k] - mlo[k]..phi[k] - mlo[k]),
                    );
                }
                view.assign(&part.labels);
            }
            new = Block { offset: mlo, labels };
        }
        blocks.push(new);
    }
    BlockVolume::new(volume.dims(), blocks, volume.background())?
        .with_spacing(volume.spacing())?
        .with_origin(volume.origin())
}

/// Publishes the current surface, drawn at `positions` (a voxel edit: the last result
/// mapped onto it) or as its staircase.
fn publish_model(shared: &Shared, c: &Current, positions: Option<&[DVec3]>) {
    let surface = Arc::clone(c.regularizer.surface());
    let model = Arc::new(Model::new(&surface, c.loaded.palette.as_ref()));
    let name = c.loaded.name.clone();
    let palette = c.loaded.palette.clone();
    let edited = positions.is_some();
    let shown = match positions {
        Some(x) => f32_bytes(x.iter().flat_map(|p| p.to_array())),
        None => model.staircase.clone(),
    };
    shared.update(|s| {
        s.model_id += 1;
        s.edited = edited;
        s.edit_ms = None;
        s.name = name;
        s.positions = Some(Arc::new(shown));
        s.frame += 1;
        s.frame_final = false;
        s.model = Some(model);
        s.surface = Some(surface);
        s.palette = palette;
        // The panel shows a surface's parameters once its solve sets them, not the last
        // input's.
        s.tuning = None;
        s.finished = None;
        s.levels = None;
        s.error = None;
    });
}

fn solve(
    shared: &Shared,
    c: &mut Current,
    tuning: Tuning,
    params: Params,
    t: Instant,
    job: u64,
    interrupt: &Interrupt,
) {
    c.tuned = Some((tuning.clone(), params.clone()));
    shared.update(|s| {
        s.busy = true;
        s.error = None;
        s.tuning = Some(tuning);
        s.first_frame_ms = None;
        s.total_ms = None;
        // The last result's levels of detail: this run replaces them.
        s.levels = None;
    });
    let mut last: Option<Instant> = None;
    // The same surface: each round starts from the last run's (the same minimizers, fewer
    // iterations); this run's rounds are kept for the next.
    let warm = c.last.clone();
    let mut rounds: Vec<Vec<DVec3>> = Vec::new();
    c.regularizer.set_interrupt(interrupt.clone());
    let result = c.regularizer.run(Run::new(&params).warm(&warm).progress(&mut |e| {
        if let (Stage::Solve { round }, Some(p), Some(input)) = (e.stage, e.iteration, e.input) {
            if rounds.len() <= round {
                rounds.resize(round + 1, Vec::new());
            }
            let x = &mut rounds[round];
            x.clear();
            x.extend(input.iter().zip(p.displacement).map(|(x, d)| *x + *d));
        }
        let label = e.stage.label(&params);
        let due = last.is_none_or(|l| l.elapsed() >= FRAME_INTERVAL);
        let iterate = if due { e.iterate() } else { None };
        match iterate {
            Some(x) => {
                last = Some(Instant::now());
                let bytes = Arc::new(f32_bytes(x.iter().flat_map(|p| p.to_array())));
                let ms = t.elapsed().as_secs_f64() * 1e3;
                shared.update(|s| {
                    s.positions = Some(bytes);
                    s.frame += 1;
                    s.job = job;
                    s.frame_final = false;
                    s.stage = label;
                    s.iteration = e.iteration.map(|p| p.iteration);
                    s.first_frame_ms.get_or_insert(ms);
                });
            }
            None if e.iteration.is_none() => shared.update(|s| {
                s.stage = label;
                s.iteration = None;
            }),
            None => {}
        }
    }));
    let ms = t.elapsed().as_secs_f64() * 1e3;
    match result {
        Ok(out) => {
            let finished = Arc::new(finish(&out));
            let iterations = out.report.solves.iter().map(|s| s.iterations()).sum();
            // The iterative solvers take the starting guesses, the direct one does not.
            let warmed = !warm.is_empty() && out.report.solves.first().is_some_and(|s| s.name() != "direct");
            // A round that reported no iterate (it started at its minimizer) keeps the
            // previous run's start, or the result for the last round; the starts end at
            // the first round without one.
            for (k, x) in rounds.iter_mut().enumerate() {
                if x.is_empty() {
                    *x = warm.get(k).cloned().unwrap_or_default();
                }
            }
            let solves = params.refinement().rounds + 1;
            if rounds.len() < solves {
                rounds.resize(solves, Vec::new());
            }
            if rounds[solves - 1].is_empty() {
                rounds[solves - 1] = out.positions.to_vec();
            }
            let kept = rounds.iter().take_while(|x| !x.is_empty()).count();
            rounds.truncate(kept);
            c.last = rounds;
            let bytes = Arc::new(f32_bytes(out.positions.iter().flat_map(|p| p.to_array())));
            shared.update(|s| {
                s.positions = Some(bytes);
                s.frame += 1;
                s.job = job;
                s.frame_final = true;
                s.stage = "done".into();
                s.iteration = None;
                s.busy = false;
                s.total_ms = Some(ms);
                s.iterations = Some(iterations);
                s.warm = warmed;
                s.finished = Some(finished);
            });
        }
        // A newer job is queued: it runs next and publishes its own state.
        Err(RegularizeError::Interrupted) => shared.update(|s| s.superseded += 1),
        Err(e) => {
            let message = format!("{}: cannot regularize: {e}", c.loaded.name);
            shared.update(|s| {
                s.busy = false;
                s.error = Some(message);
            });
        }
    }
}

fn finish(out: &Output) -> Finished {
    Finished {
        positions: out.positions.to_vec(),
        normals: f32_bytes(out.normals.as_slice().iter().flat_map(|n| n.to_array())),
        features: out.features.as_ref().map(|f| f32_bytes(f.as_slice().iter().copied())),
        report: serde_json::to_value(&out.report).unwrap_or(serde_json::Value::Null),
        summary: out.report.summary(),
    }
}

/// The mesh `voxreg regularize` writes of `surface` at `positions`: one quad per surfel,
/// one group per interface, and with a palette its materials.
pub(crate) fn result_mesh(
    surface: &voxreg_digisurf::DigitalSurface,
    positions: &[DVec3],
    palette: Option<&Palette>,
) -> QuadMesh {
    let mut mesh = QuadMesh::from_surface(surface, positions);
    if let Some(p) = palette {
        mesh.assign_materials(p);
    }
    mesh
}

/// The final result as a mesh file of format `ext` (`glb`, `ply` or `obj`), written by
/// `voxreg_io::write_mesh` (what `voxreg regularize` writes), at level of detail `level`
/// (0: the full surface; another level once computed: what `--lod` writes).
pub(crate) fn mesh_file(state: &State, ext: &str, level: usize) -> Result<Vec<u8>, String> {
    let (Some(surface), Some(finished)) = (&state.surface, &state.finished) else {
        return Err("no result yet: wait for the solve to finish".into());
    };
    let level_mesh;
    let mesh = if level == 0 {
        level_mesh = result_mesh(surface, &finished.positions, state.palette.as_ref());
        &level_mesh
    } else {
        match Levels::of(state).and_then(|l| l.get(level)) {
            Some(l) => &l.mesh,
            None => return Err(format!("level {level} is not computed for this result: choose it first")),
        }
    };
    let dir = tempfile::tempdir().map_err(|e| format!("cannot create a temporary directory: {e}"))?;
    let path = dir.path().join(format!("result.{ext}"));
    voxreg_io::write_mesh(&path, mesh).map_err(|e| e.to_string())?;
    std::fs::read(&path).map_err(|e| format!("cannot read back {}: {e}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    use voxreg_digisurf::LabelVolume;

    #[test]
    fn a_surface_over_the_memory_limit_is_refused_before_it_is_built() {
        let volume: Volume =
            LabelVolume::from_fn([8, 8, 8], |[x, y, z]| u32::from((x + y + z) % 2 == 0)).into();
        let regions = RegionMap::per_label();
        let message =
            voxreg_io::with_max_memory(1 << 20, || build(&volume, &regions, "noise.vox")).unwrap_err();
        assert!(message.starts_with("noise.vox: the regularization of its"), "{message}");
        assert!(message.contains("memory limit"), "{message}");
        assert!(build(&volume, &regions, "noise.vox").is_ok());
    }

    /// Edits of a blocks volume give the voxels of the dense volume edited alike, the
    /// blocks one voxel apart: inside a block, next to one (merged into it), bridging two
    /// (all three merged), and alone.
    #[test]
    fn block_edits_are_the_dense_edits() {
        let block = |offset: [usize; 3], dims: (usize, usize, usize), label: u32| Block {
            offset,
            labels: ndarray::Array3::from_shape_fn(dims, |(x, y, z)| label + ((x + y + z) % 2) as u32),
        };
        let blocks = vec![
            block([0, 0, 0], (2, 2, 2), 1),
            block([3, 0, 0], (2, 1, 2), 3),
            block([0, 4, 4], (1, 1, 1), 5),
        ];
        let mut volume = BlockVolume::new([6, 6, 6], blocks, 0)
            .unwrap()
            .with_spacing(glam::DVec3::new(1.0, 2.0, 0.5))
            .unwrap()
            .with_origin(glam::DVec3::splat(-3.0))
            .unwrap();
        let mut dense = volume.to_dense().unwrap();
        for (at, label) in
            [([1, 1, 1], 0), ([2, 0, 0], 7), ([2, 0, 1], 0), ([5, 5, 5], 9), ([0, 3, 4], 2), ([4, 4, 0], 0)]
        {
            volume = with_label(&volume, at, label).unwrap();
            dense.labels_mut()[at] = label;
            assert_eq!(volume.to_dense().unwrap(), dense, "{at:?} {label}");
        }
        // [2, 0, 0] joined the first two blocks, [0, 3, 4] the third; [5, 5, 5] is alone.
        assert_eq!(
            volume.blocks().len(),
            3,
            "{:?}",
            volume.blocks().iter().map(Block::bounds).collect::<Vec<_>>()
        );
        let regions = RegionMap::per_label();
        let a = build(&Volume::Blocks(volume), &regions, "s.vox").unwrap();
        let b = build(&Volume::Dense(dense), &regions, "s.vox").unwrap();
        assert_eq!(a.surface().surfels(), b.surface().surfels());
    }
}
