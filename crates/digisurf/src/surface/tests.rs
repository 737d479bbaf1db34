//! Tests of the surface's construction and queries.

use proptest::prelude::*;

use super::*;

/// The edges, their surfels, each surfel's edges and each vertex's neighbours as a
/// sort of all the surfels' sides by end points and slot gives them.
fn by_sorting(s: &DigitalSurface) -> (Vec<Edge>, Lists<SurfelId>, Vec<[EdgeId; 4]>, Lists<VertexId>) {
    let mut keys: Vec<(u64, u32)> = Vec::new();
    for (f, surfel) in s.surfels.iter().enumerate() {
        for i in 0..4 {
            let (a, b) = (surfel.vertices[i].0, surfel.vertices[(i + 1) % 4].0);
            keys.push((((a.min(b) as u64) << 32) | a.max(b) as u64, (f as u32) * 4 + i as u32));
        }
    }
    keys.sort_unstable();
    let (mut edges, mut offsets, mut items) = (Vec::new(), vec![0u32], Vec::new());
    let mut surfel_edges = vec![[EdgeId(0); 4]; s.surfels.len()];
    for group in keys.chunk_by(|x, y| x.0 == y.0) {
        let e = EdgeId(edges.len() as u32);
        let (a, b) = (VertexId((group[0].0 >> 32) as u32), VertexId(group[0].0 as u32));
        let (ca, cb) = (s.vertex_corners[a.index()], s.vertex_corners[b.index()]);
        let axis = (0..3).find(|&k| ca[k] != cb[k]).unwrap_or(0);
        for &(_, slot) in group {
            surfel_edges[(slot / 4) as usize][(slot % 4) as usize] = e;
            items.push(SurfelId(slot / 4));
        }
        offsets.push(items.len() as u32);
        let kind = s.edge_kind(ca.min(cb), axis, &items[offsets[offsets.len() - 2] as usize..]);
        edges.push(Edge { vertices: [a, b], axis: axis as u8, kind });
    }
    let mut lists = vec![Vec::new(); s.vertex_corners.len()];
    for e in &edges {
        lists[e.vertices[0].index()].push(e.vertices[1]);
        lists[e.vertices[1].index()].push(e.vertices[0]);
    }
    let mut nbr_offsets = vec![0u32];
    let mut nbrs = Vec::new();
    for mut l in lists {
        l.sort_unstable();
        nbrs.extend(l);
        nbr_offsets.push(nbrs.len() as u32);
    }
    (edges, Lists::from_parts(offsets, items), surfel_edges, Lists::from_parts(nbr_offsets, nbrs))
}

fn agrees_with_sorting(vol: &LabelVolume) {
    let Ok(s) = DigitalSurface::from_volume(vol) else { return };
    let (edges, edge_surfels, surfel_edges, neighbours) = by_sorting(&s);
    assert_eq!(s.edges, edges);
    assert_eq!(s.edge_surfels, edge_surfels);
    assert_eq!(s.surfel_edges, surfel_edges);
    assert_eq!(s.vertex_neighbours, neighbours);
    assert_eq!(s.vertex_surfels_in_one_pass(), s.vertex_surfels);
    assert_eq!(s.components_by_search(), (s.surfel_component.clone(), s.component_closed.clone()));
    // The cells as the separate passes built them.
    let mut r = s.clone();
    r.build_edges();
    r.build_vertex_lists();
    assert_eq!(
        (&r.edges, &r.edge_surfels, &r.surfel_edges, &r.vertex_neighbours),
        (&s.edges, &s.edge_surfels, &s.surfel_edges, &s.vertex_neighbours)
    );
    assert_eq!((&r.boundary_vertex, &r.pinched_vertex), (&s.boundary_vertex, &s.pinched_vertex));
}

/// Many pieces of vertices: a random 30^3 volume of three labels, closed and open.
#[test]
fn edges_built_per_vertex_are_those_of_a_sort_of_all_sides() {
    let mut x = 12345u64;
    let labels: Vec<u32> = (0..27_000)
        .map(|_| {
            x = x.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((x >> 33) % 3) as u32
        })
        .collect();
    let vol = LabelVolume::from_x_fastest([30, 30, 30], labels).unwrap();
    let s = DigitalSurface::from_volume(&vol).unwrap();
    assert!(s.num_vertices() > 4 * crate::csr::PIECE);
    agrees_with_sorting(&vol);
    agrees_with_sorting(&vol.with_background(None));
}

/// A volume of `dims` with labels `0..labels` drawn by a linear congruential generator
/// from `seed`.
fn random_volume(dims: [usize; 3], seed: u64, labels: u64) -> LabelVolume {
    let mut x = seed;
    LabelVolume::from_fn(dims, |_| {
        x = x.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        ((x >> 33) % labels) as u32
    })
}

/// The column scan cut into many ranges of rows finds the faces a single range finds, in
/// the same order.
#[test]
fn column_scan_does_not_depend_on_the_row_ranges() {
    let vol = random_volume([13, 17, 11], 777, 3);
    let vol = LabelVolume::new(vol.labels().as_standard_layout().into_owned());
    let regions = RegionMap::per_label().resolve(&vol).unwrap();
    let outside = scan::outside_of(&vol.view(), &regions);
    type Face = ([u32; 3], u8, [u32; 2], [u32; 2]);
    let flat = |tasks| -> Vec<Face> {
        let found = scan::all_faces(&vol.view(), &regions, &outside, tasks, &scan::Cap::none()).unwrap();
        found.into_iter().flatten().flatten().map(|f| (f.cell, f.axis, f.regions, f.labels)).collect()
    };
    let one = flat(1);
    assert!(one.len() > 1000);
    for tasks in [2, 5, 17, 40] {
        assert_eq!(flat(tasks), one);
    }
}

/// A volume of several times [`scan::Cap::EVERY`] faces (counted within slabs and rows,
/// not only at their ends), stored either way, builds at its size and is refused below it.
#[test]
fn a_cap_counted_many_times_builds_at_the_size_and_refuses_below() {
    let layers = random_volume([96, 90, 40], 99, 2);
    let columns = LabelVolume::new(layers.labels().as_standard_layout().into_owned());
    assert!(scan::z_fastest(&columns.view()).is_some() && scan::z_fastest(&layers.view()).is_none());
    let map = RegionMap::per_label();
    let whole = DigitalSurface::new(&layers, &map).unwrap();
    let n = whole.num_surfels() as u64;
    assert!(n > 4 * scan::Cap::EVERY, "{n}");
    for vol in [&layers, &columns] {
        assert_eq!(DigitalSurface::new_within(vol, &map, n).unwrap(), whole);
        for cap in [n - 1, scan::Cap::EVERY / 2, 1] {
            assert_eq!(DigitalSurface::new_within(vol, &map, cap), Err(SurfaceError::TooManySurfels(cap)));
        }
    }
}

proptest! {
    /// A volume stored `z` fastest (read column by column) and the same labels stored
    /// `x` fastest (read layer by layer) give the same surface.
    #[test]
    fn columns_and_layers_give_the_same_surface(
        (dims, labels) in (1usize..=6, 1usize..=6, 2usize..=6).prop_flat_map(|(x, y, z)| {
            (Just([x, y, z]), proptest::collection::vec(0u32..4, x * y * z))
        }),
        open in any::<bool>(),
        sides in any::<[[bool; 2]; 3]>(),
    ) {
        let layers = LabelVolume::from_x_fastest(dims, labels).unwrap();
        let columns = LabelVolume::new(layers.labels().as_standard_layout().into_owned());
        prop_assert!(scan::z_fastest(&columns.view()).is_some());
        prop_assert!(dims[0] * dims[1] == 1 || scan::z_fastest(&layers.view()).is_none());
        let (layers, columns) = if open {
            (layers.with_background(None), columns.with_background(None))
        } else {
            (layers.with_open_sides(sides), columns.with_open_sides(sides))
        };
        let (a, b) = (DigitalSurface::from_volume(&layers), DigitalSurface::from_volume(&columns));
        match (a, b) {
            (Ok(a), Ok(b)) => prop_assert_eq!(a, b),
            (a, b) => prop_assert_eq!(a.is_err(), b.is_err()),
        }
    }

    #[test]
    fn edges_built_per_vertex_are_those_of_a_sort_of_small_volumes(
        (dims, labels) in (1usize..=5, 1usize..=5, 1usize..=5).prop_flat_map(|(x, y, z)| {
            (Just([x, y, z]), proptest::collection::vec(0u32..4, x * y * z))
        }),
        open in any::<bool>(),
    ) {
        let vol = LabelVolume::from_x_fastest(dims, labels).unwrap();
        agrees_with_sorting(&if open { vol.with_background(None) } else { vol });
    }
}
