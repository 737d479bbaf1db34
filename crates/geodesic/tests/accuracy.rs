//! Accuracy against analytic shapes: geodesics on the regularized proxy of a digitized
//! sphere and torus against the true distances, the digital surface's own metric for
//! comparison, and the proxy's error as the grid refines. Release mode (`cargo test
//! --release -p voxreg-geodesic`); each shape is regularized once.

use glam::DVec3;
use voxreg_digisurf::LabelVolume;
use voxreg_geodesic::{exact_distances, exact_estimated_bytes, GeodesicMesh, HeatParams, HeatSolver};
use voxreg_regularize::{regularize, Params};
use voxreg_testkit::{digitize, Shape, Sphere, Torus};

/// The digital and regularized meshes of `volume` (one quad per surfel).
fn meshes(volume: &LabelVolume) -> (GeodesicMesh, GeodesicMesh) {
    let out = regularize(volume, &Params::default()).unwrap();
    let quads: Vec<[u32; 4]> = out.surface.surfels().iter().map(|s| s.vertices.map(|v| v.0)).collect();
    let digital = GeodesicMesh::new(out.surface.positions().as_slice(), &quads).unwrap();
    let proxy = GeodesicMesh::new(&out.positions, &quads).unwrap();
    (digital, proxy)
}

/// Mean and max relative error of `d` against `truth` over the vertices farther than
/// `near` from the source (relative errors near the source measure the source's
/// placement, not the metric).
fn relative_errors(d: &[f64], truth: &[f64], near: f64) -> (f64, f64) {
    let (mut sum, mut max, mut count) = (0.0, 0.0f64, 0);
    for (&d, &t) in d.iter().zip(truth) {
        if t > near {
            let e = (d - t).abs() / t;
            sum += e;
            max = max.max(e);
            count += 1;
        }
    }
    (sum / count as f64, max)
}

/// Great-circle distances on the sphere of `radius` from the direction of `positions[source]`.
fn great_circle(positions: &[DVec3], source: u32, radius: f64) -> Vec<f64> {
    let pole = positions[source as usize].normalize();
    positions.iter().map(|p| radius * pole.angle_between(*p)).collect()
}

/// The windows a run created fit in the memory estimate's share for them (128 bytes
/// each), with the estimate's model of their count.
fn assert_within_estimate(mesh: &GeodesicMesh, windows: usize) {
    let estimate = exact_estimated_bytes(mesh.triangles().len());
    let per_triangle = windows as f64 / mesh.triangles().len() as f64;
    assert!(
        (windows as u64) * 128 <= estimate,
        "{windows} windows ({per_triangle:.1} per triangle) against {estimate} B"
    );
}

fn positions(mesh: &GeodesicMesh, volume_positions: impl Fn(u32) -> DVec3) -> Vec<DVec3> {
    (0..mesh.num_vertices() as u32).map(volume_positions).collect()
}

#[test]
fn sphere_proxy_geodesics_match_great_circles_and_beat_the_digital_metric() {
    let radius = 20.0;
    let volume = digitize(&Sphere { radius }, 1.0);
    let (digital, proxy) = meshes(&volume);
    let out_positions = |m: &GeodesicMesh| positions(m, |v| m.position(v));
    let pp = out_positions(&proxy);
    let source = proxy.nearest_vertex(DVec3::new(0.0, 0.0, radius)).unwrap();
    let truth = great_circle(&pp, source, radius);
    let near = 3.0;

    let (exact, info) = exact_distances(&proxy, &[source]).unwrap();
    assert_within_estimate(&proxy, info.windows);
    let (mean, max) = relative_errors(&exact, &truth, near);
    let heat = HeatSolver::new(proxy.clone(), &HeatParams::default()).unwrap().distances(&[source]).unwrap();
    let (heat_mean, heat_max) = relative_errors(&heat, &truth, near);
    // The digital surface's metric, from the same vertex, against the same truth.
    let (staircase, _) = exact_distances(&digital, &[source]).unwrap();
    let (digital_mean, digital_max) = relative_errors(&staircase, &truth, near);
    eprintln!(
        "sphere r = 20: proxy exact mean {:.3}% max {:.3}%; heat mean {:.3}% max {:.3}%; \
         digital exact mean {:.3}% max {:.3}%",
        100.0 * mean,
        100.0 * max,
        100.0 * heat_mean,
        100.0 * heat_max,
        100.0 * digital_mean,
        100.0 * digital_max
    );
    assert!(mean < 0.01 && max < 0.03, "proxy: mean {mean}, max {max}");
    assert!(heat_mean < 0.03, "heat: mean {heat_mean}");
    assert!(digital_mean > 2.0 * mean, "digital mean {digital_mean} vs proxy {mean}");
}

#[test]
fn torus_meridian_distances_and_heat_agree_with_exact() {
    let torus = Torus { major: 16.0, minor: 8.0 };
    let volume = digitize(&torus, 1.0);
    let (_, proxy) = meshes(&volume);
    // Source on the outer equator at angle 0.
    let source = proxy.nearest_vertex(DVec3::new(torus.major + torus.minor, 0.0, 0.0)).unwrap();
    let (exact, info) = exact_distances(&proxy, &[source]).unwrap();
    assert_within_estimate(&proxy, info.windows);
    // On the source's meridian (y near 0, x > 0) the distance is the arc of the tube
    // circle, r * theta, with r the proxy's mean tube radius (the regularized tube is
    // a little thinner than the digitized one).
    let tube = |p: DVec3| p - DVec3::new(p.x, p.y, 0.0).normalize() * torus.major;
    let r = (0..proxy.num_vertices() as u32).map(|v| tube(proxy.position(v)).length()).sum::<f64>()
        / proxy.num_vertices() as f64;
    let mut errors = Vec::new();
    for v in 0..proxy.num_vertices() as u32 {
        let p = proxy.position(v);
        if p.y.abs() < 0.5 && p.x > 0.0 {
            let q = torus.project(p);
            let c = DVec3::new(torus.major, 0.0, 0.0);
            let theta = (q - c).angle_between(DVec3::X);
            let truth = r * theta;
            if truth > 3.0 {
                errors.push((exact[v as usize] - truth).abs() / truth);
            }
        }
    }
    let mean = errors.iter().sum::<f64>() / errors.len() as f64;
    eprintln!(
        "torus meridian (tube radius {r:.3}): {} vertices, mean relative error {:.3}%",
        errors.len(),
        100.0 * mean
    );
    assert!(errors.len() > 20 && mean < 0.02, "{} vertices, mean {mean}", errors.len());

    let heat = HeatSolver::new(proxy.clone(), &HeatParams::default()).unwrap().distances(&[source]).unwrap();
    let (heat_mean, _) = relative_errors(&heat, &exact, 3.0);
    assert!(heat_mean < 0.03, "heat against exact: mean {heat_mean}");
}

#[test]
fn the_proxy_error_shrinks_as_the_grid_refines() {
    let mut means = Vec::new();
    for h in [0.5, 0.25, 0.125] {
        let volume = digitize(&Sphere { radius: 2.0 }, h);
        let (_, proxy) = meshes(&volume);
        let pp: Vec<DVec3> = (0..proxy.num_vertices() as u32).map(|v| proxy.position(v)).collect();
        let source = proxy.nearest_vertex(DVec3::new(0.0, 0.0, 2.0)).unwrap();
        let truth = great_circle(&pp, source, 2.0);
        let (exact, _) = exact_distances(&proxy, &[source]).unwrap();
        means.push(relative_errors(&exact, &truth, 0.5).0);
    }
    eprintln!("sphere r = 4, 8, 16 voxels: proxy mean relative error {means:?}");
    assert!(means[1] < means[0] && means[2] < means[1], "{means:?}");
}

#[test]
fn multi_label_surfaces_with_non_manifold_edges() {
    // Two labelled boxes side by side: where they meet the background, edges carry three
    // surfels. Distances cross the interface wall and stay between the bounds.
    let volume = LabelVolume::from_fn([10, 6, 6], |[x, y, z]| {
        let inside = (1..9).contains(&x) && (1..5).contains(&y) && (1..5).contains(&z);
        if !inside {
            0
        } else if x < 5 {
            1
        } else {
            2
        }
    });
    let (digital, proxy) = meshes(&volume);
    for mesh in [&digital, &proxy] {
        let source = mesh.nearest_vertex(DVec3::new(0.0, 0.0, 0.0)).unwrap();
        let (exact, _) = exact_distances(mesh, &[source]).unwrap();
        let heat =
            HeatSolver::new(mesh.clone(), &HeatParams::default()).unwrap().distances(&[source]).unwrap();
        let s = mesh.position(source);
        for v in 0..mesh.num_vertices() as u32 {
            let d = exact[v as usize];
            assert!(d.is_finite() && d >= mesh.position(v).distance(s) - 1e-9, "vertex {v}: {d}");
        }
        let (mean, _) = relative_errors(&heat, &exact, 2.0);
        assert!(mean < 0.05, "heat against exact: {mean}");
    }
}
