//! Volumes given as dense blocks placed in a larger lattice of background: scenes of
//! objects far apart, whose bounding box is mostly empty space.

use glam::DVec3;
use ndarray::{Array3, ShapeBuilder};

use crate::error::SurfaceError;
use crate::volume::{LabelVolume, Voxel};

/// One block of a [`BlockVolume`]: dense labels whose voxel `[0, 0, 0]` is voxel
/// `offset` of the volume.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Block {
    /// Where the block's first voxel lies in the volume's lattice.
    pub offset: [usize; 3],
    /// The block's labels, indexed `[x, y, z]` (any memory layout).
    pub labels: Array3<u32>,
}

impl Block {
    /// The block's box in the volume's lattice, `[lo, hi)`.
    pub fn bounds(&self) -> ([usize; 3], [usize; 3]) {
        let d = self.labels.dim();
        let hi = [d.0, d.1, d.2];
        (self.offset, [0, 1, 2].map(|k| self.offset[k] + hi[k]))
    }
}

/// A labeled volume of dimensions `dims` that is background everywhere but in its
/// [`Block`]s: memory for the blocks' voxels only, however large the lattice.
///
/// **Separation.** Blocks are at least one voxel apart along some axis (their boxes grown
/// by one voxel towards each other do not overlap), so no voxel face and no lattice
/// corner is shared by two blocks: the digital surface of the volume is the union of the
/// blocks' surfaces, each against the background, and
/// [`DigitalSurface::from_blocks`](crate::surface::DigitalSurface::from_blocks) builds it equal, id
/// for id, to that of the volume made dense ([`BlockVolume::to_dense`]).
///
/// The embedding (spacing, origin: the centre of voxel `[0, 0, 0]`) is that of
/// [`LabelVolume`]; the background is always a label (a volume without background has
/// no empty space to leave out).
#[derive(Clone, Debug, PartialEq)]
pub struct BlockVolume {
    dims: [usize; 3],
    blocks: Vec<Block>,
    spacing: DVec3,
    origin: DVec3,
    background: u32,
}

impl BlockVolume {
    /// A volume of dimensions `dims`, background label `background` but in `blocks`;
    /// unit spacing, origin `0`. Fails when a block lies outside `dims` or when two blocks
    /// are not separated by at least one voxel along some axis.
    pub fn new(dims: [usize; 3], blocks: Vec<Block>, background: u32) -> Result<Self, SurfaceError> {
        for (i, b) in blocks.iter().enumerate() {
            let (_, hi) = b.bounds();
            if (0..3).any(|k| hi[k] > dims[k]) {
                return Err(SurfaceError::InvalidVolume(format!(
                    "block {i} ends at {hi:?}, outside dimensions {dims:?}"
                )));
            }
        }
        // Sorted by their low x, a block can only touch the blocks after it that start
        // within its x range (or right after it).
        let mut order: Vec<usize> = (0..blocks.len()).collect();
        order.sort_unstable_by_key(|&i| blocks[i].offset[0]);
        for (n, &i) in order.iter().enumerate() {
            let (alo, ahi) = blocks[i].bounds();
            for &j in &order[n + 1..] {
                let (blo, bhi) = blocks[j].bounds();
                if blo[0] > ahi[0] {
                    break;
                }
                if (0..3).all(|k| blo[k] <= ahi[k] && alo[k] <= bhi[k]) {
                    return Err(SurfaceError::InvalidVolume(format!(
                        "blocks {i} and {j} are not one voxel apart along any axis"
                    )));
                }
            }
        }
        Ok(BlockVolume { dims, blocks, spacing: DVec3::ONE, origin: DVec3::ZERO, background })
    }

    /// Sets the physical size of a voxel (finite and positive, as
    /// [`LabelVolume::with_spacing`]).
    pub fn with_spacing(mut self, spacing: DVec3) -> Result<Self, SurfaceError> {
        self.spacing = LabelVolume::from_fn([0, 0, 0], |_| 0).with_spacing(spacing)?.spacing();
        Ok(self)
    }

    /// Sets the physical position of the centre of voxel `[0, 0, 0]` (finite).
    pub fn with_origin(mut self, origin: DVec3) -> Result<Self, SurfaceError> {
        self.origin = LabelVolume::from_fn([0, 0, 0], |_| 0).with_origin(origin)?.origin();
        Ok(self)
    }

    /// Number of voxels of the lattice along x, y and z.
    pub fn dims(&self) -> [usize; 3] {
        self.dims
    }

    /// Number of voxels of the lattice (blocks and background).
    pub fn len(&self) -> u128 {
        self.dims.iter().map(|&d| d as u128).product()
    }

    /// Whether the lattice has no voxel.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Number of voxels held in blocks: what the volume stores.
    pub fn block_voxels(&self) -> usize {
        self.blocks.iter().map(|b| b.labels.len()).sum()
    }

    /// The blocks.
    pub fn blocks(&self) -> &[Block] {
        &self.blocks
    }

    /// Physical size of a voxel.
    pub fn spacing(&self) -> DVec3 {
        self.spacing
    }

    /// Physical position of the centre of voxel `[0, 0, 0]`.
    pub fn origin(&self) -> DVec3 {
        self.origin
    }

    /// The background label: every voxel outside the blocks, and the outside of the domain.
    pub fn background(&self) -> u32 {
        self.background
    }

    /// The label of voxel `v` (the background outside the blocks and the domain).
    pub fn label(&self, v: Voxel) -> u32 {
        for b in &self.blocks {
            let (lo, hi) = b.bounds();
            if (0..3).all(|k| v[k] >= lo[k] as i64 && v[k] < hi[k] as i64) {
                return b.labels[[0, 1, 2].map(|k| (v[k] - lo[k] as i64) as usize)];
            }
        }
        self.background
    }

    /// The distinct labels of the volume with their voxel counts, sorted by label; the
    /// background counts the voxels outside the blocks too.
    pub fn label_counts(&self) -> Vec<(u32, u64)> {
        let mut counts: Vec<(u32, u64)> = Vec::new();
        for b in &self.blocks {
            let view = crate::volume::LabelView::from_view(b.labels.view());
            counts.extend(view.label_counts());
        }
        let outside = self.len().saturating_sub(self.block_voxels() as u128);
        if outside > 0 {
            counts.push((self.background, u64::try_from(outside).unwrap_or(u64::MAX)));
        }
        counts.sort_unstable_by_key(|c| c.0);
        let mut merged: Vec<(u32, u64)> = Vec::with_capacity(counts.len());
        for (l, c) in counts {
            match merged.last_mut() {
                Some(last) if last.0 == l => last.1 = last.1.saturating_add(c),
                _ => merged.push((l, c)),
            }
        }
        merged
    }

    /// The largest label (the background included).
    pub fn max_label(&self) -> u32 {
        self.label_counts().last().map_or(self.background, |c| c.0)
    }

    /// The same volume made dense (all of the lattice stored, `x` fastest).
    pub fn to_dense(&self) -> Result<LabelVolume, SurfaceError> {
        let n = self.dims.iter().try_fold(1usize, |a, &d| a.checked_mul(d)).ok_or_else(|| {
            SurfaceError::TooLarge(format!("dimensions {}x{}x{}", self.dims[0], self.dims[1], self.dims[2]))
        })?;
        let mut labels =
            Array3::from_shape_vec((self.dims[0], self.dims[1], self.dims[2]).f(), vec![self.background; n])
                .map_err(|e| SurfaceError::InvalidVolume(e.to_string()))?;
        for b in &self.blocks {
            let (lo, hi) = b.bounds();
            let mut view = labels.view_mut();
            for k in 0..3 {
                view.slice_axis_inplace(ndarray::Axis(k), ndarray::Slice::from(lo[k]..hi[k]));
            }
            view.assign(&b.labels);
        }
        LabelVolume::new(labels)
            .with_background(Some(self.background))
            .with_spacing(self.spacing)?
            .with_origin(self.origin)
    }
}
