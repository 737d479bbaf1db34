//! `voxreg`: regularize voxel volumes into smooth quad meshes.
//!
//! Argument parsing and glue only: the work happens in the library crates.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use clap::{Args, Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use serde_json::json;
use voxreg_digisurf::{DigitalSurface, InterfaceId, LabelVolume, PatchParams, RegionId, RegionMap};
use voxreg_io::{
    interface_name, read_mesh, read_raw, read_voxels, region_name, write_mesh, write_ply_with_vertex_scalar,
    write_volume, DataType, Endian, MeshBatch, Palette, QuadMesh, RawSpec, Voxels,
};
use voxreg_normals::{
    multigrid_radius, AmbrosioTortorelli, AtParams, ConvolvedTrivial, IntegralInvariant, NormalEstimator,
    Trivial,
};
use voxreg_regularize::{
    run_pipeline, self_intersections, Energy, EnergyParams, EnergyTerms, FairnessMask, PipelineOutput,
    PipelineParams, Progress, SolverChoice, SolverParams, Weights,
};
use voxreg_upscale::{upscale, UpscaleParams};

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
    /// Regularize INPUT's surface, then voxelize it at K times the resolution (papers,
    /// Fig. 13): a finer voxel model whose staircase follows the smooth surface.
    Upscale(UpscaleArgs),
    /// Count the self-intersections of MESH (.obj or .ply, quads split into two triangles;
    /// faces sharing a vertex do not count); exits with an error if there are any.
    Check(CheckArgs),
}

#[derive(Args, Debug)]
#[command(mut_arg("output", |a| a.help(
    "Output volume: .vox (MagicaVoxel; split into models of at most 256 voxels per axis, \
     placed by a scene graph) or .vol (DGtal)"
)))]
struct UpscaleArgs {
    #[command(flatten)]
    regularize: RegularizeArgs,
    /// Refinement factor per axis (2, 4 or 8 are typical; 1 to 16).
    #[arg(short = 'k', long, value_name = "K", default_value_t = 2)]
    factor: usize,
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
    /// With --split interfaces or regions, a directory (created if missing).
    #[arg(short, long, value_name = "OUTPUT")]
    output: PathBuf,
    /// One file (none), one file per interface between two regions, named
    /// interface_A_B.EXT after their smallest labels (interfaces), or one closed,
    /// outward-oriented surface per region, region_A.EXT (regions; open along the volume
    /// border with --no-background). Vertices shared by several files have identical
    /// coordinates in each.
    #[arg(long, value_enum, default_value_t = Split::None)]
    split: Split,
    /// The format of the files --split writes.
    #[arg(long, value_enum, value_name = "EXT", default_value_t = SplitFormat::Ply)]
    split_format: SplitFormat,
    /// With --split: duplicate pinched edges and vertices (two voxels of a region touching
    /// only along an edge or at a corner) so each file is a 2-manifold mesh.
    #[arg(long)]
    manifold: bool,
    /// Attachment weight (must be > 0; the papers use 1e-3, which lets thin curved shapes
    /// shrink).
    #[arg(long, default_value_t = PipelineParams::ENERGY.alpha)]
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
    /// With --normals at: most alternations of the sharpening stage after the last epsilon
    /// (0 turns it off: plain Ambrosio-Tortorelli, about a quarter faster). It keeps the
    /// edges of boxes sharp down to the surfels next to them.
    #[arg(long, value_name = "N", default_value_t = AtParams::default().sharpen_iterations)]
    sharpen: usize,
    /// With --normals at: the sharpening stage's threshold on the feature field v; surfels
    /// with a corner below it trust their input normal less. Higher keeps box edges sharper
    /// (0.4: both surfel rows beside a cube's edges within 3 degrees), lower smooths small,
    /// very curved parts better (0.3: a sphere of radius 6 voxels at 3.95 degrees mean error
    /// instead of 5.18).
    #[arg(long, value_name = "TAU", default_value_t = AtParams::default().sharpen_threshold)]
    sharpen_threshold: f64,
    /// Solver: auto (exact factorization for small surfaces, else cg), direct (sparse
    /// Cholesky), cg (multigrid conjugate gradient) or gd (gradient descent).
    #[arg(long, value_enum, default_value_t = SolverKind::Auto)]
    solver: SolverKind,
    /// Keep every vertex in the cube of edge (1 - EPS) voxel around its input position,
    /// which rules out self-intersections (paper, Proposition 2); EPS in voxels, 0.01 when
    /// omitted. Implies --solver gd. On by default for .vox inputs (voxel art must come
    /// out clean) unless --no-clamp or --solver direct|cg.
    #[arg(long, value_name = "EPS", num_args = 0..=1, default_missing_value = "0.01")]
    clamp: Option<f64>,
    /// Do not clamp, even for .vox inputs (faster; the result may self-intersect where
    /// thin parts collapse: check it with `voxreg check`).
    #[arg(long, conflicts_with = "clamp")]
    no_clamp: bool,
    /// Iterative solvers: stop when every vertex is estimated within this many voxels of
    /// the exact minimizer.
    #[arg(long, value_name = "VOXELS", default_value_t = 1e-3)]
    tolerance: f64,
    /// Normal refinement rounds: re-estimate the normals from the regularized quads
    /// (keeping sharp edges) and solve again, K times [default: 3; 0 for .vox inputs,
    /// whose blocky art is not a sampled smooth shape, and where each round is a clamped
    /// solve].
    #[arg(long, value_name = "K")]
    refine: Option<usize>,
    /// Do not re-centre the attachment targets between refinement rounds (the papers'
    /// behaviour: thin curved shapes shrink).
    #[arg(long)]
    no_preserve_size: bool,
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

/// How `--split` divides the output.
#[derive(Copy, Clone, Debug, PartialEq, Eq, clap::ValueEnum)]
enum Split {
    /// One mesh file.
    None,
    /// One file per interface (pair of regions).
    Interfaces,
    /// One outward-oriented surface per region (the background excepted).
    Regions,
}

/// The file formats of `--split-format`.
#[derive(Copy, Clone, Debug, PartialEq, Eq, clap::ValueEnum)]
enum SplitFormat {
    /// Binary PLY with face labels.
    Ply,
    /// Wavefront OBJ with one group per interface.
    Obj,
    /// Binary glTF.
    Glb,
    /// glTF JSON with an embedded buffer.
    Gltf,
}

impl SplitFormat {
    fn extension(self) -> &'static str {
        match self {
            SplitFormat::Ply => "ply",
            SplitFormat::Obj => "obj",
            SplitFormat::Glb => "glb",
            SplitFormat::Gltf => "gltf",
        }
    }
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
    fn estimator(self, radius: Option<f64>, at: &AtParams) -> Box<dyn NormalEstimator + Send + Sync> {
        match self {
            NormalsKind::Trivial => Box::new(Trivial),
            NormalsKind::Convolved => Box::new(ConvolvedTrivial { radius }),
            NormalsKind::Ii => Box::new(IntegralInvariant { radius }),
            NormalsKind::At => Box::new(at_estimator(radius, at)),
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

/// The `at` estimator: Ambrosio-Tortorelli (`params`) on integral invariants of the given
/// radius.
fn at_estimator(radius: Option<f64>, params: &AtParams) -> AmbrosioTortorelli {
    AmbrosioTortorelli::new(params.clone(), Box::new(IntegralInvariant { radius }))
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
        Command::Regularize(args) => regularize(&args, Product::Mesh),
        Command::Upscale(args) => regularize(&args.regularize, Product::Volume { factor: args.factor }),
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

/// Whether `path` is a MagicaVoxel file (voxel art: one solid region and clamping by
/// default).
fn is_vox(path: &Path) -> bool {
    path.extension().is_some_and(|e| e.eq_ignore_ascii_case("vox"))
}

/// Reads the input volume (see [`read_input`]); returns it with its region map and its
/// palette (colours and materials per label), if the format has one.
fn load(args: &InputArgs) -> Result<(LabelVolume, RegionMap, Option<Palette>)> {
    let (volume, palette) = read_input(args)?;
    let map = match args.regions.as_deref() {
        None if is_vox(&args.input) => RegionMap::single_solid(),
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

/// What `regularize` makes of the regularized surface.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
enum Product {
    /// The quad mesh (`voxreg regularize`).
    Mesh,
    /// A labeled volume `factor` times finer (`voxreg upscale`).
    Volume { factor: usize },
}

fn check_output(path: &Path, product: Product) -> Result<()> {
    let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    match (product, ext.as_deref()) {
        (Product::Mesh, Some("obj" | "ply" | "glb" | "gltf")) => Ok(()),
        (Product::Mesh, _) => {
            bail!("{}: unsupported output format (expected .obj, .ply, .glb or .gltf)", path.display())
        }
        (Product::Volume { factor }, Some("vox" | "vol")) => {
            if !(1..=16).contains(&factor) {
                bail!("--factor {factor}: must be in 1..=16");
            }
            Ok(())
        }
        (Product::Volume { .. }, _) => {
            bail!("{}: unsupported output format (expected .vox or .vol)", path.display())
        }
    }
}

fn terms_json(t: &EnergyTerms) -> serde_json::Value {
    json!({ "attachment": t.attachment, "alignment": t.alignment, "fairness": t.fairness, "total": t.total })
}

/// The meshes of `--split interfaces|regions` as `(file name, mesh)`, in interface or
/// region order; each vertex copies its position from `positions` bit for bit.
fn split_meshes(
    args: &RegularizeArgs,
    surface: &DigitalSurface,
    positions: &[glam::DVec3],
) -> Vec<(String, QuadMesh)> {
    let params = PatchParams { manifold: args.manifold };
    let ext = args.split_format.extension();
    match args.split {
        Split::None => Vec::new(),
        Split::Interfaces => (0..surface.interfaces().len() as u32)
            .map(|i| {
                let patch = surface.interface_patch(InterfaceId(i), &params);
                let name = format!("{}.{ext}", interface_name(surface, InterfaceId(i)));
                (name, QuadMesh::from_patch(surface, &patch, positions))
            })
            .collect(),
        Split::Regions => (0..surface.regions().len() as u32)
            .map(RegionId)
            .filter(|&r| Some(r) != surface.regions().background())
            .map(|r| {
                let patch = surface.region_patch(r, &params);
                (
                    format!("{}.{ext}", region_name(surface, r)),
                    QuadMesh::from_patch(surface, &patch, positions),
                )
            })
            .filter(|(_, mesh)| mesh.num_faces() > 0)
            .collect(),
    }
}

/// Writes the regularized surface: one file, or with `--split` a directory of files
/// written all or nothing. Returns what was written, for the summary line.
fn write_output(
    args: &RegularizeArgs,
    surface: &DigitalSurface,
    positions: &[glam::DVec3],
    palette: Option<&Palette>,
) -> Result<String> {
    let colour = |mut mesh: QuadMesh| {
        if let Some(palette) = palette {
            // Colour transfer: each quad takes the colour and material of its solid voxel.
            mesh.assign_materials(palette);
        }
        mesh
    };
    if args.split == Split::None {
        write_mesh(&args.output, &colour(QuadMesh::from_surface(surface, positions)))?;
        return Ok(args.output.display().to_string());
    }
    let mut batch = MeshBatch::new(&args.output)?;
    let meshes = split_meshes(args, surface, positions);
    for (name, mesh) in meshes {
        batch.write(&name, &colour(mesh))?;
    }
    let files = batch.commit()?;
    Ok(format!("{} files in {}", files.len(), args.output.display()))
}

fn regularize(args: &RegularizeArgs, product: Product) -> Result<()> {
    match (product, args.split) {
        (Product::Volume { .. }, Split::None) if args.manifold => {
            bail!("--manifold applies to split meshes (voxreg regularize --split), not to voxreg upscale")
        }
        (Product::Volume { .. }, Split::None) => check_output(&args.output, product)?,
        (Product::Volume { .. }, _) => {
            bail!("--split applies to meshes (voxreg regularize), not to voxreg upscale")
        }
        (Product::Mesh, Split::None) if args.manifold => {
            bail!("--manifold needs --split interfaces or regions (where three regions meet, one mesh cannot be manifold)")
        }
        (Product::Mesh, Split::None) => check_output(&args.output, product)?,
        _ if args.output.is_file() => {
            bail!("{}: --split writes a directory, but this is a file", args.output.display())
        }
        _ => {}
    }
    if let Some(path) = &args.features {
        if product != Product::Mesh {
            bail!("--features {}: voxreg upscale writes no mesh to carry the feature field", path.display());
        }
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
    if !(args.sharpen_threshold.is_finite() && args.sharpen_threshold > 0.0) {
        bail!("--sharpen-threshold must be finite and positive, got {}", args.sharpen_threshold);
    }
    let at_params = AtParams {
        sharpen_iterations: args.sharpen,
        sharpen_threshold: args.sharpen_threshold,
        ..AtParams::default()
    };
    let estimator = args.normals.estimator(args.radius, &at_params);
    let radius = args.normals.radius(args.radius, &surface);
    let label = match radius {
        Some(r) => format!("normals ({}, radius {r:.3})", estimator.name()),
        None => format!("normals ({})", estimator.name()),
    };
    let (normals, features) = stages.run("normals", &label, || match &args.features {
        Some(_) => {
            let (u, v) = at_estimator(args.radius, &at_params).estimate_with_features(&surface)?;
            Ok((u, Some(v)))
        }
        None => Ok((estimator.estimate(&surface)?, None)),
    })?;
    let positions = surface.positions();
    let weights = Weights {
        fairness: args.texture_aware.then(|| FairnessMask::texture_aware(&surface)),
        ..Default::default()
    };
    let pipeline = PipelineParams {
        energy: params,
        refine: args.refine.unwrap_or(if is_vox(input) { 0 } else { PipelineParams::default().refine }),
        preserve_size: !args.no_preserve_size,
        solver: solver_params(args)?,
        ..Default::default()
    };
    let out = solve(&mut stages, &surface, &normals, &weights, &pipeline, args.tolerance)?;
    let info = out.solves.last().expect("at least one solve").clone();
    // Report the solvers' own split, summed over the rounds: `assemble` = operator pattern
    // + numeric assembly, `solve` = symbolic analysis + numeric factorization + triangular
    // solves (or iterations), `refine` = normal refinement and re-centring.
    stages.timings.retain(|(k, _)| *k != "factor");
    let sum = |f: fn(&voxreg_regularize::SolveInfo) -> f64| out.solves.iter().map(f).sum::<f64>();
    stages.timings.push(("assemble", sum(|i| i.pattern_seconds + i.assemble_seconds)));
    stages.timings.push(("solve", sum(|i| i.symbolic_seconds + i.factor_seconds + i.solve_seconds)));
    stages.timings.push(("refine", out.refine_seconds));
    let regularized = &out.positions;
    // The energy of the last round (its normals and attachment targets).
    let energy = Energy::new(&surface, &out.normals, &out.targets, params)?.with_weights(&weights)?;
    let written = match product {
        Product::Mesh => stages.run("write", "write mesh", || {
            let written = write_output(args, &surface, regularized, palette.as_ref())?;
            if let (Some(path), Some(v)) = (&args.features, &features) {
                let mesh = QuadMesh::from_surface(&surface, regularized);
                write_ply_with_vertex_scalar(path, &mesh, "feature", v.as_slice())?;
            }
            Ok(written)
        })?,
        Product::Volume { factor } => {
            let fine = stages.run("upscale", &format!("upscale x{factor}"), || {
                upscale(&surface, regularized, &volume, &UpscaleParams { factor })
                    .with_context(|| format!("{}: cannot upscale", input.display()))
            })?;
            stages
                .run("write", "write volume", || Ok(write_volume(&args.output, &fine, palette.as_ref())?))?;
            args.output.display().to_string()
        }
    };

    let before = energy.terms(&positions);
    let after = energy.terms(regularized);
    let c = surface.counts();
    if !args.quiet {
        eprintln!(
            "{} quads, {} vertices; energy {:.6e} -> {:.6e}; relative gradient {:.1e}; wrote {written}",
            c.surfels, c.vertices, before.total, after.total, info.relative_gradient,
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
                "sharpen": (estimator.name() == "at").then_some(args.sharpen),
                "sharpen_threshold": (estimator.name() == "at").then_some(args.sharpen_threshold),
                "refine": pipeline.refine,
                "preserve_size": pipeline.preserve_size,
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
                "solves": out.solves.len(),
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
                "clamp": pipeline.solver.descent.clamp.filter(|_| info.solver == "gd"),
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
    let clamp = match (args.clamp, args.no_clamp, args.solver) {
        (Some(eps), _, _) => Some(eps),
        (None, false, SolverKind::Auto | SolverKind::Gd) if is_vox(&args.input.input) => Some(0.01),
        _ => None,
    };
    let choice = match (args.solver, clamp) {
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
    params.descent.clamp = clamp;
    Ok(params)
}

/// Runs the regularization pipeline (solve, then `--refine` rounds), with a progress bar
/// for the iterative solvers (iteration, estimated distance to the minimizer against the
/// tolerance, relative gradient).
fn solve(
    stages: &mut Stages,
    surface: &DigitalSurface,
    normals: &voxreg_normals::NormalField,
    weights: &Weights,
    params: &PipelineParams,
    tolerance: f64,
) -> Result<PipelineOutput> {
    let message = format!("solve ({} refinement rounds)", params.refine);
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
        let out = run_pipeline(surface, normals, Some(weights), params, &mut report);
        bar.finish_and_clear();
        if !quiet {
            if let Ok(PipelineOutput { solves, .. }) = &out {
                for info in solves.iter().filter(|i| i.solver != "direct") {
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
