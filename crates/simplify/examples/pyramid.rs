//! The four-level pyramid of a volume's regularized surface, for profiling and for
//! comparing runs: regularize the volume, then `simplify_levels(pyramid_targets(4, 4,
//! 0.5))` on it.
//!
//! `cargo run -p voxreg-simplify --release --example pyramid -- VOLUME [LEVELS]` prints,
//! as one JSON object, the full mesh's faces, the times of both steps, and per level the
//! faces, the quad fraction, the distance bound and a hash of the mesh (equal hashes at
//! different thread counts show the output does not depend on them).

mod common;

use std::hash::{Hash, Hasher};
use std::time::Instant;

use voxreg_io::QuadMesh;
use voxreg_simplify::{pyramid_targets, simplify_levels, Options};

fn hash(mesh: &QuadMesh) -> u64 {
    let mut h = std::collections::hash_map::DefaultHasher::new();
    mesh.quads.hash(&mut h);
    mesh.face_labels.hash(&mut h);
    for p in &mesh.positions {
        p.to_array().map(f64::to_bits).hash(&mut h);
    }
    h.finish()
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(path) = args.first() else {
        eprintln!("usage: pyramid VOLUME [LEVELS]");
        std::process::exit(1);
    };
    let levels: usize = args.get(1).map_or(4, |s| s.parse().expect("LEVELS"));
    let (_, full, regularize_s) = common::regularized_mesh(path);
    let t1 = Instant::now();
    let l = simplify_levels(&full, &pyramid_targets(levels, 4.0, 0.5), &Options::default()).expect("pyramid");
    let pyramid_s = t1.elapsed().as_secs_f64();
    let list =
        |f: &dyn Fn(&voxreg_simplify::Simplified) -> String| l.iter().map(f).collect::<Vec<_>>().join(", ");
    println!(
        "{{\"input\": \"{path}\", \"faces_in\": {}, \"regularize_s\": {regularize_s:.2}, \"pyramid_s\": {pyramid_s:.2}, \
         \"level_faces\": [{}], \"level_quads\": [{}], \"level_bounds\": [{}], \"level_hashes\": [{}]}}",
        full.quads.len(),
        list(&|x| x.stats.faces.to_string()),
        list(&|x| format!("{:.4}", x.stats.quads as f64 / x.stats.faces as f64)),
        list(&|x| format!("{:.4}", x.stats.error_bound)),
        list(&|x| format!("\"{:016x}\"", hash(&x.mesh))),
    );
}
