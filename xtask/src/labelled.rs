//! The multi-label and anisotropic part of `cargo xtask compare`: the test kit's label
//! shapes (split ball, quartered ball, touching balls) and anisotropically sampled
//! spheres and tori, voxreg against marching cubes (and, with `--surfacenets`, VTK's
//! SurfaceNets3D run by `bench/accuracy/surfacenets_labels.py`), by part: surfaces (interfaces with
//! the background), inner interfaces, junction curves, junction points.

use std::fmt::Write as _;
use std::io::Write as _;
use std::path::Path;

use anyhow::{bail, Context, Result};
use glam::{DVec2, DVec3};
use voxreg_baselines::{marching_cubes_volume, Mesh};
use voxreg_digisurf::{DigitalSurface, LabelVolume};
use voxreg_regularize::{Params, Regularizer};
use voxreg_testkit::{
    digitize_labels, label_fidelity, JunctionKind, LabelFidelity, LabelShape, QuarteredBall, Solid, Sphere,
    SplitBall, Stat, Torus, TouchingBalls,
};

/// One label shape at one spacing.
pub(crate) struct LabelCase {
    pub(crate) shape: Box<dyn LabelShape>,
    pub(crate) spacing: DVec3,
    pub(crate) label: String,
}

static SPHERE_20: Sphere = Sphere { radius: 20.0 };
static TORUS: Torus = Torus { major: 12.0, minor: 5.0 };

/// The cases: the split ball, the quartered ball and the touching balls at unit spacing,
/// the sphere of radius 20 at `(1, 1, 2.5)`, `(1, 1, 5)` and `(1, 2, 3)`, a torus at
/// `(1, 1, 2.5)` and `(1, 1, 5)`.
pub(crate) fn label_cases() -> Vec<LabelCase> {
    let c = |shape: Box<dyn LabelShape>, spacing: DVec3, label: &str| LabelCase {
        shape,
        spacing,
        label: label.to_string(),
    };
    vec![
        c(Box::new(SplitBall { radius: 20.0, cut: 0.5 }), DVec3::ONE, "split ball r=20, cut z=0.5"),
        c(Box::new(quartered_ball()), DVec3::ONE, "quartered ball r=20"),
        c(Box::<TouchingBalls>::default(), DVec3::ONE, "touching balls in a ball r=19"),
        c(Box::new(Solid(&SPHERE_20)), DVec3::new(1.0, 1.0, 2.5), "sphere r=20, spacing (1, 1, 2.5)"),
        c(Box::new(Solid(&SPHERE_20)), DVec3::new(1.0, 1.0, 5.0), "sphere r=20, spacing (1, 1, 5)"),
        c(Box::new(Solid(&TORUS)), DVec3::new(1.0, 1.0, 2.5), "torus 12/5, spacing (1, 1, 2.5)"),
        c(Box::new(Solid(&TORUS)), DVec3::new(1.0, 1.0, 5.0), "torus 12/5, spacing (1, 1, 5)"),
        c(Box::new(Solid(&SPHERE_20)), DVec3::new(1.0, 2.0, 3.0), "sphere r=20, spacing (1, 2, 3)"),
    ]
}

/// The ball of radius 20 centred on the line where its two cutting planes `x = 0.5`,
/// `z = 0.5` cross (so each end of that line is one digital vertex).
pub(crate) fn quartered_ball() -> QuarteredBall {
    QuarteredBall { radius: 20.0, centre: DVec3::new(0.5, 0.0, 0.5), cuts: DVec2::splat(0.5) }
}

/// The fidelity of the default pipeline on `case`.
pub(crate) fn voxreg_fidelity(case: &LabelCase, params: &Params) -> Result<LabelFidelity> {
    let volume = digitize_labels(case.shape.as_ref(), case.spacing);
    let surface = DigitalSurface::from_volume(&volume)?;
    let out = Regularizer::new(surface.clone()).run(params)?;
    Ok(label_fidelity(&surface, &out.positions, case.shape.as_ref()))
}

/// Marching cubes of each region's indicator, each vertex measured against the interface
/// of the two labels at the ends of the lattice edge it lies on (junctions: none).
pub(crate) fn marching_cubes_fidelity(volume: &LabelVolume, shape: &dyn LabelShape) -> LabelFidelity {
    let mut labels: Vec<u32> =
        volume.label_counts().into_iter().map(|(l, _)| l).filter(|&l| l != 0).collect();
    labels.sort_unstable();
    let unit = volume.spacing().min_element();
    let (mut dist, mut normals): ([Vec<f64>; 2], [Vec<f64>; 2]) = Default::default();
    for &k in &labels {
        let mesh: Mesh = marching_cubes_volume(volume, |l| l == k);
        let pairs: Vec<Option<(u32, u32)>> = mesh.positions.iter().map(|p| edge_labels(volume, *p)).collect();
        for (p, pair) in mesh.positions.iter().zip(&pairs) {
            if let Some((a, b)) = pair {
                if let Some((q, _)) = shape.interface(*a, *b, *p) {
                    dist[usize::from(*a != 0)].push(p.distance(q) / unit);
                }
            }
        }
        for f in mesh.faces() {
            let Some((a, b)) = pairs[f[0] as usize] else { continue };
            let [p0, p1, p2] = [f[0], f[1], f[2]].map(|i| mesh.positions[i as usize]);
            let n = (p1 - p0).cross(p2 - p0).normalize_or_zero();
            if let Some((_, t)) = shape.interface(a, b, (p0 + p1 + p2) / 3.0) {
                normals[usize::from(a != 0)].push(n.dot(t).abs().min(1.0).acos().to_degrees());
            }
        }
    }
    let stat = |v: &[f64]| {
        let (mean, max) = voxreg_testkit::mean_max(v);
        Stat { mean, max, count: v.len() }
    };
    LabelFidelity {
        surface: stat(&dist[0]),
        inner: stat(&dist[1]),
        surface_normals: stat(&normals[0]),
        inner_normals: stat(&normals[1]),
        ..Default::default()
    }
}

/// The labels (sorted) of the two voxels at the ends of the lattice edge through `p`.
fn edge_labels(volume: &LabelVolume, p: DVec3) -> Option<(u32, u32)> {
    let u = (p - volume.origin()) / volume.spacing();
    let axis = (0..3).max_by(|&i, &j| frac_dist(u[i]).total_cmp(&frac_dist(u[j])))?;
    let mut lo = [0i64; 3];
    for k in 0..3 {
        lo[k] = if k == axis { u[k].floor() } else { u[k].round() } as i64;
    }
    let mut hi = lo;
    hi[axis] += 1;
    let (a, b) = (volume.label(lo)?, volume.label(hi)?);
    (a != b).then_some((a.min(b), a.max(b)))
}

fn frac_dist(x: f64) -> f64 {
    (x - x.round()).abs()
}

fn cell(s: Stat) -> String {
    if s.count == 0 {
        "-".into()
    } else {
        format!("{:.3} / {:.3}", s.mean, s.max)
    }
}

/// A Markdown row of `f` for `method`.
pub(crate) fn fidelity_row(method: &str, f: &LabelFidelity) -> String {
    format!(
        "| {method} | {} | {} | {} | {} | {} ({}) | {} ({}) |\n",
        cell(f.surface),
        cell(f.surface_normals),
        cell(f.inner),
        cell(f.inner_normals),
        cell(f.junction),
        f.junction.count,
        cell(f.points),
        f.points.count
    )
}

/// The header of [`fidelity_row`]'s table.
pub(crate) const FIDELITY_HEADER: &str = "| method | surface distance mean / max | surface normals (deg) | inner interface distance | inner normals (deg) | junction curves (vertices) | junction points (vertices) |\n|---|---|---|---|---|---|---|\n";

/// The legend of the tables.
pub(crate) const FIDELITY_LEGEND: &str = "Distances in voxels of the finest spacing (in-plane voxels for thick \
slices), from each vertex to the true part it belongs to, by the labels of its faces: surface = two labels, one the \
background; inner interface = two labels, neither the background; junction curves = three or more labels along a \
curve; junction points = where the curves end. Normals: unsigned angle between each face's normal and the true \
normal at the nearest point of its interface, mean / max. voxreg: the default pipeline. Marching cubes: iso 0.5 on \
each label's indicator, separately (no shared junction vertices), each vertex measured against the interface of the \
two labels at the ends of its lattice edge. VTK SurfaceNets3D (`--surfacenets`, `bench/accuracy/surfacenets_labels.py`): its \
defaults (every label, constrained smoothing on, triangles), each vertex measured by the labels of its triangles.\n";

/// The tables of every [`label_cases`] case; with `surfacenets`, a folder where each
/// case's volume is written and `bench/accuracy/surfacenets_labels.py` meshes it, a row for VTK's
/// SurfaceNets3D too.
pub(crate) fn label_tables(surfacenets: Option<&Path>) -> Result<String> {
    let cases = label_cases();
    let volumes: Vec<LabelVolume> =
        cases.iter().map(|c| digitize_labels(c.shape.as_ref(), c.spacing)).collect();
    if let Some(dir) = surfacenets {
        run_surface_nets(dir, &volumes)?;
    }
    let mut md =
        format!("# Multi-label interfaces, junctions and anisotropic spacing\n\n{FIDELITY_LEGEND}\n");
    for (k, (case, volume)) in cases.iter().zip(&volumes).enumerate() {
        let surface = DigitalSurface::from_volume(volume)?;
        let input = label_fidelity(&surface, &surface.positions(), case.shape.as_ref());
        let voxreg = voxreg_fidelity(case, &Params::default())?;
        let mc = marching_cubes_fidelity(volume, case.shape.as_ref());
        let _ = write!(
            md,
            "## {}\n\n{FIDELITY_HEADER}{}{}{}",
            case.label,
            fidelity_row("digital surface (input)", &input),
            fidelity_row("voxreg (default)", &voxreg),
            fidelity_row("marching cubes (per label)", &mc)
        );
        if let Some(dir) = surfacenets {
            let mesh = dir.join(format!("case_{k}.snets"));
            let f = surface_nets_fidelity(&mesh, volume.spacing().min_element(), case.shape.as_ref())
                .with_context(|| format!("{}", mesh.display()))?;
            md.push_str(&fidelity_row("VTK SurfaceNets3D (defaults)", &f));
        }
        md.push('\n');
        eprintln!("{}: done", case.label);
    }
    Ok(md)
}

/// Writes each volume to `dir/case_K.npy` (`u32` labels, shape `(X, Y, Z)`) with its
/// spacing and origin in `dir/case_K.json`, and runs `bench/accuracy/surfacenets_labels.py` on `dir`.
fn run_surface_nets(dir: &Path, volumes: &[LabelVolume]) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    for (k, volume) in volumes.iter().enumerate() {
        let [nx, ny, nz] = volume.dims();
        let path = dir.join(format!("case_{k}.npy"));
        let mut f = std::io::BufWriter::new(
            std::fs::File::create(&path).with_context(|| format!("{}: cannot create", path.display()))?,
        );
        f.write_all(&voxreg_testkit::npy_bytes("<u4", [nx, ny, nz], []))?;
        // C order, shape (X, Y, Z): z fastest.
        for x in 0..nx as i64 {
            for y in 0..ny as i64 {
                for z in 0..nz as i64 {
                    f.write_all(&volume.label([x, y, z]).unwrap_or(0).to_le_bytes())?;
                }
            }
        }
        f.flush()?;
        let (h, o) = (volume.spacing(), volume.origin());
        std::fs::write(
            dir.join(format!("case_{k}.json")),
            format!(
                "{{\"spacing\": [{:?}, {:?}, {:?}], \"origin\": [{:?}, {:?}, {:?}]}}\n",
                h.x, h.y, h.z, o.x, o.y, o.z
            ),
        )?;
    }
    let script = crate::root().join("bench/accuracy/surfacenets_labels.py");
    let status = std::process::Command::new("python3")
        .arg(&script)
        .arg(dir)
        .status()
        .context("running python3 (SurfaceNets3D needs Python with numpy and pip's vtk)")?;
    if !status.success() {
        bail!("{} failed ({status}); it needs numpy and pip's vtk (pip install vtk)", script.display());
    }
    Ok(())
}

/// The fidelity of a SurfaceNets3D mesh written by `bench/accuracy/surfacenets_labels.py`, with
/// [`label_fidelity`]'s metric: each vertex measured against the part given by the labels
/// of its triangles (two labels: an interface; three or more: a junction curve or point),
/// each triangle's normal against its interface's; distances over `unit`.
fn surface_nets_fidelity(path: &Path, unit: f64, shape: &dyn LabelShape) -> Result<LabelFidelity> {
    let text = std::fs::read_to_string(path)?;
    let mut lines = text.lines();
    let counts: Vec<usize> =
        lines.next().context("empty")?.split_whitespace().map(str::parse).collect::<Result<_, _>>()?;
    let [n, m] = counts[..] else { bail!("the first line must be `vertices triangles`") };
    let mut points = Vec::with_capacity(n);
    for _ in 0..n {
        let v: Vec<f64> = lines
            .next()
            .context("too few vertices")?
            .split_whitespace()
            .map(str::parse)
            .collect::<Result<_, _>>()?;
        points.push(DVec3::new(v[0], v[1], v[2]));
    }
    let mut labels: Vec<Vec<u32>> = vec![Vec::new(); n];
    let mut normals: [Vec<f64>; 2] = Default::default();
    for _ in 0..m {
        let t: Vec<i64> = lines
            .next()
            .context("too few triangles")?
            .split_whitespace()
            .map(str::parse)
            .collect::<Result<_, _>>()?;
        let [i, j, k, a, b] = t[..] else { bail!("a triangle line must be `i j k a b`") };
        let (a, b) = (a.min(b) as u32, a.max(b) as u32);
        for v in [i, j, k] {
            labels[v as usize].extend([a, b]);
        }
        let [p0, p1, p2] = [i, j, k].map(|v| points[v as usize]);
        let area = (p1 - p0).cross(p2 - p0);
        if let Some((_, t)) = shape.interface(a, b, (p0 + p1 + p2) / 3.0) {
            let cos = area.normalize_or_zero().dot(t).abs().min(1.0);
            normals[usize::from(a != 0)].push(cos.acos().to_degrees());
        }
    }
    let mut parts: [Vec<f64>; 4] = Default::default();
    for (p, l) in points.iter().zip(&mut labels) {
        l.sort_unstable();
        l.dedup();
        if l.len() == 2 {
            if let Some((q, _)) = shape.interface(l[0], l[1], *p) {
                parts[usize::from(l[0] != 0)].push(p.distance(q) / unit);
            }
        } else if l.len() >= 3 {
            if let Some((q, kind)) = shape.junction(l, *p) {
                parts[if kind == JunctionKind::Curve { 2 } else { 3 }].push(p.distance(q) / unit);
            }
        }
    }
    let stat = |v: &[f64]| {
        let (mean, max) = voxreg_testkit::mean_max(v);
        Stat { mean, max, count: v.len() }
    };
    Ok(LabelFidelity {
        surface: stat(&parts[0]),
        inner: stat(&parts[1]),
        junction: stat(&parts[2]),
        points: stat(&parts[3]),
        surface_normals: stat(&normals[0]),
        inner_normals: stat(&normals[1]),
    })
}
