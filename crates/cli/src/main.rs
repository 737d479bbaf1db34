//! `voxreg`: regularize voxel volumes into smooth quad meshes.
//!
//! Argument parsing and glue only: the work happens in the library crates.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use clap::{Args, Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use serde_json::json;
use voxreg_digisurf::{DigitalSurface, LabelVolume, RegionMap};
use voxreg_io::{read_volume, write_mesh, QuadMesh};
use voxreg_normals::{NormalEstimator, Trivial};
use voxreg_regularize::{DirectSolver, Energy, EnergyParams, EnergyTerms};

/// Regularize voxel data (digital surfaces, multi-label interfaces) into smooth,
/// faithful quad meshes that keep one quad per voxel face.
#[derive(Parser, Debug)]
#[command(name = "voxreg", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Extract the digital surface of INPUT, regularize it and write it as a mesh.
    Regularize(RegularizeArgs),
    /// Describe INPUT: dimensions, labels, and its digital surface's cells.
    Info(InputArgs),
}

#[derive(Args, Debug)]
struct InputArgs {
    /// Input volume: .vol (DGtal), .vox (MagicaVoxel).
    input: PathBuf,
    /// Make a binary volume from a grey-level one: voxels with value > T are inside.
    #[arg(long, value_name = "T")]
    threshold: Option<u32>,
    /// How labels form regions: "label" (each label its own region; the default except
    /// for .vox), "solid" (all non-background labels one region; the default for .vox),
    /// or groups such as "1,2,3;7".
    #[arg(long, value_name = "SPEC")]
    regions: Option<String>,
}

#[derive(Args, Debug)]
struct RegularizeArgs {
    #[command(flatten)]
    input: InputArgs,
    /// Output mesh: .obj (quads, one group per interface) or .ply (binary quads).
    #[arg(short, long, value_name = "OUTPUT")]
    output: PathBuf,
    /// Attachment weight (must be > 0).
    #[arg(long, default_value_t = EnergyParams::default().alpha)]
    alpha: f64,
    /// Alignment weight.
    #[arg(long, default_value_t = EnergyParams::default().beta)]
    beta: f64,
    /// Fairness weight.
    #[arg(long, default_value_t = EnergyParams::default().gamma)]
    gamma: f64,
    /// Write a machine-readable JSON report of the run (timings, counts, energies, solver).
    #[arg(long, value_name = "FILE.json")]
    report: Option<PathBuf>,
    /// Print nothing but errors.
    #[arg(short, long)]
    quiet: bool,
}

/// Shows a spinner for one stage of work and measures it.
struct Stages {
    quiet: bool,
    timings: Vec<(&'static str, f64)>,
}

impl Stages {
    fn run<T>(&mut self, key: &'static str, message: &str, f: impl FnOnce() -> Result<T>) -> Result<T> {
        let bar = if self.quiet { ProgressBar::hidden() } else { ProgressBar::new_spinner() };
        bar.set_style(ProgressStyle::with_template("{spinner} {msg} {elapsed}").expect("valid template"));
        bar.set_message(message.to_string());
        bar.enable_steady_tick(Duration::from_millis(100));
        let t = Instant::now();
        let out = f();
        let secs = t.elapsed().as_secs_f64();
        bar.finish_and_clear();
        self.timings.push((key, secs));
        if !self.quiet && out.is_ok() {
            eprintln!("{message}: {secs:.3} s");
        }
        out
    }
}

fn main() -> std::process::ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Info(args) => info(&args),
        Command::Regularize(args) => regularize(&args),
    };
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            // One line: the error and those of its causes that it does not already quote.
            let mut line = e.to_string();
            for cause in e.chain().skip(1) {
                let cause = cause.to_string();
                if !line.contains(&cause) {
                    line = format!("{line}: {cause}");
                }
            }
            eprintln!("error: {line}");
            std::process::ExitCode::FAILURE
        }
    }
}

/// Reads the input volume and applies `--threshold`; returns it with its region map.
fn load(args: &InputArgs) -> Result<(LabelVolume, RegionMap)> {
    let loaded = read_volume(&args.input)?;
    let is_vox = args.input.extension().is_some_and(|e| e.eq_ignore_ascii_case("vox"));
    let mut volume = loaded.volume;
    if let Some(t) = args.threshold {
        volume = volume.binarize(|l| l > t);
    }
    let map = match args.regions.as_deref() {
        None if is_vox => RegionMap::single_solid(),
        None | Some("label") => RegionMap::per_label(),
        Some("solid") => RegionMap::single_solid(),
        Some(spec) => RegionMap::parse(spec).with_context(|| format!("--regions '{spec}'"))?,
    };
    Ok((volume, map))
}

fn surface_of(path: &Path, volume: &LabelVolume, map: &RegionMap) -> Result<DigitalSurface> {
    DigitalSurface::new(volume, map).with_context(|| format!("{}: no surface to regularize", path.display()))
}

fn info(args: &InputArgs) -> Result<()> {
    let (volume, map) = load(args)?;
    let [x, y, z] = volume.dims();
    let s = volume.spacing();
    println!("file: {}", args.input.display());
    println!("dimensions: {x} x {y} x {z} ({} voxels)", volume.len());
    println!("spacing: {} {} {}", s.x, s.y, s.z);
    match volume.background() {
        Some(b) => println!("background: {b}"),
        None => println!("background: none"),
    }
    println!("labels:");
    for (label, count) in volume.label_counts() {
        println!("  {label}: {count} voxels");
    }
    let surface = surface_of(&args.input, &volume, &map)?;
    let c = surface.counts();
    println!("regions: {}", surface.regions().len());
    println!("surfels: {}", c.surfels);
    println!("vertices: {}", c.vertices);
    println!("edges: {}", c.edges);
    println!("euler characteristic: {}", surface.euler_characteristic());
    println!(
        "components: {} ({} closed)",
        c.components,
        surface.components_closed().iter().filter(|&&b| b).count()
    );
    println!("interfaces: {}", c.interfaces);
    for iface in surface.interfaces() {
        let name = |r| {
            let labels = surface.regions().labels(r);
            labels.iter().map(u32::to_string).collect::<Vec<_>>().join("+")
        };
        println!(
            "  {} | {}: {} surfels",
            name(iface.regions[0]),
            name(iface.regions[1]),
            iface.surfels.len()
        );
    }
    println!("boundary vertices: {}", c.boundary_vertices);
    println!("boundary edges: {}", c.boundary_edges);
    println!("junction edges: {}", c.junction_edges);
    println!("pinched edges: {}", c.pinched_edges);
    println!("pinched vertices: {}", c.pinched_vertices);
    Ok(())
}

fn check_output(path: &Path) -> Result<()> {
    let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    match ext.as_deref() {
        Some("obj" | "ply") => Ok(()),
        _ => bail!("{}: unsupported output format (expected .obj or .ply)", path.display()),
    }
}

fn terms_json(t: &EnergyTerms) -> serde_json::Value {
    json!({ "attachment": t.attachment, "alignment": t.alignment, "fairness": t.fairness, "total": t.total })
}

fn regularize(args: &RegularizeArgs) -> Result<()> {
    check_output(&args.output)?;
    let params = EnergyParams { alpha: args.alpha, beta: args.beta, gamma: args.gamma };
    params.validate()?;
    let mut stages = Stages { quiet: args.quiet, timings: Vec::new() };
    let input = &args.input.input;
    let (volume, map) = stages.run("read", "read volume", || load(&args.input))?;
    let surface = stages.run("surface", "digital surface", || surface_of(input, &volume, &map))?;
    let normals = stages.run("normals", "normals (trivial)", || Ok(Trivial.estimate(&surface)?))?;
    let positions = surface.positions();
    let energy = Energy::new(&surface, &normals, &positions, params)?;
    let mut solver = stages.run("assemble", "analyse operator", || Ok(DirectSolver::new(&surface)?))?;
    let (regularized, info) =
        stages.run("solve", "assemble, factor and solve", || Ok(solver.solve(&energy)?))?;
    let mesh = QuadMesh::from_surface(&surface, &regularized);
    stages.run("write", "write mesh", || Ok(write_mesh(&args.output, &mesh)?))?;

    let before = energy.terms(&positions);
    let after = energy.terms(&regularized);
    let c = surface.counts();
    if !args.quiet {
        eprintln!(
            "{} quads, {} vertices; energy {:.6e} -> {:.6e}; relative gradient {:.1e}; wrote {}",
            c.surfels,
            c.vertices,
            before.total,
            after.total,
            info.relative_gradient,
            args.output.display()
        );
    }
    if let Some(path) = &args.report {
        let mut stage_json = serde_json::Map::new();
        for (k, v) in &stages.timings {
            stage_json.insert((*k).to_string(), json!(v));
        }
        let report = json!({
            "input": input.display().to_string(),
            "output": args.output.display().to_string(),
            "params": { "alpha": params.alpha, "beta": params.beta, "gamma": params.gamma, "normals": Trivial.name() },
            "stages": stage_json,
            "counts": {
                "surfels": c.surfels,
                "vertices": c.vertices,
                "edges": c.edges,
                "interfaces": c.interfaces,
                "boundary_vertices": c.boundary_vertices,
                "junction_edges": c.junction_edges,
                "pinched_edges": c.pinched_edges,
                "pinched_vertices": c.pinched_vertices,
            },
            "energy": { "before": terms_json(&before), "after": terms_json(&after) },
            "solver": {
                "kind": info.solver,
                "iterations": info.iterations,
                "relative_gradient": info.relative_gradient,
                "factor_nnz": info.factor_nnz,
                "pattern_seconds": info.pattern_seconds,
                "symbolic_seconds": info.symbolic_seconds,
                "assemble_seconds": info.assemble_seconds,
                "factor_seconds": info.factor_seconds,
                "solve_seconds": info.solve_seconds,
            },
        });
        write_report(path, &report)?;
    }
    Ok(())
}

/// Writes the report through a temporary file and a rename, like the mesh writers.
fn write_report(path: &Path, report: &serde_json::Value) -> Result<()> {
    let dir = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let mut tmp =
        tempfile::NamedTempFile::new_in(dir).with_context(|| format!("{}: cannot write", path.display()))?;
    serde_json::to_writer_pretty(&mut tmp, report)?;
    tmp.persist(path).with_context(|| format!("{}: cannot write", path.display()))?;
    Ok(())
}
