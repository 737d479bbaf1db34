//! Binary PLY output.

use std::io::{self, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use glam::DVec3;

use crate::error::IoError;
use crate::mesh::QuadMesh;
use crate::mesh::{write_atomically, write_temporary};

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
/// A mesh whose labels have names ([`QuadMesh::named_labels`]) lists them after the
/// first comment, one `comment label 3 color 216 101 79 255 name left kidney` line per
/// label (colour as sRGB and alpha; the name last, non-ASCII and control characters
/// as `\u{hex}`, a backslash doubled).
///
/// Then the vertices (positions rounded to `f32`) and the faces in face order, each
/// with its 4 vertex indices (0-based) and `[inner, outer]` labels. A mesh with
/// materials adds `property uchar red`, `green`, `blue`, `alpha` to the faces: the
/// face's material colour (sRGB) and opacity. Groups are not
/// written: the labels carry the interfaces. Labels and vertex indices must fit the
/// signed 32-bit `int` of PLY, and positions `f32`; otherwise, or if the mesh is
/// inconsistent, the mesh is refused with [`IoError::InvalidMesh`] before anything is
/// created.
///
/// Written to a temporary file renamed onto `path` when complete (see
/// `write_mesh`).
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

/// The first line of every PLY file this crate writes, its format and comment.
const PLY_START: &str = "ply\nformat binary_little_endian 1.0\ncomment voxreg quad mesh\n";

/// The header's elements: `vertices` positions and `faces` quads with their labels.
fn elements(vertices: usize, faces: usize) -> String {
    format!(
        "element vertex {vertices}\nproperty float x\nproperty float y\nproperty float z\n\
         element face {faces}\nproperty list uchar int vertex_indices\n\
         property int inner_label\nproperty int outer_label\n"
    )
}

/// A vertex's record: its position rounded to `f32`.
fn vertex_record(p: DVec3) -> [u8; 12] {
    let mut record = [0u8; 12];
    for (chunk, c) in record.chunks_exact_mut(4).zip(p.as_vec3().to_array()) {
        chunk.copy_from_slice(&c.to_le_bytes());
    }
    record
}

/// A face's record: 4, its vertex indices and labels as `int`, and 4 bytes for a colour.
fn face_record(quad: &[u32; 4], labels: &[u32; 2]) -> [u8; 29] {
    let mut record = [0u8; 29];
    record[0] = 4;
    for (chunk, &v) in record[1..25].chunks_exact_mut(4).zip(quad.iter().chain(labels)) {
        chunk.copy_from_slice(&(v as i32).to_le_bytes());
    }
    record
}

/// Writes the PLY header and body of `mesh`, assumed checked, to `w`.
pub(crate) fn encode_ply(mesh: &QuadMesh, w: &mut dyn Write) -> io::Result<()> {
    w.write_all(PLY_START.as_bytes())?;
    for label in &mesh.named_labels {
        writeln!(w, "comment {}", label.comment(true))?;
    }
    w.write_all(elements(mesh.positions.len(), mesh.quads.len()).as_bytes())?;
    let colored = !mesh.face_materials.is_empty();
    if colored {
        writeln!(w, "property uchar red\nproperty uchar green\nproperty uchar blue\nproperty uchar alpha")?;
    }
    writeln!(w, "end_header")?;
    for p in &mesh.positions {
        w.write_all(&vertex_record(*p))?;
    }
    for (f, (quad, labels)) in mesh.quads.iter().zip(&mesh.face_labels).enumerate() {
        let mut record = face_record(quad, labels);
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

/// A binary PLY file laid out as [`write_ply`] writes a mesh without names or colours,
/// written in parts: runs of vertices and of faces at their indices, in any order, so that
/// a mesh larger than memory is written piece by piece (the Python package's chunked
/// merge writes each label's surface so, one chunk at a time).
///
/// The file is a temporary one in the directory of its path until [`PlyParts::finish`]
/// renames it onto the path, once every vertex and face has been written; dropped before,
/// it is removed and the path left as it was.
#[derive(Debug)]
pub struct PlyParts {
    path: PathBuf,
    file: tempfile::NamedTempFile,
    header: u64,
    counts: [usize; 2],
    written: [usize; 2],
}

impl PlyParts {
    /// Starts the file of a mesh of `vertices` vertices and `faces` quads at `path`.
    pub fn create(path: &Path, vertices: usize, faces: usize) -> Result<PlyParts, IoError> {
        if vertices > i32::MAX as usize {
            let message = format!("{vertices} vertices: PLY int indices reach {}", i32::MAX);
            return Err(IoError::InvalidMesh { path: path.to_path_buf(), message });
        }
        let header = format!("{PLY_START}{}end_header\n", elements(vertices, faces));
        let file = write_temporary(path, |w| w.write_all(header.as_bytes()))?;
        let header = header.len() as u64;
        Ok(PlyParts { path: path.to_path_buf(), file, header, counts: [vertices, faces], written: [0; 2] })
    }

    /// Writes `positions` as vertices `first..first + positions.len()`.
    pub fn write_vertices(&mut self, first: usize, positions: &[DVec3]) -> Result<(), IoError> {
        self.check_range(0, first, positions.len())?;
        if let Some(i) = positions.iter().position(|p| !p.as_vec3().is_finite()) {
            return self.invalid(format!(
                "vertex {} at {} does not fit a PLY float",
                first + i,
                positions[i]
            ));
        }
        let bytes: Vec<u8> = positions.iter().flat_map(|&p| vertex_record(p)).collect();
        self.write_at(self.header + 12 * first as u64, &bytes)?;
        self.written[0] += positions.len();
        Ok(())
    }

    /// Writes `quads` (vertex indices) with their `[inner, outer]` `labels` as faces
    /// `first..first + quads.len()`.
    pub fn write_faces(
        &mut self,
        first: usize,
        quads: &[[u32; 4]],
        labels: &[[u32; 2]],
    ) -> Result<(), IoError> {
        if quads.len() != labels.len() {
            return self.invalid(format!("{} quads but {} label pairs", quads.len(), labels.len()));
        }
        self.check_range(1, first, quads.len())?;
        if let Some(f) = quads.iter().position(|q| q.iter().any(|&v| v as usize >= self.counts[0])) {
            return self.invalid(format!("face {} uses a vertex beyond the {}", first + f, self.counts[0]));
        }
        if let Some(f) = labels.iter().position(|l| l.iter().any(|&l| l > i32::MAX as u32)) {
            return self.invalid(format!(
                "face {} has labels {:?}, beyond the PLY int range",
                first + f,
                labels[f]
            ));
        }
        let bytes: Vec<u8> =
            quads.iter().zip(labels).flat_map(|(q, l)| face_record(q, l)[..25].to_vec()).collect();
        self.write_at(self.header + 12 * self.counts[0] as u64 + 25 * first as u64, &bytes)?;
        self.written[1] += quads.len();
        Ok(())
    }

    /// Renames the complete file onto its path; fails, removing it, where some vertex or
    /// face was not written (or written twice).
    pub fn finish(mut self) -> Result<(), IoError> {
        if self.written != self.counts {
            let [v, f] = self.written;
            let [nv, nf] = self.counts;
            return self.invalid(format!("{v} of {nv} vertices and {f} of {nf} faces written"));
        }
        self.file.as_file_mut().flush().map_err(|e| IoError::io(&self.path, e))?;
        self.file.persist(&self.path).map_err(|e| IoError::io(&self.path, e.error))?;
        Ok(())
    }

    /// Fails where `count` elements of kind `k` (0 vertices, 1 faces) from `first` do not fit.
    fn check_range(&self, k: usize, first: usize, count: usize) -> Result<(), IoError> {
        if first.checked_add(count).is_none_or(|end| end > self.counts[k]) {
            let what = ["vertices", "faces"][k];
            return self.invalid(format!("{what} {first}..{} beyond the {}", first + count, self.counts[k]));
        }
        Ok(())
    }

    fn invalid<T>(&self, message: String) -> Result<T, IoError> {
        Err(IoError::InvalidMesh { path: self.path.clone(), message })
    }

    fn write_at(&mut self, offset: u64, bytes: &[u8]) -> Result<(), IoError> {
        let file = self.file.as_file_mut();
        file.seek(SeekFrom::Start(offset))
            .and_then(|_| file.write_all(bytes))
            .map_err(|e| IoError::io(&self.path, e))
    }
}

/// Writes `mesh` to `path` as a binary PLY file with one scalar per vertex: a `float`
/// property named `name` holding `values[v]` (rounded to `f32`) and a colour ramp of it,
/// for inspecting a per-vertex field (e.g. the discontinuity field of the
/// Ambrosio-Tortorelli normal estimator, `name = "feature"`) in any PLY viewer.
///
/// Header (the faces are those of [`write_ply`], without material colours):
///
/// ```text
/// ply
/// format binary_little_endian 1.0
/// comment voxreg quad mesh
/// comment <name> colour ramp: 0 dark red, 0.5 amber, 1 light grey
/// element vertex <number of vertices>
/// property float x
/// property float y
/// property float z
/// property float <name>
/// property uchar red
/// property uchar green
/// property uchar blue
/// element face <number of quads>
/// property list uchar int vertex_indices
/// property int inner_label
/// property int outer_label
/// end_header
/// ```
///
/// The colour is [`scalar_ramp`] of the value. Refused with [`IoError::InvalidMesh`]
/// before anything is created for the reasons of [`write_ply_with_vertex_field`]. Written
/// to a temporary file renamed onto `path` when complete.
pub fn write_ply_with_vertex_scalar(
    path: &Path,
    mesh: &QuadMesh,
    name: &str,
    values: &[f64],
) -> Result<(), IoError> {
    let colours: Vec<[u8; 3]> = values.iter().map(|&v| scalar_ramp(v)).collect();
    write_vertex_field(path, mesh, name, values, &colours, true)
}

/// Writes `mesh` to `path` as the binary PLY of [`write_ply_with_vertex_scalar`], with
/// the given vertex colours instead of the ramp (e.g. a distance field with iso-lines);
/// the header's colour comment is left out.
///
/// Refused with [`IoError::InvalidMesh`] before anything is created if `values` or
/// `colours` do not have one entry per vertex, a value is not a finite `f32`, `name` is
/// not a plain identifier (ASCII letters, digits and `_`, not starting with a digit) or
/// is taken by another vertex property, or for the reasons of [`write_ply`].
pub fn write_ply_with_vertex_field(
    path: &Path,
    mesh: &QuadMesh,
    name: &str,
    values: &[f64],
    colours: &[[u8; 3]],
) -> Result<(), IoError> {
    write_vertex_field(path, mesh, name, values, colours, false)
}

/// [`write_ply_with_vertex_field`], with the ramp's header comment when `ramp`.
fn write_vertex_field(
    path: &Path,
    mesh: &QuadMesh,
    name: &str,
    values: &[f64],
    colours: &[[u8; 3]],
    ramp: bool,
) -> Result<(), IoError> {
    let check = |mesh: &QuadMesh| -> Result<(), String> {
        check_ply(mesh)?;
        let plain = name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_');
        if name.is_empty() || !plain || name.starts_with(|c: char| c.is_ascii_digit()) {
            return Err(format!("{name:?} is not a valid PLY property name"));
        }
        if ["x", "y", "z", "red", "green", "blue"].contains(&name) {
            return Err(format!("{name:?} is already a vertex property"));
        }
        if values.len() != mesh.positions.len() {
            return Err(format!("{} values for {} vertices", values.len(), mesh.positions.len()));
        }
        if colours.len() != mesh.positions.len() {
            return Err(format!("{} colours for {} vertices", colours.len(), mesh.positions.len()));
        }
        if let Some(i) = values.iter().position(|x| !(*x as f32).is_finite()) {
            return Err(format!("vertex {i} has value {}, not a finite PLY float", values[i]));
        }
        Ok(())
    };
    write_atomically(path, mesh, check, |mesh, w| {
        encode_ply_with_vertex_scalar(mesh, name, values, colours, ramp, w)
    })
}

/// The colour of `value` on the ramp of [`write_ply_with_vertex_scalar`]: clamped to
/// `[0, 1]`, then linear from dark red `(160, 0, 0)` at 0 to amber `(255, 190, 0)` at 0.5
/// and light grey `(230, 230, 230)` at 1.
pub fn scalar_ramp(value: f64) -> [u8; 3] {
    const STOPS: [[f64; 3]; 3] = [[160.0, 0.0, 0.0], [255.0, 190.0, 0.0], [230.0, 230.0, 230.0]];
    let t = if value.is_nan() { 0.0 } else { value.clamp(0.0, 1.0) } * 2.0;
    let (i, s) = if t < 1.0 { (0, t) } else { (1, t - 1.0) };
    std::array::from_fn(|c| (STOPS[i][c] + s * (STOPS[i + 1][c] - STOPS[i][c])).round() as u8)
}

/// Writes the PLY of [`write_ply_with_vertex_scalar`], assumed checked, to `w`.
fn encode_ply_with_vertex_scalar(
    mesh: &QuadMesh,
    name: &str,
    values: &[f64],
    colours: &[[u8; 3]],
    ramp: bool,
    w: &mut dyn Write,
) -> io::Result<()> {
    write!(w, "ply\nformat binary_little_endian 1.0\ncomment voxreg quad mesh\n")?;
    if ramp {
        writeln!(w, "comment {name} colour ramp: 0 dark red, 0.5 amber, 1 light grey")?;
    }
    write!(
        w,
        "element vertex {}\nproperty float x\nproperty float y\nproperty float z\n\
         property float {name}\nproperty uchar red\nproperty uchar green\nproperty uchar blue\n\
         element face {}\nproperty list uchar int vertex_indices\n\
         property int inner_label\nproperty int outer_label\nend_header\n",
        mesh.positions.len(),
        mesh.quads.len()
    )?;
    for ((p, &value), colour) in mesh.positions.iter().zip(values).zip(colours) {
        let mut record = [0u8; 19];
        let floats = p.as_vec3().to_array().into_iter().chain([value as f32]);
        for (chunk, c) in record[..16].chunks_exact_mut(4).zip(floats) {
            chunk.copy_from_slice(&c.to_le_bytes());
        }
        record[16..].copy_from_slice(colour);
        w.write_all(&record)?;
    }
    for (quad, labels) in mesh.quads.iter().zip(&mesh.face_labels) {
        let mut record = [0u8; 25];
        record[0] = 4;
        for (chunk, &v) in record[1..].chunks_exact_mut(4).zip(quad.iter().chain(labels)) {
            chunk.copy_from_slice(&(v as i32).to_le_bytes());
        }
        w.write_all(&record)?;
    }
    Ok(())
}
