//! Levels of detail of the result shown: the regularized mesh simplified with its partition
//! kept ([`voxreg_simplify`]), the pyramid `voxreg regularize --lod` writes (each level a
//! quarter of the faces of the one before, within half a voxel doubled per level), so
//! that the page can show a coarser level without solving again.
//!
//! The levels are computed on their own thread, once per result and only once the page
//! has chosen a level other than the full surface; they belong to the frame of the result
//! they simplify, so that a new run (which publishes new frames) drops them, and a
//! computation that a new run overtook is discarded when it ends.

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::Arc;

use voxreg_digisurf::DigitalSurface;
use voxreg_io::{Palette, QuadMesh};
use voxreg_simplify::{pyramid_targets, simplify_levels, Options, Simplified};

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
        let (frame, surface, finished, palette) = {
            let s = shared.lock();
            let s = shared
                .changed
                .wait_while(s, |s| !s.shutdown && !wanted(s))
                .unwrap_or_else(|e| e.into_inner());
            if s.shutdown {
                return;
            }
            let (Some(surface), Some(finished)) = (s.surface.clone(), s.finished.clone()) else { continue };
            (s.frame, surface, finished, s.palette.clone())
        };
        shared.update(|s| s.levels_busy = true);
        let t = std::time::Instant::now();
        let result =
            catch_unwind(AssertUnwindSafe(|| pyramid(&surface, &finished.positions, palette.as_ref())))
                .unwrap_or_else(|panic| Err(format!("internal error: {}", panic_message(&*panic))));
        shared.update(|s| {
            s.levels_busy = false;
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

/// The pyramid of the result at `positions` on `surface`, as the command line computes
/// it from the mesh it writes.
fn pyramid(
    surface: &DigitalSurface,
    positions: &[glam::DVec3],
    palette: Option<&Palette>,
) -> Result<Vec<Simplified>, String> {
    let mesh = result_mesh(surface, positions, palette);
    let targets = pyramid_targets(LEVELS, FACTOR, MAX_ERROR_VOXELS * surface.spacing().min_element());
    simplify_levels(&mesh, &targets, &Options::default()).map_err(|e| e.to_string())
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
