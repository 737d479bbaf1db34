//! Integration tests of `voxreg-io`, through its public API only.
//!
//! Index:
//!
//! - **Bundled volumes** (`data/`): every `.vol` and `.vox` file reads with the
//!   documented dimensions and labels; `not_a.vox` and files with the wrong extension
//!   are refused with errors naming the file.
//! - **Snapshots** (`tests/snapshots/`): the OBJ text and a PLY dump (header, then one
//!   hex record per line) of the surface of a single voxel, and the same with a
//!   per-vertex scalar (`feature`) and its colour ramp.
//! - **Round trips**: a real surface written as PLY and parsed back by a minimal PLY
//!   reader; the same surface written as OBJ and counted.
//! - **Failed writes** leave nothing behind: missing directory, a directory as target,
//!   unknown extension, an invalid mesh (and an existing file is kept unchanged).
//! - [`formats`]: TIFF, NRRD and MRC samples written by the formats' own Python
//!   tools read as the same labels, spacing and units; round trips.
//! - [`fuzz_readers`]: mutated files never make a reader panic; replayed regressions.
//! - [`hostile`]: small files declaring huge sizes or exploding scene graphs are refused
//!   before allocating; contradictory data (overlapping pieces, bad palettes) too.
//! - [`materials`]: colours and materials from .vox palettes to glTF, OBJ/MTL and PLY.
//! - [`mesh_formats`]: STL (closed solids of the right volume) and VTK PolyData, parsed
//!   back by independent minimal readers.
//! - [`untrusted`]: inputs reaching outside themselves (detached data, links, FIFOs,
//!   devices), files and chunks over the budget, unrepresentable placements, corrupt
//!   scene graphs, control characters in units: clear errors, never a hang.
//! - [`names`]: label names (`.seg.nrrd` segments, `.vox` material names) in every
//!   writer (snapshots), file names of awkward names, files without names unchanged.

mod formats;
mod fuzz_readers;
mod hostile;
mod materials;
mod mesh_formats;
mod names;
mod untrusted;

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use glam::DVec3;
use voxreg_digisurf::{DigitalSurface, InterfaceId, LabelVolume, PatchParams};
use voxreg_io::{
    interface_name, read_volume, region_name, scalar_ramp, write_mesh, write_obj, write_ply,
    write_ply_with_vertex_scalar, FaceGroup, IoError, LoadedVolume, MeshBatch, QuadMesh,
};

fn data(name: &str) -> PathBuf {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../../data")).join(name)
}

fn labels(volume: &LabelVolume) -> BTreeSet<u32> {
    volume.label_counts().into_iter().map(|(l, _)| l).collect()
}

// ---------------------------------------------------------------- bundled volumes

#[test]
fn bundled_vol_files() {
    let cases: [(&str, usize, Option<&[u32]>); 5] = [
        ("bunny-32.vol", 35, None),
        ("bunny-64.vol", 64, Some(&[0, 255])),
        ("bunny-128.vol", 128, Some(&[0, 255])),
        ("cat10.vol", 40, Some(&[0, 96])),
        ("Al.100.vol", 100, Some(&[0, 1])),
    ];
    for (name, n, expected) in cases {
        let LoadedVolume { volume, palette, .. } = read_volume(&data(name)).unwrap();
        assert_eq!(volume.dims(), [n; 3], "{name}");
        assert_eq!(palette, None);
        assert_eq!(volume.background(), Some(0));
        assert_eq!(volume.spacing(), DVec3::ONE);
        let found = labels(&volume);
        match expected {
            Some(expected) => assert_eq!(found, expected.iter().copied().collect(), "{name}"),
            None => assert!(found.len() > 2, "{name}: grey levels expected, found {found:?}"),
        }
    }
}

#[test]
fn bunny_32_is_grey_levels_that_threshold_to_one_solid() {
    let volume = read_volume(&data("bunny-32.vol")).unwrap().volume;
    let solid = volume.binarize(|l| l >= 128);
    let surface = DigitalSurface::from_volume(&solid).unwrap();
    assert!(surface.num_surfels() > 1000);
    assert_eq!(surface.interfaces().len(), 1);
}

#[test]
fn bundled_vox_files() {
    for (name, dims, colours) in [("chr_army1.vox", [8, 7, 12], 8), ("veh_fire.vox", [24, 58, 20], 17)] {
        let LoadedVolume { volume, palette, .. } = read_volume(&data(name)).unwrap();
        assert_eq!(volume.dims(), dims, "{name}");
        let found = labels(&volume);
        assert!(found.contains(&0), "{name}: some voxels are empty");
        assert_eq!(found.len() - 1, colours, "{name}: colours {found:?}");
        // Lattice corners at integer MagicaVoxel coordinates.
        assert_eq!(volume.corner_position([0, 0, 0]), DVec3::ZERO);
        assert_eq!(volume.corner_position([1, 2, 3]), DVec3::new(1.0, 2.0, 3.0));
        let palette = palette.expect("a .vox file has a palette").colors;
        assert_eq!(palette.len(), 256);
        assert_eq!(palette[0], [0, 0, 0, 0]);
        for l in found.into_iter().filter(|&l| l != 0) {
            assert_eq!(palette[l as usize][3], 255, "{name}: label {l} is opaque");
        }
    }
}

#[test]
fn not_a_vox_is_refused() {
    let path = data("not_a.vox");
    let err = read_volume(&path).unwrap_err();
    assert!(matches!(err, IoError::Format { .. }), "{err:?}");
    assert_eq!(err.path(), path);
    let text = err.to_string();
    assert!(text.starts_with(&format!("{}: ", path.display())), "{text}");
    assert!(text.contains("not a valid MagicaVoxel .vox file"), "{text}");
}

#[test]
fn wrong_format_for_the_extension() {
    let dir = tempfile::tempdir().unwrap();
    // A .vox file named .vol, and the other way round.
    let vol = dir.path().join("really_a_vox.vol");
    std::fs::copy(data("chr_army1.vox"), &vol).unwrap();
    let err = read_volume(&vol).unwrap_err();
    assert!(err.to_string().contains("not a DGtal .vol file"), "{err}");
    let vox = dir.path().join("really_a_vol.vox");
    std::fs::copy(data("cat10.vol"), &vox).unwrap();
    assert!(matches!(read_volume(&vox), Err(IoError::Format { .. })));
    let err = read_volume(&data("README.md")).unwrap_err();
    assert!(matches!(err, IoError::UnsupportedExtension { .. }));
    assert!(
        err.to_string().ends_with(
            "README.md: unknown file extension (expected .vol, .longvol, .pgm3d, .vox, .nii, .nii.gz, .vti, \
             .npy, .tif, .tiff (or a directory or pattern of slices), .nrrd, .nhdr, .mrc, .map, .rec or a .zarr directory)"
        ),
        "{err}"
    );
}

// ---------------------------------------------------------------- snapshots

/// The surface of one voxel of label 7 at `[1, 1, 1]` in a 3^3 volume of background 0,
/// spacing 1 and origin 0: a unit cube from 0.5 to 1.5.
pub(crate) fn single_voxel_mesh() -> QuadMesh {
    let volume = LabelVolume::from_fn([3, 3, 3], |p| if p == [1, 1, 1] { 7 } else { 0 });
    let surface = DigitalSurface::from_volume(&volume).unwrap();
    QuadMesh::from_surface(&surface, &surface.positions())
}

#[test]
fn obj_snapshot() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("cube.obj");
    write_mesh(&path, &single_voxel_mesh()).unwrap();
    insta::assert_snapshot!(std::fs::read_to_string(&path).unwrap());
}

/// The PLY header as text, then each vertex and face record in hex, one per line.
fn ply_dump(bytes: &[u8], vertices: usize, faces: usize) -> String {
    ply_dump_sized(bytes, [(vertices, 12), (faces, 25)])
}

/// [`ply_dump`] with the vertex and face record sizes given.
fn ply_dump_sized(bytes: &[u8], records: [(usize, usize); 2]) -> String {
    let end = b"end_header\n";
    let body = bytes.windows(end.len()).position(|w| w == end).unwrap() + end.len();
    let mut out = String::from_utf8(bytes[..body].to_vec()).unwrap();
    let mut rest = &bytes[body..];
    for (count, size) in records {
        for _ in 0..count {
            let (record, tail) = rest.split_at(size);
            let hex: Vec<String> = record.iter().map(|b| format!("{b:02x}")).collect();
            out += &hex.join(" ");
            out.push('\n');
            rest = tail;
        }
    }
    assert!(rest.is_empty(), "{} bytes after the last face", rest.len());
    out
}

#[test]
fn ply_snapshot() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("cube.ply");
    write_mesh(&path, &single_voxel_mesh()).unwrap();
    insta::assert_snapshot!(ply_dump(&std::fs::read(&path).unwrap(), 8, 6));
}

#[test]
fn ply_vertex_scalar_snapshot() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("feature.ply");
    let mesh = single_voxel_mesh();
    let values: Vec<f64> = (0..8).map(|i| i as f64 / 7.0).collect();
    write_ply_with_vertex_scalar(&path, &mesh, "feature", &values).unwrap();
    insta::assert_snapshot!(ply_dump_sized(&std::fs::read(&path).unwrap(), [(8, 19), (6, 25)]));
}

#[test]
fn scalar_ramp_stops_and_clamping() {
    assert_eq!(scalar_ramp(0.0), [160, 0, 0]);
    assert_eq!(scalar_ramp(0.5), [255, 190, 0]);
    assert_eq!(scalar_ramp(1.0), [230, 230, 230]);
    assert_eq!(scalar_ramp(-3.0), scalar_ramp(0.0));
    assert_eq!(scalar_ramp(7.0), scalar_ramp(1.0));
    assert_eq!(scalar_ramp(0.25), [208, 95, 0]);
}

#[test]
fn ply_vertex_scalar_refuses_bad_values_and_names() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("feature.ply");
    let mesh = single_voxel_mesh();
    let ok = vec![0.5; 8];
    let mut nan = ok.clone();
    nan[3] = f64::NAN;
    for (name, values, expected) in [
        ("feature", &ok[..7], "7 values for 8 vertices"),
        ("feature", &nan[..], "vertex 3 has value NaN"),
        ("two words", &ok[..], "not a valid PLY property name"),
        ("", &ok[..], "not a valid PLY property name"),
        ("red", &ok[..], "already a vertex property"),
    ] {
        let err = write_ply_with_vertex_scalar(&path, &mesh, name, values).unwrap_err();
        assert!(matches!(err, IoError::InvalidMesh { .. }), "{err}");
        assert!(err.to_string().contains(expected), "{err}");
        assert!(err.to_string().contains("feature.ply"), "{err}");
        assert!(!path.exists());
    }
}

// ---------------------------------------------------------------- round trips

/// What [`read_ply`] reads.
struct PlyMesh {
    vertices: Vec<[f32; 3]>,
    quads: Vec<[u32; 4]>,
    face_labels: Vec<[u32; 2]>,
}

/// A minimal reader for the PLY files of this crate: checks the exact header and
/// returns the vertices, quads and face labels.
fn read_ply(bytes: &[u8]) -> PlyMesh {
    let end = b"end_header\n";
    let body = bytes.windows(end.len()).position(|w| w == end).expect("end_header") + end.len();
    let header = std::str::from_utf8(&bytes[..body]).unwrap();
    let mut lines = header.lines();
    let mut count = |element: &str| -> usize {
        let line = lines.find(|l| l.starts_with("element ")).unwrap();
        let rest = line.strip_prefix(&format!("element {element} ")).unwrap();
        rest.parse().unwrap()
    };
    let (nv, nf) = (count("vertex"), count("face"));
    let expected_header = format!(
        "ply\nformat binary_little_endian 1.0\ncomment voxreg quad mesh\nelement vertex {nv}\n\
         property float x\nproperty float y\nproperty float z\nelement face {nf}\n\
         property list uchar int vertex_indices\nproperty int inner_label\nproperty int outer_label\n\
         end_header\n"
    );
    assert_eq!(header, expected_header);
    let mut rest = &bytes[body..];
    let mut take = |n: usize| {
        let (head, tail) = rest.split_at(n);
        rest = tail;
        head
    };
    let f32_at = |b: &[u8], i: usize| f32::from_le_bytes(b[4 * i..4 * i + 4].try_into().unwrap());
    let i32_at = |b: &[u8], i: usize| i32::from_le_bytes(b[4 * i..4 * i + 4].try_into().unwrap());
    let vertices: Vec<[f32; 3]> =
        (0..nv).map(|_| take(12)).map(|b| [0, 1, 2].map(|i| f32_at(b, i))).collect();
    let mut quads = Vec::new();
    let mut face_labels = Vec::new();
    for _ in 0..nf {
        assert_eq!(take(1), [4], "quads have 4 vertices");
        let b = take(24);
        quads.push([0, 1, 2, 3].map(|i| u32::try_from(i32_at(b, i)).unwrap()));
        face_labels.push([4, 5].map(|i| u32::try_from(i32_at(b, i)).unwrap()));
    }
    assert!(rest.is_empty());
    PlyMesh { vertices, quads, face_labels }
}

#[test]
fn ply_round_trip_of_a_real_surface() {
    let loaded = read_volume(&data("chr_army1.vox")).unwrap();
    let surface = DigitalSurface::from_volume(&loaded.volume).unwrap();
    // Move the vertices off the lattice, as a regularizer would.
    let positions: Vec<DVec3> =
        surface.positions().iter().enumerate().map(|(i, p)| *p + 0.01 * (i % 7) as f64).collect();
    let mesh = QuadMesh::from_surface(&surface, &positions);
    assert!(mesh.groups.len() > 8, "several interfaces between colours");

    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("army.PLY");
    write_mesh(&path, &mesh).unwrap();
    let PlyMesh { vertices, quads, face_labels } = read_ply(&std::fs::read(&path).unwrap());
    assert_eq!(vertices.len(), mesh.positions.len());
    for (v, p) in vertices.iter().zip(&mesh.positions) {
        assert_eq!(*v, p.as_vec3().to_array());
    }
    assert_eq!(quads, mesh.quads);
    assert_eq!(face_labels, mesh.face_labels);
}

#[test]
fn obj_of_a_real_surface() {
    let volume = read_volume(&data("cat10.vol")).unwrap().volume;
    let surface = DigitalSurface::from_volume(&volume).unwrap();
    let mesh = QuadMesh::from_surface(&surface, &surface.positions());
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("cat.obj");
    write_obj(&path, &mesh).unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    let mut faces = Vec::new();
    let mut vertices = Vec::new();
    for line in text.lines() {
        let mut words = line.split_whitespace();
        match words.next() {
            Some("v") => vertices.push(words.map(|w| w.parse::<f64>().unwrap()).collect::<Vec<_>>()),
            Some("f") => faces.push(words.map(|w| w.parse::<u32>().unwrap() - 1).collect::<Vec<_>>()),
            Some("g") => assert_eq!(words.next(), Some("interface_96_0")),
            _ => {}
        }
    }
    assert_eq!(vertices.len(), mesh.positions.len());
    for (v, p) in vertices.iter().zip(&mesh.positions) {
        assert_eq!(v[..], p.to_array());
    }
    // One group holding every face, in surfel order.
    let expected: Vec<Vec<u32>> = mesh.quads.iter().map(|q| q.to_vec()).collect();
    assert_eq!(faces, expected);
}

// ---------------------------------------------------------------- failed writes

pub(crate) fn entries(dir: &Path) -> Vec<PathBuf> {
    let mut all: Vec<PathBuf> = std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().path()).collect();
    all.sort();
    all
}

#[test]
fn write_to_missing_directory_fails_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("missing").join("mesh.obj");
    let err = write_mesh(&path, &single_voxel_mesh()).unwrap_err();
    assert!(matches!(err, IoError::Io { .. }), "{err:?}");
    assert!(err.to_string().starts_with(&format!("{}: ", path.display())), "{err}");
    assert!(entries(dir.path()).is_empty());
}

#[test]
fn write_onto_a_directory_fails_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    for name in ["mesh.obj", "mesh.ply"] {
        let target = dir.path().join(name);
        std::fs::create_dir(&target).unwrap();
        let err = write_mesh(&target, &single_voxel_mesh()).unwrap_err();
        assert!(matches!(err, IoError::Io { .. }), "{err:?}");
        assert!(target.is_dir());
        assert!(entries(&target).is_empty());
    }
    // No temporary file left next to them.
    assert_eq!(entries(dir.path()), [dir.path().join("mesh.obj"), dir.path().join("mesh.ply")]);
}

#[test]
fn unknown_extension_creates_nothing() {
    let dir = tempfile::tempdir().unwrap();
    for name in ["mesh.off", "mesh"] {
        let err = write_mesh(&dir.path().join(name), &single_voxel_mesh()).unwrap_err();
        assert!(matches!(err, IoError::UnsupportedExtension { .. }), "{err:?}");
        assert!(
            err.to_string()
                .ends_with("unknown file extension (expected .obj, .ply, .glb, .gltf, .stl or .vtp)"),
            "{err}"
        );
    }
    assert!(entries(dir.path()).is_empty());
}

#[test]
fn invalid_mesh_keeps_the_existing_file() {
    let dir = tempfile::tempdir().unwrap();
    let good = single_voxel_mesh();
    let mut bad = good.clone();
    bad.quads[2][1] = 99;
    let mut big_label = good.clone();
    big_label.face_labels[0][0] = u32::MAX;
    let mut bad_group = good.clone();
    bad_group.groups.push(FaceGroup { name: "two words".into(), faces: Vec::new() });
    for (name, mesh) in [("a.obj", &bad), ("a.ply", &bad), ("b.ply", &big_label), ("c.obj", &bad_group)] {
        let path = dir.path().join(name);
        std::fs::write(&path, "old").unwrap();
        let err = write_mesh(&path, mesh).unwrap_err();
        assert!(matches!(err, IoError::InvalidMesh { .. }), "{name}: {err:?}");
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "old");
    }
    assert_eq!(entries(dir.path()).len(), 4);
    // Labels beyond i32 are fine in OBJ, which does not write them.
    write_ply(&dir.path().join("b.ply"), &good).unwrap();
    write_obj(&dir.path().join("b.obj"), &big_label).unwrap();
    assert_eq!(entries(dir.path()).len(), 5);
}

#[test]
fn write_replaces_an_existing_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("mesh.obj");
    std::fs::write(&path, "old content").unwrap();
    write_mesh(&path, &single_voxel_mesh()).unwrap();
    assert!(std::fs::read_to_string(&path).unwrap().starts_with("# voxreg quad mesh: 8 vertices, 6 quads"));
    assert_eq!(entries(dir.path()), [path]);
}

// ---------------------------------------------------------------- patches and batches

/// Labels 3 and 5 side by side in a 4x3x3 volume of background 0: three interfaces.
fn two_labels() -> DigitalSurface {
    let volume = LabelVolume::from_fn([4, 3, 3], |p| match p {
        [1, 1, 1] => 3,
        [2, 1, 1] => 5,
        _ => 0,
    });
    DigitalSurface::from_volume(&volume).unwrap()
}

/// Region 5's closed surface: its 1|2 surfel flipped (labels `[5, 3]`), groups
/// `interface_3_5` and `interface_5_0`.
#[test]
fn region_patch_snapshots() {
    let surface = two_labels();
    let r = surface.regions().region_of(5).unwrap();
    let patch = surface.region_patch(r, &PatchParams::default());
    let mesh = QuadMesh::from_patch(&surface, &patch, &surface.positions());
    assert_eq!(region_name(&surface, r), "region_5");
    let names: Vec<&str> = mesh.groups.iter().map(|g| g.name.as_str()).collect();
    assert_eq!(names, ["interface_3_5", "interface_5_0"]);
    assert_eq!(mesh.face_labels.iter().filter(|l| **l == [5, 3]).count(), 1);
    let dir = tempfile::tempdir().unwrap();
    write_mesh(&dir.path().join("r.obj"), &mesh).unwrap();
    write_mesh(&dir.path().join("r.ply"), &mesh).unwrap();
    insta::assert_snapshot!("region_5_obj", std::fs::read_to_string(dir.path().join("r.obj")).unwrap());
    insta::assert_snapshot!(
        "region_5_ply",
        ply_dump(&std::fs::read(dir.path().join("r.ply")).unwrap(), 8, 6)
    );
}

#[test]
fn interface_patches_share_exact_positions() {
    let surface = two_labels();
    // Regularized-like positions with no short decimal form.
    let positions: Vec<DVec3> = surface
        .positions()
        .iter()
        .map(|p| *p + DVec3::new(0.1, 1.0 / 3.0, std::f64::consts::PI / 7.0))
        .collect();
    let meshes: Vec<(String, QuadMesh)> = (0..surface.interfaces().len())
        .map(|i| {
            let i = InterfaceId(i as u32);
            let patch = surface.interface_patch(i, &PatchParams::default());
            (interface_name(&surface, i), QuadMesh::from_patch(&surface, &patch, &positions))
        })
        .collect();
    let names: Vec<&str> = meshes.iter().map(|m| m.0.as_str()).collect();
    assert_eq!(names, ["interface_3_5", "interface_3_0", "interface_5_0"]);
    // The 3|5 square's 4 corners lie on both other interfaces, bit for bit.
    for p in &meshes[0].1.positions {
        for (_, other) in &meshes[1..] {
            assert!(other
                .positions
                .iter()
                .any(|q| q.to_array().map(f64::to_bits) == p.to_array().map(f64::to_bits)));
        }
    }
}

#[test]
fn mesh_batch_is_all_or_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("new").join("out");
    let mut batch = MeshBatch::new(&out).unwrap();
    batch.write("a.ply", &single_voxel_mesh()).unwrap();
    batch.write("b.obj", &single_voxel_mesh()).unwrap();
    // Staged only: nothing visible but the hidden staging directory.
    assert!(entries(&out).iter().all(|p| p.file_name().unwrap().to_string_lossy().starts_with(".voxreg-")));
    let written = batch.commit().unwrap();
    assert_eq!(written, [out.join("a.ply"), out.join("b.obj")]);
    assert_eq!(entries(&out), [out.join("a.ply"), out.join("b.obj")]);

    // A failure midway: the batch is dropped, nothing new appears, old files stay.
    let mut batch = MeshBatch::new(&out).unwrap();
    batch.write("c.ply", &single_voxel_mesh()).unwrap();
    let bad = QuadMesh { quads: vec![[0, 1, 2, 99]], face_labels: vec![[1, 0]], ..single_voxel_mesh() };
    let err = batch.write("d.ply", &bad).unwrap_err();
    assert!(err.to_string().contains(&out.join("d.ply").display().to_string()), "{err}");
    assert!(batch.write("../e.ply", &single_voxel_mesh()).is_err());
    drop(batch);
    assert_eq!(entries(&out), [out.join("a.ply"), out.join("b.obj")]);
}
