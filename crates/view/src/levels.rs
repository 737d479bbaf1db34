//! Levels of detail of the result shown: the regularized mesh simplified with its partition
//! kept ([`voxreg_simplify`]), the pyramid `voxreg regularize --lod` writes (each level a
//! quarter of the faces of the one before, within half a voxel doubled per level), so
//! that the page can show a coarser level without solving again.
//!
//! The levels are computed on their own thread, once per result and only once the page
//! has chosen a level other than the full surface; they belong to the frame of the result
//! they simplify, so that a new run (which publishes new frames) drops them. Each
//! computation polls an interrupt of its own, raised by a new job, a new frame or the
//! viewer's end: a simplification that a new run overtook stops within milliseconds and
//! leaves the thread free for the newer result.

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::Arc;

use voxreg_digisurf::DigitalSurface;
use voxreg_io::{Palette, QuadMesh};
use voxreg_simplify::{
    pyramid_targets, simplify_levels_reporting, Interrupt, Options, Progress, Simplified, SimplifyError,
};

use crate::model::{f32_bytes, Model};
use crate::session::{panic_message, result_mesh, Levels, Shared, State};

/// The levels of the pyramid, the full surface included (as `--lod 4`).
pub(crate) const LEVELS: usize = 4;

/// Each level keeps about `1 / FACTOR` of the faces of the one before.
const FACTOR: f64 = 4.0;

/// The distance bound of level 1, in voxels (the command line's default `--max-error`);
/// it doubles with each level.
const MAX_ERROR_VOXELS: f64 = 0.5;

/// The level the page should draw: the chosen one once it is computed for the result
/// shown, else the full surface.
pub(crate) fn shown(state: &State) -> usize {
    match Levels::of(state) {
        Some(l) if state.level < l.len() => state.level,
        _ => 0,
    }
}

/// Whether the levels of the result shown are wanted and not there yet: a level other
/// than the full surface is chosen, the run is over and its levels are not computed.
fn wanted(state: &State) -> bool {
    state.level > 0
        && !state.busy
        && state.frame_final
        && state.finished.is_some()
        && state.surface.is_some()
        && state.levels.as_ref().is_none_or(|l| l.frame != state.frame)
}

/// The levels' thread: computes the pyramid of each result whose levels are wanted, until
/// the viewer stops.
pub(crate) fn worker(shared: Arc<Shared>) {
    loop {
        let (frame, surface, finished, palette, interrupt) = {
            let s = shared.lock();
            let s = shared
                .changed
                .wait_while(s, |s| !s.shutdown && !wanted(s))
                .unwrap_or_else(|e| e.into_inner());
            if s.shutdown {
                return;
            }
            let (Some(surface), Some(finished)) = (s.surface.clone(), s.finished.clone()) else { continue };
            // Registered with the state locked, so that no change of frame is missed.
            let interrupt = shared.start_levels(&s);
            (s.frame, surface, finished, s.palette.clone(), interrupt)
        };
        shared.update(|s| {
            s.levels_busy = true;
            s.levels_progress = 0.0;
        });
        let t = std::time::Instant::now();
        let mut percent = 0;
        let mut report = |p: &Progress| {
            let now = (p.overall() * 100.0).round() as u32;
            if now != percent {
                percent = now;
                shared.update(|s| s.levels_progress = f64::from(now) / 100.0);
            }
        };
        let result = catch_unwind(AssertUnwindSafe(|| {
            pyramid(&surface, &finished.positions, palette.as_ref(), &interrupt, &mut report)
        }))
        .unwrap_or_else(|panic| Err(Stop::Failed(format!("internal error: {}", panic_message(&*panic)))));
        shared.end_levels();
        shared.update(|s| {
            s.levels_busy = false;
            let result = match result {
                Ok(levels) => Ok(levels),
                Err(Stop::Failed(e)) => Err(e),
                Err(Stop::Interrupted) => {
                    s.levels_stopped += 1;
                    return;
                }
            };
            // A newer result replaced this one meanwhile: its levels are computed next.
            if s.frame != frame {
                return;
            }
            if let Err(e) = &result {
                s.error = Some(format!("{}: cannot simplify: {e}", s.name));
            }
            s.levels = Some(Arc::new(Levels { frame, result, ms: t.elapsed().as_secs_f64() * 1e3 }));
        });
    }
}

/// Why a pyramid was not computed.
enum Stop {
    /// Its interrupt was raised: a newer result replaced the one it simplified.
    Interrupted,
    /// The simplification failed, with this message.
    Failed(String),
}

/// The pyramid of the result at `positions` on `surface`, as the command line computes
/// it from the mesh it writes, stopped once `interrupt` is raised; `report` follows it.
fn pyramid(
    surface: &DigitalSurface,
    positions: &[glam::DVec3],
    palette: Option<&Palette>,
    interrupt: &Interrupt,
    report: &mut dyn FnMut(&Progress),
) -> Result<Vec<Simplified>, Stop> {
    let mesh = result_mesh(surface, positions, palette);
    let targets = pyramid_targets(LEVELS, FACTOR, MAX_ERROR_VOXELS * surface.spacing().min_element());
    simplify_levels_reporting(&mesh, &targets, &Options::default(), interrupt, report).map_err(|e| match e {
        SimplifyError::Interrupted => Stop::Interrupted,
        e => Stop::Failed(e.to_string()),
    })
}

/// A level as the page draws it (`/api/level?k=K`): the face and vertex counts (`u32`),
/// then the faces (4 `u32` vertex ids each; a triangle repeats its last vertex), the face
/// groups of `model` (`u32`), the faces' `[inner, outer]` labels (2 `u32`), the positions
/// (3 `f32` per vertex) and the face colours (3 `u8` per face, as `model`'s), little-endian.
pub(crate) fn level_bytes(mesh: &QuadMesh, model: &Model, palette: Option<&Palette>) -> Vec<u8> {
    let faces = mesh.quads.len();
    let groups = model.face_groups_of(mesh);
    let mut out = Vec::with_capacity(8 + 28 * faces + 12 * mesh.positions.len() + 3 * faces);
    out.extend_from_slice(&(faces as u32).to_le_bytes());
    out.extend_from_slice(&(mesh.positions.len() as u32).to_le_bytes());
    out.extend(mesh.quads.iter().flatten().flat_map(|v| v.to_le_bytes()));
    out.extend(groups.iter().flat_map(|g| g.to_le_bytes()));
    out.extend(mesh.face_labels.iter().flatten().flat_map(|l| l.to_le_bytes()));
    out.extend(f32_bytes(mesh.positions.iter().flat_map(|p| p.to_array())));
    out.extend(mesh.face_labels.iter().flat_map(|l| crate::model::face_color(palette, l[0])));
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    use std::time::{Duration, Instant};

    use voxreg_digisurf::{LabelVolume, RegionMap};

    use crate::session::Finished;

    /// Waits until `done` holds, at most `limit`; how long it took.
    fn wait(shared: &Shared, what: &str, limit: Duration, done: impl Fn(&State) -> bool) -> Duration {
        let t = Instant::now();
        let mut s = shared.lock();
        while !done(&s) {
            assert!(t.elapsed() < limit, "{what}: not within {limit:?}");
            s = shared
                .changed
                .wait_timeout(s, Duration::from_millis(10))
                .unwrap_or_else(|e| e.into_inner())
                .0;
        }
        t.elapsed()
    }

    /// Three labels in wavy layers: a staircase whose pyramid takes seconds (11 s on the
    /// shared 2-core machine, against the 1.5 s the test allows a stopped one).
    fn layers() -> (Arc<DigitalSurface>, Vec<glam::DVec3>) {
        let volume = LabelVolume::from_fn([72, 72, 40], |[x, y, z]| {
            let (x, y, z) = (x as f64, y as f64, z as f64);
            let a = 13.0 + 5.0 * (x / 5.0).sin() * (y / 7.0).cos();
            let b = 27.0 + 5.0 * (x / 6.0 + y / 9.0).sin();
            1 + u32::from(z > a) + u32::from(z > b)
        });
        let surface = DigitalSurface::new(&volume, &RegionMap::per_label()).expect("a surface");
        let positions = surface.positions().into_vec();
        (Arc::new(surface), positions)
    }

    /// A finished result of `surface` at `positions`, as a run publishes it, with the
    /// first coarser level chosen.
    fn shown(surface: Arc<DigitalSurface>, positions: Vec<glam::DVec3>) -> Arc<Shared> {
        let shared = Arc::new(Shared::default());
        let finished = Finished {
            positions,
            normals: Vec::new(),
            features: None,
            report: serde_json::Value::Null,
            summary: String::new(),
        };
        shared.update(|s| {
            s.surface = Some(surface);
            s.finished = Some(Arc::new(finished));
            s.frame = 1;
            s.frame_final = true;
            s.level = 1;
        });
        shared
    }

    #[test]
    fn a_new_run_and_the_end_stop_a_simplification_at_once() {
        let (surface, positions) = layers();
        let shared = shown(surface, positions);
        let thread = {
            let shared = Arc::clone(&shared);
            std::thread::spawn(move || worker(shared))
        };
        let limit = Duration::from_secs(120);
        // The uninterrupted pyramid takes seconds (more under load); a stopped one
        // returns within a collapse or a pass over the triangles.
        let bound = Duration::from_millis(1500);
        let stopped = |n: u64| move |s: &State| s.levels_stopped == n && !s.levels_busy;
        wait(&shared, "the levels' start", limit, |s| s.levels_busy);
        // The page sees the simplification advance.
        wait(&shared, "the levels' progress", limit, |s| s.levels_progress > 0.0);
        std::thread::sleep(Duration::from_millis(300));
        // A new run starts and publishes its first iterate.
        shared.update(|s| {
            s.busy = true;
            s.frame += 1;
            s.frame_final = false;
        });
        wait(&shared, "the levels' thread free after a new run", bound, stopped(1));
        assert!(shared.lock().levels.is_none());
        // The new run ends: its levels are computed; a newer job stops them at once (they
        // start again, as that job has not published a frame yet).
        shared.update(|s| {
            s.frame_final = true;
            s.busy = false;
        });
        wait(&shared, "the levels' start", limit, |s| s.levels_busy);
        std::thread::sleep(Duration::from_millis(300));
        shared.next_job();
        wait(&shared, "the levels stopped by a new job", bound, |s| s.levels_stopped == 2);
        // The viewer's end stops them too.
        wait(&shared, "the levels' start", limit, |s| s.levels_busy);
        std::thread::sleep(Duration::from_millis(300));
        shared.update(|s| s.shutdown = true);
        wait(&shared, "the levels' thread free at the end", bound, stopped(3));
        thread.join().expect("the levels' thread ends");
        let s = shared.lock();
        assert!(s.levels.is_none() && s.error.is_none(), "{:?}", s.error);
    }

    /// A simplification that nothing replaces ends with its levels, as before.
    #[test]
    fn an_uninterrupted_simplification_publishes_its_levels() {
        let volume = LabelVolume::from_fn([12, 12, 12], |[x, y, z]| {
            let d = |c: usize| c as f64 - 5.5;
            u32::from(d(x).powi(2) + d(y).powi(2) + d(z).powi(2) <= 20.0) + u32::from(x > 5)
        });
        let surface = DigitalSurface::new(&volume, &RegionMap::per_label()).expect("a surface");
        let positions = surface.positions().into_vec();
        let shared = shown(Arc::new(surface), positions);
        let thread = {
            let shared = Arc::clone(&shared);
            std::thread::spawn(move || worker(shared))
        };
        wait(&shared, "the levels", Duration::from_secs(60), |s| s.levels.is_some());
        shared.update(|s| s.shutdown = true);
        thread.join().expect("the levels' thread ends");
        let s = shared.lock();
        assert_eq!(s.levels_stopped, 0);
        assert_eq!(s.levels_progress, 1.0);
        assert_eq!(Levels::of(&s).map(<[Simplified]>::len), Some(LEVELS));
    }
}
