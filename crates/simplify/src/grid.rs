//! A uniform grid of triangle boxes for the intersection tests of collapses.

use glam::DVec3;
use rustc_hash::FxHashMap;

/// A triangle whose box spans more cells than this is kept in a list tested always.
const MAX_CELLS: i64 = 512;

/// Triangles by the grid cells their boxes overlap. Entries are never removed: a
/// triangle that changed is entered again in its new cells, and queries return
/// candidates to test, stale ones included.
pub(crate) struct Grid {
    cell: f64,
    cells: FxHashMap<[i32; 3], Vec<u32>>,
    large: Vec<u32>,
    seen: Vec<u32>,
    stamp: u32,
}

impl Grid {
    pub(crate) fn new(cell: f64, triangles: usize) -> Grid {
        Grid { cell, cells: FxHashMap::default(), large: Vec::new(), seen: vec![0; triangles], stamp: 0 }
    }

    fn range(&self, lo: DVec3, hi: DVec3) -> ([i32; 3], [i32; 3]) {
        let f = |x: f64| (x / self.cell).floor().clamp(-1e9, 1e9) as i32;
        ([f(lo.x), f(lo.y), f(lo.z)], [f(hi.x), f(hi.y), f(hi.z)])
    }

    fn count(lo: [i32; 3], hi: [i32; 3]) -> i64 {
        (0..3).map(|k| i64::from(hi[k]) - i64::from(lo[k]) + 1).product()
    }

    /// Enters triangle `t` with box `[lo, hi]`.
    pub(crate) fn insert(&mut self, t: u32, lo: DVec3, hi: DVec3) {
        let (a, b) = self.range(lo, hi);
        if Self::count(a, b) > MAX_CELLS {
            self.large.push(t);
            return;
        }
        for x in a[0]..=b[0] {
            for y in a[1]..=b[1] {
                for z in a[2]..=b[2] {
                    self.cells.entry([x, y, z]).or_default().push(t);
                }
            }
        }
    }

    /// Calls `f` once for each triangle entered in a cell that the box `[lo, hi]`
    /// overlaps (or in the large list), until `f` returns `true`; returns whether it did.
    pub(crate) fn any(&mut self, lo: DVec3, hi: DVec3, mut f: impl FnMut(u32) -> bool) -> bool {
        self.stamp = self.stamp.wrapping_add(1);
        if self.stamp == 0 {
            self.seen.fill(0);
            self.stamp = 1;
        }
        let stamp = self.stamp;
        let (a, b) = self.range(lo, hi);
        let mut visit = |t: u32, seen: &mut Vec<u32>| {
            if seen[t as usize] == stamp {
                return false;
            }
            seen[t as usize] = stamp;
            f(t)
        };
        for &t in &self.large {
            if visit(t, &mut self.seen) {
                return true;
            }
        }
        if Self::count(a, b) > MAX_CELLS * 8 {
            // A huge query box: every triangle entered anywhere.
            for list in self.cells.values() {
                for &t in list {
                    if visit(t, &mut self.seen) {
                        return true;
                    }
                }
            }
            return false;
        }
        for x in a[0]..=b[0] {
            for y in a[1]..=b[1] {
                for z in a[2]..=b[2] {
                    if let Some(list) = self.cells.get(&[x, y, z]) {
                        for &t in list {
                            if visit(t, &mut self.seen) {
                                return true;
                            }
                        }
                    }
                }
            }
        }
        false
    }
}
