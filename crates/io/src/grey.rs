//! Voxel values as read from a file: labels, or grey levels to threshold.

use glam::DVec3;
use ndarray::{Array3, ShapeBuilder};
use voxreg_digisurf::{checked_origin, checked_spacing, x_fastest_array, LabelVolume, SurfaceError};

/// A 3D array of grey levels (`f64`, never NaN) with a physical embedding.
///
/// Value `[x, y, z]` is stored at index `[x, y, z]`; spacing and origin mean what they
/// mean for a [`LabelVolume`] (the origin is the centre of voxel `[0, 0, 0]`). Readers
/// return one for data that are not labels: floats that are not all integral, negative
/// or wider-than-`u32` integers, and NIfTI data scaled by `scl_slope`/`scl_inter`. Turn
/// it into labels with [`GreyVolume::threshold`] or, when every value is an integer in
/// `0..=u32::MAX`, [`GreyVolume::to_labels`].
#[derive(Clone, Debug, PartialEq)]
pub struct GreyVolume {
    values: Array3<f64>,
    spacing: DVec3,
    origin: DVec3,
}

/// A grey level that is not a label: not an integer in `0..=u32::MAX`.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
#[error(
    "grey level {value} at voxel [{}, {}, {}] is not a label (an integer in 0..=4294967295)",
    .voxel[0], .voxel[1], .voxel[2]
)]
pub struct NotALabel {
    /// The first such voxel, in `x`-fastest order.
    pub voxel: [usize; 3],
    /// Its value.
    pub value: f64,
}

impl GreyVolume {
    /// A volume over `values` with unit spacing and origin `0`; fails if a value is NaN.
    pub fn new(values: Array3<f64>) -> Result<Self, SurfaceError> {
        if let Some(((x, y, z), _)) = values.indexed_iter().find(|(_, v)| v.is_nan()) {
            return Err(SurfaceError::InvalidVolume(format!("grey level NaN at voxel [{x}, {y}, {z}]")));
        }
        Ok(GreyVolume { values, spacing: DVec3::ONE, origin: DVec3::ZERO })
    }

    /// A volume from values listed with `x` fastest, then `y`, then `z`; fails if their
    /// number is not the product of `dims` or a value is NaN.
    pub fn from_x_fastest(dims: [usize; 3], values: Vec<f64>) -> Result<Self, SurfaceError> {
        Self::new(x_fastest_array(dims, values, "grey levels")?)
    }

    /// Sets the physical size of a voxel (default `1, 1, 1`); each component must be
    /// finite and positive.
    pub fn with_spacing(mut self, spacing: DVec3) -> Result<Self, SurfaceError> {
        self.spacing = checked_spacing(spacing)?;
        Ok(self)
    }

    /// Sets the physical position of the centre of voxel `[0, 0, 0]` (default `0`).
    pub fn with_origin(mut self, origin: DVec3) -> Result<Self, SurfaceError> {
        self.origin = checked_origin(origin)?;
        Ok(self)
    }

    /// Number of voxels along x, y and z.
    pub fn dims(&self) -> [usize; 3] {
        let d = self.values.dim();
        [d.0, d.1, d.2]
    }

    /// Physical size of a voxel along x, y and z.
    pub fn spacing(&self) -> DVec3 {
        self.spacing
    }

    /// Physical position of the centre of voxel `[0, 0, 0]`.
    pub fn origin(&self) -> DVec3 {
        self.origin
    }

    /// The grey levels, indexed `[x, y, z]`.
    pub fn values(&self) -> &Array3<f64> {
        &self.values
    }

    /// The smallest and largest grey level (`None` for an empty volume).
    pub fn range(&self) -> Option<(f64, f64)> {
        self.values.iter().fold(None, |acc, &v| match acc {
            None => Some((v, v)),
            Some((lo, hi)) => Some((v.min(lo), v.max(hi))),
        })
    }

    /// A binary volume: label `1` where the grey level is `> t`, `0` (the background)
    /// elsewhere. Spacing and origin are kept.
    pub fn threshold(&self, t: f64) -> LabelVolume {
        self.labels_with(|v| u32::from(v > t))
    }

    /// The grey levels as labels, if every one is an integer in `0..=u32::MAX`
    /// (background `0`; spacing and origin kept); otherwise the first that is not.
    pub fn to_labels(&self) -> Result<LabelVolume, NotALabel> {
        let [nx, ny, _] = self.dims();
        // Scan in x-fastest order, so that the voxel reported is the first in file order.
        let first = self.values.t().iter().position(|&v| as_label(v).is_none());
        if let Some(i) = first {
            let voxel = [i % nx, (i / nx) % ny, i / (nx * ny)];
            return Err(NotALabel { voxel, value: self.values[voxel] });
        }
        Ok(self.labels_with(|v| as_label(v).unwrap_or(0)))
    }

    fn labels_with(&self, f: impl Fn(f64) -> u32) -> LabelVolume {
        let labels = Array3::from_shape_fn(self.values.raw_dim().f(), |i| f(self.values[i]));
        embed(LabelVolume::new(labels), self.spacing, self.origin)
    }
}

/// `v` as a label, if it is an integer in `0..=u32::MAX`.
pub(crate) fn as_label(v: f64) -> Option<u32> {
    (v >= 0.0 && v <= f64::from(u32::MAX) && v.fract() == 0.0).then_some(v as u32)
}

/// Gives `volume` the spacing and origin of a valid volume (they were validated there).
fn embed(volume: LabelVolume, spacing: DVec3, origin: DVec3) -> LabelVolume {
    let placed = volume.with_spacing(spacing).and_then(|v| v.with_origin(origin));
    placed.expect("spacing and origin come from a valid volume")
}

/// The voxels of a file: labels, or grey levels that need a threshold.
#[derive(Clone, Debug, PartialEq)]
pub enum Voxels {
    /// Integer values that fit a `u32` label (background `0`).
    Labels(LabelVolume),
    /// Values that are not all labels (see [`GreyVolume`]).
    Grey(GreyVolume),
}

impl Voxels {
    /// Number of voxels along x, y and z.
    pub fn dims(&self) -> [usize; 3] {
        match self {
            Voxels::Labels(v) => v.dims(),
            Voxels::Grey(g) => g.dims(),
        }
    }

    /// Physical size of a voxel along x, y and z.
    pub fn spacing(&self) -> DVec3 {
        match self {
            Voxels::Labels(v) => v.spacing(),
            Voxels::Grey(g) => g.spacing(),
        }
    }

    /// Physical position of the centre of voxel `[0, 0, 0]`.
    pub fn origin(&self) -> DVec3 {
        match self {
            Voxels::Labels(v) => v.origin(),
            Voxels::Grey(g) => g.origin(),
        }
    }

    /// Sets the physical size of a voxel (each component finite and positive).
    pub fn with_spacing(self, spacing: DVec3) -> Result<Self, SurfaceError> {
        Ok(match self {
            Voxels::Labels(v) => Voxels::Labels(v.with_spacing(spacing)?),
            Voxels::Grey(g) => Voxels::Grey(g.with_spacing(spacing)?),
        })
    }

    /// Sets the physical position of the centre of voxel `[0, 0, 0]`.
    pub fn with_origin(self, origin: DVec3) -> Result<Self, SurfaceError> {
        Ok(match self {
            Voxels::Labels(v) => Voxels::Labels(v.with_origin(origin)?),
            Voxels::Grey(g) => Voxels::Grey(g.with_origin(origin)?),
        })
    }

    /// A binary volume: label `1` where the value (label or grey level) is `> t`, `0`
    /// (the background) elsewhere. Spacing and origin are kept.
    pub fn threshold(&self, t: f64) -> LabelVolume {
        match self {
            Voxels::Labels(v) => v.binarize(|l| f64::from(l) > t),
            Voxels::Grey(g) => g.threshold(t),
        }
    }

    /// The labels: as they are, or grey levels that are all integers in
    /// `0..=u32::MAX` (see [`GreyVolume::to_labels`]).
    pub fn into_labels(self) -> Result<LabelVolume, NotALabel> {
        match self {
            Voxels::Labels(v) => Ok(v),
            Voxels::Grey(g) => g.to_labels(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn threshold_and_labels() {
        let g = GreyVolume::from_x_fastest([3, 1, 1], vec![0.5, 2.0, -1.0]).unwrap();
        assert_eq!(g.range(), Some((-1.0, 2.0)));
        let t = g.threshold(0.25);
        assert_eq!(t.label_counts(), vec![(0, 1), (1, 2)]);
        let err = g.to_labels().unwrap_err();
        assert_eq!(err, NotALabel { voxel: [0, 0, 0], value: 0.5 });
        assert!(err.to_string().starts_with("grey level 0.5 at voxel [0, 0, 0] is not a label"), "{err}");
        let g = GreyVolume::from_x_fastest([2, 2, 1], vec![0.0, 3.0, 1.0, 4.5]).unwrap();
        assert_eq!(g.to_labels().unwrap_err().voxel, [1, 1, 0]);
        let g = GreyVolume::from_x_fastest([2, 1, 1], vec![0.0, 3.0]).unwrap();
        let g = g.with_spacing(DVec3::new(1.0, 2.0, 3.0)).unwrap().with_origin(DVec3::ONE).unwrap();
        let v = Voxels::Grey(g).into_labels().unwrap();
        assert_eq!(v.label([1, 0, 0]), Some(3));
        assert_eq!(v.spacing(), DVec3::new(1.0, 2.0, 3.0));
        assert_eq!(v.origin(), DVec3::ONE);
    }

    #[test]
    fn nan_and_bad_embedding_are_refused() {
        let err = GreyVolume::from_x_fastest([2, 1, 1], vec![0.0, f64::NAN]).unwrap_err();
        assert!(err.to_string().contains("NaN at voxel [1, 0, 0]"), "{err}");
        assert!(GreyVolume::from_x_fastest([2, 1, 1], vec![0.0]).is_err());
        let g = GreyVolume::from_x_fastest([1, 1, 1], vec![0.0]).unwrap();
        assert!(g.clone().with_spacing(DVec3::new(0.0, 1.0, 1.0)).is_err());
        assert!(g.with_origin(DVec3::INFINITY).is_err());
    }

    #[test]
    fn label_range() {
        assert_eq!(as_label(4294967295.0), Some(u32::MAX));
        assert_eq!(as_label(4294967296.0), None);
        assert_eq!(as_label(-0.0), Some(0));
        assert_eq!(as_label(-1.0), None);
        assert_eq!(as_label(f64::INFINITY), None);
    }
}
