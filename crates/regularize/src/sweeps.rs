//! The fast pipeline's solver: a fixed number of damped block-Jacobi sweeps.

use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;
use serde::Serialize;
use voxreg_digisurf::DigitalSurface;
use voxreg_normals::{Interrupt, QuadGraph};

use crate::energy::Energy;
use crate::error::RegularizeError;
use crate::info::{SolveTimings, SweepsInfo};
use crate::progress::Progress;
use crate::stencil::{Stencil, CHUNK};
use crate::vecops::{sym_inverse, sym_mul};
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
/// Not a solver to a tolerance: a few sweeps from the staircase smooth it towards the
/// minimizer and stop early, which acts as extra attachment to the (unbiased) staircase.
/// The fast pipeline ([`crate::Params::fast`]) alternates batches of sweeps with cheap
/// re-estimates of the normals ([`voxreg_normals::Diffused`]); see
/// `docs/design/fast-preset.md`.
#[derive(Debug)]
pub struct SweepsSolver {
    params: SweepsParams,
    /// The connectivity, built at the first solve (for its energy's fairness mask).
    stencil: Option<Stencil>,
    mask: Option<FairnessMask>,
    spacing: DVec3,
    graph: Option<QuadGraph>,
    structure_seconds: f64,
    interrupt: Interrupt,
    /// Work arrays, kept across solves.
    dinv: Vec<[f64; 6]>,
    next: Vec<DVec3>,
    fair: Vec<DVec3>,
    partials: Vec<(f64, f64)>,
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
            next: Vec::new(),
            fair: Vec::new(),
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

    /// The surfel graph of the re-estimates ([`voxreg_normals::Diffused`]), built on first
    /// use and kept.
    pub(crate) fn graph(&mut self, surface: &DigitalSurface) -> &QuadGraph {
        self.graph.get_or_insert_with(|| QuadGraph::new(surface))
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
        let mut x = match start {
            Some(x) => {
                energy.check_start(&x)?;
                x
            }
            None => input.to_vec(),
        };
        let mut seconds = SolveTimings::default();
        let mask = energy.weights().and_then(|w| w.fairness.as_ref());
        if self.stencil.is_none() || mask != self.mask.as_ref() {
            let t = Instant::now();
            self.stencil = Some(Stencil::new(surface, mask)?);
            self.mask = mask.cloned();
            self.structure_seconds += t.elapsed().as_secs_f64();
        }
        let stencil = self.stencil.as_ref().expect("built above");
        seconds.structure = std::mem::take(&mut self.structure_seconds);
        let t = Instant::now();
        let c = stencil.coefficients(energy);
        self.dinv.resize(n, [0.0; 6]);
        let diagonal = stencil.diagonal(&c);
        self.dinv.par_iter_mut().zip(&diagonal).for_each(|(o, d)| *o = sym_inverse(d));
        drop(diagonal);
        for v in [&mut self.next, &mut self.fair] {
            v.resize(n, DVec3::ZERO);
        }
        self.partials.resize(n.div_ceil(CHUNK), (0.0, 0.0));
        seconds.assemble = t.elapsed().as_secs_f64();

        let t = Instant::now();
        let omega = self.params.omega;
        let h = self.spacing.min_element();
        let (mut first, mut last, mut last_move) = (f64::NAN, f64::NAN, 0.0);
        for k in 0..self.params.sweeps {
            self.interrupt.check()?;
            let xs = &x[..];
            // Pass 1: the fairness residuals t_i = gamma_i / |S_i| (x_i - mean of x_j).
            self.fair.par_chunks_mut(CHUNK).enumerate().for_each(|(chunk, out)| {
                let base = chunk * CHUNK;
                for (o, ti) in out.iter_mut().enumerate() {
                    let i = base + o;
                    let ci = c.fair[i];
                    *ti = if ci == 0.0 {
                        DVec3::ZERO
                    } else {
                        let nb = stencil.fair_neighbours(i);
                        let sum: DVec3 = nb.iter().map(|&j| xs[j as usize]).sum();
                        ci * (xs[i] - sum / nb.len() as f64)
                    };
                }
            });
            // Pass 2: the residual r = b - H x and the damped block step, fused.
            let (fair, dinv) = (&self.fair[..], &self.dinv[..]);
            self.partials.par_iter_mut().zip(self.next.par_chunks_mut(CHUNK)).enumerate().for_each(
                |(chunk, (part, next))| {
                    let base = chunk * CHUNK;
                    let (mut r2, mut step2) = (0.0, 0.0f64);
                    for (o, out) in next.iter_mut().enumerate() {
                        let i = base + o;
                        let xi = xs[i];
                        let a = c.alpha.get(i);
                        let mut hx = a * xi;
                        for s in stencil.faces(i) {
                            let m = c.face_normals[s.face as usize];
                            hx += (2.0 * xi - xs[s.prev as usize] - xs[s.next as usize]).dot(m) * m;
                        }
                        let nb = stencil.fair_neighbours(i);
                        let sum: DVec3 = nb.iter().map(|&j| fair[j as usize]).sum();
                        hx += nb.len() as f64 * fair[i] - sum;
                        let r = a * input[i] - hx;
                        let step = omega * sym_mul(&dinv[i], r);
                        *out = xi + step;
                        r2 += r.length_squared();
                        step2 = step2.max(step.length_squared());
                    }
                    *part = (r2, step2);
                },
            );
            std::mem::swap(&mut x, &mut self.next);
            let r2: f64 = self.partials.iter().map(|p| p.0).sum();
            last_move = self.partials.iter().fold(0.0f64, |m, p| m.max(p.1)).sqrt() / h;
            last = r2.sqrt();
            if k == 0 {
                first = last;
            }
        }
        if self.params.sweeps > 0 {
            // The iterate, once per solve: the fairness buffer is free now.
            let moved = &mut self.fair;
            moved.par_iter_mut().zip(&x).zip(input).for_each(|((m, x), p)| *m = *x - *p);
            progress(&Progress {
                iteration: self.params.sweeps,
                energy: f64::NAN,
                gradient_norm: 2.0 * last,
                relative_gradient: if first > 0.0 { last / first } else { 0.0 },
                error_bound: f64::INFINITY,
                error_estimate: last_move,
                displacement: moved,
            });
        }
        seconds.solve = t.elapsed().as_secs_f64();
        let memory_bytes = stencil.bytes()
            + 48 * self.dinv.len()
            + 24 * (self.next.len() + self.fair.len() + x.len())
            + self.graph.as_ref().map_or(0, QuadGraph::memory_bytes);
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
        // From the minimizer, a sweep does not move.
        let mut one = SweepsSolver::for_surface(&s, SweepsParams { sweeps: 1, omega: 0.6 }).unwrap();
        let (y, info) = one.solve(&energy, Some(exact.clone()), &mut |_| {}).unwrap();
        assert!(info.last_move < 1e-9 && y.iter().zip(&exact).all(|(a, b)| (*a - *b).length() < 1e-9));
        assert!(SweepsParams { sweeps: 8, omega: 1.5 }.validate().is_err());
    }
}
