//! STL and VTK PolyData output, parsed back by independent minimal readers.

use std::collections::HashMap;

use glam::{DVec3, Vec3};
use voxreg_digisurf::{DigitalSurface, LabelVolume, PatchParams};
use voxreg_io::{write_mesh, Palette, QuadMesh};

/// Labels 1 (a 3x2x2 block with a notch) and 2 (a 2x2x1 slab on top) in background 0.
fn surface() -> DigitalSurface {
    let volume = LabelVolume::from_fn([6, 5, 5], |[x, y, z]| match (x, y, z) {
        (1..=3, 1..=2, 1..=2) if (x, y, z) != (3, 2, 2) => 1,
        (1..=2, 1..=2, 3) => 2,
        _ => 0,
    });
    DigitalSurface::from_volume(&volume).unwrap()
}

/// The triangles of a binary STL file: normal and three corners each.
fn parse_stl(bytes: &[u8]) -> Vec<[Vec3; 4]> {
    assert!(!bytes.starts_with(b"solid"));
    let n = u32::from_le_bytes(bytes[80..84].try_into().unwrap()) as usize;
    assert_eq!(bytes.len(), 84 + 50 * n);
    let f = |o: usize| f32::from_le_bytes(bytes[o..o + 4].try_into().unwrap());
    (0..n)
        .map(|t| {
            let base = 84 + 50 * t;
            assert_eq!(&bytes[base + 48..base + 50], &[0, 0]);
            std::array::from_fn(|k| {
                let o = base + 12 * k;
                Vec3::new(f(o), f(o + 4), f(o + 8))
            })
        })
        .collect()
}

/// Each region's STL is a closed, outward solid: every directed edge appears once and
/// its reverse once, the normals agree with the corners' winding, and the enclosed
/// volume (divergence theorem) is the region's voxel count.
#[test]
fn stl_regions_are_closed_solids_of_the_right_volume() {
    let surface = surface();
    let dir = tempfile::tempdir().unwrap();
    for (label, voxels) in [(1u32, 11.0f64), (2, 4.0)] {
        let r = surface.regions().region_of(label).unwrap();
        let patch = surface.region_patch(r, &PatchParams::default());
        let mesh = QuadMesh::from_patch(&surface, &patch, &surface.positions());
        let path = dir.path().join(format!("r{label}.stl"));
        write_mesh(&path, &mesh).unwrap();
        let tris = parse_stl(&std::fs::read(&path).unwrap());
        assert_eq!(tris.len(), 2 * mesh.num_faces());
        let key = |p: Vec3| p.to_array().map(f32::to_bits);
        let mut edges: HashMap<_, i32> = HashMap::new();
        let mut volume = 0.0;
        for [n, a, b, c] in &tris {
            let cross = (*b - *a).cross(*c - *a);
            assert!((cross.normalize() - *n).length() < 1e-6, "normal {n} against winding {cross}");
            volume += f64::from(a.dot(b.cross(*c))) / 6.0;
            for (p, q) in [(a, b), (b, c), (c, a)] {
                *edges.entry((key(*p), key(*q))).or_default() += 1;
            }
        }
        for (&(p, q), &count) in &edges {
            assert_eq!(count, 1, "directed edge used {count} times");
            assert_eq!(edges.get(&(q, p)), Some(&1), "edge without its reverse: the solid is open");
        }
        assert!((volume - voxels).abs() < 1e-9, "region {label}: volume {volume}, expected {voxels}");
    }
}

/// Little-endian numbers of one appended VTK array.
fn words<const N: usize>(bytes: &[u8]) -> impl Iterator<Item = [u8; N]> + '_ {
    bytes.chunks_exact(N).map(|c| c.try_into().unwrap())
}

/// The `.vtp` file parsed with an XML parser and its appended arrays decoded give back
/// the mesh exactly: points, quads, both labels and the material colours.
#[test]
fn vtp_reads_back_exactly() {
    let surface = surface();
    let mut mesh = QuadMesh::from_surface(&surface, &surface.positions());
    mesh.positions.iter_mut().for_each(|p| *p = *p * 0.1 + DVec3::new(1.0 / 3.0, 0.0, -2.5));
    mesh.assign_materials(&Palette::from_colors(vec![[0, 0, 0, 0], [255, 0, 0, 255], [0, 90, 200, 128]]));
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("m.vtp");
    write_mesh(&path, &mesh).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    let tag = b"<AppendedData encoding=\"raw\">";
    let start = bytes.windows(tag.len()).position(|w| w == tag).unwrap();
    let marker = start + bytes[start..].iter().position(|&b| b == b'_').unwrap() + 1;
    let xml = format!("{}</VTKFile>", String::from_utf8_lossy(&bytes[..start]));
    let appended = &bytes[marker..];
    assert!(bytes.ends_with(b"\n  </AppendedData>\n</VTKFile>\n"));
    let doc = roxmltree::Document::parse(&xml).unwrap();
    let piece = doc.descendants().find(|n| n.has_tag_name("Piece")).unwrap();
    assert_eq!(piece.attribute("NumberOfPoints"), Some(mesh.positions.len().to_string().as_str()));
    assert_eq!(piece.attribute("NumberOfPolys"), Some(mesh.num_faces().to_string().as_str()));
    let array = |name: &str| -> &[u8] {
        let node = doc.descendants().find(|n| n.attribute("Name") == Some(name)).unwrap();
        assert_eq!(node.attribute("format"), Some("appended"));
        let offset: usize = node.attribute("offset").unwrap().parse().unwrap();
        let len = u64::from_le_bytes(appended[offset..offset + 8].try_into().unwrap()) as usize;
        &appended[offset + 8..offset + 8 + len]
    };
    let points: Vec<f64> = words::<8>(array("Points")).map(f64::from_le_bytes).collect();
    let expected: Vec<f64> = mesh.positions.iter().flat_map(|p| p.to_array()).collect();
    assert_eq!(points, expected);
    let conn: Vec<u32> = words::<8>(array("connectivity")).map(|w| i64::from_le_bytes(w) as u32).collect();
    assert_eq!(conn, mesh.quads.iter().flatten().copied().collect::<Vec<_>>());
    let offsets: Vec<i64> = words::<8>(array("offsets")).map(i64::from_le_bytes).collect();
    assert_eq!(offsets, (1..=mesh.num_faces() as i64).map(|f| 4 * f).collect::<Vec<_>>());
    for (side, name) in ["inner_label", "outer_label"].into_iter().enumerate() {
        let labels: Vec<u32> = words::<4>(array(name)).map(u32::from_le_bytes).collect();
        assert_eq!(labels, mesh.face_labels.iter().map(|l| l[side]).collect::<Vec<_>>(), "{name}");
    }
    let colors: Vec<[u8; 4]> = words::<4>(array("color")).collect();
    for (f, c) in colors.iter().enumerate() {
        let expected = match mesh.face_labels[f][0] {
            1 => [255, 0, 0, 255],
            2 => [0, 90, 200, 128],
            other => panic!("inner label {other}"),
        };
        assert_eq!(*c, expected, "face {f}");
    }
}

#[test]
fn ply_written_in_parts_is_write_ply_s_file() {
    let s = surface();
    let mut mesh = QuadMesh::from_surface(&s, &s.positions());
    mesh.groups.clear();
    let dir = tempfile::tempdir().unwrap();
    let whole = dir.path().join("whole.ply");
    write_mesh(&whole, &mesh).unwrap();
    let (nv, nf) = (mesh.positions.len(), mesh.quads.len());
    let parts = dir.path().join("parts.ply");
    let mut w = voxreg_io::PlyParts::create(&parts, nv, nf).unwrap();
    // Faces first, then vertices, each in two runs written last to first.
    w.write_faces(nf / 2, &mesh.quads[nf / 2..], &mesh.face_labels[nf / 2..]).unwrap();
    w.write_faces(0, &mesh.quads[..nf / 2], &mesh.face_labels[..nf / 2]).unwrap();
    w.write_vertices(nv / 3, &mesh.positions[nv / 3..]).unwrap();
    assert!(!parts.exists(), "the file appears only when finished");
    w.write_vertices(0, &mesh.positions[..nv / 3]).unwrap();
    w.finish().unwrap();
    assert_eq!(std::fs::read(&parts).unwrap(), std::fs::read(&whole).unwrap());

    // Out of range, or unfinished: an error, and no file.
    let bad = dir.path().join("bad.ply");
    let mut w = voxreg_io::PlyParts::create(&bad, nv, nf).unwrap();
    assert!(w.write_vertices(nv, &mesh.positions[..1]).is_err());
    assert!(w.write_faces(0, &[[0, 1, 2, nv as u32]], &[[0, 1]]).is_err());
    w.write_vertices(0, &mesh.positions).unwrap();
    let e = w.finish().unwrap_err().to_string();
    assert!(e.contains(&format!("0 of {nf} faces written")), "{e}");
    assert!(!bad.exists());
    let names: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert_eq!(names.len(), 2, "temporaries left: {names:?}");
}
