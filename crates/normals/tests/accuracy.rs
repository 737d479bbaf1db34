//! Accuracy of the normal estimators against exact answers: analytic shapes with known
//! normals (`voxreg-testkit`), errors that shrink as the grid refines, and multi-label
//! configurations whose answer is known by symmetry. (The exact digital moments are
//! checked against brute-force sums beside the code, in `src/ii.rs`.)
//!
//! Run in release mode: `cargo test --release -p voxreg-normals --test tests accuracy::`.

use glam::DVec3;
use voxreg_digisurf::{DigitalSurface, EdgeKind, LabelVolume};
use voxreg_normals::{
    default_radius, multigrid_radius, ConvolvedTrivial, IntegralInvariant, NormalEstimator, NormalField,
    Trivial,
};
use voxreg_testkit::{angles_deg, digitize, mean_max, true_normals, Goursat, Shape, Sphere, Torus};

/// Mean and max angular error (degrees) of `estimator` on `shape` digitized at step `h`.
fn errors(shape: &dyn Shape, h: f64, estimator: &dyn NormalEstimator) -> (f64, f64) {
    let volume = digitize(shape, h);
    let surface = DigitalSurface::from_volume(&volume).unwrap();
    let normals = estimator.estimate(&surface).unwrap();
    mean_max(&angles_deg(normals.as_slice(), &true_normals(&surface, shape)))
}

#[test]
fn ii_on_a_sphere_of_radius_20_voxels() {
    // Target: mean error at most 2 degrees at the default radius (3 voxels at
    // h = 1; the reference's II: 3.2, its VCM 1.8).
    let sphere = Sphere { radius: 20.0 };
    let ii = IntegralInvariant::default();
    assert_eq!(ii.radius_for(&DigitalSurface::from_volume(&digitize(&sphere, 1.0)).unwrap()), 3.0);
    let (mean3, max3) = errors(&sphere, 1.0, &ii);
    let (mean5, max5) = errors(&sphere, 1.0, &IntegralInvariant { radius: Some(5.0) });
    eprintln!(
        "sphere r=20, II default r=3: mean {mean3:.3} max {max3:.2}; r=5: mean {mean5:.3} max {max5:.2}"
    );
    // Measured: r = 3: 1.91 / 7.7 degrees (voxel centres in the ball: 3.38 / 9.2; exact
    // partial volumes of the voxel cubes: 2.04 / 7.9); r = 5: 0.86 / 3.3.
    assert!(mean3 <= 2.0 && max3 <= 9.0, "r = 3: {mean3} / {max3}");
    assert!(mean5 <= 1.0 && max5 <= 4.0, "r = 5: {mean5} / {max5}");
    // The trivial normals, for scale: 45 degrees on average.
    let (trivial, _) = errors(&sphere, 1.0, &Trivial);
    assert!(trivial > 40.0);
}

/// II errors at the default (multigrid) radius for decreasing `h`: each must be smaller
/// than the last, and the error must fall at least as `h^0.5` over the range (theory:
/// `h^{2/3}`).
fn check_multigrid_convergence(shape: &dyn Shape, steps: &[f64]) {
    let means: Vec<f64> = steps.iter().map(|&h| errors(shape, h, &IntegralInvariant::default()).0).collect();
    eprintln!("{}: h {steps:?} -> mean errors {means:.3?}", shape.name());
    for (w, h) in means.windows(2).zip(steps.windows(2)) {
        assert!(
            w[1] < w[0],
            "{}: error rose from {} (h = {}) to {} (h = {})",
            shape.name(),
            w[0],
            h[0],
            w[1],
            h[1]
        );
    }
    let (first, last) = (means[1], means[means.len() - 1]);
    let rate = (first / last).ln() / (steps[1] / steps[steps.len() - 1]).ln();
    assert!(rate > 0.5, "{}: convergence rate {rate}", shape.name());
}

#[test]
fn ii_converges_on_a_sphere() {
    check_multigrid_convergence(&Sphere { radius: 5.0 }, &[1.0, 0.5, 0.25, 0.125]);
}

#[test]
fn ii_converges_on_a_torus() {
    check_multigrid_convergence(&Torus { major: 6.0, minor: 2.0 }, &[1.0, 0.5, 0.25, 0.125]);
}

#[test]
fn ii_converges_on_goursat() {
    check_multigrid_convergence(&Goursat, &[1.0, 0.5, 0.25, 0.125]);
}

#[test]
fn ii_honours_anisotropic_spacing() {
    // A sphere of radius 16 sampled with voxels 1 x 1 x 1.6 (physical units): the ball
    // must be a ball in physical space, an ellipsoid of voxels.
    let spacing = DVec3::new(1.0, 1.0, 1.6);
    let sphere = Sphere { radius: 16.0 };
    let n = [36, 36, 24];
    let volume = LabelVolume::from_fn(n, |p| {
        let x = DVec3::new(p[0] as f64 - 17.5, p[1] as f64 - 17.5, p[2] as f64 - 11.5) * spacing;
        u32::from(sphere.value(x) <= 0.0)
    })
    .with_spacing(spacing)
    .unwrap()
    .with_origin(DVec3::new(-17.5, -17.5, -11.5) * spacing)
    .unwrap();
    let surface = DigitalSurface::from_volume(&volume).unwrap();
    let truth = true_normals(&surface, &sphere);
    let (mean, max) = mean_max(&angles_deg(
        IntegralInvariant { radius: Some(5.0) }.estimate(&surface).unwrap().as_slice(),
        &truth,
    ));
    eprintln!("anisotropic sphere: mean {mean:.2} max {max:.2}");
    assert!(mean < 2.5 && max < 8.0, "{mean} / {max}");
}

#[test]
fn convolved_trivial_on_a_sphere() {
    let sphere = Sphere { radius: 20.0 };
    let (mean3, max3) = errors(&sphere, 1.0, &ConvolvedTrivial { radius: Some(3.0) });
    let (mean5, max5) = errors(&sphere, 1.0, &ConvolvedTrivial { radius: Some(5.0) });
    eprintln!(
        "sphere r=20, convolved t=3: mean {mean3:.2} max {max3:.2}; t=5: mean {mean5:.2} max {max5:.2}"
    );
    // Measured: t = 3: 4.08 / 10.7 degrees; t = 5: 1.62 / 6.1 degrees.
    assert!(mean3 <= 5.0 && max3 <= 14.0, "t = 3: {mean3} / {max3}");
    assert!(mean5 <= 2.5 && max5 <= 8.0, "t = 5: {mean5} / {max5}");
}

#[test]
fn convolution_runs_over_the_surface_not_through_space() {
    // A plate 2 voxels thick: its two faces are 2 apart in space, but far apart over the
    // surface away from the rim, where each face keeps its own normal exactly.
    let volume = LabelVolume::from_fn([24, 24, 4], |[x, y, z]| {
        u32::from((1..23).contains(&x) && (1..23).contains(&y) && (1..3).contains(&z))
    });
    let surface = DigitalSurface::from_volume(&volume).unwrap();
    let normals = ConvolvedTrivial { radius: Some(3.0) }.estimate(&surface).unwrap();
    let mut checked = 0;
    for (s, n) in surface.surfels().iter().zip(normals.as_slice()) {
        let away = s.axis == 2 && (6..18).contains(&s.cell[0]) && (6..18).contains(&s.cell[1]);
        if away {
            assert!((*n - s.normal()).length() < 1e-12, "{n} vs {}", s.normal());
            checked += 1;
        }
    }
    assert_eq!(checked, 2 * 12 * 12);
}

/// Two boxes of labels 1 and 2, mirror images of each other across the plane `x = 12`,
/// touching along it, in background 0.
fn two_boxes() -> LabelVolume {
    LabelVolume::from_fn([24, 16, 16], |[x, y, z]| {
        let in_yz = (4..12).contains(&y) && (4..12).contains(&z);
        match x {
            4..12 if in_yz => 1,
            12..20 if in_yz => 2,
            _ => 0,
        }
    })
}

/// Checks that the surfels between labels 1 and 2 get the direction of x (exactly: by the
/// mirror symmetry, the two sides' tilts cancel), oriented like their trivial normals.
fn assert_interface_along_x(surface: &DigitalSurface, normals: &NormalField) -> usize {
    let mut count = 0;
    for (s, n) in surface.surfels().iter().zip(normals.as_slice()) {
        let mut labels = s.labels;
        labels.sort_unstable();
        if labels == [1, 2] {
            assert_eq!(s.axis, 0);
            assert!((*n - s.normal()).length() < 1e-9, "{n} vs {}", s.normal());
            count += 1;
        }
    }
    count
}

#[test]
fn multi_label_interface_gets_its_axis() {
    let surface = DigitalSurface::from_volume(&two_boxes()).unwrap();
    // The junction edges (three regions meet) are the rim of the 8 x 8 interface.
    let junctions: Vec<_> =
        (0..surface.num_edges()).filter(|&e| surface.edges()[e].kind == EdgeKind::Junction).collect();
    assert_eq!(junctions.len(), 32);
    for &e in &junctions {
        let incident = surface.edge_surfels(voxreg_digisurf::EdgeId(e as u32));
        let mut regions: Vec<_> = incident.iter().flat_map(|&s| surface.surfel(s).regions).collect();
        regions.sort_unstable();
        regions.dedup();
        assert_eq!((incident.len(), regions.len()), (3, 3));
    }
    for estimator in [
        &IntegralInvariant { radius: Some(3.0) } as &dyn NormalEstimator,
        &IntegralInvariant { radius: Some(5.0) },
        &ConvolvedTrivial { radius: Some(3.0) },
    ] {
        let normals = estimator.estimate(&surface).unwrap();
        assert_eq!(assert_interface_along_x(&surface, &normals), 64, "{}", estimator.name());
        // Every surfel's normal stays on the side of its trivial normal, junctions included.
        let (_, max) =
            mean_max(&angles_deg(normals.as_slice(), Trivial.estimate(&surface).unwrap().as_slice()));
        assert!(max < 60.0, "{}: {max}", estimator.name());
        for (s, n) in surface.surfels().iter().zip(normals.as_slice()) {
            assert!(n.dot(s.normal()) > 0.0);
        }
    }
}

#[test]
fn open_border_interfaces_meet_the_border_squarely() {
    // No background: labels 1 | 2 split at x = 10; the interface ends on the domain
    // border, where the ball is cut. The cut tilts each side's estimate, mirror-wise, so
    // the average is exact.
    let volume = LabelVolume::from_fn([20, 12, 12], |[x, _, _]| 1 + u32::from(x >= 10)).with_background(None);
    let surface = DigitalSurface::from_volume(&volume).unwrap();
    assert!(surface.has_open_border());
    for estimator in [
        &IntegralInvariant { radius: Some(4.0) } as &dyn NormalEstimator,
        &ConvolvedTrivial { radius: Some(4.0) },
    ] {
        let normals = estimator.estimate(&surface).unwrap();
        assert_eq!(assert_interface_along_x(&surface, &normals), 144, "{}", estimator.name());
    }
}

#[test]
fn ii_normals_are_unit_and_oriented_like_trivial_on_bunny() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data/bunny-64.vol");
    let volume = voxreg_io::read_volume(&path).unwrap().volume;
    let surface = DigitalSurface::from_volume(&volume).unwrap();
    let ii = IntegralInvariant::default();
    assert_eq!(ii.radius_for(&surface), multigrid_radius(volume.spacing()));
    assert_eq!(ii.radius_for(&surface), 3.0);
    let normals = ii.estimate(&surface).unwrap();
    for (s, n) in surface.surfels().iter().zip(normals.as_slice()) {
        assert!((n.length() - 1.0).abs() < 1e-12);
        assert!(n.dot(s.normal()) > 0.0);
    }
    assert_eq!(ii.name(), "ii");
    assert_eq!(ConvolvedTrivial::default().name(), "convolved");
}

#[test]
fn the_default_radius_stays_within_3_to_12_voxels_whatever_the_unit() {
    let ball = LabelVolume::from_fn([12, 12, 12], |[x, y, z]| {
        u32::from((x as f64 - 5.5).powi(2) + (y as f64 - 5.5).powi(2) + (z as f64 - 5.5).powi(2) < 16.0)
    });
    let radius = |spacing: DVec3| {
        let surface = DigitalSurface::from_volume(&ball.clone().with_spacing(spacing).unwrap()).unwrap();
        default_radius(&surface)
    };
    // The multigrid rule where it applies (h from 1/8 to 1)...
    for h in [1.0, 0.5, 0.25, 0.125] {
        assert_eq!(radius(DVec3::splat(h)), multigrid_radius(DVec3::splat(h)), "h = {h}");
    }
    // ... and bounded in voxels otherwise: millimetre voxels written in metres, in microns.
    assert!((radius(DVec3::splat(0.001)) / 0.001 - 12.0).abs() < 1e-9);
    assert!((radius(DVec3::splat(1000.0)) / 1000.0 - 3.0).abs() < 1e-9);
    // Anisotropic: at least 3 of the finest step, at most 12 of the coarsest.
    let r = radius(DVec3::new(0.001, 0.001, 0.005));
    assert!((0.003..=0.06).contains(&r), "{r}");
    // A volume smaller than the ball: the diagonal.
    let one = LabelVolume::from_fn([1, 1, 1], |_| 1).with_spacing(DVec3::splat(0.001)).unwrap();
    let surface = DigitalSurface::from_volume(&one).unwrap();
    let diagonal = 0.001 * 3f64.sqrt() * surface.dims()[0] as f64;
    assert!(default_radius(&surface) <= diagonal + 1e-12);
    assert!(IntegralInvariant::default().estimate(&surface).is_ok());
}

#[test]
fn a_radius_larger_than_the_volume_is_refused() {
    let volume = LabelVolume::from_fn([40, 40, 40], |[x, y, z]| {
        u32::from(x.min(y).min(z) > 10 && x.max(y).max(z) < 30)
    });
    let surface = DigitalSurface::from_volume(&volume).unwrap();
    let err = IntegralInvariant { radius: Some(400.0) }.estimate(&surface).unwrap_err().to_string();
    assert!(err.contains("radius 400") && err.contains("larger than the whole volume"), "{err}");
    assert!(IntegralInvariant { radius: Some(12.0) }.estimate(&surface).is_ok());
}
