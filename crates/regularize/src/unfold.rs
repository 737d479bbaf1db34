//! The fold-free post-condition: vertices of folded quads pulled back towards the input.

use glam::DVec3;
use rayon::prelude::*;
use voxreg_digisurf::{DigitalSurface, EdgeId, VertexId};
use voxreg_quality::{folded_pairs, folded_pairs_of, folded_quads};

/// Removes every folded quad and folded adjacent pair (as [`voxreg_quality`] defines
/// them) by moving the vertices of the folded quads back along their displacement from
/// the input: each round halves the displacement of every vertex of a folded quad, and
/// from the eighth round on sets it to zero. Returns the number of vertices moved.
///
/// It terminates with no fold: the input staircase has none (its quads are flat and
/// adjacent ones meet at 0 or 90 degrees), a quad or pair whose vertices are all back at
/// the input cannot fold, and after the eighth round each round sends at least one more
/// quad back. Each vertex stays on the segment from its input to its solved position,
/// so inside its clamping box (Proposition 2 still holds).
pub(crate) fn unfold(surface: &DigitalSurface, input: &[DVec3], positions: &mut [DVec3]) -> usize {
    let quads: Vec<[u32; 4]> = surface.surfels().iter().map(|s| s.vertices.map(|v| v.0)).collect();
    let displacement: Vec<DVec3> = positions.iter().zip(input).map(|(x, p)| *x - *p).collect();
    let mut keep = vec![1.0f64; positions.len()];
    let mut moved = vec![false; positions.len()];
    // The quads to check: all at first, then those within reach of the vertices just moved
    // (every quad around every vertex of a quad around a moved vertex), so that each
    // edge at a moved vertex has all its quads in the subset and pairs count as on the
    // whole mesh.
    let mut candidates: Vec<usize> = (0..quads.len()).collect();
    let mut mark = vec![false; quads.len()];
    for round in 0.. {
        let mut folded: Vec<usize>;
        if round == 0 {
            // Every quad: the surface's own edges give the shared ones without a sort.
            folded = folded_quads(positions, &quads);
            let shared = shared_edges(surface);
            folded.extend(folded_pairs_of(positions, &quads, &shared).into_iter().flat_map(|(a, b)| [a, b]));
        } else {
            let sub: Vec<[u32; 4]> = candidates.iter().map(|&f| quads[f]).collect();
            folded = folded_quads(positions, &sub).into_iter().map(|i| candidates[i]).collect();
            folded.extend(
                folded_pairs(positions, &sub).into_iter().flat_map(|(a, b)| [candidates[a], candidates[b]]),
            );
        }
        if folded.is_empty() {
            break;
        }
        let mut changed = Vec::new();
        for f in folded {
            for v in quads[f] {
                let v = v as usize;
                keep[v] = if round >= 7 { 0.0 } else { 0.5 * keep[v] };
                moved[v] = true;
                positions[v] = input[v] + keep[v] * displacement[v];
                changed.push(v);
            }
        }
        changed.sort_unstable();
        changed.dedup();
        let mut ring = Vec::new();
        for &v in &changed {
            for s in surface.vertex_surfels(VertexId(v as u32)) {
                for w in surface.surfel(*s).vertices {
                    ring.push(w);
                }
            }
        }
        ring.sort_unstable();
        ring.dedup();
        candidates.clear();
        for w in ring {
            for s in surface.vertex_surfels(w) {
                if !mark[s.index()] {
                    mark[s.index()] = true;
                    candidates.push(s.index());
                }
            }
        }
        candidates.iter().for_each(|&f| mark[f] = false);
        candidates.sort_unstable();
    }
    moved.iter().filter(|m| **m).count()
}

/// The edges exactly two surfels share, as `(f, i, g, j)`: edge `i` of surfel `f` is edge
/// `j` of surfel `g` ([`folded_pairs_of`]'s input).
fn shared_edges(surface: &DigitalSurface) -> Vec<(usize, usize, usize, usize)> {
    (0..surface.edges().len())
        .into_par_iter()
        .filter_map(|e| {
            let e = EdgeId(e as u32);
            let &[f, g] = surface.edge_surfels(e) else { return None };
            let slot = |s| surface.surfel_edges(s).iter().position(|&x| x == e);
            (f != g).then_some((f.index(), slot(f)?, g.index(), slot(g)?))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use voxreg_digisurf::{LabelVolume, RegionMap};

    #[test]
    fn the_surface_edges_give_the_folded_pairs_a_sort_finds() {
        // Two labels, a pinched edge (two voxels meeting along an edge: four surfels
        // there) and a one-voxel rod; every vertex moved at random, so that many pairs fold.
        let volume = LabelVolume::from_fn([6, 5, 5], |[x, y, z]| match (x, y, z) {
            (1, 1, 1) | (2, 2, 1) => 1,
            (4, 1..=3, 2) => 2,
            (1..=2, 3, 3) => 1,
            _ => 0,
        })
        .with_background(Some(0));
        let surface = DigitalSurface::new(&volume, &RegionMap::per_label()).unwrap();
        let quads: Vec<[u32; 4]> = surface.surfels().iter().map(|s| s.vertices.map(|v| v.0)).collect();
        let mut rng = voxreg_testkit::Lcg::new(5);
        let shared = shared_edges(&surface);
        // The same pairs of quads as the sort finds (`voxreg_quality`'s adjacent pairs).
        let mut pairs: Vec<(usize, usize)> =
            shared.iter().map(|&(f, _, g, _)| (f.min(g), f.max(g))).collect();
        pairs.sort_unstable();
        let by_sort: Vec<(usize, usize)> = voxreg_quality::adjacent_angles_deg(&surface.positions(), &quads)
            .into_iter()
            .map(|p| p.0)
            .collect();
        assert_eq!(pairs, by_sort);
        let mut folds = 0;
        for _ in 0..20 {
            let x: Vec<DVec3> = surface.positions().iter().map(|p| *p + rng.vec3(-0.8, 0.8)).collect();
            let by_sort = folded_pairs(&x, &quads);
            assert_eq!(folded_pairs_of(&x, &quads, &shared), by_sort);
            folds += by_sort.len();
        }
        assert!(folds > 20, "{folds} folded pairs");
    }

    #[test]
    fn folds_are_pulled_back_and_the_rest_is_kept() {
        let volume = LabelVolume::from_fn([4, 4, 4], |[x, y, z]| {
            u32::from((1..3).contains(&x) && (1..3).contains(&y) && (1..3).contains(&z))
        })
        .with_background(Some(0));
        let surface = DigitalSurface::new(&volume, &RegionMap::single_solid()).unwrap();
        let input = surface.positions();
        // Shrink everything a little, then fold one quad over its diagonal.
        let centre = DVec3::splat(1.5);
        let mut x: Vec<DVec3> = input.iter().map(|p| centre + 0.9 * (*p - centre)).collect();
        let q = surface.surfels()[0].vertices.map(|v| v.index());
        x[q[3]] = x[q[0]] + 0.9 * (x[q[1]] - x[q[0]]) + 0.2 * (x[q[2]] - x[q[1]]);
        let quads: Vec<[u32; 4]> = surface.surfels().iter().map(|s| s.vertices.map(|v| v.0)).collect();
        assert!(!folded_quads(&x, &quads).is_empty());
        let before = x.clone();
        let moved = unfold(&surface, &input, &mut x);
        assert!(folded_quads(&x, &quads).is_empty() && folded_pairs(&x, &quads).is_empty());
        assert!((1..=8).contains(&moved), "{moved}");
        // Unflagged vertices did not move; moved ones lie between input and solution.
        let unchanged = x.iter().zip(&before).filter(|(a, b)| a == b).count();
        assert_eq!(unchanged, x.len() - moved);
        for ((a, b), p) in x.iter().zip(&before).zip(input.iter()) {
            assert!((*a - *p).length() <= (*b - *p).length() + 1e-12);
        }
    }
}
