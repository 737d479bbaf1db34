//! Per-surfel normal fields.

use glam::DVec3;
use rayon::prelude::*;
use voxreg_digisurf::{SurfelData, SurfelId};

/// One unit normal per surfel, indexed by [`SurfelId`].
#[derive(Clone, Debug, PartialEq, Default)]
pub struct NormalField {
    normals: SurfelData<DVec3>,
}

impl NormalField {
    /// Wraps `normals`, normalizing each; zero or non-finite vectors are kept as zero
    /// (such a surfel then exerts no alignment force).
    pub fn new(mut normals: Vec<DVec3>) -> Self {
        normals.par_iter_mut().for_each(|n| *n = n.try_normalize().unwrap_or(DVec3::ZERO));
        NormalField { normals: normals.into() }
    }

    /// The normal of surfel `s`.
    pub fn get(&self, s: SurfelId) -> DVec3 {
        self.normals[s]
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

    /// The normals to overwrite in place; the caller keeps them unit or zero.
    pub(crate) fn normals_mut(&mut self) -> &mut [DVec3] {
        &mut self.normals
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

impl std::ops::Index<SurfelId> for NormalField {
    type Output = DVec3;
    fn index(&self, s: SurfelId) -> &DVec3 {
        &self.normals[s]
    }
}
