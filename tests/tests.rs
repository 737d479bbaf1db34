//! Cross-crate integration tests: the whole pipeline, volume -> digital surface ->
//! normals -> regularized positions -> mesh file, on the bundled real inputs.
//!
//! Index:
//! - `bunny_128_round_trip`: the foundation's "done when": a closed quad mesh with one
//!   quad per surfel, certified optimal.
//! - `vox_model_pipeline`: a MagicaVoxel model as one solid, through PLY.
//! - `multi_label_open_interfaces`: junctions and open rims survive the pipeline.
//! - `anisotropic_spacing_scales_positions`: spacing is honoured end to end.
//!
//! Per-crate tests live beside each crate (`crates/*/tests`, `mod tests`).

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use glam::DVec3;
use voxreg::digisurf::{DigitalSurface, LabelVolume, RegionMap};
use voxreg::io::{read_volume, write_mesh, QuadMesh};
use voxreg::normals::{NormalEstimator, Trivial};
use voxreg::regularize::{regularize, EnergyParams};

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("data").join(name)
}

/// Reads back the vertices and quads of an OBJ file written by voxreg.
fn read_obj(path: &Path) -> (Vec<DVec3>, Vec<[usize; 4]>) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut v = Vec::new();
    let mut f = Vec::new();
    for line in text.lines() {
        let t: Vec<&str> = line.split_whitespace().collect();
        match t.first() {
            Some(&"v") => {
                v.push(DVec3::new(t[1].parse().unwrap(), t[2].parse().unwrap(), t[3].parse().unwrap()))
            }
            Some(&"f") => f.push([1, 2, 3, 4].map(|i| t[i].parse::<usize>().unwrap() - 1)),
            _ => {}
        }
    }
    (v, f)
}

/// Undirected edge -> number of incident quads.
fn edge_incidence(quads: &[[usize; 4]]) -> HashMap<(usize, usize), usize> {
    let mut m = HashMap::new();
    for q in quads {
        for i in 0..4 {
            let (a, b) = (q[i], q[(i + 1) % 4]);
            *m.entry((a.min(b), a.max(b))).or_insert(0) += 1;
        }
    }
    m
}

#[test]
fn bunny_128_round_trip() {
    let loaded = read_volume(&data("bunny-128.vol")).unwrap();
    let surface = DigitalSurface::from_volume(&loaded.volume).unwrap();
    assert_eq!(surface.num_surfels(), 55262);
    let normals = Trivial.estimate(&surface).unwrap();
    let result = regularize(&surface, &normals, EnergyParams::default()).unwrap();
    assert!(result.info.relative_gradient <= 1e-9, "{}", result.info.relative_gradient);
    assert!(result.after.total < result.before.total);

    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bunny.obj");
    write_mesh(&path, &QuadMesh::from_surface(&surface, &result.positions)).unwrap();
    let (v, f) = read_obj(&path);
    assert_eq!(f.len(), surface.num_surfels(), "one quad per surfel");
    assert_eq!(v.len(), surface.num_vertices());
    assert!(edge_incidence(&f).values().all(|&c| c % 2 == 0), "closed");
    // The written positions are the regularized ones, and they moved off the lattice.
    for (a, b) in v.iter().zip(&result.positions) {
        assert!((*a - *b).length() < 1e-9);
    }
    let moved = v.iter().zip(surface.positions()).filter(|(a, b)| (**a - *b).length() > 1e-3).count();
    assert!(moved > v.len() / 2);
}

#[test]
fn vox_model_pipeline() {
    let loaded = read_volume(&data("veh_fire.vox")).unwrap();
    assert!(loaded.palette.is_some());
    let surface = DigitalSurface::new(&loaded.volume, &RegionMap::single_solid()).unwrap();
    assert_eq!(surface.interfaces().len(), 1);
    let result = regularize(&surface, &Trivial.estimate(&surface).unwrap(), EnergyParams::default()).unwrap();
    assert!(result.info.relative_gradient <= 1e-9);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("fire.ply");
    write_mesh(&path, &QuadMesh::from_surface(&surface, &result.positions)).unwrap();
    assert!(std::fs::metadata(&path).unwrap().len() > 0);
}

#[test]
fn multi_label_open_interfaces() {
    // Three materials filling the whole domain (no background): interfaces end at the
    // border; a junction line runs where all three meet.
    let vol = LabelVolume::from_fn([12, 12, 8], |[x, y, z]| {
        if (x as f64 - 5.5).hypot(y as f64 - 5.5) < 3.5 + 0.2 * z as f64 {
            7
        } else if x < 6 {
            1
        } else {
            2
        }
    })
    .with_background(None);
    let surface = DigitalSurface::from_volume(&vol).unwrap();
    let c = surface.counts();
    assert_eq!(c.interfaces, 3);
    assert!(c.junction_edges > 0 && c.boundary_vertices > 0);
    let result = regularize(&surface, &Trivial.estimate(&surface).unwrap(), EnergyParams::default()).unwrap();
    assert!(result.info.relative_gradient <= 1e-9);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("ml.obj");
    let mesh = QuadMesh::from_surface(&surface, &result.positions);
    assert_eq!(mesh.groups.len(), 3);
    write_mesh(&path, &mesh).unwrap();
    let (_, f) = read_obj(&path);
    let inc = edge_incidence(&f);
    assert!(inc.values().any(|&c| c == 1), "open rims");
    assert!(inc.values().any(|&c| c >= 3), "junction edges shared by three interfaces");
}

#[test]
fn anisotropic_spacing_scales_positions() {
    let base = LabelVolume::from_fn([5, 5, 5], |[x, y, z]| {
        u32::from([x, y, z].iter().all(|&c| (1..4).contains(&c)))
    });
    let spacing = DVec3::new(0.5, 1.0, 2.0);
    let scaled = base.clone().with_spacing(spacing).unwrap();
    let (s0, s1) =
        (DigitalSurface::from_volume(&base).unwrap(), DigitalSurface::from_volume(&scaled).unwrap());
    for (a, b) in s0.positions().iter().zip(s1.positions()) {
        assert!((*a * spacing - b).length() < 1e-12);
    }
    let r = regularize(&s1, &Trivial.estimate(&s1).unwrap(), EnergyParams::default()).unwrap();
    assert!(r.info.relative_gradient <= 1e-9);
    let extent = r.positions.iter().fold(DVec3::ZERO, |m, p| m.max(p.abs()));
    assert!(extent.z > 2.0 * extent.y && extent.y > 1.5 * extent.x, "{extent}");
}
