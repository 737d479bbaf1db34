//! Colours and materials from .vox palettes to glTF, OBJ/MTL and PLY.

use std::path::{Path, PathBuf};

use voxreg_digisurf::{DigitalSurface, LabelVolume, RegionMap};
use voxreg_io::{read_volume, write_mesh, Material, Palette, QuadMesh};

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data").join(name)
}

pub(crate) fn coloured_mesh(name: &str) -> (QuadMesh, Palette) {
    let loaded = read_volume(&data(name)).unwrap();
    let palette = loaded.palette.unwrap();
    let surface = DigitalSurface::new(&loaded.volume, &RegionMap::single_solid()).unwrap();
    let mut mesh = QuadMesh::from_surface(&surface, &surface.positions());
    mesh.assign_materials(&palette);
    (mesh, palette)
}

#[test]
fn every_face_takes_the_colour_of_its_solid_voxel() {
    let (mesh, palette) = coloured_mesh("chr_army1.vox");
    // One material per colour on the surface (chr_army1 has 8 colours; one is interior).
    let mut visible: Vec<u32> = mesh.face_labels.iter().map(|l| l[0]).collect();
    visible.sort_unstable();
    visible.dedup();
    assert_eq!((mesh.materials.len(), visible.len()), (7, 7));
    for (f, labels) in mesh.face_labels.iter().enumerate() {
        assert_eq!(labels[1], 0, "single solid: the outer side is the background");
        let m = &mesh.materials[mesh.face_materials[f] as usize];
        assert_eq!(m.color, palette.colors[labels[0] as usize]);
        assert_eq!(m.name, format!("color_{}", labels[0]));
    }
}

#[test]
fn vox_materials_are_read() {
    let loaded = read_volume(&data("metal-material.vox")).unwrap();
    let palette = loaded.palette.unwrap();
    let label = 85; // the only colour used; its MATL is "_metal" with "_weight" 0.526316
    assert!(loaded.volume.labels().iter().all(|&l| l == 0 || l == label));
    let m = palette.material(label).unwrap();
    assert!((m.metallic - 0.526316).abs() < 1e-5 && (m.roughness - 0.252632).abs() < 1e-5, "{m:?}");
    assert_eq!(palette.material(1).unwrap().metallic, 0.0);
}

#[test]
fn gltf_round_trip() {
    let (mesh, _) = coloured_mesh("chr_army1.vox");
    let dir = tempfile::tempdir().unwrap();
    for ext in ["glb", "gltf"] {
        let path = dir.path().join(format!("army.{ext}"));
        write_mesh(&path, &mesh).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        if ext == "glb" {
            assert_eq!(&bytes[..4], b"glTF");
        }
        let doc = gltf::Gltf::from_slice(&bytes).unwrap();
        assert_eq!(doc.materials().count(), mesh.materials.len());
        let prims: Vec<_> = doc.meshes().flat_map(|m| m.primitives()).collect();
        assert_eq!(prims.len(), mesh.materials.len());
        let triangles: usize = prims.iter().map(|p| p.indices().unwrap().count() / 3).sum();
        assert_eq!(triangles, 2 * mesh.num_faces());
        for (p, m) in prims.iter().zip(&mesh.materials) {
            let gm = p.material();
            assert_eq!(gm.name(), Some(m.name.as_str()));
            let [r, g, b] = m.linear_rgb();
            assert_eq!(gm.pbr_metallic_roughness().base_color_factor(), [r, g, b, 1.0]);
        }
    }
}

#[test]
fn gltf_single_voxel_snapshot() {
    let volume = LabelVolume::from_fn([3, 3, 3], |p| if p == [1, 1, 1] { 2 } else { 0 });
    let surface = DigitalSurface::from_volume(&volume).unwrap();
    let mut mesh = QuadMesh::from_surface(&surface, &surface.positions());
    let mut palette = Palette::from_colors(vec![[0, 0, 0, 0], [0, 0, 0, 255], [255, 128, 0, 255]]);
    palette.materials[2] = Material { transparency: 0.5, ..palette.materials[2].clone() };
    mesh.assign_materials(&palette);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("voxel.gltf");
    write_mesh(&path, &mesh).unwrap();
    insta::assert_snapshot!(std::fs::read_to_string(&path).unwrap());
}

#[test]
fn obj_gets_a_material_library_and_ply_colours() {
    let (mesh, palette) = coloured_mesh("chr_army1.vox");
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("army.obj");
    write_mesh(&obj, &mesh).unwrap();
    let text = std::fs::read_to_string(&obj).unwrap();
    assert!(text.lines().nth(1) == Some("mtllib army.mtl"), "{}", &text[..200]);
    let mtl = std::fs::read_to_string(dir.path().join("army.mtl")).unwrap();
    assert_eq!(mtl.matches("newmtl ").count(), mesh.materials.len());
    // Each face is preceded by the material of its solid voxel.
    let mut current = String::new();
    let mut face = 0usize;
    let order: Vec<u32> = mesh.groups.iter().flat_map(|g| g.faces.clone()).collect();
    for line in text.lines() {
        if let Some(name) = line.strip_prefix("usemtl ") {
            current = name.to_string();
        } else if line.starts_with("f ") {
            let f = order[face] as usize;
            assert_eq!(current, format!("color_{}", mesh.face_labels[f][0]));
            face += 1;
        }
    }
    assert_eq!(face, mesh.num_faces());

    let ply = dir.path().join("army.ply");
    write_mesh(&ply, &mesh).unwrap();
    let bytes = std::fs::read(&ply).unwrap();
    let header_end = bytes.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
    let header = std::str::from_utf8(&bytes[..header_end]).unwrap();
    assert!(header
        .contains("property uchar red\nproperty uchar green\nproperty uchar blue\nproperty uchar alpha\n"));
    let faces = &bytes[header_end + 12 * mesh.positions.len()..];
    assert_eq!(faces.len(), 29 * mesh.num_faces());
    for (f, record) in faces.chunks_exact(29).enumerate() {
        let label = mesh.face_labels[f][0] as usize;
        assert_eq!(&record[25..29], &palette.colors[label]);
    }
}

#[test]
fn failed_obj_write_leaves_no_material_library() {
    let (mut mesh, _) = coloured_mesh("chr_army1.vox");
    mesh.positions[0].x = f64::NAN; // refused before anything is written
    let dir = tempfile::tempdir().unwrap();
    assert!(write_mesh(&dir.path().join("bad.obj"), &mesh).is_err());
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
}

/// Runs the Khronos glTF validator (npm package pinned in tools/gltf-validate) on the
/// glTF written for every bundled .vox model. Needs `node` and `npm`; CI installs the
/// package (`npm ci --prefix tools/gltf-validate`). Skipped with a note when node is
/// missing outside CI.
#[test]
fn khronos_validator_accepts_our_gltf() {
    let dir = tempfile::tempdir().unwrap();
    let mut files = Vec::new();
    // organs.seg.nrrd: named labels, one node per label.
    for name in [
        "chr_army1.vox",
        "veh_fire.vox",
        "metal-material.vox",
        "placeholder-with-materials.vox",
        "formats/organs.seg.nrrd",
    ] {
        let (mesh, _) = coloured_mesh(name);
        for ext in ["glb", "gltf"] {
            let path = dir.path().join(format!("{}.{ext}", name.replace('/', "_")));
            write_mesh(&path, &mesh).unwrap();
            files.push(path);
        }
    }
    let Some(report) = voxreg_testkit::validate_gltf(&files) else {
        eprintln!("skipped: node is not installed");
        return;
    };
    assert_eq!(report.lines().filter(|l| l.contains(": 0 errors")).count(), files.len(), "{report}");
}
