//! Criterion benchmarks of the solvers on digitized spheres of about 20k, 100k and 367k
//! quads (radius 33, 73 and 140 voxels), with the spheres' exact normals.
//!
//! Run with `cargo bench --bench solvers` (all) or filter, e.g.
//! `cargo bench --bench solvers -- cg/20k`. Each CG sample is the whole minimization:
//! connectivity and hierarchy (`CgSolver::new`), coarse operators, and the iterations to
//! the default tolerance (1e-3 voxel, estimated). The direct solver is benchmarked on the
//! smallest sphere only (its factorization takes 1.6 s there, 28 s at 120k quads).

#![allow(missing_docs)] // criterion_group! generates an undocumented function.

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion};
use voxreg::digisurf::DigitalSurface;
use voxreg::normals::NormalEstimator;
use voxreg::normals::NormalField;
use voxreg::regularize::{
    BoundedParams, BoundedSolver, CgParams, CgSolver, DirectSolver, Energy, EnergyParams, Preconditioner,
    SolveRequest,
};
use voxreg_testkit::{digitize, true_normals, Sphere};

fn sphere(radius: f64) -> (DigitalSurface, NormalField) {
    let shape = Sphere { radius };
    let surface = DigitalSurface::from_volume(&digitize(&shape, 1.0)).expect("a sphere has a surface");
    let normals = NormalField::new(true_normals(&surface, &shape));
    (surface, normals)
}

fn solvers(c: &mut Criterion) {
    let mut g = c.benchmark_group("solvers");
    g.sample_size(10);
    for (name, radius) in [("20k", 33.0), ("100k", 73.0), ("367k", 140.0)] {
        let (surface, normals) = sphere(radius);
        let input = surface.positions();
        let energy = Energy::new(&surface, &normals, &input, EnergyParams::default()).expect("valid energy");
        g.bench_function(format!("cg/{name}"), |b| {
            b.iter(|| {
                CgSolver::for_surface(black_box(&surface), CgParams::default())
                    .unwrap()
                    .solve(&energy, SolveRequest::default())
                    .unwrap()
            })
        });
        let mut reused = CgSolver::for_surface(&surface, CgParams::default()).unwrap();
        g.bench_function(format!("cg-reused/{name}"), |b| {
            b.iter(|| reused.solve(black_box(&energy), SolveRequest::default()).unwrap())
        });
        if radius < 50.0 {
            let block = CgParams { preconditioner: Preconditioner::BlockJacobi, ..Default::default() };
            g.bench_function(format!("cg-block-jacobi/{name}"), |b| {
                b.iter(|| {
                    CgSolver::for_surface(black_box(&surface), block)
                        .unwrap()
                        .solve(&energy, SolveRequest::default())
                        .unwrap()
                })
            });
            g.bench_function(format!("direct/{name}"), |b| {
                b.iter(|| DirectSolver::for_surface(black_box(&surface)).unwrap().solve(&energy).unwrap())
            });
        }
    }
    // The clamped descent (the default for voxel art) on a bundled MagicaVoxel model.
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("data/veh_fire.vox");
    let loaded = voxreg::io::read_voxels(&path).expect("bundled model");
    let voxreg::io::Voxels::Labels(volume) = loaded.voxels else { panic!(".vox models are labels") };
    let surface =
        DigitalSurface::new(&volume, &voxreg::digisurf::RegionMap::single_solid()).expect("surface");
    let normals = voxreg::normals::IntegralInvariant { radius: None }.estimate(&surface).expect("normals");
    let input = surface.positions();
    let energy = Energy::new(&surface, &normals, &input, EnergyParams::default()).expect("valid energy");
    let clamped = BoundedParams { clamp: Some(0.01), ..Default::default() };
    g.bench_function("gd-clamped/veh_fire", |b| {
        b.iter(|| {
            BoundedSolver::for_surface(black_box(&surface), clamped)
                .unwrap()
                .solve(&energy, SolveRequest::default())
                .unwrap()
        })
    });
    g.finish();
}

criterion_group!(benches, solvers);
criterion_main!(benches);
