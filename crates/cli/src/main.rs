//! `voxreg`: regularize voxel volumes into smooth quad meshes.
//!
//! Argument parsing and glue only: the work happens in the library crates, whose
//! presets ([`voxreg_regularize::Params`]) hold every default.

mod args;
mod check;
mod geodesic;
mod info;
mod input;
mod output;
mod progress;
mod report;
mod signals;
mod simplify;
mod terminal;
mod view;

use anyhow::{Context, Result};
use clap::Parser as _;
use voxreg_io::{write_ply_with_vertex_scalar, write_volume, write_volume_blocks, Outputs, QuadMesh};
use voxreg_regularize::Run;
use voxreg_upscale::{upscale, upscale_blocks, UpscaleParams};

use crate::args::{Cli, Command, RegularizeArgs};
use crate::input::Source;
use crate::output::Product;
use crate::progress::Stages;
use crate::report::{CliReport, IoTimes};

/// glibc's allocator raises its threshold for giving a large block its own mapping to
/// the size of the largest such block freed (up to 32 MiB); the blocks below it then come
/// from heaps that keep freed memory resident (about 9% of a 1.5M-surfel run's peak). The
/// threshold is read from the environment at start, and setting it keeps it fixed: the
/// command runs itself again once with glibc's default of 128 KiB set (and a single
/// arena), unless it is set already (or the run cannot be replaced, when it goes on as
/// it is).
#[cfg(all(target_os = "linux", target_env = "gnu"))]
fn fix_allocator_threshold() {
    use std::os::unix::process::CommandExt as _;
    const THRESHOLD: &str = "MALLOC_MMAP_THRESHOLD_";
    if std::env::var_os(THRESHOLD).is_some() {
        return;
    }
    let Ok(exe) = std::env::current_exe() else { return };
    let mut args = std::env::args_os();
    let arg0 = args.next().unwrap_or_else(|| exe.clone().into_os_string());
    // `exec` returns only when the process could not be replaced.
    // One arena: the pool's threads reuse each other's freed blocks instead of each
    // keeping its own arena's (about 2% of a 1.5M-surfel run's peak).
    let _ = std::process::Command::new(exe)
        .arg0(arg0)
        .args(args)
        .env(THRESHOLD, "131072")
        .env("MALLOC_ARENA_MAX", "1")
        .exec();
}

fn main() -> std::process::ExitCode {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    fix_allocator_threshold();
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => return usage_error(&e),
    };
    signals::install();
    quiet_panics();
    if let Some(bytes) = cli.max_memory {
        voxreg_io::set_max_memory(bytes);
    }
    // The commands that compute run on a thread of rayon's pool: a parallel pass started
    // from outside the pool wakes a worker and sleeps until it is done, two context
    // switches per pass (a tenth of a voxel-art run's time). The viewer serves for its
    // whole life and runs its solves on the pool itself.
    let result = std::panic::catch_unwind(|| match cli.command {
        Command::Info(args) => info::info(&args),
        Command::Regularize(args) => rayon::scope(|_| regularize(&args, Product::Mesh)),
        Command::Upscale(args) => {
            rayon::scope(|_| regularize(&args.regularize, Product::Volume { factor: args.factor }))
        }
        Command::Geodesic(args) => {
            rayon::scope(|_| regularize(&args.regularize, Product::Geodesic(&args.geodesic)))
        }
        Command::Check(args) => rayon::scope(|_| check::check(&args)),
        Command::View(args) => view::view(&args),
    })
    .unwrap_or_else(|_| {
        let what = LAST_PANIC.lock().ok().and_then(|p| p.clone()).unwrap_or_else(|| "a panic".into());
        Err(anyhow::anyhow!("internal error (a bug in voxreg; please report it): {what}"))
    });
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", terminal::one_line(&e));
            std::process::ExitCode::FAILURE
        }
    }
}

/// The message and location of the last panic, for the one-line report of a panic that
/// reaches `main`.
static LAST_PANIC: std::sync::Mutex<Option<String>> = std::sync::Mutex::new(None);

/// Replaces the default panic hook, which prints several lines to standard error, by one
/// that only records the panic: a panic caught on purpose (a third-party decoder failing
/// on a corrupt file, which the reader turns into an error) prints nothing, and one that
/// reaches `main` becomes a single error line. `RUST_BACKTRACE` set keeps the default
/// hook, for debugging.
fn quiet_panics() {
    if std::env::var_os("RUST_BACKTRACE").is_some() {
        return;
    }
    std::panic::set_hook(Box::new(|info| {
        let message = info
            .payload()
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| info.payload().downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "a panic".into());
        let at = info.location().map(|l| format!(" at {}:{}", l.file(), l.line())).unwrap_or_default();
        if let Ok(mut last) = LAST_PANIC.lock() {
            *last = Some(format!("{}{at}", message.lines().next().unwrap_or("")));
        }
    }));
}

/// Help and version go to standard output (exit 0); any other argument error is one line
/// on standard error naming the option, exit 1, like every other error.
fn usage_error(e: &clap::Error) -> std::process::ExitCode {
    use clap::error::ErrorKind;
    match e.kind() {
        ErrorKind::DisplayHelp | ErrorKind::DisplayVersion => {
            let _ = e.print();
            std::process::ExitCode::SUCCESS
        }
        _ => {
            // clap's message up to its usage block, folded into one line.
            let text = e.render().to_string();
            let parts: Vec<&str> = text
                .lines()
                .map(str::trim)
                .take_while(|l| !l.starts_with("Usage:") && !l.starts_with("For more information"))
                .filter(|l| !l.is_empty())
                .collect();
            let line = parts.join(" ");
            let line = line.strip_prefix("error: ").unwrap_or(&line);
            eprintln!("error: {line} (see voxreg --help)");
            std::process::ExitCode::FAILURE
        }
    }
}

/// `voxreg regularize`, `voxreg upscale` and `voxreg geodesic`.
fn regularize(args: &RegularizeArgs, product: Product<'_>) -> Result<()> {
    output::check_outputs(args, product)?;
    let params = args.params(input::voxel_art(&args.input))?;
    let stages = Stages::new(args.quiet);
    let path = &args.input.input;
    // As blocks where INPUT is a MagicaVoxel scene of models far apart (an upscale of it
    // then upscales block by block).
    let ((source, palette, _units), read) = stages.run("read volume", || input::read_source(&args.input))?;
    output::check_volume(args, product, &source)?;
    output::check_library(args, product, palette.is_some())?;
    let (mut regularizer, _) = stages.run("digital surface", || {
        // Refused before the surface is built, by the extraction's own count.
        match product {
            // Exact geodesics' windows outgrow the surface: refused here too, not hours later.
            Product::Geodesic(opts) if opts.method == args::GeodesicMethod::Exact => source.regularizer_within(
                &args.input,
                &params,
                |surfels| voxreg_geodesic::exact_estimated_bytes(2 * surfels as usize),
                |n| format!("the regularization of its {n} surfels and their exact geodesics (--method heat needs less)"),
            ),
            _ => source.regularizer_within(&args.input, &params, |_| 0, |n| {
                format!("the regularization of its {n} surfels")
            }),
        }
    })?;
    // What the run needs of the volume is in the surface now: unless the output is a
    // volume, its memory goes back before the solves (the run's peak).
    let labels =
        args.report.as_ref().map(|_| report::named_labels(&source, palette.as_ref())).unwrap_or_default();
    let volume = match product {
        Product::Volume { .. } => Some(source),
        _ => {
            drop(source);
            None
        }
    };
    // One run: the initial normals need not outlive it.
    regularizer.set_keep_normals(false);
    let out = stages.pipeline(&params, |progress| {
        regularizer
            .run(Run::new(&params).progress(progress))
            .with_context(|| format!("{}: cannot regularize", path.display()))
    })?;
    // The solver's state and the fields the outputs do not use go back before the
    // outputs are made (a simplification's peak).
    drop(regularizer);
    let voxreg_regularize::Output { surface, positions, features, report: r, .. } = out;
    let surface = &surface;
    let mut io = IoTimes { read, ..Default::default() };
    // Every file of the run is staged, then committed together (or none, on an error).
    let mut outputs = Outputs::new();
    let written = match product {
        Product::Mesh => {
            let (written, secs) = stages.run_reporting("write mesh", |status| {
                let written =
                    output::write_meshes(args, &mut outputs, surface, &positions, palette.as_ref(), status)?;
                if let (Some(path), Some(v)) = (&args.features, &features) {
                    let mesh = QuadMesh::from_surface(surface, &positions);
                    outputs
                        .write(path, |p| write_ply_with_vertex_scalar(p, &mesh, "feature", v.as_slice()))?;
                }
                Ok(written)
            })?;
            io.write = secs;
            written
        }
        Product::Geodesic(opts) => {
            let (written, secs) = stages.run("geodesic distances", || {
                geodesic::write_distances(args, &mut outputs, opts, surface, &positions)
            })?;
            io.write = secs;
            written
        }
        Product::Volume { factor } => {
            let volume = volume.as_ref().expect("the input volume is kept for an upscale");
            let params = UpscaleParams { factor };
            let (fine, secs) = stages.run(&format!("upscale x{factor}"), || {
                match volume {
                    Source::Dense(v) => upscale(surface, &positions, v, &params).map(Source::Dense),
                    Source::Blocks(v) => upscale_blocks(surface, &positions, v, &params).map(Source::Blocks),
                }
                .with_context(|| format!("{}: cannot upscale", path.display()))
            })?;
            io.upscale = Some(secs);
            output::check_upscaled(args, volume, &fine, factor)?;
            let ((), secs) = stages.run("write volume", || {
                Ok(outputs.write(&args.output, |p| match &fine {
                    Source::Dense(v) => write_volume(p, v, palette.as_ref()),
                    Source::Blocks(v) => write_volume_blocks(p, v, palette.as_ref()),
                })?)
            })?;
            io.write = secs;
            args.output.display().to_string()
        }
    };
    if let Some(report) = &args.report {
        let full = CliReport {
            input: path.display().to_string(),
            output: args.output.display().to_string(),
            labels,
            io,
            peak_memory: report::peak_memory(),
            run: &r,
        };
        report::write_report(&mut outputs, report, &full)?;
    }
    outputs.commit()?;
    if !args.quiet {
        eprintln!("{}; wrote {written}", r.summary());
    }
    Ok(())
}
