//! `--simplify`, `--max-error`, `--lod`: the regularized mesh simplified with its partition
//! kept (`voxreg_simplify`), one file or a pyramid of levels.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use voxreg_io::{write_mesh, Outputs, QuadMesh};
use voxreg_simplify::{pyramid_targets, simplify_levels_reporting, Interrupt, Options, Target};

use crate::args::{RegularizeArgs, Split};

/// Refuses simplification options that do not apply, before any work (`writes_mesh`:
/// the command writes `voxreg regularize`'s mesh).
pub(crate) fn check(args: &RegularizeArgs, writes_mesh: bool) -> Result<()> {
    let s = &args.simplify;
    if !s.active() {
        return Ok(());
    }
    if !writes_mesh {
        bail!("--simplify, --max-error and --lod apply to voxreg regularize's mesh");
    }
    if args.split != Split::None {
        bail!("--simplify, --max-error and --lod write one mesh, not --split files");
    }
    if let Some(r) = s.simplify {
        if r.is_nan() || r <= 0.0 || r > 1.0 {
            bail!("--simplify {r}: the ratio must be in (0, 1]");
        }
    }
    if let Some(e) = s.max_error {
        if e.is_nan() || e < 0.0 || e.is_infinite() {
            bail!("--max-error {e}: must be a non-negative number of voxels");
        }
    }
    match s.lod {
        Some(n) if !(1..=12).contains(&n) => bail!("--lod {n}: between 1 and 12 levels"),
        Some(_) if s.simplify.is_some() => bail!("--lod sets each level's ratio: use it without --simplify"),
        _ => {}
    }
    Ok(())
}

/// `path` with `.lod{k}` before its extension.
pub(crate) fn level_path(path: &Path, k: usize) -> PathBuf {
    let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    let name = match path.extension() {
        Some(ext) => format!("{stem}.lod{k}.{}", ext.to_string_lossy()),
        None => format!("{stem}.lod{k}"),
    };
    path.with_file_name(name)
}

/// Writes `mesh` to the output as the options say (as it is, simplified, or as levels
/// of detail), staged in `outputs` to be committed with the run's other files; returns
/// what was written. `voxel` is the smallest voxel spacing; `status` shows the
/// simplification's level, stage and progress.
pub(crate) fn write(
    args: &RegularizeArgs,
    outputs: &mut Outputs,
    mesh: QuadMesh,
    voxel: f64,
    status: &dyn Fn(&str),
) -> Result<String> {
    let s = &args.simplify;
    let out = &args.output;
    if !s.active() {
        outputs.write(out, |path| write_mesh(path, &mesh))?;
        return Ok(out.display().to_string());
    }
    let e = s.max_error.unwrap_or(0.5) * voxel;
    let targets = match s.lod {
        Some(n) => pyramid_targets(n, 4.0, e),
        None => vec![Target { ratio: s.simplify, max_error: e }],
    };
    let mut report = |p: &voxreg_simplify::Progress| {
        let stage = p.stage.label();
        let level = if p.levels > 1 { format!("level {}/{} ", p.level + 1, p.levels) } else { String::new() };
        status(&format!("simplify: {level}{stage} {:.0}%", 100.0 * p.fraction));
    };
    // SIGINT ends the process (its staged outputs removed), so no interrupt is needed.
    let levels =
        simplify_levels_reporting(&mesh, &targets, &Options::default(), &Interrupt::never(), &mut report)
            .with_context(|| format!("{}: cannot simplify", out.display()))?;
    if s.lod.is_none() {
        outputs.write(out, |path| write_mesh(path, &levels[0].mesh))?;
        return Ok(out.display().to_string());
    }
    let mut names = Vec::new();
    for (k, level) in levels.iter().enumerate() {
        let path = level_path(out, k);
        outputs.write(&path, |p| write_mesh(p, &level.mesh))?;
        names.push(path.display().to_string());
    }
    Ok(names.join(", "))
}
