//! The collapse engine: the triangle complex, its vertex classes, and the ordered
//! half-edge collapses with their checks.

use std::cmp::Reverse;
use std::collections::BinaryHeap;

use glam::DVec3;
use rustc_hash::FxHashMap;
use voxreg_io::QuadMesh;
use voxreg_quality::{point_triangle_distance, triangles_intersect, triangles_meet_off_shared};

use crate::grid::Grid;
use crate::quadric::Quadric;
use crate::{Options, Simplified, SimplifyError, Stats, Target};

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
struct Plan {
    u: u32,
    v: u32,
    removed: Vec<u32>,
    modified: Vec<(u32, [u32; 3])>,
    /// Input vertices and the triangle that answers for each, with the distance.
    assigned: Vec<(u32, u32, f64)>,
}

pub(crate) struct Engine {
    options: Options,
    pos: Vec<DVec3>,
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
    input: QuadMesh,
    input_triangles: usize,
    error_bound: f64,
    /// Tie-break weight of the squared edge length in a collapse's cost.
    length_weight: f64,
    max_error: f64,
    cos_normal: f64,
}

fn tri_normal(p: [DVec3; 3]) -> DVec3 {
    (p[1] - p[0]).cross(p[2] - p[0])
}

fn quality(p: [DVec3; 3]) -> f64 {
    let l = (p[1] - p[0]).length_squared() + (p[2] - p[1]).length_squared() + (p[0] - p[2]).length_squared();
    if l <= 0.0 {
        return 0.0;
    }
    2.0 * 3f64.sqrt() * tri_normal(p).length() / l
}

fn is_feature(sig: &Signature) -> bool {
    !(sig.len() == 2 && sig[0].0 == sig[1].0 && sig[0].1 != sig[1].1)
}

/// The signature of edge `(a, w)` over `tris` (each with its key).
fn signature<'a>(tris: impl Iterator<Item = (&'a [u32; 3], u32)>, a: u32, w: u32) -> Signature {
    let mut sig: Signature = tris
        .filter(|(t, _)| t.contains(&a) && t.contains(&w))
        .map(|(t, k)| {
            let i = t.iter().position(|&x| x == a).unwrap();
            (k, t[(i + 1) % 3] == w)
        })
        .collect();
    sig.sort_unstable();
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

impl Engine {
    pub(crate) fn new(mesh: &QuadMesh, options: &Options) -> Result<Engine, SimplifyError> {
        let n = mesh.positions.len();
        let bad = |s: String| Err(SimplifyError::InvalidMesh(s));
        if let Some(i) = mesh.positions.iter().position(|p| !p.is_finite()) {
            return bad(format!("vertex {i} has a non-finite position"));
        }
        if mesh.face_labels.len() != mesh.quads.len() {
            return bad(format!("{} faces but {} label pairs", mesh.quads.len(), mesh.face_labels.len()));
        }
        if !mesh.face_materials.is_empty() && mesh.face_materials.len() != mesh.quads.len() {
            return bad(format!(
                "{} faces but {} face materials",
                mesh.quads.len(),
                mesh.face_materials.len()
            ));
        }
        let mut group = vec![NONE; mesh.quads.len()];
        for (g, fg) in mesh.groups.iter().enumerate() {
            for &f in &fg.faces {
                match group.get_mut(f as usize) {
                    None => return bad(format!("group {} lists face {f}, out of range", fg.name)),
                    Some(x) if *x == NONE => *x = g as u32,
                    Some(_) => {}
                }
            }
        }
        let mut key_ids: FxHashMap<Key, u32> = FxHashMap::default();
        let mut keys = Vec::new();
        let mut tris = Vec::with_capacity(2 * mesh.quads.len());
        let mut tri_key = Vec::with_capacity(2 * mesh.quads.len());
        let mut tri_face = Vec::with_capacity(2 * mesh.quads.len());
        for (f, q) in mesh.quads.iter().enumerate() {
            if let Some(&v) = q.iter().find(|&&v| v as usize >= n) {
                return bad(format!("face {f} refers to vertex {v}, out of range"));
            }
            let key = Key {
                labels: mesh.face_labels[f],
                material: mesh.face_materials.get(f).copied().unwrap_or(NONE),
                group: group[f],
            };
            let k = *key_ids.entry(key).or_insert_with(|| {
                keys.push(key);
                keys.len() as u32 - 1
            });
            let mut distinct: Vec<u32> = Vec::with_capacity(4);
            for (i, &v) in q.iter().enumerate() {
                if v != q[(i + 3) % 4] {
                    distinct.push(v);
                }
            }
            if distinct.is_empty() {
                distinct.push(q[0]);
            }
            let mut sorted = distinct.clone();
            sorted.sort_unstable();
            sorted.dedup();
            if sorted.len() != distinct.len() || distinct.len() < 3 {
                return bad(format!("face {f} has fewer than three distinct vertices"));
            }
            if distinct.len() == 4 {
                tris.push([q[0], q[1], q[2]]);
                tris.push([q[0], q[2], q[3]]);
                tri_key.extend([k, k]);
                tri_face.extend([f as u32, f as u32]);
            } else {
                tris.push([distinct[0], distinct[1], distinct[2]]);
                tri_key.push(k);
                tri_face.push(f as u32);
            }
        }
        let pos = mesh.positions.clone();
        let mut vtris = vec![Vec::new(); n];
        for (t, tri) in tris.iter().enumerate() {
            for &v in tri {
                vtris[v as usize].push(t as u32);
            }
        }
        let nt = tris.len();
        let area_sum: f64 = tris.iter().map(|t| tri_normal(t.map(|v| pos[v as usize])).length() * 0.5).sum();
        let mean_area = if nt > 0 { (area_sum / nt as f64).max(1e-300) } else { 1.0 };
        let mut edge_len = 0.0;
        for t in &tris {
            for i in 0..3 {
                edge_len += pos[t[i] as usize].distance(pos[t[(i + 1) % 3] as usize]);
            }
        }
        let mean_edge = if nt > 0 { (edge_len / (3 * nt) as f64).max(1e-300) } else { 1.0 };
        let mut engine = Engine {
            options: *options,
            pos,
            tri_alive: vec![true; nt],
            alive: nt,
            class: vec![Class::Corner; n],
            version: vec![0; n],
            quadric: vec![Quadric::default(); n],
            points: vec![Vec::new(); nt],
            grid: None,
            heap: BinaryHeap::new(),
            keys,
            frozen: vec![NONE; nt],
            input: mesh.clone(),
            input_triangles: nt,
            error_bound: 0.0,
            length_weight: 1e-3,
            max_error: 0.0,
            cos_normal: options.max_normal_change_deg.to_radians().cos(),
            tris,
            tri_key,
            vtris,
        };
        // Plane quadrics, weighted by area relative to the mean, so costs are squared
        // lengths.
        for t in 0..nt {
            let p = engine.tris[t].map(|v| engine.pos[v as usize]);
            let nrm = tri_normal(p);
            let len = nrm.length();
            if len <= 0.0 {
                continue;
            }
            let q = Quadric::plane(p[0], nrm / len, 0.5 * len / mean_area);
            for &v in &engine.tris[t] {
                engine.quadric[v as usize].add(&q);
            }
        }
        for v in 0..n as u32 {
            engine.classify(v, mean_edge);
        }
        if options.check_intersections {
            let mut grid = Grid::new(2.0 * mean_edge, nt);
            for t in 0..nt {
                let (lo, hi) = engine.tri_box(&engine.tris[t]);
                grid.insert(t as u32, lo, hi);
            }
            for t in 0..nt {
                let tri = engine.tris[t];
                let p = tri.map(|x| engine.pos[x as usize]);
                let (lo, hi) = engine.tri_box(&tri);
                let mut hits = Vec::new();
                grid.any(lo, hi, |s| {
                    let st = engine.tris[s as usize];
                    if s as usize > t
                        && !st.iter().any(|x| tri.contains(x))
                        && triangles_intersect(&p, &st.map(|x| engine.pos[x as usize]))
                    {
                        hits.push(s as usize);
                    }
                    false
                });
                for s in hits {
                    engine.frozen[s] = tri_face[s];
                    engine.frozen[t] = tri_face[t];
                }
            }
            // Both triangles of a frozen face.
            for t in 0..nt {
                if engine.frozen[t] != NONE {
                    for s in [t.wrapping_sub(1), t + 1] {
                        if s < nt && tri_face[s] == tri_face[t] {
                            engine.frozen[s] = tri_face[t];
                        }
                    }
                }
            }
            engine.grid = Some(grid);
        }
        Ok(engine)
    }

    fn tri_box(&self, t: &[u32; 3]) -> (DVec3, DVec3) {
        let p = t.map(|v| self.pos[v as usize]);
        (p[0].min(p[1]).min(p[2]), p[0].max(p[1]).max(p[2]))
    }

    fn neighbours(&self, v: u32) -> Vec<u32> {
        let mut n: Vec<u32> =
            self.vtris[v as usize].iter().flat_map(|&t| self.tris[t as usize]).filter(|&w| w != v).collect();
        n.sort_unstable();
        n.dedup();
        n
    }

    fn star_signature(&self, a: u32, w: u32) -> Signature {
        signature(
            self.vtris[a as usize].iter().map(|&t| (&self.tris[t as usize], self.tri_key[t as usize])),
            a,
            w,
        )
    }

    /// Sets the class of `v`, and adds the line quadrics of its feature edges.
    fn classify(&mut self, v: u32, mean_edge: f64) {
        let star = self.vtris[v as usize].clone();
        if star.is_empty() {
            return;
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
                let q = Quadric::line(self.pos[v as usize], d / len, len / mean_edge);
                self.quadric[v as usize].add(&q);
            }
        }
        let roots: Vec<usize> = (0..star.len()).map(|i| uf.find(i)).collect();
        let mut sectors = roots.clone();
        sectors.sort_unstable();
        sectors.dedup();
        self.class[v as usize] = match features.len() {
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
    }

    fn cost(&self, u: u32, v: u32) -> f64 {
        let (pu, pv) = (self.pos[u as usize], self.pos[v as usize]);
        let mut q = self.quadric[u as usize];
        q.add(&self.quadric[v as usize]);
        q.eval(pv) + self.length_weight * pu.distance_squared(pv)
    }

    fn push_vertex(&mut self, x: u32) {
        for y in self.neighbours(x) {
            for (a, b) in [(x, y), (y, x)] {
                if self.class[a as usize] != Class::Corner {
                    let c = self.cost(a, b);
                    let entry = (c.to_bits(), a, b, self.version[a as usize], self.version[b as usize]);
                    self.heap.push(Reverse(entry));
                }
            }
        }
    }

    /// Collapses edges in order of cost until `target` is reached or no collapse passes.
    pub(crate) fn run(&mut self, target: &Target) {
        self.max_error = target.max_error;
        let goal = match target.ratio {
            Some(r) => (r * self.input_triangles as f64).ceil() as usize,
            None => 0,
        };
        if self.alive <= goal {
            return;
        }
        self.heap.clear();
        for v in 0..self.pos.len() as u32 {
            if self.class[v as usize] != Class::Corner && !self.vtris[v as usize].is_empty() {
                // Pushing each non-corner vertex's edges covers both directions of them.
                self.push_vertex(v);
            }
        }
        while self.alive > goal {
            let Some(Reverse((_, u, v, su, sv))) = self.heap.pop() else { break };
            if self.version[u as usize] != su
                || self.version[v as usize] != sv
                || self.vtris[u as usize].is_empty()
                || self.vtris[v as usize].is_empty()
            {
                continue;
            }
            if let Some(plan) = self.plan(u, v) {
                self.apply(plan);
            }
        }
    }

    /// The collapse of `u` into `v`, if every check passes.
    fn plan(&mut self, u: u32, v: u32) -> Option<Plan> {
        if self.class[u as usize] == Class::Corner {
            return None;
        }
        let star_u = self.vtris[u as usize].clone();
        if star_u.iter().any(|&t| self.frozen[t as usize] != NONE) {
            return None;
        }
        let mut removed = Vec::new();
        let mut modified = Vec::new();
        for &t in &star_u {
            let tri = self.tris[t as usize];
            if tri.contains(&v) {
                removed.push(t);
            } else {
                modified.push((t, tri.map(|x| if x == u { v } else { x })));
            }
        }
        if removed.is_empty() {
            return None;
        }
        // The feature rule: an interior vertex collapses along an interior edge, a line
        // vertex along its line.
        let uv = self.star_signature(u, v);
        match self.class[u as usize] {
            Class::Interior if is_feature(&uv) => return None,
            Class::Line if !is_feature(&uv) => return None,
            _ => {}
        }
        // The link condition on the whole complex.
        let nu = self.neighbours(u);
        let nv = self.neighbours(v);
        for &w in &nu {
            if w != v
                && nv.binary_search(&w).is_ok()
                && !removed.iter().any(|&t| self.tris[t as usize].contains(&w))
            {
                return None;
            }
        }
        for (t, _) in &modified {
            let tri = self.tris[*t as usize];
            let others: Vec<u32> = tri.iter().copied().filter(|&x| x != u).collect();
            if others.iter().all(|w| nv.binary_search(w).is_ok())
                && self.vtris[v as usize].iter().any(|&s| {
                    let st = &self.tris[s as usize];
                    st.contains(&others[0]) && st.contains(&others[1])
                })
            {
                return None;
            }
        }
        // Every edge at v keeps its incident patches and their orientations.
        let after: Vec<([u32; 3], u32, u32)> = self.vtris[v as usize]
            .iter()
            .filter(|t| !removed.contains(t))
            .map(|&t| (self.tris[t as usize], self.tri_key[t as usize], t))
            .chain(modified.iter().map(|&(t, tri)| (tri, self.tri_key[t as usize], t)))
            .collect();
        let mut after_nbrs: Vec<u32> = after.iter().flat_map(|x| x.0).filter(|&w| w != v).collect();
        after_nbrs.sort_unstable();
        after_nbrs.dedup();
        for &w in &after_nbrs {
            let sig_after = signature(after.iter().map(|x| (&x.0, x.1)), v, w);
            let sig_before = if nv.binary_search(&w).is_ok() {
                self.star_signature(v, w)
            } else {
                self.star_signature(u, w)
            };
            if sig_after != sig_before {
                return None;
            }
        }
        // Geometry: no normal turns too far, no sliver.
        let min_q = self.options.min_triangle_quality;
        for (t, tri) in &modified {
            let old = self.tris[*t as usize].map(|x| self.pos[x as usize]);
            let new = tri.map(|x| self.pos[x as usize]);
            let (n0, n1) = (tri_normal(old), tri_normal(new));
            if n1.length_squared() <= 0.0 || n0.length_squared() <= 0.0 {
                return None;
            }
            if n0.normalize().dot(n1.normalize()) < self.cos_normal {
                return None;
            }
            if quality(new) < min_q.min(quality(old)) {
                return None;
            }
        }
        // The distance budget: every input vertex u and u's triangles answer for goes
        // to the nearest triangle of v's new star.
        let mut assigned = Vec::new();
        let pts =
            std::iter::once(u).chain(star_u.iter().flat_map(|&t| self.points[t as usize].iter().copied()));
        for p in pts {
            let pp = self.pos[p as usize];
            let mut best = (f64::INFINITY, NONE);
            for (tri, _, t) in &after {
                let d = point_triangle_distance(pp, tri.map(|x| self.pos[x as usize]));
                if d < best.0 {
                    best = (d, *t);
                }
            }
            if best.0.is_nan() || best.0 > self.max_error {
                return None;
            }
            assigned.push((p, best.1, best.0));
        }
        // No new intersection: with a triangle that shares no vertex, none at all; with one
        // that shares vertices, none off the shared corners and edges (exactly, as
        // `voxreg check` tests).
        if let Some(mut grid) = self.grid.take() {
            let mut hit = false;
            for (_, tri) in &modified {
                let p = tri.map(|x| self.pos[x as usize]);
                let (lo, hi) = (p[0].min(p[1]).min(p[2]), p[0].max(p[1]).max(p[2]));
                hit = grid.any(lo, hi, |s| {
                    if !self.tri_alive[s as usize] || star_u.contains(&s) {
                        return false;
                    }
                    let st = self.tris[s as usize];
                    let q = st.map(|x| self.pos[x as usize]);
                    if st.iter().any(|x| tri.contains(x)) {
                        let with_ids =
                            |t: [u32; 3], p: [DVec3; 3]| [(t[0], p[0]), (t[1], p[1]), (t[2], p[2])];
                        return triangles_meet_off_shared(with_ids(*tri, p), with_ids(st, q));
                    }
                    triangles_intersect(&p, &q)
                });
                if hit {
                    break;
                }
            }
            // The new triangles among themselves (all around `v`).
            if !hit {
                let with_ids = |t: [u32; 3]| t.map(|x| (x, self.pos[x as usize]));
                'pairs: for (i, (_, a)) in modified.iter().enumerate() {
                    for (_, b) in &modified[i + 1..] {
                        if triangles_meet_off_shared(with_ids(*a), with_ids(*b)) {
                            hit = true;
                            break 'pairs;
                        }
                    }
                }
            }
            self.grid = Some(grid);
            if hit {
                return None;
            }
        }
        Some(Plan { u, v, removed, modified, assigned })
    }

    fn apply(&mut self, plan: Plan) {
        let Plan { u, v, removed, modified, assigned } = plan;
        for &t in &removed {
            self.tri_alive[t as usize] = false;
            self.alive -= 1;
            for x in self.tris[t as usize] {
                if x != u {
                    self.vtris[x as usize].retain(|&s| s != t);
                }
            }
            self.points[t as usize].clear();
        }
        for &(t, tri) in &modified {
            self.tris[t as usize] = tri;
            self.points[t as usize].clear();
            self.vtris[v as usize].push(t);
            if let Some(grid) = self.grid.as_mut() {
                let p = tri.map(|x| self.pos[x as usize]);
                grid.insert(t, p[0].min(p[1]).min(p[2]), p[0].max(p[1]).max(p[2]));
            }
        }
        self.vtris[u as usize].clear();
        for (p, t, d) in assigned {
            self.points[t as usize].push(p);
            self.error_bound = self.error_bound.max(d);
        }
        let qu = self.quadric[u as usize];
        self.quadric[v as usize].add(&qu);
        let ring = self.neighbours(v);
        self.version[u as usize] += 1;
        self.version[v as usize] += 1;
        for &x in &ring {
            self.version[x as usize] += 1;
        }
        self.push_vertex(v);
        for &x in &ring {
            self.push_vertex(x);
        }
    }

    /// The mesh as it is now: triangles paired into quads, vertices renumbered in input
    /// order.
    pub(crate) fn snapshot(&self) -> Simplified {
        if self.alive == self.input_triangles {
            let stats = Stats {
                input_faces: self.input.quads.len(),
                input_triangles: self.input_triangles,
                triangles_left: self.alive,
                faces: self.input.quads.len(),
                quads: self.input.quads.iter().filter(|q| q[3] != q[2] && q[3] != q[0]).count(),
                ..self.counts()
            };
            return Simplified { mesh: self.input.clone(), stats };
        }
        let alive: Vec<u32> = (0..self.tris.len() as u32).filter(|&t| self.tri_alive[t as usize]).collect();
        let tris: Vec<[u32; 3]> = alive.iter().map(|&t| self.tris[t as usize]).collect();
        let keys: Vec<u32> = alive.iter().map(|&t| self.tri_key[t as usize]).collect();
        let frozen: Vec<u32> = alive.iter().map(|&t| self.frozen[t as usize]).collect();
        let faces = crate::pair::pair(
            &self.pos,
            &tris,
            &keys,
            &frozen,
            &self.input.quads,
            self.options.quads.then_some(self.options.max_quad_dihedral_deg),
        );
        let mut used = vec![u32::MAX; self.pos.len()];
        for t in &tris {
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
            let key = self.keys[k as usize];
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
            triangles_left: self.alive,
            faces: mesh.quads.len(),
            quads,
            ..self.counts()
        };
        Simplified { mesh, stats }
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
