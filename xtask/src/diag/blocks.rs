//! Chunked solves against the whole-volume solve, on a label volume read by
//! `voxreg_io::read_volume` (a `.npy` indexed `[x, y, z]`, or any other format):
//!
//! - `stitched`: every block through `regularize_block`, stitched by lattice id, against
//!   the whole volume: mean, max and 99.9th percentile of the vertex deviation, by
//!   distance to the nearest chunk border, and across the surface (along the whole-volume
//!   quads' normals).
//! - `blocks`: each block's deviation after each refinement round (`0..=REFINE`), and the
//!   vertices that deviate most after the last.
//! - `sensitivity`: the refined normals at the whole-volume positions against the same
//!   positions moved by a tiny random amount.
//!
//! Knobs (environment variables): `VOXREG_DIAG_CHUNK` (32), `VOXREG_DIAG_HALO` (24),
//! `VOXREG_DIAG_REFINE` (the preset's for `stitched`, 3 for `blocks`), `VOXREG_DIAG_PRESERVE`
//! (size preservation, 1), `VOXREG_DIAG_TOL` and `VOXREG_DIAG_ITOL` (the solver's tolerance
//! and the intermediate factor, both sides), `VOXREG_DIAG_BLOCK_TOL` and
//! `VOXREG_DIAG_BLOCK_ITOL` (the blocks' own), `VOXREG_DIAG_BLOCKS=I,J` (`stitched`: only
//! those blocks), `VOXREG_DIAG_BLOCK=I` (`blocks`: only that block), `VOXREG_EPS`
//! (`sensitivity`'s displacement, 1e-4 voxel).

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use glam::DVec3;
use voxreg_digisurf::{DigitalSurface, LabelVolume, VertexId};
use voxreg_normals::{NormalEstimator, Refined};
use voxreg_regularize::{lattice_id, regularize, regularize_block, Block, Params, Regularizer};

use super::{env_opt, env_or};

/// The volume at `path` (label 0 the background, as `voxreg regularize` reads it).
fn read(path: &Path) -> Result<LabelVolume> {
    Ok(voxreg_io::read_volume(path).with_context(|| format!("{}: cannot read", path.display()))?.volume)
}

/// The lattice corner of a global vertex id (the inverse of [`lattice_id`]).
fn corner_of(id: u64, dims: [usize; 3]) -> [usize; 3] {
    let (nx, ny) = (dims[0] as u64 + 1, dims[1] as u64 + 1);
    [(id % nx) as usize, ((id / nx) % ny) as usize, (id / (nx * ny)) as usize]
}

/// The voxels `start..end` of `volume`, placed where they are in it.
fn sub(volume: &LabelVolume, start: [usize; 3], end: [usize; 3]) -> Result<LabelVolume> {
    let dims = [0, 1, 2].map(|k| end[k] - start[k]);
    let origin =
        volume.origin() + DVec3::new(start[0] as f64, start[1] as f64, start[2] as f64) * volume.spacing();
    Ok(LabelVolume::from_fn(dims, |p| volume.labels()[[p[0] + start[0], p[1] + start[1], p[2] + start[2]]])
        .with_spacing(volume.spacing())?
        .with_origin(origin)?
        .with_background(volume.background()))
}

/// The blocks of `chunk` voxels a side, with their index and sub-volume range for `halo`.
fn blocks_of(dims: [usize; 3], chunk: usize, halo: usize) -> Vec<(usize, Block, [usize; 3])> {
    let grid: Vec<Vec<[usize; 2]>> = (0..3)
        .map(|k| (0..dims[k]).step_by(chunk).map(|lo| [lo, (lo + chunk).min(dims[k])]).collect())
        .collect();
    let mut out = Vec::new();
    for i in &grid[0] {
        for j in &grid[1] {
            for l in &grid[2] {
                let owned = [*i, *j, *l];
                let start = owned.map(|[lo, _]| lo.saturating_sub(halo));
                let end = [0, 1, 2].map(|k| (owned[k][1] + halo).min(dims[k]));
                out.push((out.len(), Block { global_dims: dims, start, owned }, end));
            }
        }
    }
    out
}

/// The positions of `surface`'s vertices keyed by global lattice id.
fn keyed(surface: &DigitalSurface, positions: &[DVec3], dims: [usize; 3]) -> HashMap<u64, DVec3> {
    (0..surface.num_vertices())
        .map(|v| {
            let c = surface.vertex_corner(VertexId(v as u32)).map(|c| c as usize);
            (lattice_id(c, dims), positions[v])
        })
        .collect()
}

/// The default parameters with the knobs' solver settings (`prefix` `VOXREG_DIAG` or
/// `VOXREG_DIAG_BLOCK`) over `params`.
fn tolerances(mut params: Params, prefix: &str) -> Result<Params> {
    if let Some(tol) = env_opt::<f64>(&format!("{prefix}_TOL"))? {
        params.solver = params.solver.with_tolerance(tol);
    }
    if let Some(itol) = env_opt::<f64>(&format!("{prefix}_ITOL"))? {
        if let Some(f) = params.mode.fidelity_mut() {
            f.intermediate_tolerance = itol;
        }
    }
    Ok(params)
}

/// Mean, max and 99.9th percentile of `d`.
fn summary(d: &[f64]) -> (f64, f64, f64) {
    let mut s = d.to_vec();
    s.sort_by(f64::total_cmp);
    let mean = s.iter().sum::<f64>() / s.len().max(1) as f64;
    let p999 = s.get(((s.len() as f64 * 0.999) as usize).min(s.len().saturating_sub(1))).copied();
    (mean, s.last().copied().unwrap_or(0.0), p999.unwrap_or(0.0))
}

/// `cargo xtask diag stitched VOLUME`.
pub(super) fn stitched(path: PathBuf) -> Result<()> {
    let (chunk, halo) = (env_or("VOXREG_DIAG_CHUNK", 32)?, env_or("VOXREG_DIAG_HALO", 24)?);
    let volume = read(&path)?;
    let dims = volume.dims();
    let mut params = Params::default();
    if env_or::<u8>("VOXREG_DIAG_PRESERVE", 1)? == 0 {
        params.mode.fidelity_mut().expect("the default preset's mode").recentring = None;
    }
    params.refinement_mut().rounds = env_or("VOXREG_DIAG_REFINE", Params::default().refinement().rounds)?;
    let params = tolerances(params, "VOXREG_DIAG")?;
    let block_params = tolerances(params.clone(), "VOXREG_DIAG_BLOCK")?;
    let only: Option<Vec<usize>> = std::env::var("VOXREG_DIAG_BLOCKS")
        .ok()
        .map(|v| v.split(',').filter_map(|b| b.parse().ok()).collect());
    let t = std::time::Instant::now();
    let whole = regularize(&volume, &params)?;
    let (ws, wp) = (&whole.surface, whole.positions.as_slice());
    println!("whole: {} quads, {:.1} s", ws.num_surfels(), t.elapsed().as_secs_f64());
    let mut expected = keyed(ws, wp, dims);
    let t = std::time::Instant::now();
    let (mut got, mut quads) = (HashMap::<u64, DVec3>::new(), 0);
    for (index, block, end) in blocks_of(dims, chunk, halo) {
        if only.as_ref().is_some_and(|o| !o.contains(&index)) {
            continue;
        }
        let part = regularize_block(&sub(&volume, block.start, end)?, &block, &block_params)?;
        quads += part.quads.len();
        for (v, &id) in part.vertex_ids.iter().enumerate() {
            if part.owns_vertex[v] {
                anyhow::ensure!(got.insert(id, part.positions[v]).is_none(), "vertex {id} owned twice");
            }
        }
    }
    println!("chunked: {quads} quads, {:.1} s", t.elapsed().as_secs_f64());
    if only.is_none() {
        anyhow::ensure!(quads == ws.num_surfels(), "{quads} quads stitched, {} whole", ws.num_surfels());
        anyhow::ensure!(
            got.len() == expected.len(),
            "{} vertices stitched, {} whole",
            got.len(),
            expected.len()
        );
    }
    expected.retain(|id, _| got.contains_key(id));
    // The deviation across the surface: its largest component along the whole-volume
    // normals of the vertex's quads (a vertex sliding within its quads' planes leaves the
    // surface where it was).
    let unit: Vec<DVec3> = ws
        .surfels()
        .iter()
        .map(|s| {
            let [a, b, c, d] = s.vertices.map(|v| wp[v.index()]);
            (c - a).cross(d - b).normalize_or_zero()
        })
        .collect();
    let mut across: HashMap<u64, f64> = HashMap::new();
    for v in 0..ws.num_vertices() {
        let vid = VertexId(v as u32);
        let id = lattice_id(ws.vertex_corner(vid).map(|c| c as usize), dims);
        if let Some(g) = got.get(&id) {
            let d = *g - wp[v];
            across.insert(
                id,
                ws.vertex_surfels(vid).iter().map(|q| d.dot(unit[q.index()]).abs()).fold(0.0, f64::max),
            );
        }
    }
    let mut worst: Vec<(f64, u64)> = expected.iter().map(|(id, p)| ((got[id] - *p).length(), *id)).collect();
    worst.sort_by(|a, b| b.0.total_cmp(&a.0));
    for (d, id) in worst.iter().take(8) {
        println!("worst {d:.3e} (across the surface {:.3e}) at {:?}", across[id], corner_of(*id, dims));
    }
    let rows: Vec<(f64, f64, usize)> = expected
        .iter()
        .map(|(id, p)| {
            let c = corner_of(*id, dims);
            let to_border = (0..3)
                .flat_map(|k| (chunk..dims[k]).step_by(chunk).map(move |b| c[k].abs_diff(b)))
                .min()
                .unwrap_or(usize::MAX);
            ((got[id] - *p).length(), across[id], to_border)
        })
        .collect();
    let report = |name: &str, d: Vec<f64>| {
        if d.is_empty() {
            return;
        }
        let (mean, max, p999) = summary(&d);
        let above = d.iter().filter(|&&x| x > 1e-2).count();
        println!(
            "{name}: {} vertices, mean {mean:.2e}, max {max:.2e}, 99.9th {p999:.2e}, above 1e-2: {above}",
            d.len()
        );
    };
    report("all", rows.iter().map(|r| r.0).collect());
    for (lo, hi) in [(0, 2), (2, 8), (8, 16), (16, 32), (32, usize::MAX)] {
        let range = if hi == usize::MAX { format!("{lo}+") } else { format!("{lo}-{hi}") };
        report(
            &format!("{range} from a border"),
            rows.iter().filter(|r| lo <= r.2 && r.2 < hi).map(|r| r.0).collect(),
        );
    }
    report("all, across the surface", rows.iter().map(|r| r.1).collect());
    Ok(())
}

/// `cargo xtask diag blocks VOLUME`.
pub(super) fn blocks(path: PathBuf) -> Result<()> {
    let (chunk, halo) = (env_or("VOXREG_DIAG_CHUNK", 32)?, env_or("VOXREG_DIAG_HALO", 24)?);
    let max_refine: usize = env_or("VOXREG_DIAG_REFINE", 3)?;
    let only: Option<usize> = env_opt("VOXREG_DIAG_BLOCK")?;
    let volume = read(&path)?;
    let dims = volume.dims();
    let mut params = Params::default();
    let fidelity = params.mode.fidelity_mut().expect("the default preset's mode");
    fidelity.intermediate_tolerance = 1.0;
    if env_or::<u8>("VOXREG_DIAG_PRESERVE", 1)? == 0 {
        fidelity.recentring = None;
    }
    params.solver = params.solver.with_tolerance(env_or("VOXREG_DIAG_TOL", 1e-3)?);
    let round = |r: usize| {
        let mut p = params.clone();
        p.refinement_mut().rounds = r;
        p
    };
    let mut whole = Regularizer::from_volume(&volume, &params.regions)?;
    let whole_k: Vec<HashMap<u64, DVec3>> = (0..=max_refine)
        .map(|r| {
            let out = whole.run(&round(r))?;
            Ok(keyed(&out.surface, out.positions.as_slice(), dims))
        })
        .collect::<Result<_>>()?;
    println!("whole done");
    let mut all_dev: Vec<(f64, u64, usize)> = Vec::new();
    for (index, block, end) in blocks_of(dims, chunk, halo) {
        if only.is_some_and(|o| o != index) {
            continue;
        }
        let sv = sub(&volume, block.start, end)?;
        let inside = |id: u64| {
            let c = corner_of(id, dims);
            (0..3).all(|k| block.owned[k][0] <= c[k] && c[k] <= block.owned[k][1])
        };
        let mut line = format!("block {index} owned {:?}:", block.owned);
        for (r, kw) in whole_k.iter().enumerate() {
            let part = regularize_block(&sv, &block, &round(r))?;
            if part.report.is_none() {
                break;
            }
            let mut dev: Vec<(f64, u64)> = part
                .vertex_ids
                .iter()
                .zip(&part.positions)
                .filter(|(id, _)| inside(**id))
                .map(|(id, p)| ((*p - kw[id]).length(), *id))
                .collect();
            dev.sort_by(|a, b| b.0.total_cmp(&a.0));
            let (mean, max, _) = summary(&dev.iter().map(|d| d.0).collect::<Vec<_>>());
            let above = dev.iter().filter(|d| d.0 > 1e-2).count();
            line += &format!(" | r{r}: mean {mean:.1e} max {max:.1e} (>1e-2: {above})");
            if r == max_refine {
                let block_pos: HashMap<u64, DVec3> =
                    part.vertex_ids.iter().copied().zip(part.positions.iter().copied()).collect();
                for d in dev.iter().take(3) {
                    all_dev.push((d.0, d.1, index));
                    let c = DVec3::from_array(corner_of(d.1, dims).map(|x| x as f64));
                    println!(
                        "  vertex {c:?}: whole - corner {:.3?}, block - corner {:.3?}",
                        kw[&d.1] - c,
                        block_pos[&d.1] - c
                    );
                }
            }
        }
        println!("{line}");
    }
    all_dev.sort_by(|a, b| b.0.total_cmp(&a.0));
    for (d, id, b) in all_dev.iter().take(20) {
        let [x, y, z] = corner_of(*id, dims);
        println!("top: dev {d:.3e} corner {x} {y} {z} block {b}");
    }
    Ok(())
}

/// `cargo xtask diag sensitivity VOLUME`.
pub(super) fn sensitivity(path: PathBuf) -> Result<()> {
    let eps: f64 = env_or("VOXREG_EPS", 1e-4)?;
    let volume = read(&path)?;
    let mut params = Params::default();
    params.refinement_mut().rounds = 1;
    let out = regularize(&volume, &params)?;
    let s = &out.surface;
    let p = out.positions.as_slice();
    let mut rng = voxreg_testkit::Lcg::new(12345);
    let q: Vec<DVec3> = p.iter().map(|x| *x + eps * rng.vec3(-1.0, 1.0)).collect();
    let est = |positions: &[DVec3]| {
        Refined {
            positions,
            previous: &out.normals,
            radius: params.refinement().radius,
            feature_angle_deg: params.refinement().feature_angle_deg,
        }
        .estimate(s)
    };
    let (a, b) = (est(p)?, est(&q)?);
    let mut d: Vec<(f64, usize)> = a
        .as_slice()
        .iter()
        .zip(b.as_slice())
        .enumerate()
        .map(|(i, (x, y))| (x.dot(*y).clamp(-1.0, 1.0).acos().to_degrees(), i))
        .collect();
    d.sort_by(|x, y| y.0.total_cmp(&x.0));
    let over = |t: f64| d.iter().filter(|x| x.0 > t).count();
    println!(
        "eps {eps:e}: {} quads; normals moved > 0.01 deg: {}, > 0.1: {}, > 1: {}, > 5: {}",
        d.len(),
        over(0.01),
        over(0.1),
        over(1.0),
        over(5.0)
    );
    // A quad's area at the positions (the length of its vector area).
    let area = |f: usize| {
        let [a, b, c, d] = s.surfels()[f].vertices.map(|v| p[v.index()]);
        0.5 * (c - a).cross(d - b).length()
    };
    for (ang, i) in d.iter().take(8) {
        let sf = s.surfels()[*i];
        let smallest = s
            .surfel_edges(voxreg_digisurf::SurfelId(*i as u32))
            .iter()
            .flat_map(|e| s.edge_surfels(*e).iter().map(|g| area(g.index())))
            .fold(f64::INFINITY, f64::min);
        println!(
            "  {ang:.3} deg: surfel {i} cell {:?} axis {} regions {:?}, area {:.3}, smallest edge neighbour {smallest:.3}",
            sf.cell,
            sf.axis,
            sf.regions,
            area(*i)
        );
    }
    let mut areas: Vec<f64> = (0..s.num_surfels()).map(area).collect();
    areas.sort_by(f64::total_cmp);
    println!(
        "quad areas: 0.1 % {:.3}, 1 % {:.3}, median {:.3}",
        areas[areas.len() / 1000],
        areas[areas.len() / 100],
        areas[areas.len() / 2]
    );
    Ok(())
}
