//! Outputs through the `voxreg` binary: only regular files or new paths are written,
//! never a file the input reads, every output of a run committed together or none,
//! names checked before any work, temporaries owned through a lock, and every
//! interruption cleaned up.

use std::path::{Path, PathBuf};
use std::process::Command;

mod common;
#[cfg(unix)]
use common::wait_code;
use common::{data, one_error, s, stderr, voxreg};
use voxreg_testkit::dir_names;

/// Runs `voxreg args`, expects exit 1 and one error line holding every one of `needles`.
fn refused(args: &[&str], needles: &[&str]) -> String {
    one_error(args, &voxreg(args), needles)
}

/// A `.vol` that no reader takes: a run that gets past the output checks fails on it, so
/// a refusal that names the output proves the check came first, and no output is touched
/// even by a build without the checks.
fn unreadable(dir: &Path, name: &str) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, b"not a volume").unwrap();
    path
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        if e.file_type().unwrap().is_dir() {
            copy_dir(&e.path(), &to.join(e.file_name()));
        } else {
            std::fs::copy(e.path(), to.join(e.file_name())).unwrap();
        }
    }
}

#[cfg(unix)]
#[test]
fn device_nodes_are_refused_as_outputs_whatever_the_permissions() {
    use std::os::unix::fs::FileTypeExt;
    let dir = tempfile::tempdir().unwrap();
    let bad = unreadable(dir.path(), "bad.vol");
    let mesh = dir.path().join("m.ply");
    for device in ["/dev/null", "/dev/full"] {
        if !Path::new(device).exists() {
            continue;
        }
        refused(&["regularize", s(&bad), "-o", s(&mesh), "--report", device], &[device, "a device"]);
        assert!(std::fs::metadata(device).unwrap().file_type().is_char_device(), "{device} replaced");
    }
    if std::fs::symlink_metadata("/dev/stdout").is_ok_and(|m| m.file_type().is_symlink()) {
        refused(
            &["regularize", s(&bad), "-o", s(&mesh), "--report", "/dev/stdout"],
            &["/dev/stdout", "symbolic link"],
        );
    }
    assert_eq!(dir_names(dir.path()), ["bad.vol"]);
}

#[cfg(unix)]
#[test]
fn fifos_sockets_and_symbolic_links_are_refused_as_outputs() {
    use std::os::unix::fs::FileTypeExt;
    let dir = tempfile::tempdir().unwrap();
    let cat = data("cat10.vol");
    let fifo = dir.path().join("f.obj");
    assert!(Command::new("mkfifo").arg(&fifo).status().unwrap().success());
    refused(&["regularize", s(&cat), "-o", s(&fifo), "-q"], &["f.obj", "a FIFO, not a regular file"]);
    assert!(std::fs::symlink_metadata(&fifo).unwrap().file_type().is_fifo());

    let socket = dir.path().join("s.json");
    let _listener = std::os::unix::net::UnixListener::bind(&socket).unwrap();
    refused(
        &["regularize", s(&cat), "-o", s(&dir.path().join("m.ply")), "--report", s(&socket), "-q"],
        &["s.json", "a socket"],
    );
    assert!(std::fs::symlink_metadata(&socket).unwrap().file_type().is_socket());

    // A symbolic link is refused, not replaced by a file nor written through.
    let target = dir.path().join("target.obj");
    std::fs::write(&target, b"kept").unwrap();
    let link = dir.path().join("link.obj");
    std::os::unix::fs::symlink(&target, &link).unwrap();
    refused(&["regularize", s(&cat), "-o", s(&link), "-q"], &["link.obj", "symbolic link"]);
    assert!(std::fs::symlink_metadata(&link).unwrap().file_type().is_symlink());
    assert_eq!(std::fs::read(&target).unwrap(), b"kept");
    assert_eq!(dir_names(dir.path()), ["f.obj", "link.obj", "s.json", "target.obj"]);
}

#[test]
fn files_the_input_reads_are_never_outputs() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("m.ply");
    // A detached header's data file.
    let nhdr = dir.path().join("detached.nhdr");
    let raw = dir.path().join("detached.raw");
    std::fs::copy(data("formats/detached.nhdr"), &nhdr).unwrap();
    std::fs::copy(data("formats/detached.raw"), &raw).unwrap();
    let before = std::fs::read(&raw).unwrap();
    refused(
        &["regularize", s(&nhdr), "-o", s(&out), "--report", s(&raw), "-q"],
        &["detached.raw: --report would overwrite", "which the input reads"],
    );
    assert_eq!(std::fs::read(&raw).unwrap(), before);
    // A slice of a directory of TIFF slices.
    let slices = dir.path().join("slices");
    copy_dir(&data("formats/slices"), &slices);
    let slice = slices.join("slice_000.tif");
    let before = std::fs::read(&slice).unwrap();
    refused(
        &["regularize", s(&slices), "-o", s(&out), "--report", s(&slice), "-q"],
        &["slice_000.tif", "which the input reads"],
    );
    assert_eq!(std::fs::read(&slice).unwrap(), before);
    // Anything inside a Zarr store.
    let store = dir.path().join("labels_v3.zarr");
    copy_dir(&data("formats/labels_v3.zarr"), &store);
    let meta = store.join("zarr.json");
    let before = std::fs::read(&meta).unwrap();
    refused(
        &["regularize", s(&store), "-o", s(&out), "--report", s(&meta), "-q"],
        &["zarr.json", "lies inside"],
    );
    assert_eq!(std::fs::read(&meta).unwrap(), before);
    assert!(!out.exists());
}

#[test]
fn the_material_library_of_an_obj_is_no_other_output() {
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("a.obj");
    refused(
        &["regularize", s(&data("axes.vox")), "-o", s(&obj), "--report", s(&dir.path().join("a.mtl")), "-q"],
        &["a.mtl: the material library of -o and --report name the same file"],
    );
    assert!(dir_names(dir.path()).is_empty());
}

#[test]
fn names_are_checked_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    // Coloured input (voxel art): its OBJ's material library cannot hold a space.
    let bad_vox = unreadable(dir.path(), "bad.vox");
    refused(&["regularize", s(&bad_vox), "-o", s(&dir.path().join("my mesh.obj"))], &["holds whitespace"]);
    let bad = unreadable(dir.path(), "bad.vol");
    let long = dir.path().join(format!("{}.ply", "a".repeat(296)));
    refused(&["regularize", s(&bad), "-o", s(&long)], &["300 bytes long, over the 255"]);
    let slash = format!("{}/", s(&dir.path().join("out.ply")));
    refused(&["regularize", s(&bad), "-o", &slash], &["out.ply/: -o names a directory, not a file"]);
    refused(
        &[
            "regularize",
            s(&bad),
            "-o",
            s(&dir.path().join("m.ply")),
            "--report",
            &format!("{}/", s(&dir.path().join("r.json"))),
        ],
        &["--report names a directory"],
    );
    assert_eq!(dir_names(dir.path()), ["bad.vol", "bad.vox"]);
}

#[test]
fn a_material_library_in_the_way_stops_the_run_before_the_mesh_is_written() {
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("m.obj");
    std::fs::create_dir(dir.path().join("m.mtl")).unwrap();
    refused(&["regularize", s(&data("axes.vox")), "-o", s(&obj), "-q"], &["m.mtl", "names a directory"]);
    assert_eq!(dir_names(dir.path()), ["m.mtl"]);
}

/// `voxreg args` under a file size limit of `kib` KiB (bash's `ulimit -f`).
#[cfg(unix)]
fn under_file_size_limit(kib: u64, args: &[&str]) -> std::process::Output {
    Command::new("bash")
        .arg("-c")
        .arg(format!("ulimit -f {kib} && exec \"$0\" \"$@\""))
        .arg(env!("CARGO_BIN_EXE_voxreg"))
        .args(args)
        .output()
        .unwrap()
}

#[cfg(unix)]
#[test]
fn outputs_are_committed_together_or_not_at_all() {
    let dir = tempfile::tempdir().unwrap();
    let input = data("cat10.vol");
    let (mesh, features, report) =
        (dir.path().join("m.ply"), dir.path().join("f.ply"), dir.path().join("r.json"));
    let args = |m: &Path, f: &Path, r: &Path| -> Vec<String> {
        ["regularize", s(&input), "-o", s(m), "--normals", "at", "--features", s(f), "--report", s(r), "-q"]
            .map(String::from)
            .to_vec()
    };
    // Sizes of a complete run: the feature field's PLY is larger than the mesh's.
    let full = tempfile::tempdir().unwrap();
    let (m, f, r) = (full.path().join("m.ply"), full.path().join("f.ply"), full.path().join("r.json"));
    let a = args(&m, &f, &r);
    let ok = voxreg(&a.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(ok.status.success(), "{}", stderr(&ok));
    let size = |p: &Path| std::fs::metadata(p).unwrap().len();
    let limit = size(&m).max(size(&r)) / 1024 + 1;
    assert!(size(&f) > limit * 1024, "the feature field fits the limit: {} {}", size(&f), size(&m));
    // Old files in place: a failed run leaves them as they were.
    for p in [&mesh, &features, &report] {
        std::fs::write(p, b"old").unwrap();
    }
    let a = args(&mesh, &features, &report);
    let out = under_file_size_limit(limit, &a.iter().map(String::as_str).collect::<Vec<_>>());
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    assert!(stderr(&out).contains("f.ply"), "{}", stderr(&out));
    for p in [&mesh, &features, &report] {
        assert!(std::fs::read(p).unwrap() == b"old", "{} changed", p.display());
    }
    assert_eq!(dir_names(dir.path()), ["f.ply", "m.ply", "r.json"], "temporaries left");
}

#[cfg(unix)]
#[test]
fn temporaries_are_removed_only_when_no_live_run_holds_them() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // Another run, in another pid namespace or on another host: its process id is not
    // visible here, but its lock is.
    let live = d.join(".voxreg-999999999.00000000000000aa-live.tmp");
    let _held = voxreg_io::inflight::create_locked(&live).unwrap();
    let live_dir = d.join(".voxreg-999999999.00000000000000aa-stage");
    std::fs::create_dir(&live_dir).unwrap();
    let _held_dir = voxreg_io::inflight::create_locked(&live_dir.join(".voxreg-lock")).unwrap();
    std::fs::write(live_dir.join("part.ply"), b"being written").unwrap();
    // An entry named as older versions name theirs: no lock says whether it is in use.
    let unknown = d.join(".voxreg-999999999-a1b2.tmp");
    std::fs::write(&unknown, b"unknown owner").unwrap();
    // Left by a killed run: nothing holds their locks.
    let dead = d.join(".voxreg-999999999.00000000000000bb-dead.tmp");
    std::fs::write(&dead, b"partial").unwrap();
    let dead_dir = d.join(".voxreg-999999999.00000000000000bb-stage");
    std::fs::create_dir(&dead_dir).unwrap();
    std::fs::write(dead_dir.join(".voxreg-lock"), b"").unwrap();
    std::fs::write(dead_dir.join("part.ply"), b"partial").unwrap();

    let out = d.join("cube.ply");
    let run = voxreg(&["regularize", s(&data("bunny-32.vol")), "-o", s(&out), "-q"]);
    assert!(run.status.success(), "{}", stderr(&run));
    assert!(out.exists());
    assert!(live.exists() && live_dir.join("part.ply").exists(), "a live run's entries removed");
    assert!(unknown.exists(), "an entry of unknown owner removed");
    assert!(!dead.exists() && !dead_dir.exists(), "a killed run's entries kept");
}

#[cfg(unix)]
#[test]
fn sigquit_and_sighup_exit_with_nothing_left_behind() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("bunny.vol");
    std::fs::copy(data("bunny-128.vol"), &input).unwrap();
    for (signal, code) in [("QUIT", 131), ("HUP", 129)] {
        let out_dir = dir.path().join(format!("out-{signal}"));
        std::fs::create_dir(&out_dir).unwrap();
        let mut child = Command::new(env!("CARGO_BIN_EXE_voxreg"))
            .args([
                "regularize",
                s(&input),
                "-o",
                s(&out_dir.join("new/parts")),
                "--split",
                "regions",
                "--report",
                s(&out_dir.join("r.json")),
                "-q",
            ])
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        std::thread::sleep(std::time::Duration::from_millis(300));
        let killed =
            Command::new("kill").args([format!("-{signal}"), child.id().to_string()]).status().unwrap();
        assert!(killed.success());
        assert_eq!(wait_code(&mut child, 20), Some(code), "SIG{signal}");
        let mut err = String::new();
        std::io::Read::read_to_string(&mut child.stderr.take().unwrap(), &mut err).unwrap();
        assert!(err.contains(&format!("interrupted by SIG{signal}")), "{err}");
        assert!(dir_names(&out_dir).is_empty(), "SIG{signal} left {:?}", dir_names(&out_dir));
    }
}
