//! Warm starts of the front door (`Run::warm`): a re-run from the previous
//! positions reaches the same minimizer as a cold run, in fewer iterations.

use glam::DVec3;
use voxreg_digisurf::RegionMap;
use voxreg_regularize::{
    Output, Params, RegularizeError, Regularizer, Run, SolveInfo, SolverChoice, SolverParams, Stage,
};
use voxreg_testkit::{digitize, Sphere, Torus};

mod common;
use common::max_distance;

fn iterations(out: &Output) -> usize {
    out.report.solves.iter().map(|s| s.iterations()).sum()
}

fn with_solver(mut p: Params, choice: SolverChoice) -> Params {
    p.solver = SolverParams { choice, ..p.solver };
    p
}

/// A run, and each solve round's last iterate (what a viewer keeps for the next run).
fn run_keeping_iterates(
    r: &mut Regularizer,
    params: &Params,
    warm: &[Vec<DVec3>],
) -> (Output, Vec<Vec<DVec3>>) {
    let mut rounds: Vec<Vec<DVec3>> = Vec::new();
    let out = r
        .run(Run::new(params).warm(warm).progress(&mut |e| {
            if let (Stage::Solve { round }, Some(x)) = (e.stage, e.iterate()) {
                rounds.resize(round + 1, Vec::new());
                rounds[round] = x;
            }
        }))
        .unwrap();
    (out, rounds)
}

fn torus() -> Regularizer {
    let volume = digitize(&Torus { major: 11.0, minor: 4.3 }, 1.0);
    Regularizer::from_volume(&volume, &RegionMap::per_label()).unwrap()
}

#[test]
fn a_warm_single_solve_reaches_the_cold_minimizer_in_fewer_iterations() {
    let mut r = torus();
    let before = with_solver(Params::papers(), SolverChoice::Cg);
    let previous = r.run(&before).unwrap();
    // Small changes of each weight: the minimizer moves a little.
    for change in [|p: &mut Params| p.energy.gamma *= 1.3, |p: &mut Params| p.energy.alpha *= 1.5] {
        let mut after = before.clone();
        change(&mut after);
        let cold = r.run(&after).unwrap();
        let warm = r.run(Run::new(&after).warm(&[previous.positions.to_vec()])).unwrap();
        let exact = r.run(&with_solver(after.clone(), SolverChoice::Direct)).unwrap();
        let tol = after.solver.cg.tolerance;
        // Both within the tolerance of the exact minimizer, so within twice it of each other.
        assert!(max_distance(&warm.positions, &exact.positions) <= tol, "warm vs exact");
        assert!(max_distance(&cold.positions, &exact.positions) <= tol, "cold vs exact");
        assert!(max_distance(&warm.positions, &cold.positions) <= 2.0 * tol);
        let moved = max_distance(&previous.positions, &exact.positions);
        assert!(moved > 10.0 * tol, "the change moves the minimizer ({moved} voxel)");
        let (w, c) = (iterations(&warm), iterations(&cold));
        assert!(w < c, "warm {w} iterations, cold {c}");
        assert!(warm.report.solves[0].converged());
    }
}

#[test]
fn a_warm_refined_run_matches_the_cold_one_in_fewer_iterations() {
    // The default pipeline (refinement rounds, re-centring): each round starts from the
    // previous run's solution of that round, and every solve stops within the tolerance
    // of its own minimizer, so the results agree to a few times it.
    let mut r =
        Regularizer::from_volume(&digitize(&Sphere { radius: 9.6 }, 1.0), &RegionMap::per_label()).unwrap();
    let before = with_solver(Params::default(), SolverChoice::Cg);
    let (_, rounds) = run_keeping_iterates(&mut r, &before, &[]);
    assert_eq!(rounds.len(), before.refinement().rounds + 1);
    let mut after = before.clone();
    after.energy.gamma *= 1.2;
    let cold = r.run(&after).unwrap();
    let (warm, _) = run_keeping_iterates(&mut r, &after, &rounds);
    let tol = after.solver.cg.tolerance;
    let d = max_distance(&warm.positions, &cold.positions);
    assert!(d <= 10.0 * tol, "warm and cold differ by {d} voxel");
    let (w, c) = (iterations(&warm), iterations(&cold));
    assert!(w < c, "warm {w} iterations, cold {c}");
    for (k, (w, c)) in warm.report.solves.iter().zip(&cold.report.solves).enumerate() {
        assert!(w.converged() && w.iterations() <= c.iterations(), "round {k}: {w:?} vs {c:?}");
    }
}

#[test]
fn a_warm_run_far_from_the_last_one_reaches_the_cold_result() {
    // Each warm round's first iteration is preconditioned by the last solve's multigrid
    // cycle (a quick start); changes far larger than a slider step make it a poor match,
    // and the results must still be the cold run's, every round with its own minimizer.
    let mut r =
        Regularizer::from_volume(&digitize(&Sphere { radius: 9.6 }, 1.0), &RegionMap::per_label()).unwrap();
    let before = with_solver(Params::default(), SolverChoice::Cg);
    let (_, rounds) = run_keeping_iterates(&mut r, &before, &[]);
    let changes: [fn(&mut Params); 3] = [
        |p| p.energy.gamma *= 10.0,
        |p| p.energy.alpha /= 4.0,
        |p| {
            p.energy.beta *= 3.0;
            p.energy.gamma /= 5.0;
        },
    ];
    for (k, change) in changes.into_iter().enumerate() {
        let mut after = before.clone();
        change(&mut after);
        // The kept cycle is the first parameters' (their run comes just before).
        run_keeping_iterates(&mut r, &before, &rounds);
        let (warm, _) = run_keeping_iterates(&mut r, &after, &rounds);
        let cold = r.run(&after).unwrap();
        let tol = after.solver.cg.tolerance;
        let d = max_distance(&warm.positions, &cold.positions);
        assert!(d <= 10.0 * tol, "change {k}: warm and cold differ by {d} voxel");
        let (ew, ec) = (warm.report.energy.after.total, cold.report.energy.after.total);
        assert!((ew - ec).abs() <= 1e-4 * ec.abs(), "change {k}: energies {ew} warm, {ec} cold");
        for (round, (w, c)) in warm.report.solves.iter().zip(&cold.report.solves).enumerate() {
            let (SolveInfo::Cg(w), SolveInfo::Cg(c)) = (w, c) else { panic!("the conjugate gradient") };
            assert!(w.converged && c.converged, "change {k}, round {round}");
            assert_eq!(
                (w.quick_start_iterations, c.quick_start_iterations),
                (1, 0),
                "change {k}, round {round}"
            );
        }
    }
}

#[test]
fn the_direct_solver_ignores_the_start_and_a_wrong_length_is_an_error() {
    let mut r = torus();
    let p = with_solver(Params::papers(), SolverChoice::Direct);
    let cold = r.run(&p).unwrap();
    let far: Vec<DVec3> = cold.positions.iter().map(|x| *x + DVec3::splat(3.0)).collect();
    let warm = r.run(Run::new(&p).warm(std::slice::from_ref(&far))).unwrap();
    assert_eq!(warm.positions.as_slice(), cold.positions.as_slice());
    let short = far[..far.len() - 1].to_vec();
    let err = r.run(Run::new(&p).warm(&[far, short])).unwrap_err();
    assert!(matches!(err, RegularizeError::SizeMismatch(_)), "{err}");
    assert!(err.to_string().contains("start positions"), "{err}");
}

fn products(out: &Output) -> usize {
    out.report
        .solves
        .iter()
        .map(|s| match s {
            SolveInfo::Bounded(b) => b.operator_applications,
            other => panic!("not the bounded solver: {}", other.name()),
        })
        .sum()
}

#[test]
fn a_warm_clamped_solve_reaches_the_cold_minimizer_with_fewer_operator_products() {
    // The voxel-art preset (clamped, bounded solver) on a torus, then small changes of a
    // weight and of the boxes: each re-solve starts from the previous run's solution
    // projected into its boxes.
    let mut r = torus();
    let before = Params::voxel_art();
    let (first, rounds) = run_keeping_iterates(&mut r, &before, &[]);
    assert!(first.report.solves[0].name() == "bounded" && first.report.solves[0].converged());
    let input = r.surface().positions().clone();
    let changes: [fn(Params) -> Params; 3] = [
        |mut p| {
            p.energy.gamma *= 1.3;
            p
        },
        |mut p| {
            p.energy.alpha *= 1.5;
            p
        },
        |p| p.with_smoothness(0.8).unwrap(),
    ];
    for (k, change) in changes.into_iter().enumerate() {
        let after = change(before.clone());
        let cold = r.run(&after).unwrap();
        let (warm, _) = run_keeping_iterates(&mut r, &after, &rounds);
        assert!(warm.report.solves[0].converged() && cold.report.solves[0].converged(), "change {k}");
        // Both stop by the tolerance's estimate rule on the same convex problem.
        let tol = after.solver.bounded.tolerance;
        let d = max_distance(&warm.positions, &cold.positions);
        assert!(d <= 10.0 * tol, "change {k}: warm and cold differ by {d} voxel");
        let (ew, ec) = (warm.report.energy.after.total, cold.report.energy.after.total);
        assert!((ew - ec).abs() <= 1e-4 * ec.abs(), "change {k}: energies {ew} warm, {ec} cold");
        let moved = max_distance(&first.positions, &cold.positions);
        assert!(moved > 10.0 * tol, "change {k}: the change moves the minimizer ({moved} voxel)");
        // Inside the new boxes (the warm start was projected into them).
        let half = 0.5 * (1.0 - after.mode.clamped().unwrap().margin) + 1e-9;
        for (x, p) in warm.positions.iter().zip(input.iter()) {
            assert!((*x - *p).abs().max_element() <= half, "change {k}: {x} outside the box of {p}");
        }
        let (w, c) = (products(&warm), products(&cold));
        assert!(w < c, "change {k}: warm {w} operator products, cold {c}");
    }
}

/// A regularizer that does not keep its initial normals gives the same output, run after
/// run (each run estimates them again).
#[test]
fn a_regularizer_without_kept_normals_gives_the_same_runs() {
    let params = Params::default();
    let kept = torus().run(&params).unwrap();
    let mut r = torus();
    r.set_keep_normals(false);
    for _ in 0..2 {
        let out = r.run(&params).unwrap();
        assert_eq!(out.positions.as_slice(), kept.positions.as_slice());
        assert_eq!(out.normals.as_slice(), kept.normals.as_slice());
    }
}
