//! Construction and queries of the digital surface.

use std::collections::HashMap;

use glam::DVec3;
use rayon::prelude::*;

#[cfg(test)]
use crate::csr::split_lengths;
use crate::csr::Lists;
use crate::data::VertexData;
use crate::error::SurfaceError;
use crate::ids::{EdgeId, InterfaceId, RegionId, SurfelId, VertexId};
use crate::regions::{RegionMap, Regions};
use crate::union_find::union_find_root;
use crate::volume::{LabelStorage, LabelView, LabelVolume, Voxel};

mod blocks;
mod scan;

use scan::{all_faces, outside_of, range_faces, Cap, Scan};

const NONE: u32 = u32::MAX;

/// One piece of vertices' part of the surface's cells ([`DigitalSurface::build_cells`]),
/// numbered within the piece.
#[derive(Default)]
struct VertexPass {
    edges: Vec<Edge>,
    /// Each edge's surfels, and where each edge's end (exclusive) in `items`.
    items: Vec<SurfelId>,
    item_ends: Vec<u32>,
    neighbours: Vec<VertexId>,
    neighbour_ends: Vec<u32>,
    /// Per vertex: on a rim, pinched.
    flags: Vec<(bool, bool)>,
}

/// A surfel's corners and the lattice directions of its sides, as the vertex pass reads
/// them at random: a fifth of a [`Surfel`]'s bytes.
struct SurfelCorners {
    vertices: [VertexId; 4],
    /// `2 * axis + flipped`, the row of [`SIDE_DIRECTIONS`].
    code: u8,
}

/// The lattice direction (`2 * axis + negative`) of side `j` of a surfel, from its corner `j`
/// to corner `j + 1`, by the surfel's `2 * axis + flipped`: with `(u, v)` the axes after
/// `axis`, the corners go `+u, +v, -u, -v` (flipped: `+v, +u, -v, -u`).
const SIDE_DIRECTIONS: [[u8; 4]; 6] = {
    let mut t = [[0u8; 4]; 6];
    let mut axis = 0;
    while axis < 3 {
        let (u, v) = (2 * ((axis + 1) % 3) as u8, 2 * ((axis + 2) % 3) as u8);
        t[2 * axis] = [u, v, u + 1, v + 1];
        t[2 * axis + 1] = [v, u, v + 1, u + 1];
        axis += 1;
    }
    t
};

/// A surfel: the square face between two face-adjacent voxels of different regions.
///
/// The face lies in the lattice plane perpendicular to `axis` through lattice
/// corner `cell`; it separates voxel `cell - e_axis` (the *negative side*) from
/// voxel `cell` (the *positive side*).
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub struct Surfel {
    /// Lattice coordinates of the face's minimal corner.
    pub cell: [u32; 3],
    /// The axis (0 = x, 1 = y, 2 = z) the face is perpendicular to.
    pub axis: u8,
    /// Whether the oriented normal is `-e_axis` rather than `+e_axis`.
    pub flipped: bool,
    /// `[inner, outer]` regions, `inner < outer`: the oriented normal points from
    /// the inner voxel into the outer one.
    pub regions: [RegionId; 2],
    /// Labels of the `[inner, outer]` voxels (the background label for the outside
    /// of the domain).
    pub labels: [u32; 2],
    /// The four corners, counter-clockwise seen from the tip of the oriented normal.
    pub vertices: [VertexId; 4],
    /// The interface (region pair) the surfel belongs to.
    pub interface: InterfaceId,
}

impl Surfel {
    /// The oriented unit normal (the trivial normal): `±e_axis`, from inner to outer.
    pub fn normal(&self) -> DVec3 {
        let mut n = DVec3::ZERO;
        n[self.axis as usize] = if self.flipped { -1.0 } else { 1.0 };
        n
    }

    /// The `[inner, outer]` voxels. Either may lie outside the domain.
    pub fn voxels(&self) -> [Voxel; 2] {
        let pos = [self.cell[0] as i64, self.cell[1] as i64, self.cell[2] as i64];
        let mut neg = pos;
        neg[self.axis as usize] -= 1;
        if self.flipped {
            [pos, neg]
        } else {
            [neg, pos]
        }
    }
}

/// How an edge sits in the complex, by its incident surfels.
#[derive(Copy, Clone, Debug, PartialEq, Eq, Hash)]
pub enum EdgeKind {
    /// On the rim of an open surface (the domain border of a volume without background).
    Boundary,
    /// Two incident surfels: a manifold edge.
    Regular,
    /// Three or four incident surfels around three or more regions: where interfaces meet.
    Junction,
    /// Four incident surfels around only two regions: two diagonal voxels of a region
    /// touching along this edge (an edge pinch).
    Pinch,
}

/// An edge of the complex: a lattice edge incident to at least one surfel.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub struct Edge {
    /// End points, the lower id first.
    pub vertices: [VertexId; 2],
    /// The axis the edge is parallel to.
    pub axis: u8,
    /// How the edge sits in the complex.
    pub kind: EdgeKind,
}

/// The surfels between one unordered pair of regions.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Interface {
    /// The two regions, lower first (surfel normals point from the first to the second).
    pub regions: [RegionId; 2],
    /// The interface's surfels, in increasing id order.
    pub surfels: Vec<SurfelId>,
}

/// Counts describing a digital surface, as reported by `voxreg info`.
#[derive(Clone, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct SurfaceCounts {
    /// Number of surfels (quads).
    pub surfels: usize,
    /// Number of vertices.
    pub vertices: usize,
    /// Number of edges.
    pub edges: usize,
    /// Number of interfaces (region pairs with at least one surfel).
    pub interfaces: usize,
    /// Number of edge-connected components of surfels.
    pub components: usize,
    /// Number of vertices on the rim of open surfaces.
    pub boundary_vertices: usize,
    /// Number of rim edges.
    pub boundary_edges: usize,
    /// Number of junction edges (three or more regions meet).
    pub junction_edges: usize,
    /// Number of pinched edges (two diagonal voxels of one region).
    pub pinched_edges: usize,
    /// Number of pinched vertices (the surfels around the vertex form several fans).
    pub pinched_vertices: usize,
}

/// The digital surface of a labeled volume: surfels, edges, vertices and interfaces,
/// with their incidences.
///
/// It holds structure only (ids and incidences) plus the embedding of the lattice;
/// per-element quantities (normals, positions, weights) live in plain arrays indexed
/// by the ids. Build it with [`DigitalSurface::new`].
#[derive(Clone, Debug, PartialEq)]
pub struct DigitalSurface {
    dims: [usize; 3],
    spacing: DVec3,
    origin: DVec3,
    open_sides: [[bool; 2]; 3],
    regions: Regions,
    surfels: Vec<Surfel>,
    surfel_edges: Vec<[EdgeId; 4]>,
    vertex_corners: Vec<[u32; 3]>,
    vertex_surfels: Lists<SurfelId>,
    vertex_neighbours: Lists<VertexId>,
    boundary_vertex: Vec<bool>,
    pinched_vertex: Vec<bool>,
    edges: Vec<Edge>,
    edge_surfels: Lists<SurfelId>,
    interfaces: Vec<Interface>,
    surfel_component: Vec<u32>,
    component_closed: Vec<bool>,
}

/// Touches every page of `v`'s spare capacity from the pool's threads (one zeroed slot a
/// page), so that a sequential loop filling it then finds its pages resident.
fn prefault<T: Send>(v: &mut Vec<T>) {
    let step = (4096 / std::mem::size_of::<T>().max(1)).max(1);
    v.spare_capacity_mut().par_chunks_mut(64 * step).for_each(|chunk| {
        for slot in chunk.iter_mut().step_by(step) {
            *slot = std::mem::MaybeUninit::zeroed();
        }
    });
}

/// `n` copies of `value`, written in parallel: a fresh array's pages are first touched by
/// the threads that fill them, where `vec![value; n]` (for values other than zeroed
/// primitives, which come from zeroed pages) has one thread write them all.
fn par_filled<T: Copy + Send + Sync>(value: T, n: usize) -> Vec<T> {
    (0..n).into_par_iter().map(|_| value).collect()
}

impl DigitalSurface {
    /// The digital surface of `volume` with every label its own region.
    pub fn from_volume<S: LabelStorage>(volume: &LabelVolume<S>) -> Result<Self, SurfaceError> {
        Self::new(volume, &RegionMap::per_label())
    }

    /// The digital surface of `volume`, with labels grouped into regions by `map`.
    ///
    /// Cost: one pass over the voxels (linear), memory for the slab being scanned plus
    /// the complex itself (proportional to the number of surfels). Fails with
    /// [`SurfaceError::Empty`] when no surfel separates two regions. The volume may own
    /// or borrow its labels (a [`LabelView`](crate::volume::LabelView)); either is read in place.
    pub fn new<S: LabelStorage>(volume: &LabelVolume<S>, map: &RegionMap) -> Result<Self, SurfaceError> {
        Self::of_view(&volume.view(), map, &Cap::none())
    }

    /// [`DigitalSurface::new`] with at most `max_surfels` surfels: fails with
    /// [`SurfaceError::TooManySurfels`] as soon as its pass over the voxels has found more,
    /// before the complex's arrays are made, so that a caller can refuse a surface too
    /// large for its memory without a separate count ([`DigitalSurface::count_surfels`])
    /// of a surface that fits. The faces found before the refusal hold at most about
    /// 32 bytes a surfel of the cap.
    pub fn new_within<S: LabelStorage>(
        volume: &LabelVolume<S>,
        map: &RegionMap,
        max_surfels: u64,
    ) -> Result<Self, SurfaceError> {
        Self::of_view(&volume.view(), map, &Cap::new(max_surfels))
    }

    /// [`DigitalSurface::new`], compiled once for every storage.
    fn of_view(volume: &LabelView<'_>, map: &RegionMap, cap: &Cap) -> Result<Self, SurfaceError> {
        let regions = map.resolve(volume)?;
        let [nx, ny, nz] = volume.dims();
        if nx.max(ny).max(nz) >= (u32::MAX as usize) - 1 {
            return Err(SurfaceError::TooLarge(format!("dimensions {nx}x{ny}x{nz}")));
        }
        let outside = outside_of(volume, &regions);
        let layer = (nx + 1) * (ny + 1);
        let mut scan = Scan {
            nx,
            surfels: Vec::new(),
            vertex_corners: Vec::new(),
            corners_lo: vec![NONE; layer],
            corners_hi: vec![NONE; layer],
            interface_of_pair: HashMap::new(),
            last_pair: ((NONE, NONE), NONE),
        };
        // Faces are found in parallel (voxel-proportional work), then numbered sequentially
        // in slab order (surfel-proportional work).
        let found = all_faces(volume, &regions, &outside, rayon::current_num_threads().max(1), cap)?;
        // The surfels' array sized once (a grown one holds up to twice its surfels), and
        // the vertices' for as many (a closed surface has about one a surfel); their pages
        // faulted in by the pool rather than one at a time by the numbering below.
        let total = found.iter().flatten().map(Vec::len).sum();
        scan.surfels.reserve_exact(total);
        scan.vertex_corners.reserve_exact(total);
        prefault(&mut scan.surfels);
        prefault(&mut scan.vertex_corners);
        for (k, pieces) in found.into_iter().enumerate() {
            for f in pieces.into_iter().flatten() {
                scan.face(f.cell, f.axis as usize, f.regions[0], f.regions[1], f.labels[0], f.labels[1], k)?;
            }
            std::mem::swap(&mut scan.corners_lo, &mut scan.corners_hi);
            scan.corners_hi.fill(NONE);
        }
        let Scan { surfels, vertex_corners, interface_of_pair, .. } = scan;
        Self::assemble(
            [nx, ny, nz],
            (volume.spacing(), volume.origin(), volume.open_sides()),
            regions,
            surfels,
            vertex_corners,
            interface_of_pair,
        )
    }

    /// The surface of the surfels found by a scan (in scan order, their vertices numbered
    /// in order of first use, their interfaces by pair in order of first use): interfaces
    /// numbered by region pair, then edges, vertex lists and components.
    fn assemble(
        dims: [usize; 3],
        (spacing, origin, open_sides): (DVec3, DVec3, [[bool; 2]; 3]),
        regions: Regions,
        mut surfels: Vec<Surfel>,
        mut vertex_corners: Vec<[u32; 3]>,
        interface_of_pair: HashMap<(u32, u32), u32>,
    ) -> Result<Self, SurfaceError> {
        vertex_corners.shrink_to_fit();
        if surfels.is_empty() {
            return Err(SurfaceError::Empty);
        }

        // Interfaces, numbered by region pair.
        let mut pairs: Vec<((u32, u32), u32)> = interface_of_pair.into_iter().collect();
        pairs.sort_unstable();
        let mut renumber = vec![0u32; pairs.len()];
        for (new, &(_, old)) in pairs.iter().enumerate() {
            renumber[old as usize] = new as u32;
        }
        let mut sizes = vec![0usize; pairs.len()];
        surfels.iter().for_each(|s| sizes[s.interface.index()] += 1);
        let mut interfaces: Vec<Interface> = pairs
            .iter()
            .map(|&((a, b), old)| Interface {
                regions: [RegionId(a), RegionId(b)],
                surfels: Vec::with_capacity(sizes[old as usize]),
            })
            .collect();
        for (i, s) in surfels.iter_mut().enumerate() {
            s.interface = InterfaceId(renumber[s.interface.index()]);
            interfaces[s.interface.index()].surfels.push(SurfelId(i as u32));
        }

        let mut surface = DigitalSurface {
            dims,
            spacing,
            origin,
            open_sides,
            regions,
            surfel_edges: Vec::new(),
            vertex_surfels: Lists::default(),
            vertex_neighbours: Lists::default(),
            boundary_vertex: Vec::new(),
            pinched_vertex: Vec::new(),
            edges: Vec::new(),
            edge_surfels: Lists::default(),
            interfaces,
            surfel_component: Vec::new(),
            component_closed: Vec::new(),
            vertex_corners,
            surfels,
        };
        surface.build_vertex_surfels();
        surface.build_cells();
        surface.build_components();
        Ok(surface)
    }

    /// The number of surfels [`DigitalSurface::new`] would build from `volume` and `map`,
    /// counted in one pass over the voxels without storing a face, so that a caller can
    /// refuse a surface too large for its memory before building it.
    pub fn count_surfels<S: LabelStorage>(
        volume: &LabelVolume<S>,
        map: &RegionMap,
    ) -> Result<u64, SurfaceError> {
        let volume = &volume.view();
        let regions = map.resolve(volume)?;
        let nz = volume.dims()[2];
        let outside = outside_of(volume, &regions);
        let tasks = rayon::current_num_threads().max(1);
        let per_task = (nz + 1).div_ceil(tasks);
        (0..tasks)
            .into_par_iter()
            .map(|t| {
                range_faces::<u64>(
                    volume,
                    &regions,
                    &outside,
                    (t * per_task).min(nz + 1)..((t + 1) * per_task).min(nz + 1),
                    &Cap::none(),
                )
            })
            .try_reduce(|| 0, |a, b| Ok(a + b))
    }

    /// Each vertex's surfels, in increasing order: the surfels cut into one chunk per
    /// thread, each counting its surfels' corners per vertex and then writing them at its
    /// own cursor within each vertex's list (so no two chunks write the same slot).
    fn build_vertex_surfels(&mut self) {
        use std::sync::atomic::{AtomicU32, Ordering};
        let (nv, nf) = (self.vertex_corners.len(), self.surfels.len());
        let per = nf.div_ceil(rayon::current_num_threads().clamp(1, 8)).max(1);
        let surfels = &self.surfels;
        let chunk = |c: usize| (c * per..((c + 1) * per).min(nf)).zip(&surfels[c * per..]);
        // `counts[c][v]`: vertex `v`'s corners among chunk `c`'s surfels.
        let mut counts: Vec<Vec<u32>> = (0..nf.div_ceil(per))
            .into_par_iter()
            .map(|c| {
                let mut n = vec![0u32; nv];
                for (_, f) in chunk(c) {
                    for v in f.vertices {
                        n[v.index()] += 1;
                    }
                }
                n
            })
            .collect();
        // The lists' offsets, and each chunk's cursor: where its first surfel at `v` goes.
        let mut offsets = vec![0u32; nv + 1];
        let mut at = 0u32;
        for (v, offset) in offsets[..nv].iter_mut().enumerate() {
            *offset = at;
            for n in counts.iter_mut() {
                let k = n[v];
                n[v] = at;
                at += k;
            }
        }
        offsets[nv] = at;
        let items: Vec<AtomicU32> = (0..at).map(|_| AtomicU32::new(0)).collect();
        counts.into_par_iter().enumerate().for_each(|(c, mut cursor)| {
            for (s, f) in chunk(c) {
                for v in f.vertices {
                    items[cursor[v.index()] as usize].store(s as u32, Ordering::Relaxed);
                    cursor[v.index()] += 1;
                }
            }
        });
        let items = items.into_iter().map(|a| SurfelId(a.into_inner())).collect();
        self.vertex_surfels = Lists::from_parts(offsets, items);
    }

    /// [`DigitalSurface::build_vertex_surfels`] in one thread, counting then filling: the
    /// reference it is tested against.
    #[cfg(test)]
    fn vertex_surfels_in_one_pass(&self) -> Lists<SurfelId> {
        let surfels = &self.surfels;
        Lists::from_pairs(self.vertex_corners.len(), |f| {
            for (s, surfel) in surfels.iter().enumerate() {
                for v in surfel.vertices {
                    f(v.index(), SurfelId(s as u32));
                }
            }
        })
    }

    /// The edges (numbered by their end points `(a, b)`, `a < b`, each listing its surfels
    /// in increasing order), each surfel's four edges, each vertex's neighbours (sorted),
    /// whether it is on a rim and whether it is pinched: one pass over the vertices in
    /// parallel pieces, each vertex sorting the sides of its surfels at it once
    /// ([`DigitalSurface::vertex_pass`]), then a parallel copy of the pieces into the
    /// surface's arrays. Linear in the surfels, no sort of all `4 F` sides.
    fn build_cells(&mut self) {
        use std::sync::atomic::{AtomicU32, Ordering};
        const PIECE: usize = crate::csr::PIECE;
        let nv = self.vertex_corners.len();
        let this = &*self;
        // The surfels' corners alone, a quarter of their records' bytes: read at random.
        let corners: Vec<SurfelCorners> = self
            .surfels
            .par_iter()
            .map(|f| SurfelCorners { vertices: f.vertices, code: 2 * f.axis + u8::from(f.flipped) })
            .collect();
        // Each side's edge, numbered within the piece of the side's lower end first.
        let surfel_edges: Vec<[AtomicU32; 4]> =
            (0..self.surfels.len()).into_par_iter().map(|_| [0; 4].map(AtomicU32::new)).collect();
        let pieces: Vec<VertexPass> = (0..nv.div_ceil(PIECE))
            .into_par_iter()
            .map(|p| {
                let (start, end) = (p * PIECE, ((p + 1) * PIECE).min(nv));
                // Two sides a surfel at each vertex; on a closed surface, half of them
                // are items of the vertex's edges (a side's edge is its lower end's), a
                // quarter edges, half neighbours. A quarter more, for the pieces above.
                let offsets = this.vertex_surfels.offsets();
                let sides = 2 * (offsets[end] - offsets[start]) as usize;
                let (quarter, half) = (sides * 5 / 16 + 16, sides * 5 / 8 + 16);
                let mut out = VertexPass {
                    edges: Vec::with_capacity(quarter),
                    items: Vec::with_capacity(half),
                    item_ends: Vec::with_capacity(quarter),
                    neighbours: Vec::with_capacity(half.min(6 * (end - start))),
                    neighbour_ends: Vec::with_capacity(end - start),
                    flags: Vec::with_capacity(end - start),
                };
                for a in start..end {
                    this.vertex_pass(a, &corners, &mut out, &surfel_edges);
                }
                out
            })
            .collect();
        let num_edges: usize = pieces.iter().map(|p| p.edges.len()).sum();
        let num_items: usize = pieces.iter().map(|p| p.items.len()).sum();
        let num_nbrs: usize = pieces.iter().map(|p| p.neighbours.len()).sum();
        let blank = Edge { vertices: [VertexId(0); 2], axis: 0, kind: EdgeKind::Regular };
        let mut edges = par_filled(blank, num_edges);
        let mut offsets = vec![0u32; num_edges + 1];
        let mut items = par_filled(SurfelId(0), num_items);
        let mut nbr_offsets = vec![0u32; nv + 1];
        let mut nbrs = par_filled(VertexId(0), num_nbrs);
        let mut flags = vec![(false, false); nv];
        let mut edge_bases = Vec::with_capacity(pieces.len());
        // Each piece's slices of the outputs, and where its edges, items and neighbours start.
        let (mut e_rest, mut o_rest, mut i_rest) = (&mut edges[..], &mut offsets[1..], &mut items[..]);
        let (mut no_rest, mut n_rest, mut f_rest) = (&mut nbr_offsets[1..], &mut nbrs[..], &mut flags[..]);
        let mut at = [0usize; 3];
        let mut parts = Vec::with_capacity(pieces.len());
        for p in &pieces {
            let (e, o, i, no, n, f);
            (e, e_rest) = std::mem::take(&mut e_rest).split_at_mut(p.edges.len());
            (o, o_rest) = std::mem::take(&mut o_rest).split_at_mut(p.edges.len());
            (i, i_rest) = std::mem::take(&mut i_rest).split_at_mut(p.items.len());
            (no, no_rest) = std::mem::take(&mut no_rest).split_at_mut(p.flags.len());
            (n, n_rest) = std::mem::take(&mut n_rest).split_at_mut(p.neighbours.len());
            (f, f_rest) = std::mem::take(&mut f_rest).split_at_mut(p.flags.len());
            parts.push((at, e, o, i, no, n, f));
            edge_bases.push(at[0] as u32);
            at = [at[0] + p.edges.len(), at[1] + p.items.len(), at[2] + p.neighbours.len()];
        }
        parts.into_par_iter().zip(pieces).for_each(|((at, e, o, i, no, n, f), p)| {
            e.copy_from_slice(&p.edges);
            i.copy_from_slice(&p.items);
            n.copy_from_slice(&p.neighbours);
            f.copy_from_slice(&p.flags);
            for (dst, &end) in o.iter_mut().zip(&p.item_ends) {
                *dst = (at[1] + end as usize) as u32;
            }
            for (dst, &end) in no.iter_mut().zip(&p.neighbour_ends) {
                *dst = (at[2] + end as usize) as u32;
            }
        });
        surfel_edges.par_iter().zip(&corners).for_each(|(c, vs)| {
            for j in 0..4 {
                let owner = vs.vertices[j].min(vs.vertices[(j + 1) % 4]).index();
                c[j].fetch_add(edge_bases[owner / PIECE], Ordering::Relaxed);
            }
        });
        // Same size and alignment: collected in place, no second array.
        self.surfel_edges = surfel_edges.into_iter().map(|c| c.map(|e| EdgeId(e.into_inner()))).collect();
        self.edges = edges;
        self.edge_surfels = Lists::from_parts(offsets, items);
        self.vertex_neighbours = Lists::from_parts(nbr_offsets, nbrs);
        self.boundary_vertex = flags.iter().map(|f| f.0).collect();
        self.pinched_vertex = flags.iter().map(|f| f.1).collect();
    }

    /// Vertex `a`'s part of [`DigitalSurface::build_cells`] (`corners`: each surfel's
    /// vertices and side directions), appended to `out`: its surfels' sides at `a`
    /// bucketed by their lattice direction (slot `4s + j` is side `j` of surfel `s`, from
    /// its corner `j` to corner `j + 1`; a side's bucket holds its surfels in increasing
    /// order); its neighbours, the other ends of the non-empty buckets, sorted; its edges,
    /// those to higher vertices (a side belongs to its lower end), each side's edge
    /// numbered within the piece in `surfel_edges`; its fans, its surfels joined where two
    /// share a side. The direction gives the edge's axis and lower corner, so no other
    /// vertex's corner is read and no list of sides is sorted.
    fn vertex_pass(
        &self,
        a: usize,
        corners: &[SurfelCorners],
        out: &mut VertexPass,
        surfel_edges: &[[std::sync::atomic::AtomicU32; 4]],
    ) {
        let around = self.vertex_surfels.get(a);
        // A lattice corner has 6 lattice edges, each with at most 4 faces, and 12 faces.
        let mut ends = [NONE; 6];
        let mut sizes = [0u8; 6];
        let mut sides = [[(0u32, 0u8); 4]; 6];
        debug_assert!(around.len() <= 12);
        for (k, &s) in around.iter().enumerate() {
            let c = &corners[s.index()];
            let i = c.vertices.iter().position(|v| v.index() == a).unwrap_or(0);
            let dirs = &SIDE_DIRECTIONS[c.code as usize];
            let (j_prev, i_next) = ((i + 3) % 4, (i + 1) % 4);
            // Side `i` leaves `a`; side `i - 1` arrives at it (its direction reversed).
            for (d, slot, end) in [
                (dirs[i], 4 * s.0 + i as u32, c.vertices[i_next].0),
                (dirs[j_prev] ^ 1, 4 * s.0 + j_prev as u32, c.vertices[j_prev].0),
            ] {
                let d = d as usize;
                ends[d] = end;
                sides[d][sizes[d] as usize] = (slot, k as u8);
                sizes[d] += 1;
            }
        }
        // The non-empty directions by their other end's id.
        let mut order = [0u8; 6];
        let mut n = 0;
        for d in 0..6u8 {
            if sizes[d as usize] > 0 {
                let mut at = n;
                while at > 0 && ends[order[at - 1] as usize] > ends[d as usize] {
                    order[at] = order[at - 1];
                    at -= 1;
                }
                order[at] = d;
                n += 1;
            }
        }
        let ca = self.vertex_corners[a];
        let open = self.has_open_border();
        let mut boundary = false;
        for &d in &order[..n] {
            let d = d as usize;
            let (b, group) = (ends[d], &sides[d][..sizes[d] as usize]);
            out.neighbours.push(VertexId(b));
            if (b as usize) < a && !open {
                continue;
            }
            let axis = d / 2;
            let mut low = ca;
            low[axis] -= (d & 1) as u32;
            if (b as usize) < a {
                boundary |= self.on_open_side(low, axis);
                continue;
            }
            let first = out.items.len();
            let e = out.edges.len() as u32;
            for &(slot, _) in group {
                out.items.push(SurfelId(slot / 4));
                surfel_edges[slot as usize / 4][slot as usize % 4]
                    .store(e, std::sync::atomic::Ordering::Relaxed);
            }
            out.item_ends.push(out.items.len() as u32);
            let kind = self.edge_kind(low, axis, &out.items[first..]);
            boundary |= kind == EdgeKind::Boundary;
            out.edges.push(Edge { vertices: [VertexId(a as u32), VertexId(b)], axis: axis as u8, kind });
        }
        out.neighbour_ends.push(out.neighbours.len() as u32);
        // The fan of the first surfel: grown through the directions (each joins the
        // surfels with a side along it) until it stops growing.
        let masks =
            [0, 1, 2, 3, 4, 5].map(|d| sides[d][..sizes[d] as usize].iter().fold(0u16, |m, t| m | 1 << t.1));
        let mut fan = 1u16;
        loop {
            let grown = masks.iter().fold(fan, |f, &m| if f & m != 0 { f | m } else { f });
            if grown == fan {
                break;
            }
            fan = grown;
        }
        let pinched = fan.count_ones() as usize != around.len();
        out.flags.push((boundary, pinched));
    }

    /// Whether the lattice edge from `corner` along `axis` lies on an open side of the
    /// domain (a rim edge).
    fn on_open_side(&self, corner: [u32; 3], axis: usize) -> bool {
        let open = &self.open_sides;
        (0..3).any(|u| {
            u != axis
                && ((open[u][0] && corner[u] == 0) || (open[u][1] && corner[u] as usize == self.dims[u]))
        })
    }

    #[cfg(test)]
    /// Vertex `a`'s sides `(b, slot)` with `b > a`, sorted: the sides of its surfels that
    /// it owns (a side belongs to its lower end). Slot `4s + j` is side `j` of surfel `s`,
    /// from its corner `j` to corner `j + 1`.
    fn owned_sides(&self, a: usize, out: &mut Vec<(u32, u32)>) {
        out.clear();
        for &s in self.vertex_surfels.get(a) {
            let vs = self.surfels[s.index()].vertices;
            let i = vs.iter().position(|v| v.index() == a).unwrap_or(0);
            let (next, prev) = (vs[(i + 1) % 4].0, vs[(i + 3) % 4].0);
            if next as usize > a {
                out.push((next, 4 * s.0 + i as u32));
            }
            if prev as usize > a {
                out.push((prev, 4 * s.0 + ((i + 3) % 4) as u32));
            }
        }
        out.sort_unstable();
    }

    #[cfg(test)]
    /// The edges, numbered by their end points `(a, b)`, `a < b`, each listing its surfels
    /// in increasing order, and each surfel's four: built per vertex from its own sides
    /// ([`DigitalSurface::owned_sides`]) in parallel over pieces of vertices, in time
    /// linear in the surfels (no sort of all `4F` sides).
    fn build_edges(&mut self) {
        use std::sync::atomic::{AtomicU32, Ordering};
        const PIECE: usize = crate::csr::PIECE;
        let nv = self.vertex_corners.len();
        let this = &*self;
        // Edges and sides of each piece of vertices.
        let counts: Vec<(usize, usize)> = (0..nv.div_ceil(PIECE))
            .into_par_iter()
            .map_init(Vec::new, |out, p| {
                let (mut edges, mut sides) = (0, 0);
                for a in p * PIECE..((p + 1) * PIECE).min(nv) {
                    this.owned_sides(a, out);
                    sides += out.len();
                    edges += out.chunk_by(|x, y| x.0 == y.0).count();
                }
                (edges, sides)
            })
            .collect();
        let num_edges: usize = counts.iter().map(|c| c.0).sum();
        let num_sides: usize = counts.iter().map(|c| c.1).sum();
        debug_assert_eq!(num_sides, 4 * self.surfels.len());
        let blank = Edge { vertices: [VertexId(0); 2], axis: 0, kind: EdgeKind::Regular };
        let mut edges = par_filled(blank, num_edges);
        let mut offsets = vec![0u32; num_edges + 1];
        let mut items = par_filled(SurfelId(0), num_sides);
        let surfel_edges: Vec<AtomicU32> =
            (0..num_sides).into_par_iter().map(|_| AtomicU32::new(0)).collect();
        // Each piece's slices of the outputs, and where they start.
        let bases: Vec<(usize, usize)> = counts
            .iter()
            .scan((0, 0), |at, &(ne, ns)| {
                let base = *at;
                *at = (at.0 + ne, at.1 + ns);
                Some(base)
            })
            .collect();
        let pieces = bases
            .into_par_iter()
            .enumerate()
            .zip(split_lengths(&mut edges, counts.iter().map(|c| c.0)))
            .zip(split_lengths(&mut offsets[1..], counts.iter().map(|c| c.0)))
            .zip(split_lengths(&mut items, counts.iter().map(|c| c.1)));
        pieces.for_each_init(Vec::new, |out, ((((p, (e_base, i_base)), edges), ends), items)| {
            let (mut le, mut li) = (0, 0);
            for a in p * PIECE..((p + 1) * PIECE).min(nv) {
                this.owned_sides(a, out);
                for group in out.chunk_by(|x, y| x.0 == y.0) {
                    let e = (e_base + le) as u32;
                    let first = li;
                    for &(_, slot) in group {
                        items[li] = SurfelId(slot / 4);
                        surfel_edges[slot as usize].store(e, Ordering::Relaxed);
                        li += 1;
                    }
                    ends[le] = (i_base + li) as u32;
                    let b = group[0].0;
                    let (ca, cb) = (this.vertex_corners[a], this.vertex_corners[b as usize]);
                    let axis = (0..3).find(|&k| ca[k] != cb[k]).unwrap_or(0);
                    let kind = this.edge_kind(ca.min(cb), axis, &items[first..li]);
                    edges[le] = Edge { vertices: [VertexId(a as u32), VertexId(b)], axis: axis as u8, kind };
                    le += 1;
                }
            }
        });
        self.surfel_edges = surfel_edges
            .par_chunks(4)
            .map(|c| [0, 1, 2, 3].map(|j| EdgeId(c[j].load(Ordering::Relaxed))))
            .collect();
        self.edges = edges;
        self.edge_surfels = Lists::from_parts(offsets, items);
    }

    fn edge_kind(&self, corner: [u32; 3], axis: usize, incident: &[SurfelId]) -> EdgeKind {
        if self.on_open_side(corner, axis) {
            return EdgeKind::Boundary;
        }
        match incident.len() {
            0..=2 => EdgeKind::Regular,
            3 => EdgeKind::Junction,
            _ => {
                let mut rs: Vec<RegionId> =
                    incident.iter().flat_map(|s| self.surfels[s.index()].regions).collect();
                rs.sort_unstable();
                rs.dedup();
                if rs.len() == 2 {
                    EdgeKind::Pinch
                } else {
                    EdgeKind::Junction
                }
            }
        }
    }

    #[cfg(test)]
    fn build_vertex_lists(&mut self) {
        let nv = self.vertex_corners.len();
        // A vertex's neighbours: the other ends of its surfels' sides at it, sorted.
        let (surfels, vertex_surfels) = (&self.surfels, &self.vertex_surfels);
        self.vertex_neighbours = Lists::par_from_fn(nv, |a, out| {
            for &s in vertex_surfels.get(a) {
                let vs = surfels[s.index()].vertices;
                let i = vs.iter().position(|v| v.index() == a).unwrap_or(0);
                out.push(vs[(i + 1) % 4]);
                out.push(vs[(i + 3) % 4]);
            }
            out.sort_unstable();
            out.dedup();
        });
        let mut boundary = vec![false; nv];
        for e in &self.edges {
            if e.kind == EdgeKind::Boundary {
                boundary[e.vertices[0].index()] = true;
                boundary[e.vertices[1].index()] = true;
            }
        }
        self.boundary_vertex = boundary;
        self.pinched_vertex =
            (0..nv).into_par_iter().map(|v| self.fan_count(VertexId(v as u32)) > 1).collect();
    }

    #[cfg(test)]
    /// Number of fans around `v`: groups of incident surfels connected through
    /// edges incident to `v`.
    fn fan_count(&self, v: VertexId) -> usize {
        let around = self.vertex_surfels.get(v.index());
        // (edge, local surfel index) for the two edges of each surfel that touch v.
        let mut links: Vec<(EdgeId, u32)> = Vec::with_capacity(2 * around.len());
        for (li, s) in (0u32..).zip(around) {
            let sf = &self.surfels[s.index()];
            let i = sf.vertices.iter().position(|&w| w == v).unwrap_or(0);
            let es = self.surfel_edges[s.index()];
            links.push((es[i], li));
            links.push((es[(i + 3) % 4], li));
        }
        links.sort_unstable();
        let mut parent: Vec<u32> = (0..around.len() as u32).collect();
        for group in links.chunk_by(|a, b| a.0 == b.0) {
            for w in group.windows(2) {
                let (a, b) = (union_find_root(&mut parent, w[0].1), union_find_root(&mut parent, w[1].1));
                parent[a as usize] = b;
            }
        }
        (0..around.len() as u32).filter(|&i| union_find_root(&mut parent, i) == i).count()
    }

    /// The edge-connected components of the surfels, numbered in the order of their
    /// first surfels, and whether each is closed: a union-find over the edges in id order
    /// (each edge's surfels are neighbours in the scan, so the parents read stay close),
    /// then one pass over the surfels.
    fn build_components(&mut self) {
        let n = self.surfels.len();
        // `parent[s] <= s`: each tree's root is its smallest surfel.
        let mut parent: Vec<u32> = (0..n as u32).collect();
        for e in 0..self.edges.len() {
            let incident = self.edge_surfels.get(e);
            let mut a = union_find_root(&mut parent, incident[0].0);
            for t in &incident[1..] {
                let b = union_find_root(&mut parent, t.0);
                if a != b {
                    let (lo, hi) = (a.min(b), a.max(b));
                    parent[hi as usize] = lo;
                    a = lo;
                }
            }
        }
        // Roots come first in their trees, so one pass numbers components in order.
        let mut closed = Vec::new();
        for s in 0..n {
            let p = parent[s];
            parent[s] = if p as usize == s {
                closed.push(true);
                (closed.len() - 1) as u32
            } else {
                // The parent's component is already numbered; compress through it.
                parent[p as usize]
            };
        }
        for (e, edge) in self.edges.iter().enumerate() {
            if edge.kind == EdgeKind::Boundary {
                closed[parent[self.edge_surfels.get(e)[0].index()] as usize] = false;
            }
        }
        self.surfel_component = parent;
        self.component_closed = closed;
    }

    /// [`DigitalSurface::build_components`] by a depth-first search from each surfel in
    /// turn, as it was built before: the reference the union-find is tested against.
    #[cfg(test)]
    fn components_by_search(&self) -> (Vec<u32>, Vec<bool>) {
        let n = self.surfels.len();
        let mut comp = vec![NONE; n];
        let mut closed = Vec::new();
        let mut stack = Vec::new();
        for start in 0..n {
            if comp[start] != NONE {
                continue;
            }
            let c = closed.len() as u32;
            let mut is_closed = true;
            comp[start] = c;
            stack.push(start);
            while let Some(s) = stack.pop() {
                for e in self.surfel_edges[s] {
                    if self.edges[e.index()].kind == EdgeKind::Boundary {
                        is_closed = false;
                    }
                    for t in self.edge_surfels.get(e.index()) {
                        if comp[t.index()] == NONE {
                            comp[t.index()] = c;
                            stack.push(t.index());
                        }
                    }
                }
            }
            closed.push(is_closed);
        }
        (comp, closed)
    }

    // ---- queries ------------------------------------------------------------------

    /// Number of voxels along x, y and z of the source volume.
    pub fn dims(&self) -> [usize; 3] {
        self.dims
    }

    /// Physical voxel size of the source volume.
    pub fn spacing(&self) -> DVec3 {
        self.spacing
    }

    /// The regions of the source volume.
    pub fn regions(&self) -> &Regions {
        &self.regions
    }

    /// Whether some side of the domain is open (the volume has no background, or was
    /// cut out of a larger one), so surfaces may end there.
    pub fn has_open_border(&self) -> bool {
        self.open_sides.iter().flatten().any(|&o| o)
    }

    /// The open sides of the domain, `[axis][low, high]`: every side when the volume has
    /// no background, else those of [`LabelVolume::with_open_sides`].
    pub fn open_sides(&self) -> [[bool; 2]; 3] {
        self.open_sides
    }

    /// All surfels, indexed by [`SurfelId`].
    pub fn surfels(&self) -> &[Surfel] {
        &self.surfels
    }

    /// Surfel `s`.
    pub fn surfel(&self, s: SurfelId) -> &Surfel {
        &self.surfels[s.index()]
    }

    /// The four edges of surfel `s`; edge `i` joins its vertices `i` and `i + 1 (mod 4)`.
    pub fn surfel_edges(&self, s: SurfelId) -> [EdgeId; 4] {
        self.surfel_edges[s.index()]
    }

    /// Number of surfels.
    pub fn num_surfels(&self) -> usize {
        self.surfels.len()
    }

    /// Number of vertices.
    pub fn num_vertices(&self) -> usize {
        self.vertex_corners.len()
    }

    /// Number of edges.
    pub fn num_edges(&self) -> usize {
        self.edges.len()
    }

    /// All edges, indexed by [`EdgeId`].
    pub fn edges(&self) -> &[Edge] {
        &self.edges
    }

    /// The surfels incident to edge `e` (1 on a rim, 2 on a manifold edge, up to 4).
    pub fn edge_surfels(&self, e: EdgeId) -> &[SurfelId] {
        self.edge_surfels.get(e.index())
    }

    /// Lattice coordinates of vertex `v` (integers in `0..=dims`).
    pub fn vertex_corner(&self, v: VertexId) -> [u32; 3] {
        self.vertex_corners[v.index()]
    }

    /// Physical position of vertex `v`: `origin + (corner - 0.5) * spacing`.
    pub fn vertex_position(&self, v: VertexId) -> DVec3 {
        let c = self.vertex_corners[v.index()];
        self.origin + (DVec3::new(c[0] as f64, c[1] as f64, c[2] as f64) - 0.5) * self.spacing
    }

    /// Physical positions of all vertices, indexed by [`VertexId`].
    pub fn positions(&self) -> VertexData<DVec3> {
        VertexData::new(
            (0..self.num_vertices())
                .into_par_iter()
                .map(|v| self.vertex_position(VertexId(v as u32)))
                .collect(),
        )
    }

    /// The edge-neighbours of vertex `v`, sorted by id. Across interfaces too.
    pub fn vertex_neighbours(&self, v: VertexId) -> &[VertexId] {
        self.vertex_neighbours.get(v.index())
    }

    /// The surfels incident to vertex `v`.
    pub fn vertex_surfels(&self, v: VertexId) -> &[SurfelId] {
        self.vertex_surfels.get(v.index())
    }

    /// Every vertex's incident surfels ([`DigitalSurface::vertex_surfels`]) as one flat
    /// list with offsets: for arrays laid out slot by slot beside it, which then need
    /// neither offsets nor surfel ids of their own.
    pub fn vertex_surfel_lists(&self) -> &Lists<SurfelId> {
        &self.vertex_surfels
    }

    /// Whether `v` lies on the rim of an open surface.
    pub fn is_boundary_vertex(&self, v: VertexId) -> bool {
        self.boundary_vertex[v.index()]
    }

    /// All interfaces, ordered by region pair.
    pub fn interfaces(&self) -> &[Interface] {
        &self.interfaces
    }

    /// The edge-connected component of surfel `s` (components are numbered from 0).
    pub fn surfel_component(&self, s: SurfelId) -> u32 {
        self.surfel_component[s.index()]
    }

    /// For each component, whether it is closed (has no rim edge).
    pub fn components_closed(&self) -> &[bool] {
        &self.component_closed
    }

    /// `V - E + F` of the whole complex (pinched cells counted once).
    pub fn euler_characteristic(&self) -> i64 {
        self.num_vertices() as i64 - self.num_edges() as i64 + self.num_surfels() as i64
    }

    /// Summary counts.
    pub fn counts(&self) -> SurfaceCounts {
        let count_kind = |k| self.edges.iter().filter(|e| e.kind == k).count();
        SurfaceCounts {
            surfels: self.num_surfels(),
            vertices: self.num_vertices(),
            edges: self.num_edges(),
            interfaces: self.interfaces.len(),
            components: self.component_closed.len(),
            boundary_vertices: self.boundary_vertex.iter().filter(|&&b| b).count(),
            boundary_edges: count_kind(EdgeKind::Boundary),
            junction_edges: count_kind(EdgeKind::Junction),
            pinched_edges: count_kind(EdgeKind::Pinch),
            pinched_vertices: self.pinched_vertex.iter().filter(|&&b| b).count(),
        }
    }
}

#[cfg(test)]
mod tests;
