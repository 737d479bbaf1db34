//! Interruption: SIGINT, SIGTERM, SIGHUP and SIGQUIT end the run with nothing half-written.
//!
//! A thread waits for the signals; on one it removes this process's temporary files and
//! staging directories (`voxreg_io::inflight::remove_in_flight`, which also keeps any
//! new one from being created and any `--split` commit from being cut in two), then
//! exits with 128 + the signal number (130 for SIGINT, 143 for SIGTERM, 129 for SIGHUP,
//! 131 for SIGQUIT: no core dump). SIGXFSZ (the
//! file size limit) is caught too, so a write past the limit fails like any other write,
//! removing its temporary file, instead of killing the process.

/// Installs the handlers; where they cannot be installed the run goes on without them.
#[cfg(unix)]
pub(crate) fn install() {
    use std::sync::atomic::AtomicBool;
    use std::sync::Arc;

    use signal_hook::consts::{SIGHUP, SIGINT, SIGQUIT, SIGTERM, SIGXFSZ};

    let _ = signal_hook::flag::register(SIGXFSZ, Arc::new(AtomicBool::new(false)));
    let Ok(mut signals) = signal_hook::iterator::Signals::new([SIGINT, SIGTERM, SIGHUP, SIGQUIT]) else {
        return;
    };
    std::thread::spawn(move || {
        if let Some(signal) = signals.forever().next() {
            let _held = voxreg_io::inflight::remove_in_flight();
            let name = match signal {
                SIGINT => "SIGINT",
                SIGTERM => "SIGTERM",
                SIGQUIT => "SIGQUIT",
                _ => "SIGHUP",
            };
            eprintln!("\nerror: interrupted by {name}; temporary files removed");
            std::process::exit(128 + signal);
        }
    });
}

/// Installs nothing where there are no Unix signals.
#[cfg(not(unix))]
pub(crate) fn install() {}
