//! The run's memory estimate is an upper bound: the peak resident memory a run adds,
//! from the volume to the output, stays below `Regularizer::estimated_bytes_of` on
//! single- and multi-label surfaces, with every preset and normal estimator.
//!
//! Each case runs in a child process (this test binary, re-run on one case), which
//! builds its volume, resets the kernel's peak resident set (`/proc/self/clear_refs`),
//! runs, and reports the peak above its resident set before the run: a fresh process,
//! so no memory freed by an earlier case is reused unseen.

use glam::{DVec2, DVec3};
use voxreg_digisurf::LabelVolume;
use voxreg_regularize::{Estimator, Params, Regularizer};
use voxreg_testkit::{digitize, digitize_labels, QuarteredBall, Sphere, SplitBall, Torus};

const CASE: &str = "VOXREG_MEMORY_CASE";

fn volume(name: &str) -> LabelVolume {
    match name {
        "sphere" => digitize(&Sphere { radius: 1.0 }, 0.012),
        "torus" => digitize(&Torus { major: 1.0, minor: 0.4 }, 0.012),
        "split ball" => digitize_labels(&SplitBall { radius: 60.0, cut: 0.5 }, DVec3::ONE),
        "quartered ball" => digitize_labels(
            &QuarteredBall { radius: 60.0, centre: DVec3::new(0.5, 0.0, 0.5), cuts: DVec2::splat(0.5) },
            DVec3::ONE,
        ),
        _ => panic!("no volume {name}"),
    }
}

fn params(name: &str) -> Params {
    match name {
        "default" => Params::default(),
        "papers" => Params::papers(),
        "voxel art" => Params::voxel_art(),
        "fast" => Params::fast(),
        "at" => {
            let mut p = Params::default();
            p.normals.estimator = Estimator::At;
            p
        }
        "voxel art, at" => {
            let mut p = Params::voxel_art();
            p.normals.estimator = Estimator::At;
            p
        }
        _ => panic!("no preset {name}"),
    }
}

/// A field of `/proc/self/status`, in bytes.
fn status_bytes(field: &str) -> u64 {
    let status = std::fs::read_to_string("/proc/self/status").unwrap();
    let line = status.lines().find(|l| l.starts_with(field)).unwrap();
    line.split_whitespace().nth(1).unwrap().parse::<u64>().unwrap() * 1024
}

/// The child: runs the case named in the environment and prints its figures.
#[test]
fn memory_case() {
    let Ok(case) = std::env::var(CASE) else { return };
    let (shape, preset) = case.split_once('/').unwrap();
    let volume = volume(shape);
    let params = params(preset);
    let (_, estimate) = Regularizer::estimated_bytes_of(&volume, &params).unwrap();
    let before = status_bytes("VmRSS:");
    // Some sandboxes refuse the reset of the peak: nothing to measure there.
    if std::fs::write("/proc/self/clear_refs", "5").is_err() {
        println!("\nMEMORY unmeasured");
        return;
    }
    let out = Regularizer::from_volume(&volume, &params.regions).unwrap().run(&params).unwrap();
    let peak = status_bytes("VmHWM:") - before;
    assert!(out.report.converged());
    println!("\nMEMORY {peak} {estimate}");
}

/// Runs `shape` with `preset` in a child process; its peak and estimate (`None` where the
/// peak cannot be reset).
fn measured(shape: &str, preset: &str) -> Option<(u64, u64)> {
    let out = std::process::Command::new(std::env::current_exe().unwrap())
        .args(["memory_case", "--exact", "--nocapture", "--test-threads", "1"])
        .env(CASE, format!("{shape}/{preset}"))
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{shape}, {preset}: {stdout}{}", String::from_utf8_lossy(&out.stderr));
    let line = stdout.lines().find_map(|l| l.split_once("MEMORY ").map(|(_, f)| f)).unwrap();
    if line == "unmeasured" {
        return None;
    }
    let figures: Vec<u64> = line.split(' ').map(|f| f.parse().unwrap()).collect();
    Some((figures[0], figures[1]))
}

#[cfg(target_os = "linux")]
#[test]
fn runs_stay_within_the_memory_estimate() {
    let cases = [
        ("sphere", "default"),
        ("sphere", "papers"),
        ("sphere", "voxel art"),
        ("sphere", "at"),
        ("sphere", "voxel art, at"),
        ("torus", "default"),
        ("split ball", "default"),
        ("split ball", "voxel art"),
        ("split ball", "voxel art, at"),
        ("quartered ball", "default"),
        ("quartered ball", "at"),
        ("sphere", "fast"),
        ("split ball", "fast"),
        ("quartered ball", "fast"),
    ];
    for (shape, preset) in cases {
        let Some((peak, estimate)) = measured(shape, preset) else {
            eprintln!("{shape}, {preset}: the peak resident set cannot be reset here: not measured");
            continue;
        };
        eprintln!(
            "{shape}, {preset}: peak {:.1} MiB, estimate {:.1} MiB ({:.2})",
            peak as f64 / 1048576.0,
            estimate as f64 / 1048576.0,
            peak as f64 / estimate as f64
        );
        assert!(peak <= estimate, "{shape}, {preset}: peak {peak} B above the estimate {estimate} B");
    }
}
