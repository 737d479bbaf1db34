//! `voxreg check`: a mesh's self-intersections and folds, and with `--voxels` its fidelity
//! to the voxels it came from.

use anyhow::{bail, Result};
use voxreg_io::read_mesh;

use crate::args::CheckArgs;
use crate::terminal::print_stdout;

/// `voxreg check`: counts the mesh's self-intersections and folds.
pub(crate) fn check(args: &CheckArgs) -> Result<()> {
    let mesh = read_mesh(&args.mesh)?;
    let r = voxreg_quality::check(&mesh.positions, &mesh.quads);
    print_stdout(&format!(
        "{}: {} faces, {} self-intersecting face pairs, {} folded quads, {} folded adjacent pairs\n",
        args.mesh.display(),
        r.faces,
        r.intersecting_pairs,
        r.folded_quads,
        r.folded_pairs,
    ))?;
    if let Some(path) = &args.voxels {
        let volume = voxreg_io::read_volume(path)?.volume;
        let (bg, labels) = (volume.background(), volume.labels());
        let occ = voxreg_quality::Occupancy::from_fn(volume.dims(), volume.origin(), volume.spacing(), |v| {
            Some(labels[v]) != bg
        });
        let s = voxreg_quality::solid_report(&occ, &mesh.positions, &mesh.quads);
        print_stdout(&format!(
            "{}: {} of {} solid voxel centres outside, {} of {} empty ones inside, {} of {} thin voxels \
             less than 0.25 voxel deep (thinnest {:.3})\n",
            path.display(),
            s.solid_outside,
            s.solid_surface_voxels,
            s.empty_inside,
            s.empty_surface_voxels,
            s.thin_shallow,
            s.thin_voxels,
            s.thin_min_depth
        ))?;
        // Smoothness and sharpness need the staircase: found where every vertex stayed
        // within half a voxel of its corner (clamped outputs, the voxel-art preset's).
        if let Some(stair) = occ.staircase_of(&mesh.positions, &mesh.quads) {
            let a = voxreg_quality::angle_report(
                &stair,
                &mesh.positions,
                &mesh.quads,
                &occ.thin_quads(&stair, &mesh.quads),
            );
            print_stdout(&format!(
                "{}: mean angle between adjacent quads {:.1} deg (voxels {:.1}; {:.1} on the {} pairs at thin \
                 voxels, {:.1} on the {} others), {} hard edges at {:.1} deg (90 in the voxels)\n",
                args.mesh.display(),
                a.mean,
                voxreg_quality::mean_adjacent_angle_deg(&stair, &mesh.quads),
                a.thin.0,
                a.thin.1,
                a.elsewhere.0,
                a.elsewhere.1,
                a.hard_edges.1,
                a.hard_edges.0
            ))?;
        }
    }
    if let Some((a, b)) = r.first_intersection {
        bail!(
            "{}: {} self-intersections (first: faces {a} and {b})",
            args.mesh.display(),
            r.intersecting_pairs
        );
    }
    if r.invalid_faces > 0 {
        bail!(
            "{}: {} faces with a vertex that is not finite (NaN or infinite)",
            args.mesh.display(),
            r.invalid_faces
        );
    }
    if !r.is_clean() {
        bail!(
            "{}: {} folded quads, {} folded adjacent pairs",
            args.mesh.display(),
            r.folded_quads,
            r.folded_pairs
        );
    }
    Ok(())
}
