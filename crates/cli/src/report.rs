//! The JSON report of `--report`: the library's [`Report`], with the command's own
//! input, output and I/O timings.

use std::path::Path;

use crate::input::Source;
use anyhow::{Context, Result};
use serde::Serialize;
use voxreg_io::{Outputs, Palette};
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

/// A label the input names (`.seg.nrrd` segments, named `.vox` materials).
#[derive(Clone, Debug, Serialize)]
pub(crate) struct LabelEntry {
    /// The label value.
    pub(crate) value: u32,
    /// Its name, as the file writes it.
    pub(crate) name: String,
    /// Its colour, sRGB and alpha bytes.
    pub(crate) color: [u8; 4],
}

/// The labels of `volume` that `palette` names, in increasing order.
pub(crate) fn named_labels(volume: &Source, palette: Option<&Palette>) -> Vec<LabelEntry> {
    let Some(palette) = palette.filter(|p| !p.names.is_empty()) else { return Vec::new() };
    palette
        .named_labels(volume.label_counts().into_iter().map(|(l, _)| l))
        .into_iter()
        .map(|l| LabelEntry { value: l.label, name: l.name, color: l.color })
        .collect()
}

/// What `--report` writes.
#[derive(Serialize)]
pub(crate) struct CliReport<'a> {
    pub(crate) input: String,
    pub(crate) output: String,
    /// The labels the input names, when it names any.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub(crate) labels: Vec<LabelEntry>,
    pub(crate) io: IoTimes,
    /// The process's peak resident memory so far, in bytes (Linux: `VmHWM`), when the
    /// system reports it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub(crate) peak_memory: Option<u64>,
    #[serde(flatten)]
    pub(crate) run: &'a Report,
}

/// The process's peak resident set size so far (`VmHWM` of `/proc/self/status`), where
/// the system reports it.
pub(crate) fn peak_memory() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find_map(|l| l.strip_prefix("VmHWM:"))?;
    let kib: u64 = line.trim().strip_suffix("kB")?.trim().parse().ok()?;
    kib.checked_mul(1024)
}

/// Stages `report` in `outputs`, committed with the run's other files.
pub(crate) fn write_report(outputs: &mut Outputs, path: &Path, report: &CliReport<'_>) -> Result<()> {
    outputs
        .write(path, |staged| {
            voxreg_io::write_file_atomically(staged, |w| {
                serde_json::to_writer_pretty(&mut *w, report).map_err(std::io::Error::other)
            })
        })
        .with_context(|| format!("{}: cannot write", path.display()))
}
