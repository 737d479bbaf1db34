//! Writing the regularized surface: one mesh, a directory of split meshes, or an
//! upscaled volume; and checking the output paths before any work.

use std::path::Path;

use anyhow::{bail, Result};
use voxreg_digisurf::{DigitalSurface, InterfaceId, LabelVolume, PatchParams, RegionId};
use voxreg_io::{named_interface_name, named_region_name, write_mesh, MeshBatch, Palette, QuadMesh};

use crate::args::{GeodesicOptions, RegularizeArgs, Split};

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

/// Every output path (`-o`, `--report`, `--features`) can be written: its directory
/// exists and is writable, it is not a directory (except `-o` with `--split`), it is not
/// the input, and no two outputs are the same file.
fn check_paths(args: &RegularizeArgs, product: Product<'_>) -> Result<()> {
    let split = product == Product::Mesh && args.split != Split::None;
    let mut outputs: Vec<(&str, &Path)> = vec![("-o", &args.output)];
    outputs.extend(args.report.as_deref().map(|p| ("--report", p)));
    outputs.extend(args.features.as_deref().map(|p| ("--features", p)));
    for (k, &(option, path)) in outputs.iter().enumerate() {
        if same_file(path, &args.input.input) {
            bail!("{}: {option} would overwrite the input", path.display());
        }
        if let Some(&(other, _)) = outputs[..k].iter().find(|(_, p)| same_file(p, path)) {
            bail!("{}: {option} and {other} name the same file", path.display());
        }
        if split && option == "-o" {
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
        if path.is_dir() {
            bail!("{}: {option} names a directory", path.display());
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

/// Whether `a` and `b` are the same file: equal paths, or both existing with the same
/// device and inode (or the same canonical path off Unix).
fn same_file(a: &Path, b: &Path) -> bool {
    if a == b {
        return true;
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        match (std::fs::metadata(a), std::fs::metadata(b)) {
            (Ok(x), Ok(y)) => x.dev() == y.dev() && x.ino() == y.ino(),
            _ => false,
        }
    }
    #[cfg(not(unix))]
    {
        matches!((a.canonicalize(), b.canonicalize()), (Ok(x), Ok(y)) if x == y)
    }
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
pub(crate) fn check_volume(args: &RegularizeArgs, product: Product<'_>, volume: &LabelVolume) -> Result<()> {
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
        let voxels = fine.iter().product::<u128>();
        // The upscaled labels, the per-column buffers they are gathered from, and the
        // written file's bytes.
        let what = format!("upscaling x{factor} to {}x{}x{} voxels", fine[0], fine[1], fine[2]);
        voxreg_io::check_memory(input, &what, voxels * 9)?;
    }
    Ok(())
}

/// Refuses an upscaled volume that lost the model: empty, or with less than half the
/// solid voxels the input has at the finer resolution (thin parts collapsed).
pub(crate) fn check_upscaled(
    args: &RegularizeArgs,
    coarse: &LabelVolume,
    fine: &LabelVolume,
    factor: usize,
) -> Result<()> {
    let solid = |v: &LabelVolume| {
        let b = v.background();
        v.labels().iter().filter(|&&l| Some(l) != b).count() as u128
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
/// copies its position from `positions` bit for bit.
fn split_meshes(
    args: &RegularizeArgs,
    surface: &DigitalSurface,
    positions: &[glam::DVec3],
    palette: Option<&Palette>,
) -> Vec<(String, QuadMesh)> {
    let params = PatchParams { manifold: args.manifold };
    let ext = args.split_format.extension();
    match args.split {
        Split::None => Vec::new(),
        Split::Interfaces => (0..surface.interfaces().len() as u32)
            .map(|i| {
                let patch = surface.interface_patch(InterfaceId(i), &params);
                let name = format!("{}.{ext}", named_interface_name(surface, InterfaceId(i), palette));
                (name, QuadMesh::from_patch(surface, &patch, positions))
            })
            .collect(),
        Split::Regions => (0..surface.regions().len() as u32)
            .map(RegionId)
            .filter(|&r| Some(r) != surface.regions().background())
            .map(|r| {
                let patch = surface.region_patch(r, &params);
                (
                    format!("{}.{ext}", named_region_name(surface, r, palette)),
                    QuadMesh::from_patch(surface, &patch, positions),
                )
            })
            .filter(|(_, mesh)| mesh.num_faces() > 0)
            .collect(),
    }
}

/// Writes the regularized surface: one file, or with `--split` a directory of files
/// written all or nothing. Returns what was written, for the summary line.
pub(crate) fn write_meshes(
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
    for (name, mesh) in split_meshes(args, surface, positions, palette) {
        batch.write(&name, &colour(mesh))?;
    }
    let files = batch.commit()?;
    Ok(format!("{} files in {}", files.len(), args.output.display()))
}
