//! Reading quad meshes back: OBJ and PLY as written by voxreg (and most others').

use std::path::Path;

use glam::DVec3;

use crate::error::IoError;
use crate::files::lowercase_extension;
use crate::mesh::{FaceGroup, QuadMesh};

/// Reads the positions and faces of an OBJ or PLY mesh (by extension, case insensitive)
/// into a [`QuadMesh`]: quads as they are, triangles as quads repeating their last vertex
/// (`[a, b, c, c]`); polygons of more than 4 vertices are refused.
///
/// - OBJ (ASCII): `v x y z [w]` and `f` lines (indices `i`, `i/t`, `i//n`, `i/t/n`, 1-based
///   or negative), `g` groups kept as [`FaceGroup`]s; other lines ignored; labels `[0, 0]`.
/// - PLY (`ascii`, `binary_little_endian`, `binary_big_endian`): the `vertex` element's
///   `x`, `y`, `z` and the `face` element's `vertex_indices` (or `vertex_index`) list,
///   with `inner_label`/`outer_label` when present (voxreg's PLY); other elements and
///   properties skipped.
///
/// Never panics on malformed input: errors name the file ([`IoError::Format`]).
pub fn read_mesh(path: &Path) -> Result<QuadMesh, IoError> {
    let ext = lowercase_extension(path);
    if !matches!(ext.as_deref(), Some("obj" | "ply")) {
        return Err(IoError::UnsupportedExtension { path: path.to_path_buf(), expected: ".obj or .ply" });
    }
    let bytes = std::fs::read(path).map_err(|e| IoError::io(path, e))?;
    read_mesh_bytes(&bytes, path)
}

/// Reads an OBJ or PLY mesh held in memory, the format chosen by the extension of
/// `path`, which otherwise only names the file in errors. See [`read_mesh`].
pub fn read_mesh_bytes(bytes: &[u8], path: &Path) -> Result<QuadMesh, IoError> {
    let result = match lowercase_extension(path).as_deref() {
        Some("obj") => parse_obj(bytes),
        Some("ply") => parse_ply(bytes),
        _ => {
            return Err(IoError::UnsupportedExtension { path: path.to_path_buf(), expected: ".obj or .ply" })
        }
    };
    let mesh = result.map_err(|m| IoError::format(path, m))?;
    mesh.check().map_err(|m| IoError::format(path, m))?;
    Ok(mesh)
}

/// A polygon of 3 or 4 vertices as a quad.
fn quad_of(face: &[u32]) -> Result<[u32; 4], String> {
    match *face {
        [a, b, c] => Ok([a, b, c, c]),
        [a, b, c, d] => Ok([a, b, c, d]),
        _ => Err(format!("a face of {} vertices (only triangles and quads are read)", face.len())),
    }
}

fn parse_obj(bytes: &[u8]) -> Result<QuadMesh, String> {
    let text = std::str::from_utf8(bytes).map_err(|_| "not UTF-8 text".to_string())?;
    let mut mesh = QuadMesh::default();
    let mut group: Option<usize> = None;
    for (n, line) in text.lines().enumerate() {
        let at = |m: String| format!("line {}: {m}", n + 1);
        let mut words = line.split_whitespace();
        match words.next() {
            Some("v") => {
                let c: Vec<f64> = words
                    .take(3)
                    .map(str::parse)
                    .collect::<Result<_, _>>()
                    .map_err(|_| at("bad vertex".into()))?;
                if c.len() != 3 {
                    return Err(at("a vertex needs 3 coordinates".into()));
                }
                mesh.positions.push(DVec3::new(c[0], c[1], c[2]));
            }
            Some("f") => {
                let count = mesh.positions.len() as i64;
                let face: Vec<u32> = words
                    .map(|w| {
                        let i: i64 = w
                            .split('/')
                            .next()
                            .unwrap_or("")
                            .parse()
                            .map_err(|_| at(format!("bad index '{w}'")))?;
                        let i = if i < 0 { count + i } else { i - 1 };
                        u32::try_from(i)
                            .ok()
                            .filter(|&i| i64::from(i) < count)
                            .ok_or_else(|| at(format!("index {w} out of range")))
                    })
                    .collect::<Result<_, _>>()?;
                mesh.quads.push(quad_of(&face).map_err(at)?);
                mesh.face_labels.push([0, 0]);
                if let Some(g) = group {
                    mesh.groups[g].faces.push(mesh.quads.len() as u32 - 1);
                }
            }
            Some("g") => {
                let name: Vec<&str> = words.collect();
                group = (!name.is_empty()).then(|| {
                    mesh.groups.push(FaceGroup { name: name.join("_"), faces: Vec::new() });
                    mesh.groups.len() - 1
                });
            }
            _ => {}
        }
    }
    mesh.groups.retain(|g| !g.faces.is_empty());
    Ok(mesh)
}

#[derive(Copy, Clone, Debug, PartialEq)]
enum Format {
    Ascii,
    Little,
    Big,
}

#[derive(Clone, Debug)]
enum Kind {
    Scalar(&'static str),
    List(&'static str, &'static str),
}

fn scalar_type(name: &str) -> Option<&'static str> {
    Some(match name {
        "char" | "int8" => "i8",
        "uchar" | "uint8" => "u8",
        "short" | "int16" => "i16",
        "ushort" | "uint16" => "u16",
        "int" | "int32" => "i32",
        "uint" | "uint32" => "u32",
        "float" | "float32" => "f32",
        "double" | "float64" => "f64",
        _ => return None,
    })
}

fn type_size(t: &str) -> usize {
    match t {
        "i8" | "u8" => 1,
        "i16" | "u16" => 2,
        "i32" | "u32" | "f32" => 4,
        _ => 8,
    }
}

struct Element {
    name: String,
    count: usize,
    properties: Vec<(String, Kind)>,
}

/// Reads PLY scalars from the body, ASCII or binary.
struct Body<'a> {
    bytes: &'a [u8],
    pos: usize,
    format: Format,
}

impl Body<'_> {
    fn read(&mut self, t: &str) -> Result<f64, String> {
        if self.format == Format::Ascii {
            while self.pos < self.bytes.len() && self.bytes[self.pos].is_ascii_whitespace() {
                self.pos += 1;
            }
            let start = self.pos;
            while self.pos < self.bytes.len() && !self.bytes[self.pos].is_ascii_whitespace() {
                self.pos += 1;
            }
            let word = std::str::from_utf8(&self.bytes[start..self.pos]).map_err(|_| "bad ASCII value")?;
            return word.parse::<f64>().map_err(|_| format!("bad value '{word}'"));
        }
        let size = type_size(t);
        let raw = self.bytes.get(self.pos..self.pos + size).ok_or("truncated data")?;
        self.pos += size;
        let mut b = [0u8; 8];
        b[..size].copy_from_slice(raw);
        if self.format == Format::Big {
            b[..size].reverse();
        }
        Ok(match t {
            "i8" => f64::from(b[0] as i8),
            "u8" => f64::from(b[0]),
            "i16" => f64::from(i16::from_le_bytes([b[0], b[1]])),
            "u16" => f64::from(u16::from_le_bytes([b[0], b[1]])),
            "i32" => f64::from(i32::from_le_bytes([b[0], b[1], b[2], b[3]])),
            "u32" => f64::from(u32::from_le_bytes([b[0], b[1], b[2], b[3]])),
            "f32" => f64::from(f32::from_le_bytes([b[0], b[1], b[2], b[3]])),
            _ => f64::from_le_bytes(b),
        })
    }
}

fn parse_ply(bytes: &[u8]) -> Result<QuadMesh, String> {
    let end = bytes.windows(10).position(|w| w == b"end_header").ok_or("no end_header")?;
    let header = std::str::from_utf8(&bytes[..end]).map_err(|_| "header not text")?;
    let mut body_start = end + 10;
    while body_start < bytes.len() && bytes[body_start] != b'\n' {
        body_start += 1;
    }
    body_start += 1;
    let mut lines = header.lines();
    if lines.next().map(str::trim) != Some("ply") {
        return Err("not a PLY file".into());
    }
    let mut format = None;
    let mut elements: Vec<Element> = Vec::new();
    for line in lines {
        let w: Vec<&str> = line.split_whitespace().collect();
        match w.as_slice() {
            ["format", f, _] => {
                format = Some(match *f {
                    "ascii" => Format::Ascii,
                    "binary_little_endian" => Format::Little,
                    "binary_big_endian" => Format::Big,
                    _ => return Err(format!("unknown format {f}")),
                })
            }
            ["element", name, count] => elements.push(Element {
                name: name.to_string(),
                count: count.parse().map_err(|_| format!("bad element count '{count}'"))?,
                properties: Vec::new(),
            }),
            ["property", "list", c, t, name] => {
                let e = elements.last_mut().ok_or("property before element")?;
                let (c, t) =
                    (scalar_type(c).ok_or("bad list count type")?, scalar_type(t).ok_or("bad list type")?);
                e.properties.push((name.to_string(), Kind::List(c, t)));
            }
            ["property", t, name] => {
                let e = elements.last_mut().ok_or("property before element")?;
                e.properties
                    .push((name.to_string(), Kind::Scalar(scalar_type(t).ok_or("bad property type")?)));
            }
            _ => {}
        }
    }
    let format = format.ok_or("no format line")?;
    let mut body = Body { bytes: bytes.get(body_start..).unwrap_or(&[]), pos: 0, format };
    let mut mesh = QuadMesh::default();
    for e in &elements {
        // Each element's count bounds what we allocate by the bytes left.
        if e.count > body.bytes.len() + 1 {
            return Err(format!("{} {} elements cannot fit the file", e.count, e.name));
        }
        for _ in 0..e.count {
            let (mut xyz, mut face, mut labels) = ([0.0; 3], Vec::new(), [0u32; 2]);
            for (name, kind) in &e.properties {
                match kind {
                    Kind::Scalar(t) => {
                        let v = body.read(t)?;
                        match name.as_str() {
                            "x" => xyz[0] = v,
                            "y" => xyz[1] = v,
                            "z" => xyz[2] = v,
                            "inner_label" => labels[0] = v.max(0.0) as u32,
                            "outer_label" => labels[1] = v.max(0.0) as u32,
                            _ => {}
                        }
                    }
                    Kind::List(c, t) => {
                        let len = body.read(c)?;
                        if !(0.0..=64.0).contains(&len) {
                            return Err(format!("a list of {len} items"));
                        }
                        let items: Vec<f64> =
                            (0..len as usize).map(|_| body.read(t)).collect::<Result<_, _>>()?;
                        if name == "vertex_indices" || name == "vertex_index" {
                            face = items.iter().map(|&i| i as u32).collect();
                            if items.iter().any(|&i| i < 0.0 || i.fract() != 0.0) {
                                return Err("a negative or fractional vertex index".into());
                            }
                        }
                    }
                }
            }
            match e.name.as_str() {
                "vertex" => mesh.positions.push(DVec3::from(xyz)),
                "face" => {
                    mesh.quads.push(quad_of(&face)?);
                    mesh.face_labels.push(labels);
                }
                _ => {}
            }
        }
    }
    Ok(mesh)
}

#[cfg(test)]
mod tests {
    use voxreg_digisurf::{DigitalSurface, LabelVolume};

    use super::*;
    use crate::mesh_writer::write_mesh;

    #[test]
    fn reads_back_what_voxreg_writes() {
        let volume = LabelVolume::from_fn([4, 3, 3], |[x, y, z]| match (x, y, z) {
            (1, 1, 1) => 3,
            (2, 1, 1) => 5,
            _ => 0,
        });
        let surface = DigitalSurface::from_volume(&volume).unwrap();
        let positions: Vec<DVec3> = surface.positions().iter().map(|p| *p * 0.75 + 0.125).collect();
        let mesh = QuadMesh::from_surface(&surface, &positions);
        let dir = tempfile::tempdir().unwrap();
        for ext in ["obj", "ply", "OBJ"] {
            let path = dir.path().join(format!("m.{ext}"));
            write_mesh(&path, &mesh).unwrap();
            let back = read_mesh(&path).unwrap();
            // OBJ writes faces group by group: compare as sets.
            let sorted = |q: &[[u32; 4]]| {
                let mut q = q.to_vec();
                q.sort_unstable();
                q
            };
            assert_eq!(sorted(&back.quads), sorted(&mesh.quads), "{ext}");
            for (a, b) in back.positions.iter().zip(&mesh.positions) {
                assert!((*a - *b).length() < 1e-6, "{ext}");
            }
            if ext == "ply" {
                assert_eq!(back.face_labels, mesh.face_labels);
            }
        }
    }

    #[test]
    fn parses_ascii_variants_and_refuses_garbage() {
        let obj = b"# x\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\ng a\nf 1/1 2/2/2 3//3\nf -4 -3 -2 -1\n";
        let m = parse_obj(obj).unwrap();
        assert_eq!(m.quads, vec![[0, 1, 2, 2], [0, 1, 2, 3]]);
        assert_eq!(m.groups[0].faces, vec![0, 1]);
        let ply = b"ply\nformat ascii 1.0\nelement vertex 3\nproperty double x\nproperty double y\nproperty double z\nelement face 1\nproperty list uchar uint vertex_index\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
        assert_eq!(parse_ply(ply).unwrap().quads, vec![[0, 1, 2, 2]]);
        for bad in [&b"v 1 2\n"[..], b"v 0 0 0\nf 1 2 3\n", b"f 1 2 3 4 5\n"] {
            assert!(parse_obj(bad).is_err());
        }
        for bad in [
            &b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nend_header\n1\n"[..],
            b"ply\nend_header\n",
            b"nope",
        ] {
            assert!(parse_ply(bad).is_err());
        }
        let huge = b"ply\nformat binary_little_endian 1.0\nelement vertex 4000000000\nproperty float x\nend_header\n";
        assert!(parse_ply(huge).is_err());
    }
}
