//! The bound-constrained solver: preconditioned CG inside per-vertex boxes (MPRGP), the
//! clamping of the paper's sec. 3.4.

use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;
use voxreg_digisurf::DigitalSurface;

use crate::cg::check_tolerance;
use crate::info::{BoundedInfo, SolveTimings};
use crate::iterative::{Preconditioner, Setup};
use crate::multigrid::MultigridParams;
use crate::stencil::CHUNK;
use crate::vecops::{dot, norm, tail_estimate};
use crate::{Energy, MatrixFreeOperator, Progress, RegularizeError};

/// Parameters of [`BoundedSolver`].
#[derive(Copy, Clone, Debug, PartialEq, serde::Serialize)]
pub struct BoundedParams {
    /// Stop when the estimated remaining movement of the farthest vertex, in voxels, is at
    /// most this: its last correction extrapolated with the recent reduction rate of the
    /// (projected) gradient, times 2 (as [`StoppingRule::Estimate`](crate::StoppingRule)).
    /// Default: `1e-3`.
    pub tolerance: f64,
    /// Give up after this many iterations. Default: `10000`.
    pub max_iterations: usize,
    /// Clamping (paper, sec. 3.4, rule (ii) of Proposition 2): when `Some(eps)`, every
    /// vertex stays in the closed axis-aligned box of edge `(1 - eps) h` centred on its
    /// input position, `h` the voxel spacing along each axis and `eps` in voxels,
    /// `0 < eps < 1`. With faces embedded in the convex hull of their vertices (two
    /// triangles per quad), the result then has no self-intersection. Default: `None`.
    pub clamp: Option<f64>,
    /// The metric of the descent: the direction is `-M^-1 grad E` (restricted to the free
    /// coordinates when clamping); [`Preconditioner::Identity`] is plain steepest
    /// descent. Default: [`Preconditioner::Multigrid`].
    pub preconditioner: Preconditioner,
    /// Multigrid settings. Default: [`MultigridParams::default`].
    pub multigrid: MultigridParams,
    /// When clamping: accelerate the descent with conjugate directions on the coordinates
    /// strictly inside their boxes (a preconditioned MPRGP: CG on the current face,
    /// projected gradient steps to add bounds, proportioning steps to release them). Tens
    /// of times fewer iterations than the projected descent, with the same guarantees
    /// (feasible iterates, monotone energy). It starts from the unconstrained minimizer
    /// (found by the same iteration without bounds, i.e. preconditioned CG) projected into
    /// the boxes when that lowers the energy, else from the input; [`BoundedInfo::iterations`](crate::BoundedInfo::iterations)
    /// counts the bounded iterations only, [`BoundedInfo::operator_applications`](crate::BoundedInfo::operator_applications) all.
    /// `false`: plain projected descent. Default: `true`.
    pub conjugate: bool,
}

impl Default for BoundedParams {
    fn default() -> Self {
        BoundedParams {
            tolerance: 1e-3,
            max_iterations: 10_000,
            clamp: None,
            preconditioner: Preconditioner::Multigrid,
            multigrid: MultigridParams::default(),
            conjugate: true,
        }
    }
}

/// Minimizes the energy with every vertex kept in a closed box around its input position
/// (when [`BoundedParams::clamp`] is set), reusable across solves on one surface.
///
/// The method is MPRGP (modified proportioning with reduced gradient projections):
/// preconditioned conjugate gradient on the coordinates strictly inside their boxes,
/// projected gradient steps (with the exact step `t = (g . d) / (2 d^T H d)` of the
/// quadratic, halved until the energy does not increase) to add bounds, and proportioning
/// steps to release them. Iterates stay feasible and the energy decreases monotonically.
/// With [`BoundedParams::conjugate`] off it is the plain projected descent of the paper.
/// Without boxes it converges to the same minimizer as [`crate::DirectSolver`] and
/// [`crate::CgSolver`].
#[derive(Debug)]
pub struct BoundedSolver {
    params: BoundedParams,
    setup: Setup,
}

impl BoundedSolver {
    /// The solver of energies on `surface`: its operator ([`MatrixFreeOperator::new`]),
    /// then [`BoundedSolver::new`].
    pub fn for_surface(surface: &DigitalSurface, params: BoundedParams) -> Result<Self, RegularizeError> {
        Self::new(MatrixFreeOperator::new(surface)?, params)
    }

    /// The solver of energies with the matrix-free `operator`, inside the boxes of
    /// `params.clamp` (scaled by the operator's voxel spacing).
    pub fn new(operator: MatrixFreeOperator, params: BoundedParams) -> Result<Self, RegularizeError> {
        check_tolerance(params.tolerance)?;
        if let Some(eps) = params.clamp {
            if !(eps > 0.0 && eps < 1.0) {
                return Err(RegularizeError::InvalidParams(format!(
                    "the clamping margin must be in (0, 1) voxel, got {eps}"
                )));
            }
        }
        Ok(BoundedSolver { params, setup: Setup::new(operator, params.preconditioner, params.multigrid)? })
    }

    /// The parameters.
    pub fn params(&self) -> &BoundedParams {
        &self.params
    }

    /// Minimizes `energy` from its input positions.
    pub fn solve(&mut self, energy: &Energy<'_>) -> Result<(Vec<DVec3>, BoundedInfo), RegularizeError> {
        self.solve_with(energy, &mut |_| {})
    }

    /// [`BoundedSolver::solve`], calling `progress` after each iteration.
    pub fn solve_with(
        &mut self,
        energy: &Energy<'_>,
        progress: &mut dyn FnMut(&Progress),
    ) -> Result<(Vec<DVec3>, BoundedInfo), RegularizeError> {
        let mut prepared = self.setup.prepare(energy)?;
        let stencil = &self.setup.stencil;
        let coef = &prepared.coef;
        let n = stencil.len();
        let input = energy.input();
        let h = self.setup.spacing;
        let half = self.params.clamp.map(|eps| (1.0 - eps) * 0.5 * self.setup.voxel);

        let t0 = Instant::now();
        let zero = || vec![DVec3::ZERO; n];
        // u: displacement from the input; r = -grad E / 2 = b - H u.
        let (mut u, mut r, mut z, mut q, mut tmp, mut trial) =
            (zero(), zero(), zero(), zero(), zero(), zero());
        let mut rp = zero();
        stencil.apply(coef, input, &mut r, &mut tmp, false);
        r.par_iter_mut().for_each(|x| *x = -*x);
        let rhs = r.clone();
        let r0 = norm(&r);
        let alpha_min = energy.min_alpha();
        let tol = self.params.tolerance * h;
        let mut e = energy.terms(input).total;
        let mut applications = 1;
        let mut residuals = Vec::new();
        let mut estimate = f64::INFINITY;
        let mut correction = None;
        let mut iterations = 0;
        if let (Some(w), true) = (half, self.params.conjugate) {
            // Warm start: the unconstrained minimizer (the same iteration without bounds,
            // i.e. PCG) projected into the boxes, so that the bounded iteration starts
            // with nearly the right set of clamped coordinates.
            let free = crate::boxqp::minimize_in_boxes(
                stencil,
                &mut prepared,
                DVec3::splat(f64::INFINITY),
                &mut u,
                &mut r,
                &rhs,
                tol,
                self.params.max_iterations,
                e,
                r0,
                alpha_min,
                h,
                &mut |_| {},
            );
            applications += free.applications;
            u.par_iter_mut().for_each(|d| *d = d.clamp(-w, w));
            let start = energy.terms(&input.iter().zip(&u).map(|(p, d)| *p + *d).collect::<Vec<_>>()).total;
            if start <= e {
                e = start;
            } else {
                // The projection can cost more than it gained: start from the input.
                u.iter_mut().for_each(|d| *d = DVec3::ZERO);
            }
            stencil.residual(&prepared.coef, &u, &rhs, &mut r, &mut tmp);
            applications += 1;
            let stats = crate::boxqp::minimize_in_boxes(
                stencil,
                &mut prepared,
                w,
                &mut u,
                &mut r,
                &rhs,
                tol,
                self.params.max_iterations,
                e,
                r0,
                alpha_min,
                h,
                progress,
            );
            iterations = stats.iterations;
            applications += stats.applications;
            estimate = stats.estimate;
            e += stats.energy_change;
        }
        let coef = &prepared.coef;
        while !(half.is_some() && self.params.conjugate) {
            // Projected residual: zero the coordinates held on their box by the gradient.
            rp.copy_from_slice(&r);
            if let Some(w) = half {
                project_residual(&u, w, &mut rp);
            }
            let rp_norm = norm(&rp);
            residuals.push(rp_norm);
            if let Some(c) = correction {
                estimate = 2.0 * tail_estimate(c, &residuals[residuals.len().saturating_sub(6)..]);
                progress(&Progress {
                    iteration: iterations,
                    energy: e,
                    gradient_norm: 2.0 * rp_norm,
                    relative_gradient: if r0 > 0.0 { rp_norm / r0 } else { 0.0 },
                    error_bound: rp_norm / alpha_min / h,
                    error_estimate: estimate / h,
                });
            }
            let done = rp_norm == 0.0 || (half.is_none() && rp_norm <= alpha_min * tol) || estimate <= tol;
            if done || iterations >= self.params.max_iterations {
                break;
            }
            prepared.pre.apply(stencil, &rp, &mut z);
            if let Some(w) = half {
                freeze(&u, &r, w, &mut z);
            }
            let rd = dot(&r, &z);
            stencil.apply(coef, &z, &mut q, &mut tmp, true);
            applications += 1;
            let dq = dot(&z, &q);
            if !(rd > 0.0 && dq > 0.0) {
                break; // converged to rounding
            }
            let mut step = rd / dq;
            match half {
                None => {
                    u.par_chunks_mut(CHUNK).zip(z.par_chunks(CHUNK)).for_each(|(u, z)| {
                        u.iter_mut().zip(z).for_each(|(u, z)| *u += step * *z);
                    });
                    r.par_chunks_mut(CHUNK).zip(q.par_chunks(CHUNK)).for_each(|(r, q)| {
                        r.iter_mut().zip(q).for_each(|(r, q)| *r -= step * *q);
                    });
                    e -= step * rd;
                    correction = Some(step * z.par_iter().map(|v| v.length()).reduce(|| 0.0, f64::max));
                }
                Some(w) => {
                    // Project, and halve the step until the energy does not increase:
                    // E(u + s) - E(u) = -2 r.s + s.H s.
                    let mut accepted = false;
                    let mut de = 0.0;
                    for _ in 0..40 {
                        trial
                            .par_chunks_mut(CHUNK)
                            .zip(u.par_chunks(CHUNK))
                            .zip(z.par_chunks(CHUNK))
                            .for_each(|((s, u), z)| {
                                for i in 0..s.len() {
                                    s[i] = (u[i] + step * z[i]).clamp(-w, w) - u[i];
                                }
                            });
                        stencil.apply(coef, &trial, &mut q, &mut tmp, true);
                        applications += 1;
                        de = -2.0 * dot(&r, &trial) + dot(&trial, &q);
                        if de <= 0.0 {
                            accepted = true;
                            break;
                        }
                        step *= 0.5;
                    }
                    if !accepted {
                        break;
                    }
                    e += de;
                    u.par_chunks_mut(CHUNK).zip(trial.par_chunks(CHUNK)).for_each(|(u, s)| {
                        for i in 0..u.len() {
                            u[i] = (u[i] + s[i]).clamp(-w, w);
                        }
                    });
                    r.par_chunks_mut(CHUNK).zip(q.par_chunks(CHUNK)).for_each(|(r, q)| {
                        r.iter_mut().zip(q).for_each(|(r, q)| *r -= *q);
                    });
                    correction = Some(trial.par_iter().map(|v| v.length()).reduce(|| 0.0, f64::max));
                }
            }
            iterations += 1;
            if iterations % 50 == 0 {
                // Refresh the residual: the updates drift from b - H u.
                stencil.residual(coef, &u, &rhs, &mut r, &mut tmp);
                applications += 1;
            }
        }
        // The certificate, on the true residual.
        stencil.residual(coef, &u, &rhs, &mut r, &mut tmp);
        applications += 1;
        rp.copy_from_slice(&r);
        let clamped = half.map(|w| {
            project_residual(&u, w, &mut rp);
            u.iter().filter(|d| (d.abs() - w).max_element() >= -1e-12 * w.max_element()).count()
        });
        let rp_norm_true = norm(&rp);
        let x: Vec<DVec3> = input.par_iter().zip(&u).map(|(p, u)| *p + *u).collect();
        let solve_seconds = t0.elapsed().as_secs_f64();
        let estimate = if r0 > 0.0 { estimate / h } else { 0.0 };
        let bound = (half.is_none()).then(|| rp_norm_true / alpha_min / h);
        let converged =
            estimate <= self.params.tolerance || bound.is_some_and(|b| b <= self.params.tolerance);
        let traffic = self.setup.traffic_model(&prepared, 1 + usize::from(half.is_some()), 14);
        let memory = self.setup.memory_bytes(&prepared) + 9 * 24 * n;
        Ok((
            x,
            BoundedInfo {
                iterations,
                operator_applications: applications,
                relative_gradient: if r0 > 0.0 { rp_norm_true / r0 } else { 0.0 },
                error_bound: bound,
                error_estimate: estimate,
                converged,
                clamp: self.params.clamp,
                clamped_vertices: clamped.unwrap_or(0),
                preconditioner: self.params.preconditioner,
                memory_bytes: memory,
                bytes_per_iteration: traffic,
                seconds: SolveTimings {
                    structure: self.setup.structure_seconds,
                    symbolic: 0.0,
                    assemble: prepared.assemble_seconds,
                    factor: prepared.factor_seconds,
                    solve: solve_seconds,
                },
            },
        ))
    }
}

/// Whether coordinate `u` is on the bound `+-w` towards which `r` (the descent direction
/// of the unpreconditioned gradient) pushes.
#[inline]
fn held(u: f64, r: f64, w: f64) -> bool {
    let eps = 1e-12 * w;
    (u >= w - eps && r > 0.0) || (u <= -w + eps && r < 0.0)
}

/// Zeroes the residual's coordinates held on their bound.
fn project_residual(u: &[DVec3], w: DVec3, r: &mut [DVec3]) {
    r.par_chunks_mut(CHUNK).zip(u.par_chunks(CHUNK)).for_each(|(r, u)| {
        for i in 0..r.len() {
            for a in 0..3 {
                if held(u[i][a], r[i][a], w[a]) {
                    r[i][a] = 0.0;
                }
            }
        }
    });
}

/// Zeroes the direction's coordinates held on their bound (by the gradient `r`), so that
/// it stays a descent direction: `r . d = rp^T M^-1 rp > 0`.
fn freeze(u: &[DVec3], r: &[DVec3], w: DVec3, d: &mut [DVec3]) {
    d.par_chunks_mut(CHUNK).zip(u.par_chunks(CHUNK)).zip(r.par_chunks(CHUNK)).for_each(|((d, u), r)| {
        for i in 0..d.len() {
            for a in 0..3 {
                if held(u[i][a], r[i][a], w[a]) {
                    d[i][a] = 0.0;
                }
            }
        }
    });
}
