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
