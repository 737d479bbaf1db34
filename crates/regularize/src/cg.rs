//! Preconditioned conjugate gradient on the energy's linear system, matrix-free.

use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;
use voxreg_digisurf::DigitalSurface;

use crate::energy::Energy;
use crate::error::RegularizeError;
use crate::info::{CgInfo, Preconditioner};
use crate::iterative::Setup;
use crate::multigrid::MultigridParams;
use crate::progress::Progress;
use crate::request::{SolveRequest, SolveStart};
use crate::stencil::MatrixFreeOperator;
use crate::stencil::{Coefficients, Stencil, CHUNK};
use crate::vecops::{cg_update, dot, norm, scale_add, tail_estimate};
use voxreg_normals::Interrupt;

/// When an iterative solver stops.
#[derive(Copy, Clone, Debug, PartialEq, Eq, Default, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum StoppingRule {
    /// Stop when the *estimated* largest distance of a vertex to the exact minimizer is at
    /// most the tolerance: the largest vertex correction of the last iteration,
    /// `max_i |x_i^(k+1) - x_i^(k)|`, extrapolated as a geometric series with the recent
    /// residual reduction rate `rho` and a safety factor of 2: `2 correction / (1 - rho)`.
    /// Measured with the multigrid preconditioner on spheres, tori and random volumes, the
    /// true error at the stop is 2 to 10 times below the tolerance (see the crate's
    /// tests), but it is an estimate: with weaker preconditioners CG can plateau (the
    /// error stalls while the corrections are tiny) and stop early; use
    /// [`StoppingRule::Guaranteed`] with those.
    #[default]
    Estimate,
    /// Stop when the distance of every vertex to the exact minimizer is *guaranteed* below
    /// the tolerance: since `H >= alpha_min I`, the error `e` of an iterate with residual
    /// `r = -grad E / 2` obeys `max_i |e_i| <= |e|_2 <= |r|_2 / alpha_min`. About twice
    /// the iterations of [`StoppingRule::Estimate`]: the bound is pessimistic by 2 to 3
    /// orders of magnitude on typical surfaces.
    Guaranteed,
}

/// Parameters of [`CgSolver`].
#[derive(Copy, Clone, Debug, PartialEq, serde::Serialize)]
pub struct CgParams {
    /// Tolerance of the [`StoppingRule`], in voxels (physical tolerance `tolerance * h`,
    /// `h` the smallest voxel spacing). Default: `1e-3`.
    pub tolerance: f64,
    /// How the tolerance is read. Default: [`StoppingRule::Estimate`].
    pub stopping: StoppingRule,
    /// Give up after this many iterations (the result is then returned, with its bound,
    /// and [`CgInfo::converged`](crate::CgInfo::converged) false). Default: `5000`.
    pub max_iterations: usize,
    /// The preconditioner. Default: [`Preconditioner::Multigrid`].
    pub preconditioner: Preconditioner,
    /// Multigrid settings. Default: [`MultigridParams::default`].
    pub multigrid: MultigridParams,
}

impl Default for CgParams {
    fn default() -> Self {
        CgParams {
            tolerance: 1e-3,
            stopping: StoppingRule::Estimate,
            max_iterations: 5000,
            preconditioner: Preconditioner::Multigrid,
            multigrid: MultigridParams::default(),
        }
    }
}

/// A preconditioned conjugate gradient solver for the energy's linear system
/// `H x = alpha p`, reusable across solves on one surface.
///
/// [`CgSolver::new`] builds the surface's connectivity for the matrix-free operator
/// ([`Operator`](crate::Operator) is never assembled) and, for the multigrid
/// preconditioner, the aggregation hierarchy; each [`CgSolver::solve`] only computes the
/// coefficients (and coarse operators) of its energy, then iterates from the input
/// positions, solving for the displacement like [`crate::DirectSolver`]. Memory: about
/// 0.6 KiB per vertex with multigrid (see [`CgInfo::memory_bytes`](crate::CgInfo::memory_bytes)).
#[derive(Debug)]
pub struct CgSolver {
    params: CgParams,
    setup: Setup,
    /// Whether solves from a given start begin on the last solve's multigrid cycle
    /// ([`SolveRequest::quick_start`]).
    quick_start: bool,
    /// Polled by the multigrid setup (between levels) and before each iteration.
    interrupt: Interrupt,
}

/// The true residual `r = b - H u` without `b = -(H - diag(alpha)) p`: as
/// `-(H - diag(alpha)) (p + u) - diag(alpha) u`, where `H - diag(alpha)` only sees
/// differences of positions (`x` and `t` are scratch).
fn true_residual(
    stencil: &Stencil,
    coef: &Coefficients<'_>,
    p: &[DVec3],
    u: &[DVec3],
    r: &mut [DVec3],
    x: &mut [DVec3],
    t: &mut [DVec3],
) {
    x.par_chunks_mut(CHUNK)
        .zip(p.par_chunks(CHUNK).zip(u.par_chunks(CHUNK)))
        .for_each(|(x, (p, u))| x.iter_mut().zip(p.iter().zip(u)).for_each(|(x, (p, u))| *x = *p + *u));
    stencil.apply(coef, x, r, t, false);
    r.par_chunks_mut(CHUNK).zip(u.par_chunks(CHUNK)).enumerate().for_each(|(k, (r, u))| {
        for (i, (r, u)) in r.iter_mut().zip(u).enumerate() {
            *r = -*r - coef.alpha.get(k * CHUNK + i) * *u;
        }
    });
}

/// Where a solve starts: the input positions, or given ones (borrowed, or taken so that
/// their vector becomes the iterate's).
enum Start<'s> {
    Input,
    Given(&'s [DVec3]),
    Taken(Vec<DVec3>),
}

/// Work vectors of one solve.
struct Buffers {
    u: Vec<DVec3>,
    r: Vec<DVec3>,
    /// The preconditioned residual, and the operator's scratch once `p` has taken it in
    /// (one vector fewer held during the solve).
    z: Vec<DVec3>,
    p: Vec<DVec3>,
    /// `H p`, and the preconditioner's scratch once the update has taken it in.
    q: Vec<DVec3>,
}

pub(crate) fn check_tolerance(tolerance: f64) -> Result<(), RegularizeError> {
    if tolerance > 0.0 && tolerance.is_finite() {
        Ok(())
    } else {
        Err(RegularizeError::InvalidParams(format!(
            "the tolerance must be positive and finite, got {tolerance}"
        )))
    }
}

impl CgSolver {
    /// The solver of energies on `surface`: its operator ([`MatrixFreeOperator::new`]),
    /// then [`CgSolver::new`].
    pub fn for_surface(surface: &DigitalSurface, params: CgParams) -> Result<Self, RegularizeError> {
        Self::new(MatrixFreeOperator::new(surface)?, params)
    }

    /// The solver of energies with the matrix-free `operator`.
    pub fn new(operator: MatrixFreeOperator, params: CgParams) -> Result<Self, RegularizeError> {
        check_tolerance(params.tolerance)?;
        Ok(CgSolver {
            params,
            setup: Setup::new(operator, params.preconditioner, params.multigrid)?,
            quick_start: false,
            interrupt: Interrupt::never(),
        })
    }

    /// The parameters.
    pub fn params(&self) -> &CgParams {
        &self.params
    }

    /// The flag the next solves poll: once raised, a solve returns
    /// [`RegularizeError::Interrupted`] at its next multigrid level or iteration, keeping
    /// its cycle for the next quick start. Default: [`Interrupt::never`].
    pub(crate) fn set_interrupt(&mut self, interrupt: Interrupt) {
        self.interrupt = interrupt;
    }

    /// Number of multigrid levels, the surface included (1 without multigrid).
    pub fn levels(&self) -> usize {
        self.setup.levels()
    }

    /// Minimizes `energy` as `request` asks; returns the positions and a report.
    ///
    /// - `start`: the input positions, or given ones (one per vertex): the same minimizer
    ///   to the same tolerance, in fewer iterations when the start is close to it (the
    ///   previous solve of a refinement loop, whose normals and targets changed little);
    ///   the reported relative gradient stays relative to the gradient at the input. An
    ///   owned start becomes the iterate's vector (one vector fewer held).
    /// - `tolerance`: replaces [`CgParams::tolerance`] for this solve and the next.
    /// - `quick_start`: from a given start and with a listener, begin on the last solve's
    ///   kept multigrid cycle, its fine level put on the new energy, and build the energy's
    ///   own cycle only after the first iteration, restarting from that iterate: the first
    ///   iterate comes without waiting for the coarse levels' setup. The minimizer and the
    ///   stopping rule are those of any solve; the iterations may differ by one or two.
    /// - `keep_cycle`: keep this solve's cycle for a next quick start (an interrupted solve
    ///   keeps it anyway); otherwise its memory is freed at the end.
    /// - `progress`: called after each iteration (its energy costs two extra dot products
    ///   per iteration).
    pub fn solve(
        &mut self,
        energy: &Energy<'_>,
        request: SolveRequest<'_>,
    ) -> Result<(Vec<DVec3>, CgInfo), RegularizeError> {
        let SolveRequest { start, tolerance, quick_start, keep_cycle, progress } = request;
        if let Some(t) = tolerance {
            check_tolerance(t)?;
            self.params.tolerance = t;
        }
        self.quick_start = quick_start;
        let start = match start {
            SolveStart::Input => Start::Input,
            SolveStart::Given(x) => {
                energy.check_start(x)?;
                Start::Given(x)
            }
            SolveStart::Owned(x) => {
                energy.check_start(&x)?;
                Start::Taken(x)
            }
        };
        let out = self.run(energy, start, progress)?;
        if !keep_cycle {
            self.setup.forget_kept();
        }
        Ok(out)
    }

    fn run(
        &mut self,
        energy: &Energy<'_>,
        start: Start<'_>,
        mut progress: Option<&mut dyn FnMut(&Progress)>,
    ) -> Result<(Vec<DVec3>, CgInfo), RegularizeError> {
        let warm = !matches!(start, Start::Input);
        let quick = self.quick_start && warm && progress.is_some();
        let mut prepared = self.setup.prepare(energy, quick, &self.interrupt)?;
        if self.interrupt.is_raised() {
            self.setup.keep(prepared);
            return Err(RegularizeError::Interrupted);
        }
        let stencil = &self.setup.stencil;
        let n = stencil.len();
        let input = energy.input();

        let t = Instant::now();
        let zero = || vec![DVec3::ZERO; n];
        let mut b = Buffers { u: Vec::new(), r: zero(), z: zero(), p: zero(), q: zero() };
        // r = alpha p - H p = -(H - diag(alpha)) p: only differences of positions, exact.
        stencil.apply(&prepared.coef, input, &mut b.r, &mut b.z, false);
        b.r.par_chunks_mut(CHUNK).for_each(|c| c.iter_mut().for_each(|x| *x = -*x));
        let r0 = norm(&b.r);
        let mut applications = 1;
        let mut rnorm = r0;
        // Solve for the displacement from the input: u = start - p, r = b - H u.
        b.u = match start {
            Start::Input => zero(),
            Start::Given(s) => s.par_iter().zip(input).map(|(s, p)| *s - *p).collect(),
            Start::Taken(mut u) => {
                u.par_iter_mut().zip(input).for_each(|(u, p)| *u -= *p);
                u
            }
        };
        let e0 = if progress.is_some() { energy.terms(input).total } else { 0.0 };
        // The energy at the iterate, `E(p + u) = E(p) - u.b - u.r`, then followed step by
        // step (the right-hand side `b` is not kept through the iterations).
        let mut energy_now = e0;
        if warm {
            // `q` holds the right-hand side while the residual is formed.
            std::mem::swap(&mut b.r, &mut b.q);
            stencil.residual(&prepared.coef, &b.u, &b.q, &mut b.r, &mut b.z);
            applications += 1;
            rnorm = norm(&b.r);
            if progress.is_some() {
                energy_now = e0 - dot(&b.u, &b.q) - dot(&b.u, &b.r);
            }
        }
        let alpha_min = energy.min_alpha();
        let h = self.setup.spacing;
        let tol = self.params.tolerance * h;
        let guaranteed = alpha_min * tol;

        let mut iterations = 0;
        let mut stale_iterations = 0;
        let mut estimate = f64::INFINITY;
        let mut residuals = vec![rnorm];
        let mut restarts = 0;
        let mut interrupted = false;
        'outer: while rnorm > guaranteed && iterations < self.params.max_iterations {
            prepared.pre.apply_in(stencil, &b.r, &mut b.z, &mut b.q);
            scale_add(&mut b.p, 0.0, &b.z);
            let mut rz = dot(&b.r, &b.z);
            loop {
                if self.interrupt.is_raised() {
                    interrupted = true;
                    break 'outer;
                }
                let pq = stencil.apply_dot(&prepared.coef, &b.p, &mut b.q, &mut b.z);
                applications += 1;
                if !(pq > 0.0 && rz > 0.0) {
                    break 'outer; // converged to rounding
                }
                let a = rz / pq;
                // E changes by -2 a (r . p) + a^2 (p . q), with r . p = r . z = rz.
                energy_now += -2.0 * a * rz + a * a * pq;
                let (r2, p2) = cg_update(&mut b.u, &mut b.r, a, &b.p, &b.q);
                rnorm = r2.sqrt();
                residuals.push(rnorm);
                iterations += 1;
                estimate = 2.0 * tail_estimate(a * p2.sqrt(), &residuals);
                let done = match self.params.stopping {
                    StoppingRule::Estimate => estimate <= tol || rnorm <= guaranteed,
                    StoppingRule::Guaranteed => rnorm <= guaranteed,
                };
                if done || iterations >= self.params.max_iterations {
                    // The recursive residual drifts from the true one: report the latter.
                    true_residual(stencil, &prepared.coef, input, &b.u, &mut b.r, &mut b.z, &mut b.q);
                    applications += 1;
                    rnorm = norm(&b.r);
                    let drifted = self.params.stopping == StoppingRule::Guaranteed && rnorm > guaranteed;
                    if drifted && restarts < 3 && iterations < self.params.max_iterations {
                        restarts += 1;
                        continue 'outer;
                    }
                    break 'outer;
                }
                if let Some(report) = progress.as_mut() {
                    report(&Progress {
                        iteration: iterations,
                        energy: energy_now,
                        gradient_norm: 2.0 * rnorm,
                        relative_gradient: if r0 > 0.0 { rnorm / r0 } else { 0.0 },
                        error_bound: rnorm / alpha_min / h,
                        error_estimate: estimate / h,
                        displacement: &b.u,
                    });
                }
                if prepared.stale {
                    // The first iterate is out: this energy's own cycle, and a restart
                    // (the directions so far are conjugate for the stale one).
                    stale_iterations = iterations;
                    if self.interrupt.is_raised() {
                        interrupted = true;
                        break 'outer;
                    }
                    self.setup.renew(&mut prepared, &self.interrupt)?;
                    continue 'outer;
                }
                prepared.pre.apply_in(stencil, &b.r, &mut b.z, &mut b.q);
                let rz_new = dot(&b.r, &b.z);
                scale_add(&mut b.p, rz_new / rz, &b.z);
                rz = rz_new;
            }
        }
        if interrupted {
            // The cycle stays valid for the next quick start.
            self.setup.keep(prepared);
            return Err(RegularizeError::Interrupted);
        }
        // The positions in the displacement's own vector: no new one at the solve's peak.
        let mut x = std::mem::take(&mut b.u);
        x.par_iter_mut().zip(input.par_iter()).for_each(|(u, p)| *u = *p + *u);
        let solve_seconds = t.elapsed().as_secs_f64();
        let relative = if r0 > 0.0 { rnorm / r0 } else { 0.0 };
        let bound = rnorm / alpha_min / h;
        let estimate = if r0 > 0.0 || warm { (estimate / h).min(bound) } else { 0.0 };
        let converged = match self.params.stopping {
            StoppingRule::Estimate => estimate <= self.params.tolerance,
            StoppingRule::Guaranteed => bound <= self.params.tolerance,
        };
        tracing::debug!(iterations, relative, bound, estimate, "conjugate gradient done");
        // Per iteration: one product, dot(p, q), the update (u, r, p, q), dot(r, z), p's
        // update (p, z), and the preconditioner.
        let traffic = self.setup.traffic_model(&prepared, 1, 2 + 6 + 2 + 3);
        let memory = self.setup.memory_bytes(&prepared) + 6 * 24 * n;
        if prepared.stale {
            stale_iterations = iterations;
        }
        let seconds = self.setup.timings(&prepared, solve_seconds);
        // A solve that stopped on the stale cycle keeps it: its energy's own was not built.
        self.setup.keep(prepared);
        Ok((
            x,
            CgInfo {
                iterations,
                quick_start_iterations: stale_iterations,
                operator_applications: applications,
                relative_gradient: relative,
                error_bound: bound,
                error_estimate: estimate,
                converged,
                preconditioner: self.params.preconditioner,
                memory_bytes: memory,
                bytes_per_iteration: traffic,
                seconds,
            },
        ))
    }
}

#[cfg(test)]
mod kernel_timings {
    //! `cargo test --release -p voxreg-regularize --lib kernel_timings -- --ignored --nocapture`
    //! (`R=` sphere radius, default 140): timings of the iteration's kernels and the
    //! memory bandwidth they are compared with.
    use super::*;
    use crate::energy::{Energy, EnergyParams};
    use crate::iterative::Pre;
    use crate::multigrid::Hierarchy;
    use crate::stencil::Stencil;
    use crate::vecops::sym_inverse;
    use voxreg_testkit::{digitize, true_normals, Sphere};

    /// Median of 20 runs, in milliseconds.
    fn time(f: &mut dyn FnMut()) -> f64 {
        let mut v: Vec<f64> = (0..20)
            .map(|_| {
                let t = Instant::now();
                f();
                t.elapsed().as_secs_f64() * 1e3
            })
            .collect();
        v.sort_by(f64::total_cmp);
        v[10]
    }

    /// The kernels' throughput (printed; `R` sets the sphere's radius), checking each
    /// kernel's result on the way.
    #[test]
    #[ignore]
    fn kernels() {
        let r: f64 = std::env::var("R").map(|v| v.parse().unwrap()).unwrap_or(140.0);
        let s = DigitalSurface::from_volume(&digitize(&Sphere { radius: r }, 1.0)).unwrap();
        let normals = voxreg_normals::NormalField::new(true_normals(&s, &Sphere { radius: r }));
        let input = s.positions();
        let e = Energy::new(&s, &normals, &input, EnergyParams::default()).unwrap();
        let st = Stencil::new(&s, None).unwrap();
        let c = st.coefficients(&e);
        let n = st.len();
        let (mut y, mut t, mut u) = (vec![DVec3::ZERO; n], vec![DVec3::ZERO; n], vec![DVec3::ONE; n]);
        // Streaming bandwidth: a triad over three arrays of this size (4 x 24 n bytes with
        // the write-allocate).
        let triad = time(&mut || {
            y.par_chunks_mut(CHUNK).zip(input.par_chunks(CHUNK)).zip(u.par_chunks(CHUNK)).for_each(
                |((y, a), b)| {
                    for i in 0..y.len() {
                        y[i] = a[i] + 0.5 * b[i];
                    }
                },
            )
        });
        eprintln!("n = {n}: triad {:.2} GB/s", 4.0 * 24.0 * n as f64 / triad * 1e-6);
        assert!(y.iter().zip(&input).all(|(y, a)| *y == *a + 0.5 * DVec3::ONE), "the triad's result");
        let apply = time(&mut || st.apply(&c, &input, &mut y, &mut t, true));
        let bytes = st.bytes() + 24 * normals.len() + 8 * n + 5 * 24 * n;
        eprintln!(
            "product: {apply:.3} ms, {:.1} MB -> {:.2} GB/s",
            bytes as f64 * 1e-6,
            bytes as f64 / apply * 1e-6
        );
        assert!(y.iter().chain(&t).all(|v| v.is_finite()), "the product is finite");
        let d = time(&mut || {
            std::hint::black_box(dot(&y, &t));
        });
        eprintln!("dot: {d:.3} ms");
        let serial: f64 = y.iter().zip(&t).map(|(a, b)| a.dot(*b)).sum();
        assert!((dot(&y, &t) - serial).abs() <= 1e-9 * serial.abs().max(1.0), "the parallel dot product");
        let upd = time(&mut || {
            std::hint::black_box(cg_update(&mut u, &mut y, 0.1, &t, &input));
        });
        eprintln!("cg update: {upd:.3} ms");
        let mut block = Pre::Block(st.diagonal(&c).iter().map(sym_inverse).collect());
        eprintln!("block jacobi: {:.3} ms", time(&mut || block.apply(&st, &y, &mut t)));
        let h = Hierarchy::new(&st, crate::stencil::lattice_corners(&s), &MultigridParams::default());
        eprintln!(
            "multigrid numeric: {:.3} ms",
            time(&mut || {
                std::hint::black_box(h.numeric(&st, &c, &Interrupt::never(), None).unwrap());
            })
        );
        let mut v = h.numeric(&st, &c, &Interrupt::never(), None).unwrap();
        let cycle = time(&mut || v.apply(&st, &y, &mut t));
        eprintln!("v-cycle: {cycle:.3} ms ({} levels)", h.levels());
        assert!(h.levels() > 1 && t.iter().all(|v| v.is_finite()), "the cycle's levels and result");
        for ms in [triad, apply, d, upd, cycle] {
            assert!(ms.is_finite() && ms > 0.0, "a kernel's time: {ms} ms");
        }
    }
}

#[cfg(test)]
mod quick_start {
    //! The quick start of a warm re-solve: the first iterate before the new energy's
    //! multigrid setup, and the same minimizer as a cold solve.
    use super::*;
    use crate::direct::DirectSolver;
    use crate::energy::EnergyParams;
    use crate::multigrid::tests::setups;
    use voxreg_normals::{NormalEstimator, NormalField, Trivial};
    use voxreg_testkit::{digitize, true_normals, Torus};

    fn max_distance(a: &[DVec3], b: &[DVec3]) -> f64 {
        a.iter().zip(b).map(|(x, y)| (*x - *y).length()).fold(0.0, f64::max)
    }

    /// A solve from `start`: the result, its report, and the multigrid setups done on
    /// this thread before its first iterate and in all.
    fn solve(
        solver: &mut CgSolver,
        energy: &Energy<'_>,
        start: &[DVec3],
        quick: bool,
    ) -> (Vec<DVec3>, CgInfo, Option<usize>, usize) {
        let before = setups();
        let mut first = None;
        let mut progress = |_: &Progress| _ = *first.get_or_insert(setups() - before);
        let request = SolveRequest::from(SolveStart::Given(start))
            .quick_start(quick)
            .keep_cycle(true)
            .progress(&mut progress);
        let (x, info) = solver.solve(energy, request).unwrap();
        (x, info, first, setups() - before)
    }

    /// A cold solve that keeps its cycle.
    fn cold(solver: &mut CgSolver, energy: &Energy<'_>) -> (Vec<DVec3>, CgInfo) {
        solver.solve(energy, SolveRequest::default().keep_cycle(true)).unwrap()
    }

    #[test]
    fn a_quick_start_iterates_before_any_setup_and_reaches_the_minimizer() {
        let torus = Torus { major: 11.0, minor: 4.3 };
        let s = DigitalSurface::from_volume(&digitize(&torus, 1.0)).unwrap();
        let exact_normals = NormalField::new(true_normals(&s, &torus));
        let trivial = Trivial.estimate(&s).unwrap();
        let input = s.positions();
        let base = EnergyParams::default();
        let mut solver = CgSolver::for_surface(&s, CgParams::default()).unwrap();
        assert!(solver.levels() > 2, "a hierarchy with coarse levels");
        let before = Energy::new(&s, &exact_normals, &input, base).unwrap();
        let (x0, _) = cold(&mut solver, &before);
        // Changes far larger than a slider step: the stale cycle is a poor match.
        let changes = [
            (EnergyParams { gamma: base.gamma * 10.0, ..base }, &exact_normals),
            (EnergyParams { alpha: base.alpha / 3.0, beta: base.beta * 2.0, ..base }, &exact_normals),
            (base, &trivial),
        ];
        for (params, normals) in changes {
            let energy = Energy::new(&s, normals, &input, params).unwrap();
            let (exact, _) = DirectSolver::for_surface(&s).unwrap().solve(&energy).unwrap();
            // The kept cycle is the first energy's; the quick start begins on it.
            cold(&mut solver, &before);
            let (quick, info, first, total) = solve(&mut solver, &energy, &x0, true);
            assert_eq!(first, Some(0), "{params:?}: no multigrid setup before the first iterate");
            assert_eq!(total, 1, "the energy's own cycle after it");
            assert_eq!(info.quick_start_iterations, 1);
            let (plain, plain_info, first, total) = solve(&mut solver, &energy, &x0, false);
            assert_eq!((first, total), (Some(1), 1), "without it, the setup comes first");
            let tol = solver.params().tolerance;
            assert!(info.converged);
            assert!(max_distance(&quick, &exact) <= tol, "{params:?}: quick vs exact");
            assert!(max_distance(&plain, &exact) <= tol, "{params:?}: plain vs exact");
            assert!(
                // The restart after the first iteration costs a few; a change this
                // large, up to an eighth (63 against 56 with gamma x10).
                info.iterations <= plain_info.iterations + plain_info.iterations / 4 + 2,
                "{params:?}: {} iterations, {} without the quick start",
                info.iterations,
                plain_info.iterations
            );
        }
    }

    #[test]
    fn a_quick_start_needs_a_start_a_listener_and_a_kept_cycle() {
        let torus = Torus { major: 9.0, minor: 3.5 };
        let s = DigitalSurface::from_volume(&digitize(&torus, 1.0)).unwrap();
        let normals = NormalField::new(true_normals(&s, &torus));
        let input = s.positions();
        let energy = Energy::new(&s, &normals, &input, EnergyParams::default()).unwrap();
        let mut solver = CgSolver::for_surface(&s, CgParams::default()).unwrap();
        // Nothing kept yet: the first solve sets up its own cycle first.
        let (x, info, first, _) = solve(&mut solver, &energy, &input, true);
        assert_eq!((first, info.quick_start_iterations), (Some(1), 0));
        // No start (a cold solve) or no listener: nothing to show early.
        let request = SolveRequest::default().quick_start(true).keep_cycle(true);
        let (_, info) = solver.solve(&energy, request.progress(&mut |_| {})).unwrap();
        assert_eq!(info.quick_start_iterations, 0);
        let request = SolveRequest::from(SolveStart::Given(&x)).quick_start(true).keep_cycle(true);
        let (_, info) = solver.solve(&energy, request).unwrap();
        assert_eq!(info.quick_start_iterations, 0);
    }
}

#[cfg(test)]
mod residuals {
    //! The end-of-solve residual without the right-hand side against `b - H u`.
    use super::*;
    use crate::energy::EnergyParams;
    use crate::stencil::Stencil;
    use crate::weights::{FairnessMask, Weights};
    use voxreg_normals::NormalField;
    use voxreg_testkit::{digitize, true_normals, Lcg, Torus};

    #[test]
    fn the_true_residual_without_the_right_hand_side_is_b_minus_h_u() {
        let shape = Torus { major: 6.0, minor: 2.5 };
        let s = DigitalSurface::from_volume(&digitize(&shape, 0.5)).unwrap();
        let normals = NormalField::new(true_normals(&s, &shape));
        let input = s.positions();
        let mut rng = Lcg::new(7);
        // Per-vertex attachment weights and a fairness mask, as the pipeline's runs have.
        let weights = Weights {
            alpha: Some((0..s.num_vertices()).map(|_| rng.range(0.5, 2.0)).collect::<Vec<_>>().into()),
            fairness: Some(FairnessMask::junction_curves(&s)),
            ..Default::default()
        };
        let energy = Energy::new(&s, &normals, &input, EnergyParams::default())
            .unwrap()
            .with_weights(&weights)
            .unwrap();
        let stencil = Stencil::new(&s, weights.fairness.as_ref()).unwrap();
        let coef = stencil.coefficients(&energy);
        let n = stencil.len();
        let u: Vec<DVec3> = (0..n).map(|_| rng.vec3(-0.4, 0.4)).collect();
        let (mut b, mut t) = (vec![DVec3::ZERO; n], vec![DVec3::ZERO; n]);
        stencil.apply(&coef, &input, &mut b, &mut t, false);
        b.iter_mut().for_each(|x| *x = -*x);
        let mut expected = vec![DVec3::ZERO; n];
        stencil.residual(&coef, &u, &b, &mut expected, &mut t);
        let (mut r, mut x) = (vec![DVec3::ZERO; n], vec![DVec3::ZERO; n]);
        true_residual(&stencil, &coef, &input, &u, &mut r, &mut x, &mut t);
        let scale = norm(&expected);
        let diff = r.iter().zip(&expected).map(|(a, e)| (*a - *e).length()).fold(0.0, f64::max);
        assert!(scale > 1e-3 && diff <= 1e-12 * scale.max(1.0), "{diff} against {scale}");
    }
}
