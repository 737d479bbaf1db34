//! Writing a mesh in the format its file name says.

use std::path::Path;

use crate::error::IoError;
use crate::files::lowercase_extension;
use crate::gltf::write_gltf;
use crate::mesh::QuadMesh;
use crate::obj::write_obj;
use crate::ply::write_ply;
use crate::stl::write_stl;
use crate::vtp::write_vtp;

/// Writes `mesh` to `path`, choosing the format by the extension (case insensitive):
///
/// - `.obj`: Wavefront OBJ, ASCII, with groups, see [`write_obj`];
/// - `.ply`: binary little-endian PLY with per-face labels (and colours), see [`write_ply`];
/// - `.glb`, `.gltf`: glTF 2.0 with materials, see [`write_gltf`];
/// - `.stl`: binary STL, triangles only, see [`write_stl`];
/// - `.vtp`: VTK XML PolyData with per-face labels (and colours), see [`write_vtp`].
///
/// Fails with [`IoError::UnsupportedExtension`] for any other name, before creating
/// anything. Like every writer of this crate, it writes a temporary file next to
/// `path` and renames it onto `path` only once complete, so a failure leaves no
/// partial file (and an existing file at `path` untouched).
pub fn write_mesh(path: &Path, mesh: &QuadMesh) -> Result<(), IoError> {
    match lowercase_extension(path).as_deref() {
        Some("obj") => write_obj(path, mesh),
        Some("ply") => write_ply(path, mesh),
        Some("glb" | "gltf") => write_gltf(path, mesh),
        Some("stl") => write_stl(path, mesh),
        Some("vtp") => write_vtp(path, mesh),
        _ => Err(IoError::UnsupportedExtension {
            path: path.to_path_buf(),
            expected: ".obj, .ply, .glb, .gltf, .stl or .vtp",
        }),
    }
}
