//! Edge flips inside a patch, made before the triangles are paired into quads, with the
//! checks a collapse makes.

use glam::DVec3;
use voxreg_quality::point_triangle_distance;

use super::{
    is_feature, meet_off_shared, quality, tri_normal, Engine, SimplifyError, AREA_TOLERANCE, NONE,
    VOLUME_TOLERANCE,
};

/// How many passes of flips are made at most (a second one finds hardly any).
const FLIP_PASSES: usize = 1;

/// How many triangles one augmenting-path search visits at most.
const MAX_SEARCH: usize = 64;

/// How many triangles around one left alone (itself, its neighbours, then theirs) have
/// their edges tried.
const RING: usize = 4;

/// Pairs of triangles (by engine ids), with a log of changes that can be undone.
struct Matching {
    mate: Vec<u32>,
    log: Vec<(u32, u32)>,
    via: Vec<u32>,
    stamp: Vec<u32>,
    round: u32,
}

impl Matching {
    fn set(&mut self, t: u32, m: u32) {
        self.log.push((t, self.mate[t as usize]));
        self.mate[t as usize] = m;
    }

    fn undo(&mut self) {
        while let Some((t, m)) = self.log.pop() {
            self.mate[t as usize] = m;
        }
    }
}

/// What undoes a flip.
pub(super) struct Undo {
    t: [u32; 2],
    old: [[u32; 3]; 2],
    points: [Vec<u32>; 2],
    error_bound: f64,
    deltas: [(bool, u32, f64); 3],
}

/// A flip that passed every check: the two triangles' new corners and the input vertices
/// each answers for, with their distances.
pub(super) struct Flip {
    t: [u32; 2],
    new: [[u32; 3]; 2],
    assigned: Vec<(u32, u32, f64)>,
    deltas: [(bool, u32, f64); 3],
}

impl Engine<'_> {
    /// Flips edges inside patches where that lets more triangles pair into quads: the
    /// triangles are matched (best quads first, then augmenting paths, as the pairing
    /// does); then, for each triangle left alone in turn, the edges of it and of the
    /// triangles nearest it inside its patch (four in all) are tried in order, and a flip
    /// that passes every check is kept where the matching then grows (an augmenting path
    /// from a triangle it left alone), and undone otherwise. Sequential and in a fixed
    /// order: the result does not depend on the thread count. `Interrupted` once the
    /// interrupt is raised (polled per triangle in each pass).
    pub(crate) fn flip_for_quads(&mut self) -> Result<(), SimplifyError> {
        if self.alive == self.input_triangles {
            return Ok(());
        }
        let n = self.tris.len();
        let mut m = Matching {
            mate: vec![NONE; n],
            log: Vec::new(),
            via: vec![NONE; n],
            stamp: vec![0; n],
            round: 0,
        };
        let mut cands: Vec<(u64, u32, u32)> = Vec::new();
        for t in 0..n as u32 {
            self.stop()?;
            if self.tri_alive[t as usize] {
                for k in 0..3 {
                    if let Some((s, score)) = self.quad_across(t, k) {
                        if t < s {
                            cands.push((score.to_bits(), t, s));
                        }
                    }
                }
            }
        }
        cands.sort_unstable();
        for &(_, t, s) in &cands {
            if m.mate[t as usize] == NONE && m.mate[s as usize] == NONE {
                m.mate[t as usize] = s;
                m.mate[s as usize] = t;
            }
        }
        drop(cands);
        for t in 0..n as u32 {
            self.stop()?;
            if self.tri_alive[t as usize] && m.mate[t as usize] == NONE && self.frozen[t as usize] == NONE {
                self.augment(&mut m, t);
            }
        }
        m.log.clear();
        let mut edges: Vec<(u32, usize)> = Vec::new();
        let mut ring: Vec<u32> = Vec::new();
        let mut seen: Vec<(u32, u32)> = Vec::new();
        for _ in 0..FLIP_PASSES {
            let mut grown = 0;
            for t in 0..n as u32 {
                self.stop()?;
                if !self.tri_alive[t as usize]
                    || m.mate[t as usize] != NONE
                    || self.frozen[t as usize] != NONE
                {
                    continue;
                }
                // The edges of t, then of its neighbours, then of theirs.
                edges.clear();
                ring.clear();
                ring.push(t);
                let mut i = 0;
                while i < ring.len() && ring.len() < RING {
                    let x = ring[i];
                    i += 1;
                    for k in 0..3 {
                        if let Some((s, _)) = self.across(x, k) {
                            if !ring.contains(&s) {
                                ring.push(s);
                            }
                        }
                    }
                }
                for &x in &ring {
                    for k in 0..3 {
                        let e = self.tris[x as usize];
                        let key = (e[k].min(e[(k + 1) % 3]), e[k].max(e[(k + 1) % 3]));
                        if !seen.contains(&key) {
                            seen.push(key);
                            edges.push((x, k));
                        }
                    }
                }
                seen.clear();
                for &(t1, k) in &edges {
                    if m.mate[t as usize] != NONE {
                        break;
                    }
                    if !self.flip_could_pair(t1, k) {
                        continue;
                    }
                    let Some(f) = self.plan_flip(t1, k) else { continue };
                    let [t1, t2] = f.t;
                    let undo = self.apply_flip_undoable(f);
                    m.log.clear();
                    let mut roots = vec![t, t1, t2];
                    for x in [t1, t2] {
                        let old = m.mate[x as usize];
                        if old != NONE {
                            m.set(x, NONE);
                            m.set(old, NONE);
                            roots.push(old);
                        }
                    }
                    // The matching must end with more pairs than it had before the flip.
                    let broken = roots.len() - 3;
                    let mut found = 0;
                    for &r in &roots {
                        if m.mate[r as usize] == NONE && self.augment(&mut m, r) {
                            found += 1;
                        }
                    }
                    if found > broken {
                        grown += 1;
                    } else {
                        m.undo();
                        self.undo_flip(undo);
                    }
                }
            }
            if grown == 0 {
                break;
            }
        }
        Ok(())
    }

    /// Whether, after the flip of edge `k` of `t1`, each of the two new triangles would
    /// make an acceptable quad with a neighbour (the other new one included): a flip
    /// that leaves one of them with none cannot let the matching grow.
    fn flip_could_pair(&self, t1: u32, k: usize) -> bool {
        let Some((t2, y)) = self.across(t1, k) else { return false };
        let s1 = self.tris[t1 as usize];
        let (a, b, x) = (s1[k], s1[(k + 1) % 3], s1[(k + 2) % 3]);
        let s2 = self.tris[t2 as usize];
        let j = s2.iter().position(|&w| w == b).expect("across");
        let dih = self.options.max_quad_dihedral_deg;
        let quad = |t: u32, e: usize, p: u32, q: u32, r: u32| {
            // New triangle (p, q, r), its edge p -> q where edge e of t is.
            self.across(t, e).is_some_and(|(_, w)| crate::pair::score(&self.pos, p, q, r, w, dih).is_some())
        };
        let together = crate::pair::score(&self.pos, x, y, b, a, dih).is_some();
        // n1 = (x, a, y): edges x -> a (t1's edge (k + 2)) and a -> y (t2's edge j + 1).
        let n1 = together || quad(t1, (k + 2) % 3, x, a, y) || quad(t2, (j + 1) % 3, a, y, x);
        // n2 = (y, b, x): edges y -> b (t2's edge j + 2) and b -> x (t1's edge k + 1).
        let n2 = together || quad(t2, (j + 2) % 3, y, b, x) || quad(t1, (k + 1) % 3, b, x, y);
        n1 && n2
    }

    /// The triangle across edge `k` of `t` and the score of their quad, where they pair.
    fn quad_across(&self, t: u32, k: usize) -> Option<(u32, f64)> {
        let (s, y) = self.across(t, k)?;
        let tri = self.tris[t as usize];
        let (a, b, x) = (tri[k], tri[(k + 1) % 3], tri[(k + 2) % 3]);
        crate::pair::score(&self.pos, a, b, x, y, self.options.max_quad_dihedral_deg).map(|sc| (s, sc))
    }

    /// An augmenting path from `root` (left alone) to another triangle left alone, along
    /// quads, by a bounded breadth-first search; swaps its pairs. Whether one was found.
    fn augment(&self, m: &mut Matching, root: u32) -> bool {
        m.round += 1;
        let round = m.round;
        let mut queue = vec![root];
        m.stamp[root as usize] = round;
        let mut head = 0;
        let mut end = None;
        'search: while head < queue.len() && queue.len() < MAX_SEARCH {
            let t = queue[head];
            head += 1;
            for k in 0..3 {
                let Some((s, _)) = self.quad_across(t, k) else { continue };
                if m.stamp[s as usize] == round {
                    continue;
                }
                m.stamp[s as usize] = round;
                m.via[s as usize] = t;
                let r = m.mate[s as usize];
                if r == NONE {
                    end = Some(s);
                    break 'search;
                }
                if m.stamp[r as usize] != round {
                    m.stamp[r as usize] = round;
                    queue.push(r);
                }
            }
        }
        let Some(mut s) = end else { return false };
        loop {
            let t = m.via[s as usize];
            let prev = m.mate[t as usize];
            m.set(s, t);
            m.set(t, s);
            if t == root {
                return true;
            }
            s = prev;
        }
    }

    /// The triangle across edge `k` of triangle `t1` (from corner `k` to the next) and its
    /// third corner, where the edge is inside one patch (exactly two triangles of one
    /// patch, running it in opposite directions) and neither triangle is frozen.
    pub(super) fn across(&self, t1: u32, k: usize) -> Option<(u32, u32)> {
        let s1 = self.tris[t1 as usize];
        let (a, b) = (s1[k], s1[(k + 1) % 3]);
        let mut other = None;
        let mut count = 0;
        for &t in &self.vtris[a as usize] {
            if self.tris[t as usize].contains(&b) {
                count += 1;
                if t != t1 {
                    other = Some(t);
                }
            }
        }
        let t2 = other?;
        if count != 2
            || self.tri_key[t1 as usize] != self.tri_key[t2 as usize]
            || self.frozen[t1 as usize] != NONE
            || self.frozen[t2 as usize] != NONE
        {
            return None;
        }
        let s2 = self.tris[t2 as usize];
        let j = s2.iter().position(|&w| w == b)?;
        (s2[(j + 1) % 3] == a).then_some((t2, s2[(j + 2) % 3]))
    }

    /// Plans the flip of edge `k` of triangle `t1`: triangles `(a, b, x)` and `(b, a, y)`
    /// become `(x, a, y)` and `(y, b, x)`. Refused where the edge is not inside one patch,
    /// where `x` and `y` are joined already (anywhere in the complex), where a normal would
    /// turn more than a collapse may turn one or a triangle of lower quality than a
    /// collapse may make would appear, where a region's volume or a patch's area would
    /// leave its tolerance, where an input vertex the two triangles answer for would lie
    /// farther than the budget from both new ones, or where a new triangle would meet
    /// another off their shared corners and edges.
    pub(super) fn plan_flip(&mut self, t1: u32, k: usize) -> Option<Flip> {
        let (t2, y) = self.across(t1, k)?;
        let s1 = self.tris[t1 as usize];
        let (a, b, x) = (s1[k], s1[(k + 1) % 3], s1[(k + 2) % 3]);
        if x == y || self.vtris[x as usize].iter().any(|&t| self.tris[t as usize].contains(&y)) {
            return None;
        }
        let sig = self.star_signature(a, b);
        if is_feature(&sig) {
            return None;
        }
        let new = [[x, a, y], [y, b, x]];
        let old = [s1, self.tris[t2 as usize]];
        let at = |t: [u32; 3]| t.map(|w| self.pos[w as usize]);
        let min_q = self.options.min_triangle_quality.min(quality(at(old[0]))).min(quality(at(old[1])));
        for n in new {
            let n1 = tri_normal(at(n));
            if n1.length_squared() <= 0.0 || quality(at(n)) < min_q {
                return None;
            }
            for o in old {
                let n0 = tri_normal(at(o));
                if n0.length_squared() <= 0.0 || n0.normalize().dot(n1.normalize()) < self.cos_normal {
                    return None;
                }
            }
        }
        // Area and six times the volume (relative to a), changes.
        let key = self.tri_key[t1 as usize];
        let area = |t: [u32; 3]| 0.5 * tri_normal(at(t)).length();
        let da = area(new[0]) + area(new[1]) - area(old[0]) - area(old[1]);
        let pa = self.pos[a as usize];
        let r = [y, b, x].map(|w| self.pos[w as usize] - pa);
        let dv = r[0].dot(r[1].cross(r[2]));
        let [ra, rb] = self.key_regions[key as usize];
        let deltas = [(false, key, da), (true, ra, dv), (true, rb, -dv)];
        for &(kind, id, d) in &deltas {
            let (total, so_far) =
                if kind { self.region_volume[id as usize] } else { self.patch_area[id as usize] };
            let tolerance = if kind { VOLUME_TOLERANCE } else { AREA_TOLERANCE };
            if (so_far + d).abs() > tolerance * total.abs() {
                return None;
            }
        }
        // The distance budget.
        let mut assigned = Vec::new();
        for &t in &[t1, t2] {
            for &p in &self.points[t as usize] {
                let pp = self.input.positions[p as usize];
                let (d0, d1) =
                    (point_triangle_distance(pp, at(new[0])), point_triangle_distance(pp, at(new[1])));
                let best = if d1 < d0 { (d1, t2) } else { (d0, t1) };
                if best.0.is_nan() || best.0 > self.max_error {
                    return None;
                }
                assigned.push((p, best.1, best.0));
            }
        }
        // No new intersection, tested exactly as a collapse's.
        if let Some(grid) = self.grid.as_ref() {
            let tested = new.map(|n| (n, at(n)));
            let (mut lo, mut hi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
            for (_, p3) in &tested {
                lo = lo.min(p3[0].min(p3[1]).min(p3[2]));
                hi = hi.max(p3[0].max(p3[1]).max(p3[2]));
            }
            let mut near = Vec::new();
            grid.candidates_into(lo, hi, &mut near);
            for &s in &near {
                if s == t1 || s == t2 || !self.tri_alive[s as usize] {
                    continue;
                }
                let st = self.tris[s as usize];
                let q = at(st);
                for (tri, p3) in &tested {
                    if !super::boxes_meet(p3, &q) {
                        continue;
                    }
                    let meet = meet_off_shared((*tri, *p3), (st, q));
                    if meet {
                        return None;
                    }
                }
            }
            if meet_off_shared(tested[0], tested[1]) {
                return None;
            }
        }
        Some(Flip { t: [t1, t2], new, assigned, deltas })
    }

    /// Makes a planned flip, keeping what undoes it.
    pub(super) fn apply_flip_undoable(&mut self, f: Flip) -> Undo {
        let undo = Undo {
            t: f.t,
            old: f.t.map(|t| self.tris[t as usize]),
            points: f.t.map(|t| self.points[t as usize].clone()),
            error_bound: self.error_bound,
            deltas: f.deltas,
        };
        self.apply_flip(f);
        undo
    }

    /// Undoes the flip made last.
    pub(super) fn undo_flip(&mut self, u: Undo) {
        let [t1, t2] = u.t;
        let [x, a, y] = self.tris[t1 as usize];
        let b = self.tris[t2 as usize][1];
        self.relink(u.t, u.old, [(y, t1), (x, t2)], [(a, t2), (b, t1)]);
        let [p1, p2] = u.points;
        self.points[t1 as usize] = p1;
        self.points[t2 as usize] = p2;
        self.error_bound = u.error_bound;
        self.add_deltas(&u.deltas, -1.0);
        self.rebox(t1);
        self.rebox(t2);
    }

    /// Makes a planned flip.
    pub(super) fn apply_flip(&mut self, f: Flip) {
        let [t1, t2] = f.t;
        let (a, b) = (f.new[0][1], f.new[1][1]);
        let (x, y) = (f.new[0][0], f.new[0][2]);
        self.relink(f.t, f.new, [(a, t2), (b, t1)], [(y, t1), (x, t2)]);
        for t in [t1, t2] {
            self.points[t as usize].clear();
        }
        for (p, t, d) in f.assigned {
            self.points[t as usize].push(p);
            self.error_bound = self.error_bound.max(d);
        }
        self.add_deltas(&f.deltas, 1.0);
        self.rebox(t1);
        self.rebox(t2);
        for v in [a, b, x, y] {
            self.version[v as usize] += 1;
        }
    }

    /// Gives the pair `t` the corners `tris`, taking each `(vertex, triangle)` of `off`
    /// out of the vertex's triangles and adding each of `on`, in that order (a flip and
    /// its undo are the same change with the lists swapped).
    fn relink(&mut self, t: [u32; 2], tris: [[u32; 3]; 2], off: [(u32, u32); 2], on: [(u32, u32); 2]) {
        self.tris[t[0] as usize] = tris[0];
        self.tris[t[1] as usize] = tris[1];
        for (v, gone) in off {
            self.vtris[v as usize].retain(|&t| t != gone);
        }
        for (v, added) in on {
            self.vtris[v as usize].push(added);
        }
    }
}
