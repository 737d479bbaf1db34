//! The fold-free post-condition: vertices of folded quads pulled back towards the input.

use glam::DVec3;
use voxreg_digisurf::{DigitalSurface, VertexId};
use voxreg_quality::{folded_pairs, folded_quads};

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
        let sub: Vec<[u32; 4]> = candidates.iter().map(|&f| quads[f]).collect();
        let mut folded: Vec<usize> =
            folded_quads(positions, &sub).into_iter().map(|i| candidates[i]).collect();
        folded.extend(
            folded_pairs(positions, &sub).into_iter().flat_map(|(a, b)| [candidates[a], candidates[b]]),
        );
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

#[cfg(test)]
mod tests {
    use super::*;
    use voxreg_digisurf::{LabelVolume, RegionMap};

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
