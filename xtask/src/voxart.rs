//! `cargo xtask voxart`: voxel art's targets measured per model (the table of
//! docs/accuracy.md), and `cargo xtask gallery`: every bundled model rendered before and
//! after (docs/gallery/).

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use glam::DVec3;
use voxreg_baselines::Mesh;
use voxreg_digisurf::LabelVolume;
use voxreg_io::{read_volume, QuadMesh};
use voxreg_quality::{
    angle_report, check, mean_adjacent_angle_deg, solid_report, AngleReport, Occupancy, SolidReport,
};
use voxreg_regularize::{Output, Params, Regularizer};
use voxreg_render::{Camera, Image, Shading};

use crate::figures::{grid, panel, Shot};

/// The bundled MagicaVoxel models.
pub(crate) use voxreg_testkit::BUNDLED_VOX_MODELS as MODELS;

/// The solid voxels of `volume` (every label but the background).
pub(crate) fn occupancy(volume: &LabelVolume) -> Occupancy {
    let bg = volume.background();
    let labels = volume.labels();
    Occupancy::from_fn(volume.dims(), volume.origin(), volume.spacing(), |v| Some(labels[v]) != bg)
}

/// One model's figures.
pub(crate) struct Row {
    pub(crate) name: String,
    pub(crate) quads: usize,
    pub(crate) seconds: f64,
    pub(crate) solid: SolidReport,
    pub(crate) folded_quads: usize,
    pub(crate) folded_pairs: usize,
    pub(crate) intersections: usize,
    pub(crate) angle_input: f64,
    /// The output's smoothness on and off thin voxels and its angle at the hard edges.
    pub(crate) angles: AngleReport,
}

/// Runs `params` on the model at `path` and measures it.
pub(crate) fn measure(path: &Path, params: &Params) -> Result<(Row, Output, voxreg_io::LoadedVolume)> {
    let loaded = read_volume(path).with_context(|| format!("reading {}", path.display()))?;
    let t = Instant::now();
    let mut r = Regularizer::from_volume(&loaded.volume, &params.regions)?;
    let out = r.run(params)?;
    let seconds = t.elapsed().as_secs_f64();
    let surface = out.surface.clone();
    let quads = QuadMesh::from_surface(&surface, &surface.positions()).quads;
    let input = surface.positions();
    let report = check(&out.positions, &quads);
    let occ = occupancy(&loaded.volume);
    let angles = angle_report(&input, &out.positions, &quads, &occ.thin_quads(&input, &quads));
    let row = Row {
        name: path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default(),
        quads: quads.len(),
        seconds,
        solid: solid_report(&occ, &out.positions, &quads),
        folded_quads: report.folded_quads,
        folded_pairs: report.folded_pairs,
        intersections: report.intersecting_pairs,
        angle_input: mean_adjacent_angle_deg(&input, &quads),
        angles,
    };
    Ok((row, out, loaded))
}

/// The voxel-art preset before thin parts kept their depth: uniform clamping boxes, no
/// fold removal, ii normals of the multigrid rule's radius (3 voxels), `gamma = 0.1`.
pub(crate) fn former_default() -> Params {
    let mut p = Params::voxel_art();
    p.mode.clamped_mut().expect("the preset clamps").thin_depth = None;
    p.fold_free = false;
    p.normals.radius_voxels = None;
    p.energy.gamma = Params::ENERGY.gamma;
    p
}

fn model_paths(files: &[String]) -> Vec<PathBuf> {
    if files.is_empty() {
        MODELS.iter().map(|m| crate::root().join("data").join(m)).collect()
    } else {
        files.iter().map(PathBuf::from).collect()
    }
}

/// `cargo xtask voxart [--former] [--smoothness S] [FILE...]`: the table of voxel art's
/// targets (options apply in order: `--former` first, then the others on top).
pub(crate) fn voxart(args: &[String]) -> Result<()> {
    let mut params = Params::voxel_art();
    let mut files = Vec::new();
    let mut it = args.iter();
    while let Some(a) = it.next() {
        match a.as_str() {
            "--smoothness" => {
                let s: f64 = it.next().context("--smoothness needs a number")?.parse()?;
                params = params.with_smoothness(s)?;
            }
            "--no-clamp" => params.mode = params.mode.unclamped(),
            // The parts of the preset, one at a time (for the design record's comparisons).
            "--thin-depth" => {
                let d = it.next().context("--thin-depth needs a number or none")?;
                let depth = if d == "none" { None } else { Some(d.parse()?) };
                params.mode.clamped_mut().context("--thin-depth needs the boxes")?.thin_depth = depth;
            }
            "--no-unfold" => params.fold_free = false,
            "--former" => params = former_default(),
            "--alpha" => params.energy.alpha = it.next().context("--alpha needs a number")?.parse()?,
            "--gamma" => params.energy.gamma = it.next().context("--gamma needs a number")?.parse()?,
            "--normals" => {
                params.normals.estimator = match it.next().map(String::as_str) {
                    Some("at") => voxreg_regularize::Estimator::At,
                    Some("ii") => voxreg_regularize::Estimator::Ii,
                    Some("convolved") => voxreg_regularize::Estimator::Convolved,
                    _ => bail!("--normals needs at, ii or convolved"),
                }
            }
            "--radius" => {
                params.normals.radius = Some(it.next().context("--radius needs a number")?.parse()?)
            }
            other if other.starts_with("--") => bail!("unknown option {other}"),
            other => files.push(other.to_string()),
        }
    }
    println!(
        "| model | quads | solid centres outside | empty centres inside | thin voxels | thin < 0.25 deep | \
         thinnest depth | folded quads | folded pairs | intersecting pairs | mean angle: voxels, output | \
         output's mean angle: pairs with a thin voxel's quad, others | hard edges: mean angle (edges) | time |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    for path in model_paths(&files) {
        let (r, _, _) = measure(&path, &params)?;
        let s = &r.solid;
        println!(
            "| {} | {} | {} / {} | {} / {} | {} | {} | {:.3} | {} | {} | {} | {:.1}, {:.2} deg | {:.1} deg ({}), {:.1} deg ({}) | {:.1} deg ({}) | {:.2} s |",
            r.name,
            r.quads,
            s.solid_outside,
            s.solid_surface_voxels,
            s.empty_inside,
            s.empty_surface_voxels,
            s.thin_voxels,
            s.thin_shallow,
            s.thin_min_depth,
            r.folded_quads,
            r.folded_pairs,
            r.intersections,
            r.angle_input,
            r.angles.mean,
            r.angles.thin.0,
            r.angles.thin.1,
            r.angles.elsewhere.0,
            r.angles.elsewhere.1,
            r.angles.hard_edges.0,
            r.angles.hard_edges.1,
            r.seconds
        );
    }
    Ok(())
}

/// The quads' palette colours (grey without a palette).
fn colours(loaded: &voxreg_io::LoadedVolume, out: &Output) -> Vec<[u8; 3]> {
    crate::figures::palette_colours(loaded.palette.as_ref(), &out.surface, &out.positions)
        .unwrap_or_else(|| vec![[200, 200, 200]; out.surface.num_surfels()])
}

/// `cargo xtask gallery [--out DIR]`: every bundled model as voxels, with the former
/// default ([`former_default`]), the default and `--smoothness 0.3`, from two
/// views, in `docs/gallery/` (one PNG per model) with the measurements in
/// `docs/gallery/README.md`.
pub(crate) fn gallery(args: &[String]) -> Result<()> {
    let mut out_dir = crate::root().join("docs/gallery");
    let mut it = args.iter();
    while let Some(a) = it.next() {
        match a.as_str() {
            "--out" => out_dir = PathBuf::from(it.next().context("--out needs a folder")?),
            other => bail!("unknown argument {other}; usage: cargo xtask gallery [--out DIR]"),
        }
    }
    std::fs::create_dir_all(&out_dir).with_context(|| format!("creating {}", out_dir.display()))?;
    let former = former_default();
    let variants: [(&str, Params); 4] = [
        ("voxels", Params::voxel_art()),
        ("before: uniform boxes", former),
        ("default", Params::voxel_art()),
        ("--smoothness 0.3", Params::voxel_art().with_smoothness(0.3)?),
    ];
    let mut md = String::from(
        "# Gallery\n\nEvery bundled MagicaVoxel model (`data/`), made by `cargo xtask gallery`: the voxels; the \
         former default (uniform clamping boxes, no fold removal, ii radius 3, gamma 0.1: thin parts collapse, \
         some quads fold); \
         voxreg's output with the default options; and with `--smoothness 0.3`; from two views, in the \
         palette's colours.\n\n",
    );
    for path in model_paths(&[]) {
        let name = path.file_stem().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        let mut rows: Vec<(String, Vec<Image>)> = Vec::new();
        let mut cameras = Vec::new();
        let mut columns: Vec<Vec<Image>> = vec![Vec::new(), Vec::new()];
        let mut default_row = None;
        for (k, (caption, params)) in variants.iter().enumerate() {
            let (row, out, loaded) = measure(&path, params)?;
            let c = colours(&loaded, &out);
            let input = out.surface.positions();
            if cameras.is_empty() {
                let (lo, hi) = input
                    .iter()
                    .fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(a, b), p| (a.min(*p), b.max(*p)));
                cameras.push(Camera::fit(lo, hi, DVec3::new(-0.6, 0.75, -0.3), DVec3::Z));
                cameras.push(Camera::fit(lo, hi, DVec3::new(0.6, -0.75, -0.3), DVec3::Z));
            }
            let positions = if k == 0 { input.to_vec() } else { out.positions.to_vec() };
            let shot = Shot {
                caption: caption.to_string(),
                mesh: Mesh::from_surface(&out.surface, &positions),
                colours: Some(c),
                shading: Shading::Flat,
                wireframe: false,
            };
            for (v, cam) in cameras.iter().enumerate() {
                columns[v].push(panel(&shot, cam));
            }
            if k == 2 {
                default_row = Some(row);
            }
        }
        for (v, col) in columns.into_iter().enumerate() {
            rows.push((format!("view {}", v + 1), col));
        }
        let img = grid(&name, &rows);
        let file = format!("{name}.png");
        img.write_png(&out_dir.join(&file)).with_context(|| format!("writing {file}"))?;
        let r = default_row.expect("the default ran");
        md.push_str(&format!(
            "## {name}\n\n![{name}]({file})\n\n{} quads; default: {} folded quads, {} folded pairs, {} intersecting \
             pairs, thinnest voxel {:.2} deep, mean angle between adjacent quads {:.1} deg (voxels {:.1}).\n\n",
            r.quads, r.folded_quads, r.folded_pairs, r.intersections, r.solid.thin_min_depth, r.angles.mean, r.angle_input
        ));
        eprintln!("{name}: done");
    }
    std::fs::write(out_dir.join("README.md"), md)?;
    Ok(())
}
