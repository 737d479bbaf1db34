//! The fast pipeline's solver: a fixed number of damped block-Jacobi sweeps.

use std::time::Instant;

use glam::{DVec3, Vec3A};
use rayon::prelude::*;
use serde::Serialize;
use voxreg_digisurf::{DigitalSurface, Lists, SurfelId, VertexId};
use voxreg_normals::{Interrupt, QuadGraph};

use crate::energy::Energy;
use crate::error::RegularizeError;
use crate::info::{SolveTimings, SweepsInfo};
use crate::progress::Progress;
use crate::stencil::{corner_neighbours, fill, FairNeighbours, CHUNK};
use crate::vecops::sym_inverse;
use crate::weights::FairnessMask;

/// Settings of [`SweepsSolver`].
#[derive(Copy, Clone, Debug, PartialEq, Serialize)]
pub struct SweepsParams {
    /// Sweeps per solve: each is one product by the operator. Default: `8`.
    pub sweeps: usize,
    /// The damping `w` of each sweep `x <- x + w D^-1 (b - H x)`, in `(0, 1]`. The
    /// iteration converges for `w < 2 / lambda_max(D^-1 H)`; the fairness term alone
    /// reaches `lambda = 3.2` on a flat grid (a checkerboard along the surface, where the
    /// alignment adds nothing to the diagonal), so `w` must stay below `0.625`: at `0.7`
    /// those modes grow by 1.24 a sweep, harmless for 32 sweeps, ruinous for 128.
    /// Default: `0.6`.
    pub omega: f64,
}

impl Default for SweepsParams {
    fn default() -> Self {
        SweepsParams { sweeps: 8, omega: 0.6 }
    }
}

impl SweepsParams {
    /// The most sweeps a solve accepts.
    pub const MAX_SWEEPS: usize = 10_000;

    /// Checks the ranges.
    pub fn validate(&self) -> Result<(), RegularizeError> {
        if self.sweeps > Self::MAX_SWEEPS {
            return Err(RegularizeError::InvalidParams(format!(
                "the sweeps per solve must be at most {}, got {}",
                Self::MAX_SWEEPS,
                self.sweeps
            )));
        }
        if !(self.omega > 0.0 && self.omega <= 1.0) {
            return Err(RegularizeError::InvalidParams(format!(
                "the sweeps' damping must be in (0, 1], got {}",
                self.omega
            )));
        }
        Ok(())
    }
}

/// A fixed number of damped block-Jacobi sweeps on the energy's normal equations `H x = b`
/// (`b = alpha p`), from a start (the staircase, or the last round's positions):
/// `x <- x + w D^-1 (b - H x)`, `D` the 3x3 diagonal blocks of `H`, inverted once per
/// solve. Each sweep is one matrix-free product in two passes over the vertices, in
/// parallel, fused with the update; no memory is allocated per sweep.
///
/// The sweeps run in `f32` on the displacement `d = x - p` from the input, whose
/// right-hand side `g = -(H - diag(alpha)) p` is computed once per solve in `f64`: the
/// displacements are a few voxels at most, so single precision keeps them to about
/// `1e-7` voxel, and the product reads half the bytes (`f32` vectors of 16 bytes, which
/// the compiler maps to SIMD registers). The per-face terms (`sqrt(beta_f) n_f`), the
/// fairness coefficients and the block inverses are computed once per solve, not per
/// sweep.
///
/// Not a solver to a tolerance: a few sweeps from the staircase smooth it towards the
/// minimizer and stop early, which acts as extra attachment to the (unbiased) staircase.
/// The fast pipeline ([`crate::Params::fast`]) alternates batches of sweeps with cheap
/// re-estimates of the normals ([`voxreg_normals::Diffused`]); see
/// `docs/design/fast-preset.md`.
#[derive(Debug)]
pub struct SweepsSolver {
    params: SweepsParams,
    /// The connectivity, built at the first solve (for its energy's fairness mask).
    stencil: Option<Corners>,
    mask: Option<FairnessMask>,
    spacing: DVec3,
    graph: Option<QuadGraph>,
    structure_seconds: f64,
    interrupt: Interrupt,
    /// Work arrays, kept across solves: `w D^-1` per vertex (symmetric, 6 numbers), the
    /// face terms per face, `gamma_i / |S_i|` per vertex, the right-hand side `g`, the
    /// displacement and its next value, the fairness residuals.
    dinv: Vec<[f32; 6]>,
    face_normals: Vec<Vec3A>,
    fair: Vec<f32>,
    rhs: Vec<Vec3A>,
    disp: Vec<Vec3A>,
    next: Vec<Vec3A>,
    resid: Vec<Vec3A>,
    partials: Vec<(f64, f64)>,
}

/// The sweeps' connectivity: per slot of the surface's vertex-surfel lists
/// ([`DigitalSurface::vertex_surfel_lists`], which give the faces), the slot's corner's
/// two neighbours in its quad (previous, next); and the barycenter neighbours. 8 bytes a
/// slot beside the surface's 4, where the operator's own stencil holds 12 and offsets.
#[derive(Clone, Debug)]
struct Corners {
    pairs: Vec<[u32; 2]>,
    fair: FairNeighbours,
}

impl Corners {
    fn new(surface: &DigitalSurface, mask: Option<&FairnessMask>) -> Result<Self, RegularizeError> {
        let lists = surface.vertex_surfel_lists();
        let pairs = fill(lists.offsets(), |v, out: &mut [[u32; 2]]| {
            for (pair, f) in out.iter_mut().zip(lists.get(v)) {
                *pair = corner_neighbours(surface, *f, v);
            }
        });
        Ok(Corners { pairs, fair: FairNeighbours::new(surface, mask)? })
    }

    fn len(&self) -> usize {
        self.fair.len()
    }

    fn bytes(&self) -> usize {
        8 * self.pairs.len() + self.fair.bytes()
    }
}

/// The faces around vertex `i`: each as (face, previous corner, next corner).
#[inline(always)]
fn faces<'a>(
    lists: &'a Lists<SurfelId>,
    pairs: &'a [[u32; 2]],
    i: usize,
) -> impl Iterator<Item = (usize, usize, usize)> + 'a {
    let offsets = lists.offsets();
    let range = offsets[i] as usize..offsets[i + 1] as usize;
    lists.items()[range.clone()]
        .iter()
        .zip(&pairs[range])
        .map(|(f, [p, q])| (f.index(), *p as usize, *q as usize))
}

/// `v` made `n` items long, item `i` being `f(i)`, written in parallel: a fresh vector's
/// pages are first touched by the threads that fill them, where a `resize` would have one
/// thread zero them all first.
fn par_fill<T: Send>(v: &mut Vec<T>, n: usize, f: impl Fn(usize) -> T + Sync + Send) {
    v.clear();
    v.par_extend((0..n).into_par_iter().map(f));
}

/// `m x` for a symmetric `m` stored as `[xx, yy, zz, xy, xz, yz]`, in `f32`, as three
/// column products in SIMD lanes.
#[inline(always)]
fn sym_mul32(m: &[f32; 6], x: Vec3A) -> Vec3A {
    Vec3A::new(m[0], m[3], m[4]) * x.x
        + Vec3A::new(m[3], m[1], m[5]) * x.y
        + Vec3A::new(m[4], m[5], m[2]) * x.z
}

impl SweepsSolver {
    /// The solver of energies on `surface`.
    pub fn for_surface(surface: &DigitalSurface, params: SweepsParams) -> Result<Self, RegularizeError> {
        params.validate()?;
        Ok(SweepsSolver {
            params,
            stencil: None,
            mask: None,
            spacing: surface.spacing(),
            graph: None,
            structure_seconds: 0.0,
            interrupt: Interrupt::never(),
            dinv: Vec::new(),
            face_normals: Vec::new(),
            fair: Vec::new(),
            rhs: Vec::new(),
            disp: Vec::new(),
            next: Vec::new(),
            resid: Vec::new(),
            partials: Vec::new(),
        })
    }

    /// The settings.
    pub fn params(&self) -> SweepsParams {
        self.params
    }

    pub(crate) fn set_interrupt(&mut self, interrupt: Interrupt) {
        self.interrupt = interrupt;
    }

    /// Lets go of the work arrays (a solve makes them again): after a run's last solve,
    /// so that its finish does not hold them beside the positions it makes.
    pub(crate) fn release_work(&mut self) {
        for v in [&mut self.face_normals, &mut self.rhs, &mut self.disp, &mut self.next, &mut self.resid] {
            *v = Vec::new();
        }
        self.dinv = Vec::new();
        self.fair = Vec::new();
        self.partials = Vec::new();
    }

    /// Lends the re-estimates' graph, if it was built ([`SweepsSolver::set_graph`] gives
    /// it back).
    pub(crate) fn take_graph(&mut self) -> Option<QuadGraph> {
        self.graph.take()
    }

    /// Makes `graph` (the [`QuadGraph`] of this solver's surface) the re-estimates' graph.
    pub(crate) fn set_graph(&mut self, graph: QuadGraph) {
        self.graph = Some(graph);
    }

    /// The surfel graph of the re-estimates ([`voxreg_normals::Diffused`]), built on first
    /// use and kept.
    pub(crate) fn graph(&mut self, surface: &DigitalSurface) -> &QuadGraph {
        self.graph.get_or_insert_with(|| QuadGraph::new(surface))
    }

    /// The per-solve numbers of `energy`: the face terms in slot order, the fairness
    /// coefficients, `w D^-1`, and the right-hand side `g = -(H - diag(alpha)) p` (in
    /// `f64`, stored in `f32`).
    fn prepare(&mut self, energy: &Energy<'_>) {
        let stencil = self.stencil.as_ref().expect("built before");
        let surface = energy.surface();
        let (lists, pairs) = (surface.vertex_surfel_lists(), &stencil.pairs[..]);
        let (input, normals) = (energy.input(), energy.normals());
        let n = stencil.len();
        par_fill(&mut self.face_normals, normals.len(), |f| {
            (energy.beta_at(f).sqrt() * normals[f]).as_vec3a()
        });
        par_fill(&mut self.fair, n, |v| {
            let deg = stencil.fair.of(v).len();
            if deg == 0 || surface.is_boundary_vertex(VertexId(v as u32)) {
                0.0
            } else {
                (energy.gamma_at(v) / deg as f64) as f32
            }
        });
        let (m, fair) = (&self.face_normals[..], &self.fair[..]);
        let omega = self.params.omega;
        par_fill(&mut self.dinv, n, |i| {
            let a = energy.alpha_at(i);
            let nb = stencil.fair.of(i);
            let mut f = f64::from(fair[i]) * nb.len() as f64;
            for &j in nb {
                let dj = stencil.fair.of(j as usize).len();
                if dj > 0 {
                    f += f64::from(fair[j as usize]) / dj as f64;
                }
            }
            let mut d = [a + f, a + f, a + f, 0.0, 0.0, 0.0];
            for (f, _, _) in faces(lists, pairs, i) {
                let m = 2.0 * m[f].as_dvec3();
                let m2 = m / 2.0;
                d[0] += m.x * m2.x;
                d[1] += m.y * m2.y;
                d[2] += m.z * m2.z;
                d[3] += m.x * m2.y;
                d[4] += m.x * m2.z;
                d[5] += m.y * m2.z;
            }
            sym_inverse(&d).map(|v| (omega * v) as f32)
        });
        // g: the fairness residuals of p, then the alignment and fairness rows, with the
        // differences of positions taken in f64.
        par_fill(&mut self.resid, n, |i| {
            let nb = stencil.fair.of(i);
            if fair[i] == 0.0 {
                Vec3A::ZERO
            } else {
                let sum: DVec3 = nb.iter().map(|&j| input[j as usize]).sum();
                f64::from(fair[i]) as f32 * (input[i] - sum / nb.len() as f64).as_vec3a()
            }
        });
        let t = &self.resid[..];
        par_fill(&mut self.rhs, n, |i| {
            let p = input[i];
            let mut acc = Vec3A::ZERO;
            for (f, prev, next) in faces(lists, pairs, i) {
                let m = m[f];
                let e = (2.0 * p - input[prev] - input[next]).as_vec3a();
                acc += e.dot(m) * m;
            }
            let nb = stencil.fair.of(i);
            let sum: Vec3A = nb.iter().map(|&j| t[j as usize]).sum();
            -(acc + nb.len() as f32 * t[i] - sum)
        });
    }

    /// Runs the sweeps on `energy` from `start` (the energy's input when `None`); calls
    /// `progress` once, after the last sweep (its energy is not computed: NaN; its error
    /// estimate is the last sweep's largest move, in voxels).
    pub fn solve(
        &mut self,
        energy: &Energy<'_>,
        start: Option<Vec<DVec3>>,
        progress: &mut dyn FnMut(&Progress),
    ) -> Result<(Vec<DVec3>, SweepsInfo), RegularizeError> {
        let surface = energy.surface();
        let input = energy.input();
        let n = surface.num_vertices();
        if input.len() != n || self.stencil.as_ref().is_some_and(|s| s.len() != n) {
            return Err(RegularizeError::SizeMismatch("the energy is not on this solver's surface".into()));
        }
        if let Some(x) = &start {
            energy.check_start(x)?;
        }
        let mut seconds = SolveTimings::default();
        let mask = energy.weights().and_then(|w| w.fairness.as_ref());
        if self.stencil.is_none() || mask != self.mask.as_ref() {
            let t = Instant::now();
            self.stencil = Some(Corners::new(surface, mask)?);
            self.mask = mask.cloned();
            self.structure_seconds += t.elapsed().as_secs_f64();
        }
        seconds.structure = std::mem::take(&mut self.structure_seconds);
        let t = Instant::now();
        // The start becomes the displacement first: its f64 positions go before the
        // solve's other arrays are made.
        match start {
            Some(x) => par_fill(&mut self.disp, n, |i| (x[i] - input[i]).as_vec3a()),
            None => par_fill(&mut self.disp, n, |_| Vec3A::ZERO),
        }
        self.prepare(energy);
        par_fill(&mut self.next, n, |_| Vec3A::ZERO);
        self.partials.resize(n.div_ceil(CHUNK), (0.0, 0.0));
        seconds.assemble = t.elapsed().as_secs_f64();

        let t = Instant::now();
        let stencil = self.stencil.as_ref().expect("built above");
        let (lists, pairs) = (surface.vertex_surfel_lists(), &stencil.pairs[..]);
        let h = self.spacing.min_element();
        let (mut first, mut last, mut last_move) = (f64::NAN, f64::NAN, 0.0);
        let (m, fair, dinv, rhs) = (&self.face_normals[..], &self.fair[..], &self.dinv[..], &self.rhs[..]);
        // One attachment weight for all vertices unless the energy scales them.
        let uniform_alpha =
            energy.weights().is_none_or(|w| w.alpha.is_none()).then(|| energy.alpha_at(0) as f32);
        let alpha_at = |i: usize| uniform_alpha.unwrap_or_else(|| energy.alpha_at(i) as f32);
        for k in 0..self.params.sweeps {
            self.interrupt.check()?;
            // The residual's norm is reported for the first and the last sweep, the
            // largest move for the last.
            let track = k == 0 || k + 1 == self.params.sweeps;
            let d = &self.disp[..];
            // Pass 1: the fairness residuals t_i = gamma_i / |S_i| (d_i - mean of d_j).
            self.resid.par_chunks_mut(CHUNK).enumerate().for_each(|(chunk, out)| {
                let base = chunk * CHUNK;
                for (o, ti) in out.iter_mut().enumerate() {
                    let i = base + o;
                    let ci = fair[i];
                    *ti = if ci == 0.0 {
                        Vec3A::ZERO
                    } else {
                        let nb = stencil.fair.of(i);
                        let sum: Vec3A = nb.iter().map(|&j| d[j as usize]).sum();
                        ci * (d[i] - sum / nb.len() as f32)
                    };
                }
            });
            // Pass 2: the residual r = g - H d and the damped block step, fused.
            let t = &self.resid[..];
            self.partials.par_iter_mut().zip(self.next.par_chunks_mut(CHUNK)).enumerate().for_each(
                |(chunk, (part, next))| {
                    let base = chunk * CHUNK;
                    let (mut r2, mut step2) = (0.0f64, 0.0f32);
                    for (o, out) in next.iter_mut().enumerate() {
                        let i = base + o;
                        let di = d[i];
                        let di2 = 2.0 * di;
                        let mut hx = alpha_at(i) * di;
                        for (f, prev, next) in faces(lists, pairs, i) {
                            let m = m[f];
                            hx += (di2 - d[prev] - d[next]).dot(m) * m;
                        }
                        let nb = stencil.fair.of(i);
                        let sum: Vec3A = nb.iter().map(|&j| t[j as usize]).sum();
                        hx += nb.len() as f32 * t[i] - sum;
                        let r = rhs[i] - hx;
                        let step = sym_mul32(&dinv[i], r);
                        *out = di + step;
                        if track {
                            r2 += f64::from(r.length_squared());
                            step2 = step2.max(step.length_squared());
                        }
                    }
                    *part = (r2, f64::from(step2));
                },
            );
            std::mem::swap(&mut self.disp, &mut self.next);
            let r2: f64 = self.partials.iter().map(|p| p.0).sum();
            last_move = self.partials.iter().fold(0.0f64, |m, p| m.max(p.1)).sqrt() / h;
            last = r2.sqrt();
            if k == 0 {
                first = last;
            }
        }
        let memory_bytes = stencil.bytes()
            + 24 * self.dinv.len()
            + 16 * self.face_normals.len()
            + 4 * self.fair.len()
            + 16 * (self.rhs.len() + 3 * self.disp.len())
            + self.graph.as_ref().map_or(0, QuadGraph::memory_bytes);
        // The next value and the residuals are rebuilt by the next solve: freed before
        // the f64 outputs, so that the peak holds them or these, not both.
        self.next = Vec::new();
        self.resid = Vec::new();
        // The displacement in the callback's f64, reported once per solve, then made the
        // positions in place: the solve's end holds one `f64` vector, not two.
        let mut x: Vec<DVec3> = self.disp.par_iter().map(|d| d.as_dvec3()).collect();
        if self.params.sweeps > 0 {
            progress(&Progress {
                iteration: self.params.sweeps,
                energy: f64::NAN,
                gradient_norm: 2.0 * last,
                relative_gradient: if first > 0.0 { last / first } else { 0.0 },
                error_bound: f64::INFINITY,
                error_estimate: last_move,
                displacement: &x,
            });
        }
        x.par_iter_mut().zip(input).for_each(|(x, p)| *x = *p + *x);
        seconds.solve = t.elapsed().as_secs_f64();
        let relative_gradient = if first > 0.0 { last / first } else { 0.0 };
        Ok((
            x,
            SweepsInfo {
                iterations: self.params.sweeps,
                relative_gradient: if relative_gradient.is_finite() { relative_gradient } else { 0.0 },
                last_move,
                memory_bytes,
                seconds,
            },
        ))
    }
}

#[cfg(test)]
mod tests {
    use voxreg_digisurf::LabelVolume;
    use voxreg_normals::{NormalEstimator, Trivial};

    use super::*;
    use crate::energy::EnergyParams;
    use crate::solver::{SolverChoice, SolverParams};
    use crate::{SolveRequest, Solver};

    /// Many sweeps converge to the exact minimizer (the direct solver's): the iteration
    /// is the damped block-Jacobi one of the same operator.
    #[test]
    fn many_sweeps_reach_the_minimizer() {
        let v = LabelVolume::from_fn([9, 9, 9], |[x, y, z]| {
            u32::from((x as i64 - 4).pow(2) + (y as i64 - 4).pow(2) + (z as i64 - 4).pow(2) <= 10)
        });
        let s = DigitalSurface::from_volume(&v).unwrap();
        let normals = Trivial.estimate(&s).unwrap();
        let input = s.positions();
        let energy =
            Energy::new(&s, &normals, &input, EnergyParams { alpha: 0.1, beta: 1.0, gamma: 0.1 }).unwrap();
        let direct = SolverParams { choice: SolverChoice::Direct, ..Default::default() };
        let (exact, _) = Solver::new(&s, &direct).unwrap().solve(&energy, SolveRequest::default()).unwrap();
        let mut solver = SweepsSolver::for_surface(&s, SweepsParams { sweeps: 2000, omega: 0.6 }).unwrap();
        let mut calls = 0;
        let (x, info) = solver
            .solve(&energy, None, &mut |p| {
                calls += 1;
                assert_eq!((p.iteration, p.displacement.len()), (2000, input.len()));
            })
            .unwrap();
        assert_eq!((calls, info.iterations), (1, 2000));
        let err = x.iter().zip(&exact).map(|(a, b)| (*a - *b).length()).fold(0.0, f64::max);
        assert!(err < 1e-6, "{err}");
        assert!(info.relative_gradient < 1e-6, "{info:?}");
        // From the minimizer, a sweep does not move (to the f32 rounding of the sweeps).
        let mut one = SweepsSolver::for_surface(&s, SweepsParams { sweeps: 1, omega: 0.6 }).unwrap();
        let (y, info) = one.solve(&energy, Some(exact.clone()), &mut |_| {}).unwrap();
        assert!(
            info.last_move < 1e-6 && y.iter().zip(&exact).all(|(a, b)| (*a - *b).length() < 1e-6),
            "{info:?}"
        );
        assert!(SweepsParams { sweeps: 8, omega: 1.5 }.validate().is_err());
    }
}
