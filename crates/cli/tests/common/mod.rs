//! Helpers shared by the CLI's integration tests (each test file uses a subset).
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

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

/// Runs the Khronos validator on `files`; `None` when node is missing outside CI.
pub(crate) fn validate_gltf(files: &[PathBuf]) -> Option<String> {
    let tool = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tools/gltf-validate");
    let have_node = Command::new("node").arg("--version").output().is_ok_and(|o| o.status.success());
    if !have_node {
        assert!(std::env::var_os("CI").is_none(), "CI needs node for the glTF validator");
        return None;
    }
    if !tool.join("node_modules/gltf-validator").exists() {
        let ok = Command::new("npm")
            .args(["ci", "--silent", "--prefix"])
            .arg(&tool)
            .status()
            .is_ok_and(|s| s.success());
        assert!(ok, "npm ci in tools/gltf-validate failed");
    }
    let out = Command::new("node").arg(tool.join("validate.mjs")).args(files).output().unwrap();
    let report = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(out.status.success(), "validator: {report}{}", String::from_utf8_lossy(&out.stderr));
    Some(report)
}
