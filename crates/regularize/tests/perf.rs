//! The solver benchmark table (ignored by default: minutes, and meant for a quiet machine):
//!
//! ```text
//! cargo test --release -p voxreg-regularize --test perf -- --ignored --nocapture
//! RADII=33,73 RUNS=3 NORMALS=trivial COARSEST=800 cargo test --release -p voxreg-regularize --test perf -- --ignored --nocapture
//! ```
//!
//! For digitized spheres (default radii 33, 73, 140, 282 voxels: about 20k, 100k, 367k and
//! 1.5M quads) it prints the multigrid CG's iterations, the median time of the whole
//! minimization (connectivity, hierarchy, coarse operators, iterations) over `RUNS` runs,
//! the time per iteration against the memory-bandwidth bound of the bytes one iteration
//! moves (the solver's traffic model over the measured streaming bandwidth), the solver's
//! memory and the process's peak memory, and the largest vertex distance to a reference
//! solved with the guaranteed rule at 1e-6 voxel.

use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;
use voxreg_digisurf::DigitalSurface;
use voxreg_normals::{NormalEstimator, NormalField, Trivial};
use voxreg_regularize::{CgParams, CgSolver, Energy, EnergyParams, StoppingRule};
use voxreg_testkit::{digitize, true_normals, Sphere};

/// Streaming bandwidth in GB/s: the best of 5 triads `a = b + s c` over 3 arrays of
/// `bytes` each, counting 4 streams (the store's write-allocate read included).
fn triad_bandwidth(bytes: usize) -> f64 {
    let n = bytes / 8;
    let (mut a, b, c) = (vec![0.0f64; n], vec![1.0f64; n], vec![2.0f64; n]);
    let mut best = f64::MAX;
    for _ in 0..5 {
        let t = Instant::now();
        a.par_chunks_mut(1 << 14).zip(b.par_chunks(1 << 14)).zip(c.par_chunks(1 << 14)).for_each(
            |((a, b), c)| {
                for i in 0..a.len() {
                    a[i] = b[i] + 0.5 * c[i];
                }
            },
        );
        best = best.min(t.elapsed().as_secs_f64());
    }
    std::hint::black_box(&a);
    4.0 * bytes as f64 / best * 1e-9
}

/// CPU time of all the process's threads, in seconds (from /proc/self/task/*/schedstat;
/// 0 where unavailable): less sensitive than wall time to other processes on a shared
/// machine.
fn cpu_seconds() -> f64 {
    let Ok(tasks) = std::fs::read_dir("/proc/self/task") else { return 0.0 };
    tasks
        .filter_map(|t| std::fs::read_to_string(t.ok()?.path().join("schedstat")).ok())
        .filter_map(|s| s.split_whitespace().next()?.parse::<f64>().ok())
        .sum::<f64>()
        * 1e-9
}

fn peak_rss_mib() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| s.lines().find(|l| l.starts_with("VmHWM:")).map(|l| l.to_string()))
        .and_then(|l| l.split_whitespace().nth(1).and_then(|k| k.parse::<f64>().ok()))
        .map_or(f64::NAN, |kib| kib / 1024.0)
}

#[test]
#[ignore]
fn solver_table() {
    let radii: Vec<f64> = std::env::var("RADII")
        .map(|v| v.split(',').map(|x| x.parse().unwrap()).collect())
        .unwrap_or(vec![33.0, 73.0, 140.0, 282.0]);
    let runs: usize = std::env::var("RUNS").map(|v| v.parse().unwrap()).unwrap_or(5);
    let trivial = std::env::var("NORMALS").is_ok_and(|v| v == "trivial");
    let dram = triad_bandwidth(256 << 20);
    let l3 = triad_bandwidth(8 << 20);
    eprintln!(
        "threads {}; streaming bandwidth: {dram:.1} GB/s (3 x 256 MB), {l3:.1} GB/s (3 x 8 MB)",
        rayon::current_num_threads()
    );
    eprintln!("| quads | vertices | levels | iterations | median time (s) | setup / iterate (s) | ms/iteration | bytes/iteration | bound at DRAM bw (ms) | solver memory (MiB) | peak RSS (MiB) | max error (voxel) |");
    eprintln!("|---|---|---|---|---|---|---|---|---|---|---|---|");
    for r in radii {
        let shape = Sphere { radius: r };
        let s = DigitalSurface::from_volume(&digitize(&shape, 1.0)).unwrap();
        let normals =
            if trivial { Trivial.estimate(&s).unwrap() } else { NormalField::new(true_normals(&s, &shape)) };
        let input = s.positions();
        let energy = Energy::new(&s, &normals, &input, EnergyParams::default()).unwrap();
        let mut times = Vec::new();
        let mut cpu = Vec::new();
        let mut last = None;
        for _ in 0..runs {
            let t = Instant::now();
            let c0 = cpu_seconds();
            let mut params = CgParams::default();
            if let Some(c) = std::env::var("COARSEST").ok().and_then(|c| c.parse().ok()) {
                params.multigrid.coarsest_nodes = c;
            }
            if let Some(c) = std::env::var("SMOOTH").ok().and_then(|c| c.parse().ok()) {
                params.multigrid.smoothing_steps = c;
            }
            if let Some(c) = std::env::var("COARSE_SMOOTH").ok().and_then(|c| c.parse().ok()) {
                params.multigrid.coarse_smoothing_steps = c;
            }
            if let Some(c) = std::env::var("DAMP").ok().and_then(|c| c.parse().ok()) {
                params.multigrid.damping = c;
            }
            let mut cg = CgSolver::for_surface(&s, params).unwrap();
            let levels = cg.levels();
            let (x, info) = cg.solve(&energy).unwrap();
            times.push(t.elapsed().as_secs_f64());
            cpu.push(cpu_seconds() - c0);
            last = Some((x, info, levels));
        }
        times.sort_by(f64::total_cmp);
        let median = times[times.len() / 2];
        cpu.sort_by(f64::total_cmp);
        eprintln!("cpu seconds per solve (all threads): median {:.3}, min {:.3}", cpu[cpu.len() / 2], cpu[0]);
        let (x, info, levels) = last.unwrap();
        let tight = CgParams { tolerance: 1e-6, stopping: StoppingRule::Guaranteed, ..Default::default() };
        let (reference, _) = CgSolver::for_surface(&s, tight).unwrap().solve(&energy).unwrap();
        let err =
            x.iter().zip(&reference).map(|(a, b): (&DVec3, &DVec3)| (*a - *b).length()).fold(0.0, f64::max);
        let setup = info.seconds.structure + info.seconds.assemble + info.seconds.factor;
        let per_iter = info.seconds.solve / info.iterations.max(1) as f64 * 1e3;
        let bytes = info.bytes_per_iteration as f64;
        eprintln!(
            "| {} | {} | {levels} | {} | {median:.3} | {setup:.3} / {:.3} | {per_iter:.1} | {:.0} MB | {:.1} | {:.0} | {:.0} | {err:.1e} |",
            s.num_surfels(),
            s.num_vertices(),
            info.iterations,
            info.seconds.solve,
            bytes * 1e-6,
            bytes / (dram * 1e9) * 1e3,
            info.memory_bytes as f64 / (1 << 20) as f64,
            peak_rss_mib(),
        );
    }
}
