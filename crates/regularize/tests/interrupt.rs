//! Interrupting the front door (`Regularizer::set_interrupt`): an interrupt raised in any
//! stage stops the run before its next progress event, and what the regularizer keeps
//! (normals, solver, multigrid cycle) leaves its next runs as they would have been.

use glam::DVec3;
use voxreg_digisurf::{LabelVolume, RegionMap};
use voxreg_regularize::{
    Estimator, Interrupt, Output, Params, RegularizeError, Regularizer, Run, SolverChoice, Stage,
};
use voxreg_testkit::{digitize, Torus};

mod common;
use common::max_distance;

fn torus() -> LabelVolume {
    digitize(&Torus { major: 11.0, minor: 4.3 }, 1.0)
}

/// A run that raises its interrupt at its `k`-th progress event: the run's result and
/// how many events came after the raise.
fn raised_at(
    r: &mut Regularizer,
    params: &Params,
    warm: &[Vec<DVec3>],
    k: usize,
) -> (Result<Output, RegularizeError>, usize) {
    let interrupt = Interrupt::new();
    r.set_interrupt(interrupt.clone());
    let (mut seen, mut after) = (0, 0);
    let result = r.run(Run::new(params).warm(warm).progress(&mut |_| {
        if seen == k {
            interrupt.raise();
        } else if seen > k {
            after += 1;
        }
        seen += 1;
    }));
    r.set_interrupt(Interrupt::never());
    (result, after)
}

/// Each stage's first two events and every fourth event besides: where the interrupt is
/// raised.
fn raise_points(r: &mut Regularizer, params: &Params, warm: &[Vec<DVec3>]) -> Vec<usize> {
    let mut labels = Vec::new();
    r.run(Run::new(params).warm(warm).progress(&mut |e| {
        labels.push(format!("{:?} {}", e.stage, e.iteration.is_some()));
    }))
    .unwrap();
    (0..labels.len())
        .filter(|&k| {
            k % 4 == 0 || (k > 0 && labels[k - 1] != labels[k]) || (k > 1 && labels[k - 2] != labels[k - 1])
        })
        .collect()
}

/// Every stage of `params`' pipeline stops at once when interrupted, on a fresh
/// regularizer and on one that already ran; a run after each interruption gives the
/// fresh regularizer's result bit for bit.
fn check_every_stage(volume: &LabelVolume, params: &Params) {
    let fresh = Regularizer::from_volume(volume, &params.regions).unwrap().run(params).unwrap();
    let mut used = Regularizer::from_volume(volume, &params.regions).unwrap();
    let points = raise_points(&mut used, params, &[]);
    // At least the estimate, the solver's setup (with the bounded solver's start and
    // active-set rounds, which report no events) and an iteration.
    assert!(points.len() >= 3, "{points:?}");
    for k in points {
        for r in [&mut Regularizer::from_volume(volume, &params.regions).unwrap(), &mut used] {
            let (result, after) = raised_at(r, params, &[], k);
            assert_eq!(result.err(), Some(RegularizeError::Interrupted), "raised at event {k}");
            assert_eq!(after, 0, "{after} events after the raise at event {k}");
            let again = r.run(params).unwrap();
            assert_eq!(again.positions, fresh.positions, "the run after an interruption at event {k}");
        }
    }
}

#[test]
fn the_default_pipeline_stops_in_every_stage() {
    // The iterative solver, whose setup (multigrid) and iterations poll the interrupt;
    // refinement rounds with re-centring.
    let mut params = Params::default();
    params.solver.choice = SolverChoice::Cg;
    check_every_stage(&torus(), &params);
}

#[test]
fn the_clamped_pipeline_and_the_at_normals_stop_in_every_stage() {
    // The bounded solver's phases (its unconstrained start and active-set rounds report
    // no events: they stop at their next iteration), and the Ambrosio-Tortorelli normals.
    let mut params = Params::voxel_art();
    params.normals.estimator = Estimator::At;
    params.regions = RegionMap::per_label();
    check_every_stage(&digitize(&Torus { major: 7.0, minor: 3.2 }, 1.0), &params);
}

#[test]
fn a_warm_run_after_an_interrupted_one_reaches_the_same_minimizers() {
    // The viewer's pattern: a warm re-solve interrupted in its first iterations (the quick
    // start's cycle kept), then the next warm re-solve.
    let volume = torus();
    let mut params = Params::default();
    params.solver.choice = SolverChoice::Cg;
    let mut r = Regularizer::from_volume(&volume, &params.regions).unwrap();
    let mut warm: Vec<Vec<DVec3>> = Vec::new();
    r.run(Run::new(&params).warm(&[]).progress(&mut |e| {
        if let (Stage::Solve { round }, Some(x)) = (e.stage, e.iterate()) {
            warm.resize(warm.len().max(round + 1), Vec::new());
            warm[round] = x;
        }
    }))
    .unwrap();
    params.energy.gamma *= 1.2;
    let mut reference = Regularizer::from_volume(&volume, &params.regions).unwrap();
    reference.run(&params).unwrap();
    let expected = reference.run(Run::new(&params).warm(&warm)).unwrap();
    for k in [1, 2, 3] {
        let (result, _) = raised_at(&mut r, &params, &warm, k);
        assert_eq!(result.err(), Some(RegularizeError::Interrupted));
        let out = r.run(Run::new(&params).warm(&warm)).unwrap();
        assert!(out.report.converged());
        // Each solve within the tolerance of its minimizer: the results agree to a few
        // times it.
        let tol = params.solver.cg.tolerance;
        let d = max_distance(&out.positions, &expected.positions);
        assert!(d <= 4.0 * tol, "interrupted at event {k}: {d} voxel from the uninterrupted run");
    }
}
