//! Wavefront OBJ output.

use std::io::{self, Write};
use std::path::Path;

use rayon::prelude::*;

use crate::error::IoError;
use crate::mesh::QuadMesh;
use crate::mesh::{write_atomically, write_temporary, SmallWrites};

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
/// `write_mesh`); an inconsistent mesh is refused with
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
    if let Ok(meta) = std::fs::symlink_metadata(&mtl) {
        if !meta.is_file() {
            let what = crate::files::file_kind(&meta);
            return Err(IoError::io(
                &mtl,
                io::Error::other(format!("{what} is in the way of the material library")),
            ));
        }
    }
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
    write_lines(w, mesh.positions.len(), |out, v| {
        let p = mesh.positions[v];
        let _ = writeln!(out, "v {} {} {}", p.x, p.y, p.z);
    })?;
    // The faces in the order they are written, in segments (the ungrouped faces, then
    // each group after its `g` line); `usemtl` where a face's material differs from the
    // face written before it.
    let material = |f: u32| mtllib.map(|_| mesh.face_materials[f as usize]);
    let mut last: Option<u32> = None;
    let mut segment = |w: &mut dyn Write, faces: &[u32]| -> io::Result<()> {
        let before = last;
        write_lines(w, faces.len(), |out, i| {
            let f = faces[i];
            if let Some(m) = material(f) {
                let previous = if i == 0 { before.and_then(material) } else { material(faces[i - 1]) };
                if previous != Some(m) {
                    let _ = writeln!(out, "usemtl {}", mesh.materials[m as usize].name);
                }
            }
            let [a, b, c, d] = mesh.quads[f as usize].map(|v| u64::from(v) + 1);
            let _ = writeln!(out, "f {a} {b} {c} {d}");
        })?;
        last = faces.last().copied().or(before);
        Ok(())
    };
    let mut grouped = vec![false; mesh.quads.len()];
    for g in &mesh.groups {
        for &f in &g.faces {
            grouped[f as usize] = true;
        }
    }
    let ungrouped: Vec<u32> = (0..mesh.quads.len() as u32).filter(|&f| !grouped[f as usize]).collect();
    segment(w, &ungrouped)?;
    for g in &mesh.groups {
        writeln!(w, "g {}", g.name)?;
        segment(w, &g.faces)?;
    }
    Ok(())
}

/// Writes `n` lines, line `i` formatted by `line(out, i)` (onto a buffer, which cannot
/// fail), in parallel in pieces written in order: the same bytes as formatting them one
/// after the other, without one core formatting millions of numbers alone. The pieces'
/// buffers are kept from block to block (fresh memory is slow to fault in).
fn write_lines(w: &mut dyn Write, n: usize, line: impl Fn(&mut Vec<u8>, usize) + Sync) -> io::Result<()> {
    const PIECE: usize = 1 << 14;
    const PIECES: usize = 16;
    let mut buffers: Vec<Vec<u8>> = vec![Vec::new(); PIECES.min(n.div_ceil(PIECE))];
    for start in (0..n).step_by(PIECE * PIECES) {
        buffers.par_iter_mut().enumerate().for_each(|(k, out)| {
            out.clear();
            let s = (start + k * PIECE).min(n);
            for i in s..(s + PIECE).min(n) {
                line(out, i);
            }
        });
        for piece in &buffers {
            SmallWrites(&mut *w).write_all(piece)?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use glam::DVec3;

    use super::*;
    use crate::material::Material;
    use crate::mesh::FaceGroup;

    /// The OBJ text written one line at a time, as the encoder did before it formatted in
    /// parallel pieces.
    fn one_line_at_a_time(mesh: &QuadMesh, mtllib: Option<&str>) -> Vec<u8> {
        let mut w = Vec::new();
        writeln!(
            w,
            "# voxreg quad mesh: {} vertices, {} quads, {} groups",
            mesh.positions.len(),
            mesh.quads.len(),
            mesh.groups.len()
        )
        .unwrap();
        if let Some(lib) = mtllib {
            writeln!(w, "mtllib {lib}").unwrap();
        }
        for p in &mesh.positions {
            writeln!(w, "v {} {} {}", p.x, p.y, p.z).unwrap();
        }
        let mut current = None;
        let mut face = |w: &mut Vec<u8>, f: u32| {
            if mtllib.is_some() {
                let m = mesh.face_materials[f as usize];
                if current != Some(m) {
                    writeln!(w, "usemtl {}", mesh.materials[m as usize].name).unwrap();
                    current = Some(m);
                }
            }
            let [a, b, c, d] = mesh.quads[f as usize].map(|v| u64::from(v) + 1);
            writeln!(w, "f {a} {b} {c} {d}").unwrap();
        };
        let mut grouped = vec![false; mesh.quads.len()];
        mesh.groups.iter().flat_map(|g| &g.faces).for_each(|&f| grouped[f as usize] = true);
        for f in (0..mesh.quads.len() as u32).filter(|&f| !grouped[f as usize]) {
            face(&mut w, f);
        }
        for g in &mesh.groups {
            writeln!(w, "g {}", g.name).unwrap();
            for &f in &g.faces {
                face(&mut w, f);
            }
        }
        w
    }

    /// More lines than one block of pieces, materials changing within pieces and at their
    /// boundaries, groups after the ungrouped faces: the same bytes.
    #[test]
    fn lines_formatted_in_pieces_are_the_lines_one_at_a_time() {
        let mut rng = voxreg_testkit::Lcg::new(11);
        let n = 300_000;
        let positions: Vec<DVec3> = (0..n)
            .map(|_| DVec3::new(rng.next_f64() * 100.0, rng.next_f64(), -rng.next_f64() * 1e-3))
            .collect();
        let quads: Vec<[u32; 4]> =
            (0..n as u32).map(|i| [i, (i + 1) % n as u32, (i + 7) % n as u32, (i + 3) % n as u32]).collect();
        // Runs of materials: long ones, then short ones, across the pieces' boundaries.
        let face_materials: Vec<u32> =
            (0..n as u32).map(|f| if f < 100_000 { (f / 40_000) % 3 } else { (f / 3) % 3 }).collect();
        let groups = vec![
            FaceGroup { name: "first".into(), faces: (50_000..70_000).rev().collect() },
            // Starts with the material the first group ends with: no `usemtl` there.
            FaceGroup { name: "second".into(), faces: (200_001..290_000).step_by(2).collect() },
        ];
        let mesh = QuadMesh {
            positions,
            quads,
            face_labels: vec![[0, 1]; n],
            groups,
            materials: ["a", "b", "c"].map(|m| Material::diffuse(m, [1, 2, 3, 255])).to_vec(),
            face_materials,
            named_labels: Vec::new(),
        };
        for mtllib in [None, Some("m.mtl")] {
            let mut w = Vec::new();
            encode_obj(&mesh, mtllib, &mut w).unwrap();
            assert!(w == one_line_at_a_time(&mesh, mtllib), "{mtllib:?}");
        }
    }
}
