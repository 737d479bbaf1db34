//! Interrupting a simplification: a raised flag returns `Interrupted` (raised before the
//! call, or from another thread during any stage), soon after the raise; a flag never
//! raised changes nothing.

use std::sync::mpsc;
use std::time::{Duration, Instant};

use glam::DVec3;
use voxreg_digisurf::{DigitalSurface, LabelVolume};
use voxreg_io::QuadMesh;
use voxreg_simplify::{
    pyramid_targets, simplify_interruptible, simplify_levels, simplify_levels_interruptible, Interrupt,
    Options, SimplifyError, Target,
};

/// Six labels in Voronoi cells inside an ellipsoid, as a staircase of quads.
fn cells(dims: [usize; 3]) -> QuadMesh {
    let d = DVec3::new(dims[0] as f64, dims[1] as f64, dims[2] as f64);
    let centre = d * 0.5;
    let radii = d * 0.42;
    let seeds: Vec<DVec3> = (0..6)
        .map(|i| {
            let a = f64::from(i) * 1.1;
            centre + DVec3::new(a.cos(), a.sin(), (2.0 * a).cos()) * radii * 0.5
        })
        .collect();
    let volume = LabelVolume::from_fn(dims, |[x, y, z]| {
        let p = DVec3::new(x as f64, y as f64, z as f64) + 0.5;
        if ((p - centre) / radii).length_squared() > 1.0 {
            return 0;
        }
        let near = (0..seeds.len())
            .min_by(|&i, &j| p.distance_squared(seeds[i]).total_cmp(&p.distance_squared(seeds[j])));
        near.map_or(0, |i| i as u32 + 1)
    });
    let surface = DigitalSurface::from_volume(&volume).unwrap();
    QuadMesh::from_surface(&surface, &surface.positions())
}

#[test]
fn a_flag_raised_before_the_call_returns_interrupted() {
    let input = cells([10, 10, 10]);
    let raised = Interrupt::new();
    raised.raise();
    let o = Options::default();
    let target = Target { ratio: Some(0.25), max_error: 0.5 };
    assert_eq!(simplify_interruptible(&input, target, &o, &raised).unwrap_err(), SimplifyError::Interrupted);
    let targets = pyramid_targets(3, 4.0, 0.5);
    assert_eq!(
        simplify_levels_interruptible(&input, &targets, &o, &raised).unwrap_err(),
        SimplifyError::Interrupted
    );
    // Bad targets are still refused first, as without a flag.
    assert!(matches!(
        simplify_levels_interruptible(&input, &[], &o, &raised),
        Err(SimplifyError::InvalidTarget(_))
    ));
    // A flag never raised, or not yet raised, gives the levels of `simplify_levels`.
    let plain = simplify_levels(&input, &targets, &o).unwrap();
    for flag in [Interrupt::never(), Interrupt::new()] {
        let levels = simplify_levels_interruptible(&input, &targets, &o, &flag).unwrap();
        for (a, b) in plain.iter().zip(&levels) {
            assert_eq!(a.mesh, b.mesh);
            assert_eq!(a.stats, b.stats);
        }
    }
}

/// A run raised from another thread after `delay`: its result, and how long after the
/// raise it returned (`None` if it returned before the raise).
fn raised_after(input: &QuadMesh, delay: Duration) -> (Result<usize, SimplifyError>, Option<Duration>) {
    let interrupt = Interrupt::new();
    let (tx, rx) = mpsc::channel::<()>();
    let raiser = {
        let interrupt = interrupt.clone();
        std::thread::spawn(move || {
            // The run's end (a message or a closed channel) before the delay: no raise.
            match rx.recv_timeout(delay) {
                Err(mpsc::RecvTimeoutError::Timeout) => {
                    let at = Instant::now();
                    interrupt.raise();
                    Some(at)
                }
                _ => None,
            }
        })
    };
    let result =
        simplify_levels_interruptible(input, &pyramid_targets(4, 4.0, 0.5), &Options::default(), &interrupt)
            .map(|levels| levels.len());
    let end = Instant::now();
    drop(tx);
    let raised_at = raiser.join().unwrap();
    (result, raised_at.map(|at| end.saturating_duration_since(at)))
}

#[test]
fn a_flag_raised_from_another_thread_stops_every_stage_soon() {
    let input = cells([56, 52, 44]);
    let t = Instant::now();
    let full = simplify_levels(&input, &pyramid_targets(4, 4.0, 0.5), &Options::default()).unwrap();
    let whole = t.elapsed();
    assert_eq!(full.len(), 4);
    // Raises through the run: in the setup, the collapses, the flips and the pairing of
    // the levels (an uninterrupted run takes `whole`).
    let mut stopped = 0;
    for fraction in [0.0, 0.02, 0.1, 0.25, 0.4, 0.55, 0.7] {
        let delay = whole.mul_f64(fraction);
        let (result, after) = raised_after(&input, delay);
        match after {
            Some(after) => {
                assert_eq!(result, Err(SimplifyError::Interrupted), "raised at {fraction} of {whole:?}");
                // Milliseconds on an idle machine; a generous bound for a loaded one.
                assert!(after < Duration::from_millis(750), "returned {after:?} after the raise");
                eprintln!("raised at {fraction} of {whole:?}: returned {after:?} after the raise");
                stopped += 1;
            }
            None => assert_eq!(result, Ok(4)),
        }
    }
    assert!(stopped >= 4, "only {stopped} raises came before the run's end ({whole:?})");
}
