//! Wavefront OBJ output.

use std::io::{self, Write};
use std::path::Path;

use crate::mesh::{write_atomically, write_temporary};
use crate::{IoError, QuadMesh};

/// Writes `mesh` to `path` as an ASCII Wavefront OBJ file.
///
/// Layout: a `#` comment line (followed, for a mesh whose labels have names, by one
/// `# label 3 color 216 101 79 255 name left kidney` line per
/// [`QuadMesh::named_labels`] entry: colour as sRGB and alpha, the name last with its
/// control characters as `\u{hex}`), one `v x y z` line per vertex (each coordinate the
/// shortest decimal that reads back as the same `f64`), then the faces as
/// `f a b c d` lines with 1-based indices: first any faces in no group, in face order,
/// then for each group a `g name` line and its faces in the group's order. Labels are
/// not written, except through the group names (see [`QuadMesh::from_surface`]).
///
/// Written to a temporary file renamed onto `path` when complete (see
/// [`write_mesh`](crate::write_mesh)); an inconsistent mesh is refused with
/// [`IoError::InvalidMesh`] before anything is created.
///
/// A mesh with materials also gets a material library next to it, `<stem>.mtl`
/// (named by `mtllib` in the OBJ, selected per face by `usemtl`), with the diffuse
/// colour `Kd` (sRGB), opacity `d`, emission `Ke`, and the PBR extensions `Pm`
/// (metalness) and `Pr` (roughness) that Blender reads. Both are written to temporary
/// files first; the library replaces an existing one only once the OBJ has.
pub fn write_obj(path: &Path, mesh: &QuadMesh) -> Result<(), IoError> {
    if mesh.materials.is_empty() || mesh.face_materials.is_empty() {
        return write_atomically(path, mesh, |_| Ok(()), |mesh, w| encode_obj(mesh, None, w));
    }
    let mtl = path.with_extension("mtl");
    let mtl_name = mtl.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    if mtl_name.chars().any(char::is_whitespace) {
        return Err(IoError::InvalidMesh {
            path: path.to_path_buf(),
            message: format!(
                "the material library name '{mtl_name}' holds whitespace, which OBJ cannot name"
            ),
        });
    }
    mesh.check().map_err(|message| IoError::InvalidMesh { path: path.to_path_buf(), message })?;
    // Both written in full before either replaces anything: a failed OBJ leaves the old
    // OBJ and its old library.
    let mtl_tmp = write_temporary(&mtl, |w| encode_mtl(mesh, w))?;
    let obj_tmp = write_temporary(path, |w| encode_obj(mesh, Some(&mtl_name), w))?;
    // Both renames or neither, should the process be interrupted (see `remove_in_flight`).
    let _in_flight = crate::inflight::lock();
    obj_tmp.persist(path).map_err(|e| IoError::io(path, e.error))?;
    mtl_tmp.persist(&mtl).map_err(|e| IoError::io(&mtl, e.error))?;
    Ok(())
}

/// Writes the MTL text of `mesh`'s materials to `w`.
pub(crate) fn encode_mtl(mesh: &QuadMesh, w: &mut dyn Write) -> io::Result<()> {
    writeln!(w, "# voxreg materials: {}", mesh.materials.len())?;
    for m in &mesh.materials {
        let c = m.color.map(|c| f32::from(c) / 255.0);
        writeln!(w, "\nnewmtl {}", m.name)?;
        writeln!(w, "Kd {} {} {}", c[0], c[1], c[2])?;
        writeln!(w, "Ka 0 0 0")?;
        writeln!(w, "d {}", m.opacity())?;
        let e = m.emission.clamp(0.0, 1.0);
        writeln!(w, "Ke {} {} {}", c[0] * e, c[1] * e, c[2] * e)?;
        writeln!(w, "Pm {}", m.metallic)?;
        writeln!(w, "Pr {}", m.roughness)?;
        writeln!(w, "illum 2")?;
    }
    Ok(())
}

/// Writes the OBJ text of `mesh`, assumed consistent, to `w`.
pub(crate) fn encode_obj(mesh: &QuadMesh, mtllib: Option<&str>, w: &mut dyn Write) -> io::Result<()> {
    writeln!(
        w,
        "# voxreg quad mesh: {} vertices, {} quads, {} groups",
        mesh.positions.len(),
        mesh.quads.len(),
        mesh.groups.len()
    )?;
    for label in &mesh.named_labels {
        writeln!(w, "# {}", label.comment(false))?;
    }
    if let Some(lib) = mtllib {
        writeln!(w, "mtllib {lib}")?;
    }
    for p in &mesh.positions {
        writeln!(w, "v {} {} {}", p.x, p.y, p.z)?;
    }
    let mut current: Option<u32> = None;
    let mut face = |w: &mut dyn Write, f: u32| {
        if mtllib.is_some() {
            let m = mesh.face_materials[f as usize];
            if current != Some(m) {
                writeln!(w, "usemtl {}", mesh.materials[m as usize].name)?;
                current = Some(m);
            }
        }
        let [a, b, c, d] = mesh.quads[f as usize].map(|v| u64::from(v) + 1);
        writeln!(w, "f {a} {b} {c} {d}")
    };
    let mut grouped = vec![false; mesh.quads.len()];
    for g in &mesh.groups {
        for &f in &g.faces {
            grouped[f as usize] = true;
        }
    }
    for (f, _) in grouped.iter().enumerate().filter(|(_, &g)| !g) {
        face(w, f as u32)?;
    }
    for g in &mesh.groups {
        writeln!(w, "g {}", g.name)?;
        for &f in &g.faces {
            face(w, f)?;
        }
    }
    Ok(())
}
