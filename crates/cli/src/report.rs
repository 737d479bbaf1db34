//! The JSON report of `--report`: the library's [`Report`], with the command's own
//! input, output and I/O timings.

use std::path::Path;

use anyhow::{Context, Result};
use serde::Serialize;
use voxreg_regularize::Report;

/// Seconds of the command's own stages.
#[derive(Clone, Debug, Default, Serialize)]
pub(crate) struct IoTimes {
    /// Reading the input.
    pub(crate) read: f64,
    /// Voxelizing at the finer resolution (`voxreg upscale`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub(crate) upscale: Option<f64>,
    /// Writing the output.
    pub(crate) write: f64,
}

/// What `--report` writes.
#[derive(Serialize)]
pub(crate) struct CliReport<'a> {
    pub(crate) input: String,
    pub(crate) output: String,
    pub(crate) io: IoTimes,
    #[serde(flatten)]
    pub(crate) run: &'a Report,
}

/// Writes `report` through a temporary file and a rename, like the mesh writers.
pub(crate) fn write_report(path: &Path, report: &CliReport<'_>) -> Result<()> {
    voxreg_io::write_file_atomically(path, |w| {
        serde_json::to_writer_pretty(&mut *w, report).map_err(std::io::Error::other)
    })
    .with_context(|| format!("{}: cannot write", path.display()))
}
