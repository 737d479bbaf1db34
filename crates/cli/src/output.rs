//! Writing the regularized surface: one mesh, a directory of split meshes, or an
//! upscaled volume; and checking the output paths before any work.

use std::path::{Path, PathBuf};

use anyhow::{bail, Result};
use glam::DVec3;
use voxreg_digisurf::{DigitalSurface, InterfaceId, Patch, PatchParams, RegionId};
use voxreg_io::{file_kind, named_interface_name, named_region_name, MeshBatch, Outputs, Palette, QuadMesh};

use crate::args::{GeodesicOptions, RegularizeArgs, Split};
use crate::input::Source;

/// What `regularize` makes of the regularized surface.
#[derive(Copy, Clone, Debug, PartialEq)]
pub(crate) enum Product<'a> {
    /// The quad mesh (`voxreg regularize`).
    Mesh,
    /// A labeled volume `factor` times finer (`voxreg upscale`).
    Volume { factor: usize },
    /// The quad mesh with geodesic distances (`voxreg geodesic`).
    Geodesic(&'a GeodesicOptions),
}

/// Refuses option combinations and output paths that cannot be written, before any work.
pub(crate) fn check_outputs(args: &RegularizeArgs, product: Product<'_>) -> Result<()> {
    match (product, args.split) {
        (Product::Volume { .. }, Split::None) if args.manifold => {
            bail!("--manifold applies to split meshes (voxreg regularize --split), not to voxreg upscale")
        }
        (Product::Volume { .. }, Split::None) => check_extension(&args.output, product)?,
        (Product::Volume { .. }, _) => {
            bail!("--split applies to meshes (voxreg regularize), not to voxreg upscale")
        }
        (Product::Mesh, Split::None) if args.manifold => {
            bail!("--manifold needs --split interfaces or regions (where three regions meet, one mesh cannot be manifold)")
        }
        (Product::Mesh, Split::None) => check_extension(&args.output, product)?,
        (Product::Geodesic(_), Split::None) if args.manifold => {
            bail!("--manifold applies to split meshes (voxreg regularize --split), not to voxreg geodesic")
        }
        (Product::Geodesic(_), Split::None) => check_extension(&args.output, product)?,
        (Product::Geodesic(_), _) => {
            bail!("--split applies to voxreg regularize, not to voxreg geodesic (one mesh carries the distances)")
        }
        _ if args.output.is_file() => {
            bail!("{}: --split writes a directory, but this is a file", args.output.display())
        }
        _ => {}
    }
    check_paths(args, product)?;
    if crate::input::voxel_art(&args.input) {
        check_library(args, product, true)?;
    }
    crate::simplify::check(args, product == Product::Mesh)?;
    if let Some(path) = &args.features {
        if product != Product::Mesh {
            bail!("--features {}: only voxreg regularize writes the feature field", path.display());
        }
        if args.options.normals != Some(crate::args::NormalsKind::At) {
            bail!("--features {}: only --normals at has a feature field", path.display());
        }
        if !path.extension().is_some_and(|e| e.eq_ignore_ascii_case("ply")) {
            bail!("{}: --features writes PLY only (expected .ply)", path.display());
        }
    }
    Ok(())
}

/// Every output path (`-o`, `--report`, `--features`, and the `.mtl` beside an OBJ) can
/// be written: a plain file name (no trailing `/`, at most 255 bytes), a regular file or a
/// new path (never a symbolic link, a device, a FIFO or a socket; a directory only for
/// `-o` with `--split`), its directory exists and is writable, it resolves to none of
/// the files the input reads, and no two outputs resolve to the same file.
fn check_paths(args: &RegularizeArgs, product: Product<'_>) -> Result<()> {
    let split = product == Product::Mesh && args.split != Split::None;
    let mut outputs: Vec<(&str, PathBuf)> = vec![("-o", args.output.clone())];
    outputs.extend(args.report.clone().map(|p| ("--report", p)));
    outputs.extend(args.features.clone().map(|p| ("--features", p)));
    // Reserved whether or not the mesh has materials: no other output may take its name.
    if let Some(mtl) = library(args, product) {
        outputs.push((LIBRARY, mtl));
    }
    let input = &args.input.input;
    let read = voxreg_io::input_files(input, args.input.dims.is_some());
    for (k, (option, path)) in outputs.iter().enumerate() {
        let option = *option;
        let dir_output = split && option == "-o";
        check_name(option, path, dir_output)?;
        if option != LIBRARY {
            check_kind(option, path, dir_output)?;
        }
        if let Some(file) = read.clash(path) {
            if read.dirs.iter().any(|d| d == file) {
                bail!("{}: {option} lies inside {}, which the input reads", path.display(), file.display());
            }
            if file == input.as_path() {
                bail!("{}: {option} would overwrite the input", path.display());
            }
            bail!("{}: {option} would overwrite {}, which the input reads", path.display(), file.display());
        }
        if let Some((other, _)) = outputs[..k].iter().find(|(_, p)| voxreg_io::same_output(p, path)) {
            bail!("{}: {option} and {other} name the same file", path.display());
        }
        if split && option != "-o" && split_name(args, path) {
            bail!(
                "{}: {option} may be one of the files --split writes in {}",
                path.display(),
                args.output.display()
            );
        }
        if option == LIBRARY {
            continue;
        }
        if dir_output {
            // The directory is created if missing: its nearest existing ancestor must be
            // a writable directory.
            let existing = path.ancestors().find(|a| a.as_os_str().is_empty() || a.exists());
            match existing {
                Some(a) if a == path => writable_dir(path, option)?,
                Some(a) => writable_dir(if a.as_os_str().is_empty() { Path::new(".") } else { a }, option)
                    .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?,
                None => {}
            }
            continue;
        }
        let parent = match path.parent() {
            Some(p) if !p.as_os_str().is_empty() => p,
            _ => Path::new("."),
        };
        if !parent.is_dir() {
            bail!("{}: {option}: the directory {} does not exist", path.display(), parent.display());
        }
        writable_dir(parent, option).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    }
    Ok(())
}

/// How errors name the `.mtl` beside an OBJ `-o`.
const LIBRARY: &str = "the material library of -o";

/// The most bytes of a file name that common file systems take.
const NAME_MAX: usize = 255;

/// Refuses an output path that names no file (a trailing `/`, or `.` or `..` last)
/// unless it is the `--split` directory, and a file name longer than file systems take.
fn check_name(option: &str, path: &Path, dir_output: bool) -> Result<()> {
    let text = path.as_os_str().to_string_lossy();
    let trailing = text.ends_with('/') || text.ends_with(std::path::MAIN_SEPARATOR);
    match path.file_name() {
        Some(name) if name.len() > NAME_MAX => bail!(
            "{}: {option}: the file name is {} bytes long, over the {NAME_MAX} that file systems take",
            path.display(),
            name.len()
        ),
        _ if dir_output => Ok(()),
        Some(_) if !trailing => Ok(()),
        _ => bail!("{}: {option} names a directory, not a file", path.display()),
    }
}

/// Refuses an output that exists and is not a regular file: a symbolic link (replacing
/// it would replace the link, not the file it points to, and writing through it would
/// write where the command line does not say), a device (`/dev/null`), a FIFO or a
/// socket; a directory unless `dir_output` (the `--split` directory, which may be a link
/// to one: the files are written inside it).
fn check_kind(option: &str, path: &Path, dir_output: bool) -> Result<()> {
    let Ok(meta) = std::fs::symlink_metadata(path) else { return Ok(()) };
    let t = meta.file_type();
    if t.is_file() || (dir_output && path.is_dir()) {
        return Ok(());
    }
    if t.is_dir() {
        bail!("{}: {option} names a directory", path.display());
    }
    if t.is_symlink() {
        bail!(
            "{}: {option} is a symbolic link: voxreg writes only regular files or new paths (name the file it points to)",
            path.display()
        );
    }
    bail!(
        "{}: {option} is {}, not a regular file: voxreg writes only regular files or new paths",
        path.display(),
        file_kind(&meta)
    )
}

/// The material library an OBJ `-o` may come with: `<stem>.mtl` beside it.
fn library(args: &RegularizeArgs, product: Product<'_>) -> Option<PathBuf> {
    let obj = args.output.extension().is_some_and(|e| e.eq_ignore_ascii_case("obj"));
    (product == Product::Mesh && args.split == Split::None && obj).then(|| args.output.with_extension("mtl"))
}

/// Whether `path` lies in the `--split` directory under a name the split files take.
fn split_name(args: &RegularizeArgs, path: &Path) -> bool {
    let parent = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    let name = path.file_name().map(|n| n.to_string_lossy()).unwrap_or_default();
    (name.starts_with("region_") || name.starts_with("interface_"))
        && voxreg_io::same_output(parent, &args.output)
}

/// Checks what writing the materials of a coloured input needs: the `.mtl` beside an OBJ
/// `-o` has a name OBJ can write (no whitespace) and is a regular file or a new path.
/// Called before any work for inputs known to be coloured (voxel art), else once the
/// input is read and has a palette.
pub(crate) fn check_library(args: &RegularizeArgs, product: Product<'_>, coloured: bool) -> Result<()> {
    let Some(mtl) = library(args, product).filter(|_| coloured) else { return Ok(()) };
    let name = mtl.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    if name.chars().any(char::is_whitespace) {
        bail!(
            "{}: the material library name '{name}' holds whitespace, which OBJ cannot name (the input is \
             coloured): rename the output",
            args.output.display()
        );
    }
    check_kind(LIBRARY, &mtl, false)
}

/// Checks that `dir` is a directory in which a file can be created (by creating and
/// removing a temporary one).
fn writable_dir(dir: &Path, option: &str) -> Result<()> {
    if !dir.is_dir() {
        bail!("{option}: {} is not a directory", dir.display());
    }
    tempfile::Builder::new()
        .prefix(&voxreg_io::inflight::temp_prefix())
        .suffix(".tmp")
        .tempfile_in(dir)
        .map(drop)
        .map_err(|e| anyhow::anyhow!("{option}: cannot write in {}: {e}", dir.display()))
}

/// Checks, once the volume is read and before the regularization, what the output
/// needs of it: labels PLY can hold, and for `upscale` a fine volume within the memory
/// budget.
pub(crate) fn check_volume(args: &RegularizeArgs, product: Product<'_>, volume: &Source) -> Result<()> {
    let input = &args.input.input;
    let ply = match product {
        Product::Mesh if args.split == Split::None => {
            args.output.extension().is_some_and(|e| e.eq_ignore_ascii_case("ply"))
        }
        Product::Mesh => args.split_format == crate::args::SplitFormat::Ply,
        Product::Geodesic(_) => true,
        Product::Volume { .. } => false,
    };
    if ply {
        if let Some(max) = volume.max_label().filter(|&m| m > i32::MAX as u32) {
            bail!(
                "{}: label {max} does not fit PLY's int labels (at most {}): write .obj or .glb",
                input.display(),
                i32::MAX
            );
        }
    }
    if let Product::Volume { factor } = product {
        let fine = volume.dims().map(|d| d as u128 * factor as u128);
        let vox = args.output.extension().is_some_and(|e| e.eq_ignore_ascii_case("vox"));
        let (voxels, what) = match volume {
            // Block by block into a .vox scene: the blocks' boxes, grown by a voxel on each
            // side (the smooth surface leaves the staircase by less).
            Source::Blocks(v) if vox => {
                let grown: u128 = v
                    .blocks()
                    .iter()
                    .map(|b| {
                        b.labels.shape().iter().map(|&d| (d as u128 + 2) * factor as u128).product::<u128>()
                    })
                    .sum();
                (grown, format!("upscaling x{factor} to {grown} voxels in blocks"))
            }
            _ => {
                let voxels = fine.iter().product::<u128>();
                (voxels, format!("upscaling x{factor} to {}x{}x{} voxels", fine[0], fine[1], fine[2]))
            }
        };
        // The upscaled labels, the per-column buffers they are gathered from, and the
        // written file's bytes.
        voxreg_io::check_memory(input, &what, voxels * 9)?;
    }
    Ok(())
}

/// Refuses an upscaled volume that lost the model: empty, or with less than half the
/// solid voxels the input has at the finer resolution (thin parts collapsed).
pub(crate) fn check_upscaled(
    args: &RegularizeArgs,
    coarse: &Source,
    fine: &Source,
    factor: usize,
) -> Result<()> {
    let solid = |v: &Source| match v {
        Source::Dense(v) => {
            let b = v.background();
            v.labels().iter().filter(|&&l| Some(l) != b).count() as u128
        }
        Source::Blocks(v) => {
            let b = v.background();
            v.blocks().iter().map(|k| k.labels.iter().filter(|&&l| l != b).count() as u128).sum()
        }
    };
    let (before, after) = (solid(coarse) * (factor as u128).pow(3), solid(fine));
    if after * 2 < before {
        bail!(
            "{}: the smooth surface keeps {after} of the {before} solid voxels at x{factor} \
             (thin parts collapse); nothing written to {}",
            args.input.input.display(),
            args.output.display()
        );
    }
    Ok(())
}

fn check_extension(path: &Path, product: Product<'_>) -> Result<()> {
    let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    match (product, ext.as_deref()) {
        (Product::Mesh, Some("obj" | "ply" | "glb" | "gltf" | "stl" | "vtp")) => Ok(()),
        (Product::Mesh, _) => {
            bail!(
                "{}: unsupported output format (expected .obj, .ply, .glb, .gltf, .stl or .vtp)",
                path.display()
            )
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
        (Product::Geodesic(_), Some("ply")) => Ok(()),
        (Product::Geodesic(_), _) => {
            bail!("{}: voxreg geodesic writes PLY only (expected .ply)", path.display())
        }
    }
}

/// The meshes of `--split interfaces|regions` as `(file name, mesh)`, in interface or
/// region order, named after the labels' names where `palette` has them; each vertex
/// copies its position from `positions` bit for bit, or with `--manifold` from
/// [`untangled`] positions.
fn split_meshes(
    args: &RegularizeArgs,
    surface: &DigitalSurface,
    positions: &[glam::DVec3],
    palette: Option<&Palette>,
) -> Vec<(String, QuadMesh)> {
    let params = PatchParams { manifold: args.manifold };
    let ext = args.split_format.extension();
    let patches: Vec<(String, Patch)> = match args.split {
        Split::None => Vec::new(),
        Split::Interfaces => (0..surface.interfaces().len() as u32)
            .map(|i| {
                let patch = surface.interface_patch(InterfaceId(i), &params);
                (format!("{}.{ext}", named_interface_name(surface, InterfaceId(i), palette)), patch)
            })
            .collect(),
        Split::Regions => (0..surface.regions().len() as u32)
            .map(RegionId)
            .filter(|&r| Some(r) != surface.regions().background())
            .map(|r| {
                (
                    format!("{}.{ext}", named_region_name(surface, r, palette)),
                    surface.region_patch(r, &params),
                )
            })
            .filter(|(_, patch)| !patch.quads.is_empty())
            .collect(),
    };
    let untangled;
    let positions = if args.manifold {
        untangled = self::untangled(surface, patches.iter().map(|p| &p.1), positions);
        &untangled
    } else {
        positions
    };
    patches
        .into_iter()
        .map(|(name, patch)| (name, QuadMesh::from_patch(surface, &patch, positions)))
        .collect()
}

/// `positions` with the vertices of every face that `voxreg check` faults in one of
/// `patches` (a face crossing another, folded over its diagonal or onto a neighbour)
/// moved back towards their voxel corners, until no patch has such a face: each round
/// halves those vertices' displacements, and from the eighth round on sets them to
/// zero.
///
/// The regularization keeps one position per surface vertex, and nothing but the
/// voxel-art preset's boxes and fold-free post-condition (which sees only edges of two
/// quads) keeps the faces around a pinch apart: without them, coplanar quads across a
/// pinched edge slide over one another (a checkerboard's every edge). A manifold patch
/// at the voxel corners has no such face (its faces meet only along the edges and
/// corners they share), and each round from the eighth sets at least one more vertex back,
/// so this ends; a clean patch is unchanged.
fn untangled<'a>(
    surface: &DigitalSurface,
    patches: impl Iterator<Item = &'a Patch> + Clone,
    positions: &[DVec3],
) -> Vec<DVec3> {
    let corners = surface.positions();
    let mut x = positions.to_vec();
    let mut keep = vec![1.0f64; x.len()];
    // Each round from the eighth sets at least one more vertex back: at most one per
    // vertex, plus eight, end it (a bound against a patch faulty at its voxel corners).
    for round in 0..x.len() + 8 {
        let mut faulty: Vec<usize> = Vec::new();
        for patch in patches.clone() {
            let local: Vec<DVec3> = patch.vertices.iter().map(|v| x[v.index()]).collect();
            let quads = &patch.quads;
            let faces = voxreg_quality::self_intersections(&local, quads)
                .into_iter()
                .chain(voxreg_quality::folded_pairs(&local, quads))
                .flat_map(|(a, b)| [a, b])
                .chain(voxreg_quality::folded_quads(&local, quads));
            faulty.extend(faces.flat_map(|f| patch.quads[f].map(|v| patch.vertices[v as usize].index())));
        }
        if faulty.is_empty() {
            break;
        }
        faulty.sort_unstable();
        faulty.dedup();
        for v in faulty {
            keep[v] = if round >= 7 { 0.0 } else { 0.5 * keep[v] };
            x[v] = corners[v] + keep[v] * (positions[v] - corners[v]);
        }
    }
    x
}

/// Stages the regularized surface in `outputs`: one file, or with `--split` a directory
/// of files. Returns what is written, for the summary line; `status` shows how a
/// simplification goes.
pub(crate) fn write_meshes(
    args: &RegularizeArgs,
    outputs: &mut Outputs,
    surface: &DigitalSurface,
    positions: &[glam::DVec3],
    palette: Option<&Palette>,
    status: &dyn Fn(&str),
) -> Result<String> {
    let colour = |mut mesh: QuadMesh| {
        if let Some(palette) = palette {
            // Colour transfer: each quad takes the colour and material of its solid voxel.
            mesh.assign_materials(palette);
        }
        mesh
    };
    if args.split == Split::None {
        let mesh = colour(QuadMesh::from_surface(surface, positions));
        return crate::simplify::write(args, outputs, mesh, surface.spacing().min_element(), status);
    }
    let mut batch = MeshBatch::new(&args.output)?;
    for (name, mesh) in split_meshes(args, surface, positions, palette) {
        batch.write(&name, &colour(mesh))?;
    }
    let files = batch.names().len();
    outputs.add_batch(batch);
    Ok(format!("{files} files in {}", args.output.display()))
}
