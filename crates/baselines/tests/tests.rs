//! Baselines against analytic shapes: each test fails if its method or metric breaks.
//!
//! - marching cubes: every cube configuration closed and oriented; digitized sphere and
//!   torus closed, oriented, with the digital surface's Euler characteristic, near the
//!   true surface;
//! - smoothing: Taubin shrinks less than Laplacian and both smooth the normals;
//! - dual contouring: closed, oriented; finer quantization is more accurate;
//! - shrouds: dual of the digital surface, parameters in bounds, energy decreases,
//!   closer to the sphere than the staircase; pinches kept apart; refuses junctions;
//! - metrics: the digital surface is at distance 0 from itself; Proposition 1 scaling.

use glam::DVec3;
use voxreg_baselines::{
    accuracy, distance_to, dual_contour, laplacian_smooth, marching_cubes, marching_cubes_volume, quality,
    quantize, shrouds, taubin_smooth, BaselineError, DcParams, LaplacianParams, Mesh, QualityParams,
    ScalarGrid, ShroudsParams, TaubinParams, TriangleIndex,
};
use voxreg_digisurf::{DigitalSurface, LabelVolume};
use voxreg_testkit::{digitize, Shape, Sphere, Torus};

fn check_closed_oriented(mesh: &Mesh, what: &str) {
    assert!(mesh.num_faces() > 0, "{what}: empty");
    assert!(mesh.is_closed(), "{what}: not closed");
    assert!(mesh.is_consistently_oriented(), "{what}: not consistently oriented");
    assert!(mesh.signed_volume() > 0.0, "{what}: oriented inward");
}

#[test]
fn marching_cubes_closes_every_cube_configuration() {
    for config in 1..=255u32 {
        let volume = LabelVolume::from_fn([2, 2, 2], |[x, y, z]| config >> (x + 2 * y + 4 * z) & 1);
        let mesh = marching_cubes_volume(&volume, |l| l == 1);
        check_closed_oriented(&mesh, &format!("config {config:#010b}"));
        // Each component is a sphere: inside corners are 6-connected, and a 2x2x2 block
        // holds no tunnel.
        assert_eq!(mesh.euler_characteristic() % 2, 0, "config {config:#010b}");
        let inside = config.count_ones() as f64;
        assert!(mesh.signed_volume() < inside, "config {config:#010b}");
    }
}

#[test]
fn marching_cubes_of_a_digitized_sphere_and_torus() {
    for (shape, h) in
        [(&Sphere { radius: 10.0 } as &dyn Shape, 1.0), (&Torus { major: 6.0, minor: 2.0 }, 0.25)]
    {
        let volume = digitize(shape, h);
        let surface = DigitalSurface::from_volume(&volume).unwrap();
        let mesh = marching_cubes_volume(&volume, |l| l == 1);
        check_closed_oriented(&mesh, shape.name());
        assert_eq!(mesh.euler_characteristic(), surface.euler_characteristic(), "{}", shape.name());
        let acc = accuracy(&mesh, &shape);
        assert!(acc.distance_mean < 0.3 * h && acc.distance_max < 0.8 * h, "{}: {acc:?}", shape.name());
        assert!(acc.normal_mean_deg < 25.0, "{}: {acc:?}", shape.name());
        let digital = Mesh::from_surface(&surface, &surface.positions());
        let staircase = accuracy(&digital, &shape);
        assert!(acc.normal_mean_deg < staircase.normal_mean_deg, "{acc:?} vs {staircase:?}");
        // Every MC vertex of a binary volume is the midpoint of two voxel centres across
        // the surface: a surfel centre, on the digital surface.
        let d = distance_to(&mesh, &TriangleIndex::new(&digital));
        assert!(d.max < 1e-12, "{d:?}");
    }
}

#[test]
fn marching_cubes_of_the_exact_function_is_more_accurate() {
    let sphere = Sphere { radius: 8.0 };
    let volume = digitize(&sphere, 1.0);
    let binary = marching_cubes_volume(&volume, |l| l == 1);
    let exact = marching_cubes(&ScalarGrid::sample(&sphere, &volume), 0.0);
    check_closed_oriented(&exact, "sphere, exact values");
    let (b, e) = (accuracy(&binary, &sphere), accuracy(&exact, &sphere));
    assert!(e.distance_max < 0.05 && e.distance_mean < 0.2 * b.distance_mean, "{e:?} vs {b:?}");
}

#[test]
fn taubin_shrinks_less_than_laplacian() {
    let sphere = Sphere { radius: 10.0 };
    let volume = digitize(&sphere, 1.0);
    let mc = marching_cubes_volume(&volume, |l| l == 1);
    let lap = laplacian_smooth(&mc, &LaplacianParams { iterations: 20, lambda: 0.5 });
    let tau = taubin_smooth(&mc, &TaubinParams { iterations: 20, ..Default::default() });
    let (m, l, t) = (accuracy(&mc, &sphere), accuracy(&lap, &sphere), accuracy(&tau, &sphere));
    assert!(l.bias < -0.1, "laplacian should shrink: {l:?}");
    assert!(t.bias.abs() < 0.5 * l.bias.abs(), "taubin {t:?} vs laplacian {l:?}");
    assert!(
        l.normal_mean_deg < m.normal_mean_deg && t.normal_mean_deg < m.normal_mean_deg,
        "{m:?} {l:?} {t:?}"
    );
    check_closed_oriented(&tau, "taubin");
    assert_eq!(lap.num_faces(), mc.num_faces());
}

#[test]
fn dual_contouring_from_binary_and_quantized_data() {
    let sphere = Sphere { radius: 8.0 };
    let volume = digitize(&sphere, 1.0);
    let surface = DigitalSurface::from_volume(&volume).unwrap();
    let binary = dual_contour(&ScalarGrid::indicator(&volume, |l| l == 1), 0.5, &DcParams::default());
    check_closed_oriented(&binary, "dc binary");
    // One quad per surfel: each crossed grid edge is a surfel's dual edge.
    assert_eq!(binary.num_faces(), surface.num_surfels());
    let exact = ScalarGrid::sample(&sphere, &volume);
    let errors: Vec<f64> = [1, 2, 4, 8]
        .iter()
        .map(|&bits| {
            let mesh = dual_contour(&quantize(&exact, bits, 2.0), 0.0, &DcParams::default());
            check_closed_oriented(&mesh, &format!("dc {bits} bits"));
            accuracy(&mesh, &sphere).distance_mean
        })
        .collect();
    let b = accuracy(&binary, &sphere).distance_mean;
    assert!((errors[0] - b).abs() < 1e-9, "1 bit is the binary map: {errors:?} vs {b}");
    assert!(errors[3] < 0.05 && errors[3] < errors[1] && errors[1] < errors[0], "{errors:?}");
}

#[test]
fn quantization_keeps_signs_and_levels() {
    let grid =
        ScalarGrid::new([5, 1, 1], DVec3::ZERO, DVec3::ONE, vec![-3.0, -0.1, 0.0, 0.4, 9.0], -10.0).unwrap();
    let q1 = quantize(&grid, 1, 1.0);
    assert_eq!(q1.values(), &[-0.5, -0.5, 0.5, 0.5, 0.5]);
    let q2 = quantize(&grid, 2, 1.0);
    assert_eq!(q2.values(), &[-0.75, -0.25, 0.25, 0.25, 0.75]);
    assert!(ScalarGrid::new([2, 1, 1], DVec3::ZERO, DVec3::ONE, vec![0.0], 0.0).is_err());
}

#[test]
fn shrouds_of_a_digitized_sphere() {
    let sphere = Sphere { radius: 8.0 };
    let volume = digitize(&sphere, 1.0);
    let surface = DigitalSurface::from_volume(&volume).unwrap();
    let params = ShroudsParams::default();
    let (mesh, info) = shrouds(&surface, &params).unwrap();
    check_closed_oriented(&mesh, "shrouds");
    assert_eq!(mesh.positions.len(), surface.num_surfels());
    assert_eq!(mesh.num_faces(), surface.num_vertices());
    assert_eq!(mesh.euler_characteristic(), surface.euler_characteristic());
    assert!(info.parameters.iter().all(|&t| t >= params.eps && t <= 1.0 - params.eps));
    assert!(
        info.energy_after < 0.5 * info.energy_before,
        "energy {} -> {} in {} sweeps",
        info.energy_before,
        info.energy_after,
        info.iterations
    );
    let staircase = accuracy(&Mesh::from_surface(&surface, &surface.positions()), &sphere);
    let start = {
        let (m, _) = shrouds(&surface, &ShroudsParams { max_iterations: 0, ..params }).unwrap();
        accuracy(&m, &sphere)
    };
    let acc = accuracy(&mesh, &sphere);
    assert!(
        acc.distance_mean < start.distance_mean && acc.distance_mean < staircase.distance_mean,
        "{acc:?} {start:?}"
    );
    assert!(acc.normal_mean_deg < start.normal_mean_deg, "{acc:?} {start:?}");
}

#[test]
fn shrouds_keeps_pinched_voxels_apart_and_refuses_junctions() {
    // Two voxels touching along an edge (an edge pinch with four surfels), and two
    // touching at a corner (a pinched vertex): two separate closed shrouds, like MC.
    for second in [[2, 2, 1], [2, 2, 2]] {
        let volume = LabelVolume::from_fn([4, 4, 4], |p| u32::from(p == [1, 1, 1] || p == second));
        let surface = DigitalSurface::from_volume(&volume).unwrap();
        let (mesh, _) = shrouds(&surface, &ShroudsParams::default()).unwrap();
        check_closed_oriented(&mesh, &format!("shrouds, voxels [1, 1, 1] and {second:?}"));
        assert_eq!(mesh.euler_characteristic(), 4, "two spheres");
        assert_eq!(
            mesh.euler_characteristic(),
            marching_cubes_volume(&volume, |l| l == 1).euler_characteristic()
        );
    }
    // Three regions meeting along edges.
    let volume =
        LabelVolume::from_fn([4, 3, 3], |[x, y, z]| if y == 1 && z == 1 && x > 0 { x as u32 } else { 0 });
    let surface = DigitalSurface::from_volume(&volume).unwrap();
    assert!(matches!(shrouds(&surface, &ShroudsParams::default()), Err(BaselineError::Unsupported(_))));
}

#[test]
fn metrics_of_the_digital_surface() {
    let sphere = Sphere { radius: 6.0 };
    let volume = digitize(&sphere, 0.5);
    let surface = DigitalSurface::from_volume(&volume).unwrap();
    let digital = Mesh::from_surface(&surface, &surface.positions());
    let index = TriangleIndex::new(&digital);
    assert_eq!(distance_to(&digital, &index).max, 0.0);
    let q = quality(&digital, &QualityParams::default());
    assert_eq!((q.faces, q.degenerate, q.inverted), (surface.num_surfels(), 0, 0));
    assert!((q.aspect_max - 1.0).abs() < 1e-12 && (q.jacobian_min - 1.0).abs() < 1e-12 && q.area_cv < 1e-12);
    assert!((q.area_mean - 0.25).abs() < 1e-12);
    // The staircase lies within sqrt(3)/2 h of the sphere (Gauss digitization).
    let acc = accuracy(&digital, &sphere);
    assert!(acc.distance_max <= 3f64.sqrt() / 2.0 * 0.5 + 1e-9, "{acc:?}");
}

#[test]
fn distance_to_the_digital_surface_is_o_of_h() {
    // Proposition 1's scaling for a surface within O(h) of the staircase: halving h about
    // halves the mean distance of the digital surface's vertices to the MC surface.
    let sphere = Sphere { radius: 5.0 };
    let d: Vec<f64> = [0.5, 0.25]
        .iter()
        .map(|&h| {
            let volume = digitize(&sphere, h);
            let surface = DigitalSurface::from_volume(&volume).unwrap();
            let index = TriangleIndex::new(&marching_cubes_volume(&volume, |l| l == 1));
            distance_to(&Mesh::from_surface(&surface, &surface.positions()), &index).mean
        })
        .collect();
    assert!(d[1] < 0.7 * d[0] && d[1] > 0.3 * d[0], "{d:?}");
}
