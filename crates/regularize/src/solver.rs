//! Choosing a solver: exact factorization, conjugate gradient, or (clamped) descent.

use glam::DVec3;
use voxreg_digisurf::DigitalSurface;

use crate::{
    CgParams, CgSolver, DescentParams, DescentSolver, DirectSolver, Energy, Progress, RegularizeError,
    SolveInfo,
};

/// Which solver [`Solver::new`] builds.
#[derive(Copy, Clone, Debug, PartialEq, Eq, Default)]
pub enum SolverChoice {
    /// [`SolverChoice::Direct`] when its Cholesky factor fits
    /// [`SolverParams::direct_budget`], else [`SolverChoice::Cg`].
    #[default]
    Auto,
    /// Sparse Cholesky ([`DirectSolver`]): exact to rounding, memory `8 * factor_nnz`.
    Direct,
    /// Multigrid-preconditioned conjugate gradient ([`CgSolver`]).
    Cg,
    /// Gradient descent ([`DescentSolver`]), the only one that can clamp.
    Gd,
}

impl SolverChoice {
    /// Parses `auto`, `direct`, `cg` or `gd`.
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "auto" => Some(SolverChoice::Auto),
            "direct" => Some(SolverChoice::Direct),
            "cg" => Some(SolverChoice::Cg),
            "gd" => Some(SolverChoice::Gd),
            _ => None,
        }
    }
}

/// Parameters of [`Solver::new`].
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct SolverParams {
    /// The solver. Default: [`SolverChoice::Auto`].
    pub choice: SolverChoice,
    /// Bytes the automatic choice lets the direct solver's Cholesky factor take
    /// (`8 * factor_nnz`); above, it iterates. The factor grows like `n^1.27` (measured on
    /// spheres: 100 entries per unknown at 176 vertices, 540 at 120k) and its numeric
    /// factorization is slower than the multigrid CG at every size measured (2.6k
    /// vertices: 85 ms vs 36 ms; 24k: 1.6 s vs 0.12 s), so the default only takes the exact
    /// route where it is cheap: surfaces of up to about 3,000 vertices. Raise it (or
    /// choose [`SolverChoice::Direct`]) to trade time for an answer exact to rounding.
    /// Default: `16 MiB`.
    pub direct_budget: usize,
    /// Settings of the conjugate gradient. Default: [`CgParams::default`].
    pub cg: CgParams,
    /// Settings of the descent. Default: [`DescentParams::default`].
    pub descent: DescentParams,
}

impl Default for SolverParams {
    fn default() -> Self {
        SolverParams {
            choice: SolverChoice::Auto,
            direct_budget: 16 << 20,
            cg: CgParams::default(),
            descent: DescentParams::default(),
        }
    }
}

/// A solver for energies on one surface, chosen once by [`Solver::new`] and reused by
/// [`Solver::solve`] (each keeps its analysis across solves).
#[derive(Debug)]
pub enum Solver {
    /// Exact sparse Cholesky.
    Direct(DirectSolver),
    /// Preconditioned conjugate gradient.
    Cg(CgSolver),
    /// Gradient descent, possibly clamped.
    Gd(DescentSolver),
}

/// A quick estimate of the Cholesky factor's entries for a surface of `n` vertices
/// (fitted on digitized spheres, within about 15% of faer's symbolic count from 176 to
/// 120k vertices), to skip the symbolic analysis where it cannot fit anyway.
pub fn estimate_factor_nnz(n: usize) -> f64 {
    let n = n.max(1) as f64;
    3.0 * n * 100.0 * (n / 176.0).max(1.0).powf(0.27)
}

impl Solver {
    /// Builds the solver `params.choice` names for energies on `surface`.
    ///
    /// [`SolverChoice::Auto`] first estimates the factor size ([`estimate_factor_nnz`]);
    /// if that is within twice the budget, it runs the symbolic analysis
    /// ([`DirectSolver::new`]) and keeps the direct solver when its exact
    /// [`DirectSolver::factor_nnz`] fits [`SolverParams::direct_budget`]; otherwise it
    /// builds the conjugate gradient.
    pub fn new(surface: &DigitalSurface, params: &SolverParams) -> Result<Self, RegularizeError> {
        Ok(match params.choice {
            SolverChoice::Direct => Solver::Direct(DirectSolver::new(surface)?),
            SolverChoice::Cg => Solver::Cg(CgSolver::new(surface, params.cg)?),
            SolverChoice::Gd => Solver::Gd(DescentSolver::new(surface, params.descent)?),
            SolverChoice::Auto => {
                let budget = params.direct_budget as f64 / 8.0;
                if estimate_factor_nnz(surface.num_vertices()) <= 2.0 * budget {
                    let direct = DirectSolver::new(surface)?;
                    if direct.factor_nnz() as f64 <= budget {
                        return Ok(Solver::Direct(direct));
                    }
                }
                Solver::Cg(CgSolver::new(surface, params.cg)?)
            }
        })
    }

    /// `"direct"`, `"cg"` or `"gd"`.
    pub fn kind(&self) -> &'static str {
        match self {
            Solver::Direct(_) => "direct",
            Solver::Cg(_) => "cg",
            Solver::Gd(_) => "gd",
        }
    }

    /// Minimizes `energy` (see each solver's `solve`).
    pub fn solve(&mut self, energy: &Energy<'_>) -> Result<(Vec<DVec3>, SolveInfo), RegularizeError> {
        self.solve_with(energy, &mut |_| {})
    }

    /// [`Solver::solve`], reporting each iteration of the iterative solvers to `progress`
    /// (the direct solver reports nothing).
    pub fn solve_with(
        &mut self,
        energy: &Energy<'_>,
        progress: &mut dyn FnMut(&Progress),
    ) -> Result<(Vec<DVec3>, SolveInfo), RegularizeError> {
        match self {
            Solver::Direct(s) => s.solve(energy),
            Solver::Cg(s) => s.solve_with(energy, progress),
            Solver::Gd(s) => s.solve_with(energy, progress),
        }
    }
}

#[cfg(test)]
mod tests {
    use voxreg_digisurf::LabelVolume;

    use super::*;

    #[test]
    fn auto_factors_small_surfaces_and_iterates_on_large_ones() {
        let ball = |r: f64| {
            let n = (2.0 * r) as usize + 3;
            let c = (n as f64 - 1.0) / 2.0;
            let v = LabelVolume::from_fn([n, n, n], |[x, y, z]| {
                u32::from(DVec3::new(x as f64 - c, y as f64 - c, z as f64 - c).length() <= r)
            });
            DigitalSurface::from_volume(&v).unwrap()
        };
        let small = ball(4.0);
        assert_eq!(Solver::new(&small, &SolverParams::default()).unwrap().kind(), "direct");
        let tight = SolverParams { direct_budget: 1024, ..Default::default() };
        assert_eq!(Solver::new(&small, &tight).unwrap().kind(), "cg");
        let large = ball(30.0);
        assert_eq!(Solver::new(&large, &SolverParams::default()).unwrap().kind(), "cg");
        let gd = SolverParams { choice: SolverChoice::Gd, ..Default::default() };
        assert_eq!(Solver::new(&small, &gd).unwrap().kind(), "gd");
        assert_eq!(SolverChoice::parse("cg"), Some(SolverChoice::Cg));
        assert_eq!(SolverChoice::parse("lu"), None);
    }

    #[test]
    fn the_factor_estimate_is_close_to_the_symbolic_count() {
        for r in [3.0, 8.0, 14.0] {
            let n = (2.0 * r) as usize + 3;
            let c = (n as f64 - 1.0) / 2.0;
            let v = LabelVolume::from_fn([n, n, n], |[x, y, z]| {
                u32::from(DVec3::new(x as f64 - c, y as f64 - c, z as f64 - c).length() <= r)
            });
            let s = DigitalSurface::from_volume(&v).unwrap();
            let exact = DirectSolver::new(&s).unwrap().factor_nnz() as f64;
            let est = estimate_factor_nnz(s.num_vertices());
            assert!((est / exact - 1.0).abs() < 0.35, "r = {r}: estimate {est} vs {exact}");
        }
    }
}
