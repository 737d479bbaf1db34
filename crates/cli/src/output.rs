//! Writing the regularized surface: one mesh, a directory of split meshes, or an
//! upscaled volume; and checking the output paths before any work.

use std::path::Path;

use anyhow::{bail, Result};
use voxreg_digisurf::{DigitalSurface, InterfaceId, PatchParams, RegionId};
use voxreg_io::{interface_name, region_name, write_mesh, MeshBatch, Palette, QuadMesh};

use crate::args::{RegularizeArgs, Split};

/// What `regularize` makes of the regularized surface.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub(crate) enum Product {
    /// The quad mesh (`voxreg regularize`).
    Mesh,
    /// A labeled volume `factor` times finer (`voxreg upscale`).
    Volume { factor: usize },
}

/// Refuses option combinations and output paths that cannot be written, before any work.
pub(crate) fn check_outputs(args: &RegularizeArgs, product: Product) -> Result<()> {
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
        _ if args.output.is_file() => {
            bail!("{}: --split writes a directory, but this is a file", args.output.display())
        }
        _ => {}
    }
    if let Some(path) = &args.features {
        if product != Product::Mesh {
            bail!("--features {}: voxreg upscale writes no mesh to carry the feature field", path.display());
        }
        if args.normals != Some(crate::args::NormalsKind::At) {
            bail!("--features {}: only --normals at has a feature field", path.display());
        }
        if !path.extension().is_some_and(|e| e.eq_ignore_ascii_case("ply")) {
            bail!("{}: --features writes PLY only (expected .ply)", path.display());
        }
    }
    Ok(())
}

fn check_extension(path: &Path, product: Product) -> Result<()> {
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
    for (name, mesh) in split_meshes(args, surface, positions) {
        batch.write(&name, &colour(mesh))?;
    }
    let files = batch.commit()?;
    Ok(format!("{} files in {}", files.len(), args.output.display()))
}
