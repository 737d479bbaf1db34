//! The live-tuning panel's state: a preset and the library's [`Overrides`], resolved
//! into [`Params`] as `voxreg regularize` resolves its options, and the equivalent
//! command line.

use serde::{Deserialize, Deserializer, Serialize};
use voxreg_regularize::{InputFacts, Overrides, Params, Preset};

/// What the page's tuning panel sets: a preset and the options over it. On the wire, one
/// JSON object: `preset` and the [`Overrides`] fields (`normals`, `alpha`, `clamp`, ...).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Tuning {
    /// The preset the options apply over.
    pub preset: Preset,
    /// The options, as the command line's flags and Python's keyword arguments.
    #[serde(flatten)]
    pub overrides: Overrides,
}

impl<'de> Deserialize<'de> for Tuning {
    /// `preset` and the [`Overrides`] fields; an unknown field is refused.
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        use serde::de::Error;
        let mut map = serde_json::Map::deserialize(d)?;
        let preset = map.remove("preset").ok_or_else(|| D::Error::missing_field("preset"))?;
        let preset = Preset::deserialize(preset).map_err(D::Error::custom)?;
        let overrides = Overrides::deserialize(serde_json::Value::Object(map)).map_err(D::Error::custom)?;
        Ok(Tuning { preset, overrides })
    }
}

impl Tuning {
    /// The panel's values for `params`, resolved from `preset` and `base`: the panel's
    /// fields explicit ([`Overrides::explicit`]), the others `base`'s.
    pub fn of(preset: Preset, base: &Overrides, params: &Params) -> Tuning {
        Tuning { preset, overrides: base.explicit(params) }
    }

    /// The panel's values for `preset` alone.
    pub fn preset(preset: Preset) -> Tuning {
        Tuning::of(preset, &Overrides::default(), &preset.params())
    }

    /// The options in force: `base` (those the viewer was started with, over
    /// `base_preset`) overlaid by the panel's ([`Overrides::overlaid`]) when the preset is
    /// unchanged, else the panel's alone.
    pub fn merged(&self, base_preset: Preset, base: &Overrides) -> Tuning {
        let overrides =
            if self.preset == base_preset { base.overlaid(&self.overrides) } else { self.overrides.clone() };
        Tuning { preset: self.preset, overrides }
    }

    /// The library's parameters of [`Tuning::merged`] ([`Overrides::resolve`]); errors
    /// are the library's messages.
    pub fn params(&self, base_preset: Preset, base: &Overrides) -> Result<Params, String> {
        self.merged(base_preset, base).resolve()
    }

    /// The library's parameters of these options alone.
    pub fn resolve(&self) -> Result<Params, String> {
        self.overrides.resolve(Some(self.preset), &InputFacts::default()).map_err(|e| e.to_string())
    }

    /// The `voxreg regularize` command line that computes the same surface from `input`
    /// (a file name, quoted for a POSIX shell when needed), writing `output`: one flag
    /// per given option, in [`Overrides::FIELDS`]' order.
    pub fn command_line(&self, input: &str, output: &str) -> String {
        let mut c = format!(
            "voxreg regularize {} -o {} --preset {}",
            shell_quote(input),
            shell_quote(output),
            self.preset
        );
        let value = serde_json::to_value(&self.overrides).unwrap_or_default();
        for &field in Overrides::FIELDS {
            let flag = field.replace('_', "-");
            match value.get(field).unwrap_or(&serde_json::Value::Null) {
                serde_json::Value::Null => {}
                serde_json::Value::Bool(b) => match (field, b) {
                    ("clamp", true) => c.push_str(" --clamp"),
                    ("clamp", false) => c.push_str(" --no-clamp"),
                    // The command line's flags: `--no-preserve-size`, `--texture-aware`; the
                    // other values are every preset's.
                    ("preserve_size", false) | ("texture_aware", true) => {
                        c.push_str(&format!(" --{}{flag}", if *b { "" } else { "no-" }))
                    }
                    _ => {}
                },
                serde_json::Value::Number(n) => match n.as_u64() {
                    Some(k) => c.push_str(&format!(" --{flag} {k}")),
                    None => c.push_str(&format!(" --{flag} {}", n.as_f64().unwrap_or(f64::NAN))),
                },
                serde_json::Value::String(s) => c.push_str(&format!(" --{flag} {}", shell_quote(s))),
                serde_json::Value::Array(groups) => {
                    let groups: Vec<String> = groups
                        .iter()
                        .map(|g| {
                            let labels: Vec<String> =
                                g.as_array().into_iter().flatten().map(|l| l.to_string()).collect();
                            labels.join(",")
                        })
                        .collect();
                    c.push_str(&format!(" --{flag} {}", shell_quote(&groups.join(";"))));
                }
                serde_json::Value::Object(_) => {}
            }
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
    use voxreg_regularize::{Clamp, Estimator};

    #[test]
    fn the_panel_lists_every_preset() {
        let html = include_str!("../assets/index.html");
        for preset in Preset::ALL {
            assert!(html.contains(&format!("<option>{}</option>", preset.name())), "{preset}");
        }
    }

    #[test]
    fn every_preset_round_trips_through_the_panel() {
        for preset in Preset::ALL {
            let p = preset.params();
            let t = Tuning::preset(preset);
            let q = t.params(preset, &Overrides::default()).unwrap();
            assert_eq!(q, p, "{preset:?}");
            assert_eq!(Tuning::of(preset, &Overrides::default(), &q), t, "{preset:?}");
            let wire: Tuning = serde_json::from_value(serde_json::to_value(&t).unwrap()).unwrap();
            assert_eq!(wire, t);
        }
    }

    #[test]
    fn the_panel_overrides_the_preset_and_keeps_the_command_line_options() {
        let mut base = Overrides::default();
        base.radius = Some(1.5);
        let mut t = Tuning::of(Preset::VoxelArt, &base, &Preset::VoxelArt.params());
        t.overrides.clamp = Some(Clamp::Off);
        t.overrides.alpha = Some(0.5);
        t.overrides.normals = Some(Estimator::At);
        let p = t.params(Preset::VoxelArt, &base).unwrap();
        assert!(!p.clamps());
        assert_eq!(p.energy.alpha, 0.5);
        assert_eq!(p.normals.estimator, Estimator::At);
        assert_eq!(p.normals.radius, Some(1.5));
        // Another preset starts from its own parameters, not the base's.
        t.preset = Preset::Papers;
        let mut panel = Tuning::preset(Preset::Papers);
        panel.overrides.alpha = Some(0.5);
        let p = panel.params(Preset::VoxelArt, &base).unwrap();
        assert_eq!(p.regions, Params::papers().regions);
        assert_eq!(p.normals.radius, None);
    }

    #[test]
    fn bad_values_give_the_library_messages_and_unknown_fields_are_refused() {
        let t = Tuning::preset(Preset::Default);
        let bad = |f: &dyn Fn(&mut Overrides)| {
            let mut t = t.clone();
            f(&mut t.overrides);
            t.params(Preset::Default, &Overrides::default()).unwrap_err()
        };
        assert!(bad(&|o| o.alpha = Some(0.0)).starts_with("alpha must be"));
        assert!(bad(&|o| o.beta = Some(f64::NAN)).starts_with("beta must be"));
        assert!(bad(&|o| o.clamp = Some(Clamp::Margin(1.5))).contains("(0, 1)"));
        assert!(bad(&|o| {
            o.clamp = None;
            o.smoothness = Some(0.0)
        })
        .starts_with("smoothness must be in (0, 1]"));
        let mut v = serde_json::to_value(&t).unwrap();
        v["estimator"] = "ii".into();
        assert!(serde_json::from_value::<Tuning>(v).is_err());
        let v = serde_json::json!({"preset": "voxel-art", "normals": "magic"});
        assert!(serde_json::from_value::<Tuning>(v).unwrap_err().to_string().contains("magic"));
    }

    #[test]
    fn the_smoothness_sets_the_boxes_as_the_command_line_does() {
        let mut t = Tuning::preset(Preset::VoxelArt);
        t.overrides.clamp = None;
        t.overrides.smoothness = Some(0.3);
        let p = t.params(Preset::VoxelArt, &Overrides::default()).unwrap();
        let expected = Params::voxel_art().with_smoothness(0.3).unwrap();
        assert_eq!((p.solver, p.mode), (expected.solver, expected.mode));
        let line = t.command_line("a.vox", "a.glb");
        assert!(line.contains("--smoothness 0.3"), "{line}");
        assert!(!line.contains("clamp"), "{line}");
        // The panel's boxes replace the base's smoothness.
        let mut base = Overrides::default();
        base.smoothness = Some(0.5);
        let mut margin = Tuning::preset(Preset::VoxelArt);
        margin.overrides.clamp = Some(Clamp::Margin(0.2));
        let p = margin.params(Preset::VoxelArt, &base).unwrap();
        assert_eq!(p.mode.clamped().map(|c| c.margin), Some(0.2));
    }

    #[test]
    fn the_command_line_names_every_given_option() {
        let mut t = Tuning::preset(Preset::VoxelArt);
        t.overrides.texture_aware = Some(true);
        assert_eq!(
            t.command_line("my model.vox", "out.glb"),
            "voxreg regularize 'my model.vox' -o out.glb --preset voxel-art --normals ii --alpha 0.01 \
             --beta 1 --gamma 1 --clamp 0.01 --refine 0 --texture-aware"
        );
        t.overrides.clamp = Some(Clamp::Off);
        t.overrides.preserve_size = Some(false);
        assert!(t
            .command_line("a.vox", "a.glb")
            .ends_with("--no-clamp --refine 0 --no-preserve-size --texture-aware"));
    }
}
