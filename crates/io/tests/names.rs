//! Label names (`.seg.nrrd` segments, `.vox` material `_name`s) from the readers to the
//! writers: snapshots of what each format carries, file names of awkward names (`/`,
//! spaces, non-ASCII, duplicates, empty), and files without names left as before.

use std::path::{Path, PathBuf};

use voxreg_digisurf::{DigitalSurface, InterfaceId, RegionId, RegionMap};
use voxreg_io::{
    file_name_part, named_interface_name, named_region_name, read_volume, read_vox_bytes, write_mesh,
    LoadedVolume, QuadMesh,
};

fn data(name: &str) -> PathBuf {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../../data")).join(name)
}

/// [`voxreg_testkit::odd_names_seg_nrrd`] written to `path`.
pub(crate) fn write_odd_names(path: &Path) {
    std::fs::write(path, voxreg_testkit::odd_names_seg_nrrd()).unwrap();
}

fn mesh_of(loaded: &LoadedVolume) -> (DigitalSurface, QuadMesh) {
    let surface = DigitalSurface::from_volume(&loaded.volume).unwrap();
    let mut mesh = QuadMesh::from_surface(&surface, &surface.positions());
    mesh.assign_materials(loaded.palette.as_ref().unwrap());
    (surface, mesh)
}

/// What every writer says about the labels' names: PLY header, OBJ comments and
/// `usemtl` lines, MTL names, the VTP XML before its appended data, glTF node, mesh
/// and material names.
fn names_in_writers(mesh: &QuadMesh) -> String {
    let dir = tempfile::tempdir().unwrap();
    let file = |ext: &str| {
        let path = dir.path().join(format!("m.{ext}"));
        write_mesh(&path, mesh).unwrap();
        std::fs::read(&path).unwrap()
    };
    let mut out = String::new();
    let ply = file("ply");
    let end = ply.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
    out += &format!("--- ply header\n{}", std::str::from_utf8(&ply[..end]).unwrap());
    let obj = String::from_utf8(file("obj")).unwrap();
    out += "--- obj\n";
    for line in obj.lines().filter(|l| l.starts_with(['#', 'm', 'u', 'g'])) {
        out += &format!("{line}\n");
    }
    let mtl = std::fs::read_to_string(dir.path().join("m.mtl")).unwrap();
    out += "--- mtl\n";
    for line in mtl.lines().filter(|l| l.starts_with("newmtl")) {
        out += &format!("{line}\n");
    }
    let vtp = file("vtp");
    let end = vtp.windows(13).position(|w| w == b"<AppendedData").unwrap();
    out += &format!("--- vtp\n{}\n", std::str::from_utf8(&vtp[..end]).unwrap().trim_end());
    let gltf: serde_json::Value = serde_json::from_slice(&file("gltf")).unwrap();
    let names = |key: &str| -> Vec<String> {
        gltf[key].as_array().unwrap().iter().map(|n| n["name"].as_str().unwrap_or("").to_string()).collect()
    };
    out += &format!(
        "--- gltf\nnodes: {:?}\nmeshes: {:?}\nmaterials: {:?}\nroot children: {}\n",
        names("nodes"),
        names("meshes"),
        names("materials"),
        gltf["nodes"].as_array().unwrap().last().unwrap()["children"]
    );
    out
}

#[test]
fn seg_nrrd_names_in_every_writer() {
    // Written by pynrrd (data/formats/make.py).
    let loaded = read_volume(&data("formats/organs.seg.nrrd")).unwrap();
    let palette = loaded.palette.as_ref().unwrap();
    let names: Vec<(u32, &str)> = palette.names.iter().map(|(&l, n)| (l, n.as_str())).collect();
    assert_eq!(names, [(1, "liver"), (2, "spleen")]);
    let (_, mesh) = mesh_of(&loaded);
    insta::assert_snapshot!(names_in_writers(&mesh));
}

#[test]
fn awkward_names_are_kept_and_made_safe() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("odd.seg.nrrd");
    write_odd_names(&path);
    let loaded = read_volume(&path).unwrap();
    let palette = loaded.palette.as_ref().unwrap();
    // Names as written, the empty one left out; material names without whitespace and
    // unique (the duplicate gets its label).
    let names: Vec<&str> = (1..=7).map(|l| palette.name(l).unwrap_or("-")).collect();
    assert_eq!(names, ["Left kidney", "a/b\\c", "肝臓 région", "liver", "liver", "-", "../.."]);
    let materials: Vec<&str> = (1..=7).map(|l| palette.material(l).unwrap().name.as_str()).collect();
    assert_eq!(materials, ["Left_kidney", "a/b\\c", "肝臓_région", "liver", "liver_5", "segment_6", "../.."]);

    let (surface, mesh) = mesh_of(&loaded);
    let regions: Vec<String> = (0..surface.regions().len() as u32)
        .map(RegionId)
        .filter(|&r| Some(r) != surface.regions().background())
        .map(|r| named_region_name(&surface, r, loaded.palette.as_ref()))
        .collect();
    assert_eq!(
        regions,
        [
            "region_1_Left_kidney",
            "region_2_a_b_c",
            "region_3_肝臓_région",
            "region_4_liver",
            "region_5_liver",
            "region_6",
            "region_7"
        ]
    );
    let mut interfaces: Vec<String> = (0..surface.interfaces().len() as u32)
        .map(|i| named_interface_name(&surface, InterfaceId(i), loaded.palette.as_ref()))
        .collect();
    interfaces.sort();
    let expected = [
        "interface_1_Left_kidney__0",
        "interface_1_Left_kidney__2_a_b_c",
        "interface_2_a_b_c__0",
        "interface_2_a_b_c__3_肝臓_région",
        "interface_3_肝臓_région__0",
        "interface_3_肝臓_région__4_liver",
        "interface_4_liver__0",
        "interface_4_liver__5_liver",
        "interface_5_liver__0",
        "interface_5_liver__6",
        "interface_6_0",
        "interface_6_7",
        "interface_7_0",
    ];
    assert_eq!(interfaces, expected);
    // Without a palette: today's names.
    assert_eq!(named_region_name(&surface, RegionId(0), None), voxreg_io::region_name(&surface, RegionId(0)));

    // Every writer takes them; PLY's header stays ASCII, one line per label.
    let text = names_in_writers(&mesh);
    let ply = text.split("--- obj").next().unwrap();
    assert!(ply.is_ascii(), "{ply}");
    assert!(ply.contains("comment label 2 color 26 128 255 255 name a/b\\\\c\n"), "{ply}");
    assert!(ply.contains("name \\u{809d}\\u{81d3} r\\u{e9}gion\n"), "{ply}");
    assert!(!ply.contains("label 6 "), "an empty name lists nothing: {ply}");
    assert!(text.contains("# label 3 color 51 128 255 255 name 肝臓 région\n"), "{text}");
    // The VTP string array: each name's UTF-8 bytes, each ended by 0.
    let vtp = text.split("--- vtp").nth(1).unwrap();
    let line = vtp.lines().find(|l| l.contains("label_names")).unwrap();
    let numbers = line.split('>').nth(1).unwrap().split('<').next().unwrap();
    let bytes: Vec<u8> = numbers.split(' ').map(|n| n.parse().unwrap()).collect();
    let decoded: Vec<&str> =
        bytes.split(|&b| b == 0).filter(|s| !s.is_empty()).map(|s| std::str::from_utf8(s).unwrap()).collect();
    assert_eq!(decoded, ["Left kidney", "a/b\\c", "肝臓 région", "liver", "liver", "../.."]);
    let gltf = text.split("--- gltf").nth(1).unwrap();
    assert!(gltf.contains(r#""肝臓 région""#) && gltf.contains(r#""segment_6""#), "{gltf}");
}

#[test]
fn file_name_parts() {
    let cases = [
        ("liver", "liver"),
        ("Left kidney", "Left_kidney"),
        ("  a / b  ", "a_b"),
        ("a__b", "a_b"),
        ("../..", ""),
        ("", ""),
        ("C:\\x\ny", "C_x_y"),
        ("région-2", "région-2"),
        ("\u{0}\u{7f}", ""),
    ];
    for (name, part) in cases {
        assert_eq!(file_name_part(name), part, "{name:?}");
    }
    // Long names are cut at 64 bytes, on a character boundary.
    let long = "é".repeat(40);
    let part = file_name_part(&long);
    assert_eq!(part.len(), 64);
    assert!(part.chars().all(|c| c == 'é'));
}

/// A one-voxel-per-colour `.vox` whose `MATL` chunks name colours 1 and 3 (dot_vox's
/// palette index + 1 is the label).
fn named_vox() -> Vec<u8> {
    use dot_vox::{Color, DotVoxData, Material, Model, Size, Voxel};
    let material = |id: u32, name: &str| Material {
        id,
        properties: [("_type".to_string(), "_diffuse".to_string()), ("_name".to_string(), name.to_string())]
            .into_iter()
            .collect(),
    };
    let data = DotVoxData {
        version: 150,
        index_map: dot_vox::DEFAULT_INDEX_MAP.to_vec(),
        models: vec![Model {
            size: Size { x: 3, y: 1, z: 1 },
            voxels: (0..3u8).map(|x| Voxel { x, y: 0, z: 0, i: x }).collect(),
        }],
        palette: (0..=255u8).map(|i| Color { r: i, g: 100, b: 7, a: 255 }).collect(),
        materials: vec![material(1, "Rusty metal"), material(3, "glass/blue")],
        scenes: Vec::new(),
        layers: Vec::new(),
    };
    let mut bytes = Vec::new();
    data.write_vox(&mut bytes).unwrap();
    bytes
}

#[test]
fn vox_material_names() {
    let loaded = read_vox_bytes(&named_vox(), Path::new("named.vox")).unwrap();
    let palette = loaded.palette.as_ref().unwrap();
    let names: Vec<(u32, &str)> = palette.names.iter().map(|(&l, n)| (l, n.as_str())).collect();
    assert_eq!(names, [(1, "Rusty metal"), (3, "glass/blue")]);
    assert_eq!(palette.material(1).unwrap().name, "Rusty_metal");
    assert_eq!(palette.material(2).unwrap().name, "color_2");
    let surface = DigitalSurface::new(&loaded.volume, &RegionMap::single_solid()).unwrap();
    let mut mesh = QuadMesh::from_surface(&surface, &surface.positions());
    mesh.assign_materials(palette);
    insta::assert_snapshot!(names_in_writers(&mesh));
}

#[test]
fn files_without_names_are_written_as_before() {
    // The bundled .vox files have no `_name`s: no comments, one glTF node.
    let loaded = read_volume(&data("chr_army1.vox")).unwrap();
    assert!(loaded.palette.as_ref().unwrap().names.is_empty());
    let surface = DigitalSurface::new(&loaded.volume, &RegionMap::single_solid()).unwrap();
    let mut mesh = QuadMesh::from_surface(&surface, &surface.positions());
    mesh.assign_materials(loaded.palette.as_ref().unwrap());
    assert!(mesh.named_labels.is_empty());
    let text = names_in_writers(&mesh);
    assert!(!text.contains("label "), "{text}");
    assert!(!text.contains("FieldData"), "{text}");
    assert!(text.contains("nodes: [\"voxreg\"]\nmeshes: [\"voxreg\"]"), "{text}");
}
