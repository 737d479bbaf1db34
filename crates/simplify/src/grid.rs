//! A uniform grid of triangle boxes for the intersection tests of collapses.

use glam::DVec3;

/// A triangle whose box spans more cells than this is kept in a list tested always.
const MAX_CELLS: i64 = 512;

/// Where a triangle is entered.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Entry {
    /// Not entered (dead, or never entered).
    None,
    /// In the cells of this range.
    Cells([i32; 3], [i32; 3]),
    /// In the list of large triangles.
    Large,
}

/// Triangles by the grid cells their boxes overlap: a dense array of cells over a box
/// (coordinates outside it are clamped to its border cells, which keeps every query
/// conservative). Each triangle is entered in the cells of its current box only: an
/// update moves it out of the cells of its former box.
pub(crate) struct Grid {
    cell: f64,
    origin: DVec3,
    dims: [i32; 3],
    cells: Vec<Vec<u32>>,
    large: Vec<u32>,
    entries: Vec<Entry>,
}

impl Grid {
    /// A grid over the box `[lo, hi]` with cells of about `cell` (larger where the box
    /// would need more than a few cells per triangle).
    pub(crate) fn new(lo: DVec3, hi: DVec3, cell: f64, triangles: usize) -> Grid {
        let extent = (hi - lo).max(DVec3::ZERO);
        let budget = (4 * triangles).max(1024) as f64;
        let mut cell = cell.max(1e-300);
        let count = |c: f64| (extent / c).floor() + DVec3::ONE;
        while {
            let n = count(cell);
            n.x * n.y * n.z > budget
        } {
            cell *= 1.25;
        }
        let n = count(cell);
        let dims = [n.x as i32, n.y as i32, n.z as i32];
        Grid {
            cell,
            origin: lo,
            dims,
            cells: vec![Vec::new(); (n.x * n.y * n.z) as usize],
            large: Vec::new(),
            entries: vec![Entry::None; triangles],
        }
    }

    fn range(&self, lo: DVec3, hi: DVec3) -> ([i32; 3], [i32; 3]) {
        // Clamped first, then truncated: the floor of the clamped value, without a call to
        // `floor` (the cast saturates, and maps NaN to 0 as the clamp of a NaN floor does).
        let f = |x: f64, o: f64, n: i32| ((x - o) / self.cell).clamp(0.0, f64::from(n - 1)) as i32;
        let g = |p: DVec3| {
            [
                f(p.x, self.origin.x, self.dims[0]),
                f(p.y, self.origin.y, self.dims[1]),
                f(p.z, self.origin.z, self.dims[2]),
            ]
        };
        (g(lo), g(hi))
    }

    fn count(lo: [i32; 3], hi: [i32; 3]) -> i64 {
        (0..3).map(|k| i64::from(hi[k]) - i64::from(lo[k]) + 1).product()
    }

    fn index(&self, x: i32, y: i32, z: i32) -> usize {
        ((z as usize * self.dims[1] as usize) + y as usize) * self.dims[0] as usize + x as usize
    }

    fn for_cells(a: [i32; 3], b: [i32; 3], mut f: impl FnMut(i32, i32, i32)) {
        for z in a[2]..=b[2] {
            for y in a[1]..=b[1] {
                for x in a[0]..=b[0] {
                    f(x, y, z);
                }
            }
        }
    }

    /// Takes triangle `t` out of the grid.
    pub(crate) fn remove(&mut self, t: u32) {
        match std::mem::replace(&mut self.entries[t as usize], Entry::None) {
            Entry::None => {}
            Entry::Large => self.large.retain(|&s| s != t),
            Entry::Cells(a, b) => {
                let mut cells = std::mem::take(&mut self.cells);
                Self::for_cells(a, b, |x, y, z| {
                    let list = &mut cells[self.index(x, y, z)];
                    if let Some(i) = list.iter().position(|&s| s == t) {
                        list.swap_remove(i);
                    }
                });
                self.cells = cells;
            }
        }
    }

    /// Enters triangle `t` with box `[lo, hi]`, in place of where it was.
    pub(crate) fn insert(&mut self, t: u32, lo: DVec3, hi: DVec3) {
        let (a, b) = self.range(lo, hi);
        let entry = if Self::count(a, b) > MAX_CELLS { Entry::Large } else { Entry::Cells(a, b) };
        if self.entries[t as usize] == entry {
            return;
        }
        self.remove(t);
        self.entries[t as usize] = entry;
        match entry {
            Entry::Large => self.large.push(t),
            Entry::Cells(a, b) => {
                let mut cells = std::mem::take(&mut self.cells);
                Self::for_cells(a, b, |x, y, z| cells[self.index(x, y, z)].push(t));
                self.cells = cells;
            }
            Entry::None => {}
        }
    }

    /// The triangles entered in a cell that the box `[lo, hi]` overlaps (or in the large
    /// list), sorted, into `out`: a query that leaves the grid as it is, for parallel use.
    pub(crate) fn candidates_into(&self, lo: DVec3, hi: DVec3, out: &mut Vec<u32>) {
        out.clear();
        out.extend_from_slice(&self.large);
        let (a, b) = self.range(lo, hi);
        Self::for_cells(a, b, |x, y, z| out.extend_from_slice(&self.cells[self.index(x, y, z)]));
        out.sort_unstable();
        out.dedup();
    }

    /// Calls `f` once for each triangle entered in a cell that the box `[lo, hi]`
    /// overlaps (or in the large list), until `f` returns `true`; returns whether it did.
    /// A triangle in several of those cells is visited in the first of them (the corner
    /// of its cells' range and the query's that is least on every axis), so the query
    /// keeps no marks and leaves the grid as it is: for parallel use.
    pub(crate) fn any(&self, lo: DVec3, hi: DVec3, mut f: impl FnMut(u32) -> bool) -> bool {
        for &t in &self.large {
            if f(t) {
                return true;
            }
        }
        let (a, b) = self.range(lo, hi);
        for z in a[2]..=b[2] {
            for y in a[1]..=b[1] {
                for x in a[0]..=b[0] {
                    for &t in &self.cells[self.index(x, y, z)] {
                        let Entry::Cells(c, _) = self.entries[t as usize] else { continue };
                        if c[0].max(a[0]) == x && c[1].max(a[1]) == y && c[2].max(a[2]) == z && f(t) {
                            return true;
                        }
                    }
                }
            }
        }
        false
    }
}
