//! Progress reports: every stage of every level in order, fractions from 0 to 1 that never
//! go back within a stage, reports during the collapses, and the same levels as without
//! them.

use glam::DVec3;
use voxreg_digisurf::{DigitalSurface, LabelVolume};
use voxreg_io::QuadMesh;
use voxreg_simplify::{
    pyramid_targets, simplify_levels, simplify_levels_reporting, Interrupt, Options, Progress, Stage,
};

/// Two labels in the halves of a ball, as a staircase of quads.
fn split_ball(n: usize) -> QuadMesh {
    let c = n as f64 * 0.5;
    let r = n as f64 * 0.42;
    let volume = LabelVolume::from_fn([n, n, n], |[x, y, z]| {
        let p = DVec3::new(x as f64, y as f64, z as f64) + 0.5 - c;
        if p.length() > r {
            0
        } else if p.x < 0.0 {
            1
        } else {
            2
        }
    });
    let surface = DigitalSurface::from_volume(&volume).unwrap();
    QuadMesh::from_surface(&surface, &surface.positions())
}

#[test]
fn progress_reports_every_stage_in_order_and_changes_nothing() {
    let input = split_ball(40);
    let targets = pyramid_targets(3, 4.0, 0.5);
    let mut seen: Vec<Progress> = Vec::new();
    let levels =
        simplify_levels_reporting(&input, &targets, &Options::default(), &Interrupt::never(), &mut |p| {
            seen.push(*p)
        })
        .unwrap();

    // The same levels as without reports.
    let plain = simplify_levels(&input, &targets, &Options::default()).unwrap();
    assert_eq!(levels.len(), plain.len());
    for (a, b) in levels.iter().zip(&plain) {
        assert_eq!(a.mesh.quads, b.mesh.quads);
        assert_eq!(a.mesh.positions, b.mesh.positions);
    }

    // Setup once, then each level's collapses, flips and pairing, each opened at 0 and
    // closed at 1 (a pairing other than the last level's overlaps the next level's
    // collapses and is only opened), fractions in [0, 1] and non-decreasing within a stage.
    let order = |p: &Progress| {
        let s = match p.stage {
            Stage::Setup => 0,
            Stage::Collapses => 1,
            Stage::Flips => 2,
            Stage::Pairing => 3,
        };
        if p.stage == Stage::Setup {
            0
        } else {
            1 + 3 * p.level + (s - 1)
        }
    };
    assert!(seen.iter().all(|p| p.levels == 3 && p.level < 3 && (0.0..=1.0).contains(&p.fraction)));
    for w in seen.windows(2) {
        let (a, b) = (&w[0], &w[1]);
        assert!(order(a) <= order(b), "{a:?} then {b:?}");
        if order(a) == order(b) {
            assert!(a.fraction <= b.fraction, "{a:?} then {b:?}");
        }
    }
    for stage in 0..(1 + 3 * 3) {
        let of: Vec<f64> = seen.iter().filter(|p| order(p) == stage).map(|p| p.fraction).collect();
        assert_eq!(of.first(), Some(&0.0), "stage {stage} not opened at 0");
        let handed_off = stage > 0 && stage % 3 == 0 && stage < 3 * 3;
        if !handed_off {
            assert_eq!(of.last(), Some(&1.0), "stage {stage} not closed at 1");
        }
    }
    // The first level's collapses (to a quarter of about 13k triangles) report between
    // their ends, and reach most of the way there.
    let first: Vec<f64> = seen
        .iter()
        .filter(|p| p.level == 1 && p.stage == Stage::Collapses)
        .map(|p| p.fraction)
        .filter(|&f| f > 0.0 && f < 1.0)
        .collect();
    assert!(first.len() >= 3, "{first:?}");
    assert!(first.last().unwrap() > &0.5, "{first:?}");
    assert_eq!(Stage::Collapses.label(), "collapses");
    // One bar for the whole run: from 0 to 1, never back.
    let overall: Vec<f64> = seen.iter().map(Progress::overall).collect();
    assert_eq!(overall.first(), Some(&0.0));
    assert!((overall.last().unwrap() - 1.0).abs() < 1e-12, "{overall:?}");
    assert!(overall.windows(2).all(|w| w[0] <= w[1]), "{overall:?}");
}
