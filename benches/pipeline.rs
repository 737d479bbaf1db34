//! Criterion benchmarks of every pipeline stage, and of whole runs through the front door.
//!
//! Run with `cargo bench --bench pipeline` (all) or filter, e.g.
//! `cargo bench --bench pipeline -- surface`. Inputs: the bundled bunny-128 volume
//! (55k surfels) and a synthetic 256^3 ball volume for the surface extraction.

#![allow(missing_docs)] // criterion_group! generates an undocumented function.

use std::hint::black_box;
use std::path::Path;

use criterion::{criterion_group, criterion_main, Criterion};
use voxreg::digisurf::{DigitalSurface, LabelVolume};
use voxreg::io::{read_volume, write_mesh, QuadMesh};
use voxreg::normals::{NormalEstimator, Trivial};
use voxreg::regularize::{DirectSolver, Energy, EnergyParams, Operator, OperatorPattern};
use voxreg::Params;

fn bunny() -> LabelVolume {
    read_volume(&Path::new(env!("CARGO_MANIFEST_DIR")).join("data/bunny-128.vol")).unwrap().volume
}

/// A ball of radius 100 voxels in a 256^3 volume (about 16.8M voxels, 377k surfels).
fn ball_256() -> LabelVolume {
    LabelVolume::from_fn([256, 256, 256], |[x, y, z]| {
        let d = |c: usize| c as f64 - 127.5;
        u32::from(d(x).powi(2) + d(y).powi(2) + d(z).powi(2) <= 100.0f64.powi(2))
    })
}

fn stages(c: &mut Criterion) {
    let mut g = c.benchmark_group("stages");
    g.sample_size(10);
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("data/bunny-128.vol");
    g.bench_function("read/bunny-128.vol", |b| b.iter(|| read_volume(black_box(&path)).unwrap()));

    let ball = ball_256();
    g.bench_function("surface/ball-256", |b| {
        b.iter(|| DigitalSurface::from_volume(black_box(&ball)).unwrap())
    });
    drop(ball);
    let volume = bunny();
    g.bench_function("surface/bunny-128", |b| {
        b.iter(|| DigitalSurface::from_volume(black_box(&volume)).unwrap())
    });

    let surface = DigitalSurface::from_volume(&volume).unwrap();
    g.bench_function("normals/trivial/bunny-128", |b| {
        b.iter(|| Trivial.estimate(black_box(&surface)).unwrap())
    });

    let normals = Trivial.estimate(&surface).unwrap();
    let input = surface.positions();
    let energy = Energy::new(&surface, &normals, &input, EnergyParams::default()).unwrap();
    g.bench_function("energy/gradient/bunny-128", |b| b.iter(|| energy.gradient(black_box(&input))));
    g.bench_function("assemble/pattern/bunny-128", |b| {
        b.iter(|| OperatorPattern::new(black_box(&surface)).unwrap())
    });
    let pattern = OperatorPattern::new(&surface).unwrap();
    g.bench_function("assemble/numeric/bunny-128", |b| {
        b.iter(|| Operator::assemble(&pattern, black_box(&energy)))
    });
    g.bench_function("solve/symbolic/bunny-128", |b| {
        b.iter(|| DirectSolver::for_surface(black_box(&surface)).unwrap())
    });
    let mut solver = DirectSolver::for_surface(&surface).unwrap();
    g.bench_function("solve/numeric/bunny-128", |b| b.iter(|| solver.solve(black_box(&energy)).unwrap()));

    let (x, _) = solver.solve(&energy).unwrap();
    let mesh = QuadMesh::from_surface(&surface, &x);
    let dir = tempfile::tempdir().unwrap();
    for ext in ["obj", "ply"] {
        let out = dir.path().join(format!("bunny.{ext}"));
        g.bench_function(format!("write/{ext}/bunny-128"), |b| {
            b.iter(|| write_mesh(&out, black_box(&mesh)).unwrap())
        });
    }
    g.finish();
}

/// The whole default run through the front door, as `voxreg regularize` does it.
fn front_door(c: &mut Criterion) {
    let mut g = c.benchmark_group("front door");
    g.sample_size(10);
    let volume = bunny();
    for (name, params) in [("default", Params::default()), ("papers", Params::papers())] {
        g.bench_function(format!("{name}/bunny-128"), |b| {
            b.iter(|| voxreg::regularize(black_box(&volume), &params).unwrap())
        });
    }
    g.finish();
}

criterion_group!(benches, stages, front_door);
criterion_main!(benches);
