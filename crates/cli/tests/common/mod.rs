//! Helpers shared by the CLI's integration tests (each test file uses a subset).
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

#[allow(unused_imports)]
pub(crate) use voxreg_testkit::validate_gltf;

/// A file of the repository's `data/` folder.
pub(crate) fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data").join(name)
}

/// Runs the `voxreg` binary with `args`.
pub(crate) fn voxreg(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_voxreg")).args(args).output().expect("voxreg runs")
}

/// The standard output of a run, as text.
pub(crate) fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// The standard error of a run, as text.
pub(crate) fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// A path as a command-line argument.
pub(crate) fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Checks that the run `out` of `voxreg args` exited 1 with one error line holding every
/// one of `needles`; its standard error.
pub(crate) fn one_error(args: &[&str], out: &Output, needles: &[&str]) -> String {
    let err = stderr(out);
    assert_eq!(out.status.code(), Some(1), "voxreg {args:?} (killed by a signal if None): {err}");
    let errors: Vec<&str> = err.lines().filter(|l| l.starts_with("error:")).collect();
    assert_eq!(errors.len(), 1, "voxreg {args:?}: not one error line: {err}");
    for n in needles {
        assert!(err.contains(n), "voxreg {args:?}: '{n}' not in {err}");
    }
    err
}

/// Waits for `child` at most `secs` seconds, then kills it; its exit code.
#[cfg(unix)]
pub(crate) fn wait_code(child: &mut std::process::Child, secs: u64) -> Option<i32> {
    let start = std::time::Instant::now();
    while start.elapsed().as_secs() < secs {
        if let Some(status) = child.try_wait().unwrap() {
            return status.code();
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    let _ = child.kill();
    panic!("voxreg did not exit within {secs} s of the signal");
}

/// Runs `voxreg regularize input -o output extra...`, which must succeed; its output.
pub(crate) fn regularize_ok(input: &Path, output: &Path, extra: &[&str]) -> Output {
    let mut args = vec!["regularize", s(input), "-o", s(output)];
    args.extend(extra);
    let out = voxreg(&args);
    assert!(out.status.success(), "voxreg {args:?}: {}", stderr(&out));
    out
}

/// The JSON of a `--report` file.
pub(crate) fn report_of(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}
