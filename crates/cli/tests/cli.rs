//! End-to-end tests of the `voxreg` binary.

use std::collections::HashMap;
use std::path::Path;

mod common;
use common::{data, regularize_ok, report_of, s, stderr, voxreg};

/// Parses the quads of an OBJ file.
fn obj_quads(path: &Path) -> (usize, Vec<[usize; 4]>, Vec<String>) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut vertices = 0;
    let mut quads = Vec::new();
    let mut groups = Vec::new();
    for line in text.lines() {
        let mut it = line.split_whitespace();
        match it.next() {
            Some("v") => vertices += 1,
            Some("g") => groups.push(it.next().unwrap().to_string()),
            Some("f") => {
                let idx: Vec<usize> = it.map(|t| t.parse().unwrap()).collect();
                quads.push([idx[0], idx[1], idx[2], idx[3]]);
            }
            _ => {}
        }
    }
    (vertices, quads, groups)
}

#[test]
fn info_snapshot() {
    let out = voxreg(&["info", data("cat10.vol").to_str().unwrap()]);
    assert!(out.status.success(), "{}", stderr(&out));
    let text = String::from_utf8(out.stdout).unwrap();
    // The path depends on the checkout: keep only the file name.
    let text = text.replace(data("cat10.vol").to_str().unwrap(), "cat10.vol");
    insta::assert_snapshot!(text);
}

#[test]
fn info_of_a_vox_model_groups_colours_into_one_solid() {
    let out = voxreg(&["info", data("chr_army1.vox").to_str().unwrap()]);
    assert!(out.status.success(), "{}", stderr(&out));
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(text.contains("dimensions: 8 x 7 x 12"), "{text}");
    assert!(text.contains("interfaces: 1"), "{text}");
    // Per-label regions on request: one interface per colour pair.
    let out = voxreg(&["info", data("chr_army1.vox").to_str().unwrap(), "--regions", "label"]);
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(!text.contains("interfaces: 1\n"), "{text}");
}

#[test]
fn regularize_writes_a_closed_quad_mesh_and_a_report() {
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("cat.obj");
    let report = dir.path().join("report.json");
    let out = regularize_ok(&data("cat10.vol"), &obj, &["--report", s(&report), "--quiet"]);
    assert!(stderr(&out).is_empty(), "--quiet printed: {}", stderr(&out));
    let r = report_of(&report);
    let (vertices, quads, groups) = obj_quads(&obj);
    assert_eq!(quads.len() as u64, r["counts"]["surfels"].as_u64().unwrap());
    assert_eq!(vertices as u64, r["counts"]["vertices"].as_u64().unwrap());
    assert_eq!(groups, vec!["interface_96_0"]);
    // Closed: every undirected edge is used by an even number of quads, and each
    // directed edge is matched by its reverse (consistent orientation).
    let mut directed: HashMap<(usize, usize), i32> = HashMap::new();
    for q in &quads {
        for i in 0..4 {
            let (a, b) = (q[i], q[(i + 1) % 4]);
            *directed.entry((a.min(b), a.max(b))).or_default() += if a < b { 1 } else { -1 };
        }
    }
    assert!(directed.values().all(|&c| c == 0));
    for key in ["surface", "normals", "assemble", "solve", "refine"] {
        assert!(r["stages"][key].as_f64().unwrap() >= 0.0, "stage {key}");
    }
    for key in ["read", "write"] {
        assert!(r["io"][key].as_f64().unwrap() >= 0.0, "stage {key}");
    }
    assert_eq!(r["solves"].as_array().unwrap().len(), 4, "the default preset refines three times");
    for term in ["attachment", "alignment", "fairness", "total"] {
        assert!(r["energy"]["before"][term].is_number() && r["energy"]["after"][term].is_number());
    }
    assert!(r["energy"]["after"]["total"].as_f64() < r["energy"]["before"]["total"].as_f64());
    // The automatic choice: exact factorization for small surfaces, else CG to 1e-3 voxel.
    let solve = last_solve(&r);
    match solve["solver"].as_str().unwrap() {
        "direct" => assert!(solve["relative_gradient"].as_f64().unwrap() <= 1e-9),
        kind => {
            assert_eq!(kind, "cg");
            assert_eq!(solve["converged"], true);
            assert!(solve["error_estimate"].as_f64().unwrap() <= 1e-3);
        }
    }
    assert!(r["counts"]["edges"].as_u64().unwrap() > 0 && r["counts"]["interfaces"] == 1);
    assert_eq!(r["counts"]["boundary_vertices"], 0);
}

#[test]
fn regularize_a_vox_model_to_ply() {
    let dir = tempfile::tempdir().unwrap();
    let ply = dir.path().join("army.ply");
    let out = regularize_ok(&data("chr_army1.vox"), &ply, &[]);
    let bytes = std::fs::read(&ply).unwrap();
    assert!(bytes.starts_with(b"ply\nformat binary_little_endian 1.0\n"));
    assert!(stderr(&out).contains("400 quads"), "{}", stderr(&out));
}

#[test]
fn threshold_makes_a_binary_volume() {
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("b.obj");
    regularize_ok(&data("bunny-32.vol"), &obj, &["--threshold", "0", "-q"]);
    let (_, _, groups) = obj_quads(&obj);
    assert_eq!(groups, vec!["interface_1_0"]);
}

#[test]
fn bad_input_is_a_clear_error_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let out_path = dir.path().join("out.obj");
    let out_str = out_path.to_str().unwrap();
    let cases: Vec<(Vec<String>, &str)> = vec![
        (
            vec!["regularize".into(), data("not_a.vox").display().to_string(), "-o".into(), out_str.into()],
            "not_a.vox",
        ),
        (vec!["regularize".into(), "missing.vol".into(), "-o".into(), out_str.into()], "missing.vol"),
        (
            vec!["regularize".into(), data("cat10.vol").display().to_string(), "-o".into(), "out.off".into()],
            "out.off",
        ),
        (
            vec![
                "regularize".into(),
                data("cat10.vol").display().to_string(),
                "-o".into(),
                out_str.into(),
                "--alpha".into(),
                "0".into(),
            ],
            "alpha",
        ),
        (
            vec![
                "regularize".into(),
                data("cat10.vol").display().to_string(),
                "-o".into(),
                out_str.into(),
                "--threshold".into(),
                "255".into(),
            ],
            "empty",
        ),
        (vec!["info".into(), data("not_a.vox").display().to_string()], "not_a.vox"),
    ];
    for (args, needle) in cases {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let out = voxreg(&args);
        assert!(!out.status.success(), "{args:?} succeeded");
        let err = stderr(&out);
        let last = err.lines().last().unwrap_or("");
        assert!(last.starts_with("error: ") && last.contains(needle), "{args:?}: {err}");
        assert!(!err.contains("panicked"), "{err}");
        assert!(!out_path.exists(), "{args:?} left an output file");
    }
    // Nothing at all was left in the output directory (no temporary files either).
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
}

#[test]
fn vox_to_coloured_gltf() {
    let dir = tempfile::tempdir().unwrap();
    let glb = dir.path().join("army.glb");
    regularize_ok(&data("chr_army1.vox"), &glb, &["-q"]);
    let bytes = std::fs::read(&glb).unwrap();
    assert_eq!(&bytes[..4], b"glTF");
    // The JSON chunk names one material per visible colour of the model.
    let json_len = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
    let json: serde_json::Value = serde_json::from_slice(&bytes[20..20 + json_len]).unwrap();
    assert_eq!(json["materials"].as_array().unwrap().len(), 7);
    assert_eq!(json["meshes"][0]["primitives"].as_array().unwrap().len(), 7);
}

#[test]
fn vox_scene_graphs_are_assembled() {
    // axes.vox: 4 models, 10 instances in nested groups; extended.vox: 6 models in layers.
    for (name, dims, components) in [
        ("axes.vox", "dimensions: 260 x 287 x 199", "components: 14 (14 closed)"),
        ("extended.vox", "dimensions: 120 x 86 x 40", "components: 6 (6 closed)"),
    ] {
        let out = voxreg(&["info", data(name).to_str().unwrap()]);
        assert!(out.status.success(), "{}", stderr(&out));
        let text = String::from_utf8(out.stdout).unwrap();
        assert!(text.contains(dims) && text.contains(components), "{name}: {text}");
    }
}

#[test]
fn regularize_with_each_normal_estimator_records_it_in_the_report() {
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("cat.obj");
    let report = dir.path().join("report.json");
    let input = data("cat10.vol");
    let run = |extra: &[&str]| {
        regularize_ok(&input, &obj, &[&["--report", s(&report), "-q"], extra].concat());
        report_of(&report)["normals"].clone()
    };
    // The default: integral invariant normals at the multigrid radius (3 at unit spacing).
    let p = run(&[]);
    assert_eq!((p["estimator"].as_str(), p["radius"].as_f64()), (Some("ii"), Some(3.0)));
    for (kind, radius) in
        [("ii", Some(4.5)), ("convolved", Some(2.0)), ("convolved", None), ("at", Some(3.5))]
    {
        let r = radius.map(|r: f64| r.to_string());
        let mut extra = vec!["--normals", kind];
        if let Some(r) = &r {
            extra.extend(["--radius", r.as_str()]);
        }
        let p = run(&extra);
        assert_eq!(p["estimator"], kind);
        assert_eq!(p["radius"].as_f64(), Some(radius.unwrap_or(3.0)), "{kind}");
    }
    let p = run(&["--normals", "trivial"]);
    assert_eq!((p["estimator"].as_str(), p["radius"].is_null()), (Some("trivial"), true));
    assert!(p["at"].is_null());
    // The AT sharpening stage: on by default, --sharpen 0 turns it off (its report counts
    // the stage's alternations).
    assert!(run(&["--normals", "at"])["at"]["sharpen_iterations"].as_u64().unwrap() > 0);
    assert_eq!(run(&["--normals", "at", "--sharpen", "0"])["at"]["sharpen_iterations"].as_u64(), Some(0));
    regularize_fails(
        &input,
        &obj,
        &["--normals", "at", "--sharpen-threshold=-1"],
        "--sharpen-threshold must be finite and positive",
    );

    regularize_fails(&input, &obj, &["--radius=0"], "--radius must be finite and positive");
    regularize_fails(&input, &obj, &["--normals", "pca"], "");
}

/// Checks that `voxreg regularize input -o obj extra...` fails with `message` in its
/// standard error.
fn regularize_fails(input: &Path, obj: &Path, extra: &[&str], message: &str) {
    let args = [&["regularize", s(input), "-o", s(obj)], extra].concat();
    let out = voxreg(&args);
    assert!(!out.status.success(), "voxreg {args:?} succeeded");
    assert!(stderr(&out).contains(message), "voxreg {args:?}: '{message}' not in {}", stderr(&out));
}

/// The `feature` values of a PLY written by `--features`, checking its header.
fn ply_features(path: &Path) -> Vec<f32> {
    let bytes = std::fs::read(path).unwrap();
    let end = b"end_header\n";
    let body = bytes.windows(end.len()).position(|w| w == end).unwrap() + end.len();
    let header = String::from_utf8(bytes[..body].to_vec()).unwrap();
    assert!(header.contains("property float feature\nproperty uchar red\n"), "{header}");
    let count: usize =
        header.lines().find_map(|l| l.strip_prefix("element vertex ")).unwrap().parse().unwrap();
    (0..count)
        .map(|i| {
            let o = body + 19 * i + 12;
            f32::from_le_bytes(bytes[o..o + 4].try_into().unwrap())
        })
        .collect()
}

#[test]
fn features_writes_the_at_feature_field() {
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("cat.obj");
    let ply = dir.path().join("features.ply");
    let input = data("cat10.vol");
    let f = s(&ply);
    regularize_ok(&input, &obj, &["-q", "--normals", "at", "--features", f]);
    let (vertices, _, _) = obj_quads(&obj);
    let v = ply_features(&ply);
    assert_eq!(v.len(), vertices);
    // Low along the cat's sharp features (ears, paws), about 1 on its smooth parts.
    assert!(v.iter().all(|x| x.is_finite() && *x < 1.0 + 1e-6));
    let low = v.iter().filter(|&&x| x < 0.5).count();
    let high = v.iter().filter(|&&x| x > 0.8).count();
    assert!(low > 0 && high > v.len() / 2, "{low} low, {high} high of {}", v.len());

    // Only AT has a feature field, and it is written as PLY only: clear errors, no files.
    std::fs::remove_file(&ply).unwrap();
    for (extra, message) in [
        (vec!["--features", f], "--features"),
        (vec!["--normals", "ii", "--features", f], "only --normals at has a feature field"),
        (vec!["--normals", "at", "--features", "features.obj"], "expected .ply"),
    ] {
        let other = dir.path().join("other.obj");
        regularize_fails(&input, &other, &[&["-q"], &extra[..]].concat(), message);
        assert!(!ply.exists() && !other.exists());
    }
}

/// Vertex positions of an OBJ file.
fn obj_positions(path: &Path) -> Vec<[f64; 3]> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .filter_map(|l| l.strip_prefix("v "))
        .map(|l| {
            let c: Vec<f64> = l.split_whitespace().map(|t| t.parse().unwrap()).collect();
            [c[0], c[1], c[2]]
        })
        .collect()
}

#[test]
fn every_solver_reaches_the_same_surface_and_reports_itself() {
    let dir = tempfile::tempdir().unwrap();
    let input = data("cat10.vol");
    let run = |solver: &str, extra: &[&str]| {
        let obj = dir.path().join(format!("{solver}.obj"));
        let report = dir.path().join(format!("{solver}.json"));
        regularize_ok(
            &input,
            &obj,
            &[&["--report", s(&report), "--quiet", "--solver", solver], extra].concat(),
        );
        (obj_positions(&obj), report_of(&report))
    };
    let (exact, r) = run("direct", &[]);
    assert_eq!(last_solve(&r)["solver"], "direct");
    for (solver, kind) in [("cg", "cg"), ("bounded", "bounded"), ("gd", "bounded")] {
        let (x, r) = run(solver, &["--tolerance", "1e-4"]);
        let r = last_solve(&r);
        assert_eq!(r["solver"], kind);
        assert_eq!(r["converged"], true);
        assert_eq!(r["preconditioner"], "multigrid");
        assert!(r["iterations"].as_u64().unwrap() > 0);
        assert!(r["error_estimate"].as_f64().unwrap() <= 1e-4);
        let err = x
            .iter()
            .zip(&exact)
            .map(|(a, b)| (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f64>().sqrt())
            .fold(0.0, f64::max);
        assert!(err < 1e-4, "{solver}: {err}");
    }
}

/// `--preset fast` resolves through the library's presets: diffused normals, then one
/// batch of sweeps (the report names the solver and its sweeps), no integral invariants.
#[test]
fn the_fast_preset_runs_its_sweeps() {
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("fast.obj");
    let report = dir.path().join("fast.json");
    regularize_ok(&data("cat10.vol"), &obj, &["--report", s(&report), "--preset", "fast", "--quiet"]);
    let r = report_of(&report);
    let solves = r["solves"].as_array().unwrap();
    assert_eq!(solves.len(), 1);
    assert!(solves.iter().all(|s| s["solver"] == "sweeps" && s["iterations"] == 20), "{solves:?}");
    assert_eq!(r["normals"]["estimator"], "diffused");
    assert_eq!(r["normals"]["radius"], 8.0);
    assert_eq!(r["params"]["solver"]["choice"], "sweeps");
    assert_eq!(obj_positions(&obj).len(), r["counts"]["vertices"].as_u64().unwrap() as usize);
}

#[test]
fn clamped_output_stays_in_cubes_and_passes_the_check() {
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("clamped.obj");
    let report = dir.path().join("clamped.json");
    let free = dir.path().join("free.obj");
    let input = data("cat10.vol");
    regularize_ok(&input, &obj, &["--report", s(&report), "--clamp", "--alpha", "1e-4", "--quiet"]);
    let r = report_of(&report);
    let r = last_solve(&r);
    assert_eq!(r["solver"], "bounded");
    assert_eq!(r["clamp"], 0.01);
    assert!(r["clamped_vertices"].as_u64().is_some());
    // Against the staircase (the regularization with an overwhelming attachment).
    regularize_ok(&input, &free, &["--alpha", "1e9", "--quiet"]);
    for (a, b) in obj_positions(&obj).iter().zip(&obj_positions(&free)) {
        for k in 0..3 {
            assert!((a[k] - b[k]).abs() <= 0.495 + 1e-6, "{a:?} left the cube of {b:?}");
        }
    }
    let out = voxreg(&["check", obj.to_str().unwrap()]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(String::from_utf8_lossy(&out.stdout).contains(" 0 self-intersecting face pairs"));
    // Clamping needs the descent.
    regularize_fails(&input, &obj, &["--clamp", "--solver", "cg"], "--clamp needs the bounded solver");
}

/// `voxreg check` on the OBJ file `obj`, which must fail: its standard output and error.
fn check_fails(obj: &str) -> (String, String) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("mesh.obj");
    std::fs::write(&path, obj).unwrap();
    let out = voxreg(&["check", path.to_str().unwrap()]);
    assert!(!out.status.success());
    (String::from_utf8_lossy(&out.stdout).into_owned(), stderr(&out))
}

#[test]
fn check_reports_folds_and_fails() {
    // Two unit squares sharing the edge x = 1, the second folded back over the first.
    let (text, err) =
        check_fails("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0.2 0 0.05\nv 0.2 1 0.05\nf 1 2 3 4\nf 2 5 6 3\n");
    assert!(
        text.contains("0 self-intersecting face pairs, 0 folded quads, 1 folded adjacent pairs"),
        "{text}"
    );
    assert!(err.contains("1 folded adjacent pairs"), "{err}");
}

#[test]
fn check_reports_self_intersections_and_fails() {
    // Two unit squares crossing each other, sharing no vertex.
    let (text, err) = check_fails(
        "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0.5 0.5 -1\nv 0.6 0.5 -1\nv 0.6 0.5 1\nv 0.5 0.5 1\nf 1 2 3 4\nf 5 6 7 8\n",
    );
    assert!(text.contains("2 faces, 1 self-intersecting face pairs"), "{text}");
    assert!(err.contains("1 self-intersections (first: faces 0 and 1)"), "{err}");
    let dir = tempfile::tempdir().unwrap();
    let out = voxreg(&["check", dir.path().join("missing.obj").to_str().unwrap()]);
    assert!(!out.status.success());
}

/// The report of the last solve in a `--report` JSON.
fn last_solve(r: &serde_json::Value) -> &serde_json::Value {
    r["solves"].as_array().unwrap().last().unwrap()
}

#[test]
fn view_refuses_bad_input_before_listening() {
    let missing = data("no-such-file.vox");
    let out = voxreg(&["view", missing.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(1));
    let err = stderr(&out);
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(err.starts_with("error: ") && err.contains("no-such-file.vox"), "{err}");
    let out = voxreg(&["view", data("axes.vox").to_str().unwrap(), "--clamp", "2"]);
    assert_eq!(out.status.code(), Some(1));
    assert!(stderr(&out).contains("--clamp must be a margin in (0, 1) voxel"), "{}", stderr(&out));
}

/// One request to the viewer (`Connection: close`): the status and the body.
fn http(addr: &str, method: &str, path: &str, body: &[u8]) -> (u16, String) {
    use std::io::{Read, Write};
    let mut s = std::net::TcpStream::connect(addr).unwrap();
    let head = format!(
        "{method} {path} HTTP/1.1\r\nHost: {addr}\r\nContent-Length: {}\r\nConnection: close\r\n\r\n",
        body.len()
    );
    s.write_all(head.as_bytes()).unwrap();
    s.write_all(body).unwrap();
    let mut out = String::new();
    s.read_to_string(&mut out).unwrap();
    let status = out[9..12].parse().unwrap();
    (status, out.split_once("\r\n\r\n").unwrap().1.to_string())
}

#[test]
fn view_serves_the_input_and_reads_dropped_files_with_the_options() {
    use std::io::{BufRead, BufReader};
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_voxreg"))
        .args(["view", data("axes.vox").to_str().unwrap(), "--gamma", "0.5"])
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut line = String::new();
    BufReader::new(child.stderr.take().unwrap()).read_line(&mut line).unwrap();
    let result = std::panic::catch_unwind(|| {
        let url = line.trim().strip_prefix("voxreg view: ").unwrap().split_whitespace().next().unwrap();
        // The address carries the session's token, which every API request needs.
        let (addr, token) = url.trim_start_matches("http://").split_once("/?token=").unwrap();
        assert!(addr.starts_with("127.0.0.1:"), "{line}");
        assert_eq!(token.len(), 32, "{line}");
        assert_eq!(http(addr, "GET", "/api/state", b"").0, 403);
        let api = |path: &str| format!("{path}{}token={token}", if path.contains('?') { '&' } else { '?' });
        let t = std::time::Instant::now();
        let state = loop {
            let state: serde_json::Value =
                serde_json::from_str(&http(addr, "GET", &api("/api/state"), b"").1).unwrap();
            if state["final"] == true {
                break state;
            }
            assert!(t.elapsed().as_secs() < 60, "{state}");
            std::thread::sleep(std::time::Duration::from_millis(20));
        };
        assert_eq!(state["name"], "axes.vox");
        assert_eq!(state["tuning"]["preset"], "voxel-art");
        assert_eq!(state["tuning"]["gamma"], 0.5);
        // A corrupt drop: the reader's one-line message, naming the dropped file only.
        let (status, body) = http(addr, "POST", &api("/api/open?name=bad.vox"), b"VOX 1234");
        assert_eq!(status, 400, "{body}");
        let message: serde_json::Value = serde_json::from_str(&body).unwrap();
        let message = message["error"].as_str().unwrap();
        assert!(message.starts_with("bad.vox"), "{message}");
        assert!(!message.contains("/tmp"), "{message}");
        // A dropped detached header is read from memory: the file it names is not read.
        let header = format!(
            "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 2 2\nencoding: raw\ndata file: {}\n\n",
            data("cat10.vol").display()
        );
        let (status, body) = http(addr, "POST", &api("/api/open?name=a.nhdr"), header.as_bytes());
        assert_eq!(status, 400, "{body}");
        assert!(body.contains("a.nhdr") && body.contains("detached"), "{body}");
    });
    child.kill().unwrap();
    child.wait().unwrap();
    result.unwrap();
}

/// The per-vertex `distance` values and vertex positions of a `voxreg geodesic` PLY.
fn ply_distances(path: &Path) -> (Vec<f32>, Vec<[f32; 3]>) {
    let bytes = std::fs::read(path).unwrap();
    let end = b"end_header\n";
    let body = bytes.windows(end.len()).position(|w| w == end).unwrap() + end.len();
    let header = String::from_utf8(bytes[..body].to_vec()).unwrap();
    assert!(header.contains("property float distance\nproperty uchar red\n"), "{header}");
    let count: usize =
        header.lines().find_map(|l| l.strip_prefix("element vertex ")).unwrap().parse().unwrap();
    let float = |o: usize| f32::from_le_bytes(bytes[o..o + 4].try_into().unwrap());
    (0..count)
        .map(|i| {
            let o = body + 19 * i;
            (float(o + 12), [float(o), float(o + 4), float(o + 8)])
        })
        .unzip()
}

#[test]
fn geodesic_writes_distances_on_the_proxy_and_the_digital_surface() {
    let dir = tempfile::tempdir().unwrap();
    let input = data("cat10.vol");
    let i = input.to_str().unwrap();
    let run = |name: &str, extra: &[&str]| {
        let path = dir.path().join(name);
        let mut args = vec!["geodesic", i, "--from", "0,0,0", "-o", path.to_str().unwrap(), "-q"];
        args.extend(extra);
        let out = voxreg(&args);
        assert!(out.status.success(), "{}", stderr(&out));
        ply_distances(&path)
    };
    let (exact, proxy) = run("exact.ply", &[]);
    let (heat, _) = run("heat.ply", &["--method", "heat"]);
    let (on_digital, digital) = run("on-digital.ply", &["--on", "digital"]);
    let (staircase, _) = run("digital.ply", &["--metric", "digital", "--on", "digital"]);
    // The source is the surface point nearest the origin (on a face, or a vertex at
    // distance 0): within a voxel of a vertex; the same distances on either mesh, whose
    // vertices differ; heat within a few percent of exact; the staircase metric longer.
    let least = exact.iter().copied().fold(f32::INFINITY, f32::min);
    assert!(exact.iter().filter(|&&d| d == 0.0).count() <= 1 && least < 1.0, "least {least}");
    assert!(exact.iter().all(|&d| d >= 0.0));
    assert_eq!(exact, on_digital);
    assert_ne!(proxy, digital);
    let far: Vec<usize> = (0..exact.len()).filter(|&v| exact[v] > 3.0).collect();
    let rel =
        |a: &[f32]| far.iter().map(|&v| (a[v] - exact[v]).abs() / exact[v]).sum::<f32>() / far.len() as f32;
    assert!(rel(&heat) < 0.05, "heat {}", rel(&heat));
    let longer = far.iter().filter(|&&v| staircase[v] > exact[v]).count();
    assert!(longer > far.len() / 2, "{longer} of {}", far.len());

    for (args, message) in [
        (vec!["geodesic", i, "-o", "x.ply"], "--from"),
        (vec!["geodesic", i, "--from", "0,0", "-o", "x.ply"], "three coordinates"),
        (vec!["geodesic", i, "--from", "0,0,0", "-o", "x.obj"], "expected .ply"),
    ] {
        let out = voxreg(&args);
        assert!(!out.status.success());
        assert!(stderr(&out).contains(message), "{}", stderr(&out));
    }
}

/// The input volume goes back before the solves (the run's peak): the same sphere in a
/// volume 19 MiB larger (as `u32` labels) peaks within half that of the cropped one.
#[test]
#[cfg(target_os = "linux")]
fn the_input_volume_is_not_held_through_the_solves() {
    const R: f64 = 73.0;
    let dir = tempfile::tempdir().unwrap();
    let sphere = |n: usize| {
        let c = 75.0;
        let path = dir.path().join(format!("sphere{n}.npy"));
        let labels = (0..n * n * n).map(|i| {
            let (x, y, z) = (i / (n * n), i / n % n, i % n);
            let d2 = [x, y, z].iter().map(|&v| (v as f64 - c).powi(2)).sum::<f64>();
            u8::from(d2 <= R * R)
        });
        std::fs::write(&path, voxreg_testkit::npy_bytes("|u1", [n, n, n], labels)).unwrap();
        path
    };
    let peak = |input: &Path| {
        let report = dir.path().join("report.json");
        regularize_ok(input, &dir.path().join("out.ply"), &["-q", "--report", s(&report)]);
        let r = report_of(&report);
        (r["peak_memory"].as_u64().expect("a peak on Linux"), r["counts"]["surfels"].as_u64().unwrap())
    };
    let (cropped, surfels) = peak(&sphere(152));
    let (padded, padded_surfels) = peak(&sphere(203));
    assert_eq!(surfels, padded_surfels);
    let more = (203u64.pow(3) - 152u64.pow(3)) * 4;
    assert!(
        padded < cropped + more / 2,
        "peak {padded} bytes padded against {cropped} cropped: the input volume is held"
    );
}
