//! The surfels of a surface looked up by their face of the lattice, for the rules that walk
//! the voxels next to a surface (the clamping boxes' thin voxels, the thin-sheet rule).

use rayon::prelude::*;
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

    fn key(&self, axis: usize, cell: [i64; 3]) -> Option<u64> {
        let mut key = axis as u64;
        for k in 0..3 {
            let c = u64::try_from(cell[k] + 1).ok().filter(|&c| c < self.sides[k])?;
            key = key * self.sides[k] + c;
        }
        Some(key)
    }
}

/// The surfels' faces as sorted keys, for walks that look up few faces or look them up
/// in order: built in parallel (the surface's own order is already sorted by these keys,
/// so usually without a sort), where [`FaceIndex`]'s hash map is filled on one thread but
/// answers random lookups faster.
pub(crate) struct FaceKeys {
    /// `dims + 1` along each axis: the key's strides.
    sides: [u64; 3],
    /// `(key, surfel)`, sorted.
    keys: Vec<(u64, u32)>,
}

impl FaceKeys {
    pub(crate) fn new(surface: &DigitalSurface) -> FaceKeys {
        let sides = surface.dims().map(|d| d as u64 + 1);
        let mut out = FaceKeys { sides, keys: Vec::new() };
        out.keys = surface
            .surfels()
            .par_iter()
            .enumerate()
            .map(|(i, s)| {
                (
                    out.key(s.axis as usize, s.cell.map(i64::from)).expect("a surfel's face is in range"),
                    i as u32,
                )
            })
            .collect();
        if !out.keys.par_windows(2).all(|w| w[0].0 < w[1].0) {
            out.keys.par_sort_unstable();
        }
        out
    }

    /// The position in [`FaceKeys::keys`] of face `(axis, cell)` at or after `from`, if
    /// that face is a surfel: a galloping search from `from`, cheap for a face close
    /// after it in the keys' order.
    fn find_from(&self, from: usize, axis: usize, cell: [i64; 3]) -> Option<usize> {
        let key = self.key(axis, cell)?;
        let keys = &self.keys;
        let mut step = 1;
        let mut lo = from;
        while lo + step < keys.len() && keys[lo + step].0 < key {
            lo += step;
            step *= 2;
        }
        let hi = (lo + step + 1).min(keys.len());
        let at = lo + keys[lo..hi].partition_point(|k| k.0 < key);
        (at < keys.len() && keys[at].0 == key).then_some(at)
    }

    /// Whether face `(axis, cell)` is a surfel.
    #[cfg(test)]
    pub(crate) fn contains(&self, axis: usize, cell: [i64; 3]) -> bool {
        self.find_from(0, axis, cell).is_some()
    }

    /// The voxels whose two faces along some axis are both surfels, each once per such
    /// axis, with those two surfels (lower, upper), in parallel: each surfel looks for the
    /// face one voxel after it along its axis, which comes after it in the keys' order.
    pub(crate) fn between_two_faces(&self) -> Vec<([i64; 3], [u32; 2])> {
        (0..self.keys.len())
            .into_par_iter()
            .with_min_len(4096)
            .filter_map(|p| {
                let (axis, cell) = self.face(self.keys[p].0);
                let mut up = cell;
                up[axis] += 1;
                self.find_from(p, axis, up).map(|q| (cell, [self.keys[p].1, self.keys[q].1]))
            })
            .collect()
    }

    /// Keys increase with `z`, then the axis (z, x, y), then `y`, then `x`: the order in
    /// which the surface's scan finds faces.
    fn key(&self, axis: usize, cell: [i64; 3]) -> Option<u64> {
        let [sx, sy, _] = self.sides;
        let c = |k: usize| u64::try_from(cell[k]).ok().filter(|&c| c < self.sides[k]);
        let rank = [1, 2, 0][axis];
        Some(((c(2)? * 3 + rank) * sy + c(1)?) * sx + c(0)?)
    }

    /// The face of `key`.
    fn face(&self, key: u64) -> (usize, [i64; 3]) {
        let [sx, sy, _] = self.sides;
        let (x, rest) = (key % sx, key / sx);
        let (y, rest) = (rest % sy, rest / sy);
        let (rank, z) = (rest % 3, rest / 3);
        ([2, 0, 1][rank as usize], [x as i64, y as i64, z as i64])
    }
}

#[cfg(test)]
mod tests {
    use voxreg_digisurf::LabelVolume;

    use super::*;

    /// Both indexes answer every face in and around a random volume alike, and the
    /// voxels between two faces are those found by looking both faces up.
    #[test]
    fn sorted_keys_and_the_hash_map_agree() {
        let mut rng = voxreg_testkit::Lcg::new(3);
        let volume =
            LabelVolume::from_fn([9, 7, 5], |_| u32::from(rng.next_f64() < 0.4)).with_background(Some(0));
        let surface = DigitalSurface::from_volume(&volume).unwrap();
        let (index, keys) = (FaceIndex::new(&surface), FaceKeys::new(&surface));
        // The surface's own order (no sort needed): if the scan's order changes, the keys'
        // order should follow it.
        assert!(keys.keys.iter().enumerate().all(|(i, k)| k.1 as usize == i), "surfels not in key order");
        let mut both = Vec::new();
        for axis in 0..3 {
            for z in -2..8 {
                for y in -2..10 {
                    for x in -2..12 {
                        let cell = [x, y, z];
                        assert_eq!(
                            index.get(axis, cell).is_some(),
                            keys.contains(axis, cell),
                            "{axis} {cell:?}"
                        );
                        let mut up = cell;
                        up[axis] += 1;
                        if index.get(axis, cell).is_some() && index.get(axis, up).is_some() {
                            both.push(cell);
                        }
                    }
                }
            }
        }
        let pairs = keys.between_two_faces();
        // Each voxel's two surfels: its lower face, and the face one voxel up the same axis.
        for (cell, [lower, upper]) in &pairs {
            let (lo, hi) = (surface.surfels()[*lower as usize], surface.surfels()[*upper as usize]);
            assert_eq!(lo.axis, hi.axis);
            let mut up = *cell;
            up[lo.axis as usize] += 1;
            assert_eq!((lo.cell.map(i64::from), hi.cell.map(i64::from)), (*cell, up));
        }
        let mut found: Vec<[i64; 3]> = pairs.into_iter().map(|p| p.0).collect();
        found.sort_unstable();
        both.sort_unstable();
        assert!(!both.is_empty());
        assert_eq!(found, both);
    }
}
