//! Dev-only test kit: analytic shapes with known surfaces and normals, their Gauss
//! digitizations, error metrics, deterministic random generators ([`Lcg`], [`Xorshift`]) and small
//! input files written byte by byte. Shared by tests, benches and xtask.
//!
//! A shape is an implicit function `f` (inside where `f <= 0`). [`digitize`] makes the
//! volume whose voxel `p` (integer coordinates) is inside iff `f(h p) <= 0`, with spacing
//! `h` and an origin such that voxel centres sit at `h p`: physical coordinates of the
//! surface are then directly comparable with the shape's. Every shape here is also a
//! `voxreg_baselines::Implicit`, so it goes straight into the baselines' metrics, as do
//! `&dyn Shape` and `Box<dyn Shape>`.
//!
//! # Example
//!
//! ```
//! use voxreg_digisurf::DigitalSurface;
//! use voxreg_testkit::{digitize, true_normals, Sphere};
//!
//! let sphere = Sphere { radius: 5.0 };
//! let volume = digitize(&sphere, 1.0);
//! let surface = DigitalSurface::from_volume(&volume).unwrap();
//! let normals = true_normals(&surface, &sphere);
//! assert_eq!(normals.len(), surface.num_surfels());
//! ```

mod files;
mod labelled;
mod rng;

pub use files::{
    dir_names, npy_bytes, odd_names_seg_nrrd, two_model_vox, validate_gltf, vox_bytes, vox_scene,
    BUNDLED_VOX_MODELS, ODD_NAMES,
};

pub use labelled::{
    digitize_labels, label_fidelity, vertex_labels, JunctionKind, LabelFidelity, LabelShape, QuarteredBall,
    Solid, SplitBall, Stat, TouchingBalls,
};
pub use rng::{Lcg, Xorshift};

use glam::DVec3;
use rayon::prelude::*;
use voxreg_baselines::Implicit;
use voxreg_digisurf::{DigitalSurface, LabelVolume};

/// An implicit shape: inside where [`Shape::value`] `<= 0`.
pub trait Shape: Sync {
    /// The implicit function.
    fn value(&self, p: DVec3) -> f64;
    /// Its gradient (pointing outward).
    fn gradient(&self, p: DVec3) -> DVec3;
    /// A box containing the shape: `(min, max)`.
    fn bounds(&self) -> (DVec3, DVec3);
    /// A short name.
    fn name(&self) -> &'static str;

    /// The point of the surface nearest to `p` (Newton steps along the gradient, for points
    /// near the surface).
    fn project(&self, p: DVec3) -> DVec3 {
        voxreg_baselines::newton_project(|q| self.value(q), |q| self.gradient(q), p)
    }

    /// The outward unit normal at the surface point nearest to `p`.
    fn normal_near(&self, p: DVec3) -> DVec3 {
        self.gradient(self.project(p)).normalize_or_zero()
    }

    /// Distance from `p` to the surface (to its projection), signed: negative inside.
    fn signed_distance(&self, p: DVec3) -> f64 {
        let d = (p - self.project(p)).length();
        if self.value(p) <= 0.0 {
            -d
        } else {
            d
        }
    }
}

/// A sphere of given radius centred at the origin.
#[derive(Copy, Clone, Debug)]
pub struct Sphere {
    /// Radius.
    pub radius: f64,
}

impl Shape for Sphere {
    fn value(&self, p: DVec3) -> f64 {
        p.length() - self.radius
    }
    fn gradient(&self, p: DVec3) -> DVec3 {
        p.normalize_or_zero()
    }
    fn bounds(&self) -> (DVec3, DVec3) {
        (DVec3::splat(-self.radius), DVec3::splat(self.radius))
    }
    fn name(&self) -> &'static str {
        "sphere"
    }
    fn project(&self, p: DVec3) -> DVec3 {
        p.normalize_or_zero() * self.radius
    }
}

/// A torus around the z axis, centred at the origin.
#[derive(Copy, Clone, Debug)]
pub struct Torus {
    /// Distance from the centre to the tube's centre line.
    pub major: f64,
    /// Tube radius.
    pub minor: f64,
}

impl Torus {
    fn tube_centre(&self, p: DVec3) -> DVec3 {
        let xy = DVec3::new(p.x, p.y, 0.0).normalize_or(DVec3::X);
        xy * self.major
    }
}

impl Shape for Torus {
    fn value(&self, p: DVec3) -> f64 {
        (p - self.tube_centre(p)).length() - self.minor
    }
    fn gradient(&self, p: DVec3) -> DVec3 {
        (p - self.tube_centre(p)).normalize_or_zero()
    }
    fn bounds(&self) -> (DVec3, DVec3) {
        let e = self.major + self.minor;
        (DVec3::new(-e, -e, -self.minor), DVec3::new(e, e, self.minor))
    }
    fn name(&self) -> &'static str {
        "torus"
    }
    fn project(&self, p: DVec3) -> DVec3 {
        let c = self.tube_centre(p);
        c + (p - c).normalize_or(DVec3::Z) * self.minor
    }
}

/// DGtal's "goursat" surface: `-(8 - 0.03 (x^4 + y^4 + z^4) + 2 (x^2 + y^2 + z^2)) <= 0`,
/// a rounded cube with dimples. It reaches `|x| = 8.39` on the axes but `9.66` off them
/// (at `|y| = |z| = 1/sqrt(0.03)`), so its bounds are `[-9.7, 9.7]^3`.
#[derive(Copy, Clone, Debug, Default)]
pub struct Goursat;

impl Shape for Goursat {
    fn value(&self, p: DVec3) -> f64 {
        let q = p * p;
        -(8.0 - 0.03 * (q * q).element_sum() + 2.0 * q.element_sum())
    }
    fn gradient(&self, p: DVec3) -> DVec3 {
        0.12 * p * p * p - 4.0 * p
    }
    fn bounds(&self) -> (DVec3, DVec3) {
        (DVec3::splat(-9.7), DVec3::splat(9.7))
    }
    fn name(&self) -> &'static str {
        "goursat"
    }
}

/// A box `[-half, half]` (sharp edges, for feature-preserving estimators).
#[derive(Copy, Clone, Debug)]
pub struct Cuboid {
    /// Half extents.
    pub half: DVec3,
}

impl Shape for Cuboid {
    fn value(&self, p: DVec3) -> f64 {
        let d = p.abs() - self.half;
        d.max(DVec3::ZERO).length() + d.max_element().min(0.0)
    }
    fn gradient(&self, p: DVec3) -> DVec3 {
        let d = p.abs() - self.half;
        let k = if d.x >= d.y && d.x >= d.z {
            0
        } else if d.y >= d.z {
            1
        } else {
            2
        };
        let mut g = DVec3::ZERO;
        g[k] = p[k].signum();
        g
    }
    fn bounds(&self) -> (DVec3, DVec3) {
        (-self.half, self.half)
    }
    fn name(&self) -> &'static str {
        "cuboid"
    }
    fn project(&self, p: DVec3) -> DVec3 {
        let g = Shape::gradient(self, p);
        let k = (0..3).find(|&k| g[k] != 0.0).unwrap_or(0);
        let mut q = p.clamp(-self.half, self.half);
        q[k] = self.half[k] * p[k].signum();
        q
    }
}

/// Implements the baselines' [`Implicit`] by [`Shape`]'s methods, for shapes and (`deref`)
/// for pointers to shapes.
macro_rules! implicit_from_shape {
    ($($t:ty),*) => {$(
        impl Implicit for $t {
            fn value(&self, p: DVec3) -> f64 {
                Shape::value(self, p)
            }
            fn gradient(&self, p: DVec3) -> DVec3 {
                Shape::gradient(self, p)
            }
            fn project(&self, p: DVec3) -> DVec3 {
                Shape::project(self, p)
            }
        }
    )*};
    (deref $($t:ty),*) => {$(
        impl Implicit for $t {
            fn value(&self, p: DVec3) -> f64 {
                (**self).value(p)
            }
            fn gradient(&self, p: DVec3) -> DVec3 {
                (**self).gradient(p)
            }
            fn project(&self, p: DVec3) -> DVec3 {
                (**self).project(p)
            }
        }
    )*};
}

// A blanket `impl<S: Shape> Implicit for S` is not allowed here (the trait is foreign): each
// shape, and the trait objects, one by one.
implicit_from_shape!(Sphere, Torus, Goursat, Cuboid);
implicit_from_shape!(deref &dyn Shape, Box<dyn Shape>);

/// Gauss digitization of `shape` at grid step `h`: voxel `p` is inside (label 1) iff
/// `f(h p) <= 0`; background 0 with a margin of one voxel; spacing `h`, voxel centres at `h p`.
pub fn digitize(shape: &dyn Shape, h: f64) -> LabelVolume {
    sample_grid(shape.bounds(), DVec3::splat(h), |p| u32::from(shape.value(p) <= 0.0))
}

/// The volume of the labels `label(spacing * p)` at the integer points `p` covering
/// `bounds` with a margin of one voxel (background 0); spacing `spacing`, voxel centres at
/// `spacing * p`.
pub(crate) fn sample_grid(
    bounds: (DVec3, DVec3),
    spacing: DVec3,
    label: impl Fn(DVec3) -> u32 + Sync,
) -> LabelVolume {
    let (lo, hi) = bounds;
    let pmin = (lo / spacing).floor() - 1.0;
    let pmax = (hi / spacing).ceil() + 1.0;
    let dims = (pmax - pmin + 1.0).as_uvec3();
    let dims = [dims.x as usize, dims.y as usize, dims.z as usize];
    let labels: Vec<u32> = (0..dims[0] * dims[1] * dims[2])
        .into_par_iter()
        .map(|i| {
            let (x, y, z) = (i % dims[0], (i / dims[0]) % dims[1], i / (dims[0] * dims[1]));
            label((pmin + DVec3::new(x as f64, y as f64, z as f64)) * spacing)
        })
        .collect();
    LabelVolume::from_x_fastest(dims, labels)
        .expect("dimensions match")
        .with_spacing(spacing)
        .expect("positive spacing")
        .with_origin(pmin * spacing)
        .expect("finite origin")
}

/// Centre of surfel `s` in physical coordinates.
pub fn surfel_centre(surface: &DigitalSurface, s: usize) -> DVec3 {
    let sf = &surface.surfels()[s];
    sf.vertices.iter().map(|&v| surface.vertex_position(v)).sum::<DVec3>() / 4.0
}

/// The true outward normal of `shape` near each surfel centre.
pub fn true_normals(surface: &DigitalSurface, shape: &dyn Shape) -> Vec<DVec3> {
    (0..surface.num_surfels()).into_par_iter().map(|s| shape.normal_near(surfel_centre(surface, s))).collect()
}

/// Angles in degrees between corresponding directions, orientation ignored.
pub fn angles_deg(a: &[DVec3], b: &[DVec3]) -> Vec<f64> {
    a.iter()
        .zip(b)
        .map(|(x, y)| x.normalize_or_zero().dot(y.normalize_or_zero()).abs().min(1.0).acos().to_degrees())
        .collect()
}

/// Mean and maximum of `values`.
pub fn mean_max(values: &[f64]) -> (f64, f64) {
    let mean = values.iter().sum::<f64>() / values.len().max(1) as f64;
    (mean, values.iter().copied().fold(0.0, f64::max))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One of each shape.
    fn shapes() -> Vec<Box<dyn Shape>> {
        vec![
            Box::new(Sphere { radius: 3.0 }),
            Box::new(Torus { major: 6.0, minor: 2.0 }),
            Box::new(Goursat),
            Box::new(Cuboid { half: DVec3::new(1.0, 2.0, 3.0) }),
        ]
    }

    #[test]
    fn projections_land_on_the_surfaces() {
        let shapes = shapes();
        for s in &shapes {
            for p in [DVec3::new(1.0, 2.0, 3.5), DVec3::new(-4.0, 5.5, 1.0), DVec3::new(7.0, 0.3, -0.2)] {
                let q = s.project(p);
                assert!(s.value(q).abs() < 1e-9, "{}: f({q}) = {}", s.name(), s.value(q));
            }
        }
    }

    #[test]
    fn shapes_and_pointers_to_them_are_implicit() {
        let sphere = Sphere { radius: 3.0 };
        let dyn_sphere: &dyn Shape = &sphere;
        let boxed: Box<dyn Shape> = Box::new(Torus { major: 6.0, minor: 2.0 });
        let cases: [(&dyn Implicit, &dyn Shape); 3] =
            [(&sphere, &sphere), (&dyn_sphere, &sphere), (&boxed, boxed.as_ref())];
        for (implicit, shape) in cases {
            for p in [DVec3::new(1.0, 2.0, 3.5), DVec3::new(-4.0, 5.5, 1.0)] {
                assert_eq!(implicit.value(p), shape.value(p));
                assert_eq!(implicit.gradient(p), shape.gradient(p));
                assert_eq!(implicit.project(p), shape.project(p));
                assert_eq!(implicit.signed_distance(p), shape.signed_distance(p));
                assert_eq!(implicit.normal_near(p), shape.normal_near(p));
            }
        }
    }

    #[test]
    fn digitization_embeds_voxel_centres_at_h_p() {
        let v = digitize(&Sphere { radius: 2.0 }, 0.5);
        let c = v.voxel_centre([0, 0, 0]);
        assert!(((c / 0.5).round() - c / 0.5).length() < 1e-12);
        let inside = v.labels().iter().filter(|&&l| l == 1).count();
        assert!(inside > 100 && inside < 400, "{inside}"); // 4/3 pi 4^3 = 268
    }

    #[test]
    fn bounds_contain_the_shapes() {
        // A shape sticking out of its bounds would be cut flat by the digitization's box.
        let shapes = shapes();
        for s in &shapes {
            let v = digitize(s.as_ref(), 0.25);
            let [nx, ny, nz] = v.dims();
            for ((x, y, z), &l) in v.labels().indexed_iter() {
                let border = x == 0 || y == 0 || z == 0 || x + 1 == nx || y + 1 == ny || z + 1 == nz;
                assert!(!(border && l == 1), "{}: voxel {x} {y} {z} inside on the border", s.name());
            }
        }
    }
}
