//! The analytic shapes that metrics and Hermite data are computed against.

use glam::DVec3;

/// The point of the zero set of `value` nearest to `p` by Newton steps along `gradient`
/// (at most 30, until a step is under `1e-13`): good for points near the surface.
pub fn newton_project(value: impl Fn(DVec3) -> f64, gradient: impl Fn(DVec3) -> DVec3, p: DVec3) -> DVec3 {
    let mut q = p;
    for _ in 0..30 {
        let g = gradient(q);
        let g2 = g.length_squared();
        if g2 == 0.0 {
            break;
        }
        let step = value(q) / g2 * g;
        q -= step;
        if step.length() < 1e-13 {
            break;
        }
    }
    q
}

/// An implicit shape: inside where [`Implicit::value`] `<= 0`, with its outward
/// gradient and the nearest point of its surface.
///
/// This is the least the metrics and the implicit-function baselines need; the dev-only
/// test kit implements it for its shapes, so this crate does not depend on the test kit.
pub trait Implicit: Sync {
    /// The implicit function (a signed distance where possible).
    fn value(&self, p: DVec3) -> f64;

    /// Its gradient, pointing outward.
    fn gradient(&self, p: DVec3) -> DVec3;

    /// The point of the surface nearest to `p`. Default: Newton steps along the gradient
    /// (good for points near the surface); shapes with an exact projection override it.
    fn project(&self, p: DVec3) -> DVec3 {
        newton_project(|q| self.value(q), |q| self.gradient(q), p)
    }

    /// Distance from `p` to the surface, negative inside.
    fn signed_distance(&self, p: DVec3) -> f64 {
        let d = (p - self.project(p)).length();
        if self.value(p) <= 0.0 {
            -d
        } else {
            d
        }
    }

    /// The outward unit normal at the surface point nearest to `p`.
    fn normal_near(&self, p: DVec3) -> DVec3 {
        self.gradient(self.project(p)).normalize_or_zero()
    }
}

/// A ball, the simplest [`Implicit`] (used in examples and tests).
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Ball {
    /// Centre.
    pub centre: DVec3,
    /// Radius.
    pub radius: f64,
}

impl Implicit for Ball {
    fn value(&self, p: DVec3) -> f64 {
        (p - self.centre).length() - self.radius
    }
    fn gradient(&self, p: DVec3) -> DVec3 {
        (p - self.centre).normalize_or(DVec3::Z)
    }
    fn project(&self, p: DVec3) -> DVec3 {
        self.centre + (p - self.centre).normalize_or(DVec3::Z) * self.radius
    }
}
