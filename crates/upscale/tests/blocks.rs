//! Upscaling a volume given as blocks gives, everywhere, the voxels of the upscale of
//! the volume made dense.

use glam::DVec3;
use ndarray::Array3;
use voxreg_digisurf::{Block, BlockVolume, DigitalSurface};
use voxreg_regularize::{Params, Regularizer, Run};
use voxreg_testkit::Lcg;
use voxreg_upscale::{upscale, upscale_blocks, UpscaleParams};

/// Blocks one voxel apart (across x, and diagonally), one far off, two labels, a cavity.
fn scene() -> BlockVolume {
    let mut rng = Lcg::new(11);
    let mut block = |offset: [usize; 3], dims: (usize, usize, usize), fill: f64| Block {
        offset,
        labels: Array3::from_shape_fn(dims, |_| match rng.below(100) {
            r if f64::from(r) < 100.0 * fill => 1 + r % 2,
            _ => 0,
        }),
    };
    let mut blocks = vec![
        block([0, 0, 0], (4, 3, 3), 0.8),
        block([5, 0, 0], (3, 3, 2), 0.9),
        block([9, 4, 3], (2, 2, 2), 1.0),
        block([30, 20, 1], (3, 2, 4), 0.7),
    ];
    // A hollow cube: a cavity inside its block.
    blocks.push(Block {
        offset: [14, 10, 0],
        labels: Array3::from_shape_fn((4, 4, 4), |(x, y, z)| {
            u32::from(!(1..3).contains(&x) || !(1..3).contains(&y) || !(1..3).contains(&z)) * 2
        }),
    });
    BlockVolume::new([34, 23, 6], blocks, 0)
        .unwrap()
        .with_spacing(DVec3::new(1.0, 1.5, 0.75))
        .unwrap()
        .with_origin(DVec3::new(-3.0, 2.0, 0.5))
        .unwrap()
}

#[test]
fn blocks_upscale_as_the_dense_volume_does() {
    let blocks = scene();
    let dense = blocks.to_dense().unwrap();
    let params = Params::voxel_art();
    let out = Regularizer::from_blocks(&blocks, &params.regions).unwrap().run(Run::new(&params)).unwrap();
    let surface = &out.surface;
    assert_eq!(surface.surfels(), DigitalSurface::new(&dense, &params.regions).unwrap().surfels());
    // The regularized positions, and positions moved by up to 0.45 voxel at random (the
    // smooth surface bulging across the one-voxel gaps).
    let mut rng = Lcg::new(3);
    let spacing = blocks.spacing();
    let moved: Vec<DVec3> = out
        .positions
        .iter()
        .map(|p| {
            let mut r = || (f64::from(rng.below(1000)) / 1000.0 - 0.5) * 0.9;
            *p + DVec3::new(r(), r(), r()) * spacing
        })
        .collect();
    for positions in [out.positions.as_slice(), &moved] {
        for factor in [1, 2, 3] {
            let params = UpscaleParams { factor };
            let a = upscale_blocks(surface, positions, &blocks, &params).unwrap();
            let b = upscale(surface, positions, &dense, &params).unwrap();
            let stored: usize = a.blocks().iter().map(|b| b.labels.len()).sum();
            assert!(stored * 2 < b.len(), "x{factor}: {stored} of {}", b.len());
            assert_eq!(a.to_dense().unwrap(), b, "x{factor}");
            assert!(b.labels().iter().any(|&l| l == 2) && b.labels().iter().any(|&l| l == 1));
        }
    }
}

#[test]
fn models_far_apart_upscale_within_their_boxes() {
    // Two two-voxel models 2,000 voxels apart along each axis (a 32 GiB lattice at x2).
    let block = |offset: [usize; 3]| Block { offset, labels: Array3::from_elem((2, 1, 1), 3) };
    let blocks =
        BlockVolume::new([2002, 2001, 2001], vec![block([0, 0, 0]), block([2000, 2000, 2000])], 0).unwrap();
    let surface = DigitalSurface::from_blocks(&blocks, &voxreg_digisurf::RegionMap::single_solid()).unwrap();
    let fine = upscale_blocks(&surface, &surface.positions(), &blocks, &UpscaleParams { factor: 2 }).unwrap();
    assert_eq!(fine.dims(), [4004, 4002, 4002]);
    assert_eq!(fine.blocks().len(), 2);
    assert!(fine.block_voxels() < 1000, "{}", fine.block_voxels());
    // The unmoved surface: each voxel's 8 sub-voxels, where they lie.
    assert_eq!(fine.label_counts().iter().find(|c| c.0 == 3).map(|c| c.1), Some(32));
    assert_eq!(fine.label([4001, 4001, 4001]), 3);
    assert_eq!(fine.label([3, 1, 1]), 3);
    assert_eq!(fine.label([4, 1, 1]), 0);
}
