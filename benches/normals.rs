//! Criterion benchmarks of the normal estimators.
//!
//! Run with `cargo bench --bench normals` (all) or filter, e.g.
//! `cargo bench --bench normals -- ii`. Inputs: the bundled bunny-128 volume (55k
//! surfels, unit spacing) and DGtal's goursat surface digitized at h = 0.156 (96k
//! surfels; default radius 3 h^(1/3) = 1.61, about 10 voxels).

#![allow(missing_docs)] // `criterion_group!` defines an undocumented function

use std::hint::black_box;
use std::path::Path;

use criterion::{criterion_group, criterion_main, Criterion};
use voxreg::digisurf::DigitalSurface;
use voxreg::io::read_volume;
use voxreg::normals::{ConvolvedTrivial, IntegralInvariant, NormalEstimator};
use voxreg_testkit::{digitize, Goursat};

fn estimators(c: &mut Criterion) {
    let mut g = c.benchmark_group("normals");
    g.sample_size(10);
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("data/bunny-128.vol");
    let bunny = DigitalSurface::from_volume(&read_volume(&path).unwrap().volume).unwrap();
    let ii3 = IntegralInvariant { radius: Some(3.0) };
    g.bench_function("ii/bunny-128/r3", |b| b.iter(|| ii3.estimate(black_box(&bunny)).unwrap()));
    let conv3 = ConvolvedTrivial { radius: Some(3.0) };
    g.bench_function("convolved/bunny-128/r3", |b| b.iter(|| conv3.estimate(black_box(&bunny)).unwrap()));
    drop(bunny);

    let goursat = DigitalSurface::from_volume(&digitize(&Goursat, 0.156)).unwrap();
    let ii = IntegralInvariant::default();
    g.bench_function("ii/goursat-0.156/default", |b| b.iter(|| ii.estimate(black_box(&goursat)).unwrap()));
    g.finish();
}

criterion_group!(benches, estimators);
criterion_main!(benches);
