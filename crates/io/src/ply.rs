//! Binary PLY output.

use std::io::{self, Write};
use std::path::Path;

use crate::mesh::write_atomically;
use crate::{IoError, QuadMesh};

/// Writes `mesh` to `path` as a binary little-endian PLY file.
///
/// Header:
///
/// ```text
/// ply
/// format binary_little_endian 1.0
/// comment voxreg quad mesh
/// element vertex <number of vertices>
/// property float x
/// property float y
/// property float z
/// element face <number of quads>
/// property list uchar int vertex_indices
/// property int inner_label
/// property int outer_label
/// end_header
/// ```
///
/// then the vertices (positions rounded to `f32`) and the faces in face order, each
/// with its 4 vertex indices (0-based) and `[inner, outer]` labels. A mesh with
/// materials adds `property uchar red`, `green`, `blue`, `alpha` to the faces: the
/// face's material colour (sRGB) and opacity. Groups are not
/// written: the labels carry the interfaces. Labels and vertex indices must fit the
/// signed 32-bit `int` of PLY, and positions `f32`; otherwise, or if the mesh is
/// inconsistent, the mesh is refused with [`IoError::InvalidMesh`] before anything is
/// created.
///
/// Written to a temporary file renamed onto `path` when complete (see
/// [`write_mesh`](crate::write_mesh)).
pub fn write_ply(path: &Path, mesh: &QuadMesh) -> Result<(), IoError> {
    write_atomically(path, mesh, check_ply, |mesh, w| encode_ply(mesh, w))
}

/// What PLY's `float` and `int` cannot hold.
fn check_ply(mesh: &QuadMesh) -> Result<(), String> {
    if mesh.positions.len() > i32::MAX as usize {
        return Err(format!("{} vertices: PLY int indices reach {}", mesh.positions.len(), i32::MAX));
    }
    if let Some(i) = mesh.positions.iter().position(|p| !p.as_vec3().is_finite()) {
        return Err(format!("vertex {i} at {} does not fit a PLY float", mesh.positions[i]));
    }
    if let Some(f) = mesh.face_labels.iter().position(|l| l.iter().any(|&l| l > i32::MAX as u32)) {
        return Err(format!("face {f} has labels {:?}, beyond the PLY int range", mesh.face_labels[f]));
    }
    Ok(())
}

/// Writes the PLY header and body of `mesh`, assumed checked, to `w`.
pub(crate) fn encode_ply(mesh: &QuadMesh, w: &mut dyn Write) -> io::Result<()> {
    write!(
        w,
        "ply\nformat binary_little_endian 1.0\ncomment voxreg quad mesh\n\
         element vertex {}\nproperty float x\nproperty float y\nproperty float z\n\
         element face {}\nproperty list uchar int vertex_indices\n\
         property int inner_label\nproperty int outer_label\n",
        mesh.positions.len(),
        mesh.quads.len()
    )?;
    let colored = !mesh.face_materials.is_empty();
    if colored {
        writeln!(w, "property uchar red\nproperty uchar green\nproperty uchar blue\nproperty uchar alpha")?;
    }
    writeln!(w, "end_header")?;
    for p in &mesh.positions {
        let mut record = [0u8; 12];
        for (chunk, c) in record.chunks_exact_mut(4).zip(p.as_vec3().to_array()) {
            chunk.copy_from_slice(&c.to_le_bytes());
        }
        w.write_all(&record)?;
    }
    for (f, (quad, labels)) in mesh.quads.iter().zip(&mesh.face_labels).enumerate() {
        let mut record = [0u8; 29];
        record[0] = 4;
        let ints = quad.iter().chain(labels);
        for (chunk, &v) in record[1..25].chunks_exact_mut(4).zip(ints) {
            chunk.copy_from_slice(&(v as i32).to_le_bytes());
        }
        if colored {
            let m = &mesh.materials[mesh.face_materials[f] as usize];
            record[25..28].copy_from_slice(&m.color[..3]);
            record[28] = (m.opacity() * 255.0).round() as u8;
            w.write_all(&record)?;
        } else {
            w.write_all(&record[..25])?;
        }
    }
    Ok(())
}
