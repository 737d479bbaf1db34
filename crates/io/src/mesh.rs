//! Quad meshes, and writing them to a file of any supported format.

use std::io::{self, BufWriter, Write};
use std::path::Path;

use glam::DVec3;
use voxreg_digisurf::{DigitalSurface, InterfaceId, Patch, RegionId};

use crate::error::IoError;
use crate::material::{Material, NamedLabel, Palette};

/// A mesh of quads with two labels per face and named groups of faces: what the
/// writers take.
///
/// Built from a digital surface by [`QuadMesh::from_surface`], or by hand. The writers
/// check its consistency ([`IoError::InvalidMesh`]) before creating any file.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct QuadMesh {
    /// Vertex positions.
    pub positions: Vec<DVec3>,
    /// Faces: four indices into `positions`, counter-clockwise seen from the side the
    /// face's normal points to.
    pub quads: Vec<[u32; 4]>,
    /// Per face, the `[inner, outer]` labels: the labels on the back and front side of
    /// the face (the normal points from inner to outer). Same length as `quads`.
    pub face_labels: Vec<[u32; 2]>,
    /// Named groups of faces (indices into `quads`); a face belongs to at most one group.
    pub groups: Vec<FaceGroup>,
    /// Materials the faces refer to (empty: no materials).
    pub materials: Vec<Material>,
    /// Per face, an index into `materials`; empty when the mesh has no materials,
    /// else the same length as `quads`.
    pub face_materials: Vec<u32>,
    /// The labels of the faces that the input names, in increasing label order, with
    /// their colours (empty: no names). Listed in PLY and OBJ header comments and a VTP
    /// field-data array; the glTF writer names its nodes after them.
    pub named_labels: Vec<NamedLabel>,
}

/// A named set of faces of a [`QuadMesh`], written as an OBJ group.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct FaceGroup {
    /// The group's name: non-empty, no whitespace.
    pub name: String,
    /// Indices into [`QuadMesh::quads`], in the order they are written.
    pub faces: Vec<u32>,
}

impl QuadMesh {
    /// The mesh of `surface` with vertex `v` at `positions[v]`: one quad per surfel, in
    /// surfel order (face `i` is surfel `i`), with the surfel's vertices and
    /// `[inner, outer]` labels, and one group per interface, in interface order, named
    /// `interface_{a}_{b}` where `a` and `b` are the smallest labels of the interface's
    /// inner and outer regions.
    ///
    /// `positions` are typically [`DigitalSurface::positions`] or regularized ones.
    ///
    /// # Panics
    ///
    /// If `positions.len()` differs from `surface.num_vertices()`.
    pub fn from_surface(surface: &DigitalSurface, positions: &[DVec3]) -> QuadMesh {
        assert_eq!(
            positions.len(),
            surface.num_vertices(),
            "QuadMesh::from_surface: one position per vertex of the surface"
        );
        let surfels = surface.surfels();
        let quads = surfels.iter().map(|s| s.vertices.map(|v| v.0)).collect();
        let face_labels = surfels.iter().map(|s| s.labels).collect();
        let groups = surface
            .interfaces()
            .iter()
            .enumerate()
            .map(|(i, interface)| FaceGroup {
                name: interface_name(surface, InterfaceId(i as u32)),
                faces: interface.surfels.iter().map(|s| s.0).collect(),
            })
            .collect();
        QuadMesh { positions: positions.to_vec(), quads, face_labels, groups, ..Default::default() }
    }

    /// The mesh of `patch`, a part of `surface` (see [`Patch`]), with surface vertex `v`
    /// at `positions[v]`: one quad per patch surfel, in patch order, oriented as in the
    /// patch; `[inner, outer]` labels swapped on flipped surfels (so the normal still
    /// points from the inner label to the outer one); one group per interface present,
    /// in interface order, named as by [`interface_name`].
    ///
    /// Local vertex `i` is at `positions[patch.vertices[i]]`: the same `f64` in every
    /// patch that shares the surface vertex, so meshes of adjacent patches meet exactly.
    ///
    /// # Panics
    ///
    /// If `positions.len()` differs from `surface.num_vertices()`.
    pub fn from_patch(surface: &DigitalSurface, patch: &Patch, positions: &[DVec3]) -> QuadMesh {
        assert_eq!(
            positions.len(),
            surface.num_vertices(),
            "QuadMesh::from_patch: one position per vertex of the surface"
        );
        let face_labels = patch
            .surfels
            .iter()
            .zip(&patch.flipped)
            .map(|(&s, &flipped)| {
                let [a, b] = surface.surfel(s).labels;
                if flipped {
                    [b, a]
                } else {
                    [a, b]
                }
            })
            .collect();
        let mut by_interface: Vec<(InterfaceId, u32)> =
            patch.surfels.iter().enumerate().map(|(f, &s)| (surface.surfel(s).interface, f as u32)).collect();
        by_interface.sort_unstable();
        let groups = by_interface
            .chunk_by(|a, b| a.0 == b.0)
            .map(|run| FaceGroup {
                name: interface_name(surface, run[0].0),
                faces: run.iter().map(|&(_, f)| f).collect(),
            })
            .collect();
        QuadMesh {
            positions: patch.vertices.iter().map(|v| positions[v.index()]).collect(),
            quads: patch.quads.clone(),
            face_labels,
            groups,
            ..Default::default()
        }
    }

    /// Gives each face the material of its solid side's label from `palette`: the
    /// face's inner label (its normal points out of the inner voxel; with a background,
    /// whose region comes last, the inner voxel is the solid one). One material per
    /// label in use, in increasing label order; labels beyond the palette get a grey
    /// diffuse material. Also lists the palette's names of the labels on either side
    /// of the faces in [`QuadMesh::named_labels`].
    pub fn assign_materials(&mut self, palette: &Palette) {
        let mut used: Vec<u32> = self.face_labels.iter().map(|l| l[0]).collect();
        used.sort_unstable();
        used.dedup();
        self.materials = used
            .iter()
            .map(|&l| {
                palette
                    .material(l)
                    .cloned()
                    .unwrap_or_else(|| Material::diffuse(format!("color_{l}"), [200, 200, 200, 255]))
            })
            .collect();
        self.face_materials =
            self.face_labels.iter().map(|l| used.binary_search(&l[0]).unwrap_or(0) as u32).collect();
        self.named_labels = palette.named_labels(self.face_labels.iter().flatten().copied());
    }

    /// Number of faces.
    pub fn num_faces(&self) -> usize {
        self.quads.len()
    }

    /// Why the mesh cannot be written, if it cannot: a vertex index or group face out
    /// of range, a non-finite position, `face_labels` of the wrong length, a face in
    /// two groups, or a group name that is empty or holds whitespace.
    pub(crate) fn check(&self) -> Result<(), String> {
        let n = self.positions.len();
        if let Some(i) = self.positions.iter().position(|p| !p.is_finite()) {
            return Err(format!("vertex {i} has a non-finite position {}", self.positions[i]));
        }
        if let Some((f, q)) = self.quads.iter().enumerate().find(|(_, q)| q.iter().any(|&v| v as usize >= n))
        {
            return Err(format!("face {f} {q:?} names a vertex beyond the {n} vertices"));
        }
        if self.face_labels.len() != self.quads.len() {
            return Err(format!(
                "{} face label pairs for {} faces",
                self.face_labels.len(),
                self.quads.len()
            ));
        }
        if !self.face_materials.is_empty() {
            if self.face_materials.len() != self.quads.len() {
                return Err(format!(
                    "{} face materials for {} faces",
                    self.face_materials.len(),
                    self.quads.len()
                ));
            }
            if let Some(f) = self.face_materials.iter().position(|&m| m as usize >= self.materials.len()) {
                return Err(format!(
                    "face {f} names material {}, beyond the {}",
                    self.face_materials[f],
                    self.materials.len()
                ));
            }
        }
        let mut names: Vec<&str> = self.materials.iter().map(|m| m.name.as_str()).collect();
        names.sort_unstable();
        if let Some(w) = names.windows(2).find(|w| w[0] == w[1]) {
            return Err(format!("two materials are named '{}'", w[0]));
        }
        if let Some(m) = self
            .materials
            .iter()
            .find(|m| m.name.is_empty() || m.name.chars().any(|c| c.is_whitespace() || c.is_control()))
        {
            return Err(format!("material name '{}' is empty or holds whitespace", m.name.escape_debug()));
        }
        let mut grouped = vec![false; self.quads.len()];
        for g in &self.groups {
            if g.name.is_empty() || g.name.chars().any(|c| c.is_whitespace() || c.is_control()) {
                return Err(format!("group name '{}' is empty or holds whitespace", g.name.escape_debug()));
            }
            for &f in &g.faces {
                match grouped.get_mut(f as usize) {
                    None => {
                        return Err(format!(
                            "group {} names face {f}, beyond the {} faces",
                            g.name,
                            self.quads.len()
                        ))
                    }
                    Some(true) => return Err(format!("face {f} is in two groups (the second: {})", g.name)),
                    Some(seen) => *seen = true,
                }
            }
        }
        Ok(())
    }
}

/// The name of interface `i` of `surface`: `interface_{a}_{b}`, where `a` and `b` are
/// the smallest labels of its lower and higher regions (the background's region comes
/// last). Distinct interfaces have distinct names. Used for OBJ groups and, by
/// `voxreg regularize --split interfaces`, for file names.
pub fn interface_name(surface: &DigitalSurface, i: InterfaceId) -> String {
    let [a, b] = surface.interfaces()[i.index()].regions.map(|r| first_label(surface, r));
    format!("interface_{a}_{b}")
}

/// The name of region `r` of `surface`: `region_{a}`, where `a` is its smallest label.
pub fn region_name(surface: &DigitalSurface, r: RegionId) -> String {
    format!("region_{}", first_label(surface, r))
}

/// [`interface_name`] with the names `palette` gives the two labels, for inputs that
/// name them (`.seg.nrrd` segments): `interface_{a}_{name a}__{b}_{name b}`, each name
/// through [`file_name_part`] and left out (with its `_`) where the label has no name or
/// nothing of it survives. Exactly [`interface_name`] when neither label has a name.
/// Distinct interfaces have distinct names: the label numbers are kept. Used by
/// `voxreg regularize --split interfaces` for file names.
pub fn named_interface_name(surface: &DigitalSurface, i: InterfaceId, palette: Option<&Palette>) -> String {
    let [a, b] = surface.interfaces()[i.index()].regions.map(|r| first_label(surface, r));
    match [a, b].map(|l| label_part(palette, l)) {
        [None, None] => format!("interface_{a}_{b}"),
        [na, nb] => format!("interface_{a}{}__{b}{}", na.unwrap_or_default(), nb.unwrap_or_default()),
    }
}

/// [`region_name`] with the name `palette` gives the region's smallest label:
/// `region_{a}_{name}`, the name through [`file_name_part`]; exactly [`region_name`]
/// when the label has no name or nothing of it survives. Used by `voxreg regularize
/// --split regions` for file names.
pub fn named_region_name(surface: &DigitalSurface, r: RegionId, palette: Option<&Palette>) -> String {
    let a = first_label(surface, r);
    format!("region_{a}{}", label_part(palette, a).unwrap_or_default())
}

/// `_{file name part}` of the name of `label`, if it has one that survives.
fn label_part(palette: Option<&Palette>, label: u32) -> Option<String> {
    let part = file_name_part(palette?.name(label)?);
    (!part.is_empty()).then(|| format!("_{part}"))
}

/// The longest [`file_name_part`], in bytes: with two of them and two label numbers a
/// file name stays far below the 255 bytes file systems allow.
const NAME_PART_BYTES: usize = 64;

/// A label name as part of a file name that every common file system (and a shell
/// without quotes) takes: letters and digits (any script) and `-` kept, every other
/// character (`/`, `\`, `.`, spaces, punctuation, controls) as `_`, runs of `_` as one
/// (so `__` can separate two names), none at either end, at most 64 bytes (cut at a
/// character boundary). Possibly empty.
pub fn file_name_part(name: &str) -> String {
    let mut out = String::new();
    for c in name.chars() {
        let c = if c.is_alphanumeric() || c == '-' { c } else { '_' };
        if c == '_' && (out.is_empty() || out.ends_with('_')) {
            continue;
        }
        if out.len() + c.len_utf8() > NAME_PART_BYTES {
            break;
        }
        out.push(c);
    }
    while out.ends_with('_') {
        out.pop();
    }
    out
}

fn first_label(surface: &DigitalSurface, r: RegionId) -> u32 {
    surface.regions().labels(r).first().copied().unwrap_or(0)
}

/// Checks `mesh`, then writes it through `encode` atomically (see
/// [`write_file_atomically`]).
pub(crate) fn write_atomically(
    path: &Path,
    mesh: &QuadMesh,
    check: impl FnOnce(&QuadMesh) -> Result<(), String>,
    encode: impl FnOnce(&QuadMesh, &mut dyn Write) -> io::Result<()>,
) -> Result<(), IoError> {
    mesh.check()
        .and_then(|()| check(mesh))
        .map_err(|message| IoError::InvalidMesh { path: path.to_path_buf(), message })?;
    write_file_atomically(path, |w| encode(mesh, w))
}

/// Writes through `encode` to a temporary file in the directory of `path`, and renames
/// that onto `path`. On any failure the temporary file is removed and `path` is left as
/// it was.
pub fn write_file_atomically(
    path: &Path,
    encode: impl FnOnce(&mut dyn Write) -> io::Result<()>,
) -> Result<(), IoError> {
    let tmp = write_temporary(path, encode)?;
    tmp.persist(path).map_err(|e| IoError::io(path, e.error))?;
    Ok(())
}

/// Writes through `encode` to a temporary file in the directory of `path`, to be
/// renamed onto `path` by the caller (dropping it removes it).
pub(crate) fn write_temporary(
    path: &Path,
    encode: impl FnOnce(&mut dyn Write) -> io::Result<()>,
) -> Result<tempfile::NamedTempFile, IoError> {
    let dir = match path.parent() {
        Some(dir) if !dir.as_os_str().is_empty() => dir,
        _ => Path::new("."),
    };
    let mut tmp = crate::inflight::temp_file(dir, ".tmp").map_err(|e| IoError::io(path, e))?;
    {
        let mut writer = BufWriter::new(tmp.as_file_mut());
        encode(&mut writer).and_then(|()| writer.flush()).map_err(|e| IoError::io(path, e))?;
    }
    Ok(tmp)
}

/// A writer that passes each write on in parts of at most 8 KiB, the parts a `BufWriter`
/// flushes. Why: a large buffer written to a file in one call took the kernel longer than
/// the same bytes in small parts (`docs/history.md`, "Writing large meshes").
pub(crate) struct SmallWrites<'a>(pub(crate) &'a mut dyn Write);

impl Write for SmallWrites<'_> {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        self.0.write(&buf[..buf.len().min(1 << 13)])
    }

    fn flush(&mut self) -> io::Result<()> {
        self.0.flush()
    }
}

#[cfg(test)]
mod tests {
    use voxreg_digisurf::LabelVolume;

    use super::*;

    #[test]
    fn from_surface_of_two_labels() {
        // Labels 3 and 5 side by side in background 0.
        let volume = LabelVolume::from_fn([4, 3, 3], |[x, y, z]| match (x, y, z) {
            (1, 1, 1) => 3,
            (2, 1, 1) => 5,
            _ => 0,
        });
        let surface = DigitalSurface::from_volume(&volume).unwrap();
        let mesh = QuadMesh::from_surface(&surface, &surface.positions());
        assert_eq!(mesh.num_faces(), 11);
        assert_eq!(mesh.positions.len(), surface.num_vertices());
        let names: Vec<&str> = mesh.groups.iter().map(|g| g.name.as_str()).collect();
        assert_eq!(names, ["interface_3_5", "interface_3_0", "interface_5_0"]);
        let sizes: Vec<usize> = mesh.groups.iter().map(|g| g.faces.len()).collect();
        assert_eq!(sizes, [1, 5, 5]);
        assert_eq!(mesh.face_labels[mesh.groups[0].faces[0] as usize], [3, 5]);
        for g in &mesh.groups[1..] {
            assert!(g.faces.iter().all(|&f| mesh.face_labels[f as usize][1] == 0));
        }
        assert_eq!(mesh.check(), Ok(()));
    }

    #[test]
    fn check_finds_inconsistencies() {
        let good = QuadMesh {
            positions: vec![DVec3::ZERO; 4],
            quads: vec![[0, 1, 2, 3]],
            face_labels: vec![[1, 0]],
            groups: vec![FaceGroup { name: "a".into(), faces: vec![0] }],
            ..Default::default()
        };
        assert_eq!(good.check(), Ok(()));
        let cases: Vec<(QuadMesh, &str)> = vec![
            (QuadMesh { quads: vec![[0, 1, 2, 4]], ..good.clone() }, "beyond the 4 vertices"),
            (QuadMesh { positions: vec![DVec3::NAN; 4], ..good.clone() }, "non-finite"),
            (QuadMesh { face_labels: vec![], ..good.clone() }, "0 face label pairs for 1 faces"),
            (
                QuadMesh { groups: vec![FaceGroup { name: "a b".into(), faces: vec![] }], ..good.clone() },
                "holds whitespace",
            ),
            (
                QuadMesh { groups: vec![FaceGroup { name: "a".into(), faces: vec![1] }], ..good.clone() },
                "face 1",
            ),
            (
                QuadMesh {
                    groups: vec![
                        FaceGroup { name: "a".into(), faces: vec![0] },
                        FaceGroup { name: "b".into(), faces: vec![0] },
                    ],
                    ..good.clone()
                },
                "face 0 is in two groups",
            ),
        ];
        for (mesh, expected) in cases {
            let message = mesh.check().unwrap_err();
            assert!(message.contains(expected), "expected '{expected}' in '{message}'");
        }
    }
}
