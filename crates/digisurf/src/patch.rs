//! Parts of the digital surface as meshes of their own: one interface, or the closed
//! surface of one region, optionally made 2-manifold by splitting pinches.

use crate::ids::{InterfaceId, RegionId, SurfelId, VertexId};
use crate::surface::DigitalSurface;
use crate::union_find::union_find_root as find;
use crate::volume::Voxel;

const NONE: u32 = u32::MAX;

/// Two pairs of face slots (`4 * face + edge index`) of one edge: each pair's faces are
/// joined across the edge, the two pairs are not.
type Pairing = [(u32, u32); 2];

/// A part of a [`DigitalSurface`] as a mesh of its own: some of its surfels, each kept
/// or flipped, over local vertices that copy surface vertices.
///
/// Local vertex `i` copies surface vertex `vertices[i]`, so a quantity per surface
/// vertex (a regularized position) maps to the patch exactly, and vertices shared by
/// two patches (along junctions) take identical values in both. Without splitting,
/// each surface vertex has at most one copy; with [`PatchParams::manifold`], a pinched
/// vertex or edge gets one copy per sheet through it.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Patch {
    /// The surfels, in increasing id order.
    pub surfels: Vec<SurfelId>,
    /// Per surfel, whether the patch reverses its orientation (its normal then points
    /// from its outer region to its inner one).
    pub flipped: Vec<bool>,
    /// Per surfel, its four local vertices, counter-clockwise seen from the tip of its
    /// normal in the patch (the surfel's own order, reversed when flipped).
    pub quads: Vec<[u32; 4]>,
    /// Per local vertex, the surface vertex it copies.
    pub vertices: Vec<VertexId>,
}

/// How [`DigitalSurface::interface_patch`] and [`DigitalSurface::region_patch`] build
/// a patch.
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq)]
pub struct PatchParams {
    /// Split pinches so the patch is 2-manifold where its own region (or, for an
    /// interface, its lower region) touches itself only along an edge or at a corner:
    /// the two voxels are treated as apart, each keeping its own copy of the edge and
    /// its vertices. Default: `false` (pinched cells are shared, as in the complex).
    pub manifold: bool,
}

impl DigitalSurface {
    /// The surfels of interface `i`, oriented as in the complex (from the interface's
    /// lower region to its higher one).
    ///
    /// With [`PatchParams::manifold`], the lower region's pinches are split: at an edge
    /// where its two diagonal voxels meet the higher region's two, the edge gets one
    /// copy per lower-region voxel.
    pub fn interface_patch(&self, i: InterfaceId, params: &PatchParams) -> Patch {
        let interface = &self.interfaces()[i.index()];
        let lower = interface.regions[0];
        self.patch(interface.surfels.clone(), |_| false, lower, params.manifold)
    }

    /// The surface of region `r`, oriented outward from `r`: the surfels of every
    /// interface of `r`, flipped where `r` is the outer region.
    ///
    /// **Closedness.** When the volume has a background (the outside of the domain is
    /// the background region), every region other than the background gets a closed
    /// surface: its faces on the domain border are surfels too. Without background
    /// ([`DigitalSurface::has_open_border`]), the domain border is not part of any
    /// surface: a region touching it gets an open surface whose rim lies on the border.
    ///
    /// With [`PatchParams::manifold`], `r`'s pinches (two of its voxels touching only
    /// along an edge or at a corner) are split, so every edge of the patch has exactly
    /// two faces (one on the rim) and every vertex's faces form a single fan: the patch
    /// is then a 2-manifold (with boundary when open).
    pub fn region_patch(&self, r: RegionId, params: &PatchParams) -> Patch {
        let mut surfels: Vec<SurfelId> = self
            .interfaces()
            .iter()
            .filter(|i| i.regions.contains(&r))
            .flat_map(|i| i.surfels.iter().copied())
            .collect();
        surfels.sort_unstable();
        self.patch(surfels, |s| self.surfel(s).regions[1] == r, r, params.manifold)
    }

    /// Builds the patch of `surfels` (sorted), flipping those where `flip` holds;
    /// pinches of region `side` are split when `manifold`.
    fn patch(
        &self,
        surfels: Vec<SurfelId>,
        flip: impl Fn(SurfelId) -> bool,
        side: RegionId,
        manifold: bool,
    ) -> Patch {
        let flipped: Vec<bool> = surfels.iter().map(|&s| flip(s)).collect();
        // A class per face corner: the surface vertex, or with `manifold` the fan of
        // faces around it (numbered by a corner of the fan, below `4 * surfels.len()`).
        let (corners, classes) = if manifold {
            (self.split_corners(&surfels, side), 4 * surfels.len())
        } else {
            let corners = surfels.iter().map(|&s| self.surfel(s).vertices.map(|v| v.0)).collect();
            (corners, self.num_vertices())
        };
        // Local vertices numbered by first appearance.
        let mut local_of = vec![NONE; classes];
        let mut vertices = Vec::new();
        let mut quads = Vec::with_capacity(surfels.len());
        for ((&s, c), &flip) in surfels.iter().zip(&corners).zip(&flipped) {
            let global = self.surfel(s).vertices;
            let mut q = [0u32; 4];
            for k in 0..4 {
                let local = &mut local_of[c[k] as usize];
                if *local == NONE {
                    *local = vertices.len() as u32;
                    vertices.push(global[k]);
                }
                q[k] = *local;
            }
            quads.push(if flip { [q[0], q[3], q[2], q[1]] } else { q });
        }
        Patch { surfels, flipped, quads, vertices }
    }

    /// For each surfel of `surfels` and each of its corners, a class id: two corners
    /// share a class when they are the same surface vertex and their faces are joined
    /// around it through edges of the patch. At a pinch (an edge with four faces of the
    /// patch, two on each of two diagonal voxels of region `side`), faces are joined
    /// only within a pair: per voxel of `side`, or per voxel of the other side where
    /// that alone keeps the two copies of the edge on distinct vertices.
    fn split_corners(&self, surfels: &[SurfelId], side: RegionId) -> Vec<[u32; 4]> {
        // (edge, face-local slot) for every edge of every face.
        let mut slots: Vec<(u32, u32)> = Vec::with_capacity(4 * surfels.len());
        for (f, &s) in surfels.iter().enumerate() {
            for (i, e) in self.surfel_edges(s).iter().enumerate() {
                slots.push((e.0, (4 * f + i) as u32));
            }
        }
        slots.sort_unstable();
        let mut parent: Vec<u32> = (0..4 * surfels.len() as u32).collect();
        // The voxel on the `side` region's side of face `f` (`own`), or on the other side.
        let voxel = |f: u32, own: bool| -> Voxel {
            let sf = self.surfel(surfels[(f / 4) as usize]);
            sf.voxels()[usize::from((sf.regions[0] != side) == own)]
        };
        // Slot `a`'s corner on vertex `k` of its face, for a slot of the same edge.
        let corner = |a: u32, k: usize| -> u32 {
            let (f, i) = (a / 4, (a % 4) as usize);
            let vs = self.surfel(surfels[f as usize]).vertices;
            let mut c = [i, (i + 1) % 4];
            if vs[c[0]].index() != k {
                c.swap(0, 1);
            }
            4 * f + c[0] as u32
        };
        // Joins the corners of two slots of the same edge on each of its two vertices.
        let join = |parent: &mut Vec<u32>, a: u32, b: u32| {
            let (fa, ia) = (a / 4, (a % 4) as usize);
            let va = self.surfel(surfels[fa as usize]).vertices;
            for ka in [ia, (ia + 1) % 4] {
                union(parent, 4 * fa + ka as u32, corner(b, va[ka].index()));
            }
        };
        // The pairs of slots of a four-face edge lying on the same voxel (of `side` when
        // `own`, else of the other side), if the faces pair up that way.
        let pairs = |group: &[(u32, u32)], own: bool| -> Option<Pairing> {
            let v: Vec<Voxel> = group.iter().map(|&(_, slot)| voxel(slot, own)).collect();
            let k = (1..4).find(|&k| v[k] == v[0])?;
            let rest: Vec<usize> = (1..4).filter(|&j| j != k).collect();
            (v[rest[0]] == v[rest[1]] && v[rest[0]] != v[0])
                .then(|| [(group[0].1, group[k].1), (group[rest[0]].1, group[rest[1]].1)])
        };
        // First every edge but the pinches, whose faces are all joined.
        let mut pinches = Vec::new();
        for group in slots.chunk_by(|x, y| x.0 == y.0) {
            if group.len() == 4 && pairs(group, true).is_some() {
                pinches.push(group);
                continue;
            }
            for w in group.windows(2) {
                join(&mut parent, w[0].1, w[1].1);
            }
        }
        // Then the pinches: each one's faces are joined per voxel of `side`, so `side`'s
        // two voxels are apart there; unless they are joined around both end points
        // anyway, which would leave two copies of the edge on the same two vertices:
        // then the other side's two voxels are kept apart instead. Choices interact
        // along chains of pinches, so they are revised until none collides (a few
        // rounds; pinches are rare).
        let collide = |parent: &mut Vec<u32>, [(a, _), (b, _)]: Pairing| {
            let (fa, ia) = (a / 4, (a % 4) as usize);
            let va = self.surfel(surfels[fa as usize]).vertices;
            [ia, (ia + 1) % 4].iter().all(|&ka| {
                let k = va[ka].index();
                find(parent, corner(a, k)) == find(parent, corner(b, k))
            })
        };
        let options: Vec<[Option<Pairing>; 2]> =
            pinches.iter().map(|g| [pairs(g, true), pairs(g, false)]).collect();
        let mut choice = vec![0usize; pinches.len()];
        let base = parent.clone();
        for round in 0..8 {
            parent.clone_from(&base);
            for (o, &c) in options.iter().zip(&choice) {
                for (a, b) in o[c].expect("the chosen pairing exists") {
                    join(&mut parent, a, b);
                }
            }
            let mut changed = false;
            for (o, c) in options.iter().zip(choice.iter_mut()) {
                let other = 1 - *c;
                if o[other].is_some() && collide(&mut parent, o[*c].expect("chosen")) && round < 7 {
                    *c = other;
                    changed = true;
                }
            }
            if !changed {
                break;
            }
        }
        (0..surfels.len()).map(|f| std::array::from_fn(|k| find(&mut parent, (4 * f + k) as u32))).collect()
    }
}

fn union(parent: &mut [u32], a: u32, b: u32) {
    let (ra, rb) = (find(parent, a), find(parent, b));
    if ra != rb {
        parent[ra.max(rb) as usize] = ra.min(rb);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::volume::LabelVolume;

    /// `(vertices, faces, faces per undirected edge)` of a patch.
    fn shape(p: &Patch) -> (usize, usize, Vec<usize>) {
        let mut edges = std::collections::HashMap::new();
        for q in &p.quads {
            for k in 0..4 {
                let (a, b) = (q[k], q[(k + 1) % 4]);
                *edges.entry((a.min(b), a.max(b))).or_insert(0) += 1;
            }
        }
        let mut counts: Vec<usize> = edges.into_values().collect();
        counts.sort_unstable();
        (p.vertices.len(), p.quads.len(), counts)
    }

    fn two_voxels(a: [usize; 3], b: [usize; 3]) -> DigitalSurface {
        let volume = LabelVolume::from_fn([4, 4, 4], |p| u32::from(p == a || p == b));
        DigitalSurface::from_volume(&volume).unwrap()
    }

    #[test]
    fn edge_pinch_is_split_into_two_cubes() {
        let s = two_voxels([1, 1, 1], [2, 2, 1]);
        let r = s.regions().region_of(1).unwrap();
        let (v, f, counts) = shape(&s.region_patch(r, &PatchParams::default()));
        assert_eq!((v, f), (14, 12));
        assert_eq!(counts.iter().filter(|&&c| c == 4).count(), 1);
        let p = s.region_patch(r, &PatchParams { manifold: true });
        let (v, f, counts) = shape(&p);
        assert_eq!((v, f), (16, 12));
        assert!(counts.iter().all(|&c| c == 2));
        assert_eq!(counts.len(), 24); // V - E + F = 4: two spheres.
                                      // The two copies of each pinched vertex copy the same surface vertex.
        let mut copies = p.vertices.clone();
        copies.sort_unstable();
        copies.dedup();
        assert_eq!(copies.len(), 14);
    }

    #[test]
    fn vertex_pinch_is_split() {
        let s = two_voxels([1, 1, 1], [2, 2, 2]);
        let r = s.regions().region_of(1).unwrap();
        assert_eq!(shape(&s.region_patch(r, &PatchParams::default())).0, 15);
        let (v, f, counts) = shape(&s.region_patch(r, &PatchParams { manifold: true }));
        assert_eq!((v, f, counts.len()), (16, 12, 24));
    }

    #[test]
    fn region_patches_are_oriented_outward() {
        // Labels 1 and 2 side by side in background 0: the 1|2 surfel points from 1
        // to 2, so region 2's patch flips it.
        let volume = LabelVolume::from_fn([4, 3, 3], |p| match p {
            [1, 1, 1] => 1,
            [2, 1, 1] => 2,
            _ => 0,
        });
        let s = DigitalSurface::from_volume(&volume).unwrap();
        let positions = s.positions();
        for label in [1, 2] {
            let r = s.regions().region_of(label).unwrap();
            let p = s.region_patch(r, &PatchParams::default());
            assert_eq!(p.quads.len(), 6);
            assert_eq!(p.flipped.iter().filter(|&&f| f).count(), usize::from(label == 2));
            // Signed volume by the divergence theorem (quads as two triangles): +1 voxel.
            let volume: f64 = p
                .quads
                .iter()
                .map(|q| {
                    let x = q.map(|v| positions[p.vertices[v as usize].index()]);
                    (x[0].dot(x[1].cross(x[2])) + x[0].dot(x[2].cross(x[3]))) / 6.0
                })
                .sum();
            assert!((volume - 1.0).abs() < 1e-12, "region {label}: volume {volume}");
        }
        let i = s.interfaces().iter().position(|i| i.surfels.len() == 1).unwrap();
        let p = s.interface_patch(InterfaceId(i as u32), &PatchParams::default());
        assert_eq!((p.quads.len(), p.vertices.len(), p.flipped.as_slice()), (1, 4, &[false][..]));
    }
}
