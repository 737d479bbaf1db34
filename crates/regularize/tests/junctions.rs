//! Fidelity where labels meet and on anisotropic voxels, against the test kit's analytic
//! label shapes (distances in voxels of the finest spacing, `voxreg_testkit::label_fidelity`).
//! The bounds are what the default pipeline achieves, with a margin; the targets
//! where they are not met are in docs/accuracy.md.

use glam::{DVec2, DVec3};
use voxreg_digisurf::DigitalSurface;
use voxreg_normals::{NormalEstimator, Trivial};
use voxreg_regularize::{Params, Regularizer, Run};
use voxreg_testkit::{
    digitize_labels, label_fidelity, Cuboid, LabelFidelity, LabelShape, QuarteredBall, Shape, Solid, Sphere,
    SplitBall, Torus, TouchingBalls,
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
    // 0.026 / 0.072 (target 0.03 / 0.1). Before junction fairness and cross-interface
    // refinement: 0.109 / 0.245; before the interior normals next to the curve: 0.054 /
    // 0.180; before the wider discs where the sphere continues across it: 0.048 / 0.165.
    assert!(f.junction.mean <= 0.03 && f.junction.max <= 0.1, "{f:?}");
    // The sphere and the cut disc no worse than before (0.024 / 0.215 and 0.006 / 0.017):
    // 0.023 / 0.168 and 0.002 / 0.004.
    assert!(f.surface.mean <= 0.025 && f.surface.max <= 0.2, "{f:?}");
    assert!(f.inner.mean <= 0.005 && f.inner.max <= 0.008, "{f:?}");
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
    // Lines 0.034 / 0.083 (target 0.04), points 0.031 (target 0.1). Before: lines 0.091 /
    // 0.482, points 0.573; before the interior normals next to the curves: 0.053 / 0.350
    // and 0.382; before the wider discs across the curves: 0.049 / 0.149 and 0.075.
    assert!(f.junction.mean <= 0.04 && f.junction.max <= 0.1 && f.points.max <= 0.1, "{f:?}");
    assert!(f.surface.mean <= 0.026 && f.surface.max <= 0.14, "{f:?}");
}

#[test]
fn split_balls_kept_aside_from_tuning() {
    // Other radii and a cut off the equator: 0.026 / 0.049 (r = 23), 0.050 / 0.075
    // (r = 17), 0.037 / 0.050 (r = 20, cut 6.5, whose cut disc sits 0.2 voxel off the
    // lattice); before the wider discs: 0.059 / 0.174, 0.090 / 0.152, 0.049 / 0.068.
    for (radius, cut, mean, max) in
        [(23.0, 0.5, 0.03, 0.07), (17.0, 0.5, 0.055, 0.09), (20.0, 6.5, 0.042, 0.06)]
    {
        let f = fidelity(&SplitBall { radius, cut }, DVec3::ONE, &Params::default());
        eprintln!("split ball r = {radius}, cut {cut}: {f:?}");
        assert!(f.junction.mean <= mean && f.junction.max <= max, "r = {radius}: {f:?}");
    }
}

#[test]
fn touching_balls_junction_circle() {
    // Kept aside from tuning: a crease where two spheres and a plane meet, no interface
    // continuing smoothly across it. 0.075 / 0.238 (0.355 / 0.518 before the interior
    // normals next to the curve).
    let f = fidelity(&TouchingBalls::default(), DVec3::ONE, &Params::default());
    eprintln!("touching balls: {f:?}");
    assert!(f.junction.mean <= 0.1 && f.junction.max <= 0.3, "{f:?}");
    assert!(f.surface.mean <= 0.03 && f.inner.mean <= 0.04, "{f:?}");
}

#[test]
fn sphere_on_thick_slices() {
    let sphere = Sphere { radius: 20.0 };
    let f = fidelity(&Solid(&sphere), DVec3::new(1.0, 1.0, 2.5), &Params::default());
    eprintln!("sphere at (1, 1, 2.5): {f:?}");
    // The target: 0.03 voxel, normals 0.6 degrees. 0.025 / 0.097, normals 0.48 degrees
    // (0.044 / 0.206, 0.57 degrees before the re-centring's sample weights, sagitta lift
    // and plateau weights).
    assert!(f.surface.mean <= 0.028 && f.surface.max <= 0.12 && f.surface_normals.mean <= 0.55, "{f:?}");
    // Reported, not a target: 0.050 / 0.312, normals 1.01 degrees (0.105 / 0.332 and
    // 1.35 degrees before; 0.375 / 1.197 and 7.3 degrees before the first-order
    // refinement fit on anisotropic voxels).
    let f = fidelity(&Solid(&sphere), DVec3::new(1.0, 1.0, 5.0), &Params::default());
    eprintln!("sphere at (1, 1, 5): {f:?}");
    assert!(f.surface.mean <= 0.06 && f.surface.max <= 0.4 && f.surface_normals.mean <= 1.2, "{f:?}");
}

/// A sphere of radius `radius` centred at `centre` (off the lattice's points).
struct OffCentre {
    radius: f64,
    centre: DVec3,
}

impl Shape for OffCentre {
    fn value(&self, p: DVec3) -> f64 {
        (p - self.centre).length() - self.radius
    }
    fn gradient(&self, p: DVec3) -> DVec3 {
        (p - self.centre).normalize_or_zero()
    }
    fn bounds(&self) -> (DVec3, DVec3) {
        (self.centre - DVec3::splat(self.radius), self.centre + DVec3::splat(self.radius))
    }
    fn name(&self) -> &'static str {
        "off-centre sphere"
    }
    fn project(&self, p: DVec3) -> DVec3 {
        self.centre + (p - self.centre).normalize_or(DVec3::Z) * self.radius
    }
}

#[test]
fn spheres_on_thick_slices_kept_aside_from_tuning() {
    // Other radii, and spheres whose centres are off the lattice's points (each a
    // different digitization), at (1, 1, 2.5). Mean distances 0.011, 0.026, 0.025, 0.033,
    // 0.028, 0.026 (set mean 0.025), normals at most 0.53 degrees; before the re-centring's
    // sample weights, sagitta lift and plateau weights: 0.030, 0.036, 0.042, 0.042, 0.034,
    // 0.029 (0.035). One of the six stays above the 0.03 target (its poles sit 0.09 voxel
    // inside).
    let spacing = DVec3::new(1.0, 1.0, 2.5);
    let mut means = Vec::new();
    for (radius, centre) in [
        (15.3, DVec3::ZERO),
        (23.7, DVec3::ZERO),
        (20.0, DVec3::new(0.31, 0.72, 0.45) * spacing),
        (20.0, DVec3::new(0.83, 0.17, 0.91) * spacing),
        (17.1, DVec3::new(0.56, 0.38, 0.12) * spacing),
        (26.4, DVec3::new(0.07, 0.64, 0.69) * spacing),
    ] {
        let f = fidelity(&Solid(&OffCentre { radius, centre }), spacing, &Params::default());
        eprintln!("sphere r = {radius}, centre {centre}: {f:?}");
        assert!(
            f.surface.mean <= 0.036 && f.surface_normals.mean <= 0.6,
            "r = {radius}, centre {centre}: {f:?}"
        );
        means.push(f.surface.mean);
    }
    let mean = means.iter().sum::<f64>() / means.len() as f64;
    eprintln!("mean distance over the set: {mean:.4}");
    assert!(mean <= 0.027, "{means:?}");
}

#[test]
fn torus_on_thick_slices() {
    // Kept aside from tuning, like the sphere at (1, 2, 3) below.
    let torus = Torus { major: 12.0, minor: 5.0 };
    let f = fidelity(&Solid(&torus), DVec3::new(1.0, 1.0, 2.5), &Params::default());
    eprintln!("torus at (1, 1, 2.5): {f:?}");
    // 0.123 / 0.412, normals 5.6 degrees (0.330 / 0.757 and 12.4 degrees before the
    // plateau weights and the re-centring's sample weights; 0.378 / 0.872 and 14.1
    // degrees before the first-order refinement fit).
    assert!(f.surface.mean <= 0.14 && f.surface_normals.mean <= 6.5, "{f:?}");
    let f = fidelity(&Solid(&torus), DVec3::new(1.0, 1.0, 5.0), &Params::default());
    eprintln!("torus at (1, 1, 5): {f:?}");
    // Two slices across the tube: reported only (0.85 / 1.99, normals 18 degrees; 1.21 /
    // 2.31 and 29 degrees before, 1.09 / 2.15 and 26 degrees before the first-order fit).
    assert!(f.surface.mean <= 0.95, "{f:?}");
}

#[test]
fn sphere_on_voxels_of_three_sizes() {
    let sphere = Sphere { radius: 20.0 };
    let f = fidelity(&Solid(&sphere), DVec3::new(1.0, 2.0, 3.0), &Params::default());
    eprintln!("sphere at (1, 2, 3): {f:?}");
    // 0.057 / 0.155, normals 0.64 degrees (0.056 / 0.178, 0.73 degrees before the
    // re-centring's weights; 0.061 / 0.191, 0.78 degrees before the first-order fit).
    assert!(f.surface.mean <= 0.06 && f.surface_normals.mean <= 0.7, "{f:?}");
}

#[test]
fn refinement_keeps_the_edges_of_a_cube_sharp_on_thick_slices() {
    // The first-order fit is used on anisotropic voxels only; on a cube it must not round
    // the edges off (it did on cubic voxels, where it is not used).
    let cube = Cuboid { half: DVec3::new(6.0, 6.0, 7.5) };
    let surface =
        DigitalSurface::from_volume(&digitize_labels(&Solid(&cube), DVec3::new(1.0, 1.0, 2.5))).unwrap();
    let normals = Trivial.estimate(&surface).unwrap();
    let out =
        Regularizer::new(surface.clone()).run(Run::new(&Params::default()).from_normals(&normals)).unwrap();
    let worst = surface
        .surfels()
        .iter()
        .zip(normals.as_slice())
        .map(|(s, n)| {
            let [a, b, c, d] = s.vertices.map(|v| out.positions[v.index()]);
            (c - a).cross(d - b).normalize().dot(*n).abs().min(1.0).acos().to_degrees()
        })
        .fold(0.0, f64::max);
    eprintln!("cube at (1, 1, 2.5): worst face {worst:.2} degrees");
    assert!(worst <= 5.0, "{worst}");
}

/// A spherical shell: label 1 inside radius `inner`, 2 out to `outer`, background past it.
struct Shell {
    inner: f64,
    outer: f64,
}

impl LabelShape for Shell {
    fn label(&self, p: DVec3) -> u32 {
        let r = p.length();
        if r <= self.inner {
            1
        } else if r <= self.outer {
            2
        } else {
            0
        }
    }
    fn bounds(&self) -> (DVec3, DVec3) {
        (DVec3::splat(-self.outer - 1.0), DVec3::splat(self.outer + 1.0))
    }
    fn name(&self) -> &'static str {
        "shell"
    }
    fn interface(&self, a: u32, b: u32, p: DVec3) -> Option<(DVec3, DVec3)> {
        let r = match (a, b) {
            (1, 2) => self.inner,
            (0, 2) => self.outer,
            _ => return None,
        };
        let n = p.normalize_or(DVec3::Z);
        Some((r * n, n))
    }
    fn junction(&self, _: &[u32], _: DVec3) -> Option<(DVec3, voxreg_testkit::JunctionKind)> {
        None
    }
}

#[test]
fn thin_shells_keep_their_place() {
    // Sheets 1.8 and 2.2 voxels thick: the thin-sheet rule keeps the first refinement
    // round's normals on them, which costs a little of the later rounds' accuracy (mean
    // 0.0325 against 0.0261 and 0.0338 against 0.0310) for rounds that settle.
    for (inner, outer, mean) in [(15.2, 17.0, 0.035), (20.3, 22.5, 0.036)] {
        let shell = Shell { inner, outer };
        let held = fidelity(&shell, DVec3::ONE, &Params::default());
        let mut every_round = Params::default();
        every_round.refinement_mut().sheet_thickness = 0.0;
        let free = fidelity(&shell, DVec3::ONE, &every_round);
        eprintln!("shell {inner}..{outer}: {:?}, every round refined {:?}", held.surface, free.surface);
        assert!(held.surface.mean <= mean && held.surface.max <= 0.2, "{held:?}");
        assert!(held.surface.mean <= 1.3 * free.surface.mean, "{held:?}\n{free:?}");
    }
}
