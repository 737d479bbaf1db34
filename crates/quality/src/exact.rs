//! Exact intersection tests of points, segments and triangles, on Shewchuk's adaptive
//! orientation predicates (the `robust` crate): every sign they give is the sign of the
//! exact determinant of the `f64` inputs, so touching, coplanar and degenerate
//! configurations are decided exactly, never within a tolerance.
//!
//! A simplex is given by its distinct points: one (a point), two (a segment) or three (a
//! triangle, possibly with collinear points, which [`reduce`] turns into its segment).

use glam::DVec3;
use robust::{orient2d, orient3d, Coord, Coord3D};

/// The sign (-1, 0 or 1) of the orientation of `d` against the plane `a b c`.
fn o3(a: DVec3, b: DVec3, c: DVec3, d: DVec3) -> i8 {
    let k = |p: DVec3| Coord3D { x: p.x, y: p.y, z: p.z };
    sign(orient3d(k(a), k(b), k(c), k(d)))
}

/// The sign of the orientation of `a b c` projected along axis `k` (dropped).
fn o2(k: usize, a: DVec3, b: DVec3, c: DVec3) -> i8 {
    let (i, j) = ((k + 1) % 3, (k + 2) % 3);
    let p = |v: DVec3| Coord { x: v[i], y: v[j] };
    sign(orient2d(p(a), p(b), p(c)))
}

fn sign(x: f64) -> i8 {
    if x > 0.0 {
        1
    } else if x < 0.0 {
        -1
    } else {
        0
    }
}

/// Whether three points are collinear (exactly: every axis projection is).
pub(crate) fn collinear(a: DVec3, b: DVec3, c: DVec3) -> bool {
    (0..3).all(|k| o2(k, a, b, c) == 0)
}

/// An axis along which the triangle `a b c` (not collinear) projects onto a triangle.
fn injective_axis(a: DVec3, b: DVec3, c: DVec3) -> usize {
    (0..3).find(|&k| o2(k, a, b, c) != 0).unwrap_or(2)
}

/// An axis along which `a` and `b` (distinct) differ.
fn varying_axis(a: DVec3, b: DVec3) -> usize {
    (0..3).find(|&k| a[k] != b[k]).unwrap_or(0)
}

/// The simplex of the given points: duplicates removed, three collinear points replaced by
/// the two outermost. At most three points.
pub(crate) fn reduce(points: &[DVec3]) -> Vec<DVec3> {
    let mut out: Vec<DVec3> = Vec::with_capacity(3);
    for &p in points {
        if !out.contains(&p) {
            out.push(p);
        }
    }
    if out.len() == 3 && collinear(out[0], out[1], out[2]) {
        let k = (0..3).find(|&k| out[0][k] != out[1][k] || out[0][k] != out[2][k]).unwrap_or(0);
        out.sort_by(|a, b| a[k].total_cmp(&b[k]));
        out.remove(1);
    }
    out
}

/// Whether `x` lies on the closed segment `a b` (`a != b`).
fn on_segment(a: DVec3, b: DVec3, x: DVec3) -> bool {
    collinear(a, b, x) && {
        let k = varying_axis(a, b);
        a[k].min(b[k]) <= x[k] && x[k] <= a[k].max(b[k])
    }
}

/// Whether `x` lies in the closed triangle `t` (not collinear).
fn in_triangle(t: [DVec3; 3], x: DVec3) -> bool {
    if o3(t[0], t[1], t[2], x) != 0 {
        return false;
    }
    in_triangle_2d(injective_axis(t[0], t[1], t[2]), t, x)
}

/// [`in_triangle`] for a point known to be in the triangle's plane, projected along `k`.
fn in_triangle_2d(k: usize, t: [DVec3; 3], x: DVec3) -> bool {
    let s = o2(k, t[0], t[1], t[2]);
    (0..3).all(|i| o2(k, t[i], t[(i + 1) % 3], x) * s >= 0)
}

/// Whether the closed segments `a b` and `c d` meet, all four points in one plane (or
/// line) onto which the projection along `k` is one to one.
fn segments_meet_2d(k: usize, a: DVec3, b: DVec3, c: DVec3, d: DVec3) -> bool {
    let on = |p: DVec3, q: DVec3, x: DVec3| {
        let (i, j) = ((k + 1) % 3, (k + 2) % 3);
        p[i].min(q[i]) <= x[i] && x[i] <= p[i].max(q[i]) && p[j].min(q[j]) <= x[j] && x[j] <= p[j].max(q[j])
    };
    let (d1, d2) = (o2(k, c, d, a), o2(k, c, d, b));
    let (d3, d4) = (o2(k, a, b, c), o2(k, a, b, d));
    if d1 * d2 < 0 && d3 * d4 < 0 {
        return true;
    }
    (d1 == 0 && on(c, d, a))
        || (d2 == 0 && on(c, d, b))
        || (d3 == 0 && on(a, b, c))
        || (d4 == 0 && on(a, b, d))
}

/// Whether the closed segments `a b` and `c d` (each of distinct ends) meet.
fn segments_meet(a: DVec3, b: DVec3, c: DVec3, d: DVec3) -> bool {
    if o3(a, b, c, d) != 0 {
        return false;
    }
    // Coplanar: project along an axis one to one on their plane (or line).
    let k = [(a, b, c), (a, b, d), (a, c, d), (b, c, d)]
        .into_iter()
        .find(|&(p, q, r)| !collinear(p, q, r))
        .map(|(p, q, r)| injective_axis(p, q, r))
        .unwrap_or_else(|| {
            // All on one line: drop an axis other than one along which it varies.
            let (p, q) = if a != b { (a, b) } else { (c, d) };
            (varying_axis(p, q) + 1) % 3
        });
    segments_meet_2d(k, a, b, c, d)
}

/// Whether the closed segment `a b` meets the closed triangle `t` (not collinear).
fn segment_meets_triangle(t: [DVec3; 3], a: DVec3, b: DVec3) -> bool {
    let (da, db) = (o3(t[0], t[1], t[2], a), o3(t[0], t[1], t[2], b));
    if da * db > 0 {
        return false;
    }
    match (da, db) {
        (0, 0) => {
            let k = injective_axis(t[0], t[1], t[2]);
            in_triangle_2d(k, t, a)
                || in_triangle_2d(k, t, b)
                || (0..3).any(|i| segments_meet_2d(k, t[i], t[(i + 1) % 3], a, b))
        }
        (0, _) => in_triangle(t, a),
        (_, 0) => in_triangle(t, b),
        _ => {
            // One crossing point of the plane: inside iff the segment's line passes no
            // edge on the wrong side.
            let s: [i8; 3] = std::array::from_fn(|i| o3(a, b, t[i], t[(i + 1) % 3]));
            s.iter().all(|&x| x >= 0) || s.iter().all(|&x| x <= 0)
        }
    }
}

/// Whether two closed simplices meet (each given by [`reduce`]d points).
pub(crate) fn simplices_meet(s: &[DVec3], t: &[DVec3]) -> bool {
    let (s, t) = if s.len() >= t.len() { (s, t) } else { (t, s) };
    match (s.len(), t.len()) {
        (3, 3) => {
            let (a, b) = ([s[0], s[1], s[2]], [t[0], t[1], t[2]]);
            (0..3).any(|i| segment_meets_triangle(b, a[i], a[(i + 1) % 3]))
                || (0..3).any(|i| segment_meets_triangle(a, b[i], b[(i + 1) % 3]))
        }
        (3, 2) => segment_meets_triangle([s[0], s[1], s[2]], t[0], t[1]),
        (3, 1) => in_triangle([s[0], s[1], s[2]], t[0]),
        (2, 2) => segments_meet(s[0], s[1], t[0], t[1]),
        (2, 1) => on_segment(s[0], s[1], t[0]),
        (1, 1) => s[0] == t[0],
        _ => false,
    }
}

/// Whether `conv(others ∪ {p})` and `conv(t_others ∪ {p})` meet anywhere but at `p`
/// (`p` in neither list, the lists of distinct points).
///
/// Every point of the first hull but `p` lies on a segment from `p` to a point of
/// `conv(others)`, and the same for the second: two such segments along one ray from `p`
/// overlap past `p` exactly when the far end of the shorter lies in the other hull. So
/// the hulls meet past `p` iff `conv(others)` meets the second hull, or `conv(t_others)`
/// the first, anywhere but at `p`.
fn meet_past(p: DVec3, others: &[DVec3], t_others: &[DVec3]) -> bool {
    far_side_meets(p, others, t_others) || far_side_meets(p, t_others, others)
}

/// Whether `conv(far)` meets `conv(t_others ∪ {p})` anywhere but at `p`.
fn far_side_meets(p: DVec3, far: &[DVec3], t_others: &[DVec3]) -> bool {
    let contains_p = match far {
        [] => return false,
        [a] => *a == p,
        [a, b] => on_segment(*a, *b, p),
        _ => in_triangle([far[0], far[1], far[2]], p),
    };
    if !contains_p {
        let mut t = t_others.to_vec();
        t.push(p);
        return simplices_meet(&reduce(far), &reduce(&t));
    }
    // `p` inside the segment `a b` (the only case the callers make): its two halves.
    far.iter().any(|&a| meet_past(p, &[a], t_others))
}

/// Whether two triangles of different faces meet anywhere outside the segments between
/// the positions they share (those segments are where neighbouring faces are meant to
/// touch). Each triangle is given by the ids of its three corners (ids equal exactly when
/// the positions are) and the positions.
///
/// - No shared position: whether the closed triangles meet.
/// - One, `p`: whether they meet anywhere but at `p` (see `meet_past`).
/// - Two, `p q`: whether they meet off the segment `p q`: they overlap in their common
///   plane on the same side of `p q`, or, both flat along the line `p q`, both reach past
///   the same end.
/// - Three: the same triangle, reported unless it is flat (then it is the segments).
pub fn triangles_meet_off_shared(s: [(u32, DVec3); 3], t: [(u32, DVec3); 3]) -> bool {
    let distinct = |x: [(u32, DVec3); 3]| {
        let mut out: Vec<(u32, DVec3)> = Vec::with_capacity(3);
        for v in x {
            if !out.iter().any(|w| w.0 == v.0) {
                out.push(v);
            }
        }
        out
    };
    let (s, t) = (distinct(s), distinct(t));
    let shared: Vec<DVec3> = s.iter().filter(|v| t.iter().any(|w| w.0 == v.0)).map(|v| v.1).collect();
    let only = |x: &[(u32, DVec3)]| -> Vec<DVec3> {
        x.iter().filter(|v| !shared.contains(&v.1)).map(|v| v.1).collect()
    };
    let (so, to) = (only(&s), only(&t));
    match shared.len() {
        0 => {
            let pts = |x: &[(u32, DVec3)]| reduce(&x.iter().map(|v| v.1).collect::<Vec<_>>());
            simplices_meet(&pts(&s), &pts(&t))
        }
        1 => meet_past(shared[0], &so, &to),
        2 => {
            let (p, q) = (shared[0], shared[1]);
            let (Some(&a), Some(&b)) = (so.first(), to.first()) else { return false };
            if o3(p, q, a, b) != 0 {
                return false;
            }
            match (collinear(p, q, a), collinear(p, q, b)) {
                (false, false) => {
                    let k = injective_axis(p, q, a);
                    o2(k, p, q, a) == o2(k, p, q, b)
                }
                (true, true) => {
                    let k = varying_axis(p, q);
                    let dir = sign(q[k] - p[k]);
                    let past_q = |x: DVec3| sign(x[k] - q[k]) == dir;
                    let past_p = |x: DVec3| sign(x[k] - p[k]) == -dir;
                    (past_q(a) && past_q(b)) || (past_p(a) && past_p(b))
                }
                _ => false,
            }
        }
        _ => !collinear(shared[0], shared[1], shared[2]),
    }
}

/// Whether two triangles of faces sharing the corners `shared` (ids) meet anywhere outside
/// the segments between the corners they share, each triangle first fanned around every
/// shared corner of the other face that lies in it (a folded face can hold its
/// neighbour's corner inside a triangle that does not have it as a corner): the pieces
/// are then tested with [`triangles_meet_off_shared`].
pub(crate) fn pieces_meet(s: [(u32, DVec3); 3], t: [(u32, DVec3); 3], shared: &[u32]) -> bool {
    pieces_meet_fanned(s, t, shared, &[])
}

/// [`pieces_meet`], never fanning again around a corner in `fanned`: on degenerate faces
/// (corners collinear or coincident) a fan around one corner can leave another inside a
/// piece and the fan around that one the first, without end. Each fan adds a distinct
/// shared corner, so the depth is at most the number of shared corners.
fn pieces_meet_fanned(s: [(u32, DVec3); 3], t: [(u32, DVec3); 3], shared: &[u32], fanned: &[u32]) -> bool {
    for (x, y) in [(s, t), (t, s)] {
        let inside = x.iter().find(|v| {
            shared.contains(&v.0) && !fanned.contains(&v.0) && !y.iter().any(|w| w.0 == v.0) && {
                let hull = reduce(&y.map(|w| w.1));
                simplices_meet(&hull, &[v.1])
            }
        });
        if let Some(&p) = inside {
            let fanned: Vec<u32> = fanned.iter().copied().chain([p.0]).collect();
            return (0..3).any(|i| pieces_meet_fanned(x, [p, y[i], y[(i + 1) % 3]], shared, &fanned));
        }
    }
    triangles_meet_off_shared(s, t)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn v(a: [f64; 3]) -> DVec3 {
        DVec3::from_array(a)
    }

    #[test]
    fn touching_and_coplanar_cases_are_exact() {
        let t = [v([0., 0., 0.]), v([1., 0., 0.]), v([0., 1., 0.])];
        // A segment touching the hypotenuse at its midpoint from above.
        assert!(segment_meets_triangle(t, v([0.5, 0.5, 0.]), v([0.5, 0.5, 1.])));
        // Just past it.
        assert!(!segment_meets_triangle(t, v([0.5, 0.5 + 1e-16, 0.]), v([0.5, 0.5 + 1e-16, 1.])));
        // Coplanar segments crossing, and collinear ones overlapping or only touching.
        assert!(segments_meet(v([0., 0., 0.]), v([1., 1., 0.]), v([0., 1., 0.]), v([1., 0., 0.])));
        assert!(segments_meet(v([0., 0., 0.]), v([2., 2., 2.]), v([1., 1., 1.]), v([3., 3., 3.])));
        assert!(segments_meet(v([0., 0., 0.]), v([1., 1., 1.]), v([1., 1., 1.]), v([3., 3., 3.])));
        assert!(!segments_meet(v([0., 0., 0.]), v([1., 1., 1.]), v([2., 2., 2.]), v([3., 3., 3.])));
        // Collinear corners make a segment.
        assert_eq!(reduce(&[v([0., 0., 0.]), v([2., 0., 0.]), v([1., 0., 0.])]).len(), 2);
    }

    #[test]
    fn shared_corners_allow_touching_only() {
        let id = |i: u32, p: [f64; 3]| (i, v(p));
        let s = [id(0, [0., 0., 0.]), id(1, [1., 0., 0.]), id(2, [0., 1., 0.])];
        // Sharing a corner, pointing away: fine; piercing through the other: not.
        let away = [id(0, [0., 0., 0.]), id(3, [-1., 0., 0.5]), id(4, [0., -1., 0.5])];
        assert!(!triangles_meet_off_shared(s, away));
        let through = [id(0, [0., 0., 0.]), id(3, [0.5, 0.2, 1.]), id(4, [0.2, 0.5, -1.])];
        assert!(triangles_meet_off_shared(s, through));
        // Sharing an edge: folded over it (same side, coplanar) or hinged.
        let folded = [id(1, [1., 0., 0.]), id(2, [0., 1., 0.]), id(5, [0.2, 0.2, 0.])];
        assert!(triangles_meet_off_shared(s, folded));
        let hinged = [id(1, [1., 0., 0.]), id(2, [0., 1., 0.]), id(5, [1., 1., 1.])];
        assert!(!triangles_meet_off_shared(s, hinged));
        let flat_beyond = [id(1, [1., 0., 0.]), id(2, [0., 1., 0.]), id(5, [1., 1., 0.])];
        assert!(!triangles_meet_off_shared(s, flat_beyond));
        // The same triangle twice.
        assert!(triangles_meet_off_shared(s, s));
    }
}
