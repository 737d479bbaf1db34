//! Per-surfel normal fields.

use glam::DVec3;

/// One unit normal per surfel, indexed by [`SurfelId`](voxreg_digisurf::SurfelId).
#[derive(Clone, Debug, PartialEq, Default)]
pub struct NormalField {
    normals: Vec<DVec3>,
}

impl NormalField {
    /// Wraps `normals`, normalizing each; zero or non-finite vectors are kept as zero
    /// (such a surfel then exerts no alignment force).
    pub fn new(mut normals: Vec<DVec3>) -> Self {
        for n in &mut normals {
            *n = n.try_normalize().unwrap_or(DVec3::ZERO);
        }
        NormalField { normals }
    }

    /// Number of normals (surfels).
    pub fn len(&self) -> usize {
        self.normals.len()
    }

    /// Whether the field is empty.
    pub fn is_empty(&self) -> bool {
        self.normals.is_empty()
    }

    /// The normals, in surfel order.
    pub fn as_slice(&self) -> &[DVec3] {
        &self.normals
    }

    /// Largest angle, in degrees, between the directions of `self` and `other`,
    /// orientation ignored (for tests and reports).
    pub fn max_angle_deg(&self, other: &NormalField) -> f64 {
        self.normals
            .iter()
            .zip(&other.normals)
            .map(|(a, b)| a.dot(*b).abs().clamp(0.0, 1.0).acos().to_degrees())
            .fold(0.0, f64::max)
    }
}
