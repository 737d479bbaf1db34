//! Preconditioned conjugate gradient on the energy's linear system, matrix-free.

use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;
use voxreg_digisurf::DigitalSurface;

use crate::multigrid::{Hierarchy, MultigridParams, Vcycle};
use crate::stencil::{Coefficients, Stencil, CHUNK};
use crate::vecops::{cg_update, dot, norm, scale_add, sym_inverse, sym_mul, tail_estimate};
use crate::{Energy, FairnessMask, Progress, RegularizeError, SolveInfo};

/// The preconditioner of [`CgSolver`].
#[derive(Copy, Clone, Debug, PartialEq, Eq, Default)]
pub enum Preconditioner {
    /// The scalar diagonal of `H`.
    Jacobi,
    /// The 3x3 diagonal blocks of `H` (couples the coordinates through the normals).
    BlockJacobi,
    /// One V-cycle of aggregation multigrid over the voxel hierarchy (see
    /// [`MultigridParams`]): the default, several times fewer iterations.
    #[default]
    Multigrid,
}

/// When an iterative solver stops.
#[derive(Copy, Clone, Debug, PartialEq, Eq, Default)]
pub enum StoppingRule {
    /// Stop when the *estimated* largest distance of a vertex to the exact minimizer is at
    /// most the tolerance: the largest vertex correction of the last iteration,
    /// `max_i |x_i^(k+1) - x_i^(k)|`, extrapolated as a geometric series with the recent
    /// residual reduction rate `rho`: `correction / (1 - rho)`. Measured on spheres, tori
    /// and random volumes, the true error at the stop is 1.3 to 4 times below the
    /// tolerance (see the crate's tests), but it is an estimate.
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
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct CgParams {
    /// Tolerance of the [`StoppingRule`], in voxels (physical tolerance `tolerance * h`,
    /// `h` the smallest voxel spacing). Default: `1e-3`.
    pub tolerance: f64,
    /// How the tolerance is read. Default: [`StoppingRule::Estimate`].
    pub stopping: StoppingRule,
    /// Give up after this many iterations (the result is then returned, with its bound,
    /// and [`SolveInfo::converged`] false). Default: `5000`.
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
/// [`CgSolver::new`] builds the surface's connectivity for the matrix-free operator and,
/// for the multigrid preconditioner, the aggregation hierarchy; each
/// [`CgSolver::solve`] only computes the numeric coefficients (and coarse operators) of
/// its energy, then iterates from the input positions (solving for the displacement,
/// like [`crate::DirectSolver`]). Memory: about 0.3 KiB per vertex with multigrid.
#[derive(Debug)]
pub struct CgSolver {
    params: CgParams,
    stencil: Stencil,
    mask: Option<FairnessMask>,
    hierarchy: Option<Hierarchy>,
    spacing: f64,
    structure_seconds: f64,
}

/// Work vectors of one solve.
struct Buffers {
    u: Vec<DVec3>,
    r: Vec<DVec3>,
    z: Vec<DVec3>,
    p: Vec<DVec3>,
    q: Vec<DVec3>,
    t: Vec<DVec3>,
}

impl CgSolver {
    /// Prepares a solver for energies on `surface` (without fairness mask: a masked
    /// energy makes [`CgSolver::solve`] rebuild the connectivity once).
    pub fn new(surface: &DigitalSurface, params: CgParams) -> Result<Self, RegularizeError> {
        if !(params.tolerance > 0.0 && params.tolerance.is_finite()) {
            return Err(RegularizeError::InvalidParams(format!(
                "the tolerance must be positive and finite, got {}",
                params.tolerance
            )));
        }
        let t = Instant::now();
        let stencil = Stencil::new(surface, None)?;
        let hierarchy = match params.preconditioner {
            Preconditioner::Multigrid => Some(Hierarchy::new(surface, &stencil, &params.multigrid)?),
            _ => None,
        };
        let spacing = surface.spacing().min_element();
        Ok(CgSolver {
            params,
            stencil,
            mask: None,
            hierarchy,
            spacing,
            structure_seconds: t.elapsed().as_secs_f64(),
        })
    }

    /// The parameters.
    pub fn params(&self) -> &CgParams {
        &self.params
    }

    /// Number of multigrid levels (1 without multigrid).
    pub fn levels(&self) -> usize {
        self.hierarchy.as_ref().map_or(1, |h| h.levels())
    }

    /// Minimizes `energy` from its input positions; returns the positions and a report.
    pub fn solve(&mut self, energy: &Energy<'_>) -> Result<(Vec<DVec3>, SolveInfo), RegularizeError> {
        self.run(energy, None)
    }

    /// [`CgSolver::solve`], calling `progress` after each iteration (its energy costs two
    /// extra dot products per iteration).
    pub fn solve_with(
        &mut self,
        energy: &Energy<'_>,
        progress: &mut dyn FnMut(&Progress),
    ) -> Result<(Vec<DVec3>, SolveInfo), RegularizeError> {
        self.run(energy, Some(progress))
    }

    fn run(
        &mut self,
        energy: &Energy<'_>,
        mut progress: Option<&mut dyn FnMut(&Progress)>,
    ) -> Result<(Vec<DVec3>, SolveInfo), RegularizeError> {
        let surface = energy.surface();
        let n = self.stencil.len();
        if energy.input().len() != n || surface.num_vertices() != n {
            return Err(RegularizeError::SizeMismatch("the energy is not on this solver's surface".into()));
        }
        let mask = energy.weights().and_then(|w| w.fairness.as_ref());
        let mut structure_seconds = self.structure_seconds;
        if mask != self.mask.as_ref() {
            let t = Instant::now();
            self.stencil = Stencil::new(surface, mask)?;
            self.mask = mask.cloned();
            structure_seconds += t.elapsed().as_secs_f64();
        }
        let input = energy.input();

        let t = Instant::now();
        let coef = self.stencil.coefficients(energy);
        let mut pre = match self.params.preconditioner {
            Preconditioner::Jacobi => Pre::Jacobi(
                self.stencil
                    .diagonal(&coef)
                    .iter()
                    .map(|d| DVec3::new(1.0 / d[0], 1.0 / d[1], 1.0 / d[2]))
                    .collect(),
            ),
            Preconditioner::BlockJacobi => {
                Pre::Block(self.stencil.diagonal(&coef).iter().map(sym_inverse).collect())
            }
            Preconditioner::Multigrid => {
                let h = self.hierarchy.as_ref().expect("built with the multigrid");
                Pre::Multigrid(Box::new(h.numeric(&self.stencil, &coef)?))
            }
        };
        let (assemble_seconds, factor_seconds) = match &pre {
            Pre::Multigrid(v) => (t.elapsed().as_secs_f64() - v.factor_seconds, v.factor_seconds),
            _ => (t.elapsed().as_secs_f64(), 0.0),
        };

        let t = Instant::now();
        let zero = || vec![DVec3::ZERO; n];
        let mut b = Buffers { u: zero(), r: zero(), z: zero(), p: zero(), q: zero(), t: zero() };
        // r = alpha p - H p = -(H - diag(alpha)) p: only differences of positions, exact.
        self.stencil.apply(&coef, input, &mut b.r, &mut b.t, false);
        b.r.par_chunks_mut(CHUNK).for_each(|c| c.iter_mut().for_each(|x| *x = -*x));
        let rhs = b.r.clone();
        let r0 = norm(&b.r);
        let alpha_min = energy.min_alpha();
        let h = self.spacing;
        let tol = self.params.tolerance * h;
        let guaranteed = alpha_min * tol;
        let e0 = if progress.is_some() { energy.terms(input).total } else { 0.0 };

        let mut iterations = 0;
        let mut applications = 1;
        let mut rnorm = r0;
        let mut estimate = f64::INFINITY;
        let mut residuals = vec![r0];
        let mut restarts = 0;
        'outer: while rnorm > guaranteed && iterations < self.params.max_iterations {
            pre.apply(&self.stencil, &coef, &b.r, &mut b.z);
            scale_add(&mut b.p, 0.0, &b.z);
            let mut rz = dot(&b.r, &b.z);
            loop {
                self.stencil.apply(&coef, &b.p, &mut b.q, &mut b.t, true);
                applications += 1;
                let pq = dot(&b.p, &b.q);
                if !(pq > 0.0 && rz > 0.0) {
                    break 'outer; // converged to rounding
                }
                let a = rz / pq;
                let (r2, p2) = cg_update(&mut b.u, &mut b.r, a, &b.p, &b.q);
                rnorm = r2.sqrt();
                residuals.push(rnorm);
                iterations += 1;
                estimate = tail_estimate(a * p2.sqrt(), &residuals);
                let done = match self.params.stopping {
                    StoppingRule::Estimate => estimate <= tol || rnorm <= guaranteed,
                    StoppingRule::Guaranteed => rnorm <= guaranteed,
                };
                if done || iterations >= self.params.max_iterations {
                    // The recursive residual drifts from the true one: report the latter.
                    self.stencil.apply(&coef, &b.u, &mut b.q, &mut b.t, true);
                    applications += 1;
                    b.r.par_chunks_mut(CHUNK).zip(rhs.par_chunks(CHUNK)).zip(b.q.par_chunks(CHUNK)).for_each(
                        |((r, f), q)| {
                            for i in 0..r.len() {
                                r[i] = f[i] - q[i];
                            }
                        },
                    );
                    rnorm = norm(&b.r);
                    let drifted = self.params.stopping == StoppingRule::Guaranteed && rnorm > guaranteed;
                    if drifted && restarts < 3 && iterations < self.params.max_iterations {
                        restarts += 1;
                        continue 'outer;
                    }
                    break 'outer;
                }
                pre.apply(&self.stencil, &coef, &b.r, &mut b.z);
                let rz_new = dot(&b.r, &b.z);
                if let Some(report) = progress.as_mut() {
                    // E(p + u) = E(p) - u.b - u.r for the quadratic with H u = b - r.
                    let energy_now = e0 - dot(&b.u, &rhs) - dot(&b.u, &b.r);
                    report(&Progress {
                        iteration: iterations,
                        energy: energy_now,
                        gradient_norm: 2.0 * rnorm,
                        relative_gradient: if r0 > 0.0 { rnorm / r0 } else { 0.0 },
                        error_bound: rnorm / alpha_min / h,
                        error_estimate: estimate / h,
                    });
                }
                scale_add(&mut b.p, rz_new / rz, &b.z);
                rz = rz_new;
            }
        }
        let x: Vec<DVec3> = input.par_iter().zip(&b.u).map(|(p, u)| *p + *u).collect();
        let solve_seconds = t.elapsed().as_secs_f64();
        let relative = if r0 > 0.0 { rnorm / r0 } else { 0.0 };
        let bound = rnorm / alpha_min / h;
        let estimate = if r0 > 0.0 { estimate.min(bound * h) / h } else { 0.0 };
        let converged = match self.params.stopping {
            StoppingRule::Estimate => estimate <= self.params.tolerance || bound <= self.params.tolerance,
            StoppingRule::Guaranteed => bound <= self.params.tolerance,
        };
        tracing::debug!(iterations, relative, bound, estimate, "conjugate gradient done");
        Ok((
            x,
            SolveInfo {
                solver: "cg",
                iterations,
                relative_gradient: relative,
                factor_nnz: None,
                pattern_seconds: structure_seconds,
                symbolic_seconds: 0.0,
                assemble_seconds,
                factor_seconds,
                solve_seconds,
                error_bound: Some(bound),
                error_estimate: Some(estimate),
                converged,
                preconditioner: Some(match self.params.preconditioner {
                    Preconditioner::Jacobi => "jacobi",
                    Preconditioner::BlockJacobi => "block-jacobi",
                    Preconditioner::Multigrid => "multigrid",
                }),
                operator_applications: applications,
                clamped_vertices: None,
            },
        ))
    }
}

enum Pre {
    Jacobi(Vec<DVec3>),
    Block(Vec<[f64; 6]>),
    Multigrid(Box<Vcycle>),
}

impl Pre {
    fn apply(&mut self, stencil: &Stencil, coef: &Coefficients<'_>, r: &[DVec3], z: &mut [DVec3]) {
        match self {
            Pre::Jacobi(d) => {
                z.par_chunks_mut(CHUNK).zip(r.par_chunks(CHUNK)).zip(d.par_chunks(CHUNK)).for_each(
                    |((z, r), d)| {
                        for i in 0..z.len() {
                            z[i] = r[i] * d[i];
                        }
                    },
                )
            }
            Pre::Block(d) => {
                z.par_chunks_mut(CHUNK).zip(r.par_chunks(CHUNK)).zip(d.par_chunks(CHUNK)).for_each(
                    |((z, r), d)| {
                        for i in 0..z.len() {
                            z[i] = sym_mul(&d[i], r[i]);
                        }
                    },
                )
            }
            Pre::Multigrid(v) => v.apply(stencil, coef, r, z),
        }
    }
}

#[cfg(test)]
mod bench_tests {
    use super::*;
    use crate::{Energy, EnergyParams};
    use voxreg_testkit::{digitize, true_normals, Sphere};

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
        let mut y = vec![DVec3::ZERO; n];
        let mut t = vec![DVec3::ZERO; n];
        let mut u = vec![DVec3::ONE; n];
        fn cpu_ns() -> u64 {
            std::fs::read_dir("/proc/self/task")
                .unwrap()
                .map(|e| {
                    let p = e.unwrap().path().join("schedstat");
                    std::fs::read_to_string(p)
                        .unwrap()
                        .split_whitespace()
                        .next()
                        .unwrap()
                        .parse::<u64>()
                        .unwrap()
                })
                .sum()
        }
        let time = |name: &str, f: &mut dyn FnMut()| {
            let mut v = Vec::new();
            let c0 = cpu_ns();
            for _ in 0..20 {
                let t = Instant::now();
                f();
                v.push(t.elapsed().as_secs_f64());
            }
            let cpu = (cpu_ns() - c0) as f64 / 20.0 * 1e-6;
            v.sort_by(f64::total_cmp);
            eprintln!("{name}: wall min {:.3} median {:.3} ms, cpu {cpu:.3} ms", v[0] * 1e3, v[10] * 1e3);
        };
        eprintln!("n = {n}, stencil bytes {}", st.bytes());
        time("apply", &mut || st.apply(&c, &input, &mut y, &mut t, true));
        if std::env::var("ONLY_APPLY").is_ok() {
            for _ in 0..200 {
                st.apply(&c, &input, &mut y, &mut t, true);
            }
            return;
        }
        time("dot", &mut || {
            std::hint::black_box(dot(&y, &t));
        });
        time("cg_update", &mut || {
            std::hint::black_box(cg_update(&mut u, &mut y, 0.1, &t, &input));
        });
        let d: Vec<[f64; 6]> = st.diagonal(&c).iter().map(sym_inverse).collect();
        let mut pre = Pre::Block(d);
        time("block jacobi", &mut || pre.apply(&st, &c, &y, &mut t));
        let env = |k: &str, d: f64| std::env::var(k).map(|v| v.parse().unwrap()).unwrap_or(d);
        let mg = MultigridParams {
            max_levels: env("LEVELS", 16.0) as usize,
            coarsest_nodes: env("COARSEST", 800.0) as usize,
            smoothing_steps: env("STEPS", 1.0) as usize,
            damping: env("DAMP", 1.8),
        };
        let h = Hierarchy::new(&s, &st, &mg).unwrap();
        if std::env::var("ONLY_MG").is_ok() {
            for _ in 0..20 {
                std::hint::black_box(h.numeric(&st, &c).unwrap());
            }
            return;
        }
        time("mg numeric", &mut || {
            std::hint::black_box(h.numeric(&st, &c).unwrap());
        });
        let mut v = h.numeric(&st, &c).unwrap();
        eprintln!("levels {} coarse bytes {}", v.levels(), v.coarse_bytes());
        time("vcycle", &mut || v.apply(&st, &c, &y, &mut t));
    }
}
