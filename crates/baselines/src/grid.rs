//! Scalar samples on a regular grid: the input of marching cubes and dual contouring.

use glam::DVec3;
use voxreg_digisurf::LabelVolume;

use crate::{BaselineError, Implicit};

/// Scalar values sampled at the points `origin + [x, y, z] * spacing` of a regular grid
/// (`x` fastest), with one value, [`ScalarGrid::exterior`], standing for every point
/// outside it.
///
/// **Inside** is where the value is `>= iso` (for a label indicator: `1 >= 0.5`). A grid
/// sampled from a label volume puts its samples at the voxel centres, so contours and the
/// volume's digital surface share one embedding.
#[derive(Clone, Debug, PartialEq)]
pub struct ScalarGrid {
    dims: [usize; 3],
    origin: DVec3,
    spacing: DVec3,
    values: Vec<f64>,
    exterior: f64,
}

impl ScalarGrid {
    /// A grid of `dims` samples listed `x` fastest; `exterior` is the value outside the
    /// grid (below the iso-value for closed contours).
    pub fn new(
        dims: [usize; 3],
        origin: DVec3,
        spacing: DVec3,
        values: Vec<f64>,
        exterior: f64,
    ) -> Result<Self, BaselineError> {
        if dims.iter().product::<usize>() != values.len() {
            return Err(BaselineError::InvalidInput(format!(
                "{} values for a {}x{}x{} grid",
                values.len(),
                dims[0],
                dims[1],
                dims[2]
            )));
        }
        if !(spacing.is_finite() && spacing.min_element() > 0.0 && origin.is_finite()) {
            return Err(BaselineError::InvalidInput(format!(
                "bad grid embedding: origin {origin}, spacing {spacing}"
            )));
        }
        Ok(ScalarGrid { dims, origin, spacing, values, exterior })
    }

    /// The indicator of `inside(label)` on the voxels of `volume` (1 inside, 0 outside and
    /// beyond the volume), sampled at the voxel centres.
    pub fn indicator(volume: &LabelVolume, inside: impl Fn(u32) -> bool) -> Self {
        let dims = volume.dims();
        let labels = volume.labels();
        let mut values = Vec::with_capacity(volume.len());
        for z in 0..dims[2] {
            for y in 0..dims[1] {
                for x in 0..dims[0] {
                    values.push(if inside(labels[[x, y, z]]) { 1.0 } else { 0.0 });
                }
            }
        }
        ScalarGrid { dims, origin: volume.origin(), spacing: volume.spacing(), values, exterior: 0.0 }
    }

    /// `-shape.value` sampled on the voxel centres of `volume` (inside where `>= 0`), with
    /// `-infinity` outside the grid. `volume` gives only the grid (dimensions, origin,
    /// spacing), e.g. a digitization of `shape`.
    pub fn sample(shape: &dyn Implicit, volume: &LabelVolume) -> Self {
        let dims = volume.dims();
        let (origin, spacing) = (volume.origin(), volume.spacing());
        let mut values = Vec::with_capacity(volume.len());
        for z in 0..dims[2] {
            for y in 0..dims[1] {
                for x in 0..dims[0] {
                    values.push(-shape.value(origin + DVec3::new(x as f64, y as f64, z as f64) * spacing));
                }
            }
        }
        ScalarGrid { dims, origin, spacing, values, exterior: f64::NEG_INFINITY }
    }

    /// This grid with each value `v` replaced by `f(v)` (the exterior value too).
    pub fn map(&self, f: impl Fn(f64) -> f64) -> Self {
        ScalarGrid {
            dims: self.dims,
            origin: self.origin,
            spacing: self.spacing,
            values: self.values.iter().map(|&v| f(v)).collect(),
            exterior: f(self.exterior),
        }
    }

    /// Number of samples along x, y and z.
    pub fn dims(&self) -> [usize; 3] {
        self.dims
    }

    /// Position of sample `[0, 0, 0]`.
    pub fn origin(&self) -> DVec3 {
        self.origin
    }

    /// Distance between samples along x, y and z.
    pub fn spacing(&self) -> DVec3 {
        self.spacing
    }

    /// The value standing for every point outside the grid.
    pub fn exterior(&self) -> f64 {
        self.exterior
    }

    /// The samples, `x` fastest.
    pub fn values(&self) -> &[f64] {
        &self.values
    }

    /// The value at integer point `p` (the exterior value outside the grid).
    pub fn get(&self, p: [i64; 3]) -> f64 {
        let d = self.dims;
        if (0..3).all(|k| p[k] >= 0 && (p[k] as u64) < d[k] as u64) {
            self.values[p[0] as usize + d[0] * (p[1] as usize + d[1] * p[2] as usize)]
        } else {
            self.exterior
        }
    }

    /// Physical position of integer point `p`.
    pub fn position(&self, p: [i64; 3]) -> DVec3 {
        self.origin + DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64) * self.spacing
    }
}
