//! The front door's report: what was done, with which parameters, how long it took.

use serde::Serialize;
use voxreg_digisurf::SurfaceCounts;
use voxreg_normals::AtInfo;

use crate::energy::EnergyTerms;
use crate::info::SolveInfo;
use crate::params::Params;

/// Seconds spent in each stage of a run (all rounds together).
#[derive(Copy, Clone, Debug, Default, PartialEq, Serialize)]
pub struct StageTimes {
    /// Building the digital surface (0 when the regularizer was given one).
    pub surface: f64,
    /// Estimating the initial normal field (0 when it was given or reused).
    pub normals: f64,
    /// The operator's structure and numeric assembly (pattern, hierarchy, coefficients).
    pub assemble: f64,
    /// Symbolic analysis, numeric factorization, triangular solves or iterations.
    pub solve: f64,
    /// Normal refinement and re-centring between solves.
    pub refine: f64,
}

impl StageTimes {
    /// The sum of every stage.
    pub fn total(&self) -> f64 {
        self.surface + self.normals + self.assemble + self.solve + self.refine
    }
}

/// The initial normal field's estimator.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct NormalsReport {
    /// `"trivial"`, `"convolved"`, `"ii"`, `"at"`, `"diffused"`, or `"given"` when the
    /// caller supplied the field.
    pub estimator: &'static str,
    /// The radius used, in physical units (`None` without one).
    pub radius: Option<f64>,
    /// The Ambrosio-Tortorelli iterations and timings.
    pub at: Option<AtInfo>,
}

/// The energy of the last solve's terms (its normals and attachment targets) at the
/// input positions and at the result.
#[derive(Copy, Clone, Debug, PartialEq, Serialize)]
pub struct EnergyReport {
    /// At the input (staircase) positions.
    pub before: EnergyTerms,
    /// At the regularized positions.
    pub after: EnergyTerms,
}

/// What a run did: serializable (the CLI's `--report` is this struct as JSON).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Report {
    /// The parameters of the run.
    pub params: Params,
    /// The digital surface's cells.
    pub counts: SurfaceCounts,
    /// The initial normal field.
    pub normals: NormalsReport,
    /// Seconds per stage.
    pub stages: StageTimes,
    /// Energy before and after.
    pub energy: EnergyReport,
    /// Every solve's report, in order (`1 + refine` of them).
    pub solves: Vec<SolveInfo>,
}

impl Report {
    /// The last solve's report.
    pub fn last_solve(&self) -> &SolveInfo {
        self.solves.last().expect("a run solves at least once")
    }

    /// One line for people: `"N quads, M vertices; energy a -> b; relative gradient g"`
    /// (the CLI's summary, also the Python `Mesh.summary`).
    pub fn summary(&self) -> String {
        format!(
            "{} quads, {} vertices; energy {:.6e} -> {:.6e}; relative gradient {:.1e}",
            self.counts.surfels,
            self.counts.vertices,
            self.energy.before.total,
            self.energy.after.total,
            self.last_solve().relative_gradient(),
        )
    }

    /// Whether every solve met its stopping rule.
    pub fn converged(&self) -> bool {
        self.solves.iter().all(SolveInfo::converged)
    }
}
