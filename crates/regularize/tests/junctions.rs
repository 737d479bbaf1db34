//! Fidelity where labels meet and on anisotropic voxels, against the test kit's analytic
//! label shapes (distances in voxels of the finest spacing, `voxreg_testkit::label_fidelity`).
//! The bounds are what the default pipeline achieves, with a margin; the targets
//! where they are not met are in docs/accuracy.md.

use glam::{DVec2, DVec3};
use voxreg_digisurf::DigitalSurface;
use voxreg_regularize::{Params, Regularizer};
use voxreg_testkit::{
    digitize_labels, label_fidelity, LabelFidelity, LabelShape, QuarteredBall, Solid, Sphere, SplitBall,
};

fn fidelity(shape: &dyn LabelShape, spacing: DVec3, params: &Params) -> LabelFidelity {
    let surface = DigitalSurface::from_volume(&digitize_labels(shape, spacing)).unwrap();
    let out = Regularizer::new(surface.clone()).run(params).unwrap();
    assert!(out.report.converged());
    label_fidelity(&surface, &out.positions, shape)
}

#[test]
fn split_ball_junction_circle_is_as_close_as_measured() {
    let ball = SplitBall { radius: 20.0, cut: 0.5 };
    let f = fidelity(&ball, DVec3::ONE, &Params::default());
    eprintln!("split ball: {f:?}");
    assert_eq!(f.junction.count, 156);
    // Before junction fairness and cross-interface refinement: 0.109 / 0.245.
    assert!(f.junction.mean <= 0.065 && f.junction.max <= 0.21, "{f:?}");
    // The sphere and the cut disc no worse than before (0.024 / 0.215 and 0.006 / 0.017).
    assert!(f.surface.mean <= 0.025 && f.surface.max <= 0.215, "{f:?}");
    assert!(f.inner.mean <= 0.012 && f.inner.max <= 0.02, "{f:?}");
    // Without the junction handling, the same pipeline is farther off.
    let old = fidelity(&ball, DVec3::ONE, &Params { junction_fairness: false, ..Default::default() });
    assert!(old.junction.mean > f.junction.mean, "{old:?}");
}

#[test]
fn quartered_ball_junction_lines_and_points() {
    let ball = QuarteredBall { radius: 20.0, centre: DVec3::new(0.5, 0.0, 0.5), cuts: DVec2::splat(0.5) };
    let f = fidelity(&ball, DVec3::ONE, &Params::default());
    eprintln!("quartered ball: {f:?}");
    assert_eq!(f.points.count, 2);
    // Before: lines 0.091 / 0.482, points 0.573.
    assert!(f.junction.mean <= 0.065 && f.points.max <= 0.45, "{f:?}");
    assert!(f.surface.mean <= 0.03, "{f:?}");
}

#[test]
fn sphere_on_thick_slices() {
    let sphere = Sphere { radius: 20.0 };
    let f = fidelity(&Solid(&sphere), DVec3::new(1.0, 1.0, 5.0), &Params::default());
    eprintln!("sphere at (1, 1, 5): {f:?}");
    // Far from the in-plane figures (0.375 / 1.197, normals 7.3 degrees): reported, not a target.
    assert!(f.surface.mean <= 0.45 && f.surface_normals.mean <= 8.5, "{f:?}");
    // At (1, 1, 2.5) the normals meet the target (0.6 degrees), the distance does not
    // (0.044 against 0.03).
    let f = fidelity(&Solid(&sphere), DVec3::new(1.0, 1.0, 2.5), &Params::default());
    eprintln!("sphere at (1, 1, 2.5): {f:?}");
    assert!(f.surface_normals.mean <= 0.6 && f.surface.mean <= 0.05, "{f:?}");
}
