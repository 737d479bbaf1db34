//! The four-level pyramid of a volume's regularized surface, for profiling and for
//! comparing runs: regularize the volume, then `simplify_levels_reporting(pyramid_targets(4,
//! 4, 0.5))` on it.
//!
//! `cargo run -p voxreg-simplify --release --example pyramid -- VOLUME [LEVELS]` prints,
//! as one JSON object, the full mesh's faces, the times of both steps, per level the
//! faces, the quad fraction, the distance bound and a hash of the mesh (equal hashes at
//! different thread counts show the output does not depend on them), and the seconds of
//! each level's stages (`"1 collapses"`, `"1 flips"`, ...).

mod common;

use std::hash::{Hash, Hasher};
use std::time::Instant;

use voxreg_io::QuadMesh;
use voxreg_simplify::{pyramid_targets, simplify_levels_reporting, Interrupt, Options};

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
    let mut last = (Instant::now(), String::new());
    let mut stages: Vec<(String, f64)> = Vec::new();
    let l = simplify_levels_reporting(
        &full,
        &pyramid_targets(levels, 4.0, 0.5),
        &Options::default(),
        &Interrupt::never(),
        &mut |p| {
            let name = format!("{} {}", p.level, p.stage.label());
            if name != last.1 {
                stages.push((std::mem::replace(&mut last.1, name), last.0.elapsed().as_secs_f64()));
                last.0 = Instant::now();
            }
        },
    )
    .expect("pyramid");
    stages.push((last.1.clone(), last.0.elapsed().as_secs_f64()));
    // Each stage's seconds, by the first report of the next (levels' pairings overlap the
    // next level's collapses: their time shows in the collapses).
    let stage_s = stages
        .iter()
        .filter(|(n, s)| !n.is_empty() && *s >= 0.0005)
        .map(|(n, s)| format!("\"{n}\": {s:.3}"))
        .collect::<Vec<_>>()
        .join(", ");
    let pyramid_s = t1.elapsed().as_secs_f64();
    let list =
        |f: &dyn Fn(&voxreg_simplify::Simplified) -> String| l.iter().map(f).collect::<Vec<_>>().join(", ");
    println!(
        "{{\"input\": \"{path}\", \"faces_in\": {}, \"regularize_s\": {regularize_s:.2}, \"pyramid_s\": {pyramid_s:.2}, \
         \"level_faces\": [{}], \"level_quads\": [{}], \"level_bounds\": [{}], \"level_hashes\": [{}], \
         \"stage_s\": {{{stage_s}}}}}",
        full.quads.len(),
        list(&|x| x.stats.faces.to_string()),
        list(&|x| format!("{:.4}", x.stats.quads as f64 / x.stats.faces as f64)),
        list(&|x| format!("{:.4}", x.stats.error_bound)),
        list(&|x| format!("\"{:016x}\"", hash(&x.mesh))),
    );
}
