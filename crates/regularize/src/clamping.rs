//! The clamping boxes of voxel art: the papers' cubes around each vertex, shrunk around
//! thin voxels so that one-voxel parts keep their thickness.

use glam::DVec3;
use rayon::prelude::*;
use rustc_hash::FxHashSet as HashSet;
use voxreg_digisurf::{DigitalSurface, VertexId};

use crate::boxqp::Boxes;
use crate::faces::FaceKeys;

/// The voxels (lattice coordinates, possibly one outside the domain) whose two neighbours
/// along some axis are both separated from them by a surfel: the thin voxels of every
/// region, background included (one-voxel slits).
#[cfg(test)]
pub(crate) fn thin_voxels(surface: &DigitalSurface) -> HashSet<[i64; 3]> {
    thin_and_corners(surface).0
}

/// The thin voxels, and per vertex whether it is a corner of one: each corner of a thin
/// voxel lies on one of the two surfels that make it thin, whose vertices are the
/// surface's at those corners (one vertex per lattice corner).
fn thin_and_corners(surface: &DigitalSurface) -> (HashSet<[i64; 3]>, Vec<bool>) {
    // Surfel (axis, cell) is the lower face of voxel `cell`: is its upper face one too?
    let pairs = FaceKeys::new(surface).between_two_faces();
    let mut corner = vec![false; surface.num_vertices()];
    for (_, surfels) in &pairs {
        for s in surfels {
            for v in surface.surfels()[*s as usize].vertices {
                corner[v.index()] = true;
            }
        }
    }
    (pairs.into_iter().map(|p| p.0).collect(), corner)
}

/// The boxes of the displacement from the input: `[-half, half]` voxel along each axis
/// (scaled by the spacing), except towards a thin voxel ([`thin_voxels`]) that has the
/// vertex as a corner: along each axis where the voxel's face on the vertex's side is a
/// surfel, the bound towards the voxel is `min(half, thin)`.
///
/// With `thin = 0.5 - d`, each surfel of a thin voxel keeps its vertices at least `d`
/// voxel from the voxel's centre along its axis, so the face stays `d` away from it;
/// along the other axes (across a solid neighbour) the vertices slide freely. The boxes
/// lie inside the uniform ones, so the result still has no self-intersection.
pub(crate) fn clamp_boxes(surface: &DigitalSurface, half: f64, thin: Option<f64>) -> Boxes {
    let n = surface.num_vertices();
    let h = surface.spacing();
    let mut boxes = Boxes::uniform(n, half * h);
    let Some(t) = thin else { return boxes };
    let cap = t.min(half) * h;
    let (thin, corner) = thin_and_corners(surface);
    if thin.is_empty() {
        return boxes;
    }
    // Each vertex bounds only its own box, and only a thin voxel's corner has one to bound:
    // in parallel.
    let Boxes { lo, hi } = &mut boxes;
    lo.par_iter_mut().zip(hi.par_iter_mut()).enumerate().for_each(|(v, (lo, hi))| {
        if !corner[v] {
            return;
        }
        let v = VertexId(v as u32);
        // A face at the vertex's corner that is a surfel is one of the vertex's.
        let is_surfel = |a: usize, cell: [i64; 3]| {
            surface.vertex_surfels(v).iter().any(|&s| {
                let s = surface.surfel(s);
                s.axis as usize == a && s.cell.map(i64::from) == cell
            })
        };
        bound_towards_thin(surface.vertex_corner(v), &thin, cap, lo, hi, is_surfel);
    });
    boxes
}

/// Bounds the box `[lo, hi]` of the vertex at lattice corner `corner` towards each thin
/// voxel at that corner, along each axis where the voxel's face on the vertex's side is a
/// surfel (`is_surfel(axis, cell)`), to `cap`.
fn bound_towards_thin(
    corner: [u32; 3],
    thin: &HashSet<[i64; 3]>,
    cap: DVec3,
    lo: &mut DVec3,
    hi: &mut DVec3,
    is_surfel: impl Fn(usize, [i64; 3]) -> bool,
) {
    let k = corner.map(i64::from);
    for o in 0..8usize {
        let off = [o & 1, (o >> 1) & 1, (o >> 2) & 1];
        // Voxel `k - off` has its centre on the + side along axis a when off[a] = 0.
        let voxel = [k[0] - off[0] as i64, k[1] - off[1] as i64, k[2] - off[2] as i64];
        if !thin.contains(&voxel) {
            continue;
        }
        for a in 0..3 {
            // The voxel's face on the vertex's side along a: its lower face when the
            // voxel is on the + side.
            let mut cell = voxel;
            cell[a] += off[a] as i64;
            if !is_surfel(a, cell) {
                continue;
            }
            if off[a] == 0 {
                hi[a] = hi[a].min(cap[a]);
            } else {
                lo[a] = lo[a].max(-cap[a]);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;
    use voxreg_digisurf::{LabelVolume, RegionMap};

    /// [`clamp_boxes`] computed the long way: every vertex, each face looked up in the
    /// surface's sorted faces.
    fn boxes_by_lookups(surface: &DigitalSurface, half: f64, t: f64) -> Boxes {
        let h = surface.spacing();
        let (thin, faces) = (thin_voxels(surface), FaceKeys::new(surface));
        let mut boxes = Boxes::uniform(surface.num_vertices(), half * h);
        for v in 0..surface.num_vertices() {
            let corner = surface.vertex_corner(VertexId(v as u32));
            let (lo, hi) = (&mut boxes.lo[v], &mut boxes.hi[v]);
            bound_towards_thin(corner, &thin, t.min(half) * h, lo, hi, |a, cell| faces.contains(a, cell));
        }
        boxes
    }

    /// The boxes bounded from the thin voxels' corners and the vertices' own surfels are
    /// those of every vertex looking every face up, on random volumes of a few labels
    /// (pinched edges and vertices, one-voxel parts and slits), with and without a
    /// background label.
    #[test]
    fn boxes_from_the_thin_voxels_corners_are_those_of_every_vertex() {
        let mut rng = voxreg_testkit::Lcg::new(7);
        for (case, labels) in [2u32, 3, 4, 2].into_iter().enumerate() {
            let dims = [6 + rng.below(5) as usize, 5 + rng.below(5) as usize, 4 + rng.below(5) as usize];
            let volume = LabelVolume::from_fn(dims, |_| rng.below(labels));
            let volume = if case % 2 == 0 { volume.with_background(Some(0)) } else { volume };
            let surface = DigitalSurface::new(&volume, &RegionMap::per_label()).unwrap();
            assert!(!thin_voxels(&surface).is_empty());
            for (half, t) in [(0.495, 0.2), (0.3, 0.45)] {
                assert_eq!(
                    clamp_boxes(&surface, half, Some(t)),
                    boxes_by_lookups(&surface, half, t),
                    "case {case}"
                );
            }
        }
    }

    #[test]
    fn a_plate_is_thin_and_its_vertices_keep_a_quarter_voxel_from_its_mid_plane() {
        // A 1 x 3 x 3 plate in a 3^3 volume.
        let volume = LabelVolume::from_fn([3, 3, 3], |[x, _, _]| u32::from(x == 1)).with_background(Some(0));
        let surface = DigitalSurface::new(&volume, &RegionMap::single_solid()).unwrap();
        let thin = thin_voxels(&surface);
        for y in 0..3 {
            for z in 0..3 {
                assert!(thin.contains(&[1, y, z]), "{y} {z}");
            }
        }
        let boxes = clamp_boxes(&surface, 0.495, Some(0.25));
        for v in 0..surface.num_vertices() {
            let id = VertexId(v as u32);
            let x = surface.vertex_position(id).x;
            let (lo, hi) = (boxes.lo[v], boxes.hi[v]);
            assert!(lo.cmple(DVec3::ZERO).all() && hi.cmpge(DVec3::ZERO).all());
            // The -x side moves at most 0.25 in +x, the +x side at most 0.25 in -x.
            if x < 1.0 {
                assert_eq!(hi.x, 0.25, "{v}");
                assert_eq!(lo.x, -0.495);
            } else {
                assert_eq!(lo.x, -0.25);
                assert_eq!(hi.x, 0.495);
            }
        }
        // Without a thin cap, the uniform boxes.
        assert_eq!(
            clamp_boxes(&surface, 0.495, None),
            Boxes::uniform(surface.num_vertices(), DVec3::splat(0.495))
        );
    }
}
