//! The V-cycle itself: one energy's preconditioner and its application, on the whole
//! operator or restricted to a face.

use std::sync::Arc;

use glam::{DVec3, Vec3A};
use rayon::prelude::*;

use super::coarse::{Coarsest, Level, Work, WorkMut};
use super::fine::{fine_majorant, inverse_blocks, masked, FineNumbers};
use super::parts::{block_mul, Aggregation, Block, Rows, Stored, FACE};
use crate::stencil::{Coefficients, Stencil, CHUNK};

/// The coarse levels of a face's operator ([`Vcycle::set_face`]).
#[derive(Debug)]
pub(super) struct FaceLevels {
    pub(super) levels: Vec<Level>,
    pub(super) coarsest: Option<Coarsest>,
    /// Every coarse level's rows (the first coarse level's first), and the face they
    /// were built for, to update them for the next face
    /// ([`Vcycle::updated_face_hierarchy`]).
    pub(super) rows: Vec<Rows<FACE>>,
    pub(super) face: Vec<Vec3A>,
}

/// One energy's multigrid preconditioner: `z = V(r)`.
#[derive(Debug)]
pub(crate) struct Vcycle {
    pub(super) fine: FineNumbers,
    pub(super) fine_smoother: Vec<Block>,
    /// The smoother of the face operator ([`Vcycle::set_face`]).
    pub(super) face_smoother: Vec<Block>,
    /// The face operator's own coarse levels ([`Vcycle::set_face`]).
    pub(super) face_levels: Option<FaceLevels>,
    /// The fine majorant's blocks, for the face smoothers: computed by the first
    /// [`Vcycle::set_face`] (48 bytes a vertex that unconstrained solves never hold).
    pub(super) majorant: Vec<[f64; 6]>,
    pub(super) damping: f64,
    pub(super) levels: Vec<Level>,
    pub(super) aggregations: Arc<[Aggregation]>,
    pub(super) coarsest: Option<Coarsest>,
    pub(super) works: Vec<Work>,
    pub(super) steps: usize,
    pub(super) coarse_steps: usize,
    /// Seconds spent factoring the coarsest level.
    pub(crate) factor_seconds: f64,
}

/// `x = m r` (or `x += m r` with `add`), masked by `face` when given.
fn smooth<R: Stored, X: Stored>(m: &[Block], r: &[R], x: &mut [X], add: bool, face: Option<&[Vec3A]>) {
    x.par_chunks_mut(CHUNK).zip(r.par_chunks(CHUNK)).zip(m.par_chunks(CHUNK)).enumerate().for_each(
        |(k, ((x, r), m))| {
            for i in 0..x.len() {
                let d = block_mul(&m[i], r[i].get());
                x[i] = X::put(masked(face, k * CHUNK + i, if add { x[i].get() + d } else { d }));
            }
        },
    );
}

fn restrict<R: Stored, C: Stored>(agg: &Aggregation, fine: &[R], coarse: &mut [C]) {
    coarse.par_chunks_mut(CHUNK).enumerate().for_each(|(k, out)| {
        for (o, c) in out.iter_mut().enumerate() {
            *c = C::put(agg.members(k * CHUNK + o).iter().map(|&i| fine[i as usize].get()).sum());
        }
    });
}

/// `fine += P coarse`, masked by `face` when given.
fn prolong_add<C: Stored, F: Stored>(parent: &[u32], coarse: &[C], fine: &mut [F], face: Option<&[Vec3A]>) {
    fine.par_chunks_mut(CHUNK).zip(parent.par_chunks(CHUNK)).enumerate().for_each(|(k, (f, p))| {
        for i in 0..f.len() {
            f[i] = F::put(masked(face, k * CHUNK + i, f[i].get() + coarse[p[i] as usize].get()));
        }
    });
}

/// Slices of the given vectors, handed out in turn: each from the first vector with room
/// left for it.
struct Lender<'a, T> {
    rooms: Vec<&'a mut [T]>,
}

impl<'a, T> Lender<'a, T> {
    /// Whether slices of lengths `lens`, in order, fit in rooms of lengths `rooms`.
    fn fits(lens: impl Iterator<Item = usize>, mut rooms: Vec<usize>) -> bool {
        lens.into_iter().all(|n| match rooms.iter_mut().find(|r| **r >= n) {
            Some(r) => {
                *r -= n;
                true
            }
            None => false,
        })
    }

    fn take(&mut self, n: usize) -> &'a mut [T] {
        let k = self.rooms.iter().position(|r| r.len() >= n).expect("checked by `Lender::fits`");
        let (here, rest) = std::mem::take(&mut self.rooms[k]).split_at_mut(n);
        self.rooms[k] = rest;
        here
    }
}

impl Vcycle {
    /// Bytes of the coarse levels, smoothers and work vectors.
    pub(crate) fn memory_bytes(&self) -> usize {
        let agg: usize =
            self.aggregations.iter().map(|a| 4 * (a.parent.len() + a.members.len() + a.offsets.len())).sum();
        let levels: usize = self.levels.iter().map(|l| l.matrix.bytes() + 24 * l.n).sum();
        let works: usize = self.works.iter().map(|w| 16 * (w.r.len() + w.x.len() + w.t.len())).sum();
        let coarsest = self.coarsest.as_ref().map_or(0, |c| 8 * c.factor.len());
        let face = self.face_levels.as_ref().map_or(0, |f| {
            let levels: usize = f.levels.iter().map(|l| l.matrix.bytes() + 24 * l.n).sum();
            levels
                + f.coarsest.as_ref().map_or(0, |c| 8 * c.factor.len())
                + f.rows.iter().map(Rows::bytes).sum::<usize>()
                + 16 * f.face.len()
        });
        face + 24 * (self.fine_smoother.len() + self.face_smoother.len())
            + 48 * self.majorant.len()
            + self.fine.own_bytes()
            + agg
            + levels
            + works
            + coarsest
    }

    /// Puts the fine level on the operator of `coef` (its numbers, majorant and smoother)
    /// and keeps the coarse levels, which stay those of the energy the cycle was built
    /// for: the cycle of a quick start ([`crate::iterative::Setup::prepare`]), O(n) instead
    /// of a setup. Still a fixed symmetric positive definite preconditioner of the new
    /// operator `A`: with the smoother `S = damping M^-1`, `M >= A` and damping below 2,
    /// the cycle is `2S - SAS + (I - SA) P C P^T (I - AS)`, where `2S - SAS` is positive
    /// definite and `C` (the old levels' own symmetric cycle) positive semi-definite; how
    /// close the old levels are to the new operator's only sets the rate.
    pub(crate) fn refresh_fine(&mut self, stencil: &Stencil, coef: &Coefficients<'_>) {
        self.fine_smoother = inverse_blocks(
            &fine_majorant(stencil, coef),
            self.damping,
            std::mem::take(&mut self.fine_smoother),
        );
        self.fine = FineNumbers::new(stencil, coef, std::mem::take(&mut self.fine));
        self.forget_face();
    }

    /// Lets go of the numbers the fine level shares with its solve's coefficients: a kept
    /// cycle, before the next solve's coefficients are made (it gets theirs).
    pub(crate) fn release_shared(&mut self) {
        self.fine.release_shared();
    }

    /// Drops the face's levels, smoother and majorant ([`Vcycle::set_face`]): once the
    /// active-set rounds are over, or the operator's numbers changed.
    pub(crate) fn forget_face(&mut self) {
        self.face_levels = None;
        self.face_smoother = Vec::new();
        self.majorant = Vec::new();
    }

    /// Bytes moved by one cycle (`connectivity`: bytes of the stencil's connectivity).
    pub(crate) fn traffic(&self, connectivity: usize, n: usize) -> usize {
        let (s, cs) = (self.steps, self.coarse_steps);
        // Fine, in f32: products (connectivity, numbers, 5 vectors), smoothing (r, M, z),
        // residual updates, conversions in and out, restriction, prolongation.
        let product = connectivity + self.fine.bytes() + 5 * 16 * n;
        let fine = 2 * s * product + 2 * s * 56 * n + 2 * s * 48 * n + 2 * 40 * n + 40 * n;
        let coarse: usize =
            self.levels.iter().map(|l| 2 * cs * (l.matrix.bytes() + 3 * 16 * l.n) + 10 * 16 * l.n).sum();
        let coarsest = self.coarsest.as_ref().map_or(0, |c| 2 * 8 * c.factor.len());
        fine + coarse + coarsest
    }

    /// `z = V(r)`: one symmetric V-cycle, in `f32`.
    pub(crate) fn apply(&mut self, stencil: &Stencil, r: &[DVec3], z: &mut [DVec3]) {
        self.cycle(stencil, r, z, None, None);
    }

    /// [`Vcycle::apply`] with the fine level's residual kept in `z` (until the output
    /// replaces it) and its product's scratch in `spare`, a vector of the caller's that
    /// is free during the cycle (the conjugate gradient's `H p`): the same numbers, and
    /// two `f32` vectors fewer held at the solve's peak.
    pub(crate) fn apply_in(&mut self, stencil: &Stencil, r: &[DVec3], z: &mut [DVec3], spare: &mut [DVec3]) {
        self.cycle(stencil, r, z, None, Some(spare));
    }

    /// [`Vcycle::apply`] for the operator restricted to a face (the coordinates where
    /// `face` is 1; it is 0 on the others, held fixed): every fine-level smoothing,
    /// residual, restriction and prolongation is masked, so the fine level smooths the
    /// face's own operator `D H D` (`D = diag(face)`) and the coarse correction only moves
    /// free coordinates. Symmetric positive definite on the face, like the V-cycle; a much
    /// better preconditioner there than the whole operator's cycle masked afterwards,
    /// whose smoother moves held coordinates that the mask then discards.
    pub(crate) fn apply_on_face(
        &mut self,
        stencil: &Stencil,
        r: &[DVec3],
        z: &mut [DVec3],
        face: Option<&[Vec3A]>,
    ) {
        self.cycle(stencil, r, z, face, None);
    }

    /// The cycle, on `face` where given; the fine level's residual and scratch in `z` and
    /// `spare` where given, else in the cycle's own vectors (made at their first use).
    fn cycle(
        &mut self,
        stencil: &Stencil,
        r: &[DVec3],
        z: &mut [DVec3],
        face: Option<&[Vec3A]>,
        spare: Option<&mut [DVec3]>,
    ) {
        let mut works = std::mem::take(&mut self.works);
        let (fine, rest) = works.split_at_mut(1);
        let w = &mut fine[0];
        let face_smoother = std::mem::take(&mut self.face_smoother);
        let smoother = if face.is_some() && face_smoother.len() == w.x.len() {
            &face_smoother
        } else {
            &self.fine_smoother
        };
        // Fine level: the right-hand side in `f32`, read from `r` where used (not stored),
        // and the pre-smoothing from zero, then the residual restricted.
        let b = |i: usize| masked(face, i, r[i].as_vec3a());
        w.x.par_chunks_mut(CHUNK).zip(smoother.par_chunks(CHUNK)).enumerate().for_each(|(k, (x, m))| {
            for i in 0..x.len() {
                let j = k * CHUNK + i;
                x[i] = masked(face, j, block_mul(&m[i], b(j)));
            }
        });
        if self.levels.is_empty() {
            z.par_chunks_mut(CHUNK).zip(w.x.par_chunks(CHUNK)).for_each(|(z, x)| {
                for (z, x) in z.iter_mut().zip(x) {
                    *z = x.as_dvec3();
                }
            });
        } else {
            let Work { x, r: own_r, t: own_t } = w;
            // The last post-smoothing step and the output in `f64`, in the residual's pass.
            match spare {
                Some(t) if t.len() == x.len() => {
                    let correct = |res: &mut [DVec3], t: &mut [DVec3], x: &mut [Vec3A]| {
                        if self.lent_fits(x.len()) {
                            self.lent_correction(res, t, x, face);
                        } else {
                            self.own_correction(&*res, x, rest, face);
                        }
                    };
                    self.fine_correction(stencil, &b, smoother, x, &mut *z, &mut *t, face, correct);
                    let x = &*x;
                    let out = |i: usize, res: Vec3A| {
                        masked(face, i, x[i] + block_mul(&smoother[i], res)).as_dvec3()
                    };
                    self.fine.residual_map(stencil, x, &b, z, t, face, out);
                }
                _ => {
                    if own_r.len() != x.len() {
                        *own_r = vec![Vec3A::ZERO; x.len()];
                        *own_t = vec![Vec3A::ZERO; x.len()];
                    }
                    let correct = |res: &mut [Vec3A], _: &mut [Vec3A], x: &mut [Vec3A]| {
                        self.own_correction(&*res, x, rest, face)
                    };
                    self.fine_correction(
                        stencil,
                        &b,
                        smoother,
                        x,
                        own_r.as_mut_slice(),
                        own_t.as_mut_slice(),
                        face,
                        correct,
                    );
                    let x = &*x;
                    let out = |i: usize, res: Vec3A| {
                        masked(face, i, x[i] + block_mul(&smoother[i], res)).as_dvec3()
                    };
                    self.fine.residual_map(stencil, x, &b, z, own_t.as_mut_slice(), face, out);
                }
            }
        }
        self.face_smoother = face_smoother;
        self.works = works;
    }

    /// The fine level's part of the cycle between the pre-smoothing and the last
    /// post-smoothing step: residual, coarse correction (`correct`, given the residual,
    /// the scratch and `x`), and the other smoothing steps, on `x`, with the residual in
    /// `res` and the product's scratch in `t`.
    #[allow(clippy::too_many_arguments)]
    fn fine_correction<R: Stored, T: Stored>(
        &self,
        stencil: &Stencil,
        b: &(impl Fn(usize) -> Vec3A + Sync),
        smoother: &[Block],
        x: &mut [Vec3A],
        res: &mut [R],
        t: &mut [T],
        face: Option<&[Vec3A]>,
        mut correct: impl FnMut(&mut [R], &mut [T], &mut [Vec3A]),
    ) {
        let steps = self.steps;
        for s in 0..steps {
            self.fine.residual_map(stencil, x, b, res, t, face, |_, r| R::put(r));
            if s + 1 < steps {
                smooth(smoother, res, x, true, face);
            }
        }
        correct(&mut *res, &mut *t, &mut *x);
        for _ in 1..steps {
            self.fine.residual_map(stencil, x, b, res, t, face, |_, r| R::put(r));
            smooth(smoother, res, x, true, face);
        }
    }

    /// The coarse levels of the cycle on `face` where given (its own levels where set).
    fn coarse_of(&self, face: Option<&[Vec3A]>) -> (&[Level], Option<&Coarsest>) {
        match (face, &self.face_levels) {
            (Some(_), Some(f)) => (&f.levels, f.coarsest.as_ref()),
            _ => (&self.levels, self.coarsest.as_ref()),
        }
    }

    /// `x += P V(P^T res)` in the cycle's own coarse work vectors (made at their first use).
    fn own_correction<R: Stored>(
        &self,
        res: &[R],
        x: &mut [Vec3A],
        rest: &mut [Work],
        face: Option<&[Vec3A]>,
    ) {
        for (w, level) in rest.iter_mut().zip(&self.levels) {
            if w.x.len() != level.n {
                *w = Work {
                    r: vec![Vec3A::ZERO; level.n],
                    x: vec![Vec3A::ZERO; level.n],
                    t: vec![Vec3A::ZERO; level.n],
                };
            }
        }
        let mut works: Vec<WorkMut<'_, Vec3A>> =
            rest.iter_mut().map(|w| WorkMut { r: &mut w.r, x: &mut w.x, t: &mut w.t }).collect();
        restrict(&self.aggregations[0], res, works[0].r);
        let (levels, coarsest) = self.coarse_of(face);
        self.coarse_cycle(levels, coarsest, 0, &mut works);
        prolong_add(&self.aggregations[0].parent, works[0].x, x, face);
    }

    /// The coarse levels' work vectors in order (`r`, `x`, `t` of each, no `t` on the
    /// coarsest level, which is solved directly), each level's length.
    fn lent_lengths(&self) -> impl Iterator<Item = usize> + '_ {
        let last = self.levels.len().saturating_sub(1);
        self.levels
            .iter()
            .enumerate()
            .flat_map(move |(l, level)| [level.n, level.n, if l == last { 0 } else { level.n }])
    }

    /// Whether the coarse levels' work vectors fit in two lent vectors of `n` entries, the
    /// first coarse level's residual in the first (the fine residual, in the second, is
    /// read while it is written).
    pub(super) fn lent_fits(&self, n: usize) -> bool {
        self.levels.first().is_some_and(|first| first.n <= n)
            && Lender::<DVec3>::fits(self.lent_lengths().skip(1), vec![n - self.levels[0].n, n])
    }

    /// [`Vcycle::own_correction`] with the coarse levels' work vectors in `t` and `res`,
    /// the conjugate gradient's vectors that hold the fine level's scratch and residual
    /// (`f32` values stored in `f64`, exactly): both are free once the residual is
    /// restricted, until the fine level's next residual.
    fn lent_correction(&self, res: &mut [DVec3], t: &mut [DVec3], x: &mut [Vec3A], face: Option<&[Vec3A]>) {
        let (r0, t) = t.split_at_mut(self.levels[0].n);
        restrict(&self.aggregations[0], &*res, &mut *r0);
        let mut lender = Lender { rooms: vec![t, res] };
        let lens: Vec<usize> = self.lent_lengths().collect();
        let mut works = Vec::with_capacity(self.levels.len());
        let mut first = Some(r0);
        for l in lens.chunks_exact(3) {
            let r = first.take().unwrap_or_else(|| lender.take(l[0]));
            works.push(WorkMut { r, x: lender.take(l[1]), t: lender.take(l[2]) });
        }
        let (levels, coarsest) = self.coarse_of(face);
        self.coarse_cycle(levels, coarsest, 0, &mut works);
        prolong_add(&self.aggregations[0].parent, &*works[0].x, x, face);
    }

    /// Solves approximately on coarse level `l + 1` (`works[l]`): `x = V(r)`.
    fn coarse_cycle<S: Stored>(
        &self,
        levels: &[Level],
        coarsest: Option<&Coarsest>,
        l: usize,
        works: &mut [WorkMut<'_, S>],
    ) {
        let last = l + 1 == levels.len();
        if last {
            let w = &mut works[0];
            coarsest.expect("factored").solve(&*w.r, &mut *w.x);
            return;
        }
        let steps = self.coarse_steps;
        let (here, rest) = works.split_at_mut(1);
        let w = &mut here[0];
        let level = &levels[l];
        smooth(&level.smoother, &*w.r, &mut *w.x, false, None);
        for s in 0..steps {
            level.matrix.residual(&*w.x, &*w.r, &mut *w.t);
            if s + 1 < steps {
                smooth(&level.smoother, &*w.t, &mut *w.x, true, None);
            }
        }
        restrict(&self.aggregations[l + 1], &*w.t, &mut *rest[0].r);
        self.coarse_cycle(levels, coarsest, l + 1, rest);
        let level = &levels[l];
        let (here, rest) = works.split_at_mut(1);
        let w = &mut here[0];
        prolong_add(&self.aggregations[l + 1].parent, &*rest[0].x, &mut *w.x, None);
        for _ in 0..steps {
            level.matrix.residual(&*w.x, &*w.r, &mut *w.t);
            smooth(&level.smoother, &*w.t, &mut *w.x, true, None);
        }
    }
}
