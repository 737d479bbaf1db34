//! Minimization of the energy over the clamping boxes: a preconditioned variant of
//! Dostál's MPRGP (modified proportioning with reduced gradient projections).
//!
//! The constraint `lo_a <= u_a <= hi_a` (one interval per coordinate of every vertex's
//! displacement `u`, containing 0) makes the problem a bound-constrained convex QP. Plain projected
//! descent converges as slowly as unpreconditioned steepest descent on the smooth modes
//! (thousands of iterations). MPRGP runs conjugate gradients on the current *face* (the
//! coordinates strictly inside their interval), and leaves the face in two ways:
//!
//! - *expansion*: when the CG step would cross a bound, it goes as far as the bound
//!   allows, then takes one projected preconditioned gradient step (with backtracking),
//!   which can put several coordinates on their bounds at once;
//! - *proportioning*: when the gradient pulling bound coordinates back inside (the
//!   *chopped* gradient) dominates the gradient on the face, it steps along it.
//!
//! Every step keeps `u` in the boxes and never increases the energy. The preconditioner
//! (multigrid by default) is restricted to the face: `z = P_F M^-1 P_F r`, symmetric
//! positive definite on the face, so each face solve is an ordinary PCG.

use glam::{DVec3, Vec3A};
use rayon::prelude::*;

use crate::iterative::{Pre, Prepared};
use crate::progress::Progress;
use crate::stencil::{Coefficients, Stencil, CHUNK};
use crate::vecops::{cg_update, dot, scale_add, tail_estimate};
use voxreg_normals::Interrupt;

/// Per-vertex boxes of the displacement from the input: `lo <= u <= hi` coordinate-wise,
/// with `lo <= 0 <= hi` (the input is feasible).
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Boxes {
    pub(crate) lo: Vec<DVec3>,
    pub(crate) hi: Vec<DVec3>,
}

impl Boxes {
    /// The same box `[-w, w]` for each of `n` vertices.
    pub(crate) fn uniform(n: usize, w: DVec3) -> Boxes {
        Boxes { lo: vec![-w; n], hi: vec![w; n] }
    }

    /// `u` projected into the boxes.
    pub(crate) fn project(&self, u: &mut [DVec3]) {
        u.par_chunks_mut(CHUNK).zip(self.chunks()).for_each(|(u, (lo, hi))| {
            for i in 0..u.len() {
                u[i] = u[i].clamp(lo[i], hi[i]);
            }
        });
    }

    /// The coordinates on a bound.
    pub(crate) fn count_on_bound(&self, u: &[DVec3]) -> usize {
        u.iter()
            .zip(self.lo.iter().zip(&self.hi))
            .filter(|(u, (lo, hi))| (0..3).any(|a| place(u[a], 0.0, lo[a], hi[a]) != Place::Inside))
            .count()
    }

    pub(crate) fn chunks(&self) -> impl IndexedParallelIterator<Item = (&[DVec3], &[DVec3])> {
        self.lo.par_chunks(CHUNK).zip(self.hi.par_chunks(CHUNK))
    }
}

/// How a coordinate sits in its interval.
#[derive(Copy, Clone, PartialEq, Eq, Debug)]
pub(crate) enum Place {
    Inside,
    /// On a bound, and the descent direction `r` points out of the interval.
    Held,
    /// On a bound, and `r` points back inside (or is zero).
    Chopped,
}

/// Where `u` sits in `[lo, hi]` given the descent direction `r`.
#[inline]
pub(crate) fn place(u: f64, r: f64, lo: f64, hi: f64) -> Place {
    let tol = 1e-12 * (hi - lo).min(1.0);
    let (at_hi, at_lo) = (u >= hi - tol, u <= lo + tol);
    if (at_hi && r > 0.0) || (at_lo && r < 0.0) || (at_hi && at_lo) {
        Place::Held
    } else if at_hi || at_lo {
        Place::Chopped
    } else {
        Place::Inside
    }
}

/// Splits `r` into its part on the face (`phi`) and its chopped part (`beta`); returns
/// `(|phi|^2, |beta|^2)`.
fn split(u: &[DVec3], r: &[DVec3], b: &Boxes, phi: &mut [DVec3], beta: &mut [DVec3]) -> (f64, f64) {
    phi.par_chunks_mut(CHUNK)
        .zip(beta.par_chunks_mut(CHUNK))
        .zip(u.par_chunks(CHUNK).zip(r.par_chunks(CHUNK)))
        .zip(b.chunks())
        .map(|(((phi, beta), (u, r)), (lo, hi))| {
            let (mut f, mut g) = (0.0, 0.0);
            for i in 0..u.len() {
                for a in 0..3 {
                    let (x, y) = match place(u[i][a], r[i][a], lo[i][a], hi[i][a]) {
                        Place::Inside => (r[i][a], 0.0),
                        Place::Held => (0.0, 0.0),
                        Place::Chopped => (0.0, r[i][a]),
                    };
                    phi[i][a] = x;
                    beta[i][a] = y;
                    f += x * x;
                    g += y * y;
                }
            }
            (f, g)
        })
        .collect::<Vec<_>>()
        .into_iter()
        .fold((0.0, 0.0), |x, y| (x.0 + y.0, x.1 + y.1))
}

/// Zeroes the coordinates of `z` that are not on the face of `u`.
fn restrict_to_face(u: &[DVec3], b: &Boxes, z: &mut [DVec3]) {
    z.par_chunks_mut(CHUNK).zip(u.par_chunks(CHUNK)).zip(b.chunks()).for_each(|((z, u), (lo, hi))| {
        for i in 0..z.len() {
            for a in 0..3 {
                if place(u[i][a], 0.0, lo[i][a], hi[i][a]) != Place::Inside {
                    z[i][a] = 0.0;
                }
            }
        }
    });
}

/// The largest `t >= 0` with `lo <= u + t d <= hi` coordinate-wise.
fn feasible_step(u: &[DVec3], d: &[DVec3], b: &Boxes) -> f64 {
    u.par_chunks(CHUNK)
        .zip(d.par_chunks(CHUNK))
        .zip(b.chunks())
        .map(|((u, d), (lo, hi))| {
            let mut t = f64::INFINITY;
            for i in 0..u.len() {
                for a in 0..3 {
                    let (x, y) = (u[i][a], d[i][a]);
                    if y > 0.0 {
                        t = t.min(((hi[i][a] - x) / y).max(0.0));
                    } else if y < 0.0 {
                        t = t.min(((lo[i][a] - x) / y).max(0.0));
                    }
                }
            }
            t
        })
        .reduce(|| f64::INFINITY, f64::min)
}

/// `u += t d`, `r -= t q`, then `u` clamped (rounding at a bound); returns the largest
/// vertex movement.
fn step(u: &mut [DVec3], r: &mut [DVec3], t: f64, d: &[DVec3], q: &[DVec3], b: &Boxes) -> f64 {
    u.par_chunks_mut(CHUNK)
        .zip(r.par_chunks_mut(CHUNK))
        .zip(d.par_chunks(CHUNK).zip(q.par_chunks(CHUNK)))
        .zip(b.chunks())
        .map(|(((u, r), (d, q)), (lo, hi))| {
            let mut m = 0.0f64;
            for i in 0..u.len() {
                u[i] = (u[i] + t * d[i]).clamp(lo[i], hi[i]);
                r[i] -= t * q[i];
                m = m.max((t * d[i]).length());
            }
            m
        })
        .reduce(|| 0.0, f64::max)
}

/// `trial = P(u + s d) - u`, `P` the projection into the boxes.
fn project_step(u: &[DVec3], d: &[DVec3], s: f64, b: &Boxes, trial: &mut [DVec3]) {
    trial.par_chunks_mut(CHUNK).zip(u.par_chunks(CHUNK)).zip(d.par_chunks(CHUNK)).zip(b.chunks()).for_each(
        |(((t, u), d), (lo, hi))| {
            for i in 0..t.len() {
                t[i] = (u[i] + s * d[i]).clamp(lo[i], hi[i]) - u[i];
            }
        },
    );
}

/// What [`minimize_in_boxes`] reports.
pub(crate) struct BoxStats {
    pub(crate) iterations: usize,
    pub(crate) applications: usize,
    pub(crate) estimate: f64,
    pub(crate) energy_change: f64,
}

/// The fixed data of a bound-constrained minimization: `E(input + u)` with
/// `r = rhs - H u`, for the progress reports and the stopping rule.
pub(crate) struct BoxProblem<'a> {
    pub(crate) stencil: &'a Stencil,
    /// `-grad E / 2` at the input.
    pub(crate) rhs: &'a [DVec3],
    /// The stopping tolerance in physical units (see [`crate::BoundedParams::tolerance`]).
    pub(crate) tol: f64,
    pub(crate) max_iterations: usize,
    /// The energy at the starting `u`.
    pub(crate) energy0: f64,
    /// `|rhs|`, the unit of relative gradients.
    pub(crate) r0: f64,
    /// The smallest attachment weight and the smallest spacing, for the error bounds.
    pub(crate) alpha_min: f64,
    pub(crate) h: f64,
    /// Every phase stops at its next iteration once it is raised (the caller reports it).
    pub(crate) interrupt: &'a Interrupt,
}

impl BoxProblem<'_> {
    /// The progress report of an iterate `input + u` of energy `energy`, whose projected
    /// residual has norm `rp` (half the projected gradient's) and whose error estimate is
    /// `estimate` (physical units).
    pub(crate) fn progress<'u>(
        &self,
        iteration: usize,
        energy: f64,
        rp: f64,
        estimate: f64,
        u: &'u [DVec3],
    ) -> Progress<'u> {
        Progress {
            iteration,
            energy,
            gradient_norm: 2.0 * rp,
            relative_gradient: if self.r0 > 0.0 { rp / self.r0 } else { 0.0 },
            error_bound: rp / self.alpha_min / self.h,
            error_estimate: estimate / self.h,
            displacement: u,
        }
    }
}

/// Minimizes `E(input + u)` over the boxes `b` (MPRGP), from `u` (feasible), where
/// `r = rhs - H u` on entry.
pub(crate) fn minimize_in_boxes(
    problem: &BoxProblem<'_>,
    prepared: &mut Prepared<'_>,
    w: &Boxes,
    u: &mut [DVec3],
    r: &mut [DVec3],
    work: &mut Work,
    progress: &mut dyn FnMut(&Progress),
) -> BoxStats {
    let BoxProblem { stencil, rhs, tol, max_iterations, energy0, interrupt, .. } = *problem;
    let n = u.len();
    let coef = &prepared.coef;
    let zero = || vec![DVec3::ZERO; n];
    let (mut phi, mut beta, mut trial, mut tq) = (zero(), zero(), zero(), zero());
    let Work { z, p, q, t } = work;
    let (z, p, q, t) = (&mut z[..], &mut p[..], &mut q[..], &mut t[..]);
    let mut applications = 0;
    let mut iterations = 0;
    let mut residuals = Vec::new();
    let mut estimate = f64::INFINITY;
    let mut de_total = 0.0;
    let mut restart = true;
    let mut rz = 0.0;
    // Gamma of MPRGP: proportioning when |beta| > GAMMA |phi|.
    const GAMMA: f64 = 1.0;
    loop {
        let (f2, b2) = split(u, r, w, &mut phi, &mut beta);
        let rp = (f2 + b2).sqrt();
        residuals.push(rp);
        if iterations > 0 {
            progress(&problem.progress(iterations, energy0 + de_total, rp, estimate, u));
        }
        if rp == 0.0 || estimate <= tol || iterations >= max_iterations || interrupt.is_raised() {
            break;
        }
        iterations += 1;
        let correction;
        if b2 > GAMMA * GAMMA * f2 {
            // Proportioning: release coordinates from their bounds along beta.
            stencil.apply(coef, &beta, q, t, true);
            applications += 1;
            let bq = dot(&beta, q);
            let a = if bq > 0.0 { b2 / bq } else { f64::INFINITY };
            let a = a.min(feasible_step(u, &beta, w));
            if !(a > 0.0 && a.is_finite()) {
                break;
            }
            de_total += -2.0 * a * b2 + a * a * bq;
            correction = step(u, r, a, &beta, q, w);
            restart = true;
        } else {
            // Conjugate gradient on the face.
            prepared.pre.apply(stencil, &phi, z);
            restrict_to_face(u, w, z);
            let rz_new = dot(&phi, z);
            if rz_new.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
                break;
            }
            if restart {
                p.copy_from_slice(z);
            } else {
                let s = rz_new / rz;
                p.par_chunks_mut(CHUNK).zip(z.par_chunks(CHUNK)).for_each(|(p, z)| {
                    p.iter_mut().zip(z).for_each(|(p, z)| *p = *p * s + *z);
                });
            }
            rz = rz_new;
            restart = false;
            stencil.apply(coef, p, q, t, true);
            applications += 1;
            let pq = dot(p, q);
            if pq.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
                break;
            }
            let rpd = dot(r, p);
            let a_cg = rpd / pq;
            let a_f = feasible_step(u, p, w);
            if a_cg <= a_f {
                de_total += -2.0 * a_cg * rpd + a_cg * a_cg * pq;
                correction = step(u, r, a_cg, p, q, w);
            } else if let Some((de, moved)) = {
                // Expansion, projected: the full CG step projected into the boxes, which
                // puts every coordinate it crosses on its bound at once; taken when it
                // does better than stopping at the first bound.
                project_step(u, p, a_cg, w, &mut trial);
                stencil.apply(coef, &trial, &mut tq, t, true);
                applications += 1;
                let de = -2.0 * dot(r, &trial) + dot(&trial, &tq);
                (de <= -2.0 * a_f * rpd + a_f * a_f * pq).then(|| (de, step(u, r, 1.0, &trial, &tq, w)))
            } {
                de_total += de;
                correction = moved;
                restart = true;
            } else {
                // Expansion: to the bound, then one projected preconditioned gradient
                // step with backtracking.
                de_total += -2.0 * a_f * rpd + a_f * a_f * pq;
                let c0 = step(u, r, a_f, p, q, w);
                split(u, r, w, &mut phi, &mut beta);
                prepared.pre.apply(stencil, &phi, z);
                restrict_to_face(u, w, z);
                stencil.apply(coef, z, q, t, true);
                applications += 1;
                let (rz1, zq) = (dot(r, z), dot(z, q));
                let mut moved = 0.0;
                if rz1 > 0.0 && zq > 0.0 {
                    let mut s = rz1 / zq;
                    for _ in 0..30 {
                        project_step(u, z, s, w, &mut trial);
                        stencil.apply(coef, &trial, &mut tq, t, true);
                        applications += 1;
                        let de = -2.0 * dot(r, &trial) + dot(&trial, &tq);
                        if de <= 0.0 {
                            de_total += de;
                            moved = step(u, r, 1.0, &trial, &tq, w);
                            break;
                        }
                        s *= 0.5;
                    }
                }
                correction = c0.max(moved);
                restart = true;
            }
        }
        estimate = 2.0 * tail_estimate(correction, &residuals[residuals.len().saturating_sub(6)..]);
        if iterations % 50 == 0 {
            // Refresh the residual: the updates drift from rhs - H u.
            stencil.residual(coef, u, rhs, r, t);
            applications += 1;
        }
    }
    BoxStats { iterations, applications, estimate, energy_change: de_total }
}

/// Minimizes `E(input + u)` without bounds from `u` (`r = rhs - H u` on entry) by
/// preconditioned CG, to `tol` (the stopping rule of [`minimize_in_boxes`]): the
/// unconstrained start of the active-set rounds. The same iteration as
/// [`minimize_in_boxes`] in boxes that never bind, without its passes over the boxes.
pub(crate) fn minimize_free(
    problem: &BoxProblem<'_>,
    prepared: &mut Prepared<'_>,
    tol: f64,
    u: &mut [DVec3],
    r: &mut [DVec3],
    work: &mut Work,
) -> BoxStats {
    let BoxProblem { stencil, max_iterations, interrupt, .. } = *problem;
    let Prepared { coef, pre, .. } = prepared;
    let cg = Cg { stencil, coef, tol, max_iterations, interrupt, lagged_rate: true };
    let run = cg.run(u, r, work, |r, z| pre.apply(stencil, r, z), |_, r2| r2.sqrt());
    BoxStats {
        iterations: run.iterations,
        applications: run.applications,
        estimate: run.estimate,
        energy_change: run.energy_change,
    }
}

/// The vectors of [`Cg::run`] and [`minimize_in_boxes`]: one set (96 bytes per vertex)
/// for every phase of a bounded solve, each writing every entry before reading it, rather
/// than fresh memory for the system to zero again in each phase.
pub(crate) struct Work {
    z: Vec<DVec3>,
    p: Vec<DVec3>,
    q: Vec<DVec3>,
    /// Also the operator's scratch for the callers' own products.
    pub(crate) t: Vec<DVec3>,
}

impl Work {
    pub(crate) fn new(n: usize) -> Work {
        #[cfg(test)]
        let fill = if tests::POISONED_WORK.with(|p| p.get()) { DVec3::NAN } else { DVec3::ZERO };
        #[cfg(not(test))]
        let fill = DVec3::ZERO;
        let vector = || vec![fill; n];
        Work { z: vector(), p: vector(), q: vector(), t: vector() }
    }
}

/// Preconditioned CG on `H`, shared by the unconstrained start and the active-set rounds;
/// the preconditioner and the residual's norm passed to [`Cg::run`] choose the space it
/// runs on (every coordinate, or a face's free ones). The norm is given `r` and `|r|^2`
/// over every coordinate.
struct Cg<'a, 'c> {
    stencil: &'a Stencil,
    coef: &'a Coefficients<'c>,
    /// The stopping tolerance (physical units) of the error estimate.
    tol: f64,
    max_iterations: usize,
    interrupt: &'a Interrupt,
    /// The estimate's rate from the residuals before each step (as in
    /// [`minimize_in_boxes`]) rather than after it.
    lagged_rate: bool,
}

/// What [`Cg::run`] did.
struct CgRun {
    iterations: usize,
    applications: usize,
    estimate: f64,
    /// The energy's change, `-a rz` summed over the steps.
    energy_change: f64,
}

impl Cg<'_, '_> {
    /// Iterates from `u` (`r = rhs - H u` on entry, kept so) until the error estimate is
    /// at most `tol`, `max_iterations` steps, or the interrupt.
    fn run(
        &self,
        u: &mut [DVec3],
        r: &mut [DVec3],
        work: &mut Work,
        mut precondition: impl FnMut(&[DVec3], &mut [DVec3]),
        norm: impl Fn(&[DVec3], f64) -> f64,
    ) -> CgRun {
        let Work { z, p, q, t } = work;
        let mut run = CgRun { iterations: 0, applications: 0, estimate: f64::INFINITY, energy_change: 0.0 };
        let mut residuals = vec![norm(r, dot(r, r))];
        precondition(r, p);
        let mut rz = dot(r, p);
        while rz > 0.0 && run.iterations < self.max_iterations && !self.interrupt.is_raised() {
            self.stencil.apply(self.coef, p, q, t, true);
            run.applications += 1;
            let pq = dot(p, q);
            if pq.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
                break;
            }
            let a = rz / pq;
            // E changes by -2 a (r . p) + a^2 (p . q), with r . p = r . z = rz.
            run.energy_change += -2.0 * a * rz + a * a * pq;
            let (r2, p2) = cg_update(u, r, a, p, q);
            run.iterations += 1;
            if self.lagged_rate {
                run.estimate = 2.0 * tail_estimate(a * p2.sqrt(), &residuals);
                residuals.push(norm(r, r2));
            } else {
                residuals.push(norm(r, r2));
                run.estimate = 2.0 * tail_estimate(a * p2.sqrt(), &residuals);
            }
            if run.estimate <= self.tol {
                break;
            }
            precondition(r, z);
            let rz_new = dot(r, z);
            scale_add(p, rz_new / rz, z);
            rz = rz_new;
        }
        run
    }
}

/// The factor of the tolerance at which the active-set rounds stop their CG while the
/// holds change, and at which the unconstrained start before them stops.
pub(crate) const ACTIVE_SET_LOOSE: f64 = 100.0;

/// The most CG iterations of an active-set round while the holds change, with the
/// multigrid preconditioner: such a round only has to show which coordinates cross their
/// bounds, and the next round, on another face, starts from its iterate.
pub(crate) const ACTIVE_SET_LOOSE_ITERATIONS: usize = 3;

/// The most CG iterations of the unconstrained start before the active-set rounds, with
/// the multigrid preconditioner: like a loose round, it only shows which coordinates
/// cross their bounds.
pub(crate) const ACTIVE_SET_START_ITERATIONS: usize = 4;

/// At most `cap` of the `remaining` iterations with the multigrid preconditioner, which
/// solves most of a problem in a few; all of them with the others.
pub(crate) fn loose_iterations(prepared: &Prepared<'_>, cap: usize, remaining: usize) -> usize {
    match prepared.pre {
        Pre::Multigrid(_) => cap.min(remaining),
        _ => remaining,
    }
}

/// How the active-set phase treats a coordinate: free, or held on its lower or upper
/// bound.
#[derive(Copy, Clone, PartialEq, Eq, Debug, Default)]
enum Hold {
    #[default]
    Free,
    Lo,
    Hi,
}

/// What [`active_set`] reports.
pub(crate) struct ActiveSetStats {
    /// Conjugate gradient iterations, all rounds together.
    pub(crate) iterations: usize,
    pub(crate) applications: usize,
    /// Rounds run (face solves).
    pub(crate) rounds: usize,
    /// Whether the last round changed no coordinate's hold: the face solve is then a
    /// minimizer in the boxes to its tolerance (up to the final projection).
    pub(crate) settled: bool,
    /// The last round's error estimate (physical units).
    pub(crate) estimate: f64,
    /// When settled, the norm of the last round's residual on its free coordinates (the
    /// projected gradient's, halved).
    pub(crate) gradient: f64,
}

/// The primal-dual active-set iteration (semismooth Newton for bounds, Hintermüller, Ito
/// and Kunisch 2003), from the unconstrained minimizer `u` (`r = rhs - H u`), at most
/// `max_rounds` rounds.
///
/// Each round holds a set of coordinates on their bounds and minimizes over the others
/// as the unconstrained solve does: preconditioned CG (with the multigrid cycle of the
/// face's operator, its own Galerkin coarse levels included,
/// [`Pre::apply_on_face`](crate::iterative::Pre::apply_on_face)),
/// warm-started from the previous round and stopped by the same estimate rule (at
/// `100 tol`, or after [`ACTIVE_SET_LOOSE_ITERATIONS`] iterations of multigrid CG, while
/// the holds change, then at `tol`). Then every free coordinate outside its interval is
/// held on the bound it crossed, and every held coordinate whose gradient pulls it back
/// inside is freed. When
/// no hold changes, the iterate satisfies the optimality conditions of the box problem.
/// Inexact rounds can cycle (a coordinate freed and held in turn): a loose round that
/// changes at least as many holds as the one before ends the loose rounds, and a second
/// such round at the tolerance ends the phase ([`RoundRule`]).
/// Unlike MPRGP, whose CG restarts each time a step meets a bound (once every two
/// iterations on voxel art, where thousands of coordinates bind), a round changes many
/// holds at once, and a few rounds settle. Iterates may leave the boxes: the caller
/// projects the result and, unless the rounds settled (the projection then moves
/// nothing), finishes with [`minimize_in_boxes`], which keeps the guarantees whatever
/// this phase did.
pub(crate) fn active_set(
    problem: &BoxProblem<'_>,
    prepared: &mut Prepared<'_>,
    w: &Boxes,
    max_rounds: usize,
    u: &mut [DVec3],
    r: &mut [DVec3],
    work: &mut Work,
) -> ActiveSetStats {
    let BoxProblem { stencil, rhs, tol, max_iterations, interrupt, .. } = *problem;
    let n = u.len();
    let mut hold = vec![[Hold::Free; 3]; n];
    let mut stats = ActiveSetStats {
        iterations: 0,
        applications: 0,
        rounds: 0,
        settled: false,
        estimate: f64::INFINITY,
        gradient: f64::INFINITY,
    };
    // The first holds: the coordinates the start puts outside (the unconstrained
    // minimizer), or on a bound with the gradient pushing them out (a warm start inside
    // the boxes).
    update_holds(u, r, w, &mut hold);
    hold_pushed_out(u, r, w, &mut hold);
    // Rounds whose holds still change need no accurate face solve: they stop at
    // `LOOSE` times the tolerance or after a few iterations, until one changes nothing
    // (or no fewer than the round before); then rounds at the tolerance, warm, make it
    // exact.
    const LOOSE: f64 = ACTIVE_SET_LOOSE;
    let mut loose = LOOSE;
    let mut rule = RoundRule::default();
    let mut face = vec![Vec3A::ONE; n];
    while stats.rounds < max_rounds && stats.iterations < max_iterations && !interrupt.is_raised() {
        stats.rounds += 1;
        hold_on_bounds(&hold, w, u);
        face_of(&hold, &mut face);
        // Later rounds change few holds: their face's levels are updated, not rebuilt.
        prepared.pre.set_face(stencil, &prepared.coef, &face, stats.rounds > 1);
        stencil.residual(&prepared.coef, u, rhs, r, &mut work.t);
        stats.applications += 1;
        // Preconditioned CG on the free coordinates; the face's preconditioner masks its
        // input, so `r` goes in as it is.
        let remaining = max_iterations - stats.iterations;
        let max_iterations = if loose > 1.0 {
            loose_iterations(prepared, ACTIVE_SET_LOOSE_ITERATIONS, remaining)
        } else {
            remaining
        };
        let Prepared { coef, pre, .. } = &mut *prepared;
        let cg = Cg { stencil, coef, tol: tol * loose, max_iterations, interrupt, lagged_rate: false };
        let run =
            cg.run(u, r, work, |r, z| pre.apply_on_face(stencil, r, z, &face), |r, _| free_norm(&hold, r));
        stats.iterations += run.iterations;
        stats.applications += run.applications;
        stats.estimate = run.estimate;
        // The multipliers' signs are read from the recursive residual (CG updates it on
        // the held coordinates too); the next round starts from a true one.
        let changes = update_holds(u, r, w, &mut hold);
        match rule.next(changes, loose > 1.0) {
            Round::Loose => {}
            Round::Tight => loose = 1.0,
            Round::Settled => {
                stats.gradient = free_norm(&hold, r);
                stats.settled = true;
                break;
            }
            Round::Stop => break,
        }
    }
    stats
}

/// What follows an active-set round.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
enum Round {
    /// Another loose round.
    Loose,
    /// Rounds at the tolerance from now on.
    Tight,
    /// The holds are those of the minimizer in the boxes.
    Settled,
    /// The rounds do not converge: the caller's MPRGP finishes.
    Stop,
}

/// What follows each active-set round, from the number of holds it changed: no change
/// ends the loose rounds, or settles at the tolerance; no fewer changes than the last
/// round that changed any (a coordinate freed and held in turn, which inexact rounds can
/// do) ends the loose rounds, and the second time at the tolerance ends the phase (the
/// first may be a round at the tolerance finishing what the loose ones left).
#[derive(Clone, Debug)]
struct RoundRule {
    /// Changes of the last round that changed any (`usize::MAX` before).
    last: usize,
    /// Rounds at the tolerance that changed no fewer holds than the one before.
    tight_stalls: usize,
}

impl Default for RoundRule {
    fn default() -> Self {
        RoundRule { last: usize::MAX, tight_stalls: 0 }
    }
}

impl RoundRule {
    fn next(&mut self, changes: usize, loose: bool) -> Round {
        if changes == 0 {
            return if loose { Round::Tight } else { Round::Settled };
        }
        let stalled = changes >= self.last;
        self.last = changes;
        match (stalled, loose) {
            (false, true) => Round::Loose,
            (false, false) | (true, true) => Round::Tight,
            (true, false) => {
                self.tight_stalls += 1;
                if self.tight_stalls > 1 {
                    Round::Stop
                } else {
                    Round::Tight
                }
            }
        }
    }
}

/// Updates the holds from `u` and `r`: a free coordinate outside its interval is held on
/// the bound it crossed; a held one is freed when `r` (the descent direction) points
/// back inside. Returns the number of changes.
fn update_holds(u: &[DVec3], r: &[DVec3], b: &Boxes, hold: &mut [[Hold; 3]]) -> usize {
    hold.par_chunks_mut(CHUNK)
        .zip(u.par_chunks(CHUNK).zip(r.par_chunks(CHUNK)))
        .zip(b.chunks())
        .map(|((hold, (u, r)), (lo, hi))| {
            let mut changes = 0;
            for i in 0..hold.len() {
                for a in 0..3 {
                    let new = match hold[i][a] {
                        _ if lo[i][a] >= hi[i][a] => Hold::Lo,
                        Hold::Free if u[i][a] > hi[i][a] => Hold::Hi,
                        Hold::Free if u[i][a] < lo[i][a] => Hold::Lo,
                        Hold::Hi if r[i][a] <= 0.0 => Hold::Free,
                        Hold::Lo if r[i][a] >= 0.0 => Hold::Free,
                        h => h,
                    };
                    changes += usize::from(new != hold[i][a]);
                    hold[i][a] = new;
                }
            }
            changes
        })
        .sum()
}

/// Holds the free coordinates that sit on a bound with `r` pointing out of the interval.
fn hold_pushed_out(u: &[DVec3], r: &[DVec3], b: &Boxes, hold: &mut [[Hold; 3]]) {
    hold.par_chunks_mut(CHUNK).zip(u.par_chunks(CHUNK).zip(r.par_chunks(CHUNK))).zip(b.chunks()).for_each(
        |((hold, (u, r)), (lo, hi))| {
            for i in 0..hold.len() {
                for a in 0..3 {
                    if hold[i][a] == Hold::Free && place(u[i][a], r[i][a], lo[i][a], hi[i][a]) == Place::Held
                    {
                        hold[i][a] =
                            if hi[i][a] - u[i][a] <= u[i][a] - lo[i][a] { Hold::Hi } else { Hold::Lo };
                    }
                }
            }
        },
    );
}

/// `face` = 1 on the free coordinates, 0 on the held ones.
fn face_of(hold: &[[Hold; 3]], face: &mut [Vec3A]) {
    face.par_chunks_mut(CHUNK).zip(hold.par_chunks(CHUNK)).for_each(|(f, hold)| {
        for i in 0..f.len() {
            let g = |a: usize| if hold[i][a] == Hold::Free { 1.0 } else { 0.0 };
            f[i] = Vec3A::new(g(0), g(1), g(2));
        }
    });
}

/// Puts the held coordinates of `u` on their bounds.
fn hold_on_bounds(hold: &[[Hold; 3]], b: &Boxes, u: &mut [DVec3]) {
    u.par_chunks_mut(CHUNK).zip(hold.par_chunks(CHUNK)).zip(b.chunks()).for_each(|((u, hold), (lo, hi))| {
        for i in 0..u.len() {
            for a in 0..3 {
                match hold[i][a] {
                    Hold::Free => {}
                    Hold::Lo => u[i][a] = lo[i][a],
                    Hold::Hi => u[i][a] = hi[i][a],
                }
            }
        }
    });
}

/// The norm of `r` on the free coordinates (the held ones zeroed).
fn free_norm(hold: &[[Hold; 3]], r: &[DVec3]) -> f64 {
    crate::vecops::ordered(r.par_chunks(CHUNK).zip(hold.par_chunks(CHUNK)).map(|(r, hold)| {
        let mut s = 0.0;
        for i in 0..r.len() {
            let mut m = r[i];
            for a in 0..3 {
                if hold[i][a] != Hold::Free {
                    m[a] = 0.0;
                }
            }
            s += m.dot(m);
        }
        s
    }))
    .sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    thread_local! {
        /// Whether [`Work::new`] fills its vectors with NaN on this thread.
        pub(super) static POISONED_WORK: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
    }

    /// The phases of a bounded solve share one [`Work`]: each must write every entry
    /// before reading it. With the vectors full of NaN at the start, any entry read first
    /// would spread through the dot products into the result.
    #[test]
    fn every_phase_writes_the_shared_vectors_before_reading_them() {
        use crate::bounded::{BoundedParams, BoundedSolver};
        use crate::energy::{Energy, EnergyParams};
        use crate::request::SolveRequest;
        use voxreg_digisurf::DigitalSurface;
        use voxreg_normals::NormalField;
        use voxreg_testkit::{digitize, true_normals, Sphere};
        let shape = Sphere { radius: 5.0 };
        let s = DigitalSurface::from_volume(&digitize(&shape, 1.0)).unwrap();
        let normals = NormalField::new(true_normals(&s, &shape));
        let input = s.positions();
        let energy =
            Energy::new(&s, &normals, &input, EnergyParams { alpha: 1e-3, ..Default::default() }).unwrap();
        // MPRGP alone, one round then MPRGP, and rounds until they settle.
        for rounds in [0, 1, 30] {
            let params = BoundedParams { clamp: Some(0.01), active_set_rounds: rounds, ..Default::default() };
            let solve = |poisoned: bool| {
                POISONED_WORK.with(|p| p.set(poisoned));
                let out =
                    BoundedSolver::for_surface(&s, params).unwrap().solve(&energy, SolveRequest::default());
                POISONED_WORK.with(|p| p.set(false));
                out.unwrap()
            };
            let (clean, info) = solve(false);
            let (poisoned, _) = solve(true);
            assert!(info.converged && info.clamped_vertices > 0, "{rounds} rounds: {info:?}");
            if rounds < 30 {
                assert!(info.iterations > 0, "{rounds} rounds: MPRGP did not run: {info:?}");
            }
            assert_eq!(clean, poisoned, "{rounds} rounds");
        }
    }

    #[test]
    fn rounds_end_when_the_holds_stop_settling() {
        use Round::*;
        let run = |rounds: &[(usize, bool)]| {
            let mut rule = RoundRule::default();
            rounds.iter().map(|&(changes, loose)| rule.next(changes, loose)).collect::<Vec<_>>()
        };
        // Fewer changes each round, then none: loose, then tight, then settled.
        assert_eq!(
            run(&[(40, true), (12, true), (0, true), (3, false), (0, false)]),
            [Loose, Loose, Tight, Tight, Settled]
        );
        // A loose round changing as many holds as the last one that changed any ends the
        // loose rounds (one coordinate freed and held in turn).
        assert_eq!(run(&[(40, true), (5, true), (0, true)]), [Loose, Loose, Tight]);
        assert_eq!(run(&[(40, true), (5, true), (5, true)]), [Loose, Loose, Tight]);
        // At the tolerance, the second stall ends the phase, the first does not.
        assert_eq!(run(&[(9, true), (22, true), (22, false), (22, false)]), [Loose, Tight, Tight, Stop]);
        assert_eq!(
            run(&[(9, true), (9, true), (4, false), (5, false), (2, false), (2, false)]),
            [Loose, Tight, Tight, Tight, Tight, Stop]
        );
    }

    #[test]
    fn places_and_feasible_steps() {
        assert!(place(0.5, 1.0, -0.5, 0.5) == Place::Held);
        assert!(place(0.5, -1.0, -0.5, 0.5) == Place::Chopped);
        assert!(place(-0.5, -1.0, -0.5, 0.5) == Place::Held);
        assert!(place(0.2, 1.0, -0.5, 0.5) == Place::Inside);
        // A coordinate whose interval is a point is held whatever the direction.
        assert!(place(0.0, -1.0, 0.0, 0.0) == Place::Held && place(0.0, 1.0, 0.0, 0.0) == Place::Held);
        let b = Boxes::uniform(1, DVec3::splat(0.5));
        let u = vec![DVec3::new(0.0, 0.25, -0.5)];
        let d = vec![DVec3::new(1.0, 1.0, 0.0)];
        assert_eq!(feasible_step(&u, &d, &b), 0.25);
        let d = vec![DVec3::new(0.0, 0.0, -1.0)];
        assert_eq!(feasible_step(&u, &d, &b), 0.0);
        // Asymmetric: room 0.1 upwards along x.
        let b = Boxes { lo: vec![DVec3::splat(-0.5)], hi: vec![DVec3::new(0.1, 0.5, 0.5)] };
        let d = vec![DVec3::new(1.0, 0.0, 0.0)];
        assert_eq!(feasible_step(&[DVec3::ZERO], &d, &b), 0.1);
    }
}
