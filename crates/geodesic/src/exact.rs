//! Exact polyhedral geodesics by window propagation: the improved Chen-Han algorithm
//! (Xin and Wang 2009), on the triangles of a [`GeodesicMesh`].

use std::f64::consts::PI;

use glam::DVec2;

use crate::{GeodesicError, GeodesicMesh, SurfacePoint};

/// What one exact run did.
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq)]
pub struct ExactInfo {
    /// Windows created (pushed on the queue).
    pub windows: usize,
    /// Windows propagated (popped and not filtered out).
    pub propagated: usize,
    /// Pseudo-sources expanded (sources, and saddle or boundary vertices).
    pub pseudo_sources: usize,
}

/// The id of a vertex event on the queue (its `tri` is the vertex).
const VERTEX: u32 = u32::MAX;
/// Slack, in radians, of the angle tests around a pseudo-source.
const ANGLE_SLACK: f64 = 1e-9;

/// A window: an interval `[b0, b1]` of side `k` of triangle `tri`, seen straight from a
/// (pseudo-)source unfolded into the side's frame, about to be propagated into `tri`.
///
/// Frame: corner `k` of `tri` at the origin, corner `k + 1` at `(len, 0)`, the third
/// corner at positive `y`; the source at `s` (`s.y < 0`), at geodesic distance `sigma`
/// from the nearest real source. `id` numbers the windows in creation order.
#[derive(Copy, Clone, Debug)]
struct Window {
    tri: u32,
    id: u32,
    k: u8,
    b0: f64,
    b1: f64,
    s: DVec2,
    sigma: f64,
}

impl Window {
    /// The least distance the window gives to a point of its interval.
    fn key(&self) -> f64 {
        let x = self.s.x.clamp(self.b0, self.b1);
        self.sigma + self.s.distance(DVec2::new(x, 0.0))
    }

    fn at(&self, x: f64) -> f64 {
        self.sigma + self.s.distance(DVec2::new(x, 0.0))
    }

    /// Whether `self` gives a shorter distance than `other` on all of `[lo, hi]` (both
    /// windows on the same side). Where they are equal, `sigma1 + |s1 x| = sigma2 +
    /// |s2 x|`, squaring twice leaves a quadratic in `x`: shorter at both ends and no
    /// root between means shorter throughout.
    fn shorter(&self, other: &Window, lo: f64, hi: f64) -> bool {
        let margin = 1e-12 * (1.0 + self.sigma.max(other.sigma));
        let ends_shorter = other.at(lo) - self.at(lo) > margin && other.at(hi) - self.at(hi) > margin;
        if !ends_shorter {
            return false;
        }
        let (a1, c1, a2, c2) = (self.s.x, self.s.y, other.s.x, other.s.y);
        let d = self.sigma - other.sigma;
        let alpha = 2.0 * (a1 - a2);
        let beta = a2 * a2 - a1 * a1 + c2 * c2 - c1 * c1 - d * d;
        let qa = 4.0 * d * d - alpha * alpha;
        let qb = -8.0 * d * d * a1 - 2.0 * alpha * beta;
        let qc = 4.0 * d * d * (a1 * a1 + c1 * c1) - beta * beta;
        let inside = |x: f64| x > lo && x < hi;
        let scale = qa.abs().max(qb.abs()).max(qc.abs());
        if scale == 0.0 {
            return true;
        }
        if qa.abs() <= 1e-12 * scale {
            return qb == 0.0 || !inside(-qc / qb);
        }
        let disc = qb * qb - 4.0 * qa * qc;
        if disc < 0.0 {
            return true;
        }
        let r = disc.sqrt();
        !inside((-qb - r) / (2.0 * qa)) && !inside((-qb + r) / (2.0 * qa))
    }
}

/// The queue of windows and vertex events (windows with the id [`VERTEX`]), by value,
/// least key first: a radix heap (Ahuja, Mehlhorn, Orlin and Tarjan 1990) on the keys' bits, which
/// order as the keys do for keys `>= 0`. It needs the keys pushed to be no less than the
/// last popped, as here, where a window's children and a vertex's windows lie farther
/// than it (a key lower by rounding is raised to the last one). Each entry moves down
/// the 65 buckets at most once per bit, through sequential memory, where a binary heap
/// of millions of entries misses the cache at every level. Entries are carried by
/// value: popped in key order, a window looked up by id in an arena missed the cache.
struct Queue<T> {
    buckets: Vec<Vec<(u64, T)>>,
    last: u64,
}

impl<T: Copy> Queue<T> {
    fn new() -> Self {
        Queue { buckets: vec![Vec::new(); 65], last: 0 }
    }

    fn bucket(x: u64) -> usize {
        (64 - x.leading_zeros()) as usize
    }

    fn push(&mut self, key: f64, id: T) {
        let bits = (key + 0.0).to_bits().max(self.last);
        self.buckets[Self::bucket(bits ^ self.last)].push((bits, id));
    }

    fn pop(&mut self) -> Option<(f64, T)> {
        if self.buckets[0].is_empty() {
            let i = (1..self.buckets.len()).find(|&i| !self.buckets[i].is_empty())?;
            let mut items = std::mem::take(&mut self.buckets[i]);
            self.last = items.iter().map(|e| e.0).min().expect("a non-empty bucket");
            // Every entry shares the bits above `i` with the new least key: each goes
            // to a lower bucket.
            for &e in &items {
                self.buckets[Self::bucket(e.0 ^ self.last)].push(e);
            }
            items.clear();
            self.buckets[i] = items;
        }
        self.buckets[0].pop().map(|(bits, id)| (f64::from_bits(bits), id))
    }
}

/// A triangle side's frame: its length and the third corner (`y >= 0`).
#[derive(Copy, Clone)]
struct Frame {
    len: f64,
    apex: DVec2,
}

/// Another triangle on a side's edge: its side `k` there, and whether that side runs
/// the same way (from the same corner).
#[derive(Copy, Clone)]
struct Link {
    tri: u32,
    k: u8,
    forward: bool,
}

/// The direction back along the shortest path found to a vertex: corner `corner` of
/// triangle `tri` is the vertex, and the direction makes `angle` with the side towards
/// corner `corner + 1`, counted towards corner `corner + 2` (outside `[0, corner
/// angle]` when the path arrives through another triangle of the fan).
#[derive(Copy, Clone)]
struct Arrival {
    tri: u32,
    corner: u8,
    angle: f64,
}

/// Where the shortest path found to a vertex crossed the side (`3 tri + k`) of the
/// window that found it, the vertex being that triangle's apex.
#[derive(Copy, Clone)]
struct Split {
    side: u32,
    crossing: f64,
}

struct Propagation<'m> {
    mesh: &'m GeodesicMesh,
    /// Per triangle side (`3 tri + k`).
    frames: Vec<Frame>,
    /// The other triangles on each side's edge: `links[link_offsets[side]..link_offsets[side + 1]]`.
    link_offsets: Vec<u32>,
    links: Vec<Link>,
    /// Per side, copies of the windows kept there, for trimming later windows
    /// (contiguous: scanning them is most of the work on large meshes).
    kept: Vec<Vec<Window>>,
    /// Bits by window id: windows found longer, over all their interval, than a later
    /// one on their side, skipped when popped.
    dead: Vec<u64>,
    dist: Vec<f64>,
    arrival: Vec<Option<Arrival>>,
    split: Vec<Option<Split>>,
    queue: Queue<Window>,
    info: ExactInfo,
    /// Intervals shorter than this (relative to the mesh scale) are dropped.
    tiny: f64,
    /// Scratch: parts of a new window covered by kept ones, and what is left.
    covered: Vec<(f64, f64)>,
    pieces: Vec<(f64, f64)>,
    /// Scratch: per triangle around a pseudo-source, the angles it is open over.
    open: Vec<(f64, f64)>,
}

/// Exact geodesic distance on the polyhedral surface of `mesh` from the nearest of
/// `sources` (vertex indices) at every vertex; `f64::INFINITY` where unreached.
///
/// Spec: windows (intervals of edges seen straight from one unfolded source) are
/// propagated across triangles in order of their least distance (Chen and Han 1990),
/// with the improvements of Xin and Wang 2009: a window is dropped when a vertex of its
/// triangle already reaches every point of it by a shorter path (`d(v) + |v x| < sigma +
/// |s x|`, checked where it decides for the whole interval), and a window seeing a
/// vertex that an earlier window reached by a shorter path through the same side keeps
/// only its child on its own side of that path (one angle, one split). As in
/// Mitchell-Mount-Papadimitriou, a new window loses the parts of its interval where a
/// window already on the same side is shorter, and a window it is shorter than
/// everywhere is dropped. Saddle vertices (angle sum above `2 pi`, see
/// [`GeodesicMesh`]) and vertices on boundary or non-manifold edges become
/// pseudo-sources once final; a shortest path through a vertex turns by at least `pi`
/// on both sides, so a saddle sends windows only into its shadow, the directions within
/// `[pi, Theta - pi]` of the one its shortest path arrives from (`Theta` its angle sum).
/// Every rule only drops windows that another path dominates, so the distances are exact
/// up to rounding. The run works on a copy of the mesh renumbered along a space-filling
/// curve (for the cache); the result is in `mesh`'s numbering.
pub fn exact_distances(mesh: &GeodesicMesh, sources: &[u32]) -> Result<(Vec<f64>, ExactInfo), GeodesicError> {
    mesh.check_sources(sources)?;
    let (local, vertex_ids, _) = mesh.spatially_ordered()?;
    let mut run = Propagation::new(&local);
    for &s in sources {
        run.start_vertex(vertex_ids[s as usize]);
    }
    run.run();
    Ok((vertex_ids.iter().map(|&v| run.dist[v as usize]).collect(), run.info))
}

/// An upper estimate of the memory [`exact_distances`] takes on a mesh of `triangles`
/// triangles, in bytes, so that a caller can refuse a run that cannot fit before it
/// starts: the windows grow faster than the mesh (21 per triangle on 27k triangles, 37
/// on 110k, about as the square root of the size), so the estimate is
/// `40 T max(1, (T / 10^5)^(1/2))` windows of 128 bytes (a window queued and kept, with
/// the vectors' growth), plus the mesh's renumbered copy.
pub fn exact_estimated_bytes(triangles: usize) -> u64 {
    let t = triangles as f64;
    let windows = 40.0 * t * (t / 1e5).sqrt().max(1.0);
    (windows * 128.0 + t * 200.0).min(u64::MAX as f64) as u64
}

/// [`exact_distances`] from points anywhere on the surface (on a triangle, an edge or
/// a vertex), such as [`GeodesicMesh::nearest_point`] gives.
pub fn exact_distances_from(
    mesh: &GeodesicMesh,
    sources: &[SurfacePoint],
) -> Result<(Vec<f64>, ExactInfo), GeodesicError> {
    mesh.check_points(sources)?;
    let (local, vertex_ids, triangle_ids) = mesh.spatially_ordered()?;
    let mut run = Propagation::new(&local);
    for &p in sources {
        let p = SurfacePoint { triangle: triangle_ids[p.triangle as usize], ..p };
        match local.snap(p) {
            Snapped::Vertex(v) => run.start_vertex(v),
            Snapped::Point(tris, point) => {
                for t in tris {
                    run.start_in_triangle(t, point);
                }
            }
        }
    }
    run.run();
    Ok((vertex_ids.iter().map(|&v| run.dist[v as usize]).collect(), run.info))
}

/// A source point, placed: a vertex, or a position on the triangles listed (one, or
/// those on the edge it lies on).
pub(crate) enum Snapped {
    Vertex(u32),
    Point(Vec<u32>, glam::DVec3),
}

/// Corner `k`, `k + 1`, `k + 2` of `tri`.
fn corners(tri: [u32; 3], k: usize) -> [u32; 3] {
    [tri[k], tri[(k + 1) % 3], tri[(k + 2) % 3]]
}

/// The point where the ray from `from` at `angle` (radians, counterclockwise from the
/// direction to the origin) meets the x axis, as a parameter in `[0, len]`.
fn ray_hit(from: DVec2, angle: f64, len: f64) -> f64 {
    let u = (-from).normalize_or_zero();
    let (sin, cos) = angle.sin_cos();
    let d = DVec2::new(u.x * cos - u.y * sin, u.x * sin + u.y * cos);
    if d.y >= 0.0 {
        return len;
    }
    (from.x - from.y / d.y * d.x).clamp(0.0, len)
}

impl<'m> Propagation<'m> {
    fn new(mesh: &'m GeodesicMesh) -> Self {
        let sides = 3 * mesh.triangles.len();
        let mut frames = Vec::with_capacity(sides);
        let mut link_offsets = Vec::with_capacity(sides + 1);
        let mut links = Vec::with_capacity(sides);
        link_offsets.push(0);
        for (t, &tri) in mesh.triangles.iter().enumerate() {
            for k in 0..3 {
                let [a, b, c] = corners(tri, k);
                let (pa, pb, pc) = (mesh.pos(a), mesh.pos(b), mesh.pos(c));
                let len = pa.distance(pb);
                let (l1, l2) = (pa.distance(pc), pb.distance(pc));
                let x = if len > 0.0 { (len * len + l1 * l1 - l2 * l2) / (2.0 * len) } else { 0.0 };
                let y = (l1 * l1 - x * x).max(0.0).sqrt();
                frames.push(Frame { len, apex: DVec2::new(x, y) });
                for &t2 in mesh.edge_tris(mesh.triangle_edges[t][k]) {
                    if t2 as usize == t {
                        continue;
                    }
                    let other = mesh.triangles[t2 as usize];
                    if let Some(k2) = (0..3).find(|&i| {
                        let (p, q) = (other[i], other[(i + 1) % 3]);
                        (p == a && q == b) || (p == b && q == a)
                    }) {
                        links.push(Link { tri: t2, k: k2 as u8, forward: other[k2] == a });
                    }
                }
                link_offsets.push(links.len() as u32);
            }
        }
        let n = mesh.num_vertices();
        Propagation {
            mesh,
            frames,
            link_offsets,
            links,
            kept: vec![Vec::new(); sides],
            dead: Vec::new(),
            dist: vec![f64::INFINITY; n],
            arrival: vec![None; n],
            split: vec![None; n],
            queue: Queue::new(),
            info: ExactInfo::default(),
            tiny: 1e-12 * mesh.mean_edge_length().max(f64::MIN_POSITIVE),
            covered: Vec::new(),
            pieces: Vec::new(),
            open: Vec::new(),
        }
    }

    fn start_vertex(&mut self, v: u32) {
        self.dist[v as usize] = 0.0;
        self.arrival[v as usize] = None;
        self.queue.push(0.0, Self::vertex_event(v));
    }

    fn vertex_event(v: u32) -> Window {
        Window { tri: v, id: VERTEX, k: 0, b0: 0.0, b1: 0.0, s: DVec2::ZERO, sigma: 0.0 }
    }

    /// A source at `point` on triangle `t`: its corners directly, and a window across
    /// each side that does not hold the point.
    fn start_in_triangle(&mut self, t: u32, point: glam::DVec3) {
        let mesh = self.mesh;
        let tri = mesh.triangles[t as usize];
        for k in 0..3 {
            let [a, b, _] = corners(tri, k);
            let (pa, pb) = (mesh.pos(a), mesh.pos(b));
            // Corner k, the path arriving from the point.
            if self.lower(a, pa.distance(point)) {
                let angle = (pb - pa).angle_between(point - pa);
                self.arrival[a as usize] = Some(Arrival { tri: t, corner: k as u8, angle });
                self.split[a as usize] = None;
            }
            let frame = self.frames[3 * t as usize + k];
            if frame.len <= 0.0 {
                continue;
            }
            let u = (pb - pa) / frame.len;
            let x = (point - pa).dot(u);
            let y = (point - pa - x * u).length();
            if y <= self.tiny {
                continue;
            }
            let ends = [DVec2::ZERO, DVec2::new(frame.len, 0.0)];
            self.cross_side(3 * t as usize + k, ends, frame.apex, 0.0, frame.len, DVec2::new(x, y), 0.0);
        }
    }

    fn run(&mut self) {
        let n = self.mesh.num_vertices();
        let mut expanded = vec![false; n];
        while let Some((_, w)) = self.queue.pop() {
            if w.id == VERTEX {
                // The first of a vertex's events popped is its least distance's (the
                // queue's keys were raised by at most rounding).
                let v = w.tri;
                if expanded[v as usize] {
                    continue;
                }
                expanded[v as usize] = true;
                self.info.pseudo_sources += 1;
                self.expand_vertex(v);
            } else {
                if self.dead[w.id as usize / 64] >> (w.id % 64) & 1 != 0 || self.dominated(&w) {
                    continue;
                }
                self.info.propagated += 1;
                self.propagate(&w);
            }
        }
    }

    /// Lowers the distance of `v` to `d` if shorter (the caller then records how it
    /// arrived); a lowered bend vertex is queued as a pseudo-source.
    fn lower(&mut self, v: u32, d: f64) -> bool {
        if d < self.dist[v as usize] {
            self.dist[v as usize] = d;
            if self.mesh.bends[v as usize] {
                self.queue.push(d, Self::vertex_event(v));
            }
            true
        } else {
            false
        }
    }

    fn frame(&self, tri: u32, k: usize) -> Frame {
        self.frames[3 * tri as usize + k]
    }

    /// A pseudo-source at `v`: its neighbours directly, and a window over the part of
    /// the far side of every triangle around it that a shortest path through `v` can
    /// enter (its shadow).
    fn expand_vertex(&mut self, v: u32) {
        let mesh = self.mesh;
        let dv = self.dist[v as usize];
        let restricted = self.shadow(v);
        for (i, &t) in mesh.vertex_tris(v).iter().enumerate() {
            let tri = mesh.triangles[t as usize];
            let j = tri.iter().position(|&x| x == v).expect("vertex of its triangle");
            // The side opposite v: corners j+1, j+2 (side k = j + 1 of t).
            let k = (j + 1) % 3;
            let Frame { len, apex } = self.frame(t, k);
            let [a, b, _] = corners(tri, k);
            // Corner k (a) sees v at its corner angle, corner k + 1 (b) along its side.
            if self.lower(a, dv + apex.length()) {
                let angle = apex.y.atan2(apex.x);
                self.arrival[a as usize] = Some(Arrival { tri: t, corner: k as u8, angle });
                self.split[a as usize] = None;
            }
            if self.lower(b, dv + apex.distance(DVec2::new(len, 0.0))) {
                self.arrival[b as usize] = Some(Arrival { tri: t, corner: ((k + 1) % 3) as u8, angle: 0.0 });
                self.split[b as usize] = None;
            }
            let (t0, t1) = if restricted {
                let (lo, hi) = self.open[i];
                if lo.is_nan() || hi < lo {
                    continue;
                }
                let corner = (-apex).angle_to(DVec2::new(len, 0.0) - apex).abs();
                let t0 = if lo <= 0.0 { 0.0 } else { ray_hit(apex, lo, len) };
                let t1 = if hi >= corner { len } else { ray_hit(apex, hi, len) };
                (t0, t1)
            } else {
                (0.0, len)
            };
            // In the frame of side k of t the source is the apex; the window goes into
            // every other triangle on that side.
            self.cross_side(3 * t as usize + k, [DVec2::ZERO, DVec2::new(len, 0.0)], apex, t0, t1, apex, dv);
        }
    }

    /// Fills `open` with, per triangle around `v` (in `vertex_tris` order), the angles
    /// at `v` (from its side towards the next corner after `v`, as in [`Arrival`]) a
    /// shortest path through `v` can continue into (`(NAN, NAN)` for none); `false`
    /// when every direction is open.
    ///
    /// A shortest path through a vertex turns by at least `pi` on both sides (otherwise
    /// it shortens around the vertex), so from the direction it arrives from, measured
    /// around `v` (total angle `Theta`), it leaves within `[pi, Theta - pi]`: only the
    /// saddle's shadow. Known when the path's arrival at `v` is and `v`'s triangles form
    /// one fan of manifold edges.
    fn shadow(&mut self, v: u32) -> bool {
        let Some(arrival) = self.arrival[v as usize] else {
            return false;
        };
        let mesh = self.mesh;
        let fan = mesh.vertex_tris(v);
        let pv = mesh.pos(v);
        self.open.clear();
        self.open.resize(fan.len(), (f64::NAN, f64::NAN));
        // Per triangle of the fan: the walk's angle where it starts, its corner angle,
        // and whether the walk crosses it against the corner order.
        let mut spans = [(f64::NAN, 0.0, false); 32];
        if fan.len() > spans.len() {
            return false;
        }
        let start = mesh.triangles[arrival.tri as usize];
        let j = arrival.corner as usize;
        let (mut t, mut from, mut to, mut phi) = (arrival.tri, start[(j + 1) % 3], start[(j + 2) % 3], 0.0);
        for _ in 0..fan.len() {
            let Some(i) = fan.iter().position(|&x| x == t) else {
                return false;
            };
            let tri = mesh.triangles[t as usize];
            let jt = tri.iter().position(|&x| x == v).expect("vertex of its triangle");
            let angle = (mesh.pos(from) - pv).angle_between(mesh.pos(to) - pv);
            spans[i] = (phi, angle, tri[(jt + 1) % 3] != from);
            phi += angle;
            // Across the side v-to into the next triangle of the fan.
            let Some(side) = (0..3).find(|&s| {
                let (p, q) = (tri[s], tri[(s + 1) % 3]);
                (p == v && q == to) || (p == to && q == v)
            }) else {
                return false;
            };
            let side = 3 * t as usize + side;
            let (l0, l1) = (self.link_offsets[side] as usize, self.link_offsets[side + 1] as usize);
            if l1 - l0 != 1 {
                return false;
            }
            t = self.links[l0].tri;
            let next = mesh.triangles[t as usize];
            from = to;
            let Some(&x) = next.iter().find(|&&x| x != v && x != from) else {
                return false;
            };
            to = x;
        }
        if t != arrival.tri || spans[..fan.len()].iter().any(|s| s.0.is_nan()) {
            return false;
        }
        let theta = phi;
        let back = arrival.angle.rem_euclid(theta);
        let (lo, hi) = (back + PI - ANGLE_SLACK, back + theta - PI + ANGLE_SLACK);
        for (i, &(p0, angle, reversed)) in spans[..fan.len()].iter().enumerate() {
            let (mut a, mut b) = (f64::INFINITY, f64::NEG_INFINITY);
            for shift in [0.0, theta] {
                let (x, y) = ((lo - shift).max(p0), (hi - shift).min(p0 + angle));
                if y >= x {
                    a = a.min(x - p0);
                    b = b.max(y - p0);
                }
            }
            if b >= a {
                self.open[i] = if reversed { (angle - b, angle - a) } else { (a, b) };
            }
        }
        true
    }

    /// Queues the windows continuing interval `[t0, t1]` (from corner `k` towards corner
    /// `k + 1` of the side `side = 3 tri + k`) into the other triangles on that side.
    /// `ends` are the side's two corners and `other` the third corner of `tri`, all in
    /// the frame `s` is in.
    #[allow(clippy::too_many_arguments)]
    fn cross_side(
        &mut self,
        side: usize,
        ends: [DVec2; 2],
        other: DVec2,
        t0: f64,
        t1: f64,
        s: DVec2,
        sigma: f64,
    ) {
        if t1 - t0 <= self.tiny {
            return;
        }
        let len = ends[0].distance(ends[1]);
        for l in self.link_offsets[side]..self.link_offsets[side + 1] {
            let Link { tri, k, forward } = self.links[l as usize];
            let (origin, end) = if forward { (ends[0], ends[1]) } else { (ends[1], ends[0]) };
            let u = (end - origin) / len;
            let mut v = u.perp();
            if (other - origin).dot(v) > 0.0 {
                v = -v;
            }
            let rel = s - origin;
            let s2 = DVec2::new(rel.dot(u), rel.dot(v));
            let (b0, b1) = if forward { (t0, t1) } else { (len - t1, len - t0) };
            if s2.y > -self.tiny {
                continue;
            }
            self.push(Window { tri, id: 0, k, b0: b0.max(0.0), b1: b1.min(len), s: s2, sigma });
        }
    }

    /// Queues what is left of `w` once the parts where a window already on its side is
    /// shorter are cut out (none of it if a vertex dominates it), and drops the windows
    /// there that it is shorter than on all of their interval.
    fn push(&mut self, w: Window) {
        if w.b1 - w.b0 <= self.tiny || self.dominated(&w) {
            return;
        }
        let side = 3 * w.tri as usize + w.k as usize;
        self.covered.clear();
        let mut i = 0;
        while i < self.kept[side].len() {
            let old = self.kept[side][i];
            let (lo, hi) = (old.b0.max(w.b0), old.b1.min(w.b1));
            if hi - lo > self.tiny {
                if old.shorter(&w, lo, hi) {
                    self.covered.push((lo, hi));
                } else if lo == old.b0 && hi == old.b1 && w.shorter(&old, lo, hi) {
                    // `w` (or, where `w` is cut out, a window shorter still) is shorter
                    // on all of it: no longer kept, and skipped if still queued.
                    self.dead[old.id as usize / 64] |= 1 << (old.id % 64);
                    self.kept[side].swap_remove(i);
                    continue;
                }
            }
            i += 1;
        }
        self.covered.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
        self.pieces.clear();
        let mut start = w.b0;
        for &(lo, hi) in &self.covered {
            if lo > start + self.tiny {
                self.pieces.push((start, lo));
            }
            start = start.max(hi);
        }
        if w.b1 > start + self.tiny {
            self.pieces.push((start, w.b1));
        }
        for p in 0..self.pieces.len() {
            let (b0, b1) = self.pieces[p];
            let id = u32::try_from(self.info.windows)
                .ok()
                .filter(|&id| id != VERTEX)
                .expect("fewer than 2^32 - 1 windows");
            let piece = Window { b0, b1, id, ..w };
            if id % 64 == 0 {
                self.dead.push(0);
            }
            self.kept[side].push(piece);
            self.info.windows += 1;
            self.queue.push(piece.key(), piece);
        }
    }

    /// Whether a vertex of the window's triangle reaches all of its interval by a shorter
    /// path.
    ///
    /// For an end `v` of the side, `d(v) + |v x| - (sigma + |s x|)` only grows towards
    /// `v` along the side (`|s x|` changes by at most the distance moved), so the far end
    /// of the interval decides. For the apex `c`, the points where
    /// `|s x| - |c x| >= m`, `m >= 0`, form a convex set (the focus-`c` side of a
    /// hyperbola branch, a half-plane for `m = 0`): with `m = max(d(c) - sigma, 0)`, both
    /// ends of the interval in it put the whole interval in it.
    fn dominated(&self, w: &Window) -> bool {
        let [a, b, c] = corners(self.mesh.triangles[w.tri as usize], w.k as usize);
        let Frame { len, apex: pc } = self.frame(w.tri, w.k as usize);
        let ends = [DVec2::new(w.b0, 0.0), DVec2::new(w.b1, 0.0)];
        let via_source = |x: DVec2| w.sigma + w.s.distance(x);
        let margin = 1e-12 * (1.0 + w.sigma);
        if self.dist[a as usize] + w.b1 + margin < via_source(ends[1])
            || self.dist[b as usize] + (len - w.b0) + margin < via_source(ends[0])
        {
            return true;
        }
        let dc = self.dist[c as usize];
        dc.is_finite() && {
            let m = (dc - w.sigma).max(0.0) + margin;
            ends.iter().all(|&x| w.s.distance(x) - pc.distance(x) > m)
        }
    }

    /// Propagates `w` across its triangle: the apex's distance, and the children on the
    /// two far sides.
    fn propagate(&mut self, w: &Window) {
        let tri = self.mesh.triangles[w.tri as usize];
        let k = w.k as usize;
        let [a, b, c] = corners(tri, k);
        let Frame { len, apex: pc } = self.frame(w.tri, k);
        let (pa, pb) = (DVec2::ZERO, DVec2::new(len, 0.0));
        if w.b0 <= self.tiny && self.lower(a, w.sigma + w.s.length()) {
            let angle = w.s.y.atan2(w.s.x);
            self.arrival[a as usize] = Some(Arrival { tri: w.tri, corner: k as u8, angle });
            self.split[a as usize] = None;
        }
        if w.b1 >= len - self.tiny && self.lower(b, w.sigma + w.s.distance(pb)) {
            // Through the triangles behind side k (the window's), so in (angle at b,
            // angle at b + pi), as the plane of the unfolding measures it.
            let angle = (pc - pb).angle_to(w.s - pb).rem_euclid(2.0 * PI);
            self.arrival[b as usize] = Some(Arrival { tri: w.tri, corner: ((k + 1) % 3) as u8, angle });
            self.split[b as usize] = None;
        }
        // Where the ray from the source to the apex crosses the side.
        let dy = pc.y - w.s.y;
        let tc = if dy > 0.0 { w.s.x + (pc.x - w.s.x) * (-w.s.y) / dy } else { f64::NAN };
        let mut left = w.b0 < tc;
        let mut right = w.b1 > tc;
        let side = (3 * w.tri as usize + k) as u32;
        if w.b0 <= tc && tc <= w.b1 {
            if self.lower(c, w.sigma + w.s.distance(pc)) {
                let angle = (pa - pc).angle_to(w.s - pc);
                self.arrival[c as usize] = Some(Arrival { tri: w.tri, corner: ((k + 2) % 3) as u8, angle });
                self.split[c as usize] = Some(Split { side, crossing: tc });
            } else if let Some(o) = self.split[c as usize] {
                if o.side == side {
                    // A shorter path to c crosses the side at o.crossing: this window
                    // loses on the far side of it.
                    if w.b0 >= o.crossing {
                        left = false;
                    }
                    if w.b1 <= o.crossing {
                        right = false;
                    }
                }
            }
        }
        if tc.is_nan() {
            left = true;
            right = false;
        }
        let ray = |b: f64, p: DVec2, q: DVec2| -> f64 {
            // Parameter (length from p) where the ray from s through (b, 0) meets line pq.
            let d = DVec2::new(b, 0.0) - w.s;
            let e = q - p;
            let denom = e.perp_dot(d);
            let mu = if denom.abs() > 0.0 { (w.s - p).perp_dot(d) / denom } else { 0.0 };
            (mu.clamp(0.0, 1.0)) * e.length()
        };
        // Side k + 2 of the triangle runs from c to a; side k + 1 from b to c.
        if left {
            // On side (a, c), parameters from a.
            let lac = pc.length();
            let t0 = ray(w.b0, pa, pc);
            let t1 = if w.b1 >= tc { lac } else { ray(w.b1, pa, pc) };
            // Side k + 2 runs c -> a: parameters from c.
            let side = 3 * w.tri as usize + (k + 2) % 3;
            self.cross_side(side, [pc, pa], pb, lac - t1, lac - t0, w.s, w.sigma);
        }
        if right {
            // On side (b, c), parameters from b.
            let lbc = pb.distance(pc);
            let t0 = ray(w.b1, pb, pc);
            let t1 = if w.b0 <= tc { lbc } else { ray(w.b0, pb, pc) };
            // Side k + 1 runs b -> c.
            let side = 3 * w.tri as usize + (k + 1) % 3;
            self.cross_side(side, [pb, pc], pa, t0, t1, w.s, w.sigma);
        }
    }
}

#[cfg(test)]
pub(crate) mod tests;
