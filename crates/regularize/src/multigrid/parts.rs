//! The pieces the other parts share: aggregations, `f32` blocks, and the rows of an
//! operator under construction.

use glam::{DVec3, Vec3A, Vec3Swizzles, Vec4, Vec4Swizzles};
use rayon::prelude::*;

use crate::stencil::CHUNK;

/// The aggregation of one level into the next: structure only.
#[derive(Clone, Debug)]
pub(super) struct Aggregation {
    /// For each node of the finer level, its aggregate (a node of the coarser level).
    pub(super) parent: Vec<u32>,
    /// Members of each aggregate: `members[offsets[a]..offsets[a + 1]]`.
    pub(super) offsets: Vec<u32>,
    pub(super) members: Vec<u32>,
}

impl Aggregation {
    pub(super) fn len(&self) -> usize {
        self.offsets.len() - 1
    }

    pub(super) fn members(&self, a: usize) -> &[u32] {
        &self.members[self.offsets[a] as usize..self.offsets[a + 1] as usize]
    }
}

/// How a cycle's `f32` 3-vector is stored: in `f32` ([`Vec3A`]), or in an `f64` vector
/// ([`DVec3`]) lent by the caller. `f32` to `f64` and back is exact, so the cycle's
/// numbers are the same either way.
pub(super) trait Stored: Copy + Send + Sync {
    fn get(self) -> Vec3A;
    fn put(v: Vec3A) -> Self;
}

impl Stored for Vec3A {
    #[inline(always)]
    fn get(self) -> Vec3A {
        self
    }

    #[inline(always)]
    fn put(v: Vec3A) -> Self {
        v
    }
}

impl Stored for DVec3 {
    #[inline(always)]
    fn get(self) -> Vec3A {
        self.as_vec3a()
    }

    #[inline(always)]
    fn put(v: Vec3A) -> Self {
        v.as_dvec3()
    }
}

pub(super) fn scale6(m: &[f64; 6], s: f64) -> [f64; 6] {
    m.map(|x| x * s)
}

/// The items of `items` in `buf` when it has their number (written in place, no new
/// memory to fault in), else collected anew.
pub(super) fn refill<T: Send>(mut buf: Vec<T>, items: impl IndexedParallelIterator<Item = T>) -> Vec<T> {
    if buf.len() == items.len() {
        buf.par_iter_mut().zip(items).for_each(|(b, x)| *b = x);
        buf
    } else {
        drop(buf);
        items.collect()
    }
}

/// A symmetric 3x3 block in `f32`, stored as `[xx, yy, xz, yz, zz, xy]`: 24 bytes, half
/// of three SIMD columns (the smoothers are streamed once per sweep, so their size is
/// their cost), in the order that lets [`block_mul`] read it as two overlapping 4-lane
/// loads.
pub(super) type Block = [f32; 6];

/// The block of the symmetric `m = [xx, yy, zz, xy, xz, yz]` ([`narrow`]ed).
pub(super) fn block(m: &[f64; 6]) -> Block {
    let [xx, yy, zz, xy, xz, yz] = narrow(m);
    [xx, yy, xz, yz, zz, xy]
}

/// `m` in `f32`, its entries below `f32::EPSILON^2` times the largest set to zero.
///
/// They are rounding residue (a voxel face's normal has components like `1e-17`, whose
/// products reach `1e-34`) and change no product beyond `f32` rounding, but their
/// products with the cycle's vectors fall below `f32::MIN_POSITIVE`, and subnormal
/// arithmetic is many times slower than normal arithmetic on common processors.
#[inline]
fn narrow<const N: usize>(m: &[f64; N]) -> [f32; N] {
    let cut = m.iter().fold(0.0f64, |a, x| a.max(x.abs())) * f64::from(f32::EPSILON * f32::EPSILON);
    m.map(|x| if x.abs() < cut { 0.0 } else { x as f32 })
}

/// `m v`: with `m = [a, d, c, e, f, b]` (that is `[xx, yy, xz, yz, zz, xy]`), the lanes
/// `[a x + b y, d y + b x, c x + e y] + [c, e, f] z`, from the loads `[a, d, c, e]` and
/// `[c, e, f, b]` and four shuffles. Each lane adds the same products in the same order
/// as the column sum `(col_0 x + col_1 y) + col_2 z`, so the result is that sum's to the
/// bit.
#[inline(always)]
pub(super) fn block_mul(m: &Block, v: Vec3A) -> Vec3A {
    let lo = Vec4::from_array([m[0], m[1], m[2], m[3]]);
    let hi = Vec4::from_array([m[2], m[3], m[4], m[5]]);
    Vec3A::from_vec4(lo * v.xyxx() + hi.wwyy() * v.yxyy() + hi * v.zzzz())
}

/// A general 3x3 block, its columns one after the other, in `f32` (36 bytes: no SIMD
/// padding).
pub(super) type Full = [f32; 9];

#[inline(always)]
pub(super) fn full_mul(m: &Full, v: Vec3A) -> Vec3A {
    Vec3A::new(m[0], m[1], m[2]) * v.x
        + Vec3A::new(m[3], m[4], m[5]) * v.y
        + Vec3A::new(m[6], m[7], m[8]) * v.z
}

/// The rows of an operator under construction, flat: sorted columns and blocks of `W`
/// numbers. For the whole operator (`W = 10`) each block is the sum of an alignment part
/// (a 3x3 block, column-major, entries `0..9`: positive semi-definite on the diagonal,
/// negative semi-definite off it) and a multiple of the identity (entry `9`: attachment
/// and fairness), kept apart so that the smoother's majorant needs no eigenvalues; for a
/// face's operator, see [`FACE`].
#[derive(Debug)]
pub(super) struct Rows<const W: usize = 10> {
    pub(super) offsets: Vec<usize>,
    pub(super) cols: Vec<u32>,
    /// Accumulated in `f64`, stored in `f32`: they only precondition. Kept in the parts
    /// they were built in (each a range of whole rows), never joined.
    pub(super) vals: Parts<[f32; W]>,
}

/// A sequence stored as the consecutive parts it was built in, each a range of whole
/// rows: joining them would copy the level's numbers into fresh memory, which the system
/// must fault in page by page.
#[derive(Debug, Default)]
pub(super) struct Parts<T> {
    pub(super) parts: Vec<Vec<T>>,
    /// Where each part starts in the sequence, and its length last.
    pub(super) starts: Vec<usize>,
}

impl<T> Parts<T> {
    fn new(parts: Vec<Vec<T>>) -> Self {
        let mut starts = Vec::with_capacity(parts.len() + 1);
        starts.push(0);
        for p in &parts {
            starts.push(starts.last().unwrap() + p.len());
        }
        Parts { parts, starts }
    }

    pub(super) fn len(&self) -> usize {
        *self.starts.last().unwrap_or(&0)
    }

    /// The part holding entry `k`.
    fn part_of(&self, k: usize) -> usize {
        self.starts.partition_point(|&s| s <= k) - 1
    }

    /// Entries `r`, which lie in one part (a row's).
    pub(super) fn slice(&self, r: std::ops::Range<usize>) -> &[T] {
        if r.is_empty() {
            return &[];
        }
        let p = self.part_of(r.start);
        let s = self.starts[p];
        &self.parts[p][r.start - s..r.end - s]
    }

    pub(super) fn iter(&self) -> impl Iterator<Item = &T> {
        self.parts.iter().flatten()
    }

    /// `out[k] = f(&self[k])` for every entry, in parallel part by part.
    pub(super) fn map_into<U: Send>(&self, out: &mut [U], f: impl Fn(&T) -> U + Sync)
    where
        T: Sync,
    {
        let mut pieces = Vec::with_capacity(self.parts.len());
        let mut rest = out;
        for p in &self.parts {
            let (here, tail) = rest.split_at_mut(p.len());
            pieces.push((p, here));
            rest = tail;
        }
        pieces.into_par_iter().for_each(|(p, out)| {
            out.par_chunks_mut(CHUNK).zip(p.par_chunks(CHUNK)).for_each(|(o, v)| {
                o.iter_mut().zip(v).for_each(|(o, v)| *o = f(v));
            })
        });
    }

    /// [`Parts::map_into`], each part freed once mapped (in parallel within a part).
    pub(super) fn map_into_freeing<U: Send>(self, out: &mut [U], f: impl Fn(&T) -> U + Sync)
    where
        T: Sync,
    {
        let mut rest = out;
        for p in self.parts {
            let (here, tail) = rest.split_at_mut(p.len());
            here.par_chunks_mut(CHUNK).zip(p.par_chunks(CHUNK)).for_each(|(o, v)| {
                o.iter_mut().zip(v).for_each(|(o, v)| *o = f(v));
            });
            rest = tail;
        }
    }

    /// `f(&self[k])` for every entry, in a new vector.
    pub(super) fn map<U: Send + Default + Clone>(&self, f: impl Fn(&T) -> U + Sync) -> Vec<U>
    where
        T: Sync,
    {
        let mut out = vec![U::default(); self.len()];
        self.map_into(&mut out, f);
        out
    }
}

impl<T: PartialEq> PartialEq for Parts<T> {
    fn eq(&self, other: &Self) -> bool {
        self.len() == other.len() && self.iter().eq(other.iter())
    }
}

impl<const W: usize> Rows<W> {
    pub(super) fn len(&self) -> usize {
        self.offsets.len() - 1
    }

    /// Rows `dirty` (ascending) computed anew by `f` (as [`Rows::build`] does, so to the
    /// bit), in place and in parallel; `false` if a row's columns differ (its pattern is
    /// not this one's: the rows are then partly rewritten, and the caller builds anew).
    pub(super) fn recompute(
        &mut self,
        dirty: &[usize],
        f: impl Fn(&mut Accumulator<W>, usize) + Sync,
    ) -> bool {
        let n = self.len();
        let Rows { offsets, cols, vals } = self;
        // Each dirty row's values, a slice of its own (in its part).
        let mut rows: Vec<(usize, &mut [[f32; W]])> = Vec::with_capacity(dirty.len());
        let mut dirty = dirty.iter().copied().peekable();
        for (p, part) in vals.parts.iter_mut().enumerate() {
            let (start, end) = (vals.starts[p], vals.starts[p + 1]);
            let (mut rest, mut at): (&mut [[f32; W]], usize) = (part, start);
            while let Some(&a) = dirty.peek() {
                if offsets[a] >= end && offsets[a + 1] > offsets[a] {
                    break;
                }
                dirty.next();
                debug_assert!(offsets[a] >= at, "dirty rows ascending");
                let (_, tail) = std::mem::take(&mut rest).split_at_mut(offsets[a] - at);
                let (row, tail) = tail.split_at_mut(offsets[a + 1] - offsets[a]);
                rows.push((a, row));
                (rest, at) = (tail, offsets[a + 1]);
            }
        }
        let (offsets, cols) = (&*offsets, &*cols);
        rows.into_par_iter()
            .map_init(
                || Accumulator { slot: vec![u32::MAX; n], row: Vec::with_capacity(64) },
                |acc, (a, out)| {
                    f(acc, a);
                    acc.flush_checked(&cols[offsets[a]..offsets[a + 1]], out)
                },
            )
            .all(|same| same)
    }

    pub(super) fn nnz(&self) -> usize {
        self.cols.len()
    }

    pub(super) fn bytes(&self) -> usize {
        8 * self.offsets.len() + (4 + 4 * W) * self.cols.len()
    }

    pub(super) fn row(&self, i: usize) -> impl Iterator<Item = (u32, [f64; W])> + '_ {
        let r = self.offsets[i]..self.offsets[i + 1];
        self.cols[r.clone()].iter().zip(self.vals.slice(r)).map(|(c, v)| (*c, v.map(f64::from)))
    }

    /// Builds `n` rows with `f(accumulator, row)`, columns in `0..cols`, in parallel
    /// chunks of rows (one marker array and one output buffer per chunk).
    pub(super) fn build(n: usize, cols: usize, f: impl Fn(&mut Accumulator<W>, usize) + Sync) -> Rows<W> {
        type Part<const W: usize> = (Vec<usize>, Vec<u32>, Vec<[f32; W]>);
        // A few parts per thread, each a large block that the level keeps (its numbers
        // are never joined): freed with the level, a large block goes back to the system,
        // where many small ones would stay in the allocator's heaps.
        let rows = n.div_ceil(4 * rayon::current_num_threads().max(1)).max(1024);
        // One marker array per worker, not per chunk of rows: `cols` entries each, so a
        // fresh one per chunk would cost time quadratic in the level's size.
        let parts: Vec<Part<W>> = (0..n.div_ceil(rows))
            .into_par_iter()
            .map_init(
                || Accumulator { slot: vec![u32::MAX; cols], row: Vec::with_capacity(64) },
                |acc, c| {
                    let mut part: Part<W> = (Vec::with_capacity(rows), Vec::new(), Vec::new());
                    for i in c * rows..((c + 1) * rows).min(n) {
                        f(acc, i);
                        part.0.push(acc.row.len());
                        acc.flush_into(&mut part.1, &mut part.2);
                    }
                    // Grown by doubling: at their size, since the numbers stay in the
                    // level and the columns are joined below.
                    part.1.shrink_to_fit();
                    part.2.shrink_to_fit();
                    part
                },
            )
            .collect();
        let total = parts.iter().map(|p| p.1.len()).sum();
        let mut offsets = Vec::with_capacity(n + 1);
        offsets.push(0);
        // The columns (4 bytes an entry) joined; the numbers stay in their parts.
        let mut all_cols = Vec::with_capacity(total);
        let mut vals = Vec::with_capacity(parts.len());
        for (lens, c, v) in parts {
            for l in lens {
                offsets.push(offsets.last().unwrap() + l);
            }
            all_cols.extend(c);
            vals.push(v);
        }
        Rows { offsets, cols: all_cols, vals: Parts::new(vals) }
    }
}

/// Row accumulator with a dense marker.
pub(super) struct Accumulator<const W: usize = 10> {
    slot: Vec<u32>,
    row: Vec<(u32, [f64; W])>,
}

impl<const W: usize> Accumulator<W> {
    #[inline]
    pub(super) fn entry(&mut self, col: u32) -> &mut [f64; W] {
        let s = &mut self.slot[col as usize];
        if *s == u32::MAX {
            *s = self.row.len() as u32;
            self.row.push((col, [0.0; W]));
        }
        &mut self.row[*s as usize].1
    }

    /// Writes the row, sorted by column, to `out` if its columns are `cols`; clears it.
    fn flush_checked(&mut self, cols: &[u32], out: &mut [[f32; W]]) -> bool {
        for (c, _) in &self.row {
            self.slot[*c as usize] = u32::MAX;
        }
        self.row.sort_unstable_by_key(|e| e.0);
        let same = self.row.len() == cols.len() && self.row.iter().zip(cols).all(|(e, c)| e.0 == *c);
        if same {
            for (o, e) in out.iter_mut().zip(&self.row) {
                *o = narrow(&e.1);
            }
        }
        self.row.clear();
        same
    }

    /// Appends the row, sorted by column, to `cols` and `vals`, and clears it.
    fn flush_into(&mut self, cols: &mut Vec<u32>, vals: &mut Vec<[f32; W]>) {
        for (c, _) in &self.row {
            self.slot[*c as usize] = u32::MAX;
        }
        self.row.sort_unstable_by_key(|e| e.0);
        cols.extend(self.row.iter().map(|e| e.0));
        vals.extend(self.row.iter().map(|e| narrow(&e.1)));
        self.row.clear();
    }
}

/// The numbers of a block of a face's operator `P^T D H D P` (`D` the 0/1 diagonal of the
/// face's free coordinates): entries `0..9`, the alignment part, a general 3x3 block
/// (column-major); `9..12`, the diagonal part (attachment and fairness, masked at both
/// ends: no longer a multiple of the identity); `12..18`, a symmetric `[xx, yy, zz, xy,
/// xz, yz]` block bounding what the alignment part adds to its row's majorant off the
/// diagonal: the sum of `b (D_i n)(D_i n)^T` over the fine couplings it aggregates, since
/// `[[0, -b u v^T], [-b v u^T, 0]] <= diag(b u u^T, b v v^T)`. (Masking breaks the sign
/// structure the whole operator's blocks have; this carries the bound instead.)
pub(super) const FACE: usize = 18;

#[cfg(test)]
mod block_tests {
    use super::*;

    /// The shuffled product is the column sum to the bit, on blocks with mixed signs and
    /// magnitudes.
    #[test]
    fn block_mul_is_the_column_sum_to_the_bit() {
        let mut rng = voxreg_testkit::Lcg::new(3);
        for _ in 0..1000 {
            let mut r = || (rng.next_f64() - 0.5) * 10f64.powi((rng.next_f64() * 12.0) as i32 - 6);
            let m = [r(), r(), r(), r(), r(), r()];
            let v = Vec3A::new(r() as f32, r() as f32, r() as f32);
            let [a, d, f, b, c, e] = m.map(|x| x as f32);
            let want = Vec3A::new(a, b, c) * v.x + Vec3A::new(b, d, e) * v.y + Vec3A::new(c, e, f) * v.z;
            let got = block_mul(&block(&m), v);
            assert_eq!(got.to_array().map(f32::to_bits), want.to_array().map(f32::to_bits), "{m:?} {v:?}");
        }
    }
}
