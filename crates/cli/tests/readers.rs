//! End-to-end tests of the input side of `voxreg`: every reader through the binary,
//! grey levels and `--threshold`, `--labels`, `--background`, `--no-background`, raw
//! data (`--dims`, `--dtype`, `--spacing`), and errors that name the file.

use std::path::Path;

use glam::DVec3;

mod common;
use common::{data, stderr, stdout, voxreg};

/// Runs `voxreg info` and returns its output, which must be a success.
fn info(args: &[&str]) -> String {
    let out = voxreg(&[&["info"], args].concat());
    assert!(out.status.success(), "voxreg info {args:?} failed: {}", stderr(&out));
    stdout(&out)
}

/// The integer after `key: ` in `info` output.
fn count(text: &str, key: &str) -> u64 {
    let line =
        text.lines().find(|l| l.starts_with(&format!("{key}: "))).unwrap_or_else(|| panic!("no {key}"));
    line[key.len() + 2..].split_whitespace().next().unwrap().parse().unwrap()
}

/// The labels listed by `info`.
fn labels(text: &str) -> Vec<u32> {
    text.lines()
        .skip_while(|l| *l != "labels:")
        .skip(1)
        .take_while(|l| l.starts_with("  "))
        .map(|l| l.trim().split(':').next().unwrap().parse().unwrap())
        .collect()
}

/// The vertices of a binary little-endian PLY file whose vertices are float properties
/// starting with x, y, z.
fn ply_vertices(path: &Path) -> Vec<DVec3> {
    let bytes = std::fs::read(path).unwrap();
    let end = bytes.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
    let header = std::str::from_utf8(&bytes[..end]).unwrap();
    assert!(header.contains("format binary_little_endian 1.0"));
    let mut lines = header.lines().skip_while(|l| !l.starts_with("element vertex "));
    let n: usize = lines.next().unwrap()["element vertex ".len()..].parse().unwrap();
    let props: Vec<&str> = lines.take_while(|l| l.starts_with("property ")).collect();
    assert_eq!(&props[..3], ["property float x", "property float y", "property float z"]);
    assert!(props.iter().all(|p| p.starts_with("property float ")), "{props:?}");
    let stride = 4 * props.len();
    (0..n)
        .map(|i| {
            let f = |k: usize| {
                let at = end + i * stride + 4 * k;
                f64::from(f32::from_le_bytes(bytes[at..at + 4].try_into().unwrap()))
            };
            DVec3::new(f(0), f(1), f(2))
        })
        .collect()
}

/// The vertices of an OBJ file.
fn obj_vertices(path: &Path) -> Vec<DVec3> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .filter_map(|l| l.strip_prefix("v "))
        .map(|l| {
            let v: Vec<f64> = l.split_whitespace().map(|t| t.parse().unwrap()).collect();
            DVec3::new(v[0], v[1], v[2])
        })
        .collect()
}

fn bounds(points: &[DVec3]) -> (DVec3, DVec3) {
    points.iter().fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(lo, hi), &p| (lo.min(p), hi.max(p)))
}

#[test]
fn channels_vti_without_background_has_five_facies_open_interfaces_and_junctions() {
    let text = info(&[data("channels.vti").to_str().unwrap(), "--no-background"]);
    assert!(text.contains("dimensions: 250 x 250 x 100 (6250000 voxels)"), "{text}");
    assert!(text.contains("background: none"), "{text}");
    assert_eq!(labels(&text), [0, 1, 2, 3, 4]);
    assert_eq!(count(&text, "regions"), 5);
    // Facies meet the border of the volume: interfaces end there, open.
    assert!(count(&text, "boundary vertices") > 0, "{text}");
    assert!(count(&text, "boundary edges") > 0, "{text}");
    // Three facies meet along curves.
    assert!(count(&text, "junction edges") > 0, "{text}");
    assert!(count(&text, "interfaces") >= 4, "{text}");

    // With facies 0 as the background (the default), every surface is closed.
    let text = info(&[data("channels.vti").to_str().unwrap()]);
    assert!(text.contains("background: 0"), "{text}");
    assert_eq!(count(&text, "boundary vertices"), 0, "{text}");
}

#[test]
fn labels_and_background_select_what_is_material() {
    let path = data("channels.vti");
    let path = path.to_str().unwrap();
    let text = info(&[path, "--labels", "1,3"]);
    assert_eq!(labels(&text), [0, 1, 3]);
    assert_eq!(count(&text, "regions"), 3);
    // Others become the chosen background.
    let text = info(&[path, "--labels", "1,3", "--background", "3"]);
    assert_eq!(labels(&text), [1, 3]);
    assert!(text.contains("background: 3"), "{text}");
    assert_eq!(count(&text, "regions"), 2);

    let out = voxreg(&["info", path, "--labels", "1", "--no-background"]);
    assert!(!out.status.success());
    assert!(stderr(&out).contains("cannot be used with"), "{}", stderr(&out));
    let out = voxreg(&["info", path, "--labels", "1", "--threshold", "0.5"]);
    assert!(!out.status.success());
    assert!(stderr(&out).contains("cannot be used with"), "{}", stderr(&out));
}

/// Lobster CT crop (grey levels 0..253): T = 30 is past the background mode of the
/// histogram (values 0 to ~20, peak at 10, then a plateau of ~600 voxels a level up to
/// the shell's peak at ~135), and gives the fewest components (18, against 78 at T = 20
/// and 23 at T = 40).
const LOBSTER_THRESHOLD: &str = "30";

#[test]
fn regularize_lobster_nifti_in_header_coordinates() {
    let dir = tempfile::tempdir().unwrap();
    let ply = dir.path().join("lobster.ply");
    let input = data("lobsterCroped2.nii.gz");
    let out = voxreg(&[
        "regularize",
        input.to_str().unwrap(),
        "--threshold",
        LOBSTER_THRESHOLD,
        "-o",
        ply.to_str().unwrap(),
        "--quiet",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let vertices = ply_vertices(&ply);
    assert!(vertices.len() > 10_000, "{}", vertices.len());

    // The same threshold through the library: the voxel corners of the inside, in the
    // header's coordinates (qform: x and y flipped, offset (-50, -50, 10), spacing 1).
    let voxels = voxreg_io::read_voxels(&input).unwrap().voxels;
    let solid = voxels.threshold(LOBSTER_THRESHOLD.parse().unwrap());
    assert_eq!(solid.origin(), DVec3::new(-150.0, -150.0, 10.0));
    let mut corners = Vec::new();
    for ((x, y, z), &l) in solid.labels().indexed_iter() {
        if l == 1 {
            let c = solid.voxel_centre([x as i64, y as i64, z as i64]);
            corners.extend([c - 0.5 * solid.spacing(), c + 0.5 * solid.spacing()]);
        }
    }
    let (lo, hi) = bounds(&corners);
    let (vlo, vhi) = bounds(&vertices);
    // Regularized vertices move by at most a voxel off the lattice's bounding box (the
    // default re-centring restores the size of thin tips and may overshoot it by about
    // half a voxel on this noisy data; measured 0.56), and thin tips shrink by a few
    // voxels at most.
    let within = (vlo - lo).cmpge(DVec3::splat(-1.0)).all() && (hi - vhi).cmpge(DVec3::splat(-1.0)).all();
    assert!(within, "{vlo} {vhi} vs {lo} {hi}");
    assert!((vlo - lo).max_element() < 3.0 && (hi - vhi).max_element() < 3.0, "{vlo} {vhi} vs {lo} {hi}");
    // Inside the header's box (x, y in [-150.5, -49.5], z in [9.5, 50.5]) give or take that
    // half voxel.
    assert!(
        vlo.cmpge(DVec3::new(-151.5, -151.5, 8.5)).all() && vhi.cmple(DVec3::new(-48.5, -48.5, 51.5)).all()
    );
}

/// A NIfTI-1 file of `dims` u8 voxels (value 1 inside `inside`), pixdim `spacing` and
/// qform offset `offset` (identity rotation).
fn write_nifti(
    path: &Path,
    dims: [i16; 3],
    spacing: [f32; 3],
    offset: [f32; 3],
    inside: impl Fn([i16; 3]) -> bool,
) {
    let mut h = vec![0u8; 352];
    let mut put = |at: usize, b: &[u8]| h[at..at + b.len()].copy_from_slice(b);
    put(0, &348i32.to_le_bytes());
    put(40, &3i16.to_le_bytes());
    for k in 0..3 {
        put(42 + 2 * k, &dims[k].to_le_bytes());
        put(80 + 4 * k, &spacing[k].to_le_bytes());
        put(268 + 4 * k, &offset[k].to_le_bytes());
    }
    put(70, &2i16.to_le_bytes()); // uint8
    put(76, &1f32.to_le_bytes()); // qfac
    put(108, &352f32.to_le_bytes());
    put(252, &1i16.to_le_bytes()); // qform_code
    put(344, b"n+1\0");
    for z in 0..dims[2] {
        for y in 0..dims[1] {
            for x in 0..dims[0] {
                h.push(u8::from(inside([x, y, z])));
            }
        }
    }
    std::fs::write(path, h).unwrap();
}

#[test]
fn nifti_spacing_and_offset_reach_the_mesh() {
    let dir = tempfile::tempdir().unwrap();
    let nii = dir.path().join("cube.nii");
    write_nifti(&nii, [8, 8, 8], [0.5, 2.0, 3.0], [10.0, 20.0, 30.0], |p| {
        p.iter().all(|&c| (2..6).contains(&c))
    });
    let obj = dir.path().join("cube.obj");
    // Trivial normals keep the regularized cube inside its voxels' bounds (a ball-based
    // estimator would round a cube only 4 voxels wide).
    let args =
        ["regularize", nii.to_str().unwrap(), "-o", obj.to_str().unwrap(), "--normals", "trivial", "--quiet"];
    let out = voxreg(&args);
    assert!(out.status.success(), "{}", stderr(&out));
    let vertices = obj_vertices(&obj);
    // Voxels 2..=5 along each axis: corners from origin + 1.5 * spacing to origin + 5.5 * spacing.
    let (origin, spacing) = (DVec3::new(10.0, 20.0, 30.0), DVec3::new(0.5, 2.0, 3.0));
    let (lo, hi) = (origin + 1.5 * spacing, origin + 5.5 * spacing);
    let (vlo, vhi) = bounds(&vertices);
    assert!(vlo.cmpge(lo - 1e-4).all() && vhi.cmple(hi + 1e-4).all(), "{vlo} {vhi} vs {lo} {hi}");
    // The cube is symmetric under each axis flip, so is its regularized surface.
    let centroid = vertices.iter().sum::<DVec3>() / vertices.len() as f64;
    assert!((centroid - (lo + hi) / 2.0).length() < 1e-4, "{centroid}");
    // Extent per axis proportional to the spacing: far from isotropic.
    assert!((vhi - vlo).z > 4.0 * (vhi - vlo).x, "{vlo} {vhi}");

    // --spacing overrides the header's.
    let text = info(&[nii.to_str().unwrap(), "--spacing", "1,1,0.25"]);
    assert!(text.contains("spacing: 1 1 0.25"), "{text}");
}

#[test]
fn raw_data_need_dims_and_read_with_dtype_and_spacing() {
    let dir = tempfile::tempdir().unwrap();
    let raw = dir.path().join("block.raw");
    // 4x3x2 u16 big endian, value 1000 in voxel [1, 1, 0], 7 in [2, 1, 1].
    let mut values = [0u16; 24];
    values[1 + 4] = 1000;
    values[2 + 4 + 12] = 7;
    std::fs::write(&raw, values.iter().flat_map(|v| v.to_be_bytes()).collect::<Vec<u8>>()).unwrap();
    let path = raw.to_str().unwrap();
    let text =
        info(&[path, "--dims", "4,3,2", "--dtype", "u16", "--endian", "big", "--spacing", "0.5,0.5,2"]);
    assert!(text.contains("dimensions: 4 x 3 x 2 (24 voxels)"), "{text}");
    assert!(text.contains("spacing: 0.5 0.5 2"), "{text}");
    assert_eq!(labels(&text), [0, 7, 1000]);

    let fails = |args: &[&str], expected: &str| {
        let out = voxreg(args);
        assert!(!out.status.success(), "{args:?} succeeded");
        assert!(stderr(&out).contains(expected), "{args:?}: expected '{expected}' in {}", stderr(&out));
    };
    fails(&["info", path], "block.raw: raw data have no header: give --dims X,Y,Z and --dtype");
    fails(&["info", path, "--dims", "4,3,2", "--dtype", "u32"], "block.raw: truncated voxel data");
    fails(&["info", path, "--dims", "4,3,2"], "block.raw: dimensions do not match the data");
    fails(&["info", path, "--dtype", "u16"], "--dims");
    fails(&["info", path, "--dims", "4,3", "--dtype", "u16"], "is not three dimensions");
    fails(&["info", path, "--dims", "4,3,2", "--dtype", "u12"], "unknown data type 'u12'");
    fails(&["info", path, "--dims", "4,3,2", "--spacing", "1,0,1"], "must be finite and positive");
    fails(&["info", path, "--dims", "100000,100000,100000"], "exceeds the limit");
}

/// A version-1 `.npy` file of little-endian f32 values, shape `(X, Y, Z)` in C order.
fn write_npy_f32(path: &Path, shape: [usize; 3], values: &[f32]) {
    std::fs::write(
        path,
        voxreg_testkit::npy_bytes("<f4", shape, values.iter().flat_map(|v| v.to_le_bytes())),
    )
    .unwrap();
}

#[test]
fn grey_levels_need_a_threshold_and_nan_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let npy = dir.path().join("density.npy");
    // A 4x4x4 field, 0.75 in the middle 2x2x2 block, 0.25 elsewhere.
    let values: Vec<f32> = (0..64)
        .map(|i| {
            let (x, y, z) = (i / 16, (i / 4) % 4, i % 4);
            if [x, y, z].iter().all(|c| (1..3).contains(c)) {
                0.75
            } else {
                0.25
            }
        })
        .collect();
    write_npy_f32(&npy, [4, 4, 4], &values);
    let path = npy.to_str().unwrap();
    let out = voxreg(&["info", path]);
    assert!(!out.status.success());
    let err = stderr(&out);
    assert!(err.contains("density.npy: grey-level data needs --threshold T"), "{err}");
    assert!(err.contains("values range from 0.25 to 0.75"), "{err}");
    let text = info(&[path, "--threshold", "0.5"]);
    assert_eq!(labels(&text), [0, 1]);
    assert!(text.contains("  1: 8 voxels"), "{text}");
    assert_eq!(count(&text, "surfels"), 24);
    // Negative thresholds parse.
    let text = info(&[path, "--threshold", "-1"]);
    assert!(text.contains("  1: 64 voxels"), "{text}");

    // Integral, non-negative floats are labels without a threshold.
    let ints: Vec<f32> = values.iter().map(|&v| if v > 0.5 { 3.0 } else { 0.0 }).collect();
    write_npy_f32(&npy, [4, 4, 4], &ints);
    assert_eq!(labels(&info(&[path])), [0, 3]);

    let mut nan = values.clone();
    nan[21] = f32::NAN;
    write_npy_f32(&npy, [4, 4, 4], &nan);
    let out = voxreg(&["info", path, "--threshold", "0.5"]);
    assert!(!out.status.success());
    assert!(stderr(&out).contains("density.npy: grey level NaN at voxel [1, 1, 1]"), "{}", stderr(&out));
    let out = voxreg(&["info", path, "--threshold", "nan"]);
    assert!(!out.status.success());
}

#[test]
fn every_bundled_format_reads_through_the_cli() {
    for (name, dims) in [
        ("test.longvol", "16 x 16 x 16"),
        ("cat10.pgm3d", "40 x 40 x 40"),
        ("ascii_ball.pgm3d", "9 x 9 x 9"),
        ("lobsterCroped2.nii.gz", "101 x 101 x 41"),
    ] {
        let text = info(&[data(name).to_str().unwrap(), "--threshold", "0"]);
        assert!(text.contains(&format!("dimensions: {dims}")), "{name}: {text}");
    }
    // A corrupt file is an error naming it, not a panic.
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.vti");
    let mut bytes = std::fs::read(data("channels.vti")).unwrap();
    bytes.truncate(bytes.len() / 2);
    std::fs::write(&bad, bytes).unwrap();
    let out = voxreg(&["info", bad.to_str().unwrap()]);
    assert!(!out.status.success());
    let err = stderr(&out);
    assert!(err.starts_with(&format!("error: {}: ", bad.display())), "{err}");
    assert!(!err.contains("panicked"), "{err}");
}

/// `voxreg info` of the samples of `data/formats/` (written by tifffile, pynrrd,
/// mrcfile, zarr: see `data/formats/make.py`): dimensions, spacing with its unit, segment
/// names.
#[test]
fn info_snapshots_of_scientific_formats() {
    let root = data("formats");
    for name in [
        "stack_imagej.tif",
        "stack.ome.tif",
        "slices",
        "organs.seg.nrrd",
        "detached.nhdr",
        "mode6.mrc",
        "labels_v2.zarr",
        "labels_v3.zarr",
        "image.ome.zarr",
    ] {
        let path = root.join(name);
        let text = info(&[path.to_str().unwrap()]).replace(root.to_str().unwrap(), "data/formats");
        insta::assert_snapshot!(format!("info_{}", name.replace(['.', '/'], "_")), text);
    }
}

/// A broken file of each new reader: one line naming the file on stderr, exit status 1.
#[test]
fn broken_scientific_files_fail_with_one_line() {
    let dir = tempfile::tempdir().unwrap();
    let cases = [
        ("bad.tif", &b"II*\x00\x08\x00\x00\x00\xff"[..], "bad.tif: "),
        (
            "bad.nrrd",
            b"NRRD0004\ntype: uchar\ndimension: 3\nsizes: 9 9 9\nencoding: raw\n\n\x01",
            "truncated data",
        ),
        ("bad.mrc", b"short", "bad.mrc: not an MRC file"),
        ("bad.zarr", b"{\"zarr_format\": 2, \"shape\": [2, 2]", "bad.zarr: .zarray: EOF"),
    ];
    for (name, bytes, expected) in cases {
        let path = dir.path().join(name);
        if name.ends_with(".zarr") {
            std::fs::create_dir(&path).unwrap();
            std::fs::write(path.join(".zarray"), bytes).unwrap();
        } else {
            std::fs::write(&path, bytes).unwrap();
        }
        let out =
            voxreg(&["regularize", path.to_str().unwrap(), "-o", dir.path().join("m.stl").to_str().unwrap()]);
        assert_eq!(out.status.code(), Some(1), "{name}");
        let err = stderr(&out);
        assert_eq!(err.trim_end().lines().count(), 1, "{name}: {err}");
        assert!(err.contains(path.to_str().unwrap()) && err.contains(expected), "{name}: {err}");
        assert!(!dir.path().join("m.stl").exists());
    }
}
