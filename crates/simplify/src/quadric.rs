//! Quadrics: sums of squared distances to planes and lines, `p^T A p - 2 b.p + c`.

use glam::{DMat3, DVec3};

/// A symmetric quadratic form in the position.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Quadric {
    /// `A` as `[xx, xy, xz, yy, yz, zz]`.
    a: [f64; 6],
    b: DVec3,
    c: f64,
}

impl Quadric {
    /// `w` times the squared distance to the plane through `p` of unit normal `n`.
    pub(crate) fn plane(p: DVec3, n: DVec3, w: f64) -> Quadric {
        let d = -n.dot(p);
        Quadric {
            a: [n.x * n.x, n.x * n.y, n.x * n.z, n.y * n.y, n.y * n.z, n.z * n.z].map(|x| w * x),
            b: -d * w * n,
            c: w * d * d,
        }
    }

    /// `w` times the squared distance to the line through `p` of unit direction `t`.
    pub(crate) fn line(p: DVec3, t: DVec3, w: f64) -> Quadric {
        let a = [1.0 - t.x * t.x, -t.x * t.y, -t.x * t.z, 1.0 - t.y * t.y, -t.y * t.z, 1.0 - t.z * t.z];
        let ap = DVec3::new(
            a[0] * p.x + a[1] * p.y + a[2] * p.z,
            a[1] * p.x + a[3] * p.y + a[4] * p.z,
            a[2] * p.x + a[4] * p.y + a[5] * p.z,
        );
        Quadric { a: a.map(|x| w * x), b: w * ap, c: w * p.dot(ap) }
    }

    /// The form's value at `p` (clamped at 0 against rounding).
    pub(crate) fn eval(&self, p: DVec3) -> f64 {
        let a = &self.a;
        let ap = DVec3::new(
            a[0] * p.x + a[1] * p.y + a[2] * p.z,
            a[1] * p.x + a[3] * p.y + a[4] * p.z,
            a[2] * p.x + a[4] * p.y + a[5] * p.z,
        );
        (p.dot(ap) - 2.0 * self.b.dot(p) + self.c).max(0.0)
    }

    /// The minimizer of the form plus `eps` times the trace over three times
    /// `|p - m|^2` (a pull towards `m` where the form is flat) on the plane `g.p = h`,
    /// or on all space where `g` is zero; `None` if the system is singular.
    pub(crate) fn minimize_on_plane(&self, eps: f64, m: DVec3, g: DVec3, h: f64) -> Option<DVec3> {
        let a = &self.a;
        let e = eps * (a[0] + a[3] + a[5]) / 3.0 + 1e-300;
        let mat = DMat3::from_cols(
            DVec3::new(a[0] + e, a[1], a[2]),
            DVec3::new(a[1], a[3] + e, a[4]),
            DVec3::new(a[2], a[4], a[5] + e),
        );
        // The inverse by cofactors, with the determinant computed once (the same
        // operations as `DMat3::determinant` and `DMat3::inverse`).
        let (c0, c1, c2) =
            (mat.y_axis.cross(mat.z_axis), mat.z_axis.cross(mat.x_axis), mat.x_axis.cross(mat.y_axis));
        let det = mat.z_axis.dot(c2);
        if !det.is_normal() {
            return None;
        }
        let r = DVec3::splat(det.recip());
        let inv = DMat3::from_cols(c0 * r, c1 * r, c2 * r).transpose();
        let p0 = inv * (self.b + e * m);
        let ig = inv * g;
        let d = g.dot(ig);
        let p = if d.is_normal() { p0 - (g.dot(p0) - h) / d * ig } else { p0 };
        p.is_finite().then_some(p)
    }

    pub(crate) fn add(&mut self, o: &Quadric) {
        for k in 0..6 {
            self.a[k] += o.a[k];
        }
        self.b += o.b;
        self.c += o.c;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn distances() {
        let q = Quadric::plane(DVec3::new(0.0, 0.0, 1.0), DVec3::Z, 2.0);
        assert!((q.eval(DVec3::new(5.0, -3.0, 4.0)) - 18.0).abs() < 1e-12);
        let l = Quadric::line(DVec3::new(1.0, 1.0, 0.0), DVec3::Z, 1.0);
        assert!((l.eval(DVec3::new(1.0, 4.0, 7.0)) - 9.0).abs() < 1e-12);
        let mut s = q;
        s.add(&l);
        assert!((s.eval(DVec3::new(1.0, 4.0, 1.0)) - 9.0).abs() < 1e-12);
    }

    #[test]
    fn constrained_minimum() {
        // Two planes z = 1 and y = 2: the minimizers form the line x free; the plane
        // x = 3 picks one point of it.
        let mut q = Quadric::plane(DVec3::new(0.0, 0.0, 1.0), DVec3::Z, 1.0);
        q.add(&Quadric::plane(DVec3::new(0.0, 2.0, 0.0), DVec3::Y, 1.0));
        let p = q.minimize_on_plane(1e-6, DVec3::ZERO, DVec3::X, 3.0).unwrap();
        assert!((p - DVec3::new(3.0, 2.0, 1.0)).length() < 1e-5, "{p}");
        // Without a constraint, the pull picks the point of the line nearest m.
        let p = q.minimize_on_plane(1e-6, DVec3::new(-1.0, 0.0, 0.0), DVec3::ZERO, 0.0).unwrap();
        assert!((p - DVec3::new(-1.0, 2.0, 1.0)).length() < 1e-5, "{p}");
    }
}
