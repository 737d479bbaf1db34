//! `cargo xtask table1`: the paper's Table 1 (performances) on this machine.
//!
//! For each input: quads, integral-invariant normal estimation, the precomputation of
//! each solver (direct: operator pattern and symbolic Cholesky analysis; CG: connectivity
//! and multigrid hierarchy), the direct solve (numeric assembly, factorization,
//! triangular solves) and the CG solve (multigrid preconditioner, default tolerance), as
//! medians of `--runs` runs (default 3). Inputs: the ball+tet shape at 40^3 (as in the
//! paper) and the bundled `bunny-128.vol` (the paper's bunny row), or the given files.

use std::time::Instant;

use anyhow::{Context, Result};
use voxreg_digisurf::{DigitalSurface, LabelVolume, RegionMap};
use voxreg_io::read_volume;
use voxreg_normals::{IntegralInvariant, NormalEstimator};
use voxreg_regularize::{CgParams, CgSolver, DirectSolver, Energy, EnergyParams};
use voxreg_testkit::digitize;

use crate::compare::BallTet;
use crate::median;

/// Seconds of each measured step of one run.
struct Run {
    normals: f64,
    direct_pre: f64,
    direct_solve: f64,
    cg_pre: f64,
    cg_solve: f64,
    cg_iterations: usize,
}

fn run_once(surface: &DigitalSurface) -> Result<Run> {
    let t = Instant::now();
    let normals = IntegralInvariant::default().estimate(surface)?;
    let normals_s = t.elapsed().as_secs_f64();
    let input = surface.positions();
    let energy = Energy::new(surface, &normals, &input, EnergyParams::default())?;
    let t = Instant::now();
    let mut direct = DirectSolver::for_surface(surface)?;
    let direct_pre = t.elapsed().as_secs_f64();
    let t = Instant::now();
    direct.solve(&energy)?;
    let direct_solve = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let mut cg = CgSolver::for_surface(surface, CgParams::default())?;
    let cg_pre = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let (_, info) = cg.solve(&energy, voxreg_regularize::SolveRequest::default())?;
    let cg_solve = t.elapsed().as_secs_f64();
    Ok(Run { normals: normals_s, direct_pre, direct_solve, cg_pre, cg_solve, cg_iterations: info.iterations })
}

/// Runs the table; `args`: `[--runs N] [FILE...]`.
pub(crate) fn table1(args: &[String]) -> Result<()> {
    let (runs, mut files) = crate::runs_and_files(args, 3)?;
    let mut inputs: Vec<(String, LabelVolume)> = Vec::new();
    if files.is_empty() {
        inputs.push(("ball+tet".into(), digitize(&BallTet::new(), 0.5)));
        files.push(crate::root().join("data/bunny-128.vol"));
    }
    for f in &files {
        let name = f.file_stem().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        inputs.push((name, read_volume(f).with_context(|| format!("reading {}", f.display()))?.volume));
    }
    let mut md = String::from(
        "| object | domain | quads | normals (II) | direct: precomputation | direct: solve | CG: precomputation | CG: solve | CG iterations |\n|---|---|---|---|---|---|---|---|---|\n",
    );
    for (name, volume) in &inputs {
        let surface = DigitalSurface::new(volume, &RegionMap::single_solid())?;
        let all: Vec<Run> = (0..runs.max(1)).map(|_| run_once(&surface)).collect::<Result<_>>()?;
        let m = |f: fn(&Run) -> f64| format!("{:.3}", median(all.iter().map(f).collect()));
        let d = volume.dims();
        let line = format!(
            "| {name} | {}x{}x{} | {} | {} | {} | {} | {} | {} | {} |\n",
            d[0],
            d[1],
            d[2],
            surface.num_surfels(),
            m(|r| r.normals),
            m(|r| r.direct_pre),
            m(|r| r.direct_solve),
            m(|r| r.cg_pre),
            m(|r| r.cg_solve),
            all[0].cg_iterations
        );
        eprint!("{line}");
        md.push_str(&line);
    }
    let note = format!(
        "\nSeconds, medians of {runs} runs on {} cores (`cargo xtask table1`). II: default radius `3 h^(1/3)`; default weights; CG: multigrid preconditioner, default tolerance (1e-3 voxel).\n",
        std::thread::available_parallelism()?
    );
    md.push_str(&note);
    let out = crate::root().join("target/xtask");
    std::fs::create_dir_all(&out)?;
    std::fs::write(out.join("table1.md"), &md)?;
    println!("{md}");
    Ok(())
}
