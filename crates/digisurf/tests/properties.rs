//! Property tests of the digital surface on small random volumes.
//!
//! Every property is checked against an independent computation from the voxels
//! (brute-force face scans, cubical-complex Euler characteristics), never against the
//! complex's own bookkeeping.

use std::collections::HashMap;

use proptest::prelude::*;
use proptest::test_runner::TestCaseError;
use voxreg_digisurf::{
    DigitalSurface, EdgeKind, InterfaceId, LabelVolume, Patch, PatchParams, RegionId, RegionMap,
    SurfaceError, VertexId,
};

/// A random volume of dimensions 1..=5 per axis with labels in `0..labels`.
fn volume(labels: u32) -> impl Strategy<Value = LabelVolume> {
    (1usize..=5, 1usize..=5, 1usize..=5).prop_flat_map(move |(x, y, z)| {
        proptest::collection::vec(0..labels, x * y * z)
            .prop_map(move |v| LabelVolume::from_x_fastest([x, y, z], v).unwrap())
    })
}

/// Region id of a voxel (outside: the background's region, or None).
fn region(vol: &LabelVolume, map: &voxreg_digisurf::Regions, v: [i64; 3]) -> Option<u32> {
    vol.label(v).map(|l| map.region_of(l).unwrap().0)
}

/// Number of surfels by brute force: face-adjacent voxel pairs (outside included) of
/// different regions.
fn brute_surfels(vol: &LabelVolume) -> usize {
    let map = RegionMap::per_label().resolve(vol).unwrap();
    let d = vol.dims().map(|x| x as i64);
    let mut n = 0;
    for axis in 0..3 {
        for x in -1..d[0] {
            for y in -1..d[1] {
                for z in -1..d[2] {
                    let a = [x, y, z];
                    let mut b = a;
                    b[axis] += 1;
                    let inside = |v: [i64; 3]| (0..3).all(|k| v[k] >= 0 && v[k] < d[k]);
                    if !inside(a) && !inside(b) {
                        continue;
                    }
                    match (region(vol, &map, a), region(vol, &map, b)) {
                        (Some(ra), Some(rb)) if ra != rb => n += 1,
                        _ => {}
                    }
                }
            }
        }
    }
    n
}

/// Euler characteristic of the union of closed unit cubes of the voxels where `f` holds,
/// over a box padded by `pad` voxels, by counting Khalimsky cells.
fn cubical_euler(dims: [usize; 3], pad: i64, f: impl Fn([i64; 3]) -> bool) -> i64 {
    let size: Vec<i64> = dims.iter().map(|&d| 2 * (d as i64 + 2 * pad) + 1).collect();
    let mut marked = vec![false; (size[0] * size[1] * size[2]) as usize];
    for x in -pad..dims[0] as i64 + pad {
        for y in -pad..dims[1] as i64 + pad {
            for z in -pad..dims[2] as i64 + pad {
                if !f([x, y, z]) {
                    continue;
                }
                let c = [2 * (x + pad) + 1, 2 * (y + pad) + 1, 2 * (z + pad) + 1];
                for dx in -1..=1 {
                    for dy in -1..=1 {
                        for dz in -1..=1 {
                            let (i, j, k) = (c[0] + dx, c[1] + dy, c[2] + dz);
                            marked[(i + size[0] * (j + size[1] * k)) as usize] = true;
                        }
                    }
                }
            }
        }
    }
    let mut chi = 0;
    for k in 0..size[2] {
        for j in 0..size[1] {
            for i in 0..size[0] {
                if marked[(i + size[0] * (j + size[1] * k)) as usize] {
                    let dim = (i % 2) + (j % 2) + (k % 2);
                    chi += if dim % 2 == 0 { 1 } else { -1 };
                }
            }
        }
    }
    chi
}

/// Counts of lattice cells (vertices, edges, faces) whose surrounding voxels hold two or
/// more regions: exactly the cells of the complex.
fn brute_cells(vol: &LabelVolume) -> (usize, usize, usize) {
    let map = RegionMap::per_label().resolve(vol).unwrap();
    let d = vol.dims().map(|x| x as i64);
    let mut counts = [0usize; 3];
    // Khalimsky coordinates of cells: 0..=2d; even coordinate = lattice plane.
    for i in 0..=2 * d[0] {
        for j in 0..=2 * d[1] {
            for k in 0..=2 * d[2] {
                let c = [i, j, k];
                let dim = c.iter().filter(|&&x| x % 2 == 1).count();
                if dim == 3 {
                    continue;
                }
                // The voxels around: for an even coordinate, both neighbours.
                let opts: Vec<Vec<i64>> = c
                    .iter()
                    .map(|&x| if x % 2 == 1 { vec![(x - 1) / 2] } else { vec![x / 2 - 1, x / 2] })
                    .collect();
                let mut regions = Vec::new();
                for &a in &opts[0] {
                    for &b in &opts[1] {
                        for &cc in &opts[2] {
                            if let Some(r) = region(vol, &map, [a, b, cc]) {
                                regions.push(r);
                            }
                        }
                    }
                }
                regions.sort_unstable();
                regions.dedup();
                if regions.len() >= 2 {
                    counts[dim] += 1;
                }
            }
        }
    }
    (counts[0], counts[1], counts[2])
}

fn flip_x(vol: &LabelVolume) -> LabelVolume {
    let d = vol.dims();
    LabelVolume::from_fn(d, |[x, y, z]| vol.labels()[[d[0] - 1 - x, y, z]]).with_background(vol.background())
}

fn check_common(vol: &LabelVolume, s: &DigitalSurface) {
    let map = RegionMap::per_label().resolve(vol).unwrap();
    // Every surfel separates its two recorded voxels, of different regions.
    for sf in s.surfels() {
        let [a, b] = sf.voxels();
        let (ra, rb) = (region(vol, &map, a), region(vol, &map, b));
        assert_eq!(ra, Some(sf.regions[0].0));
        assert_eq!(rb, Some(sf.regions[1].0));
        assert!(sf.regions[0] < sf.regions[1]);
        assert_eq!(vol.label(a), Some(sf.labels[0]));
        // The four vertices are the corners of the face, in order around the normal.
        let p: Vec<_> = sf.vertices.iter().map(|&v| s.vertex_position(v)).collect();
        let n = (p[1] - p[0]).cross(p[2] - p[1]);
        assert!((n.normalize() - sf.normal()).length() < 1e-12, "orientation of {sf:?}");
    }
    assert_eq!(s.num_surfels(), brute_surfels(vol));
    let (v, e, f) = brute_cells(vol);
    assert_eq!((s.num_vertices(), s.num_edges(), s.num_surfels()), (v, e, f));
    for (i, edge) in s.edges().iter().enumerate() {
        let k = s.edge_surfels(voxreg_digisurf::EdgeId(i as u32)).len();
        assert!((1..=4).contains(&k));
        match edge.kind {
            EdgeKind::Boundary => assert!(s.has_open_border()),
            EdgeKind::Regular => assert_eq!(k, 2),
            EdgeKind::Junction => assert!(k >= 3),
            EdgeKind::Pinch => assert_eq!(k, 4),
        }
    }
    // Neighbours are symmetric.
    for v in 0..s.num_vertices() {
        let v = VertexId(v as u32);
        for &w in s.vertex_neighbours(v) {
            assert!(s.vertex_neighbours(w).contains(&v));
        }
    }
    // Each region's boundary, oriented out of the region, is a cycle: every non-rim edge
    // is walked as often in each direction.
    for r in 0..s.regions().len() as u32 {
        let mut walks: HashMap<(u32, u32), i32> = HashMap::new();
        for (si, sf) in s.surfels().iter().enumerate() {
            let sign = if sf.regions[0].0 == r {
                1
            } else if sf.regions[1].0 == r {
                -1
            } else {
                continue;
            };
            let es = s.surfel_edges(voxreg_digisurf::SurfelId(si as u32));
            for i in 0..4 {
                if s.edges()[es[i].index()].kind == EdgeKind::Boundary {
                    continue;
                }
                let (a, b) = (sf.vertices[i].0, sf.vertices[(i + 1) % 4].0);
                let (key, dir) = if a < b { ((a, b), sign) } else { ((b, a), -sign) };
                *walks.entry(key).or_default() += dir;
            }
        }
        assert!(walks.values().all(|&w| w == 0), "region {r} boundary is not a cycle");
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    #[test]
    fn binary_volumes(vol in volume(2)) {
        match DigitalSurface::from_volume(&vol) {
            Err(SurfaceError::Empty) => prop_assert!(vol.labels().iter().all(|&l| l == 0)),
            Err(e) => panic!("{e}"),
            Ok(s) => {
                check_common(&vol, &s);
                // Closed: every edge has an even number of surfels.
                for i in 0..s.num_edges() {
                    prop_assert_eq!(s.edge_surfels(voxreg_digisurf::EdgeId(i as u32)).len() % 2, 0);
                }
                prop_assert!(s.components_closed().iter().all(|&c| c));
                // Euler characteristic: chi(dP) = chi(P) + chi(Q) - chi(box), by Mayer-Vietoris.
                let inside = |v: [i64; 3]| vol.label(v) == Some(1);
                let chi_p = cubical_euler(vol.dims(), 1, inside);
                let chi_q = cubical_euler(vol.dims(), 1, |v| !inside(v));
                prop_assert_eq!(s.euler_characteristic(), chi_p + chi_q - 1);
                // Each closed component without pinches has an even Euler characteristic.
                if s.counts().pinched_edges == 0 && s.counts().pinched_vertices == 0 {
                    prop_assert_eq!(s.euler_characteristic() % 2, 0);
                }
            }
        }
    }

    #[test]
    fn multi_label_volumes(vol in volume(4), open in any::<bool>(), sides in any::<[[bool; 2]; 3]>()) {
        // Closed by the background except on some sides cut open, or open everywhere.
        let vol = if open { vol.with_background(None) } else { vol.with_open_sides(sides) };
        let counted = DigitalSurface::count_surfels(&vol, &RegionMap::per_label()).unwrap();
        match DigitalSurface::from_volume(&vol) {
            Err(SurfaceError::Empty) => prop_assert_eq!(counted, 0),
            Err(e) => panic!("{e}"),
            Ok(s) => {
                // The counting pass agrees with the surface it predicts.
                prop_assert_eq!(counted, s.num_surfels() as u64);
                check_common(&vol, &s);
                let dims = vol.dims();
                let open_sides = vol.open_sides();
                for (i, e) in s.edges().iter().enumerate() {
                    let k = s.edge_surfels(voxreg_digisurf::EdgeId(i as u32)).len();
                    if e.kind != EdgeKind::Boundary {
                        prop_assert!(k >= 2);
                    } else {
                        // A rim edge lies in the plane of an open side.
                        let [a, b] = e.vertices.map(|v| s.vertex_corner(v));
                        let on = (0..3).any(|u| {
                            (open_sides[u][0] && a[u] == 0 && b[u] == 0)
                                || (open_sides[u][1] && a[u] as usize == dims[u] && b[u] as usize == dims[u])
                        });
                        prop_assert!(on, "rim edge {:?} off the open sides {:?}", e, open_sides);
                    }
                }
                let boundary = (0..s.num_vertices()).filter(|&v| s.is_boundary_vertex(VertexId(v as u32))).count();
                if !open && sides == [[false; 2]; 3] {
                    prop_assert_eq!(boundary, 0);
                }
            }
        }
    }

    #[test]
    fn invariant_under_flips_and_permutations(vol in volume(3), open in any::<bool>()) {
        let vol = if open { vol.with_background(None) } else { vol };
        let permuted = LabelVolume::from_fn(vol.dims(), |[x, y, z]| [0, 2, 1][vol.labels()[[x, y, z]] as usize])
            .with_background(vol.background());
        let a = DigitalSurface::from_volume(&vol).map(|s| s.counts());
        let b = DigitalSurface::from_volume(&flip_x(&vol)).map(|s| s.counts());
        let c = DigitalSurface::from_volume(&permuted).map(|s| s.counts());
        prop_assert_eq!(&a, &b);
        prop_assert_eq!(&a, &c);
    }
}

#[test]
fn single_voxel_cube() {
    let vol = LabelVolume::from_fn([1, 1, 1], |_| 7);
    let s = DigitalSurface::from_volume(&vol).unwrap();
    assert_eq!((s.num_surfels(), s.num_edges(), s.num_vertices()), (6, 12, 8));
    assert_eq!(s.interfaces().len(), 1);
    assert_eq!(s.euler_characteristic(), 2);
}

#[test]
fn single_voxel_without_background_is_empty() {
    let vol = LabelVolume::from_fn([1, 1, 1], |_| 7).with_background(None);
    assert_eq!(DigitalSurface::from_volume(&vol).unwrap_err(), SurfaceError::Empty);
}

#[test]
fn edge_and_vertex_pinches_are_shared_and_reported() {
    // Two voxels touching along an edge.
    let vol = LabelVolume::from_fn([2, 2, 1], |[x, y, _]| u32::from(x == y));
    let s = DigitalSurface::from_volume(&vol).unwrap();
    let c = s.counts();
    assert_eq!((c.surfels, c.pinched_edges, c.components), (12, 1, 1));
    assert_eq!(c.edges, 23); // 24 - 1 shared
                             // Two voxels touching at a corner.
    let vol = LabelVolume::from_fn([2, 2, 2], |[x, y, z]| u32::from(x == y && y == z));
    let s = DigitalSurface::from_volume(&vol).unwrap();
    let c = s.counts();
    assert_eq!((c.surfels, c.vertices, c.pinched_vertices, c.components), (12, 15, 1, 2));
}

#[test]
fn four_label_junction() {
    // Four labels around one edge, no background: one junction edge with 4 surfels.
    let vol = LabelVolume::from_fn([2, 2, 1], |[x, y, _]| (x + 2 * y) as u32 + 1).with_background(None);
    let s = DigitalSurface::from_volume(&vol).unwrap();
    let c = s.counts();
    // Each surfel's three other edges lie on the domain border (the slab is 1 voxel thick).
    assert_eq!((c.surfels, c.interfaces, c.junction_edges, c.boundary_edges), (4, 4, 1, 12));
    assert_eq!((c.vertices, c.boundary_vertices), (10, 10));
}

#[test]
fn open_interface_plane() {
    // Labels 1 | 2 split along x, no background: one open 3x3 plane of surfels.
    let vol = LabelVolume::from_fn([2, 3, 3], |[x, _, _]| x as u32 + 1).with_background(None);
    let s = DigitalSurface::from_volume(&vol).unwrap();
    let c = s.counts();
    assert_eq!((c.surfels, c.vertices, c.boundary_vertices, c.components), (9, 16, 12, 1));
    assert_eq!(s.components_closed(), &[false]);
    assert_eq!(s.euler_characteristic(), 1); // a disc
}

#[test]
fn grouped_regions_have_no_inner_surfels() {
    let vol = LabelVolume::from_fn([2, 1, 1], |[x, _, _]| x as u32 + 1);
    let per_label = DigitalSurface::from_volume(&vol).unwrap();
    let grouped = DigitalSurface::new(&vol, &RegionMap::single_solid()).unwrap();
    assert_eq!(per_label.num_surfels(), 11);
    assert_eq!(grouped.num_surfels(), 10);
    assert_eq!(grouped.interfaces().len(), 1);
}

// ---- patches: per-interface and per-region meshes ------------------------------------

/// Checks that `p` is an oriented 2-manifold, possibly with boundary: every edge has
/// one or two faces, each direction used once (consistent orientation), and the faces
/// around every vertex form a single fan (its link is one cycle, or one path on the
/// rim). Returns the rim edges as pairs of surface vertices, and `V - E + F`.
fn check_manifold(p: &Patch) -> Result<(Vec<[VertexId; 2]>, i64), TestCaseError> {
    let mut directed = HashMap::new();
    for q in &p.quads {
        for k in 0..4 {
            *directed.entry((q[k], q[(k + 1) % 4])).or_insert(0) += 1;
        }
    }
    prop_assert!(directed.values().all(|&n| n == 1), "an edge is used twice in one direction");
    let mut rim = Vec::new();
    let mut edges = 0i64;
    for &(a, b) in directed.keys() {
        if !directed.contains_key(&(b, a)) {
            rim.push([p.vertices[a as usize], p.vertices[b as usize]]);
        }
        if a < b || !directed.contains_key(&(b, a)) {
            edges += 1;
        }
    }
    // Links: each face around v adds the link edge between v's two neighbours in it.
    let mut links: Vec<Vec<(u32, u32)>> = vec![Vec::new(); p.vertices.len()];
    for q in &p.quads {
        for k in 0..4 {
            links[q[k] as usize].push((q[(k + 3) % 4], q[(k + 1) % 4]));
        }
    }
    for (v, link) in links.iter().enumerate() {
        // A single path or cycle: walk from a link vertex with no incoming link edge
        // (or from anywhere on a cycle) and visit every link edge.
        let next: HashMap<u32, u32> = link.iter().copied().collect();
        prop_assert_eq!(next.len(), link.len());
        let targets: std::collections::HashSet<u32> = link.iter().map(|e| e.1).collect();
        let start = link.iter().map(|e| e.0).find(|a| !targets.contains(a)).unwrap_or(link[0].0);
        let (mut at, mut walked) = (start, 0);
        while let Some(&n) = next.get(&at) {
            walked += 1;
            at = n;
            if at == start || walked > link.len() {
                break;
            }
        }
        prop_assert_eq!(walked, link.len(), "vertex {} has several fans", v);
    }
    Ok((rim, p.vertices.len() as i64 - edges + p.quads.len() as i64))
}

/// Number of edge-connected components of the faces of `p`.
fn patch_components(p: &Patch) -> i64 {
    let mut by_edge: HashMap<(u32, u32), Vec<usize>> = HashMap::new();
    for (f, q) in p.quads.iter().enumerate() {
        for k in 0..4 {
            let (a, b) = (q[k], q[(k + 1) % 4]);
            by_edge.entry((a.min(b), a.max(b))).or_default().push(f);
        }
    }
    let mut comp = vec![usize::MAX; p.quads.len()];
    let mut n = 0;
    for start in 0..p.quads.len() {
        if comp[start] != usize::MAX {
            continue;
        }
        comp[start] = n;
        let mut stack = vec![start];
        while let Some(f) = stack.pop() {
            let q = p.quads[f];
            for k in 0..4 {
                let (a, b) = (q[k], q[(k + 1) % 4]);
                for &g in &by_edge[&(a.min(b), a.max(b))] {
                    if comp[g] == usize::MAX {
                        comp[g] = n;
                        stack.push(g);
                    }
                }
            }
        }
        n += 1;
    }
    n as i64
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]

    /// With pinches split, every region's surface is an oriented 2-manifold: closed when
    /// the volume has a background (Euler characteristic even, at most 2 per
    /// component, and twice the solid's when the region has no pinch), otherwise open exactly
    /// along the domain border. Interface patches are manifolds with boundary. Vertices
    /// are copies of the complex's.
    #[test]
    fn manifold_patches(vol in volume(3), open in any::<bool>()) {
        let vol = if open { vol.with_background(None) } else { vol };
        let Ok(s) = DigitalSurface::from_volume(&vol) else { return Ok(()) };
        let params = PatchParams { manifold: true };
        let dims = vol.dims();
        let on_border = |v: VertexId, axis: usize| {
            let c = s.vertex_corner(v);
            (0..3).any(|k| k != axis && (c[k] == 0 || c[k] as usize == dims[k]))
        };
        let mut faces = 0;
        for r in 0..s.regions().len() {
            let r = RegionId(r as u32);
            if Some(r) == s.regions().background() {
                continue;
            }
            let p = s.region_patch(r, &params);
            faces += p.quads.len();
            let (rim, chi) = check_manifold(&p)?;
            if open {
                for [a, b] in rim {
                    let axis = (0..3).find(|&k| s.vertex_corner(a)[k] != s.vertex_corner(b)[k]).unwrap();
                    prop_assert!(on_border(a, axis) && on_border(b, axis), "rim edge inside the domain");
                }
            } else {
                prop_assert!(rim.is_empty(), "open region surface with a background");
                prop_assert_eq!(chi % 2, 0);
                prop_assert!(chi <= 2 * patch_components(&p));
                // Nothing split: the region's closed union of cubes is a manifold.
                let unsplit = s.region_patch(r, &PatchParams::default());
                if unsplit.vertices.len() == p.vertices.len() {
                    let label = s.regions().labels(r)[0];
                    prop_assert_eq!(chi, 2 * cubical_euler(dims, 1, |v| vol.label(v) == Some(label)));
                }
            }
            for (q, &surfel) in p.quads.iter().zip(&p.surfels) {
                let mut copied = q.map(|v| p.vertices[v as usize]);
                copied.sort_unstable();
                let mut own = s.surfel(surfel).vertices;
                own.sort_unstable();
                prop_assert_eq!(copied, own);
            }
        }
        // Every surfel lies in two region surfaces (one when the other side is the background).
        let expected: usize = s.surfels().iter().map(|sf| {
            2 - usize::from(s.regions().background().is_some_and(|b| sf.regions.contains(&b)))
        }).sum();
        prop_assert_eq!(faces, expected);
        for i in 0..s.interfaces().len() {
            check_manifold(&s.interface_patch(InterfaceId(i as u32), &params))?;
        }
    }
}

/// Regions of the diagonal-pinch fixtures: each voxel its own sphere when split.
#[test]
fn diagonal_pinch_fixtures_become_spheres() {
    let edge = LabelVolume::from_fn([2, 2, 1], |[x, y, _]| u32::from(x == y));
    let corner = LabelVolume::from_fn([2, 2, 2], |[x, y, z]| u32::from(x == y && y == z));
    // Both pinches at once, plus a third voxel of another label on the pinched edge.
    let both = LabelVolume::from_fn([3, 3, 3], |p| match p {
        [0, 0, 0] | [1, 1, 0] | [2, 2, 1] => 1,
        [1, 0, 0] => 2,
        _ => 0,
    });
    for (vol, spheres) in [(edge, 2), (corner, 2), (both, 3)] {
        let s = DigitalSurface::from_volume(&vol).unwrap();
        let r = s.regions().region_of(1).unwrap();
        let p = s.region_patch(r, &PatchParams { manifold: true });
        let (rim, chi) = check_manifold(&p).unwrap();
        assert!(rim.is_empty());
        assert_eq!(chi, 2 * spheres);
        assert_eq!(p.vertices.len() as i64, 8 * spheres);
    }
}

proptest! {
    /// A volume stored `z` fastest (a C-order array, as numpy writes it, read several
    /// layers at a time) and the same labels stored `x` fastest give the same complex:
    /// the same surfels in the same order, vertices, edges and counts, and the same
    /// surface count; with open sides too. Depths up to 80 give batches of up to 8
    /// layers, and remainders.
    #[test]
    fn storage_order_does_not_change_the_surface(
        (dims, labels) in (1usize..=3, 1usize..=3, 1usize..=80).prop_flat_map(|(x, y, z)| {
            (Just([x, y, z]), proptest::collection::vec(0u32..3, x * y * z))
        }),
        open in proptest::array::uniform3(proptest::array::uniform2(any::<bool>())),
    ) {
        let [nx, ny, nz] = dims;
        let fortran = LabelVolume::from_x_fastest(dims, labels.clone()).unwrap().with_open_sides(open);
        let c = ndarray::Array3::from_shape_fn((nx, ny, nz), |(x, y, z)| labels[x + nx * (y + ny * z)]);
        prop_assert!(c.is_standard_layout());
        let c = LabelVolume::new(c).with_open_sides(open);
        let map = RegionMap::per_label();
        prop_assert_eq!(
            DigitalSurface::count_surfels(&fortran, &map).ok(),
            DigitalSurface::count_surfels(&c, &map).ok()
        );
        match (DigitalSurface::new(&fortran, &map), DigitalSurface::new(&c, &map)) {
            (Ok(a), Ok(b)) => {
                prop_assert_eq!(a.surfels(), b.surfels());
                prop_assert_eq!(a.edges(), b.edges());
                prop_assert_eq!(a.num_vertices(), b.num_vertices());
                for v in 0..a.num_vertices() {
                    prop_assert_eq!(a.vertex_corner(VertexId(v as u32)), b.vertex_corner(VertexId(v as u32)));
                }
                prop_assert_eq!(a.counts(), b.counts());
                // A cap at the surface's size builds it; one below refuses it, in both
                // orders (the column scan counts per row, the layer scan per slab).
                let n = a.num_surfels() as u64;
                for vol in [&fortran, &c] {
                    prop_assert_eq!(&DigitalSurface::new_within(vol, &map, n).unwrap(), &a);
                    prop_assert_eq!(
                        DigitalSurface::new_within(vol, &map, n - 1),
                        Err(SurfaceError::TooManySurfels(n - 1))
                    );
                    prop_assert_eq!(
                        DigitalSurface::new_within(vol, &map, 0),
                        Err(SurfaceError::TooManySurfels(0))
                    );
                }
            }
            (a, b) => prop_assert_eq!(a.err().map(|e| e.to_string()), b.err().map(|e| e.to_string())),
        }
    }
}
