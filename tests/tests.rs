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
//! - `front_door_presets`: the one-shot `regularize` with each preset.
//!
//! Per-crate tests live beside each crate (`crates/*/tests`, `mod tests`).

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use glam::DVec3;
use voxreg::digisurf::{DigitalSurface, LabelVolume, RegionMap};
use voxreg::io::{read_volume, write_mesh, QuadMesh};
use voxreg::normals::{NormalEstimator, NormalField, Trivial};
use voxreg::regularize::{Output, Params, Regularizer, Run, SolverChoice};

/// The papers' single solve, exact (sparse Cholesky), from `normals`.
fn exact(surface: &DigitalSurface, normals: &NormalField) -> Output {
    let mut params = Params::papers();
    params.solver.choice = SolverChoice::Direct;
    Regularizer::new(surface.clone()).run(Run::new(&params).from_normals(normals)).unwrap()
}

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
    let result = exact(&surface, &normals);
    assert!(
        result.report.last_solve().relative_gradient() <= 1e-9,
        "{}",
        result.report.last_solve().relative_gradient()
    );
    assert!(result.report.energy.after.total < result.report.energy.before.total);

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
    let result = exact(&surface, &Trivial.estimate(&surface).unwrap());
    assert!(result.report.last_solve().relative_gradient() <= 1e-9);
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
    let result = exact(&surface, &Trivial.estimate(&surface).unwrap());
    assert!(result.report.last_solve().relative_gradient() <= 1e-9);
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
    let r = exact(&s1, &Trivial.estimate(&s1).unwrap());
    assert!(r.report.last_solve().relative_gradient() <= 1e-9);
    let extent = r.positions.iter().fold(DVec3::ZERO, |m, p| m.max(p.abs()));
    assert!(extent.z > 2.0 * extent.y && extent.y > 1.5 * extent.x, "{extent}");
}

#[test]
fn front_door_presets() {
    let loaded = read_volume(&data("chr_army1.vox")).unwrap();
    let art = voxreg::regularize(&loaded.volume, &voxreg::Params::voxel_art()).unwrap();
    assert_eq!(art.surface.interfaces().len(), 1, "one solid");
    assert_eq!(art.report.solves.len(), 1);
    let input = art.surface.positions();
    let half = 0.5 * (1.0 - 0.01) + 1e-12;
    assert!(art.positions.iter().zip(&input).all(|(x, p)| (*x - *p).abs().max_element() <= half));

    let loaded = read_volume(&data("cat10.vol")).unwrap();
    let default = voxreg::regularize(&loaded.volume, &voxreg::Params::default()).unwrap();
    assert_eq!(default.report.solves.len(), 4);
    assert!(default.report.converged());
    let papers = voxreg::regularize(&loaded.volume, &voxreg::Params::papers()).unwrap();
    assert_eq!(papers.report.solves.len(), 1);
    // The report serializes, with the solver's own fields.
    let json = serde_json::to_value(&default.report).unwrap();
    assert_eq!(json["counts"]["surfels"].as_u64().unwrap() as usize, default.surface.num_surfels());
    assert!(json["solves"][0]["solver"].is_string());
}

#[test]
fn non_finite_arithmetic_is_an_error_not_a_result() {
    // A spacing whose squares overflow: the solve cannot be trusted, and says so.
    let vol =
        LabelVolume::from_fn([4, 4, 4], |[x, y, z]| u32::from([x, y, z].iter().all(|c| (1..3).contains(c))))
            .with_spacing(DVec3::splat(1e300))
            .unwrap();
    let err = voxreg::regularize(&vol, &voxreg::Params::default()).unwrap_err();
    assert!(matches!(err, voxreg::regularize::RegularizeError::NotFinite(_)), "{err}");
    assert!(err.to_string().contains("out of range"), "{err}");
}
