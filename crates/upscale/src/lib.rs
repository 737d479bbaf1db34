//! Upscaling: voxelize a regularized digital surface at `K` times the resolution of its
//! volume (papers: section 4.5, Fig. 13), turning blocky voxel art into a finer voxel
//! model whose staircase follows the smooth surface.
//!
//! [`upscale`] takes the digital surface, its regularized vertex positions and the
//! source volume, and returns a [`LabelVolume`] `K` times finer along each axis:
//!
//! - **Inside or outside** by parity along z-columns: each quad is split into two
//!   triangles (as the mesh writers do), the triangles bounding the solid (the faces
//!   with the background on their outer side) are rasterized over the fine columns, and
//!   a fine voxel is inside when an odd number of crossings lies below its centre. Points
//!   on shared triangle edges are counted once, by a top-left rule evaluated on
//!   canonically ordered edges, so the parity is exact on closed surfaces.
//! - **Labels** (and so colours): the label of the source voxel holding the fine voxel's
//!   centre when that voxel is solid (colour blocks stay where the artist put them);
//!   for the fine voxels that the smooth surface gained from empty source voxels, the
//!   solid-side label of the nearest regularized quad (within the 27 source voxels
//!   around), else of the nearest solid source voxel.
//!
//! # Example
//!
//! ```
//! use voxreg_digisurf::{DigitalSurface, LabelVolume};
//! use voxreg_upscale::{upscale, UpscaleParams};
//!
//! let volume = LabelVolume::from_fn([3, 3, 3], |p| u32::from(p == [1, 1, 1]) * 5);
//! let surface = DigitalSurface::from_volume(&volume)?;
//! let fine = upscale(&surface, &surface.positions(), &volume, &UpscaleParams { factor: 2 })?;
//! assert_eq!(fine.dims(), [6, 6, 6]);
//! // The unmoved surface of one voxel encloses exactly its 8 sub-voxels.
//! assert_eq!(fine.labels().iter().filter(|&&l| l == 5).count(), 8);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use glam::{DVec2, DVec3};
use ndarray::{Array3, Axis, ShapeBuilder, Slice};
use rayon::prelude::*;
use voxreg_digisurf::{Block, BlockVolume, DigitalSurface, LabelVolume, SurfaceError, Voxel};

/// Parameters of [`upscale`].
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub struct UpscaleParams {
    /// Refinement factor `K` per axis, `1..=16`. Default: `2`.
    pub factor: usize,
}

impl Default for UpscaleParams {
    fn default() -> Self {
        UpscaleParams { factor: 2 }
    }
}

/// What can go wrong when upscaling.
#[derive(Debug, thiserror::Error, Clone, PartialEq, Eq)]
pub enum UpscaleError {
    /// A parameter or input is out of range.
    #[error("invalid input: {0}")]
    Invalid(String),
    /// The finer volume could not be built.
    #[error(transparent)]
    Volume(#[from] SurfaceError),
}

/// One crossing of a fine column (`i + fine_x * j`) by a boundary triangle.
struct Crossing {
    column: u64,
    z: f64,
}

/// The top-left rule on a canonically ordered edge: returns whether a point exactly on
/// edge `a -> b` of a counter-clockwise triangle counts as inside, and the edge function.
#[inline]
fn edge(a: DVec2, b: DVec2, p: DVec2) -> (f64, bool) {
    // Evaluate with the endpoints in a fixed order so that the two triangles sharing the
    // edge get bitwise opposite values.
    let swapped = (b.x, b.y) < (a.x, a.y);
    let (lo, hi) = if swapped { (b, a) } else { (a, b) };
    let e = (hi - lo).perp_dot(p - lo);
    let e = if swapped { -e } else { e };
    let d = b - a;
    (e, d.y > 0.0 || (d.y == 0.0 && d.x < 0.0))
}

/// Upscales `volume` by `params.factor`, using the regularized `positions` of `surface`
/// (one per vertex; physical coordinates, as from the regularizers).
///
/// The source volume needs a background (the solid is what the background surrounds).
/// The result has spacing `spacing / K`, the same physical extent, and background 0.
pub fn upscale(
    surface: &DigitalSurface,
    positions: &[DVec3],
    volume: &LabelVolume,
    params: &UpscaleParams,
) -> Result<LabelVolume, UpscaleError> {
    let Some(background) = volume.background() else {
        return Err(UpscaleError::Invalid("upscaling needs a volume with a background".into()));
    };
    let lattice = Lattice::new(surface, positions, volume.dims(), volume.spacing(), volume.origin(), params)?;
    let fine = lattice.fine;
    if fine.iter().map(|&d| d as u128).product::<u128>() > (1u128 << 32) {
        return Err(UpscaleError::Invalid(format!(
            "{}x{}x{} voxels is too large",
            fine[0], fine[1], fine[2]
        )));
    }
    let prepared = Prepared::new(surface, positions, &lattice, background);
    let labels = prepared.fill(&lattice, [0; 3], fine, &|v| volume.label(v));
    let out = LabelVolume::from_x_fastest(fine, labels)?
        .with_spacing(lattice.h)?
        .with_origin(lattice.corner0 + 0.5 * lattice.h)?
        .with_background(Some(0));
    Ok(out)
}

/// [`upscale`] of a volume given as blocks (a scene of models far apart), block by block:
/// the result holds the fine voxels of a box around each block's regularized surface
/// (boxes merged where they come within a voxel of each other), and its lattice is the
/// finer lattice of `volume`. Its voxels are those of [`upscale`] on `volume` made dense,
/// everywhere (outside the boxes, that upscale is background: a block's solid boundary
/// crosses each column outside its box an even number of times on each side of a
/// centre), for the memory and time of the boxes alone. `surface` is `volume`'s
/// ([`DigitalSurface::from_blocks`]).
pub fn upscale_blocks(
    surface: &DigitalSurface,
    positions: &[DVec3],
    volume: &BlockVolume,
    params: &UpscaleParams,
) -> Result<BlockVolume, UpscaleError> {
    let background = volume.background();
    let lattice = Lattice::new(surface, positions, volume.dims(), volume.spacing(), volume.origin(), params)?;
    let prepared = Prepared::new(surface, positions, &lattice, background);
    let boxes = merged(prepared.block_boxes(surface, positions, &lattice, volume));
    let stored: u128 =
        boxes.iter().map(|(lo, hi)| (0..3).map(|a| (hi[a] - lo[a]) as u128).product::<u128>()).sum();
    if stored > (1u128 << 32) {
        let f = lattice.fine;
        return Err(UpscaleError::Invalid(format!(
            "{stored} voxels in blocks of a {}x{}x{} lattice is too large",
            f[0], f[1], f[2]
        )));
    }
    let k = lattice.k;
    let dims = lattice.dims;
    let mut blocks = Vec::with_capacity(boxes.len());
    for (lo, hi) in boxes {
        // The source voxels of the box's fine voxels and their neighbours, dense.
        let slo = lo.map(|l| (l / k).saturating_sub(1));
        let shi = [0, 1, 2].map(|a| ((hi[a] - 1) / k + 2).min(dims[a]));
        let mut window = Array3::from_elem((shi[0] - slo[0], shi[1] - slo[1], shi[2] - slo[2]), background);
        for b in volume.blocks() {
            let (blo, bhi) = b.bounds();
            let (clo, chi) = ([0, 1, 2].map(|a| blo[a].max(slo[a])), [0, 1, 2].map(|a| bhi[a].min(shi[a])));
            if (0..3).any(|a| clo[a] >= chi[a]) {
                continue;
            }
            let (mut to, mut from) = (window.view_mut(), b.labels.view());
            for a in 0..3 {
                to.slice_axis_inplace(Axis(a), Slice::from(clo[a] - slo[a]..chi[a] - slo[a]));
                from.slice_axis_inplace(Axis(a), Slice::from(clo[a] - blo[a]..chi[a] - blo[a]));
            }
            to.assign(&from);
        }
        let source = |v: Voxel| -> Option<u32> {
            if (0..3).any(|a| v[a] < 0 || v[a] as usize >= dims[a]) {
                return None;
            }
            let w = [0, 1, 2].map(|a| (v[a] as usize).wrapping_sub(slo[a]));
            match window.get(w) {
                Some(&l) => Some(l),
                None => Some(volume.label(v)),
            }
        };
        let labels = prepared.fill(&lattice, lo, hi, &source);
        if labels.iter().all(|&l| l == 0) {
            continue;
        }
        let shape = (hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]).f();
        let labels =
            Array3::from_shape_vec(shape, labels).map_err(|e| UpscaleError::Invalid(e.to_string()))?;
        blocks.push(Block { offset: lo, labels });
    }
    let out = BlockVolume::new(lattice.fine, blocks, 0)?
        .with_spacing(lattice.h)?
        .with_origin(lattice.corner0 + 0.5 * lattice.h)?;
    Ok(out)
}

/// Boxes `[lo, hi)` merged into their bounding boxes until every two are one voxel apart
/// along some axis (a [`BlockVolume`]'s blocks).
fn merged(mut boxes: Vec<([usize; 3], [usize; 3])>) -> Vec<([usize; 3], [usize; 3])> {
    let touch = |a: &([usize; 3], [usize; 3]), b: &([usize; 3], [usize; 3])| {
        (0..3).all(|k| b.0[k] <= a.1[k] && a.0[k] <= b.1[k])
    };
    loop {
        boxes.sort_unstable();
        let mut out: Vec<([usize; 3], [usize; 3])> = Vec::with_capacity(boxes.len());
        let mut changed = false;
        'next: for b in boxes {
            // Sorted by their low x: a box can only touch the kept ones that reach it.
            for kept in out.iter_mut().rev() {
                if touch(kept, &b) {
                    for k in 0..3 {
                        kept.0[k] = kept.0[k].min(b.0[k]);
                        kept.1[k] = kept.1[k].max(b.1[k]);
                    }
                    changed = true;
                    continue 'next;
                }
            }
            out.push(b);
        }
        boxes = out;
        if !changed {
            return boxes;
        }
    }
}

/// The fine lattice of an upscale.
struct Lattice {
    k: usize,
    /// The source lattice's dimensions and voxel size.
    dims: [usize; 3],
    spacing: DVec3,
    /// The fine lattice's dimensions and voxel size.
    fine: [usize; 3],
    h: DVec3,
    /// The volume's min corner (fine voxel `i` has its centre at `corner0 + (i + 1/2) h`).
    corner0: DVec3,
}

impl Lattice {
    fn new(
        surface: &DigitalSurface,
        positions: &[DVec3],
        dims: [usize; 3],
        spacing: DVec3,
        origin: DVec3,
        params: &UpscaleParams,
    ) -> Result<Lattice, UpscaleError> {
        let k = params.factor;
        if !(1..=16).contains(&k) {
            return Err(UpscaleError::Invalid(format!("factor {k}: must be in 1..=16")));
        }
        if positions.len() != surface.num_vertices() {
            return Err(UpscaleError::Invalid(format!(
                "{} positions for {} vertices",
                positions.len(),
                surface.num_vertices()
            )));
        }
        let fine = dims.map(|d| d * k);
        Ok(Lattice { k, dims, spacing, fine, h: spacing / k as f64, corner0: origin - 0.5 * spacing })
    }

    fn centre(&self, i: [usize; 3]) -> DVec3 {
        self.corner0 + (DVec3::new(i[0] as f64, i[1] as f64, i[2] as f64) + 0.5) * self.h
    }

    /// The source voxel holding `p`, if in the lattice.
    fn cell_of(&self, p: DVec3) -> Option<[usize; 3]> {
        let c = ((p - self.corner0) / self.spacing).floor();
        (0..3).all(|a| c[a] >= 0.0 && (c[a] as usize) < self.dims[a]).then_some([
            c.x as usize,
            c.y as usize,
            c.z as usize,
        ])
    }

    /// The source voxel's index, x fastest.
    fn key(&self, v: [usize; 3]) -> u64 {
        v[0] as u64 + self.dims[0] as u64 * (v[1] as u64 + self.dims[1] as u64 * v[2] as u64)
    }
}

/// What the fill reads: the triangles' crossings of the fine columns, and the quads near
/// each source voxel.
struct Prepared<'a> {
    surface: &'a DigitalSurface,
    positions: &'a [DVec3],
    background: u32,
    /// The quads bounding the solid (the background on their outer side).
    boundary: Vec<usize>,
    /// Sorted by column, then height.
    crossings: Vec<Crossing>,
    /// `(source voxel key, quad)`, sorted: the quads whose centre each source voxel holds.
    bucket_of: Vec<(u64, u32)>,
}

impl<'a> Prepared<'a> {
    fn new(surface: &'a DigitalSurface, positions: &'a [DVec3], lattice: &Lattice, background: u32) -> Self {
        let background_region = surface.regions().background();
        let (fine, h, corner0) = (lattice.fine, lattice.h, lattice.corner0);
        // Crossings of the fine columns by the triangles bounding the solid.
        let boundary: Vec<usize> = surface
            .surfels()
            .iter()
            .enumerate()
            .filter(|(_, s)| Some(s.regions[1]) == background_region && s.labels[0] != background)
            .map(|(i, _)| i)
            .collect();
        let mut crossings: Vec<Crossing> = boundary
            .par_iter()
            .flat_map_iter(|&s| {
                let q = surface.surfels()[s].vertices.map(|v| positions[v.index()]);
                let mut out = Vec::new();
                for tri in [[q[0], q[1], q[2]], [q[0], q[2], q[3]]] {
                    let mut p = tri.map(|v| DVec2::new(v.x, v.y));
                    let mut z = tri.map(|v| v.z);
                    let area = (p[1] - p[0]).perp_dot(p[2] - p[0]);
                    if area == 0.0 {
                        continue; // vertical in projection: no column crosses its interior
                    }
                    if area < 0.0 {
                        p.swap(1, 2);
                        z.swap(1, 2);
                    }
                    let lo = p[0].min(p[1]).min(p[2]);
                    let hi = p[0].max(p[1]).max(p[2]);
                    let i0 = (((lo.x - corner0.x) / h.x - 0.5).ceil().max(0.0)) as usize;
                    let j0 = (((lo.y - corner0.y) / h.y - 0.5).ceil().max(0.0)) as usize;
                    let i1 = (((hi.x - corner0.x) / h.x - 0.5).floor()).min(fine[0] as f64 - 1.0);
                    let j1 = (((hi.y - corner0.y) / h.y - 0.5).floor()).min(fine[1] as f64 - 1.0);
                    if i1 < 0.0 || j1 < 0.0 {
                        continue;
                    }
                    for j in j0..=j1 as usize {
                        for i in i0..=i1 as usize {
                            let c = lattice.centre([i, j, 0]);
                            let pc = DVec2::new(c.x, c.y);
                            let mut w = [0.0; 3];
                            let mut inside = true;
                            for e in 0..3 {
                                let (v, top_left) = edge(p[e], p[(e + 1) % 3], pc);
                                if v < 0.0 || (v == 0.0 && !top_left) {
                                    inside = false;
                                    break;
                                }
                                w[(e + 2) % 3] = v;
                            }
                            if inside {
                                let sum = w[0] + w[1] + w[2];
                                let zc = (w[0] * z[0] + w[1] * z[1] + w[2] * z[2]) / sum;
                                out.push(Crossing { column: i as u64 + fine[0] as u64 * j as u64, z: zc });
                            }
                        }
                    }
                }
                out.into_iter()
            })
            .collect();
        crossings.par_sort_unstable_by(|a, b| a.column.cmp(&b.column).then(a.z.total_cmp(&b.z)));
        // Quads near each source voxel, for labels near the surface: bucket the regularized
        // quad centres by the source voxel that holds them.
        let quad_centre = |s: usize| {
            let q = surface.surfels()[s].vertices.map(|v| positions[v.index()]);
            (q[0] + q[1] + q[2] + q[3]) / 4.0
        };
        let mut bucket_of: Vec<(u64, u32)> = boundary
            .iter()
            .filter_map(|&s| lattice.cell_of(quad_centre(s)).map(|v| (lattice.key(v), s as u32)))
            .collect();
        bucket_of.sort_unstable();
        Prepared { surface, positions, background, boundary, crossings, bucket_of }
    }

    fn quad_centre(&self, s: usize) -> DVec3 {
        let q = self.surface.surfels()[s].vertices.map(|v| self.positions[v.index()]);
        (q[0] + q[1] + q[2] + q[3]) / 4.0
    }

    /// The label of a fine voxel inside the smooth surface, centred at `p`; `source`
    /// gives the source volume's labels (`None` outside its lattice).
    fn label_at(&self, lattice: &Lattice, p: DVec3, source: &impl Fn(Voxel) -> Option<u32>) -> u32 {
        let background = self.background;
        let dims = lattice.dims;
        let Some(v) = lattice.cell_of(p) else { return 0 };
        let [x, y, z] = v.map(|c| c as i64);
        if let Some(l) = source([x, y, z]).filter(|&l| l != background) {
            return l;
        }
        let mut best: Option<(f64, u32)> = None;
        for dz in -1..=1i64 {
            for dy in -1..=1i64 {
                for dx in -1..=1i64 {
                    let n = [x + dx, y + dy, z + dz];
                    if (0..3).any(|a| n[a] < 0 || n[a] as usize >= dims[a]) {
                        continue;
                    }
                    let key = lattice.key(n.map(|c| c as usize));
                    let start = self.bucket_of.partition_point(|e| e.0 < key);
                    for &(kk, s) in &self.bucket_of[start..] {
                        if kk != key {
                            break;
                        }
                        let d = (self.quad_centre(s as usize) - p).length_squared();
                        if best.is_none_or(|b| d < b.0) {
                            best = Some((d, self.surface.surfels()[s as usize].labels[0]));
                        }
                    }
                }
            }
        }
        match best {
            Some((_, l)) => l,
            None => {
                // No quad nearby: the nearest solid neighbour voxel.
                let mut best: Option<(i64, u32)> = None;
                for dz in -1..=1i64 {
                    for dy in -1..=1i64 {
                        for dx in -1..=1i64 {
                            if let Some(l) = source([x + dx, y + dy, z + dz]).filter(|&l| l != background) {
                                let d = dx * dx + dy * dy + dz * dz;
                                if best.is_none_or(|b| d < b.0) {
                                    best = Some((d, l));
                                }
                            }
                        }
                    }
                }
                best.map_or(background, |b| b.1)
            }
        }
    }

    /// The fine voxels of the box `[lo, hi)`, `x` fastest: inside by parity of the
    /// crossings below each centre (all of its column's), labelled by [`Self::label_at`].
    fn fill(
        &self,
        lattice: &Lattice,
        lo: [usize; 3],
        hi: [usize; 3],
        source: &(impl Fn(Voxel) -> Option<u32> + Sync),
    ) -> Vec<u32> {
        let size = [0, 1, 2].map(|a| hi[a] - lo[a]);
        let columns = size[0] * size[1];
        // In parallel over columns.
        let column_labels: Vec<Vec<u32>> = (0..columns)
            .into_par_iter()
            .map(|c| {
                let (i, j) = (lo[0] + c % size[0], lo[1] + c / size[0]);
                let column = i as u64 + lattice.fine[0] as u64 * j as u64;
                let start = self.crossings.partition_point(|x| x.column < column);
                let end = start + self.crossings[start..].partition_point(|x| x.column == column);
                let zs = &self.crossings[start..end];
                let mut out = vec![0u32; size[2]];
                let mut below = 0;
                for (kz, slot) in out.iter_mut().enumerate() {
                    let p = lattice.centre([i, j, lo[2] + kz]);
                    while below < zs.len() && zs[below].z < p.z {
                        below += 1;
                    }
                    if below % 2 == 1 {
                        *slot = self.label_at(lattice, p, source);
                    }
                }
                out
            })
            .collect();
        let mut labels = vec![0u32; columns * size[2]];
        for (c, col) in column_labels.iter().enumerate() {
            for (kz, &l) in col.iter().enumerate() {
                labels[c + columns * kz] = l;
            }
        }
        labels
    }

    /// The fine boxes `[lo, hi)` around each block's quads bounding the solid (their
    /// regularized positions, with a fine voxel to spare), within the lattice: a block's
    /// quads bounding the solid bound its solid voxels, a closed surface, which crosses
    /// each column an even number of times; outside its box, all of them on one side of
    /// a centre, so that no fine voxel outside every box is inside.
    fn block_boxes(
        &self,
        surface: &DigitalSurface,
        positions: &[DVec3],
        lattice: &Lattice,
        volume: &BlockVolume,
    ) -> Vec<([usize; 3], [usize; 3])> {
        // Blocks share no lattice corner, so each connected part of the surface lies in
        // one block: the one holding the solid voxel of any of its quads.
        let mut block_of_part: std::collections::HashMap<u32, usize> = Default::default();
        let mut bounds: std::collections::BTreeMap<usize, (DVec3, DVec3)> = Default::default();
        for &s in &self.boundary {
            let part = surface.surfel_component(voxreg_digisurf::SurfelId(s as u32));
            let block = *block_of_part.entry(part).or_insert_with(|| {
                let v = surface.surfels()[s].voxels()[0];
                volume
                    .blocks()
                    .iter()
                    .position(|b| {
                        let (lo, hi) = b.bounds();
                        (0..3).all(|a| v[a] >= lo[a] as i64 && v[a] < hi[a] as i64)
                    })
                    .unwrap_or(usize::MAX)
            });
            let e = bounds.entry(block).or_insert((DVec3::INFINITY, DVec3::NEG_INFINITY));
            for v in surface.surfels()[s].vertices {
                let p = positions[v.index()];
                e.0 = e.0.min(p);
                e.1 = e.1.max(p);
            }
        }
        bounds
            .into_values()
            .map(|(min, max)| {
                let lo = ((min - lattice.corner0) / lattice.h).floor() - 1.0;
                let hi = ((max - lattice.corner0) / lattice.h).ceil() + 1.0;
                let lo = [0, 1, 2].map(|a| lo[a].clamp(0.0, lattice.fine[a] as f64) as usize);
                let hi = [0, 1, 2].map(|a| hi[a].clamp(0.0, lattice.fine[a] as f64) as usize);
                (lo, hi)
            })
            .filter(|(lo, hi)| (0..3).all(|a| lo[a] < hi[a]))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn solid_count(v: &LabelVolume) -> usize {
        v.labels().iter().filter(|&&l| l != 0).count()
    }

    #[test]
    fn unmoved_surfaces_upscale_exactly() {
        // Without regularization, upscaling by K gives each voxel K^3 sub-voxels of its own
        // label: the parity fill and label transfer are exact, pinches and cavities included.
        let v = LabelVolume::from_fn([5, 4, 4], |[x, y, z]| match (x, y, z) {
            (1..=3, 1..=2, 1..=2) if (x, y, z) != (2, 1, 1) => 1 + (x as u32 % 2),
            (4, 3, 3) => 7,
            _ => 0,
        });
        let s = DigitalSurface::new(&v, &voxreg_digisurf::RegionMap::single_solid()).unwrap();
        for k in [1, 2, 3] {
            let fine = upscale(&s, &s.positions(), &v, &UpscaleParams { factor: k }).unwrap();
            assert_eq!(solid_count(&fine), solid_count(&v) * k * k * k, "K = {k}");
            for z in 0..fine.dims()[2] {
                for y in 0..fine.dims()[1] {
                    for x in 0..fine.dims()[0] {
                        let coarse = v.labels()[[x / k, y / k, z / k]];
                        assert_eq!(fine.labels()[[x, y, z]], coarse, "K = {k} at {x} {y} {z}");
                    }
                }
            }
            let c = fine.voxel_centre([0, 0, 0]);
            assert!((c - (v.origin() - 0.5 + 0.5 / k as f64)).length() < 1e-12);
        }
    }

    #[test]
    fn bad_input() {
        let v = LabelVolume::from_fn([3, 3, 3], |p| u32::from(p == [1, 1, 1]));
        let s = DigitalSurface::from_volume(&v).unwrap();
        assert!(upscale(&s, &s.positions(), &v, &UpscaleParams { factor: 0 }).is_err());
        assert!(upscale(&s, &s.positions()[1..], &v, &UpscaleParams::default()).is_err());
        let open = v.clone().with_background(None);
        assert!(upscale(&s, &s.positions(), &open, &UpscaleParams::default()).is_err());
    }
}
