//! The convolved trivial estimator: trivial normals averaged over a geodesic disc.

use std::cmp::Reverse;
use std::collections::BinaryHeap;

use glam::DVec3;
use rayon::prelude::*;
use voxreg_digisurf::{DigitalSurface, RegionId, SurfelId};

use crate::error::NormalError;
use crate::estimator::NormalEstimator;
use crate::field::NormalField;
use crate::ii::default_radius;
use crate::interrupt::Interrupt;
use crate::sides::combine_sides;

/// Trivial normals convolved over the surface: each surfel's normal is the normalized,
/// distance-weighted average of the trivial normals of the surfels within distance `t`
/// of it, distance measured *over the surface*:
///
/// ```text
/// n(s) = normalize( sum_{s' : d(s, s') <= t} (1 - d(s, s') / t) n_triv(s') ),
/// ```
///
/// where `d` is the shortest-path distance in the graph of edge-adjacent surfels, each
/// step weighted by the Euclidean distance between surfel centres (Dijkstra, stopped at
/// `t`). Sheets that are close in space but far apart on the surface do not mix.
///
/// **Multi-label volumes** (the paper's sec. 3.1): as for
/// [`IntegralInvariant`](crate::ii::IntegralInvariant), each of a surfel's two regions is
/// treated as the shape: the average runs over that region's boundary only (surfels with
/// that region on one side, trivial normals pointing out of it), and the two directions
/// are averaged, then oriented like the trivial normal. On a binary volume both
/// boundaries are the whole surface and the two estimates coincide. On an open border (a
/// volume without background) the disc is cut by the surface's rim.
///
/// Cost: one bounded Dijkstra per surfel and region, `O(k log k)` for the `k ~ (t/h)^2`
/// surfels within reach; surfels are processed in parallel.
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct ConvolvedTrivial {
    /// Convolution radius `t` in physical units (distance over the surface); `None`
    /// picks [`default_radius`] (3 at unit spacing). Default: `None`.
    pub radius: Option<f64>,
}

impl ConvolvedTrivial {
    /// The radius used on `surface`: [`ConvolvedTrivial::radius`], or [`default_radius`].
    pub fn radius_for(&self, surface: &DigitalSurface) -> f64 {
        self.radius.unwrap_or_else(|| default_radius(surface))
    }
}

/// The surfel adjacency graph: for each surfel, its edge-neighbours with centre distances.
struct Graph {
    offsets: Vec<usize>,
    targets: Vec<(u32, f64)>,
}

impl Graph {
    fn new(surface: &DigitalSurface) -> Self {
        let centres: Vec<DVec3> = surface
            .surfels()
            .par_iter()
            .map(|s| s.vertices.iter().map(|&v| surface.vertex_position(v)).sum::<DVec3>() / 4.0)
            .collect();
        let n = surface.num_surfels();
        let mut offsets = Vec::with_capacity(n + 1);
        let mut targets = Vec::with_capacity(4 * n);
        offsets.push(0);
        for s in 0..n {
            for e in surface.surfel_edges(SurfelId(s as u32)) {
                for &t in surface.edge_surfels(e) {
                    if t.index() != s {
                        targets.push((t.0, centres[s].distance(centres[t.index()])));
                    }
                }
            }
            offsets.push(targets.len());
        }
        Graph { offsets, targets }
    }

    fn neighbours(&self, s: usize) -> &[(u32, f64)] {
        &self.targets[self.offsets[s]..self.offsets[s + 1]]
    }
}

/// Per-thread Dijkstra buffers, reset lazily through the list of touched surfels.
struct Scratch {
    dist: Vec<f64>,
    touched: Vec<u32>,
    heap: BinaryHeap<Reverse<(u64, u32)>>,
}

impl Scratch {
    fn new(n: usize) -> Self {
        Scratch { dist: vec![f64::INFINITY; n], touched: Vec::new(), heap: BinaryHeap::new() }
    }

    /// Sum of `(1 - d / t) n(s')` over the surfels `s'` of `region`'s boundary within
    /// surface distance `t` of `start`, with `n(s')` the trivial normal pointing out of
    /// `region` (`region == None`: the whole surface, normals as they are).
    fn convolve(
        &mut self,
        surface: &DigitalSurface,
        graph: &Graph,
        start: usize,
        region: Option<RegionId>,
        t: f64,
    ) -> DVec3 {
        let surfels = surface.surfels();
        let on_boundary = |s: usize| region.is_none_or(|r| surfels[s].regions.contains(&r));
        let mut sum = DVec3::ZERO;
        self.dist[start] = 0.0;
        self.touched.push(start as u32);
        // Distances are non-negative, so their bit patterns order like their values.
        self.heap.push(Reverse((0, start as u32)));
        while let Some(Reverse((key, s))) = self.heap.pop() {
            let (d, s) = (f64::from_bits(key), s as usize);
            if d > self.dist[s] {
                continue; // a stale entry
            }
            let sf = &surfels[s];
            let outward = if region.is_some_and(|r| sf.regions[1] == r) { -sf.normal() } else { sf.normal() };
            sum += (1.0 - d / t) * outward;
            for &(n, w) in graph.neighbours(s) {
                let (n, nd) = (n as usize, d + w);
                if nd <= t && nd < self.dist[n] && on_boundary(n) {
                    if self.dist[n] == f64::INFINITY {
                        self.touched.push(n as u32);
                    }
                    self.dist[n] = nd;
                    self.heap.push(Reverse((nd.to_bits(), n as u32)));
                }
            }
        }
        for &s in &self.touched {
            self.dist[s as usize] = f64::INFINITY;
        }
        self.touched.clear();
        sum
    }
}

impl NormalEstimator for ConvolvedTrivial {
    fn name(&self) -> &'static str {
        "convolved"
    }

    /// Polls `interrupt` once per surfel.
    fn estimate_interruptible(
        &self,
        surface: &DigitalSurface,
        interrupt: &Interrupt,
    ) -> Result<NormalField, NormalError> {
        interrupt.check()?;
        let t = self.radius_for(surface);
        if !(t.is_finite() && t > 0.0) {
            return Err(NormalError::InvalidParameter(format!(
                "convolution radius must be finite and positive, got {t}"
            )));
        }
        let graph = Graph::new(surface);
        // With two regions, every surfel bounds both: one pass over the whole surface.
        let binary = surface.regions().len() <= 2;
        let n = surface.num_surfels();
        let normals = (0..n)
            .into_par_iter()
            .map_init(
                || Scratch::new(n),
                |scratch, s| {
                    let sf = &surface.surfels()[s];
                    let trivial = sf.normal();
                    if interrupt.is_raised() {
                        return trivial;
                    }
                    if binary {
                        let m = scratch.convolve(surface, &graph, s, None, t);
                        return m.try_normalize().unwrap_or(trivial);
                    }
                    let [inner, outer] = sf.regions;
                    let a = scratch.convolve(surface, &graph, s, Some(inner), t);
                    let b = scratch.convolve(surface, &graph, s, Some(outer), t);
                    let a = a.try_normalize().unwrap_or(trivial);
                    let b = b.try_normalize().unwrap_or(-trivial);
                    combine_sides(a, b, trivial)
                },
            )
            .collect();
        interrupt.check()?;
        Ok(NormalField::new(normals))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use voxreg_digisurf::LabelVolume;

    #[test]
    fn flat_faces_keep_their_axis_and_corners_average() {
        // A 6x6x6 cube: the centre surfel of a face sees only its face.
        let volume = LabelVolume::from_fn([8, 8, 8], |p| u32::from(p.iter().all(|&c| (1..7).contains(&c))));
        let surface = DigitalSurface::from_volume(&volume).unwrap();
        let normals = ConvolvedTrivial { radius: Some(1.5) }.estimate(&surface).unwrap();
        for (s, n) in surface.surfels().iter().zip(normals.as_slice()) {
            let (u, v) = ((s.axis as usize + 1) % 3, (s.axis as usize + 2) % 3);
            let interior = (3..5).contains(&s.cell[u]) && (3..5).contains(&s.cell[v]);
            if interior {
                assert!((*n - s.normal()).length() < 1e-12);
            }
            assert!(n.dot(s.normal()) > 0.5, "{n} vs {}", s.normal());
        }
    }

    #[test]
    fn rejects_bad_radii() {
        let volume = LabelVolume::from_fn([3, 3, 3], |p| u32::from(p == [1, 1, 1]));
        let surface = DigitalSurface::from_volume(&volume).unwrap();
        assert!(ConvolvedTrivial { radius: Some(0.0) }.estimate(&surface).is_err());
        assert!(ConvolvedTrivial { radius: Some(f64::NAN) }.estimate(&surface).is_err());
    }
}
