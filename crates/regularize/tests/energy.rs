//! The energy, its gradient and operator, and the direct solve, checked against each other.

use glam::DVec3;
use proptest::prelude::*;
use voxreg_digisurf::{DigitalSurface, LabelVolume};
use voxreg_normals::{NormalEstimator, NormalField, Trivial};
use voxreg_regularize::{
    DirectSolver, Energy, EnergyParams, Operator, OperatorPattern, Params, Regularizer, Run, SolverChoice,
};
use voxreg_testkit::Lcg;

mod common;
use common::{pinched, random_normals, three_labels_open};

/// The voxels within `r` of the centre of a cube of side `2r + 3`.
fn ball(r: f64) -> LabelVolume {
    let n = (2.0 * r) as usize + 3;
    let c = (n as f64 - 1.0) / 2.0;
    LabelVolume::from_fn([n, n, n], |[x, y, z]| {
        let d = DVec3::new(x as f64 - c, y as f64 - c, z as f64 - c);
        u32::from(d.length() <= r)
    })
}

/// `g` (the gradient at `p`) agrees with central differences of the energy at every
/// `step`-th vertex.
fn assert_gradient_matches_differences(
    name: &str,
    energy: &Energy<'_>,
    p: &[DVec3],
    g: &[DVec3],
    step: usize,
) {
    let h = 1e-5;
    for v in (0..p.len()).step_by(step) {
        for k in 0..3 {
            let mut plus = p.to_vec();
            plus[v][k] += h;
            let mut minus = p.to_vec();
            minus[v][k] -= h;
            let fd = (energy.terms(&plus).total - energy.terms(&minus).total) / (2.0 * h);
            assert!(
                (fd - g[v][k]).abs() < 1e-6 * (1.0 + fd.abs()),
                "{name}: vertex {v} axis {k}: {fd} vs {}",
                g[v][k]
            );
        }
    }
}

fn cases() -> Vec<(&'static str, DigitalSurface)> {
    vec![
        ("ball", DigitalSurface::from_volume(&ball(3.2)).unwrap()),
        ("open multi-label", DigitalSurface::from_volume(&three_labels_open()).unwrap()),
        ("pinched", pinched()),
    ]
}

#[test]
fn gradient_matches_finite_differences() {
    let mut rng = Lcg::new(1);
    for (name, s) in cases() {
        let normals = random_normals(&s, &mut rng);
        let input = s.positions();
        let energy =
            Energy::new(&s, &normals, &input, EnergyParams { alpha: 0.3, beta: 1.1, gamma: 0.7 }).unwrap();
        let p: Vec<DVec3> = input.iter().map(|q| *q + 0.3 * rng.vec3(-0.5, 0.5)).collect();
        let g = energy.gradient(&p);
        assert_gradient_matches_differences(name, &energy, &p, &g, 3);
    }
}

#[test]
fn operator_matches_gradient_and_energy() {
    let mut rng = Lcg::new(2);
    for (name, s) in cases() {
        let normals = random_normals(&s, &mut rng);
        let input = s.positions();
        let params = EnergyParams { alpha: 0.01, beta: 1.0, gamma: 0.25 };
        let energy = Energy::new(&s, &normals, &input, params).unwrap();
        let op = Operator::assemble(&OperatorPattern::new(&s).unwrap(), &energy);
        let p: Vec<DVec3> = input.iter().map(|q| *q + rng.vec3(-0.5, 0.5)).collect();
        let flat: Vec<f64> = p.iter().flat_map(|v| v.to_array()).collect();
        let hp = op.apply(&flat);
        let g = energy.gradient(&p);
        for (i, gi) in g.iter().enumerate() {
            for k in 0..3 {
                let from_matrix = 2.0 * (hp[3 * i + k] - params.alpha * input[i][k]);
                assert!((from_matrix - gi[k]).abs() < 1e-9, "{name}: {from_matrix} vs {}", gi[k]);
            }
        }
        // E(p) = p^T H p - 2 alpha p^T q + alpha |q|^2.
        let quad: f64 = flat.iter().zip(&hp).map(|(a, b)| a * b).sum::<f64>()
            - 2.0 * params.alpha * p.iter().zip(&input).map(|(a, b)| a.dot(*b)).sum::<f64>()
            + params.alpha * input.iter().map(|q| q.length_squared()).sum::<f64>();
        let e = energy.terms(&p).total;
        assert!((quad - e).abs() < 1e-9 * e.abs().max(1.0), "{name}: {quad} vs {e}");
        // Symmetric.
        let m = op.matrix().to_dense();
        for i in 0..m.nrows() {
            for j in 0..i {
                assert!((m[(i, j)] - m[(j, i)]).abs() <= 1e-12 * (1.0 + m[(i, j)].abs()));
            }
        }
    }
}

/// The papers' single solve through the front door, exact.
fn exact_solve(s: &DigitalSurface, normals: &NormalField) -> voxreg_regularize::Output {
    let mut params = Params::papers();
    params.solver.choice = SolverChoice::Direct;
    Regularizer::new(s.clone()).run(Run::new(&params).from_normals(normals)).unwrap()
}

#[test]
fn direct_solution_is_optimal() {
    let mut rng = Lcg::new(3);
    for (name, s) in cases() {
        for normals in [Trivial.estimate(&s).unwrap(), random_normals(&s, &mut rng)] {
            let input = s.positions();
            let params = EnergyParams::default();
            let energy = Energy::new(&s, &normals, &input, params).unwrap();
            let mut solver = DirectSolver::for_surface(&s).unwrap();
            let (x, info) = solver.solve(&energy).unwrap();
            assert!(info.relative_gradient <= 1e-9, "{name}: {}", info.relative_gradient);
            let ex = energy.terms(&x).total;
            assert!(ex <= energy.terms(&input).total + 1e-12, "{name}");
            for _ in 0..20 {
                let y: Vec<DVec3> = x.iter().map(|v| *v + 1e-3 * rng.vec3(-0.5, 0.5)).collect();
                assert!(energy.terms(&y).total > ex, "{name}: a perturbation has lower energy");
            }
        }
    }
}

#[test]
fn solver_reuses_its_analysis_across_weights() {
    let s = DigitalSurface::from_volume(&ball(4.0)).unwrap();
    let normals = Trivial.estimate(&s).unwrap();
    let input = s.positions();
    let mut solver = DirectSolver::for_surface(&s).unwrap();
    let mut previous: Option<Vec<DVec3>> = None;
    for gamma in [0.0, 0.1, 1.0] {
        let energy = Energy::new(&s, &normals, &input, EnergyParams { gamma, ..Default::default() }).unwrap();
        let (x, info) = solver.solve(&energy).unwrap();
        assert!(info.relative_gradient <= 1e-9);
        if let Some(prev) = previous {
            assert!(prev.iter().zip(&x).any(|(a, b)| (*a - *b).length() > 1e-6));
        }
        previous = Some(x);
    }
}

/// Vertex distances to the sphere of radius `r` centred at `c`: (mean |d|, signed mean).
fn sphere_distance(p: &[DVec3], c: DVec3, r: f64) -> (f64, f64) {
    let d: Vec<f64> = p.iter().map(|q| (*q - c).length() - r).collect();
    let n = d.len() as f64;
    (d.iter().map(|x| x.abs()).sum::<f64>() / n, d.iter().sum::<f64>() / n)
}

#[test]
fn ball_with_exact_normals_converges_to_the_sphere() {
    // With the true normals at the surfel centres, the papers' energy recovers the sphere
    // far better than the staircase (the normal field, not the energy, limits accuracy).
    let mut errors = Vec::new();
    for r in [6.0, 10.0] {
        let vol = ball(r);
        let c = DVec3::splat((vol.dims()[0] as f64 - 1.0) / 2.0);
        let s = DigitalSurface::from_volume(&vol).unwrap();
        let exact = NormalField::new(
            s.surfels()
                .iter()
                .map(|sf| {
                    let centre: DVec3 =
                        sf.vertices.iter().map(|&v| s.vertex_position(v)).sum::<DVec3>() / 4.0;
                    centre - c
                })
                .collect(),
        );
        let result = exact_solve(&s, &exact);
        let (before, _) = sphere_distance(&s.positions(), c, r);
        let (after, bias) = sphere_distance(&result.positions, c, r);
        eprintln!("r = {r}: staircase {before:.4}, regularized {after:.4} (bias {bias:.4})");
        assert!(after < 0.25 * before, "r = {r}: {after} vs staircase {before}");
        assert!(after < 0.06, "r = {r}: mean distance {after}");
        errors.push(after);
    }
    assert!(errors[1] < 0.5 * errors[0], "no convergence under refinement: {errors:?}");
}

#[test]
fn bad_parameters_are_errors() {
    let s = DigitalSurface::from_volume(&ball(2.0)).unwrap();
    let n = Trivial.estimate(&s).unwrap();
    let input = s.positions();
    assert!(Energy::new(&s, &n, &input, EnergyParams { alpha: 0.0, ..Default::default() }).is_err());
    assert!(Energy::new(&s, &n, &input, EnergyParams { beta: f64::NAN, ..Default::default() }).is_err());
    assert!(Energy::new(&s, &n, &input.as_slice()[1..], EnergyParams::default()).is_err());
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(40))]

    /// On random multi-label volumes (open or closed), the direct solve is certified
    /// optimal and never increases the energy.
    #[test]
    fn direct_solve_on_random_volumes(
        dims in (1usize..=4, 1usize..=4, 1usize..=4),
        seed in any::<u64>(),
        open in any::<bool>(),
    ) {
        let mut rng = Lcg::new(seed);
        let vol = LabelVolume::from_fn([dims.0, dims.1, dims.2], |_| ((rng.range(-0.5, 0.5) + 0.5) * 3.0) as u32);
        let vol = if open { vol.with_background(None) } else { vol };
        let Ok(s) = DigitalSurface::from_volume(&vol) else { return Ok(()) };
        let normals = random_normals(&s, &mut rng);
        let r = exact_solve(&s, &normals);
        let g = r.report.last_solve().relative_gradient();
        prop_assert!(g <= 1e-9, "relative gradient {}", g);
        prop_assert!(r.report.energy.after.total <= r.report.energy.before.total + 1e-12);
    }
}

/// Per-element weights and a fairness mask: the gradient still matches finite
/// differences, and the assembled operator still matches the gradient.
#[test]
fn weighted_and_masked_energy_is_consistent() {
    use voxreg_regularize::{FairnessMask, Weights};
    let mut rng = Lcg::new(21);
    for (name, s) in cases() {
        let normals = random_normals(&s, &mut rng);
        let input = s.positions();
        let cut: Vec<bool> = (0..s.num_edges()).map(|_| rng.range(-0.5, 0.5) > 0.2).collect();
        let weights = Weights {
            alpha: Some((0..s.num_vertices()).map(|_| 0.6 + rng.range(-0.5, 0.5)).collect()),
            beta: Some((0..s.num_surfels()).map(|_| 0.6 + rng.range(-0.5, 0.5)).collect()),
            gamma: Some((0..s.num_vertices()).map(|_| 0.6 + rng.range(-0.5, 0.5)).collect()),
            fairness: Some(FairnessMask::from_cut_edges(&s, &cut).unwrap()),
        };
        let params = EnergyParams { alpha: 0.3, beta: 1.1, gamma: 0.7 };
        let energy = Energy::new(&s, &normals, &input, params).unwrap().with_weights(&weights).unwrap();
        let p: Vec<DVec3> = input.iter().map(|q| *q + 0.3 * rng.vec3(-0.5, 0.5)).collect();
        let g = energy.gradient(&p);
        assert_gradient_matches_differences(name, &energy, &p, &g, 1);
        let op = Operator::assemble(&OperatorPattern::new(&s).unwrap(), &energy);
        let flat: Vec<f64> = p.iter().flat_map(|v| v.to_array()).collect();
        let hp = op.apply(&flat);
        for (i, gi) in g.iter().enumerate() {
            for k in 0..3 {
                let alpha_i = energy.alpha_at(i);
                let from_matrix = 2.0 * (hp[3 * i + k] - alpha_i * input[i][k]);
                assert!((from_matrix - gi[k]).abs() < 1e-9, "{name}: {from_matrix} vs {}", gi[k]);
            }
        }
        // Bad weights are refused.
        let bad = Weights { alpha: Some(vec![0.0; s.num_vertices()].into()), ..Default::default() };
        assert!(Energy::new(&s, &normals, &input, params).unwrap().with_weights(&bad).is_err());
        let short = Weights { beta: Some(vec![1.0; 1].into()), ..Default::default() };
        assert!(Energy::new(&s, &normals, &input, params).unwrap().with_weights(&short).is_err());
    }
}

#[path = "../../../fuzz/fuzz_targets/pipeline_case.rs"]
mod pipeline_case;

/// The seeds of the `pipeline` fuzz target (fuzz/seeds/pipeline/): finite positions or an
/// error, never a panic.
#[test]
fn pipeline_fuzz_seeds_replay() {
    let dir = std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../../fuzz/seeds/pipeline"));
    let mut replayed = 0;
    for file in std::fs::read_dir(dir).unwrap() {
        let path = file.unwrap().path();
        let bytes = std::fs::read(&path).unwrap();
        let Some((volume, params)) = pipeline_case::case(&bytes) else { continue };
        if let Ok(out) = voxreg_regularize::regularize(&volume, &params) {
            assert!(out.positions.as_slice().iter().all(|p| p.is_finite()), "{}", path.display());
        }
        replayed += 1;
    }
    assert!(replayed >= 8, "{replayed} seeds");
}
