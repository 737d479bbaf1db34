use rayon::prelude::*;
use std::time::Instant;
use voxreg_digisurf::DigitalSurface;
use voxreg_normals::{NormalEstimator, Trivial};
use voxreg_regularize::*;
use voxreg_testkit::{digitize, Sphere};

#[test]
#[ignore]
fn bandwidth() {
    for n in [1usize << 16, 1 << 20, 1 << 22, 1 << 25, 1 << 27] {
        let a = vec![1.0f64; n];
        let b = vec![2.0f64; n];
        let mut c = vec![0.0f64; n];
        let reps = (1usize << 28) / n;
        let mut best = f64::MAX;
        for _ in 0..3 {
            let t = Instant::now();
            for _ in 0..reps.max(1) {
                c.par_chunks_mut(1 << 14).zip(a.par_chunks(1 << 14)).zip(b.par_chunks(1 << 14)).for_each(
                    |((c, a), b)| {
                        for i in 0..c.len() {
                            c[i] = a[i] + 3.0 * b[i];
                        }
                    },
                );
            }
            best = best.min(t.elapsed().as_secs_f64() / reps.max(1) as f64);
        }
        // triad: 2 reads + 1 write (+1 write-allocate read)
        eprintln!(
            "n={} MB/array={:.1} triad {:.2} GB/s (3 arrays) {:.2} (4 incl. WA)",
            n,
            n as f64 * 8e-6,
            3.0 * 8.0 * n as f64 / best * 1e-9,
            4.0 * 8.0 * n as f64 / best * 1e-9
        );
        let t = Instant::now();
        let s: f64 = a.par_iter().sum();
        let dt = t.elapsed().as_secs_f64();
        eprintln!("   read sum {:.2} GB/s ({s})", 8.0 * n as f64 / dt * 1e-9);
    }
}

#[test]
#[ignore]
fn sizes() {
    for r in [20.0, 36.0, 60.0, 80.0, 120.0, 156.0, 320.0] {
        let t = Instant::now();
        let v = digitize(&Sphere { radius: r }, 1.0);
        let s = DigitalSurface::from_volume(&v).unwrap();
        eprintln!(
            "sphere r={r}: {} quads {} vertices ({:.2}s)",
            s.num_surfels(),
            s.num_vertices(),
            t.elapsed().as_secs_f64()
        );
        if r > 200.0 {
            continue;
        }
        let normals = Trivial.estimate(&s).unwrap();
        let input = s.positions();
        let e = Energy::new(&s, &normals, &input, EnergyParams::default()).unwrap();
        let t = Instant::now();
        let g = e.gradient(&input);
        eprintln!(
            "  gradient {:.4}s |g0|={}",
            t.elapsed().as_secs_f64(),
            g.iter().map(|x| x.length_squared()).sum::<f64>().sqrt()
        );
        let t = Instant::now();
        let pat = OperatorPattern::new(&s).unwrap();
        eprintln!("  pattern {:.4}s nnz {}", t.elapsed().as_secs_f64(), pat.nnz());
        let t = Instant::now();
        let _op = Operator::assemble(&pat, &e);
        eprintln!("  assemble {:.4}s", t.elapsed().as_secs_f64());
        if r < 100.0 {
            let t = Instant::now();
            let mut d = DirectSolver::new(&s).unwrap();
            let t1 = t.elapsed().as_secs_f64();
            let (_x, info) = d.solve(&e).unwrap();
            eprintln!(
                "  direct new {:.3}s solve {:.3}s factor nnz {} ({:?})",
                t1,
                t.elapsed().as_secs_f64() - t1,
                d.factor_nnz(),
                info
            );
        }
    }
}

fn sphere_surface(r: f64) -> DigitalSurface {
    DigitalSurface::from_volume(&digitize(&Sphere { radius: r }, 1.0)).unwrap()
}

#[test]
#[ignore]
fn cg_vs_direct() {
    let r: f64 = std::env::var("R").map(|v| v.parse().unwrap()).unwrap_or(20.0);
    let s = sphere_surface(r);
    let normals = voxreg_normals::NormalField::new(voxreg_testkit::true_normals(&s, &Sphere { radius: r }));
    let input = s.positions();
    let e = Energy::new(&s, &normals, &input, EnergyParams::default()).unwrap();
    let (xd, _) = DirectSolver::new(&s).unwrap().solve(&e).unwrap();
    let env = |k: &str, d: f64| std::env::var(k).map(|v| v.parse().unwrap()).unwrap_or(d);
    let mg = MultigridParams {
        max_levels: env("LEVELS", 16.0) as usize,
        coarsest_nodes: env("COARSEST", 800.0) as usize,
        smoothing_steps: env("STEPS", 1.0) as usize,
        damping: env("DAMP", 1.8),
    };
    for pre in [Preconditioner::Jacobi, Preconditioner::BlockJacobi, Preconditioner::Multigrid] {
        let mut cg =
            CgSolver::new(&s, CgParams { preconditioner: pre, multigrid: mg, ..Default::default() }).unwrap();
        let t = Instant::now();
        let (x, info) = cg.solve(&e).unwrap();
        let dt = t.elapsed().as_secs_f64();
        let err = x.iter().zip(&xd).map(|(a, b)| (*a - *b).length()).fold(0.0, f64::max);
        let g = e.gradient_norm(&x) / e.gradient_norm(&input);
        eprintln!(
            "{pre:?}: {dt:.3}s iters {} levels {} err {err:.2e} bound {:.2e} rel {:.2e} (true {g:.2e})",
            info.iterations,
            cg.levels(),
            info.error_bound.unwrap(),
            info.relative_gradient
        );
    }
}

#[test]
#[ignore]
fn cg_timing() {
    let radii: Vec<f64> = std::env::var("RADII")
        .map(|v| v.split(',').map(|x| x.parse().unwrap()).collect())
        .unwrap_or(vec![33.0, 73.0, 140.0]);
    for r in radii {
        let s = sphere_surface(r);
        let normals = if std::env::var("TRIVIAL").is_ok() {
            Trivial.estimate(&s).unwrap()
        } else {
            voxreg_normals::NormalField::new(voxreg_testkit::true_normals(&s, &Sphere { radius: r }))
        };
        let input = s.positions();
        let e = Energy::new(&s, &normals, &input, EnergyParams::default()).unwrap();
        eprintln!("r={r}: {} quads", s.num_surfels());
        let env = |k: &str, d: f64| std::env::var(k).map(|v| v.parse().unwrap()).unwrap_or(d);
        let mg = MultigridParams {
            max_levels: env("LEVELS", 16.0) as usize,
            coarsest_nodes: env("COARSEST", 800.0) as usize,
            smoothing_steps: env("STEPS", 1.0) as usize,
            damping: env("DAMP", 1.8),
        };
        let pres = if std::env::var("MGONLY").is_ok() {
            vec![Preconditioner::Multigrid]
        } else {
            vec![Preconditioner::BlockJacobi, Preconditioner::Multigrid]
        };
        for pre in pres {
            for _ in 0..2 {
                let c0 = cpu_ns();
                let t = Instant::now();
                let mut cg =
                    CgSolver::new(&s, CgParams { preconditioner: pre, multigrid: mg, ..Default::default() })
                        .unwrap();
                let t1 = t.elapsed().as_secs_f64();
                let (_x, info) = cg.solve(&e).unwrap();
                let dt = t.elapsed().as_secs_f64();
                let cpu = (cpu_ns() - c0) as f64 * 1e-9;
                eprintln!("  {pre:?}: cpu {cpu:.3}s total {dt:.3}s (new {t1:.3}, assemble {:.3}, factor {:.3}, iterate {:.3}) iters {} levels {} bound {:.2e} per-iter {:.2}ms", info.assemble_seconds, info.factor_seconds, info.solve_seconds, info.iterations, cg.levels(), info.error_bound.unwrap(), info.solve_seconds / info.iterations as f64 * 1e3);
            }
        }
    }
}

#[test]
#[ignore]
fn error_trace() {
    let r: f64 = std::env::var("R").map(|v| v.parse().unwrap()).unwrap_or(20.0);
    let alpha: f64 = std::env::var("ALPHA").map(|v| v.parse().unwrap()).unwrap_or(1e-3);
    let s = sphere_surface(r);
    let trivial = std::env::var("TRIVIAL").is_ok();
    let normals = if trivial {
        Trivial.estimate(&s).unwrap()
    } else {
        voxreg_normals::NormalField::new(voxreg_testkit::true_normals(&s, &Sphere { radius: r }))
    };
    let input = s.positions();
    let e = Energy::new(&s, &normals, &input, EnergyParams { alpha, ..Default::default() }).unwrap();
    let env = |k: &str, d: f64| std::env::var(k).map(|v| v.parse().unwrap()).unwrap_or(d);
    let mg = MultigridParams {
        max_levels: env("LEVELS", 16.0) as usize,
        coarsest_nodes: env("COARSEST", 800.0) as usize,
        smoothing_steps: env("STEPS", 1.0) as usize,
        damping: env("DAMP", 1.8),
    };
    let params = CgParams { multigrid: mg, ..Default::default() };
    let mut cg = CgSolver::new(&s, params).unwrap();
    let (xd, _) =
        CgSolver::new(&s, CgParams { tolerance: 1e-9, stopping: StoppingRule::Guaranteed, ..params })
            .unwrap()
            .solve(&e)
            .unwrap();
    // Re-run, tracking the error through a shadow copy: the callback has no iterate, so re-solve with a max iteration count.
    let (_, info) = cg
        .solve_with(&e, &mut |p| {
            eprintln!(
                "it {:3} rel {:.2e} bound {:.2e} est {:.2e}",
                p.iteration, p.relative_gradient, p.error_bound, p.error_estimate
            );
        })
        .unwrap();
    let (x, _) = cg.solve(&e).unwrap();
    let err = x.iter().zip(&xd).map(|(a, b)| (*a - *b).length()).fold(0.0, f64::max);
    eprintln!("stopped at {} error {err:.2e} estimate {:.2e}", info.iterations, info.error_estimate.unwrap());
    if std::env::var("TRACE").is_err() {
        return;
    }
    for k in 1..=info.iterations {
        let (x, _) = CgSolver::new(&s, CgParams { max_iterations: k, ..params }).unwrap().solve(&e).unwrap();
        let err = x.iter().zip(&xd).map(|(a, b)| (*a - *b).length()).fold(0.0, f64::max);
        eprintln!("it {k:3} true max error {err:.2e}");
    }
}

fn cpu_ns() -> u64 {
    std::fs::read_dir("/proc/self/task")
        .unwrap()
        .map(|e| {
            let p = e.unwrap().path().join("schedstat");
            std::fs::read_to_string(p)
                .map(|s| s.split_whitespace().next().unwrap().parse::<u64>().unwrap())
                .unwrap_or(0)
        })
        .sum()
}
