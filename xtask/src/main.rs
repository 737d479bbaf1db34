//! Project automation, run as `cargo xtask <command>`.
//!
//! - `timings [--runs N] [FILE...]`: times each stage of the default run (read, surface,
//!   normals, assemble, solve, refine, write; the input's preset, as the CLI runs it) on
//!   the given volumes (default: the bundled bunny-128 and cat10) and prints a Markdown
//!   table of medians.
//! - `compare [--quick] [--labels] [--surfacenets] [--out DIR]`: every meshing method (voxreg
//!   with each normal estimator, marching cubes, smoothed MC, dual contouring, shrouds)
//!   against every metric of `voxreg-baselines` on analytic shapes; Markdown and CSV tables
//!   in `target/xtask/compare/` (see `compare.rs`). `--labels`: the label shapes' tables
//!   alone (`labelled.rs`); `--surfacenets`: with VTK's SurfaceNets3D on them, run by
//!   `bench/accuracy/surfacenets_labels.py` (needs Python with numpy and pip's `vtk`).
//! - `table1 [--runs N] [FILE...]`: the paper's Table 1 (normals, precomputation, direct
//!   and CG solves) on ball+tet 40^3 and bunny-128 (see `table1.rs`).
//! - `synth-labels [--dims X,Y,Z] [--seed N] [--out FILE.npy]`: a deterministic 25-label volume of
//!   500 x 470 x 136 voxels, like a tissue segmentation (see `synth.rs`).
//! - `figures [--quick] [--out DIR]`: the papers' Figs. 4, 7, 8, 9, 10, 11 and 15 as PNG
//!   renders and charts with an `index.html`, in `target/xtask/figures/` (see
//!   `figures.rs`).
//! - `voxart [--former] [--smoothness S] [--no-clamp] [FILE.vox...]`: voxel art's targets
//!   per model (voxel centres inside and outside, thin voxels' depth, folds, intersections,
//!   mean angle between adjacent quads, on and off thin voxels, the angle kept at hard
//!   edges, time), default: the bundled models; `--former`: the former preset (see
//!   `voxart.rs`).
//! - `gallery [--out DIR]`: every bundled model rendered as voxels and output, two views,
//!   into `docs/gallery/` (see `voxart.rs`).
//! - `lod-figure [--out FILE.png] [--ratio R] VOLUME...`: each volume before and after
//!   simplification with the partition kept (default a tenth of the faces), side by side,
//!   into `docs/figures/simplify.png` (see `lod_figure.rs`).
//! - `diag NAME [VOLUME]`: measurements and diagnostics that print figures (the solver
//!   table, AT's CG tolerance, chunked solves against the whole volume, interrupt latency,
//!   geodesic speed; see `diag.rs`).

mod compare;
mod diag;
mod figures;
mod labelled;
mod lod_figure;
mod synth;
mod table1;
mod voxart;

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use voxreg_io::{is_voxel_art, read_volume, write_mesh, QuadMesh};
use voxreg_regularize::{regularize, Params};

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args.first().map(String::as_str) {
        Some("timings") => timings(&args[1..]),
        Some("compare") => compare::compare(&args[1..]),
        Some("table1") => table1::table1(&args[1..]),
        Some("synth-labels") => synth::synth_labels(&args[1..]),
        Some("figures") => figures::figures(&args[1..]),
        Some("voxart") => voxart::voxart(&args[1..]),
        Some("gallery") => voxart::gallery(&args[1..]),
        Some("diag") => diag::diag(&args[1..]),
        Some("lod-figure") => lod_figure::lod_figure(&args[1..]),
        _ => {
            eprintln!("usage: cargo xtask timings [--runs N] [FILE...]");
            eprintln!("       cargo xtask compare [--quick] [--labels] [--surfacenets] [--out DIR]");
            eprintln!("       cargo xtask table1 [--runs N] [FILE...]");
            eprintln!("       cargo xtask synth-labels [--dims X,Y,Z] [--seed N] [--out FILE.npy]");
            eprintln!("       cargo xtask figures [--quick] [--out DIR]");
            eprintln!("       cargo xtask voxart [--smoothness S] [--no-clamp] [FILE.vox...]");
            eprintln!("       cargo xtask gallery [--out DIR]");
            eprintln!("       cargo xtask diag NAME [VOLUME] (cargo xtask diag: the names)");
            eprintln!("       cargo xtask lod-figure [--out FILE.png] [--ratio R] VOLUME...");
            bail!("unknown or missing command")
        }
    }
}

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().expect("xtask sits in the workspace").to_path_buf()
}

/// The arguments `[--runs N] [FILE...]`: `N` (default `runs`) and the files.
fn runs_and_files(args: &[String], mut runs: usize) -> Result<(usize, Vec<PathBuf>)> {
    let mut files = Vec::new();
    let mut it = args.iter();
    while let Some(a) = it.next() {
        if a == "--runs" {
            runs = it.next().context("--runs needs a number")?.parse().context("--runs needs a number")?;
        } else {
            files.push(PathBuf::from(a));
        }
    }
    Ok((runs, files))
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Stage timings of one run, in seconds, plus counts.
struct Run {
    stages: [f64; 7],
    surfels: usize,
    solves: usize,
    converged: bool,
}

/// One run of the default command line's work: read, the front door with the input's
/// preset, write.
fn run_once(path: &Path, out: &Path) -> Result<Run> {
    let t = Instant::now();
    let loaded = read_volume(path)?;
    let read = t.elapsed().as_secs_f64();
    let params = if is_voxel_art(path) { Params::voxel_art() } else { Params::default() };
    let result = regularize(&loaded.volume, &params)?;
    let t = Instant::now();
    write_mesh(out, &QuadMesh::from_surface(&result.surface, &result.positions))?;
    let write = t.elapsed().as_secs_f64();
    let s = result.report.stages;
    Ok(Run {
        stages: [read, s.surface, s.normals, s.assemble, s.solve, s.refine, write],
        surfels: result.surface.num_surfels(),
        solves: result.report.solves.len(),
        converged: result.report.converged(),
    })
}

fn timings(args: &[String]) -> Result<()> {
    let (runs, mut files) = runs_and_files(args, 5)?;
    if files.is_empty() {
        files = vec![root().join("data/bunny-128.vol"), root().join("data/cat10.vol")];
    }
    let dir = std::env::temp_dir().join(format!("voxreg-xtask-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    println!("| input | surfels | solves | read | surface | normals | assemble | solve | refine | write (OBJ) | total |");
    println!("|---|---|---|---|---|---|---|---|---|---|---|");
    for file in &files {
        let out = dir.join("out.obj");
        let all: Vec<Run> = (0..runs).map(|_| run_once(file, &out)).collect::<Result<_>>()?;
        if let Some(r) = all.iter().find(|r| !r.converged) {
            bail!("{}: a solve did not converge ({} solves)", file.display(), r.solves);
        }
        let med: Vec<f64> = (0..7).map(|k| median(all.iter().map(|r| r.stages[k]).collect())).collect();
        let total = median(all.iter().map(|r| r.stages.iter().sum()).collect());
        let name = file.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        let fmt = |s: f64| if s < 0.1 { format!("{:.1} ms", s * 1e3) } else { format!("{s:.2} s") };
        let cells: Vec<String> = med.iter().map(|&s| fmt(s)).collect();
        println!(
            "| {name} | {} | {} | {} | {} |",
            all[0].surfels,
            all[0].solves,
            cells.join(" | "),
            fmt(total)
        );
    }
    std::fs::remove_dir_all(&dir).ok();
    println!(
        "\nmedians of {runs} runs of the default pipeline (the input's preset); `cargo xtask timings` on {} cores",
        std::thread::available_parallelism()?
    );
    Ok(())
}

/// Parses `[--quick] [--out DIR]` for `command`, whose output folder defaults to
/// `target/xtask/<command>`.
pub(crate) fn quick_and_out(command: &str, args: &[String]) -> Result<(bool, PathBuf)> {
    let mut quick = false;
    let mut out = root().join("target/xtask").join(command);
    let mut it = args.iter();
    while let Some(a) = it.next() {
        match a.as_str() {
            "--quick" => quick = true,
            "--out" => out = PathBuf::from(it.next().context("--out needs a folder")?),
            other => bail!("unknown argument {other}; usage: cargo xtask {command} [--quick] [--out DIR]"),
        }
    }
    std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
    Ok((quick, out))
}
