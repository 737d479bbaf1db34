//! End-to-end tests of `voxreg regularize --simplify`, `--max-error` and `--lod`.

use std::collections::HashMap;
use std::path::Path;

mod common;
use common::{data, stderr, validate_gltf, voxreg};

/// Faces of a mesh file, and whether every edge is used an even number of times.
fn faces_and_closed(path: &Path) -> (usize, bool) {
    let mesh = voxreg_io::read_mesh(path).unwrap();
    let mut edges: HashMap<(u32, u32), usize> = HashMap::new();
    for q in &mesh.quads {
        let p: Vec<u32> = (0..4).filter(|&i| q[i] != q[(i + 3) % 4]).map(|i| q[i]).collect();
        for i in 0..p.len() {
            let (a, b) = (p[i], p[(i + 1) % p.len()]);
            *edges.entry((a.min(b), a.max(b))).or_default() += 1;
        }
    }
    (mesh.quads.len(), edges.values().all(|c| c % 2 == 0))
}

fn regularize(input: &str, out: &Path, extra: &[&str]) -> std::process::Output {
    let mut args = vec!["regularize", input, "-o", out.to_str().unwrap(), "--quiet"];
    args.extend_from_slice(extra);
    voxreg(&args)
}

#[test]
fn simplify_writes_a_closed_mesh_with_fewer_faces() {
    let dir = tempfile::tempdir().unwrap();
    let input = data("cat10.vol");
    let full = dir.path().join("full.ply");
    let small = dir.path().join("small.ply");
    let o = regularize(input.to_str().unwrap(), &full, &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = regularize(input.to_str().unwrap(), &small, &["--simplify", "0.2", "--max-error", "0.5"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let (n_full, closed_full) = faces_and_closed(&full);
    let (n_small, closed_small) = faces_and_closed(&small);
    assert!(closed_full && closed_small);
    assert!(n_small * 2 < n_full, "{n_small} faces of {n_full}");
}

#[test]
fn simplify_lod_writes_nested_levels() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("cat.obj");
    let o = regularize(data("cat10.vol").to_str().unwrap(), &out, &["--lod", "3"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(!out.exists(), "the levels replace the single file");
    let counts: Vec<usize> = (0..3)
        .map(|k| {
            let (n, closed) = faces_and_closed(&dir.path().join(format!("cat.lod{k}.obj")));
            assert!(closed, "level {k} open");
            n
        })
        .collect();
    assert!(counts[1] < counts[0] && counts[2] < counts[1], "{counts:?}");
}

#[test]
fn simplify_refuses_bad_options_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("x.ply");
    let input = data("cat10.vol");
    for extra in [
        &["--simplify", "0"][..],
        &["--simplify", "1.5"],
        &["--max-error", "-1"],
        &["--lod", "0"],
        &["--lod", "3", "--simplify", "0.5"],
        &["--simplify", "0.5", "--split", "regions"],
    ] {
        let o = regularize(input.to_str().unwrap(), &out, extra);
        assert_eq!(o.status.code(), Some(1), "{extra:?}");
        let err = stderr(&o);
        assert_eq!(err.trim().lines().count(), 1, "{extra:?}: {err}");
        assert!(!out.exists());
    }
}

/// Triangles of a .glb file (the index accessors' counts over three).
fn glb_triangles(path: &Path) -> u64 {
    let bytes = std::fs::read(path).unwrap();
    assert_eq!(&bytes[..4], b"glTF");
    let json_len = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
    let json: serde_json::Value = serde_json::from_slice(&bytes[20..20 + json_len]).unwrap();
    let accessors = json["accessors"].as_array().unwrap();
    json["meshes"]
        .as_array()
        .unwrap()
        .iter()
        .flat_map(|m| m["primitives"].as_array().unwrap())
        .map(|p| accessors[p["indices"].as_u64().unwrap() as usize]["count"].as_u64().unwrap() / 3)
        .sum()
}

#[test]
fn every_gltf_level_passes_the_khronos_validator() {
    let dir = tempfile::tempdir().unwrap();
    let mut files = Vec::new();
    for (name, stem) in [("cat10.vol", "cat"), ("chr_army1.vox", "army")] {
        let out = dir.path().join(format!("{stem}.glb"));
        let o = regularize(data(name).to_str().unwrap(), &out, &["--lod", "3"]);
        assert!(o.status.success(), "{name}: {}", stderr(&o));
        let levels: Vec<_> = (0..3).map(|k| dir.path().join(format!("{stem}.lod{k}.glb"))).collect();
        let triangles: Vec<u64> = levels.iter().map(|p| glb_triangles(p)).collect();
        assert!(triangles[0] > triangles[1] && triangles[1] > triangles[2], "{name}: {triangles:?}");
        files.extend(levels);
    }
    if let Some(report) = validate_gltf(&files) {
        assert_eq!(report.lines().filter(|l| l.contains(": 0 errors")).count(), files.len(), "{report}");
        // Not even a warning: no degenerate triangle from the triangles among the quads.
        assert_eq!(report.lines().filter(|l| l.contains(", 0 warnings")).count(), files.len(), "{report}");
    }
}

/// Ctrl-C during the simplification of `--lod` (after the solves, before any level is
/// written) exits with 130 and leaves nothing: the signal thread removes the staged
/// outputs and ends the process, the simplification with it.
#[cfg(unix)]
#[test]
fn sigint_during_the_levels_leaves_nothing() {
    use std::io::BufRead;

    let dir = tempfile::tempdir().unwrap();
    let out_dir = dir.path().join("out");
    std::fs::create_dir(&out_dir).unwrap();
    let input = data("bunny-64.vol");
    let out = out_dir.join("b.obj");
    let report = out_dir.join("r.json");
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_voxreg"))
        .args([
            "regularize",
            common::s(&input),
            "-o",
            common::s(&out),
            "--lod",
            "4",
            "--report",
            common::s(&report),
        ])
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // The solver's summary comes once the solves are over; the levels (seconds on
    // bunny-64) follow.
    let mut lines = std::io::BufReader::new(child.stderr.take().unwrap()).lines();
    let mut seen = String::new();
    for line in lines.by_ref() {
        let line = line.unwrap();
        seen.push_str(&line);
        seen.push('\n');
        if line.starts_with("cg converged") {
            break;
        }
    }
    assert!(seen.contains("cg converged"), "{seen}");
    std::thread::sleep(std::time::Duration::from_millis(300));
    let killed = std::process::Command::new("kill").args(["-INT", &child.id().to_string()]).status().unwrap();
    assert!(killed.success());
    assert_eq!(common::wait_code(&mut child, 20), Some(130), "{seen}");
    let rest: Vec<String> = lines.map_while(Result::ok).collect();
    assert!(
        !rest.iter().any(|l| l.starts_with("write mesh")),
        "the levels were written before the signal: {rest:?}"
    );
    assert!(rest.iter().any(|l| l.contains("interrupted by SIGINT")), "{rest:?}");
    let left: Vec<_> = std::fs::read_dir(&out_dir).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert!(left.is_empty(), "SIGINT left {left:?}");
}

/// The four-level pyramid's run peaks within twice the plain run's (the simplifier's
/// queue, quadrics and grid, and the level being paired, beside the mesh the writers
/// read; the regularizer's state is let go before).
#[cfg(target_os = "linux")]
#[test]
fn the_levels_stay_within_twice_the_plain_runs_peak() {
    let dir = tempfile::tempdir().unwrap();
    let input = data("bunny-128.vol");
    let peak = |extra: &[&str]| {
        let report = dir.path().join("report.json");
        let mut args = vec!["--report", report.to_str().unwrap()];
        args.extend_from_slice(extra);
        let o = regularize(input.to_str().unwrap(), &dir.path().join("out.glb"), &args);
        assert!(o.status.success(), "{}", stderr(&o));
        common::report_of(&report)["peak_memory"].as_u64().expect("a peak on Linux")
    };
    let plain = peak(&[]);
    let levels = peak(&["--lod", "4"]);
    assert!(levels <= 2 * plain, "peak {levels} bytes with four levels against {plain} without");
}
