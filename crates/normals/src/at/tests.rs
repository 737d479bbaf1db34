//! Unit tests of the AT solver: the assembled systems against the energy, the two linear
//! solvers against each other, and the coupling of junction and pinch edges.

use super::*;
use voxreg_digisurf::LabelVolume;

fn ball(radius: f64) -> DigitalSurface {
    let n = (2.0 * radius).ceil() as usize + 3;
    let c = (n as f64 - 1.0) / 2.0;
    let volume = LabelVolume::from_fn([n, n, n], |p| {
        u32::from(p.iter().map(|&x| (x as f64 - c).powi(2)).sum::<f64>() <= radius * radius)
    });
    DigitalSurface::from_volume(&volume).unwrap()
}

/// A deterministic pseudo-random sequence in `[-1, 1]`.
fn wiggle(i: usize, k: usize) -> f64 {
    ((i * 7919 + k * 104_729) as f64 * 0.618_033_988_75).fract() * 2.0 - 1.0
}

/// The assembled systems are the exact Hessians of [`AtSolver::energy`]: each half-step's
/// solution is a critical point (central differences vanish) and a minimum.
#[test]
fn each_half_step_minimizes_the_energy() {
    let surface = ball(4.0);
    let mut solver = AtSolver::new(&surface).unwrap();
    let params = AtParams::default();
    let eps = 0.5;
    let ns = surface.num_surfels();
    let nv = surface.num_vertices();
    let g = NormalField::new(
        surface
            .surfels()
            .iter()
            .enumerate()
            .map(|(i, s)| s.normal() + 0.3 * DVec3::new(wiggle(i, 0), wiggle(i, 1), wiggle(i, 2)))
            .collect(),
    );
    let v: Vec<[f64; 1]> = (0..nv).map(|i| [0.6 + 0.4 * wiggle(i, 3)]).collect();
    let v_flat: Vec<f64> = v.iter().map(|x| x[0]).collect();

    // u-step.
    let mut rhs = vec![[0.0; 3]; ns];
    solver.assemble_u(g.as_slice(), &v, params.alpha, None, &mut rhs);
    let mut u_raw = vec![[0.0; 3]; ns];
    solver.u_system.solve(&rhs, &mut u_raw, None, 0, faer::Par::Seq).unwrap();
    let u: Vec<DVec3> = u_raw.iter().map(|x| DVec3::from_array(*x)).collect();
    let e0 = solver.energy(&g, &u, &v_flat, &params, eps);
    let h = 1e-4;
    for k in 0..4 {
        let d: Vec<DVec3> =
            (0..ns).map(|i| DVec3::new(wiggle(i, 4 + k), wiggle(i, 8 + k), wiggle(i, 12 + k))).collect();
        let shifted = |t: f64| -> Vec<DVec3> { u.iter().zip(&d).map(|(a, b)| *a + t * *b).collect() };
        let plus = solver.energy(&g, &shifted(h), &v_flat, &params, eps);
        let minus = solver.energy(&g, &shifted(-h), &v_flat, &params, eps);
        assert!(
            ((plus - minus) / (2.0 * h)).abs() < 1e-6 * e0.max(1.0),
            "u gradient {}",
            (plus - minus) / (2.0 * h)
        );
        assert!(plus >= e0 && minus >= e0);
    }

    // v-step (on the normalized u, as in the solver).
    let u_unit: Vec<DVec3> = u.iter().map(|x| x.normalize()).collect();
    let mut rhs = vec![[0.0; 1]; nv];
    solver.assemble_v(&u_unit, params.lambda, eps, &mut rhs);
    let mut v_star = vec![[0.0; 1]; nv];
    solver.v_system.solve(&rhs, &mut v_star, None, 0, faer::Par::Seq).unwrap();
    let v_star: Vec<f64> = v_star.iter().map(|x| x[0]).collect();
    let e0 = solver.energy(&g, &u_unit, &v_star, &params, eps);
    for k in 0..4 {
        let shifted = |t: f64| -> Vec<f64> {
            v_star.iter().enumerate().map(|(i, x)| x + t * wiggle(i, 20 + k)).collect()
        };
        let plus = solver.energy(&g, &u_unit, &shifted(h), &params, eps);
        let minus = solver.energy(&g, &u_unit, &shifted(-h), &params, eps);
        assert!(
            ((plus - minus) / (2.0 * h)).abs() < 1e-6 * e0.max(1.0),
            "v gradient {}",
            (plus - minus) / (2.0 * h)
        );
        assert!(plus >= e0 && minus >= e0);
    }
}

/// The surface's trivial normals, perturbed deterministically (unnormalized).
fn wiggled_normals(surface: &DigitalSurface) -> NormalField {
    NormalField::new(
        surface
            .surfels()
            .iter()
            .enumerate()
            .map(|(i, s)| s.normal() + 0.2 * DVec3::new(wiggle(i, 0), wiggle(i, 1), wiggle(i, 2)))
            .collect(),
    )
}

/// Conjugate gradients and Cholesky give the same fields.
#[test]
fn cg_and_cholesky_agree() {
    let surface = ball(6.0);
    let g = wiggled_normals(&surface);
    let mut solver = AtSolver::new(&surface).unwrap();
    let direct = AtParams { linear_solver: AtLinearSolver::Cholesky, ..AtParams::default() };
    let iterative = AtParams {
        linear_solver: AtLinearSolver::ConjugateGradient { tolerance: 1e-12, max_iterations: 10_000 },
        ..AtParams::default()
    };
    let (u1, v1, i1) = solver.solve(&g, &direct).unwrap();
    let (u2, v2, i2) = solver.solve(&g, &iterative).unwrap();
    assert!(i1.factorizations > 0 && i1.cg_iterations == 0);
    assert!(i2.factorizations == 0 && i2.cg_iterations > 0);
    // The sharpening stage's data weights (down to 1e-3) condition the u-system up to
    // about 1e4: a residual of 1e-12 leaves about 1e-6 degrees (measured 1.2e-6).
    assert!(u1.max_angle_deg(&u2) < 1e-5, "{}", u1.max_angle_deg(&u2));
    let dv = v1.as_slice().iter().zip(v2.as_slice()).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
    assert!(dv < 1e-8, "{dv}");
    assert_eq!(i1.iterations, i2.iterations);
}

/// The default (CG to a relative residual of `1e-5`) stays close to exact solves.
#[test]
fn default_solver_is_close_to_cholesky() {
    let surface = ball(6.0);
    let g = wiggled_normals(&surface);
    let mut solver = AtSolver::new(&surface).unwrap();
    let exact = AtParams { linear_solver: AtLinearSolver::Cholesky, ..AtParams::default() };
    let (u1, v1, _) = solver.solve(&g, &exact).unwrap();
    let (u2, v2, info) = solver.solve(&g, &AtParams::default()).unwrap();
    assert_eq!(info.factorizations, 0);
    assert!(u1.max_angle_deg(&u2) < 1e-2, "{}", u1.max_angle_deg(&u2));
    let dv = v1.as_slice().iter().zip(v2.as_slice()).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
    assert!(dv < 1e-4, "{dv}");
}

/// Junction and pinch edges couple only perpendicular surfels of one interface.
#[test]
fn links_follow_interfaces() {
    // Two labels side by side in background: junction edges where they meet the outside.
    let volume = LabelVolume::from_fn([6, 4, 4], |[x, y, z]| {
        if (1..3).contains(&y) && (1..3).contains(&z) && (1..5).contains(&x) {
            1 + u32::from(x >= 3)
        } else {
            0
        }
    });
    let surface = DigitalSurface::from_volume(&volume).unwrap();
    let solver = AtSolver::new(&surface).unwrap();
    for l in &solver.links {
        let [a, b] = l.surfels.map(|s| surface.surfel(SurfelId(s)));
        assert_eq!(a.interface, b.interface);
    }
    // Every surfel is coupled to at least one neighbour, and only across its own edges.
    let mut coupled = vec![0; surface.num_surfels()];
    for l in &solver.links {
        for s in l.surfels {
            assert!(surface.surfel_edges(SurfelId(s)).iter().any(|e| e.0 == l.edge));
            coupled[s as usize] += 1;
        }
    }
    assert!(coupled.iter().all(|&c| (1..=4).contains(&c)), "{coupled:?}");
}
