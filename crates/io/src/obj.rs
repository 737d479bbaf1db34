//! Wavefront OBJ output.

use std::io::{self, Write};
use std::path::Path;

use crate::mesh::write_atomically;
use crate::{IoError, QuadMesh};

/// Writes `mesh` to `path` as an ASCII Wavefront OBJ file.
///
/// Layout: a `#` comment line, one `v x y z` line per vertex (each coordinate the
/// shortest decimal that reads back as the same `f64`), then the faces as
/// `f a b c d` lines with 1-based indices: first any faces in no group, in face order,
/// then for each group a `g name` line and its faces in the group's order. Labels are
/// not written, except through the group names (see [`QuadMesh::from_surface`]).
///
/// Written to a temporary file renamed onto `path` when complete (see
/// [`write_mesh`](crate::write_mesh)); an inconsistent mesh is refused with
/// [`IoError::InvalidMesh`] before anything is created.
pub fn write_obj(path: &Path, mesh: &QuadMesh) -> Result<(), IoError> {
    write_atomically(path, mesh, |_| Ok(()), |mesh, w| encode_obj(mesh, w))
}

/// Writes the OBJ text of `mesh`, assumed consistent, to `w`.
pub(crate) fn encode_obj(mesh: &QuadMesh, w: &mut dyn Write) -> io::Result<()> {
    writeln!(
        w,
        "# voxreg quad mesh: {} vertices, {} quads, {} groups",
        mesh.positions.len(),
        mesh.quads.len(),
        mesh.groups.len()
    )?;
    for p in &mesh.positions {
        writeln!(w, "v {} {} {}", p.x, p.y, p.z)?;
    }
    let face = |w: &mut dyn Write, f: u32| {
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
