//! The one place where a front end's options become [`Params`]: a [`Preset`] and the
//! [`Overrides`] applied over it ([`Overrides::resolve`]).
//!
//! The command line flattens [`Overrides`] into its flags, the viewer's panel holds one,
//! and Python's keyword arguments are deserialized into one; all three therefore share
//! the field names, the order in which fields apply, the validation and its messages.

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Deserializer, Serialize, Serializer};
use voxreg_digisurf::RegionMap;

use crate::bounded::BoundedParams;
use crate::error::RegularizeError;
use crate::mode::{check_intermediate_tolerance, Mode, Recentring};
use crate::params::{Estimator, Params};
use crate::solver::{ClampOverride, OverrideError, SolverChoice, SolverParams};

/// The named parameter sets every option applies over.
#[derive(Copy, Clone, Debug, PartialEq, Eq, Hash)]
pub enum Preset {
    /// [`Params::default`]: the fidelity pipeline.
    Default,
    /// [`Params::papers`]: the papers' single solve.
    Papers,
    /// [`Params::voxel_art`]: one solve clamped to the voxels' boxes.
    VoxelArt,
    /// [`Params::fast`]: batches of sweeps and cheap re-estimates.
    Fast,
}

impl Preset {
    /// Every preset, in the order help texts list them.
    pub const ALL: [Preset; 4] = [Preset::Default, Preset::Papers, Preset::VoxelArt, Preset::Fast];

    /// The name front ends take (`voxel-art`; [`Preset::from_str`] also takes `voxel_art`).
    pub fn name(self) -> &'static str {
        match self {
            Preset::Default => "default",
            Preset::Papers => "papers",
            Preset::VoxelArt => "voxel-art",
            Preset::Fast => "fast",
        }
    }

    /// One line for help texts.
    pub fn description(self) -> &'static str {
        match self {
            Preset::Default => {
                "The fidelity pipeline: ii normals, alpha 1e-2, 3 refinement rounds, re-centring"
            }
            Preset::Papers => "The papers' single solve (alpha 1e-3, no refinement)",
            Preset::VoxelArt => {
                "One solve clamped to the voxels' boxes (never self-intersecting), all colours one solid"
            }
            Preset::Fast => "Speed of surface nets: diffused normals, 20 block-Jacobi sweeps",
        }
    }

    /// The preset's parameters: every default lives here.
    pub fn params(self) -> Params {
        match self {
            Preset::Default => Params::default(),
            Preset::Papers => Params::papers(),
            Preset::VoxelArt => Params::voxel_art(),
            Preset::Fast => Params::fast(),
        }
    }

    /// The halo, in voxels, a chunked run of this preset reads around each chunk by
    /// default (see [`regularize_block`](crate::regularize_block)): the narrowest of those
    /// measured whose stitched mesh stays within 1e-2 voxel of the whole-volume solve on
    /// the synthetic tissues and `channels.vti` (`docs/scale.md`). The fidelity pipeline's
    /// refinement rounds carry a chunk's cut far (64 voxels); the fast preset's sweeps and
    /// diffusion steps reach a bounded distance, and 32 voxels leave it within 1e-4.
    pub fn chunk_halo(self) -> usize {
        match self {
            Preset::Fast => 32,
            Preset::Default | Preset::Papers | Preset::VoxelArt => 64,
        }
    }

    /// The box margin, in voxels, that [`Clamp::On`] gives under this preset.
    pub fn clamp_margin(self) -> f64 {
        Params::CLAMP_MARGIN
    }

    /// The preset an input calls for when none is named: [`Preset::VoxelArt`] for voxel
    /// art, else [`Preset::Default`].
    pub fn for_input(input: &InputFacts) -> Preset {
        if input.voxel_art {
            Preset::VoxelArt
        } else {
            Preset::Default
        }
    }
}

impl fmt::Display for Preset {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl Serialize for Preset {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.name())
    }
}

impl<'de> Deserialize<'de> for Preset {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        String::deserialize(d)?.parse().map_err(serde::de::Error::custom)
    }
}

/// Lists `names` as `'a', 'b', 'c'` for error messages.
fn quoted(names: impl IntoIterator<Item = &'static str>) -> String {
    names.into_iter().map(|n| format!("'{n}'")).collect::<Vec<_>>().join(", ")
}

impl FromStr for Preset {
    type Err = String;

    /// A preset's name; `_` may stand for `-` (`voxel_art`, Python's spelling).
    fn from_str(s: &str) -> Result<Self, String> {
        let name = s.replace('_', "-");
        Preset::ALL
            .into_iter()
            .find(|p| p.name() == name)
            .ok_or_else(|| format!("must be one of {}, got '{s}'", quoted(Preset::ALL.map(Preset::name))))
    }
}

/// What a front end knows of its input before it reads the voxels, and which picks the
/// preset when none is named ([`Preset::for_input`]).
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq)]
#[non_exhaustive]
pub struct InputFacts {
    /// The input is voxel art (a MagicaVoxel `.vox` model).
    pub voxel_art: bool,
}

impl InputFacts {
    /// The facts of an input that is voxel art or not.
    pub fn voxel_art(voxel_art: bool) -> Self {
        InputFacts { voxel_art }
    }
}

/// How labels form regions ([`Overrides::regions`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum Regions {
    /// `"label"` (each label its own region), `"solid"` (every non-background label one
    /// region), or groups written as `"1,2,3;7"` ([`RegionMap::parse`]).
    Spec(String),
    /// Groups of labels ([`RegionMap::from_groups`]).
    Groups(Vec<Vec<u32>>),
}

impl Regions {
    /// The region map, or a one-line error quoting the spec.
    pub fn map(&self) -> Result<RegionMap, RegularizeError> {
        match self {
            Regions::Spec(s) if s == "label" => Ok(RegionMap::per_label()),
            Regions::Spec(s) if s == "solid" => Ok(RegionMap::single_solid()),
            Regions::Spec(s) => {
                RegionMap::parse(s).map_err(|e| option_error("regions", format!("'{s}': {e}")))
            }
            Regions::Groups(g) => {
                RegionMap::from_groups(g.clone()).map_err(|e| option_error("regions", format!("{g:?}: {e}")))
            }
        }
    }
}

/// The boxes option ([`Overrides::clamp`]): serialized as `false`, `true` or the margin.
#[derive(Copy, Clone, Debug, PartialEq)]
pub enum Clamp {
    /// No boxes, whatever the preset.
    Off,
    /// Boxes of the preset's margin ([`Preset::clamp_margin`]).
    On,
    /// Boxes of this margin in voxels, `0 < eps < 1`.
    Margin(f64),
}

#[derive(Serialize, Deserialize)]
#[serde(untagged)]
enum ClampRepr {
    Flag(bool),
    Margin(f64),
}

impl Serialize for Clamp {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match *self {
            Clamp::Off => ClampRepr::Flag(false),
            Clamp::On => ClampRepr::Flag(true),
            Clamp::Margin(eps) => ClampRepr::Margin(eps),
        }
        .serialize(s)
    }
}

impl<'de> Deserialize<'de> for Clamp {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        match ClampRepr::deserialize(d)
            .map_err(|_| serde::de::Error::custom("must be a boolean or a margin in voxels"))?
        {
            ClampRepr::Flag(false) => Ok(Clamp::Off),
            ClampRepr::Flag(true) => Ok(Clamp::On),
            ClampRepr::Margin(eps) => Ok(Clamp::Margin(eps)),
        }
    }
}

/// Deserializes through `FromStr`, whose error is the message.
fn by_name<'de, D: Deserializer<'de>, T: FromStr<Err = String>>(d: D) -> Result<Option<T>, D::Error> {
    Option::<String>::deserialize(d)?.map(|s| s.parse().map_err(serde::de::Error::custom)).transpose()
}

/// Deserializes a count, refusing negative and fractional numbers in one line.
fn count<'de, D: Deserializer<'de>>(d: D) -> Result<Option<usize>, D::Error> {
    let Some(x) = Option::<f64>::deserialize(d)? else { return Ok(None) };
    if x >= 0.0 && x.fract() == 0.0 && x <= usize::MAX as f64 {
        Ok(Some(x as usize))
    } else {
        Err(serde::de::Error::custom(format!("must be a non-negative integer, got {x}")))
    }
}

fn display<S: Serializer, T: fmt::Display>(x: &Option<T>, s: S) -> Result<S::Ok, S::Error> {
    x.as_ref().map(ToString::to_string).serialize(s)
}

/// The options a front end applies over a [`Preset`], each `None` unless given: the
/// command line's flags (`alpha` is `--alpha`, `clamp` both `--clamp [EPS]` and
/// `--no-clamp`, `preserve_size` `--no-preserve-size`), Python's keyword arguments and
/// the viewer's panel. [`Overrides::resolve`] turns them into [`Params`].
///
/// Deserialized from a map of these names (unknown names are refused); the estimator,
/// the solver and the preset by name.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
#[non_exhaustive]
pub struct Overrides {
    /// How labels form regions [preset: every label its own; one solid for voxel art].
    pub regions: Option<Regions>,
    /// The normal estimator of the alignment term [preset: `ii`].
    #[serde(default, deserialize_with = "by_name", serialize_with = "display")]
    pub normals: Option<Estimator>,
    /// Radius of the ball and disc estimators in physical units, `> 0` [preset: the
    /// multigrid rule; 2 voxels for voxel art].
    pub radius: Option<f64>,
    /// Most alternations of the Ambrosio-Tortorelli sharpening stage (`0`: off).
    #[serde(default, deserialize_with = "count")]
    pub sharpen: Option<usize>,
    /// The sharpening stage's threshold on the feature field, `> 0`.
    pub sharpen_threshold: Option<f64>,
    /// Attachment weight, `> 0`.
    pub alpha: Option<f64>,
    /// Alignment weight, `>= 0`.
    pub beta: Option<f64>,
    /// Fairness weight, `>= 0`.
    pub gamma: Option<f64>,
    /// The solver; `direct`, `cg` or `sweeps` drop the preset's boxes.
    #[serde(default, deserialize_with = "by_name", serialize_with = "display")]
    pub solver: Option<SolverChoice>,
    /// The boxes: off, on at the preset's margin, or a margin; boxes imply the bounded
    /// solver.
    pub clamp: Option<Clamp>,
    /// Voxel art's roundness `s` in `(0, 1]`: boxes of margin `1 - 0.99 s`
    /// ([`Params::with_smoothness`]); excludes `clamp`.
    pub smoothness: Option<f64>,
    /// The iterative solvers' tolerance in voxels, `> 0`.
    pub tolerance: Option<f64>,
    /// Normal refinement rounds, at most [`Params::MAX_REFINE`].
    #[serde(default, deserialize_with = "count")]
    pub refine: Option<usize>,
    /// Tolerance factor of the solves before the last round, `>= 1`
    /// ([`crate::Fidelity::intermediate_tolerance`]); checked in every mode, applied in the
    /// fidelity mode only (the clamped mode's bounded solver keeps its tolerance).
    pub intermediate_tolerance: Option<f64>,
    /// Re-centre the attachment targets between refinement rounds
    /// ([`crate::Fidelity::recentring`]); applies to the fidelity mode only (the clamped
    /// mode's boxes are centred on the input, so it never re-centres).
    pub preserve_size: Option<bool>,
    /// Texture-aware fairness.
    pub texture_aware: Option<bool>,
}

/// The error of option `option`: `"{option} {message}"`.
fn option_error(option: &'static str, message: impl Into<String>) -> RegularizeError {
    RegularizeError::InvalidOption { option, message: message.into() }
}

fn positive(option: &'static str, x: Option<f64>) -> Result<Option<f64>, RegularizeError> {
    match x {
        Some(x) if !(x.is_finite() && x > 0.0) => {
            Err(option_error(option, format!("must be finite and positive, got {x}")))
        }
        _ => Ok(x),
    }
}

fn non_negative(option: &'static str, x: Option<f64>) -> Result<Option<f64>, RegularizeError> {
    match x {
        Some(x) if !(x.is_finite() && x >= 0.0) => {
            Err(option_error(option, format!("must be finite and non-negative, got {x}")))
        }
        _ => Ok(x),
    }
}

impl Overrides {
    /// The field names, as every front end spells them (with `-` for `_` on the command
    /// line).
    pub const FIELDS: &'static [&'static str] = &[
        "regions",
        "normals",
        "radius",
        "sharpen",
        "sharpen_threshold",
        "alpha",
        "beta",
        "gamma",
        "solver",
        "clamp",
        "smoothness",
        "tolerance",
        "refine",
        "intermediate_tolerance",
        "preserve_size",
        "texture_aware",
    ];

    /// `self`, with every field that `over` gives replaced by `over`'s; the boxes
    /// (`clamp` and `smoothness`) go together: either given in `over` replaces both, and
    /// boxes asked for by `over` drop an unbounded solver (`direct`, `cg`, `sweeps`) that only `self`
    /// names, since they need the bounded one.
    pub fn overlaid(&self, over: &Overrides) -> Overrides {
        fn pick<T: Clone>(a: &Option<T>, b: &Option<T>) -> Option<T> {
            b.clone().or_else(|| a.clone())
        }
        let boxes = over.clamp.is_some() || over.smoothness.is_some();
        let boxed = over.smoothness.is_some() || matches!(over.clamp, Some(Clamp::On | Clamp::Margin(_)));
        let solver = match (over.solver, self.solver) {
            (Some(s), _) => Some(s),
            (None, Some(SolverChoice::Direct | SolverChoice::Cg | SolverChoice::Sweeps)) if boxed => None,
            (None, s) => s,
        };
        Overrides {
            regions: pick(&self.regions, &over.regions),
            normals: pick(&self.normals, &over.normals),
            radius: pick(&self.radius, &over.radius),
            sharpen: pick(&self.sharpen, &over.sharpen),
            sharpen_threshold: pick(&self.sharpen_threshold, &over.sharpen_threshold),
            alpha: pick(&self.alpha, &over.alpha),
            beta: pick(&self.beta, &over.beta),
            gamma: pick(&self.gamma, &over.gamma),
            solver,
            clamp: if boxes { over.clamp } else { self.clamp },
            smoothness: if boxes { over.smoothness } else { self.smoothness },
            tolerance: pick(&self.tolerance, &over.tolerance),
            refine: pick(&self.refine, &over.refine),
            intermediate_tolerance: pick(&self.intermediate_tolerance, &over.intermediate_tolerance),
            preserve_size: pick(&self.preserve_size, &over.preserve_size),
            texture_aware: pick(&self.texture_aware, &over.texture_aware),
        }
    }

    /// The parameters: `preset` (else the one `input` calls for, [`Preset::for_input`])
    /// with every given field applied over it, validated ([`Params::validate`]). Errors
    /// are one line, naming the option ([`RegularizeError::InvalidOption`]) where one
    /// option is at fault.
    pub fn resolve(&self, preset: Option<Preset>, input: &InputFacts) -> Result<Params, RegularizeError> {
        let preset = preset.unwrap_or_else(|| Preset::for_input(input));
        let mut p = preset.params();
        if let Some(r) = &self.regions {
            p.regions = r.map()?;
        }
        if let Some(a) = positive("alpha", self.alpha)? {
            p.energy.alpha = a;
        }
        if let Some(b) = non_negative("beta", self.beta)? {
            p.energy.beta = b;
        }
        if let Some(g) = non_negative("gamma", self.gamma)? {
            p.energy.gamma = g;
        }
        if let Some(n) = self.normals {
            p.normals.estimator = n;
        }
        p.normals.radius = positive("radius", self.radius)?.or(p.normals.radius);
        if let Some(k) = self.sharpen {
            p.normals.at.sharpen_iterations = k;
        }
        if let Some(t) = positive("sharpen_threshold", self.sharpen_threshold)? {
            p.normals.at.sharpen_threshold = t;
        }
        if let Some(k) = self.refine {
            p.refinement_mut().rounds = k;
        }
        if let Some(t) = self.texture_aware {
            p.texture_aware = t;
        }
        if let Some(t) = positive("tolerance", self.tolerance)? {
            p.solver = p.solver.with_tolerance(t);
        }
        if let Some(s) = self.smoothness {
            if self.clamp.is_some() {
                return Err(option_error(
                    "smoothness",
                    "and clamp exclude each other (smoothness sets the boxes)",
                ));
            }
            p = p
                .with_smoothness(s)
                .map_err(|_| option_error("smoothness", format!("must be in (0, 1], got {s}")))?;
        }
        let clamp = match self.clamp {
            None => ClampOverride::Keep,
            Some(Clamp::Off) => ClampOverride::Off,
            Some(Clamp::On) => ClampOverride::Eps(preset.clamp_margin()),
            Some(Clamp::Margin(eps)) => ClampOverride::Eps(eps),
        };
        // The solver's rule on the solver with the mode's boxes, whose result picks the
        // mode: boxes make it clamped (keeping the refinement), none the fidelity mode.
        let solver = p.solver_params().overridden(self.solver, clamp).map_err(|e| match e {
            OverrideError::ClampNeedsBoundedSolver => {
                option_error("clamp", "needs the bounded solver (solver bounded or auto)")
            }
            OverrideError::ClampOutOfRange(eps) => {
                option_error("clamp", format!("must be a margin in (0, 1) voxel, got {eps}"))
            }
        })?;
        p.mode = match solver.bounded.clamp {
            Some(margin) => p.mode.with_margin(margin),
            None => p.mode.unclamped(),
        };
        p.solver = SolverParams {
            bounded: BoundedParams { clamp: None, thin_depth: None, ..solver.bounded },
            ..solver
        };
        // The fidelity mode's options, over the mode now settled; the clamped mode has no
        // intermediate solves to loosen (the bounded solver keeps its tolerance) and never
        // re-centres (its boxes are centred on the input).
        if let Some(f) = self.intermediate_tolerance {
            check_intermediate_tolerance(f)?;
        }
        if let Mode::Fidelity(f) = &mut p.mode {
            if let Some(factor) = self.intermediate_tolerance {
                f.intermediate_tolerance = factor;
            }
            match self.preserve_size {
                Some(false) => f.recentring = None,
                Some(true) if f.recentring.is_none() => f.recentring = Some(Recentring::default()),
                _ => {}
            }
        }
        p.validate()?;
        Ok(p)
    }

    /// The overrides that describe `params` (resolved from `preset`) in the fields a
    /// tuning panel shows: estimator, weights, refinement, boxes and texture-awareness,
    /// each explicit; the other fields are `self`'s.
    pub fn explicit(&self, params: &Params) -> Overrides {
        Overrides {
            normals: Some(params.normals.estimator),
            alpha: Some(params.energy.alpha),
            beta: Some(params.energy.beta),
            gamma: Some(params.energy.gamma),
            refine: Some(params.refinement().rounds),
            clamp: match (self.smoothness, params.mode.clamped()) {
                (Some(_), _) => None,
                (None, Some(c)) => Some(Clamp::Margin(c.margin)),
                (None, None) => Some(Clamp::Off),
            },
            texture_aware: Some(params.texture_aware),
            ..self.clone()
        }
    }
}

#[cfg(test)]
// The tests set one field after another, as a front end fills its overrides.
#[allow(clippy::field_reassign_with_default)]
mod tests {
    use super::*;

    fn resolve(o: &Overrides, preset: Preset) -> Result<Params, RegularizeError> {
        o.resolve(Some(preset), &InputFacts::default())
    }

    #[test]
    fn presets_parse_and_print_their_names() {
        for p in Preset::ALL {
            assert_eq!(p.to_string().parse::<Preset>(), Ok(p));
            assert!(!p.description().is_empty());
        }
        assert_eq!("voxel_art".parse::<Preset>(), Ok(Preset::VoxelArt));
        let e = "quick".parse::<Preset>().unwrap_err();
        assert_eq!(e, "must be one of 'default', 'papers', 'voxel-art', 'fast', got 'quick'");
        assert_eq!("fast".parse::<Preset>(), Ok(Preset::Fast));
        assert_eq!(Preset::for_input(&InputFacts::voxel_art(true)), Preset::VoxelArt);
        assert_eq!(Preset::for_input(&InputFacts::default()), Preset::Default);
    }

    #[test]
    fn no_overrides_resolve_to_the_presets() {
        for p in Preset::ALL {
            assert_eq!(resolve(&Overrides::default(), p).unwrap(), p.params());
        }
    }

    #[test]
    fn overrides_deserialize_from_their_names_and_refuse_others() {
        let o: Overrides = serde_json::from_str(
            r#"{"alpha": 0.5, "normals": "at", "solver": "gd", "clamp": true, "refine": 2,
                "regions": [[1, 2], [3]], "preserve_size": false}"#,
        )
        .unwrap();
        assert_eq!(o.alpha, Some(0.5));
        assert_eq!(o.normals, Some(Estimator::At));
        assert_eq!(o.solver, Some(SolverChoice::Bounded));
        assert_eq!(o.clamp, Some(Clamp::On));
        assert_eq!(o.regions, Some(Regions::Groups(vec![vec![1, 2], vec![3]])));
        let back: Overrides = serde_json::from_value(serde_json::to_value(&o).unwrap()).unwrap();
        assert_eq!(back, o);
        let clamp: Overrides = serde_json::from_str(r#"{"clamp": 0.2, "regions": "solid"}"#).unwrap();
        assert_eq!(clamp.clamp, Some(Clamp::Margin(0.2)));
        assert_eq!(clamp.regions, Some(Regions::Spec("solid".into())));
        for bad in [r#"{"alhpa": 1}"#, r#"{"refine": -1}"#, r#"{"normals": "pca"}"#] {
            assert!(serde_json::from_str::<Overrides>(bad).is_err(), "{bad}");
        }
        let e = serde_json::from_str::<Overrides>(r#"{"normals": "pca"}"#).unwrap_err().to_string();
        assert!(
            e.starts_with("must be one of 'trivial', 'convolved', 'ii', 'at', 'diffused', got 'pca'"),
            "{e}"
        );
        // Every field has its name in the list.
        let names: Vec<String> = serde_json::to_value(Overrides::default())
            .unwrap()
            .as_object()
            .unwrap()
            .keys()
            .cloned()
            .collect();
        let mut listed: Vec<String> = Overrides::FIELDS.iter().map(|s| s.to_string()).collect();
        let mut names = names;
        names.sort();
        listed.sort();
        assert_eq!(names, listed);
    }

    #[test]
    fn clamping_and_smoothness_set_the_mode() {
        // The other overrides are checked against the former mapping, preset by preset, in
        // `tests/options.rs`.
        // The boxes: on at the preset's margin, off, or by smoothness.
        let clamp = |c| {
            let mut o = Overrides::default();
            o.clamp = Some(c);
            o
        };
        let on = resolve(&clamp(Clamp::On), Preset::Default).unwrap();
        assert_eq!(on.solver_params(), Params::default().solver.clamped(Some(0.01)));
        // The boxes make the mode clamped, keeping the preset's refinement.
        assert_eq!(
            on.mode.clamped().map(|c| (c.margin, c.refinement)),
            Some((0.01, *Params::default().refinement()))
        );
        let off = resolve(&clamp(Clamp::Off), Preset::VoxelArt).unwrap();
        assert_eq!(off.solver.choice, SolverChoice::Auto);
        assert_eq!(
            off.mode,
            Mode::Fidelity(crate::Fidelity {
                refinement: *Params::voxel_art().refinement(),
                ..Default::default()
            })
        );
        let mut s = Overrides::default();
        s.smoothness = Some(0.3);
        assert_eq!(resolve(&s, Preset::VoxelArt).unwrap(), Params::voxel_art().with_smoothness(0.3).unwrap());
    }

    #[test]
    fn bad_options_are_refused_in_one_line_naming_the_option() {
        let bad = |f: &dyn Fn(&mut Overrides)| {
            let mut o = Overrides::default();
            f(&mut o);
            resolve(&o, Preset::Default).unwrap_err().to_string()
        };
        assert_eq!(bad(&|o| o.alpha = Some(0.0)), "alpha must be finite and positive, got 0");
        assert_eq!(bad(&|o| o.beta = Some(-1.0)), "beta must be finite and non-negative, got -1");
        assert!(bad(&|o| o.radius = Some(f64::NAN)).starts_with("radius must be finite and positive"));
        assert!(bad(&|o| o.sharpen_threshold = Some(-1.0)).starts_with("sharpen_threshold must be"));
        assert!(bad(&|o| o.clamp = Some(Clamp::Margin(1.5)))
            .starts_with("clamp must be a margin in (0, 1) voxel"));
        let cg = bad(&|o| {
            o.clamp = Some(Clamp::On);
            o.solver = Some(SolverChoice::Cg)
        });
        assert!(cg.starts_with("clamp needs the bounded solver"), "{cg}");
        assert_eq!(bad(&|o| o.smoothness = Some(0.0)), "smoothness must be in (0, 1], got 0");
        let both = bad(&|o| {
            o.smoothness = Some(0.5);
            o.clamp = Some(Clamp::On)
        });
        assert!(both.starts_with("smoothness and clamp exclude each other"), "{both}");
        assert!(bad(&|o| o.regions = Some(Regions::Spec("1,2;2".into()))).starts_with("regions '1,2;2'"));
        assert!(bad(&|o| o.intermediate_tolerance = Some(0.5)).contains("intermediate tolerance"));
        assert!(bad(&|o| o.refine = Some(1_000_000_000)).contains("refinement rounds"));
        for e in [bad(&|o| o.alpha = Some(0.0)), bad(&|o| o.refine = Some(usize::MAX))] {
            assert!(!e.contains('\n'));
        }
    }

    #[test]
    fn overlaid_replaces_given_fields_and_the_boxes_together() {
        let mut base = Overrides::default();
        base.smoothness = Some(0.5);
        base.alpha = Some(0.1);
        let mut over = Overrides::default();
        over.clamp = Some(Clamp::Off);
        over.gamma = Some(2.0);
        let o = base.overlaid(&over);
        assert_eq!((o.alpha, o.gamma, o.clamp, o.smoothness), (Some(0.1), Some(2.0), Some(Clamp::Off), None));
        let explicit = Overrides::default().explicit(&Params::voxel_art());
        assert_eq!(resolve(&explicit, Preset::VoxelArt).unwrap(), Params::voxel_art());
    }
}
