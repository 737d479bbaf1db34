//! Latencies and speed budgets measured on bunny-128.
//!
//! - `interrupt-latency`: how long a replaced run takes to stop (the default preset, warm
//!   re-solves as the viewer's worker runs them). For each raise time `STEP_MS` (default
//!   10) apart through a run, `RUNS` times (default 1) with offsets between: a run whose
//!   interrupt is raised then (the wait from the raise to its return), and the same run
//!   not interrupted (the wait from then to its next progress event, where a run stopped
//!   before the interrupt). Prints both per stage under way at the raise (median, max).
//! - `geodesic-speed`: the exact method on the regularized bunny within 2 s of the
//!   computing thread's CPU time (what wall time is on an idle core), the heat method
//!   within 0.3 s wall once factored (best of 3 each), the heat distances within 3% of
//!   the exact ones; fails where a budget is missed. The budgets are the reference 2-core
//!   machine's targets; `VOXREG_BUNNY=bunny-64.vol` times a smaller bunny (budgets, set
//!   for bunny-128, not checked).

use std::collections::BTreeMap;
use std::sync::Mutex;
use std::time::{Duration, Instant};

use anyhow::{bail, ensure, Result};
use glam::DVec3;
use voxreg_geodesic::{exact_distances, GeodesicMesh, HeatParams, HeatSolver};
use voxreg_regularize::{regularize, Event, Interrupt, Params, RegularizeError, Regularizer, Run, Stage};

use super::env_or;

/// `n raises, median, max` of the waits `w` (milliseconds), or `-`.
fn summary(w: &[f64]) -> String {
    let mut w = w.to_vec();
    w.sort_by(f64::total_cmp);
    match w.len() {
        0 => "-".to_string(),
        n => format!("{n} raises, median {:.1} ms, max {:.1} ms", w[n / 2], w[n - 1]),
    }
}

pub(super) fn interrupt_latency() -> Result<()> {
    let (step, runs): (u64, u64) = (env_or("STEP_MS", 10)?, env_or("RUNS", 1)?);
    let v = voxreg_io::read_volume(&crate::root().join("data/bunny-128.vol"))?;
    let mut params = Params::default();
    let mut r = Regularizer::from_volume(&v.volume, &params.regions)?;
    // Each round's last iterate, the warm starts the worker keeps.
    let mut warm: Vec<Vec<DVec3>> = Vec::new();
    r.run(Run::new(&params).progress(&mut |e| {
        if let (Stage::Solve { round }, Some(x)) = (e.stage, e.iterate()) {
            warm.resize(warm.len().max(round + 1), Vec::new());
            warm[round] = x;
        }
    }))?;
    // The stage under way, finer than the events' stages: a solve's setup (before its
    // first iterate) apart from its iterations.
    let label = |e: &Event, params: &Params| match (e.stage, e.iteration) {
        (Stage::Solve { .. }, None) => format!("{} setup", e.stage.label(params)),
        (Stage::Solve { .. }, Some(_)) => format!("{} iterations", e.stage.label(params)),
        _ => e.stage.label(params),
    };
    // One run raising its interrupt (if `interrupted`) `at` into it: the stage under way
    // then, the wait for the run's return (interrupted) or next event (not), the run's time.
    let mut run = |params: &Params, at: Duration, interrupted: bool| -> Result<(String, Option<f64>, f64)> {
        let interrupt = if interrupted { Interrupt::new() } else { Interrupt::never() };
        r.set_interrupt(interrupt.clone());
        let stage = Mutex::new((String::from("start"), None::<Instant>));
        let raised = Mutex::new(None::<(Instant, String)>);
        let start = Instant::now();
        let result = std::thread::scope(|scope| {
            scope.spawn(|| {
                std::thread::sleep(at);
                let mut s = stage.lock().unwrap();
                *raised.lock().unwrap() = Some((Instant::now(), s.0.clone()));
                s.1 = None;
                interrupt.raise();
            });
            r.run(Run::new(params).warm(&warm).progress(&mut |e| {
                let mut s = stage.lock().unwrap();
                let now = Instant::now();
                if raised.lock().unwrap().is_some() && s.1.is_none() {
                    s.1 = Some(now);
                }
                s.0 = label(e, params);
            }))
        });
        let end = Instant::now();
        let (when, under_way) = raised.lock().unwrap().take().expect("the raise ran");
        let next = stage.lock().unwrap().1;
        let wait = match (result, interrupted) {
            (Err(RegularizeError::Interrupted), true) => Some(end - when),
            (Ok(_), false) => next.map(|n| n - when),
            (Ok(_), true) => None, // done before the raise
            (Err(e), _) => bail!(e),
        };
        Ok((under_way, wait.map(|w| w.as_secs_f64() * 1e3), (end - start).as_secs_f64() * 1e3))
    };
    let (_, _, whole) = run(&params, Duration::ZERO, false)?;
    println!("warm re-solve {whole:.0} ms");
    let mut waits: BTreeMap<String, [Vec<f64>; 2]> = BTreeMap::new();
    for k in 0..runs {
        let mut at = Duration::from_millis(step * k / runs.max(1));
        let mut factor = 1.1;
        while at.as_secs_f64() * 1e3 < whole {
            params.energy.gamma *= factor;
            factor = 1.0 / factor;
            for interrupted in [true, false] {
                if let (stage, Some(w), _) = run(&params, at, interrupted)? {
                    waits.entry(stage).or_default()[usize::from(!interrupted)].push(w);
                }
            }
            at += Duration::from_millis(step);
        }
    }
    let mut all = [Vec::new(), Vec::new()];
    for (stage, [now, before]) in &waits {
        println!("{stage}: interrupted {}; next event {}", summary(now), summary(before));
        all[0].extend(now);
        all[1].extend(before);
    }
    println!("all: interrupted {}; next event {}", summary(&all[0]), summary(&all[1]));
    Ok(())
}

/// CPU time of this thread (Linux: `/proc/thread-self/schedstat`, nanoseconds on a CPU);
/// NaN elsewhere.
fn thread_cpu_seconds() -> f64 {
    std::fs::read_to_string("/proc/thread-self/schedstat")
        .ok()
        .and_then(|s| s.split_whitespace().next()?.parse::<f64>().ok())
        .map_or(f64::NAN, |ns| ns * 1e-9)
}

/// Mean relative error of `d` against `truth` over the vertices farther than `near` from
/// the source.
fn mean_relative_error(d: &[f64], truth: &[f64], near: f64) -> f64 {
    let e: Vec<f64> =
        d.iter().zip(truth).filter(|(_, &t)| t > near).map(|(&d, &t)| (d - t).abs() / t).collect();
    e.iter().sum::<f64>() / e.len().max(1) as f64
}

pub(super) fn geodesic_speed() -> Result<()> {
    let name = std::env::var("VOXREG_BUNNY").unwrap_or_else(|_| "bunny-128.vol".into());
    let budgets = name == "bunny-128.vol";
    let loaded = voxreg_io::read_volume(&crate::root().join("data").join(&name))?;
    let params = Params { regions: voxreg_digisurf::RegionMap::single_solid(), ..Params::default() };
    let t = Instant::now();
    let out = regularize(&loaded.volume, &params)?;
    println!("{name}: regularized in {:.2} s", t.elapsed().as_secs_f64());
    let quads: Vec<[u32; 4]> = out.surface.surfels().iter().map(|s| s.vertices.map(|v| v.0)).collect();
    let proxy = GeodesicMesh::new(&out.positions, &quads)?;
    let source = proxy.nearest_vertex(DVec3::ZERO).expect("a vertex");
    let (mut exact_s, mut exact_cpu_s, mut exact) = (Vec::new(), Vec::new(), Vec::new());
    for _ in 0..3 {
        let (t, cpu) = (Instant::now(), thread_cpu_seconds());
        let (d, info) = exact_distances(&proxy, &[source])?;
        let wall = t.elapsed().as_secs_f64();
        exact_s.push(wall);
        // Wall time where the CPU time is not available.
        exact_cpu_s.push(Some(thread_cpu_seconds() - cpu).filter(|x| x.is_finite()).unwrap_or(wall));
        println!("{info:?}");
        exact = d;
    }
    let t = Instant::now();
    let solver = HeatSolver::new(proxy.clone(), &HeatParams::default())?;
    let factor_s = t.elapsed().as_secs_f64();
    let (mut heat_s, mut heat) = (Vec::new(), Vec::new());
    for _ in 0..3 {
        let t = Instant::now();
        heat = solver.distances(&[source])?;
        heat_s.push(t.elapsed().as_secs_f64());
    }
    let mean = mean_relative_error(&heat, &exact, 3.0);
    println!(
        "{name}, {} quads: exact {exact_s:?} s wall, {exact_cpu_s:?} s CPU; heat factor {factor_s:.3} s, solve {heat_s:?} s; \
         heat vs exact mean {:.2}%",
        quads.len(),
        100.0 * mean
    );
    let best = |v: &[f64]| v.iter().copied().fold(f64::INFINITY, f64::min);
    ensure!(mean < 0.03, "heat against exact: {mean}");
    if budgets {
        ensure!(best(&heat_s) <= 0.3, "heat {heat_s:?} s, over the 0.3 s budget");
        ensure!(best(&exact_cpu_s) <= 2.0, "exact {exact_cpu_s:?} s CPU, over the 2 s budget");
    }
    Ok(())
}
