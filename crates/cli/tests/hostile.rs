//! Hostile inputs and options through the `voxreg` binary: each is refused with one
//! line on standard error naming the file or the option, exit 1, before any work and
//! without leaving output behind.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

mod common;
#[cfg(unix)]
use common::wait_code;
use common::{data, one_error, s, stderr, voxreg};

/// Runs `voxreg args`, expects exit 1 and one error line, the last, holding every one of
/// `needles`.
fn refused(args: &[&str], needles: &[&str]) -> String {
    let err = one_error(args, &voxreg(args), needles);
    let last = err.lines().rev().find(|l| !l.trim().is_empty()).unwrap_or("");
    assert!(last.starts_with("error:"), "voxreg {args:?}: the error is not last: {err}");
    err
}

/// A C-order `.npy` of `u4` labels, shape `dims`, from `f(x, y, z)`.
fn write_npy_u32(path: &Path, dims: [usize; 3], f: impl Fn(usize, usize, usize) -> u32) {
    let [nx, ny, nz] = dims;
    let labels = (0..nx).flat_map(|x| (0..ny).flat_map(move |y| (0..nz).map(move |z| (x, y, z))));
    let data = labels.flat_map(|(x, y, z)| f(x, y, z).to_le_bytes());
    std::fs::write(path, voxreg_testkit::npy_bytes("<u4", dims, data)).unwrap();
}

fn zlib(bytes: &[u8]) -> Vec<u8> {
    let mut e = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
    e.write_all(bytes).unwrap();
    e.finish().unwrap()
}

#[test]
fn max_memory_refuses_a_zlib_vol_declaring_700_cubed_voxels() {
    let dir = tempfile::tempdir().unwrap();
    let bomb = dir.path().join("bomb.vol");
    let mut bytes = b"X: 700\nY: 700\nZ: 700\nVersion: 3\n.\n".to_vec();
    bytes.extend(zlib(&[0; 4096]));
    std::fs::write(&bomb, bytes).unwrap();
    refused(
        &["info", s(&bomb), "--max-memory", "1G"],
        &["bomb.vol: a volume of 700x700x700 voxels", "memory limit of 1.0 GiB"],
    );
    refused(&["info", s(&bomb), "--max-memory", "lots"], &["--max-memory 'lots'"]);
}

#[test]
fn upscale_beyond_the_budget_is_refused_before_the_solve() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("fine.vol");
    let start = Instant::now();
    refused(
        &["upscale", s(&data("Al.100.vol")), "--factor", "16", "-o", s(&out), "--max-memory", "2G", "-q"],
        &["Al.100.vol: upscaling x16 to 1600x1600x1600 voxels needs", "memory limit of 2.0 GiB"],
    );
    assert!(start.elapsed().as_secs() < 20, "{:?}", start.elapsed());
    assert!(!out.exists());
}

#[test]
fn an_output_that_is_the_input_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("x.vol");
    std::fs::copy(data("cat10.vol"), &input).unwrap();
    let before = std::fs::read(&input).unwrap();
    refused(&["upscale", s(&input), "-o", s(&input)], &["x.vol: -o would overwrite the input"]);
    // The same file by another name.
    std::fs::create_dir(dir.path().join("sub")).unwrap();
    let other = dir.path().join("sub/../x.vol");
    refused(&["upscale", s(&input), "-o", s(&other)], &["would overwrite the input"]);
    refused(
        &["regularize", s(&input), "-o", s(&dir.path().join("m.obj")), "--report", s(&input)],
        &["--report would overwrite the input"],
    );
    assert_eq!(std::fs::read(&input).unwrap(), before);
}

#[test]
fn bad_report_and_features_paths_fail_before_the_mesh_is_written() {
    let dir = tempfile::tempdir().unwrap();
    let mesh = dir.path().join("m.obj");
    let cat = data("cat10.vol");
    let missing = dir.path().join("nowhere/r.json");
    refused(&["regularize", s(&cat), "-o", s(&mesh), "--report", s(&missing)], &["r.json", "does not exist"]);
    refused(
        &["regularize", s(&cat), "-o", s(&mesh), "--report", s(dir.path())],
        &["--report names a directory"],
    );
    let features = dir.path().join("nowhere/f.ply");
    refused(
        &["regularize", s(&cat), "-o", s(&mesh), "--normals", "at", "--features", s(&features)],
        &["f.ply", "does not exist"],
    );
    refused(&["regularize", s(&cat), "-o", s(&dir.path().join("no/m.obj"))], &["m.obj", "does not exist"]);
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0, "something was written");
}

#[test]
fn empty_region_groups_are_refused() {
    for spec in ["", ";", "1,2;;3", "1,,2"] {
        refused(&["info", s(&data("cat10.vol")), "--regions", spec], &["--regions"]);
    }
}

#[test]
fn ply_labels_above_i32_are_refused_before_the_solve() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("big.npy");
    write_npy_u32(&input, [4, 4, 4], |x, y, z| {
        if (1..3).contains(&x) && (1..3).contains(&y) && (1..3).contains(&z) {
            3_000_000_000
        } else {
            0
        }
    });
    let out = dir.path().join("m.ply");
    refused(&["regularize", s(&input), "-o", s(&out), "-q"], &["big.npy: label 3000000000 does not fit PLY"]);
    assert!(!out.exists());
}

#[test]
fn upscale_that_loses_the_model_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("fine.vox");
    // A single voxel, and a thin line of ten.
    let one = dir.path().join("one.npy");
    write_npy_u32(&one, [3, 3, 3], |x, y, z| u32::from([x, y, z] == [1, 1, 1]));
    refused(
        &["upscale", s(&one), "-o", s(&out), "-q"],
        &["one.npy: the smooth surface keeps", "nothing written"],
    );
    let line = dir.path().join("line.npy");
    write_npy_u32(&line, [12, 3, 3], |x, y, z| u32::from((1..11).contains(&x) && y == 1 && z == 1));
    refused(
        &["upscale", s(&line), "-o", s(&out), "-q"],
        &["line.npy: the smooth surface keeps ", " of the 80 solid voxels at x2 (thin parts collapse)"],
    );
    assert!(!out.exists());
}

/// An OBJ of 2,000 tiny triangles and one a million units wide above them.
fn spiky_obj(path: &Path) {
    let mut text = String::new();
    for k in 0..2000 {
        let (x, y) = ((k % 50) as f64 * 0.1, (k / 50) as f64 * 0.1);
        text += &format!("v {x} {y} 0\nv {} {y} 0\nv {x} {} 0\n", x + 0.01, y + 0.01);
    }
    text += "v -1000000 -1000000 10\nv 1000000 -1000000 10\nv 0 1000000 10\n";
    for k in 0..2001 {
        text += &format!("f {} {} {}\n", 3 * k + 1, 3 * k + 2, 3 * k + 3);
    }
    std::fs::write(path, text).unwrap();
}

#[test]
fn check_survives_one_huge_triangle_among_tiny_ones() {
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("spiky.obj");
    spiky_obj(&obj);
    let start = Instant::now();
    let out = voxreg(&["check", s(&obj)]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(common::stdout(&out).contains("2001 faces, 0 self-intersecting"), "{}", common::stdout(&out));
    assert!(start.elapsed().as_secs() < 20);
}

/// Found by the mesh fuzzer: faces with coincident and collinear corners (one at 1e308)
/// made the exact intersection test fan two triangles around each other's shared
/// corners without end (a stack overflow). Now the check finishes and reports.
#[test]
fn check_survives_degenerate_faces_sharing_corners() {
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("degenerate.obj");
    // The fuzz seed's first byte picks the format (even: OBJ); the rest is the file.
    let seed = include_bytes!("../../../fuzz/seeds/mesh/degenerate_fan.obj.bin");
    std::fs::write(&obj, &seed[1..]).unwrap();
    let out = voxreg(&["check", s(&obj)]);
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    assert!(stderr(&out).contains("self-intersections"), "{}", stderr(&out));
}

/// Regularizes `dims` labels of `f` with `--split regions --manifold` and runs
/// `voxreg check` on each file: (self-intersecting pairs, check passed) per file.
fn split_and_check(dims: [usize; 3], f: impl Fn(usize, usize, usize) -> u32) -> Vec<(String, bool)> {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("v.npy");
    write_npy_u32(&input, dims, f);
    let out = dir.path().join("parts");
    let o = voxreg(&["regularize", s(&input), "-o", s(&out), "--split", "regions", "--manifold", "-q"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let mut files: Vec<PathBuf> = std::fs::read_dir(&out).unwrap().map(|e| e.unwrap().path()).collect();
    files.sort();
    files
        .iter()
        .map(|f| {
            let c = voxreg(&["check", s(f)]);
            (common::stdout(&c), c.status.success())
        })
        .collect()
}

#[test]
fn split_regions_manifold_output_passes_check() {
    // Two boxes side by side.
    let boxes = split_and_check([8, 5, 5], |x, y, z| {
        if (1..7).contains(&x) && (1..4).contains(&y) && (1..4).contains(&z) {
            1 + u32::from(x >= 4)
        } else {
            0
        }
    });
    assert_eq!(boxes.len(), 2);
    assert!(boxes.iter().all(|(_, ok)| *ok), "{boxes:?}");
    // A checkerboard: every region pinched everywhere; the duplicated pinch vertices
    // coincide and must not count as contacts, and the quads around them, which the
    // default preset lets slide over one another, are moved back until none crosses.
    let inside = |v: usize| (1..5).contains(&v);
    let checker = split_and_check([6, 6, 6], |x, y, z| {
        if inside(x) && inside(y) && inside(z) {
            1 + ((x + y + z) % 2) as u32
        } else {
            0
        }
    });
    assert_eq!(checker.len(), 2);
    assert!(
        checker.iter().all(|(out, ok)| *ok && out.contains(" 0 self-intersecting face pairs")),
        "{checker:?}"
    );
}

#[test]
fn failed_split_leaves_no_directory() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("big.npy");
    write_npy_u32(&input, [4, 4, 4], |x, y, z| {
        if [x, y, z] == [1, 1, 1] {
            3_000_000_000
        } else {
            u32::from([x, y, z] == [2, 2, 2])
        }
    });
    let out = dir.path().join("new/parts");
    refused(&["regularize", s(&input), "-o", s(&out), "--split", "regions", "-q"], &["does not fit PLY"]);
    assert!(!dir.path().join("new").exists());
}

#[cfg(unix)]
#[test]
fn sigint_and_sigterm_exit_with_nothing_left_behind() {
    let dir = tempfile::tempdir().unwrap();
    // Two balls of radius 60 (about 140k surfels): seconds of work on an idle machine, so
    // the signal, sent 300 ms after the start, lands mid-run.
    let input = dir.path().join("balls.npy");
    write_npy_u32(&input, [240, 130, 130], |x, y, z| {
        let d = |c: f64| (x as f64 - c).powi(2) + (y as f64 - 65.0).powi(2) + (z as f64 - 65.0).powi(2);
        u32::from(d(61.0) < 3600.0) + 2 * u32::from(d(179.0) < 3600.0)
    });
    for (signal, code) in [("INT", 130), ("TERM", 143)] {
        let out_dir = dir.path().join(format!("out-{signal}"));
        std::fs::create_dir(&out_dir).unwrap();
        let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_voxreg"))
            .args(["regularize", s(&input), "-o", s(&out_dir.join("parts")), "--split", "regions", "-q"])
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        std::thread::sleep(std::time::Duration::from_millis(300));
        let killed = std::process::Command::new("kill")
            .args([format!("-{signal}"), child.id().to_string()])
            .status()
            .unwrap();
        assert!(killed.success());
        assert_eq!(wait_code(&mut child, 20), Some(code), "SIG{signal}");
        let mut err = String::new();
        std::io::Read::read_to_string(&mut child.stderr.take().unwrap(), &mut err).unwrap();
        assert!(err.contains(&format!("interrupted by SIG{signal}")), "{err}");
        let left: Vec<_> = std::fs::read_dir(&out_dir).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert!(left.is_empty(), "SIG{signal} left {left:?}");
    }
}

#[test]
fn a_vanishing_alpha_is_refused_naming_it() {
    let input = data("bunny-32.vol");
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("m.ply");
    refused(&["regularize", s(&input), "-o", s(&out), "--alpha", "1e-300"], &["alpha 1e-300 is too small"]);
    assert!(!out.exists());
}

#[test]
fn spacing_in_other_units_and_huge_radii_cost_no_more_than_bounded() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("m.ply");
    let input = data("cat10.vol");
    // Millimetre voxels written in metres: the default radius stays within 12 voxels.
    let start = Instant::now();
    let run = voxreg(&["regularize", s(&input), "-o", s(&out), "--spacing", "0.001,0.001,0.001", "-q"]);
    assert!(run.status.success(), "{}", stderr(&run));
    assert!(start.elapsed().as_secs() < 30, "took {:?}", start.elapsed());
    refused(
        &["regularize", s(&input), "-o", s(&out.with_extension("obj")), "--radius", "400"],
        &["radius 400", "larger than the whole volume"],
    );
}

#[test]
fn a_run_beyond_the_budget_is_refused_before_the_solve() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("m.ply");
    let input = data("bunny-128.vol");
    let start = Instant::now();
    refused(
        &["regularize", s(&input), "-o", s(&out), "--max-memory", "48M"],
        &["bunny-128.vol: the regularization of its", "surfels", "memory limit"],
    );
    assert!(!out.exists());
    assert!(start.elapsed().as_secs() < 20, "refused only after {:?}", start.elapsed());
}

#[test]
fn exact_geodesics_beyond_the_budget_are_refused_before_the_solve() {
    // bunny-128: about 110 MB for the regularization, several hundred for the windows.
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("d.ply");
    let input = data("bunny-128.vol");
    let start = Instant::now();
    refused(
        &["geodesic", s(&input), "--from", "0,0,0", "-o", s(&out), "--max-memory", "300M"],
        &["bunny-128.vol:", "exact geodesics", "--method heat", "memory limit"],
    );
    assert!(!out.exists());
    assert!(start.elapsed().as_secs() < 20, "refused only after {:?}", start.elapsed());
}

#[test]
fn a_decoder_panic_on_a_corrupt_zarr_store_is_one_error_line() {
    // The fuzz regression whose corrupt shard index made the zarrs decoder panic (on a
    // store in memory; read from files, its byte range fails first): one error line, no
    // panic message. The seed packs the store's files as `key\n<bytes>` joined by `\n%%\n`.
    let seed =
        concat!(env!("CARGO_MANIFEST_DIR"), "/../../fuzz/seeds/zarr/regression_shard_index_range.pack");
    let packed = std::fs::read(seed).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let store = dir.path().join("corrupt.zarr");
    let mut rest = &packed[..];
    loop {
        let end = rest.windows(4).position(|w| w == b"\n%%\n");
        let entry = &rest[..end.unwrap_or(rest.len())];
        let key_end = entry.iter().position(|&b| b == b'\n').unwrap_or(entry.len());
        let path = store.join(std::str::from_utf8(&entry[..key_end]).unwrap());
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(&path, entry.get(key_end + 1..).unwrap_or(&[])).unwrap();
        match end {
            Some(e) => rest = &rest[e + 4..],
            None => break,
        }
    }
    let err = refused(&["info", s(&store)], &["corrupt.zarr"]);
    assert!(!err.contains("panicked"), "{err}");
    assert_eq!(err.lines().count(), 1, "{err}");
}
