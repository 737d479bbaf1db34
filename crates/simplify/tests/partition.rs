//! The partition invariants of simplification, checked against independent computations
//! on the meshes (never the simplifier's own bookkeeping): regions closed, Euler
//! characteristics of regions and interfaces unchanged, junction lines with the same
//! end points, no intersection added, every input vertex within the distance budget,
//! each region's volume within 1% and each interface's area within 2%.

use std::collections::{BTreeMap, BTreeSet, HashMap};

use glam::DVec3;
use proptest::prelude::*;
use voxreg_digisurf::{DigitalSurface, LabelVolume};
use voxreg_io::QuadMesh;
use voxreg_quality::{point_triangle_distance, self_intersections};
use voxreg_simplify::{simplify, simplify_levels, Options, Simplified, SimplifyError, Target};

/// The distinct vertices of a face in order (a triangle is a quad repeating a vertex).
fn polygon(q: &[u32; 4]) -> Vec<u32> {
    let mut p: Vec<u32> = Vec::with_capacity(4);
    for (i, &v) in q.iter().enumerate() {
        if v != q[(i + 3) % 4] {
            p.push(v);
        }
    }
    p
}

fn edge(a: u32, b: u32) -> (u32, u32) {
    (a.min(b), a.max(b))
}

/// Euler characteristic of the faces where `keep` holds, and the number of their edges
/// used an odd number of times (open edges).
fn euler_and_open(mesh: &QuadMesh, keep: impl Fn(usize) -> bool) -> (i64, usize) {
    let mut verts = BTreeSet::new();
    let mut edges: HashMap<(u32, u32), usize> = HashMap::new();
    let mut faces = 0i64;
    for (f, q) in mesh.quads.iter().enumerate() {
        if !keep(f) {
            continue;
        }
        faces += 1;
        let p = polygon(q);
        for i in 0..p.len() {
            verts.insert(p[i]);
            *edges.entry(edge(p[i], p[(i + 1) % p.len()])).or_default() += 1;
        }
    }
    let open = edges.values().filter(|&&c| c % 2 == 1).count();
    (verts.len() as i64 - edges.len() as i64 + faces, open)
}

fn labels(mesh: &QuadMesh) -> BTreeSet<u32> {
    mesh.face_labels.iter().flatten().copied().collect()
}

fn pairs(mesh: &QuadMesh) -> BTreeSet<[u32; 2]> {
    mesh.face_labels.iter().map(|l| [l[0].min(l[1]), l[0].max(l[1])]).collect()
}

type Pos = [u64; 3];

/// A junction line: its end points and the label pairs along it.
type Line = (Vec<Pos>, Vec<[u32; 2]>);

/// An edge and the label pairs of its faces.
type FeatureEdge = ((u32, u32), Vec<[u32; 2]>);

fn bits(p: DVec3) -> Pos {
    p.to_array().map(f64::to_bits)
}

/// The junction lines: chains of feature edges (edges not inside one interface: not
/// exactly two faces of the same label pair) cut at the vertices of feature degree other
/// than two. Each line as its end points (by position) and the label pairs along it;
/// loops without an end point have none.
fn lines(mesh: &QuadMesh) -> (Vec<Line>, BTreeSet<Pos>) {
    let mut at: BTreeMap<(u32, u32), Vec<[u32; 2]>> = BTreeMap::new();
    for (f, q) in mesh.quads.iter().enumerate() {
        let p = polygon(q);
        let l = mesh.face_labels[f];
        for i in 0..p.len() {
            at.entry(edge(p[i], p[(i + 1) % p.len()])).or_default().push([l[0].min(l[1]), l[0].max(l[1])]);
        }
    }
    let feature: Vec<FeatureEdge> = at
        .into_iter()
        .filter(|(_, ls)| !(ls.len() == 2 && ls[0] == ls[1]))
        .map(|(e, mut ls)| {
            ls.sort_unstable();
            (e, ls)
        })
        .collect();
    let mut degree: HashMap<u32, usize> = HashMap::new();
    let mut adj: HashMap<u32, Vec<usize>> = HashMap::new();
    for (i, ((a, b), _)) in feature.iter().enumerate() {
        *degree.entry(*a).or_default() += 1;
        *degree.entry(*b).or_default() += 1;
        adj.entry(*a).or_default().push(i);
        adj.entry(*b).or_default().push(i);
    }
    let corner = |v: u32| degree[&v] != 2;
    let corners: BTreeSet<Pos> =
        degree.keys().filter(|&&v| corner(v)).map(|&v| bits(mesh.positions[v as usize])).collect();
    let mut seen = vec![false; feature.len()];
    let mut out = Vec::new();
    for start in 0..feature.len() {
        if seen[start] {
            continue;
        }
        // Walk both ways from the edge until corners (or around a loop).
        seen[start] = true;
        let mut ends = Vec::new();
        let mut pairs: BTreeSet<[u32; 2]> = feature[start].1.iter().copied().collect();
        let (a0, b0) = feature[start].0;
        for from in [a0, b0] {
            let (mut v, mut e) = (from, start);
            loop {
                if corner(v) {
                    ends.push(bits(mesh.positions[v as usize]));
                    break;
                }
                let Some(&next) = adj[&v].iter().find(|&&x| x != e) else { break };
                if seen[next] {
                    break;
                }
                seen[next] = true;
                pairs.extend(feature[next].1.iter().copied());
                let (a, b) = feature[next].0;
                v = if a == v { b } else { a };
                e = next;
            }
        }
        ends.sort_unstable();
        out.push((ends, pairs.into_iter().collect()));
    }
    out.sort();
    (out, corners)
}

fn triangles(mesh: &QuadMesh) -> Vec<[DVec3; 3]> {
    let mut t = Vec::new();
    for q in &mesh.quads {
        let p = q.map(|v| mesh.positions[v as usize]);
        t.push([p[0], p[1], p[2]]);
        t.push([p[0], p[2], p[3]]);
    }
    t
}

/// Signed volume enclosed per label (faces oriented from their first label to their
/// second) and area per label pair.
fn measures(mesh: &QuadMesh) -> (BTreeMap<u32, f64>, BTreeMap<[u32; 2], f64>) {
    let (mut vol, mut area) = (BTreeMap::new(), BTreeMap::new());
    for (q, l) in mesh.quads.iter().zip(&mesh.face_labels) {
        let p = q.map(|v| mesh.positions[v as usize]);
        for t in [[p[0], p[1], p[2]], [p[0], p[2], p[3]]] {
            let v = t[0].dot(t[1].cross(t[2])) / 6.0;
            *vol.entry(l[0]).or_insert(0.0) += v;
            *vol.entry(l[1]).or_insert(0.0) -= v;
            let a = 0.5 * (t[1] - t[0]).cross(t[2] - t[0]).length();
            *area.entry([l[0].min(l[1]), l[0].max(l[1])]).or_insert(0.0) += a;
        }
    }
    (vol, area)
}

/// Every invariant of `out`, simplified from `input` within `max_error`.
fn check(input: &QuadMesh, out: &Simplified, max_error: f64) -> Result<(), TestCaseError> {
    let mesh = &out.mesh;
    prop_assert_eq!(labels(input), labels(mesh));
    prop_assert_eq!(pairs(input), pairs(mesh));
    for r in labels(input) {
        let of = |m: &QuadMesh| {
            let fl = m.face_labels.clone();
            euler_and_open(m, move |f| fl[f].contains(&r))
        };
        let (chi_in, open_in) = of(input);
        let (chi_out, open_out) = of(mesh);
        prop_assert_eq!(open_in, 0, "input region {} open", r);
        prop_assert_eq!(open_out, 0, "region {} open after simplification", r);
        prop_assert_eq!(chi_in, chi_out, "Euler characteristic of region {}", r);
    }
    for p in pairs(input) {
        let of = |m: &QuadMesh| {
            let fl = m.face_labels.clone();
            euler_and_open(m, move |f| [fl[f][0].min(fl[f][1]), fl[f][0].max(fl[f][1])] == p).0
        };
        prop_assert_eq!(of(input), of(mesh), "Euler characteristic of interface {:?}", p);
    }
    let (lines_in, corners_in) = lines(input);
    let (lines_out, corners_out) = lines(mesh);
    prop_assert_eq!(corners_in, corners_out, "corners");
    prop_assert_eq!(lines_in, lines_out, "junction lines");
    if self_intersections(&input.positions, &input.quads).is_empty() {
        prop_assert!(self_intersections(&mesh.positions, &mesh.quads).is_empty(), "intersection added");
    }
    // Each region's volume within 1% and each interface's area within 2% of the input's.
    let (v_in, a_in) = measures(input);
    let (v_out, a_out) = measures(mesh);
    for (r, v) in &v_in {
        let change = (v_out[r] - v).abs();
        prop_assert!(change <= 0.01 * v.abs() + 1e-9, "region {} volume {} -> {}", r, v, v_out[r]);
    }
    for (p, a) in &a_in {
        let change = (a_out[p] - a).abs();
        prop_assert!(change <= 0.02 * a + 1e-9, "interface {:?} area {} -> {}", p, a, a_out[p]);
    }
    let tris = triangles(mesh);
    let mut worst: f64 = 0.0;
    for p in &input.positions {
        let d = tris.iter().map(|t| point_triangle_distance(*p, *t)).fold(f64::INFINITY, f64::min);
        worst = worst.max(d);
    }
    prop_assert!(worst <= max_error + 1e-9, "distance {} over the budget {}", worst, max_error);
    prop_assert!(
        worst <= out.stats.error_bound + 1e-9,
        "distance {} over the bound {}",
        worst,
        out.stats.error_bound
    );
    prop_assert!(out.stats.error_bound <= max_error);
    prop_assert_eq!(out.stats.faces, mesh.quads.len());
    Ok(())
}

/// A volume of `dims` with background 0 outside a random ellipsoid and labels `1..=k`
/// inside it by nearest of `k` random seeds.
fn blob_volume(dims: [usize; 3], k: u32, seed: u64) -> LabelVolume {
    let mut s = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    let mut rnd = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64
    };
    let d = DVec3::new(dims[0] as f64, dims[1] as f64, dims[2] as f64);
    let centre = d * 0.5;
    let radii = DVec3::new(rnd() * 0.15 + 0.3, rnd() * 0.15 + 0.3, rnd() * 0.15 + 0.3) * d;
    let seeds: Vec<DVec3> =
        (0..k).map(|_| centre + (DVec3::new(rnd(), rnd(), rnd()) - 0.5) * radii * 1.4).collect();
    LabelVolume::from_fn(dims, |[x, y, z]| {
        let p = DVec3::new(x as f64, y as f64, z as f64) + 0.5;
        if ((p - centre) / radii).length_squared() > 1.0 {
            return 0;
        }
        let mut best = (f64::INFINITY, 0);
        for (i, s) in seeds.iter().enumerate() {
            let dd = p.distance_squared(*s);
            if dd < best.0 {
                best = (dd, i as u32 + 1);
            }
        }
        best.1
    })
}

fn regularized(volume: &LabelVolume) -> QuadMesh {
    let out = voxreg_regularize::regularize(volume, &voxreg_regularize::Params::default()).unwrap();
    QuadMesh::from_surface(&out.surface, &out.positions)
}

fn staircase(volume: &LabelVolume) -> QuadMesh {
    let surface = DigitalSurface::from_volume(volume).unwrap();
    QuadMesh::from_surface(&surface, &surface.positions())
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 12, ..ProptestConfig::default() })]

    /// Regularized blobs of 2 to 4 labels (background included), simplified hard.
    #[test]
    fn regularized_blobs_keep_the_partition(
        n in 6usize..=10, k in 1u32..=3, seed in any::<u64>(), ratio in 0.05f64..0.5,
    ) {
        let input = regularized(&blob_volume([n, n, n], k, seed));
        let target = Target { ratio: Some(ratio), max_error: 0.5 };
        let out = simplify(&input, target, &Options::default()).unwrap();
        check(&input, &out, 0.5)?;
        prop_assert!(out.stats.triangles_left < out.stats.input_triangles, "nothing collapsed");
    }

    /// Random voxels (pinches, tunnels, single voxels) on the staircase.
    #[test]
    fn random_staircases_keep_the_partition(
        dims in (2usize..=6, 2usize..=6, 2usize..=6), k in 2u32..=4,
        voxels in proptest::collection::vec(0u32..4, 216), e in 0.2f64..1.0,
    ) {
        let (x, y, z) = dims;
        let labels: Vec<u32> = voxels[..x * y * z].iter().map(|v| v % k).collect();
        let volume = LabelVolume::from_x_fastest([x, y, z], labels).unwrap();
        let input = staircase(&volume);
        let out = simplify(&input, Target { ratio: None, max_error: e }, &Options::default()).unwrap();
        check(&input, &out, e)?;
    }
}

#[test]
fn levels_nest_and_keep_the_partition() {
    let input = regularized(&blob_volume([10, 10, 10], 3, 7));
    let targets = voxreg_simplify::pyramid_targets(4, 4.0, 0.25);
    let levels = simplify_levels(&input, &targets, &Options::default()).unwrap();
    assert_eq!(levels[0].mesh, input, "level 0 is the input");
    for (l, t) in levels.iter().zip(&targets) {
        check(&input, l, t.max_error).unwrap();
    }
    for w in levels.windows(2) {
        assert!(w[1].stats.triangles_left <= w[0].stats.triangles_left);
        assert!(w[1].stats.error_bound >= w[0].stats.error_bound);
    }
    assert!(levels[1].stats.triangles_left < levels[0].stats.triangles_left);
}

#[test]
fn a_regularized_ball_reaches_a_tenth_mostly_in_quads() {
    let volume = LabelVolume::from_fn([16, 16, 16], |[x, y, z]| {
        let p = DVec3::new(x as f64, y as f64, z as f64) + 0.5 - 8.0;
        u32::from(p.length() < 6.0) + u32::from(p.length() < 6.0 && p.x > 0.5)
    });
    let input = regularized(&volume);
    let out = simplify(&input, Target { ratio: Some(0.1), max_error: 0.5 }, &Options::default()).unwrap();
    check(&input, &out, 0.5).unwrap();
    let s = out.stats;
    assert!(s.faces as f64 <= 0.2 * s.input_faces as f64, "{s:?}");
    assert!(s.quads as f64 >= 0.6 * s.faces as f64, "{s:?}");
}

#[test]
fn output_is_deterministic_and_carries_materials() {
    let mut input = regularized(&blob_volume([8, 8, 8], 2, 3));
    input.materials = vec![
        voxreg_io::Material::diffuse("a", [255, 0, 0, 255]),
        voxreg_io::Material::diffuse("b", [0, 255, 0, 255]),
    ];
    // A colour border across every interface: faces alternate materials by their centre's x.
    input.face_materials = input
        .quads
        .iter()
        .map(|q| u32::from(q.iter().map(|&v| input.positions[v as usize].x).sum::<f64>() > 16.0))
        .collect();
    let t = Target { ratio: Some(0.2), max_error: 0.5 };
    let a = simplify(&input, t, &Options::default()).unwrap();
    let b = simplify(&input, t, &Options::default()).unwrap();
    assert_eq!(a.mesh, b.mesh);
    check(&input, &a, 0.5).unwrap();
    // Each material's faces keep their side of the border: its Euler characteristic.
    for m in 0..2 {
        let chi = |mesh: &QuadMesh| euler_and_open(mesh, |f| mesh.face_materials[f] == m).0;
        assert_eq!(chi(&input), chi(&a.mesh), "material {m}");
    }
    assert_eq!(a.mesh.materials, input.materials);
}

#[test]
fn levels_do_not_depend_on_the_thread_count() {
    let input = regularized(&blob_volume([16, 16, 16], 4, 5));
    let targets = voxreg_simplify::pyramid_targets(4, 4.0, 0.5);
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| simplify_levels(&input, &targets, &Options::default()).unwrap())
    };
    let one = run(1);
    assert!(one[1].stats.triangles_left < one[0].stats.triangles_left);
    for threads in [2, 3] {
        let many = run(threads);
        for (a, b) in one.iter().zip(&many) {
            assert_eq!(a.mesh, b.mesh, "{threads} threads");
            assert_eq!(a.stats, b.stats, "{threads} threads");
        }
    }
}

#[test]
fn bad_input_and_targets_are_errors() {
    let input = staircase(&blob_volume([6, 6, 6], 1, 1));
    let o = Options::default();
    for t in [Target { ratio: Some(0.0), max_error: 1.0 }, Target { ratio: Some(0.5), max_error: f64::NAN }] {
        assert!(matches!(simplify(&input, t, &o), Err(SimplifyError::InvalidTarget(_))));
    }
    let nested = [Target { ratio: Some(0.5), max_error: 1.0 }, Target { ratio: Some(0.6), max_error: 1.0 }];
    assert!(matches!(simplify_levels(&input, &nested, &o), Err(SimplifyError::InvalidTarget(_))));
    let mut broken = input.clone();
    broken.quads[0][1] = broken.positions.len() as u32;
    let t = Target { ratio: Some(0.5), max_error: 1.0 };
    assert!(matches!(simplify(&broken, t, &o), Err(SimplifyError::InvalidMesh(_))));
    let mut broken = input;
    broken.face_labels.pop();
    assert!(matches!(simplify(&broken, t, &o), Err(SimplifyError::InvalidMesh(_))));
}

/// Six labels in a blob at a tenth: 62.8% of the faces are quads (58.1% without the flips
/// that let the matching grow); the bound leaves a margin for changes of the collapses.
#[test]
fn a_six_label_blob_at_a_tenth_keeps_its_quad_share() {
    let input = regularized(&blob_volume([24, 24, 16], 6, 3));
    let out = simplify(&input, Target { ratio: Some(0.1), max_error: 0.5 }, &Options::default()).unwrap();
    check(&input, &out, 0.5).unwrap();
    let s = out.stats;
    assert!(s.quads as f64 >= 0.60 * s.faces as f64, "{s:?}");
}
