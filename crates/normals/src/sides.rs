//! One normal per surfel from the estimates of its two sides (the paper's sec. 3.1).

use glam::DVec3;

/// Averages the directions of `a` and `b` (the estimates of a surfel's two regions, each
/// treated as the shape), forgetting their orientations, and orients the result like
/// `trivial`.
///
/// Each estimate's sign is aligned with the trivial normal before the two are summed and
/// normalized. Aligning them with `trivial` rather than with each other matters where the
/// two sides disagree by more than 90 degrees, as they may at a junction: there each side
/// reads the interface plus its own other boundary, and only the trivial normal says which
/// part is the interface. When the sum vanishes, `a` is kept.
///
/// The exception: two estimates nearly opposite once aligned (more than about 154 degrees
/// apart, [`OPPOSED`]) are nearly the *same* direction, both nearly perpendicular to the
/// trivial normal, which then cannot tell their relative sign (aligning them with it
/// would cancel them into noise). They are summed with `b` flipped. This happens where a
/// surfel is one step of a staircase whose true normal is perpendicular to it (the top of
/// a torus's tube; see docs/design/two-sided-estimates.md).
pub(crate) fn combine_sides(a: DVec3, b: DVec3, trivial: DVec3) -> DVec3 {
    let align = |v: DVec3| if v.dot(trivial) < 0.0 { -v } else { v };
    let (a, mut b) = (align(a), align(b));
    if a.dot(b) < OPPOSED * a.length() * b.length() {
        b = -b;
    }
    align((a + b).try_normalize().unwrap_or(a))
}

/// The cosine below which two aligned estimates count as one direction of ambiguous sign.
const OPPOSED: f64 = -0.9;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn averages_directions_and_orients_like_the_trivial_normal() {
        let n = combine_sides(
            DVec3::new(1.0, 0.1, 0.0).normalize(),
            DVec3::new(-1.0, 0.1, 0.0).normalize(),
            -DVec3::X,
        );
        assert!((n - -DVec3::X).length() < 1e-15, "{n}");
        assert_eq!(combine_sides(DVec3::Z, DVec3::Z, DVec3::Z), DVec3::Z);
        // Two sides more than 90 degrees apart, each near its own trivial orientation.
        let n = combine_sides(DVec3::new(1.0, 0.0, 2.0), DVec3::new(-1.0, 0.0, 2.0), DVec3::X);
        assert!((n - DVec3::X).length() < 1e-15, "{n}");
    }

    #[test]
    fn estimates_perpendicular_to_the_trivial_normal_do_not_cancel() {
        // Both sides read +z (to rounding), on a surfel whose trivial normal is x: aligned
        // with x they would point opposite ways and cancel.
        let a = DVec3::new(1e-4, 0.0, 1.0).normalize();
        let b = DVec3::new(1e-4, 0.0, -1.0).normalize();
        let n = combine_sides(a, b, DVec3::X);
        assert!(n.z.abs() > 1.0 - 1e-6 && n.x >= 0.0, "{n}");
    }
}
