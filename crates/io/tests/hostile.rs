//! Hostile inputs: small files declaring huge sizes, scene graphs that explode, data
//! that contradict themselves. Each is refused with an error naming the file, before
//! anything large is allocated (a test that regressed would abort the process).

use std::io::Write;
use std::path::Path;

use dot_vox::{Color, Frame, Model, SceneNode, ShapeModel, Size, Voxel};
use flate2::write::{GzEncoder, ZlibEncoder};
use flate2::Compression;
use voxreg_io::{read_nifti_bytes, read_vol_bytes, read_vox_bytes, read_vti_bytes, with_max_memory, IoError};
use voxreg_testkit::vox_bytes;

fn zlib(bytes: &[u8]) -> Vec<u8> {
    let mut e = ZlibEncoder::new(Vec::new(), Compression::default());
    e.write_all(bytes).unwrap();
    e.finish().unwrap()
}

/// A `.vti` of `extent` cells of `Float64`, zlib-compressed with `UInt64` header words,
/// whose header declares `blocks` blocks of one byte: its block count is all a reader
/// may trust.
fn vti_with_block_count(extent: &str, blocks: u64) -> Vec<u8> {
    let mut header = Vec::new();
    for w in [blocks, 1, 1, 9] {
        header.extend_from_slice(&w.to_le_bytes());
    }
    format!(
        "<VTKFile type=\"ImageData\" header_type=\"UInt64\" compressor=\"vtkZLibDataCompressor\">\
         <ImageData WholeExtent=\"{extent}\"><Piece><CellData>\
         <DataArray type=\"Float64\" Name=\"a\" format=\"binary\">{}</DataArray>\
         </CellData></Piece></ImageData></VTKFile>",
        base64(&header)
    )
    .into_bytes()
}

fn base64(bytes: &[u8]) -> String {
    const A: &[u8] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::new();
    for c in bytes.chunks(3) {
        let n = u32::from(c[0]) << 16
            | u32::from(*c.get(1).unwrap_or(&0)) << 8
            | u32::from(*c.get(2).unwrap_or(&0));
        for k in 0..4 {
            out.push(if k <= c.len() { A[(n >> (18 - 6 * k) & 63) as usize] as char } else { '=' });
        }
    }
    out
}

#[test]
fn vti_block_count_is_bounded_by_the_bytes_present() {
    // 2^31 cells of 8 bytes: 2^34 blocks of one byte is a consistent header, and
    // reserving a size word per block would take 128 GiB.
    let bytes = vti_with_block_count("0 2048 0 1024 0 1024", 1 << 34);
    assert!(bytes.len() < 400, "{}", bytes.len());
    let err = with_max_memory(u64::MAX, || read_vti_bytes(&bytes, Path::new("bomb.vti"))).unwrap_err();
    assert!(matches!(err, IoError::Format { .. }), "{err}");
    assert!(err.to_string().starts_with("bomb.vti: "), "{err}");
    assert!(err.to_string().contains("17179869184 compressed blocks"), "{err}");
    // The same file under the default budget.
    assert!(read_vti_bytes(&bytes, Path::new("bomb.vti")).is_err());
}

#[test]
fn vti_declared_size_beyond_what_zlib_can_expand_is_refused() {
    // One block declaring 2^30 bytes from a handful of compressed bytes.
    let mut header = Vec::new();
    for w in [1u32, 1 << 30, 0, 8] {
        header.extend_from_slice(&w.to_le_bytes());
    }
    let text = format!(
        "<VTKFile type=\"ImageData\" compressor=\"vtkZLibDataCompressor\">\
         <ImageData WholeExtent=\"0 1024 0 1024 0 1024\"><Piece><CellData>\
         <DataArray type=\"UInt8\" format=\"binary\">{}{}</DataArray>\
         </CellData></Piece></ImageData></VTKFile>",
        base64(&header),
        base64(&zlib(&[0; 8])[..8])
    );
    let err = with_max_memory(u64::MAX, || read_vti_bytes(text.as_bytes(), Path::new("z.vti"))).unwrap_err();
    assert!(err.to_string().contains("compressed bytes that follow can hold"), "{err}");
}

/// A `.vti` of `whole` with cell-data pieces of the given extents, ASCII `UInt8` ones.
fn vti_pieces(whole: &str, pieces: &[&str]) -> Vec<u8> {
    let mut s = format!("<VTKFile type=\"ImageData\"><ImageData WholeExtent=\"{whole}\">");
    for e in pieces {
        let n: usize = e
            .split_whitespace()
            .map(|t| t.parse::<usize>().unwrap())
            .collect::<Vec<_>>()
            .chunks(2)
            .map(|c| (c[1] - c[0]).max(1))
            .product();
        s += &format!(
            "<Piece Extent=\"{e}\"><CellData><DataArray type=\"UInt8\" Name=\"a\" format=\"ascii\">{}</DataArray></CellData></Piece>",
            vec!["1"; n].join(" ")
        );
    }
    s += "</ImageData></VTKFile>";
    s.into_bytes()
}

#[test]
fn vti_overlapping_pieces_and_holes_are_refused() {
    let path = Path::new("p.vti");
    let tiled = vti_pieces("0 4 0 1 0 1", &["0 2 0 1 0 1", "2 4 0 1 0 1"]);
    assert!(read_vti_bytes(&tiled, path).is_ok());
    // Three pieces hold enough values for the 4 cells, but two overlap and one cell is
    // left out.
    let overlapping = vti_pieces("0 4 0 1 0 1", &["0 2 0 1 0 1", "1 3 0 1 0 1"]);
    let err = read_vti_bytes(&overlapping, path).unwrap_err().to_string();
    assert!(err.contains("piece 1: its Extent overlaps that of piece 0"), "{err}");
}

fn one_voxel(i: u8) -> Model {
    Model { size: Size { x: 1, y: 1, z: 1 }, voxels: vec![Voxel { x: 0, y: 0, z: 0, i }] }
}

fn palette() -> Vec<Color> {
    vec![Color { r: 200, g: 100, b: 50, a: 255 }; 256]
}

fn transform(child: u32, t: &str) -> SceneNode {
    let mut attributes = dot_vox::Dict::new();
    attributes.insert("_t".into(), t.into());
    SceneNode::Transform {
        attributes: dot_vox::Dict::new(),
        frames: vec![Frame::new(attributes)],
        child,
        layer_id: 0,
    }
}

fn shape(model_id: u32) -> SceneNode {
    SceneNode::Shape {
        attributes: dot_vox::Dict::new(),
        models: vec![ShapeModel { model_id, attributes: dot_vox::Dict::new() }],
    }
}

fn group(children: Vec<u32>) -> SceneNode {
    SceneNode::Group { attributes: dot_vox::Dict::new(), children }
}

#[test]
fn vox_groups_listing_a_child_twice_thirty_deep_are_refused() {
    // Node 0 -> group 1 -> ... -> group 30, each listing the next twice, -> one shape:
    // 2^30 instances.
    let mut scenes = vec![transform(1, "0 0 0")];
    for k in 1..=30 {
        scenes.push(group(vec![k + 1, k + 1]));
    }
    scenes.push(transform(32, "0 0 0"));
    scenes.push(shape(0));
    let bytes = vox_bytes(vec![one_voxel(0), one_voxel(1)], palette(), scenes);
    assert!(bytes.len() < 4096);
    let start = std::time::Instant::now();
    let err = read_vox_bytes(&bytes, Path::new("bomb.vox")).unwrap_err();
    assert!(start.elapsed().as_secs() < 5);
    assert!(matches!(err, IoError::Unsupported { .. }), "{err}");
    assert!(err.to_string().starts_with("bomb.vox: unsupported: the scene graph"), "{err}");
}

/// Two one-voxel models placed at `a` and `b` by a group.
fn two_models_at(a: &str, b: &str) -> Vec<u8> {
    let scenes =
        vec![transform(1, "0 0 0"), group(vec![2, 4]), transform(3, a), shape(0), transform(5, b), shape(1)];
    vox_bytes(vec![one_voxel(0), one_voxel(1)], palette(), scenes)
}

#[test]
fn vox_models_far_apart_are_refused_over_the_memory_budget() {
    // A 2048 x 1024 x 1024 bounding volume: 2^31 voxels, 8 GiB of labels.
    let bytes = two_models_at("0 0 0", "2047 1023 1023");
    let err = with_max_memory(1 << 30, || read_vox_bytes(&bytes, Path::new("far.vox"))).unwrap_err();
    assert!(matches!(err, IoError::OverBudget { .. }), "{err}");
    let text = err.to_string();
    assert!(text.starts_with("far.vox: a volume of 2048x1024x1024 voxels needs 8.0 GiB"), "{text}");
    assert!(text.contains("memory limit of 1.0 GiB"), "{text}");
    // Close together, the same file reads.
    let near =
        with_max_memory(1 << 30, || read_vox_bytes(&two_models_at("0 0 0", "3 0 0"), Path::new("n.vox")));
    assert_eq!(near.unwrap().volume.label_counts(), vec![(0, 2), (1, 1), (2, 1)]);
}

#[test]
fn vox_unparsable_translation_is_refused() {
    for t in ["1 2 x", "1 2", "1 2 3 4", "9999999999 0 0"] {
        let err = read_vox_bytes(&two_models_at("0 0 0", t), Path::new("t.vox")).unwrap_err().to_string();
        assert!(err.contains(&format!("'{t}' is not a translation (_t")), "{t}: {err}");
    }
}

#[test]
fn vox_colour_index_zero_is_empty_space() {
    // Two voxels of colour 5; then the file's index byte of the first is set to 0.
    let model = Model {
        size: Size { x: 2, y: 1, z: 1 },
        voxels: vec![Voxel { x: 0, y: 0, z: 0, i: 4 }, Voxel { x: 1, y: 0, z: 0, i: 4 }],
    };
    let mut bytes = vox_bytes(vec![model], palette(), Vec::new());
    let xyzi = bytes.windows(4).position(|w| w == b"XYZI").unwrap();
    assert_eq!(bytes[xyzi + 12 + 4 + 3], 5);
    bytes[xyzi + 12 + 4 + 3] = 0;
    let v = read_vox_bytes(&bytes, Path::new("zero.vox")).unwrap().volume;
    assert_eq!(v.label([0, 0, 0]), Some(0));
    assert_eq!(v.label([1, 0, 0]), Some(5));
}

#[test]
fn vox_colour_index_past_a_short_palette_is_refused() {
    let short = vec![Color { r: 1, g: 2, b: 3, a: 255 }; 8];
    let ok = vox_bytes(vec![one_voxel(7)], short.clone(), Vec::new());
    let loaded = read_vox_bytes(&ok, Path::new("s.vox")).unwrap();
    assert_eq!(loaded.palette.unwrap().colors[8], [1, 2, 3, 255]);
    let err =
        read_vox_bytes(&vox_bytes(vec![one_voxel(20)], short, Vec::new()), Path::new("s.vox")).unwrap_err();
    assert!(
        err.to_string().contains("colour index 21 has no entry in the file's palette of 8 colours"),
        "{err}"
    );
}

/// A `.vol` header of `dims`, version 3 (zlib), followed by `data`.
fn vol3(dims: [u32; 3], data: &[u8]) -> Vec<u8> {
    let mut bytes = format!("X: {}\nY: {}\nZ: {}\nVersion: 3\n.\n", dims[0], dims[1], dims[2]).into_bytes();
    bytes.extend_from_slice(data);
    bytes
}

#[test]
fn zlib_vol_and_nifti_over_the_budget_are_refused_before_inflating() {
    // 700^3 voxels from a few bytes: refused from the header alone.
    let bytes = vol3([700; 3], &zlib(&[0; 1000]));
    let err = with_max_memory(1 << 30, || read_vol_bytes(&bytes, Path::new("bomb.vol"))).unwrap_err();
    assert!(matches!(err, IoError::OverBudget { .. }), "{err}");
    assert!(err.to_string().starts_with("bomb.vol: a volume of 700x700x700 voxels needs 1.6 GiB"), "{err}");

    let mut header = vec![0u8; 352];
    header[0..4].copy_from_slice(&348i32.to_le_bytes());
    for (k, v) in [3i16, 700, 700, 700, 1, 1, 1, 1].into_iter().enumerate() {
        header[40 + 2 * k..42 + 2 * k].copy_from_slice(&v.to_le_bytes());
    }
    header[70..72].copy_from_slice(&2i16.to_le_bytes()); // uint8
    header[72..74].copy_from_slice(&8i16.to_le_bytes());
    header[108..112].copy_from_slice(&352f32.to_le_bytes());
    header[344..348].copy_from_slice(b"n+1\0");
    let mut gz = GzEncoder::new(Vec::new(), Compression::default());
    gz.write_all(&header).unwrap();
    let bytes = gz.finish().unwrap();
    let err = with_max_memory(1 << 30, || read_nifti_bytes(&bytes, Path::new("bomb.nii.gz"))).unwrap_err();
    assert!(matches!(err, IoError::OverBudget { .. }), "{err}");
}

#[test]
fn zlib_data_are_never_inflated_past_the_declared_size() {
    // 10^3 voxels declared, 64 MiB of zeros compressed to about 64 KiB.
    let bytes = vol3([10; 3], &zlib(&vec![0; 64 << 20]));
    let err = with_max_memory(1 << 20, || read_vol_bytes(&bytes, Path::new("long.vol"))).unwrap_err();
    assert!(err.to_string().contains("after decompression"), "{err}");
}

#[test]
fn mesh_batch_with_a_directory_in_the_way_changes_nothing() {
    use voxreg_io::MeshBatch;
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    std::fs::create_dir_all(out.join("b.ply")).unwrap();
    std::fs::write(out.join("a.ply"), "old").unwrap();
    let mut batch = MeshBatch::new(&out).unwrap();
    for name in ["a.ply", "b.ply", "c.ply"] {
        batch.write(name, &crate::single_voxel_mesh()).unwrap();
    }
    let err = batch.commit().unwrap_err();
    assert!(err.to_string().starts_with(&out.join("b.ply").display().to_string()), "{err}");
    assert_eq!(std::fs::read_to_string(out.join("a.ply")).unwrap(), "old");
    assert_eq!(crate::entries(&out), [out.join("a.ply"), out.join("b.ply")]);
}

#[test]
fn failed_mesh_batch_removes_the_directories_it_created() {
    let dir = tempfile::tempdir().unwrap();
    let batch = voxreg_io::MeshBatch::new(&dir.path().join("x").join("y")).unwrap();
    assert!(dir.path().join("x/y").is_dir());
    drop(batch);
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
}

#[test]
fn failed_obj_write_keeps_the_old_material_library() {
    let (mesh, _) = crate::materials::coloured_mesh("chr_army1.vox");
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("m.obj");
    std::fs::create_dir(&obj).unwrap(); // the OBJ cannot replace a directory
    std::fs::write(dir.path().join("m.mtl"), "old").unwrap();
    assert!(voxreg_io::write_mesh(&obj, &mesh).is_err());
    assert_eq!(std::fs::read_to_string(dir.path().join("m.mtl")).unwrap(), "old");
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 2);
}

/// A `line skip` far beyond the data's lines stops at the data's end (the skip looped
/// once per declared line: a fuzzer's input with a skip of 10^17 ran for minutes).
#[test]
fn nrrd_line_skip_beyond_the_data_is_refused_at_once() {
    let bytes = b"NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 2 2\nencoding: raw\nline skip: 100000000000000000\n\n\x01\x02\n";
    let t = std::time::Instant::now();
    let err = voxreg_io::read_nrrd_bytes(bytes, Path::new("skip.nrrd")).map(drop).unwrap_err();
    assert!(t.elapsed().as_secs_f64() < 1.0, "{:?}", t.elapsed());
    let msg = err.to_string();
    assert!(msg.contains("skip.nrrd") && msg.contains("truncated"), "{msg}");
}
