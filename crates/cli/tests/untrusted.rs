//! Inputs that would exhaust memory or block, through the binary, run under an
//! address-space limit of 4 GiB (`ulimit -v 4194304`, as batch schedulers set): each
//! ends in one error line naming the file (or in the right result), never in an
//! allocation failure's abort or a hang.

use std::io::Write;
use std::path::Path;
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

mod common;
use common::{one_error, s, stderr, stdout};

/// Runs `voxreg args` under `ulimit -v 4194304` (a 4 GiB address space).
fn limited(args: &[&str]) -> Output {
    Command::new("sh")
        .arg("-c")
        .arg("ulimit -v 4194304 && exec \"$0\" \"$@\"")
        .arg(env!("CARGO_BIN_EXE_voxreg"))
        .args(args)
        .output()
        .expect("sh runs")
}

/// `limited(args)` exits 1 with one error line holding every one of `needles`.
fn refused(args: &[&str], needles: &[&str]) {
    one_error(args, &limited(args), needles);
}

#[test]
fn a_zarr_json_declaring_a_billion_voxels_is_refused_under_ulimit() {
    let dir = tempfile::tempdir().unwrap();
    let store = dir.path().join("big.zarr");
    std::fs::create_dir(&store).unwrap();
    let meta = r#"{"zarr_format": 3, "node_type": "array", "shape": [1000, 1000, 1000], "data_type": "uint8",
        "chunk_grid": {"name": "regular", "configuration": {"chunk_shape": [100, 100, 100]}},
        "chunk_key_encoding": {"name": "default"}, "fill_value": 1, "codecs": [{"name": "bytes"}]}"#;
    assert!(meta.len() < 400);
    std::fs::write(store.join("zarr.json"), meta).unwrap();
    let out = dir.path().join("m.obj");
    for args in [vec!["info", s(&store)], vec!["regularize", s(&store), "-o", s(&out), "-q"]] {
        refused(&args, &["big.zarr: a volume of 1000x1000x1000 voxels needs", "over the memory limit"]);
    }
    assert!(!out.exists());
}

/// A `.vox` scene: models of `sizes` (each full of colour 1, then 2, ...), placed by
/// translations `at`.
fn vox_scene(models: &[[u32; 3]], at: &[&str]) -> Vec<u8> {
    use dot_vox::{Color, Frame, Model, SceneNode, ShapeModel, Size, Voxel};
    let model = |k: usize, [x, y, z]: [u32; 3]| Model {
        size: Size { x, y, z },
        voxels: (0..x * y * z)
            .map(|i| Voxel { x: (i % x) as u8, y: (i / x % y) as u8, z: (i / x / y) as u8, i: k as u8 })
            .collect(),
    };
    let mut scenes = vec![SceneNode::Transform {
        attributes: dot_vox::Dict::new(),
        frames: vec![Frame::new(dot_vox::Dict::new())],
        child: 1,
        layer_id: 0,
    }];
    scenes.push(SceneNode::Group {
        attributes: dot_vox::Dict::new(),
        children: (0..at.len() as u32).map(|k| 2 + 2 * k).collect(),
    });
    for (k, t) in at.iter().enumerate() {
        let mut frame = dot_vox::Dict::new();
        frame.insert("_t".into(), t.to_string());
        scenes.push(SceneNode::Transform {
            attributes: dot_vox::Dict::new(),
            frames: vec![Frame::new(frame)],
            child: 3 + 2 * k as u32,
            layer_id: 0,
        });
        scenes.push(SceneNode::Shape {
            attributes: dot_vox::Dict::new(),
            models: vec![ShapeModel { model_id: k as u32, attributes: dot_vox::Dict::new() }],
        });
    }
    let models = models.iter().enumerate().map(|(k, &m)| model(k, m)).collect();
    voxreg_testkit::vox_bytes(models, vec![Color { r: 1, g: 2, b: 3, a: 255 }; 256], scenes)
}

/// The quads of an OBJ file.
fn obj_quads(path: &Path) -> usize {
    std::fs::read_to_string(path).unwrap().lines().filter(|l| l.starts_with("f ")).count()
}

#[test]
fn vox_models_far_apart_are_regularized_from_their_own_boxes_under_ulimit() {
    // One-voxel models 2047 x 1023 x 1023 apart: a 2048 x 1024 x 1024 scene (8 GiB of
    // labels made dense), and two-voxel models 2,000 voxels apart along each axis.
    let dir = tempfile::tempdir().unwrap();
    for (name, models, at, quads, dims) in [
        ("far.vox", [[1, 1, 1]; 2], ["0 0 0", "2047 1023 1023"], 12, "2048 x 1024 x 1024"),
        ("apart.vox", [[2, 1, 1]; 2], ["0 0 0", "2000 2000 2000"], 20, "2002 x 2001 x 2001"),
    ] {
        let path = dir.path().join(name);
        std::fs::write(&path, vox_scene(&models, &at)).unwrap();
        let start = Instant::now();
        let out = limited(&["info", s(&path)]);
        assert_eq!(out.status.code(), Some(0), "{name}: {}", stderr(&out));
        let text = stdout(&out);
        assert!(text.contains(&format!("dimensions: {dims}")), "{name}: {text}");
        assert!(text.contains(&format!("surfels: {quads}")), "{name}: {text}");
        let mesh = dir.path().join(format!("{name}.obj"));
        let out = limited(&["regularize", s(&path), "-o", s(&mesh), "-q"]);
        assert_eq!(out.status.code(), Some(0), "{name}: {}", stderr(&out));
        assert_eq!(obj_quads(&mesh), quads, "{name}");
        // Seconds where the dense volume took tens (and 8 GiB).
        assert!(start.elapsed() < Duration::from_secs(20), "{name}: {:?}", start.elapsed());
    }
    // Under a budget smaller than the dense volume (2^31 voxels, 8 GiB) by far.
    let far = dir.path().join("far.vox");
    let mesh = dir.path().join("small.obj");
    let out = limited(&["regularize", s(&far), "-o", s(&mesh), "--max-memory", "100M", "-q"]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    assert_eq!(obj_quads(&mesh), 12);
}

#[test]
fn vox_models_far_apart_upscale_block_by_block_under_ulimit() {
    // Two two-voxel models 2,000 voxels apart along each axis: x2 is a 4004 x 4002 x 4002
    // lattice (256 GiB of labels made dense), written as a .vox scene of its blocks.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("apart.vox");
    std::fs::write(&path, vox_scene(&[[2, 1, 1]; 2], &["0 0 0", "2000 2000 2000"])).unwrap();
    let fine = dir.path().join("fine.vox");
    let start = Instant::now();
    let out = limited(&["upscale", s(&path), "--factor", "2", "-o", s(&fine), "-q"]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    assert!(start.elapsed() < Duration::from_secs(20), "{:?}", start.elapsed());
    let bytes = std::fs::read(&fine).unwrap();
    let scene = voxreg_io::read_vox_scene_bytes(&bytes, &fine, &Default::default()).unwrap();
    assert_eq!(scene.volume.dims(), [4004, 4002, 4002]);
    let solid: u64 = scene.volume.label_counts().iter().filter(|c| c.0 != 0).map(|c| c.1).sum();
    // Each model's 2 x 8 sub-voxels, less what the smooth surface rounds off.
    assert!((16..=32).contains(&solid), "{solid}");
    // Its lattice made dense (a .vol) is refused before the solve, in one line.
    let vol = dir.path().join("fine.vol");
    refused(
        &["upscale", s(&path), "-o", s(&vol), "-q"],
        &["apart.vox: upscaling x2 to 4004x4002x4002 voxels"],
    );
    assert!(!vol.exists());
}

#[test]
fn a_gzip_nrrd_skipping_gigabytes_reads_under_ulimit() {
    // 2.5 GiB of zeros to skip, from 40 gzip members of 64 MiB (2.6 MB): inflated and
    // dropped, never held.
    let mut e = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::best());
    e.write_all(&vec![0; 64 << 20]).unwrap();
    let member = e.finish().unwrap();
    let skip = 40u64 << 26;
    let mut bytes =
        format!("NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 1 1\nencoding: gzip\nbyte skip: {skip}\n\n")
            .into_bytes();
    bytes.extend(member.repeat(40));
    let mut e = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::best());
    e.write_all(&[0, 1]).unwrap();
    bytes.extend(e.finish().unwrap());
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("skip.nrrd");
    std::fs::write(&path, bytes).unwrap();
    let out = limited(&["info", s(&path)]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    let text = stdout(&out);
    assert!(text.contains("dimensions: 2 x 1 x 1 (2 voxels)") && text.contains("  1: 1 voxels"), "{text}");
}

#[test]
fn a_file_larger_than_the_budget_is_refused_before_it_is_read() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("big.npy");
    let mut header = "{'descr': '|u1', 'fortran_order': False, 'shape': (2, 2, 2), }".to_string();
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(' ');
    }
    header.push('\n');
    let mut file = std::fs::File::create(&path).unwrap();
    file.write_all(b"\x93NUMPY\x01\x00").unwrap();
    file.write_all(&(header.len() as u16).to_le_bytes()).unwrap();
    file.write_all(header.as_bytes()).unwrap();
    // 3 GiB, sparse: no disk is used.
    file.set_len(3 << 30).unwrap();
    drop(file);
    let start = Instant::now();
    refused(
        &["info", s(&path), "--max-memory", "1G"],
        &["big.npy: the file needs 3.0 GiB", "memory limit of 1.0 GiB"],
    );
    assert!(start.elapsed() < Duration::from_secs(10), "{:?}", start.elapsed());
}

#[test]
fn a_fifo_input_is_refused_without_blocking() {
    let dir = tempfile::tempdir().unwrap();
    let fifo = dir.path().join("pipe.vol");
    assert!(Command::new("mkfifo").arg(&fifo).status().unwrap().success());
    let mut child = Command::new(env!("CARGO_BIN_EXE_voxreg"))
        .args(["info", s(&fifo)])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let start = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        if start.elapsed() > Duration::from_secs(10) {
            child.kill().unwrap();
            child.wait().unwrap();
            panic!("voxreg info on a FIFO still runs after 10 s");
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let mut err = String::new();
    std::io::Read::read_to_string(&mut child.stderr.take().unwrap(), &mut err).unwrap();
    assert_eq!(status.code(), Some(1), "{err}");
    assert!(err.contains("pipe.vol: a FIFO, not a regular file"), "{err}");
}

#[test]
fn info_is_refused_over_the_budget_as_regularize_is() {
    // 16^3 voxels in a checkerboard: the volume is small, its regularization's estimate
    // (tens of MB) is not.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("checker.npy");
    let checker = (0..16 * 16 * 16).map(|i: usize| ((i + i / 16 + i / 256) % 2) as u8);
    let bytes = voxreg_testkit::npy_bytes("|u1", [16; 3], checker);
    std::fs::write(&path, bytes).unwrap();
    let out = dir.path().join("m.obj");
    for args in [
        vec!["info", s(&path), "--max-memory", "4M"],
        vec!["regularize", s(&path), "-o", s(&out), "--max-memory", "4M", "-q"],
    ] {
        refused(
            &args,
            &["checker.npy: the regularization of its ", " surfels needs", "memory limit of 4.0 MiB"],
        );
    }
    // Under a budget that its fixed part fits, the extraction stops partway through the
    // volume; the message still names the whole surface, as `info` does.
    refused(
        &["regularize", s(&path), "-o", s(&out), "--max-memory", "40M", "-q"],
        &["checker.npy: the regularization of its 12288 surfels needs 48 MiB, over the memory limit of 40 MiB"],
    );
    assert!(!out.exists());
    let ok = limited(&["info", s(&path)]);
    assert_eq!(ok.status.code(), Some(0), "{}", stderr(&ok));
}

#[test]
fn a_sparse_scene_regularizes_as_the_same_scene_made_dense() {
    use voxreg_regularize::{Params, Regularizer, Run};
    // Models apart (one across a gap of 9 voxels, one far below), touching and
    // overlapping (the later model overwrites): read as blocks, the same surface and the
    // same positions, bit for bit, as the dense volume, with the voxel-art preset.
    let bytes = vox_scene(
        &[[3, 2, 2], [2, 3, 2], [2, 2, 1], [1, 4, 1]],
        &["0 0 0", "2 1 1", "14 3 -5", "-3 -30 -20"],
    );
    let scene = voxreg_io::read_vox_scene_bytes(&bytes, Path::new("s.vox"), &Default::default()).unwrap();
    assert!(scene.is_sparse() && scene.volume.blocks().len() == 3, "{:?}", scene.volume.blocks().len());
    let dense = scene.volume.to_dense().unwrap();
    let params = Params::voxel_art();
    let run = |mut r: Regularizer| r.run(Run::new(&params)).unwrap();
    let a = run(Regularizer::from_blocks(&scene.volume, &params.regions).unwrap());
    let b = run(Regularizer::from_volume(&dense, &params.regions).unwrap());
    assert_eq!(a.surface.surfels(), b.surface.surfels());
    assert_eq!(a.surface.num_vertices(), b.surface.num_vertices());
    assert_eq!(a.positions.as_slice(), b.positions.as_slice());
    // The bundled scenes read as blocks (dense ones too): the dense reader's volume and
    // surface.
    for name in
        ["axes.vox", "extended.vox", "veh_fire.vox", "chr_army1.vox", "placeholder-with-materials.vox"]
    {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data").join(name);
        let bytes = std::fs::read(&path).unwrap();
        let scene = voxreg_io::read_vox_scene_bytes(&bytes, &path, &Default::default()).unwrap();
        let dense = voxreg_io::read_vox_bytes(&bytes, &path).unwrap().volume;
        assert_eq!(scene.volume.to_dense().unwrap(), dense, "{name}");
        let a = voxreg_digisurf::DigitalSurface::from_blocks(&scene.volume, &params.regions).unwrap();
        let b = voxreg_digisurf::DigitalSurface::new(&dense, &params.regions).unwrap();
        assert_eq!(a.surfels(), b.surfels(), "{name}");
        assert_eq!(a.positions().as_slice(), b.positions().as_slice(), "{name}");
        assert_eq!(a.edges(), b.edges(), "{name}");
    }
}
