//! Progress on the terminal: a spinner per stage, the solver's iterations, and the time
//! each stage took.

use std::time::{Duration, Instant};

use anyhow::Result;
use indicatif::{ProgressBar, ProgressStyle};
use voxreg_regularize::{Event, Output, Params, SolveInfo, Stage};

/// Shows a spinner for one stage of work at a time and measures it.
pub(crate) struct Stages {
    quiet: bool,
}

fn spinner(quiet: bool) -> ProgressBar {
    let bar = if quiet { ProgressBar::hidden() } else { ProgressBar::new_spinner() };
    bar.set_style(ProgressStyle::with_template("{spinner} {msg} {elapsed}").expect("valid template"));
    bar.enable_steady_tick(Duration::from_millis(100));
    bar
}

impl Stages {
    pub(crate) fn new(quiet: bool) -> Self {
        Stages { quiet }
    }

    /// Runs `f` under a spinner showing `message`; returns its result and its seconds.
    pub(crate) fn run<T>(&self, message: &str, f: impl FnOnce() -> Result<T>) -> Result<(T, f64)> {
        self.run_reporting(message, |_| f())
    }

    /// [`Stages::run`], where `f` may show what it is doing after `message` (a
    /// simplification's level and stage) through the function it receives.
    pub(crate) fn run_reporting<T>(
        &self,
        message: &str,
        f: impl FnOnce(&dyn Fn(&str)) -> Result<T>,
    ) -> Result<(T, f64)> {
        let bar = spinner(self.quiet);
        bar.set_message(message.to_string());
        let t = Instant::now();
        let out = f(&|detail: &str| bar.set_message(format!("{message}: {detail}")));
        let secs = t.elapsed().as_secs_f64();
        bar.finish_and_clear();
        if !self.quiet && out.is_ok() {
            eprintln!("{message}: {secs:.3} s");
        }
        Ok((out?, secs))
    }

    /// Runs the library's pipeline through `f`, which receives the progress callback;
    /// the spinner follows the library's stages and the solver's iterations.
    pub(crate) fn pipeline(
        &self,
        params: &Params,
        f: impl FnOnce(&mut dyn FnMut(&Event)) -> Result<Output>,
    ) -> Result<Output> {
        let bar = spinner(self.quiet);
        let tolerance = params.solver.cg.tolerance;
        let mut started: Option<(Stage, Instant)> = None;
        let quiet = self.quiet;
        let finish = |started: &mut Option<(Stage, Instant)>| {
            if let (Some((stage, t)), false) = (started.take(), quiet) {
                bar.suspend(|| eprintln!("{}: {:.3} s", stage.label(params), t.elapsed().as_secs_f64()));
            }
        };
        let mut report = |e: &Event| {
            if started.as_ref().map(|(s, _)| *s) != Some(e.stage) {
                finish(&mut started);
                started = Some((e.stage, Instant::now()));
            }
            let label = e.stage.label(params);
            match e.iteration {
                Some(p) => bar.set_message(format!(
                    "{label}: iteration {}: estimated error {:.1e} voxel (tolerance {tolerance:.0e}), relative gradient {:.1e}",
                    p.iteration, p.error_estimate, p.relative_gradient
                )),
                None => bar.set_message(label),
            }
        };
        let out = f(&mut report);
        finish(&mut started);
        bar.finish_and_clear();
        let out = out?;
        if !self.quiet {
            for info in &out.report.solves {
                if let SolveInfo::Direct(_) = info {
                    continue;
                }
                let status = if info.converged() { "converged" } else { "NOT converged" };
                eprintln!(
                    "{} {status} in {} iterations: estimated error {:.1e} voxel, relative gradient {:.1e}",
                    info.name(),
                    info.iterations(),
                    info.error_estimate().unwrap_or(0.0),
                    info.relative_gradient()
                );
            }
        }
        Ok(out)
    }
}
