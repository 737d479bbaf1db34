//! Unit tests of the refined normals.

use voxreg_digisurf::SurfelId;
use voxreg_testkit::{
    digitize, digitize_labels, vertex_labels, LabelShape, Lcg, Shape, Solid, Sphere, SplitBall, Torus,
};

use super::*;

/// The disc search written plainly (edges walked per quad, distances recomputed, each
/// quad's reach found by relaxing `reach_k = max(reach_k, pass_g)` over the disc's
/// edges until nothing changes): the reference the widest-first search must match (to
/// rounding: the same terms, summed in another order).
fn reference(surface: &DigitalSurface, positions: &[DVec3], field: &NormalField, radius: f64) -> Vec<DVec3> {
    let n = surface.num_surfels();
    let r = radius * surface.spacing().max_element();
    let ramp = FeatureRamp::new(30.0);
    let areas: Vec<DVec3> = (0..n).map(|s| area_vector(surface, positions, s)).collect();
    let centres: Vec<DVec3> = surface
        .surfels()
        .iter()
        .map(|s| s.vertices.iter().map(|v| positions[v.index()]).sum::<DVec3>() / 4.0)
        .collect();
    (0..n)
        .map(|f| {
            let nf = field.as_slice()[f];
            let regions = surface.surfels()[f].regions;
            let neighbours = |g: usize| -> Vec<usize> {
                let mut out = Vec::new();
                for e in surface.surfel_edges(SurfelId(g as u32)) {
                    for &k in surface.edge_surfels(e) {
                        let k = k.index();
                        let other = surface.surfels()[k].regions;
                        if k != g
                            && surface.surfels()[g].regions.iter().any(|r| other.contains(r))
                            && other.iter().any(|r| regions.contains(r))
                            && centres[k].distance(centres[f]) < r
                        {
                            out.push(k);
                        }
                    }
                }
                out
            };
            let cos = |g: usize| {
                let len = areas[g].length();
                if len > 0.0 {
                    areas[g].dot(nf) / len
                } else {
                    0.0
                }
            };
            let phi = |g: usize| if g == f { 1.0 } else { ramp.weight(cos(g).abs()) };
            let mut reach = std::collections::HashMap::from([(f, 1.0f64)]);
            loop {
                let mut changed = false;
                for (g, rg) in reach.clone() {
                    let d = centres[g].distance(centres[f]);
                    let pass = phi(g).min(rg).min((1.0 - d / r) / RIM_FRACTION);
                    if pass <= 0.0 {
                        continue;
                    }
                    for k in neighbours(g) {
                        let e = reach.entry(k).or_insert(0.0);
                        if pass > *e {
                            *e = pass;
                            changed = true;
                        }
                    }
                }
                if !changed {
                    break;
                }
            }
            let mut sum = DVec3::ZERO;
            for (&g, &rg) in &reach {
                let d = centres[g].distance(centres[f]);
                sum += (1.0 - d / r) * phi(g).min(rg) * areas[g] * cos(g).signum();
            }
            let own = ramp.weight(cos(f).abs());
            let m = sum.normalize_or_zero();
            if own <= 0.0 || m == DVec3::ZERO {
                nf
            } else {
                (own * m + (1.0 - own) * nf).normalize()
            }
        })
        .collect()
}

/// [`refined_interruptible`] with the probe, never interrupted.
fn refined(
    estimator: Refined<'_>,
    surface: &DigitalSurface,
    blend: f64,
    near_junction: &[bool],
) -> NormalField {
    refined_interruptible(&estimator, surface, blend, near_junction, true, None, &Interrupt::never())
}

#[test]
fn matches_the_reference_disc_search() {
    let mut rng = Lcg::new(7);
    for volume in [digitize(&Sphere { radius: 6.3 }, 1.0), digitize(&Torus { major: 6.0, minor: 2.5 }, 0.5)] {
        let surface = DigitalSurface::from_volume(&volume).unwrap();
        let positions: Vec<DVec3> =
            surface.positions().iter().map(|p| *p + 0.3 * rng.vec3(-1.0, 1.0)).collect();
        let field = NormalField::new(surface.surfels().iter().map(|s| s.normal()).collect());
        let fast = Refined { positions: &positions, previous: &field, radius: 3.0, feature_angle_deg: 30.0 }
            .estimate(&surface)
            .unwrap();
        let slow = reference(&surface, &positions, &field, 3.0);
        for (a, b) in fast.as_slice().iter().zip(&slow) {
            assert!((*a - *b).length() < 1e-12, "{a} vs {b}");
        }
    }
}

/// Mean angle (degrees) between each quad's refined normal and the sphere's normal at
/// the quad's centre.
fn sphere_error(surface: &DigitalSurface, on_sphere: &[DVec3], field: &NormalField) -> f64 {
    let errors: Vec<f64> = surface
        .surfels()
        .iter()
        .zip(field.as_slice())
        .map(|(s, n)| {
            let c = s.vertices.iter().map(|v| on_sphere[v.index()]).sum::<DVec3>() / 4.0;
            n.dot(c.normalize()).abs().min(1.0).acos().to_degrees()
        })
        .collect();
    voxreg_testkit::mean_max(&errors).0
}

#[test]
fn the_fit_removes_the_tilt_of_uneven_discs_on_thick_slices() {
    // Quads on the exact sphere, sampled on slices 2.5 and 5 times thicker than the
    // in-plane spacing: the plain mean is tilted by the uneven quad areas, the fit
    // is closer to the analytic normal.
    let sphere = Sphere { radius: 12.0 };
    for spacing in [DVec3::new(1.0, 1.0, 2.5), DVec3::new(1.0, 1.0, 5.0), DVec3::new(1.0, 2.0, 3.0)] {
        let surface = DigitalSurface::from_volume(&digitize_labels(&Solid(&sphere), spacing)).unwrap();
        let on_sphere: Vec<DVec3> = surface.positions().iter().map(|p| sphere.project(*p)).collect();
        let start = NormalField::new(surface.surfels().iter().map(|s| s.normal()).collect());
        let no_junction = vec![false; surface.num_surfels()];
        let [plain, fit] = [0.0, 1.0].map(|blend| {
            sphere_error(
                &surface,
                &on_sphere,
                &refined(
                    Refined { positions: &on_sphere, previous: &start, radius: 3.0, feature_angle_deg: 90.0 },
                    &surface,
                    blend,
                    &no_junction,
                ),
            )
        });
        eprintln!("spacing {spacing}: plain mean {plain:.3} deg, fit {fit:.3} deg");
        assert!(fit < 0.5 * plain, "spacing {spacing}: plain mean {plain:.3} deg, fit {fit:.3} deg");
    }
}

#[test]
fn cubic_voxels_take_the_plain_mean() {
    for h in [1.0, 0.3, 2.0] {
        assert_eq!(anisotropic_fit_weight(DVec3::splat(h)), 0.0);
    }
    assert_eq!(anisotropic_fit_weight(DVec3::new(1.0, 1.0, 1.5)), 0.5);
    assert_eq!(anisotropic_fit_weight(DVec3::new(2.0, 1.0, 5.0)), 1.0);
    // At unit spacing the estimator is the plain mean, bit for bit.
    let surface = DigitalSurface::from_volume(&digitize(&Sphere { radius: 5.2 }, 1.0)).unwrap();
    let mut rng = Lcg::new(11);
    let positions: Vec<DVec3> = surface.positions().iter().map(|p| *p + 0.2 * rng.vec3(-1.0, 1.0)).collect();
    let field = NormalField::new(surface.surfels().iter().map(|s| s.normal()).collect());
    let estimator = Refined { positions: &positions, previous: &field, radius: 3.0, feature_angle_deg: 30.0 };
    let estimated = estimator.estimate(&surface).unwrap();
    let no_junction = vec![false; surface.num_surfels()];
    assert_eq!(estimated, refined(estimator, &surface, 0.0, &no_junction));
}

#[test]
fn the_wide_disc_probe_changes_no_normal() {
    // Junction curves that are smooth continuations (the split ball's sphere) and
    // creases (its cut disc against the sphere; boxes of five labels), at jittered
    // positions: the estimate with the probe is the full search's, bit for bit.
    let mut rng = Lcg::new(11);
    let ball = SplitBall { radius: 9.0, cut: 0.5 };
    let volumes = [
        digitize_labels(&ball, DVec3::ONE),
        voxreg_digisurf::LabelVolume::from_fn([12, 11, 10], |[x, y, z]| {
            1 + u32::from(x > 5) + u32::from(y > 4) + 2 * u32::from(z > 6 && x > 2)
        })
        .with_background(Some(0)),
        // Junctions nearly everywhere (as in a porous medium of several phases): blocks
        // of two voxels of four labels at random, where most quads are near a junction
        // and most wide discs are ruled out by the interior quads' test alone.
        {
            let mut blocks = Lcg::new(5);
            let labels: Vec<u32> = (0..8 * 8 * 8).map(|_| blocks.next_u32() % 4).collect();
            voxreg_digisurf::LabelVolume::from_fn([16, 16, 16], |[x, y, z]| {
                labels[x / 2 + 8 * (y / 2 + 8 * (z / 2))]
            })
        },
    ];
    for volume in &volumes {
        let surface = DigitalSurface::from_volume(volume).unwrap();
        let positions: Vec<DVec3> =
            surface.positions().iter().map(|p| *p + 0.2 * rng.vec3(-1.0, 1.0)).collect();
        let field = crate::trivial::Trivial.estimate(&surface).unwrap();
        let near = near_junction_surfels(&surface);
        assert!(near.iter().any(|&n| n));
        let never = Interrupt::never();
        let run = |probe: bool, hints: Option<&mut Vec<bool>>| {
            let estimator =
                Refined { positions: &positions, previous: &field, radius: 3.0, feature_angle_deg: 30.0 };
            refined_interruptible(&estimator, &surface, 0.0, &near, probe, hints, &never)
        };
        let plain = run(false, None);
        assert_eq!(run(true, None), plain);
        // Hints from a first estimate, then any hints at all: the same estimate.
        let mut hints = vec![false; surface.num_surfels()];
        assert_eq!(run(true, Some(&mut hints)), plain);
        assert!(hints.iter().any(|&h| h), "no wide disc with a share");
        assert_eq!(run(true, Some(&mut hints)), plain);
        let mut all = vec![true; surface.num_surfels()];
        assert_eq!(run(true, Some(&mut all)), plain);
    }
}

#[test]
fn quads_near_a_junction_take_the_interior_of_their_surface() {
    // Quads on the split ball (each vertex on its true part: interface or junction
    // circle), the circle's vertices displaced. Next to the circle the plain mean
    // averages the bent quads; the interior's extrapolated mean is closer to the truth
    // (the truth at each quad's centre, from its interface).
    let ball = SplitBall { radius: 12.0, cut: 0.5 };
    let surface = DigitalSurface::from_volume(&digitize_labels(&ball, DVec3::ONE)).unwrap();
    let labels = vertex_labels(&surface);
    // The junction vertices pulled 0.3 voxel towards the axis, as the cut disc pulls
    // them: the quads touching the circle bend.
    let exact: Vec<DVec3> = surface
        .positions()
        .iter()
        .zip(&labels)
        .map(|(p, l)| match l.len() {
            2 => ball.interface(l[0], l[1], *p).unwrap().0,
            _ => {
                let q = ball.junction(l, *p).unwrap().0;
                q - 0.3 * DVec3::new(q.x, q.y, 0.0).normalize()
            }
        })
        .collect();
    let truth: Vec<DVec3> = surface
        .surfels()
        .iter()
        .map(|s| {
            let c = s.vertices.iter().map(|v| exact[v.index()]).sum::<DVec3>() / 4.0;
            let [a, b] = [s.labels[0].min(s.labels[1]), s.labels[0].max(s.labels[1])];
            let n = ball.interface(a, b, c).unwrap().1;
            if n.dot(s.normal()) < 0.0 {
                -n
            } else {
                n
            }
        })
        .collect();
    let previous = NormalField::new(truth.clone());
    let near = near_junction_surfels(&surface);
    assert!(near.iter().any(|&n| n) && near.iter().any(|&n| !n));
    let none = vec![false; surface.num_surfels()];
    let [plain, interior] = [&none, &near].map(|mask| {
        let estimator =
            Refined { positions: &exact, previous: &previous, radius: 3.0, feature_angle_deg: 30.0 };
        let field = refined(estimator, &surface, 0.0, mask);
        let errors: Vec<f64> = (0..surface.num_surfels())
            .filter(|&s| near[s])
            .map(|s| field.as_slice()[s].dot(truth[s]).min(1.0).acos().to_degrees())
            .collect();
        voxreg_testkit::mean_max(&errors)
    });
    eprintln!("near the junction: plain {plain:?} deg, interior {interior:?} deg");
    assert!(interior.0 < 0.5 * plain.0 && interior.1 < plain.1, "plain {plain:?}, interior {interior:?}");
}

#[test]
fn waiting_entries_order_as_their_triples() {
    // The packed entries of the widest-first search compare as (reach, quad, parent).
    let mut rng = Lcg::new(3);
    let reaches = [0.0, 1e-300, 0.25, 0.5, 0.5000000000000001, 0.75, 1.0];
    let triples: Vec<(f64, u32, u32)> = (0..400)
        .map(|_| {
            let r = reaches[(rng.next_u32() % reaches.len() as u32) as usize];
            // Quads at both ends of their range: small ids and ids near `u32::MAX`.
            let k = rng.next_u32() % 5;
            let k = if rng.next_u32() % 2 == 0 { k } else { u32::MAX - k };
            (r, k, rng.next_u32() % 4)
        })
        .collect();
    for a in &triples {
        for b in &triples {
            let by_tuple = a.0.partial_cmp(&b.0).unwrap().then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2));
            assert_eq!(
                waiting_entry(a.0, a.1, a.2).cmp(&waiting_entry(b.0, b.1, b.2)),
                by_tuple,
                "{a:?} {b:?}"
            );
        }
    }
}
