//! Choosing a solver: exact factorization, conjugate gradient, or the bound-constrained
//! solver.

use glam::DVec3;
use voxreg_digisurf::DigitalSurface;

use serde::Serialize;

use crate::bounded::{BoundedParams, BoundedSolver};
use crate::cg::{CgParams, CgSolver};
use crate::direct::DirectSolver;
use crate::energy::Energy;
use crate::error::RegularizeError;
use crate::info::SolveInfo;
use crate::progress::Progress;
use crate::request::{SolveRequest, SolveStart};
use crate::sweeps::{SweepsParams, SweepsSolver};
use voxreg_normals::Interrupt;

/// Which solver [`Solver::new`] builds.
#[derive(Copy, Clone, Debug, PartialEq, Eq, Default, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum SolverChoice {
    /// [`SolverChoice::Direct`] when its Cholesky factor fits
    /// [`SolverParams::direct_budget`], else [`SolverChoice::Cg`].
    #[default]
    Auto,
    /// Sparse Cholesky ([`DirectSolver`]): exact to rounding, memory `8 * factor_nnz`.
    Direct,
    /// Multigrid-preconditioned conjugate gradient ([`CgSolver`]).
    Cg,
    /// Bound-constrained conjugate gradient ([`BoundedSolver`]), the only one that can
    /// clamp.
    Bounded,
    /// A fixed number of damped block-Jacobi sweeps ([`SweepsSolver`]), not to a
    /// tolerance: the fast pipeline, whose refinement rounds re-estimate the normals with
    /// [`voxreg_normals::Diffused`] ([`crate::Params::fast`]).
    Sweeps,
}

impl SolverChoice {
    /// Every choice.
    pub const ALL: [SolverChoice; 5] = [
        SolverChoice::Auto,
        SolverChoice::Direct,
        SolverChoice::Cg,
        SolverChoice::Bounded,
        SolverChoice::Sweeps,
    ];

    /// `"auto"`, `"direct"`, `"cg"`, `"bounded"` or `"sweeps"`.
    pub fn name(self) -> &'static str {
        match self {
            SolverChoice::Auto => "auto",
            SolverChoice::Direct => "direct",
            SolverChoice::Cg => "cg",
            SolverChoice::Bounded => "bounded",
            SolverChoice::Sweeps => "sweeps",
        }
    }
}

impl std::fmt::Display for SolverChoice {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for SolverChoice {
    type Err = String;

    /// A choice's [`SolverChoice::name`], or `gd` (the former name of `bounded`).
    fn from_str(s: &str) -> Result<Self, String> {
        if s == "gd" {
            return Ok(SolverChoice::Bounded);
        }
        SolverChoice::ALL.into_iter().find(|c| c.name() == s).ok_or_else(|| {
            let names: Vec<String> = SolverChoice::ALL.iter().map(|c| format!("'{}'", c.name())).collect();
            format!("must be one of {}, got '{s}'", names.join(", "))
        })
    }
}

/// How a front end's clamping option changes a preset's boxes
/// ([`SolverParams::overridden`]).
#[derive(Copy, Clone, Debug, PartialEq)]
pub enum ClampOverride {
    /// Keep the preset's boxes (unless an unbounded solver is chosen).
    Keep,
    /// No boxes, whatever the preset.
    Off,
    /// Boxes of margin `eps` voxel, `0 < eps < 1`.
    Eps(f64),
}

/// Why [`SolverParams::overridden`] refuses a combination; each front end words it with
/// its own option names.
#[derive(Copy, Clone, Debug, PartialEq)]
pub enum OverrideError {
    /// Boxes asked for together with the direct or CG solver.
    ClampNeedsBoundedSolver,
    /// A box margin outside `(0, 1)` voxel.
    ClampOutOfRange(f64),
}

/// Parameters of [`Solver::new`].
#[derive(Copy, Clone, Debug, PartialEq, Serialize)]
pub struct SolverParams {
    /// The solver. Default: [`SolverChoice::Auto`].
    pub choice: SolverChoice,
    /// Bytes the automatic choice lets the direct solver's Cholesky factor take
    /// (`8 * factor_nnz`); above, it iterates. The factor grows faster than the surface
    /// and its factorization is slower than the multigrid CG, so the default only takes
    /// the exact route where it is cheap: surfaces of up to about 3,000 vertices
    /// (`docs/design/solver-choice.md`). Raise it (or choose [`SolverChoice::Direct`]) to
    /// trade time for an answer exact to rounding. Default: `16 MiB`.
    pub direct_budget: usize,
    /// Settings of the conjugate gradient. Default: [`CgParams::default`].
    pub cg: CgParams,
    /// Settings of the bound-constrained solver (its boxes included). Default:
    /// [`BoundedParams::default`].
    pub bounded: BoundedParams,
    /// Settings of the sweeps. Default: [`SweepsParams::default`].
    pub sweeps: SweepsParams,
}

impl SolverParams {
    /// The iterative solvers' tolerance in voxels: [`CgParams::tolerance`] and
    /// [`BoundedParams::tolerance`], set together.
    pub fn with_tolerance(mut self, tolerance: f64) -> Self {
        self.cg.tolerance = tolerance;
        self.bounded.tolerance = tolerance;
        self
    }

    /// The same settings with every vertex clamped to its box of margin `eps` voxel
    /// ([`BoundedParams::clamp`]), which needs the bounded solver: `Auto` becomes
    /// [`SolverChoice::Bounded`].
    pub fn clamped(mut self, eps: Option<f64>) -> Self {
        self.bounded.clamp = eps;
        if eps.is_some() && self.choice == SolverChoice::Auto {
            self.choice = SolverChoice::Bounded;
        }
        self
    }

    /// A preset's solver settings with a front end's choices applied over them (the CLI's
    /// `--solver` and `--clamp`/`--no-clamp`, the Python `solver=` and `clamp=`):
    /// `choice`, when given, replaces the preset's; an explicit unbounded choice
    /// ([`SolverChoice::Direct`], [`SolverChoice::Cg`] or [`SolverChoice::Sweeps`]) or [`ClampOverride::Off`] drops
    /// the preset's boxes; [`ClampOverride::Eps`] sets them, which needs the bounded
    /// solver (`Auto`, or no choice, becomes [`SolverChoice::Bounded`]); dropping the
    /// voxel-art preset's boxes without a choice returns to [`SolverChoice::Auto`].
    pub fn overridden(
        self,
        choice: Option<SolverChoice>,
        clamp: ClampOverride,
    ) -> Result<Self, OverrideError> {
        let unbounded =
            matches!(choice, Some(SolverChoice::Direct | SolverChoice::Cg | SolverChoice::Sweeps));
        let eps = match clamp {
            ClampOverride::Eps(_) if unbounded => return Err(OverrideError::ClampNeedsBoundedSolver),
            ClampOverride::Eps(eps) if !(eps > 0.0 && eps < 1.0) => {
                return Err(OverrideError::ClampOutOfRange(eps))
            }
            ClampOverride::Eps(eps) => Some(eps),
            ClampOverride::Off => None,
            ClampOverride::Keep if unbounded => None,
            ClampOverride::Keep => self.bounded.clamp,
        };
        let mut p = self;
        p.choice = match choice {
            Some(c) => c,
            None if eps.is_some() => SolverChoice::Bounded,
            None if p.choice == SolverChoice::Bounded && clamp == ClampOverride::Off => SolverChoice::Auto,
            None => p.choice,
        };
        Ok(p.clamped(eps))
    }

    /// Checks the combination: boxes need [`SolverChoice::Bounded`].
    pub fn validate(&self) -> Result<(), RegularizeError> {
        if self.bounded.clamp.is_some() && !matches!(self.choice, SolverChoice::Bounded) {
            return Err(RegularizeError::InvalidParams(format!(
                "clamping needs the bounded solver, not {:?}",
                self.choice
            )));
        }
        self.sweeps.validate()
    }
}

impl Default for SolverParams {
    fn default() -> Self {
        SolverParams {
            choice: SolverChoice::Auto,
            direct_budget: 16 << 20,
            cg: CgParams::default(),
            bounded: BoundedParams::default(),
            sweeps: SweepsParams::default(),
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
    /// Bound-constrained conjugate gradient, possibly clamped.
    Bounded(BoundedSolver),
    /// Damped block-Jacobi sweeps.
    Sweeps(SweepsSolver),
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
        params.validate()?;
        Ok(match params.choice {
            SolverChoice::Direct => Solver::Direct(DirectSolver::for_surface(surface)?),
            SolverChoice::Cg => Solver::Cg(CgSolver::for_surface(surface, params.cg)?),
            SolverChoice::Bounded => Solver::Bounded(BoundedSolver::for_surface(surface, params.bounded)?),
            SolverChoice::Sweeps => Solver::Sweeps(SweepsSolver::for_surface(surface, params.sweeps)?),
            SolverChoice::Auto => {
                let budget = params.direct_budget as f64 / 8.0;
                if estimate_factor_nnz(surface.num_vertices()) <= 2.0 * budget {
                    let direct = DirectSolver::for_surface(surface)?;
                    if direct.factor_nnz() as f64 <= budget {
                        return Ok(Solver::Direct(direct));
                    }
                }
                Solver::Cg(CgSolver::for_surface(surface, params.cg)?)
            }
        })
    }

    /// `"direct"`, `"cg"`, `"bounded"` or `"sweeps"`.
    pub fn kind(&self) -> &'static str {
        match self {
            Solver::Direct(_) => "direct",
            Solver::Cg(_) => "cg",
            Solver::Bounded(_) => "bounded",
            Solver::Sweeps(_) => "sweeps",
        }
    }

    /// The box margin when the solver clamps.
    pub fn clamp(&self) -> Option<f64> {
        match self {
            Solver::Bounded(s) => s.params().clamp,
            _ => None,
        }
    }

    /// The flag the iterative solvers poll in their setup and iterations (the direct
    /// solver's factorization cannot be stopped, and is small).
    pub(crate) fn set_interrupt(&mut self, interrupt: Interrupt) {
        match self {
            Solver::Cg(s) => s.set_interrupt(interrupt),
            Solver::Bounded(s) => s.set_interrupt(interrupt),
            Solver::Sweeps(s) => s.set_interrupt(interrupt),
            Solver::Direct(_) => {}
        }
    }

    /// Minimizes `energy` as `request` asks: from its start, to its tolerance, reporting
    /// each iteration of the iterative solvers to its progress (the direct solver is exact,
    /// ignores the start and reports nothing).
    pub fn solve(
        &mut self,
        energy: &Energy<'_>,
        request: SolveRequest<'_>,
    ) -> Result<(Vec<DVec3>, SolveInfo), RegularizeError> {
        // The iterative solvers always get a listener (a silent one where none is given):
        // their iterations are then the same whether anyone listens or not.
        let SolveRequest { start, tolerance, quick_start, keep_cycle, progress } = request;
        let mut silent = |_: &Progress| {};
        let progress: &mut dyn FnMut(&Progress) = match progress {
            Some(p) => p,
            None => &mut silent,
        };
        let request = SolveRequest { start, tolerance, quick_start, keep_cycle, progress: Some(progress) };
        match self {
            Solver::Direct(s) => s.solve(energy).map(|(x, i)| (x, SolveInfo::Direct(i))),
            Solver::Cg(s) => s.solve(energy, request).map(|(x, i)| (x, SolveInfo::Cg(i))),
            Solver::Bounded(s) => s.solve(energy, request).map(|(x, i)| (x, SolveInfo::Bounded(i))),
            Solver::Sweeps(s) => {
                let SolveRequest { start, progress, .. } = request;
                let start = match start {
                    SolveStart::Input => None,
                    SolveStart::Given(x) => Some(x.to_vec()),
                    SolveStart::Owned(x) => Some(x),
                };
                let progress = progress.expect("a listener is always given above");
                s.solve(energy, start, progress).map(|(x, i)| (x, SolveInfo::Sweeps(i)))
            }
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
        let bounded = SolverParams { choice: SolverChoice::Bounded, ..Default::default() };
        assert_eq!(Solver::new(&small, &bounded).unwrap().kind(), "bounded");
        assert_eq!(SolverParams::default().clamped(Some(0.01)).choice, SolverChoice::Bounded);
        let direct = SolverParams { choice: SolverChoice::Direct, ..Default::default() }.clamped(Some(0.01));
        assert!(direct.validate().is_err());
    }

    #[test]
    fn front_end_overrides_of_the_presets_solver() {
        let (plain, art) = (SolverParams::default(), SolverParams::default().clamped(Some(0.01)));
        let o = |p: SolverParams, c, k| p.overridden(c, k).map(|p| (p.choice, p.bounded.clamp));
        use ClampOverride::{Eps, Keep, Off};
        assert_eq!(o(plain, None, Keep), Ok((SolverChoice::Auto, None)));
        assert_eq!(o(art, None, Keep), Ok((SolverChoice::Bounded, Some(0.01))));
        assert_eq!(o(art, None, Off), Ok((SolverChoice::Auto, None)));
        assert_eq!(o(art, Some(SolverChoice::Cg), Keep), Ok((SolverChoice::Cg, None)));
        assert_eq!(o(art, Some(SolverChoice::Bounded), Off), Ok((SolverChoice::Bounded, None)));
        assert_eq!(o(plain, None, Eps(0.05)), Ok((SolverChoice::Bounded, Some(0.05))));
        assert_eq!(o(plain, Some(SolverChoice::Bounded), Keep), Ok((SolverChoice::Bounded, None)));
        assert_eq!(
            o(plain, Some(SolverChoice::Direct), Eps(0.05)),
            Err(OverrideError::ClampNeedsBoundedSolver)
        );
        assert_eq!(o(plain, None, Eps(1.5)), Err(OverrideError::ClampOutOfRange(1.5)));
        assert_eq!("cg".parse(), Ok(SolverChoice::Cg));
        assert_eq!("gd".parse(), Ok(SolverChoice::Bounded));
        assert!("lu".parse::<SolverChoice>().is_err());
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
            let exact = DirectSolver::for_surface(&s).unwrap().factor_nnz() as f64;
            let est = estimate_factor_nnz(s.num_vertices());
            assert!((est / exact - 1.0).abs() < 0.35, "r = {r}: estimate {est} vs {exact}");
        }
    }
}
