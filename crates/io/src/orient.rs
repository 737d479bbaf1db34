//! Placing a volume in space from an index-to-world map (NIfTI qform/sform, VTK
//! `Direction`), as far as a [`LabelVolume`]'s axis-aligned embedding can.

use glam::{DMat3, DVec3};
use ndarray::{Array3, ArrayView3, Axis, ShapeBuilder};
use voxreg_digisurf::{LabelVolume, SurfaceError};

use crate::grey::{GreyVolume, Voxels};

/// Off-axis entries of a column below this fraction of its largest entry count as zero.
const AXIS_TOLERANCE: f64 = 1e-6;

/// Columns whose parallelepiped has a volume below this fraction of the product of
/// their lengths are collinear or coplanar (the sine of their angles, about).
const DEGENERATE_TOLERANCE: f64 = 1e-6;

/// How a volume was placed by [`place`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Placement {
    /// The map is a scaling, up to axis permutations and flips, which were applied:
    /// voxel centres are exactly where the map puts them.
    Exact,
    /// The map rotates the grid obliquely: the grid was kept axis-aligned, with the
    /// map's voxel sizes and translation, and the rotation was dropped.
    RotationDropped,
}

/// Places `voxels` so that the centre of index `[i, j, k]` of the stored grid lies at
/// `translation + matrix * [i, j, k]` (the columns of `matrix` are the world steps of
/// the three index axes).
///
/// When each column has a single non-zero entry, in distinct rows, the grid's axes are
/// permuted and flipped to follow the world axes (the voxels are re-stored, `x`
/// fastest, only when that changes anything), so the placement is exact. Otherwise the
/// rotation is dropped: spacing = the columns' lengths, origin = `translation`.
///
/// Fails on a degenerate (zero, non-finite) column or translation, and on columns that
/// are collinear or coplanar.
pub(crate) fn place(
    voxels: Voxels,
    matrix: DMat3,
    translation: DVec3,
) -> Result<(Voxels, Placement), SurfaceError> {
    let cols = [matrix.x_axis, matrix.y_axis, matrix.z_axis];
    if cols.iter().any(|c| !c.is_finite() || c.abs().max_element() == 0.0) {
        return Err(SurfaceError::InvalidVolume(format!(
            "degenerate index-to-world map: columns {}, {}, {}",
            cols[0], cols[1], cols[2]
        )));
    }
    // Columns that are (nearly) collinear or coplanar map the grid onto a plane or a
    // line: no placement of voxels, whatever rotation is dropped.
    let volume = matrix.determinant().abs();
    let product = cols.iter().map(|c| c.length()).product::<f64>();
    if volume.is_nan() || volume <= DEGENERATE_TOLERANCE * product {
        return Err(SurfaceError::InvalidVolume(format!(
            "degenerate index-to-world map: columns {}, {}, {} are collinear or coplanar",
            cols[0], cols[1], cols[2]
        )));
    }
    // For each index axis c: the world axis it runs along, if it is axis-aligned.
    let world_axis = |c: DVec3| {
        let a = c.abs();
        let k = if a.x >= a.y && a.x >= a.z {
            0
        } else if a.y >= a.z {
            1
        } else {
            2
        };
        let off = (0..3).filter(|&j| j != k).map(|j| a[j]).fold(0.0, f64::max);
        (off <= AXIS_TOLERANCE * a[k]).then_some(k)
    };
    let axes = cols.map(world_axis);
    let dims = voxels.dims();
    if let [Some(a0), Some(a1), Some(a2)] = axes {
        if a0 != a1 && a1 != a2 && a0 != a2 {
            let perm = [a0, a1, a2];
            let flips = [0, 1, 2].map(|c| cols[c][perm[c]] < 0.0);
            let mut spacing = DVec3::ZERO;
            let mut origin = translation;
            for c in 0..3 {
                spacing[perm[c]] = cols[c][perm[c]].abs();
                if flips[c] {
                    origin += cols[c] * dims[c].saturating_sub(1) as f64;
                }
            }
            let voxels =
                if perm == [0, 1, 2] && flips == [false; 3] { voxels } else { reorient(voxels, perm, flips) };
            return Ok((voxels.with_spacing(spacing)?.with_origin(origin)?, Placement::Exact));
        }
    }
    let spacing = DVec3::new(cols[0].length(), cols[1].length(), cols[2].length());
    Ok((voxels.with_spacing(spacing)?.with_origin(translation)?, Placement::RotationDropped))
}

/// The smallest voxel spacing, and the largest coordinate, accepted: well inside the
/// normal range of `f32`, in which PLY, STL and glTF store positions.
pub const COORDINATE_RANGE: f64 = 1e30;

/// A voxel spacing must exceed the largest coordinate magnitude times this (`2^-36`):
/// vertex positions, `f64`, then resolve a voxel in `2^16` steps.
const RELATIVE_RESOLUTION: f64 = 1.0 / (1u64 << 36) as f64;

/// Checks that the lattice corners of a volume of `dims` voxels of size `spacing`, the
/// centre of voxel `[0, 0, 0]` at `origin`, have coordinates a mesh can represent
/// distinctly: every spacing at least `1e-30` ([`COORDINATE_RANGE`]`^-1`), every corner
/// coordinate at most `1e30` in magnitude, and every spacing at least `2^-36` times the
/// largest corner coordinate's magnitude. Otherwise vertex positions collapse (an origin
/// of `1e30` leaves a voxel spacing of `1` below the precision of the coordinates: a flat
/// mesh), or underflow (a spacing of `1e-40` puts every vertex at `0`). The message says
/// which axis and why.
pub fn check_coordinates(dims: [usize; 3], spacing: DVec3, origin: DVec3) -> Result<(), String> {
    let corner = |k: usize| {
        let a = origin[k] - 0.5 * spacing[k];
        let b = origin[k] + (dims[k] as f64 - 0.5) * spacing[k];
        a.abs().max(b.abs())
    };
    let largest = (0..3).map(corner).fold(0.0, f64::max);
    let axis = ["x", "y", "z"];
    for k in 0..3 {
        let s = spacing[k];
        if !(s.is_finite() && s >= 1.0 / COORDINATE_RANGE) {
            return Err(format!(
                "voxel spacing {s:e} along {} is below 1e-30: vertex coordinates would underflow",
                axis[k]
            ));
        }
        if corner(k).is_nan() || corner(k) > COORDINATE_RANGE {
            return Err(format!(
                "coordinates along {} reach {:e} (origin {:e}, spacing {s}): beyond 1e30, a mesh cannot store them",
                axis[k],
                corner(k),
                origin[k]
            ));
        }
        if s < largest * RELATIVE_RESOLUTION {
            return Err(format!(
                "voxel spacing {s} along {} is below the precision of coordinates reaching {largest:e} (origin {:e}, {:e}, {:e}): the vertices would collapse; move the origin nearer to 0",
                axis[k],
                origin.x,
                origin.y,
                origin.z
            ));
        }
    }
    Ok(())
}

/// Re-stores the voxels so that new axis `perm[c]` is old axis `c`, reversed where
/// `flips[c]`. Spacing and origin are left for the caller to set.
fn reorient(voxels: Voxels, perm: [usize; 3], flips: [bool; 3]) -> Voxels {
    // `permuted_axes(inv)` makes new axis a the old axis inv[a].
    let mut inv = [0; 3];
    for c in 0..3 {
        inv[perm[c]] = c;
    }
    fn restore<T: Copy>(a: &Array3<T>, inv: [usize; 3], flips: [bool; 3]) -> Array3<T> {
        let mut view: ArrayView3<T> = a.view();
        for (c, &flip) in flips.iter().enumerate() {
            if flip {
                view.invert_axis(Axis(c));
            }
        }
        let view = view.permuted_axes(inv);
        Array3::from_shape_fn(view.raw_dim().f(), |i| view[i])
    }
    match voxels {
        Voxels::Labels(v) => {
            let labels = restore(v.labels(), inv, flips);
            Voxels::Labels(LabelVolume::new(labels).with_background(v.background()))
        }
        Voxels::Grey(g) => {
            let values = restore(g.values(), inv, flips);
            Voxels::Grey(GreyVolume::new(values).expect("the values were checked for NaN already"))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn labels(dims: [usize; 3]) -> Voxels {
        let volume = LabelVolume::from_fn(dims, |p| (p[0] + 10 * p[1] + 100 * p[2]) as u32);
        Voxels::Labels(volume)
    }

    fn label(v: &Voxels, p: [i64; 3]) -> Option<u32> {
        match v {
            Voxels::Labels(v) => v.label(p),
            Voxels::Grey(_) => None,
        }
    }

    #[test]
    fn scaling_is_kept_as_is() {
        let m = DMat3::from_diagonal(DVec3::new(0.5, 2.0, 3.0));
        let (v, how) = place(labels([2, 3, 4]), m, DVec3::new(1.0, 2.0, 3.0)).unwrap();
        assert_eq!(how, Placement::Exact);
        assert_eq!(v.dims(), [2, 3, 4]);
        assert_eq!(v.spacing(), DVec3::new(0.5, 2.0, 3.0));
        assert_eq!(v.origin(), DVec3::new(1.0, 2.0, 3.0));
        assert_eq!(label(&v, [1, 2, 3]), Some(321));
    }

    #[test]
    fn flips_and_permutations_put_every_voxel_where_the_map_says() {
        // Index i runs along -y (step 2), j along +z (step 3), k along -x (step 0.5).
        let m = DMat3::from_cols(
            DVec3::new(0.0, -2.0, 0.0),
            DVec3::new(0.0, 0.0, 3.0),
            DVec3::new(-0.5, 0.0, 0.0),
        );
        let t = DVec3::new(10.0, 20.0, 30.0);
        let dims = [2, 3, 4];
        let (v, how) = place(labels(dims), m, t).unwrap();
        assert_eq!(how, Placement::Exact);
        assert_eq!(v.dims(), [4, 2, 3]);
        assert_eq!(v.spacing(), DVec3::new(0.5, 2.0, 3.0));
        let Voxels::Labels(volume) = &v else { unreachable!() };
        for i in 0..2 {
            for j in 0..3 {
                for k in 0..4 {
                    let world = t + m * DVec3::new(i as f64, j as f64, k as f64);
                    // The voxel of the new volume whose centre is `world`.
                    let q = ((world - volume.origin()) / volume.spacing()).round();
                    let q = [q.x as i64, q.y as i64, q.z as i64];
                    assert_eq!(volume.voxel_centre(q), world);
                    assert_eq!(volume.label(q), Some((i + 10 * j + 100 * k) as u32), "{i} {j} {k}");
                }
            }
        }
    }

    #[test]
    fn oblique_maps_drop_the_rotation_and_degenerate_ones_fail() {
        let (c, s) = (0.6, 0.8);
        let m = DMat3::from_cols(DVec3::new(c, s, 0.0), DVec3::new(-s, c, 0.0), DVec3::new(0.0, 0.0, 2.0));
        let (v, how) = place(labels([2, 2, 2]), m, DVec3::ONE).unwrap();
        assert_eq!(how, Placement::RotationDropped);
        assert!((v.spacing() - DVec3::new(1.0, 1.0, 2.0)).length() < 1e-12);
        assert_eq!(v.origin(), DVec3::ONE);
        assert_eq!(label(&v, [1, 0, 0]), Some(1));
        let zero = DMat3::from_cols(DVec3::X, DVec3::ZERO, DVec3::Z);
        assert!(place(labels([1, 1, 1]), zero, DVec3::ZERO).is_err());
        assert!(place(labels([1, 1, 1]), DMat3::IDENTITY, DVec3::NAN).is_err());
        // Two index axes along the same world axis: the grid collapses onto a plane.
        let same = DMat3::from_cols(DVec3::X, DVec3::X * 2.0, DVec3::Z);
        let err = place(labels([1, 1, 1]), same, DVec3::ZERO).unwrap_err().to_string();
        assert!(err.contains("collinear or coplanar"), "{err}");
    }
}
