//! Pairing triangles into quads: greedy by quad quality, within one patch.

use glam::DVec3;
use rayon::prelude::*;

use crate::Interrupt;

/// An output face: a triangle left alone, or a quad with one of its two triangles.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Face {
    /// Triangle `i` of the list.
    Tri(u32),
    /// A quad `[a, y, b, x]` of triangles `(a, b, x)` and `(b, a, y)` (its split along the
    /// diagonal from its first vertex gives them back), and the lower of their indices.
    Quad([u32; 4], u32),
}

fn angle(a: DVec3, b: DVec3) -> f64 {
    a.angle_between(b).to_degrees()
}

/// Pairs triangles `tris` (with patch `keys`) across edges inside a patch, best quads
/// first: a pair is a candidate when the two triangles run the edge in opposite
/// directions, are the only ones at the edge, have normals within `max_dihedral_deg` and
/// make a quad convex at the diagonal's ends (each corner under 170 degrees). The score
/// is the largest deviation of a corner from 90 degrees plus the dihedral angle. Faces
/// come out in the order of their lowest triangle. Triangles with a `frozen` input face
/// (not `u32::MAX`) come out as that face of `input`, once. `max_dihedral_deg` `None`:
/// no pairs. Once `interrupt` is raised the scores and the augmenting paths are skipped
/// (the caller discards the faces).
pub(crate) fn pair(
    pos: &[DVec3],
    tris: &[[u32; 3]],
    keys: &[u32],
    frozen: &[u32],
    input: &[[u32; 4]],
    max_dihedral_deg: Option<f64>,
    interrupt: &Interrupt,
) -> Vec<Face> {
    let mut taken = vec![false; tris.len()];
    let mut faces: Vec<(u32, Face)> = Vec::with_capacity(tris.len());
    for t in 0..tris.len() {
        if frozen[t] != u32::MAX {
            taken[t] = true;
            if t == 0 || frozen[t - 1] != frozen[t] {
                faces.push((t as u32, Face::Quad(input[frozen[t] as usize], t as u32)));
            }
        }
    }
    let Some(max_dihedral_deg) = max_dihedral_deg else {
        faces.extend((0..tris.len()).filter(|&t| !taken[t]).map(|t| (t as u32, Face::Tri(t as u32))));
        faces.sort_unstable_by_key(|f| f.0);
        return faces.into_iter().map(|f| f.1).collect();
    };
    // (edge low, edge high, triangle, corner index of the edge's start)
    let mut edges: Vec<(u32, u32, u32, u8)> = Vec::with_capacity(3 * tris.len());
    for (i, t) in tris.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            edges.push((a.min(b), a.max(b), i as u32, k as u8));
        }
    }
    edges.par_sort_unstable();
    // The pairs of triangles of one patch at an edge with no other, running it in
    // opposite directions; then their scores, in parallel.
    let mut pairs: Vec<(u32, u32, [u32; 4])> = Vec::new();
    let mut i = 0;
    while i < edges.len() {
        let mut j = i + 1;
        while j < edges.len() && edges[j].0 == edges[i].0 && edges[j].1 == edges[i].1 {
            j += 1;
        }
        if j - i == 2 {
            let (t1, k1) = (edges[i].2, edges[i].3 as usize);
            let (t2, k2) = (edges[i + 1].2, edges[i + 1].3 as usize);
            let (s1, s2) = (tris[t1 as usize], tris[t2 as usize]);
            let (a, b, x) = (s1[k1], s1[(k1 + 1) % 3], s1[(k1 + 2) % 3]);
            if keys[t1 as usize] == keys[t2 as usize] && s2[k2] == b && s2[(k2 + 1) % 3] == a {
                let y = s2[(k2 + 2) % 3];
                pairs.push((t1.min(t2), t1.max(t2), [a, y, b, x]));
            }
        }
        i = j;
    }
    drop(edges);
    let mut candidates: Vec<(u64, u32, u32, [u32; 4])> = pairs
        .par_iter()
        .filter_map(|&(t1, t2, q)| {
            if interrupt.is_raised() {
                return None;
            }
            let [a, y, b, x] = q;
            score(pos, a, b, x, y, max_dihedral_deg).map(|s| (s.to_bits(), t1, t2, q))
        })
        .collect();
    drop(pairs);
    candidates.par_sort_unstable();
    // Greedy, best quads first; then augmenting paths, so that a triangle left alone by
    // the greedy pass is paired by re-pairing a chain of its neighbours.
    let mut mate = vec![NO_MATE; tris.len()];
    for (c, &(_, t1, t2, _)) in candidates.iter().enumerate() {
        if !taken[t1 as usize]
            && !taken[t2 as usize]
            && mate[t1 as usize] == NO_MATE
            && mate[t2 as usize] == NO_MATE
        {
            mate[t1 as usize] = c as u32;
            mate[t2 as usize] = c as u32;
        }
    }
    augment(&candidates, &mut mate, &taken, interrupt);
    for (t, &m) in mate.iter().enumerate() {
        if m != NO_MATE {
            let (_, t1, _, q) = candidates[m as usize];
            if t1 as usize == t {
                taken[t] = true;
                faces.push((t1, Face::Quad(q, t1)));
            }
        } else if !taken[t] {
            faces.push((t as u32, Face::Tri(t as u32)));
        }
    }
    faces.sort_unstable_by_key(|f| f.0);
    faces.into_iter().map(|f| f.1).collect()
}

/// No pair.
const NO_MATE: u32 = u32::MAX;

/// How many triangles one augmenting-path search visits at most (keeps the pass linear).
const MAX_SEARCH: usize = 256;

/// Grows the matching `mate` (per triangle, the index of its pair in `candidates`) by
/// augmenting paths: from each triangle left alone, a breadth-first search along
/// alternating paths (a candidate pair, then a matched pair) to another triangle left
/// alone; the path's pairs then swap. Searches are bounded and ignore odd cycles, so
/// the matching grows but need not become maximum; every pair stays a candidate.
fn augment(
    candidates: &[(u64, u32, u32, [u32; 4])],
    mate: &mut [u32],
    frozen: &[bool],
    interrupt: &Interrupt,
) {
    let n = mate.len();
    let mut adj: Vec<Vec<u32>> = vec![Vec::new(); n];
    for (c, &(_, t1, t2, _)) in candidates.iter().enumerate() {
        if !frozen[t1 as usize] && !frozen[t2 as usize] {
            adj[t1 as usize].push(c as u32);
            adj[t2 as usize].push(c as u32);
        }
    }
    let other = |c: u32, t: u32| {
        let (_, a, b, _) = candidates[c as usize];
        if a == t {
            b
        } else {
            a
        }
    };
    // Per triangle reached: the candidate that reached it from the even side, and a stamp.
    let mut via = vec![NO_MATE; n];
    let mut stamp = vec![0u32; n];
    let mut queue: Vec<u32> = Vec::new();
    for (root, round) in (0..n).zip(1u32..) {
        if mate[root] != NO_MATE || frozen[root] || adj[root].is_empty() {
            continue;
        }
        if interrupt.is_raised() {
            return;
        }
        queue.clear();
        queue.push(root as u32);
        stamp[root] = round;
        let mut head = 0;
        let mut end = None;
        'search: while head < queue.len() && queue.len() < MAX_SEARCH {
            let t = queue[head];
            head += 1;
            for &c in &adj[t as usize] {
                let s = other(c, t);
                if stamp[s as usize] == round {
                    continue;
                }
                stamp[s as usize] = round;
                via[s as usize] = c;
                if mate[s as usize] == NO_MATE {
                    end = Some(s);
                    break 'search;
                }
                // Go on from s's partner.
                let r = other(mate[s as usize], s);
                if stamp[r as usize] == round {
                    continue;
                }
                stamp[r as usize] = round;
                queue.push(r);
            }
        }
        // Swap along the path: s takes its via pair, its old partner r goes on back.
        let Some(mut s) = end else { continue };
        loop {
            let c = via[s as usize];
            let t = other(c, s);
            let prev = mate[t as usize];
            mate[s as usize] = c;
            mate[t as usize] = c;
            if t as usize == root {
                break;
            }
            s = other(prev, t);
            let _ = prev;
        }
    }
}

/// The score of the quad `[a, y, b, x]` (lower is better), if it is acceptable.
pub(crate) fn score(pos: &[DVec3], a: u32, b: u32, x: u32, y: u32, max_dihedral_deg: f64) -> Option<f64> {
    let [pa, pb, px, py] = [a, b, x, y].map(|v| pos[v as usize]);
    let n1 = (pb - pa).cross(px - pa);
    let n2 = (pa - pb).cross(py - pb);
    if n1.length_squared() <= 0.0 || n2.length_squared() <= 0.0 {
        return None;
    }
    let dihedral = angle(n1, n2);
    if dihedral.is_nan() || dihedral > max_dihedral_deg {
        return None;
    }
    let at_a = angle(pb - pa, px - pa) + angle(pb - pa, py - pa);
    let at_b = angle(pa - pb, px - pb) + angle(pa - pb, py - pb);
    if at_a.is_nan() || at_b.is_nan() || at_a >= 170.0 || at_b >= 170.0 {
        return None;
    }
    let at_x = angle(pa - px, pb - px);
    let at_y = angle(pa - py, pb - py);
    let dev = [at_a, at_b, at_x, at_y].iter().map(|t| (t - 90.0).abs()).fold(0.0, f64::max);
    Some(dev + dihedral)
}
