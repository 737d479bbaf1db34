//! Ctrl-C during a long call: the work runs on a thread of its own with the GIL released,
//! while the calling thread runs Python's signal handlers and raises the work's
//! [`Interrupt`] when one of them raises.

use std::sync::mpsc::{channel, RecvTimeoutError};
use std::time::Duration;

use pyo3::prelude::*;
use voxreg_regularize::Interrupt;

use crate::error::{no_panic, Error, Kind, Result};

/// How often the waiting thread runs Python's signal handlers.
const SIGNAL_POLL: Duration = Duration::from_millis(50);

/// Runs `f` on a thread of its own with the GIL released, while the calling thread runs
/// Python's signal handlers every 50 ms (`check_signals`, which only acts on the main
/// thread): when one raises (`KeyboardInterrupt` on Ctrl-C), `f`'s interrupt is raised,
/// `f` is waited for (it returns within milliseconds) and the exception propagates.
pub(crate) fn interruptible<T: Send>(
    py: Python<'_>,
    f: impl FnOnce(&Interrupt) -> Result<T> + Send,
) -> PyResult<T> {
    let interrupt = Interrupt::new();
    std::thread::scope(|scope| {
        let (tx, mut rx) = channel();
        let flag = &interrupt;
        scope.spawn(move || {
            let _ = tx.send(no_panic(|| f(flag)));
        });
        loop {
            // The receiver goes to the waiting closure and back (it cannot be shared).
            let got;
            (got, rx) = py.detach(move || (rx.recv_timeout(SIGNAL_POLL), rx));
            match got {
                Ok(result) => return result.map_err(PyErr::from),
                Err(RecvTimeoutError::Disconnected) => {
                    return Err(Error::new(Kind::Voxreg, "the computation stopped without a result").into())
                }
                Err(RecvTimeoutError::Timeout) => {}
            }
            if let Err(signal) = py.check_signals() {
                interrupt.raise();
                // The scope joins the thread; its result (Interrupted) is dropped.
                py.detach(move || drop(rx.recv()));
                return Err(signal);
            }
        }
    })
}
