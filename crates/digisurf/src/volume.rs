//! Labeled voxel volumes.

use glam::DVec3;
use ndarray::{
    Array3, ArrayBase, ArrayView3, Data, Ix3, OwnedRepr, RawData, RawDataClone, ShapeBuilder, ViewRepr,
};
use rayon::prelude::*;

use crate::error::SurfaceError;

/// A voxel's integer coordinates `[x, y, z]`. Coordinates may lie outside the
/// volume (e.g. `-1`) when they name the outside of the domain.
pub type Voxel = [i64; 3];

/// A 3D array of labels with a physical embedding.
///
/// Labels are `u32`. Voxel `[x, y, z]` is stored at index `[x, y, z]` of the
/// array (any memory layout is accepted; volumes read from files use `x`
/// fastest).
///
/// **Storage.** `S` is the array's storage: owned (`LabelVolume`, the default) or
/// borrowed ([`LabelView`], over labels someone else owns, e.g. a numpy array), so a
/// caller holding labels need not copy them to build a surface. Every read-only method
/// is available on both; [`LabelVolume::view`] borrows any volume as a [`LabelView`].
///
/// **Embedding.** The centre of voxel `[x, y, z]` lies at
/// `origin + [x * sx, y * sy, z * sz]` (the convention of NIfTI, DGtal and VTK
/// point data), so the lattice corner `c` (integer, `0..=dims`) of the
/// digital surface lies at `origin + (c - 0.5) * spacing`.
///
/// **Background.** By default label `0` is the background: empty space, which
/// also fills everything outside the domain, so objects touching the border
/// still get closed surfaces. A volume with no background ([`LabelVolume::with_background`]
/// with `None`) treats every label as a material; then the domain border carries no
/// surfels and interfaces end there as open surfaces.
///
/// **Open sides.** A crop of a larger volume can mark the sides where it was cut open
/// ([`LabelVolume::with_open_sides`]): those carry no surfels, as the whole border of a
/// volume without background, while the other sides stay closed by the background.
/// Beyond a cut lies unknown data, not empty space, so no surface is invented there.
pub struct LabelVolume<S = OwnedRepr<u32>>
where
    S: RawData<Elem = u32>,
{
    labels: ArrayBase<S, Ix3>,
    spacing: DVec3,
    origin: DVec3,
    background: Option<u32>,
    open_sides: [[bool; 2]; 3],
}

/// No open side.
const CLOSED: [[bool; 2]; 3] = [[false; 2]; 3];

/// A [`LabelVolume`] over borrowed labels (any strides): what building a surface reads.
pub type LabelView<'a> = LabelVolume<ViewRepr<&'a u32>>;

/// The storages a [`LabelVolume`]'s labels can have, owned or borrowed (ndarray's
/// `Data<Elem = u32>`): what functions generic over volumes ask for.
pub trait LabelStorage: Data<Elem = u32> {}

impl<S: Data<Elem = u32>> LabelStorage for S {}

impl<S: RawDataClone<Elem = u32>> Clone for LabelVolume<S> {
    fn clone(&self) -> Self {
        LabelVolume {
            labels: self.labels.clone(),
            spacing: self.spacing,
            origin: self.origin,
            background: self.background,
            open_sides: self.open_sides,
        }
    }
}

impl<S: Data<Elem = u32>> std::fmt::Debug for LabelVolume<S> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LabelVolume")
            .field("labels", &self.labels)
            .field("spacing", &self.spacing)
            .field("origin", &self.origin)
            .field("background", &self.background)
            .field("open_sides", &self.open_sides)
            .finish()
    }
}

impl<S: Data<Elem = u32>, T: Data<Elem = u32>> PartialEq<LabelVolume<T>> for LabelVolume<S> {
    fn eq(&self, other: &LabelVolume<T>) -> bool {
        self.labels == other.labels
            && self.spacing == other.spacing
            && self.origin == other.origin
            && self.background == other.background
            && self.open_sides == other.open_sides
    }
}

impl<S: RawData<Elem = u32>> LabelVolume<S> {
    /// Unit spacing, origin `0`, background label `0`, no open side.
    fn with_defaults(labels: ArrayBase<S, Ix3>) -> Self {
        LabelVolume {
            labels,
            spacing: DVec3::ONE,
            origin: DVec3::ZERO,
            background: Some(0),
            open_sides: CLOSED,
        }
    }
}

impl<'a> LabelView<'a> {
    /// A volume over borrowed `labels` (any memory layout, no copy) with unit spacing,
    /// origin `0` and background label `0`.
    pub fn from_view(labels: ArrayView3<'a, u32>) -> Self {
        LabelVolume::with_defaults(labels)
    }
}

impl LabelVolume {
    /// A volume over `labels` with unit spacing, origin `0` and background label `0`.
    pub fn new(labels: Array3<u32>) -> Self {
        LabelVolume::with_defaults(labels)
    }

    /// A volume of dimensions `dims` whose label at `[x, y, z]` is `f([x, y, z])`.
    /// Stored with `x` fastest.
    pub fn from_fn(dims: [usize; 3], mut f: impl FnMut([usize; 3]) -> u32) -> Self {
        let labels = Array3::from_shape_fn((dims[0], dims[1], dims[2]).f(), |(x, y, z)| f([x, y, z]));
        Self::new(labels)
    }

    /// A volume from labels listed with `x` fastest, then `y`, then `z` (the order of
    /// most file formats).
    pub fn from_x_fastest(dims: [usize; 3], labels: Vec<u32>) -> Result<Self, SurfaceError> {
        Ok(Self::new(x_fastest_array(dims, labels, "labels")?))
    }

    /// Mutable access to the label array, indexed `[x, y, z]`.
    pub fn labels_mut(&mut self) -> &mut Array3<u32> {
        &mut self.labels
    }
}

/// The array of dimensions `dims` over `values` listed with `x` fastest, then `y`, then
/// `z`, else the one-line error every volume gives when their number is not the product
/// of `dims` (`what` names the values: `"labels"`, `"grey levels"`).
pub fn x_fastest_array<T>(dims: [usize; 3], values: Vec<T>, what: &str) -> Result<Array3<T>, SurfaceError> {
    let expected = dims.iter().try_fold(1usize, |acc, &d| acc.checked_mul(d));
    if expected != Some(values.len()) {
        return Err(SurfaceError::InvalidVolume(format!(
            "{} {what} given for dimensions {}x{}x{}",
            values.len(),
            dims[0],
            dims[1],
            dims[2]
        )));
    }
    Array3::from_shape_vec((dims[0], dims[1], dims[2]).f(), values)
        .map_err(|e| SurfaceError::InvalidVolume(e.to_string()))
}

/// `spacing` if each component is finite and positive (a voxel's physical size), else
/// the one-line error every volume gives for it.
pub fn checked_spacing(spacing: DVec3) -> Result<DVec3, SurfaceError> {
    if !(spacing.is_finite() && spacing.min_element() > 0.0) {
        return Err(SurfaceError::InvalidVolume(format!(
            "voxel spacing must be finite and positive, got {spacing}"
        )));
    }
    Ok(spacing)
}

/// `origin` if it is finite (the centre of voxel `[0, 0, 0]`), else the one-line error
/// every volume gives for it.
pub fn checked_origin(origin: DVec3) -> Result<DVec3, SurfaceError> {
    if !origin.is_finite() {
        return Err(SurfaceError::InvalidVolume(format!("origin must be finite, got {origin}")));
    }
    Ok(origin)
}

impl<S: Data<Elem = u32>> LabelVolume<S> {
    /// Sets the physical size of a voxel along x, y and z (default `1, 1, 1`).
    /// Each component must be finite and positive.
    pub fn with_spacing(mut self, spacing: DVec3) -> Result<Self, SurfaceError> {
        self.spacing = checked_spacing(spacing)?;
        Ok(self)
    }

    /// Sets the physical position of the centre of voxel `[0, 0, 0]` (default `0`).
    pub fn with_origin(mut self, origin: DVec3) -> Result<Self, SurfaceError> {
        self.origin = checked_origin(origin)?;
        Ok(self)
    }

    /// Sets the background label (default `Some(0)`); `None` makes every label a material.
    pub fn with_background(mut self, background: Option<u32>) -> Self {
        self.background = background;
        self
    }

    /// Opens the sides `open[axis][low, high]` of the domain (default: none): no surfel
    /// lies on an open side, and the interfaces that reach it end there as open surfaces.
    pub fn with_open_sides(mut self, open: [[bool; 2]; 3]) -> Self {
        self.open_sides = open;
        self
    }

    /// The open sides of the domain, `[axis][low, high]`: every side of a volume without
    /// background, else those set by [`LabelVolume::with_open_sides`].
    pub fn open_sides(&self) -> [[bool; 2]; 3] {
        if self.background.is_none() {
            [[true; 2]; 3]
        } else {
            self.open_sides
        }
    }

    /// Number of voxels along x, y and z.
    pub fn dims(&self) -> [usize; 3] {
        let d = self.labels.dim();
        [d.0, d.1, d.2]
    }

    /// Total number of voxels.
    pub fn len(&self) -> usize {
        self.labels.len()
    }

    /// Whether the volume has no voxel at all.
    pub fn is_empty(&self) -> bool {
        self.labels.is_empty()
    }

    /// Physical size of a voxel along x, y and z.
    pub fn spacing(&self) -> DVec3 {
        self.spacing
    }

    /// Physical position of the centre of voxel `[0, 0, 0]`.
    pub fn origin(&self) -> DVec3 {
        self.origin
    }

    /// The background label, if the volume has one.
    pub fn background(&self) -> Option<u32> {
        self.background
    }

    /// The label array, indexed `[x, y, z]`.
    pub fn labels(&self) -> &ArrayBase<S, Ix3> {
        &self.labels
    }

    /// The volume borrowed: the same labels (no copy) and embedding.
    pub fn view(&self) -> LabelView<'_> {
        LabelVolume {
            labels: self.labels.view(),
            spacing: self.spacing,
            origin: self.origin,
            background: self.background,
            open_sides: self.open_sides,
        }
    }

    /// An owned copy of the volume (its labels in the same memory order where they are
    /// contiguous).
    pub fn to_owned(&self) -> LabelVolume {
        LabelVolume {
            labels: self.labels.to_owned(),
            spacing: self.spacing,
            origin: self.origin,
            background: self.background,
            open_sides: self.open_sides,
        }
    }

    /// The label of voxel `v`: the background label outside the domain, or `None`
    /// beyond an open side (every side of a volume without background).
    pub fn label(&self, v: Voxel) -> Option<u32> {
        let d = self.dims();
        if (0..3).all(|k| v[k] >= 0 && (v[k] as u64) < d[k] as u64) {
            return Some(self.labels[[v[0] as usize, v[1] as usize, v[2] as usize]]);
        }
        let open = self.open_sides();
        let beyond_open = (0..3)
            .any(|k| (v[k] < 0 && open[k][0]) || (v[k] >= 0 && v[k] as u64 >= d[k] as u64 && open[k][1]));
        if beyond_open {
            None
        } else {
            self.background
        }
    }

    /// Physical position of lattice corner `c` (integer coordinates `0..=dims`).
    pub fn corner_position(&self, c: [u32; 3]) -> DVec3 {
        let c = DVec3::new(c[0] as f64, c[1] as f64, c[2] as f64);
        self.origin + (c - 0.5) * self.spacing
    }

    /// Physical position of the centre of voxel `v`.
    pub fn voxel_centre(&self, v: Voxel) -> DVec3 {
        let v = DVec3::new(v[0] as f64, v[1] as f64, v[2] as f64);
        self.origin + v * self.spacing
    }

    /// The largest label (`None` for an empty volume), found in parallel.
    pub fn max_label(&self) -> Option<u32> {
        match self.labels.as_slice_memory_order() {
            Some(slice) => slice.par_iter().copied().max(),
            None => self.labels.iter().copied().max(),
        }
    }

    /// The distinct labels of the volume with their voxel counts, sorted by label.
    pub fn label_counts(&self) -> Vec<(u32, u64)> {
        let tallies = match self.labels.as_slice_memory_order() {
            // One tally per thread (at most eight: a dense one can reach 8 MiB).
            Some(slice) => {
                let parts = rayon::current_num_threads().clamp(1, 8);
                let chunk = slice.len().div_ceil(parts).max(1 << 16);
                slice.par_chunks(chunk).map(|c| Tally::of(c.iter().copied())).collect()
            }
            None => vec![Tally::of(self.labels.iter().copied())],
        };
        Tally::merge(tallies)
    }

    /// A binary volume: label `1` where `inside(label)` holds, `0` (background) elsewhere.
    /// Spacing and origin are kept.
    pub fn binarize(&self, mut inside: impl FnMut(u32) -> bool) -> LabelVolume {
        LabelVolume {
            labels: self.labels.mapv(|l| u32::from(inside(l))),
            spacing: self.spacing,
            origin: self.origin,
            background: Some(0),
            open_sides: self.open_sides,
        }
    }
}

/// Voxel counts of labels: dense while labels stay small, a list to sort beyond.
struct Tally {
    dense: Vec<u64>,
    large: Vec<u32>,
}

impl Tally {
    fn of(labels: impl Iterator<Item = u32>) -> Tally {
        let mut t = Tally { dense: Vec::new(), large: Vec::new() };
        // Counted per run of equal labels (labels come in long runs): one update a run.
        let mut add = |l: u32, n: u64| {
            if (l as usize) < (1 << 20) {
                if l as usize >= t.dense.len() {
                    t.dense.resize(l as usize + 1, 0);
                }
                t.dense[l as usize] += n;
            } else {
                t.large.extend(std::iter::repeat_n(l, n as usize));
            }
        };
        let mut run: Option<(u32, u64)> = None;
        for l in labels {
            run = match run {
                Some((r, n)) if r == l => Some((r, n + 1)),
                Some((r, n)) => {
                    add(r, n);
                    Some((l, 1))
                }
                None => Some((l, 1)),
            };
        }
        if let Some((r, n)) = run {
            add(r, n);
        }
        t
    }

    /// The labels of all `parts` with their counts, sorted by label.
    fn merge(parts: Vec<Tally>) -> Vec<(u32, u64)> {
        let mut dense: Vec<u64> = vec![0; parts.iter().map(|t| t.dense.len()).max().unwrap_or(0)];
        let mut large: Vec<u32> = Vec::new();
        for t in parts {
            dense.iter_mut().zip(&t.dense).for_each(|(d, c)| *d += c);
            large.extend(t.large);
        }
        let mut counts: Vec<(u32, u64)> =
            dense.iter().enumerate().filter(|(_, &c)| c > 0).map(|(l, &c)| (l as u32, c)).collect();
        large.sort_unstable();
        for chunk in large.chunk_by(|a, b| a == b) {
            counts.push((chunk[0], chunk.len() as u64));
        }
        counts
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn x_fastest_layout() {
        let v = LabelVolume::from_x_fastest([2, 3, 4], (0..24).collect()).unwrap();
        assert_eq!(v.label([1, 0, 0]), Some(1));
        assert_eq!(v.label([0, 1, 0]), Some(2));
        assert_eq!(v.label([0, 0, 1]), Some(6));
        assert_eq!(v.label([-1, 0, 0]), Some(0));
        assert_eq!(v.clone().with_background(None).label([0, 3, 0]), None);
        assert!(LabelVolume::from_x_fastest([2, 3, 4], vec![0; 23]).is_err());
    }

    #[test]
    fn embedding_and_validation() {
        let v = LabelVolume::from_fn([1, 1, 1], |_| 1)
            .with_spacing(DVec3::new(1.0, 2.0, 3.0))
            .unwrap()
            .with_origin(DVec3::splat(10.0))
            .unwrap();
        assert_eq!(v.corner_position([0, 0, 0]), DVec3::new(9.5, 9.0, 8.5));
        assert_eq!(v.corner_position([1, 1, 1]), DVec3::new(10.5, 11.0, 11.5));
        assert!(v.clone().with_spacing(DVec3::new(0.0, 1.0, 1.0)).is_err());
        assert!(v.with_origin(DVec3::NAN).is_err());
    }

    #[test]
    fn counts() {
        let v = LabelVolume::from_fn([3, 1, 1], |p| [5, 0, 5][p[0]]);
        assert_eq!(v.label_counts(), vec![(0, 1), (5, 2)]);
        let big = LabelVolume::from_fn([2, 1, 1], |p| [u32::MAX, 7][p[0]]);
        assert_eq!(big.label_counts(), vec![(7, 1), (u32::MAX, 1)]);
        // Counted in parallel parts (2^16 voxels or more each), small and large labels
        // spread over them: the same as one tally.
        let label = |[x, y, z]: [usize; 3]| match (x * 7 + y * 3 + z) % 11 {
            0 => u32::MAX - (x % 3) as u32,
            1 => (1 << 20) + (y % 5) as u32,
            k => (k * (z % 4)) as u32,
        };
        let v = LabelVolume::from_fn([90, 50, 40], label);
        let mut expected = std::collections::BTreeMap::new();
        for x in 0..90 {
            for y in 0..50 {
                for z in 0..40 {
                    *expected.entry(label([x, y, z])).or_insert(0u64) += 1;
                }
            }
        }
        assert_eq!(v.max_label(), expected.keys().next_back().copied());
        assert_eq!(v.label_counts(), expected.into_iter().collect::<Vec<_>>());
    }

    #[test]
    fn borrowed_labels_make_the_owned_surface() {
        use crate::regions::RegionMap;
        use crate::surface::DigitalSurface;
        // Two labels in a ball-ish blob, stored x fastest.
        let owned = LabelVolume::from_fn([7, 6, 5], |[x, y, z]| {
            let d = (x as i64 - 3).pow(2) + (y as i64 - 3).pow(2) + (z as i64 - 2).pow(2);
            u32::from(d <= 6) * (1 + u32::from(x > 3))
        })
        .with_spacing(DVec3::new(1.0, 2.0, 0.5))
        .unwrap()
        .with_background(Some(0));
        // The same labels in C order, and inside a larger array read through a strided view.
        let c_order = owned.labels().as_standard_layout().into_owned();
        let mut padded = Array3::from_elem((14, 6, 10), 9u32);
        let every_other = ndarray::Slice::new(0, None, 2);
        let mut holes = padded.slice_axis_mut(ndarray::Axis(0), every_other);
        holes.slice_axis_inplace(ndarray::Axis(2), every_other);
        holes.assign(&c_order);
        let mut strided = padded.view();
        strided.slice_axis_inplace(ndarray::Axis(0), every_other);
        strided.slice_axis_inplace(ndarray::Axis(2), every_other);
        assert!(strided.as_slice_memory_order().is_none());
        let map = RegionMap::per_label();
        let reference = DigitalSurface::new(&owned, &map).unwrap();
        for view in [c_order.view(), strided] {
            let v = LabelView::from_view(view).with_spacing(owned.spacing()).unwrap();
            assert_eq!(v, owned);
            assert_eq!(v.label_counts(), owned.label_counts());
            let s = DigitalSurface::new(&v, &map).unwrap();
            assert_eq!(s.surfels(), reference.surfels());
            assert_eq!(s.counts(), reference.counts());
        }
        assert_eq!(owned.view().to_owned(), owned);
    }
}
