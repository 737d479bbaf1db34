//! Surfaces, normals and distances shared by the regularizer's integration tests (each
//! test file uses a subset).
#![allow(dead_code)]

use glam::DVec3;
use voxreg_digisurf::{DigitalSurface, LabelVolume};
use voxreg_normals::NormalField;
use voxreg_testkit::Lcg;

/// Random unit normals (not the trivial ones), to exercise all couplings.
pub(crate) fn random_normals(s: &DigitalSurface, rng: &mut Lcg) -> NormalField {
    NormalField::new(s.surfels().iter().map(|sf| sf.normal() + 0.7 * rng.vec3(-0.5, 0.5)).collect())
}

/// Three labels meeting along junction lines, no background: open interfaces.
pub(crate) fn three_labels_open() -> LabelVolume {
    LabelVolume::from_fn([6, 6, 5], |[x, y, z]| {
        if x + z / 2 < 3 {
            1
        } else if y < 3 {
            2
        } else {
            3
        }
    })
    .with_background(None)
}

/// Two voxels of a 2x2x2 volume touching at one corner: a pinched vertex.
pub(crate) fn pinched() -> DigitalSurface {
    DigitalSurface::from_volume(&LabelVolume::from_fn([2, 2, 2], |[x, y, z]| u32::from(x == y && y == z)))
        .unwrap()
}

/// The largest distance between corresponding points of `a` and `b`.
pub(crate) fn max_distance(a: &[DVec3], b: &[DVec3]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (*x - *y).length()).fold(0.0, f64::max)
}
