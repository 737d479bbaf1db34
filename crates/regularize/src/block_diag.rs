//! Diagnostic (ignored): where a block's solve departs from the whole-volume solve.
//!
//! VOXREG_DIAG=volume.npy (u8, C order [x, y, z]) VOXREG_DIAG_CHUNK=32 VOXREG_DIAG_HALO=24
//! cargo test --release -p voxreg-regularize --lib diag -- --ignored --nocapture

use std::collections::HashMap;

use glam::DVec3;
use voxreg_digisurf::{DigitalSurface, LabelVolume, SurfelId, VertexId};

use super::{block_regularizer, Block};
use crate::{lattice_id, Output, Params, Regularizer};

fn read_npy(path: &str) -> LabelVolume {
    let bytes = std::fs::read(path).unwrap();
    let hlen = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
    let header = std::str::from_utf8(&bytes[10..10 + hlen]).unwrap();
    let shape = header.split("'shape': (").nth(1).unwrap().split(')').next().unwrap();
    let dims: Vec<usize> =
        shape.split(',').filter(|s| !s.trim().is_empty()).map(|s| s.trim().parse().unwrap()).collect();
    let data = &bytes[10 + hlen..];
    let [nx, ny, nz] = [dims[0], dims[1], dims[2]];
    let _ = nx;
    LabelVolume::from_fn([dims[0], dims[1], dims[2]], |[x, y, z]| data[(x * ny + y) * nz + z] as u32)
        .with_background(Some(0))
}

fn env(name: &str, default: usize) -> usize {
    std::env::var(name).ok().and_then(|v| v.parse().ok()).unwrap_or(default)
}

/// The lattice corner of a global vertex id (the inverse of [`lattice_id`]).
fn corner_of(id: u64, dims: [usize; 3]) -> [usize; 3] {
    let (nx, ny) = (dims[0] as u64 + 1, dims[1] as u64 + 1);
    [(id % nx) as usize, ((id / nx) % ny) as usize, (id / (nx * ny)) as usize]
}

fn sub(volume: &LabelVolume, start: [usize; 3], end: [usize; 3]) -> LabelVolume {
    let dims = [0, 1, 2].map(|k| end[k] - start[k]);
    LabelVolume::from_fn(dims, |p| volume.labels()[[p[0] + start[0], p[1] + start[1], p[2] + start[2]]])
        .with_origin(volume.origin() + DVec3::new(start[0] as f64, start[1] as f64, start[2] as f64))
        .unwrap()
        .with_background(volume.background())
}

/// The straddling test of the crease weights.
fn straddling(surface: &DigitalSurface, normals: &[DVec3], deg: f64) -> Vec<bool> {
    let cos_max = deg.to_radians().cos();
    (0..surface.num_surfels())
        .map(|f| {
            let sf = surface.surfels()[f];
            let tilted = normals[f].dot(sf.normal()) < cos_max;
            tilted
                && surface.surfel_edges(SurfelId(f as u32)).iter().any(|&e| {
                    surface.edge_surfels(e).iter().any(|g| {
                        surface.surfel(*g).interface == sf.interface
                            && normals[g.index()].dot(normals[f]) < cos_max
                    })
                })
        })
        .collect()
}

/// The vector area of quad `f` at `positions` (half the cross product of its diagonals).
fn vector_area(surface: &DigitalSurface, positions: &[DVec3], f: usize) -> DVec3 {
    let [a, b, c, d] = surface.surfels()[f].vertices.map(|v| positions[v.index()]);
    0.5 * (c - a).cross(d - b)
}

fn plateau(surface: &DigitalSurface) -> Vec<bool> {
    (0..surface.num_vertices())
        .map(|v| {
            let v = VertexId(v as u32);
            let sf = surface.vertex_surfels(v);
            let n0 = sf.first().map(|s| surface.surfel(*s).normal());
            sf.len() == 4
                && !surface.is_boundary_vertex(v)
                && sf.iter().all(|s| Some(surface.surfel(*s).normal()) == n0)
        })
        .collect()
}

struct Keyed {
    pos: HashMap<u64, DVec3>,
    target: HashMap<u64, DVec3>,
    plateau: HashMap<u64, bool>,
    normal: HashMap<u64, DVec3>,
    crease: HashMap<u64, bool>,
}

fn keyed(out: &Output, start: [usize; 3], dims: [usize; 3]) -> Keyed {
    let s = &out.surface;
    let g = |c: [u32; 3]| [0, 1, 2].map(|k| c[k] as usize + start[k]);
    let vid = |v: VertexId| lattice_id(g(s.vertex_corner(v)), dims);
    let fid = |f: usize| {
        let sf = s.surfels()[f];
        lattice_id(g(sf.cell), dims) * 3 + sf.axis as u64
    };
    let pl = plateau(s);
    let cr = straddling(s, out.normals.as_slice(), 20.0);
    let mut k = Keyed {
        pos: HashMap::new(),
        target: HashMap::new(),
        plateau: HashMap::new(),
        normal: HashMap::new(),
        crease: HashMap::new(),
    };
    for v in 0..s.num_vertices() {
        let id = vid(VertexId(v as u32));
        k.pos.insert(id, out.positions.as_slice()[v]);
        k.target.insert(id, out.targets.as_slice()[v]);
        k.plateau.insert(id, pl[v]);
    }
    for f in 0..s.num_surfels() {
        k.normal.insert(fid(f), out.normals.as_slice()[f]);
        k.crease.insert(fid(f), cr[f]);
    }
    k
}

#[test]
#[ignore]
fn diagnose_blocks() {
    let path = std::env::var("VOXREG_DIAG").expect("VOXREG_DIAG=volume.npy");
    let chunk = env("VOXREG_DIAG_CHUNK", 32);
    let halo = env("VOXREG_DIAG_HALO", 24);
    let max_refine = env("VOXREG_DIAG_REFINE", 3);
    let only: Option<usize> = std::env::var("VOXREG_DIAG_BLOCK").ok().and_then(|v| v.parse().ok());
    let preserve = std::env::var("VOXREG_DIAG_PRESERVE").map(|v| v != "0").unwrap_or(true);
    let tol: f64 = std::env::var("VOXREG_DIAG_TOL").ok().and_then(|v| v.parse().ok()).unwrap_or(1e-3);
    let margin = env("VOXREG_DIAG_MARGIN", 0);
    let volume = read_npy(&path);
    let dims = volume.dims();
    let mut params = Params { preserve_size: preserve, intermediate_tolerance: 1.0, ..Params::default() };
    params.solver = params.solver.with_tolerance(tol);
    let rounds: Vec<usize> = (0..=max_refine).collect();
    let mut whole = Regularizer::from_volume(&volume, &params.regions).unwrap();
    let whole_k: Vec<Keyed> = rounds
        .iter()
        .map(|&r| keyed(&whole.run(&Params { refine: r, ..params.clone() }).unwrap(), [0; 3], dims))
        .collect();
    eprintln!("whole done");
    let grid: Vec<Vec<[usize; 2]>> = (0..3)
        .map(|k| (0..dims[k]).step_by(chunk).map(|lo| [lo, (lo + chunk).min(dims[k])]).collect())
        .collect();
    let mut b = 0;
    let mut all_dev: Vec<(f64, u64, usize)> = Vec::new();
    for i in 0..grid[0].len() {
        for j in 0..grid[1].len() {
            for l in 0..grid[2].len() {
                let owned = [grid[0][i], grid[1][j], grid[2][l]];
                b += 1;
                if only.is_some_and(|o| o != b - 1) {
                    continue;
                }
                let start = owned.map(|[lo, _]| lo.saturating_sub(halo));
                let end = [0, 1, 2].map(|k| (owned[k][1] + halo).min(dims[k]));
                let sv = sub(&volume, start, end);
                let block = Block { global_dims: dims, start, owned };
                let Ok(Some(mut reg)) = block_regularizer(&sv, &block, &params, margin) else { continue };
                let inside = |id: u64| {
                    let c = corner_of(id, dims);
                    (0..3).all(|k| owned[k][0] <= c[k] && c[k] <= owned[k][1])
                };
                let mut line = format!("block {} owned {:?}:", b - 1, owned);
                for (ri, &r) in rounds.iter().enumerate() {
                    let out = reg.run(&Params { refine: r, ..params.clone() }).unwrap();
                    let kb = keyed(&out, start, dims);
                    let kw = &whole_k[ri];
                    let mut dev: Vec<(f64, u64)> = kb
                        .pos
                        .iter()
                        .filter(|(id, _)| inside(**id))
                        .map(|(id, p)| ((*p - kw.pos[id]).length(), *id))
                        .collect();
                    dev.sort_by(|a, b| b.0.partial_cmp(&a.0).unwrap());
                    let mean = dev.iter().map(|d| d.0).sum::<f64>() / dev.len().max(1) as f64;
                    let tdev = kb
                        .target
                        .iter()
                        .filter(|(id, _)| inside(**id))
                        .map(|(id, p)| (*p - kw.target[id]).length())
                        .fold(0.0, f64::max);
                    let ndev = kb
                        .normal
                        .iter()
                        .filter(|(id, _)| inside(**id / 3))
                        .map(|(id, n)| n.dot(kw.normal[id]).clamp(-1.0, 1.0).acos().to_degrees())
                        .fold(0.0, f64::max);
                    let cflip =
                        kb.crease.iter().filter(|(id, c)| inside(**id / 3) && kw.crease[id] != **c).count();
                    let pflip =
                        kb.plateau.iter().filter(|(id, c)| inside(**id) && kw.plateau[id] != **c).count();
                    line += &format!(
                        " | r{r}: mean {mean:.1e} max {:.1e} (>1e-2: {}) tgt {tdev:.1e} nrm {ndev:.2}deg creaseflip {cflip} plateauflip {pflip}",
                        dev.first().map_or(0.0, |d| d.0),
                        dev.iter().filter(|d| d.0 > 1e-2).count()
                    );
                    if r == max_refine {
                        for d in dev.iter().take(3) {
                            all_dev.push((d.0, d.1, b - 1));
                            let c = corner_of(d.1, dims).map(|x| x as f64);
                            let c = DVec3::from_array(c);
                            eprintln!(
                                "  vertex {c:?}: whole - corner {:.3?}, block - corner {:.3?}, target whole - corner {:.3?}, block {:.3?}",
                                kw.pos[&d.1] - c,
                                kb.pos[&d.1] - c,
                                kw.target[&d.1] - c,
                                kb.target[&d.1] - c
                            );
                        }
                    }
                }
                eprintln!("{line}");
            }
        }
    }
    all_dev.sort_by(|a, b| b.0.partial_cmp(&a.0).unwrap());
    for (d, id, b) in all_dev.iter().take(20) {
        let [x, y, z] = corner_of(*id, dims);
        eprintln!("top: dev {d:.3e} corner {x} {y} {z} block {b}");
    }
}

/// The stitched blocks (through [`super::regularize_block`]) against the whole-volume solve
/// with the default parameters: mean / max deviation, and by the corner's distance to the
/// nearest chunk border.
#[test]
#[ignore]
fn stitched_deviation() {
    let path = std::env::var("VOXREG_DIAG").expect("VOXREG_DIAG=volume.npy");
    let chunk = env("VOXREG_DIAG_CHUNK", 32);
    let halo = env("VOXREG_DIAG_HALO", 24);
    let preserve = std::env::var("VOXREG_DIAG_PRESERVE").map(|v| v != "0").unwrap_or(true);
    let volume = read_npy(&path);
    let dims = volume.dims();
    let refine = env("VOXREG_DIAG_REFINE", Params::default().refine);
    let mut params = Params { preserve_size: preserve, refine, ..Params::default() };
    if let Some(itol) = std::env::var("VOXREG_DIAG_ITOL").ok().and_then(|v| v.parse::<f64>().ok()) {
        params.intermediate_tolerance = itol;
    }
    let only: Option<Vec<usize>> = std::env::var("VOXREG_DIAG_BLOCKS")
        .ok()
        .map(|v| v.split(',').filter_map(|b| b.parse().ok()).collect());
    if let Some(tol) = std::env::var("VOXREG_DIAG_TOL").ok().and_then(|v| v.parse::<f64>().ok()) {
        params.solver = params.solver.with_tolerance(tol);
    }
    let margin = env("VOXREG_DIAG_MARGIN", super::CUT_MARGIN);
    // The blocks' own solver tolerances, when they differ from the whole volume's.
    let mut block_params = params.clone();
    if let Some(tol) = std::env::var("VOXREG_DIAG_BLOCK_TOL").ok().and_then(|v| v.parse::<f64>().ok()) {
        block_params.solver = block_params.solver.with_tolerance(tol);
    }
    if let Some(itol) = std::env::var("VOXREG_DIAG_BLOCK_ITOL").ok().and_then(|v| v.parse::<f64>().ok()) {
        block_params.intermediate_tolerance = itol;
    }
    let t = std::time::Instant::now();
    let whole = crate::regularize(&volume, &params).unwrap();
    eprintln!("whole: {} quads, {:.1} s", whole.surface.num_surfels(), t.elapsed().as_secs_f64());
    let mut expected: HashMap<u64, DVec3> = HashMap::new();
    for v in 0..whole.surface.num_vertices() {
        let c = whole.surface.vertex_corner(VertexId(v as u32)).map(|c| c as usize);
        expected.insert(lattice_id(c, dims), whole.positions.as_slice()[v]);
    }
    let t = std::time::Instant::now();
    let mut got: HashMap<u64, DVec3> = HashMap::new();
    let mut quads = 0;
    let grid: Vec<Vec<[usize; 2]>> = (0..3)
        .map(|k| (0..dims[k]).step_by(chunk).map(|lo| [lo, (lo + chunk).min(dims[k])]).collect())
        .collect();
    for i in 0..grid[0].len() {
        for j in 0..grid[1].len() {
            for l in 0..grid[2].len() {
                let owned = [grid[0][i], grid[1][j], grid[2][l]];
                let index = (i * grid[1].len() + j) * grid[2].len() + l;
                if only.as_ref().is_some_and(|o| !o.contains(&index)) {
                    continue;
                }
                let start = owned.map(|[lo, _]| lo.saturating_sub(halo));
                let end = [0, 1, 2].map(|k| (owned[k][1] + halo).min(dims[k]));
                let block = Block { global_dims: dims, start, owned };
                let Some(mut reg) =
                    block_regularizer(&sub(&volume, start, end), &block, &block_params, margin).unwrap()
                else {
                    continue;
                };
                let out = reg.run(&block_params).unwrap();
                let part = super::owned_part(&out.surface, out.positions.as_slice(), &block, None);
                quads += part.quads.len();
                for (v, &id) in part.vertex_ids.iter().enumerate() {
                    if part.owns_vertex[v] {
                        assert!(got.insert(id, part.positions[v]).is_none());
                    }
                }
            }
        }
    }
    eprintln!("chunked: {quads} quads, {:.1} s", t.elapsed().as_secs_f64());
    if only.is_none() {
        assert_eq!(quads, whole.surface.num_surfels());
        assert_eq!(got.len(), expected.len());
    }
    expected.retain(|id, _| got.contains_key(id));
    // The deviation across the surface: its largest component along the whole-volume
    // normals of the vertex's quads (a vertex sliding within its quads' planes leaves
    // the surface where it was).
    let wp = whole.positions.as_slice();
    let unit: Vec<DVec3> = (0..whole.surface.num_surfels())
        .map(|f| vector_area(&whole.surface, wp, f).normalize_or_zero())
        .collect();
    let mut across: HashMap<u64, f64> = HashMap::new();
    for v in 0..whole.surface.num_vertices() {
        let c = whole.surface.vertex_corner(VertexId(v as u32)).map(|c| c as usize);
        let id = lattice_id(c, dims);
        if let Some(g) = got.get(&id) {
            let d = *g - wp[v];
            let off = whole
                .surface
                .vertex_surfels(VertexId(v as u32))
                .iter()
                .map(|q| d.dot(unit[q.index()]).abs())
                .fold(0.0, f64::max);
            across.insert(id, off);
        }
    }
    {
        let mut worst: Vec<(f64, u64)> =
            expected.iter().map(|(id, p)| ((got[id] - *p).length(), *id)).collect();
        worst.sort_by(|a, b| b.0.partial_cmp(&a.0).unwrap());
        for (d, id) in worst.iter().take(8) {
            eprintln!("worst {d:.3e} (across the surface {:.3e}) at {:?}", across[id], corner_of(*id, dims));
        }
    }
    let mut rows: Vec<(f64, usize)> = Vec::new();
    let mut offs: Vec<(f64, usize)> = Vec::new();
    for (id, p) in &expected {
        let c = corner_of(*id, dims);
        let to_border = (0..3)
            .flat_map(|k| (chunk..dims[k]).step_by(chunk).map(move |b| c[k].abs_diff(b)))
            .min()
            .unwrap_or(usize::MAX);
        rows.push(((got[id] - *p).length(), to_border));
        offs.push((across[id], to_border));
    }
    let report = |name: &str, rows: &[(f64, usize)], sel: &dyn Fn(usize) -> bool| {
        let d: Vec<f64> = rows.iter().filter(|r| sel(r.1)).map(|r| r.0).collect();
        if d.is_empty() {
            return;
        }
        let mean = d.iter().sum::<f64>() / d.len() as f64;
        let max = d.iter().copied().fold(0.0, f64::max);
        let mut s = d.clone();
        s.sort_by(|a, b| a.partial_cmp(b).unwrap());
        let p999 = s[((s.len() as f64 * 0.999) as usize).min(s.len() - 1)];
        eprintln!(
            "{name}: {} vertices, mean {mean:.2e}, max {max:.2e}, 99.9th {p999:.2e}, above 1e-2: {}",
            d.len(),
            d.iter().filter(|&&x| x > 1e-2).count()
        );
    };
    report("all", &rows, &|_| true);
    for (lo, hi) in [(0, 2), (2, 8), (8, 16), (16, 32), (32, usize::MAX)] {
        let range = if hi == usize::MAX { format!("{lo}+") } else { format!("{lo}-{hi}") };
        report(&format!("{range} from a border"), &rows, &|b| b >= lo && b < hi);
    }
    report("all, across the surface", &offs, &|_| true);
}

/// Sensitivity (temporary experiment): the refined normals and crease weights at the
/// whole-volume positions against the same positions moved by a tiny random amount.
#[test]
#[ignore]
fn sensitivity() {
    use voxreg_normals::{NormalEstimator, Refined};
    let path = std::env::var("VOXREG_DIAG").expect("VOXREG_DIAG=volume.npy");
    let eps: f64 = std::env::var("VOXREG_EPS").ok().and_then(|v| v.parse().ok()).unwrap_or(1e-4);
    let volume = read_npy(&path);
    let params = Params { refine: 1, ..Params::default() };
    let out = crate::regularize(&volume, &params).unwrap();
    let s = &out.surface;
    let p = out.positions.as_slice();
    let mut rng = voxreg_testkit::Lcg::new(12345);
    let q: Vec<DVec3> = p.iter().map(|x| *x + eps * rng.vec3(-1.0, 1.0)).collect();
    let est = |pos: &[DVec3]| {
        Refined {
            positions: pos,
            previous: &out.normals,
            radius: params.refine_radius,
            feature_angle_deg: params.feature_angle_deg,
        }
        .estimate(s)
        .unwrap()
    };
    let (a, b) = (est(p), est(&q));
    let mut d: Vec<(f64, usize)> = a
        .as_slice()
        .iter()
        .zip(b.as_slice())
        .enumerate()
        .map(|(i, (x, y))| (x.dot(*y).clamp(-1.0, 1.0).acos().to_degrees(), i))
        .collect();
    d.sort_by(|x, y| y.0.partial_cmp(&x.0).unwrap());
    let over = |t: f64| d.iter().filter(|x| x.0 > t).count();
    eprintln!(
        "eps {eps:e}: {} quads; normals moved > 0.01 deg: {}, > 0.1: {}, > 1: {}, > 5: {}",
        d.len(),
        over(0.01),
        over(0.1),
        over(1.0),
        over(5.0)
    );
    // A quad's area at the positions (the length of its vector area).
    let area = |f: usize| vector_area(s, p, f).length();
    for (ang, i) in d.iter().take(8) {
        let sf = s.surfels()[*i];
        let smallest = s
            .surfel_edges(SurfelId(*i as u32))
            .iter()
            .flat_map(|e| s.edge_surfels(*e).iter().map(|g| area(g.index())))
            .fold(f64::INFINITY, f64::min);
        eprintln!(
            "  {ang:.3} deg: surfel {i} cell {:?} axis {} regions {:?}, area {:.3}, smallest edge neighbour {smallest:.3}",
            sf.cell, sf.axis, sf.regions, area(*i)
        );
    }
    let mut areas: Vec<f64> = (0..s.num_surfels()).map(area).collect();
    areas.sort_by(|a, b| a.partial_cmp(b).unwrap());
    eprintln!(
        "quad areas: 0.1 % {:.3}, 1 % {:.3}, median {:.3}",
        areas[areas.len() / 1000],
        areas[areas.len() / 100],
        areas[areas.len() / 2]
    );
    let ca = crate::pipeline::crease_weights(
        s,
        &a,
        params.crease_angle_deg,
        params.crease_alignment,
        params.crease_dilation,
    );
    let cb = crate::pipeline::crease_weights(
        s,
        &b,
        params.crease_angle_deg,
        params.crease_alignment,
        params.crease_dilation,
    );
    let cd = ca.iter().zip(&cb).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max);
    eprintln!(
        "crease weights: max change {cd:.3e}, quads changed > 1e-3: {}",
        ca.iter().zip(&cb).filter(|(x, y)| (*x - *y).abs() > 1e-3).count()
    );
}

/// The thin-sheet rule on a volume: how many quads it holds and what it costs
/// (`pipeline::thin_sheets`, three timed runs).
#[test]
#[ignore]
fn thin_sheet_count() {
    let path = std::env::var("VOXREG_DIAG").expect("VOXREG_DIAG=volume.npy");
    let surface = DigitalSurface::from_volume(&read_npy(&path)).unwrap();
    let field = Params::default().normals.estimator().estimate(&surface).unwrap();
    let thickness = Params::default().sheet_thickness;
    for _ in 0..3 {
        let t = std::time::Instant::now();
        let held = crate::pipeline::thin_sheets(&surface, &field, thickness);
        let full = held.iter().filter(|(_, s)| *s >= 1.0).count();
        eprintln!(
            "{} quads: {} held ({full} fully), {:.3} s",
            surface.num_surfels(),
            held.len(),
            t.elapsed().as_secs_f64()
        );
    }
}
