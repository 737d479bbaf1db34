//! The cheap re-estimate of the fast pipeline: the quads' vector areas diffused over the
//! surfel graph of each interface.

use glam::{DVec3, Vec3A};
use rayon::prelude::*;
use rustc_hash::{FxHashMap as HashMap, FxHashSet as HashSet};

use voxreg_digisurf::{DigitalSurface, EdgeId, EdgeKind, Surfel, SurfelId};

use crate::error::NormalError;
use crate::estimator::NormalEstimator;
use crate::field::NormalField;
use crate::interrupt::Interrupt;

/// The bits of a [`QuadGraph`] surfel's `info` that count its neighbours (0 to 4).
const COUNT: u8 = 0b111;

/// The bit of a [`QuadGraph`] surfel's `info` set when one of its edges is a junction
/// edge (its surfels span two interfaces or more).
const JUNCTION: u8 = 1 << 7;

/// The bit of a [`QuadGraph`] surfel's `info` set when one of its neighbours has the
/// opposite orientation ([`FLIP`]): the others' rounds add their neighbours' vectors as
/// they are.
const FLIPPED: u8 = 1 << 6;

/// The bit of a [`QuadGraph`] slot whose neighbour's orientation is the opposite of the
/// surfel's (surfel ids are below `2^30`).
const FLIP: u32 = 1 << 31;

/// The weight of a quad with a junction edge among the diffusion's sources: such quads
/// are bent by the other interfaces that meet there, so the field next to a junction is
/// taken from the interior (a small weight rather than none keeps a direction where no
/// interior quad is within reach).
const JUNCTION_SOURCE_WEIGHT: f64 = 1e-3;

/// Surfels per parallel task of a diffusion round.
const CHUNK: usize = 4096;

/// Each surfel's neighbours for [`Diffused`], one across each of its four edges at most:
/// the surfel of the same interface that does not face the opposite way (at a pinch edge,
/// the two perpendicular ones; never the other side of a sheet one voxel thick), else,
/// across a junction edge, the smooth continuation: the coplanar surfel of another
/// interface that shares a region with it on the same side (the sphere across the cut of a
/// split ball), its orientation flipped where the shared region is on the other side. A
/// quad is never averaged with one across a crease of the staircase between interfaces.
/// Built once per surface, 17 bytes a surfel.
#[derive(Clone, Debug, Default)]
pub struct QuadGraph {
    /// The neighbours first, then the number of surfels (a zero vector of the diffusion)
    /// in the empty slots: a step reads four slots without a branch.
    nbrs: Vec<[u32; 4]>,
    /// Per surfel, its number of neighbours ([`COUNT`]) and [`JUNCTION`].
    info: Vec<u8>,
}

impl QuadGraph {
    /// The graph of `surface`.
    pub fn new(surface: &DigitalSurface) -> Self {
        let surfels = surface.surfels();
        let none = surfels.len() as u32;
        let continuations = Continuations::new(surface);
        let (nbrs, info) = (0..surfels.len())
            .into_par_iter()
            .map(|s| {
                let me = &surfels[s];
                let mut out = [none; 4];
                let mut k = 0;
                let mut junction = false;
                for e in surface.surfel_edges(SurfelId(s as u32)) {
                    let others = surface.edge_surfels(e);
                    let mut found = false;
                    for &t in others {
                        let other = &surfels[t.index()];
                        if t.index() == s {
                            continue;
                        }
                        if other.interface != me.interface {
                            junction = true;
                            continue;
                        }
                        found = true;
                        // Not facing the opposite way: perpendicular, or the same orientation.
                        let facing = other.axis != me.axis || other.flipped == me.flipped;
                        if facing && k < 4 && !out[..k].contains(&t.0) {
                            out[k] = t.0;
                            k += 1;
                        }
                    }
                    if found || k == 4 {
                        continue;
                    }
                    for &t in others {
                        let other = &surfels[t.index()];
                        if t.index() == s {
                            continue;
                        }
                        let Some(flip) = continuation(me, other) else { continue };
                        if continuations.dominant(e, me, other) {
                            out[k] = t.0 | if flip { FLIP } else { 0 };
                            k += 1;
                            break;
                        }
                    }
                }
                let flipped = out[..k].iter().any(|&t| t & FLIP != 0);
                (out, k as u8 | if junction { JUNCTION } else { 0 } | if flipped { FLIPPED } else { 0 })
            })
            .unzip();
        QuadGraph { nbrs, info }
    }

    /// Number of surfels.
    pub fn len(&self) -> usize {
        self.nbrs.len()
    }

    /// Whether the graph has no surfel.
    pub fn is_empty(&self) -> bool {
        self.nbrs.is_empty()
    }

    /// Bytes held.
    pub fn memory_bytes(&self) -> usize {
        17 * self.nbrs.len()
    }
}

/// Whether `b`, a surfel of another interface across an edge of `a`, continues `a`'s
/// surface there: coplanar (the same axis) and sharing a region with it on the same side,
/// with `Some(true)` where `b`'s orientation is flipped relative to `a`'s (the shared
/// region is `a`'s inner and `b`'s outer, or the reverse).
fn continuation(a: &Surfel, b: &Surfel) -> Option<bool> {
    if a.axis != b.axis {
        return None;
    }
    let [p, q] = a.regions;
    let [r, t] = b.regions;
    let sign = if p == r || q == t {
        1.0
    } else if p == t || q == r {
        -1.0
    } else {
        return None;
    };
    // The same axis: the normals' dot is +1 or -1.
    let dot = if a.flipped == b.flipped { 1.0 } else { -1.0 };
    (sign * dot > 0.0).then_some(sign < 0.0)
}

/// Half the side of the window (lattice units, Chebyshev distance) over which
/// [`Continuations`] counts a pair's junction edges: wide enough to hold a stretch of a
/// junction curve with its steps, small next to a chunked run's halo, which it adds to.
const CONTINUATION_WINDOW: u32 = 6;

/// Two interfaces that meet at a junction edge, named by their label pairs so that the
/// name is the same in any chunk of the volume: `(lower, higher)`.
type PairKey = ([u32; 2], [u32; 2]);

/// The label pair of a surfel's interface, lower label first.
fn labels_of(s: &Surfel) -> [u32; 2] {
    let [a, b] = s.labels;
    [a.min(b), a.max(b)]
}

/// The key of the unordered pair of the interfaces of two surfels.
fn pair_key(a: &Surfel, b: &Surfel) -> PairKey {
    let (p, q) = (labels_of(a), labels_of(b));
    (p.min(q), p.max(q))
}

/// Per junction edge, each pair of its interfaces with the share of the junction edges
/// near it (within [`CONTINUATION_WINDOW`]) that hold the pair and at which one of the two
/// continues the other ([`continuation`]: the region between them fills two of the edge's
/// four voxels).
///
/// Why: along a junction curve the staircase makes every pair of its interfaces coplanar
/// here and there. The pair that continues each other in the geometry (the two caps of a
/// split ball, whose region between them spans 180 degrees) does so at most of its edges;
/// the others (a cap and the cut disc, at 90 degrees) only where the digital curve steps.
/// Linking those would diffuse the disc's normal into the sphere and back, and sink the
/// junction along the disc's normal. Counted in a window, not over the whole surface, so
/// that a chunk with a halo a window wider than the diffusion's reach decides as the whole
/// volume does.
struct Continuations {
    /// The junction edges, ascending.
    edges: Vec<u32>,
    /// Per junction edge, the end of its pairs in `pairs`.
    ends: Vec<u32>,
    /// Each junction edge's pairs, with their share in the window.
    pairs: Vec<(PairKey, f32)>,
}

/// Each pair of interfaces at each junction edge, edge after edge: the edge's id, its
/// lower corner, the pair, and whether they continue each other there.
fn junction_pairs(surface: &DigitalSurface) -> Vec<(u32, [u32; 3], PairKey, bool)> {
    let surfels = surface.surfels();
    // A junction edge has at most four surfels, so at most six pairs, kept inline.
    // The edges other than regular ones first (a few percent of them): a regular edge
    // has one interface.
    let edges = surface.edges();
    let candidates: Vec<u32> = (0..edges.len() as u32)
        .into_par_iter()
        .filter(|&e| edges[e as usize].kind != EdgeKind::Regular)
        .collect();
    candidates
        .par_iter()
        .flat_map_iter(|&e| {
            let mut votes = [(([0u32; 2], [0u32; 2]), false); 6];
            let mut n = 0;
            let mut corner = [0u32; 3];
            let others = surface.edge_surfels(EdgeId(e));
            let mixed = others.first().is_some_and(|s0| {
                others.iter().any(|s| surfels[s.index()].interface != surfels[s0.index()].interface)
            });
            if mixed {
                corner = surface.vertex_corner(edges[e as usize].vertices[0]);
                for (i, a) in others.iter().enumerate() {
                    let a = &surfels[a.index()];
                    for b in &others[..i] {
                        let b = &surfels[b.index()];
                        if a.interface == b.interface {
                            continue;
                        }
                        let key = pair_key(a, b);
                        let continued = continuation(a, b).is_some();
                        match votes[..n].iter_mut().find(|(k, _)| *k == key) {
                            Some((_, c)) => *c |= continued,
                            None if n < 6 => {
                                votes[n] = (key, continued);
                                n += 1;
                            }
                            None => {}
                        }
                    }
                }
            }
            votes.into_iter().take(n).map(move |(key, continued)| (e, corner, key, continued))
        })
        .collect()
}

/// Per record of [`junction_pairs`], the share of the records of its pair within
/// [`CONTINUATION_WINDOW`] of its corner (Chebyshev distance, itself included) at which
/// one interface continues the other.
fn window_shares(found: &[(u32, [u32; 3], PairKey, bool)]) -> Vec<f32> {
    // Each pair at each junction edge (its records, in the order of `found`),
    // sorted by pair and cell of the window's size, in runs (groups) of one pair and
    // cell: an edge's window is scanned for its own pair only, and a group's records
    // share the 27 groups their windows can reach. A group is named by one `u128`, the
    // pair's rank among the pairs met and the cell's three coordinates, which orders
    // as (pair, cell) and hashes in two words.
    let w = CONTINUATION_WINDOW;
    let mut pairs: Vec<PairKey> = found.iter().map(|r| r.2).collect::<HashSet<_>>().into_iter().collect();
    pairs.sort_unstable();
    let group_key = |pair: u32, [x, y, z]: [u32; 3]| {
        (u128::from(pair) << 96) | (u128::from(x) << 64) | (u128::from(y) << 32) | u128::from(z)
    };
    let parts = |key: u128| ((key >> 96) as u32, [(key >> 64) as u32, (key >> 32) as u32, key as u32]);
    let mut sorted: Vec<(u128, u32)> = found
        .par_iter()
        .enumerate()
        .map(|(r, &(_, corner, key, _))| {
            let pair = pairs.binary_search(&key).expect("every pair was collected") as u32;
            (group_key(pair, corner.map(|c| c / w)), r as u32)
        })
        .collect();
    sorted.par_sort_unstable();
    // Each record's corner and flag (0 or 1), in `sorted`'s order.
    let records: Vec<([u32; 3], u32)> =
        sorted.par_iter().map(|&(_, r)| (found[r as usize].1, u32::from(found[r as usize].3))).collect();
    let mut groups: Vec<(u128, u32)> = Vec::new(); // key, start in `sorted`
    let mut index: HashMap<u128, u32> = HashMap::default();
    for (i, &(key, _)) in sorted.iter().enumerate() {
        if groups.last().is_none_or(|g| g.0 != key) {
            index.insert(key, groups.len() as u32);
            groups.push((key, i as u32));
        }
    }
    let group_range = |g: usize| {
        let end = groups.get(g + 1).map_or(sorted.len(), |n| n.1 as usize);
        groups[g].1 as usize..end
    };
    // Each group's shares in `sorted`'s order, its candidates (the records of the 27
    // groups its windows can reach: corner and flag) gathered once into a buffer of the
    // thread's; then in record order.
    let mut by_sorted = vec![0f32; sorted.len()];
    let mut slices: Vec<&mut [f32]> = Vec::with_capacity(groups.len());
    let mut rest = &mut by_sorted[..];
    for g in 0..groups.len() {
        let (head, tail) = std::mem::take(&mut rest).split_at_mut(group_range(g).len());
        slices.push(head);
        rest = tail;
    }
    // The candidates' corners one axis an array, and their flags as 0 or 1: the
    // count below is branch-free over them, in SIMD lanes.
    let buffers = || (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    slices.into_par_iter().enumerate().for_each_init(buffers, |(xs, ys, zs, cs), (g, out)| {
        let (pair, [cx, cy, cz]) = parts(groups[g].0);
        for v in [&mut *xs, &mut *ys, &mut *zs, &mut *cs] {
            v.clear();
        }
        for x in cx.saturating_sub(1)..=cx + 1 {
            for y in cy.saturating_sub(1)..=cy + 1 {
                for z in cz.saturating_sub(1)..=cz + 1 {
                    if let Some(&n) = index.get(&group_key(pair, [x, y, z])) {
                        for &(corner, flag) in &records[group_range(n as usize)] {
                            xs.push(corner[0]);
                            ys.push(corner[1]);
                            zs.push(corner[2]);
                            cs.push(flag);
                        }
                    }
                }
            }
        }
        for (share, i) in out.iter_mut().zip(group_range(g)) {
            // Within `w` of the corner on an axis: `a - (corner - w)` at most `2 w`,
            // in wrapping arithmetic (below the corner's `- w`, it wraps past it).
            let lo = records[i].0.map(|c| c.wrapping_sub(w));
            let (mut continued, mut all) = (0u32, 0u32);
            for (((x, y), z), c) in xs.iter().zip(&*ys).zip(&*zs).zip(&*cs) {
                let inside = u32::from(x.wrapping_sub(lo[0]) <= 2 * w)
                    & u32::from(y.wrapping_sub(lo[1]) <= 2 * w)
                    & u32::from(z.wrapping_sub(lo[2]) <= 2 * w);
                continued += inside & c;
                all += inside;
            }
            *share = continued as f32 / all.max(1) as f32;
        }
    });
    let mut shares = vec![0f32; sorted.len()];
    for (&(_, r), &share) in sorted.iter().zip(&by_sorted) {
        shares[r as usize] = share;
    }
    shares
}

impl Continuations {
    fn new(surface: &DigitalSurface) -> Self {
        let found = junction_pairs(surface);
        let shares = window_shares(&found);
        let (mut edges, mut ends) = (Vec::new(), Vec::new());
        for (i, &(e, ..)) in found.iter().enumerate() {
            if edges.last() != Some(&e) {
                if i > 0 {
                    ends.push(i as u32);
                }
                edges.push(e);
            }
        }
        if !found.is_empty() {
            ends.push(found.len() as u32);
        }
        let pairs = found.iter().zip(&shares).map(|(&(_, _, key, _), &share)| (key, share)).collect();
        Continuations { edges, ends, pairs }
    }

    /// Whether the pair of `a` and `b` (surfels of two interfaces at the junction edge
    /// `e`) continues each other at least as often near `e` as any other pair of the
    /// edge's interfaces.
    fn dominant(&self, e: EdgeId, a: &Surfel, b: &Surfel) -> bool {
        let Ok(i) = self.edges.binary_search(&e.0) else { return false };
        let start = if i == 0 { 0 } else { self.ends[i - 1] as usize };
        let pairs = &self.pairs[start..self.ends[i] as usize];
        let key = pair_key(a, b);
        let Some(&(_, mine)) = pairs.iter().find(|(k, _)| *k == key) else { return false };
        pairs.iter().all(|&(_, share)| share <= mine)
    }
}

/// Normals re-estimated from given vertex positions, cheaply: each quad's vector area
/// (oriented as its surfel; a quad with a junction edge weighted by 1e-3, as it is bent by
/// the other interfaces meeting there), then [`Diffused::steps`] rounds of diffusion over the
/// [`QuadGraph`] (`u <- mean of u over the quad and its neighbours`), normalized. On a flat
/// grid each round adds a variance of 0.4 square voxel per axis, so `radius^2 / 1.6`
/// rounds spread a quad's weight as far as the uniform disc of `radius` voxels (variance
/// `radius^2 / 4`) that an area-weighted mean over a ball would use, in O(`steps`) reads a
/// surfel and without any search. A quad whose diffused vector vanishes keeps its
/// `previous` normal.
///
/// Why: the fast pipeline re-estimates its field between batches of sweeps from quads that
/// already follow the shape; [`crate::refined::Refined`]'s discs and feature rule cost more than the
/// sweeps themselves. This rule has no feature rule: creases are rounded over the radius.
#[derive(Clone, Copy, Debug)]
pub struct Diffused<'a> {
    /// One position per vertex of the surface.
    pub positions: &'a [DVec3],
    /// The field being re-estimated (kept where the estimate degenerates).
    pub previous: &'a NormalField,
    /// The radius, in lattice steps, of the disc whose spread the diffusion matches.
    pub radius: f64,
}

impl Diffused<'_> {
    /// The diffusion rounds of `radius`: `radius^2 / 1.6`, rounded.
    pub fn steps(radius: f64) -> usize {
        (radius * radius / 1.6).round() as usize
    }

    /// The estimate on `surface`, whose graph is `graph` ([`QuadGraph::new`]); polls
    /// `interrupt` before each round.
    pub fn estimate_on(
        &self,
        surface: &DigitalSurface,
        graph: &QuadGraph,
        interrupt: &Interrupt,
    ) -> Result<NormalField, NormalError> {
        let u = diffuse(self.positions, self.previous.len(), self.radius, surface, graph, interrupt)?;
        let previous = self.previous.as_slice();
        Ok(NormalField::new(
            u[..previous.len()]
                .par_iter()
                .zip(previous)
                .map(|(v, p)| v.as_dvec3().try_normalize().unwrap_or(*p))
                .collect(),
        ))
    }

    /// [`Diffused::estimate_on`] with `field` as the previous normals, replaced in place by
    /// the estimate from `positions` with `radius`: the same normals, without a second
    /// field alive beside the first (the fast pipeline's peak memory is in its rounds).
    pub fn update_on(
        positions: &[DVec3],
        radius: f64,
        surface: &DigitalSurface,
        graph: &QuadGraph,
        field: &mut NormalField,
        interrupt: &Interrupt,
    ) -> Result<(), NormalError> {
        let u = diffuse(positions, field.len(), radius, surface, graph, interrupt)?;
        // As `NormalField::new` of the estimate: normalized once more, zero if degenerate.
        field.normals_mut().par_iter_mut().zip(&u[..]).for_each(|(p, v)| {
            *p = v.as_dvec3().try_normalize().unwrap_or(*p).try_normalize().unwrap_or(DVec3::ZERO)
        });
        Ok(())
    }
}

/// The diffused vector areas of [`Diffused`] (one per surfel, then the empty slots' zero
/// vector), from `positions` and `previous` normals of `surface` (checked against it).
fn diffuse(
    positions: &[DVec3],
    previous: usize,
    radius: f64,
    surface: &DigitalSurface,
    graph: &QuadGraph,
    interrupt: &Interrupt,
) -> Result<Vec<Vec3A>, NormalError> {
    let n = surface.num_surfels();
    if positions.len() != surface.num_vertices() || previous != n || graph.len() != n {
        return Err(NormalError::InvalidParameter(format!(
            "{} positions, {previous} normals and a graph of {} surfels for a surface of {} vertices and {n} surfels",
            positions.len(),
            graph.len(),
            surface.num_vertices()
        )));
    }
    if !(radius.is_finite() && radius >= 0.0) {
        return Err(NormalError::InvalidParameter(format!(
            "the diffusion radius must be finite and non-negative, got {radius}"
        )));
    }
    interrupt.check()?;
    let x = positions;
    let mut u: Vec<Vec3A> = surface
        .surfels()
        .par_iter()
        .zip(&graph.info)
        .map(|(s, &info)| {
            let [a, b, c, d] = s.vertices.map(|v| x[v.index()]);
            let w = if info & JUNCTION != 0 { JUNCTION_SOURCE_WEIGHT } else { 1.0 };
            (0.5 * w * (c - a).cross(d - b)).as_vec3a()
        })
        .chain(rayon::iter::once(Vec3A::ZERO))
        .collect();
    // The empty slots' zero vector at `n`, in both arrays.
    // Zeroed in parallel: a fresh array's pages are first touched by the threads that
    // fill them (`vec!` would have one thread zero them all).
    let mut next: Vec<Vec3A> = (0..=n).into_par_iter().map(|_| Vec3A::ZERO).collect();
    let scale: [f32; 5] = std::array::from_fn(|c| 1.0 / (1 + c) as f32);
    for _ in 0..Diffused::steps(radius) {
        interrupt.check()?;
        next[..n]
            .par_chunks_mut(CHUNK)
            .zip(graph.nbrs.par_chunks(CHUNK).zip(graph.info.par_chunks(CHUNK)))
            .enumerate()
            .for_each(|(chunk, (out, (nbrs, info)))| {
                let base = chunk * CHUNK;
                let own = &u[base..base + out.len()];
                for (((out, nb), &info), &mine) in out.iter_mut().zip(nbrs).zip(info).zip(own) {
                    let mut sum = mine;
                    if info & FLIPPED == 0 {
                        for &t in nb {
                            sum += u[t as usize];
                        }
                    } else {
                        for &t in nb {
                            // The flip bit is the sign bit of an f32: +1 or -1.
                            let sign = f32::from_bits((t & FLIP) | 1.0f32.to_bits());
                            sum += sign * u[(t & !FLIP) as usize];
                        }
                    }
                    *out = sum * scale[usize::from(info & COUNT)];
                }
            });
        std::mem::swap(&mut u, &mut next);
    }
    Ok(u)
}

impl NormalEstimator for Diffused<'_> {
    fn name(&self) -> &'static str {
        "diffused"
    }

    fn estimate_interruptible(
        &self,
        surface: &DigitalSurface,
        interrupt: &Interrupt,
    ) -> Result<NormalField, NormalError> {
        self.estimate_on(surface, &QuadGraph::new(surface), interrupt)
    }
}

/// The staircase's normals diffused: each surfel's vector area on the digital surface
/// (its axis, weighted as in [`Diffused`]) spread by [`Diffused`]'s diffusion over a disc
/// of `radius`, from the lattice positions. A cheap initial field for the fast pipeline:
/// its first batch of sweeps then starts from smooth normals instead of the staircase's
/// own, which a batch would barely move (the trivial field is already aligned with the
/// staircase).
#[derive(Clone, Copy, Debug, Default)]
pub struct DiffusedStaircase {
    /// The disc's radius in physical units; `None`: [`DiffusedStaircase::DEFAULT_RADIUS`]
    /// voxels of the finest axis.
    pub radius: Option<f64>,
}

impl DiffusedStaircase {
    /// The default radius, in voxels of the finest axis (lattice steps): the fast
    /// pipeline's first field, whose one batch of sweeps needs it wider than the
    /// re-estimates' 6 (on the sphere R = 20 with 24 sweeps, 1.30 degrees at 6, 1.12 at 8).
    pub const DEFAULT_RADIUS: f64 = 8.0;

    /// The radius in lattice steps on `surface` (the finest axis's voxels).
    pub fn steps_radius(&self, surface: &DigitalSurface) -> f64 {
        self.radius.map_or(Self::DEFAULT_RADIUS, |r| r / surface.spacing().min_element())
    }

    /// The estimate on `surface`, whose graph is `graph` ([`QuadGraph::new`]); polls
    /// `interrupt` before each round.
    pub fn estimate_on(
        &self,
        surface: &DigitalSurface,
        graph: &QuadGraph,
        interrupt: &Interrupt,
    ) -> Result<NormalField, NormalError> {
        if let Some(r) = self.radius {
            if !(r.is_finite() && r > 0.0) {
                return Err(NormalError::InvalidParameter(format!(
                    "the diffusion radius must be finite and positive, got {r}"
                )));
            }
        }
        let mut field = crate::Trivial.estimate_interruptible(surface, interrupt)?;
        let positions = surface.positions();
        Diffused::update_on(&positions, self.steps_radius(surface), surface, graph, &mut field, interrupt)?;
        Ok(field)
    }
}

impl NormalEstimator for DiffusedStaircase {
    fn name(&self) -> &'static str {
        "diffused"
    }

    fn estimate_interruptible(
        &self,
        surface: &DigitalSurface,
        interrupt: &Interrupt,
    ) -> Result<NormalField, NormalError> {
        self.estimate_on(surface, &QuadGraph::new(surface), interrupt)
    }
}

#[cfg(test)]
mod tests {
    use voxreg_digisurf::LabelVolume;

    use super::*;
    use crate::trivial::Trivial;

    fn ball(r: f64) -> DigitalSurface {
        let n = (2.0 * r) as usize + 3;
        let c = (n as f64 - 1.0) / 2.0;
        let v = LabelVolume::from_fn([n, n, n], |[x, y, z]| {
            u32::from(DVec3::new(x as f64 - c, y as f64 - c, z as f64 - c).length() <= r)
        });
        DigitalSurface::from_volume(&v).unwrap()
    }

    #[test]
    fn the_staircase_of_a_ball_diffuses_towards_radial_normals() {
        let s = ball(10.0);
        let trivial = Trivial.estimate(&s).unwrap();
        let positions = s.positions();
        let centre = positions.iter().copied().sum::<DVec3>() / positions.len() as f64;
        let radial: Vec<DVec3> = s
            .surfels()
            .iter()
            .map(|f| {
                (f.vertices.iter().map(|v| positions[v.index()]).sum::<DVec3>() / 4.0 - centre).normalize()
            })
            .collect();
        let error = |field: &NormalField| {
            field.as_slice().iter().zip(&radial).map(|(a, b)| a.dot(*b).clamp(-1.0, 1.0).acos()).sum::<f64>()
                / radial.len() as f64
        };
        let graph = QuadGraph::new(&s);
        assert!(graph.info.iter().all(|i| i & COUNT == 4));
        let none = s.num_surfels() as u32;
        assert!(graph.nbrs.iter().all(|nb| !nb.contains(&none)));
        let zero = Diffused { positions: &positions, previous: &trivial, radius: 0.0 }
            .estimate_on(&s, &graph, &Interrupt::never())
            .unwrap();
        assert_eq!(zero, trivial, "no round: each quad's own normal");
        let three = Diffused { positions: &positions, previous: &trivial, radius: 4.0 }
            .estimate_on(&s, &graph, &Interrupt::never())
            .unwrap();
        // Orientation kept (outward), and far closer to the radial direction.
        assert!(three.as_slice().iter().zip(&radial).all(|(a, b)| a.dot(*b) > 0.8));
        assert!(error(&three) < 0.4 * error(&trivial), "{} vs {}", error(&three), error(&trivial));
        assert_eq!(
            Diffused { positions: &positions, previous: &trivial, radius: 4.0 }.estimate(&s).unwrap(),
            three
        );
    }

    /// The staircase estimator is the re-estimate from the lattice positions, with the
    /// trivial field kept where it degenerates; its radius is in physical units,
    /// [`DiffusedStaircase::DEFAULT_RADIUS`] voxels of the finest axis by default.
    #[test]
    fn the_staircase_estimate_is_the_re_estimate_of_the_lattice() {
        let s = ball(8.0);
        let trivial = Trivial.estimate(&s).unwrap();
        let positions = s.positions();
        let graph = QuadGraph::new(&s);
        let r = DiffusedStaircase::DEFAULT_RADIUS;
        let direct = Diffused { positions: &positions, previous: &trivial, radius: r }
            .estimate_on(&s, &graph, &Interrupt::never())
            .unwrap();
        let staircase = DiffusedStaircase::default();
        assert_eq!(staircase.steps_radius(&s), DiffusedStaircase::DEFAULT_RADIUS);
        assert_eq!(staircase.estimate(&s).unwrap(), direct);
        assert_eq!(DiffusedStaircase { radius: Some(r) }.estimate(&s).unwrap(), direct);
        assert_ne!(DiffusedStaircase { radius: Some(3.0) }.estimate(&s).unwrap(), direct);
        for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            assert!(DiffusedStaircase { radius: Some(bad) }.estimate(&s).is_err(), "{bad}");
        }
    }

    #[test]
    fn interfaces_do_not_mix_at_a_junction() {
        // Two labels side by side in a background: the flat wall between them keeps its
        // axis exactly, however far the diffusion runs.
        let v = LabelVolume::from_fn([8, 6, 6], |[x, y, z]| {
            if (1..7).contains(&x) && (1..5).contains(&y) && (1..5).contains(&z) {
                1 + u32::from(x >= 4)
            } else {
                0
            }
        });
        let s = DigitalSurface::from_volume(&v).unwrap();
        let trivial = Trivial.estimate(&s).unwrap();
        let positions = s.positions();
        let out = Diffused { positions: &positions, previous: &trivial, radius: 4.0 }.estimate(&s).unwrap();
        for (f, n) in s.surfels().iter().zip(out.as_slice()) {
            if f.labels == [1, 2] {
                assert!((*n - f.normal()).length() < 1e-6, "{n:?}");
            }
        }
        let bad = Diffused { positions: &positions[1..], previous: &trivial, radius: 1.0 };
        assert!(bad.estimate(&s).is_err());
    }

    /// The window's shares, counted for each record against every record of its pair:
    /// the same as the grid's count, on junctions nearly everywhere (blocks of two voxels
    /// of four labels at random) and on a ball cut in two.
    #[test]
    fn window_shares_are_the_brute_force_counts() {
        let mut rng = voxreg_testkit::Lcg::new(5);
        let labels: Vec<u32> = (0..10 * 10 * 10).map(|_| rng.next_u32() % 4).collect();
        let blocks =
            LabelVolume::from_fn([20, 20, 20], |[x, y, z]| labels[x / 2 + 10 * (y / 2 + 10 * (z / 2))]);
        let split = LabelVolume::from_fn([27, 27, 27], |[x, y, z]| {
            let d = DVec3::new(x as f64 - 13.0, y as f64 - 13.0, z as f64 - 13.0);
            if d.length() > 12.0 {
                0
            } else {
                1 + u32::from(d.z > 0.5)
            }
        });
        for volume in [blocks, split] {
            let surface = DigitalSurface::from_volume(&volume).unwrap();
            let found = junction_pairs(&surface);
            assert!(found.len() > 20, "{}", found.len());
            let w = CONTINUATION_WINDOW;
            let shares = window_shares(&found);
            for (i, &(_, corner, key, _)) in found.iter().enumerate() {
                let near: Vec<bool> = found
                    .iter()
                    .filter(|r| r.2 == key && (0..3).all(|k| corner[k].abs_diff(r.1[k]) <= w))
                    .map(|r| r.3)
                    .collect();
                let share = near.iter().filter(|&&c| c).count() as f32 / near.len() as f32;
                assert_eq!(shares[i], share, "record {i}");
            }
        }
    }
}
