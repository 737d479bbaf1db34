//! The integral invariant (II) estimator: covariance of a ball intersected with a region.

use glam::{DMat3, DVec3};
use rayon::prelude::*;
use voxreg_digisurf::{DigitalSurface, Surfel};

use crate::eigen::{smallest_eigenvector, symmetric_eigen};
use crate::runs::RegionRuns;
use crate::sides::combine_sides;
use crate::{NormalError, NormalEstimator, NormalField};

/// The default radius of the ball and convolution estimators, in physical units: the
/// multigrid rule `r = 3 h^{1/3}`, `h` the largest component of `spacing` (3 voxels at
/// unit spacing, about 10 voxels at `h = 0.156`). With it, the integral invariant
/// estimator's error falls as `O(h^{2/3})` on shapes of unit-order size (ref. \[53\]).
pub fn multigrid_radius(spacing: DVec3) -> f64 {
    3.0 * spacing.max_element().cbrt()
}

/// The integral invariant normal estimator (Lachaud, Coeurjolly and Levallois, ref. \[53\]
/// of the multi-label paper; Pottmann et al. for the continuous invariants).
///
/// For a surfel with centre `x` and a region `X` on one of its sides, the covariance
/// matrix of the ball `B_r(x)` intersected with `X` is, digitally, a sum over the voxel
/// centres `p` of `X` that lie in the ball:
///
/// ```text
/// V_r(x) = sum_{p in B_r(x) ∩ X} (p - x)(p - x)^T  -  m1 m1^T / m0,
/// m0 = #(B_r(x) ∩ X),   m1 = sum_{p in B_r(x) ∩ X} (p - x).
/// ```
///
/// Where `∂X` is smooth, `B_r ∩ X` is nearly a half ball, thinnest across the surface: the
/// normal is the eigenvector of the smallest eigenvalue of `V_r`, oriented here like the
/// trivial normal. With `r = k h^{1/3}` the error is `O(h^{2/3})` as the grid step `h`
/// goes to 0 (multigrid convergence, the paper's sec. 3.3 and ref. \[53\]).
///
/// **Multi-label volumes** (the paper's sec. 3.1). Each region is treated as the shape:
/// a surfel gets one estimate from its inner region and one from its outer region, and
/// their directions are averaged (signs aligned, orientation forgotten), then oriented
/// like the trivial normal. For a binary volume both estimates describe the same surface.
/// Outside the domain, voxels belong to the background; on an *open* border (a volume
/// without background) there is nothing beyond the domain: the ball is cut by the domain
/// border. The tilt that cut gives each side's estimate near the border is mirrored on the
/// other side, so the average cancels it where an interface meets the border at a right
/// angle.
///
/// **Exact moments, `O(r^2)` per surfel.** The moments are exact sums over voxels (no
/// sampling). Ball centres are face centres, so relative to its centre the ball's voxels
/// form one of three fixed stencils (one per surfel axis), precomputed once as chords
/// along x: `(dy, dz, x range)`. Regions are kept as runs along x, recovered from the
/// surface itself (the estimator needs no volume), and each chord is summed run by run in
/// closed form (sums of `1`, `x` and `x^2` over integer ranges). The cost per surfel is one
/// run lookup per chord, about `pi (r/h)^2`, instead of `4/3 pi (r/h)^3` voxel visits.
/// Surfels are processed in parallel.
///
/// # Example
///
/// ```
/// use voxreg_digisurf::{DigitalSurface, LabelVolume};
/// use voxreg_normals::{IntegralInvariant, NormalEstimator};
///
/// // A digital ball of radius 6: II normals point roughly away from its centre.
/// let volume = LabelVolume::from_fn([15, 15, 15], |p| {
///     u32::from(p.iter().map(|&c| (c as f64 - 7.0).powi(2)).sum::<f64>() <= 36.0)
/// });
/// let surface = DigitalSurface::from_volume(&volume)?;
/// let normals = IntegralInvariant { radius: Some(3.0) }.estimate(&surface)?;
/// let s = &surface.surfels()[0];
/// let centre = s.vertices.iter().map(|&v| surface.vertex_position(v)).sum::<glam::DVec3>() / 4.0;
/// let radial = (centre - glam::DVec3::splat(7.0)).normalize();
/// assert!(normals.as_slice()[0].dot(radial) > 0.9);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct IntegralInvariant {
    /// Ball radius in physical units; `None` picks the multigrid rule
    /// [`multigrid_radius`] `= 3 h^{1/3}` (3 at unit spacing). Default: `None`.
    pub radius: Option<f64>,
}

/// The digital moments of a ball intersected with one region, relative to the ball's
/// centre `x`, in physical units: sums over the voxel centres `p` in the intersection.
/// The default is the moments of the empty set (all zero).
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct BallMoments {
    /// Number of voxels, `m0`.
    pub count: f64,
    /// First moment `m1 = sum (p - x)`.
    pub first: DVec3,
    /// Second moment `M2 = sum (p - x)(p - x)^T` (symmetric).
    pub second: DMat3,
}

impl Default for BallMoments {
    fn default() -> Self {
        // Not derived: `DMat3::default()` is the identity.
        BallMoments { count: 0.0, first: DVec3::ZERO, second: DMat3::ZERO }
    }
}

impl BallMoments {
    /// The covariance matrix `M2 - m1 m1^T / m0` (zero for an empty intersection).
    pub fn covariance(&self) -> DMat3 {
        if self.count == 0.0 {
            return DMat3::ZERO;
        }
        let m1 = self.first;
        self.second - DMat3::from_cols(m1 * m1.x, m1 * m1.y, m1 * m1.z) / self.count
    }

    /// The unit eigenvector of the covariance's smallest eigenvalue, oriented along
    /// `hint` (`hint` itself where the covariance cannot tell a direction: an empty or
    /// one-voxel intersection). Where the two smallest eigenvalues tie, the direction of
    /// `hint` within their eigenplane.
    pub fn normal(&self, hint: DVec3) -> DVec3 {
        let cov = self.covariance();
        if let Some(n) = smallest_eigenvector(cov) {
            return if n.dot(hint) < 0.0 { -n } else { n };
        }
        let (values, vectors) = symmetric_eigen(cov);
        let scale = values[2].abs();
        if scale.is_nan() || scale == 0.0 {
            return hint;
        }
        let mut n = vectors[0];
        if values[1] - values[0] <= 1e-9 * scale {
            // A degenerate (tied) eigenplane: keep the hint's component within it.
            if let Some(p) = (hint - hint.dot(vectors[2]) * vectors[2]).try_normalize() {
                n = p;
            }
        }
        if n.dot(hint) < 0.0 {
            -n
        } else {
            n
        }
    }
}

/// The ten moments `[m0, mx, my, mz, xx, yy, zz, xy, xz, yz]` of a set of voxels.
type Sums = [f64; 10];

#[inline]
fn add_sums(acc: &mut Sums, s: &Sums) {
    for (a, b) in acc.iter_mut().zip(s) {
        *a += b;
    }
}

fn to_moments(s: &Sums) -> BallMoments {
    BallMoments {
        count: s[0],
        first: DVec3::new(s[1], s[2], s[3]),
        second: DMat3::from_cols(
            DVec3::new(s[4], s[7], s[8]),
            DVec3::new(s[7], s[5], s[9]),
            DVec3::new(s[8], s[9], s[6]),
        ),
    }
}

/// The chords of the ball around the centre of a surfel of one axis, along x.
#[derive(Clone, Debug)]
struct Stencil {
    chords: Vec<Chord>,
    /// The moments of the whole (digital) ball.
    ball: Sums,
}

/// One chord of a ball stencil: voxels `cell + (jx, dy, dz)` for `jx` in `a..=b`.
#[derive(Copy, Clone, Debug)]
struct Chord {
    dy: i32,
    dz: i32,
    a: i32,
    b: i32,
    /// Physical y and z offsets of the chord's voxel centres from the ball centre.
    uy: f64,
    uz: f64,
    /// The moments of the whole chord.
    full: Sums,
}

impl Chord {
    /// The moments of voxels `jx` in `a..=b` of this chord (offsets from the surfel's
    /// cell, physical x offsets `(jx + hx) sx`), in closed form from the integer sums
    /// of `1`, `j` and `j^2`.
    #[inline]
    fn sums(&self, a: i64, b: i64, hx: f64, sx: f64) -> Sums {
        let n = b - a + 1;
        let sum1 = (a + b) * n / 2; // exact: (a + b) n is even
        let p2 = |m: i64| m * (m + 1) * (2 * m + 1) / 6; // sum of j^2 for j in 1..=m
        let sum2 = p2(b) - p2(a - 1);
        let (n, sum1, sum2) = (n as f64, sum1 as f64, sum2 as f64);
        let s1 = sx * (sum1 + hx * n);
        let s2 = sx * sx * (sum2 + 2.0 * hx * sum1 + hx * hx * n);
        let (uy, uz) = (self.uy, self.uz);
        [n, s1, n * uy, n * uz, s2, n * (uy * uy), n * (uz * uz), s1 * uy, s1 * uz, n * (uy * uz)]
    }
}

/// At most this many chords per stencil (a radius of about 1,100 voxels): beyond, the
/// estimator would run for hours, so such a radius is refused.
const MAX_CHORDS: f64 = 4.0e6;

impl Stencil {
    /// The stencil of surfels perpendicular to `axis`: their centre lies half a voxel
    /// below lattice corner `cell` along `axis`, so voxel `cell + j` is at physical offset
    /// `(j + e_axis / 2) * spacing` from it. A voxel is in the ball iff
    /// `ux^2 + (uy^2 + uz^2) <= r^2`, evaluated in this order.
    fn new(axis: usize, spacing: DVec3, radius: f64) -> Self {
        let half = DVec3::from_array([0, 1, 2].map(|k| if k == axis { 0.5 } else { 0.0 }));
        let r2 = radius * radius;
        let reach = (radius / spacing).ceil().as_ivec3();
        let mut chords = Vec::new();
        let mut ball = [0.0; 10];
        for dz in -reach.z..=reach.z {
            let uz = (dz as f64 + half.z) * spacing.z;
            for dy in -reach.y..=reach.y {
                let uy = (dy as f64 + half.y) * spacing.y;
                let yz = uy * uy + uz * uz;
                if yz > r2 {
                    continue;
                }
                let inside = |jx: i32| {
                    let ux = (jx as f64 + half.x) * spacing.x;
                    ux * ux + yz <= r2
                };
                // The chord is an interval (the test is monotone in |ux|): its ends from a
                // square root, then settled by the exact test.
                let w = (r2 - yz).sqrt() / spacing.x;
                let (mut a, mut b) = ((-w - half.x).ceil() as i32, (w - half.x).floor() as i32);
                while inside(a - 1) {
                    a -= 1;
                }
                while a <= b && !inside(a) {
                    a += 1;
                }
                while inside(b + 1) {
                    b += 1;
                }
                while b >= a && !inside(b) {
                    b -= 1;
                }
                if a > b {
                    continue;
                }
                let mut chord = Chord { dy, dz, a, b, uy, uz, full: [0.0; 10] };
                chord.full = chord.sums(a as i64, b as i64, half.x, spacing.x);
                add_sums(&mut ball, &chord.full);
                chords.push(chord);
            }
        }
        Stencil { chords, ball }
    }
}

/// Everything the per-surfel computation needs, built once per surface.
struct Context {
    runs: RegionRuns,
    stencils: [Stencil; 3],
    spacing: DVec3,
}

impl Context {
    fn new(surface: &DigitalSurface, radius: f64) -> Result<Self, NormalError> {
        let spacing = surface.spacing();
        if !(radius.is_finite() && radius > 0.0) {
            return Err(NormalError::InvalidParameter(format!(
                "integral invariant radius must be finite and positive, got {radius}"
            )));
        }
        let chords = std::f64::consts::PI * (radius / spacing.y + 1.0) * (radius / spacing.z + 1.0);
        if chords > MAX_CHORDS {
            return Err(NormalError::InvalidParameter(format!(
                "integral invariant radius {radius} spans more than 1,000 voxels"
            )));
        }
        Ok(Context {
            runs: RegionRuns::new(surface),
            stencils: [0, 1, 2].map(|axis| Stencil::new(axis, spacing, radius)),
            spacing,
        })
    }

    /// The moments of the ball around `surfel`'s centre intersected with its `[inner,
    /// outer]` regions.
    ///
    /// Only the inner region and the *other* voxels (third regions, and the void beyond
    /// an open border) are summed; the outer region's moments are the ball's minus those.
    /// On a binary volume nothing is *other*, so each chord costs one run lookup and, when
    /// a single run covers it (most chords), one addition of its precomputed moments.
    fn moments(&self, surfel: &Surfel) -> [BallMoments; 2] {
        let axis = surfel.axis as usize;
        let stencil = &self.stencils[axis];
        let hx = if axis == 0 { 0.5 } else { 0.0 };
        let sx = self.spacing.x;
        let [cx, cy, cz] = surfel.cell.map(i64::from);
        let [inner, outer] = surfel.regions.map(|r| r.0);
        let mut sums_inner = [0.0; 10];
        let mut sums_other = [0.0; 10];
        for c in &stencil.chords {
            let (xa, xb) = (cx + c.a as i64, cx + c.b as i64);
            let (y, z) = (cy + c.dy as i64, cz + c.dz as i64);
            if let Some(r) = self.runs.uniform(y, z, xa, xb) {
                if r == inner {
                    add_sums(&mut sums_inner, &c.full);
                } else if r != outer {
                    add_sums(&mut sums_other, &c.full);
                }
                continue;
            }
            self.runs.for_each_run(y, z, xa, xb, |lo, hi, r| {
                let target = if r == inner {
                    &mut sums_inner
                } else if r != outer {
                    &mut sums_other
                } else {
                    return;
                };
                if lo == xa && hi == xb {
                    add_sums(target, &c.full);
                } else {
                    add_sums(target, &c.sums(lo - cx, hi - cx, hx, sx));
                }
            });
        }
        let mut sums_outer = stencil.ball;
        for k in 0..10 {
            sums_outer[k] -= sums_inner[k] + sums_other[k];
        }
        [to_moments(&sums_inner), to_moments(&sums_outer)]
    }

    fn normal(&self, surfel: &Surfel) -> DVec3 {
        let [inner, outer] = self.moments(surfel);
        let t = surfel.normal();
        // Each side's normal, pointing out of that side, then averaged.
        combine_sides(inner.normal(t), outer.normal(-t), t)
    }
}

impl IntegralInvariant {
    /// The radius used on `surface`: [`IntegralInvariant::radius`], or the multigrid rule
    /// for the surface's spacing.
    pub fn radius_for(&self, surface: &DigitalSurface) -> f64 {
        self.radius.unwrap_or_else(|| multigrid_radius(surface.spacing()))
    }

    /// For each surfel, the [`BallMoments`] of the ball around its centre intersected with
    /// its `[inner, outer]` regions (exact sums over voxels, see the type's doc).
    pub fn moments(&self, surface: &DigitalSurface) -> Result<Vec<[BallMoments; 2]>, NormalError> {
        let ctx = Context::new(surface, self.radius_for(surface))?;
        Ok(surface.surfels().par_iter().map(|s| ctx.moments(s)).collect())
    }
}

impl NormalEstimator for IntegralInvariant {
    fn name(&self) -> &'static str {
        "ii"
    }

    fn estimate(&self, surface: &DigitalSurface) -> Result<NormalField, NormalError> {
        let ctx = Context::new(surface, self.radius_for(surface))?;
        Ok(NormalField::new(surface.surfels().par_iter().map(|s| ctx.normal(s)).collect()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use voxreg_digisurf::LabelVolume;

    #[test]
    fn chord_sums_match_direct_sums() {
        for (a, b) in [(-5, 3), (0, 0), (-7, -2), (2, 9)] {
            for hx in [0.0, 0.5] {
                let c = Chord { dy: 0, dz: 0, a: 0, b: 0, uy: 0.7, uz: -1.1, full: [0.0; 10] };
                let s = c.sums(a, b, hx, 1.5);
                let mut direct = [0.0; 10];
                for j in a..=b {
                    let u = DVec3::new((j as f64 + hx) * 1.5, 0.7, -1.1);
                    let v = [
                        1.0,
                        u.x,
                        u.y,
                        u.z,
                        u.x * u.x,
                        u.y * u.y,
                        u.z * u.z,
                        u.x * u.y,
                        u.x * u.z,
                        u.y * u.z,
                    ];
                    add_sums(&mut direct, &v);
                }
                for k in 0..10 {
                    assert!((s[k] - direct[k]).abs() < 1e-12, "{k}: {} vs {}", s[k], direct[k]);
                }
            }
        }
    }

    #[test]
    fn stencils_hold_the_lattice_points_of_the_ball() {
        // Voxel j is at (j + e_axis / 2) * spacing from the centre: count by brute force.
        for (spacing, r) in [(DVec3::ONE, 3.0), (DVec3::new(0.7, 1.3, 0.9), 4.1), (DVec3::splat(0.25), 1.61)]
        {
            for axis in 0..3 {
                let st = Stencil::new(axis, spacing, r);
                let mut expected = Vec::new();
                let reach = 2 + (r / spacing.min_element()) as i32;
                for z in -reach..=reach {
                    for y in -reach..=reach {
                        for x in -reach..=reach {
                            let mut u = DVec3::new(x as f64, y as f64, z as f64);
                            u[axis] += 0.5;
                            if (u * spacing).length_squared() <= r * r {
                                expected.push([x, y, z]);
                            }
                        }
                    }
                }
                let mut got: Vec<[i32; 3]> =
                    st.chords.iter().flat_map(|c| (c.a..=c.b).map(move |x| [x, c.dy, c.dz])).collect();
                got.sort_by_key(|p| [p[2], p[1], p[0]]);
                expected.sort_by_key(|p| [p[2], p[1], p[0]]);
                assert_eq!(got, expected, "axis {axis}, spacing {spacing}, r {r}");
                let ball: f64 = st.chords.iter().map(|c| c.full[0]).sum();
                assert_eq!(ball, st.ball[0]);
            }
        }
    }

    #[test]
    fn empty_moments_are_zero() {
        let m = BallMoments::default();
        assert_eq!((m.count, m.first, m.second), (0.0, DVec3::ZERO, DMat3::ZERO));
        assert_eq!(m.covariance(), DMat3::ZERO);
        assert_eq!(m.normal(DVec3::Y), DVec3::Y);
    }

    #[test]
    fn rejects_bad_radii() {
        let volume = LabelVolume::from_fn([3, 3, 3], |p| u32::from(p == [1, 1, 1]));
        let surface = DigitalSurface::from_volume(&volume).unwrap();
        for r in [0.0, -1.0, f64::NAN, f64::INFINITY, 1e5] {
            assert!(IntegralInvariant { radius: Some(r) }.estimate(&surface).is_err(), "{r}");
        }
    }

    #[test]
    fn a_single_voxel_keeps_trivial_normals() {
        // Each side's intersection is tiny and symmetric: no direction is preferred but
        // the trivial one, which the estimator must return exactly.
        let volume = LabelVolume::from_fn([3, 3, 3], |p| u32::from(p == [1, 1, 1]));
        let surface = DigitalSurface::from_volume(&volume).unwrap();
        let normals = IntegralInvariant { radius: Some(0.6) }.estimate(&surface).unwrap();
        for (s, n) in surface.surfels().iter().zip(normals.as_slice()) {
            assert_eq!(*n, s.normal());
        }
    }
}
