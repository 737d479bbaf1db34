//! Analytic multi-label shapes with known interfaces and junctions, their digitization at
//! any spacing, and the fidelity metrics of a mesh of their digital surface (distances of
//! surface, inner-interface, junction-line and junction-point vertices to the truth; quad
//! normal errors).

use glam::DVec3;
use rayon::prelude::*;
use voxreg_digisurf::{DigitalSurface, LabelVolume, VertexId};

use crate::{mean_max, Shape};

/// What a set of labels meeting along a junction is: a curve or an isolated point.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum JunctionKind {
    /// A curve where the labels meet.
    Curve,
    /// A point where the labels meet (the end of a curve).
    Point,
}

/// An analytic label field: a label per point of space (`0` outside everything, the
/// background), the interfaces between pairs of labels and the junctions where three
/// or more meet, each with its nearest-point query.
pub trait LabelShape: Sync {
    /// The label at `p`.
    fn label(&self, p: DVec3) -> u32;
    /// A box containing every non-background label: `(min, max)`.
    fn bounds(&self) -> (DVec3, DVec3);
    /// A short name.
    fn name(&self) -> &'static str;
    /// The point nearest to `p` of the interface between labels `a < b`, and the
    /// interface's unit normal there (either orientation); `None` when they never meet.
    fn interface(&self, a: u32, b: u32, p: DVec3) -> Option<(DVec3, DVec3)>;
    /// The point nearest to `p` of the set where all of `labels` (sorted, at least three)
    /// meet, and whether that set is a curve or a point; `None` when they never meet.
    fn junction(&self, labels: &[u32], p: DVec3) -> Option<(DVec3, JunctionKind)>;
}

const TOL: f64 = 1e-9;

/// A half-space `{x : n . x <= d}`.
#[derive(Copy, Clone, Debug)]
struct Half {
    n: DVec3,
    d: f64,
}

impl Half {
    fn contains(&self, p: DVec3) -> bool {
        self.n.dot(p) <= self.d + TOL
    }
    fn flipped(&self) -> Half {
        Half { n: -self.n, d: -self.d }
    }
}

fn inside_all(halves: &[Half], p: DVec3) -> bool {
    halves.iter().all(|h| h.contains(p))
}

/// The nearest of `candidates` to `p`.
fn nearest_of(p: DVec3, candidates: impl IntoIterator<Item = DVec3>) -> Option<DVec3> {
    candidates.into_iter().min_by(|a, b| a.distance_squared(p).total_cmp(&b.distance_squared(p)))
}

/// The circle where the plane `{n . x = d}` (`n` unit) cuts the sphere `(c, r)`: centre,
/// radius, `None` when they miss.
fn plane_sphere_circle(n: DVec3, d: f64, c: DVec3, r: f64) -> Option<(DVec3, f64)> {
    let off = d - n.dot(c);
    (off.abs() < r).then(|| (c + n * off, (r * r - off * off).sqrt()))
}

/// The point of the circle (centre `cc`, radius `rc`, in the plane of unit normal `n`)
/// nearest to `p`.
fn circle_nearest(cc: DVec3, rc: f64, n: DVec3, p: DVec3) -> DVec3 {
    let q = p - cc;
    let inplane = q - n * n.dot(q);
    cc + inplane.try_normalize().unwrap_or_else(|| n.any_orthonormal_vector()) * rc
}

/// The two points where the line `{n1 . x = d1, n2 . x = d2}` crosses the sphere `(c, r)`,
/// and the line's point nearest to `p` (`None` when the line misses the ball).
fn line_in_ball(n1: DVec3, d1: f64, n2: DVec3, d2: f64, c: DVec3, r: f64, p: DVec3) -> Option<[DVec3; 3]> {
    let dir = n1.cross(n2).try_normalize()?;
    // A point of the line: solve in the span of n1, n2.
    let (a, b, k) = (n1.length_squared(), n2.length_squared(), n1.dot(n2));
    let det = a * b - k * k;
    let (s, t) = ((d1 * b - d2 * k) / det, (d2 * a - d1 * k) / det);
    let o = n1 * s + n2 * t;
    let oc = o - c;
    let (bq, cq) = (oc.dot(dir), oc.length_squared() - r * r);
    let disc = bq * bq - cq;
    if disc <= 0.0 {
        return None;
    }
    let (t0, t1) = (-bq - disc.sqrt(), -bq + disc.sqrt());
    let tp = (p - o).dot(dir).clamp(t0, t1);
    Some([o + dir * t0, o + dir * t1, o + dir * tp])
}

/// The point nearest to `p` of the part of the sphere `(c, r)` inside every half-space of
/// `halves` (a convex patch; candidates: the radial projection, the nearest points of the
/// boundary arcs, the arcs' end points).
fn sphere_patch(c: DVec3, r: f64, halves: &[Half], p: DVec3) -> Option<DVec3> {
    let mut cand = Vec::new();
    let radial = c + (p - c).try_normalize().unwrap_or(DVec3::Z) * r;
    cand.push(radial);
    for (i, h) in halves.iter().enumerate() {
        let n = h.n.normalize();
        let d = h.d / h.n.length();
        if let Some((cc, rc)) = plane_sphere_circle(n, d, c, r) {
            cand.push(circle_nearest(cc, rc, n, p));
            for h2 in &halves[i + 1..] {
                if let Some([a, b, _]) = line_in_ball(h.n, h.d, h2.n, h2.d, c, r, p) {
                    cand.extend([a, b]);
                }
            }
        }
    }
    nearest_of(p, cand.into_iter().filter(|q| inside_all(halves, *q)))
}

/// The point nearest to `p` of the part of the plane `{n . x = d}` (`n` unit) inside the
/// ball `(c, r)` and every half-space of `halves`.
fn plane_patch(n: DVec3, d: f64, c: DVec3, r: f64, halves: &[Half], p: DVec3) -> Option<DVec3> {
    let (cc, rc) = plane_sphere_circle(n, d, c, r)?;
    let mut cand = vec![p - n * (n.dot(p) - d), circle_nearest(cc, rc, n, p)];
    for h in halves {
        if let Some(seg) = line_in_ball(n, d, h.n, h.d, c, r, p) {
            cand.extend(seg);
        }
    }
    let in_ball = |q: &DVec3| q.distance(c) <= r + TOL;
    nearest_of(p, cand.into_iter().filter(|q| in_ball(q) && inside_all(halves, *q)))
}

/// The point nearest to `p` of the arc of the circle where the plane `{n . x = d}` cuts
/// the sphere `(c, r)`, inside every half-space of `halves`.
fn arc(n: DVec3, d: f64, c: DVec3, r: f64, halves: &[Half], p: DVec3) -> Option<DVec3> {
    let (cc, rc) = plane_sphere_circle(n, d, c, r)?;
    let mut cand = vec![circle_nearest(cc, rc, n, p)];
    for h in halves {
        if let Some([a, b, _]) = line_in_ball(n, d, h.n, h.d, c, r, p) {
            cand.extend([a, b]);
        }
    }
    nearest_of(p, cand.into_iter().filter(|q| inside_all(halves, *q)))
}

/// The ball of radius `radius` centred at the origin, cut by the plane `z = cut` into
/// label 1 (below, `z < cut`) and label 2 (above); background 0 around. Its junction is
/// the circle where the plane meets the sphere.
#[derive(Copy, Clone, Debug)]
pub struct SplitBall {
    /// The ball's radius.
    pub radius: f64,
    /// The height of the cutting plane.
    pub cut: f64,
}

impl SplitBall {
    fn below(&self) -> Half {
        Half { n: DVec3::Z, d: self.cut }
    }
}

impl LabelShape for SplitBall {
    fn label(&self, p: DVec3) -> u32 {
        if p.length() > self.radius {
            0
        } else if p.z < self.cut {
            1
        } else {
            2
        }
    }
    fn bounds(&self) -> (DVec3, DVec3) {
        (DVec3::splat(-self.radius), DVec3::splat(self.radius))
    }
    fn name(&self) -> &'static str {
        "split ball"
    }
    fn interface(&self, a: u32, b: u32, p: DVec3) -> Option<(DVec3, DVec3)> {
        let sphere = |h: Half| sphere_patch(DVec3::ZERO, self.radius, &[h], p).map(|q| (q, q / self.radius));
        match (a, b) {
            (0, 1) => sphere(self.below()),
            (0, 2) => sphere(self.below().flipped()),
            (1, 2) => {
                plane_patch(DVec3::Z, self.cut, DVec3::ZERO, self.radius, &[], p).map(|q| (q, DVec3::Z))
            }
            _ => None,
        }
    }
    fn junction(&self, labels: &[u32], p: DVec3) -> Option<(DVec3, JunctionKind)> {
        (labels == [0, 1, 2])
            .then(|| arc(DVec3::Z, self.cut, DVec3::ZERO, self.radius, &[], p))
            .flatten()
            .map(|q| (q, JunctionKind::Curve))
    }
}

/// The ball of radius `radius` centred at `centre`, cut by the planes `x = cuts.x` and
/// `z = cuts.y` into four quarters: label `1 + [x >= cuts.x] + 2 [z >= cuts.y]`;
/// background 0 around. Three labels meet along four arcs of the sphere, the four quarters
/// along the segment where the planes cross, and all five at the segment's two ends.
#[derive(Copy, Clone, Debug)]
pub struct QuarteredBall {
    /// The ball's radius.
    pub radius: f64,
    /// The ball's centre.
    pub centre: DVec3,
    /// The planes `x = cuts.x` and `z = cuts.y`.
    pub cuts: glam::DVec2,
}

impl QuarteredBall {
    /// The half-spaces of quarter `q` (label 1 to 4).
    fn quarter(&self, q: u32) -> [Half; 2] {
        let hx = Half { n: DVec3::X, d: self.cuts.x };
        let hz = Half { n: DVec3::Z, d: self.cuts.y };
        let k = q - 1;
        [if k & 1 == 0 { hx } else { hx.flipped() }, if k & 2 == 0 { hz } else { hz.flipped() }]
    }
}

impl LabelShape for QuarteredBall {
    fn label(&self, p: DVec3) -> u32 {
        if p.distance(self.centre) > self.radius {
            return 0;
        }
        1 + u32::from(p.x >= self.cuts.x) + 2 * u32::from(p.z >= self.cuts.y)
    }
    fn bounds(&self) -> (DVec3, DVec3) {
        (self.centre - self.radius, self.centre + self.radius)
    }
    fn name(&self) -> &'static str {
        "quartered ball"
    }
    fn interface(&self, a: u32, b: u32, p: DVec3) -> Option<(DVec3, DVec3)> {
        let (c, r) = (self.centre, self.radius);
        if a == 0 {
            return sphere_patch(c, r, &self.quarter(b), p).map(|q| (q, (q - c) / r));
        }
        // Two quarters share a half-plane when they differ in one bit.
        let diff = (a - 1) ^ (b - 1);
        let (n, d, keep) = match diff {
            1 => (DVec3::X, self.cuts.x, self.quarter(a)[1]),
            2 => (DVec3::Z, self.cuts.y, self.quarter(a)[0]),
            _ => return None,
        };
        plane_patch(n, d, c, r, &[keep], p).map(|q| (q, n))
    }
    fn junction(&self, labels: &[u32], p: DVec3) -> Option<(DVec3, JunctionKind)> {
        let (c, r) = (self.centre, self.radius);
        let quarters: Vec<u32> = labels.iter().copied().filter(|&l| l != 0).collect();
        let with_background = labels.first() == Some(&0);
        let segment = || line_in_ball(DVec3::X, self.cuts.x, DVec3::Z, self.cuts.y, c, r, p);
        match (with_background, quarters.len()) {
            // The two ends of the segment (three or four quarters at the background: the
            // digital point may miss one quarter).
            (true, 3 | 4) => {
                segment().and_then(|[a, b, _]| nearest_of(p, [a, b])).map(|q| (q, JunctionKind::Point))
            }
            (false, 4) => segment().map(|s| (s[2], JunctionKind::Curve)),
            (false, 3) => None,
            (true, 2) => {
                let diff = (quarters[0] - 1) ^ (quarters[1] - 1);
                let (n, d, keep) = match diff {
                    1 => (DVec3::X, self.cuts.x, self.quarter(quarters[0])[1]),
                    2 => (DVec3::Z, self.cuts.y, self.quarter(quarters[0])[0]),
                    _ => return None,
                };
                arc(n, d, c, r, &[keep], p).map(|q| (q, JunctionKind::Curve))
            }
            _ => None,
        }
    }
}

/// Two overlapping balls of labels 2 and 3 (cells), split by their radical plane (the
/// power diagram: each point of their union goes to the ball of smaller power), inside a
/// ball of label 1 centred at the origin; background 0 around. Labels 1, 2 and 3 meet
/// along one circle, tilted off the lattice's axes.
#[derive(Copy, Clone, Debug)]
pub struct TouchingBalls {
    /// Radius of the enclosing ball (label 1), centred at the origin.
    pub outer: f64,
    /// Centre and radius of the ball of label 2.
    pub a: (DVec3, f64),
    /// Centre and radius of the ball of label 3.
    pub b: (DVec3, f64),
}

impl Default for TouchingBalls {
    /// Two cells of radii 8.5 and 7.5, 11 apart along `(1, 0.35, 0.2)`, in a ball of
    /// radius 19.
    fn default() -> Self {
        let d = DVec3::new(1.0, 0.35, 0.2).normalize();
        let o = DVec3::new(0.21, -0.37, 0.13);
        TouchingBalls { outer: 19.0, a: (o - 5.5 * d, 8.5), b: (o + 5.5 * d, 7.5) }
    }
}

impl TouchingBalls {
    fn power(ball: (DVec3, f64), p: DVec3) -> f64 {
        p.distance_squared(ball.0) - ball.1 * ball.1
    }
    /// The radical plane `{n . x = d}` (`n` unit, from `a` towards `b`).
    fn radical(&self) -> (DVec3, f64) {
        let (ca, ra) = self.a;
        let (cb, rb) = self.b;
        // |x - ca|^2 - ra^2 = |x - cb|^2 - rb^2  <=>  2 (cb - ca) . x = |cb|^2 - |ca|^2 - rb^2 + ra^2
        let m = 2.0 * (cb - ca);
        let k = cb.length_squared() - ca.length_squared() - rb * rb + ra * ra;
        (m.normalize(), k / m.length())
    }
}

impl LabelShape for TouchingBalls {
    fn label(&self, p: DVec3) -> u32 {
        let (pa, pb) = (Self::power(self.a, p), Self::power(self.b, p));
        if pa.min(pb) <= 0.0 {
            if pa <= pb {
                2
            } else {
                3
            }
        } else if p.length() <= self.outer {
            1
        } else {
            0
        }
    }
    fn bounds(&self) -> (DVec3, DVec3) {
        (DVec3::splat(-self.outer), DVec3::splat(self.outer))
    }
    fn name(&self) -> &'static str {
        "touching balls"
    }
    fn interface(&self, a: u32, b: u32, p: DVec3) -> Option<(DVec3, DVec3)> {
        let (n, d) = self.radical();
        let side_a = Half { n, d };
        match (a, b) {
            (0, 1) => Some((p.normalize_or(DVec3::Z) * self.outer, p.normalize_or(DVec3::Z))),
            (1, 2) => sphere_patch(self.a.0, self.a.1, &[side_a], p).map(|q| (q, (q - self.a.0) / self.a.1)),
            (1, 3) => sphere_patch(self.b.0, self.b.1, &[side_a.flipped()], p)
                .map(|q| (q, (q - self.b.0) / self.b.1)),
            (2, 3) => plane_patch(n, d, self.a.0, self.a.1, &[], p).map(|q| (q, n)),
            _ => None,
        }
    }
    fn junction(&self, labels: &[u32], p: DVec3) -> Option<(DVec3, JunctionKind)> {
        let (n, d) = self.radical();
        (labels == [1, 2, 3])
            .then(|| arc(n, d, self.a.0, self.a.1, &[], p))
            .flatten()
            .map(|q| (q, JunctionKind::Curve))
    }
}

/// A single-label [`Shape`] as a label field (label 1 inside, 0 outside).
pub struct Solid<'a>(pub &'a dyn Shape);

impl LabelShape for Solid<'_> {
    fn label(&self, p: DVec3) -> u32 {
        u32::from(self.0.value(p) <= 0.0)
    }
    fn bounds(&self) -> (DVec3, DVec3) {
        self.0.bounds()
    }
    fn name(&self) -> &'static str {
        self.0.name()
    }
    fn interface(&self, a: u32, b: u32, p: DVec3) -> Option<(DVec3, DVec3)> {
        ((a, b) == (0, 1)).then(|| {
            let q = self.0.project(p);
            (q, self.0.gradient(q).normalize_or_zero())
        })
    }
    fn junction(&self, _labels: &[u32], _p: DVec3) -> Option<(DVec3, JunctionKind)> {
        None
    }
}

/// Gauss digitization of `shape` with voxel `spacing`: voxel `p` (integer coordinates)
/// takes the label at `spacing * p`; background 0 with a margin of one voxel.
pub fn digitize_labels(shape: &dyn LabelShape, spacing: DVec3) -> LabelVolume {
    crate::sample_grid(shape.bounds(), spacing, |p| shape.label(p))
}

/// Mean, maximum and number of a set of errors.
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct Stat {
    /// Mean (0 for none).
    pub mean: f64,
    /// Maximum (0 for none).
    pub max: f64,
    /// How many.
    pub count: usize,
}

impl Stat {
    fn of(values: &[f64]) -> Stat {
        let (mean, max) = mean_max(values);
        Stat { mean, max, count: values.len() }
    }
}

/// The fidelity of a mesh of a [`LabelShape`]'s digital surface, by part. Distances are
/// in voxels of the finest spacing (in-plane voxels for a stack of thick slices); angles
/// in degrees. A vertex belongs to the part given by the labels of its quads: two
/// labels, one of them the background (`surface`) or not (`inner`); three or more
/// (`junction`: the curves, `points`: their ends).
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct LabelFidelity {
    /// Vertices on an interface with the background.
    pub surface: Stat,
    /// Vertices on an interface between two non-background labels.
    pub inner: Stat,
    /// Vertices where three or more labels meet along a curve.
    pub junction: Stat,
    /// Vertices where labels meet at a point.
    pub points: Stat,
    /// Angle between each quad of an interface with the background and the true normal
    /// at its centre's nearest interface point.
    pub surface_normals: Stat,
    /// The same for the quads between two non-background labels.
    pub inner_normals: Stat,
}

/// The labels of the quads around each vertex, sorted and deduplicated.
pub fn vertex_labels(surface: &DigitalSurface) -> Vec<Vec<u32>> {
    (0..surface.num_vertices())
        .into_par_iter()
        .map(|v| {
            let mut l: Vec<u32> = surface
                .vertex_surfels(VertexId(v as u32))
                .iter()
                .flat_map(|s| surface.surfel(*s).labels)
                .collect();
            l.sort_unstable();
            l.dedup();
            l
        })
        .collect()
}

/// The fidelity of `positions` (one per vertex of `surface`, the digital surface of
/// [`digitize_labels`]`(shape, ..)`) to `shape`.
pub fn label_fidelity(
    surface: &DigitalSurface,
    positions: &[DVec3],
    shape: &dyn LabelShape,
) -> LabelFidelity {
    let unit = surface.spacing().min_element();
    let labels = vertex_labels(surface);
    let mut parts: [Vec<f64>; 4] = Default::default();
    let per_vertex: Vec<Option<(usize, f64)>> = (0..positions.len())
        .into_par_iter()
        .map(|v| {
            let (l, p) = (&labels[v], positions[v]);
            if l.len() == 2 {
                let (q, _) = shape.interface(l[0], l[1], p)?;
                Some((if l[0] == 0 { 0 } else { 1 }, p.distance(q) / unit))
            } else if l.len() >= 3 {
                let (q, kind) = shape.junction(l, p)?;
                Some((if kind == JunctionKind::Curve { 2 } else { 3 }, p.distance(q) / unit))
            } else {
                None
            }
        })
        .collect();
    for (part, d) in per_vertex.into_iter().flatten() {
        parts[part].push(d);
    }
    let mut normals: [Vec<f64>; 2] = Default::default();
    let per_quad: Vec<Option<(usize, f64)>> = surface
        .surfels()
        .par_iter()
        .map(|s| {
            let [a, b, c, d] = s.vertices.map(|v| positions[v.index()]);
            let area = (c - a).cross(d - b);
            let centre = (a + b + c + d) / 4.0;
            let [l0, l1] = [s.labels[0].min(s.labels[1]), s.labels[0].max(s.labels[1])];
            let (_, n) = shape.interface(l0, l1, centre)?;
            let cos = area.normalize_or_zero().dot(n).abs().min(1.0);
            Some((usize::from(l0 != 0), cos.acos().to_degrees()))
        })
        .collect();
    for (part, a) in per_quad.into_iter().flatten() {
        normals[part].push(a);
    }
    LabelFidelity {
        surface: Stat::of(&parts[0]),
        inner: Stat::of(&parts[1]),
        junction: Stat::of(&parts[2]),
        points: Stat::of(&parts[3]),
        surface_normals: Stat::of(&normals[0]),
        inner_normals: Stat::of(&normals[1]),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shapes() -> Vec<Box<dyn LabelShape>> {
        vec![
            Box::new(SplitBall { radius: 6.0, cut: 0.5 }),
            Box::new(QuarteredBall {
                radius: 6.0,
                centre: DVec3::new(0.5, 0.0, 0.5),
                cuts: glam::DVec2::splat(0.5),
            }),
            Box::new(TouchingBalls::default()),
        ]
    }

    #[test]
    fn interface_points_separate_their_labels_and_are_nearest() {
        // A brute-force check: points of each interface found by bisection between
        // neighbouring lattice samples of different labels are on it (distance ~0), and
        // the nearest-point query never does worse than any of them.
        for shape in shapes() {
            let (lo, hi) = shape.bounds();
            let h = 0.37;
            let mut found = 0;
            let mut z = lo.z - 1.0;
            while z < hi.z + 1.0 {
                let mut y = lo.y - 1.0;
                while y < hi.y + 1.0 {
                    let mut x = lo.x - 1.0;
                    while x < hi.x + 1.0 {
                        let p = DVec3::new(x, y, z);
                        let q = p + DVec3::new(h, 0.0, 0.0);
                        let (la, lb) = (shape.label(p), shape.label(q));
                        if la != lb {
                            let (mut s, mut t) = (p, q);
                            for _ in 0..50 {
                                let m = 0.5 * (s + t);
                                if shape.label(m) == la {
                                    s = m
                                } else {
                                    t = m
                                }
                            }
                            let (la, lb) = (shape.label(s), shape.label(t));
                            let (a, b) = (la.min(lb), la.max(lb));
                            let (on, n) = shape.interface(a, b, s).expect("the labels meet");
                            assert!(on.distance(s) < 1e-6, "{}: {a}|{b} at {s}: nearest {on}", shape.name());
                            assert!((n.length() - 1.0).abs() < 1e-9);
                            // Off the surface, the query is no farther than this sample.
                            let off = s + DVec3::new(0.3, -0.2, 0.1);
                            let (q2, _) = shape.interface(a, b, off).unwrap();
                            assert!(
                                q2.distance(off) <= s.distance(off) + 1e-9,
                                "{}: not nearest",
                                shape.name()
                            );
                            found += 1;
                        }
                        x += h;
                    }
                    y += 2.0 * h;
                }
                z += 2.0 * h;
            }
            assert!(found > 100, "{}: {found}", shape.name());
        }
    }

    #[test]
    fn junction_points_are_on_every_meeting_interface() {
        for shape in shapes() {
            let (lo, hi) = shape.bounds();
            let surface = DigitalSurface::from_volume(&digitize_labels(shape.as_ref(), DVec3::ONE)).unwrap();
            let labels = vertex_labels(&surface);
            let mut curves = 0;
            for (v, l) in labels.iter().enumerate().filter(|(_, l)| l.len() >= 3) {
                let p = surface.positions()[v];
                let Some((q, kind)) = shape.junction(l, p) else { continue };
                assert!(q.cmpge(lo - 1e-9).all() && q.cmple(hi + 1e-9).all());
                if kind == JunctionKind::Curve {
                    curves += 1;
                    // Every pair of the labels that share an interface has it through q.
                    for (i, &a) in l.iter().enumerate() {
                        for &b in &l[i + 1..] {
                            if let Some((on, _)) = shape.interface(a, b, q) {
                                assert!(on.distance(q) < 1e-6, "{}: {a}|{b} misses {q}", shape.name());
                            }
                        }
                    }
                }
                assert!(p.distance(q) < 1.5, "{}: vertex {p} far from its junction {q}", shape.name());
            }
            assert!(curves > 10, "{}: {curves}", shape.name());
        }
    }
}
