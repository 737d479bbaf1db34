//! Fidelity of simplification on a volume: regularize it through the front door,
//! simplify to a ratio, and measure what the full surface loses.
//!
//! `cargo run -p voxreg-simplify --release --example fidelity -- VOLUME [RATIO] [MAX_ERROR] [LEVELS]`
//! (defaults 0.1, 0.5 and 0). Prints, as one JSON object: faces before and after, the
//! quad fraction, the largest and mean distance of the full surface's vertices to the
//! simplified surface (brute force over a grid of the output's triangles), the largest
//! relative change of a region's volume and of an interface's area, a hash of the
//! simplified mesh (to compare runs at different thread counts), and the times. With
//! `LEVELS` above 0, also a pyramid of that many levels (`pyramid_targets(LEVELS, 4,
//! MAX_ERROR)`) made once more from the full surface: its time, and per level the faces,
//! the quad fraction and the distance bound.

mod common;

use std::collections::BTreeMap;
use std::time::Instant;

use glam::DVec3;
use voxreg_io::QuadMesh;
use voxreg_quality::point_triangle_distance;
use voxreg_simplify::{pyramid_targets, simplify, simplify_levels, Options, Target};

fn triangles(mesh: &QuadMesh) -> Vec<([DVec3; 3], [u32; 2])> {
    let mut t = Vec::new();
    for (q, l) in mesh.quads.iter().zip(&mesh.face_labels) {
        let p = q.map(|v| mesh.positions[v as usize]);
        t.push(([p[0], p[1], p[2]], *l));
        if q[2] != q[3] && q[3] != q[0] {
            t.push(([p[0], p[2], p[3]], *l));
        }
    }
    t
}

/// Signed volume per label (faces oriented from inner to outer label) and area per
/// label pair.
fn measures(mesh: &QuadMesh) -> (BTreeMap<u32, f64>, BTreeMap<[u32; 2], f64>) {
    let (mut vol, mut area) = (BTreeMap::new(), BTreeMap::new());
    for (t, l) in triangles(mesh) {
        let v = t[0].dot(t[1].cross(t[2])) / 6.0;
        *vol.entry(l[0]).or_insert(0.0) += v;
        *vol.entry(l[1]).or_insert(0.0) -= v;
        let a = 0.5 * (t[1] - t[0]).cross(t[2] - t[0]).length();
        *area.entry([l[0].min(l[1]), l[0].max(l[1])]).or_insert(0.0) += a;
    }
    (vol, area)
}

fn max_rel_change<K: Ord>(a: &BTreeMap<K, f64>, b: &BTreeMap<K, f64>, skip: impl Fn(&K) -> bool) -> f64 {
    a.iter()
        .filter(|(k, v)| !skip(k) && v.abs() > 0.0)
        .map(|(k, v)| ((b.get(k).copied().unwrap_or(0.0) - v) / v).abs())
        .fold(0.0, f64::max)
}

/// Distances of `points` to the triangles, through a uniform grid searched in growing
/// shells until the nearest found is closer than the unsearched space.
fn distances(points: &[DVec3], tris: &[[DVec3; 3]]) -> Vec<f64> {
    let lo = tris.iter().flatten().fold(DVec3::INFINITY, |a, p| a.min(*p));
    let mean_edge = tris.iter().map(|t| (t[1] - t[0]).length()).sum::<f64>() / tris.len() as f64;
    let h = 2.0 * mean_edge.max(1e-9);
    let cell = |p: DVec3| ((p - lo) / h).floor().as_ivec3();
    let mut grid: std::collections::HashMap<glam::IVec3, Vec<u32>> = Default::default();
    for (i, t) in tris.iter().enumerate() {
        let (a, b) = (cell(t[0].min(t[1]).min(t[2])), cell(t[0].max(t[1]).max(t[2])));
        for x in a.x..=b.x {
            for y in a.y..=b.y {
                for z in a.z..=b.z {
                    grid.entry(glam::IVec3::new(x, y, z)).or_default().push(i as u32);
                }
            }
        }
    }
    points
        .iter()
        .map(|&p| {
            let c = cell(p);
            let mut best = f64::INFINITY;
            for r in 0..1000i32 {
                for x in -r..=r {
                    for y in -r..=r {
                        for z in -r..=r {
                            if x.abs().max(y.abs()).max(z.abs()) != r {
                                continue;
                            }
                            if let Some(list) = grid.get(&(c + glam::IVec3::new(x, y, z))) {
                                for &t in list {
                                    best = best.min(point_triangle_distance(p, tris[t as usize]));
                                }
                            }
                        }
                    }
                }
                if best <= r as f64 * h {
                    break;
                }
            }
            best
        })
        .collect()
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(path) = args.first() else {
        eprintln!("usage: fidelity VOLUME [RATIO] [MAX_ERROR] [LEVELS]");
        std::process::exit(1);
    };
    let ratio: f64 = args.get(1).map_or(0.1, |s| s.parse().expect("RATIO"));
    let max_error: f64 = args.get(2).map_or(0.5, |s| s.parse().expect("MAX_ERROR"));
    let levels: usize = args.get(3).map_or(0, |s| s.parse().expect("LEVELS"));
    let (loaded, full, regularize_s) = common::regularized_mesh(path);
    let t1 = Instant::now();
    let s = simplify(&full, Target { ratio: Some(ratio), max_error }, &Options::default()).expect("simplify");
    let simplify_s = t1.elapsed().as_secs_f64();
    let tris: Vec<[DVec3; 3]> = triangles(&s.mesh).into_iter().map(|t| t.0).collect();
    let d = distances(&full.positions, &tris);
    let max = d.iter().copied().fold(0.0, f64::max);
    let mean = d.iter().sum::<f64>() / d.len() as f64;
    let (v0, a0) = measures(&full);
    let (v1, a1) = measures(&s.mesh);
    let hash = {
        use std::hash::{Hash, Hasher};
        let mut h = std::collections::hash_map::DefaultHasher::new();
        s.mesh.quads.hash(&mut h);
        s.mesh.face_labels.hash(&mut h);
        for p in &s.mesh.positions {
            p.to_array().map(f64::to_bits).hash(&mut h);
        }
        h.finish()
    };
    let pyramid = if levels > 0 {
        let t2 = Instant::now();
        let l = simplify_levels(&full, &pyramid_targets(levels, 4.0, max_error), &Options::default())
            .expect("pyramid");
        let secs = t2.elapsed().as_secs_f64();
        let faces: Vec<String> = l.iter().map(|x| x.stats.faces.to_string()).collect();
        let quads: Vec<String> =
            l.iter().map(|x| format!("{:.3}", x.stats.quads as f64 / x.stats.faces as f64)).collect();
        let bounds: Vec<String> = l.iter().map(|x| format!("{:.3}", x.stats.error_bound)).collect();
        format!(
            ", \"pyramid_s\": {secs:.2}, \"level_faces\": [{}], \"level_quads\": [{}], \"level_bounds\": [{}]",
            faces.join(", "),
            quads.join(", "),
            bounds.join(", ")
        )
    } else {
        String::new()
    };
    let background = loaded.volume.background();
    let spacing = loaded.volume.spacing();
    println!(
        "{{\"input\": \"{path}\", \"spacing\": [{}, {}, {}], \"ratio\": {ratio}, \"max_error\": {max_error}, \
         \"faces_in\": {}, \"faces_out\": {}, \"face_ratio\": {:.4}, \"quad_fraction\": {:.4}, \
         \"max_distance\": {max:.4}, \"mean_distance\": {mean:.5}, \"error_bound\": {:.4}, \
         \"max_region_volume_change\": {:.5}, \"max_interface_area_change\": {:.5}, \
         \"hash\": \"{hash:016x}\", \"regularize_s\": {regularize_s:.2}, \"simplify_s\": {simplify_s:.2}{pyramid}}}",
        spacing.x,
        spacing.y,
        spacing.z,
        s.stats.input_faces,
        s.stats.faces,
        s.stats.faces as f64 / s.stats.input_faces as f64,
        s.stats.quads as f64 / s.stats.faces as f64,
        s.stats.error_bound,
        max_rel_change(&v0, &v1, |&l| Some(l) == background),
        max_rel_change(&a0, &a1, |_| false),
    );
}
