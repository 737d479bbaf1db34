//! Normals re-estimated from a regularized geometry (the refinement rounds).

use std::cell::RefCell;
use std::collections::BinaryHeap;

use glam::{DMat3, DVec3};
use rayon::prelude::*;
use thread_local::ThreadLocal;
use voxreg_digisurf::{DigitalSurface, SurfelId, VertexId};

use crate::eigen::symmetric_eigen;
use crate::error::NormalError;
use crate::estimator::NormalEstimator;
use crate::field::NormalField;
use crate::interrupt::Interrupt;

/// Normals re-estimated from positions of the surface's vertices (typically a
/// regularized surface): for each surfel `f`, the normalized, weighted average of the
/// area vectors `a_g` of the quads `g` at those positions
///
/// ```text
/// n'_f = normalize( sum_g (1 - |c_g - c_f| / r) rho_g a_g ),
/// ```
///
/// over the quads `g` of the interfaces that share a region with `f`'s (its own, and
/// those that continue it across a junction curve) reached from `f` through edge-adjacent
/// quads of such interfaces whose centres `c_g` stay within `radius` voxels of `c_f`.
/// Orientation follows `previous`. A quad with no such neighbour keeps its normal from
/// `previous`.
///
/// **Feature rule.** `rho_g` keeps the two sides of a sharp edge, and interfaces meeting
/// at an angle, from mixing: `rho_g = min(phi_g, reach_g)`, with `phi_g` the quad's
/// weight by its angle to `previous`'s normal at `f` ([`FeatureRamp`]: 1 within
/// `feature_angle_deg` minus half of [`FEATURE_RAMP_DEG`], 0 past it plus half), and
/// `reach_g` the widest path to it: the largest, over the paths from `f`, of the smallest
/// of what the quads on the path pass on (their `rho`, falling to 0 over the outer quarter
/// of the disc). `f` itself counts and passes on fully; the result goes from the average to
/// `previous`'s normal as `f`'s own quad goes past the feature angle. Why continuous: a sharp threshold flips on any
/// change of the positions, however small, and moves a quad's normal by up to tens of
/// degrees; a volume solved in chunks sees positions that differ from the whole volume's
/// by thousandths of a voxel, and must give the same normals to within as much
/// (docs/design/continuous-rules.md).
///
/// **Junctions.** The quads within two rings of a junction curve (sharing a vertex with a
/// quad that touches one) are bent by the other interfaces
/// meeting there, so they are crossed but never averaged: a disc that reaches them takes
/// its samples from the interior of the surface only, and, since the quad being estimated
/// is then off the centre of those samples, the normal is their mean extrapolated to `c_f`
/// by a one-parameter (umbilic) fit `u(c) ~ u_mean + k t(c - c_mean)`, with `t` the
/// projection on the plane of `previous`'s normal at `f` (the correction kept below a
/// quarter of the mean). Why: the plain mean next to a junction averaged the bent quads
/// (the sphere's quads at a ball's cut reached 30 degrees of error), and the mean of the
/// interior alone is the normal of a point a voxel or more away from the quad.
/// Where the surface continues smoothly across the junction (an interior sample of
/// another interface enters the disc: the sphere's two caps at a ball's cut), the disc of
/// such a quad is [`JUNCTION_DISC_FACTOR`] times wider: the two-ring gap leaves only the
/// rim of a disc of the plain radius, whose few samples fit the curvature poorly (the
/// sphere's quads touching the cut kept 1.3 degrees of error, against 0.7 elsewhere).
/// Where it stops at the junction (one-sided discs: a crease), the plain radius is kept.
/// Each of these rules comes in with the share of the disc's weight that calls for it (in
/// full from 2 % of the weight on the junction's quads, 5 % on the interior, 5 % on
/// another interface's interior), not at the first sample, for the same continuity.
///
/// **Anisotropic voxels.** Where the spacing is not cubic, away from junctions and sharp
/// features (discs where the feature rule stopped at no jump between neighbouring quads),
/// the average is a first-order fit evaluated at `c_f` (the mean normal plus the fitted slope
/// of the quad normals times `c_f` minus the disc's weighted centre), blended in with the
/// weight [`anisotropic_fit_weight`] of the spacing (0 for cubic voxels, whose normals are
/// the plain mean bit for bit). Why: thick slices make quads of very different areas (the
/// walls of a slice `h_z / h_x` times larger than its steps), so a quad's disc is weighted
/// unevenly and its mean normal is the normal at a centre up to a voxel away, tilted by
/// that distance over the radius of curvature; the fit removes that tilt. On cubic voxels
/// it is not used: there it rounded a cube's edges and fed back through the rounds next to
/// junctions (docs/design/junctions.md, docs/design/anisotropic-spacing.md).
///
/// Why: after one solve the quads follow the shape far better than the staircase, so
/// their own normals, averaged over a small disc, are a better field than any estimate
/// from the voxels alone.
#[derive(Clone, Copy, Debug)]
pub struct Refined<'a> {
    /// One position per vertex of the surface.
    pub positions: &'a [DVec3],
    /// The field being refined (orientation and the feature rule's reference).
    pub previous: &'a NormalField,
    /// Radius of the averaging disc, in voxels (of the largest spacing).
    pub radius: f64,
    /// The feature rule's angle in degrees (the middle of its ramp).
    pub feature_angle_deg: f64,
}

impl NormalEstimator for Refined<'_> {
    fn name(&self) -> &'static str {
        "refined"
    }

    /// Polls `interrupt` once per surfel: a raised one skips the remaining discs.
    fn estimate_interruptible(
        &self,
        surface: &DigitalSurface,
        interrupt: &Interrupt,
    ) -> Result<NormalField, NormalError> {
        self.estimate_with_hints(surface, interrupt, &mut ProbeHints::default())
    }
}

impl Refined<'_> {
    /// [`NormalEstimator::estimate_interruptible`], reading and updating `hints`: the
    /// quads whose wide junction disc (see [`Refined`]) held another interface's interior
    /// in the last estimate on the same surface search it at once, without the probe that
    /// otherwise decides whether to. The estimate is the same with any hints, bit for bit
    /// (the probe only saves searches whose share would be 0); the refinement rounds of
    /// one solve, whose positions move little, keep one `ProbeHints` to skip most probes
    /// that would find something.
    pub fn estimate_with_hints(
        &self,
        surface: &DigitalSurface,
        interrupt: &Interrupt,
        hints: &mut ProbeHints,
    ) -> Result<NormalField, NormalError> {
        if self.positions.len() != surface.num_vertices() || self.previous.len() != surface.num_surfels() {
            return Err(NormalError::InvalidParameter(format!(
                "refinement needs {} positions and {} normals, got {} and {}",
                surface.num_vertices(),
                surface.num_surfels(),
                self.positions.len(),
                self.previous.len()
            )));
        }
        if !(self.radius.is_finite() && self.radius > 0.0) {
            return Err(NormalError::InvalidParameter(format!(
                "the refinement radius must be positive and finite, got {}",
                self.radius
            )));
        }
        if hints.wide.len() != surface.num_surfels() {
            hints.wide = vec![false; surface.num_surfels()];
        }
        let blend = anisotropic_fit_weight(surface.spacing());
        let near = near_junction_surfels(surface);
        interrupt.check()?;
        let field =
            refined_interruptible(self, surface, blend, &near, true, Some(&mut hints.wide), interrupt);
        // A raised interrupt left the surfels after it unestimated.
        interrupt.check()?;
        Ok(field)
    }
}

/// What one [`Refined`] estimate learned for the next on the same surface: per surfel,
/// whether its wide junction disc held another interface's interior
/// ([`Refined::estimate_with_hints`]). Empty by default (every disc probed).
#[derive(Clone, Debug, Default)]
pub struct ProbeHints {
    wide: Vec<bool>,
}

/// The vector area of surfel `s` at `positions` (half the cross product of its
/// diagonals), pointing like its oriented normal.
fn area_vector(surface: &DigitalSurface, positions: &[DVec3], s: usize) -> DVec3 {
    let [a, b, c, d] = surface.surfels()[s].vertices.map(|v| positions[v.index()]);
    0.5 * (c - a).cross(d - b)
}

/// For each surfel, the other surfels of its interface across each of its edges, in
/// the order of its edges and of each edge's surfels, all numbered by their place in
/// `order` (compressed lists: the `i`-th surfel of `order` has
/// `adjacent[starts[i]..starts[i + 1]]`). Built once per estimate so the disc searches
/// read one short list per quad instead of walking edges.
fn interface_adjacency(surface: &DigitalSurface, order: &[u32]) -> (Vec<u32>, Vec<u32>) {
    let mut rank = vec![0u32; order.len()];
    for (i, &s) in order.iter().enumerate() {
        rank[s as usize] = i as u32;
    }
    // One list a piece of quads (not one a quad), then joined.
    const PIECE: usize = 4096;
    let pieces: Vec<(Vec<u32>, Vec<u8>)> = order
        .par_chunks(PIECE)
        .map(|chunk| {
            let (mut items, mut lens) =
                (Vec::with_capacity(4 * chunk.len()), Vec::with_capacity(chunk.len()));
            for &g in chunk {
                let g = g as usize;
                let regions = surface.surfels()[g].regions;
                let before = items.len();
                for e in surface.surfel_edges(SurfelId(g as u32)) {
                    for &k in surface.edge_surfels(e) {
                        let other = surface.surfels()[k.index()].regions;
                        if k.index() != g && regions.iter().any(|r| other.contains(r)) {
                            items.push(rank[k.index()]);
                        }
                    }
                }
                lens.push((items.len() - before) as u8);
            }
            (items, lens)
        })
        .collect();
    let mut starts = Vec::with_capacity(order.len() + 1);
    starts.push(0u32);
    let mut adjacent = Vec::with_capacity(pieces.iter().map(|p| p.0.len()).sum());
    for (items, lens) in &pieces {
        let mut at = adjacent.len() as u32;
        starts.extend(lens.iter().map(|&l| {
            at += u32::from(l);
            at
        }));
        adjacent.extend_from_slice(items);
    }
    (starts, adjacent)
}

/// How much wider than [`Refined::radius`] the disc of a quad within two rings of a
/// junction is, where its surface continues smoothly across the junction (see
/// [`Refined`]).
pub const JUNCTION_DISC_FACTOR: f64 = 3.0;

/// Full width, in degrees, of the feature rule's ramp (see [`Refined`]): a quad's weight
/// falls from 1 at `feature_angle_deg - 2` to 0 at `feature_angle_deg + 2` degrees from
/// the normal being refined. The crease weights of the solve use the same ramp.
pub const FEATURE_RAMP_DEG: f64 = 4.0;

/// Shares of a disc's weight (see [`Refined`]) from which the junction rules take full
/// effect: the quads next to a junction (the interior's fit replaces the plain mean), the
/// interior samples (the fit replaces the plain sum of the bent quads), and the interior
/// samples of another interface (the wider disc replaces the plain one).
const JUNCTION_SHARE: f64 = 0.02;
const INTERIOR_SHARE: f64 = 0.05;
const CONTINUED_SHARE: f64 = 0.05;

/// A continuous angle test: the weight of a direction at cosine `c` from a reference,
/// 1 within `angle - FEATURE_RAMP_DEG / 2`, 0 past `angle + FEATURE_RAMP_DEG / 2` (never
/// past 90 degrees), linear in the cosine between.
#[derive(Clone, Copy, Debug)]
pub struct FeatureRamp {
    cos_one: f64,
    cos_zero: f64,
}

impl FeatureRamp {
    /// The ramp centred on `angle_deg`.
    pub fn new(angle_deg: f64) -> FeatureRamp {
        let half = 0.5 * FEATURE_RAMP_DEG;
        FeatureRamp {
            cos_one: (angle_deg - half).clamp(0.0, 90.0).to_radians().cos(),
            cos_zero: (angle_deg + half).clamp(0.0, 90.0).to_radians().cos(),
        }
    }

    /// The weight at cosine `c`: 1 inside the angle, 0 past it.
    pub fn weight(&self, c: f64) -> f64 {
        if c >= self.cos_one {
            1.0
        } else if c <= self.cos_zero {
            0.0
        } else {
            (c - self.cos_zero) / (self.cos_one - self.cos_zero)
        }
    }
}

/// The outer part of a disc, as a fraction of its radius, over which the reach a quad
/// passes on to its neighbours falls to 0 at the rim (see [`Refined`]).
const RIM_FRACTION: f64 = 0.25;

/// A disc search's scratch, kept per worker: the seen marks, the reached quads in
/// visiting order `(quad, parent, distance, reach)`, and the quads of partial reach
/// waiting, highest reach first (`(reach, quad, parent)` packed in one `u128` by
/// [`waiting_entry`], which orders as the triple), and per quad the highest reach it
/// waits with (0 where it does not).
type Scratch = (Vec<bool>, Vec<(u32, u32, f64, f64)>, BinaryHeap<u128>, Vec<f64>);

/// A waiting quad `k` reached from `parent` with `reach`: the reach's bits (non-negative,
/// they order as its values), then the quad, then the parent, so that one comparison of
/// integers orders the entries (a quad is pushed at most once from each parent, so no two
/// entries are equal).
fn waiting_entry(reach: f64, k: u32, parent: u32) -> u128 {
    (u128::from(reach.to_bits()) << 64) | (u128::from(k) << 32) | u128::from(parent)
}

/// The `(reach, quad, parent)` of a [`waiting_entry`].
fn waiting_parts(e: u128) -> (f64, u32, u32) {
    (f64::from_bits((e >> 64) as u64), (e >> 32) as u32, e as u32)
}

/// `t` of the direction of `a` and `1 - t` of the direction of `b` (`a` itself from
/// `t = 1`, `b` itself at `t = 0`).
fn mix(t: f64, a: DVec3, b: DVec3) -> DVec3 {
    if t >= 1.0 {
        a
    } else if t <= 0.0 {
        b
    } else {
        t * a.normalize_or_zero() + (1.0 - t) * b.normalize_or_zero()
    }
}

/// The weight of the first-order fit in [`Refined`] on a surface of voxel `spacing`:
/// `clamp(h_max / h_min - 1, 0, 1)`, 0 for cubic voxels, 1 from a ratio of 2 on, so the
/// fit comes in continuously with the anisotropy.
pub fn anisotropic_fit_weight(spacing: DVec3) -> f64 {
    (spacing.max_element() / spacing.min_element() - 1.0).clamp(0.0, 1.0)
}

/// Per surfel, whether it is within two rings of a junction curve: one of its vertices is
/// a vertex of a quad that touches a junction (a vertex whose quads span three regions or
/// more). All `false` on a surface with one interface.
fn near_junction_surfels(surface: &DigitalSurface) -> Vec<bool> {
    if surface.interfaces().len() < 2 {
        return vec![false; surface.num_surfels()];
    }
    let touching = junction_surfels(surface);
    let mut touched = vec![false; surface.num_vertices()];
    for (s, _) in touching.iter().enumerate().filter(|(_, &t)| t) {
        surface.surfels()[s].vertices.iter().for_each(|v| touched[v.index()] = true);
    }
    surface.surfels().par_iter().map(|s| s.vertices.iter().any(|v| touched[v.index()])).collect()
}

/// Per surfel, whether one of its vertices is on a junction (its quads span three
/// regions or more).
fn junction_surfels(surface: &DigitalSurface) -> Vec<bool> {
    let junction: Vec<bool> = (0..surface.num_vertices())
        .into_par_iter()
        .map(|v| {
            let mut regions =
                surface.vertex_surfels(VertexId(v as u32)).iter().flat_map(|s| surface.surfel(*s).regions);
            let first = regions.next();
            let second = regions.find(|r| Some(*r) != first);
            second.is_some_and(|b| regions.any(|r| Some(r) != first && r != b))
        })
        .collect();
    surface.surfels().par_iter().map(|s| s.vertices.iter().any(|v| junction[v.index()])).collect()
}

/// `estimator`'s estimate; once `interrupt` is raised, the surfels not yet done keep the
/// previous field's normal (the caller reports the interruption). With `probe`, a wide disc is searched
/// only where a plain search first finds another interface's interior within its reach,
/// and that search only where such an interior quad exists within the disc and the
/// feature angle at all ([`InteriorNormals`]: a per-cell bound on the normals, then the
/// probe's own test quad by quad). Where none is, its
/// share is 0 and the disc is not used: the same estimate, bit for bit, for a fraction of
/// the search where junction curves are creases. With `hints` (one per surfel), the
/// surfels marked search their wide disc without the probe (the same estimate: the probe
/// only skips searches whose share would be 0), and each surfel's mark becomes whether
/// its wide disc's share was positive.
fn refined_interruptible(
    estimator: &Refined<'_>,
    surface: &DigitalSurface,
    blend: f64,
    near_junction: &[bool],
    probe: bool,
    mut hints: Option<&mut Vec<bool>>,
    interrupt: &Interrupt,
) -> NormalField {
    let Refined { positions, previous: field, radius, feature_angle_deg } = *estimator;
    let n = surface.num_surfels();
    let h = surface.spacing().max_element();
    let r = radius * h;
    let cos_max = feature_angle_deg.to_radians().cos();
    let ramp = FeatureRamp::new(feature_angle_deg);
    // The search is bound by the latency of its reads, not by its arithmetic: it runs on
    // the quads renumbered along a Morton curve of their cells (a disc's quads close in
    // memory), reading packed records: of each candidate neighbour its centre and regions
    // (one cache line holds two), of each counted quad its area vector and length. The
    // visiting order, hence every sum, is the same as in the surface's numbering.
    let order = morton_order(surface);
    let samples: Vec<Sample> = order
        .par_iter()
        .map(|&s| {
            let area = area_vector(surface, positions, s as usize);
            Sample { area, len: area.length() }
        })
        .collect();
    let nodes: Vec<Node> = order
        .par_iter()
        .map(|&s| {
            let s = &surface.surfels()[s as usize];
            Node {
                centre: s.vertices.iter().map(|v| positions[v.index()]).sum::<DVec3>() / 4.0,
                regions: s.regions.map(|r| r.0),
                interface: s.interface.0,
            }
        })
        .collect();
    let near_junction: Vec<bool> = order.par_iter().map(|&s| near_junction[s as usize]).collect();
    let (starts, adjacent) = interface_adjacency(surface, &order);
    let normals: Vec<DVec3> = order.par_iter().map(|&s| field.as_slice()[s as usize]).collect();
    // One interface: every quad the adjacency reaches shares `f`'s regions.
    let single = surface.interfaces().len() < 2;
    let interiors = (probe && !single)
        .then(|| InteriorNormals::new(&nodes, &samples, &near_junction, JUNCTION_DISC_FACTOR * r));
    let hinted: Option<Vec<bool>> =
        hints.as_ref().map(|h| order.par_iter().map(|&s| h[s as usize]).collect());
    // Discs near junctions cost many times the others: the quads go to the threads in
    // pieces of at most 1/128 of them, so that no thread is left alone with a large piece at
    // the end (rayon splits a range it does not steal from only a few times). The pieces
    // share their thread's scratch (two arrays as long as the surface: one per piece would
    // be allocated and faulted in again and again); each search clears the marks it set.
    let scratch: ThreadLocal<RefCell<Scratch>> = ThreadLocal::new();
    let out: Vec<(DVec3, bool)> = (0..n)
        .into_par_iter()
        .with_min_len(1024)
        .with_max_len((n / 128).max(1024))
        .map_init(
            || scratch.get_or(|| RefCell::new((vec![false; n], Vec::new(), BinaryHeap::new(), vec![0.0; n]))),
            |cell, f| {
                let mut lent = cell.borrow_mut();
                let (seen, queue, waiting, best) = &mut *lent;
                if interrupt.is_raised() {
                    return (normals[f], false);
                }
                let nf = normals[f];
                let cf = nodes[f].centre;
                let regions_f = nodes[f].regions;
                let iface_f = nodes[f].interface;
                // A quad's cosine to the normal being refined (0 for a quad of no area), and
                // its feature weight: the ramp of that cosine, 1 for the quad itself (its
                // own tilt is weighed once, on the result, below).
                let cosine = |g: usize| {
                    let Sample { area, len } = samples[g];
                    if len > 0.0 {
                        area.dot(nf) / len
                    } else {
                        0.0
                    }
                };
                let feature_weight = |g: usize| if g == f { 1.0 } else { ramp.weight(cosine(g).abs()) };
                // Whether the search may cross into quad `k`: its interface shares a
                // region with `f`'s.
                let shares = |k: usize| single || nodes[k].regions.iter().any(|r| regions_f.contains(r));
                let mut disc = |r: f64, probe: bool| -> Option<(DVec3, f64)> {
                    let r2 = r * r;
                    if probe {
                        // Whether the disc can hold another interface's interior at all: a
                        // plain search over the quads it can reach (those the widest-first
                        // search below reaches, and possibly more), stopped at the first
                        // such quad. Without one its share is 0 and the disc is not used.
                        let mut found = false;
                        queue.push((f as u32, 0, 0.0, 0.0));
                        seen[f] = true;
                        let mut head = 0;
                        while head < queue.len() {
                            let g = queue[head].0 as usize;
                            head += 1;
                            if feature_weight(g) <= 0.0 {
                                continue;
                            }
                            if !near_junction[g] && samples[g].len > 0.0 && nodes[g].interface != iface_f {
                                found = true;
                                break;
                            }
                            for &k in &adjacent[starts[g] as usize..starts[g + 1] as usize] {
                                let ku = k as usize;
                                if !seen[ku] && shares(ku) && nodes[ku].centre.distance_squared(cf) < r2 {
                                    seen[ku] = true;
                                    queue.push((k, 0, 0.0, 0.0));
                                }
                            }
                        }
                        queue.drain(..).for_each(|(k, _, _, _)| seen[k as usize] = false);
                        if !found {
                            return None;
                        }
                    }
                    let mut sum = DVec3::ZERO;
                    let mut fit = FirstOrder::default();
                    // Weights: of the disc, of its quads next to a junction.
                    let (mut total, mut junction) = (0.0, 0.0);
                    // Whether the feature rule stopped at a sharp jump.
                    let mut feature = false;
                    // Widest first: the quads of full reach breadth first, then those of
                    // partial reach by decreasing reach. The queue keeps every quad reached
                    // (its visiting order), so the seen marks are cleared from it and the
                    // junctions' second pass below reads the same quads in the same order.
                    queue.push((f as u32, f as u32, 0.0, 1.0));
                    seen[f] = true;
                    let mut head = 0;
                    loop {
                        if head == queue.len() {
                            let Some((reach, k, parent)) = std::iter::from_fn(|| waiting.pop())
                                .map(waiting_parts)
                                .find(|e| !seen[e.1 as usize])
                            else {
                                break;
                            };
                            seen[k as usize] = true;
                            // Its squared distance as when it was pushed.
                            let d2 = nodes[k as usize].centre.distance_squared(cf);
                            queue.push((k, parent, d2, reach));
                        }
                        // Queued with its squared distance (the test below needs no root):
                        // the distance is taken here, and kept for the second pass.
                        let (g, parent, d2, reach) = queue[head];
                        let d = d2.sqrt();
                        queue[head].2 = d;
                        head += 1;
                        let (g, parent) = (g as usize, parent as usize);
                        let Sample { area: a, len } = samples[g];
                        let dot = cosine(g);
                        let phi = feature_weight(g);
                        if phi <= 0.0 {
                            // A sharp feature (a jump past the feature angle from the quad it
                            // was reached from, not a gradual turn of a curved surface): the
                            // fit would extrapolate across it.
                            if blend > 0.0 {
                                let from = samples[parent];
                                feature |= a.dot(from.area).abs() < cos_max * len * from.len;
                            }
                            continue; // across a feature: neither counted nor crossed
                        }
                        let rho = phi.min(reach);
                        let w = (1.0 - d / r) * rho;
                        sum += w * a * dot.signum();
                        total += w * len;
                        if near_junction[g] {
                            junction += w * len;
                        }
                        if blend > 0.0 && len > 0.0 {
                            fit.add(w * len, a / len * dot.signum(), nodes[g].centre - cf);
                        }
                        // What this quad passes on: its own weight, falling to 0 over the
                        // disc's rim.
                        let pass = rho.min((1.0 - d / r) * (1.0 / RIM_FRACTION));
                        if pass <= 0.0 {
                            continue;
                        }
                        for &k in &adjacent[starts[g] as usize..starts[g + 1] as usize] {
                            let ku = k as usize;
                            if !seen[ku] && shares(ku) {
                                let dk = nodes[ku].centre.distance_squared(cf);
                                if dk < r2 {
                                    if pass >= 1.0 {
                                        seen[ku] = true;
                                        queue.push((k, g as u32, dk, 1.0));
                                    } else {
                                        // A quad already waiting with a higher reach
                                        // leaves the heap first: this entry would be
                                        // dropped there (ties are kept: their order
                                        // depends on the rest of the entry).
                                        if pass >= best[ku] {
                                            best[ku] = pass;
                                            waiting.push(waiting_entry(pass, k, g as u32));
                                        }
                                    }
                                }
                            }
                        }
                    }
                    let plain = match fit.at_origin(r, blend) {
                        Some(m) if !feature => m,
                        _ => sum,
                    };
                    if junction <= 0.0 {
                        queue.drain(..).for_each(|(k, _, _, _)| {
                            seen[k as usize] = false;
                            best[k as usize] = 0.0;
                        });
                        return Some((plain, 0.0));
                    }
                    // Only a disc that reached a junction's quads needs the interior's fit
                    // (and the share of another interface's interior): the counted quads
                    // again, in the order they were counted.
                    let mut interior = Umbilic::default();
                    let (mut inner, mut other) = (0.0, 0.0); // weights: interior, of another interface
                    for &(g, _, d, reach) in queue.iter() {
                        let g = g as usize;
                        let Sample { area: a, len } = samples[g];
                        if near_junction[g] || len <= 0.0 {
                            continue;
                        }
                        let dot = cosine(g);
                        let rho = feature_weight(g).min(reach);
                        if rho <= 0.0 {
                            continue;
                        }
                        let w = (1.0 - d / r) * rho * len;
                        inner += w;
                        if nodes[g].interface != iface_f {
                            other += w;
                        }
                        interior.add(w, a / len * dot.signum(), nodes[g].centre - cf, nf);
                    }
                    queue.drain(..).for_each(|(k, _, _, _)| {
                        seen[k as usize] = false;
                        best[k as usize] = 0.0;
                    });
                    // Each junction rule comes in with the share of the disc's weight that
                    // calls for it, not at its first sample (see `Refined`).
                    let fitted = interior.at_origin().unwrap_or(sum);
                    let fitted = mix((inner / (INTERIOR_SHARE * total)).min(1.0), fitted, sum);
                    let m = mix((junction / (JUNCTION_SHARE * total)).min(1.0), fitted, plain);
                    Some((m, (other / (CONTINUED_SHARE * total)).min(1.0)))
                };
                // The quad's own tilt from its previous normal: past the feature angle it
                // keeps that normal (a disc of quads all past the angle says nothing), in
                // between the two by the ramp.
                let own = ramp.weight(cosine(f).abs());
                if own <= 0.0 {
                    return (nf, false);
                }
                // Next to a junction, the wider disc where the surface continues across
                // the curve (its samples on both sides); the plain radius where it stops
                // there (one-sided: a wider disc would extrapolate farther); between the
                // two by the share of the other interfaces' interior in the wider disc.
                // (A search without the probe always returns its disc.)
                let wide = near_junction[f]
                    .then(|| {
                        let wide_r = JUNCTION_DISC_FACTOR * r;
                        // No interior quad of another interface near enough and within the
                        // feature angle: nothing for the probe to find.
                        let none = interiors.as_ref().is_some_and(|b| {
                            // The probe's own test of the quad it stops at.
                            let within = |g: usize| {
                                nodes[g].centre.distance_squared(cf) < wide_r * wide_r
                                    && feature_weight(g) > 0.0
                            };
                            !b.may_continue(cf, iface_f, regions_f, (nf, ramp.cos_zero), within)
                        });
                        if none {
                            None
                        } else {
                            // Searched at once where the last estimate found a share.
                            let known = hinted.as_ref().is_some_and(|h| h[f]);
                            disc(wide_r, probe && !known)
                        }
                    })
                    .flatten();
                let shared = wide.is_some_and(|(_, c)| c > 0.0);
                let mut plain = || disc(r, false).map_or(DVec3::ZERO, |(m, _)| m);
                let m = match wide {
                    Some((wide, c)) if c >= 1.0 => wide,
                    Some((wide, c)) if c > 0.0 => mix(c, wide, plain()),
                    _ => plain(),
                }
                .normalize_or_zero();
                let m = if m == DVec3::ZERO { nf } else { mix(own, m, nf).normalize_or_zero() };
                (if m == DVec3::ZERO { nf } else { m }, shared)
            },
        )
        .collect();
    let mut field = vec![DVec3::ZERO; n];
    for (s, (m, shared)) in order.iter().zip(out) {
        field[*s as usize] = m;
        if let Some(h) = hints.as_deref_mut() {
            h[*s as usize] = shared;
        }
    }
    NormalField::new(field)
}

/// The interior quads (not next to a junction, of positive area) by cell of a grid of
/// side `side` and by interface, with each group's largest absolute components of its unit
/// normals (a bound on their cosine to any direction), so that a wide disc's probe can be
/// skipped where no such quad of another interface, within the disc and within the feature
/// angle, exists: the bound rules out a group at once, and the quads of the groups it
/// leaves are tested one by one with the search's own expressions, so the test never
/// rules out a quad the probe would find.
struct InteriorNormals {
    side: f64,
    /// Sorted by cell key: `(key, interface, regions, largest |n_x|, |n_y|, |n_z|, end of
    /// the group's quads in `quads`)`.
    entries: Vec<(u64, u32, [u32; 2], DVec3, u32)>,
    /// The interior quads, group after group.
    quads: Vec<u32>,
}

impl InteriorNormals {
    fn key(&self, c: DVec3) -> [i64; 3] {
        let k = (c / self.side).floor();
        [k.x as i64, k.y as i64, k.z as i64]
    }

    fn pack(k: [i64; 3]) -> u64 {
        // 21 bits an axis (cells of a few voxels: far more than any volume's extent).
        let b = |x: i64| (x as u64) & 0x1f_ffff;
        (b(k[2]) << 42) | (b(k[1]) << 21) | b(k[0])
    }

    fn new(nodes: &[Node], samples: &[Sample], near_junction: &[bool], side: f64) -> InteriorNormals {
        let mut this = InteriorNormals { side, entries: Vec::new(), quads: Vec::new() };
        // Sorted as (cell key, interface, quad): 16 bytes a quad while sorting, the
        // normals read from the quads (an interface's quads share its regions).
        let mut all: Vec<(u64, u32, u32)> = (0..nodes.len())
            .filter(|&g| !near_junction[g] && samples[g].len > 0.0)
            .map(|g| (Self::pack(this.key(nodes[g].centre)), nodes[g].interface, g as u32))
            .collect();
        all.par_sort_unstable();
        this.quads = all.iter().map(|e| e.2).collect();
        let unit = |g: u32| (samples[g as usize].area / samples[g as usize].len).abs();
        let mut end = 0;
        for group in all.chunk_by(|a, b| a.0 == b.0 && a.1 == b.1) {
            let m = group.iter().fold(DVec3::ZERO, |m, e| m.max(unit(e.2)));
            end += group.len() as u32;
            this.entries.push((group[0].0, group[0].1, nodes[group[0].2 as usize].regions, m, end));
        }
        this
    }

    /// Whether an interior quad `g` of an interface other than `interface`, sharing one of
    /// `regions`, with a centre within `side` of `centre`, has `within(g)`: groups whose
    /// normals' bound keeps their cosine to `normal` (a unit vector) at or below
    /// `cos_zero` in absolute value are passed over without testing their quads.
    fn may_continue(
        &self,
        centre: DVec3,
        interface: u32,
        regions: [u32; 2],
        (normal, cos_zero): (DVec3, f64),
        within: impl Fn(usize) -> bool,
    ) -> bool {
        let [x, y, z] = self.key(centre);
        let a = normal.abs();
        for dz in -1..=1 {
            for dy in -1..=1 {
                for dx in -1..=1 {
                    let key = Self::pack([x + dx, y + dy, z + dz]);
                    let mut at = self.entries.partition_point(|e| e.0 < key);
                    let mut start = if at == 0 { 0 } else { self.entries[at - 1].4 as usize };
                    while let Some(e) = self.entries.get(at).filter(|e| e.0 == key) {
                        // A margin over the rounding of the search's own cosines.
                        if e.1 != interface
                            && e.2.iter().any(|r| regions.contains(r))
                            && e.3.dot(a) > cos_zero - 1e-9
                            && self.quads[start..e.4 as usize].iter().any(|&g| within(g as usize))
                        {
                            return true;
                        }
                        start = e.4 as usize;
                        at += 1;
                    }
                }
            }
        }
        false
    }
}

/// The surfels sorted along a Morton (Z-order) curve of their cells, then by axis.
fn morton_order(surface: &DigitalSurface) -> Vec<u32> {
    fn spread(x: u32) -> u64 {
        // Bit k of `x` (21 bits kept) to bit 3k.
        let mut v = u64::from(x) & 0x1f_ffff;
        v = (v | v << 32) & 0x1f00000000ffff;
        v = (v | v << 16) & 0x1f0000ff0000ff;
        v = (v | v << 8) & 0x100f00f00f00f00f;
        v = (v | v << 4) & 0x10c30c30c30c30c3;
        (v | v << 2) & 0x1249249249249249
    }
    let mut keys: Vec<(u64, u8, u32)> = surface
        .surfels()
        .par_iter()
        .enumerate()
        .map(|(i, s)| {
            let [x, y, z] = s.cell;
            (spread(x) | spread(y) << 1 | spread(z) << 2, s.axis, i as u32)
        })
        .collect();
    keys.par_sort_unstable();
    keys.into_iter().map(|k| k.2).collect()
}

/// A quad as a disc search's candidate: its centre at the positions, its regions and
/// its interface.
#[derive(Clone, Copy)]
struct Node {
    centre: DVec3,
    regions: [u32; 2],
    interface: u32,
}

/// A quad as a disc search's sample: its vector area at the positions and its length.
#[derive(Clone, Copy)]
struct Sample {
    area: DVec3,
    len: f64,
}

/// A weighted first-order fit of unit normals `u` against positions `c` (relative to the
/// quad being estimated): `u(c) ~ u_mean + J (c - c_mean)`, evaluated at `c = 0`.
#[derive(Default)]
struct FirstOrder {
    w: f64,
    wu: DVec3,
    wc: DVec3,
    wcc: DMat3,
    wuc: DMat3,
}

impl FirstOrder {
    fn add(&mut self, w: f64, u: DVec3, c: DVec3) {
        self.w += w;
        self.wu += w * u;
        self.wc += w * c;
        self.wcc += outer(w * c, c);
        self.wuc += outer(w * u, c);
    }

    /// The mean normal plus `blend` times the first-order correction, at the origin (not
    /// normalized); `None` without weight or with `blend = 0`. The positions' covariance
    /// is inverted only along directions where the disc spans at least a tenth of the
    /// radius `r` (a thin strip of quads gives no slope across it), and the correction
    /// is kept below a quarter of the mean normal.
    fn at_origin(&self, r: f64, blend: f64) -> Option<DVec3> {
        if self.w <= 0.0 || blend <= 0.0 {
            return None;
        }
        let mean_u = self.wu / self.w;
        let mean_c = self.wc / self.w;
        let ccov = self.wcc / self.w - outer(mean_c, mean_c);
        let ucov = self.wuc / self.w - outer(mean_u, mean_c);
        let (values, vectors) = symmetric_eigen(ccov);
        let floor = (0.1 * r).powi(2);
        // J (0 - mean_c) = ucov C^+ (-mean_c).
        let mut solved = DVec3::ZERO;
        for (l, e) in values.iter().zip(vectors) {
            if *l > floor {
                solved += e * (e.dot(-mean_c) / l);
            }
        }
        let mut correction = ucov * solved;
        let cap = 0.25 * mean_u.length();
        if correction.length() > cap {
            correction *= cap / correction.length();
        }
        Some(mean_u + blend * correction)
    }
}

/// A weighted one-parameter fit of unit normals `u` against positions `c` (relative to the
/// quad being estimated), `u(c) ~ u_mean + k t(c - c_mean)` with `t` the projection on the
/// plane of a reference normal (the normals of an umbilic patch of curvature `k`),
/// evaluated at `c = 0`. One parameter, not a slope matrix: next to a junction the samples
/// lie on one side or around a hole, where a full first-order fit is ill-conditioned.
#[derive(Default)]
struct Umbilic {
    w: f64,
    wu: DVec3,
    wt: DVec3,
    wut: f64,
    wtt: f64,
}

impl Umbilic {
    fn add(&mut self, w: f64, u: DVec3, c: DVec3, n: DVec3) {
        let t = c - n * n.dot(c);
        self.w += w;
        self.wu += w * u;
        self.wt += w * t;
        self.wut += w * u.dot(t);
        self.wtt += w * t.length_squared();
    }

    /// The fitted normal at the origin (not normalized), the correction kept below a
    /// quarter of the mean normal; `None` without weight.
    fn at_origin(&self) -> Option<DVec3> {
        if self.w <= 0.0 {
            return None;
        }
        let (mean_u, mean_t) = (self.wu / self.w, self.wt / self.w);
        let spread = self.wtt / self.w - mean_t.length_squared();
        if spread <= 1e-12 {
            return Some(mean_u);
        }
        let k = (self.wut / self.w - mean_u.dot(mean_t)) / spread;
        let mut correction = -k * mean_t;
        let cap = 0.25 * mean_u.length();
        if correction.length() > cap {
            correction *= cap / correction.length();
        }
        Some(mean_u + correction)
    }
}

fn outer(a: DVec3, b: DVec3) -> DMat3 {
    DMat3::from_cols(a * b.x, a * b.y, a * b.z)
}

#[cfg(test)]
mod tests;
