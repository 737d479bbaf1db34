//! The live-tuning panel's parameters, their translation into the library's [`Params`]
//! (as `voxreg regularize` translates its options), and the equivalent command line.

use serde::{Deserialize, Serialize};
use voxreg_regularize::{ClampOverride, Estimator, OverrideError, Params, SolverChoice};

/// The presets of the panel, those of `voxreg regularize --preset`.
#[derive(Copy, Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Preset {
    /// [`Params::default`]: the fidelity pipeline.
    Default,
    /// [`Params::papers`]: the papers' single solve.
    Papers,
    /// [`Params::voxel_art`]: one solve clamped to the voxels' boxes.
    VoxelArt,
}

impl Preset {
    /// The preset's parameters.
    pub fn params(self) -> Params {
        match self {
            Preset::Default => Params::default(),
            Preset::Papers => Params::papers(),
            Preset::VoxelArt => Params::voxel_art(),
        }
    }

    /// The name `--preset` takes.
    pub fn name(self) -> &'static str {
        match self {
            Preset::Default => "default",
            Preset::Papers => "papers",
            Preset::VoxelArt => "voxel-art",
        }
    }
}

/// What the page's tuning panel sets: the options of `voxreg regularize` that change
/// the result most, every one explicit.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Tuning {
    /// The preset the other fields apply over.
    pub preset: Preset,
    /// The initial normal estimator: `trivial`, `convolved`, `ii` or `at`.
    pub estimator: String,
    /// Attachment weight (> 0).
    pub alpha: f64,
    /// Alignment weight (>= 0).
    pub beta: f64,
    /// Fairness weight (>= 0).
    pub gamma: f64,
    /// Normal refinement rounds.
    pub refine: usize,
    /// Clamping margin in voxels (`0 < eps < 1`), or `None`: no clamping.
    pub clamp: Option<f64>,
    /// The voxel-art smoothness `s` in `(0, 1]` (`--smoothness`), or `None`: when given,
    /// it sets the boxes instead of `clamp` ([`Params::with_smoothness`]: margin `1 -
    /// 0.99 s`), the slider's view of the same setting. Default: `None`.
    #[serde(default)]
    pub smoothness: Option<f64>,
    /// Texture-aware fairness (quad edges follow colour boundaries).
    pub texture_aware: bool,
}

fn estimator(name: &str) -> Result<Estimator, String> {
    Ok(match name {
        "trivial" => Estimator::Trivial,
        "convolved" => Estimator::Convolved,
        "ii" => Estimator::Ii,
        "at" => Estimator::At,
        other => return Err(format!("unknown normal estimator '{other}' (trivial, convolved, ii or at)")),
    })
}

impl Tuning {
    /// The panel's values for `params` (which came from `preset`).
    pub fn of(preset: Preset, params: &Params) -> Tuning {
        let clamped = !matches!(params.solver.choice, SolverChoice::Direct | SolverChoice::Cg);
        Tuning {
            preset,
            estimator: params.normals.estimator.name().to_string(),
            alpha: params.energy.alpha,
            beta: params.energy.beta,
            gamma: params.energy.gamma,
            refine: params.refine,
            clamp: params.solver.bounded.clamp.filter(|_| clamped),
            smoothness: None,
            texture_aware: params.texture_aware,
        }
    }

    /// The library's parameters: `base` (the parameters the viewer was started with, from
    /// `base_preset`) when the preset is unchanged, else the preset's own, with every
    /// field of the panel applied over them; checked by [`Params::validate`]. Errors are
    /// the library's messages.
    pub fn params(&self, base_preset: Preset, base: &Params) -> Result<Params, String> {
        let mut p = if self.preset == base_preset { base.clone() } else { self.preset.params() };
        p.energy.alpha = self.alpha;
        p.energy.beta = self.beta;
        p.energy.gamma = self.gamma;
        p.normals.estimator = estimator(&self.estimator)?;
        p.refine = self.refine;
        p.texture_aware = self.texture_aware;
        let clamp = match self.clamp {
            Some(eps) => ClampOverride::Eps(eps),
            None => ClampOverride::Off,
        };
        p.solver = p.solver.overridden(None, clamp).map_err(|e| match e {
            OverrideError::ClampNeedsBoundedSolver => "clamping needs the bounded solver".to_string(),
            OverrideError::ClampOutOfRange(eps) => {
                format!("clamp: the margin must be in (0, 1) voxel, got {eps}")
            }
        })?;
        if let Some(s) = self.smoothness {
            // Boxes need the bounded solver, as a margin from the panel does.
            p.solver.choice = SolverChoice::Bounded;
            p = p.with_smoothness(s).map_err(|_| format!("smoothness: must be in (0, 1], got {s}"))?;
        }
        p.validate().map_err(|e| e.to_string())?;
        Ok(p)
    }

    /// The `voxreg regularize` command line that computes the same surface from `input`
    /// (a file name, quoted for a POSIX shell when needed), writing `output`.
    pub fn command_line(&self, input: &str, output: &str) -> String {
        let mut c = format!(
            "voxreg regularize {} -o {} --preset {} --normals {} --alpha {} --beta {} --gamma {} --refine {}",
            shell_quote(input),
            shell_quote(output),
            self.preset.name(),
            self.estimator,
            self.alpha,
            self.beta,
            self.gamma,
            self.refine
        );
        match (self.smoothness, self.clamp) {
            (Some(s), _) => c.push_str(&format!(" --smoothness {s}")),
            (None, Some(eps)) => c.push_str(&format!(" --clamp {eps}")),
            (None, None) => c.push_str(" --no-clamp"),
        }
        if self.texture_aware {
            c.push_str(" --texture-aware");
        }
        c
    }
}

/// `s` as one word for a POSIX shell.
fn shell_quote(s: &str) -> String {
    let plain = !s.is_empty() && s.chars().all(|c| c.is_ascii_alphanumeric() || "._-/+,=:@".contains(c));
    if plain {
        s.to_string()
    } else {
        format!("'{}'", s.replace('\'', r"'\''"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_preset_round_trips_through_the_panel() {
        for preset in [Preset::Default, Preset::Papers, Preset::VoxelArt] {
            let p = preset.params();
            let t = Tuning::of(preset, &p);
            let q = t.params(preset, &p).unwrap();
            assert_eq!(Tuning::of(preset, &q), t, "{preset:?}");
            assert_eq!(q.energy, p.energy);
            assert_eq!(q.solver.bounded.clamp, p.solver.bounded.clamp);
            assert_eq!(q.solver.choice, p.solver.choice, "{preset:?}");
        }
    }

    #[test]
    fn the_panel_overrides_the_preset() {
        let base = Params::voxel_art();
        let mut t = Tuning::of(Preset::VoxelArt, &base);
        t.clamp = None;
        t.alpha = 0.5;
        t.estimator = "at".into();
        let p = t.params(Preset::VoxelArt, &base).unwrap();
        assert_eq!(p.solver.bounded.clamp, None);
        assert_eq!(p.energy.alpha, 0.5);
        assert_eq!(p.normals.estimator, Estimator::At);
        // Another preset starts from its own parameters, not the base's.
        t.preset = Preset::Papers;
        let p = t.params(Preset::VoxelArt, &base).unwrap();
        assert_eq!(p.regions, Params::papers().regions);
    }

    #[test]
    fn bad_values_give_the_library_messages() {
        let base = Params::default();
        let t = Tuning::of(Preset::Default, &base);
        let bad = |f: &dyn Fn(&mut Tuning)| {
            let mut t = t.clone();
            f(&mut t);
            t.params(Preset::Default, &base).unwrap_err()
        };
        assert!(bad(&|t| t.alpha = 0.0).contains("alpha"), "{}", bad(&|t| t.alpha = 0.0));
        assert!(bad(&|t| t.beta = f64::NAN).contains("beta"));
        assert!(bad(&|t| t.clamp = Some(1.5)).contains("(0, 1)"));
        assert!(bad(&|t| t.estimator = "magic".into()).contains("magic"));
        assert!(bad(&|t| t.smoothness = Some(0.0)).starts_with("smoothness:"));
        assert!(bad(&|t| t.smoothness = Some(1.5)).contains("(0, 1]"));
    }

    #[test]
    fn the_smoothness_sets_the_boxes_as_the_command_line_does() {
        let base = Params::voxel_art();
        let mut t = Tuning::of(Preset::VoxelArt, &base);
        assert_eq!(t.smoothness, None);
        t.smoothness = Some(0.3);
        // It wins over the margin field, as --smoothness without --clamp does.
        t.clamp = None;
        let p = t.params(Preset::VoxelArt, &base).unwrap();
        let expected = Params::voxel_art().with_smoothness(0.3).unwrap();
        assert_eq!(p.solver, expected.solver);
        assert_eq!(p.solver.bounded.thin_depth, Some(Params::THIN_DEPTH));
        let line = t.command_line("a.vox", "a.glb");
        assert!(line.ends_with("--refine 0 --smoothness 0.3"), "{line}");
        assert!(!line.contains("clamp"), "{line}");
        // Meaningful on other inputs too: it clamps them.
        let mut d = Tuning::of(Preset::Default, &Params::default());
        d.smoothness = Some(0.5);
        let p = d.params(Preset::Default, &Params::default()).unwrap();
        assert_eq!(
            p.solver.bounded.clamp,
            Params::default().with_smoothness(0.5).unwrap().solver.bounded.clamp
        );
        // Pages that predate the field still parse.
        let mut v = serde_json::to_value(&d).unwrap();
        v.as_object_mut().unwrap().remove("smoothness");
        assert_eq!(serde_json::from_value::<Tuning>(v).unwrap().smoothness, None);
    }

    #[test]
    fn the_command_line_names_every_panel_value() {
        let mut t = Tuning::of(Preset::VoxelArt, &Params::voxel_art());
        t.texture_aware = true;
        assert_eq!(
            t.command_line("my model.vox", "out.glb"),
            "voxreg regularize 'my model.vox' -o out.glb --preset voxel-art --normals ii --alpha 0.01 \
             --beta 1 --gamma 1 --refine 0 --clamp 0.01 --texture-aware"
        );
        t.clamp = None;
        assert!(t.command_line("a.vox", "a.glb").ends_with("--no-clamp --texture-aware"));
    }
}
