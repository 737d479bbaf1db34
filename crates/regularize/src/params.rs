//! The front door's parameters and their presets.

use serde::Serialize;
use voxreg_digisurf::{DigitalSurface, RegionMap};
use voxreg_normals::{
    default_radius, AmbrosioTortorelli, AtInfo, AtParams, ConvolvedTrivial, FeatureField, IntegralInvariant,
    Interrupt, NormalEstimator, NormalField, Trivial,
};

use crate::energy::EnergyParams;
use crate::error::RegularizeError;
use crate::solver::{SolverChoice, SolverParams};

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
}

impl Estimator {
    /// Every estimator.
    pub const ALL: [Estimator; 4] = [Estimator::Trivial, Estimator::Convolved, Estimator::Ii, Estimator::At];

    /// `"trivial"`, `"convolved"`, `"ii"` or `"at"`.
    pub fn name(self) -> &'static str {
        match self {
            Estimator::Trivial => "trivial",
            Estimator::Convolved => "convolved",
            Estimator::Ii => "ii",
            Estimator::At => "at",
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
    /// rule `3 h^(1/3)` kept within 3 to 12 voxels ([`default_radius`]; 3 at unit spacing).
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
}

/// Everything the front door ([`crate::regularize`], [`crate::Regularizer`]) does, from
/// the volume's labels to the regularized positions.
///
/// Four presets: [`Params::default`] (the fidelity pipeline: one solve, then refinement
/// rounds with re-centring and weak alignment at creases), [`Params::papers`] (the
/// papers' single solve), [`Params::voxel_art`] (one solve clamped to the voxels'
/// boxes, so the result never self-intersects) and [`Params::fast`] (batches of sweeps
/// and cheap re-estimates, at about the cost of surface nets).
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
    /// Refinement rounds: after each solve, the normal field is re-estimated from the
    /// regularized quads ([`voxreg_normals::Refined`]) and the energy solved again.
    /// Default: `3`.
    pub refine: usize,
    /// Tolerance of the solves whose result only feeds a refinement round (every solve
    /// but the last), as a multiple of the iterative solver's tolerance; the last solve
    /// stops at the tolerance itself. Their positions only go into the refined normals
    /// and the re-centring, which can amplify what they leave: at `2` the output stays
    /// within the tolerance of the one with every round solved to it (`1`), and a chunked
    /// run stays within 1e-2 voxel of the whole volume's, while larger factors save a few
    /// iterations but let some vertices move further (at `3`, 1.2e-2 voxel between a
    /// chunked and a whole run of the synthetic tissue; at `10` a tenth of a voxel on
    /// bunny-128; `docs/design/intermediate-tolerance.md`). Default: `2`.
    pub intermediate_tolerance: f64,
    /// Radius, in voxels, of the disc whose regularized quad normals are averaged into a
    /// refined normal. Default: `3`.
    pub refine_radius: f64,
    /// Feature rule of the refinement: a quad enters the average if its regularized
    /// normal is within this angle (degrees) of the normal being refined, its weight
    /// falling to 0 over a ramp of `voxreg_normals::FEATURE_RAMP_DEG` centred on it (a
    /// continuous rule: see `voxreg_normals::Refined`). Default: `30`.
    pub feature_angle_deg: f64,
    /// Size preservation (re-centring): before each refinement solve, the attachment
    /// targets move by minus the smoothed displacement of the last solve, measured
    /// outside digital plateaus; this cancels the inward drift of thin curved shapes. On
    /// anisotropic voxels the quad centres are weighted as samples by their precision,
    /// long quads' sagitta is lifted out of the measurement, and the interiors of
    /// plateaus facing a coarse axis are attached and aligned with the inverse variance
    /// of their level (docs/design/anisotropic-spacing.md).
    /// Ignored when the solver clamps (its boxes are centred on the input, which
    /// Proposition 2 needs). Default: `true`.
    pub preserve_size: bool,
    /// Standard deviation, in voxels, of the smoothing of displacements used by the
    /// re-centring. Default: `3`.
    pub recentre_sigma: f64,
    /// Alignment weight (a multiplier of `beta`) of the quads that straddle a crease
    /// (their normal more than `crease_angle_deg` from an edge-neighbour's on the same
    /// interface and from their own axis) and of those within `crease_dilation` rings of
    /// them. A quad straddling a crease, fully aligned, would be pinned to both sides'
    /// planes at once and collapse into a sliver; a weak alignment lets it fold across.
    /// Applied when the pipeline refines (`refine > 0`); `1` keeps the uniform weight.
    /// Default: `0.015`.
    pub crease_alignment: f64,
    /// The crease angle in degrees (see `crease_alignment`): the middle of the same ramp,
    /// over which the weight goes from `1` to `crease_alignment`. Default: `20`.
    pub crease_angle_deg: f64,
    /// Rings of quads around the straddling ones that also get the weak alignment.
    /// Default: `1`.
    pub crease_dilation: usize,
    /// Thin sheets: the quads of a region thinner than this along its normal (in voxels
    /// of the finest spacing; a membrane one or two voxels thick between two other
    /// labels) keep the normals of the first refinement round through the later rounds,
    /// fully below `sheet_thickness - 0.5` and not at all from `sheet_thickness + 0.5`.
    /// A sheet's tilt is held only by the weak attachment, and refining its normals again
    /// and again from that tilt does not settle (docs/design/thin-sheets.md). `0` refines
    /// every quad in every round. Default: `2.5`.
    pub sheet_thickness: f64,
    /// Texture-aware fairness (paper, sec. 4.5): barycentres leave out the neighbours
    /// across a region boundary, so quad edges follow colour boundaries. Default: `false`.
    pub texture_aware: bool,
    /// Fairness along junction curves ([`crate::FairnessMask::junction_curves`]): the
    /// vertices where three regions or more meet take the barycenter of their neighbours
    /// along the junction only. Default: `true`.
    pub junction_fairness: bool,
    /// The solver and its boxes. Default: [`SolverParams::default`] (exact factorization
    /// for small surfaces, else multigrid CG, to `1e-3` voxel; no clamping).
    pub solver: SolverParams,
    /// Fold-free post-condition: after the last solve, the vertices of quads folded over
    /// their diagonal and of edge-adjacent quads folded onto each other (as
    /// `voxreg_quality` counts them) move back towards their input positions until none is
    /// left; each stays on the segment to its solved position, so inside its box.
    /// Default: `false` (`true` in [`Params::voxel_art`]).
    pub fold_free: bool,
}

impl Params {
    /// The energy weights of the default preset: `alpha = 1e-2, beta = 1, gamma = 0.1`.
    /// Stronger attachment than the papers' `1e-3`, which lets thin curved shapes shrink.
    pub const ENERGY: EnergyParams = EnergyParams { alpha: 1e-2, beta: 1.0, gamma: 0.1 };

    /// The papers' behaviour: their weights (`alpha = 1e-3, beta = 1, gamma = 0.1`), one
    /// solve, no refinement, no re-centring, uniform alignment.
    pub fn papers() -> Self {
        Params {
            energy: EnergyParams::default(),
            refine: 0,
            preserve_size: false,
            crease_alignment: 1.0,
            ..Default::default()
        }
    }

    /// The box margin, in voxels, of [`Params::voxel_art`] and of a front end's clamping
    /// option given without a margin ([`crate::Clamp::On`]).
    pub const CLAMP_MARGIN: f64 = 0.01;

    /// The most refinement rounds [`Params::validate`] accepts: each round is a solve,
    /// and the rounds' bookkeeping is allocated up front.
    pub const MAX_REFINE: usize = 100;

    /// The depth kept inside thin voxels by [`Params::voxel_art`], in voxels
    /// ([`crate::BoundedParams::thin_depth`]).
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
        let mut solver = SolverParams::default().clamped(Some(Self::CLAMP_MARGIN));
        solver.bounded.thin_depth = Some(Self::THIN_DEPTH);
        let normals = NormalsParams { radius_voxels: Some(Self::VOXEL_ART_RADIUS), ..Default::default() };
        Params {
            regions: RegionMap::single_solid(),
            refine: 0,
            solver,
            fold_free: true,
            normals,
            energy: EnergyParams { gamma: 1.0, ..Self::ENERGY },
            ..Default::default()
        }
    }

    /// The fast pipeline, for speed on a par with surface nets: trivial normals, then four
    /// batches of [`crate::SweepsParams::default`]'s 8 damped block-Jacobi sweeps from the
    /// staircase ([`SolverChoice::Sweeps`]), the normals re-estimated between batches by
    /// diffusing the quads' vector areas over [`Params::FAST_RADIUS`] voxels
    /// ([`voxreg_normals::Diffused`]); no integral invariants, no conjugate gradient, no
    /// re-centring, crease weights or thin-sheet rule (`docs/design/fast-preset.md`).
    pub fn fast() -> Self {
        Params {
            normals: NormalsParams { estimator: Estimator::Trivial, ..Default::default() },
            refine: 3,
            refine_radius: Self::FAST_RADIUS,
            preserve_size: false,
            crease_alignment: 1.0,
            sheet_thickness: 0.0,
            solver: SolverParams { choice: SolverChoice::Sweeps, ..Default::default() },
            ..Default::default()
        }
    }

    /// The re-estimates' radius of [`Params::fast`], in lattice steps
    /// ([`voxreg_normals::Diffused`]): wider than the fidelity pipeline's 3-voxel discs,
    /// since the field comes from quads only 8 sweeps from the staircase (on the sphere
    /// R = 20, 1.89 degrees at 3, 1.26 at 6).
    pub const FAST_RADIUS: f64 = 6.0;

    /// The ii normals' ball radius of [`Params::voxel_art`], in voxels
    /// ([`NormalsParams::radius_voxels`]).
    pub const VOXEL_ART_RADIUS: f64 = 2.0;

    /// The same parameters with the boxes of smoothness `s` in `(0, 1]`: each vertex
    /// moves at most `s` times half a voxel (less `0.005`) from its voxel corner along
    /// each axis. `1` is [`Params::voxel_art`]'s default (rounded), small values keep the
    /// model blocky (clean, with softened edges). Sets the clamping margin to
    /// `1 - 0.99 s` voxel, which needs the bounded solver.
    pub fn with_smoothness(mut self, s: f64) -> Result<Self, RegularizeError> {
        if !(s > 0.0 && s <= 1.0) {
            return Err(RegularizeError::InvalidParams(format!("the smoothness must be in (0, 1], got {s}")));
        }
        let thin = self.solver.bounded.thin_depth;
        self.solver = self.solver.clamped(Some(1.0 - 0.99 * s));
        self.solver.bounded.thin_depth = thin;
        Ok(self)
    }

    /// Checks every field's range and their combination.
    pub fn validate(&self) -> Result<(), RegularizeError> {
        self.energy.validate()?;
        self.normals.validate()?;
        self.solver.validate()?;
        if self.refine > Self::MAX_REFINE {
            return Err(RegularizeError::InvalidParams(format!(
                "the refinement rounds must be at most {}, got {}",
                Self::MAX_REFINE,
                self.refine
            )));
        }
        let positive = |x: f64| x.is_finite() && x > 0.0;
        if !positive(self.refine_radius) || !positive(self.recentre_sigma) {
            return Err(RegularizeError::InvalidParams(format!(
                "the refinement radius and the re-centring sigma must be positive and finite, got {} and {}",
                self.refine_radius, self.recentre_sigma
            )));
        }
        if !(self.intermediate_tolerance.is_finite() && self.intermediate_tolerance >= 1.0) {
            return Err(RegularizeError::InvalidParams(format!(
                "the intermediate tolerance must be a finite factor of at least 1, got {}",
                self.intermediate_tolerance
            )));
        }
        if !(self.crease_alignment >= 0.0 && self.crease_alignment <= 1.0) {
            return Err(RegularizeError::InvalidParams(format!(
                "the crease alignment weight must be in [0, 1], got {}",
                self.crease_alignment
            )));
        }
        if !(self.sheet_thickness.is_finite() && self.sheet_thickness >= 0.0) {
            return Err(RegularizeError::InvalidParams(format!(
                "the sheet thickness must be finite and non-negative, got {}",
                self.sheet_thickness
            )));
        }
        for (what, a) in [("feature", self.feature_angle_deg), ("crease", self.crease_angle_deg)] {
            if !(a > 0.0 && a <= 180.0) {
                return Err(RegularizeError::InvalidParams(format!(
                    "the {what} angle must be in (0, 180] degrees, got {a}"
                )));
            }
        }
        Ok(())
    }

    /// Whether the solver keeps every vertex in its box.
    pub fn clamps(&self) -> bool {
        self.solver.choice == SolverChoice::Bounded && self.solver.bounded.clamp.is_some()
    }
}

impl Default for Params {
    fn default() -> Self {
        Params {
            regions: RegionMap::per_label(),
            normals: NormalsParams::default(),
            energy: Self::ENERGY,
            refine: 3,
            intermediate_tolerance: 2.0,
            refine_radius: 3.0,
            feature_angle_deg: 30.0,
            preserve_size: true,
            recentre_sigma: 3.0,
            crease_alignment: 0.015,
            crease_angle_deg: 20.0,
            crease_dilation: 1,
            sheet_thickness: 2.5,
            texture_aware: false,
            junction_fairness: true,
            solver: SolverParams::default(),
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
        assert!(!Params::fast().clamps() && Params::fast().normals.estimator == Estimator::Trivial);
        assert_eq!(Params::papers().energy.alpha, 1e-3);
        assert!(Params::voxel_art().clamps() && !Params::default().clamps());
        assert_eq!(Params::voxel_art().regions, RegionMap::single_solid());
        assert!(Params::voxel_art().fold_free && !Params::default().fold_free);
        let blocky = Params::voxel_art().with_smoothness(0.5).unwrap();
        assert_eq!(blocky.solver.bounded.clamp, Some(1.0 - 0.495));
        assert_eq!(blocky.solver.bounded.thin_depth, Some(Params::THIN_DEPTH));
        assert!(Params::voxel_art().with_smoothness(0.0).is_err());
        assert!(Params::voxel_art().with_smoothness(1.5).is_err());
        let bad = Params { crease_alignment: 2.0, ..Default::default() };
        assert!(bad.validate().is_err());
        let bad = Params { intermediate_tolerance: 0.5, ..Default::default() };
        assert!(bad.validate().is_err());
        for t in [-1.0, f64::NAN, f64::INFINITY] {
            assert!(Params { sheet_thickness: t, ..Default::default() }.validate().is_err());
        }
        assert!(Params { sheet_thickness: 0.0, ..Default::default() }.validate().is_ok());
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
