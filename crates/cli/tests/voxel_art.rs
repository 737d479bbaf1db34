//! Voxel art end to end: every bundled MagicaVoxel model, with default options,
//! gives a valid, coloured, self-intersection-free mesh; `voxreg upscale` doubles a model
//! into a .vox that dot_vox reads back.

use voxreg_digisurf::{DigitalSurface, RegionMap};
use voxreg_io::{read_mesh, read_voxels, Voxels};
use voxreg_quality::{angle_report, check, hard_edges, self_intersections, solid_report, Occupancy};

mod common;
use common::{data, stderr, validate_gltf, voxreg};

use voxreg_testkit::BUNDLED_VOX_MODELS as MODELS;

/// The solid voxels of a bundled model.
fn occupancy_of(name: &str) -> Occupancy {
    let loaded = read_voxels(&data(name)).unwrap();
    let Voxels::Labels(volume) = loaded.voxels else { panic!("{name}: .vox models are labels") };
    let labels = volume.labels();
    Occupancy::from_fn(volume.dims(), volume.origin(), volume.spacing(), |v| labels[v] != 0)
}

/// The digital surface the CLI builds for a .vox model by default (one solid region).
fn surface_of(name: &str) -> DigitalSurface {
    let loaded = read_voxels(&data(name)).unwrap();
    let Voxels::Labels(volume) = loaded.voxels else { panic!("{name}: .vox models are labels") };
    DigitalSurface::new(&volume, &RegionMap::single_solid()).unwrap()
}

#[test]
fn every_bundled_vox_model_gives_a_clean_coloured_mesh_by_default() {
    let dir = tempfile::tempdir().unwrap();
    let mut glbs = Vec::new();
    for name in MODELS {
        let surface = surface_of(name);
        // PLY: positions, faces and the labels on both sides of each face.
        let ply = dir.path().join(format!("{name}.ply"));
        let out = voxreg(&["regularize", data(name).to_str().unwrap(), "-o", ply.to_str().unwrap(), "-q"]);
        assert!(out.status.success(), "{name}: {}", stderr(&out));
        let mesh = read_mesh(&ply).unwrap();
        assert_eq!(mesh.quads.len(), surface.num_surfels(), "{name}");
        // Colours per quad: each face carries the palette index of its solid voxel.
        for (s, labels) in surface.surfels().iter().zip(&mesh.face_labels) {
            let solid = if s.labels[0] != 0 { s.labels[0] } else { s.labels[1] };
            assert!(labels.contains(&solid) && labels.contains(&0), "{name}: {labels:?} vs {:?}", s.labels);
        }
        // Clean by default: clamped into the cubes of Proposition 2, so no intersections.
        let half = 0.5 * (1.0 - 0.01) + 1e-4;
        for (p, q) in surface.positions().iter().zip(&mesh.positions) {
            assert!((*p - *q).abs().max_element() <= half, "{name}: {p} moved to {q}");
        }
        let pairs = self_intersections(&mesh.positions, &mesh.quads);
        assert!(pairs.is_empty(), "{name}: {} self-intersecting face pairs", pairs.len());
        assert!(mesh.positions.iter().zip(surface.positions()).any(|(q, p)| q.distance(p) > 0.1));
        // Voxel art's targets: no fold; solid centres inside, empty ones outside; thin
        // voxels (one-voxel plates, arms, slits) at least a quarter voxel deep.
        let r = check(&mesh.positions, &mesh.quads);
        assert!(r.is_clean(), "{name}: {r:?}");
        let s = solid_report(&occupancy_of(name), &mesh.positions, &mesh.quads);
        assert_eq!((s.solid_outside, s.empty_inside, s.thin_shallow), (0, 0, 0), "{name}: {s:?}");
        assert!(s.thin_min_depth >= 0.25, "{name}: {s:?}");

        // glTF: one material per colour of the model, every quad as two triangles.
        let glb = dir.path().join(format!("{name}.glb"));
        let out = voxreg(&["regularize", data(name).to_str().unwrap(), "-o", glb.to_str().unwrap(), "-q"]);
        assert!(out.status.success(), "{name}: {}", stderr(&out));
        let bytes = std::fs::read(&glb).unwrap();
        assert_eq!(&bytes[..4], b"glTF");
        let json_len = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
        let json: serde_json::Value = serde_json::from_slice(&bytes[20..20 + json_len]).unwrap();
        let colours: std::collections::BTreeSet<u32> =
            mesh.face_labels.iter().map(|l| l[0].max(l[1])).collect();
        assert_eq!(json["materials"].as_array().unwrap().len(), colours.len(), "{name}");
        let accessors = json["accessors"].as_array().unwrap();
        let triangles: u64 = json["meshes"]
            .as_array()
            .unwrap()
            .iter()
            .flat_map(|m| m["primitives"].as_array().unwrap())
            .map(|p| accessors[p["indices"].as_u64().unwrap() as usize]["count"].as_u64().unwrap() / 3)
            .sum();
        assert_eq!(triangles as usize, 2 * mesh.quads.len(), "{name}");
        glbs.push(glb);
    }
    if let Some(report) = validate_gltf(&glbs) {
        assert_eq!(report.lines().filter(|l| l.contains(": 0 errors")).count(), glbs.len(), "{report}");
    }
}

/// The preset's smoothness and sharpness against the former one (uniform boxes, no fold
/// removal, ii radius 3, `gamma = 0.1`) on the bundled models: the mean angle between
/// adjacent quads no higher on the models whose thin parts the former one did not
/// flatten much (`docs/accuracy.md`); away from thin voxels, within a degree of it on
/// every model with more than a hundred such pairs; and the box edges at least as sharp
/// on the whole.
#[test]
fn the_preset_is_smooth_away_from_thin_parts_and_keeps_hard_edges() {
    use voxreg_io::QuadMesh;
    use voxreg_regularize::{Params, Regularizer};
    let mut former = Params::voxel_art();
    former.mode.clamped_mut().unwrap().thin_depth = None;
    former.fold_free = false;
    former.normals.radius_voxels = None;
    former.energy.gamma = Params::ENERGY.gamma;
    let (mut hard_now, mut hard_before, mut hard_count) = (0.0, 0.0, 0usize);
    for name in MODELS {
        let loaded = read_voxels(&data(name)).unwrap();
        let Voxels::Labels(volume) = loaded.voxels else { panic!("{name}: .vox models are labels") };
        let occ = occupancy_of(name);
        let params = Params::voxel_art();
        let mut r = Regularizer::from_volume(&volume, &params.regions).unwrap();
        let surface = r.surface().clone();
        let input = surface.positions();
        let quads = QuadMesh::from_surface(&surface, &input).quads;
        let thin = occ.thin_quads(&input, &quads);
        let hard = hard_edges(&input, &quads).len();
        let measure = |positions: &[glam::DVec3]| angle_report(&input, positions, &quads, &thin);
        let now = measure(&r.run(&params).unwrap().positions);
        let before = measure(&r.run(&former).unwrap().positions);
        if ["veh_fire.vox", "axes.vox", "extended.vox", "placeholder-with-materials.vox"].contains(&name) {
            assert!(
                now.mean <= before.mean,
                "{name}: mean angle {} against {} before",
                now.mean,
                before.mean
            );
        }
        if now.elsewhere.1 > 100 {
            assert!(
                now.elsewhere.0 <= before.elsewhere.0 + 1.0,
                "{name}: away from thin voxels {:?} against {:?} before",
                now.elsewhere,
                before.elsewhere
            );
        }
        assert_eq!(now.hard_edges.1, hard, "{name}");
        hard_now += now.hard_edges.0 * hard as f64;
        hard_before += before.hard_edges.0 * hard as f64;
        hard_count += hard;
    }
    assert!(hard_count > 1000, "{hard_count} hard edges");
    assert!(
        hard_now >= hard_before,
        "mean angle at hard edges {} against {} before",
        hard_now / hard_count as f64,
        hard_before / hard_count as f64
    );
}

#[test]
fn smoothness_bounds_the_movement_and_check_measures_the_voxels() {
    let dir = tempfile::tempdir().unwrap();
    let ply = dir.path().join("army.ply");
    let input = data("chr_army1.vox");
    let out = voxreg(&[
        "regularize",
        input.to_str().unwrap(),
        "-o",
        ply.to_str().unwrap(),
        "-q",
        "--smoothness",
        "0.3",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let mesh = read_mesh(&ply).unwrap();
    let surface = surface_of("chr_army1.vox");
    let half = 0.3 * 0.495 + 1e-4;
    let input_positions = surface.positions();
    let moved = input_positions.iter().zip(&mesh.positions).map(|(p, q)| (*p - *q).abs().max_element());
    let most = moved.fold(0.0, f64::max);
    assert!(most <= half && most > 0.1, "moved {most}");
    // voxreg check measures the mesh against its voxels.
    let out = voxreg(&["check", ply.to_str().unwrap(), "--voxels", input.to_str().unwrap()]);
    assert!(out.status.success(), "{}", stderr(&out));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains("0 of 222 solid voxel centres outside") && text.contains("0 of 15 thin voxels"),
        "{text}"
    );
    // And its smoothness and box edges, on the staircase it recovers from the clamped
    // mesh: the pairs and edges the library counts on the model's own surface.
    assert!(
        text.contains("(voxels 40.5; ")
            && text.contains(" on the 140 pairs at thin voxels, ")
            && text.contains(" on the 660 others), 11 hard edges at "),
        "{text}"
    );
    // Out of range, or with the boxes given another way: a clear error.
    for bad in [&["--smoothness", "0"][..], &["--smoothness", "1.5"], &["--smoothness", "0.5", "--no-clamp"]]
    {
        let mut a = vec!["regularize", input.to_str().unwrap(), "-o", "x.ply", "-q"];
        a.extend_from_slice(bad);
        let out = voxreg(&a);
        assert!(!out.status.success(), "{bad:?}");
    }
}

#[test]
fn no_clamp_is_faster_but_may_self_intersect() {
    let dir = tempfile::tempdir().unwrap();
    let ply = dir.path().join("fire.ply");
    let input = data("extended.vox");
    let out =
        voxreg(&["regularize", input.to_str().unwrap(), "-o", ply.to_str().unwrap(), "-q", "--no-clamp"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let mesh = read_mesh(&ply).unwrap();
    assert!(!self_intersections(&mesh.positions, &mesh.quads).is_empty());
    let out = voxreg(&["check", ply.to_str().unwrap()]);
    assert!(!out.status.success() && stderr(&out).contains("self-intersections"));
    // --no-clamp and --clamp contradict each other.
    let out = voxreg(&["regularize", input.to_str().unwrap(), "-o", "x.ply", "--no-clamp", "--clamp"]);
    assert!(!out.status.success());
}

#[test]
fn upscale_doubles_a_model_that_round_trips_through_dot_vox() {
    let dir = tempfile::tempdir().unwrap();
    let vox = dir.path().join("army2.vox");
    let input = data("chr_army1.vox");
    let out =
        voxreg(&["upscale", input.to_str().unwrap(), "--factor", "2", "-o", vox.to_str().unwrap(), "-q"]);
    assert!(out.status.success(), "{}", stderr(&out));

    let source = dot_vox::load(input.to_str().unwrap()).unwrap();
    let fine = dot_vox::load(vox.to_str().unwrap()).unwrap();
    let (s, f) = (&source.models[0], &fine.models[0]);
    assert_eq!([f.size.x, f.size.y, f.size.z], [2 * s.size.x, 2 * s.size.y, 2 * s.size.z]);
    // The fine model uses the source's colours only, with the same palette entries.
    let used = |m: &dot_vox::Model| m.voxels.iter().map(|v| v.i).collect::<std::collections::BTreeSet<u8>>();
    assert!(used(f).is_subset(&used(s)) && !used(f).is_empty());
    for i in used(f) {
        assert_eq!(fine.palette[i as usize], source.palette[i as usize], "colour {i}");
    }
    // About 8 times the voxels (the smooth surface gains and loses a little).
    let ratio = f.voxels.len() as f64 / (8 * s.voxels.len()) as f64;
    assert!((0.8..1.2).contains(&ratio), "fine/source volume ratio {ratio}");

    // Through voxreg's reader too, at half the spacing... of the same physical size.
    let out = voxreg(&["info", vox.to_str().unwrap()]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(String::from_utf8_lossy(&out.stdout).contains("dimensions: 16 x 14 x 24"));

    // Bad requests are clear errors that write nothing.
    let bad = dir.path().join("bad.vox");
    for (args, message) in [(vec!["--factor", "0"], "--factor 0"), (vec!["--factor", "17"], "--factor 17")] {
        let mut all = vec!["upscale", input.to_str().unwrap(), "-o", bad.to_str().unwrap()];
        all.extend(args);
        let out = voxreg(&all);
        assert!(!out.status.success() && stderr(&out).contains(message), "{}", stderr(&out));
        assert!(!bad.exists());
    }
    let out = voxreg(&["upscale", input.to_str().unwrap(), "-o", dir.path().join("x.obj").to_str().unwrap()]);
    assert!(!out.status.success() && stderr(&out).contains("expected .vox or .vol"));
}

#[test]
fn every_model_of_a_file_without_a_scene_graph_opens() {
    // Animation frames: two models and no scene graph. Model 0 by default, --model K picks
    // another, voxreg info lists them.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("frames.vox");
    let model = |n: u8| dot_vox::Model {
        size: dot_vox::Size { x: u32::from(n), y: 1, z: 1 },
        voxels: (0..n).map(|x| dot_vox::Voxel { x, y: 0, z: 0, i: 1 }).collect(),
    };
    let frames = dot_vox::DotVoxData {
        version: 150,
        index_map: dot_vox::DEFAULT_INDEX_MAP.to_vec(),
        models: vec![model(2), model(3)],
        palette: dot_vox::DEFAULT_PALETTE.to_vec(),
        materials: Vec::new(),
        scenes: Vec::new(),
        layers: Vec::new(),
    };
    frames.write_vox(&mut std::fs::File::create(&path).unwrap()).unwrap();
    let info = |extra: &[&str]| {
        let mut args = vec!["info", path.to_str().unwrap()];
        args.extend(extra);
        let out = voxreg(&args);
        assert!(out.status.success(), "{}", stderr(&out));
        String::from_utf8_lossy(&out.stdout).into_owned()
    };
    let text = info(&[]);
    assert!(
        text.contains("dimensions: 2 x 1 x 1") && text.contains("models: 2\n  0: 2 x 1 x 1\n  1: 3 x 1 x 1"),
        "{text}"
    );
    assert!(info(&["--model", "1"]).contains("dimensions: 3 x 1 x 1"));
    let obj = dir.path().join("frame1.obj");
    let out =
        voxreg(&["regularize", path.to_str().unwrap(), "--model", "1", "-o", obj.to_str().unwrap(), "-q"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let out = voxreg(&["info", path.to_str().unwrap(), "--model", "2"]);
    assert!(!out.status.success() && stderr(&out).contains("model 2 does not exist"), "{}", stderr(&out));
    let out = voxreg(&["info", data("cat10.vol").to_str().unwrap(), "--model", "1"]);
    assert!(
        !out.status.success() && stderr(&out).contains("--model applies to MagicaVoxel"),
        "{}",
        stderr(&out)
    );
}

/// The clamped solve's active-set rounds reach the minimizer that MPRGP alone reaches
/// from the projected unconstrained minimizer, on bundled models: positions within the
/// solvers' tolerance of each other (both run to an estimated 1e-5 voxel), the same
/// energy, and every vertex in its box.
#[test]
fn the_active_set_rounds_reach_mprgps_minimizer() {
    use voxreg_regularize::{Energy, Params, Regularizer};
    for name in ["chr_army1.vox", "veh_fire.vox", "extended.vox"] {
        let loaded = read_voxels(&data(name)).unwrap();
        let Voxels::Labels(volume) = loaded.voxels else { panic!("{name}: .vox models are labels") };
        let mut params = Params::voxel_art();
        // The minimizers themselves, before the fold-free pass, to a tolerance tight
        // enough that the two solvers' stopping points cannot differ by more than the
        // assertion's margin.
        params.fold_free = false;
        params.solver.bounded.tolerance = 1e-5;
        let mut r = Regularizer::from_volume(&volume, &params.regions).unwrap();
        let fast = r.run(&params).unwrap();
        let mut old = params.clone();
        old.solver.bounded.active_set_rounds = 0;
        let slow = r.run(&old).unwrap();
        let far =
            fast.positions.iter().zip(&slow.positions).map(|(a, b)| (*a - *b).length()).fold(0.0, f64::max);
        assert!(far <= 1e-3, "{name}: the two minimizers are {far} voxel apart");
        let energy = Energy::new(r.surface(), &fast.normals, &fast.targets, params.energy).unwrap();
        let (ef, es) = (energy.terms(&fast.positions).total, energy.terms(&slow.positions).total);
        assert!((ef - es).abs() <= 1e-5 * es, "{name}: energies {ef} and {es}");
        let half = 0.5 * (1.0 - params.mode.clamped().unwrap().margin) + 1e-12;
        let input = r.surface().positions();
        assert!(fast.positions.iter().zip(&input).all(|(p, q)| (*p - *q).abs().max_element() <= half));
    }
}
