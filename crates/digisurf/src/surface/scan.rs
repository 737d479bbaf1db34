//! The parallel pass of the surface's construction: the faces between voxels of
//! different regions, found over ranges of z-slabs through rolling layers, or, where the
//! volume is stored `z` fastest, over ranges of `y` rows reading each `(x, y)` column of
//! labels once, in memory order (`all_faces`); and the sequential numbering of their
//! vertices through two rolling corner layers (`Scan`).

use std::collections::HashMap;
use std::sync::atomic::{AtomicU64, Ordering};

use rayon::prelude::*;

use super::{Surfel, NONE};
use crate::error::SurfaceError;
use crate::ids::{InterfaceId, RegionId, VertexId};
use crate::regions::Regions;
use crate::volume::LabelView;

/// A face between two voxels of different regions, found by the parallel slab pass.
pub(super) struct RawFace {
    pub(super) cell: [u32; 3],
    pub(super) axis: u8,
    /// Regions and labels of the negative-side and positive-side voxels.
    pub(super) regions: [u32; 2],
    pub(super) labels: [u32; 2],
}

impl RawFace {
    /// Whether the face becomes a surfel: not on an open border (no region outside).
    fn is_inner(&self) -> bool {
        self.regions[0] != NONE && self.regions[1] != NONE
    }
}

/// A cap on the surfels one extraction finds, shared by its parallel tasks: each adds its
/// count as it goes (every [`Cap::EVERY`] faces or so: a slab's faces, or a column's
/// beyond), and the first to take the total past the cap stops them all with
/// [`SurfaceError::TooManySurfels`], so that the faces held at a refusal stay within the
/// cap and about [`Cap::EVERY`] a task.
pub(super) struct Cap {
    max: u64,
    found: AtomicU64,
}

impl Cap {
    /// The most faces a task finds between two counts.
    pub(super) const EVERY: u64 = 1 << 16;

    /// At most `max` surfels.
    pub(super) fn new(max: u64) -> Self {
        Cap { max, found: AtomicU64::new(0) }
    }

    /// No cap.
    pub(super) fn none() -> Self {
        Cap::new(u64::MAX)
    }

    /// Counts `n` more surfels.
    fn take(&self, n: u64) -> Result<(), SurfaceError> {
        if n == 0 || self.max == u64::MAX {
            return Ok(());
        }
        if self.found.fetch_add(n, Ordering::Relaxed).saturating_add(n) > self.max {
            return Err(SurfaceError::TooManySurfels(self.max));
        }
        Ok(())
    }
}

/// The `(region, label)` beyond each side of the domain, `[axis][low, high]`: the
/// background's, or [`NONE`] beyond an open side.
pub(super) type Outside = [[(u32, u32); 2]; 3];

pub(super) fn outside_of(volume: &LabelView<'_>, regions: &Regions) -> Outside {
    let closed = match (volume.background(), regions.background()) {
        (Some(l), Some(r)) => (r.0, l),
        _ => (NONE, NONE),
    };
    let open = volume.open_sides();
    [0, 1, 2].map(|k| [0, 1].map(|side| if open[k][side] { (NONE, NONE) } else { closed }))
}

/// Fills `rs`/`ls` with the regions and labels of voxel layer `z`, `x` fastest; the
/// outside beyond the domain.
pub(super) fn fill_layer(
    volume: &LabelView<'_>,
    regions: &Regions,
    outside: &Outside,
    z: isize,
    rs: &mut [u32],
    ls: &mut [u32],
) -> Result<(), SurfaceError> {
    let nz = volume.dims()[2];
    if z < 0 || z as usize >= nz {
        let (r, l) = outside[2][usize::from(z >= 0)];
        rs.fill(r);
        ls.fill(l);
        return Ok(());
    }
    // Transposed, the slab is [y, x]: logical order is x fastest, matching `x + nx * y`
    // (and memory order for volumes stored x fastest).
    let slab = volume.labels().index_axis(ndarray::Axis(2), z as usize);
    for ((r, l), &label) in rs.iter_mut().zip(ls.iter_mut()).zip(slab.t().iter()) {
        *l = label;
        *r = regions.region_of(label).map_or(NONE, |id| id.0);
    }
    check_regions(rs, ls)
}

/// Fails on the first label of a layer that has no region.
pub(super) fn check_regions(rs: &[u32], ls: &[u32]) -> Result<(), SurfaceError> {
    match rs.iter().position(|&r| r == NONE) {
        Some(i) => Err(SurfaceError::InvalidRegions(format!("label {} has no region", ls[i]))),
        None => Ok(()),
    }
}

/// What [`range_faces`] gathers of the inner faces of a range of slabs.
pub(super) trait SlabSink: Default {
    /// Starts the next slab.
    fn slab(&mut self);
    /// Takes an inner face of the current slab.
    fn face(&mut self, face: RawFace);
}

/// The faces, one list per slab.
impl SlabSink for Vec<Vec<RawFace>> {
    fn slab(&mut self) {
        self.push(Vec::new());
    }

    fn face(&mut self, face: RawFace) {
        if let Some(faces) = self.last_mut() {
            faces.push(face);
        }
    }
}

/// Their number only, without storing them.
impl SlabSink for u64 {
    fn slab(&mut self) {}

    fn face(&mut self, _: RawFace) {
        *self += 1;
    }
}

/// The inner faces of slabs `range` (see [`slab_faces`]), with rolling layers: one list
/// per slab as a `Vec<Vec<RawFace>>`, or their number as a `u64`; each slab's counted
/// against `cap`.
pub(super) fn range_faces<S: SlabSink>(
    volume: &LabelView<'_>,
    regions: &Regions,
    outside: &Outside,
    range: std::ops::Range<usize>,
    cap: &Cap,
) -> Result<S, SurfaceError> {
    let mut out = S::default();
    scan_slabs(volume, regions, outside, range, |prev, cur, k| {
        out.slab();
        let (mut n, mut refused) = (0, Ok(()));
        slab_faces(volume.dims(), outside, k, prev, cur, |f| {
            if f.is_inner() && refused.is_ok() {
                n += 1;
                out.face(f);
                if n == Cap::EVERY {
                    refused = cap.take(std::mem::take(&mut n));
                }
            }
        });
        refused.and_then(|()| cap.take(n))
    })?;
    Ok(out)
}

/// Calls `visit(previous layer, current layer, k)` for each slab `k` of `range`, with
/// rolling region/label layers; stops at its first error.
///
/// A volume stored `z` fastest (a C-order array indexed `[x, y, z]`, as numpy writes it)
/// is read [`LAYER_BATCH`] layers at a time, one short contiguous run per `(x, y)`: one
/// layer alone would read a single label from each cache line and page of the whole
/// volume.
pub(super) fn scan_slabs(
    volume: &LabelView<'_>,
    regions: &Regions,
    outside: &Outside,
    range: std::ops::Range<usize>,
    mut visit: impl FnMut(&(Vec<u32>, Vec<u32>), &(Vec<u32>, Vec<u32>), usize) -> Result<(), SurfaceError>,
) -> Result<(), SurfaceError> {
    let [nx, ny, _] = volume.dims();
    // At most a quarter of the range's layers at once: the batches of all ranges hold at
    // most about half as many bytes as the volume's labels.
    let batch = if z_fastest(volume).is_some() { (range.len() / 4).clamp(1, LAYER_BATCH) } else { 1 };
    // `layers[0]` is the layer before the next batch.
    let mut layers: Vec<(Vec<u32>, Vec<u32>)> =
        (0..=batch).map(|_| (vec![0u32; nx * ny], vec![0u32; nx * ny])).collect();
    fill_layers(volume, regions, outside, range.start as isize - 1, &mut layers[..1])?;
    let mut k = range.start;
    while k < range.end {
        let m = (layers.len() - 1).min(range.end - k);
        fill_layers(volume, regions, outside, k as isize, &mut layers[1..=m])?;
        for j in 0..m {
            visit(&layers[j], &layers[j + 1], k + j)?;
        }
        layers.swap(0, m);
        k += m;
    }
    Ok(())
}

/// Layers read together from a volume stored `z` fastest: 32 bytes of each `(x, y)`'s
/// run of labels per read.
pub(super) const LAYER_BATCH: usize = 8;

/// The labels as one slice indexed `(x * ny + y) * nz + z`, when stored so.
pub(super) fn z_fastest<'a>(volume: &'a LabelView<'_>) -> Option<&'a [u32]> {
    let labels = volume.labels();
    let [_, _, nz] = volume.dims();
    (labels.is_standard_layout() && nz > 1).then(|| labels.as_slice()).flatten()
}

/// Fills `layers[j]` with the regions and labels of voxel layer `z + j`, `x` fastest;
/// the outside beyond the domain.
pub(super) fn fill_layers(
    volume: &LabelView<'_>,
    regions: &Regions,
    outside: &Outside,
    z: isize,
    layers: &mut [(Vec<u32>, Vec<u32>)],
) -> Result<(), SurfaceError> {
    let [nx, ny, nz] = volume.dims();
    let inside = |j: usize| (0..nz as isize).contains(&(z + j as isize));
    match z_fastest(volume) {
        Some(all) if layers.len() > 1 => {
            // The layers inside the volume, `lo..hi`, from one contiguous run per column.
            let lo = (0..layers.len()).find(|&j| inside(j)).unwrap_or(layers.len());
            let hi = (lo..layers.len()).find(|&j| !inside(j)).unwrap_or(layers.len());
            if lo < hi {
                let z0 = (z + lo as isize) as usize;
                for x in 0..nx {
                    for y in 0..ny {
                        let start = (x * ny + y) * nz + z0;
                        let run = &all[start..start + hi - lo];
                        let i = x + nx * y;
                        for (layer, &label) in layers[lo..hi].iter_mut().zip(run) {
                            layer.1[i] = label;
                            layer.0[i] = regions.region_of(label).map_or(NONE, |id| id.0);
                        }
                    }
                }
            }
            for (j, (rs, ls)) in layers.iter_mut().enumerate() {
                if !inside(j) {
                    let (r, l) = outside[2][usize::from(z + j as isize >= 0)];
                    rs.fill(r);
                    ls.fill(l);
                } else {
                    check_regions(rs, ls)?;
                }
            }
            Ok(())
        }
        _ => {
            for (j, (rs, ls)) in layers.iter_mut().enumerate() {
                fill_layer(volume, regions, outside, z + j as isize, rs, ls)?;
            }
            Ok(())
        }
    }
}

/// The faces of slab `k`, in scan order: faces perpendicular to z between voxel layers
/// `k - 1` and `k`, then (for `k < nz`) faces perpendicular to x, then y, within layer `k`.
pub(super) fn slab_faces(
    dims: [usize; 3],
    outside: &Outside,
    k: usize,
    (prev_r, prev_l): &(Vec<u32>, Vec<u32>),
    (cur_r, cur_l): &(Vec<u32>, Vec<u32>),
    mut emit: impl FnMut(RawFace),
) {
    let [nx, ny, nz] = dims;
    let kk = k as u32;
    for y in 0..ny {
        for x in 0..nx {
            let i = x + nx * y;
            if prev_r[i] != cur_r[i] {
                emit(RawFace {
                    cell: [x as u32, y as u32, kk],
                    axis: 2,
                    regions: [prev_r[i], cur_r[i]],
                    labels: [prev_l[i], cur_l[i]],
                });
            }
        }
    }
    if k == nz {
        return;
    }
    for y in 0..ny {
        for x in 0..=nx {
            let (a, la) = if x > 0 { (cur_r[x - 1 + nx * y], cur_l[x - 1 + nx * y]) } else { outside[0][0] };
            let (b, lb) = if x < nx { (cur_r[x + nx * y], cur_l[x + nx * y]) } else { outside[0][1] };
            if a != b {
                emit(RawFace { cell: [x as u32, y as u32, kk], axis: 0, regions: [a, b], labels: [la, lb] });
            }
        }
    }
    for y in 0..=ny {
        for x in 0..nx {
            let (a, la) =
                if y > 0 { (cur_r[x + nx * (y - 1)], cur_l[x + nx * (y - 1)]) } else { outside[1][0] };
            let (b, lb) = if y < ny { (cur_r[x + nx * y], cur_l[x + nx * y]) } else { outside[1][1] };
            if a != b {
                emit(RawFace { cell: [x as u32, y as u32, kk], axis: 1, regions: [a, b], labels: [la, lb] });
            }
        }
    }
}

/// Sequential state of the scan: vertex numbering over two rolling corner layers.
pub(super) struct Scan {
    pub(super) nx: usize,
    pub(super) surfels: Vec<Surfel>,
    pub(super) vertex_corners: Vec<[u32; 3]>,
    /// Vertex ids of corner layers `k` and `k + 1`.
    pub(super) corners_lo: Vec<u32>,
    pub(super) corners_hi: Vec<u32>,
    pub(super) interface_of_pair: HashMap<(u32, u32), u32>,
    pub(super) last_pair: ((u32, u32), u32),
}

/// The most surfels a surface holds: their four corners' slots (`4 F`) are numbered in
/// `u32`.
pub(super) const MAX_SURFELS: usize = (1 << 30) - 1;

impl Scan {
    fn vertex(&mut self, c: [u32; 3], k: usize) -> Result<VertexId, SurfaceError> {
        let idx = c[0] as usize + (self.nx + 1) * c[1] as usize;
        let layer = if c[2] as usize == k { &mut self.corners_lo } else { &mut self.corners_hi };
        if layer[idx] == NONE {
            let id = u32::try_from(self.vertex_corners.len())
                .ok()
                .filter(|&i| i != NONE)
                .ok_or_else(|| SurfaceError::TooLarge("more than 2^32 - 1 vertices".into()))?;
            layer[idx] = id;
            self.vertex_corners.push(c);
        }
        Ok(VertexId(layer[idx]))
    }

    /// Adds the surfel between region `a` (negative side) and `b` (positive side), if any.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn face(
        &mut self,
        cell: [u32; 3],
        axis: usize,
        a: u32,
        b: u32,
        la: u32,
        lb: u32,
        k: usize,
    ) -> Result<(), SurfaceError> {
        if a == b || a == NONE || b == NONE {
            return Ok(());
        }
        if self.surfels.len() >= MAX_SURFELS {
            return Err(SurfaceError::TooLarge(format!("more than {MAX_SURFELS} surfels")));
        }
        let mut surfel = oriented_surfel(cell, axis, [a, b], [la, lb], |c| self.vertex(c, k))?;
        let pair = (surfel.regions[0].0, surfel.regions[1].0);
        let interface = if self.last_pair.0 == pair {
            self.last_pair.1
        } else {
            let n = self.interface_of_pair.len() as u32;
            let id = *self.interface_of_pair.entry(pair).or_insert(n);
            self.last_pair = (pair, id);
            id
        };
        surfel.interface = InterfaceId(interface);
        self.surfels.push(surfel);
        Ok(())
    }
}

/// The surfel of the face of `cell` normal to `axis` between regions `[a, b]` with labels
/// `[la, lb]` (the negative side's first), oriented from the smaller region to the larger:
/// `vertex` numbers its corners in order; its interface is left to the caller (`0`).
pub(super) fn oriented_surfel(
    cell: [u32; 3],
    axis: usize,
    [a, b]: [u32; 2],
    [la, lb]: [u32; 2],
    mut vertex: impl FnMut([u32; 3]) -> Result<VertexId, SurfaceError>,
) -> Result<Surfel, SurfaceError> {
    let flipped = a > b;
    let (inner, outer, li, lo) = if flipped { (b, a, lb, la) } else { (a, b, la, lb) };
    let mut vertices = [VertexId(0); 4];
    for (slot, c) in vertices.iter_mut().zip(face_corners(cell, axis, flipped)) {
        *slot = vertex(c)?;
    }
    Ok(Surfel {
        cell,
        axis: axis as u8,
        flipped,
        regions: [RegionId(inner), RegionId(outer)],
        labels: [li, lo],
        vertices,
        interface: InterfaceId(0),
    })
}

/// The faces of every slab `k` in `0..=nz`, in scan order (see [`slab_faces`]), each slab's
/// as a list of pieces to be read in turn.
pub(super) type SlabFaces = Vec<Vec<Vec<RawFace>>>;

/// The faces of all slabs, found in parallel: over ranges of slabs through rolling layers
/// ([`range_faces`]), or, for a volume stored `z` fastest, over ranges of `y` rows, each
/// `(x, y)` column of labels read once as one contiguous run ([`rows_faces`]).
pub(super) fn all_faces(
    volume: &LabelView<'_>,
    regions: &Regions,
    outside: &Outside,
    tasks: usize,
    cap: &Cap,
) -> Result<SlabFaces, SurfaceError> {
    let [_, ny, nz] = volume.dims();
    if let Some(all) = z_fastest(volume) {
        let per_task = ny.div_ceil(tasks).max(1);
        let mut found: Vec<[Vec<Vec<RawFace>>; 3]> = (0..ny.div_ceil(per_task))
            .into_par_iter()
            .map(|t| {
                rows_faces(volume, all, regions, outside, t * per_task..((t + 1) * per_task).min(ny), cap)
            })
            .collect::<Result<_, _>>()?;
        // Slab `k`: its z faces row range after row range, then its x faces, then its y faces.
        let mut slabs: SlabFaces = (0..=nz).map(|_| Vec::with_capacity(3 * found.len())).collect();
        for axis in [2, 0, 1] {
            for part in &mut found {
                for (k, faces) in part[axis].iter_mut().enumerate() {
                    slabs[k].push(std::mem::take(faces));
                }
            }
        }
        return Ok(slabs);
    }
    let per_task = (nz + 1).div_ceil(tasks);
    let found: Vec<Vec<Vec<RawFace>>> = (0..tasks)
        .into_par_iter()
        .map(|t| {
            range_faces::<Vec<Vec<RawFace>>>(
                volume,
                regions,
                outside,
                (t * per_task).min(nz + 1)..((t + 1) * per_task).min(nz + 1),
                cap,
            )
        })
        .collect::<Result<_, _>>()?;
    Ok(found.into_iter().flatten().map(|faces| vec![faces]).collect())
}

/// The faces of rows `ys` of a volume stored `z` fastest (`all`, indexed
/// `(x * ny + y) * nz + z`), `[x, y, z]` faces by axis and slab: the faces perpendicular to
/// `z` between `(x, y)` columns' voxels, and those perpendicular to `x` and `y` between
/// neighbouring columns, with cell `y` in `ys` (and `y = ny` for the last rows). Each
/// slab's list is in the order of [`slab_faces`] restricted to these rows. Each row's faces
/// are counted against `cap`.
pub(super) fn rows_faces(
    volume: &LabelView<'_>,
    all: &[u32],
    regions: &Regions,
    outside: &Outside,
    ys: std::ops::Range<usize>,
    cap: &Cap,
) -> Result<[Vec<Vec<RawFace>>; 3], SurfaceError> {
    let [nx, ny, nz] = volume.dims();
    let mut out: [Vec<Vec<RawFace>>; 3] = [0, 1, 2].map(|_| (0..=nz).map(|_| Vec::new()).collect());
    let label = |x: usize, y: usize, z: usize| all[(x * ny + y) * nz + z];
    // The regions of row `y`'s voxels, `x * nz + z`.
    let row = |y: usize, rs: &mut Vec<u32>| -> Result<(), SurfaceError> {
        rs.clear();
        let labels = &all[y * nz..];
        for x in 0..nx {
            let column = &labels[x * ny * nz..x * ny * nz + nz];
            for &l in column {
                let r = regions.region_of(l).map_or(NONE, |id| id.0);
                if r == NONE {
                    return Err(SurfaceError::InvalidRegions(format!("label {l} has no region")));
                }
                rs.push(r);
            }
        }
        Ok(())
    };
    let (mut prev, mut cur) = (Vec::with_capacity(nx * nz), Vec::with_capacity(nx * nz));
    if ys.start > 0 {
        row(ys.start - 1, &mut prev)?;
    }
    // A column of the outside beyond each side, `[axis][low, high]`.
    let beyond: [[Vec<u32>; 2]; 3] = outside.map(|sides| sides.map(|(r, _)| vec![r; nz]));
    let last = if ys.end == ny { ny + 1 } else { ys.end };
    // The row's faces, counted against the cap.
    let mut n = 0u64;
    for y in ys.start..last {
        let yy = y as u32;
        if y < ny {
            row(y, &mut cur)?;
            // Faces perpendicular to z (each slab's list gets one face per column at most).
            for x in 0..nx {
                let col = &cur[x * nz..(x + 1) * nz];
                let cell = |z: usize| [x as u32, yy, z as u32];
                let label_at = |z: usize| label(x, y, z);
                let (lo, hi) = (outside[2][0], outside[2][1]);
                if col[0] != lo.0 && lo.0 != NONE {
                    n += 1;
                    out[2][0].push(RawFace {
                        cell: cell(0),
                        axis: 2,
                        regions: [lo.0, col[0]],
                        labels: [lo.1, label_at(0)],
                    });
                }
                for_differences(&col[..nz - 1], &col[1..], |j, a, b| {
                    let z = j + 1;
                    n += 1;
                    out[2][z].push(RawFace {
                        cell: cell(z),
                        axis: 2,
                        regions: [a, b],
                        labels: [label_at(z - 1), label_at(z)],
                    });
                });
                if col[nz - 1] != hi.0 && hi.0 != NONE {
                    let face = RawFace {
                        cell: cell(nz),
                        axis: 2,
                        regions: [col[nz - 1], hi.0],
                        labels: [label_at(nz - 1), hi.1],
                    };
                    n += 1;
                    out[2][nz].push(face);
                }
                if n >= Cap::EVERY {
                    cap.take(std::mem::take(&mut n))?;
                }
            }
            // Faces perpendicular to x.
            for x in 0..=nx {
                let a = if x > 0 { &cur[(x - 1) * nz..x * nz] } else { &beyond[0][0][..] };
                let b = if x < nx { &cur[x * nz..(x + 1) * nz] } else { &beyond[0][1][..] };
                for_differences(a, b, |z, ra, rb| {
                    let la = if x > 0 { label(x - 1, y, z) } else { outside[0][0].1 };
                    let lb = if x < nx { label(x, y, z) } else { outside[0][1].1 };
                    n += 1;
                    out[0][z].push(RawFace {
                        cell: [x as u32, yy, z as u32],
                        axis: 0,
                        regions: [ra, rb],
                        labels: [la, lb],
                    });
                });
                if n >= Cap::EVERY {
                    cap.take(std::mem::take(&mut n))?;
                }
            }
        }
        // Faces perpendicular to y, between rows `y - 1` and `y`.
        for x in 0..nx {
            let a = if y > 0 { &prev[x * nz..(x + 1) * nz] } else { &beyond[1][0][..] };
            let b = if y < ny { &cur[x * nz..(x + 1) * nz] } else { &beyond[1][1][..] };
            for_differences(a, b, |z, ra, rb| {
                let la = if y > 0 { label(x, y - 1, z) } else { outside[1][0].1 };
                let lb = if y < ny { label(x, y, z) } else { outside[1][1].1 };
                n += 1;
                out[1][z].push(RawFace {
                    cell: [x as u32, yy, z as u32],
                    axis: 1,
                    regions: [ra, rb],
                    labels: [la, lb],
                });
            });
            if n >= Cap::EVERY {
                cap.take(std::mem::take(&mut n))?;
            }
        }
        std::mem::swap(&mut prev, &mut cur);
        cap.take(std::mem::take(&mut n))?;
    }
    Ok(out)
}

/// Calls `f(i, a[i], b[i])` for each `i` where the two regions differ and both are regions
/// (not [`NONE`]: an open side), in increasing `i`: the common case, equal runs, is a
/// plain comparison of the two slices.
fn for_differences(a: &[u32], b: &[u32], mut f: impl FnMut(usize, u32, u32)) {
    const BLOCK: usize = 16;
    for (k, (ca, cb)) in a.chunks(BLOCK).zip(b.chunks(BLOCK)).enumerate() {
        if ca == cb {
            continue;
        }
        for (j, (&ra, &rb)) in ca.iter().zip(cb).enumerate() {
            if ra != rb && ra != NONE && rb != NONE {
                f(k * BLOCK + j, ra, rb);
            }
        }
    }
}

/// The lattice corners of the face of `cell` normal to `axis`, in the order that orients
/// its surfel from the inner region to the outer (`flipped`: the face's regions are in the
/// opposite order).
fn face_corners(cell: [u32; 3], axis: usize, flipped: bool) -> [[u32; 3]; 4] {
    let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
    let mut cu = cell;
    cu[u] += 1;
    let mut cuv = cu;
    cuv[v] += 1;
    let mut cv = cell;
    cv[v] += 1;
    if flipped {
        [cell, cv, cuv, cu]
    } else {
        [cell, cu, cuv, cv]
    }
}
