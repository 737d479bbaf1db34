//! The command line: clap definitions, and their translation into the library's
//! parameters.

use std::path::PathBuf;

use anyhow::Result;
use clap::{Args, Parser, Subcommand};
use voxreg_digisurf::RegionMap;
use voxreg_io::{DataType, Endian};
use voxreg_regularize::{
    Clamp, Estimator, InputFacts, Overrides, Params, Preset, Regions, RegularizeError, SolverChoice,
};

/// Regularize voxel data (digital surfaces, multi-label interfaces) into smooth,
/// faithful quad meshes that keep one quad per voxel face.
#[derive(Parser, Debug)]
#[command(name = "voxreg", version, about, long_about = None)]
pub(crate) struct Cli {
    #[command(subcommand)]
    pub(crate) command: Command,
    /// Memory budget: inputs (and upscaled volumes) declaring more are refused before
    /// anything is allocated for them, e.g. 4G, 512M [default: half the physical memory;
    /// never above what `ulimit -v` and the cgroup's memory limit leave].
    #[arg(long, global = true, value_name = "SIZE", value_parser = parse_memory)]
    pub(crate) max_memory: Option<u64>,
}

#[derive(Subcommand, Debug)]
pub(crate) enum Command {
    /// Extract the digital surface of INPUT, regularize it and write it as a mesh.
    Regularize(RegularizeArgs),
    /// Describe INPUT: dimensions, labels, and its digital surface's cells.
    Info(InputArgs),
    /// Regularize INPUT's surface, then voxelize it at K times the resolution (papers,
    /// Fig. 13): a finer voxel model whose staircase follows the smooth surface.
    Upscale(UpscaleArgs),
    /// Open INPUT in the browser: a local page (127.0.0.1 only) that shows the
    /// regularized surface as it converges and re-solves it as parameters are tuned.
    View(ViewArgs),
    /// Regularize INPUT's surface, then compute geodesic distances on it from the surface
    /// points nearest the --from points (papers, Fig. 12): a PLY mesh with a per-vertex
    /// `distance` and a colour ramp with iso-lines.
    Geodesic(GeodesicArgs),
    /// Count the self-intersections of MESH (.obj or .ply, quads split into two triangles;
    /// exact: faces may touch only along the edges and at the corners they share), its
    /// faces with a non-finite vertex and its folds; exits with an error if there are any.
    Check(CheckArgs),
}

#[derive(Args, Debug)]
#[command(mut_arg("output", |a| a.help(
    "Output volume: .vox (MagicaVoxel; split into models of at most 256 voxels per axis, \
     placed by a scene graph) or .vol (DGtal)"
)))]
pub(crate) struct UpscaleArgs {
    #[command(flatten)]
    pub(crate) regularize: RegularizeArgs,
    /// Refinement factor per axis (2, 4 or 8 are typical; 1 to 16).
    #[arg(short = 'k', long, value_name = "K", default_value_t = 2)]
    pub(crate) factor: usize,
}

#[derive(Args, Debug)]
#[command(
    mut_arg("output", |a| a.required(false).default_value("view.glb").hide(true)),
    mut_arg("split", |a| a.hide(true)),
    mut_arg("split_format", |a| a.hide(true)),
    mut_arg("manifold", |a| a.hide(true)),
    mut_arg("features", |a| a.hide(true)),
    mut_arg("report", |a| a.hide(true))
)]
pub(crate) struct ViewArgs {
    #[command(flatten)]
    pub(crate) regularize: RegularizeArgs,
    /// The port to listen on (on 127.0.0.1) [default: a free port].
    #[arg(long, value_name = "PORT")]
    pub(crate) port: Option<u16>,
    /// Open the page in the default browser.
    #[arg(long)]
    pub(crate) open: bool,
}

#[derive(Args, Debug)]
#[command(mut_arg("output", |a| a.help(
    "Output mesh: .ply (binary quads, face labels, a per-vertex float `distance` and a \
     colour ramp from dark red at the sources to light grey, with darker iso-lines)"
)))]
pub(crate) struct GeodesicArgs {
    #[command(flatten)]
    pub(crate) regularize: RegularizeArgs,
    #[command(flatten)]
    pub(crate) geodesic: GeodesicOptions,
}

#[derive(Args, Debug, PartialEq)]
pub(crate) struct GeodesicOptions {
    /// A source point, in the output's coordinates (the volume's, with its spacing and
    /// origin); the nearest point of the surface measured on (on a face, an edge or a
    /// vertex) is the source. Repeat for several sources: each vertex gets the distance
    /// to the nearest.
    #[arg(long = "from", value_name = "X,Y,Z", required = true, value_parser = parse_point, allow_hyphen_values = true)]
    pub(crate) from: Vec<glam::DVec3>,
    /// exact (polyhedral geodesics, window propagation) or heat (the heat method: faster
    /// on large surfaces, within a few percent).
    #[arg(long, value_enum, default_value_t = GeodesicMethod::Exact)]
    pub(crate) method: GeodesicMethod,
    /// The mesh written: the regularized surface (proxy) or the staircase (digital) with
    /// the same distances, vertex for vertex (papers, Fig. 12 (b)).
    #[arg(long, value_enum, value_name = "SURFACE", default_value_t = SurfaceKind::Proxy)]
    pub(crate) on: SurfaceKind,
    /// The surface distances are measured on: the regularized proxy, or the staircase
    /// itself for comparison (papers, Fig. 12 (a): anisotropic).
    #[arg(long, value_enum, value_name = "SURFACE", default_value_t = SurfaceKind::Proxy)]
    pub(crate) metric: SurfaceKind,
    /// Spacing of the iso-lines, in the output's units [default: a tenth of the largest
    /// distance].
    #[arg(long, value_name = "D", value_parser = positive_named("--iso"))]
    pub(crate) iso: Option<f64>,
}

/// `--method` of `voxreg geodesic`.
#[derive(Copy, Clone, Debug, PartialEq, Eq, clap::ValueEnum)]
pub(crate) enum GeodesicMethod {
    /// Exact polyhedral geodesics.
    Exact,
    /// The heat method.
    Heat,
}

impl GeodesicMethod {
    pub(crate) fn method(self) -> voxreg_geodesic::Method {
        match self {
            GeodesicMethod::Exact => voxreg_geodesic::Method::Exact,
            GeodesicMethod::Heat => voxreg_geodesic::Method::Heat,
        }
    }
}

/// `--on` and `--metric` of `voxreg geodesic`.
#[derive(Copy, Clone, Debug, PartialEq, Eq, clap::ValueEnum)]
pub(crate) enum SurfaceKind {
    /// The regularized surface.
    Proxy,
    /// The digital surface (the voxels' faces).
    Digital,
}

#[derive(Args, Debug)]
pub(crate) struct CheckArgs {
    /// The mesh: .obj or .ply (as written by voxreg regularize).
    pub(crate) mesh: PathBuf,
    /// Also measure the mesh against the labeled volume it came from (any non-background
    /// voxel solid): solid voxel centres next to the surface left outside, empty ones put
    /// inside, and thin voxels (both neighbours along an axis empty) less than 0.25 voxel
    /// deep; for a clamped mesh (every vertex within half a voxel of its corner, as the
    /// voxel-art preset makes), also the mean angle between adjacent quads on and off thin
    /// voxels and the angle kept at the voxels' box edges; reported, not errors.
    #[arg(long, value_name = "VOLUME")]
    pub(crate) voxels: Option<PathBuf>,
}

#[derive(Args, Debug, Clone)]
pub(crate) struct InputArgs {
    /// Input volume: .vol, .longvol, .pgm3d (DGtal), .vox (MagicaVoxel), .nii, .nii.gz
    /// (NIfTI-1), .vti (VTK image data), .npy (NumPy, shape (X, Y, Z)), .tif/.tiff (a
    /// stack; or a directory or 'slice_*.tif' pattern of slices), .nrrd/.nhdr (NRRD,
    /// .seg.nrrd), .mrc/.map/.rec (MRC), or raw data with --dims.
    pub(crate) input: PathBuf,
    /// Make a binary volume: voxels whose value (label or grey level) is > T are inside.
    /// Needed for grey-level data (fractional, negative or scaled values).
    #[arg(long, value_name = "T", allow_negative_numbers = true, conflicts_with = "labels")]
    pub(crate) threshold: Option<f64>,
    /// Keep only these labels; every other label becomes the background.
    #[arg(long, value_name = "L,L,...", value_delimiter = ',', conflicts_with = "no_background")]
    pub(crate) labels: Option<Vec<u32>>,
    /// The background label: empty space, which also fills the outside of the volume
    /// (default 0).
    #[arg(long, value_name = "L", conflicts_with = "no_background")]
    pub(crate) background: Option<u32>,
    /// No background: every label is a material, and interfaces that reach the border
    /// of the volume end there as open surfaces.
    #[arg(long)]
    pub(crate) no_background: bool,
    /// Read INPUT as raw data (no header, x fastest) of these dimensions.
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_dims)]
    pub(crate) dims: Option<[u64; 3]>,
    /// Raw data: the type of a value, u8 (default), u16, u32, f32 (or i8, i16, i32, u64,
    /// i64, f64).
    #[arg(long, value_name = "TYPE", requires = "dims")]
    pub(crate) dtype: Option<DataType>,
    /// Raw data: the byte order, little (default) or big.
    #[arg(long, value_name = "ORDER", requires = "dims")]
    pub(crate) endian: Option<Endian>,
    /// MagicaVoxel: read only model K (0-based, as `voxreg info` lists them), alone,
    /// instead of the scene [default: the scene graph, or model 0 of a file without one,
    /// such as animation frames].
    #[arg(long, value_name = "K")]
    pub(crate) model: Option<usize>,
    /// The size of a voxel, for raw data, or overriding the file's.
    #[arg(long, value_name = "SX,SY,SZ", value_parser = parse_spacing, allow_hyphen_values = true)]
    pub(crate) spacing: Option<glam::DVec3>,
    /// How labels form regions: "label" (each label its own region), "solid" (all
    /// non-background labels one region), or groups such as "1,2,3;7" [default: the
    /// preset's: solid for voxel art, label otherwise].
    #[arg(long, value_name = "SPEC")]
    pub(crate) regions: Option<String>,
}

impl InputArgs {
    /// The region map of `--regions`, or `None` for the preset's.
    pub(crate) fn region_map(&self) -> Result<Option<RegionMap>> {
        self.regions.as_ref().map(|s| Regions::Spec(s.clone()).map().map_err(cli_error)).transpose()
    }
}

/// `--preset`: the library's presets, with their descriptions as the values' help.
fn preset_parser() -> impl clap::builder::TypedValueParser<Value = Preset> {
    use clap::builder::{PossibleValue, PossibleValuesParser, TypedValueParser};
    PossibleValuesParser::new(Preset::ALL.map(|p| PossibleValue::new(p.name()).help(p.description())))
        .map(|s| s.parse::<Preset>().expect("a listed preset"))
}

/// A library error for the command line: an option's error names its flag
/// (`--sharpen-threshold must be ...`).
pub(crate) fn cli_error(e: RegularizeError) -> anyhow::Error {
    match e {
        RegularizeError::InvalidOption { option, message } => {
            anyhow::anyhow!("--{} {message}", option.replace('_', "-"))
        }
        e => e.into(),
    }
}

#[derive(Args, Debug, Clone)]
pub(crate) struct RegularizeArgs {
    #[command(flatten)]
    pub(crate) input: InputArgs,
    #[command(flatten)]
    pub(crate) simplify: SimplifyArgs,
    /// Output mesh: .obj (quads, one group per interface, with an .mtl for coloured
    /// inputs), .ply (binary quads, face labels and colours), .glb or .gltf (glTF 2.0,
    /// triangulated, one material per colour), .stl (binary, triangles only) or .vtp
    /// (VTK PolyData: quads, face labels and colours as cell data).
    /// With --split interfaces or regions, a directory (created if missing).
    #[arg(short, long, value_name = "OUTPUT")]
    pub(crate) output: PathBuf,
    /// One file (none), one file per interface between two regions, named
    /// interface_A_B.EXT after their smallest labels (interfaces), or one closed,
    /// outward-oriented surface per region, region_A.EXT (regions; open along the volume
    /// border with --no-background). Vertices shared by several files have identical
    /// coordinates in each.
    #[arg(long, value_enum, default_value_t = Split::None)]
    pub(crate) split: Split,
    /// The format of the files --split writes.
    #[arg(long, value_enum, value_name = "EXT", default_value_t = SplitFormat::Ply)]
    pub(crate) split_format: SplitFormat,
    /// With --split: duplicate pinched edges and vertices (two voxels of a region touching
    /// only along an edge or at a corner) so each file is a 2-manifold mesh; faces that
    /// cross or fold in a file are moved back towards their voxel corners until none does.
    #[arg(long)]
    pub(crate) manifold: bool,
    /// The parameters every other option starts from [default: voxel-art for .vox input,
    /// default otherwise].
    #[arg(long, value_parser = preset_parser())]
    pub(crate) preset: Option<Preset>,
    #[command(flatten)]
    pub(crate) options: OverrideArgs,
    /// With --normals at: also write the Ambrosio-Tortorelli feature field v (low on sharp
    /// features, about 1 elsewhere) on the output mesh, as a binary PLY with a per-vertex
    /// float property `feature` and a colour ramp (dark red 0, amber 0.5, light grey 1).
    #[arg(long, value_name = "FILE.ply")]
    pub(crate) features: Option<PathBuf>,
    /// Write a machine-readable JSON report of the run (timings, counts, energies, solver).
    #[arg(long, value_name = "FILE.json")]
    pub(crate) report: Option<PathBuf>,
    /// Print nothing but errors.
    #[arg(short, long)]
    pub(crate) quiet: bool,
}

impl RegularizeArgs {
    /// The preset: `--preset`, else the one the input calls for.
    pub(crate) fn preset(&self, voxel_art: bool) -> Preset {
        self.preset.unwrap_or_else(|| Preset::for_input(&InputFacts::voxel_art(voxel_art)))
    }

    /// The options given on the command line, as the library's overrides.
    pub(crate) fn overrides(&self) -> Overrides {
        self.options.overrides(self.input.regions.as_deref())
    }

    /// The library's parameters: the preset with every option given on the command line
    /// applied over it, validated.
    pub(crate) fn params(&self, voxel_art: bool) -> Result<Params> {
        self.overrides().resolve(Some(self.preset(voxel_art)), &InputFacts::default()).map_err(cli_error)
    }
}

/// The options that become the library's [`Overrides`], one flag per field (`clamp` is
/// `--clamp [EPS]` and `--no-clamp`, `preserve_size` `--no-preserve-size`); the library
/// validates them ([`Overrides::resolve`]).
#[derive(Args, Debug, Clone)]
pub(crate) struct OverrideArgs {
    /// Attachment weight (must be > 0; the papers use 1e-3, which lets thin curved shapes
    /// shrink) [default: the preset's, 1e-2].
    #[arg(long)]
    pub(crate) alpha: Option<f64>,
    /// Alignment weight [default: 1].
    #[arg(long)]
    pub(crate) beta: Option<f64>,
    /// Fairness weight [default: the preset's, 0.1; 1 for voxel-art].
    #[arg(long)]
    pub(crate) gamma: Option<f64>,
    /// Normal estimator driving the alignment term [default: ii].
    #[arg(long, value_enum)]
    pub(crate) normals: Option<NormalsKind>,
    /// Radius of the ii, convolved, at and diffused estimators, in physical units [default:
    /// the multigrid rule 3 h^(1/3), h the largest voxel spacing, kept within 3 to 12
    /// voxels: 3 at unit spacing; 2 voxels for the voxel-art preset; 8 voxels of the finest
    /// axis for diffused].
    #[arg(long, value_name = "R")]
    pub(crate) radius: Option<f64>,
    /// With --normals at: most alternations of the sharpening stage after the last epsilon
    /// (0 turns it off: plain Ambrosio-Tortorelli, about a quarter faster). It keeps the
    /// edges of boxes sharp down to the surfels next to them [default: 10].
    #[arg(long, value_name = "N")]
    pub(crate) sharpen: Option<usize>,
    /// With --normals at: the sharpening stage's threshold on the feature field v; surfels
    /// with a corner below it trust their input normal less. Higher keeps box edges
    /// sharper, lower smooths small, very curved parts better [default: 0.4].
    #[arg(long, value_name = "TAU")]
    pub(crate) sharpen_threshold: Option<f64>,
    /// Solver: auto (exact factorization for small surfaces, else cg), direct (sparse
    /// Cholesky), cg (multigrid conjugate gradient) or bounded (conjugate gradient inside
    /// per-vertex boxes; `gd` is its former name) [default: the preset's].
    #[arg(long, value_enum)]
    pub(crate) solver: Option<SolverKind>,
    /// Keep every vertex in the cube of edge (1 - EPS) voxel around its input position,
    /// which rules out self-intersections (paper, Proposition 2); EPS in voxels [default: the
    /// preset's, 0.01]. Implies --solver bounded. On in the voxel-art preset (the default for .vox
    /// inputs) unless --no-clamp or --solver direct|cg.
    #[arg(long, value_name = "EPS", num_args = 0..=1)]
    pub(crate) clamp: Option<Option<f64>>,
    /// Do not clamp, even for .vox inputs (faster; the result may self-intersect where
    /// thin parts collapse: check it with `voxreg check`).
    #[arg(long, conflicts_with = "clamp")]
    pub(crate) no_clamp: bool,
    /// Voxel art: how rounded, from 0 (exclusive: blocky, edges only softened) to 1
    /// (rounded, the default): each vertex moves at most S times half a voxel from its
    /// voxel corner. Thin parts keep their thickness and no face folds at any S.
    /// Implies --solver bounded.
    #[arg(long, value_name = "S", conflicts_with_all = ["clamp", "no_clamp"])]
    pub(crate) smoothness: Option<f64>,
    /// Iterative solvers: stop when every vertex is estimated within this many voxels of
    /// the exact minimizer [default: 1e-3].
    #[arg(long, value_name = "VOXELS")]
    pub(crate) tolerance: Option<f64>,
    /// Normal refinement rounds: re-estimate the normals from the regularized quads
    /// (keeping sharp edges) and solve again, K times [default: the preset's: 3; 0 for
    /// papers, for voxel art, whose blocky art is not a sampled smooth shape, and for fast,
    /// whose one batch of sweeps from its diffused field is as accurate as more rounds].
    #[arg(long, value_name = "K")]
    pub(crate) refine: Option<usize>,
    /// The solves before the last refinement round stop at F times --tolerance (their
    /// positions only feed the refined normals): larger is faster, 1 solves every round
    /// to the tolerance [default: 2].
    #[arg(long, value_name = "F")]
    pub(crate) intermediate_tolerance: Option<f64>,
    /// Do not re-centre the attachment targets between refinement rounds (the papers'
    /// behaviour: thin curved shapes shrink).
    #[arg(long)]
    pub(crate) no_preserve_size: bool,
    /// Texture-aware fairness (paper, sec. 4.5): barycenters leave out the neighbours
    /// across a colour (label) boundary, so quad edges follow colour boundaries.
    #[arg(long)]
    pub(crate) texture_aware: bool,
}

impl OverrideArgs {
    /// The overrides, with `regions` (`--regions`, an input option).
    pub(crate) fn overrides(&self, regions: Option<&str>) -> Overrides {
        let mut o = Overrides::default();
        o.regions = regions.map(|s| Regions::Spec(s.to_string()));
        o.normals = self.normals.map(NormalsKind::estimator);
        o.radius = self.radius;
        o.sharpen = self.sharpen;
        o.sharpen_threshold = self.sharpen_threshold;
        o.alpha = self.alpha;
        o.beta = self.beta;
        o.gamma = self.gamma;
        o.solver = self.solver.map(SolverKind::choice);
        o.clamp = match (self.clamp, self.no_clamp) {
            (Some(Some(eps)), _) => Some(Clamp::Margin(eps)),
            (Some(None), _) => Some(Clamp::On),
            (None, true) => Some(Clamp::Off),
            (None, false) => None,
        };
        o.smoothness = self.smoothness;
        o.tolerance = self.tolerance;
        o.refine = self.refine;
        o.intermediate_tolerance = self.intermediate_tolerance;
        o.preserve_size = self.no_preserve_size.then_some(false);
        o.texture_aware = self.texture_aware.then_some(true);
        o
    }
}

/// The solvers `--solver` can pick.
#[derive(Copy, Clone, Debug, PartialEq, Eq, clap::ValueEnum)]
pub(crate) enum SolverKind {
    /// Exact factorization when its factor is small (a few thousand vertices), else cg.
    Auto,
    /// Sparse Cholesky: exact to rounding; memory grows fast with the surface.
    Direct,
    /// Multigrid-preconditioned conjugate gradient: fast, memory linear in the surface.
    Cg,
    /// Conjugate gradient inside per-vertex boxes: the only one that can --clamp.
    #[value(alias = "gd")]
    Bounded,
    /// Fixed batches of block-Jacobi sweeps, not to a tolerance (the fast preset's).
    Sweeps,
}

impl SolverKind {
    fn choice(self) -> SolverChoice {
        match self {
            SolverKind::Auto => SolverChoice::Auto,
            SolverKind::Direct => SolverChoice::Direct,
            SolverKind::Cg => SolverChoice::Cg,
            SolverKind::Bounded => SolverChoice::Bounded,
            SolverKind::Sweeps => SolverChoice::Sweeps,
        }
    }
}

/// How `--split` divides the output.
#[derive(Copy, Clone, Debug, PartialEq, Eq, clap::ValueEnum)]
pub(crate) enum Split {
    /// One mesh file.
    None,
    /// One file per interface (pair of regions).
    Interfaces,
    /// One outward-oriented surface per region (the background excepted).
    Regions,
}

/// The file formats of `--split-format`.
#[derive(Copy, Clone, Debug, PartialEq, Eq, clap::ValueEnum)]
pub(crate) enum SplitFormat {
    /// Binary PLY with face labels.
    Ply,
    /// Wavefront OBJ with one group per interface.
    Obj,
    /// Binary glTF.
    Glb,
    /// glTF JSON with an embedded buffer.
    Gltf,
    /// Binary STL (triangles; with --split regions, one closed solid per file).
    Stl,
    /// VTK XML PolyData with face labels.
    Vtp,
}

impl SplitFormat {
    pub(crate) fn extension(self) -> &'static str {
        match self {
            SplitFormat::Ply => "ply",
            SplitFormat::Obj => "obj",
            SplitFormat::Glb => "glb",
            SplitFormat::Gltf => "gltf",
            SplitFormat::Stl => "stl",
            SplitFormat::Vtp => "vtp",
        }
    }
}

/// The normal estimators `--normals` can pick.
#[derive(Copy, Clone, Debug, PartialEq, Eq, clap::ValueEnum)]
pub(crate) enum NormalsKind {
    /// Each face's own axis (no smoothing).
    Trivial,
    /// Trivial normals averaged over the surface within the radius.
    Convolved,
    /// Integral invariant: covariance of a ball intersected with the solid.
    Ii,
    /// Ambrosio-Tortorelli regularization of the ii normals: smooth, but keeps sharp features.
    At,
    /// The faces' own axes diffused over the surface within the radius: cheap and smooth
    /// (the fast preset's).
    Diffused,
}

impl NormalsKind {
    fn estimator(self) -> Estimator {
        match self {
            NormalsKind::Trivial => Estimator::Trivial,
            NormalsKind::Convolved => Estimator::Convolved,
            NormalsKind::Ii => Estimator::Ii,
            NormalsKind::At => Estimator::At,
            NormalsKind::Diffused => Estimator::Diffused,
        }
    }
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

fn parse_point(s: &str) -> std::result::Result<glam::DVec3, String> {
    let [x, y, z] = parse_three::<f64>(s, "coordinates")?;
    let p = glam::DVec3::new(x, y, z);
    if !p.is_finite() {
        return Err(format!("'{s}': coordinates must be finite"));
    }
    Ok(p)
}

fn parse_memory(s: &str) -> std::result::Result<u64, String> {
    voxreg_io::parse_size(s).ok_or_else(|| format!("--max-memory '{s}' is not a size such as 4G or 512M"))
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

/// A parser of finite positive numbers whose message names the option.
fn positive_named(option: &'static str) -> impl Fn(&str) -> std::result::Result<f64, String> + Clone {
    move |s: &str| match s.parse::<f64>() {
        Ok(x) if x.is_finite() && x > 0.0 => Ok(x),
        _ => Err(format!("{option} must be finite and positive, got '{s}'")),
    }
}

/// Simplification options of `voxreg regularize`.
#[derive(Args, Debug, Clone, Default)]
pub(crate) struct SimplifyArgs {
    /// Simplify the mesh to about RATIO of its faces (0 < RATIO <= 1), keeping the
    /// partition: each interface simplified once, junction lines shared, their corners
    /// kept, every region closed; within --max-error of the full surface.
    #[arg(long, value_name = "RATIO")]
    pub(crate) simplify: Option<f64>,
    /// The largest distance, in voxels (of the smallest spacing), of any vertex of the
    /// full surface to the simplified one. Default with --simplify or --lod: 0.5. Alone:
    /// simplify as far as this distance allows.
    #[arg(long, value_name = "E")]
    pub(crate) max_error: Option<f64>,
    /// Write N levels of detail, OUTPUT's name with .lod0 ... .lod{N-1} before its
    /// extension: level 0 the full mesh, each next one about 1/4 of the previous one's
    /// faces within --max-error times 2^(k-1) (nested bounds).
    #[arg(long, value_name = "N")]
    pub(crate) lod: Option<usize>,
}

impl SimplifyArgs {
    /// Whether any of the options is given.
    pub(crate) fn active(&self) -> bool {
        self.simplify.is_some() || self.max_error.is_some() || self.lod.is_some()
    }
}
