//! VTK XML PolyData (`.vtp`) output.

use std::io::{self, Write};
use std::path::Path;

use crate::error::IoError;
use crate::mesh::write_atomically;
use crate::mesh::QuadMesh;

/// Writes `mesh` to `path` as a VTK XML PolyData file (`.vtp`, ParaView, VTK, pyvista,
/// meshio).
///
/// One piece: the vertices as `Float64` points (exact), the quads as polygons
/// (`Int64` `connectivity` and `offsets`), and as cell data per face `inner_label` and
/// `outer_label` (`UInt32`, the active scalars: the normal points from inner to
/// outer) and, for a mesh with materials, `color` (4 `UInt8` components: sRGB and
/// opacity). Arrays are appended raw binary, little-endian, each after a `UInt64`
/// byte count (`header_type="UInt64"`). Groups are not written: the labels carry the
/// interfaces.
///
/// A mesh whose labels have names ([`QuadMesh::named_labels`]) also gets field data
/// (ParaView's *Information* panel, pyvista's `field_data`): `label_values` (`UInt32`),
/// `label_names` (`String`, UTF-8) and `label_colors` (4 `UInt8` components), one
/// tuple per named label, in ASCII.
///
/// Written to a temporary file renamed onto `path` when complete (see
/// `write_mesh`); an inconsistent mesh is refused with
/// [`IoError::InvalidMesh`] before anything is created.
pub fn write_vtp(path: &Path, mesh: &QuadMesh) -> Result<(), IoError> {
    write_atomically(path, mesh, |_| Ok(()), |mesh, w| encode_vtp(mesh, w))
}

/// One appended array: its XML attributes and its byte length.
struct Array {
    attributes: String,
    bytes: u64,
}

/// The named labels as `FieldData`: VTK's ASCII string arrays list each string's bytes
/// as decimal numbers, each string ended by a 0.
fn write_field_data(mesh: &QuadMesh, w: &mut dyn Write) -> io::Result<()> {
    let n = mesh.named_labels.len();
    let join = |items: Vec<String>| items.join(" ");
    let values = join(mesh.named_labels.iter().map(|l| l.label.to_string()).collect());
    let names = join(
        mesh.named_labels
            .iter()
            .flat_map(|l| l.name.bytes().filter(|&b| b != 0).chain([0]))
            .map(|b| b.to_string())
            .collect(),
    );
    let colors = join(mesh.named_labels.iter().flat_map(|l| l.color).map(|c| c.to_string()).collect());
    writeln!(w, "    <FieldData>")?;
    writeln!(
        w,
        r#"      <DataArray type="UInt32" Name="label_values" NumberOfTuples="{n}" format="ascii">{values}</DataArray>"#
    )?;
    writeln!(
        w,
        r#"      <DataArray type="String" Name="label_names" NumberOfTuples="{n}" format="ascii">{names}</DataArray>"#
    )?;
    writeln!(
        w,
        r#"      <DataArray type="UInt8" Name="label_colors" NumberOfComponents="4" NumberOfTuples="{n}" format="ascii">{colors}</DataArray>"#
    )?;
    writeln!(w, "    </FieldData>")
}

fn encode_vtp(mesh: &QuadMesh, w: &mut dyn Write) -> io::Result<()> {
    let (np, nf) = (mesh.positions.len() as u64, mesh.quads.len() as u64);
    let colored = !mesh.face_materials.is_empty();
    let mut arrays = vec![
        Array { attributes: r#"type="Float64" Name="Points" NumberOfComponents="3""#.into(), bytes: 24 * np },
        Array { attributes: r#"type="Int64" Name="connectivity""#.into(), bytes: 32 * nf },
        Array { attributes: r#"type="Int64" Name="offsets""#.into(), bytes: 8 * nf },
        Array { attributes: r#"type="UInt32" Name="inner_label""#.into(), bytes: 4 * nf },
        Array { attributes: r#"type="UInt32" Name="outer_label""#.into(), bytes: 4 * nf },
    ];
    if colored {
        arrays.push(Array {
            attributes: r#"type="UInt8" Name="color" NumberOfComponents="4""#.into(),
            bytes: 4 * nf,
        });
    }
    let mut offset = 0u64;
    let mut tag = |a: &Array| {
        let s = format!("<DataArray {} format=\"appended\" offset=\"{offset}\"/>", a.attributes);
        offset += 8 + a.bytes;
        s
    };
    let tags: Vec<String> = arrays.iter().map(&mut tag).collect();
    writeln!(w, r#"<?xml version="1.0"?>"#)?;
    writeln!(w, r#"<VTKFile type="PolyData" version="1.0" byte_order="LittleEndian" header_type="UInt64">"#)?;
    writeln!(w, "  <PolyData>")?;
    if !mesh.named_labels.is_empty() {
        write_field_data(mesh, w)?;
    }
    writeln!(
        w,
        r#"    <Piece NumberOfPoints="{np}" NumberOfVerts="0" NumberOfLines="0" NumberOfStrips="0" NumberOfPolys="{nf}">"#
    )?;
    writeln!(w, "      <Points>\n        {}\n      </Points>", tags[0])?;
    writeln!(w, "      <Polys>\n        {}\n        {}\n      </Polys>", tags[1], tags[2])?;
    writeln!(w, r#"      <CellData Scalars="inner_label">"#)?;
    for t in &tags[3..] {
        writeln!(w, "        {t}")?;
    }
    writeln!(w, "      </CellData>\n    </Piece>\n  </PolyData>")?;
    write!(w, "  <AppendedData encoding=\"raw\">\n   _")?;
    let mut count = arrays.iter().map(|a| a.bytes);
    let mut header = |w: &mut dyn Write| w.write_all(&count.next().unwrap_or(0).to_le_bytes());
    header(w)?;
    for p in &mesh.positions {
        for c in p.to_array() {
            w.write_all(&c.to_le_bytes())?;
        }
    }
    header(w)?;
    for q in &mesh.quads {
        for &v in q {
            w.write_all(&i64::from(v).to_le_bytes())?;
        }
    }
    header(w)?;
    for f in 1..=nf {
        w.write_all(&(4 * f as i64).to_le_bytes())?;
    }
    for side in 0..2 {
        header(w)?;
        for l in &mesh.face_labels {
            w.write_all(&l[side].to_le_bytes())?;
        }
    }
    if colored {
        header(w)?;
        for &m in &mesh.face_materials {
            let m = &mesh.materials[m as usize];
            let [r, g, b, _] = m.color;
            w.write_all(&[r, g, b, (m.opacity() * 255.0).round() as u8])?;
        }
    }
    writeln!(w, "\n  </AppendedData>\n</VTKFile>")
}
