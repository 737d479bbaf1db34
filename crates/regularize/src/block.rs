//! One block of a volume too large to regularize at once: the block's voxels with a halo
//! around them go through the front door, and only what the block owns comes back, keyed
//! by global lattice ids so that the blocks' meshes glue into the whole-volume mesh.
//!
//! Every vertex of a digital surface is a lattice corner, so stitching is exact by
//! identity: a quad is owned by the one block whose owned voxel range holds its face, a
//! vertex by the block that owns the first of the vertex's quads (in the global order of
//! their faces), which every block using the vertex sees in its halo. The energy is local
//! (the attachment term pins every vertex), so inside the owned range a block's solution
//! approaches the whole-volume one as the halo grows; the halo's outer boundary, where the
//! sub-volume is cut, is where the two differ (see docs/scale.md for the deviation against
//! the halo width).

use glam::DVec3;
use voxreg_digisurf::{DigitalSurface, LabelStorage, LabelVolume, SurfaceError};

use crate::error::RegularizeError;
use crate::params::Params;
use crate::regularizer::Regularizer;
use crate::report::Report;

/// Where a sub-volume sits in the whole volume, and what of it the block owns.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Block {
    /// The whole volume's dimensions, in voxels.
    pub global_dims: [usize; 3],
    /// The global index of the sub-volume's voxel `[0, 0, 0]`.
    pub start: [usize; 3],
    /// The half-open global voxel range `[lo, hi)` the block owns, per axis: inside the
    /// sub-volume, at least [`MIN_HALO`] voxels from its cut sides.
    pub owned: [[usize; 2]; 3],
}

/// The narrowest halo a block accepts: with 2 voxels every quad touching a vertex of an
/// owned quad lies inside the sub-volume, away from its cut sides, so the blocks using a
/// vertex agree on its owner.
pub const MIN_HALO: usize = 2;

/// What a block owns of the regularized surface.
#[derive(Clone, Debug)]
pub struct BlockMesh {
    /// Global lattice id of each vertex the owned quads use ([`lattice_id`]).
    pub vertex_ids: Vec<u64>,
    /// Their regularized positions, in physical units.
    pub positions: Vec<DVec3>,
    /// Whether the block owns each vertex (it owns the vertex's first quad, in the global
    /// order of the quads' faces): the position to keep when stitching, every vertex
    /// being owned by exactly one block, one of those whose quads use it.
    pub owns_vertex: Vec<bool>,
    /// The owned quads, as indices into the vertex arrays, counter-clockwise seen from
    /// the tip of the normal (which points from `labels[0]` into `labels[1]`).
    pub quads: Vec<[u32; 4]>,
    /// Each quad's `[inner, outer]` labels.
    pub labels: Vec<[u32; 2]>,
    /// The sub-volume's run (`None` when it holds no surface).
    pub report: Option<Report>,
}

/// The global id of lattice corner `corner` (each coordinate `0..=dims`) in a volume of
/// `dims` voxels: `x + (X + 1) (y + (Y + 1) z)`.
pub fn lattice_id(corner: [usize; 3], dims: [usize; 3]) -> u64 {
    let [x, y, z] = corner.map(|c| c as u64);
    x + (dims[0] as u64 + 1) * (y + (dims[1] as u64 + 1) * z)
}

impl Block {
    /// Checks that the sub-volume of `dims` voxels fits the whole volume and holds the
    /// owned range with a halo of at least [`MIN_HALO`] on every side that is not the
    /// volume's border.
    pub fn validate(&self, dims: [usize; 3]) -> Result<(), RegularizeError> {
        for k in 0..3 {
            let (start, end, n) = (self.start[k], self.start[k] + dims[k], self.global_dims[k]);
            let [lo, hi] = self.owned[k];
            let bad = |what: String| Err(RegularizeError::InvalidParams(format!("block axis {k}: {what}")));
            if end > n {
                return bad(format!("the sub-volume [{start}, {end}) exceeds the volume's {n} voxels"));
            }
            if !(start <= lo && lo <= hi && hi <= end) {
                return bad(format!(
                    "the owned range [{lo}, {hi}) is not inside the sub-volume [{start}, {end})"
                ));
            }
            if (lo > 0 && lo - start < MIN_HALO) || (hi < n && end - hi < MIN_HALO) {
                return bad(format!(
                    "the owned range [{lo}, {hi}) needs a halo of at least {MIN_HALO} voxels inside [{start}, {end})"
                ));
            }
        }
        Ok(())
    }

    /// Whether the face perpendicular to `axis` with minimal corner `cell` (global) is the
    /// block's: its voxel range along the other axes, its plane along `axis` (the plane at
    /// the volume's far border belongs to the last block).
    fn owns_face(&self, cell: [usize; 3], axis: usize) -> bool {
        (0..3).all(|k| {
            let [lo, hi] = self.owned[k];
            let c = cell[k];
            (lo <= c && c < hi) || (k == axis && c == hi && hi == self.global_dims[k])
        })
    }
}

/// Regularizes `sub` (the voxels `block.start ..` of the whole volume, with their halo;
/// its origin, spacing and background those of the whole volume's part) with `params`,
/// and returns the quads and vertices `block` owns. Deterministic; a sub-volume without
/// a surface gives an empty mesh. The size preservation does not measure its drift within
/// [`CUT_MARGIN`] voxels of the sub-volume's cut sides, where the surfaces meet the caps
/// that close them (the whole volume has no such edge).
pub fn regularize_block<S: LabelStorage>(
    sub: &LabelVolume<S>,
    block: &Block,
    params: &Params,
) -> Result<BlockMesh, RegularizeError> {
    let Some(mut regularizer) = block_regularizer(sub, block, params, CUT_MARGIN)? else {
        return Ok(BlockMesh {
            vertex_ids: Vec::new(),
            positions: Vec::new(),
            owns_vertex: Vec::new(),
            quads: Vec::new(),
            labels: Vec::new(),
            report: None,
        });
    };
    regularizer.set_keep_normals(false);
    let out = regularizer.run(params)?;
    Ok(owned_part(&out.surface, out.positions.as_slice(), block, Some(out.report)))
}

/// Vertices within this many voxels of a cut side are not measured by the re-centring
/// (their drift is the cap's, which the whole-volume solve does not have).
pub const CUT_MARGIN: usize = 3;

/// The regularizer of a block's sub-volume (`None` without a surface), its cut-side
/// vertices (within `margin` voxels of a cut side) left out of the re-centring's
/// measurement.
pub(crate) fn block_regularizer<S: LabelStorage>(
    sub: &LabelVolume<S>,
    block: &Block,
    params: &Params,
    margin: usize,
) -> Result<Option<Regularizer>, RegularizeError> {
    block.validate(sub.dims())?;
    let mut regularizer = match Regularizer::from_volume(sub, &params.regions) {
        Ok(r) => r,
        Err(RegularizeError::Surface(SurfaceError::Empty)) => return Ok(None),
        Err(e) => return Err(e),
    };
    if margin > 0 {
        regularizer.untrusted = Some(cut_side_vertices(regularizer.surface(), block, sub.dims(), margin));
    }
    Ok(Some(regularizer))
}

/// Whether each vertex's corner lies within `margin` voxels of one of the sub-volume's
/// cut sides (the sides inside the whole volume, where the surfaces are capped).
fn cut_side_vertices(surface: &DigitalSurface, block: &Block, dims: [usize; 3], margin: usize) -> Vec<bool> {
    let cut_lo = [0, 1, 2].map(|k| block.start[k] > 0);
    let cut_hi = [0, 1, 2].map(|k| block.start[k] + dims[k] < block.global_dims[k]);
    (0..surface.num_vertices())
        .map(|v| {
            let c = surface.vertex_corner(voxreg_digisurf::VertexId(v as u32));
            (0..3).any(|k| {
                let c = c[k] as usize;
                (cut_lo[k] && c <= margin) || (cut_hi[k] && c + margin >= dims[k])
            })
        })
        .collect()
}

/// The part of `surface` (with `positions`) that `block` owns.
fn owned_part(
    surface: &DigitalSurface,
    positions: &[DVec3],
    block: &Block,
    report: Option<Report>,
) -> BlockMesh {
    let global = |local: [u32; 3]| -> [usize; 3] { [0, 1, 2].map(|k| local[k] as usize + block.start[k]) };
    let mut local_to_out = vec![u32::MAX; surface.num_vertices()];
    let mut mesh = BlockMesh {
        vertex_ids: Vec::new(),
        positions: Vec::new(),
        owns_vertex: Vec::new(),
        quads: Vec::new(),
        labels: Vec::new(),
        report,
    };
    for s in surface.surfels() {
        if !block.owns_face(global(s.cell), usize::from(s.axis)) {
            continue;
        }
        let quad = s.vertices.map(|v| {
            let slot = &mut local_to_out[v.index()];
            if *slot == u32::MAX {
                let corner = global(surface.vertex_corner(v));
                *slot = mesh.vertex_ids.len() as u32;
                mesh.vertex_ids.push(lattice_id(corner, block.global_dims));
                mesh.positions.push(positions[v.index()]);
                // A corner's owner by the corner's position alone would miss the vertices
                // whose quads all lie in the neighbouring blocks (a voxel touching a
                // block's corner from outside): the owner of the vertex's first quad
                // emits it.
                let (first_cell, first_axis) = surface
                    .vertex_surfels(v)
                    .iter()
                    .map(|&f| {
                        let f = surface.surfel(f);
                        (global(f.cell), f.axis)
                    })
                    .min()
                    .expect("a vertex of a quad has a quad");
                mesh.owns_vertex.push(block.owns_face(first_cell, usize::from(first_axis)));
            }
            *slot
        });
        mesh.quads.push(quad);
        mesh.labels.push(s.labels);
    }
    mesh
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;

    use crate::block::*;
    use crate::Preset;

    /// Two labels and background in 12 x 10 x 9 voxels, touching the volume's border.
    fn volume() -> LabelVolume {
        LabelVolume::from_fn([12, 10, 9], |[x, y, z]| {
            let d2 = (x as f64 - 5.0).powi(2) + (y as f64 - 4.5).powi(2) + (z as f64 - 4.0).powi(2);
            if d2 < 16.0 {
                1 + u32::from(x > 6)
            } else {
                u32::from(z == 0 && x < 3)
            }
        })
    }

    fn sub(volume: &LabelVolume, start: [usize; 3], end: [usize; 3]) -> LabelVolume {
        let dims = [0, 1, 2].map(|k| end[k] - start[k]);
        LabelVolume::from_fn(dims, |p| volume.labels()[[p[0] + start[0], p[1] + start[1], p[2] + start[2]]])
            .with_origin(volume.origin() + DVec3::new(start[0] as f64, start[1] as f64, start[2] as f64))
            .unwrap()
    }

    #[test]
    fn blocks_own_every_quad_once_and_every_vertex_once() {
        assert_blocks_partition(&volume(), [[0, 5, 12], [0, 4, 10], [0, 3, 9]]);
        // A voxel touching the blocks' common corner from one block only: its vertex at
        // that corner is used by none of the quads the corner's own block owns.
        let corner = LabelVolume::from_fn([8, 8, 8], |p| u32::from(p == [3, 3, 3]));
        assert_blocks_partition(&corner, [[0, 4, 8], [0, 4, 8], [0, 4, 8]]);
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(48))]
        /// Random labels in 2 x 2 x 2 blocks cut anywhere: every quad and every vertex
        /// has exactly one owner.
        #[test]
        fn random_volumes_partition_into_blocks(
            dims in proptest::array::uniform3(3usize..9),
            seed in 0u64..1 << 32,
            fractions in proptest::array::uniform3(0.1f64..0.9),
        ) {
            let mut rng = voxreg_testkit::Lcg::new(seed);
            let volume = LabelVolume::from_fn(dims, |_| {
                let r = rng.next_f64();
                if r < 0.6 { 0 } else { 1 + u32::from(r > 0.8) }
            });
            let cuts = [0, 1, 2].map(|k| {
                let c = ((dims[k] as f64 * fractions[k]).round() as usize).clamp(1, dims[k] - 1);
                [0, c, dims[k]]
            });
            if DigitalSurface::from_volume(&volume).is_ok() {
                assert_blocks_partition(&volume, cuts);
            }
        }
    }

    /// Splits `volume` at `cuts` (per axis: 0, the cut, the size) into 2 x 2 x 2 blocks of
    /// halo [`MIN_HALO`] and checks that their owned parts are the whole surface: each
    /// quad once, each vertex owned once, by a block that uses it.
    fn assert_blocks_partition(volume: &LabelVolume, cuts: [[usize; 3]; 3]) {
        let dims = volume.dims();
        let whole = DigitalSurface::from_volume(volume).unwrap();
        let positions = whole.positions();
        let mut whole_position: BTreeMap<u64, DVec3> = BTreeMap::new();
        for s in whole.surfels() {
            for v in s.vertices {
                let id = lattice_id(whole.vertex_corner(v).map(|c| c as usize), dims);
                whole_position.insert(id, positions.as_slice()[v.index()]);
            }
        }
        // Face sets by vertex ids: the whole surface's, and the union of the blocks'.
        let key = |ids: [u64; 4], labels: [u32; 2]| (ids, labels);
        let mut expected: Vec<_> = whole
            .surfels()
            .iter()
            .map(|s| {
                key(
                    s.vertices.map(|v| lattice_id(whole.vertex_corner(v).map(|c| c as usize), dims)),
                    s.labels,
                )
            })
            .collect();
        expected.sort_unstable();
        let mut got = Vec::new();
        let mut owners: BTreeMap<u64, usize> = BTreeMap::new();
        for i in 0..2 {
            for j in 0..2 {
                for k in 0..2 {
                    let owned = [
                        [cuts[0][i], cuts[0][i + 1]],
                        [cuts[1][j], cuts[1][j + 1]],
                        [cuts[2][k], cuts[2][k + 1]],
                    ];
                    let start = [0, 1, 2].map(|a| owned[a][0].saturating_sub(MIN_HALO));
                    let end = [0, 1, 2].map(|a| (owned[a][1] + MIN_HALO).min(dims[a]));
                    let block = Block { global_dims: dims, start, owned };
                    let s = sub(volume, start, end);
                    // The digital surface's own positions: ownership alone is under test.
                    let part = match DigitalSurface::from_volume(&s) {
                        Ok(surface) => owned_part(&surface, surface.positions().as_slice(), &block, None),
                        Err(_) => continue,
                    };
                    for (q, l) in part.quads.iter().zip(&part.labels) {
                        got.push(key(q.map(|v| part.vertex_ids[v as usize]), *l));
                    }
                    for (v, &id) in part.vertex_ids.iter().enumerate() {
                        if part.owns_vertex[v] {
                            assert!(owners.insert(id, 0).is_none(), "vertex {id} owned twice");
                            assert!((part.positions[v] - whole_position[&id]).length() < 1e-12);
                        }
                    }
                }
            }
        }
        got.sort_unstable();
        assert_eq!(got, expected, "the blocks' quads are the whole surface's, each once");
        let used: std::collections::BTreeSet<u64> = expected.iter().flat_map(|(ids, _)| *ids).collect();
        assert_eq!(used.len(), owners.len(), "every vertex has one owner");
    }

    /// The default pipeline in 2 x 2 x 2 blocks matches the whole-volume solve: same
    /// quads, and positions within 1e-2 voxel (1e-3 on average) with a halo of 12.
    #[test]
    fn stitched_blocks_match_the_whole_volume_solve() {
        let n = 24;
        let volume = LabelVolume::from_fn([n, n, n], |[x, y, z]| {
            let d2 = (x as f64 - 11.3).powi(2) + (y as f64 - 12.1).powi(2) + (z as f64 - 11.7).powi(2);
            if d2 < 81.0 {
                1 + u32::from(z > 12)
            } else {
                0
            }
        });
        let params = Params::default();
        let whole = crate::regularizer::regularize(&volume, &params).unwrap();
        let mut expected: BTreeMap<u64, DVec3> = BTreeMap::new();
        for s in whole.surface.surfels() {
            for v in s.vertices {
                let id = lattice_id(whole.surface.vertex_corner(v).map(|c| c as usize), [n; 3]);
                expected.insert(id, whole.positions.as_slice()[v.index()]);
            }
        }
        let halo = 12;
        let mut stitched: BTreeMap<u64, DVec3> = BTreeMap::new();
        let mut quads = 0;
        for b in 0..8 {
            let owned = [0, 1, 2].map(|k| if (b >> k) & 1 == 0 { [0, n / 2] } else { [n / 2, n] });
            let start = owned.map(|[lo, _]| lo.saturating_sub(halo));
            let end = owned.map(|[_, hi]| (hi + halo).min(n));
            let block = Block { global_dims: [n; 3], start, owned };
            let part = regularize_block(&sub(&volume, start, end), &block, &params).unwrap();
            quads += part.quads.len();
            for (v, &id) in part.vertex_ids.iter().enumerate() {
                if part.owns_vertex[v] {
                    assert!(stitched.insert(id, part.positions[v]).is_none());
                }
            }
        }
        assert_eq!(quads, whole.surface.num_surfels());
        assert_eq!(stitched.len(), expected.len());
        let deviations: Vec<f64> = expected.iter().map(|(id, p)| (stitched[id] - *p).length()).collect();
        let worst = deviations.iter().copied().fold(0.0, f64::max);
        let mean = deviations.iter().sum::<f64>() / deviations.len() as f64;
        assert!(worst < 1e-2 && mean < 1e-3, "deviation {mean} mean, {worst} max (voxels)");
    }

    /// Regularizes `volume` in blocks along x of `owned` voxels with `halo`, stitched,
    /// against the whole-volume solve: the largest vertex deviation (voxels).
    fn stitched_deviation_along_x(volume: &LabelVolume, params: &Params, owned: usize, halo: usize) -> f64 {
        let dims = volume.dims();
        let whole = crate::regularizer::regularize(volume, params).unwrap();
        let mut expected: BTreeMap<u64, DVec3> = BTreeMap::new();
        for s in whole.surface.surfels() {
            for v in s.vertices {
                let id = lattice_id(whole.surface.vertex_corner(v).map(|c| c as usize), dims);
                expected.insert(id, whole.positions.as_slice()[v.index()]);
            }
        }
        let mut stitched: BTreeMap<u64, DVec3> = BTreeMap::new();
        for lo in (0..dims[0]).step_by(owned) {
            let owned = [[lo, (lo + owned).min(dims[0])], [0, dims[1]], [0, dims[2]]];
            let start = [lo.saturating_sub(halo), 0, 0];
            let end = [(owned[0][1] + halo).min(dims[0]), dims[1], dims[2]];
            let block = Block { global_dims: dims, start, owned };
            let part = regularize_block(&sub(volume, start, end), &block, params).unwrap();
            for (v, &id) in part.vertex_ids.iter().enumerate() {
                if part.owns_vertex[v] {
                    assert!(stitched.insert(id, part.positions[v]).is_none());
                }
            }
        }
        assert_eq!(stitched.len(), expected.len());
        expected.iter().map(|(id, p)| (stitched[id] - *p).length()).fold(0.0, f64::max)
    }

    /// The fast preset's sweeps and diffusion reach a bounded distance: at its chunk halo
    /// the stitched blocks are the whole-volume solve to 1e-4 voxel, while a narrow halo
    /// is not (so the halo is what makes it exact).
    #[test]
    fn the_fast_preset_stitches_exactly_at_its_chunk_halo() {
        // A chain of touching ellipsoids of three labels along x, crossing every cut.
        let volume = LabelVolume::from_fn([128, 22, 20], |[x, y, z]| {
            let (x, y, z) = (x as f64 + 0.5, y as f64 - 10.6, z as f64 - 9.8);
            let k = (x / 21.0).floor();
            let cx = 21.0 * k + 10.5;
            let r = 8.5 + 1.5 * (0.7 * k).sin();
            if ((x - cx) / (r + 3.0)).powi(2) + (y / r).powi(2) + (z / (r - 1.0)).powi(2) < 1.0 {
                1 + (k as u32) % 3
            } else {
                0
            }
        });
        let params = Preset::Fast.params();
        let halo = Preset::Fast.chunk_halo();
        let exact = stitched_deviation_along_x(&volume, &params, 32, halo);
        assert!(exact < 1e-4, "halo {halo}: {exact} voxel");
        let narrow = stitched_deviation_along_x(&volume, &params, 32, 6);
        assert!(narrow > 1e-3, "halo 6: {narrow} voxel");
    }

    #[test]
    fn cut_side_vertices_are_those_near_a_cut_not_near_the_volume_border() {
        let volume = volume();
        // The sub-volume [4, 12) x [0, 10) x [0, 9): cut at x = 4 only.
        let (start, end) = ([4, 0, 0], [12, 10, 9]);
        let block = Block { global_dims: [12, 10, 9], start, owned: [[6, 12], [0, 10], [0, 9]] };
        let s = sub(&volume, start, end);
        let surface = DigitalSurface::from_volume(&s).unwrap();
        let cut = cut_side_vertices(&surface, &block, s.dims(), 2);
        for v in 0..surface.num_vertices() {
            let c = surface.vertex_corner(voxreg_digisurf::VertexId(v as u32));
            assert_eq!(cut[v], c[0] <= 2, "corner {c:?}");
        }
        assert!(cut.iter().any(|&c| c) && cut.iter().any(|&c| !c));
    }

    #[test]
    fn a_block_owning_the_whole_volume_is_the_whole_solve() {
        let volume = volume();
        let dims = volume.dims();
        let params = Params::default();
        let whole = crate::regularizer::regularize(&volume, &params).unwrap();
        let block = Block { global_dims: dims, start: [0; 3], owned: dims.map(|n| [0, n]) };
        let part = regularize_block(&volume, &block, &params).unwrap();
        let expected = owned_part(&whole.surface, whole.positions.as_slice(), &block, None);
        assert_eq!(part.vertex_ids, expected.vertex_ids);
        assert_eq!(part.positions, expected.positions, "bit for bit");
    }

    #[test]
    fn a_halo_too_thin_is_refused() {
        let block = Block { global_dims: [10, 10, 10], start: [3, 0, 0], owned: [[4, 8], [0, 10], [0, 10]] };
        let err = block.validate([7, 10, 10]).unwrap_err().to_string();
        assert!(err.contains("halo of at least 2"), "{err}");
        let ok = Block { owned: [[5, 8], [0, 10], [0, 10]], ..block };
        ok.validate([7, 10, 10]).unwrap();
    }
}
