//! End-to-end tests of `voxreg regularize --split interfaces|regions` and `--manifold`:
//! file names (with the labels' names where the input has them), exact sharing of junction vertices between files, open interfaces that
//! end at the domain border, closed outward region surfaces, and manifoldness.
//!
//! Each file's vertices and quads are checked against the library's own patch of the
//! same volume (`DigitalSurface::interface_patch`/`region_patch`, whose vertex order the
//! writer keeps), which names the surface vertex behind every vertex of every file.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use voxreg_digisurf::{DigitalSurface, InterfaceId, LabelVolume, PatchParams, VertexId};

mod common;
use common::voxreg;
use voxreg_testkit::dir_names;

fn run_ok(args: &[&str]) {
    let out = voxreg(args);
    assert!(out.status.success(), "voxreg {args:?} failed: {}", String::from_utf8_lossy(&out.stderr));
}

/// Writes `volume`'s labels (all < 256) as a C-order `.npy` of shape (X, Y, Z).
fn write_npy(path: &Path, volume: &LabelVolume) {
    let [nx, ny, nz] = volume.dims();
    let labels = (0..nx).flat_map(|x| (0..ny).flat_map(move |y| (0..nz).map(move |z| [x, y, z])));
    let data = labels.map(|p| u8::try_from(volume.labels()[p]).unwrap());
    std::fs::write(path, voxreg_testkit::npy_bytes("|u1", [nx, ny, nz], data)).unwrap();
}

/// A PLY file as written by voxreg (no colours): `f32` positions as bits, quads, labels.
struct Ply {
    positions: Vec<[u32; 3]>,
    quads: Vec<[u32; 4]>,
    labels: Vec<[u32; 2]>,
}

fn read_ply(path: &Path) -> Ply {
    let bytes = std::fs::read(path).unwrap();
    let end = bytes.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
    let header = std::str::from_utf8(&bytes[..end]).unwrap();
    let count = |key: &str| -> usize {
        let line = header.lines().find(|l| l.starts_with(key)).unwrap();
        line[key.len()..].trim().parse().unwrap()
    };
    let (nv, nf) = (count("element vertex "), count("element face "));
    assert!(header.contains("property int inner_label\nproperty int outer_label\nend_header"), "{header}");
    let word = |at: usize| u32::from_le_bytes(bytes[at..at + 4].try_into().unwrap());
    let positions = (0..nv).map(|i| std::array::from_fn(|k| word(end + 12 * i + 4 * k))).collect();
    let faces = end + 12 * nv;
    assert_eq!(bytes.len(), faces + 25 * nf);
    let quads = (0..nf).map(|f| std::array::from_fn(|k| word(faces + 25 * f + 1 + 4 * k))).collect();
    let labels = (0..nf).map(|f| std::array::from_fn(|k| word(faces + 25 * f + 17 + 4 * k))).collect();
    Ply { positions, quads, labels }
}

/// Edges of a quad mesh (as sorted vertex pairs) with their number of faces.
fn edge_faces(quads: &[[u32; 4]]) -> HashMap<(u32, u32), usize> {
    let mut edges = HashMap::new();
    for q in quads {
        for k in 0..4 {
            let (a, b) = (q[k], q[(k + 1) % 4]);
            *edges.entry((a.min(b), a.max(b))).or_insert(0) += 1;
        }
    }
    edges
}

/// A crop of `channels.vti` (5 facies, no background) around its rarest facies, so that
/// every facies and their junctions are in a volume small enough for a quick test.
fn channels_crop() -> LabelVolume {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data/channels.vti");
    let voxreg_io::Voxels::Labels(volume) = voxreg_io::read_vti(&path).unwrap() else {
        panic!("channels.vti holds labels")
    };
    let dims = volume.dims();
    let (mut sum, mut n) = ([0usize; 3], 0);
    for ((x, y, z), &l) in volume.labels().indexed_iter() {
        if l == 4 {
            sum = [sum[0] + x, sum[1] + y, sum[2] + z];
            n += 1;
        }
    }
    let size = [48, 48, 40];
    let start: [usize; 3] =
        std::array::from_fn(|k| (sum[k] / n).saturating_sub(size[k] / 2).min(dims[k] - size[k]));
    LabelVolume::from_fn(size, |[x, y, z]| volume.labels()[[start[0] + x, start[1] + y, start[2] + z]])
        .with_background(None)
}

/// `voxreg regularize channels --no-background --split interfaces -o out/`: every facies
/// interface is an open surface whose rim lies on the domain border or along junctions
/// with other interfaces, and every vertex shared by several files has bit-identical
/// coordinates in each. (The full 250x250x100 volume takes minutes with the default
/// solver; this crop, seconds. README: "Per-interface and per-region meshes".)
#[test]
fn channels_interfaces_are_open_and_meet_exactly() {
    let dir = tempfile::tempdir().unwrap();
    let volume = channels_crop();
    let input = dir.path().join("channels.npy");
    write_npy(&input, &volume);
    let out = dir.path().join("out");
    run_ok(&[
        "regularize",
        input.to_str().unwrap(),
        "--no-background",
        "--split",
        "interfaces",
        "-o",
        &format!("{}/", out.display()),
        "--quiet",
    ]);
    let surface = DigitalSurface::from_volume(&volume).unwrap();
    assert_eq!(surface.regions().len(), 5, "the crop holds all five facies");
    let dims = volume.dims();
    let on_border = |a: VertexId, b: VertexId| {
        let (ca, cb) = (surface.vertex_corner(a), surface.vertex_corner(b));
        (0..3).any(|k| ca[k] == cb[k] && (ca[k] == 0 || ca[k] as usize == dims[k]))
    };
    let mut files: Vec<PathBuf> = std::fs::read_dir(&out).unwrap().map(|e| e.unwrap().path()).collect();
    files.sort();
    assert_eq!(files.len(), surface.interfaces().len());
    // Per surface vertex, its coordinates in each file that has it.
    let mut seen: HashMap<VertexId, Vec<[u32; 3]>> = HashMap::new();
    let mut border_rims = 0;
    for (i, interface) in surface.interfaces().iter().enumerate() {
        let [a, b] = interface.regions.map(|r| surface.regions().labels(r)[0]);
        let path = out.join(format!("interface_{a}_{b}.ply"));
        assert!(files.contains(&path), "{} missing", path.display());
        let ply = read_ply(&path);
        let patch = surface.interface_patch(InterfaceId(i as u32), &PatchParams::default());
        assert_eq!(ply.quads, patch.quads);
        assert!(ply.labels.iter().all(|&l| l == [a, b]));
        for (local, &v) in patch.vertices.iter().enumerate() {
            seen.entry(v).or_default().push(ply.positions[local]);
        }
        // Open: a rim, each edge of which is on the domain border or a junction.
        let rim: Vec<(u32, u32)> =
            edge_faces(&ply.quads).into_iter().filter(|&(_, n)| n == 1).map(|(e, _)| e).collect();
        assert!(!rim.is_empty(), "interface_{a}_{b} is closed");
        for &(p, q) in &rim {
            let (p, q) = (patch.vertices[p as usize], patch.vertices[q as usize]);
            let junction =
                surface.vertex_surfels(p).iter().any(|s| surface.surfel(*s).interface.index() != i)
                    && surface.vertex_surfels(q).iter().any(|s| surface.surfel(*s).interface.index() != i);
            assert!(on_border(p, q) || junction, "interface_{a}_{b}: rim edge inside the domain");
            border_rims += usize::from(on_border(p, q));
        }
    }
    assert!(border_rims > 0);
    let shared: Vec<&Vec<[u32; 3]>> = seen.values().filter(|c| c.len() >= 2).collect();
    assert!(shared.iter().filter(|c| c.len() >= 3).count() > 0, "no vertex where three interfaces meet");
    for copies in shared {
        assert!(copies.iter().all(|c| c == &copies[0]), "a junction vertex differs between files");
    }
}

/// Two facies stacked (1 below 2) in background 0, with a diagonal pinch of facies 1.
fn stacked() -> LabelVolume {
    LabelVolume::from_fn([6, 6, 6], |[x, y, z]| match (x, y, z) {
        (1..=4, 1..=4, 1..=2) => 1,
        (1..=4, 1..=4, 3..=4) => 2,
        (5, 5, 2) => 1, // touches the block of 1 only along an edge
        _ => 0,
    })
}

/// Region surfaces: closed and outward (enclosed volume = voxel count) with a
/// background, 2-manifold with `--manifold`; open along the domain border without
/// background.
#[test]
fn region_surfaces_are_closed_outward_and_manifold() {
    let dir = tempfile::tempdir().unwrap();
    let volume = stacked();
    let input = dir.path().join("stacked.npy");
    write_npy(&input, &volume);
    let input = input.to_str().unwrap();
    for manifold in [false, true] {
        let out = dir.path().join(format!("regions-{manifold}"));
        // A strong attachment keeps this small shape near its voxels.
        let mut args = vec![
            "regularize",
            input,
            "--alpha",
            "1",
            "--split",
            "regions",
            "-o",
            out.to_str().unwrap(),
            "-q",
        ];
        if manifold {
            args.push("--manifold");
        }
        run_ok(&args);
        for (label, voxels) in [(1, 33.0), (2, 32.0)] {
            let ply = read_ply(&out.join(format!("region_{label}.ply")));
            let p: Vec<glam::DVec3> = ply
                .positions
                .iter()
                .map(|c| glam::DVec3::from(c.map(|b| f64::from(f32::from_bits(b)))))
                .collect();
            let enclosed: f64 = ply
                .quads
                .iter()
                .map(|q| {
                    let x = q.map(|v| p[v as usize]);
                    (x[0].dot(x[1].cross(x[2])) + x[0].dot(x[2].cross(x[3]))) / 6.0
                })
                .sum();
            // Regularization moves vertices (the 1|2 interface by about half a voxel
            // here); the sign and size tell orientation.
            assert!((enclosed - voxels).abs() < 0.3 * voxels, "region {label}: {enclosed}");
            assert!(ply.labels.iter().all(|l| l[0] == label), "labels are [own, other]");
            let edges = edge_faces(&ply.quads);
            assert!(edges.values().all(|&n| n % 2 == 0), "region {label} is open");
            let pinched = edges.values().filter(|&&n| n == 4).count();
            assert_eq!(pinched, usize::from(label == 1 && !manifold), "region {label}");
        }
        assert!(!out.join("region_0.ply").exists(), "no file for the background");
    }
    // Without background, region 0 gets a file too, and surfaces reaching the border
    // are open there.
    let out = dir.path().join("open");
    run_ok(&[
        "regularize",
        input,
        "--no-background",
        "--split",
        "regions",
        "-o",
        out.to_str().unwrap(),
        "--quiet",
    ]);
    let ply = read_ply(&out.join("region_0.ply"));
    assert!(edge_faces(&ply.quads).values().any(|&n| n == 1));
    assert!(ply.labels.iter().all(|l| l[0] == 0));
}

#[test]
fn split_options_are_checked_and_write_nothing_on_error() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("stacked.npy");
    write_npy(&input, &stacked());
    let input = input.to_str().unwrap();
    let out = voxreg(&["regularize", input, "-o", dir.path().join("a.ply").to_str().unwrap(), "--manifold"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--manifold needs --split"));
    let file = dir.path().join("file");
    std::fs::write(&file, "x").unwrap();
    let out = voxreg(&["regularize", input, "--split", "interfaces", "-o", file.to_str().unwrap()]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("is a file"));
    // OBJ: one group per interface, named like the files.
    let objs = dir.path().join("objs");
    run_ok(&[
        "regularize",
        input,
        "--split",
        "interfaces",
        "--split-format",
        "obj",
        "-o",
        objs.to_str().unwrap(),
        "-q",
    ]);
    let mut names: Vec<String> = std::fs::read_dir(&objs)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(names, ["interface_1_0.obj", "interface_1_2.obj", "interface_2_0.obj"]);
    let text = std::fs::read_to_string(objs.join("interface_1_2.obj")).unwrap();
    assert!(text.contains("\ng interface_1_2\n"), "{text}");
}

/// A 3D Slicer segmentation to one closed STL solid per segment, and to one VTK
/// PolyData file: the binary writers through the CLI.
#[test]
fn seg_nrrd_to_stl_solids_and_vtp() {
    let input = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../../data/formats/organs.seg.nrrd"));
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("solids");
    let args = ["regularize", input.to_str().unwrap(), "--split", "regions", "--split-format", "stl"];
    run_ok(&[&args[..], &["-o", out.to_str().unwrap()]].concat());
    let mut names: Vec<String> = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(names, ["region_1_liver.stl", "region_2_spleen.stl"]);
    for name in &names {
        let bytes = std::fs::read(out.join(name)).unwrap();
        let triangles = u32::from_le_bytes(bytes[80..84].try_into().unwrap()) as usize;
        assert!(triangles > 0 && bytes.len() == 84 + 50 * triangles, "{name}");
    }
    let vtp = dir.path().join("organs.vtp");
    run_ok(&["regularize", input.to_str().unwrap(), "-o", vtp.to_str().unwrap()]);
    let text = String::from_utf8_lossy(&std::fs::read(&vtp).unwrap()).into_owned();
    assert!(
        text.starts_with("<?xml")
            && text.contains(r#"Name="inner_label""#)
            && text.contains(r#"Name="color""#)
    );
}

/// [`voxreg_testkit::odd_names_seg_nrrd`] written to `path`.
fn write_odd_names(path: &Path) {
    std::fs::write(path, voxreg_testkit::odd_names_seg_nrrd()).unwrap();
}

/// Label names become file names (sanitized, label numbers kept, so unique), and the
/// report's `labels` table lists them as written.
#[test]
fn label_names_name_the_split_files_and_fill_the_report() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("odd.seg.nrrd");
    write_odd_names(&input);
    let input = input.to_str().unwrap();
    let regions = dir.path().join("regions");
    let report = dir.path().join("report.json");
    let fast = ["--normals", "trivial", "--refine", "0", "-q"];
    run_ok(
        &[
            &["regularize", input, "--split", "regions", "-o", regions.to_str().unwrap()][..],
            &["--report", report.to_str().unwrap()],
            &fast,
        ]
        .concat(),
    );
    assert_eq!(
        dir_names(&regions),
        [
            "region_1_Left_kidney.ply",
            "region_2_a_b_c.ply",
            "region_3_肝臓_région.ply",
            "region_4_liver.ply",
            "region_5_liver.ply",
            "region_6.ply",
            "region_7.ply",
        ]
    );
    let r: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    insta::assert_snapshot!(serde_json::to_string_pretty(&r["labels"]).unwrap());

    let interfaces = dir.path().join("interfaces");
    run_ok(
        &[&["regularize", input, "--split", "interfaces", "-o", interfaces.to_str().unwrap()][..], &fast]
            .concat(),
    );
    assert_eq!(
        dir_names(&interfaces),
        [
            "interface_1_Left_kidney__0.ply",
            "interface_1_Left_kidney__2_a_b_c.ply",
            "interface_2_a_b_c__0.ply",
            "interface_2_a_b_c__3_肝臓_région.ply",
            "interface_3_肝臓_région__0.ply",
            "interface_3_肝臓_région__4_liver.ply",
            "interface_4_liver__0.ply",
            "interface_4_liver__5_liver.ply",
            "interface_5_liver__0.ply",
            "interface_5_liver__6.ply",
            "interface_6_0.ply",
            "interface_6_7.ply",
            "interface_7_0.ply",
        ]
    );
    // A file with no names has no `labels` in its report.
    let npy = dir.path().join("plain.npy");
    write_npy(&npy, &LabelVolume::from_fn([3, 3, 3], |p| u32::from(p == [1, 1, 1])));
    let plain = dir.path().join("plain.json");
    let mesh = dir.path().join("plain.ply");
    run_ok(
        &[
            &["regularize", npy.to_str().unwrap(), "-o", mesh.to_str().unwrap()][..],
            &["--report", plain.to_str().unwrap()],
            &fast,
        ]
        .concat(),
    );
    let r: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&plain).unwrap()).unwrap();
    assert!(r.get("labels").is_none(), "{r}");
}
