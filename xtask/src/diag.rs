//! `cargo xtask diag NAME`: measurements and diagnostics that print figures rather than
//! pass or fail, kept out of the test suites and the libraries. Each prints what the
//! docs' tables quote (the docs name the command beside each table).
//!
//! - `solver-table`: the multigrid CG solver on digitized spheres (docs/performance.md,
//!   "Regularization solvers"); see `solvers.rs`.
//! - `at-cg-tolerance`: Ambrosio-Tortorelli's CG tolerance on bunny-128 (docs/performance.md,
//!   "Normal estimators"); see `at.rs`.
//! - `stitched VOLUME.npy`, `blocks VOLUME.npy`, `sensitivity VOLUME.npy`: chunked solves
//!   against the whole-volume solve (docs/scale.md, "Exactness and the halo"); see
//!   `blocks.rs`.
//! - `interrupt-latency`: how long a replaced run takes to stop (docs/performance.md,
//!   "Viewer"); see `latency.rs`.
//! - `geodesic-speed`: the geodesic methods' speed on the regularized bunny against their
//!   budgets (docs/performance.md, "Geodesics"); see `latency.rs`.

mod at;
mod blocks;
mod latency;
mod solvers;

use anyhow::{bail, Context, Result};

/// Runs `cargo xtask diag NAME [ARGS...]`.
pub(crate) fn diag(args: &[String]) -> Result<()> {
    let rest = args.get(1..).unwrap_or_default();
    match args.first().map(String::as_str) {
        Some("solver-table") => solvers::solver_table(),
        Some("at-cg-tolerance") => at::at_cg_tolerance(),
        Some("stitched") => blocks::stitched(volume_arg(rest)?),
        Some("blocks") => blocks::blocks(volume_arg(rest)?),
        Some("sensitivity") => blocks::sensitivity(volume_arg(rest)?),
        Some("interrupt-latency") => latency::interrupt_latency(),
        Some("geodesic-speed") => latency::geodesic_speed(),
        _ => {
            eprintln!(
                "usage: cargo xtask diag solver-table | at-cg-tolerance | interrupt-latency | geodesic-speed"
            );
            eprintln!("       cargo xtask diag stitched | blocks | sensitivity VOLUME.npy");
            bail!("unknown or missing diagnostic")
        }
    }
}

/// The volume argument of the block diagnostics (or `VOXREG_DIAG`).
fn volume_arg(rest: &[String]) -> Result<std::path::PathBuf> {
    rest.first()
        .cloned()
        .or_else(|| std::env::var("VOXREG_DIAG").ok())
        .map(std::path::PathBuf::from)
        .context("give the volume: cargo xtask diag NAME VOLUME.npy (or VOXREG_DIAG=VOLUME.npy)")
}

/// The environment variable `name` parsed, or `default` where it is unset.
fn env_or<T: std::str::FromStr>(name: &str, default: T) -> Result<T> {
    match std::env::var(name) {
        Ok(v) => v.parse().ok().with_context(|| format!("{name}={v}: not a valid value")),
        Err(_) => Ok(default),
    }
}

/// The environment variable `name` parsed, where it is set.
fn env_opt<T: std::str::FromStr>(name: &str) -> Result<Option<T>> {
    match std::env::var(name) {
        Ok(v) => v.parse().map(Some).ok().with_context(|| format!("{name}={v}: not a valid value")),
        Err(_) => Ok(None),
    }
}
