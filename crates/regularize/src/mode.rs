//! The pipeline's modes ([`Mode`]): what runs after the first solve, and with which
//! parameters. Each mode owns exactly the parameters it reads, so no field of the front
//! door's parameters is ignored because another is set.

use serde::Serialize;

use crate::error::RegularizeError;

/// The alignment weights at creases during refinement ([`Refinement::creases`]).
#[derive(Copy, Clone, Debug, PartialEq, Serialize)]
#[non_exhaustive]
pub struct Creases {
    /// Alignment weight (a multiplier of `beta`) of the quads that straddle a crease
    /// (their normal more than `angle_deg` from an edge-neighbour's on the same interface
    /// and from their own axis) and of those within `dilation` rings of them. A quad
    /// straddling a crease, fully aligned, would be pinned to both sides' planes at once
    /// and collapse into a sliver; a weak alignment lets it fold across. `1` keeps the
    /// uniform weight. Default: `0.015`.
    pub alignment: f64,
    /// The crease angle in degrees: the middle of the ramp over which the weight goes
    /// from `1` to `alignment`. Default: `20`.
    pub angle_deg: f64,
    /// Rings of quads around the straddling ones that also get the weak alignment.
    /// Default: `1`.
    pub dilation: usize,
}

impl Creases {
    /// The uniform alignment (weight `1` everywhere), the papers' behaviour.
    pub const UNIFORM: Creases = Creases { alignment: 1.0, angle_deg: 20.0, dilation: 1 };
}

impl Default for Creases {
    fn default() -> Self {
        Creases { alignment: 0.015, angle_deg: 20.0, dilation: 1 }
    }
}

/// Normal refinement: after each solve, the normal field is re-estimated from the
/// regularized quads ([`voxreg_normals::Refined`]) and the energy solved again, `rounds`
/// times. Both modes refine; with `rounds == 0` there is one solve and the other fields
/// have nothing to act on.
#[derive(Copy, Clone, Debug, PartialEq, Serialize)]
#[non_exhaustive]
pub struct Refinement {
    /// Refinement rounds, at most [`Refinement::MAX_ROUNDS`]. Default: `3` in the
    /// fidelity mode, `0` in the clamped one.
    pub rounds: usize,
    /// Radius, in voxels, of the disc whose regularized quad normals are averaged into a
    /// refined normal. Default: `3`.
    pub radius: f64,
    /// Feature rule of the refinement: a quad enters the average if its regularized
    /// normal is within this angle (degrees) of the normal being refined, its weight
    /// falling to 0 over a ramp of `voxreg_normals::FEATURE_RAMP_DEG` centred on it (a
    /// continuous rule: see `voxreg_normals::Refined`). Default: `30`.
    pub feature_angle_deg: f64,
    /// Thin sheets: the quads of a region thinner than this along its normal (in voxels
    /// of the finest spacing; a membrane one or two voxels thick between two other
    /// labels) keep the normals of the first refinement round through the later rounds,
    /// fully below `sheet_thickness - 0.5` and not at all from `sheet_thickness + 0.5`.
    /// A sheet's tilt is held only by the weak attachment, and refining its normals again
    /// and again from that tilt does not settle (docs/design/thin-sheets.md). `0` refines
    /// every quad in every round. Default: `2.5`.
    pub sheet_thickness: f64,
    /// Weak alignment at creases. Default: [`Creases::default`].
    pub creases: Creases,
}

impl Refinement {
    /// The most rounds [`Mode::validate`] accepts: each round is a solve, and the rounds'
    /// bookkeeping is allocated up front.
    pub const MAX_ROUNDS: usize = 100;

    /// `rounds` rounds with the default settings.
    pub fn rounds(rounds: usize) -> Self {
        Refinement { rounds, ..Default::default() }
    }

    fn validate(&self) -> Result<(), RegularizeError> {
        if self.rounds > Self::MAX_ROUNDS {
            return Err(RegularizeError::InvalidParams(format!(
                "the refinement rounds must be at most {}, got {}",
                Self::MAX_ROUNDS,
                self.rounds
            )));
        }
        if !(self.radius.is_finite() && self.radius > 0.0) {
            return Err(RegularizeError::InvalidParams(format!(
                "the refinement radius must be positive and finite, got {}",
                self.radius
            )));
        }
        if !(self.creases.alignment >= 0.0 && self.creases.alignment <= 1.0) {
            return Err(RegularizeError::InvalidParams(format!(
                "the crease alignment weight must be in [0, 1], got {}",
                self.creases.alignment
            )));
        }
        if !(self.sheet_thickness.is_finite() && self.sheet_thickness >= 0.0) {
            return Err(RegularizeError::InvalidParams(format!(
                "the sheet thickness must be finite and non-negative, got {}",
                self.sheet_thickness
            )));
        }
        for (what, a) in [("feature", self.feature_angle_deg), ("crease", self.creases.angle_deg)] {
            if !(a > 0.0 && a <= 180.0) {
                return Err(RegularizeError::InvalidParams(format!(
                    "the {what} angle must be in (0, 180] degrees, got {a}"
                )));
            }
        }
        Ok(())
    }
}

impl Default for Refinement {
    fn default() -> Self {
        Refinement {
            rounds: 3,
            radius: 3.0,
            feature_angle_deg: 30.0,
            sheet_thickness: 2.5,
            creases: Creases::default(),
        }
    }
}

/// Size preservation (re-centring, [`Fidelity::recentring`]): before each refinement solve,
/// the attachment targets move by minus the smoothed displacement of the last solve,
/// measured outside digital plateaus; this cancels the inward drift of thin curved shapes.
/// On anisotropic voxels the quad centres are weighted as samples by their precision,
/// long quads' sagitta is lifted out of the measurement, and the interiors of plateaus
/// facing a coarse axis are attached and aligned with the inverse variance of their level
/// (docs/design/anisotropic-spacing.md).
#[derive(Copy, Clone, Debug, PartialEq, Serialize)]
#[non_exhaustive]
pub struct Recentring {
    /// Standard deviation, in voxels, of the smoothing of displacements. Default: `3`.
    pub sigma: f64,
}

impl Default for Recentring {
    fn default() -> Self {
        Recentring { sigma: 3.0 }
    }
}

/// The fidelity mode: unclamped solves, refined and re-centred, for sampled smooth
/// shapes (the default preset; the papers' with no rounds).
#[derive(Copy, Clone, Debug, PartialEq, Serialize)]
#[non_exhaustive]
pub struct Fidelity {
    /// The refinement rounds. Default: [`Refinement::default`] (3 rounds).
    pub refinement: Refinement,
    /// Tolerance of the solves whose result only feeds a refinement round (every solve
    /// but the last), as a multiple of the conjugate gradient's tolerance (the direct
    /// solver is exact, the bounded one keeps its own); the last solve stops at the
    /// tolerance itself. Their positions only go into the refined normals and the
    /// re-centring, which can amplify what they leave: at `2` the output stays within the
    /// tolerance of the one with every round solved to it (`1`), and a chunked run stays
    /// within 1e-2 voxel of the whole volume's, while larger factors save a few iterations
    /// but let some vertices move further (at `3`, 1.2e-2 voxel between a chunked and a
    /// whole run of the synthetic tissue; at `10` a tenth of a voxel on bunny-128;
    /// `docs/design/intermediate-tolerance.md`). Default: `2`.
    pub intermediate_tolerance: f64,
    /// Size preservation between refinement rounds; `None`: the targets stay the input.
    /// Default: `Some(Recentring::default())`.
    pub recentring: Option<Recentring>,
}

impl Default for Fidelity {
    fn default() -> Self {
        Fidelity {
            refinement: Refinement::default(),
            intermediate_tolerance: 2.0,
            recentring: Some(Recentring::default()),
        }
    }
}

impl Fidelity {
    /// The papers' single solve: no refinement round, no re-centring, uniform alignment.
    pub fn single() -> Self {
        let refinement = Refinement { rounds: 0, creases: Creases::UNIFORM, ..Default::default() };
        Fidelity { refinement, recentring: None, ..Default::default() }
    }
}

/// The clamped mode: every vertex stays in its box around its input position, so the
/// result has no self-intersection (the papers' Proposition 2); solved by the bounded
/// solver. The boxes are centred on the input, so the targets are never re-centred.
#[derive(Copy, Clone, Debug, PartialEq, Serialize)]
#[non_exhaustive]
pub struct Clamped {
    /// The box margin `eps` in voxels, `0 < eps < 1`: each box has edge `(1 - eps) h`
    /// (the bounded solver's `clamp`). Default: [`Clamped::MARGIN`].
    pub margin: f64,
    /// The depth, in voxels, kept inside every thin voxel
    /// (the bounded solver's `thin_depth`); `None` keeps the uniform boxes.
    /// Default: `None` (0.3 voxel in the voxel-art preset).
    pub thin_depth: Option<f64>,
    /// Refinement rounds between clamped solves. Default: none
    /// (`Refinement { rounds: 0, .. }`).
    pub refinement: Refinement,
}

impl Clamped {
    /// The box margin of the voxel-art preset and of a front end's clamping option given
    /// without a margin, in voxels.
    pub const MARGIN: f64 = 0.01;

    /// Boxes of margin `margin` voxel, without thin depth or refinement.
    pub fn margin(margin: f64) -> Self {
        Clamped { margin, thin_depth: None, refinement: Refinement { rounds: 0, ..Default::default() } }
    }
}

impl Default for Clamped {
    fn default() -> Self {
        Clamped::margin(Clamped::MARGIN)
    }
}

/// What the pipeline does around its solves: the fidelity mode (refinement and
/// re-centring, unclamped) or the clamped mode (boxes).
#[derive(Copy, Clone, Debug, PartialEq, Serialize)]
#[serde(rename_all = "snake_case")]
#[non_exhaustive]
pub enum Mode {
    /// Unclamped solves, refined and re-centred.
    Fidelity(Fidelity),
    /// Solves clamped to the voxels' boxes.
    Clamped(Clamped),
}

impl Default for Mode {
    fn default() -> Self {
        Mode::Fidelity(Fidelity::default())
    }
}

impl Mode {
    /// The refinement rounds and their settings, in either mode.
    pub fn refinement(&self) -> &Refinement {
        match self {
            Mode::Fidelity(f) => &f.refinement,
            Mode::Clamped(c) => &c.refinement,
        }
    }

    /// [`Mode::refinement`], to change.
    pub fn refinement_mut(&mut self) -> &mut Refinement {
        match self {
            Mode::Fidelity(f) => &mut f.refinement,
            Mode::Clamped(c) => &mut c.refinement,
        }
    }

    /// The clamped mode's boxes, if this is it.
    pub fn clamped(&self) -> Option<&Clamped> {
        match self {
            Mode::Clamped(c) => Some(c),
            Mode::Fidelity(_) => None,
        }
    }

    /// [`Mode::clamped`], to change.
    pub fn clamped_mut(&mut self) -> Option<&mut Clamped> {
        match self {
            Mode::Clamped(c) => Some(c),
            Mode::Fidelity(_) => None,
        }
    }

    /// The fidelity mode's settings, if this is it.
    pub fn fidelity(&self) -> Option<&Fidelity> {
        match self {
            Mode::Fidelity(f) => Some(f),
            Mode::Clamped(_) => None,
        }
    }

    /// [`Mode::fidelity`], to change.
    pub fn fidelity_mut(&mut self) -> Option<&mut Fidelity> {
        match self {
            Mode::Fidelity(f) => Some(f),
            Mode::Clamped(_) => None,
        }
    }

    /// The clamped mode with boxes of margin `margin`, keeping the refinement and, from a
    /// clamped mode, the thin depth.
    pub fn with_margin(self, margin: f64) -> Mode {
        match self {
            Mode::Clamped(c) => Mode::Clamped(Clamped { margin, ..c }),
            Mode::Fidelity(f) => {
                Mode::Clamped(Clamped { refinement: f.refinement, ..Clamped::margin(margin) })
            }
        }
    }

    /// The fidelity mode, keeping the refinement and, from a fidelity mode, everything.
    pub fn unclamped(self) -> Mode {
        match self {
            Mode::Fidelity(f) => Mode::Fidelity(f),
            Mode::Clamped(c) => Mode::Fidelity(Fidelity { refinement: c.refinement, ..Default::default() }),
        }
    }

    /// Checks every field's range.
    pub fn validate(&self) -> Result<(), RegularizeError> {
        self.refinement().validate()?;
        match self {
            Mode::Fidelity(f) => {
                if let Some(r) = f.recentring {
                    if !(r.sigma.is_finite() && r.sigma > 0.0) {
                        return Err(RegularizeError::InvalidParams(format!(
                            "the re-centring sigma must be positive and finite, got {}",
                            r.sigma
                        )));
                    }
                }
                check_intermediate_tolerance(f.intermediate_tolerance)?;
            }
            Mode::Clamped(c) => {
                if !(c.margin > 0.0 && c.margin < 1.0) {
                    return Err(RegularizeError::InvalidParams(format!(
                        "the clamping margin must be in (0, 1) voxel, got {}",
                        c.margin
                    )));
                }
            }
        }
        Ok(())
    }
}

/// Checks [`Fidelity::intermediate_tolerance`].
pub(crate) fn check_intermediate_tolerance(factor: f64) -> Result<(), RegularizeError> {
    if !(factor.is_finite() && factor >= 1.0) {
        return Err(RegularizeError::InvalidParams(format!(
            "the intermediate tolerance must be a finite factor of at least 1, got {factor}"
        )));
    }
    Ok(())
}
