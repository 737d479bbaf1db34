//! The engine built from a quad mesh: its triangles, vertex classes, quadrics and first
//! candidates.

#[allow(clippy::wildcard_imports)]
use super::*;

impl<'m> Engine<'m> {
    /// The engine of `mesh`; `Interrupted` once `interrupt` is raised (the per-vertex
    /// and per-triangle passes poll it), which the engine then keeps polling.
    pub(crate) fn new(
        mesh: &'m QuadMesh,
        options: &Options,
        interrupt: &Interrupt,
    ) -> Result<Engine<'m>, SimplifyError> {
        let n = mesh.positions.len();
        let bad = |s: String| Err(SimplifyError::InvalidMesh(s));
        if let Some(i) = mesh.positions.iter().position(|p| !p.is_finite()) {
            return bad(format!("vertex {i} has a non-finite position"));
        }
        if mesh.face_labels.len() != mesh.quads.len() {
            return bad(format!("{} faces but {} label pairs", mesh.quads.len(), mesh.face_labels.len()));
        }
        if !mesh.face_materials.is_empty() && mesh.face_materials.len() != mesh.quads.len() {
            return bad(format!(
                "{} faces but {} face materials",
                mesh.quads.len(),
                mesh.face_materials.len()
            ));
        }
        let mut group = vec![NONE; mesh.quads.len()];
        for (g, fg) in mesh.groups.iter().enumerate() {
            for &f in &fg.faces {
                match group.get_mut(f as usize) {
                    None => return bad(format!("group {} lists face {f}, out of range", fg.name)),
                    Some(x) if *x == NONE => *x = g as u32,
                    Some(_) => {}
                }
            }
        }
        let mut key_ids: FxHashMap<Key, u32> = FxHashMap::default();
        let mut keys = Vec::new();
        let mut tris = Vec::with_capacity(2 * mesh.quads.len());
        let mut tri_key = Vec::with_capacity(2 * mesh.quads.len());
        let mut tri_face = Vec::with_capacity(2 * mesh.quads.len());
        for (f, q) in mesh.quads.iter().enumerate() {
            if let Some(&v) = q.iter().find(|&&v| v as usize >= n) {
                return bad(format!("face {f} refers to vertex {v}, out of range"));
            }
            let key = Key {
                labels: mesh.face_labels[f],
                material: mesh.face_materials.get(f).copied().unwrap_or(NONE),
                group: group[f],
            };
            let k = *key_ids.entry(key).or_insert_with(|| {
                keys.push(key);
                keys.len() as u32 - 1
            });
            let mut distinct: Vec<u32> = Vec::with_capacity(4);
            for (i, &v) in q.iter().enumerate() {
                if v != q[(i + 3) % 4] {
                    distinct.push(v);
                }
            }
            if distinct.is_empty() {
                distinct.push(q[0]);
            }
            let mut sorted = distinct.clone();
            sorted.sort_unstable();
            sorted.dedup();
            if sorted.len() != distinct.len() || distinct.len() < 3 {
                return bad(format!("face {f} has fewer than three distinct vertices"));
            }
            if distinct.len() == 4 {
                tris.push([q[0], q[1], q[2]]);
                tris.push([q[0], q[2], q[3]]);
                tri_key.extend([k, k]);
                tri_face.extend([f as u32, f as u32]);
            } else {
                tris.push([distinct[0], distinct[1], distinct[2]]);
                tri_key.push(k);
                tri_face.push(f as u32);
            }
        }
        let pos = mesh.positions.clone();
        let mut vtris = vec![Vec::new(); n];
        for (t, tri) in tris.iter().enumerate() {
            for &v in tri {
                vtris[v as usize].push(t as u32);
            }
        }
        let nt = tris.len();
        let area_sum: f64 = tris.iter().map(|t| tri_normal(t.map(|v| pos[v as usize])).length() * 0.5).sum();
        let mean_area = if nt > 0 { (area_sum / nt as f64).max(1e-300) } else { 1.0 };
        let mut edge_len = 0.0;
        for t in &tris {
            for i in 0..3 {
                edge_len += pos[t[i] as usize].distance(pos[t[(i + 1) % 3] as usize]);
            }
        }
        let mean_edge = if nt > 0 { (edge_len / (3 * nt) as f64).max(1e-300) } else { 1.0 };
        let mut engine = Engine {
            options: *options,
            interrupt: interrupt.clone(),
            moved: vec![false; n],
            pos,
            tri_alive: vec![true; nt],
            alive: nt,
            class: vec![Class::Corner; n],
            version: vec![0; n],
            quadric: vec![Quadric::default(); n],
            points: vec![Vec::new(); nt],
            grid: None,
            heap: BinaryHeap::new(),
            keys,
            frozen: vec![NONE; nt],
            frozen_vertex: vec![false; n],
            input: mesh,
            input_triangles: nt,
            error_bound: 0.0,
            length_weight: 1e-3,
            mean_area,
            slots: Vec::new(),
            retry: vec![false; n],
            grid_built_at: nt,
            key_regions: Vec::new(),
            region_volume: Vec::new(),
            patch_area: Vec::new(),
            max_error: 0.0,
            cos_normal: options.max_normal_change_deg.to_radians().cos(),
            tris,
            tri_key,
            vtris,
        };
        // Per vertex, in parallel: the plane quadrics of its triangles (in the order of
        // its triangles, so the sums do not depend on the thread count), weighted by area
        // relative to the mean so that costs are squared lengths; then its class and its
        // line quadrics.
        let e = &engine;
        let classified: Vec<(Class, Quadric)> = (0..n as u32)
            .into_par_iter()
            .map(|v| {
                let mut q = Quadric::default();
                if e.interrupt.is_raised() {
                    return (Class::Corner, q);
                }
                for &t in &e.vtris[v as usize] {
                    let p = e.tris[t as usize].map(|x| e.pos[x as usize]);
                    let nrm = tri_normal(p);
                    let len = nrm.length();
                    if len > 0.0 {
                        q.add(&Quadric::plane(p[0], nrm / len, 0.5 * len / mean_area));
                    }
                }
                e.classify(v, mean_edge, q)
            })
            .collect();
        engine.stop()?;
        for (v, (class, q)) in classified.into_iter().enumerate() {
            engine.class[v] = class;
            engine.quadric[v] = q;
        }
        let mut region_ids: FxHashMap<u32, u32> = FxHashMap::default();
        for k in &engine.keys {
            let ids = k.labels.map(|l| {
                let next = region_ids.len() as u32;
                *region_ids.entry(l).or_insert(next)
            });
            engine.key_regions.push(ids);
        }
        engine.region_volume = vec![(0.0, 0.0); region_ids.len()];
        engine.patch_area = vec![(0.0, 0.0); engine.keys.len()];
        for t in 0..nt {
            let p = engine.tris[t].map(|v| engine.pos[v as usize]);
            let k = engine.tri_key[t] as usize;
            let det = p[0].dot(p[1].cross(p[2]));
            let [a, b] = engine.key_regions[k];
            engine.region_volume[a as usize].0 += det;
            engine.region_volume[b as usize].0 -= det;
            engine.patch_area[k].0 += 0.5 * tri_normal(p).length();
        }
        if options.check_intersections {
            let (lo, hi) = engine.bounds();
            let mut grid = Grid::new(lo, hi, 2.0 * mean_edge, nt);
            for t in 0..nt {
                let (lo, hi) = engine.tri_box(&engine.tris[t]);
                grid.insert(t as u32, lo, hi);
            }
            // Each triangle against those after it that share no vertex with it, in
            // parallel (each pair tested once; the set of pairs found does not depend on
            // the order).
            let e = &engine;
            let pairs: Vec<(usize, usize)> = (0..nt)
                .into_par_iter()
                .fold(
                    || (Vec::new(), Vec::new()),
                    |(mut hits, mut near): (Vec<(usize, usize)>, Vec<u32>), t| {
                        if e.interrupt.is_raised() {
                            return (hits, near);
                        }
                        let tri = e.tris[t];
                        let p = tri.map(|x| e.pos[x as usize]);
                        let (lo, hi) = e.tri_box(&tri);
                        grid.candidates_into(lo, hi, &mut near);
                        for &s in &near {
                            let st = e.tris[s as usize];
                            if s as usize > t && !st.iter().any(|x| tri.contains(x)) {
                                let q = st.map(|x| e.pos[x as usize]);
                                if boxes_meet(&p, &q) && meet_off_shared((tri, p), (st, q)) {
                                    hits.push((t, s as usize));
                                }
                            }
                        }
                        (hits, near)
                    },
                )
                .map(|(hits, _)| hits)
                .reduce(Vec::new, |mut a, mut b| {
                    a.append(&mut b);
                    a
                });
            engine.stop()?;
            for (t, s) in pairs {
                engine.frozen[s] = tri_face[s];
                engine.frozen[t] = tri_face[t];
            }
            // Both triangles of a frozen face.
            for t in 0..nt {
                if engine.frozen[t] != NONE {
                    for s in [t.wrapping_sub(1), t + 1] {
                        if s < nt && tri_face[s] == tri_face[t] {
                            engine.frozen[s] = tri_face[t];
                        }
                    }
                }
            }
            for t in 0..nt {
                if engine.frozen[t] != NONE {
                    for x in engine.tris[t] {
                        engine.frozen_vertex[x as usize] = true;
                    }
                }
            }
            engine.grid = Some(grid);
        }
        Ok(engine)
    }
}
