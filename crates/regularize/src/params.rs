//! The front door's parameters and their presets.

use serde::Serialize;
use voxreg_digisurf::{DigitalSurface, RegionMap};
use voxreg_normals::{
    default_radius, AmbrosioTortorelli, AtInfo, AtParams, ConvolvedTrivial, DiffusedStaircase, FeatureField,
    IntegralInvariant, Interrupt, NormalEstimator, NormalField, QuadGraph, Trivial,
};

use crate::energy::EnergyParams;
use crate::error::RegularizeError;
use crate::mode::{Clamped, Creases, Fidelity, Mode, Refinement};
use crate::solver::{SolverChoice, SolverParams};
use crate::sweeps::SweepsParams;

/// The normal estimators of the alignment term's field.
#[derive(Copy, Clone, Debug, PartialEq, Eq, Default, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Estimator {
    /// Each surfel's own axis ([`Trivial`]).
    Trivial,
    /// Trivial normals averaged over a disc of the surface ([`ConvolvedTrivial`]).
    Convolved,
    /// Integral invariants: covariance of a ball intersected with the region
    /// ([`IntegralInvariant`]).
    #[default]
    Ii,
    /// Ambrosio-Tortorelli regularization of the integral invariants: smooth, but keeps
    /// sharp features ([`AmbrosioTortorelli`]).
    At,
    /// The staircase's normals diffused over the surface: cheap and smooth, no feature
    /// rule ([`DiffusedStaircase`]; the fast preset's first field).
    Diffused,
}

impl Estimator {
    /// Every estimator.
    pub const ALL: [Estimator; 5] =
        [Estimator::Trivial, Estimator::Convolved, Estimator::Ii, Estimator::At, Estimator::Diffused];

    /// `"trivial"`, `"convolved"`, `"ii"`, `"at"` or `"diffused"`.
    pub fn name(self) -> &'static str {
        match self {
            Estimator::Trivial => "trivial",
            Estimator::Convolved => "convolved",
            Estimator::Ii => "ii",
            Estimator::At => "at",
            Estimator::Diffused => "diffused",
        }
    }
}

impl std::fmt::Display for Estimator {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Estimator {
    type Err = String;

    /// An estimator's [`Estimator::name`].
    fn from_str(s: &str) -> Result<Self, String> {
        Estimator::ALL.into_iter().find(|e| e.name() == s).ok_or_else(|| {
            let names: Vec<String> = Estimator::ALL.iter().map(|e| format!("'{}'", e.name())).collect();
            format!("must be one of {}, got '{s}'", names.join(", "))
        })
    }
}

/// The initial normal field: which estimator, with which radius.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct NormalsParams {
    /// The estimator. Default: [`Estimator::Ii`].
    pub estimator: Estimator,
    /// Radius of the ball and disc estimators in physical units; `None` is the multigrid
    /// rule `3 h^(1/3)` kept within 3 to 12 voxels ([`default_radius`]; 3 at unit spacing),
    /// and for [`Estimator::Diffused`] 8 voxels of the finest axis.
    /// Default: `None`.
    pub radius: Option<f64>,
    /// Where `radius` is `None`: the radius in voxels along the coarsest axis (so
    /// `radius_voxels` times the largest spacing), instead of the multigrid rule. A preset
    /// sets it where the right scale is the voxel's, whatever the spacing
    /// ([`Params::voxel_art`]). Default: `None`.
    pub radius_voxels: Option<f64>,
    /// Settings of [`Estimator::At`]. Default: [`AtParams::default`].
    pub at: AtParams,
}

impl Default for NormalsParams {
    fn default() -> Self {
        NormalsParams { estimator: Estimator::Ii, radius: None, radius_voxels: None, at: AtParams::default() }
    }
}

/// The initial normal field and what its estimator reports.
#[derive(Clone, Debug)]
pub struct EstimatedNormals {
    /// One direction per surfel.
    pub field: NormalField,
    /// The Ambrosio-Tortorelli feature field (per vertex), for [`Estimator::At`].
    pub features: Option<FeatureField>,
    /// The Ambrosio-Tortorelli iterations and timings, for [`Estimator::At`].
    pub at_info: Option<AtInfo>,
}

impl NormalsParams {
    /// Checks the radius and the Ambrosio-Tortorelli settings.
    pub fn validate(&self) -> Result<(), RegularizeError> {
        for r in [self.radius, self.radius_voxels].into_iter().flatten() {
            if !(r.is_finite() && r > 0.0) {
                return Err(RegularizeError::InvalidParams(format!(
                    "the normals' radius must be finite and positive, got {r}"
                )));
            }
        }
        if self.estimator == Estimator::At {
            self.at.validate()?;
        }
        Ok(())
    }

    /// The radius the estimator uses on `surface` (physical units), or `None` for one
    /// without a radius.
    pub fn radius_on(&self, surface: &DigitalSurface) -> Option<f64> {
        match self.estimator {
            Estimator::Trivial => None,
            Estimator::Diffused => Some(
                self.explicit_radius(surface)
                    .unwrap_or_else(|| DiffusedStaircase::DEFAULT_RADIUS * surface.spacing().min_element()),
            ),
            _ => Some(self.explicit_radius(surface).unwrap_or_else(|| default_radius(surface))),
        }
    }

    /// `radius`, else `radius_voxels` in physical units on `surface`; `None` leaves the
    /// estimator its own rule.
    fn explicit_radius(&self, surface: &DigitalSurface) -> Option<f64> {
        self.radius.or_else(|| self.radius_voxels.map(|v| v * surface.spacing().max_element()))
    }

    /// The estimator as a trait object, with `radius` (`radius_voxels` needs the surface:
    /// [`NormalsParams::estimate`] resolves it).
    pub fn estimator(&self) -> Box<dyn NormalEstimator + Send + Sync> {
        let radius = self.radius;
        match self.estimator {
            Estimator::Trivial => Box::new(Trivial),
            Estimator::Convolved => Box::new(ConvolvedTrivial { radius }),
            Estimator::Ii => Box::new(IntegralInvariant { radius }),
            Estimator::At => Box::new(self.at_estimator()),
            Estimator::Diffused => Box::new(DiffusedStaircase { radius }),
        }
    }

    fn at_estimator(&self) -> AmbrosioTortorelli {
        AmbrosioTortorelli::new(self.at.clone(), Box::new(IntegralInvariant { radius: self.radius }))
    }

    /// Estimates the field on `surface`.
    pub fn estimate(&self, surface: &DigitalSurface) -> Result<EstimatedNormals, RegularizeError> {
        self.estimate_interruptible(surface, &Interrupt::never())
    }

    /// [`NormalsParams::estimate`], returning [`RegularizeError::Interrupted`] soon after
    /// `interrupt` is raised ([`NormalEstimator::estimate_interruptible`]).
    pub fn estimate_interruptible(
        &self,
        surface: &DigitalSurface,
        interrupt: &Interrupt,
    ) -> Result<EstimatedNormals, RegularizeError> {
        self.validate()?;
        // The estimators take a physical radius: `radius_voxels` resolved on this surface.
        let this = NormalsParams { radius: self.explicit_radius(surface), ..self.clone() };
        Ok(match this.estimator {
            Estimator::At => {
                let (field, features, info) =
                    this.at_estimator().estimate_with_info_interruptible(surface, interrupt)?;
                EstimatedNormals { field, features: Some(features), at_info: Some(info) }
            }
            _ => EstimatedNormals {
                field: this.estimator().estimate_interruptible(surface, interrupt)?,
                features: None,
                at_info: None,
            },
        })
    }

    /// [`NormalsParams::estimate_interruptible`] of [`Estimator::Diffused`] on the
    /// surface's surfel `graph` ([`QuadGraph::new`]), which the fast pipeline's
    /// re-estimates use too.
    pub(crate) fn diffused_on(
        &self,
        surface: &DigitalSurface,
        graph: &QuadGraph,
        interrupt: &Interrupt,
    ) -> Result<EstimatedNormals, RegularizeError> {
        self.validate()?;
        let field = DiffusedStaircase { radius: self.explicit_radius(surface) }
            .estimate_on(surface, graph, interrupt)?;
        Ok(EstimatedNormals { field, features: None, at_info: None })
    }
}

/// Everything the front door ([`crate::regularize`], [`crate::Regularizer`]) does, from
/// the volume's labels to the regularized positions.
///
/// Four presets: [`Params::default`] (the fidelity pipeline: one solve, then refinement
/// rounds with re-centring and weak alignment at creases), [`Params::papers`] (the
/// papers' single solve), [`Params::voxel_art`] (one solve clamped to the voxels'
/// boxes, so the result never self-intersects) and [`Params::fast`] (batches of sweeps
/// and cheap re-estimates, at about the cost of surface nets). What differs between the
/// fidelity and the clamped pipeline is the [`Mode`], which owns the parameters only one
/// of them reads.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Params {
    /// How labels form regions (materials). Default: every label its own region
    /// ([`RegionMap::per_label`]).
    pub regions: RegionMap,
    /// The initial normal field. Default: [`NormalsParams::default`] (integral invariants
    /// at the multigrid radius).
    pub normals: NormalsParams,
    /// The energy's weights. Default: `alpha = 1e-2, beta = 1, gamma = 0.1`
    /// ([`Params::ENERGY`]).
    pub energy: EnergyParams,
    /// Texture-aware fairness (paper, sec. 4.5): barycentres leave out the neighbours
    /// across a region boundary, so quad edges follow colour boundaries. Default: `false`.
    pub texture_aware: bool,
    /// Fairness along junction curves ([`crate::FairnessMask::junction_curves`]): the
    /// vertices where three regions or more meet take the barycenter of their neighbours
    /// along the junction only. Default: `true`.
    pub junction_fairness: bool,
    /// The solver, without boxes: the boxes are the clamped mode's ([`Clamped`]), which
    /// needs [`SolverChoice::Bounded`] (or `Auto`, which it makes bounded);
    /// [`Params::solver_params`] gives the solver's settings with them. Default:
    /// [`SolverParams::default`] (exact factorization for small surfaces, else multigrid
    /// CG, to `1e-3` voxel).
    pub solver: SolverParams,
    /// The pipeline around the solves: refinement and re-centring ([`Fidelity`]) or boxes
    /// ([`Clamped`]). Default: [`Fidelity::default`].
    pub mode: Mode,
    /// Fold-free post-condition, in either mode: after the last solve, the vertices of
    /// quads folded over their diagonal and of edge-adjacent quads folded onto each other
    /// (as `voxreg_quality` counts them) move back towards their input positions until
    /// none is left; each stays on the segment to its solved position, so inside its box
    /// when clamped. Default: `false` (`true` in [`Params::voxel_art`]).
    pub fold_free: bool,
}

impl Params {
    /// The energy weights of the default preset: `alpha = 1e-2, beta = 1, gamma = 0.1`.
    /// Stronger attachment than the papers' `1e-3`, which lets thin curved shapes shrink.
    pub const ENERGY: EnergyParams = EnergyParams { alpha: 1e-2, beta: 1.0, gamma: 0.1 };

    /// The papers' behaviour: their weights (`alpha = 1e-3, beta = 1, gamma = 0.1`), one
    /// solve, no refinement, no re-centring, uniform alignment ([`Fidelity::single`]).
    pub fn papers() -> Self {
        Params {
            energy: EnergyParams::default(),
            mode: Mode::Fidelity(Fidelity::single()),
            ..Default::default()
        }
    }

    /// The box margin, in voxels, of [`Params::voxel_art`] and of a front end's clamping
    /// option given without a margin ([`crate::Clamp::On`]).
    pub const CLAMP_MARGIN: f64 = Clamped::MARGIN;

    /// The most refinement rounds [`Params::validate`] accepts: each round is a solve,
    /// and the rounds' bookkeeping is allocated up front.
    pub const MAX_REFINE: usize = Refinement::MAX_ROUNDS;

    /// The depth kept inside thin voxels by [`Params::voxel_art`], in voxels
    /// ([`Clamped::thin_depth`]).
    pub const THIN_DEPTH: f64 = 0.3;

    /// Voxel art (MagicaVoxel models): every non-background label one solid region (the
    /// colours are materials of one object, not interfaces), one solve (blocky art is
    /// not a sampled smooth shape) with every vertex clamped to its box of margin `0.01`
    /// voxel, so the result has no self-intersection (the papers' Proposition 2); the
    /// boxes shrink around thin voxels so that one-voxel parts keep
    /// [`Params::THIN_DEPTH`] voxel of depth, and folds are removed afterwards
    /// ([`Params::fold_free`]). [`Params::with_smoothness`] trades roundness for
    /// blockiness. Normals: ii of radius [`Params::VOXEL_ART_RADIUS`] voxels, fairness
    /// `gamma = 1`: on the bundled models, smoother than
    /// radius 3 and `gamma = 0.1` with box edges at least as sharp
    /// (`docs/design/voxel-art-clamping.md`).
    pub fn voxel_art() -> Self {
        let solver = SolverParams { choice: SolverChoice::Bounded, ..Default::default() };
        let normals = NormalsParams { radius_voxels: Some(Self::VOXEL_ART_RADIUS), ..Default::default() };
        let boxes = Clamped { thin_depth: Some(Self::THIN_DEPTH), ..Clamped::margin(Self::CLAMP_MARGIN) };
        Params {
            regions: RegionMap::single_solid(),
            solver,
            mode: Mode::Clamped(boxes),
            fold_free: true,
            normals,
            energy: EnergyParams { gamma: 1.0, ..Self::ENERGY },
            ..Default::default()
        }
    }

    /// The fast pipeline, for speed on a par with surface nets: the staircase's normals
    /// diffused over [`voxreg_normals::DiffusedStaircase::DEFAULT_RADIUS`] voxels
    /// ([`Estimator::Diffused`]), then one batch of [`Params::FAST_SWEEPS`] damped
    /// block-Jacobi sweeps from the staircase ([`SolverChoice::Sweeps`]); no integral
    /// invariants, no conjugate gradient, no re-centring, crease weights or thin-sheet rule
    /// (`docs/design/fast-preset.md`). Refinement rounds, where asked for, re-estimate the
    /// normals between batches by diffusing the quads' vector areas over
    /// [`Params::FAST_RADIUS`] voxels ([`voxreg_normals::Diffused`]).
    pub fn fast() -> Self {
        let refinement = Refinement {
            rounds: 0,
            radius: Self::FAST_RADIUS,
            sheet_thickness: 0.0,
            creases: Creases { alignment: 1.0, ..Creases::default() },
            ..Refinement::default()
        };
        Params {
            normals: NormalsParams { estimator: Estimator::Diffused, ..Default::default() },
            solver: SolverParams {
                choice: SolverChoice::Sweeps,
                sweeps: SweepsParams { sweeps: Self::FAST_SWEEPS, ..SweepsParams::default() },
                ..Default::default()
            },
            mode: Mode::Fidelity(Fidelity { refinement, recentring: None, ..Fidelity::default() }),
            ..Default::default()
        }
    }

    /// The sweeps of [`Params::fast`]'s one batch: from a field diffused over 8 voxels, as
    /// accurate on the frontier's shapes as three batches of 8 with two re-estimates
    /// between them, for one setup and no re-estimate (`docs/design/fast-preset.md`).
    pub const FAST_SWEEPS: usize = 20;

    /// The re-estimates' radius of [`Params::fast`] with refinement rounds, in lattice steps
    /// ([`voxreg_normals::Diffused`]): wider than the fidelity pipeline's 3-voxel discs,
    /// since the field comes from quads only a batch of sweeps from the staircase
    /// (measured with batches of 8: on the sphere R = 20, 1.89 degrees at 3, 1.26 at 6).
    pub const FAST_RADIUS: f64 = 6.0;

    /// The ii normals' ball radius of [`Params::voxel_art`], in voxels
    /// ([`NormalsParams::radius_voxels`]).
    pub const VOXEL_ART_RADIUS: f64 = 2.0;

    /// The same parameters with the boxes of smoothness `s` in `(0, 1]`: each vertex
    /// moves at most `s` times half a voxel (less `0.005`) from its voxel corner along
    /// each axis. `1` is [`Params::voxel_art`]'s default (rounded), small values keep the
    /// model blocky (clean, with softened edges). Sets the clamped mode's margin to
    /// `1 - 0.99 s` voxel ([`Mode::with_margin`]), which needs the bounded solver (`Auto`
    /// becomes it).
    pub fn with_smoothness(mut self, s: f64) -> Result<Self, RegularizeError> {
        if !(s > 0.0 && s <= 1.0) {
            return Err(RegularizeError::InvalidParams(format!("the smoothness must be in (0, 1], got {s}")));
        }
        self.mode = self.mode.with_margin(1.0 - 0.99 * s);
        if self.solver.choice == SolverChoice::Auto {
            self.solver.choice = SolverChoice::Bounded;
        }
        Ok(self)
    }

    /// Checks every field's range and their combination.
    pub fn validate(&self) -> Result<(), RegularizeError> {
        self.energy.validate()?;
        self.normals.validate()?;
        self.solver.validate()?;
        if self.solver.bounded.clamp.is_some() || self.solver.bounded.thin_depth.is_some() {
            return Err(RegularizeError::InvalidParams(
                "the boxes are the clamped mode's (Mode::Clamped), not the solver's".into(),
            ));
        }
        self.mode.validate()?;
        if self.clamps() && matches!(self.solver.choice, SolverChoice::Direct | SolverChoice::Cg) {
            return Err(RegularizeError::InvalidParams(format!(
                "clamping needs the bounded solver, not {:?}",
                self.solver.choice
            )));
        }
        Ok(())
    }

    /// Whether the solver keeps every vertex in its box (the clamped mode).
    pub fn clamps(&self) -> bool {
        matches!(self.mode, Mode::Clamped(_))
    }

    /// The refinement rounds and their settings ([`Mode::refinement`]).
    pub fn refinement(&self) -> &Refinement {
        self.mode.refinement()
    }

    /// [`Params::refinement`], to change.
    pub fn refinement_mut(&mut self) -> &mut Refinement {
        self.mode.refinement_mut()
    }

    /// The solver's settings: [`Params::solver`] with the clamped mode's boxes
    /// ([`SolverParams::clamped`], [`crate::BoundedParams::thin_depth`]).
    pub fn solver_params(&self) -> SolverParams {
        match &self.mode {
            Mode::Clamped(c) => {
                let mut s = self.solver.clamped(Some(c.margin));
                s.bounded.thin_depth = c.thin_depth;
                s
            }
            Mode::Fidelity(_) => self.solver,
        }
    }
}

impl Default for Params {
    fn default() -> Self {
        Params {
            regions: RegionMap::per_label(),
            normals: NormalsParams::default(),
            energy: Self::ENERGY,
            texture_aware: false,
            junction_fairness: true,
            solver: SolverParams::default(),
            mode: Mode::default(),
            fold_free: false,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_validate_and_differ_where_documented() {
        for p in [Params::default(), Params::papers(), Params::voxel_art(), Params::fast()] {
            p.validate().unwrap();
        }
        assert_eq!(Params::fast().solver.choice, SolverChoice::Sweeps);
        assert!(!Params::fast().clamps() && Params::fast().normals.estimator == Estimator::Diffused);
        assert_eq!(Params::papers().energy.alpha, 1e-3);
        assert!(Params::voxel_art().clamps() && !Params::default().clamps());
        assert_eq!(Params::voxel_art().regions, RegionMap::single_solid());
        assert!(Params::voxel_art().fold_free && !Params::default().fold_free);
        let blocky = Params::voxel_art().with_smoothness(0.5).unwrap();
        assert_eq!(blocky.solver_params().bounded.clamp, Some(1.0 - 0.495));
        assert_eq!(blocky.solver_params().bounded.thin_depth, Some(Params::THIN_DEPTH));
        assert_eq!(blocky.solver_params().choice, SolverChoice::Bounded);
        assert!(Params::voxel_art().with_smoothness(0.0).is_err());
        assert!(Params::voxel_art().with_smoothness(1.5).is_err());
        let with = |f: &dyn Fn(&mut Params)| {
            let mut p = Params::default();
            f(&mut p);
            p.validate()
        };
        assert!(with(&|p| p.refinement_mut().creases.alignment = 2.0).is_err());
        assert!(with(&|p| p.mode.fidelity_mut().unwrap().intermediate_tolerance = 0.5).is_err());
        for t in [-1.0, f64::NAN, f64::INFINITY] {
            assert!(with(&|p| p.refinement_mut().sheet_thickness = t).is_err());
        }
        assert!(with(&|p| p.refinement_mut().sheet_thickness = 0.0).is_ok());
        // The boxes are the mode's: the solver's own are refused, and so is an unbounded
        // solver in the clamped mode.
        assert!(with(&|p| p.solver.bounded.clamp = Some(0.01)).is_err());
        assert!(with(&|p| p.mode = p.mode.with_margin(1.5)).is_err());
        let mut cg = Params::voxel_art();
        cg.solver.choice = SolverChoice::Cg;
        assert!(cg.validate().is_err());
        cg.solver.choice = SolverChoice::Auto;
        assert_eq!(cg.solver_params(), Params::voxel_art().solver_params());
        let bad = Params {
            normals: NormalsParams { radius: Some(-1.0), ..Default::default() },
            ..Default::default()
        };
        assert!(bad.validate().is_err());
        let bad = NormalsParams { radius_voxels: Some(f64::NAN), ..Default::default() };
        assert!(bad.validate().is_err());
    }

    #[test]
    fn a_radius_in_voxels_follows_the_coarsest_spacing_and_yields_to_an_explicit_one() {
        let volume = voxreg_digisurf::LabelVolume::from_fn([9, 9, 9], |[x, y, z]| {
            u32::from((x as i64 - 4).pow(2) + (y as i64 - 4).pow(2) + (z as i64 - 4).pow(2) <= 9)
        })
        .with_spacing(glam::DVec3::new(0.5, 0.5, 0.25))
        .unwrap();
        let surface = DigitalSurface::from_volume(&volume).unwrap();
        let voxels = Params::voxel_art().normals;
        assert_eq!(voxels.radius_on(&surface), Some(Params::VOXEL_ART_RADIUS * 0.5));
        let explicit = NormalsParams { radius: Some(0.7), ..voxels.clone() };
        assert_eq!(explicit.radius_on(&surface), Some(0.7));
        // The field is the one of the physical radius the voxels make.
        let physical = NormalsParams { radius: Some(1.0), radius_voxels: None, ..voxels.clone() };
        let (a, b) = (voxels.estimate(&surface).unwrap().field, physical.estimate(&surface).unwrap().field);
        assert_eq!(a, b);
    }
}
