//! The surfels of a surface looked up by their face of the lattice, for the rules that walk
//! the voxels next to a surface (the clamping boxes' thin voxels, the thin-sheet rule).

use rustc_hash::FxHashMap as HashMap;
use voxreg_digisurf::DigitalSurface;

/// Each surfel by its face `(axis, cell)`, the face perpendicular to `axis` whose minimal
/// corner is `cell`, for cells from `-1` to `dims + 1` along each axis (the faces of the
/// voxels one outside the domain included). A face is one 8-byte key, so the index holds
/// 12 bytes of payload per surfel.
pub(crate) struct FaceIndex {
    /// `dims + 3` along each axis: the key's strides.
    sides: [u64; 3],
    surfels: HashMap<u64, u32>,
}

impl FaceIndex {
    pub(crate) fn new(surface: &DigitalSurface) -> FaceIndex {
        let sides = surface.dims().map(|d| d as u64 + 3);
        let mut index = FaceIndex { sides, surfels: HashMap::default() };
        index.surfels.reserve(surface.num_surfels());
        for (i, s) in surface.surfels().iter().enumerate() {
            let key = index.key(s.axis as usize, s.cell.map(i64::from)).expect("a surfel's face is in range");
            index.surfels.insert(key, i as u32);
        }
        index
    }

    /// The surfel on face `(axis, cell)`, if there is one.
    pub(crate) fn get(&self, axis: usize, cell: [i64; 3]) -> Option<u32> {
        self.surfels.get(&self.key(axis, cell)?).copied()
    }

    /// Whether face `(axis, cell)` is a surfel.
    pub(crate) fn contains(&self, axis: usize, cell: [i64; 3]) -> bool {
        self.get(axis, cell).is_some()
    }

    fn key(&self, axis: usize, cell: [i64; 3]) -> Option<u64> {
        let mut key = axis as u64;
        for k in 0..3 {
            let c = u64::try_from(cell[k] + 1).ok().filter(|&c| c < self.sides[k])?;
            key = key * self.sides[k] + c;
        }
        Some(key)
    }
}
