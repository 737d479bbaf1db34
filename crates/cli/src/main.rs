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
use voxreg_io::{
    read_mesh, read_raw, read_voxels, write_mesh, write_ply_with_vertex_scalar, DataType, Endian, Palette,
    QuadMesh, RawSpec, Voxels,
};
use voxreg_normals::{
    multigrid_radius, AmbrosioTortorelli, AtParams, ConvolvedTrivial, IntegralInvariant, NormalEstimator,
    Trivial,
};
use voxreg_regularize::{
    self_intersections, Energy, EnergyParams, EnergyTerms, FairnessMask, Progress, SolveInfo, Solver,
    SolverChoice, SolverParams, Weights,
};

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
    /// Count the self-intersections of MESH (.obj or .ply, quads split into two triangles;
    /// faces sharing a vertex do not count); exits with an error if there are any.
    Check(CheckArgs),
}

#[derive(Args, Debug)]
struct CheckArgs {
    /// The mesh: .obj or .ply (as written by voxreg regularize).
    mesh: PathBuf,
}

#[derive(Args, Debug)]
struct InputArgs {
    /// Input volume: .vol, .longvol, .pgm3d (DGtal), .vox (MagicaVoxel), .nii, .nii.gz
    /// (NIfTI-1), .vti (VTK image data), .npy (NumPy, shape (X, Y, Z)), or raw data with
    /// --dims.
    input: PathBuf,
    /// Make a binary volume: voxels whose value (label or grey level) is > T are inside.
    /// Needed for grey-level data (fractional, negative or scaled values).
    #[arg(long, value_name = "T", allow_negative_numbers = true, conflicts_with = "labels")]
    threshold: Option<f64>,
    /// Keep only these labels; every other label becomes the background.
    #[arg(long, value_name = "L,L,...", value_delimiter = ',', conflicts_with = "no_background")]
    labels: Option<Vec<u32>>,
    /// The background label: empty space, which also fills the outside of the volume
    /// (default 0).
    #[arg(long, value_name = "L", conflicts_with = "no_background")]
    background: Option<u32>,
    /// No background: every label is a material, and interfaces that reach the border
    /// of the volume end there as open surfaces.
    #[arg(long)]
    no_background: bool,
    /// Read INPUT as raw data (no header, x fastest) of these dimensions.
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_dims)]
    dims: Option<[u64; 3]>,
    /// Raw data: the type of a value, u8 (default), u16, u32, f32 (or i8, i16, i32, u64,
    /// i64, f64).
    #[arg(long, value_name = "TYPE", requires = "dims")]
    dtype: Option<DataType>,
    /// Raw data: the byte order, little (default) or big.
    #[arg(long, value_name = "ORDER", requires = "dims")]
    endian: Option<Endian>,
    /// The size of a voxel, for raw data, or overriding the file's.
    #[arg(long, value_name = "SX,SY,SZ", value_parser = parse_spacing)]
    spacing: Option<glam::DVec3>,
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
    /// Output mesh: .obj (quads, one group per interface, with an .mtl for coloured
    /// inputs), .ply (binary quads, face labels and colours), .glb or .gltf (glTF 2.0,
    /// triangulated, one material per colour).
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
    /// Normal estimator driving the alignment term.
    #[arg(long, value_enum, default_value_t = NormalsKind::Ii)]
    normals: NormalsKind,
    /// Radius of the ii, convolved and at estimators, in physical units [default: the
    /// multigrid rule 3 h^(1/3), h the largest voxel spacing: 3 at unit spacing].
    #[arg(long, value_name = "R")]
    radius: Option<f64>,
    /// With --normals at: also write the Ambrosio-Tortorelli feature field v (low on sharp
    /// features, about 1 elsewhere) on the output mesh, as a binary PLY with a per-vertex
    /// float property `feature` and a colour ramp (dark red 0, amber 0.5, light grey 1).
    #[arg(long, value_name = "FILE.ply")]
    features: Option<PathBuf>,
    /// Solver: auto (exact factorization for small surfaces, else cg), direct (sparse
    /// Cholesky), cg (multigrid conjugate gradient) or gd (gradient descent).
    #[arg(long, value_enum, default_value_t = SolverKind::Auto)]
    solver: SolverKind,
    /// Keep every vertex in the cube of edge (1 - EPS) voxel around its input position,
    /// which rules out self-intersections (paper, Proposition 2); EPS in voxels, 0.01 when
    /// omitted. Implies --solver gd.
    #[arg(long, value_name = "EPS", num_args = 0..=1, default_missing_value = "0.01")]
    clamp: Option<f64>,
    /// Iterative solvers: stop when every vertex is estimated within this many voxels of
    /// the exact minimizer.
    #[arg(long, value_name = "VOXELS", default_value_t = 1e-3)]
    tolerance: f64,
    /// Texture-aware fairness (paper, sec. 4.5): barycenters leave out the neighbours
    /// across a colour (label) boundary, so quad edges follow colour boundaries.
    #[arg(long)]
    texture_aware: bool,
    /// Write a machine-readable JSON report of the run (timings, counts, energies, solver).
    #[arg(long, value_name = "FILE.json")]
    report: Option<PathBuf>,
    /// Print nothing but errors.
    #[arg(short, long)]
    quiet: bool,
}

/// The solvers `--solver` can pick.
#[derive(Copy, Clone, Debug, PartialEq, Eq, clap::ValueEnum)]
enum SolverKind {
    /// Exact factorization when its factor is small (a few thousand vertices), else cg.
    Auto,
    /// Sparse Cholesky: exact to rounding; memory grows fast with the surface.
    Direct,
    /// Multigrid-preconditioned conjugate gradient: fast, memory linear in the surface.
    Cg,
    /// Gradient descent (multigrid-preconditioned): the only one that can --clamp.
    Gd,
}

/// The normal estimators `--normals` can pick.
#[derive(Copy, Clone, Debug, PartialEq, Eq, clap::ValueEnum)]
enum NormalsKind {
    /// Each face's own axis (no smoothing).
    Trivial,
    /// Trivial normals averaged over the surface within the radius.
    Convolved,
    /// Integral invariant: covariance of a ball intersected with the solid.
    Ii,
    /// Ambrosio-Tortorelli regularization of the ii normals: smooth, but keeps sharp features.
    At,
}

impl NormalsKind {
    /// The estimator, with its radius (physical units; `None`: the multigrid default).
    fn estimator(self, radius: Option<f64>) -> Box<dyn NormalEstimator + Send + Sync> {
        match self {
            NormalsKind::Trivial => Box::new(Trivial),
            NormalsKind::Convolved => Box::new(ConvolvedTrivial { radius }),
            NormalsKind::Ii => Box::new(IntegralInvariant { radius }),
            NormalsKind::At => Box::new(at_estimator(radius)),
        }
    }

    /// The radius the estimator uses on `surface`, or `None` for one without a radius.
    fn radius(self, radius: Option<f64>, surface: &DigitalSurface) -> Option<f64> {
        match self {
            NormalsKind::Trivial => None,
            _ => Some(radius.unwrap_or_else(|| multigrid_radius(surface.spacing()))),
        }
    }
}

/// The `at` estimator: Ambrosio-Tortorelli on integral invariants of the given radius.
fn at_estimator(radius: Option<f64>) -> AmbrosioTortorelli {
    AmbrosioTortorelli::new(AtParams::default(), Box::new(IntegralInvariant { radius }))
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
        Command::Check(args) => check(&args),
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

/// Reads the input volume (see [`read_input`]); returns it with its region map and its
/// palette (colours and materials per label), if the format has one.
fn load(args: &InputArgs) -> Result<(LabelVolume, RegionMap, Option<Palette>)> {
    let (volume, palette) = read_input(args)?;
    let is_vox = args.input.extension().is_some_and(|e| e.eq_ignore_ascii_case("vox"));
    let map = match args.regions.as_deref() {
        None if is_vox => RegionMap::single_solid(),
        None | Some("label") => RegionMap::per_label(),
        Some("solid") => RegionMap::single_solid(),
        Some(spec) => RegionMap::parse(spec).with_context(|| format!("--regions '{spec}'"))?,
    };
    Ok((volume, map, palette))
}

/// Reads INPUT (raw with `--dims`, else by extension), applies `--spacing`, then
/// `--threshold` (or checks that grey levels are labels), `--labels` and the background.
fn read_input(args: &InputArgs) -> Result<(LabelVolume, Option<Palette>)> {
    let path = &args.input;
    let is_raw = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("raw"));
    let (voxels, palette) = match args.dims {
        Some(dims) => {
            let spec = RawSpec {
                dims,
                dtype: args.dtype.unwrap_or(DataType::U8),
                endian: args.endian.unwrap_or_default(),
                spacing: args.spacing.unwrap_or(glam::DVec3::ONE),
            };
            (read_raw(path, &spec)?, None)
        }
        None if is_raw => bail!("{}: raw data have no header: give --dims X,Y,Z and --dtype", path.display()),
        None => {
            let loaded = read_voxels(path)?;
            (loaded.voxels, loaded.palette)
        }
    };
    let voxels = match args.spacing {
        Some(s) => voxels.with_spacing(s).with_context(|| format!("{}: --spacing", path.display()))?,
        None => voxels,
    };
    let mut volume = match (args.threshold, voxels) {
        (Some(t), _) if t.is_nan() => bail!("--threshold: NaN is not a threshold"),
        (Some(t), voxels) => voxels.threshold(t),
        (None, Voxels::Labels(volume)) => volume,
        (None, Voxels::Grey(grey)) => match grey.to_labels() {
            Ok(volume) => volume,
            Err(e) => {
                let (lo, hi) = grey.range().unwrap_or_default();
                bail!(
                    "{}: grey-level data needs --threshold T (values range from {lo} to {hi}; {e})",
                    path.display()
                )
            }
        },
    };
    if let Some(keep) = &args.labels {
        let background = args.background.or(volume.background()).unwrap_or(0);
        volume.labels_mut().mapv_inplace(|l| if keep.contains(&l) { l } else { background });
    }
    if args.no_background {
        volume = volume.with_background(None);
    } else if let Some(b) = args.background {
        volume = volume.with_background(Some(b));
    }
    Ok((volume, palette))
}

/// Parses three comma-separated values.
fn parse_three<T: std::str::FromStr>(s: &str, what: &str) -> std::result::Result<[T; 3], String> {
    let parts: Vec<T> = s
        .split(',')
        .map(|p| p.trim().parse::<T>())
        .collect::<std::result::Result<_, _>>()
        .map_err(|_| format!("'{s}' is not three {what} separated by commas"))?;
    parts.try_into().map_err(|_| format!("'{s}' is not three {what} separated by commas"))
}

fn parse_dims(s: &str) -> std::result::Result<[u64; 3], String> {
    parse_three(s, "dimensions")
}

fn parse_spacing(s: &str) -> std::result::Result<glam::DVec3, String> {
    let [x, y, z] = parse_three::<f64>(s, "voxel sizes")?;
    let spacing = glam::DVec3::new(x, y, z);
    if !(spacing.is_finite() && spacing.min_element() > 0.0) {
        return Err(format!("'{s}': voxel sizes must be finite and positive"));
    }
    Ok(spacing)
}

fn surface_of(path: &Path, volume: &LabelVolume, map: &RegionMap) -> Result<DigitalSurface> {
    DigitalSurface::new(volume, map).with_context(|| format!("{}: no surface to regularize", path.display()))
}

fn info(args: &InputArgs) -> Result<()> {
    use std::fmt::Write as _;
    let mut out = String::new();
    let (volume, map, _) = load(args)?;
    let [x, y, z] = volume.dims();
    let s = volume.spacing();
    writeln!(out, "file: {}", args.input.display()).ok();
    writeln!(out, "dimensions: {x} x {y} x {z} ({} voxels)", volume.len()).ok();
    writeln!(out, "spacing: {} {} {}", s.x, s.y, s.z).ok();
    match volume.background() {
        Some(b) => writeln!(out, "background: {b}").ok(),
        None => writeln!(out, "background: none").ok(),
    };
    writeln!(out, "labels:").ok();
    for (label, count) in volume.label_counts() {
        writeln!(out, "  {label}: {count} voxels").ok();
    }
    let surface = surface_of(&args.input, &volume, &map)?;
    let c = surface.counts();
    writeln!(out, "regions: {}", surface.regions().len()).ok();
    writeln!(out, "surfels: {}", c.surfels).ok();
    writeln!(out, "vertices: {}", c.vertices).ok();
    writeln!(out, "edges: {}", c.edges).ok();
    writeln!(out, "euler characteristic: {}", surface.euler_characteristic()).ok();
    writeln!(
        out,
        "components: {} ({} closed)",
        c.components,
        surface.components_closed().iter().filter(|&&b| b).count()
    )
    .ok();
    writeln!(out, "interfaces: {}", c.interfaces).ok();
    for iface in surface.interfaces() {
        let name = |r| {
            let labels = surface.regions().labels(r);
            labels.iter().map(u32::to_string).collect::<Vec<_>>().join("+")
        };
        writeln!(
            out,
            "  {} | {}: {} surfels",
            name(iface.regions[0]),
            name(iface.regions[1]),
            iface.surfels.len()
        )
        .ok();
    }
    writeln!(out, "boundary vertices: {}", c.boundary_vertices).ok();
    writeln!(out, "boundary edges: {}", c.boundary_edges).ok();
    writeln!(out, "junction edges: {}", c.junction_edges).ok();
    writeln!(out, "pinched edges: {}", c.pinched_edges).ok();
    writeln!(out, "pinched vertices: {}", c.pinched_vertices).ok();
    print_stdout(&out)
}

/// Prints `text` to standard output; a closed pipe (`voxreg info ... | head`) is not an
/// error.
fn print_stdout(text: &str) -> Result<()> {
    use std::io::Write as _;
    match std::io::stdout().lock().write_all(text.as_bytes()) {
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(()),
        other => Ok(other?),
    }
}

fn check_output(path: &Path) -> Result<()> {
    let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    match ext.as_deref() {
        Some("obj" | "ply" | "glb" | "gltf") => Ok(()),
        _ => bail!("{}: unsupported output format (expected .obj, .ply, .glb or .gltf)", path.display()),
    }
}

fn terms_json(t: &EnergyTerms) -> serde_json::Value {
    json!({ "attachment": t.attachment, "alignment": t.alignment, "fairness": t.fairness, "total": t.total })
}

fn regularize(args: &RegularizeArgs) -> Result<()> {
    check_output(&args.output)?;
    if let Some(path) = &args.features {
        if args.normals != NormalsKind::At {
            bail!("--features {}: only --normals at has a feature field", path.display());
        }
        if !path.extension().is_some_and(|e| e.eq_ignore_ascii_case("ply")) {
            bail!("{}: --features writes PLY only (expected .ply)", path.display());
        }
    }
    let params = EnergyParams { alpha: args.alpha, beta: args.beta, gamma: args.gamma };
    params.validate()?;
    if let Some(r) = args.radius {
        if !(r.is_finite() && r > 0.0) {
            bail!("--radius must be finite and positive, got {r}");
        }
    }
    let mut stages = Stages { quiet: args.quiet, timings: Vec::new() };
    let input = &args.input.input;
    let (volume, map, palette) = stages.run("read", "read volume", || load(&args.input))?;
    let surface = stages.run("surface", "digital surface", || surface_of(input, &volume, &map))?;
    let estimator = args.normals.estimator(args.radius);
    let radius = args.normals.radius(args.radius, &surface);
    let label = match radius {
        Some(r) => format!("normals ({}, radius {r:.3})", estimator.name()),
        None => format!("normals ({})", estimator.name()),
    };
    let (normals, features) = stages.run("normals", &label, || match &args.features {
        Some(_) => {
            let (u, v) = at_estimator(args.radius).estimate_with_features(&surface)?;
            Ok((u, Some(v)))
        }
        None => Ok((estimator.estimate(&surface)?, None)),
    })?;
    let positions = surface.positions();
    let weights = Weights {
        fairness: args.texture_aware.then(|| FairnessMask::texture_aware(&surface)),
        ..Default::default()
    };
    let energy = Energy::new(&surface, &normals, &positions, params)?.with_weights(&weights)?;
    let solver_params = solver_params(args)?;
    let mut solver =
        stages.run("analyse", "analyse operator", || Ok(Solver::new(&surface, &solver_params)?))?;
    let (regularized, info) = solve(&mut stages, &mut solver, &energy, args.tolerance)?;
    // Report the solver's own split: `assemble` = operator pattern + numeric assembly,
    // `solve` = symbolic analysis + numeric factorization + triangular solves.
    stages.timings.retain(|(k, _)| !matches!(*k, "analyse" | "factor"));
    stages.timings.push(("assemble", info.pattern_seconds + info.assemble_seconds));
    stages.timings.push(("solve", info.symbolic_seconds + info.factor_seconds + info.solve_seconds));
    let mut mesh = QuadMesh::from_surface(&surface, &regularized);
    if let Some(palette) = &palette {
        // Colour transfer: each quad takes the colour and material of its solid voxel.
        mesh.assign_materials(palette);
    }
    stages.run("write", "write mesh", || {
        write_mesh(&args.output, &mesh)?;
        if let (Some(path), Some(v)) = (&args.features, &features) {
            write_ply_with_vertex_scalar(path, &mesh, "feature", v.as_slice())?;
        }
        Ok(())
    })?;

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
            "params": {
                "alpha": params.alpha,
                "beta": params.beta,
                "gamma": params.gamma,
                "normals": estimator.name(),
                "radius": radius,
            },
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
                "converged": info.converged,
                "error_bound": info.error_bound,
                "error_estimate": info.error_estimate,
                "tolerance": (info.solver != "direct").then_some(args.tolerance),
                "preconditioner": info.preconditioner,
                "operator_applications": info.operator_applications,
                "clamp": args.clamp,
                "clamped_vertices": info.clamped_vertices,
                "memory_bytes": info.memory_bytes,
                "texture_aware": args.texture_aware,
            },
        });
        write_report(path, &report)?;
    }
    Ok(())
}

/// The solver settings of `--solver`, `--clamp` and `--tolerance`.
fn solver_params(args: &RegularizeArgs) -> Result<SolverParams> {
    if !(args.tolerance.is_finite() && args.tolerance > 0.0) {
        bail!("--tolerance must be finite and positive, got {}", args.tolerance);
    }
    let choice = match (args.solver, args.clamp) {
        (SolverKind::Direct | SolverKind::Cg, Some(_)) => {
            bail!("--clamp needs the gd solver (--solver gd or auto)")
        }
        (_, Some(eps)) if !(eps > 0.0 && eps < 1.0) => {
            bail!("--clamp: EPS must be in (0, 1) voxel, got {eps}")
        }
        (_, Some(_)) | (SolverKind::Gd, None) => SolverChoice::Gd,
        (SolverKind::Auto, None) => SolverChoice::Auto,
        (SolverKind::Direct, None) => SolverChoice::Direct,
        (SolverKind::Cg, None) => SolverChoice::Cg,
    };
    let mut params = SolverParams { choice, ..Default::default() };
    params.cg.tolerance = args.tolerance;
    params.descent.tolerance = args.tolerance;
    params.descent.clamp = args.clamp;
    Ok(params)
}

/// Runs `solver` on `energy`, with a progress bar for the iterative solvers (iteration,
/// estimated distance to the minimizer against the tolerance, relative gradient).
fn solve(
    stages: &mut Stages,
    solver: &mut Solver,
    energy: &Energy<'_>,
    tolerance: f64,
) -> Result<(Vec<glam::DVec3>, SolveInfo)> {
    let message = match solver.kind() {
        "direct" => "assemble, factor and solve".to_string(),
        kind => format!("solve ({kind})"),
    };
    let quiet = stages.quiet;
    stages.run("factor", &message, || {
        let bar = if quiet { ProgressBar::hidden() } else { ProgressBar::new_spinner() };
        bar.set_style(ProgressStyle::with_template("{spinner} {msg} {elapsed}").expect("valid template"));
        bar.enable_steady_tick(Duration::from_millis(100));
        let mut report = |p: &Progress| {
            bar.set_message(format!(
                "iteration {}: estimated error {:.1e} voxel (tolerance {tolerance:.0e}), relative gradient {:.1e}",
                p.iteration, p.error_estimate, p.relative_gradient
            ));
        };
        let out = solver.solve_with(energy, &mut report);
        bar.finish_and_clear();
        if !quiet {
            if let Ok((_, info)) = &out {
                if info.solver != "direct" {
                    let status = if info.converged { "converged" } else { "NOT converged" };
                    eprintln!(
                        "{} {status} in {} iterations: estimated error {:.1e} voxel, relative gradient {:.1e}",
                        info.solver,
                        info.iterations,
                        info.error_estimate.unwrap_or(0.0),
                        info.relative_gradient
                    );
                }
            }
        }
        Ok(out?)
    })
}

/// `voxreg check`: counts the mesh's self-intersections.
fn check(args: &CheckArgs) -> Result<()> {
    let mesh = read_mesh(&args.mesh)?;
    let pairs = self_intersections(&mesh.positions, &mesh.quads);
    print_stdout(&format!(
        "{}: {} faces, {} self-intersecting face pairs\n",
        args.mesh.display(),
        mesh.quads.len(),
        pairs.len()
    ))?;
    if let Some((a, b)) = pairs.first() {
        bail!("{}: {} self-intersections (first: faces {a} and {b})", args.mesh.display(), pairs.len());
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
