//! Exact polyhedral geodesics by window propagation: the improved Chen-Han algorithm
//! (Xin and Wang 2009), on the triangles of a [`GeodesicMesh`].

use std::cmp::Ordering;
use std::collections::BinaryHeap;

use glam::DVec2;

use crate::{GeodesicError, GeodesicMesh};

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

/// A window: an interval `[b0, b1]` of side `k` of triangle `tri`, seen straight from a
/// (pseudo-)source unfolded into the side's frame, about to be propagated into `tri`.
///
/// Frame: corner `k` of `tri` at the origin, corner `k + 1` at `(len, 0)`, the third
/// corner at positive `y`; the source at `s` (`s.y < 0`), at geodesic distance `sigma`
/// from the nearest real source.
#[derive(Copy, Clone, Debug)]
struct Window {
    tri: u32,
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
}

enum Event {
    Window(Window),
    Vertex(u32),
}

struct Queued {
    key: f64,
    event: Event,
}

impl PartialEq for Queued {
    fn eq(&self, other: &Self) -> bool {
        self.key.total_cmp(&other.key) == Ordering::Equal
    }
}
impl Eq for Queued {}
impl PartialOrd for Queued {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Queued {
    // Reversed: the max-heap pops the least key first.
    fn cmp(&self, other: &Self) -> Ordering {
        other.key.total_cmp(&self.key)
    }
}

/// The window through which a vertex got its distance: the side it was seen through and
/// where the shortest path crossed that side (for the one-angle-one-split rule).
#[derive(Copy, Clone)]
struct Occupant {
    tri: u32,
    k: u8,
    crossing: f64,
    /// The window's source, in the frame of side `k` of `tri`.
    source: DVec2,
}

/// A window kept on its side, for trimming later windows there.
#[derive(Copy, Clone)]
struct Kept {
    b0: f64,
    b1: f64,
    s: DVec2,
    sigma: f64,
}

impl Kept {
    fn at(&self, x: f64) -> f64 {
        self.sigma + self.s.distance(DVec2::new(x, 0.0))
    }

    /// Whether `self` gives a shorter distance than `other` on all of `[lo, hi]` (both
    /// windows on the same side). Where they are equal, `sigma1 + |s1 x| = sigma2 +
    /// |s2 x|`, squaring twice leaves a quadratic in `x`: shorter at both ends and no
    /// root between means shorter throughout.
    fn shorter(&self, other: &Kept, lo: f64, hi: f64) -> bool {
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

struct Propagation<'m> {
    mesh: &'m GeodesicMesh,
    /// Windows queued so far on each triangle side (`3 * tri + k`).
    kept: Vec<Vec<Kept>>,
    dist: Vec<f64>,
    occupant: Vec<Option<Occupant>>,
    queue: BinaryHeap<Queued>,
    info: ExactInfo,
    /// Intervals shorter than this (relative to the mesh scale) are dropped.
    tiny: f64,
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
/// window already on the same side is shorter. Saddle vertices
/// (angle sum at least `2 pi`) and vertices on boundary or non-manifold edges become
/// pseudo-sources once final, a saddle reached by a window only into its shadow (where a
/// shortest path through it turns by at least `pi` on both sides). Every rule only drops windows that another path dominates,
/// so the distances are exact up to rounding.
pub fn exact_distances(mesh: &GeodesicMesh, sources: &[u32]) -> Result<(Vec<f64>, ExactInfo), GeodesicError> {
    mesh.check_sources(sources)?;
    let n = mesh.num_vertices();
    let mut run = Propagation {
        mesh,
        kept: vec![Vec::new(); 3 * mesh.triangles.len()],
        dist: vec![f64::INFINITY; n],
        occupant: vec![None; n],
        queue: BinaryHeap::new(),
        info: ExactInfo::default(),
        tiny: 1e-12 * mesh.mean_edge_length().max(f64::MIN_POSITIVE),
    };
    for &s in sources {
        run.dist[s as usize] = 0.0;
        run.queue.push(Queued { key: 0.0, event: Event::Vertex(s) });
    }
    let mut expanded = vec![false; n];
    while let Some(Queued { key, event }) = run.queue.pop() {
        match event {
            Event::Vertex(v) => {
                if expanded[v as usize] || key > run.dist[v as usize] {
                    continue;
                }
                expanded[v as usize] = true;
                run.info.pseudo_sources += 1;
                run.expand_vertex(v);
            }
            Event::Window(w) => {
                if run.dominated(&w) {
                    continue;
                }
                run.info.propagated += 1;
                run.propagate(&w);
            }
        }
    }
    Ok((run.dist, run.info))
}

/// Corner `k`, `k + 1`, `k + 2` of `tri`.
fn corners(tri: [u32; 3], k: usize) -> [u32; 3] {
    [tri[k], tri[(k + 1) % 3], tri[(k + 2) % 3]]
}

impl Propagation<'_> {
    /// Lowers the distance of `v` to `d` if shorter; a lowered bend vertex is queued as a
    /// pseudo-source.
    fn relax(&mut self, v: u32, d: f64, occupant: Option<Occupant>) -> bool {
        if d < self.dist[v as usize] {
            self.dist[v as usize] = d;
            self.occupant[v as usize] = occupant;
            if self.mesh.bends[v as usize] {
                self.queue.push(Queued { key: d, event: Event::Vertex(v) });
            }
            true
        } else {
            false
        }
    }

    /// The 2D position, in the frame of side `k` of `tri`, of its third corner.
    fn apex(&self, tri: u32, k: usize) -> (f64, DVec2) {
        let [a, b, c] = corners(self.mesh.triangles[tri as usize], k);
        let (pa, pb, pc) = (self.mesh.pos(a), self.mesh.pos(b), self.mesh.pos(c));
        let len = pa.distance(pb);
        let (l1, l2) = (pa.distance(pc), pb.distance(pc));
        let x = (len * len + l1 * l1 - l2 * l2) / (2.0 * len);
        let y = (l1 * l1 - x * x).max(0.0).sqrt();
        (len, DVec2::new(x, y))
    }

    /// A pseudo-source at `v`: its neighbours directly, and a full window on the far side
    /// of every triangle around it that a shortest path through `v` can enter.
    fn expand_vertex(&mut self, v: u32) {
        let mesh = self.mesh;
        let dv = self.dist[v as usize];
        let shadow = self.shadow(v);
        for (i, &t) in mesh.vertex_tris(v).iter().enumerate() {
            let tri = mesh.triangles[t as usize];
            let j = tri.iter().position(|&x| x == v).expect("vertex of its triangle");
            // The side opposite v: corners j+1, j+2 (side k = j + 1 of t).
            let k = (j + 1) % 3;
            let (len, apex) = self.apex(t, k);
            let [a, b, _] = corners(tri, k);
            self.relax(a, dv + apex.length(), None);
            self.relax(b, dv + apex.distance(DVec2::new(len, 0.0)), None);
            if shadow.as_ref().is_some_and(|open| !open[i]) {
                continue;
            }
            // In the frame of side k of t the source is the apex; the window goes into
            // every other triangle on that side.
            self.cross_side(t, k, [DVec2::ZERO, DVec2::new(len, 0.0)], apex, 0.0, len, apex, dv);
        }
    }

    /// Which triangles around `v` (in `vertex_tris` order) a shortest path through `v`
    /// can continue into, or `None` for all of them.
    ///
    /// A shortest path through a vertex turns by at least `pi` on both sides (otherwise
    /// it shortens around the vertex), so from the direction it arrives from, measured
    /// around `v` (total angle `Theta`), it leaves within `[pi, Theta - pi]`: only the
    /// saddle's shadow. Known when `v` got its distance from a window (its occupant) and
    /// its triangles form one fan of manifold edges; otherwise every triangle is open.
    fn shadow(&self, v: u32) -> Option<Vec<bool>> {
        let o = self.occupant[v as usize]?;
        let mesh = self.mesh;
        let fan = mesh.vertex_tris(v);
        let [a, b, _] = corners(mesh.triangles[o.tri as usize], o.k as usize);
        let (_, pc) = self.apex(o.tri, o.k as usize);
        // The arrival direction, as an angle from the side v-a towards v-b.
        let arrival = (-pc).angle_to(o.source - pc).abs();
        let pv = mesh.pos(v);
        let mut spans = vec![(f64::NAN, f64::NAN); fan.len()];
        let (mut t, mut from, mut to, mut phi) = (o.tri, a, b, 0.0);
        for _ in 0..fan.len() {
            let i = fan.iter().position(|&x| x == t)?;
            let angle = (mesh.pos(from) - pv).angle_between(mesh.pos(to) - pv);
            spans[i] = (phi, phi + angle);
            phi += angle;
            // Across the side v-to into the next triangle of the fan.
            let tri = mesh.triangles[t as usize];
            let side = (0..3).find(|&s| {
                let (p, q) = (tri[s], tri[(s + 1) % 3]);
                (p == v && q == to) || (p == to && q == v)
            })?;
            let across = mesh.edge_tris(mesh.triangle_edges[t as usize][side]);
            if across.len() != 2 {
                return None;
            }
            t = if across[0] == t { across[1] } else { across[0] };
            let next = mesh.triangles[t as usize];
            from = to;
            to = *next.iter().find(|&&x| x != v && x != from)?;
        }
        if t != o.tri || from != a || spans.iter().any(|s| s.0.is_nan()) {
            return None;
        }
        let pi = std::f64::consts::PI;
        let (lo, hi) = (arrival + pi - 1e-9, arrival + phi - pi + 1e-9);
        Some(spans.iter().map(|&(p0, p1)| p1 >= lo && p0 <= hi).collect())
    }

    /// Queues the windows continuing interval `[t0, t1]` (from corner `k` towards corner
    /// `k + 1` of `from`) into the other triangles on that side. `ends` are the side's
    /// two corners and `other` the third corner of `from`, all in the frame `s` is in.
    #[allow(clippy::too_many_arguments)]
    fn cross_side(
        &mut self,
        from: u32,
        k: usize,
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
        let mesh = self.mesh;
        let e = mesh.triangle_edges[from as usize][k];
        let (p, q) = (mesh.triangles[from as usize][k], mesh.triangles[from as usize][(k + 1) % 3]);
        let len = ends[0].distance(ends[1]);
        for &t in mesh.edge_tris(e) {
            if t == from {
                continue;
            }
            let tri = mesh.triangles[t as usize];
            let Some(k2) = (0..3).find(|&i| {
                let (a, b) = (tri[i], tri[(i + 1) % 3]);
                (a == p && b == q) || (a == q && b == p)
            }) else {
                continue;
            };
            let forward = tri[k2] == p;
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
            let w = Window { tri: t, k: k2 as u8, b0: b0.max(0.0), b1: b1.min(len), s: s2, sigma };
            self.push(w);
        }
    }

    /// Queues what is left of `w` once the parts where a window already on its side is
    /// shorter are cut out (none of it if a vertex dominates it).
    fn push(&mut self, w: Window) {
        if w.b1 - w.b0 <= self.tiny || self.dominated(&w) {
            return;
        }
        let side = 3 * w.tri as usize + w.k as usize;
        let new = Kept { b0: w.b0, b1: w.b1, s: w.s, sigma: w.sigma };
        let mut covered: Vec<(f64, f64)> = Vec::new();
        for old in &self.kept[side] {
            let (lo, hi) = (old.b0.max(w.b0), old.b1.min(w.b1));
            if hi - lo > self.tiny && old.shorter(&new, lo, hi) {
                covered.push((lo, hi));
            }
        }
        covered.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut pieces = Vec::new();
        let mut start = w.b0;
        for (lo, hi) in covered {
            if lo > start + self.tiny {
                pieces.push((start, lo));
            }
            start = start.max(hi);
        }
        if w.b1 > start + self.tiny {
            pieces.push((start, w.b1));
        }
        for (b0, b1) in pieces {
            let piece = Window { b0, b1, ..w };
            self.kept[side].push(Kept { b0, b1, ..new });
            self.info.windows += 1;
            self.queue.push(Queued { key: piece.key(), event: Event::Window(piece) });
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
        let (len, pc) = self.apex(w.tri, w.k as usize);
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
        let (len, pc) = self.apex(w.tri, k);
        let (pa, pb) = (DVec2::ZERO, DVec2::new(len, 0.0));
        if w.b0 <= self.tiny {
            self.relax(a, w.sigma + w.s.length(), None);
        }
        if w.b1 >= len - self.tiny {
            self.relax(b, w.sigma + w.s.distance(pb), None);
        }
        // Where the ray from the source to the apex crosses the side.
        let dy = pc.y - w.s.y;
        let tc = if dy > 0.0 { w.s.x + (pc.x - w.s.x) * (-w.s.y) / dy } else { f64::NAN };
        let mut left = w.b0 < tc;
        let mut right = w.b1 > tc;
        if w.b0 <= tc && tc <= w.b1 {
            let occupant = Occupant { tri: w.tri, k: w.k, crossing: tc, source: w.s };
            if !self.relax(c, w.sigma + w.s.distance(pc), Some(occupant)) {
                if let Some(o) = self.occupant[c as usize] {
                    if o.tri == w.tri && o.k == w.k {
                        // A shorter path to c crosses the side at o.crossing: this
                        // window loses on the far side of it.
                        if w.b0 >= o.crossing {
                            left = false;
                        }
                        if w.b1 <= o.crossing {
                            right = false;
                        }
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
            self.cross_side(w.tri, (k + 2) % 3, [pc, pa], pb, lac - t1, lac - t0, w.s, w.sigma);
        }
        if right {
            // On side (b, c), parameters from b.
            let lbc = pb.distance(pc);
            let t0 = ray(w.b1, pb, pc);
            let t1 = if w.b0 <= tc { lbc } else { ray(w.b0, pb, pc) };
            // Side k + 1 runs b -> c.
            self.cross_side(w.tri, (k + 1) % 3, [pb, pc], pa, t0, t1, w.s, w.sigma);
        }
        let _ = (a, b);
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use glam::DVec3;

    use super::*;

    /// A grid of `n x n` quads over `[0, 1]^2` lifted by `height`, corners jittered in
    /// the plane by a fixed pattern.
    pub(crate) fn grid(n: usize, height: impl Fn(f64, f64) -> f64) -> (Vec<DVec3>, Vec<[u32; 4]>) {
        let mut positions = Vec::new();
        for j in 0..=n {
            for i in 0..=n {
                let jitter = |a: usize, b: usize| {
                    if a == 0 || a == n || b == 0 || b == n {
                        0.0
                    } else {
                        0.3 * (((a * 7 + b * 13) % 11) as f64 / 11.0 - 0.5) / n as f64
                    }
                };
                let (x, y) = (i as f64 / n as f64 + jitter(i, j), j as f64 / n as f64 + jitter(j, i));
                positions.push(DVec3::new(x, y, height(x, y)));
            }
        }
        let id = |i: usize, j: usize| (j * (n + 1) + i) as u32;
        let quads = (0..n)
            .flat_map(|j| (0..n).map(move |i| [id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)]))
            .collect();
        (positions, quads)
    }

    /// Shortest paths along the edges (an upper bound of the geodesic distance).
    fn dijkstra(mesh: &GeodesicMesh, sources: &[u32]) -> Vec<f64> {
        let mut d = vec![f64::INFINITY; mesh.num_vertices()];
        let mut heap = BinaryHeap::new();
        for &s in sources {
            d[s as usize] = 0.0;
            heap.push(Queued { key: 0.0, event: Event::Vertex(s) });
        }
        while let Some(Queued { key, event: Event::Vertex(v) }) = heap.pop() {
            if key > d[v as usize] {
                continue;
            }
            for &t in mesh.vertex_tris(v) {
                for &u in &mesh.triangles[t as usize] {
                    let du = key + mesh.pos(v).distance(mesh.pos(u));
                    if du < d[u as usize] {
                        d[u as usize] = du;
                        heap.push(Queued { key: du, event: Event::Vertex(u) });
                    }
                }
            }
        }
        d
    }

    #[test]
    fn planar_meshes_give_euclidean_distances() {
        let (positions, quads) = grid(12, |_, _| 0.0);
        let mesh = GeodesicMesh::new(&positions, &quads).unwrap();
        for source in [0u32, 7, 80, 168] {
            let (d, _) = exact_distances(&mesh, &[source]).unwrap();
            for (v, p) in positions.iter().enumerate() {
                let truth = p.distance(positions[source as usize]);
                assert!((d[v] - truth).abs() < 1e-9, "source {source}, vertex {v}: {} vs {truth}", d[v]);
            }
        }
    }

    #[test]
    fn a_folded_sheet_unfolds() {
        // A flat grid folded by 90 degrees along the grid line x = 0.5.
        let n = 10;
        let flat: Vec<DVec3> = (0..=n)
            .flat_map(|j| (0..=n).map(move |i| DVec3::new(i as f64, j as f64, 0.0) / n as f64))
            .collect();
        let (_, quads) = grid(n, |_, _| 0.0);
        let fold = |p: DVec3| if p.x <= 0.5 { p } else { DVec3::new(0.5, p.y, p.x - 0.5) };
        let folded: Vec<DVec3> = flat.iter().map(|&p| fold(p)).collect();
        let mesh = GeodesicMesh::new(&folded, &quads).unwrap();
        for source in [0u32, 58, 120] {
            let (d, _) = exact_distances(&mesh, &[source]).unwrap();
            for v in 0..flat.len() {
                let truth = flat[v].distance(flat[source as usize]);
                assert!((d[v] - truth).abs() < 1e-9, "source {source}, vertex {v}: {} vs {truth}", d[v]);
            }
        }
    }

    #[test]
    fn bounded_by_euclidean_and_edge_paths_and_multi_source_is_the_minimum() {
        let (positions, quads) = grid(16, |x, y| 0.25 * (6.0 * x).sin() * (5.0 * y).cos());
        let mesh = GeodesicMesh::new(&positions, &quads).unwrap();
        let (a, _) = exact_distances(&mesh, &[20]).unwrap();
        let (b, _) = exact_distances(&mesh, &[250]).unwrap();
        let (both, _) = exact_distances(&mesh, &[20, 250]).unwrap();
        let edges = dijkstra(&mesh, &[20]);
        let mut strictly_shorter = 0;
        for v in 0..positions.len() {
            let straight = positions[v].distance(positions[20]);
            assert!(a[v] >= straight - 1e-12 && a[v] <= edges[v] + 1e-12, "vertex {v}");
            assert!((both[v] - a[v].min(b[v])).abs() < 1e-12, "vertex {v}");
            strictly_shorter += usize::from(a[v] < edges[v] - 1e-6);
        }
        assert!(strictly_shorter > positions.len() / 2);
    }

    #[test]
    fn the_distance_is_symmetric() {
        let (positions, quads) = grid(14, |x, y| 0.3 * (x * x - y * y));
        let mesh = GeodesicMesh::new(&positions, &quads).unwrap();
        let (from_a, _) = exact_distances(&mesh, &[17]).unwrap();
        let (from_b, _) = exact_distances(&mesh, &[190]).unwrap();
        assert!((from_a[190] - from_b[17]).abs() < 1e-10, "{} vs {}", from_a[190], from_b[17]);
    }

    #[test]
    fn unreached_components_are_infinite() {
        let (mut positions, mut quads) = grid(3, |_, _| 0.0);
        let n = positions.len() as u32;
        positions.extend([DVec3::new(5.0, 0.0, 0.0), DVec3::new(6.0, 0.0, 0.0), DVec3::new(5.0, 1.0, 0.0)]);
        quads.push([n, n + 1, n + 2, n + 2]);
        assert!(GeodesicMesh::new(&positions, &quads).is_err());
        let tris: Vec<Vec<u32>> =
            quads[..9].iter().map(|q| q.to_vec()).chain([vec![n, n + 1, n + 2]]).collect();
        let mesh = GeodesicMesh::new(&positions, &tris).unwrap();
        let (d, _) = exact_distances(&mesh, &[0]).unwrap();
        assert!(d[n as usize].is_infinite() && d[15].is_finite());
        assert_eq!(exact_distances(&mesh, &[]).unwrap_err(), GeodesicError::NoSource);
    }
}
