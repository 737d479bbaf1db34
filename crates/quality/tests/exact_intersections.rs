//! `self_intersections` against a brute-force checker in exact rational arithmetic, on
//! random small meshes whose corners sit on a small integer grid, so that shared corners,
//! shared positions, touching, coplanar, collinear and repeated faces arise often.
//!
//! The brute force computes each triangle pair's intersection as a convex point set
//! (one triangle clipped by the other's planes, in rationals) and asks whether it lies in
//! the segments between the positions the triangles share; it shares no code with the
//! predicates of the library.

use std::collections::HashMap;

use glam::DVec3;
use num_bigint::BigInt;
use num_rational::BigRational;
use num_traits::{Signed, Zero};
use proptest::prelude::*;
use voxreg_quality::{invalid_faces, self_intersections};

type Q = BigRational;
type V = [Q; 3];

fn q(x: f64) -> Q {
    Q::from_integer(BigInt::from(x as i64))
}
fn sub(a: &V, b: &V) -> V {
    [&a[0] - &b[0], &a[1] - &b[1], &a[2] - &b[2]]
}
fn dot(a: &V, b: &V) -> Q {
    &a[0] * &b[0] + &a[1] * &b[1] + &a[2] * &b[2]
}
fn cross(a: &V, b: &V) -> V {
    [&a[1] * &b[2] - &a[2] * &b[1], &a[2] * &b[0] - &a[0] * &b[2], &a[0] * &b[1] - &a[1] * &b[0]]
}
fn is_zero(a: &V) -> bool {
    a.iter().all(Zero::is_zero)
}

/// `{x in conv(points): n . x <= c}`, as the points whose hull it is.
fn clip(points: &[V], n: &V, c: &Q) -> Vec<V> {
    let side: Vec<Q> = points.iter().map(|p| dot(n, p) - c).collect();
    let mut out: Vec<V> = Vec::new();
    let push = |p: V, out: &mut Vec<V>| {
        if !out.contains(&p) {
            out.push(p);
        }
    };
    for (i, p) in points.iter().enumerate() {
        if !side[i].is_positive() {
            push(p.clone(), &mut out);
        }
        for (j, r) in points.iter().enumerate() {
            if side[i].is_negative() && side[j].is_positive() {
                let t = &side[i] / (&side[i] - &side[j]);
                let d = sub(r, p);
                push([&p[0] + &t * &d[0], &p[1] + &t * &d[1], &p[2] + &t * &d[2]], &mut out);
            }
        }
    }
    out
}

fn neg(a: &V) -> V {
    [-&a[0], -&a[1], -&a[2]]
}

/// `conv(s) ∩ conv(t)`, as the points whose hull it is.
fn intersection(s: &[V], t: &[V]) -> Vec<V> {
    let mut p = s.to_vec();
    let keep = |n: V, c: Q, p: &mut Vec<V>| *p = clip(p, &n, &c);
    let eq = |n: V, c: Q, p: &mut Vec<V>| {
        keep(n.clone(), c.clone(), p);
        keep(neg(&n), -c, p);
    };
    let (t0, t1, t2) = (&t[0], &t[1], &t[2]);
    let normal = cross(&sub(t1, t0), &sub(t2, t0));
    if !is_zero(&normal) {
        eq(normal.clone(), dot(&normal, t0), &mut p);
        for i in 0..3 {
            let (u, v, w) = (&t[i], &t[(i + 1) % 3], &t[(i + 2) % 3]);
            let mut m = cross(&normal, &sub(v, u));
            if dot(&m, &sub(w, u)).is_positive() {
                m = neg(&m);
            }
            // Keep the side of w: m . (x - u) <= 0.
            keep(m.clone(), dot(&m, u), &mut p);
        }
        return p;
    }
    // A flat triangle: the segment between its outermost corners, or a point.
    let mut ends = (t0.clone(), t0.clone());
    let mut far = Q::zero();
    for a in t {
        for b in t {
            let d = sub(b, a);
            if dot(&d, &d) > far {
                far = dot(&d, &d);
                ends = (a.clone(), b.clone());
            }
        }
    }
    let (u, v) = ends;
    let d = sub(&v, &u);
    if is_zero(&d) {
        for k in 0..3 {
            let mut e = [Q::zero(), Q::zero(), Q::zero()];
            e[k] = Q::from_integer(1.into());
            eq(e, u[k].clone(), &mut p);
        }
        return p;
    }
    for k in 0..3 {
        let mut e = [Q::zero(), Q::zero(), Q::zero()];
        e[k] = Q::from_integer(1.into());
        let c = cross(&d, &e);
        if !is_zero(&c) {
            eq(c.clone(), dot(&c, &u), &mut p);
        }
    }
    keep(neg(&d), -dot(&d, &u), &mut p);
    keep(d.clone(), dot(&d, &v), &mut p);
    p
}

/// Whether `x` is on the closed segment `u v` (a point when `u == v`).
fn on_segment(u: &V, v: &V, x: &V) -> bool {
    let d = sub(v, u);
    let e = sub(x, u);
    if is_zero(&d) {
        return is_zero(&e);
    }
    is_zero(&cross(&d, &e)) && !dot(&d, &e).is_negative() && dot(&d, &e) <= dot(&d, &d)
}

/// Whether the convex hull of `p` (non-empty) lies in the union of the segments between
/// the points of `shared`.
fn inside_segments(p: &[V], shared: &[V]) -> bool {
    let a = &p[0];
    let Some(b) = p.iter().find(|x| *x != a) else {
        return shared.iter().any(|u| shared.iter().any(|v| on_segment(u, v, a)));
    };
    let d = sub(b, a);
    if p.iter().any(|x| !is_zero(&cross(&d, &sub(x, a)))) {
        return false; // two-dimensional
    }
    // A segment along d: its parameter range, covered by the segments' ranges on its line.
    let param = |x: &V| dot(&d, &sub(x, a)) / dot(&d, &d);
    let (mut lo, mut hi) = (param(a), param(a));
    for x in p {
        let t = param(x);
        if t < lo {
            lo = t.clone();
        }
        if t > hi {
            hi = t;
        }
    }
    let on_line = |x: &V| is_zero(&cross(&d, &sub(x, a)));
    let mut ranges: Vec<(Q, Q)> = Vec::new();
    for u in shared {
        for v in shared {
            if on_line(u) && on_line(v) {
                let (s, t) = (param(u), param(v));
                ranges.push(if s <= t { (s, t) } else { (t, s) });
            }
        }
    }
    ranges.sort();
    let mut reach = lo.clone();
    for (s, t) in ranges {
        if s <= reach && t > reach {
            reach = t;
        }
    }
    reach >= hi
}

fn brute_force(positions: &[DVec3], quads: &[[u32; 4]]) -> Vec<(usize, usize)> {
    let n = positions.len();
    let finite = |q: &[u32; 4]| q.iter().all(|&v| (v as usize) < n && positions[v as usize].is_finite());
    let mut first: HashMap<[u64; 3], u32> = HashMap::new();
    let weld: Vec<u32> = positions
        .iter()
        .enumerate()
        .map(|(i, p)| *first.entry(p.to_array().map(f64::to_bits)).or_insert(i as u32))
        .collect();
    let exact: Vec<V> = positions.iter().map(|p| [q(p.x), q(p.y), q(p.z)]).collect();
    let faces: Vec<Option<[u32; 4]>> =
        quads.iter().map(|f| finite(f).then(|| f.map(|v| weld[v as usize]))).collect();
    let mut out = Vec::new();
    let mut repeated = vec![false; quads.len()];
    for b in 0..quads.len() {
        let Some(fb) = faces[b] else { continue };
        let mut kb = fb;
        kb.sort_unstable();
        if let Some(a) = (0..b).find(|&a| {
            faces[a].is_some_and(|mut ka| {
                ka.sort_unstable();
                ka == kb
            })
        }) {
            out.push((a, b));
            repeated[b] = true;
        }
    }
    let tris = |f: [u32; 4]| [[f[0], f[1], f[2]], [f[0], f[2], f[3]]];
    // Two triangles (corner ids), fanned around the faces' shared corners lying inside the
    // other (the definition's pieces); then whether any two pieces meet outside the
    // segments between their common corners.
    fn pieces(s: [u32; 3], t: [u32; 3], shared: &[u32], exact: &[V]) -> bool {
        let pts = |x: [u32; 3]| -> Vec<V> { x.iter().map(|&v| exact[v as usize].clone()).collect() };
        for (x, y) in [(s, t), (t, s)] {
            if let Some(&p) = x.iter().find(|v| {
                shared.contains(v)
                    && !y.contains(v)
                    && !intersection(&[exact[**v as usize].clone()], &pts(y)).is_empty()
            }) {
                return (0..3).any(|i| pieces(x, [p, y[i], y[(i + 1) % 3]], shared, exact));
            }
        }
        let p = intersection(&pts(s), &pts(t));
        if p.is_empty() {
            return false;
        }
        let common: Vec<V> = s.iter().filter(|v| t.contains(v)).map(|&v| exact[v as usize].clone()).collect();
        !inside_segments(&p, &common)
    }
    for a in 0..quads.len() {
        for b in a + 1..quads.len() {
            let (Some(fa), Some(fb)) = (faces[a], faces[b]) else { continue };
            if repeated[a] || repeated[b] {
                continue;
            }
            let shared: Vec<u32> = fa.iter().filter(|v| fb.contains(v)).copied().collect();
            let meet = tris(fa).iter().any(|s| tris(fb).iter().any(|t| pieces(*s, *t, &shared, &exact)));
            if meet {
                out.push((a, b));
            }
        }
    }
    out.sort_unstable();
    out
}

fn mesh() -> impl Strategy<Value = (Vec<DVec3>, Vec<[u32; 4]>)> {
    (3usize..9).prop_flat_map(|n| {
        (
            prop::collection::vec(prop::array::uniform3(0i32..3), n),
            prop::collection::vec(prop::array::uniform4(0..n as u32), 1..6),
        )
            .prop_map(|(p, q)| {
                (p.iter().map(|c| DVec3::new(c[0].into(), c[1].into(), c[2].into())).collect(), q)
            })
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(3000))]

    #[test]
    fn matches_the_exact_brute_force((positions, quads) in mesh()) {
        prop_assert_eq!(self_intersections(&positions, &quads), brute_force(&positions, &quads));
    }

    #[test]
    fn scaled_and_shifted_meshes_give_the_same_pairs((positions, quads) in mesh(), k in -3i32..4) {
        // Powers of two and integer shifts keep the positions exact: the answer is the same.
        let s = 2f64.powi(k);
        let moved: Vec<DVec3> = positions.iter().map(|p| *p * s + DVec3::new(5.0, -3.0, 1.0)).collect();
        prop_assert_eq!(self_intersections(&moved, &quads), self_intersections(&positions, &quads));
    }
}

#[test]
fn non_finite_faces_are_invalid_and_left_out() {
    let p = vec![DVec3::NAN; 4];
    assert!(self_intersections(&p, &[[0, 1, 2, 3], [0, 1, 2, 3]]).is_empty());
    assert_eq!(invalid_faces(&p, &[[0, 1, 2, 3]]), vec![0]);
    let report = voxreg_quality::check(&p, &[[0, 1, 2, 3]]);
    assert_eq!(report.invalid_faces, 1);
    assert!(!report.is_clean());
}
