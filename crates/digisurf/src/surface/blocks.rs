//! The digital surface of a [`BlockVolume`]: each block's faces found against the
//! background, then numbered as the scan of the dense volume numbers them.

use std::collections::HashMap;

use rayon::prelude::*;

use super::scan::{oriented_surfel, outside_of, range_faces, Cap, RawFace, MAX_SURFELS};
use super::NONE;
use crate::blocks::BlockVolume;
use crate::error::SurfaceError;
use crate::ids::{InterfaceId, VertexId};
use crate::regions::{RegionMap, Regions};
use crate::surface::DigitalSurface;
use crate::volume::{LabelView, LabelVolume};

impl DigitalSurface {
    /// The digital surface of `volume`, with labels grouped into regions by `map`: the
    /// surface [`DigitalSurface::new`] builds from [`BlockVolume::to_dense`], equal id for
    /// id (surfels, vertices, edges and interfaces numbered alike), built without the
    /// lattice.
    ///
    /// Cost: one pass over the blocks' voxels and a sort of the surfels; memory for one
    /// block's scan and the complex, whatever the lattice's size.
    pub fn from_blocks(volume: &BlockVolume, map: &RegionMap) -> Result<Self, SurfaceError> {
        let regions = block_regions(volume, map)?;
        let [nx, ny, nz] = volume.dims();
        if nx.max(ny).max(nz) >= (u32::MAX as usize) - 1 {
            return Err(SurfaceError::TooLarge(format!("dimensions {nx}x{ny}x{nz}")));
        }
        let found: Vec<Vec<RawFace>> = volume
            .blocks()
            .par_iter()
            .map(|b| {
                let view = block_view(volume, &b.labels);
                let outside = outside_of(&view, &regions);
                let nz = view.dims()[2];
                let at = b.offset.map(|o| o as u32);
                let slabs: Vec<Vec<RawFace>> =
                    range_faces(&view, &regions, &outside, 0..nz + 1, &Cap::none())?;
                let mut faces: Vec<RawFace> = slabs.into_iter().flatten().collect();
                for f in &mut faces {
                    f.cell = [0, 1, 2].map(|k| f.cell[k] + at[k]);
                }
                Ok(faces)
            })
            .collect::<Result<_, SurfaceError>>()?;
        let mut faces: Vec<RawFace> = found.into_iter().flatten().collect();
        // The dense scan's order: slab by slab in z, faces perpendicular to z, then x,
        // then y, each in y then x order.
        const RANK: [u8; 3] = [1, 2, 0];
        faces.par_sort_unstable_by_key(|f| (f.cell[2], RANK[f.axis as usize], f.cell[1], f.cell[0]));
        if faces.len() > MAX_SURFELS {
            return Err(SurfaceError::TooLarge(format!("more than {MAX_SURFELS} surfels")));
        }

        // Vertices numbered in order of first use, interfaces by pair in order of first
        // use, as `Scan` numbers them.
        let mut surfels = Vec::with_capacity(faces.len());
        let mut vertex_corners: Vec<[u32; 3]> = Vec::new();
        let mut vertex_of: HashMap<[u32; 3], u32> = HashMap::with_capacity(faces.len());
        let mut interface_of_pair: HashMap<(u32, u32), u32> = HashMap::new();
        for f in faces {
            let mut surfel = oriented_surfel(f.cell, f.axis as usize, f.regions, f.labels, |c| {
                let next = vertex_corners.len() as u32;
                let id = *vertex_of.entry(c).or_insert(next);
                if id == next {
                    if next == NONE {
                        return Err(SurfaceError::TooLarge("more than 2^32 - 1 vertices".into()));
                    }
                    vertex_corners.push(c);
                }
                Ok(VertexId(id))
            })?;
            let n = interface_of_pair.len() as u32;
            let pair = (surfel.regions[0].0, surfel.regions[1].0);
            surfel.interface = InterfaceId(*interface_of_pair.entry(pair).or_insert(n));
            surfels.push(surfel);
        }
        drop(vertex_of);
        let closed = [[false; 2]; 3];
        Self::assemble(
            [nx, ny, nz],
            (volume.spacing(), volume.origin(), closed),
            regions,
            surfels,
            vertex_corners,
            interface_of_pair,
        )
    }

    /// The number of surfels [`DigitalSurface::from_blocks`] would build from `volume` and
    /// `map`, counted in one pass over the blocks' voxels without storing a face.
    pub fn count_surfels_of_blocks(volume: &BlockVolume, map: &RegionMap) -> Result<u64, SurfaceError> {
        let regions = block_regions(volume, map)?;
        volume
            .blocks()
            .par_iter()
            .map(|b| {
                let view = block_view(volume, &b.labels);
                let outside = outside_of(&view, &regions);
                range_faces::<u64>(&view, &regions, &outside, 0..view.dims()[2] + 1, &Cap::none())
            })
            .try_reduce(|| 0, |a, b| Ok(a + b))
    }
}

/// The regions of `volume`'s labels, as [`RegionMap::resolve`] finds them in the dense
/// volume (which reads only which labels are present, and the background).
fn block_regions(volume: &BlockVolume, map: &RegionMap) -> Result<Regions, SurfaceError> {
    let present: Vec<u32> = volume.label_counts().into_iter().map(|(l, _)| l).collect();
    let labels = LabelVolume::from_x_fastest([present.len(), 1, 1], present)?;
    map.resolve(&labels.with_background(Some(volume.background())))
}

/// A block's labels as a volume closed by the background on every side.
fn block_view<'a>(volume: &BlockVolume, labels: &'a ndarray::Array3<u32>) -> LabelView<'a> {
    LabelView::from_view(labels.view()).with_background(Some(volume.background()))
}

#[cfg(test)]
mod tests {
    use ndarray::Array3;
    use proptest::prelude::*;

    use super::*;
    use crate::blocks::Block;

    /// Every part of the two surfaces the crate exposes, id for id.
    fn assert_same(a: &DigitalSurface, b: &DigitalSurface) {
        assert_eq!(a.dims(), b.dims());
        assert_eq!(a.spacing(), b.spacing());
        assert_eq!(a.open_sides(), b.open_sides());
        assert_eq!(a.regions().len(), b.regions().len());
        assert_eq!(a.surfels(), b.surfels());
        assert_eq!(a.edges(), b.edges());
        assert_eq!(a.interfaces(), b.interfaces());
        assert_eq!(a.counts(), b.counts());
        assert_eq!(a.components_closed(), b.components_closed());
        for v in 0..a.num_vertices() {
            let v = VertexId(v as u32);
            assert_eq!(a.vertex_corner(v), b.vertex_corner(v));
            assert_eq!(a.vertex_position(v), b.vertex_position(v));
            assert_eq!(a.vertex_neighbours(v), b.vertex_neighbours(v));
            assert_eq!(a.vertex_surfels(v), b.vertex_surfels(v));
        }
        for e in 0..a.num_edges() {
            assert_eq!(
                a.edge_surfels(crate::ids::EdgeId(e as u32)),
                b.edge_surfels(crate::ids::EdgeId(e as u32))
            );
        }
        for s in 0..a.num_surfels() {
            let s = crate::ids::SurfelId(s as u32);
            assert_eq!(a.surfel_edges(s), b.surfel_edges(s));
            assert_eq!(a.surfel_component(s), b.surfel_component(s));
        }
    }

    fn check(volume: &BlockVolume, map: &RegionMap) {
        let dense = volume.to_dense().unwrap();
        assert_eq!(volume.label_counts(), dense.label_counts());
        let expected = DigitalSurface::new(&dense, map);
        let got = DigitalSurface::from_blocks(volume, map);
        assert_eq!(DigitalSurface::count_surfels_of_blocks(volume, map).unwrap(), {
            DigitalSurface::count_surfels(&dense, map).unwrap()
        });
        match (expected, got) {
            (Ok(e), Ok(g)) => assert_same(&e, &g),
            (Err(e), Err(g)) => assert_eq!(e.to_string(), g.to_string()),
            (e, g) => panic!("dense {:?}, blocks {:?}", e.map(|s| s.counts()), g.map(|s| s.counts())),
        }
    }

    fn block(offset: [usize; 3], dims: [usize; 3], labels: &[u32]) -> Block {
        let n = dims.iter().product::<usize>();
        let labels = Array3::from_shape_vec(
            (dims[0], dims[1], dims[2]),
            labels.iter().copied().cycle().take(n).collect(),
        )
        .unwrap();
        Block { offset, labels }
    }

    #[test]
    fn blocks_far_apart_make_the_dense_surface() {
        // Two cubes of two labels and a pinched pair of voxels, apart along each axis in
        // turn, with spacing and origin.
        let blocks = vec![
            block([1, 2, 3], [3, 2, 2], &[1, 2, 2, 0, 1]),
            block([9, 0, 0], [2, 2, 2], &[3, 0, 0, 3, 0, 3, 3, 0]),
            block([0, 6, 1], [2, 1, 3], &[4]),
            block([5, 0, 7], [1, 1, 1], &[1]),
        ];
        let volume = BlockVolume::new([12, 8, 9], blocks, 0)
            .unwrap()
            .with_spacing(glam::DVec3::new(1.0, 0.5, 2.0))
            .unwrap()
            .with_origin(glam::DVec3::new(-3.0, 7.0, 0.25))
            .unwrap();
        for map in [RegionMap::per_label(), RegionMap::single_solid(), RegionMap::parse("1,3;2").unwrap()] {
            check(&volume, &map);
        }
    }

    #[test]
    fn blocks_must_be_one_voxel_apart_and_inside() {
        let a = || block([0, 0, 0], [2, 2, 2], &[1]);
        // Touching faces (x = 2), an edge or a corner: refused.
        for offset in [[2, 0, 0], [2, 2, 0], [2, 2, 2], [1, 1, 1]] {
            let err = BlockVolume::new([9, 9, 9], vec![a(), block(offset, [1, 1, 1], &[1])], 0).unwrap_err();
            assert!(err.to_string().contains("not one voxel apart"), "{offset:?}: {err}");
        }
        // One empty voxel between, along one axis: separate.
        assert!(BlockVolume::new([9, 9, 9], vec![a(), block([3, 0, 0], [1, 1, 1], &[1])], 0).is_ok());
        assert!(BlockVolume::new([9, 9, 9], vec![a(), block([0, 1, 3], [1, 1, 1], &[1])], 0).is_ok());
        let err = BlockVolume::new([2, 2, 1], vec![a()], 0).unwrap_err();
        assert!(err.to_string().contains("outside dimensions"), "{err}");
        // A lattice far larger than its blocks: memory for the blocks only.
        let far = BlockVolume::new(
            [1 << 20, 1 << 20, 1 << 20],
            vec![a(), block([(1 << 20) - 1, (1 << 20) - 3, 5], [1, 2, 1], &[2])],
            0,
        )
        .unwrap();
        let s = DigitalSurface::from_blocks(&far, &RegionMap::per_label()).unwrap();
        assert_eq!(s.num_surfels(), 24 + 10);
        assert_eq!(s.dims(), [1 << 20; 3]);
        assert_eq!(far.label([(1 << 20) - 1, (1 << 20) - 2, 5]), 2);
    }

    proptest! {
        /// Random small blocks (those one voxel apart) of up to four labels: the surface
        /// of the dense volume, id for id.
        #[test]
        fn blocks_make_the_surface_of_the_dense_volume(
            blocks in proptest::collection::vec(
                ((0usize..8, 0usize..8, 0usize..8), (1usize..4, 1usize..4, 1usize..4))
                    .prop_flat_map(|(o, d)| (Just(o), Just(d), proptest::collection::vec(0u32..4, d.0 * d.1 * d.2))),
                1..5,
            ),
            single in any::<bool>(),
        ) {
            let blocks: Vec<Block> = blocks
                .into_iter()
                .map(|((ox, oy, oz), (dx, dy, dz), labels)| block([ox, oy, oz], [dx, dy, dz], &labels))
                .collect();
            if let Ok(volume) = BlockVolume::new([11, 11, 11], blocks, 0) {
                check(&volume, &if single { RegionMap::single_solid() } else { RegionMap::per_label() });
            }
        }
    }
}
