//! Binary STL output.

use std::io::{self, Write};
use std::path::Path;

use glam::DVec3;

use crate::error::IoError;
use crate::mesh::write_atomically;
use crate::mesh::QuadMesh;

/// The start of the 80-byte header of the files written: not `solid`, so no reader
/// mistakes them for ASCII STL.
const HEADER: &[u8] = b"voxreg binary STL: quads split into triangles";

/// Writes `mesh` to `path` as a binary STL file (3-D printing, CAD).
///
/// Layout: an 80-byte header, the number of triangles (`u32`, little-endian), then per
/// triangle its unit normal and three corners (twelve `f32`) and a zero attribute word
/// (`u16`). Each quad `[a, b, c, d]` becomes the triangles `[a, b, c]` and `[a, c, d]`,
/// counter-clockwise seen from the side the normal points to; the normal is the
/// triangle's own (zero for a degenerate triangle). STL has no labels, groups or
/// colours: a closed solid per region is `voxreg regularize --split regions
/// --split-format stl`. A mesh of more than `u32::MAX / 2` quads, or with positions
/// beyond `f32`, is refused with [`IoError::InvalidMesh`] before anything is created.
///
/// Written to a temporary file renamed onto `path` when complete (see
/// `write_mesh`).
pub fn write_stl(path: &Path, mesh: &QuadMesh) -> Result<(), IoError> {
    write_atomically(path, mesh, check_stl, |mesh, w| encode_stl(mesh, w))
}

fn check_stl(mesh: &QuadMesh) -> Result<(), String> {
    if mesh.quads.len() > (u32::MAX / 2) as usize {
        return Err(format!("{} quads: STL counts at most {} triangles", mesh.quads.len(), u32::MAX));
    }
    if let Some(i) = mesh.positions.iter().position(|p| !p.as_vec3().is_finite()) {
        return Err(format!("vertex {i} at {} does not fit an STL float", mesh.positions[i]));
    }
    Ok(())
}

fn encode_stl(mesh: &QuadMesh, w: &mut dyn Write) -> io::Result<()> {
    let mut header = [0u8; 80];
    header[..HEADER.len()].copy_from_slice(HEADER);
    w.write_all(&header)?;
    w.write_all(&((2 * mesh.quads.len()) as u32).to_le_bytes())?;
    for &[a, b, c, d] in &mesh.quads {
        for tri in [[a, b, c], [a, c, d]] {
            let [p, q, r] = tri.map(|v| mesh.positions[v as usize]);
            let normal = (q - p).cross(r - p).try_normalize().unwrap_or(DVec3::ZERO);
            let mut record = [0u8; 50];
            let floats = [normal, p, q, r].into_iter().flat_map(|v| v.as_vec3().to_array());
            for (chunk, v) in record[..48].chunks_exact_mut(4).zip(floats) {
                chunk.copy_from_slice(&v.to_le_bytes());
            }
            w.write_all(&record)?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_quad_is_two_triangles_with_normals() {
        let mesh = QuadMesh {
            positions: vec![DVec3::ZERO, DVec3::X, DVec3::new(1.0, 1.0, 0.0), DVec3::Y],
            quads: vec![[0, 1, 2, 3]],
            face_labels: vec![[1, 0]],
            ..Default::default()
        };
        let mut bytes = Vec::new();
        encode_stl(&mesh, &mut bytes).unwrap();
        assert_eq!(bytes.len(), 84 + 2 * 50);
        assert!(!bytes.starts_with(b"solid"));
        assert_eq!(u32::from_le_bytes(bytes[80..84].try_into().unwrap()), 2);
        let f = |o: usize| f32::from_le_bytes(bytes[o..o + 4].try_into().unwrap());
        for t in 0..2 {
            let base = 84 + 50 * t;
            assert_eq!([f(base), f(base + 4), f(base + 8)], [0.0, 0.0, 1.0]);
        }
        // Second triangle [0, 2, 3]: its last corner is vertex 3, (0, 1, 0).
        assert_eq!([f(134 + 36), f(134 + 40), f(134 + 44)], [0.0, 1.0, 0.0]);
    }
}
