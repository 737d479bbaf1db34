//! Materials and palettes: how faces look, carried from voxel files to mesh files.

use std::collections::BTreeMap;

/// How a face looks: what glTF, OBJ/MTL and PLY colours can carry.
#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    /// A name, unique within a mesh: non-empty, no whitespace.
    pub name: String,
    /// Colour as sRGB bytes; alpha is opacity.
    pub color: [u8; 4],
    /// Metalness in `[0, 1]`.
    pub metallic: f32,
    /// Roughness in `[0, 1]`.
    pub roughness: f32,
    /// Emitted fraction of the colour, in `[0, 1]` (0: no emission).
    pub emission: f32,
    /// Transparency in `[0, 1]` (glass); combined with the colour's alpha on output.
    pub transparency: f32,
}

impl Material {
    /// A matte, opaque material of the given colour.
    pub fn diffuse(name: impl Into<String>, color: [u8; 4]) -> Self {
        Material { name: name.into(), color, metallic: 0.0, roughness: 1.0, emission: 0.0, transparency: 0.0 }
    }

    /// Opacity in `[0, 1]`: the colour's alpha times `1 - transparency`.
    pub fn opacity(&self) -> f32 {
        (f32::from(self.color[3]) / 255.0) * (1.0 - self.transparency.clamp(0.0, 1.0))
    }

    /// The colour in linear RGB (what glTF's factors expect), from sRGB.
    pub fn linear_rgb(&self) -> [f32; 3] {
        let lin = |c: u8| {
            let c = f32::from(c) / 255.0;
            if c <= 0.04045 {
                c / 12.92
            } else {
                ((c + 0.055) / 1.055).powf(2.4)
            }
        };
        [lin(self.color[0]), lin(self.color[1]), lin(self.color[2])]
    }
}

/// Colours and materials of a labeled volume, indexed by label (for MagicaVoxel files:
/// 256 entries, label = palette index + 1, entry 0 the transparent background).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Palette {
    /// RGBA colour per label.
    pub colors: Vec<[u8; 4]>,
    /// Material per label (same length as `colors`), named `color_{label}` unless the
    /// file names the label.
    pub materials: Vec<Material>,
    /// The names the file gives its labels, as written there (3D Slicer segment names,
    /// MagicaVoxel `_name` material properties), by label; never empty strings. Empty
    /// for files without names.
    pub names: BTreeMap<u32, String>,
}

/// A label the input names, with its colour: what the mesh writers list (PLY and OBJ
/// comments, glTF node names, a VTP field-data array) and the JSON report's `labels`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct NamedLabel {
    /// The label value.
    pub label: u32,
    /// Its name as the file writes it: any non-empty string.
    pub name: String,
    /// Its colour (sRGB, alpha) from the palette.
    pub color: [u8; 4],
}

impl NamedLabel {
    /// The label as a header comment's text: `label {label} color {r} {g} {b} {a} name
    /// {name}`, the name last (it may hold spaces), its control characters (and with
    /// `ascii`, every non-ASCII one: PLY headers are ASCII) as `\u{hex}` and `\` as
    /// `\\`, so the comment stays one line and reads back unambiguously.
    pub(crate) fn comment(&self, ascii: bool) -> String {
        let [r, g, b, a] = self.color;
        let mut name = String::new();
        for c in self.name.chars() {
            match c {
                '\\' => name.push_str("\\\\"),
                c if c.is_control() || (ascii && !c.is_ascii()) => {
                    name.push_str(&format!("\\u{{{:x}}}", u32::from(c)))
                }
                c => name.push(c),
            }
        }
        format!("label {} color {r} {g} {b} {a} name {name}", self.label)
    }
}

impl Palette {
    /// A palette of diffuse materials from colours, without names.
    pub fn from_colors(colors: Vec<[u8; 4]>) -> Self {
        let materials =
            colors.iter().enumerate().map(|(l, &c)| Material::diffuse(format!("color_{l}"), c)).collect();
        Palette { colors, materials, names: BTreeMap::new() }
    }

    /// The material of `label`, if the palette has one.
    pub fn material(&self, label: u32) -> Option<&Material> {
        self.materials.get(label as usize)
    }

    /// The name the file gives `label`, if any.
    pub fn name(&self, label: u32) -> Option<&str> {
        self.names.get(&label).map(String::as_str)
    }

    /// Names `label` (within the palette) `name`: recorded as written (trimmed, control
    /// characters written as escapes such as `\u{1b}`; an empty
    /// name records nothing), and the label's material renamed after it as
    /// [`material_name`] makes it, with `_{label}` appended when a material (this
    /// label's unnamed one included) has that name already: material names stay unique.
    pub fn set_name(&mut self, label: u32, name: &str) {
        let name = crate::files::printable(name.trim());
        let name = name.as_str();
        let index = label as usize;
        if index >= self.materials.len() {
            return;
        }
        let base = material_name(name, label);
        let taken = self.materials.iter().any(|m| m.name == base);
        self.materials[index].name = if taken { format!("{base}_{label}") } else { base };
        if !name.is_empty() {
            self.names.insert(label, name.to_string());
        }
    }

    /// The named labels among `labels` (any order, repeats allowed), in increasing
    /// label order, with their colours.
    pub fn named_labels(&self, labels: impl IntoIterator<Item = u32>) -> Vec<NamedLabel> {
        if self.names.is_empty() {
            return Vec::new();
        }
        let mut labels: Vec<u32> = labels.into_iter().filter(|l| self.names.contains_key(l)).collect();
        labels.sort_unstable();
        labels.dedup();
        labels
            .into_iter()
            .map(|label| NamedLabel {
                label,
                name: self.names[&label].clone(),
                color: self.colors.get(label as usize).copied().unwrap_or([200, 200, 200, 255]),
            })
            .collect()
    }
}

/// A label name as a material name (OBJ `usemtl` and MTL `newmtl` cannot hold
/// whitespace): whitespace and control characters as `_`; `segment_{label}` for an
/// empty name.
pub fn material_name(name: &str, label: u32) -> String {
    let name: String =
        name.chars().map(|c| if c.is_whitespace() || c.is_control() { '_' } else { c }).collect();
    if name.is_empty() {
        format!("segment_{label}")
    } else {
        name
    }
}

/// Reads a MagicaVoxel MATL property as a number.
fn number(props: &dot_vox::Dict, key: &str) -> Option<f32> {
    props.get(key).and_then(|v| v.trim().parse::<f32>().ok()).filter(|v| v.is_finite())
}

/// Applies a MagicaVoxel `MATL` chunk's properties to `material`.
///
/// `_type` selects the kind: `_metal` (metalness from `_metal`, else `_weight`),
/// `_glass` (transparency from `_trans`, `_alpha`, else `_weight`), `_emit` (emission
/// from `_emit`, else `_weight`); roughness from `_rough` for every kind but `_diffuse`,
/// which stays matte. Other kinds (`_plastic`, `_media`, `_blend`) keep their roughness.
pub(crate) fn apply_vox_material(material: &mut Material, props: &dot_vox::Dict) {
    let kind = props.get("_type").map(String::as_str).unwrap_or("_diffuse");
    let unit = |v: Option<f32>| v.map(|v| v.clamp(0.0, 1.0));
    if kind != "_diffuse" {
        if let Some(r) = unit(number(props, "_rough")) {
            material.roughness = r;
        }
    }
    match kind {
        "_metal" => {
            material.metallic = unit(number(props, "_metal").or(number(props, "_weight"))).unwrap_or(1.0)
        }
        "_glass" => {
            material.transparency =
                unit(number(props, "_trans").or(number(props, "_alpha")).or(number(props, "_weight")))
                    .unwrap_or(0.5)
        }
        "_emit" => {
            material.emission = unit(number(props, "_emit").or(number(props, "_weight"))).unwrap_or(1.0)
        }
        _ => {}
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dict(pairs: &[(&str, &str)]) -> dot_vox::Dict {
        pairs.iter().map(|(k, v)| (k.to_string(), v.to_string())).collect()
    }

    #[test]
    fn vox_materials() {
        let base = Material::diffuse("m", [255, 0, 0, 255]);
        let mut m = base.clone();
        apply_vox_material(&mut m, &dict(&[("_type", "_metal"), ("_weight", "0.5"), ("_rough", "0.25")]));
        assert_eq!((m.metallic, m.roughness), (0.5, 0.25));
        let mut g = base.clone();
        apply_vox_material(&mut g, &dict(&[("_type", "_glass"), ("_trans", "0.8")]));
        assert!((g.opacity() - 0.2).abs() < 1e-6);
        let mut e = base.clone();
        apply_vox_material(&mut e, &dict(&[("_type", "_emit"), ("_emit", "x")]));
        assert_eq!(e.emission, 1.0);
        let mut d = base.clone();
        apply_vox_material(&mut d, &dict(&[("_type", "_diffuse"), ("_rough", "0.1")]));
        assert_eq!(d, base);
    }

    #[test]
    fn srgb_to_linear() {
        let m = Material::diffuse("m", [255, 128, 0, 255]);
        let [r, g, b] = m.linear_rgb();
        assert!((r - 1.0).abs() < 1e-6 && (g - 0.2158).abs() < 1e-3 && b == 0.0);
    }
}
