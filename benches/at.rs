//! Criterion benchmarks of the Ambrosio-Tortorelli normal estimator on bunny-128.
//!
//! Run with `cargo bench --bench at` (all) or filter, e.g. `cargo bench --bench at --
//! solve/cholesky`. Input: the bundled bunny-128 volume (55k surfels, unit spacing).
//! - `at/bunny-128/default`: the whole estimator (II input, operators, 40 alternations).
//! - `at/bunny-128/setup`: the discrete operators and sparsity patterns only.
//! - `at/bunny-128/solve/{cholesky,cg,cg-1e-10}`: the alternations only, from a precomputed
//!   II field, with each linear solver (`cg`: the default, relative residual `1e-5`; a reused
//!   `AtSolver`: the symbolic analyses are amortized).

#![allow(missing_docs)] // `criterion_group!` defines an undocumented function

use std::hint::black_box;
use std::path::Path;

use criterion::{criterion_group, criterion_main, Criterion};
use voxreg::digisurf::DigitalSurface;
use voxreg::io::read_volume;
use voxreg::normals::{
    AmbrosioTortorelli, AtLinearSolver, AtParams, AtSolver, IntegralInvariant, NormalEstimator,
};

fn at(c: &mut Criterion) {
    let mut g = c.benchmark_group("at");
    g.sample_size(10);
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("data/bunny-128.vol");
    let bunny = DigitalSurface::from_volume(&read_volume(&path).unwrap().volume).unwrap();

    let at = AmbrosioTortorelli::default();
    g.bench_function("bunny-128/default", |b| {
        b.iter(|| at.estimate_with_features(black_box(&bunny)).unwrap())
    });
    g.bench_function("bunny-128/setup", |b| b.iter(|| AtSolver::new(black_box(&bunny)).unwrap()));

    let input = IntegralInvariant::default().estimate(&bunny).unwrap();
    let mut solver = AtSolver::new(&bunny).unwrap();
    let cholesky = AtParams { linear_solver: AtLinearSolver::Cholesky, ..AtParams::default() };
    g.bench_function("bunny-128/solve/cholesky", |b| {
        b.iter(|| solver.solve(black_box(&input), &cholesky).unwrap())
    });
    let cg = AtParams::default();
    g.bench_function("bunny-128/solve/cg", |b| b.iter(|| solver.solve(black_box(&input), &cg).unwrap()));
    let cg_tight = AtParams {
        linear_solver: AtLinearSolver::ConjugateGradient { tolerance: 1e-10, max_iterations: 1000 },
        ..AtParams::default()
    };
    g.bench_function("bunny-128/solve/cg-1e-10", |b| {
        b.iter(|| solver.solve(black_box(&input), &cg_tight).unwrap())
    });
    g.finish();
}

criterion_group!(benches, at);
criterion_main!(benches);
