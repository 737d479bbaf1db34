//! `cargo xtask figures`: the papers' figures, rendered with `voxreg-render` and charted
//! with plotters, into one folder (default `target/xtask/figures/`) with an `index.html`.
//!
//! - Fig. 4: distance to the input, `|p* - p|_inf` in voxels, without and with clamping.
//! - Fig. 7: the ball united with a tetrahedron at 10^3, 20^3, 40^3, every method side by
//!   side, plus accuracy and quality curves against the resolution.
//! - Fig. 8: a larger shape (the bundled bunny): input, Shrouds, voxreg.
//! - Fig. 9: histograms of the face aspect ratio and area: Shrouds, voxreg without the
//!   fairness term, voxreg.
//! - Fig. 10: a multi-label volume, one colour per interface.
//! - Fig. 11: voxel art with its palette colours.
//! - Figs. 12-14 (`figures/extensions.rs`): exact geodesics on the digital surface and on
//!   the regularized proxy; upscaling; texture-aware fairness.
//! - Fig. 15: the ablation grid, each energy term switched off in turn.
//!
//! Deterministic: fixed cameras, single-threaded rendering, no timing in any file; the
//! same checkout writes the same bytes. `--quick` uses smaller inputs (a few seconds).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{anyhow, Context, Result};
use glam::DVec3;
use plotters::prelude::*;
use voxreg_baselines::{
    accuracy, face_aspect_ratio, marching_cubes_volume, quality, shrouds, taubin_smooth, Mesh, QualityParams,
    ShroudsParams, TaubinParams,
};
use voxreg_digisurf::{DigitalSurface, LabelVolume, RegionMap};
use voxreg_io::{read_volume, QuadMesh};
use voxreg_normals::{IntegralInvariant, NormalEstimator, NormalField};
use voxreg_quality::self_intersections;
use voxreg_regularize::{EnergyParams, Params, Regularizer, Run, SolveInfo, SolverChoice, SolverParams};
use voxreg_render::{render, viridis, Camera, Image, RenderParams, Shading};
use voxreg_testkit::{digitize, Shape};

use crate::compare::BallTet;

mod extensions;

/// Panel size in pixels (square).
const PANEL: u32 = 280;
/// Meshes with more faces are drawn without wireframe.
const MAX_WIRED_FACES: usize = 2500;
/// Height of a panel's caption band.
const CAPTION: u32 = 22;
const TEXT: [u8; 3] = [20, 20, 20];
/// Clamping of Fig. 4, in voxels (`DescentParams::clamp`).
const CLAMP_EPS: f64 = 0.1;

/// One rendered mesh: geometry, optional per-face colours, and a caption.
pub(crate) struct Shot {
    pub(crate) caption: String,
    pub(crate) mesh: Mesh,
    pub(crate) colours: Option<Vec<[u8; 3]>>,
    pub(crate) shading: Shading,
    pub(crate) wireframe: bool,
}

impl Shot {
    fn new(caption: impl Into<String>, mesh: Mesh) -> Shot {
        Shot { caption: caption.into(), mesh, colours: None, shading: Shading::Flat, wireframe: true }
    }
}

/// A fixed camera for a volume's shapes: its bounding box seen from above-front-right.
fn camera_for(min: DVec3, max: DVec3) -> Camera {
    Camera::fit(min, max, DVec3::new(-0.55, -0.8, -0.45), DVec3::Z)
}

/// The bunny volumes have -y up: a side view from slightly above.
fn bunny_camera(min: DVec3, max: DVec3) -> Camera {
    Camera::fit(min, max, DVec3::new(0.3, 0.35, 1.0), DVec3::NEG_Y)
}

fn bounds(points: &[DVec3]) -> (DVec3, DVec3) {
    points.iter().fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(lo, hi), p| (lo.min(*p), hi.max(*p)))
}

/// Renders `shot` into a captioned panel of `PANEL x (PANEL + CAPTION)` pixels.
pub(crate) fn panel(shot: &Shot, camera: &Camera) -> Image {
    let params = RenderParams {
        width: PANEL,
        height: PANEL,
        shading: shot.shading,
        // Wires closer than a few pixels apart only darken the panel.
        wireframe: (shot.wireframe && shot.mesh.num_faces() <= MAX_WIRED_FACES).then_some([70, 70, 75]),
        wire_width: 0.5,
        ..RenderParams::default()
    };
    let img = render(&shot.mesh.positions, shot.mesh.faces(), shot.colours.as_deref(), camera, &params);
    let mut out = Image::new(PANEL, PANEL + CAPTION, [255; 3]);
    out.draw_text_centred(PANEL as f32 / 2.0, 3.0, 14.0, TEXT, &shot.caption);
    out.blit(&img, 0, i64::from(CAPTION));
    out
}

/// A captioned panel saying why a method has no result here.
fn empty_panel(caption: &str, why: &str) -> Image {
    let mut out = Image::new(PANEL, PANEL + CAPTION, [255; 3]);
    out.draw_text_centred(PANEL as f32 / 2.0, 3.0, 14.0, TEXT, caption);
    out.fill_rect(8, i64::from(CAPTION) + 8, PANEL - 16, PANEL - 16, [240, 240, 240]);
    out.draw_text_centred(PANEL as f32 / 2.0, (CAPTION + PANEL / 2 - 8) as f32, 13.0, [90, 90, 90], why);
    out
}

/// Lays out rows of equally sized panels under a title, each row with a label on its left.
pub(crate) fn grid(title: &str, rows: &[(String, Vec<Image>)]) -> Image {
    let label_w = if rows.iter().any(|(l, _)| !l.is_empty()) { 70 } else { 0 };
    let (pw, ph) = (PANEL, PANEL + CAPTION);
    let cols = rows.iter().map(|(_, r)| r.len()).max().unwrap_or(0) as u32;
    let top = 30;
    let mut out = Image::new(label_w + cols * pw, top + rows.len() as u32 * ph, [255; 3]);
    out.draw_text(8.0, 6.0, 17.0, TEXT, title);
    for (i, (label, images)) in rows.iter().enumerate() {
        let y = i64::from(top + i as u32 * ph);
        out.draw_text(6.0, (y + i64::from(ph) / 2 - 8) as f32, 15.0, TEXT, label);
        for (j, img) in images.iter().enumerate() {
            out.blit(img, i64::from(label_w + j as u32 * pw), y);
        }
    }
    out
}

/// The figures written so far, for the index page.
struct Index {
    dir: PathBuf,
    entries: Vec<(String, String, String)>,
}

impl Index {
    fn add_png(&mut self, file: &str, title: &str, caption: String, image: &Image) -> Result<()> {
        let path = self.dir.join(file);
        image.write_png(&path).with_context(|| format!("writing {}", path.display()))?;
        eprintln!("wrote {}", path.display());
        self.entries.push((file.to_string(), title.to_string(), caption));
        Ok(())
    }

    fn write(&self, quick: bool) -> Result<()> {
        let mut html = String::from(
            "<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>voxreg figures</title>\n\
             <style>body{font-family:sans-serif;max-width:1400px;margin:auto}img{max-width:100%;border:1px solid #ddd}</style>\n\
             </head><body>\n<h1>voxreg: the papers' figures</h1>\n",
        );
        let _ = writeln!(
            html,
            "<p>Written by <code>cargo xtask figures{}</code>. Default weights alpha = 1e-3, beta = 1, \
             gamma = 0.1; integral-invariant normals with the default radius; exact solves unless said. \
             Faces seen from behind are tinted red (folds).</p>\n<ul>",
            if quick { " --quick" } else { "" }
        );
        for (file, title, _) in &self.entries {
            let _ = writeln!(html, "<li><a href=\"#{file}\">{title}</a></li>");
        }
        html.push_str("</ul>\n");
        for (file, title, caption) in &self.entries {
            let _ = writeln!(
                html,
                "<h2 id=\"{file}\">{title}</h2>\n<p>{caption}</p>\n<p><img src=\"{file}\" alt=\"{title}\"></p>"
            );
        }
        html.push_str("</body></html>\n");
        let path = self.dir.join("index.html");
        std::fs::write(&path, html).with_context(|| format!("writing {}", path.display()))
    }
}

fn ii_normals(surface: &DigitalSurface) -> Result<NormalField> {
    Ok(IntegralInvariant::default().estimate(surface)?)
}

/// The papers' single exact solve from `normals` with the weights `params`.
fn voxreg(surface: &DigitalSurface, normals: &NormalField, params: EnergyParams) -> Result<Vec<DVec3>> {
    let mut p = Params { energy: params, ..Params::papers() };
    p.solver.choice = SolverChoice::Direct;
    Ok(Regularizer::new(surface.clone()).run(Run::new(&p).from_normals(normals))?.positions.into_vec())
}

/// The clamped minimizer (paper, sec. 3.4): every vertex within its box of edge
/// `(1 - eps) h`.
fn voxreg_clamped(surface: &DigitalSurface, normals: &NormalField, eps: f64) -> Result<Vec<DVec3>> {
    // 0.01 voxel is invisible in a figure and takes a third of the iterations of 1e-3.
    let mut p = Params { solver: SolverParams::default().with_tolerance(1e-2), ..Params::papers() };
    p.mode = p.mode.with_margin(eps);
    let t = Instant::now();
    let out = Regularizer::new(surface.clone()).run(Run::new(&p).from_normals(normals))?;
    if let SolveInfo::Bounded(info) = out.report.last_solve() {
        eprintln!(
            "  clamped solve: {} quads, {} iterations, {} clamped vertices, converged {}, {:.1} s",
            surface.num_surfels(),
            info.iterations,
            info.clamped_vertices,
            info.converged,
            t.elapsed().as_secs_f64()
        );
    }
    Ok(out.positions.into_vec())
}

fn quads(surface: &DigitalSurface) -> Vec<[u32; 4]> {
    QuadMesh::from_surface(surface, &surface.positions()).quads
}

/// Runs the figures; `args`: `[--quick] [--out DIR]`.
pub(crate) fn figures(args: &[String]) -> Result<()> {
    let (quick, out) = crate::quick_and_out("figures", args)?;
    plotters::style::register_font("sans-serif", FontStyle::Normal, voxreg_render::FONT_TTF)
        .map_err(|_| anyhow!("the bundled font does not load"))?;
    let start = Instant::now();
    let mut index = Index { dir: out.clone(), entries: Vec::new() };
    let timed = |what: &str, f: &mut dyn FnMut() -> Result<()>| -> Result<()> {
        let t = Instant::now();
        f()?;
        eprintln!("{what}: {:.1} s", t.elapsed().as_secs_f64());
        Ok(())
    };
    let bunny = crate::root().join(if quick { "data/bunny-32.vol" } else { "data/bunny-64.vol" });
    let art = crate::root().join("data/chr_army1.vox");
    timed("fig. 7", &mut || fig7(&mut index, quick))?;
    timed("figs. 8, 9", &mut || fig8_9(&mut index, &bunny))?;
    // The clamped descent needs thousands of iterations: Fig. 4 stays on the small bunny.
    let small_bunny = crate::root().join("data/bunny-32.vol");
    timed("fig. 4", &mut || fig4(&mut index, &small_bunny))?;
    timed("fig. 10", &mut || fig10(&mut index, quick))?;
    timed("figs. 11, 15", &mut || fig11_15(&mut index, &art))?;
    timed("fig. 12", &mut || extensions::fig12(&mut index, &bunny))?;
    // Upscaling the 64^3 bunny to 256^3 and 512^3 (quick: the 32^3 one to 128^3, 256^3).
    timed("fig. 13", &mut || extensions::fig13(&mut index, &bunny, &[4, 8]))?;
    timed("fig. 14", &mut || extensions::fig14(&mut index, &art))?;
    index.write(quick)?;
    eprintln!(
        "wrote {} figures and index.html to {} in {:.1} s",
        index.entries.len(),
        out.display(),
        start.elapsed().as_secs_f64()
    );
    Ok(())
}

/// Metrics of one method at one resolution, for the Fig. 7 curves.
struct Point {
    method: &'static str,
    n: usize,
    normal_mean_deg: f64,
    aspect_mean: f64,
}

fn fig7(index: &mut Index, quick: bool) -> Result<()> {
    let shape = BallTet::new();
    let ns: &[usize] = if quick { &[10, 20] } else { &[10, 20, 40] };
    let mut rows = Vec::new();
    let mut points = Vec::new();
    for &n in ns {
        let h = 20.0 / n as f64;
        let volume = digitize(&shape, h);
        let surface = DigitalSurface::from_volume(&volume)?;
        let input = surface.positions();
        let (lo, hi) = bounds(&input);
        let camera = camera_for(lo, hi);
        let normals = ii_normals(&surface)?;
        let mc = marching_cubes_volume(&volume, |l| l == 1);
        let mut shots: Vec<(&'static str, Option<Shot>, &'static str)> = vec![
            ("input", Some(Shot::new("digital surface", Mesh::from_surface(&surface, &input))), ""),
            ("marching cubes", Some(Shot::new("marching cubes", mc.clone())), ""),
            ("MC + Taubin", Some(Shot::new("MC + Taubin", taubin_smooth(&mc, &TaubinParams::default()))), ""),
        ];
        match shrouds(&surface, &ShroudsParams::default()) {
            Ok((mesh, _)) => shots.push(("shrouds", Some(Shot::new("Shrouds", mesh)), "")),
            Err(_) => shots.push(("shrouds", None, "non-manifold input")),
        }
        let x = voxreg(&surface, &normals, EnergyParams::default())?;
        shots.push(("voxreg (ii)", Some(Shot::new("voxreg (ii)", Mesh::from_surface(&surface, &x))), ""));
        let xc = voxreg_clamped(&surface, &normals, CLAMP_EPS)?;
        shots.push((
            "voxreg (ii) clamped",
            Some(Shot::new("voxreg (ii), clamped", Mesh::from_surface(&surface, &xc))),
            "",
        ));
        let mut images = Vec::new();
        for (method, shot, why) in &shots {
            match shot {
                Some(shot) => {
                    let acc = accuracy(&shot.mesh, &(&shape as &dyn Shape));
                    let q = quality(&shot.mesh, &QualityParams::default());
                    points.push(Point {
                        method,
                        n,
                        normal_mean_deg: acc.normal_mean_deg,
                        aspect_mean: q.aspect_mean,
                    });
                    images.push(panel(shot, &camera));
                }
                None => images.push(empty_panel("Shrouds", why)),
            }
        }
        rows.push((format!("{n}^3"), images));
    }
    let img = grid("Fig. 7: ball united with a tetrahedron, every method (same camera per row)", &rows);
    index.add_png(
        "fig7_ball_tet.png",
        "Fig. 7: ball + tetrahedron at several resolutions",
        "Rows: the shape digitized with 10, 20 (and 40) voxels across. Columns: the input digital surface, \
         marching cubes, MC followed by Taubin smoothing, Shrouds (closed 2-manifold inputs only), voxreg \
         with default weights, and voxreg clamped (eps = 0.1 voxel; descent to 0.01 voxel). Metrics: <code>cargo xtask compare</code>."
            .into(),
        &img,
    )?;
    let chart = fig7_chart(&points, ns)?;
    index.add_png(
        "fig7_curves.png",
        "Fig. 7 (measured): normal error and aspect ratio against the resolution",
        "Area-weighted mean angle between face normals and the true normals, and mean face aspect ratio \
         (Fig. 9's covariance ratio), for each method of Fig. 7."
            .into(),
        &chart,
    )?;
    Ok(())
}

const SERIES: [RGBColor; 6] = [
    RGBColor(120, 120, 120),
    RGBColor(31, 119, 180),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
];

fn fig7_chart(points: &[Point], ns: &[usize]) -> Result<Image> {
    let (w, h) = (900u32, 380u32);
    let mut buf = vec![255u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| anyhow!("{e}"))?;
        let areas = root.split_evenly((1, 2));
        let mut methods: Vec<&str> = Vec::new();
        for p in points {
            if !methods.contains(&p.method) {
                methods.push(p.method);
            }
        }
        let x_range = (*ns.first().unwrap_or(&10) as f64 * 0.9)..(*ns.last().unwrap_or(&40) as f64 * 1.1);
        for (k, area) in areas.iter().enumerate() {
            let (title, value): (&str, fn(&Point) -> f64) = if k == 0 {
                ("normal error, mean (degrees, log scale)", |p| p.normal_mean_deg)
            } else {
                ("face aspect ratio, mean (log scale)", |p| p.aspect_mean)
            };
            // Headroom of a decade above the data for the legend.
            let y_max = points.iter().map(value).fold(1.0f64, f64::max) * 10.0;
            let y_min = if k == 0 { 0.5 } else { 0.8 };
            let mut chart = ChartBuilder::on(area)
                .caption(title, ("sans-serif", 16))
                .margin(10)
                .x_label_area_size(30)
                .y_label_area_size(45)
                .build_cartesian_2d(x_range.clone().log_scale(), (y_min..y_max).log_scale())
                .map_err(|e| anyhow!("{e}"))?;
            chart
                .configure_mesh()
                .light_line_style(WHITE)
                .x_desc("voxels across")
                .x_label_formatter(&|x| format!("{x:.0}"))
                .label_style(("sans-serif", 12))
                .draw()
                .map_err(|e| anyhow!("{e}"))?;
            for (i, m) in methods.iter().enumerate() {
                let colour = SERIES[i % SERIES.len()];
                let data: Vec<(f64, f64)> = points
                    .iter()
                    .filter(|p| p.method == *m)
                    .map(|p| (p.n as f64, value(p).max(0.8)))
                    .collect();
                chart
                    .draw_series(LineSeries::new(data.clone(), colour.stroke_width(2)))
                    .map_err(|e| anyhow!("{e}"))?
                    .label(*m)
                    .legend(move |(x, y)| {
                        PathElement::new(vec![(x, y), (x + 16, y)], colour.stroke_width(2))
                    });
                chart
                    .draw_series(data.iter().map(|&p| Circle::new(p, 3, colour.filled())))
                    .map_err(|e| anyhow!("{e}"))?;
            }
            chart
                .configure_series_labels()
                .background_style(WHITE.mix(0.8))
                .border_style(BLACK)
                .label_font(("sans-serif", 11))
                .position(SeriesLabelPosition::UpperRight)
                .draw()
                .map_err(|e| anyhow!("{e}"))?;
        }
        root.present().map_err(|e| anyhow!("{e}"))?;
    }
    Image::from_rgb(w, h, buf).context("chart buffer size")
}

/// A histogram panel per method, with values clamped to `[0, max]`.
fn histograms(title: &str, series: &[(&str, Vec<f64>)], max: f64, x_desc: &str) -> Result<Image> {
    let (w, h) = (300 * series.len() as u32, 300u32);
    let mut buf = vec![255u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| anyhow!("{e}"))?;
        let root = root.titled(title, ("sans-serif", 16)).map_err(|e| anyhow!("{e}"))?;
        let bins = 25;
        let width = max / bins as f64;
        for (i, (area, (name, values))) in root.split_evenly((1, series.len())).iter().zip(series).enumerate()
        {
            let mut counts = vec![0usize; bins];
            for v in values {
                counts[((v.clamp(0.0, max) / width) as usize).min(bins - 1)] += 1;
            }
            let share: Vec<f64> = counts.iter().map(|&c| c as f64 / values.len().max(1) as f64).collect();
            let y_max = share.iter().cloned().fold(0.0, f64::max) * 1.1 + 1e-9;
            let mut chart = ChartBuilder::on(area)
                .caption(*name, ("sans-serif", 14))
                .margin(8)
                .x_label_area_size(30)
                .y_label_area_size(40)
                .build_cartesian_2d(0.0..max, 0.0..y_max)
                .map_err(|e| anyhow!("{e}"))?;
            chart
                .configure_mesh()
                .light_line_style(WHITE)
                .x_desc(x_desc)
                .y_desc("share of faces")
                .label_style(("sans-serif", 11))
                .draw()
                .map_err(|e| anyhow!("{e}"))?;
            let colour = SERIES[(i + 3) % SERIES.len()];
            chart
                .draw_series(share.iter().enumerate().map(|(k, &s)| {
                    let x0 = k as f64 * width;
                    Rectangle::new([(x0, 0.0), (x0 + width * 0.9, s)], colour.filled())
                }))
                .map_err(|e| anyhow!("{e}"))?;
        }
        root.present().map_err(|e| anyhow!("{e}"))?;
    }
    Image::from_rgb(w, h, buf).context("chart buffer size")
}

fn load(path: &Path) -> Result<(voxreg_io::LoadedVolume, DigitalSurface)> {
    let loaded = read_volume(path).with_context(|| format!("reading {}", path.display()))?;
    // One solid: grey-level volumes (bunny-32) are shapes, not label maps.
    let surface = DigitalSurface::new(&loaded.volume, &RegionMap::single_solid())?;
    Ok((loaded, surface))
}

fn file_name(path: &Path) -> String {
    path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default()
}

fn fig8_9(index: &mut Index, path: &Path) -> Result<()> {
    let (_, surface) = load(path)?;
    let input = surface.positions();
    let (lo, hi) = bounds(&input);
    let camera = bunny_camera(lo, hi);
    let normals = ii_normals(&surface)?;
    let x = voxreg(&surface, &normals, EnergyParams::default())?;
    let x_no_fair = voxreg(&surface, &normals, EnergyParams { gamma: 0.0, ..EnergyParams::default() })?;
    let shrouds_mesh = shrouds(&surface, &ShroudsParams::default()).ok().map(|(m, _)| m);
    let voxreg_mesh = Mesh::from_surface(&surface, &x);
    let mut images =
        vec![panel(&Shot::new("digital surface", Mesh::from_surface(&surface, &input)), &camera)];
    match &shrouds_mesh {
        Some(m) => images.push(panel(&Shot::new("Shrouds", m.clone()), &camera)),
        None => images.push(empty_panel("Shrouds", "non-manifold input")),
    }
    images.push(panel(&Shot::new("voxreg (ii)", voxreg_mesh.clone()), &camera));
    let mut smooth = Shot::new("voxreg, smooth shading", voxreg_mesh.clone());
    (smooth.shading, smooth.wireframe) = (Shading::Smooth, false);
    images.push(panel(&smooth, &camera));
    let name = file_name(path);
    let img = grid(&format!("Fig. 8: {name}, {} quads", surface.num_surfels()), &[(String::new(), images)]);
    index.add_png(
        "fig8_bunny.png",
        "Fig. 8: a larger shape",
        format!("{name}: the digital surface, Shrouds, voxreg (flat with quads, and smooth shading)."),
        &img,
    )?;
    // Fig. 9: aspect ratios (clamped to 5 as in the paper) and areas relative to the mean.
    let per_face = |m: &Mesh| -> (Vec<f64>, Vec<f64>) {
        let aspect = (0..m.num_faces()).map(|f| face_aspect_ratio(m, f)).collect();
        let areas: Vec<f64> = (0..m.num_faces()).map(|f| m.vector_area(f).length()).collect();
        let mean = areas.iter().sum::<f64>() / areas.len().max(1) as f64;
        (aspect, areas.iter().map(|a| a / mean).collect())
    };
    let mut series = Vec::new();
    if let Some(m) = &shrouds_mesh {
        series.push(("Shrouds", per_face(m)));
    }
    series.push(("voxreg, no fairness (gamma = 0)", per_face(&Mesh::from_surface(&surface, &x_no_fair))));
    series.push(("voxreg (gamma = 0.1)", per_face(&voxreg_mesh)));
    let aspect: Vec<(&str, Vec<f64>)> = series.iter().map(|(n, (a, _))| (*n, a.clone())).collect();
    let area: Vec<(&str, Vec<f64>)> = series.iter().map(|(n, (_, r))| (*n, r.clone())).collect();
    let a = histograms(
        &format!("Fig. 9: face aspect ratio on {name} (clamped to 5)"),
        &aspect,
        5.0,
        "aspect ratio",
    )?;
    let b =
        histograms(&format!("face area / mean area on {name} (clamped to 3)"), &area, 3.0, "area / mean")?;
    let mut both = Image::new(a.width(), a.height() + b.height(), [255; 3]);
    both.blit(&a, 0, 0);
    both.blit(&b, 0, i64::from(a.height()));
    let summary: Vec<String> = series
        .iter()
        .map(|(n, (a, _))| {
            let over = a.iter().filter(|&&x| x > 5.0).count();
            format!("{n}: {over} of {} faces with aspect > 5", a.len())
        })
        .collect();
    index.add_png(
        "fig9_histograms.png",
        "Fig. 9: face quality histograms",
        format!(
            "Aspect ratio (largest over second eigenvalue of the face vertices' covariance) and face area \
             relative to the mean, on {name}. {}.",
            summary.join("; ")
        ),
        &both,
    )
}

/// Draws a horizontal colour bar from 0 to `max` under `label`.
fn colour_bar(width: u32, max: f64, label: &str) -> Image {
    let mut img = Image::new(width, 46, [255; 3]);
    let (x0, w) = (20i64, width as i64 - 40);
    for x in 0..w {
        img.fill_rect(x0 + x, 4, 1, 14, viridis(x as f64 / (w - 1) as f64));
    }
    img.draw_text(x0 as f32, 22.0, 12.0, TEXT, "0");
    let right = format!("{max:.2}");
    img.draw_text((x0 + w) as f32 - Image::text_width(&right, 12.0), 22.0, 12.0, TEXT, &right);
    img.draw_text_centred(width as f32 / 2.0, 22.0, 12.0, TEXT, label);
    img
}

fn fig4(index: &mut Index, path: &Path) -> Result<()> {
    let (_, surface) = load(path)?;
    let input = surface.positions();
    let (lo, hi) = bounds(&input);
    let camera = bunny_camera(lo, hi);
    let normals = ii_normals(&surface)?;
    let free = voxreg(&surface, &normals, EnergyParams::default())?;
    let clamped = voxreg_clamped(&surface, &normals, CLAMP_EPS)?;
    let h = surface.spacing();
    let linf = |x: &[DVec3]| -> Vec<f64> {
        x.iter().zip(&input).map(|(a, b)| ((*a - *b) / h).abs().max_element()).collect()
    };
    let (d_free, d_clamped) = (linf(&free), linf(&clamped));
    let max = d_free.iter().chain(&d_clamped).cloned().fold(0.0, f64::max).max(1e-9);
    let quads = quads(&surface);
    let face_colours = |d: &[f64]| -> Vec<[u8; 3]> {
        quads.iter().map(|q| viridis(q.iter().map(|&v| d[v as usize]).sum::<f64>() / (4.0 * max))).collect()
    };
    let count = |x: &[DVec3]| self_intersections(x, &quads).len();
    let (si_free, si_clamped) = (count(&free), count(&clamped));
    let shot = |caption: String, x: &[DVec3], d: &[f64]| Shot {
        caption,
        mesh: Mesh::from_surface(&surface, x),
        colours: Some(face_colours(d)),
        shading: Shading::Flat,
        wireframe: false,
    };
    let images = vec![
        panel(&Shot::new("digital surface", Mesh::from_surface(&surface, &input)), &camera),
        panel(
            &shot(
                format!("unclamped: max {:.2}", d_free.iter().cloned().fold(0.0, f64::max)),
                &free,
                &d_free,
            ),
            &camera,
        ),
        panel(
            &shot(
                format!("clamped eps {CLAMP_EPS}: max {:.2}", d_clamped.iter().cloned().fold(0.0, f64::max)),
                &clamped,
                &d_clamped,
            ),
            &camera,
        ),
    ];
    let name = file_name(path);
    let grid_img = grid(&format!("Fig. 4: |p* - p|_inf in voxels on {name}"), &[(String::new(), images)]);
    let bar = colour_bar(grid_img.width(), max, "distance to the input vertex, L-inf, voxels");
    let mut img = Image::new(grid_img.width(), grid_img.height() + bar.height(), [255; 3]);
    img.blit(&grid_img, 0, 0);
    img.blit(&bar, 0, i64::from(grid_img.height()));
    index.add_png(
        "fig4_clamping.png",
        "Fig. 4: distance to the input, without and with clamping",
        format!(
            "{name}: per-face mean of the vertices' L-inf displacement in voxels. Clamping (eps = {CLAMP_EPS}) keeps \
             every vertex within (1 - eps) / 2 = {:.2} voxel of its input per axis, so no two quads intersect \
             (Proposition 2). Self-intersecting quad pairs: {si_free} unclamped, {si_clamped} clamped.",
            (1.0 - CLAMP_EPS) / 2.0
        ),
        &img,
    )
}

/// Distinct colours for interfaces and labels.
fn palette(i: usize) -> [u8; 3] {
    const P: [[u8; 3]; 8] = [
        [230, 159, 0],
        [86, 180, 233],
        [0, 158, 115],
        [240, 228, 66],
        [0, 114, 178],
        [213, 94, 0],
        [204, 121, 167],
        [160, 160, 160],
    ];
    P[i % P.len()]
}

fn fig10(index: &mut Index, quick: bool) -> Result<()> {
    // Three materials in a background: two balls side by side fused at their contact, and
    // a slab under them; interfaces between the materials meet along junction curves.
    let n = if quick { 20 } else { 32 };
    let s = n as f64 / 32.0;
    let volume = LabelVolume::from_fn([n, n, n], |[x, y, z]| {
        let p = DVec3::new(x as f64, y as f64, z as f64) / s;
        if (p - DVec3::new(11.0, 16.0, 15.0)).length() < 8.0 {
            1
        } else if (p - DVec3::new(21.0, 16.0, 15.0)).length() < 7.5 {
            2
        } else if p.z > 4.0 && p.z < 10.0 && (4.0..28.0).contains(&p.x) && (6.0..26.0).contains(&p.y) {
            3
        } else {
            0
        }
    });
    let surface = DigitalSurface::from_volume(&volume)?;
    let input = surface.positions();
    let (lo, hi) = bounds(&input);
    let camera = camera_for(lo, hi);
    let normals = ii_normals(&surface)?;
    let x = voxreg(&surface, &normals, EnergyParams::default())?;
    let qm = QuadMesh::from_surface(&surface, &input);
    let mut pairs: Vec<[u32; 2]> = qm.face_labels.clone();
    pairs.sort_unstable();
    pairs.dedup();
    let colours: Vec<[u8; 3]> =
        qm.face_labels.iter().map(|l| palette(pairs.binary_search(l).unwrap_or(0))).collect();
    let shot = |caption: &str, x: &[DVec3]| Shot {
        caption: caption.into(),
        mesh: Mesh::from_surface(&surface, x),
        colours: Some(colours.clone()),
        shading: Shading::Flat,
        wireframe: true,
    };
    let images =
        vec![panel(&shot("digital surface", &input), &camera), panel(&shot("voxreg (ii)", &x), &camera)];
    let img = grid(
        &format!("Fig. 10: three labels in a {n}^3 volume, one colour per interface"),
        &[(String::new(), images)],
    );
    index.add_png(
        "fig10_multilabel.png",
        "Fig. 10: multi-label interfaces",
        format!(
            "Two fused balls and a slab (labels 1, 2, 3) in background: {} interfaces, {} quads; the \
             junction curves where three regions meet stay shared by their interfaces.",
            pairs.len(),
            surface.num_surfels()
        ),
        &img,
    )
}

/// Each quad's colour from `palette` (its material's, as the writers give it), where there
/// is a palette.
pub(crate) fn palette_colours(
    palette: Option<&voxreg_io::Palette>,
    surface: &DigitalSurface,
    positions: &[DVec3],
) -> Option<Vec<[u8; 3]>> {
    let mut qm = QuadMesh::from_surface(surface, positions);
    qm.assign_materials(palette?);
    Some(
        qm.face_materials
            .iter()
            .map(|&m| {
                let c = qm.materials[m as usize].color;
                [c[0], c[1], c[2]]
            })
            .collect(),
    )
}

fn fig11_15(index: &mut Index, path: &Path) -> Result<()> {
    let (loaded, surface) = load(path)?;
    let input = surface.positions();
    let (lo, hi) = bounds(&input);
    let camera = Camera::fit(lo, hi, DVec3::new(-0.6, 0.75, -0.3), DVec3::Z);
    let colours = palette_colours(loaded.palette.as_ref(), &surface, &input);
    let normals = ii_normals(&surface)?;
    let shot = |caption: &str, x: &[DVec3], wire: bool| Shot {
        caption: caption.into(),
        mesh: Mesh::from_surface(&surface, x),
        colours: colours.clone(),
        shading: Shading::Flat,
        wireframe: wire,
    };
    let x = voxreg(&surface, &normals, EnergyParams::default())?;
    let name = file_name(path);
    let images = vec![
        panel(&shot("voxels", &input, false), &camera),
        panel(&shot("voxreg (ii)", &x, false), &camera),
        panel(&shot("voxreg, quads", &x, true), &camera),
    ];
    let img = grid(&format!("Fig. 11: voxel art ({name}), palette colours"), &[(String::new(), images)]);
    index.add_png(
        "fig11_voxel_art.png",
        "Fig. 11: voxel art",
        format!("{name} (Mike Judge, CC BY 4.0) as one solid; each quad keeps the colour of its voxel."),
        &img,
    )?;
    // Fig. 15: each term switched off. The energy needs alpha > 0 to be strictly convex,
    // and as alpha -> 0 the minimizer collapses to a point (alignment and fairness vanish
    // there), so "almost no attachment" is alpha = 1e-5.
    let d = EnergyParams::default();
    let variants = [
        ("all terms", d),
        ("weak attachment (alpha 1e-5)", EnergyParams { alpha: 1e-5, ..d }),
        ("no alignment (beta 0)", EnergyParams { beta: 0.0, ..d }),
        ("no fairness (gamma 0)", EnergyParams { gamma: 0.0, ..d }),
    ];
    let mut images = Vec::new();
    for (caption, params) in variants {
        let x = voxreg(&surface, &normals, params)?;
        images.push(panel(&shot(caption, &x, true), &camera));
    }
    let img = grid(&format!("Fig. 15: ablation on {name}"), &[(String::new(), images)]);
    index.add_png(
        "fig15_ablation.png",
        "Fig. 15: ablation of the energy terms",
        "Default weights alpha = 1e-3, beta = 1, gamma = 0.1, then each term switched off. Without \
         alignment only fairness and attachment remain (the surface shrinks and rounds); without fairness \
         the quads follow the normals but their sizes vary and some fold; with almost no attachment \
         (alpha = 1e-5; at alpha = 0 the energy is not strictly convex and a single point minimizes it) the surface \
         shrinks to a small blob."
            .into(),
        &img,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The plumbing of `cargo xtask figures` on its cheapest figure: PNG and index
    /// written, identical bytes on a second run; and a chart through plotters with the
    /// bundled font.
    #[test]
    fn figures_are_written_deterministically_with_an_index() {
        let dir = std::env::temp_dir().join(format!("voxreg-figures-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let mut index = Index { dir: dir.clone(), entries: Vec::new() };
        fig10(&mut index, true).unwrap();
        index.write(true).unwrap();
        let png = std::fs::read(dir.join("fig10_multilabel.png")).unwrap();
        assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");
        let html = std::fs::read_to_string(dir.join("index.html")).unwrap();
        assert!(html.contains("<img src=\"fig10_multilabel.png\"") && html.contains("--quick"));
        fig10(&mut index, true).unwrap();
        assert_eq!(std::fs::read(dir.join("fig10_multilabel.png")).unwrap(), png);
        std::fs::remove_dir_all(&dir).unwrap();

        plotters::style::register_font("sans-serif", FontStyle::Normal, voxreg_render::FONT_TTF).ok();
        let chart = histograms("t", &[("a", vec![0.5, 1.0, 1.2, 4.9]), ("b", vec![9.0])], 5.0, "x").unwrap();
        assert_eq!((chart.width(), chart.height()), (600, 300));
        let inked = chart.as_rgb().chunks(3).filter(|c| c[0] < 100 && c[1] < 100 && c[2] < 100).count();
        assert!(inked > 500, "axes and labels drawn: {inked}");
    }
}
