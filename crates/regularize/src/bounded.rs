//! The bound-constrained solver: preconditioned CG inside per-vertex boxes (MPRGP), the
//! clamping of the paper's sec. 3.4.

use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;
use voxreg_digisurf::DigitalSurface;

use crate::boxqp::{
    active_set, loose_iterations, minimize_free, minimize_in_boxes, place, BoxProblem, Boxes, Place, Work,
    ACTIVE_SET_LOOSE, ACTIVE_SET_START_ITERATIONS,
};
use crate::cg::check_tolerance;
use crate::clamping::clamp_boxes;
use crate::energy::Energy;
use crate::error::RegularizeError;
use crate::info::{BoundedInfo, Preconditioner};
use crate::iterative::{Prepared, Setup};
use crate::multigrid::MultigridParams;
use crate::progress::Progress;
use crate::request::{SolveRequest, SolveStart};
use crate::stencil::MatrixFreeOperator;
use crate::stencil::CHUNK;
use crate::vecops::{dot, norm, tail_estimate_over};
use voxreg_normals::Interrupt;

/// The iterations over which the projected descent's stopping estimate measures its
/// reduction rate, and the cap on that rate: its residual zigzags, and over 5 iterations
/// the rate read low enough on a small open surface to stop it at twice the tolerance.
const DESCENT_RATE_WINDOW: usize = 20;
const DESCENT_RATE_CAP: f64 = 0.999;

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
    /// When clamping: the depth, in voxels, kept inside every thin voxel (one whose two
    /// neighbours along some axis are both of another region: a one-voxel plate, arm or
    /// slit). Each vertex at a corner of a thin voxel moves towards that voxel's centre by
    /// at most `0.5 - thin_depth` voxel along each axis, so the thin part cannot collapse
    /// onto its mid-plane; the boxes only shrink, so Proposition 2 still holds. Needs the
    /// surface ([`BoundedSolver::for_surface`]); `None` keeps the uniform boxes.
    /// Default: `None`.
    pub thin_depth: Option<f64>,
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
    /// (found by the same iteration without bounds, i.e. preconditioned CG; only roughly
    /// when active-set rounds follow) projected into the boxes when that
    /// lowers the energy, else from the input; [`BoundedInfo::iterations`](crate::BoundedInfo::iterations)
    /// counts the bounded iterations only, [`BoundedInfo::operator_applications`](crate::BoundedInfo::operator_applications) all.
    /// `false`: plain projected descent. Default: `true`.
    pub conjugate: bool,
    /// When clamping with [`BoundedParams::conjugate`]: at most this many rounds of the
    /// primal-dual active-set iteration between the unconstrained minimizer and MPRGP.
    /// Each round holds the coordinates that cross their bounds (or are pushed onto them)
    /// and solves for the others by the unconstrained solver's own preconditioned CG; a
    /// few rounds find the binding coordinates at the cost of a few unconstrained solves,
    /// where MPRGP alone discovers them a step at a time. While the holds change, a
    /// round's CG stops at 100 times the tolerance (or after three iterations with the
    /// multigrid preconditioner, four for the unconstrained start); a round at the
    /// tolerance that changes no hold ends the solve (its iterate is then the minimizer in
    /// the boxes to the tolerance). Rounds that stop changing fewer holds (a coordinate
    /// freed and held in turn) or reach this count hand over to MPRGP, from the result
    /// projected into the boxes, so the guarantees are MPRGP's. The rounds count in
    /// [`BoundedInfo::operator_applications`](crate::BoundedInfo::operator_applications),
    /// not in its iterations, and report no progress (their iterates may leave the
    /// boxes). `0`: MPRGP from the projected unconstrained minimizer. Default: `30`.
    pub active_set_rounds: usize,
}

impl Default for BoundedParams {
    fn default() -> Self {
        BoundedParams {
            tolerance: 1e-3,
            max_iterations: 10_000,
            clamp: None,
            thin_depth: None,
            preconditioner: Preconditioner::Multigrid,
            multigrid: MultigridParams::default(),
            conjugate: true,
            active_set_rounds: 30,
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
    /// The boxes when clamping.
    boxes: Option<Boxes>,
    /// Polled by the multigrid setup and before each iteration (of every phase).
    interrupt: Interrupt,
}

impl BoundedSolver {
    /// The solver of energies on `surface`: its operator ([`MatrixFreeOperator::new`]),
    /// then [`BoundedSolver::new`], with the boxes shrunk around thin voxels when
    /// [`BoundedParams::thin_depth`] is set.
    pub fn for_surface(surface: &DigitalSurface, params: BoundedParams) -> Result<Self, RegularizeError> {
        let mut solver = Self::new(MatrixFreeOperator::new(surface)?, params)?;
        if let (Some(eps), Some(depth)) = (params.clamp, params.thin_depth) {
            // Timed with the operator's structure: the report's `assemble`.
            let t = Instant::now();
            solver.boxes = Some(clamp_boxes(surface, 0.5 * (1.0 - eps), Some(0.5 - depth)));
            solver.setup.structure_seconds += t.elapsed().as_secs_f64();
        }
        Ok(solver)
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
        if let Some(d) = params.thin_depth {
            if !(0.0..0.5).contains(&d) {
                return Err(RegularizeError::InvalidParams(format!(
                    "the thin depth must be in [0, 0.5) voxel, got {d}"
                )));
            }
        }
        let setup = Setup::new(operator, params.preconditioner, params.multigrid)?;
        let boxes =
            params.clamp.map(|eps| Boxes::uniform(setup.stencil.len(), (1.0 - eps) * 0.5 * setup.voxel));
        Ok(BoundedSolver { params, setup, boxes, interrupt: Interrupt::never() })
    }

    /// The parameters.
    pub fn params(&self) -> &BoundedParams {
        &self.params
    }

    /// The flag the next solves poll: once raised, a solve returns
    /// [`RegularizeError::Interrupted`] at its next multigrid level or iteration.
    /// Default: [`Interrupt::never`].
    pub(crate) fn set_interrupt(&mut self, interrupt: Interrupt) {
        self.interrupt = interrupt;
    }

    /// Minimizes `energy` as `request` asks, calling its `progress` after each iteration.
    ///
    /// A given start (one position per vertex) is projected into the boxes: a re-solve
    /// after a small change of the weights or the boxes, from the previous solution, finds
    /// the same minimizer (the problem is convex) with fewer operator products. When
    /// clamping with [`BoundedParams::conjugate`], the active-set rounds start from it (its
    /// coordinates on a bound that the gradient pushes outwards held), instead of from the
    /// unconstrained minimizer, which is not computed; a start whose projection has a
    /// higher energy than the input is dropped for the input. The solver keeps its own
    /// tolerance ([`BoundedParams::tolerance`]) and has no cycle to keep: the request's
    /// `tolerance`, `quick_start` and `keep_cycle` are the conjugate gradient's.
    pub fn solve(
        &mut self,
        energy: &Energy<'_>,
        request: SolveRequest<'_>,
    ) -> Result<(Vec<DVec3>, BoundedInfo), RegularizeError> {
        let mut silent = |_: &Progress| {};
        let progress = request.progress.unwrap_or(&mut silent);
        match request.start {
            SolveStart::Input => self.run(energy, None, progress),
            SolveStart::Given(start) => {
                energy.check_start(start)?;
                self.run(energy, Some(start), progress)
            }
            SolveStart::Owned(start) => {
                energy.check_start(&start)?;
                self.run(energy, Some(&start), progress)
            }
        }
    }

    fn run(
        &mut self,
        energy: &Energy<'_>,
        start: Option<&[DVec3]>,
        progress: &mut dyn FnMut(&Progress),
    ) -> Result<(Vec<DVec3>, BoundedInfo), RegularizeError> {
        let mut prepared = self.setup.prepare(energy, false, &self.interrupt)?;
        let stencil = &self.setup.stencil;
        let n = stencil.len();
        let input = energy.input();
        let h = self.setup.spacing;
        let half = self.boxes.as_ref();

        let t0 = Instant::now();
        // u: displacement from the input; r = -grad E / 2 = b - H u.
        let mut s = Iterate { u: vec![DVec3::ZERO; n], r: vec![DVec3::ZERO; n], ..Iterate::default() };
        // The phases' vectors, and `t` the products' scratch here.
        let mut work = Work::new(n);
        stencil.apply(&prepared.coef, input, &mut s.r, &mut work.t, false);
        s.r.par_iter_mut().for_each(|x| *x = -*x);
        let rhs = s.r.clone();
        let problem = BoxProblem {
            stencil,
            rhs: &rhs,
            tol: self.params.tolerance * h,
            max_iterations: self.params.max_iterations,
            energy0: energy.terms(input).total,
            r0: norm(&rhs),
            alpha_min: energy.min_alpha(),
            h,
            interrupt: &self.interrupt,
        };
        s.energy = problem.energy0;
        s.applications = 1;
        s.estimate = f64::INFINITY;
        if let Some(start) = start {
            // The displacement of the start, inside the boxes; kept where it lowers the
            // energy below the input's.
            s.u.par_iter_mut().zip(input.par_iter().zip(start)).for_each(|(u, (p, x))| *u = *x - *p);
            if let Some(w) = half {
                w.project(&mut s.u);
            }
            let x: Vec<DVec3> = input.par_iter().zip(&s.u).map(|(p, u)| *p + *u).collect();
            let e = energy.terms(&x).total;
            if e <= s.energy && e.is_finite() {
                s.energy = e;
                stencil.residual(&prepared.coef, &s.u, &rhs, &mut s.r, &mut work.t);
                s.applications += 1;
            } else {
                s.u.iter_mut().for_each(|d| *d = DVec3::ZERO);
            }
        }
        let warm = start.is_some() && s.u.iter().any(|d| *d != DVec3::ZERO);
        match (half, self.params.conjugate) {
            (Some(w), true) => {
                self.mprgp(energy, &problem, &mut prepared, w, warm, &mut s, &mut work, progress)
            }
            _ => self.projected_descent(&problem, &mut prepared, half, &mut s, progress),
        }
        // Each phase stopped at its next iteration.
        self.interrupt.check()?;
        let (r0, alpha_min) = (problem.r0, problem.alpha_min);
        let (u, mut r) = (s.u, s.r);
        let (mut applications, iterations, estimate) = (s.applications, s.iterations, s.estimate);
        let coef = &prepared.coef;
        // The certificate, on the true residual (projected in the scratch's place).
        stencil.residual(coef, &u, &rhs, &mut r, &mut work.t);
        applications += 1;
        let mut rp = work.t;
        rp.copy_from_slice(&r);
        let clamped = half.map(|w| {
            project_residual(&u, w, &mut rp);
            w.count_on_bound(&u)
        });
        let rp_norm_true = norm(&rp);
        // The positions in the displacement's own vector.
        let mut x = u;
        x.par_iter_mut().zip(input.par_iter()).for_each(|(u, p)| *u += *p);
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
                start_applications: s.start_applications,
                active_set_rounds: s.active_set_rounds,
                active_set_applications: s.active_set_applications,
                active_set_iterations: s.active_set_iterations,
                relative_gradient: if r0 > 0.0 { rp_norm_true / r0 } else { 0.0 },
                error_bound: bound,
                error_estimate: estimate,
                converged,
                clamp: self.params.clamp,
                clamped_vertices: clamped.unwrap_or(0),
                preconditioner: self.params.preconditioner,
                memory_bytes: memory,
                bytes_per_iteration: traffic,
                seconds: self.setup.timings(&prepared, solve_seconds),
            },
        ))
    }

    /// MPRGP inside the boxes `w`, warm-started from the unconstrained minimizer (the same
    /// iteration without bounds, i.e. PCG) improved by the active-set rounds
    /// ([`BoundedParams::active_set_rounds`]) and projected into the boxes when that lowers
    /// the energy, so that it starts with nearly the right set of clamped coordinates.
    /// With `warm`, `s` holds a feasible start (with its residual and energy) that replaces
    /// the unconstrained minimizer.
    #[allow(clippy::too_many_arguments)]
    fn mprgp(
        &self,
        energy: &Energy<'_>,
        problem: &BoxProblem<'_>,
        prepared: &mut Prepared<'_>,
        w: &Boxes,
        warm: bool,
        s: &mut Iterate,
        work: &mut Work,
        progress: &mut dyn FnMut(&Progress),
    ) {
        let input = energy.input();
        let rounds = self.params.active_set_rounds;
        if !warm {
            // The rounds only need the unconstrained minimizer's binding coordinates, not
            // its last digits: a start as loose as their own first solves.
            let (loose, max_iterations) = if rounds > 0 {
                let most = loose_iterations(prepared, ACTIVE_SET_START_ITERATIONS, problem.max_iterations);
                (ACTIVE_SET_LOOSE, most)
            } else {
                (1.0, problem.max_iterations)
            };
            let start = BoxProblem { max_iterations, ..*problem };
            let free = minimize_free(&start, prepared, problem.tol * loose, &mut s.u, &mut s.r, work);
            s.applications += free.applications;
            s.start_applications = free.applications;
        }
        // What MPRGP starts from if the rounds' projected result is worse: the warm start,
        // or the input.
        let fallback = warm.then(|| (s.u.clone(), s.energy));
        let mut settled = None;
        if rounds > 0 {
            let st = active_set(problem, prepared, w, rounds, &mut s.u, &mut s.r, work);
            // The face's levels (about one multigrid hierarchy) are not used again.
            prepared.pre.forget_face();
            tracing::debug!(
                rounds = st.rounds,
                iterations = st.iterations,
                settled = st.settled,
                "active set"
            );
            s.applications += st.applications;
            s.active_set_rounds = st.rounds;
            s.active_set_applications = st.applications;
            s.active_set_iterations = st.iterations;
            settled = st.settled.then_some((st.estimate, st.gradient));
        }
        w.project(&mut s.u);
        // The projected iterate's positions, in the scratch.
        work.t.par_iter_mut().zip(input.par_iter().zip(&s.u)).for_each(|(x, (p, d))| *x = *p + *d);
        let start = energy.terms(&work.t).total;
        if start <= s.energy {
            s.energy = start;
            if let Some((estimate, rp)) = settled {
                // The rounds settled: no hold changed, so the projection moved nothing and
                // the last round's iterate meets the optimality conditions in the boxes to
                // the tolerance, by MPRGP's own stopping rule. MPRGP would only spend the
                // few steps its estimate needs to see a rate. The iterate is reported as
                // MPRGP's would be: the first inside the boxes.
                s.estimate = estimate;
                progress(&problem.progress(s.active_set_iterations, s.energy, rp, estimate, &s.u));
                return;
            }
        } else if let Some((u, e)) = fallback {
            s.u = u;
            s.energy = e;
        } else {
            // The projection can cost more than it gained: start from the input.
            s.u.iter_mut().for_each(|d| *d = DVec3::ZERO);
        }
        problem.stencil.residual(&prepared.coef, &s.u, problem.rhs, &mut s.r, &mut work.t);
        s.applications += 1;
        let bounded = BoxProblem { energy0: s.energy, ..*problem };
        let stats = minimize_in_boxes(&bounded, prepared, w, &mut s.u, &mut s.r, work, progress);
        s.iterations = stats.iterations;
        s.applications += stats.applications;
        s.estimate = stats.estimate;
        s.energy += stats.energy_change;
    }

    /// Projected preconditioned descent (the papers' iteration, `half = None` without
    /// boxes): each step along `M^-1 r` restricted to the free coordinates, projected into
    /// the boxes, halved until the energy does not increase.
    fn projected_descent(
        &self,
        problem: &BoxProblem<'_>,
        prepared: &mut Prepared<'_>,
        half: Option<&Boxes>,
        s: &mut Iterate,
        progress: &mut dyn FnMut(&Progress),
    ) {
        let BoxProblem { stencil, rhs, tol, r0, alpha_min, h, .. } = *problem;
        let n = s.u.len();
        let zero = || vec![DVec3::ZERO; n];
        let (mut z, mut q, mut tmp, mut trial, mut rp) = (zero(), zero(), zero(), zero(), zero());
        let (u, r) = (&mut s.u, &mut s.r);
        let mut residuals = Vec::new();
        let mut correction = None;
        loop {
            // Projected residual: zero the coordinates held on their box by the gradient.
            rp.copy_from_slice(r);
            if let Some(w) = half {
                project_residual(u, w, &mut rp);
            }
            let rp_norm = norm(&rp);
            residuals.push(rp_norm);
            if let Some(c) = correction {
                s.estimate = 2.0 * tail_estimate_over(c, &residuals, DESCENT_RATE_WINDOW, DESCENT_RATE_CAP);
                progress(&Progress {
                    iteration: s.iterations,
                    energy: s.energy,
                    gradient_norm: 2.0 * rp_norm,
                    relative_gradient: if r0 > 0.0 { rp_norm / r0 } else { 0.0 },
                    error_bound: rp_norm / alpha_min / h,
                    error_estimate: s.estimate / h,
                    displacement: u,
                });
            }
            let done = rp_norm == 0.0 || (half.is_none() && rp_norm <= alpha_min * tol) || s.estimate <= tol;
            if done || s.iterations >= self.params.max_iterations || problem.interrupt.is_raised() {
                break;
            }
            prepared.pre.apply(stencil, &rp, &mut z);
            if let Some(w) = half {
                freeze(u, r, w, &mut z);
            }
            let rd = dot(r, &z);
            stencil.apply(&prepared.coef, &z, &mut q, &mut tmp, true);
            s.applications += 1;
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
                    s.energy -= step * rd;
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
                            .zip(w.chunks())
                            .for_each(|(((t, u), z), (lo, hi))| {
                                for i in 0..t.len() {
                                    t[i] = (u[i] + step * z[i]).clamp(lo[i], hi[i]) - u[i];
                                }
                            });
                        stencil.apply(&prepared.coef, &trial, &mut q, &mut tmp, true);
                        s.applications += 1;
                        de = -2.0 * dot(r, &trial) + dot(&trial, &q);
                        if de <= 0.0 {
                            accepted = true;
                            break;
                        }
                        step *= 0.5;
                    }
                    if !accepted {
                        break;
                    }
                    s.energy += de;
                    u.par_chunks_mut(CHUNK).zip(trial.par_chunks(CHUNK)).for_each(|(u, t)| {
                        for i in 0..u.len() {
                            u[i] += t[i];
                        }
                    });
                    w.project(u);
                    r.par_chunks_mut(CHUNK).zip(q.par_chunks(CHUNK)).for_each(|(r, q)| {
                        r.iter_mut().zip(q).for_each(|(r, q)| *r -= *q);
                    });
                    correction = Some(trial.par_iter().map(|v| v.length()).reduce(|| 0.0, f64::max));
                }
            }
            s.iterations += 1;
            if s.iterations % 50 == 0 {
                // Refresh the residual: the updates drift from b - H u.
                stencil.residual(&prepared.coef, u, rhs, r, &mut tmp);
                s.applications += 1;
            }
        }
    }
}

/// The state of a bounded solve: displacement `u` from the input, residual
/// `r = -grad E / 2`, and what is reported.
#[derive(Default)]
struct Iterate {
    u: Vec<DVec3>,
    r: Vec<DVec3>,
    energy: f64,
    applications: usize,
    iterations: usize,
    estimate: f64,
    start_applications: usize,
    active_set_rounds: usize,
    active_set_applications: usize,
    active_set_iterations: usize,
}

/// Zeroes the residual's coordinates held on their bound.
fn project_residual(u: &[DVec3], b: &Boxes, r: &mut [DVec3]) {
    r.par_chunks_mut(CHUNK).zip(u.par_chunks(CHUNK)).zip(b.chunks()).for_each(|((r, u), (lo, hi))| {
        for i in 0..r.len() {
            for a in 0..3 {
                if place(u[i][a], r[i][a], lo[i][a], hi[i][a]) == Place::Held {
                    r[i][a] = 0.0;
                }
            }
        }
    });
}

/// Zeroes the direction's coordinates held on their bound (by the gradient `r`), so that
/// it stays a descent direction: `r . d = rp^T M^-1 rp > 0`.
fn freeze(u: &[DVec3], r: &[DVec3], b: &Boxes, d: &mut [DVec3]) {
    d.par_chunks_mut(CHUNK).zip(u.par_chunks(CHUNK)).zip(r.par_chunks(CHUNK)).zip(b.chunks()).for_each(
        |(((d, u), r), (lo, hi))| {
            for i in 0..d.len() {
                for a in 0..3 {
                    if place(u[i][a], r[i][a], lo[i][a], hi[i][a]) == Place::Held {
                        d[i][a] = 0.0;
                    }
                }
            }
        },
    );
}
