//! Small input files written byte by byte, for tests of the readers and writers.

/// The bundled MagicaVoxel models (`data/README.md` gives their sources and licences).
pub const BUNDLED_VOX_MODELS: [&str; 6] = [
    "chr_army1.vox",
    "veh_fire.vox",
    "axes.vox",
    "extended.vox",
    "metal-material.vox",
    "placeholder-with-materials.vox",
];

/// A MagicaVoxel `.vox` file's bytes: two one-voxel models in one group, the second
/// translated by `offset` (`"x y z"`, the scene graph's `_t`), for readers' tests of scenes
/// far apart or corrupted.
pub fn two_model_vox(offset: &str) -> Vec<u8> {
    use dot_vox::{Color, Model, Size, Voxel};
    let model = || Model { size: Size { x: 1, y: 1, z: 1 }, voxels: vec![Voxel { x: 0, y: 0, z: 0, i: 1 }] };
    vox_bytes(
        vec![model(), model()],
        vec![Color { r: 1, g: 2, b: 3, a: 255 }; 256],
        group_scene(&["0 0 0", offset]),
    )
}

/// A scene graph of one group holding one model each, model `k` placed by the translation
/// `at[k]` (`"x y z"`, the scene graph's `_t`).
fn group_scene(at: &[&str]) -> Vec<dot_vox::SceneNode> {
    use dot_vox::{Frame, SceneNode, ShapeModel};
    let transform = |child: u32, t: &str| {
        let mut frame = dot_vox::Dict::new();
        frame.insert("_t".into(), t.into());
        SceneNode::Transform {
            attributes: dot_vox::Dict::new(),
            frames: vec![Frame::new(frame)],
            child,
            layer_id: 0,
        }
    };
    let mut scenes = vec![
        transform(1, "0 0 0"),
        SceneNode::Group {
            attributes: dot_vox::Dict::new(),
            children: (0..at.len() as u32).map(|k| 2 + 2 * k).collect(),
        },
    ];
    for (k, t) in at.iter().enumerate() {
        scenes.push(transform(3 + 2 * k as u32, t));
        scenes.push(SceneNode::Shape {
            attributes: dot_vox::Dict::new(),
            models: vec![ShapeModel { model_id: k as u32, attributes: dot_vox::Dict::new() }],
        });
    }
    scenes
}

/// A MagicaVoxel `.vox` file's bytes (version 150, the default index map, no materials
/// nor layers) of `models`, `palette` and the scene graph `scenes`.
pub fn vox_bytes(
    models: Vec<dot_vox::Model>,
    palette: Vec<dot_vox::Color>,
    scenes: Vec<dot_vox::SceneNode>,
) -> Vec<u8> {
    let data = dot_vox::DotVoxData {
        version: 150,
        index_map: dot_vox::DEFAULT_INDEX_MAP.to_vec(),
        models,
        palette,
        materials: Vec::new(),
        scenes,
        layers: Vec::new(),
    };
    let mut bytes = Vec::new();
    data.write_vox(&mut bytes).expect("writing to memory");
    bytes
}

/// A MagicaVoxel `.vox` scene's bytes: models of `sizes` (each full, of colour index 1,
/// then 2, ...) in one group, placed by the translations `at` (`"x y z"`, the scene
/// graph's `_t`): scenes of models far apart, touching or overlapping.
pub fn vox_scene(sizes: &[[u32; 3]], at: &[&str]) -> Vec<u8> {
    use dot_vox::{Color, Model, Size, Voxel};
    let model = |k: usize, [x, y, z]: [u32; 3]| Model {
        size: Size { x, y, z },
        voxels: (0..x * y * z)
            .map(|i| Voxel { x: (i % x) as u8, y: (i / x % y) as u8, z: (i / x / y) as u8, i: k as u8 })
            .collect(),
    };
    vox_bytes(
        sizes.iter().enumerate().map(|(k, &m)| model(k, m)).collect(),
        (0..256u32).map(|i| Color { r: i as u8, g: 255 - i as u8, b: 3, a: 255 }).collect(),
        group_scene(at),
    )
}

/// A version-1 `.npy` file's bytes: `descr` (`'<u4'`, `'|u1'`, `'<f4'`), shape `(X, Y, Z)`
/// in C order (z fastest), then `data` (after the header, if `data` is empty: a writer
/// can stream the values after it).
pub fn npy_bytes(descr: &str, [x, y, z]: [usize; 3], data: impl IntoIterator<Item = u8>) -> Vec<u8> {
    let mut header = format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': ({x}, {y}, {z}), }}");
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(' ');
    }
    header.push('\n');
    let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
    bytes.extend((header.len() as u16).to_le_bytes());
    bytes.extend(header.as_bytes());
    bytes.extend(data);
    bytes
}

/// The awkward label names of [`odd_names_seg_nrrd`], for labels 1 to 7: a space, a
/// slash and a backslash, non-ASCII letters, a duplicate, nothing, and only dots.
pub const ODD_NAMES: [&str; 7] = ["Left kidney", "a/b\\c", "肝臓 région", "liver", "liver", "", "../.."];

/// A 3D Slicer `.seg.nrrd` (raw `uint8`, 9 x 3 x 3) with labels 1 to 7 in a row along x,
/// in background 0, its segments named [`ODD_NAMES`].
pub fn odd_names_seg_nrrd() -> Vec<u8> {
    let mut text = String::from("NRRD0004\ntype: uint8\ndimension: 3\nsizes: 9 3 3\nencoding: raw\n");
    for (k, name) in ODD_NAMES.iter().enumerate() {
        text += &format!(
            "Segment{k}_Name:={name}\nSegment{k}_LabelValue:={}\nSegment{k}_Layer:=0\nSegment{k}_Color:=0.{k} 0.5 1\n",
            k + 1
        );
    }
    text.push('\n');
    let mut bytes = text.into_bytes();
    for z in 0..3 {
        for y in 0..3 {
            for x in 0..9u8 {
                bytes.push(if y == 1 && z == 1 && (1..=7).contains(&x) { x } else { 0 });
            }
        }
    }
    bytes
}

/// The names of the entries of `dir`, sorted.
pub fn dir_names(dir: &std::path::Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .expect("a readable directory")
        .map(|e| e.expect("a directory entry").file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

/// Runs the Khronos glTF validator (`tools/gltf-validate`, installed with `npm ci` on
/// first use) on `files`: its report, one line a file; `None` when node is missing
/// outside CI (in CI, node is required).
pub fn validate_gltf(files: &[std::path::PathBuf]) -> Option<String> {
    use std::process::Command;
    let tool = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tools/gltf-validate");
    let have_node = Command::new("node").arg("--version").output().is_ok_and(|o| o.status.success());
    if !have_node {
        assert!(std::env::var_os("CI").is_none(), "CI needs node for the glTF validator");
        return None;
    }
    if !tool.join("node_modules/gltf-validator").exists() {
        let ok = Command::new("npm")
            .args(["ci", "--silent", "--prefix"])
            .arg(&tool)
            .status()
            .is_ok_and(|s| s.success());
        assert!(ok, "npm ci in tools/gltf-validate failed");
    }
    let out = Command::new("node").arg(tool.join("validate.mjs")).args(files).output().expect("node runs");
    let report = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(out.status.success(), "validator: {report}{}", String::from_utf8_lossy(&out.stderr));
    Some(report)
}
