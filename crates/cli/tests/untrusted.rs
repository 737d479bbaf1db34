//! Inputs that would exhaust memory or block, through the binary, run under an
//! address-space limit of 4 GiB (`ulimit -v 4194304`, as batch schedulers set): each
//! ends in one error line naming the file (or in the right result), never in an
//! allocation failure's abort or a hang.

use std::io::Write;
use std::path::Path;
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

mod common;
use common::{stderr, stdout};

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
    let out = limited(args);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "voxreg {args:?} (killed by a signal if None): {err}");
    let errors: Vec<&str> = err.lines().filter(|l| l.starts_with("error:")).collect();
    assert_eq!(errors.len(), 1, "voxreg {args:?}: not one error line: {err}");
    for n in needles {
        assert!(err.contains(n), "voxreg {args:?}: '{n}' not in {err}");
    }
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
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

#[test]
fn vox_models_far_apart_are_refused_under_ulimit() {
    let bytes = voxreg_testkit::two_model_vox("2047 1023 1023");
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("far.vox");
    std::fs::write(&path, bytes).unwrap();
    refused(&["info", s(&path)], &["far.vox: a volume of 2048x1024x1024 voxels needs 8.0 GiB"]);
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
    let ok = limited(&["info", s(&path)]);
    assert_eq!(ok.status.code(), Some(0), "{}", stderr(&ok));
}
