//! The collapse engine: the triangle complex, its vertex classes, and the ordered
//! half-edge collapses with their checks.

use std::cmp::Reverse;
use std::collections::{BinaryHeap, VecDeque};

use glam::DVec3;
use rayon::prelude::*;
use rustc_hash::FxHashMap;
use voxreg_io::QuadMesh;
use voxreg_quality::point_triangle_distance;

use crate::grid::Grid;
use crate::quadric::Quadric;
use crate::types::{Options, Simplified, SimplifyError, Stats, Target};

/// The collapses report their progress each time this many more triangles are gone
/// (about a thousand collapses).
const PROGRESS_EVERY: usize = 2048;
use crate::Interrupt;

mod build;
mod flip;
mod geometry;

use geometry::{boxes_meet, meet_off_shared, quality, tri_normal};

/// A collapse may move no region's volume (enclosed by its faces) further than this
/// fraction of its input volume, counting every collapse before it.
const VOLUME_TOLERANCE: f64 = 0.005;

/// A collapse may move no patch's area further than this fraction of its input area,
/// counting every collapse before it.
const AREA_TOLERANCE: f64 = 0.01;

/// Collapses planned together, in parallel, before they are applied in queue order. A
/// constant, so that the output does not depend on the thread count.
const BATCH: usize = 32;

/// The fewest plans (or queue updates) of a batch made on the pool's threads; fewer are
/// made on the calling one. Only where they run depends on it, not what they give.
const PARALLEL_PLANS: usize = 8;

/// The queue's stale entries are dropped once it has grown by this share of its length
/// after the last drop (one in `STALE_SHARE`): most entries go stale within a few
/// collapses (every collapse changes the costs of both ends' edges), and popping them
/// one by one from a larger queue costs more than a pass over it. When they are dropped
/// does not change the queue's order.
const STALE_SHARE: usize = 16;

/// Room in the queue beyond its drop length, for the pushes of the batch that crosses it.
const QUEUE_SLACK: usize = 8192;

/// No group or no material.
pub(crate) const NONE: u32 = u32::MAX;

/// What makes two faces parts of one patch.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub(crate) struct Key {
    pub(crate) labels: [u32; 2],
    pub(crate) material: u32,
    pub(crate) group: u32,
}

/// The dimension of a vertex's feature.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Class {
    /// Inside one patch, a disc: may collapse along any edge.
    Interior,
    /// On one feature line, with the same patches on both sides: collapses along it.
    Line,
    /// Never moves.
    Corner,
}

/// An edge's incident triangles: per triangle its key and whether it runs from the
/// edge's first vertex to its second. Sorted.
type Signature = Vec<(u32, bool)>;

/// A collapse in the queue: cost bits (non-negative, so ordered as the costs), `u`, `v`,
/// and the versions of `u` and `v` it was computed at.
type Candidate = (u64, u32, u32, u32, u32);

/// A collapse that passed every check, with what it changes.
#[derive(Default)]
struct Plan {
    u: u32,
    v: u32,
    /// Where `v` goes.
    p: DVec3,
    removed: Vec<u32>,
    modified: Vec<(u32, [u32; 3])>,
    /// Input vertices and the triangle that answers for each, with the distance.
    assigned: Vec<(u32, u32, f64)>,
    /// Changes of patches' areas (`false`, patch) and six times regions' volumes (`true`,
    /// region).
    deltas: Vec<(bool, u32, f64)>,
}

/// One collapse of a batch: its plan, whether its checks passed, its buffers.
#[derive(Default)]
struct Slot {
    plan: Plan,
    ok: bool,
    scratch: Scratch,
}

/// Reused buffers of the collapse checks, so that a collapse allocates nothing.
#[derive(Default)]
struct Scratch {
    star_u: Vec<u32>,
    nu: Vec<u32>,
    nv: Vec<u32>,
    after: Vec<([u32; 3], u32, u32)>,
    after_nbrs: Vec<u32>,
    sig_a: Signature,
    sig_b: Signature,
    pool: Vec<u32>,
    tested: Vec<([u32; 3], [DVec3; 3])>,
    /// The boxes of the triangles in `tested`.
    boxes: Vec<(DVec3, DVec3)>,
    /// The new star's triangles' corners, centres and radii.
    spheres: Vec<([DVec3; 3], DVec3, f64)>,
    /// A lower bound of a point's distance to each of them.
    bounds: Vec<f64>,
}

pub(crate) struct Engine<'m> {
    options: Options,
    /// Polled in every long loop: once raised, the run returns `Interrupted`.
    interrupt: Interrupt,
    pos: Vec<DVec3>,
    /// Whether each vertex left its input position (then its input position is answered
    /// for by a triangle, as a removed vertex's is).
    moved: Vec<bool>,
    tris: Vec<[u32; 3]>,
    tri_key: Vec<u32>,
    tri_alive: Vec<bool>,
    alive: usize,
    vtris: Vec<Vec<u32>>,
    class: Vec<Class>,
    version: Vec<u32>,
    quadric: Vec<Quadric>,
    /// Removed input vertices each triangle answers for.
    points: Vec<Vec<u32>>,
    grid: Option<Grid>,
    heap: BinaryHeap<Reverse<Candidate>>,
    keys: Vec<Key>,
    /// Per triangle of an input face that intersects a triangle it shares no vertex with
    /// (hidden by the faces sharing a vertex): the input face. Such triangles never
    /// change and come out as their input face.
    frozen: Vec<u32>,
    /// Whether each vertex is a corner of a frozen triangle (frozen triangles never
    /// change, so neither does this).
    frozen_vertex: Vec<bool>,
    input: &'m QuadMesh,
    input_triangles: usize,
    error_bound: f64,
    /// Tie-break weight of the squared edge length in a collapse's cost.
    length_weight: f64,
    /// Mean triangle area (the unit of the quadrics' weights).
    mean_area: f64,
    max_error: f64,
    cos_normal: f64,
    /// Per collapse of a batch, its plan and the buffers of its checks (kept between
    /// batches, so that a collapse allocates nothing).
    slots: Vec<Slot>,
    /// Triangles alive when the grid was last built.
    grid_built_at: usize,
    /// Vertices with a refused collapse since they last queued theirs.
    retry: Vec<bool>,
    /// Per patch, its two regions (dense ids).
    key_regions: Vec<[u32; 2]>,
    /// Six times each region's input volume, and its change so far.
    region_volume: Vec<(f64, f64)>,
    /// Each patch's input area, and its change so far.
    patch_area: Vec<(f64, f64)>,
}

fn is_feature(sig: &Signature) -> bool {
    !(sig.len() == 2 && sig[0].0 == sig[1].0 && sig[0].1 != sig[1].1)
}

/// The signature of edge `(a, w)` over `tris` (each with its key), into `sig`.
fn signature_into<'a>(tris: impl Iterator<Item = (&'a [u32; 3], u32)>, a: u32, w: u32, sig: &mut Signature) {
    sig.clear();
    for (t, k) in tris {
        if let Some(i) = t.iter().position(|&x| x == a) {
            if t.contains(&w) {
                sig.push((k, t[(i + 1) % 3] == w));
            }
        }
    }
    sig.sort_unstable();
}

/// The signature of edge `(a, w)` over `tris` (each with its key).
fn signature<'a>(tris: impl Iterator<Item = (&'a [u32; 3], u32)>, a: u32, w: u32) -> Signature {
    let mut sig = Signature::new();
    signature_into(tris, a, w, &mut sig);
    sig
}

/// The signature of an edge seen from its other end.
fn reversed(sig: &Signature) -> Signature {
    let mut r: Signature = sig.iter().map(|&(k, d)| (k, !d)).collect();
    r.sort_unstable();
    r
}

struct UnionFind(Vec<usize>);

impl UnionFind {
    fn find(&mut self, mut x: usize) -> usize {
        while self.0[x] != x {
            self.0[x] = self.0[self.0[x]];
            x = self.0[x];
        }
        x
    }
    fn union(&mut self, a: usize, b: usize) {
        let (a, b) = (self.find(a), self.find(b));
        if a != b {
            self.0[a.max(b)] = a.min(b);
        }
    }
}

impl<'m> Engine<'m> {
    /// `Err(Interrupted)` once the caller raised the interrupt.
    #[inline]
    fn stop(&self) -> Result<(), SimplifyError> {
        crate::types::check(&self.interrupt)
    }

    /// Adds `sign` times each change to the running totals: a region's volume when the
    /// flag is set, a patch's area otherwise.
    fn add_deltas(&mut self, deltas: &[(bool, u32, f64)], sign: f64) {
        for &(kind, id, d) in deltas {
            if kind {
                self.region_volume[id as usize].1 += sign * d;
            } else {
                self.patch_area[id as usize].1 += sign * d;
            }
        }
    }

    /// Moves triangle `t` to the grid cells of its current box, when there is a grid.
    fn rebox(&mut self, t: u32) {
        let q = self.tris[t as usize].map(|w| self.pos[w as usize]);
        if let Some(grid) = self.grid.as_mut() {
            grid.remove(t);
            grid.insert(t, q[0].min(q[1]).min(q[2]), q[0].max(q[1]).max(q[2]));
        }
    }

    fn tri_box(&self, t: &[u32; 3]) -> (DVec3, DVec3) {
        let p = t.map(|v| self.pos[v as usize]);
        (p[0].min(p[1]).min(p[2]), p[0].max(p[1]).max(p[2]))
    }

    /// The box of the vertices of the triangles alive.
    fn bounds(&self) -> (DVec3, DVec3) {
        let (mut lo, mut hi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
        for (v, p) in self.pos.iter().enumerate() {
            if !self.vtris[v].is_empty() {
                lo = lo.min(*p);
                hi = hi.max(*p);
            }
        }
        if lo.x > hi.x {
            (DVec3::ZERO, DVec3::ZERO)
        } else {
            (lo, hi)
        }
    }

    fn neighbours(&self, v: u32) -> Vec<u32> {
        let mut n = Vec::new();
        self.neighbours_into(v, &mut n);
        n
    }

    /// The vertices sharing a triangle with `v`, sorted, into `n`.
    fn neighbours_into(&self, v: u32, n: &mut Vec<u32>) {
        n.clear();
        for &t in &self.vtris[v as usize] {
            n.extend(self.tris[t as usize].iter().copied().filter(|&w| w != v));
        }
        n.sort_unstable();
        n.dedup();
    }

    fn star_signature(&self, a: u32, w: u32) -> Signature {
        signature(
            self.vtris[a as usize].iter().map(|&t| (&self.tris[t as usize], self.tri_key[t as usize])),
            a,
            w,
        )
    }

    fn star_signature_into(&self, a: u32, w: u32, sig: &mut Signature) {
        signature_into(
            self.vtris[a as usize].iter().map(|&t| (&self.tris[t as usize], self.tri_key[t as usize])),
            a,
            w,
            sig,
        );
    }

    /// The class of `v`, and `q` plus the line quadrics of its feature edges.
    fn classify(&self, v: u32, mean_edge: f64, mut q: Quadric) -> (Class, Quadric) {
        let star = &self.vtris[v as usize];
        if star.is_empty() {
            return (Class::Corner, q);
        }
        let nbrs = self.neighbours(v);
        let mut features: Vec<(u32, Signature)> = Vec::new();
        let mut uf = UnionFind((0..star.len()).collect());
        for &w in &nbrs {
            let sig = self.star_signature(v, w);
            if is_feature(&sig) {
                features.push((w, sig));
            } else {
                let ts: Vec<usize> = star
                    .iter()
                    .enumerate()
                    .filter(|(_, &t)| self.tris[t as usize].contains(&w))
                    .map(|(i, _)| i)
                    .collect();
                uf.union(ts[0], ts[1]);
            }
        }
        for (w, _) in &features {
            let d = self.pos[*w as usize] - self.pos[v as usize];
            let len = d.length();
            if len > 0.0 {
                q.add(&Quadric::line(self.pos[v as usize], d / len, len / mean_edge));
            }
        }
        let roots: Vec<usize> = (0..star.len()).map(|i| uf.find(i)).collect();
        let mut sectors = roots.clone();
        sectors.sort_unstable();
        sectors.dedup();
        let class = match features.len() {
            0 if sectors.len() == 1 => Class::Interior,
            2 if features[0].1 == reversed(&features[1].1) && sectors.len() == features[0].1.len() => {
                // Each sector must run from one feature edge to the other.
                let (a, b) = (features[0].0, features[1].0);
                let ok = sectors.iter().all(|&s| {
                    let count = |w: u32| {
                        star.iter()
                            .zip(&roots)
                            .filter(|(&t, &r)| r == s && self.tris[t as usize].contains(&w))
                            .count()
                    };
                    count(a) == 1 && count(b) == 1
                });
                if ok {
                    Class::Line
                } else {
                    Class::Corner
                }
            }
            _ => Class::Corner,
        };
        (class, q)
    }

    /// Where `v` goes when `u` collapses into it, and the collapse's cost.
    ///
    /// Two interior vertices: the point of least quadric error (plus a small pull towards
    /// the edge's midpoint, which shapes flat areas) among those that keep the volume
    /// under the star, hence both regions' volumes (Lindstrom and Turk's volume-preserving
    /// placement). Otherwise `v` stays (corners and lines keep their vertices), and the
    /// cost adds the squared volume change of each region around `u`.
    fn place(&self, u: u32, v: u32) -> (DVec3, f64) {
        let (pu, pv) = (self.pos[u as usize], self.pos[v as usize]);
        let mut q = self.quadric[u as usize];
        q.add(&self.quadric[v as usize]);
        let tie = self.length_weight * pu.distance_squared(pv);
        let movable = self.class[u as usize] == Class::Interior
            && self.class[v as usize] == Class::Interior
            && !self.frozen_vertex[v as usize];
        if movable {
            // Six times the volume under the new star is g.(p - pv); under the old stars, old.
            let (mut g, mut old) = (DVec3::ZERO, 0.0);
            for (x, y) in [(u, v), (v, u)] {
                for &t in &self.vtris[x as usize] {
                    let tri = self.tris[t as usize];
                    let shared = tri.contains(&y);
                    if x == v && shared {
                        continue;
                    }
                    let r = tri.map(|w| self.pos[w as usize] - pv);
                    old += r[0].dot(r[1].cross(r[2]));
                    if !shared {
                        let i = tri.iter().position(|&w| w == x).expect("in the star");
                        g += r[(i + 1) % 3].cross(r[(i + 2) % 3]);
                    }
                }
            }
            let len2 = pu.distance_squared(pv);
            // Where the volume hardly changes as v stays (a flat area), v stays: exact
            // positions are kept where they can be.
            if old.abs() > 1e-9 * len2 * len2.sqrt() {
                let m = 0.5 * (pu + pv);
                if let Some(p) = q.minimize_on_plane(1e-2, m, g, old + g.dot(pv)) {
                    if p.distance_squared(m) <= len2 {
                        return (p, q.eval(p) + tie);
                    }
                }
            } else {
                return (pv, q.eval(pv) + tie);
            }
        }
        // v stays: six times each region's volume change, relative to pv (the new
        // triangles at v have none).
        let mut dv: [(u32, f64); 8] = [(NONE, 0.0); 8];
        let mut area = 0.0;
        for &t in &self.vtris[u as usize] {
            let r = self.tris[t as usize].map(|w| self.pos[w as usize] - pv);
            let d = -r[0].dot(r[1].cross(r[2]));
            area += 0.5 * (r[1] - r[0]).cross(r[2] - r[0]).length();
            let labels = self.keys[self.tri_key[t as usize] as usize].labels;
            for (l, sign) in [(labels[0], 1.0), (labels[1], -1.0)] {
                if let Some(e) = dv.iter_mut().find(|e| e.0 == l || e.0 == NONE) {
                    e.0 = l;
                    e.1 += sign * d;
                }
            }
        }
        let volume: f64 = dv.iter().map(|e| e.1 * e.1).sum::<f64>() / 36.0;
        let penalty = if area > 0.0 { volume / (area * self.mean_area) } else { 0.0 };
        (pv, q.eval(pv) + tie + penalty)
    }

    /// The queue entries of the collapses along `x`'s edges, into `out`: `x` into each
    /// neighbour, and each neighbour not in `both` (sorted) into `x`.
    fn entries_of(&self, x: u32, both: &[u32], nb: &mut Vec<u32>, out: &mut Vec<Reverse<Candidate>>) {
        self.neighbours_into(x, nb);
        for &y in nb.iter() {
            let back = both.binary_search(&y).is_err();
            for (a, b) in [(x, y), (y, x)] {
                if self.class[a as usize] != Class::Corner && (a == x || back) {
                    let c = self.place(a, b).1;
                    out.push(Reverse((
                        c.to_bits(),
                        a,
                        b,
                        self.version[a as usize],
                        self.version[b as usize],
                    )));
                }
            }
        }
    }

    /// A box that holds every triangle the collapse of `u` into `v` reads or changes,
    /// before and after: the corners of both stars, and the ball of the edge's length
    /// around its midpoint (where `v` may go), widened far above rounding.
    fn reach(&self, u: u32, v: u32) -> (DVec3, DVec3) {
        let (pu, pv) = (self.pos[u as usize], self.pos[v as usize]);
        let r = DVec3::splat(0.5 * pu.distance(pv) * (2.0 + 1e-9) + 1e-300);
        let m = 0.5 * (pu + pv);
        let (mut lo, mut hi) = (m - r, m + r);
        for x in [u, v] {
            for &t in &self.vtris[x as usize] {
                for w in self.tris[t as usize] {
                    lo = lo.min(self.pos[w as usize]);
                    hi = hi.max(self.pos[w as usize]);
                }
            }
        }
        (lo, hi)
    }

    fn is_current(&self, c: &Candidate) -> bool {
        let (_, u, v, su, sv) = *c;
        self.version[u as usize] == su
            && self.version[v as usize] == sv
            && !self.vtris[u as usize].is_empty()
            && !self.vtris[v as usize].is_empty()
    }

    /// Collapses edges in order of cost until `target` is reached or no collapse passes;
    /// `Interrupted` (the engine then unusable) once the interrupt is raised. `progress`
    /// gets the share of the triangles to remove that are removed, each time
    /// [`PROGRESS_EVERY`] more are gone.
    pub(crate) fn run(
        &mut self,
        target: &Target,
        progress: &mut dyn FnMut(f64),
    ) -> Result<(), SimplifyError> {
        self.max_error = target.max_error;
        let goal = match target.ratio {
            Some(r) => (r * self.input_triangles as f64).ceil() as usize,
            None => 0,
        };
        if self.alive <= goal {
            return Ok(());
        }
        // The previous level's queue is rebuilt below: freed first, so that the two are
        // never held together.
        self.heap = BinaryHeap::new();
        // Every vertex queues its own collapses; a corner's neighbours queue theirs into
        // it. The costs are computed in parallel; the queue's order is a total order on
        // its entries, so it does not depend on how they were gathered.
        let this = &*self;
        let entries: Vec<Reverse<Candidate>> = (0..self.pos.len() as u32)
            .into_par_iter()
            .filter(|&v| this.class[v as usize] != Class::Corner && !this.vtris[v as usize].is_empty())
            .fold(
                || (Vec::new(), Vec::new()),
                |(mut out, mut nb): (Vec<Reverse<Candidate>>, Vec<u32>), v| {
                    if this.interrupt.is_raised() {
                        return (out, nb);
                    }
                    this.neighbours_into(v, &mut nb);
                    for &y in &nb {
                        let c = this.place(v, y).1;
                        out.push(Reverse((
                            c.to_bits(),
                            v,
                            y,
                            this.version[v as usize],
                            this.version[y as usize],
                        )));
                    }
                    (out, nb)
                },
            )
            .map(|(out, _)| out)
            .reduce(Vec::new, |mut a, mut b| {
                a.append(&mut b);
                a
            });
        self.stop()?;
        let mut limit = self.set_queue(entries);
        let start = self.alive;
        let mut next_report = start.saturating_sub(PROGRESS_EVERY);
        let mut slots = std::mem::take(&mut self.slots);
        slots.resize_with(BATCH, Slot::default);
        let mut batch: Vec<(Candidate, (DVec3, DVec3))> = Vec::with_capacity(BATCH);
        let mut deferred: Vec<(Candidate, (DVec3, DVec3))> = Vec::new();
        // The entries put back, in queue order, beside the queue: the next batch takes
        // the least of both, as if they had been pushed back, without the heap's work.
        let mut held: VecDeque<Candidate> = VecDeque::new();
        let mut applied: Vec<u32> = Vec::with_capacity(BATCH);
        let mut requests: Vec<(u32, Vec<u32>)> = Vec::new();
        while self.alive > goal {
            if self.alive <= next_report {
                next_report = self.alive.saturating_sub(PROGRESS_EVERY);
                progress((start - self.alive) as f64 / (start - goal) as f64);
            }
            self.stop()?;
            if self.grid.is_some() && 2 * self.alive < self.grid_built_at {
                self.rebuild_grid();
            }
            if self.heap.len() > limit {
                let heap = std::mem::take(&mut self.heap);
                let mut kept: Vec<Reverse<Candidate>> = heap.into_vec();
                kept.retain(|c| self.is_current(&c.0));
                limit = self.set_queue(kept);
            }
            // The next collapses in queue order whose reaches meet the reach of no collapse
            // taken before them (in the batch or put back): they commute with each other
            // and with those put back, so planning them together on the same state and
            // applying them in order is applying them one by one.
            batch.clear();
            deferred.clear();
            while batch.len() < BATCH && deferred.len() < 2 * BATCH {
                let from_held = match (self.heap.peek(), held.front()) {
                    (_, None) => false,
                    (None, Some(_)) => true,
                    (Some(Reverse(h)), Some(d)) => d <= h,
                };
                let c = if from_held {
                    held.pop_front().expect("peeked")
                } else {
                    match self.heap.pop() {
                        Some(Reverse(c)) => c,
                        None => break,
                    }
                };
                if !self.is_current(&c) {
                    continue;
                }
                if self.frozen_vertex[c.1 as usize] {
                    self.retry[c.1 as usize] = true;
                    continue;
                }
                let b = self.reach(c.1, c.2);
                let meets = |x: &(Candidate, (DVec3, DVec3))| {
                    let (lo, hi) = x.1;
                    !(lo.cmpgt(b.1).any() || b.0.cmpgt(hi).any())
                };
                if batch.iter().any(meets) || deferred.iter().any(meets) {
                    deferred.push((c, b));
                } else {
                    batch.push((c, b));
                }
            }
            if batch.is_empty() {
                break;
            }
            // Taken in queue order, the entries put back all come before those still held.
            for (c, _) in deferred.iter().rev() {
                held.push_front(*c);
            }
            let this = &*self;
            let plan = |(slot, (c, _)): (&mut Slot, &(Candidate, (DVec3, DVec3)))| {
                slot.ok = this.plan_with(c.1, c.2, &mut slot.plan, &mut slot.scratch);
            };
            // A few plans are made here: waking the pool's threads for them costs more.
            if batch.len() < PARALLEL_PLANS {
                slots[..batch.len()].iter_mut().zip(&batch).for_each(plan);
            } else {
                slots[..batch.len()].par_iter_mut().zip(&batch).for_each(plan);
            }
            applied.clear();
            for slot in &slots[..batch.len()] {
                if self.alive <= goal {
                    break;
                }
                if slot.ok && self.within_tolerances(&slot.plan.deltas) {
                    self.apply(&slot.plan);
                    applied.push(slot.plan.v);
                } else {
                    self.retry[slot.plan.u as usize] = true;
                }
            }
            // The kept vertices' collapses are queued anew; those of their neighbours keep
            // their queued costs (only the order depends on them: every check is made again
            // when one is tried), and a neighbour whose collapse was refused queues its own
            // again, as the change may let it pass now. The costs are computed in parallel.
            requests.clear();
            for &v in &applied {
                let ring = self.neighbours(v);
                requests.push((v, Vec::new()));
                for &x in &ring {
                    if self.retry[x as usize] {
                        self.retry[x as usize] = false;
                        requests.push((x, ring.clone()));
                    }
                }
            }
            if requests.len() < PARALLEL_PLANS {
                let mut nb = Vec::new();
                let mut out = Vec::new();
                for (x, both) in &requests {
                    self.entries_of(*x, both, &mut nb, &mut out);
                }
                self.heap.extend(out);
            } else {
                let this = &*self;
                let pushed: Vec<Vec<Reverse<Candidate>>> = requests
                    .par_iter()
                    .map_init(Vec::new, |nb, (x, both)| {
                        let mut out = Vec::new();
                        this.entries_of(*x, both, nb, &mut out);
                        out
                    })
                    .collect();
                for e in pushed {
                    self.heap.extend(e);
                }
            }
        }
        self.slots = slots;
        Ok(())
    }

    /// Makes `entries` the queue, with room for [`STALE_SHARE`] more and the pushes of a
    /// batch, so that it seldom grows by doubling; returns the length past which its
    /// stale entries are dropped (the queue's order is the same whenever they are).
    fn set_queue(&mut self, mut entries: Vec<Reverse<Candidate>>) -> usize {
        let limit = entries.len() + entries.len() / STALE_SHARE + 1024;
        entries.shrink_to(limit + QUEUE_SLACK);
        entries.reserve_exact(limit + QUEUE_SLACK - entries.len());
        self.heap = BinaryHeap::from(entries);
        limit
    }

    /// Builds the grid again from the triangles alive, with cells of twice their mean
    /// edge: the triangles grow as they merge, and the cells would fill with the old
    /// entries of triangles that changed.
    fn rebuild_grid(&mut self) {
        let (mut sum, mut count) = (0.0, 0usize);
        for (t, tri) in self.tris.iter().enumerate() {
            if self.tri_alive[t] {
                for i in 0..3 {
                    sum += self.pos[tri[i] as usize].distance(self.pos[tri[(i + 1) % 3] as usize]);
                }
                count += 3;
            }
        }
        let mean_edge = if count > 0 { (sum / count as f64).max(1e-300) } else { 1.0 };
        let (lo, hi) = self.bounds();
        // The old grid is freed before the new one is built.
        self.grid = None;
        let mut grid = Grid::new(lo, hi, 2.0 * mean_edge, self.tris.len());
        for (t, tri) in self.tris.iter().enumerate() {
            if self.tri_alive[t] {
                let (lo, hi) = self.tri_box(tri);
                grid.insert(t as u32, lo, hi);
            }
        }
        self.grid = Some(grid);
        self.grid_built_at = self.alive;
    }

    /// Whether the changes of a planned collapse keep every region's volume and every
    /// patch's area within their tolerances, counting every collapse before it.
    fn within_tolerances(&self, deltas: &[(bool, u32, f64)]) -> bool {
        deltas.iter().all(|&(kind, id, d)| {
            let (total, so_far) =
                if kind { self.region_volume[id as usize] } else { self.patch_area[id as usize] };
            let tolerance = if kind { VOLUME_TOLERANCE } else { AREA_TOLERANCE };
            (so_far + d).abs() <= tolerance * total.abs()
        })
    }

    /// Plans the collapse of `u` into `v` in `plan`; whether every check passes, the
    /// tolerances against the totals of the collapses applied before the batch (the
    /// caller checks them again when it applies the plan). Reads only what lies in
    /// `reach(u, v)`, and the totals.
    fn plan_with(&self, u: u32, v: u32, plan: &mut Plan, sc: &mut Scratch) -> bool {
        plan.u = u;
        plan.v = v;
        if self.class[u as usize] == Class::Corner {
            return false;
        }
        sc.star_u.clear();
        sc.star_u.extend_from_slice(&self.vtris[u as usize]);
        let star_u = &sc.star_u;
        if self.frozen_vertex[u as usize] {
            return false;
        }
        plan.removed.clear();
        plan.modified.clear();
        plan.assigned.clear();
        for &t in star_u {
            let tri = self.tris[t as usize];
            if tri.contains(&v) {
                plan.removed.push(t);
            } else {
                plan.modified.push((t, tri.map(|x| if x == u { v } else { x })));
            }
        }
        if plan.removed.is_empty() {
            return false;
        }
        // The feature rule: an interior vertex collapses along an interior edge, a line
        // vertex along its line.
        self.star_signature_into(u, v, &mut sc.sig_a);
        match self.class[u as usize] {
            Class::Interior if is_feature(&sc.sig_a) => return false,
            Class::Line if !is_feature(&sc.sig_a) => return false,
            _ => {}
        }
        // The link condition on the whole complex.
        self.neighbours_into(u, &mut sc.nu);
        self.neighbours_into(v, &mut sc.nv);
        let (nu, nv) = (&sc.nu, &sc.nv);
        for &w in nu {
            if w != v
                && nv.binary_search(&w).is_ok()
                && !plan.removed.iter().any(|&t| self.tris[t as usize].contains(&w))
            {
                return false;
            }
        }
        for (t, _) in &plan.modified {
            let tri = self.tris[*t as usize];
            let mut others = tri.iter().copied().filter(|&x| x != u);
            let (o0, o1) = (others.next().expect("two"), others.next().expect("two"));
            if nv.binary_search(&o0).is_ok()
                && nv.binary_search(&o1).is_ok()
                && self.vtris[v as usize].iter().any(|&s| {
                    let st = &self.tris[s as usize];
                    st.contains(&o0) && st.contains(&o1)
                })
            {
                return false;
            }
        }
        // Every edge at v keeps its incident patches and their orientations.
        sc.after.clear();
        for &t in &self.vtris[v as usize] {
            if !plan.removed.contains(&t) {
                sc.after.push((self.tris[t as usize], self.tri_key[t as usize], t));
            }
        }
        let first_modified = sc.after.len();
        sc.after.extend(plan.modified.iter().map(|&(t, tri)| (tri, self.tri_key[t as usize], t)));
        sc.after_nbrs.clear();
        sc.after_nbrs.extend(sc.after.iter().flat_map(|x| x.0).filter(|&w| w != v));
        sc.after_nbrs.sort_unstable();
        sc.after_nbrs.dedup();
        for &w in &sc.after_nbrs {
            signature_into(sc.after.iter().map(|x| (&x.0, x.1)), v, w, &mut sc.sig_a);
            if nv.binary_search(&w).is_ok() {
                self.star_signature_into(v, w, &mut sc.sig_b);
            } else {
                self.star_signature_into(u, w, &mut sc.sig_b);
            }
            if sc.sig_a != sc.sig_b {
                return false;
            }
        }
        // Where v goes.
        let (p, _) = self.place(u, v);
        let moves = p != self.pos[v as usize];
        plan.p = p;
        let at = |x: u32| if x == v { p } else { self.pos[x as usize] };
        // Geometry: no normal turns too far, no sliver.
        let min_q = self.options.min_triangle_quality;
        let changed = if moves { 0 } else { first_modified };
        for (tri, _, t) in &sc.after[changed..] {
            let old = self.tris[*t as usize].map(|x| self.pos[x as usize]);
            let new = tri.map(at);
            let (n0, n1) = (tri_normal(old), tri_normal(new));
            if n1.length_squared() <= 0.0 || n0.length_squared() <= 0.0 {
                return false;
            }
            if n0.normalize().dot(n1.normalize()) < self.cos_normal {
                return false;
            }
            if quality(new) < min_q.min(quality(old)) {
                return false;
            }
        }
        // Each patch's area and each region's volume within their tolerances: the
        // changes of the triangles that change, volumes relative to pv.
        plan.deltas.clear();
        {
            let pv = self.pos[v as usize];
            let mut add = |key: u32, tri: [DVec3; 3], sign: f64| {
                let area = 0.5 * tri_normal(tri).length();
                let r = tri.map(|x| x - pv);
                let det = sign * r[0].dot(r[1].cross(r[2]));
                let [a, b] = self.key_regions[key as usize];
                for (kind, id, d) in [(false, key, sign * area), (true, a, det), (true, b, -det)] {
                    match plan.deltas.iter_mut().find(|e| e.0 == kind && e.1 == id) {
                        Some(e) => e.2 += d,
                        None => plan.deltas.push((kind, id, d)),
                    }
                }
            };
            for &t in star_u {
                add(self.tri_key[t as usize], self.tris[t as usize].map(|x| self.pos[x as usize]), -1.0);
            }
            if moves {
                for &t in &self.vtris[v as usize] {
                    if !plan.removed.contains(&t) {
                        add(
                            self.tri_key[t as usize],
                            self.tris[t as usize].map(|x| self.pos[x as usize]),
                            -1.0,
                        );
                    }
                }
            }
            for (tri, key, _) in &sc.after[changed..] {
                add(*key, tri.map(at), 1.0);
            }
        }
        // Refused early against the totals before the batch (checked again, against the
        // totals of the collapses applied before it, when it is applied).
        if !self.within_tolerances(&plan.deltas) {
            return false;
        }
        // The distance budget: every input vertex that u's triangles (and v's, if v
        // moves) answer for, u itself and v if it leaves its input position, goes to the
        // nearest triangle of v's new star.
        sc.pool.clear();
        if !self.moved[u as usize] {
            sc.pool.push(u);
        }
        for &t in star_u {
            sc.pool.extend_from_slice(&self.points[t as usize]);
        }
        if moves {
            if !self.moved[v as usize] {
                sc.pool.push(v);
            }
            for &t in &self.vtris[v as usize] {
                if !plan.removed.contains(&t) {
                    sc.pool.extend_from_slice(&self.points[t as usize]);
                }
            }
        }
        // Each point goes to the first triangle (in the star's order) at the least
        // distance. A triangle's bounding sphere bounds its distance from below, so only
        // the triangles whose bound is within the nearest sphere's triangle's distance
        // can hold the least one: the others are skipped, with a margin far above
        // rounding.
        sc.spheres.clear();
        sc.spheres.extend(sc.after.iter().map(|(tri, _, _)| {
            let q = tri.map(at);
            let c = (q[0] + q[1] + q[2]) / 3.0;
            let r = q.iter().map(|x| x.distance(c)).fold(0.0, f64::max);
            (q, c, r)
        }));
        for &x in &sc.pool {
            let pp = self.input.positions[x as usize];
            sc.bounds.clear();
            let (mut near, mut lb_near) = (0, f64::INFINITY);
            for (i, (_, c, r)) in sc.spheres.iter().enumerate() {
                let dc = pp.distance(*c);
                let lb = dc - r - 1e-9 * (dc + r);
                sc.bounds.push(lb);
                if lb < lb_near {
                    (near, lb_near) = (i, lb);
                }
            }
            let d_near = point_triangle_distance(pp, sc.spheres[near].0);
            let ub = if d_near.is_nan() { f64::INFINITY } else { d_near };
            let mut best = (f64::INFINITY, NONE);
            for (i, (q, _, _)) in sc.spheres.iter().enumerate() {
                if sc.bounds[i] > ub {
                    continue;
                }
                let d = if i == near { d_near } else { point_triangle_distance(pp, *q) };
                if d < best.0 {
                    best = (d, sc.after[i].2);
                }
            }
            if best.0.is_nan() || best.0 > self.max_error {
                return false;
            }
            plan.assigned.push((x, best.1, best.0));
        }
        // No new intersection: with a triangle that shares no vertex, none at all; with one
        // that shares vertices, none off the shared corners and edges (exactly, as
        // `voxreg check` tests).
        if let Some(grid) = self.grid.as_ref() {
            sc.tested.clear();
            sc.tested.extend(sc.after[changed..].iter().map(|(tri, _, _)| (*tri, tri.map(at))));
            let star_v = &self.vtris[v as usize];
            // One query over the box of all the changed triangles: each triangle near
            // them is fetched once and tested against those whose boxes its box meets
            // (triangles that share a corner always do).
            let (mut lo, mut hi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
            sc.boxes.clear();
            for (_, p3) in &sc.tested {
                let b = (p3[0].min(p3[1]).min(p3[2]), p3[0].max(p3[1]).max(p3[2]));
                lo = lo.min(b.0);
                hi = hi.max(b.1);
                sc.boxes.push(b);
            }
            let (tested, boxes) = (&sc.tested, &sc.boxes);
            let mut hit = !tested.is_empty()
                && grid.any(lo, hi, |s| {
                    if !self.tri_alive[s as usize] {
                        return false;
                    }
                    let st = self.tris[s as usize];
                    let q = st.map(|x| self.pos[x as usize]);
                    let (qlo, qhi) = (q[0].min(q[1]).min(q[2]), q[0].max(q[1]).max(q[2]));
                    // Outside the box of all the changed triangles: outside each one's.
                    if lo.cmpgt(qhi).any() || qlo.cmpgt(hi).any() {
                        return false;
                    }
                    let mut excluded = None;
                    for ((tri, p3), (blo, bhi)) in tested.iter().zip(boxes) {
                        if blo.cmpgt(qhi).any() || qlo.cmpgt(*bhi).any() {
                            continue;
                        }
                        if *excluded
                            .get_or_insert_with(|| star_u.contains(&s) || (moves && star_v.contains(&s)))
                        {
                            return false;
                        }
                        let meet = meet_off_shared((*tri, *p3), (st, q));
                        if meet {
                            return true;
                        }
                    }
                    false
                });
            // The changed triangles among themselves (all around `v`).
            if !hit {
                'pairs: for (i, (a, pa)) in sc.tested.iter().enumerate() {
                    for (b, pb) in &sc.tested[i + 1..] {
                        if meet_off_shared((*a, *pa), (*b, *pb)) {
                            hit = true;
                            break 'pairs;
                        }
                    }
                }
            }
            if hit {
                return false;
            }
        }
        true
    }

    /// Applies a planned collapse (its queue entries are made by the caller).
    fn apply(&mut self, plan: &Plan) {
        let Plan { u, v, p, ref removed, ref modified, ref assigned, ref deltas } = *plan;
        for &t in removed {
            self.tri_alive[t as usize] = false;
            self.alive -= 1;
            for x in self.tris[t as usize] {
                if x != u {
                    self.vtris[x as usize].retain(|&s| s != t);
                }
            }
            self.points[t as usize].clear();
        }
        let moves = p != self.pos[v as usize];
        for &(t, tri) in modified {
            self.tris[t as usize] = tri;
            self.points[t as usize].clear();
            self.vtris[v as usize].push(t);
        }
        self.vtris[u as usize].clear();
        if moves {
            self.pos[v as usize] = p;
            self.moved[v as usize] = true;
            for &t in &self.vtris[v as usize] {
                self.points[t as usize].clear();
            }
        }
        if let Some(grid) = self.grid.as_mut() {
            for &t in removed {
                grid.remove(t);
            }
            let changed: &[u32] = &self.vtris[v as usize];
            for &t in changed {
                if moves || modified.iter().any(|m| m.0 == t) {
                    let q = self.tris[t as usize].map(|x| self.pos[x as usize]);
                    grid.insert(t, q[0].min(q[1]).min(q[2]), q[0].max(q[1]).max(q[2]));
                }
            }
        }
        self.add_deltas(deltas, 1.0);
        for &(x, t, d) in assigned {
            self.points[t as usize].push(x);
            self.error_bound = self.error_bound.max(d);
        }
        let qu = self.quadric[u as usize];
        self.quadric[v as usize].add(&qu);
        self.version[u as usize] += 1;
        self.version[v as usize] += 1;
    }

    /// What the mesh as it is now is made from (a copy, so that it can be paired while
    /// the engine goes on to the next level).
    pub(crate) fn capture(&self) -> Capture<'m> {
        let alive: Vec<u32> = if self.alive == self.input_triangles {
            Vec::new()
        } else {
            (0..self.tris.len() as u32).filter(|&t| self.tri_alive[t as usize]).collect()
        };
        Capture {
            whole: self.alive == self.input_triangles,
            pos: if alive.is_empty() { Vec::new() } else { self.pos.clone() },
            tris: alive.iter().map(|&t| self.tris[t as usize]).collect(),
            keys: alive.iter().map(|&t| self.tri_key[t as usize]).collect(),
            frozen: alive.iter().map(|&t| self.frozen[t as usize]).collect(),
            patch_keys: self.keys.clone(),
            input: self.input,
            input_triangles: self.input_triangles,
            triangles_left: self.alive,
            counts: self.counts(),
            quads: self.options.quads.then_some(self.options.max_quad_dihedral_deg),
            interrupt: self.interrupt.clone(),
        }
    }

    /// The error bound and the vertex classes' counts.
    fn counts(&self) -> Stats {
        let count = |c: Class| {
            (0..self.pos.len()).filter(|&v| self.class[v] == c && !self.vtris[v].is_empty()).count()
        };
        Stats {
            error_bound: self.error_bound,
            corners: count(Class::Corner),
            line_vertices: count(Class::Line),
            ..Stats::default()
        }
    }
}

/// A level's triangles, copied from the engine, to be paired into the level's mesh.
pub(crate) struct Capture<'m> {
    /// No collapse yet: the level is the input itself.
    whole: bool,
    pos: Vec<DVec3>,
    tris: Vec<[u32; 3]>,
    keys: Vec<u32>,
    frozen: Vec<u32>,
    patch_keys: Vec<Key>,
    input: &'m QuadMesh,
    input_triangles: usize,
    triangles_left: usize,
    counts: Stats,
    quads: Option<f64>,
    interrupt: Interrupt,
}

impl Capture<'_> {
    /// The mesh as it is now: triangles paired into quads, vertices renumbered in input
    /// order; `Interrupted` once the interrupt is raised (the pairing polls it).
    pub(crate) fn finish(self) -> Result<Simplified, SimplifyError> {
        if self.whole {
            let stats = Stats {
                input_faces: self.input.quads.len(),
                input_triangles: self.input_triangles,
                triangles_left: self.triangles_left,
                faces: self.input.quads.len(),
                quads: self.input.quads.iter().filter(|q| q[3] != q[2] && q[3] != q[0]).count(),
                ..self.counts
            };
            return Ok(Simplified { mesh: self.input.clone(), stats });
        }
        let (tris, keys, frozen) = (&self.tris, &self.keys, &self.frozen);
        let faces =
            crate::pair::pair(&self.pos, tris, keys, frozen, &self.input.quads, self.quads, &self.interrupt);
        crate::types::check(&self.interrupt)?;
        let mut used = vec![u32::MAX; self.pos.len()];
        for t in tris {
            for &x in t {
                used[x as usize] = 0;
            }
        }
        let mut positions = Vec::new();
        for (i, u) in used.iter_mut().enumerate() {
            if *u == 0 {
                *u = positions.len() as u32;
                positions.push(self.pos[i]);
            }
        }
        let mut mesh = QuadMesh {
            positions,
            materials: self.input.materials.clone(),
            named_labels: self.input.named_labels.clone(),
            ..QuadMesh::default()
        };
        let mut groups: Vec<Vec<u32>> = vec![Vec::new(); self.input.groups.len()];
        let has_materials = !self.input.face_materials.is_empty();
        let mut quads = 0;
        for f in &faces {
            let (q, k) = match *f {
                crate::pair::Face::Tri(i) => {
                    let t = tris[i as usize];
                    ([t[0], t[1], t[2], t[2]], keys[i as usize])
                }
                crate::pair::Face::Quad(q, i) => {
                    quads += usize::from(q[2] != q[3] && q[3] != q[0]);
                    (q, keys[i as usize])
                }
            };
            let key = self.patch_keys[k as usize];
            if key.group != NONE {
                groups[key.group as usize].push(mesh.quads.len() as u32);
            }
            mesh.quads.push(q.map(|x| used[x as usize]));
            mesh.face_labels.push(key.labels);
            if has_materials {
                mesh.face_materials.push(key.material);
            }
        }
        mesh.groups = self
            .input
            .groups
            .iter()
            .zip(groups)
            .map(|(g, faces)| voxreg_io::FaceGroup { name: g.name.clone(), faces })
            .collect();
        let stats = Stats {
            input_faces: self.input.quads.len(),
            input_triangles: self.input_triangles,
            triangles_left: self.triangles_left,
            faces: mesh.quads.len(),
            quads,
            ..self.counts
        };
        Ok(Simplified { mesh, stats })
    }
}
