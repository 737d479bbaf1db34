//! The geometric predicates of the collapse checks: triangle normals and quality, box
//! overlap, and the filters in front of the exact intersection tests.

use glam::DVec3;
use voxreg_quality::{triangles_intersect, triangles_meet_off_shared};

pub(super) fn tri_normal(p: [DVec3; 3]) -> DVec3 {
    (p[1] - p[0]).cross(p[2] - p[0])
}

pub(super) fn quality(p: [DVec3; 3]) -> f64 {
    let l = (p[1] - p[0]).length_squared() + (p[2] - p[1]).length_squared() + (p[0] - p[2]).length_squared();
    if l <= 0.0 {
        return 0.0;
    }
    2.0 * 3f64.sqrt() * tri_normal(p).length() / l
}

/// Whether the boxes of two triangles meet (closed boxes: a necessary condition for
/// the triangles to meet, exact).
pub(super) fn boxes_meet(a: &[DVec3; 3], b: &[DVec3; 3]) -> bool {
    let (alo, ahi) = (a[0].min(a[1]).min(a[2]), a[0].max(a[1]).max(a[2]));
    let (blo, bhi) = (b[0].min(b[1]).min(b[2]), b[0].max(b[1]).max(b[2]));
    !(alo.cmpgt(bhi).any() || blo.cmpgt(ahi).any())
}

/// Whether the points `q` lie all strictly on one side of the plane of `t`, decided by
/// floating-point orientations whose sign is certain (Shewchuk's error bound for the
/// orientation determinant, with a margin): `false` when in doubt. Then the closed
/// triangle `t` meets the hull of `q` nowhere, and the hull of `q` together with
/// points of `t` meets `t` only in the hull of those points: a filter in front of the
/// exact tests.
pub(super) fn strictly_one_side(t: &[DVec3; 3], q: &[DVec3]) -> bool {
    let (d1, d2) = (t[1] - t[0], t[2] - t[0]);
    let c = d1.cross(d2);
    let ca = DVec3::new(
        (d1.y * d2.z).abs() + (d1.z * d2.y).abs(),
        (d1.z * d2.x).abs() + (d1.x * d2.z).abs(),
        (d1.x * d2.y).abs() + (d1.y * d2.x).abs(),
    );
    let mut side = 0.0;
    for &x in q {
        let d = x - t[0];
        let det = d.dot(c);
        let permanent = d.abs().dot(ca);
        if det.is_nan() || det.abs() <= 1e-14 * permanent || det * side < 0.0 {
            return false;
        }
        side = det;
    }
    true
}

/// Whether triangles `s` and `t` (corner ids and positions) that share corners meet off
/// the shared corners and the segment between them, as [`triangles_meet_off_shared`]
/// decides, settling first without allocation the common cases with exact orientations:
/// two shared corners with the other two off a common plane (they meet only on the shared
/// edge), or one shared corner `p` with a plane through `p` and an edge of one triangle
/// that has that triangle's third corner strictly on one side and the other triangle's
/// two other corners strictly on the other (then they meet only at `p`).
pub(super) fn shared_meet(s: ([u32; 3], [DVec3; 3]), t: ([u32; 3], [DVec3; 3])) -> bool {
    let o3 = |a: DVec3, b: DVec3, c: DVec3, d: DVec3| {
        let k = |p: DVec3| robust::Coord3D { x: p.x, y: p.y, z: p.z };
        robust::orient3d(k(a), k(b), k(c), k(d))
    };
    let in_t = |x: u32| t.0.contains(&x);
    let shared = s.0.iter().filter(|&&x| in_t(x)).count();
    let distinct = |x: [u32; 3]| x[0] != x[1] && x[1] != x[2] && x[0] != x[2];
    if distinct(s.0) && distinct(t.0) {
        if shared == 2 {
            let (i, j) = (
                (0..3).find(|&k| !in_t(s.0[k])).expect("one not shared"),
                (0..3).find(|&k| !s.0.contains(&t.0[k])).expect("one not shared"),
            );
            let (p, q) = (s.1[(i + 1) % 3], s.1[(i + 2) % 3]);
            if o3(p, q, s.1[i], t.1[j]) != 0.0 {
                return false;
            }
        } else if shared == 1 {
            let i = (0..3).find(|&k| in_t(s.0[k])).expect("one shared");
            let j = (0..3).find(|&k| t.0[k] == s.0[i]).expect("one shared");
            let p = s.1[i];
            let (s1, s2) = (s.1[(i + 1) % 3], s.1[(i + 2) % 3]);
            let (t1, t2) = (t.1[(j + 1) % 3], t.1[(j + 2) % 3]);
            for (e, opp, x1, x2) in [(s1, s2, t1, t2), (s2, s1, t1, t2), (t1, t2, s1, s2), (t2, t1, s1, s2)] {
                let n = (e - p).cross(opp - p);
                let len = n.length();
                if len.is_nan() || len <= 0.0 {
                    continue;
                }
                let r = p + n * ((e - p).length() / len);
                let side = o3(p, e, r, opp);
                if side != 0.0 && o3(p, e, r, x1) * side < 0.0 && o3(p, e, r, x2) * side < 0.0 {
                    return false;
                }
            }
        }
    }
    let with_ids = |x: ([u32; 3], [DVec3; 3])| [(x.0[0], x.1[0]), (x.0[1], x.1[1]), (x.0[2], x.1[2])];
    triangles_meet_off_shared(with_ids(s), with_ids(t))
}

/// Whether triangles `s` and `t` (corner ids and positions) meet anywhere but at their
/// shared corners and the segment between two shared corners: [`shared_meet`] when they
/// share a corner, else an exact intersection test; both behind the plane-side filter.
pub(super) fn meet_off_shared(s: ([u32; 3], [DVec3; 3]), t: ([u32; 3], [DVec3; 3])) -> bool {
    if t.0.iter().any(|x| s.0.contains(x)) {
        // The others strictly on one side of `s`'s plane meet it only at the shared ones.
        let mut others = [DVec3::ZERO; 3];
        let mut n = 0;
        for (k, x) in t.0.iter().enumerate() {
            if !s.0.contains(x) {
                others[n] = t.1[k];
                n += 1;
            }
        }
        !(n > 0 && strictly_one_side(&s.1, &others[..n])) && shared_meet(s, t)
    } else {
        !strictly_one_side(&s.1, &t.1) && !strictly_one_side(&t.1, &s.1) && triangles_intersect(&s.1, &t.1)
    }
}
