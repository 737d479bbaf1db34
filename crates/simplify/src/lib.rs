//! Simplification of a multi-label surface mesh that keeps its partition.
//!
//! The input is a [`QuadMesh`] as voxreg writes it (one quad per voxel face, or any mesh of
//! quads and triangles): each face carries its `[inner, outer]` labels, optionally a
//! material and a face group. Faces with the same labels, material and group form one
//! *patch* (an interface, or a colour area of a voxel model). The simplifier works on the
//! whole non-manifold complex at once, so that:
//!
//! - every patch is simplified once, and shared by the two regions it separates (the
//!   output has one face where the input had one wall between two labels, never two);
//! - the *feature lines* (edges where three or more faces meet, where patches of
//!   different keys meet, and open borders) are simplified once, as polylines shared by
//!   every patch that meets them;
//! - their *corners* (line end points, vertices where lines meet, pinches) never move;
//! - the combinatorial type is kept: each collapse passes the link condition of the whole
//!   complex and keeps every edge's list of incident patches, so each region stays closed
//!   and keeps its Euler characteristic;
//! - every vertex of the input lies within the distance budget of the output, tracked by
//!   construction (each face carries the removed input vertices it answers for);
//! - no collapse creates an intersection between faces that share no vertex;
//! - each region's enclosed volume stays within 0.5% and each patch's area within 1% of
//!   the input's (collapses that would go further are refused).
//!
//! The method is an edge collapse on the triangles (each quad split along the diagonal
//! from its first vertex), ordered by quadric error, with a volume-preserving placement
//! where both ends are inside one patch (corners and line vertices stay where they are),
//! then edge flips inside patches where they let more triangles pair (each checked as a
//! collapse is), and a re-pairing of the triangles into quads within each patch (greedy
//! by quad quality, then augmenting paths). The collapses run on one thread in a fixed order;
//! the setup, the queue's costs and the pairing's scores are computed in parallel into
//! ordered results: the output does not depend on the thread count. See
//! `docs/design/simplification.md`.

mod engine;
mod grid;
mod pair;
mod quadric;
mod types;

use voxreg_io::QuadMesh;

pub use types::{Options, Progress, Simplified, SimplifyError, Stage, Stats, Target};
pub use voxreg_normals::Interrupt;

/// Simplifies `mesh` down to `target`, keeping its partition (see the crate's
/// documentation).
///
/// # Errors
///
/// [`SimplifyError::InvalidMesh`] for an index out of range, a non-finite position, label
/// or material arrays of the wrong length, or a face with fewer than three distinct
/// vertices; [`SimplifyError::InvalidTarget`] for a ratio outside `(0, 1]` or a negative
/// or NaN distance.
pub fn simplify(mesh: &QuadMesh, target: Target, options: &Options) -> Result<Simplified, SimplifyError> {
    simplify_interruptible(mesh, target, options, &Interrupt::never())
}

/// [`simplify`], returning [`SimplifyError::Interrupted`] soon after `interrupt` is
/// raised (see [`simplify_levels_interruptible`]).
///
/// # Errors
///
/// As [`simplify`], and [`SimplifyError::Interrupted`].
pub fn simplify_interruptible(
    mesh: &QuadMesh,
    target: Target,
    options: &Options,
    interrupt: &Interrupt,
) -> Result<Simplified, SimplifyError> {
    Ok(simplify_levels_interruptible(mesh, &[target], options, interrupt)?.pop().expect("one level"))
}

/// Levels of detail: one simplification run, with a snapshot of the mesh at each target
/// in turn. Targets must be nested: ratios non-increasing, distances non-decreasing. Each
/// level is a simplification of the previous one, and the distance bound of each level
/// holds for every vertex of the full input (not only of the previous level).
///
/// # Errors
///
/// As [`simplify`], and [`SimplifyError::InvalidTarget`] for targets that are not nested
/// or an empty list.
pub fn simplify_levels(
    mesh: &QuadMesh,
    targets: &[Target],
    options: &Options,
) -> Result<Vec<Simplified>, SimplifyError> {
    simplify_levels_interruptible(mesh, targets, options, &Interrupt::never())
}

/// [`simplify_levels`], stopped early when `interrupt` is raised from another thread:
/// the run polls it in each of its long loops (the setup's per-vertex and per-triangle
/// passes, each collapse taken from the queue, each level's queue rebuild, the flips,
/// the pairing into quads) and then returns [`SimplifyError::Interrupted`], with no
/// level, within about a collapse or a pass over the triangles' edges (milliseconds).
/// A flag never raised changes nothing: the levels are those of [`simplify_levels`].
///
/// Why a parameter and not a field of [`Options`]: the options describe the result and
/// stay `Copy` and comparable; the flag is the same [`Interrupt`] the regularizer polls
/// (re-exported from `voxreg_normals`), so one flag can stop a regularization and the
/// simplification that follows it.
///
/// # Errors
///
/// As [`simplify_levels`], and [`SimplifyError::Interrupted`] once `interrupt` is raised
/// (also when it was raised before the call).
pub fn simplify_levels_interruptible(
    mesh: &QuadMesh,
    targets: &[Target],
    options: &Options,
    interrupt: &Interrupt,
) -> Result<Vec<Simplified>, SimplifyError> {
    simplify_levels_reporting(mesh, targets, options, interrupt, &mut |_| {})
}

/// [`simplify_levels_interruptible`], calling `progress` as it goes: at the start and end
/// of each stage of each level, and during the collapses about every thousand of them.
/// The calls are made on the calling thread; what they do cannot change the levels.
///
/// # Errors
///
/// As [`simplify_levels_interruptible`].
pub fn simplify_levels_reporting(
    mesh: &QuadMesh,
    targets: &[Target],
    options: &Options,
    interrupt: &Interrupt,
    progress: &mut dyn FnMut(&Progress),
) -> Result<Vec<Simplified>, SimplifyError> {
    check_targets(targets)?;
    types::check(interrupt)?;
    let levels = targets.len();
    let mut report = |level: usize, stage: Stage, fraction: f64| {
        progress(&Progress { level, levels, stage, fraction });
    };
    report(0, Stage::Setup, 0.0);
    let mut engine = engine::Engine::new(mesh, options, interrupt)?;
    report(0, Stage::Setup, 1.0);
    let mut out = Vec::with_capacity(levels);
    // Each level is paired into quads on another thread while this one makes the next.
    let mut pending: Option<engine::Capture<'_>> = None;
    // Outside the pool, a level is made on one of its threads and its progress reaches
    // this one through a channel: the collapses' many small parallel batches are then
    // forked from a worker, not each handed over to the pool and waited for. Inside it
    // (a caller on a worker thread), that worker makes it.
    let on_worker = rayon::current_thread_index().is_some();
    for (level, t) in targets.iter().enumerate() {
        let mut done = None;
        let mut next = None;
        rayon::in_place_scope(|s| {
            if let Some(capture) = pending.take() {
                let done = &mut done;
                s.spawn(move |_| *done = Some(capture.finish()));
            }
            let (engine, next) = (&mut engine, &mut next);
            let mut make = move |send: &mut dyn FnMut(Stage, f64)| -> Result<_, SimplifyError> {
                send(Stage::Collapses, 0.0);
                engine.run(t, &mut |f| send(Stage::Collapses, f))?;
                send(Stage::Collapses, 1.0);
                if options.quads {
                    send(Stage::Flips, 0.0);
                    engine.flip_for_quads()?;
                    send(Stage::Flips, 1.0);
                }
                send(Stage::Pairing, 0.0);
                Ok(engine.capture())
            };
            if on_worker {
                *next = Some(make(&mut |stage, f| report(level, stage, f)));
            } else {
                let (tx, rx) = std::sync::mpsc::channel();
                s.spawn(move |_| {
                    let mut make = make;
                    *next = Some(make(&mut |stage, f| {
                        let _ = tx.send((stage, f));
                    }));
                });
                for (stage, f) in rx {
                    report(level, stage, f);
                }
            }
        });
        if let Some(level) = done {
            out.push(level?);
        }
        pending = Some(next.expect("made in the scope")?);
    }
    out.push(pending.take().expect("one level").finish()?);
    report(levels - 1, Stage::Pairing, 1.0);
    types::check(interrupt)?;
    Ok(out)
}

/// A pyramid of `levels` targets: level `k` keeps `factor^-k` of the faces within
/// `max_error * 2^(k-1)` (level 0 is the input itself, with a bound of 0), so that both the
/// ratios and the bounds nest.
pub fn pyramid_targets(levels: usize, factor: f64, max_error: f64) -> Vec<Target> {
    (0..levels)
        .map(|k| {
            if k == 0 {
                Target { ratio: Some(1.0), max_error: 0.0 }
            } else {
                Target {
                    ratio: Some(factor.powi(-(k as i32))),
                    max_error: max_error * 2f64.powi(k as i32 - 1),
                }
            }
        })
        .collect()
}

fn check_targets(targets: &[Target]) -> Result<(), SimplifyError> {
    let bad = |s: String| Err(SimplifyError::InvalidTarget(s));
    if targets.is_empty() {
        return bad("no target".into());
    }
    for t in targets {
        if let Some(r) = t.ratio {
            if r.is_nan() || r <= 0.0 || r > 1.0 {
                return bad(format!("ratio {r} is not in (0, 1]"));
            }
        }
        if t.max_error.is_nan() || t.max_error < 0.0 {
            return bad(format!("distance {} is not a non-negative number", t.max_error));
        }
    }
    for w in targets.windows(2) {
        let (a, b) = (w[0].ratio.unwrap_or(0.0), w[1].ratio.unwrap_or(0.0));
        if b > a && w[0].ratio.is_some() || w[0].ratio.is_none() && w[1].ratio.is_some() {
            return bad("ratios of successive levels must not increase".into());
        }
        if w[1].max_error < w[0].max_error {
            return bad("distances of successive levels must not decrease".into());
        }
    }
    Ok(())
}
