//! The operator `H` applied matrix-free, vertex-parallel, for the iterative solvers.
//!
//! `H x` gathers, for each vertex, over its incident faces (alignment) and its
//! barycenter neighbours (fairness, in two passes), so each application reads the mesh
//! connectivity and the normals once instead of the `~13` 3x3 blocks per vertex of the
//! assembled operator: about 3 times fewer bytes per product, and no assembly.

use std::sync::Arc;

use glam::DVec3;
use rayon::prelude::*;
use voxreg_digisurf::{DigitalSurface, SurfelId, VertexId};

use crate::energy::Energy;
use crate::error::RegularizeError;
use crate::weights::FairnessMask;

pub(crate) use crate::vecops::CHUNK;

/// A vertex's slot in an incident face: the face and the face's two vertices next to it.
#[derive(Copy, Clone, Debug, Default)]
pub(crate) struct FaceSlot {
    pub(crate) face: u32,
    pub(crate) prev: u32,
    pub(crate) next: u32,
}

/// The connectivity the matrix-free operator reads: built once per surface (and
/// fairness mask), reused across weights and normals.
#[derive(Clone, Debug)]
pub(crate) struct Stencil {
    face_offsets: Vec<u32>,
    face_slots: Vec<FaceSlot>,
    fair: FairNeighbours,
}

/// Every vertex's barycenter neighbours (all vertices, rim ones included: the mask, not
/// the rim, decides who is in whose barycenter).
#[derive(Clone, Debug)]
pub(crate) struct FairNeighbours {
    offsets: Vec<u32>,
    nbrs: Vec<u32>,
}

impl FairNeighbours {
    /// The neighbours of every vertex of `surface` that the fairness `mask` (if any) keeps.
    pub(crate) fn new(
        surface: &DigitalSurface,
        mask: Option<&FairnessMask>,
    ) -> Result<Self, RegularizeError> {
        let n = surface.num_vertices();
        let vid = |v: usize| VertexId(v as u32);
        let kept = |v: usize| {
            let all = surface.vertex_neighbours(vid(v)).iter().enumerate();
            all.filter(move |&(k, _)| mask.is_none_or(|m| m.keeps(vid(v), k))).map(|(_, w)| w.0)
        };
        let offsets = offsets(n, |v| kept(v).count())?;
        let nbrs = fill(&offsets, |v, out: &mut [u32]| {
            for (o, w) in out.iter_mut().zip(kept(v)) {
                *o = w;
            }
        });
        Ok(FairNeighbours { offsets, nbrs })
    }

    /// Number of vertices.
    pub(crate) fn len(&self) -> usize {
        self.offsets.len() - 1
    }

    /// The barycenter neighbours of `v`.
    #[inline(always)]
    pub(crate) fn of(&self, v: usize) -> &[u32] {
        &self.nbrs[self.offsets[v] as usize..self.offsets[v + 1] as usize]
    }

    /// Bytes held.
    pub(crate) fn bytes(&self) -> usize {
        4 * (self.offsets.len() + self.nbrs.len())
    }
}

/// The energy's operator `H` as the iterative solvers apply it, matrix-free: the
/// connectivity it reads (the faces around each vertex, the barycentre neighbours), the
/// vertices' lattice corners (for the multigrid hierarchy) and the voxel spacing (the unit
/// of tolerances and boxes). Built once per surface; each solve takes its numbers
/// (weights, normals, targets) from an [`Energy`] on the same surface.
#[derive(Clone, Debug)]
pub struct MatrixFreeOperator {
    pub(crate) stencil: Stencil,
    pub(crate) spacing: glam::DVec3,
    pub(crate) build_seconds: f64,
    /// The vertices' lattice corners, for the multigrid hierarchy (dropped once it is
    /// built).
    pub(crate) corners: Vec<[u32; 3]>,
}

impl MatrixFreeOperator {
    /// The operator of energies on `surface`.
    pub fn new(surface: &DigitalSurface) -> Result<Self, RegularizeError> {
        let t = std::time::Instant::now();
        let stencil = Stencil::new(surface, None)?;
        Ok(MatrixFreeOperator {
            stencil,
            spacing: surface.spacing(),
            build_seconds: t.elapsed().as_secs_f64(),
            corners: lattice_corners(surface),
        })
    }

    /// Number of vertices (unknowns are three per vertex).
    pub fn num_vertices(&self) -> usize {
        self.stencil.len()
    }
}

/// Per-solve numbers: the weights and the normals of one energy, laid out for the
/// operator.
#[derive(Clone, Debug)]
pub(crate) struct Coefficients<'a> {
    pub(crate) normals: &'a [DVec3],
    /// Per vertex, `alpha_i` (or one value for all).
    pub(crate) alpha: PerItem<'a>,
    /// Per face, `beta_f`.
    pub(crate) beta: PerItem<'a>,
    /// Per vertex, `gamma_i / |S_i|`, or 0 without fairness term (shared with the
    /// multigrid cycle's fine level, which reads it in `f32`).
    pub(crate) fair: Arc<[f64]>,
    /// Per face, `sqrt(beta_f) n_f`: the product reads one vector per face slot instead
    /// of each face's normal and weight and a square root. Kept per face, not per slot
    /// (a quad has four), for a quarter of the bytes; shared like `fair`.
    pub(crate) face_normals: Arc<[DVec3]>,
}

/// One value for all items, or a global weight times each item's multiplier (the
/// energy's [`Weights`](crate::Weights), read where they are rather than copied: the same
/// product as [`Energy::alpha_at`] and [`Energy::beta_at`]).
#[derive(Clone, Copy, Debug)]
pub(crate) enum PerItem<'a> {
    Uniform(f64),
    Scaled(f64, &'a [f64]),
}

impl PerItem<'_> {
    #[inline(always)]
    pub(crate) fn get(&self, i: usize) -> f64 {
        match self {
            PerItem::Uniform(x) => *x,
            PerItem::Scaled(s, w) => *s * w[i],
        }
    }
}

/// The lattice corner of each vertex of `surface` (what the multigrid aggregates by).
pub(crate) fn lattice_corners(surface: &DigitalSurface) -> Vec<[u32; 3]> {
    (0..surface.num_vertices()).into_par_iter().map(|v| surface.vertex_corner(VertexId(v as u32))).collect()
}

/// Prefix sums of `len(v)` for `v` in `0..n`, as `u32` offsets.
fn offsets(n: usize, len: impl Fn(usize) -> usize + Sync) -> Result<Vec<u32>, RegularizeError> {
    let lens: Vec<u32> = (0..n).into_par_iter().map(|v| len(v) as u32).collect();
    let mut out = Vec::with_capacity(n + 1);
    let mut total = 0u64;
    out.push(0);
    for l in lens {
        total += u64::from(l);
        out.push(
            u32::try_from(total).map_err(|_| RegularizeError::OutOfMemory("more than 2^32 slots".into()))?,
        );
    }
    Ok(out)
}

/// The two vertices next to vertex `v` in the quad of surfel `f` (previous, next in the
/// quad's order).
pub(crate) fn corner_neighbours(surface: &DigitalSurface, f: SurfelId, v: usize) -> [u32; 2] {
    let quad = surface.surfel(f).vertices;
    let i = quad.iter().position(|w| w.index() == v).unwrap_or(0);
    [quad[(i + 3) % 4].0, quad[(i + 1) % 4].0]
}

/// A flat array with `offsets`, each vertex's slice filled by `f(v, slice)`, in parallel.
pub(crate) fn fill<T: Copy + Default + Send>(offsets: &[u32], f: impl Fn(usize, &mut [T]) + Sync) -> Vec<T> {
    let n = offsets.len() - 1;
    let mut out = vec![T::default(); offsets[n] as usize];
    let mut chunks = Vec::with_capacity(n.div_ceil(CHUNK));
    let mut rest: &mut [T] = &mut out;
    for start in (0..n).step_by(CHUNK) {
        let end = (start + CHUNK).min(n);
        let (head, tail) = rest.split_at_mut((offsets[end] - offsets[start]) as usize);
        chunks.push((start, end, head));
        rest = tail;
    }
    chunks.into_par_iter().for_each(|(start, end, chunk)| {
        let base = offsets[start] as usize;
        for v in start..end {
            f(v, &mut chunk[offsets[v] as usize - base..offsets[v + 1] as usize - base]);
        }
    });
    out
}

impl Stencil {
    /// The connectivity of `surface`, with the fairness `mask` if any.
    pub(crate) fn new(
        surface: &DigitalSurface,
        mask: Option<&FairnessMask>,
    ) -> Result<Self, RegularizeError> {
        // A vertex's slots follow the surface's own vertex-surfel lists.
        let lists = surface.vertex_surfel_lists();
        let face_offsets = lists.offsets().to_vec();
        let face_slots = fill(&face_offsets, |v, out: &mut [FaceSlot]| {
            for (slot, f) in out.iter_mut().zip(lists.get(v)) {
                let [prev, next] = corner_neighbours(surface, *f, v);
                *slot = FaceSlot { face: f.0, prev, next };
            }
        });
        Ok(Stencil { face_offsets, face_slots, fair: FairNeighbours::new(surface, mask)? })
    }

    /// Number of vertices.
    pub(crate) fn len(&self) -> usize {
        self.face_offsets.len() - 1
    }

    #[inline(always)]
    pub(crate) fn faces(&self, v: usize) -> &[FaceSlot] {
        &self.face_slots[self.face_offsets[v] as usize..self.face_offsets[v + 1] as usize]
    }

    /// The range of vertex `v`'s slots in [`Stencil::face_slots`].
    #[inline(always)]
    pub(crate) fn face_range(&self, v: usize) -> std::ops::Range<usize> {
        self.face_offsets[v] as usize..self.face_offsets[v + 1] as usize
    }

    /// Every vertex's face slots, vertex after vertex.
    pub(crate) fn face_slots(&self) -> &[FaceSlot] {
        &self.face_slots
    }

    #[inline(always)]
    pub(crate) fn fair_neighbours(&self, v: usize) -> &[u32] {
        self.fair.of(v)
    }

    /// Bytes of connectivity read by one product (for the bandwidth model).
    pub(crate) fn bytes(&self) -> usize {
        4 * self.face_offsets.len()
            + self.fair.bytes()
            + std::mem::size_of::<FaceSlot>() * self.face_slots.len()
    }

    /// The numbers of `energy` (which must be on this stencil's surface and mask).
    pub(crate) fn coefficients<'a>(&self, energy: &Energy<'a>) -> Coefficients<'a> {
        let n = self.len();
        let weights = energy.weights();
        let alpha = match weights.and_then(|w| w.alpha.as_ref()) {
            Some(w) => PerItem::Scaled(energy.params().alpha, w),
            None => PerItem::Uniform(energy.params().alpha),
        };
        let beta = match weights.and_then(|w| w.beta.as_ref()) {
            Some(w) => PerItem::Scaled(energy.params().beta, w),
            None => PerItem::Uniform(energy.params().beta),
        };
        let surface = energy.surface();
        let fair: Vec<f64> = (0..n)
            .into_par_iter()
            .map(|v| {
                let deg = self.fair_neighbours(v).len();
                if deg == 0 || surface.is_boundary_vertex(VertexId(v as u32)) {
                    0.0
                } else {
                    energy.gamma_at(v) / deg as f64
                }
            })
            .collect();
        let normals = energy.normals();
        let face_normals: Vec<DVec3> =
            normals.par_iter().enumerate().map(|(f, n)| beta.get(f).sqrt() * *n).collect();
        Coefficients { normals, alpha, beta, fair: Arc::from(fair), face_normals: Arc::from(face_normals) }
    }

    /// `y = H x`, or `y = (H - diag(alpha)) x` when `with_alpha` is false (the part of
    /// `H` that only sees differences of positions: exact on absolute positions).
    /// `t` is scratch of the same length.
    pub(crate) fn apply(
        &self,
        c: &Coefficients<'_>,
        x: &[DVec3],
        y: &mut [DVec3],
        t: &mut [DVec3],
        with_alpha: bool,
    ) {
        self.product(c, x, y, t, with_alpha, None);
    }

    /// `y = H x` as [`Stencil::apply`], returning `x . y` computed in the same pass.
    pub(crate) fn apply_dot(
        &self,
        c: &Coefficients<'_>,
        x: &[DVec3],
        y: &mut [DVec3],
        t: &mut [DVec3],
    ) -> f64 {
        self.product(c, x, y, t, true, None)
    }

    /// The residual `y = b - H x` in the same two passes (`t` is scratch).
    pub(crate) fn residual(
        &self,
        c: &Coefficients<'_>,
        x: &[DVec3],
        b: &[DVec3],
        y: &mut [DVec3],
        t: &mut [DVec3],
    ) {
        self.product(c, x, y, t, true, Some(b));
    }

    fn product(
        &self,
        c: &Coefficients<'_>,
        x: &[DVec3],
        y: &mut [DVec3],
        t: &mut [DVec3],
        with_alpha: bool,
        b: Option<&[DVec3]>,
    ) -> f64 {
        // Pass 1: t_i = gamma_i / |S_i| (x_i - b_i).
        t.par_chunks_mut(CHUNK).enumerate().for_each(|(k, out)| {
            let base = k * CHUNK;
            for (o, ti) in out.iter_mut().enumerate() {
                let i = base + o;
                let ci = c.fair[i];
                *ti = if ci == 0.0 {
                    DVec3::ZERO
                } else {
                    let nb = self.fair_neighbours(i);
                    let mut sum = DVec3::ZERO;
                    for &j in nb {
                        sum += x[j as usize];
                    }
                    ci * (x[i] - sum / nb.len() as f64)
                };
            }
        });
        // Pass 2: attachment, alignment, and (I - B)^T of the fairness residuals.
        // Returns `x . y`, summed per chunk (free: `y_i` is in registers).
        let t = &*t;
        crate::vecops::ordered(y.par_chunks_mut(CHUNK).enumerate().map(|(k, out)| {
            let base = k * CHUNK;
            let mut xy = 0.0;
            for (o, yi) in out.iter_mut().enumerate() {
                let i = base + o;
                let xi = x[i];
                let mut acc = if with_alpha { c.alpha.get(i) * xi } else { DVec3::ZERO };
                let (start, end) = (self.face_offsets[i] as usize, self.face_offsets[i + 1] as usize);
                for s in &self.face_slots[start..end] {
                    let m = c.face_normals[s.face as usize];
                    let d = (2.0 * xi - x[s.prev as usize] - x[s.next as usize]).dot(m);
                    acc += d * m;
                }
                let nb = self.fair_neighbours(i);
                let mut sum = DVec3::ZERO;
                for &j in nb {
                    sum += t[j as usize];
                }
                let hx = acc + (nb.len() as f64) * t[i] - sum;
                *yi = match b {
                    Some(b) => b[i] - hx,
                    None => hx,
                };
                xy += xi.dot(*yi);
            }
            xy
        }))
    }

    /// The 3x3 diagonal blocks of `H`, as symmetric `[xx, yy, zz, xy, xz, yz]`.
    pub(crate) fn diagonal(&self, c: &Coefficients<'_>) -> Vec<[f64; 6]> {
        (0..self.len())
            .into_par_iter()
            .map(|i| {
                let a = c.alpha.get(i);
                // Fairness: own row (gamma_i = |S_i| c_i) and rows of i's neighbours.
                let nb = self.fair_neighbours(i);
                let mut fair = c.fair[i] * nb.len() as f64;
                for &j in nb {
                    let j = j as usize;
                    let dj = self.fair_neighbours(j).len();
                    if dj > 0 {
                        fair += c.fair[j] / dj as f64;
                    }
                }
                let mut d = [a + fair, a + fair, a + fair, 0.0, 0.0, 0.0];
                self.add_alignment_block(c, i, 2.0, &mut d);
                d
            })
            .collect()
    }

    /// Adds `scale beta_f n_f n_f^T` for each face `f` around vertex `v` to the symmetric
    /// block `d` (`[xx, yy, zz, xy, xz, yz]`): the alignment term's part of a diagonal
    /// block (`scale` 2) or of its majorant (`scale` 4).
    pub(crate) fn add_alignment_block(&self, c: &Coefficients<'_>, v: usize, scale: f64, d: &mut [f64; 6]) {
        for s in self.faces(v) {
            let n = c.normals[s.face as usize];
            let b = scale * c.beta.get(s.face as usize);
            d[0] += b * n.x * n.x;
            d[1] += b * n.y * n.y;
            d[2] += b * n.z * n.z;
            d[3] += b * n.x * n.y;
            d[4] += b * n.x * n.z;
            d[5] += b * n.y * n.z;
        }
    }
}

#[cfg(test)]
mod tests {
    use voxreg_digisurf::LabelVolume;
    use voxreg_normals::NormalField;

    use super::*;
    use crate::assemble::{Operator, OperatorPattern};
    use crate::energy::EnergyParams;
    use crate::weights::Weights;

    /// Three labels, no background (open interfaces, junctions, rims), random normals
    /// and weights, and a fairness mask: the matrix-free product, its diagonal blocks and
    /// the assembled operator agree.
    #[test]
    fn matrix_free_product_matches_the_assembled_operator() {
        let volume = LabelVolume::from_fn([5, 4, 4], |[x, y, z]| {
            if x + z / 2 < 2 {
                1
            } else if y < 2 {
                2
            } else {
                3
            }
        })
        .with_background(None);
        let s = DigitalSurface::from_volume(&volume).unwrap();
        let mut rng = voxreg_testkit::Lcg::new(7);
        let mut rnd = || rng.next_f64();
        let normals = NormalField::new(
            s.surfels()
                .iter()
                .map(|f| f.normal() + 0.8 * DVec3::new(rnd() - 0.5, rnd() - 0.5, rnd() - 0.5))
                .collect(),
        );
        let input = s.positions();
        let cut: Vec<bool> = (0..s.num_edges()).map(|_| rnd() < 0.2).collect();
        let weights = Weights {
            alpha: Some((0..s.num_vertices()).map(|_| 0.5 + rnd()).collect()),
            beta: Some((0..s.num_surfels()).map(|_| rnd()).collect()),
            gamma: Some((0..s.num_vertices()).map(|_| rnd()).collect()),
            fairness: Some(FairnessMask::from_cut_edges(&s, &cut).unwrap()),
        };
        let params = EnergyParams { alpha: 0.01, beta: 1.0, gamma: 0.3 };
        for w in [None, Some(&weights)] {
            let mut energy = Energy::new(&s, &normals, &input, params).unwrap();
            if let Some(w) = w {
                energy = energy.with_weights(w).unwrap();
            }
            let op = Operator::assemble(&OperatorPattern::new(&s).unwrap(), &energy);
            let stencil = Stencil::new(&s, w.and_then(|w| w.fairness.as_ref())).unwrap();
            let c = stencil.coefficients(&energy);
            let x: Vec<DVec3> = (0..s.num_vertices()).map(|_| DVec3::new(rnd(), rnd(), rnd())).collect();
            let flat: Vec<f64> = x.iter().flat_map(|v| v.to_array()).collect();
            let want = op.apply(&flat);
            let (mut y, mut t) = (vec![DVec3::ZERO; x.len()], vec![DVec3::ZERO; x.len()]);
            stencil.apply(&c, &x, &mut y, &mut t, true);
            for (i, yi) in y.iter().enumerate() {
                for k in 0..3 {
                    assert!(
                        (yi[k] - want[3 * i + k]).abs() < 1e-12,
                        "vertex {i}: {} vs {}",
                        yi[k],
                        want[3 * i + k]
                    );
                }
            }
            // Without alpha: only differences, so a translation is in its kernel.
            stencil.apply(&c, &vec![DVec3::new(3.0, -2.0, 5.0); x.len()], &mut y, &mut t, false);
            assert!(y.iter().all(|v| v.length() < 1e-12));
            let dense = op.matrix().to_dense();
            for (i, d) in stencil.diagonal(&c).iter().enumerate() {
                let m = |r: usize, c: usize| dense[(3 * i + r, 3 * i + c)];
                let want = [m(0, 0), m(1, 1), m(2, 2), m(0, 1), m(0, 2), m(1, 2)];
                for k in 0..6 {
                    assert!((d[k] - want[k]).abs() < 1e-12, "diagonal block {i}: {d:?} vs {want:?}");
                }
            }
        }
    }
}
