//! Extracts the digital surface of a `.npy` label volume (C or Fortran order, `u8`, `u16` or
//! `u32` little-endian, as `cargo xtask synth-labels` writes it; background `0`, none
//! with `NO_BACKGROUND` set), `REPEAT` times (default 1; 0: only read it), and
//! prints the surfels and the best time: for profiling the extraction alone
//! (`cargo run --release -p voxreg-digisurf --example extract_npy -- FILE.npy [REPEAT]`).
use std::time::Instant;

use voxreg_digisurf::{DigitalSurface, LabelVolume};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let path = args.get(1).expect("usage: extract_npy FILE.npy [REPEAT]");
    let repeat: usize = args.get(2).map_or(1, |r| r.parse().expect("REPEAT is a count"));
    let bytes = std::fs::read(path).expect("readable file");
    assert_eq!(&bytes[..6], b"\x93NUMPY", "not a .npy file");
    let (major, rest) = (bytes[6], &bytes[8..]);
    let (len, rest) = if major == 1 {
        (u16::from_le_bytes([rest[0], rest[1]]) as usize, &rest[2..])
    } else {
        (u32::from_le_bytes([rest[0], rest[1], rest[2], rest[3]]) as usize, &rest[4..])
    };
    let header = std::str::from_utf8(&rest[..len]).expect("text header");
    let data = &rest[len..];
    let fortran = header.contains("'fortran_order': True");
    let shape: Vec<usize> = header
        .split("'shape': (")
        .nth(1)
        .and_then(|s| s.split(')').next())
        .expect("a shape")
        .split(',')
        .filter_map(|s| s.trim().parse().ok())
        .collect();
    let width = if header.contains("8'") {
        8
    } else if header.contains("u1") || header.contains("|b1") {
        1
    } else if header.contains("u2") {
        2
    } else {
        4
    };
    let labels: Vec<u32> = data
        .chunks_exact(width)
        .map(|c| c[..width.min(4)].iter().rev().fold(0u32, |a, &b| (a << 8) | b as u32))
        .collect();
    let dims = (shape[0], shape[1], shape[2]);
    let array = if fortran {
        ndarray::Array3::from_shape_vec(ndarray::ShapeBuilder::f(dims), labels)
    } else {
        ndarray::Array3::from_shape_vec(dims, labels)
    };
    let background = if std::env::var_os("NO_BACKGROUND").is_some() { None } else { Some(0) };
    let volume = LabelVolume::new(array.expect("shape")).with_background(background);
    if repeat == 0 {
        // Only the reading, for instruction counts of the extraction by difference.
        println!("{} voxels read", volume.len());
        return;
    }
    let (mut best, mut best_cpu) = (f64::INFINITY, f64::INFINITY);
    let mut last = None;
    for _ in 0..repeat {
        let (t, c) = (Instant::now(), cpu_seconds());
        let s = DigitalSurface::from_volume(&volume).expect("a surface");
        best = best.min(t.elapsed().as_secs_f64());
        best_cpu = best_cpu.min(cpu_seconds() - c);
        last = Some(s);
    }
    let s = last.expect("at least one run");
    let sum = if std::env::var_os("NO_CHECKSUM").is_some() { 0 } else { checksum(&s) };
    println!(
        "{} surfels, best of {repeat}: {best:.3} s, cpu {best_cpu:.2} s, checksum {sum:016x}",
        s.num_surfels()
    );
}

/// The process's user and system time so far, from `/proc/self/stat` (in clock ticks of
/// 10 ms).
fn cpu_seconds() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    let fields: Vec<&str> = stat.rsplit(')').next().unwrap_or("").split_whitespace().collect();
    let tick = |i: usize| fields.get(i).and_then(|t| t.parse::<f64>().ok()).unwrap_or(0.0);
    (tick(11) + tick(12)) / 100.0
}

/// A hash of everything the surface's queries return, to compare two builds' surfaces.
fn checksum(s: &DigitalSurface) -> u64 {
    use std::hash::{Hash, Hasher};
    use voxreg_digisurf::{EdgeId, SurfelId, VertexId};
    let mut h = std::collections::hash_map::DefaultHasher::new();
    for (i, f) in s.surfels().iter().enumerate() {
        (f.cell, f.axis, f.flipped, f.regions, f.labels, f.vertices, f.interface).hash(&mut h);
        s.surfel_edges(SurfelId(i as u32)).hash(&mut h);
        s.surfel_component(SurfelId(i as u32)).hash(&mut h);
    }
    for (e, edge) in s.edges().iter().enumerate() {
        (edge.vertices, edge.axis, edge.kind).hash(&mut h);
        s.edge_surfels(EdgeId(e as u32)).hash(&mut h);
    }
    for v in 0..s.num_vertices() as u32 {
        let v = VertexId(v);
        (s.vertex_corner(v), s.vertex_surfels(v), s.vertex_neighbours(v), s.is_boundary_vertex(v))
            .hash(&mut h);
    }
    for i in s.interfaces() {
        (i.regions, &i.surfels).hash(&mut h);
    }
    s.components_closed().hash(&mut h);
    format!("{:?}", s.counts()).hash(&mut h);
    h.finish()
}
