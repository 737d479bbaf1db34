//! Accuracy of the front door's presets against analytic shapes, measured with the
//! comparison harness's metrics (distances in voxels, area-weighted face-normal errors in
//! degrees, quad scaled Jacobian).

use glam::DVec3;
use voxreg_baselines::{accuracy, quality, Accuracy, Mesh, QualityParams};
use voxreg_digisurf::{DigitalSurface, LabelVolume};
use voxreg_normals::{IntegralInvariant, NormalEstimator, NormalField, Refined, Trivial};
use voxreg_regularize::{Params, Regularizer, Run, SolverParams};
use voxreg_testkit::{angles_deg, digitize, mean_max, Cuboid, Goursat, Shape, Sphere, Torus};

/// Digitizes `shape` at step `h`, runs the pipeline from default integral-invariant
/// normals, and measures the result: accuracy in voxels, and the minimum scaled Jacobian.
fn measure(shape: &dyn Shape, h: f64, params: &Params) -> (Accuracy, f64) {
    let surface = DigitalSurface::from_volume(&digitize(shape, h)).unwrap();
    let out = Regularizer::new(surface.clone()).run(params).unwrap();
    assert_eq!(out.report.solves.len(), params.refinement().rounds + 1);
    assert!(out.report.converged());
    let mesh = Mesh::from_surface(&surface, &out.positions);
    let mut acc = accuracy(&mesh, &shape);
    acc.distance_mean /= h;
    acc.distance_max /= h;
    acc.bias /= h;
    (acc, quality(&mesh, &QualityParams::default()).jacobian_min)
}

#[test]
fn sphere_of_radius_20_voxels_meets_the_targets() {
    let (a, sj) = measure(&Sphere { radius: 10.0 }, 0.5, &Params::default());
    let msg = format!("{a:?}, min scaled Jacobian {sj}");
    eprintln!("sphere: {msg}");
    assert!(a.distance_mean <= 0.03 && a.distance_max <= 0.2, "{msg}");
    assert!(a.bias.abs() <= 0.01, "{msg}");
    assert!(a.normal_mean_deg <= 0.8 && a.normal_max_deg <= 3.0, "{msg}");
    assert!(sj >= 0.7, "{msg}");
}

#[test]
fn goursat_at_h_0_25_meets_the_targets() {
    let (a, sj) = measure(&Goursat, 0.25, &Params::default());
    eprintln!("goursat h = 0.25: {a:?}, min scaled Jacobian {sj}");
    assert!(a.distance_mean <= 0.06 && a.normal_mean_deg <= 1.0, "{a:?}");
}

#[test]
fn torus_meets_the_targets() {
    // Issue 8's targets: |bias| <= 0.03, mean <= 0.06 voxel, normals <= 1.5 deg. This torus
    // is a hard case: its tube top sits exactly on a layer of voxel centres, so the digital
    // plateaus there lie below the true dome (the digitized volume is 0.064 voxel short,
    // the surfel centres 0.042 voxel inside); re-centring measured off the plateaus
    // (`informative_vertices`) keeps the size anyway.
    let torus = Torus { major: 6.0, minor: 2.0 };
    let (a, sj) = measure(&torus, 0.25, &Params::default());
    eprintln!("torus h = 0.25: {a:?}, min scaled Jacobian {sj}");
    assert!(a.bias.abs() <= 0.03 && a.distance_mean <= 0.06, "{a:?}");
    assert!(a.normal_mean_deg <= 1.5, "{a:?}");
    // The papers' pipeline (alpha = 1e-3, no refinement, no re-centring) shrinks it.
    let (papers, _) = measure(&torus, 0.25, &Params::papers());
    eprintln!("torus h = 0.25, papers' pipeline: {papers:?}");
    assert!(papers.bias < -0.1 && papers.distance_mean > 2.0 * a.distance_mean, "{papers:?}");
}

#[test]
fn refinement_keeps_the_edges_of_a_cube_sharp() {
    // Trivial normals are exact on an axis-aligned cube, edges included (each surfel lies
    // in one face): refinement must not round them off (the feature rule), but averaging
    // without it does.
    let cube = Cuboid { half: DVec3::splat(6.0) };
    let surface = DigitalSurface::from_volume(&digitize(&cube, 1.0)).unwrap();
    let normals = Trivial.estimate(&surface).unwrap();
    let truth = normals.as_slice();
    let mut regularizer = Regularizer::new(surface.clone());
    let mut worst = |params: &Params| {
        let out = regularizer.run(Run::new(params).from_normals(&normals)).unwrap();
        let mesh = Mesh::from_surface(&surface, &out.positions);
        let faces: Vec<DVec3> = (0..mesh.num_faces()).map(|f| mesh.vector_area(f)).collect();
        mean_max(&angles_deg(&faces, truth)).1
    };
    let params = Params::default();
    assert_eq!(params.refinement().rounds, 3);
    assert!(worst(&params) <= 5.0, "{}", worst(&params));
    let mut blind = params.clone();
    blind.refinement_mut().feature_angle_deg = 180.0;
    assert!(worst(&blind) > 10.0, "{}", worst(&blind));
}

#[test]
fn refined_normals_of_an_exact_sphere_are_radial() {
    let sphere = Sphere { radius: 8.0 };
    let surface = DigitalSurface::from_volume(&digitize(&sphere, 1.0)).unwrap();
    let on_sphere: Vec<DVec3> = surface.positions().iter().map(|p| sphere.project(*p)).collect();
    let start = Trivial.estimate(&surface).unwrap();
    let refined = Refined { positions: &on_sphere, previous: &start, radius: 3.0, feature_angle_deg: 90.0 }
        .estimate(&surface)
        .unwrap();
    let centres: Vec<DVec3> = surface
        .surfels()
        .iter()
        .map(|s| s.vertices.iter().map(|v| on_sphere[v.index()]).sum::<DVec3>() / 4.0)
        .collect();
    // Projected vertices make some quads skewed: the maximum is loose, the mean is not.
    let (mean, max) = mean_max(&angles_deg(refined.as_slice(), &centres));
    assert!(mean < 0.5 && max < 10.0, "{mean} / {max}");
    let (trivial_mean, _) = mean_max(&angles_deg(start.as_slice(), &centres));
    assert!(trivial_mean > 20.0, "{trivial_mean}");
    // Orientation follows the input field (outward).
    assert!(refined.as_slice().iter().zip(start.as_slice()).all(|(a, b)| a.dot(*b) > 0.0));
}

/// Two labelled balls touching: a multi-label surface with junction edges.
fn two_balls() -> DigitalSurface {
    let volume = LabelVolume::from_fn([22, 14, 14], |[x, y, z]| {
        let p = DVec3::new(x as f64, y as f64, z as f64);
        let (a, b) = (DVec3::new(7.0, 6.5, 6.5), DVec3::new(14.0, 6.5, 6.5));
        if p.distance(a) <= 5.5 && x <= 10 {
            1
        } else if p.distance(b) <= 5.5 {
            2
        } else {
            0
        }
    });
    let surface = DigitalSurface::from_volume(&volume).unwrap();
    assert!(surface.counts().junction_edges > 0);
    surface
}

#[test]
fn multi_label_surfaces_are_refined_per_interface() {
    let surface = two_balls();
    let normals = IntegralInvariant { radius: Some(3.0) }.estimate(&surface).unwrap();
    let out =
        Regularizer::new(surface.clone()).run(Run::new(&Params::default()).from_normals(&normals)).unwrap();
    assert!(out.positions.iter().all(|p| p.is_finite()));
    assert!(out.normals.as_slice().iter().all(|n| (n.length() - 1.0).abs() < 1e-9));
    // Re-centring moved targets by less than a voxel, and the result stays near the input.
    let input = surface.positions();
    assert!(out.targets.iter().zip(&input).all(|(t, p)| t.distance(*p) < 0.5));
    assert!(out.positions.iter().zip(&input).all(|(x, p)| x.distance(*p) < 1.0));
}

#[test]
fn clamping_keeps_every_vertex_in_its_box() {
    let surface = two_balls();
    let normals: NormalField = IntegralInvariant { radius: Some(3.0) }.estimate(&surface).unwrap();
    let mut params = Params::default();
    params.mode = params.mode.with_margin(0.01);
    assert_eq!(params.refinement().rounds, 3, "refined between clamped solves");
    let out = Regularizer::new(surface.clone()).run(Run::new(&params).from_normals(&normals)).unwrap();
    let input = surface.positions();
    assert_eq!(out.targets, input, "clamping keeps the targets (the boxes' centres) at the input");
    let half = 0.5 * (1.0 - 0.01) + 1e-12;
    assert!(out.positions.iter().zip(&input).all(|(x, p)| (*x - *p).abs().max_element() <= half));
}

#[test]
fn intermediate_solves_stop_early_without_moving_the_output() {
    // The default factor against every round solved to the tolerance, by CG on both.
    let h = 0.5;
    let surface = DigitalSurface::from_volume(&digitize(&Torus { major: 6.0, minor: 2.0 }, h)).unwrap();
    let solver = SolverParams { choice: voxreg_regularize::SolverChoice::Cg, ..Default::default() };
    let loose = Params { solver, ..Default::default() };
    assert!(loose.mode.fidelity().unwrap().intermediate_tolerance > 1.0);
    let mut tight = loose.clone();
    tight.mode.fidelity_mut().unwrap().intermediate_tolerance = 1.0;
    let mut r = Regularizer::new(surface);
    let (a, b) = (r.run(&loose).unwrap(), r.run(&tight).unwrap());
    let its = |o: &voxreg_regularize::Output| -> Vec<usize> {
        o.report.solves.iter().map(|s| s.iterations()).collect()
    };
    let (ia, ib) = (its(&a), its(&b));
    let n = ia.len() - 1;
    assert!(ia[..n].iter().sum::<usize>() < ib[..n].iter().sum::<usize>(), "{ia:?} vs {ib:?}");
    let last = a.report.solves.last().unwrap();
    assert!(last.converged() && last.error_estimate().unwrap() <= 1e-3, "{last:?}");
    let moved = a.positions.iter().zip(b.positions.iter()).map(|(p, q)| p.distance(*q) / h);
    let max = moved.fold(0.0f64, f64::max);
    assert!(max <= 2e-3, "the output moved by {max} voxel ({ia:?} vs {ib:?} iterations)");
}

/// Fewer refinement rounds: faster and a little less faithful. From one round on, the
/// sphere and Goursat targets hold; the normals' error falls with each round on the three
/// shapes (what the default's three rounds are for: the torus's targets need them).
/// Prints the rows of docs/accuracy.md's "Fewer refinement rounds".
#[test]
fn each_refinement_round_improves_the_normals() {
    let cases: [(&str, &dyn Shape, f64); 3] = [
        ("sphere r = 20", &Sphere { radius: 10.0 }, 0.5),
        ("goursat h = 0.25", &Goursat, 0.25),
        ("torus h = 0.25", &Torus { major: 6.0, minor: 2.0 }, 0.25),
    ];
    for (name, shape, h) in cases {
        let mut last = f64::INFINITY;
        for refine in 0..=3 {
            let mut params = Params::default();
            params.refinement_mut().rounds = refine;
            let (a, sj) = measure(shape, h, &params);
            eprintln!(
                "| {name} | {refine} | {:.3} / {:.3} | {:+.3} | {:.2} / {:.2} | {sj:.3} |",
                a.distance_mean, a.distance_max, a.bias, a.normal_mean_deg, a.normal_max_deg
            );
            assert!(a.normal_mean_deg <= last + 0.02, "{name}, {refine} rounds: {a:?}");
            last = a.normal_mean_deg;
            if refine >= 1 && name.starts_with("sphere") {
                assert!(a.distance_mean <= 0.03 && a.distance_max <= 0.2 && a.bias.abs() <= 0.01, "{a:?}");
                assert!(a.normal_mean_deg <= 0.8 && a.normal_max_deg <= 3.0, "{a:?}");
            }
            if refine >= 1 && name.starts_with("goursat") {
                assert!(a.distance_mean <= 0.06 && a.normal_mean_deg <= 1.0, "{a:?}");
            }
        }
    }
}
