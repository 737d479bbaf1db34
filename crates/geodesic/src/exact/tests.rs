//! Unit tests of the exact method (and the test meshes the heat method's tests share).

use glam::DVec3;

use crate::SurfacePoint;

use super::*;

/// A grid of `n x n` quads over `[0, 1]^2` lifted by `height`, corners jittered in
/// the plane by a fixed pattern.
pub(crate) fn grid(n: usize, height: impl Fn(f64, f64) -> f64) -> (Vec<DVec3>, Vec<[u32; 4]>) {
    let mut positions = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            let jitter = |a: usize, b: usize| {
                if a == 0 || a == n || b == 0 || b == n {
                    0.0
                } else {
                    0.3 * (((a * 7 + b * 13) % 11) as f64 / 11.0 - 0.5) / n as f64
                }
            };
            let (x, y) = (i as f64 / n as f64 + jitter(i, j), j as f64 / n as f64 + jitter(j, i));
            positions.push(DVec3::new(x, y, height(x, y)));
        }
    }
    let id = |i: usize, j: usize| (j * (n + 1) + i) as u32;
    let quads = (0..n)
        .flat_map(|j| (0..n).map(move |i| [id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)]))
        .collect();
    (positions, quads)
}

/// A flat `n x n` grid over `[0, 1]^2` (its vertices, unfolded) folded by 90 degrees along
/// the grid line `x = 0.5`.
fn folded_sheet(n: usize) -> (Vec<DVec3>, GeodesicMesh) {
    let flat: Vec<DVec3> =
        (0..=n).flat_map(|j| (0..=n).map(move |i| DVec3::new(i as f64, j as f64, 0.0) / n as f64)).collect();
    let (_, quads) = grid(n, |_, _| 0.0);
    let fold = |p: DVec3| if p.x <= 0.5 { p } else { DVec3::new(0.5, p.y, p.x - 0.5) };
    let folded: Vec<DVec3> = flat.iter().map(|&p| fold(p)).collect();
    (flat, GeodesicMesh::new(&folded, &quads).unwrap())
}

/// Shortest paths along the edges (an upper bound of the geodesic distance).
fn dijkstra(mesh: &GeodesicMesh, sources: &[u32]) -> Vec<f64> {
    let mut d = vec![f64::INFINITY; mesh.num_vertices()];
    let mut heap = Queue::new();
    for &s in sources {
        d[s as usize] = 0.0;
        heap.push(0.0, u64::from(s));
    }
    while let Some((key, id)) = heap.pop() {
        let v = id as u32;
        if key > d[v as usize] {
            continue;
        }
        for &t in mesh.vertex_tris(v) {
            for &u in &mesh.triangles[t as usize] {
                let du = key + mesh.pos(v).distance(mesh.pos(u));
                if du < d[u as usize] {
                    d[u as usize] = du;
                    heap.push(du, u64::from(u));
                }
            }
        }
    }
    d
}

#[test]
fn planar_meshes_give_euclidean_distances() {
    let (positions, quads) = grid(12, |_, _| 0.0);
    let mesh = GeodesicMesh::new(&positions, &quads).unwrap();
    for source in [0u32, 7, 80, 168] {
        let (d, _) = exact_distances(&mesh, &[source]).unwrap();
        for (v, p) in positions.iter().enumerate() {
            let truth = p.distance(positions[source as usize]);
            assert!((d[v] - truth).abs() < 1e-9, "source {source}, vertex {v}: {} vs {truth}", d[v]);
        }
    }
}

#[test]
fn a_folded_sheet_unfolds() {
    // A flat grid folded by 90 degrees along the grid line x = 0.5.
    let (flat, mesh) = folded_sheet(10);
    for source in [0u32, 58, 120] {
        let (d, _) = exact_distances(&mesh, &[source]).unwrap();
        for v in 0..flat.len() {
            let truth = flat[v].distance(flat[source as usize]);
            assert!((d[v] - truth).abs() < 1e-9, "source {source}, vertex {v}: {} vs {truth}", d[v]);
        }
    }
}

#[test]
fn bounded_by_euclidean_and_edge_paths_and_multi_source_is_the_minimum() {
    let (positions, quads) = grid(16, |x, y| 0.25 * (6.0 * x).sin() * (5.0 * y).cos());
    let mesh = GeodesicMesh::new(&positions, &quads).unwrap();
    let (a, _) = exact_distances(&mesh, &[20]).unwrap();
    let (b, _) = exact_distances(&mesh, &[250]).unwrap();
    let (both, _) = exact_distances(&mesh, &[20, 250]).unwrap();
    let edges = dijkstra(&mesh, &[20]);
    let mut strictly_shorter = 0;
    for v in 0..positions.len() {
        let straight = positions[v].distance(positions[20]);
        assert!(a[v] >= straight - 1e-12 && a[v] <= edges[v] + 1e-12, "vertex {v}");
        assert!((both[v] - a[v].min(b[v])).abs() < 1e-12, "vertex {v}");
        strictly_shorter += usize::from(a[v] < edges[v] - 1e-6);
    }
    assert!(strictly_shorter > positions.len() / 2);
}

/// Two computations of one quantity: the run on the renumbered copy (what
/// [`exact_distances`] does) and a run on the input numbering, on the same triangles.
#[test]
fn the_renumbered_copy_is_the_same_surface_with_the_same_distances() {
    let (positions, quads) = grid(12, |x, y| 0.3 * (5.0 * x).sin() * (4.0 * y).cos());
    let mesh = GeodesicMesh::new(&positions, &quads).unwrap();
    let (local, vertex_ids, triangle_ids) = mesh.spatially_ordered().unwrap();
    for ids in [&vertex_ids, &triangle_ids] {
        let mut sorted = ids.clone();
        sorted.sort_unstable();
        assert!(sorted.iter().enumerate().all(|(i, &x)| x as usize == i), "a permutation");
    }
    assert!(vertex_ids.iter().enumerate().any(|(i, &x)| x as usize != i), "renumbered");
    for v in 0..mesh.num_vertices() {
        assert_eq!(local.position(vertex_ids[v]), mesh.position(v as u32));
    }
    for (t, tri) in mesh.triangles().iter().enumerate() {
        assert_eq!(local.triangles()[triangle_ids[t] as usize], tri.map(|v| vertex_ids[v as usize]));
    }
    for source in [0u32, 30, 97] {
        let mut direct = Propagation::new(&mesh);
        direct.start_vertex(source);
        direct.run();
        let (d, _) = exact_distances(&mesh, &[source]).unwrap();
        for v in 0..d.len() {
            assert!((d[v] - direct.dist[v]).abs() < 1e-12, "source {source}, vertex {v}");
        }
    }
}

#[test]
fn the_distance_is_symmetric() {
    let (positions, quads) = grid(14, |x, y| 0.3 * (x * x - y * y));
    let mesh = GeodesicMesh::new(&positions, &quads).unwrap();
    let (from_a, _) = exact_distances(&mesh, &[17]).unwrap();
    let (from_b, _) = exact_distances(&mesh, &[190]).unwrap();
    assert!((from_a[190] - from_b[17]).abs() < 1e-10, "{} vs {}", from_a[190], from_b[17]);
}

#[test]
fn unreached_components_are_infinite() {
    let (mut positions, mut quads) = grid(3, |_, _| 0.0);
    let n = positions.len() as u32;
    positions.extend([DVec3::new(5.0, 0.0, 0.0), DVec3::new(6.0, 0.0, 0.0), DVec3::new(5.0, 1.0, 0.0)]);
    quads.push([n, n + 1, n + 2, n + 2]);
    assert!(GeodesicMesh::new(&positions, &quads).is_err());
    let tris: Vec<Vec<u32>> = quads[..9].iter().map(|q| q.to_vec()).chain([vec![n, n + 1, n + 2]]).collect();
    let mesh = GeodesicMesh::new(&positions, &tris).unwrap();
    let (d, _) = exact_distances(&mesh, &[0]).unwrap();
    assert!(d[n as usize].is_infinite() && d[15].is_finite());
    assert_eq!(exact_distances(&mesh, &[]).unwrap_err(), GeodesicError::NoSource);
}

/// The triangles of `positions`/`triangles` split 1-to-4 at their sides' midpoints:
/// the same polyhedral surface, so the same geodesic distances, on another mesh.
fn subdivided(positions: &[DVec3], triangles: &[[u32; 3]]) -> (Vec<DVec3>, Vec<[u32; 3]>) {
    let mut positions = positions.to_vec();
    let mut midpoints = std::collections::HashMap::new();
    let mut mid = |a: u32, b: u32, positions: &mut Vec<DVec3>| -> u32 {
        *midpoints.entry((a.min(b), a.max(b))).or_insert_with(|| {
            positions.push(0.5 * (positions[a as usize] + positions[b as usize]));
            (positions.len() - 1) as u32
        })
    };
    let mut out = Vec::new();
    for &[a, b, c] in triangles {
        let (ab, bc, ca) = (mid(a, b, &mut positions), mid(b, c, &mut positions), mid(c, a, &mut positions));
        out.extend([[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]]);
    }
    (positions, out)
}

/// Two computations of one quantity: the distances at the coarse vertices must not
/// change when every triangle is split (new vertices are flat, so nearly every one
/// is a candidate for the flat-vertex and pruning rules), on a surface with saddles
/// and on a convex polyhedron.
#[test]
fn subdividing_the_triangles_keeps_the_distances() {
    let (positions, quads) = grid(10, |x, y| 0.3 * (5.0 * x).sin() * (4.0 * y).cos());
    let bumpy = GeodesicMesh::new(&positions, &quads).unwrap();
    // A convex polyhedron: an octahedron with unequal axes and a tilted top.
    let octahedron = vec![
        DVec3::new(1.3, 0.0, 0.0),
        DVec3::new(-1.0, 0.1, 0.0),
        DVec3::new(0.0, 0.9, 0.0),
        DVec3::new(0.1, -1.1, 0.0),
        DVec3::new(0.2, 0.1, 1.2),
        DVec3::new(-0.1, 0.0, -0.8),
    ];
    let faces: Vec<[u32; 3]> =
        vec![[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]];
    let convex = GeodesicMesh::new(&octahedron, &faces).unwrap();
    for (name, mesh, source) in [("bumpy grid", bumpy, 14u32), ("octahedron", convex, 4)] {
        let coarse_positions: Vec<DVec3> =
            (0..mesh.num_vertices() as u32).map(|v| mesh.position(v)).collect();
        let (mut fine_positions, mut fine) = (coarse_positions.clone(), mesh.triangles().to_vec());
        for _ in 0..2 {
            (fine_positions, fine) = subdivided(&fine_positions, &fine);
        }
        let fine_mesh = GeodesicMesh::new(&fine_positions, &fine).unwrap();
        let (coarse_d, _) = exact_distances(&mesh, &[source]).unwrap();
        let (fine_d, _) = exact_distances(&fine_mesh, &[source]).unwrap();
        for v in 0..coarse_d.len() {
            assert!(
                (coarse_d[v] - fine_d[v]).abs() < 1e-9,
                "{name}, vertex {v}: {} coarse, {} subdivided",
                coarse_d[v],
                fine_d[v]
            );
        }
        // Every fine vertex also agrees with the fine mesh's own source on the
        // other side of the symmetry d(a, b) = d(b, a).
        let far = (0..fine_d.len()).max_by(|&a, &b| fine_d[a].total_cmp(&fine_d[b])).unwrap() as u32;
        let (back, _) = exact_distances(&fine_mesh, &[far]).unwrap();
        assert!((back[source as usize] - fine_d[far as usize]).abs() < 1e-9, "{name}: symmetry");
    }
}

/// A developable surface that closes on itself: the side of a prism over a 7-gon
/// unrolls onto a plane strip, where the distance is the Euclidean one, the least
/// over the strip's copies shifted by the perimeter.
#[test]
fn prism_sides_unroll_to_the_plane() {
    let (sides, rows) = (7usize, 9usize);
    let radius = [1.0, 1.3, 0.8, 1.1, 0.9, 1.2, 1.0];
    let corner = |i: usize| {
        let i = i % sides;
        let a = 2.0 * PI * i as f64 / sides as f64 + 0.1 * (i % 3) as f64;
        DVec3::new(radius[i] * a.cos(), radius[i] * a.sin(), 0.0)
    };
    // Arc length along the polygon to corner i.
    let mut arc = vec![0.0];
    for i in 0..sides {
        arc.push(arc[i] + corner(i).distance(corner(i + 1)));
    }
    let perimeter = arc[sides];
    let mut positions = Vec::new();
    let mut unrolled = Vec::new();
    for r in 0..=rows {
        let z = 0.25 * r as f64;
        for i in 0..sides {
            positions.push(corner(i) + DVec3::new(0.0, 0.0, z));
            unrolled.push(DVec2::new(arc[i], z));
        }
    }
    let id = |i: usize, r: usize| (r * sides + i % sides) as u32;
    let quads: Vec<[u32; 4]> = (0..rows)
        .flat_map(|r| (0..sides).map(move |i| [id(i, r), id(i + 1, r), id(i + 1, r + 1), id(i, r + 1)]))
        .collect();
    let mesh = GeodesicMesh::new(&positions, &quads).unwrap();
    let truth = |p: DVec2, q: DVec2| {
        [-perimeter, 0.0, perimeter]
            .iter()
            .map(|&shift| p.distance(q + DVec2::new(shift, 0.0)))
            .fold(f64::INFINITY, f64::min)
    };
    for source in [id(0, 0), id(3, 4), id(5, 9)] {
        let (d, _) = exact_distances(&mesh, &[source]).unwrap();
        for v in 0..positions.len() {
            let t = truth(unrolled[v], unrolled[source as usize]);
            assert!((d[v] - t).abs() < 1e-9, "source {source}, vertex {v}: {} vs {t}", d[v]);
        }
    }
}

#[test]
fn a_source_inside_a_face_of_a_plane_gives_euclidean_distances() {
    let (positions, quads) = grid(9, |_, _| 0.0);
    let mesh = GeodesicMesh::new(&positions, &quads).unwrap();
    for point in [DVec3::new(0.437, 0.512, 0.0), DVec3::new(0.05, 0.93, 0.0), DVec3::new(0.5, 0.0, 0.0)] {
        let p = mesh.nearest_point(point + DVec3::new(0.0, 0.0, 0.3)).unwrap();
        assert!(
            mesh.point_position(p).distance(point) < 1e-12,
            "{point}: placed at {}",
            mesh.point_position(p)
        );
        let (d, _) = exact_distances_from(&mesh, &[p]).unwrap();
        for (v, q) in positions.iter().enumerate() {
            let truth = q.distance(point);
            assert!((d[v] - truth).abs() < 1e-9, "{point}, vertex {v}: {} vs {truth}", d[v]);
        }
    }
    // A point at a vertex is that vertex's source.
    let at_vertex = mesh.nearest_point(positions[40]).unwrap();
    assert_eq!(
        exact_distances_from(&mesh, &[at_vertex]).unwrap().0,
        exact_distances(&mesh, &[40]).unwrap().0
    );
    let bad = SurfacePoint { triangle: u32::MAX, barycentric: [1.0, 0.0, 0.0] };
    assert!(matches!(exact_distances_from(&mesh, &[bad]), Err(GeodesicError::InvalidSource(_))));
}

#[test]
fn a_face_source_on_a_folded_sheet_unfolds() {
    let (flat, mesh) = folded_sheet(8);
    let source = DVec3::new(0.2, 0.33, 0.0);
    let p = mesh.nearest_point(source).unwrap();
    let (d, _) = exact_distances_from(&mesh, &[p]).unwrap();
    for v in 0..flat.len() {
        let truth = flat[v].distance(source);
        assert!((d[v] - truth).abs() < 1e-9, "vertex {v}: {} vs {truth}", d[v]);
    }
}
