//! `voxreg view`: reads INPUT as `voxreg regularize` does and hands it to the viewer
//! library (`voxreg_view`), with a loader that reads dropped files the same way.

use std::path::PathBuf;

use anyhow::{Context, Result};
use voxreg_view::{Loaded, Viewer};

use crate::args::{RegularizeArgs, ViewArgs};
use crate::input;

/// Reads `args.input` with the options (from `bytes`, its contents, where given: nothing
/// else is read; a MagicaVoxel scene of models far apart as blocks), and the parameters
/// of its first solve.
fn load(args: &RegularizeArgs, bytes: Option<&[u8]>) -> Result<Loaded> {
    let voxel_art = input::voxel_art(&args.input);
    let preset = args.preset(voxel_art);
    // Checked now, so that a bad option fails before the viewer starts.
    args.params(voxel_art)?;
    // A MagicaVoxel scene of models far apart as blocks, as `voxreg regularize` reads it.
    let (volume, palette) = voxreg_view::read_volume(&args.input.input, bytes, &input::options(&args.input))
        .map_err(|e| input::input_error(&args.input, e))?;
    let path = &args.input.input;
    let name =
        path.file_name().map_or_else(|| path.display().to_string(), |n| n.to_string_lossy().into_owned());
    Ok(Loaded { name, volume, palette, preset, overrides: args.overrides() })
}

pub(crate) fn view(args: &ViewArgs) -> Result<()> {
    let first = load(&args.regularize, None)?;
    let options = args.regularize.clone();
    // A dropped file: its name and contents, read from memory (never from a path its
    // header names).
    let loader = move |name: &str, bytes: &[u8]| {
        let mut a = options.clone();
        a.input.input = PathBuf::from(name);
        // A dropped file is read with the same options, but its own preset.
        if a.preset.is_some() && input::voxel_art(&a.input) != input::voxel_art(&options.input) {
            a.preset = None;
        }
        load(&a, Some(bytes)).map_err(|e| crate::terminal::one_line(&e))
    };
    let viewer = Viewer::bind(args.port.unwrap_or(0), Box::new(loader))?;
    // The address with the session's token: the page and its requests need it.
    let url = viewer.url();
    eprintln!("voxreg view: {url} (Ctrl-C to stop)");
    if args.open {
        open_browser(&url).with_context(|| format!("cannot open a browser: open {url} by hand"))?;
    }
    viewer.open(first);
    viewer.serve();
    Ok(())
}

/// Opens `url` in the desktop's default browser.
fn open_browser(url: &str) -> Result<()> {
    let program = if cfg!(target_os = "macos") {
        "open"
    } else if cfg!(windows) {
        "explorer"
    } else {
        "xdg-open"
    };
    std::process::Command::new(program).arg(url).spawn().with_context(|| format!("{program} {url}"))?;
    Ok(())
}
