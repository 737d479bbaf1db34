//! `cargo xtask diag solver-table`: the multigrid CG solver on digitized spheres with
//! their exact normals and the default weights. Meant for a quiet machine (minutes).
//!
//! ```text
//! cargo xtask diag solver-table
//! RADII=33,73 RUNS=3 NORMALS=trivial COARSEST=800 cargo xtask diag solver-table
//! ```
//!
//! For each radius (default 33, 73, 140, 282 voxels: about 20k, 100k, 367k and 1.5M quads)
//! it prints the CG iterations, the median time of the whole minimization (connectivity,
//! hierarchy, coarse operators, iterations) over `RUNS` runs (5), the time per iteration
//! against the memory-bandwidth bound of the bytes one iteration moves (the solver's
//! traffic model over the measured streaming bandwidth), the solver's memory and the
//! process's peak memory, and the largest vertex distance to a reference solved with the
//! guaranteed rule at 1e-6 voxel. `NORMALS=trivial` uses trivial normals; `COARSEST`,
//! `SMOOTH`, `COARSE_SMOOTH` and `DAMP` set the multigrid's parameters.

use std::time::Instant;

use anyhow::Result;
use glam::DVec3;
use rayon::prelude::*;
use voxreg_digisurf::DigitalSurface;
use voxreg_normals::{NormalEstimator, NormalField, Trivial};
use voxreg_regularize::{CgParams, CgSolver, Energy, EnergyParams, SolveRequest, StoppingRule};
use voxreg_testkit::{digitize, true_normals, Sphere};

use super::{env_opt, env_or};
use crate::median;

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

/// The process's peak resident set in MiB (Linux `VmHWM`; NaN elsewhere).
fn peak_rss_mib() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| s.lines().find(|l| l.starts_with("VmHWM:")).map(|l| l.to_string()))
        .and_then(|l| l.split_whitespace().nth(1).and_then(|k| k.parse::<f64>().ok()))
        .map_or(f64::NAN, |kib| kib / 1024.0)
}

/// The CG parameters with the environment's multigrid knobs.
fn cg_params() -> Result<CgParams> {
    let mut params = CgParams::default();
    let m = &mut params.multigrid;
    m.coarsest_nodes = env_or("COARSEST", m.coarsest_nodes)?;
    m.smoothing_steps = env_or("SMOOTH", m.smoothing_steps)?;
    m.coarse_smoothing_steps = env_or("COARSE_SMOOTH", m.coarse_smoothing_steps)?;
    m.damping = env_or("DAMP", m.damping)?;
    Ok(params)
}

pub(super) fn solver_table() -> Result<()> {
    let radii: Vec<f64> = match env_opt::<String>("RADII")? {
        Some(v) => v.split(',').map(|x| x.trim().parse()).collect::<Result<_, _>>()?,
        None => vec![33.0, 73.0, 140.0, 282.0],
    };
    let runs: usize = env_or("RUNS", 5)?;
    let trivial = std::env::var("NORMALS").is_ok_and(|v| v == "trivial");
    let dram = triad_bandwidth(256 << 20);
    let l3 = triad_bandwidth(8 << 20);
    println!(
        "threads {}; streaming bandwidth: {dram:.1} GB/s (3 x 256 MB), {l3:.1} GB/s (3 x 8 MB)",
        rayon::current_num_threads()
    );
    println!("| quads | vertices | levels | iterations | median time (s) | setup / iterate (s) | ms/iteration | bytes/iteration | bound at DRAM bw (ms) | solver memory (MiB) | peak RSS (MiB) | max error (voxel) |");
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|");
    for r in radii {
        let shape = Sphere { radius: r };
        let s = DigitalSurface::from_volume(&digitize(&shape, 1.0))?;
        let normals =
            if trivial { Trivial.estimate(&s)? } else { NormalField::new(true_normals(&s, &shape)) };
        let input = s.positions();
        let energy = Energy::new(&s, &normals, &input, EnergyParams::default())?;
        let (mut times, mut cpu, mut last) = (Vec::new(), Vec::new(), None);
        for _ in 0..runs.max(1) {
            let (t, c0) = (Instant::now(), cpu_seconds());
            let mut cg = CgSolver::for_surface(&s, cg_params()?)?;
            let levels = cg.levels();
            let (x, info) = cg.solve(&energy, SolveRequest::default())?;
            times.push(t.elapsed().as_secs_f64());
            cpu.push(cpu_seconds() - c0);
            last = Some((x, info, levels));
        }
        let cpu_min = cpu.iter().copied().fold(f64::INFINITY, f64::min);
        println!("cpu seconds per solve (all threads): median {:.3}, min {cpu_min:.3}", median(cpu.clone()));
        let (x, info, levels) = last.expect("at least one run");
        let tight = CgParams { tolerance: 1e-6, stopping: StoppingRule::Guaranteed, ..Default::default() };
        let (reference, _) = CgSolver::for_surface(&s, tight)?.solve(&energy, SolveRequest::default())?;
        let err =
            x.iter().zip(&reference).map(|(a, b): (&DVec3, &DVec3)| (*a - *b).length()).fold(0.0, f64::max);
        let setup = info.seconds.structure + info.seconds.assemble + info.seconds.factor;
        let per_iter = info.seconds.solve / info.iterations.max(1) as f64 * 1e3;
        let bytes = info.bytes_per_iteration as f64;
        println!(
            "| {} | {} | {levels} | {} | {:.3} | {setup:.3} / {:.3} | {per_iter:.1} | {:.0} MB | {:.1} | {:.0} | {:.0} | {err:.1e} |",
            s.num_surfels(),
            s.num_vertices(),
            info.iterations,
            median(times),
            info.seconds.solve,
            bytes * 1e-6,
            bytes / (dram * 1e9) * 1e3,
            info.memory_bytes as f64 / (1 << 20) as f64,
            peak_rss_mib(),
        );
    }
    Ok(())
}
