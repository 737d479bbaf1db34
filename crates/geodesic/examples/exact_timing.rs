//! Times the exact geodesic distances on a mesh file from the vertex nearest a point:
//! `cargo run --release -p voxreg-geodesic --example exact_timing -- MESH.obj [X,Y,Z] [RUNS]`.
//! Prints the best time (wall and this thread's CPU), the run's counts and the largest distance. With `REFERENCE=FILE`
//! it writes the distances to FILE if that is missing or empty, else compares with them.

use std::time::Instant;

use glam::DVec3;
use voxreg_geodesic::{exact_distances, GeodesicMesh};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let Some(path) = args.get(1) else {
        eprintln!("usage: exact_timing MESH.obj|MESH.ply [X,Y,Z] [RUNS]");
        std::process::exit(2);
    };
    let mesh = match voxreg_io::read_mesh(std::path::Path::new(path)) {
        Ok(mesh) => mesh,
        Err(e) => {
            eprintln!("{e}");
            std::process::exit(1);
        }
    };
    let point = args.get(2).map_or(DVec3::ZERO, |s| {
        let c: Vec<f64> = s.split(',').map(|x| x.trim().parse().expect("a number")).collect();
        DVec3::new(c[0], c[1], c[2])
    });
    let runs: usize = args.get(3).map_or(1, |s| s.parse().expect("a run count"));
    let geo = GeodesicMesh::new(&mesh.positions, &mesh.quads).expect("a mesh");
    let source = geo.nearest_vertex(point).expect("a vertex");
    let (mut best, mut best_cpu) = (f64::INFINITY, f64::INFINITY);
    for _ in 0..runs {
        let (t, cpu) = (Instant::now(), thread_cpu_seconds());
        let (d, info) = exact_distances(&geo, &[source]).expect("distances");
        best = best.min(t.elapsed().as_secs_f64());
        best_cpu = best_cpu.min(thread_cpu_seconds() - cpu);
        let largest = d.iter().copied().filter(|x| x.is_finite()).fold(0.0, f64::max);
        let sum: f64 = d.iter().copied().filter(|x| x.is_finite()).sum();
        println!("{info:?}; largest distance {largest:.9}, sum {sum:.9}");
    }
    println!("{} quads: best of {runs}: {best:.3} s, {best_cpu:.3} s CPU", mesh.quads.len());
    if let Ok(reference) = std::env::var("REFERENCE") {
        let (d, _) = exact_distances(&geo, &[source]).expect("distances");
        let text = std::fs::read_to_string(&reference).unwrap_or_default();
        if text.is_empty() {
            let out: Vec<String> = d.iter().map(|x| format!("{x:e}")).collect();
            std::fs::write(&reference, out.join("\n")).unwrap();
        } else {
            let r: Vec<f64> = text.lines().map(|l| l.parse().unwrap()).collect();
            let (mut max, mut maxrel, mut count) = (0.0f64, 0.0f64, 0);
            for (a, b) in d.iter().zip(&r) {
                let e = (a - b).abs();
                max = max.max(e);
                if *b > 0.0 {
                    maxrel = maxrel.max(e / b);
                }
                count += usize::from(e > 1e-9 * b.max(1.0));
            }
            println!("against the reference: max abs {max:e}, max rel {maxrel:e}, {count} vertices off by more than 1e-9");
        }
    }
}

/// CPU time of this thread (Linux: `/proc/thread-self/schedstat`, nanoseconds on a CPU);
/// NaN elsewhere.
fn thread_cpu_seconds() -> f64 {
    std::fs::read_to_string("/proc/thread-self/schedstat")
        .ok()
        .and_then(|s| s.split_whitespace().next()?.parse::<f64>().ok())
        .map_or(f64::NAN, |ns| ns * 1e-9)
}
