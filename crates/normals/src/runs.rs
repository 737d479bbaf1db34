//! The region of every voxel, recovered from the digital surface, as runs along x.
//!
//! Estimators receive only the [`DigitalSurface`], not the volume; the regions are
//! fully determined by it. Two face-adjacent voxels of the domain lie in the same
//! region unless a surfel separates them, and every surfel names the regions on its
//! two sides. So, line by line along x:
//!
//! - a line crossed by surfels perpendicular to x splits into runs at those surfels, each
//!   run taking the region of the surfel side it starts on;
//! - a line crossed by none is uniform: its region is the side of any surfel
//!   perpendicular to y or z that touches one of its voxels, or else (no surfel touches
//!   it at all) the region of a neighbouring line, by a breadth-first pass over lines.
//!
//! Cost: `O(ny nz + F)` time and memory (`F` surfels), far below the `nx ny nz` of a
//! dense label array on large volumes.

use std::collections::VecDeque;

use voxreg_digisurf::DigitalSurface;

const UNKNOWN: u32 = u32::MAX;

/// The "region" of the void beyond an open border (a volume without background).
pub(crate) const VOID: u32 = u32::MAX - 1;

/// Regions of the voxels of a domain, as runs along x, one list of runs per line `(y, z)`.
#[derive(Clone, Debug)]
pub(crate) struct RegionRuns {
    dims: [i64; 3],
    /// Region of the voxels outside the domain beyond a closed side: the background's, or
    /// [`VOID`] when the volume has none.
    outside: u32,
    /// The open sides `[axis][low, high]`, beyond which lies [`VOID`].
    open: [[bool; 2]; 3],
    /// Which runs each line owns.
    lines: Lines,
    /// The runs, line after line.
    runs: Vec<Run>,
}

/// Where each line's runs are.
#[derive(Clone, Debug)]
enum Lines {
    /// Line `y + ny z` owns runs `offsets[line]..offsets[line + 1]`.
    Dense { offsets: Vec<usize> },
    /// Only the lines surfels touch (`keys`, sorted) own runs, `offsets[i]..offsets[i + 1]`
    /// for `keys[i]`; any other line is uniform, of the region of the nearest touched
    /// line below it in y (no surfel between them), or of the outside below the domain:
    /// `single[region]`, a run of its own. For closed domains whose lattice holds far more
    /// lines than surfels (scenes of objects far apart): memory of the surface's size.
    Sparse { keys: Vec<u64>, offsets: Vec<usize>, single: Vec<Run> },
}

/// Voxels `start..` (up to the next run's start, or the end of the line) of one region.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub(crate) struct Run {
    /// First x of the run (the first run of a line starts at 0).
    pub(crate) start: u32,
    /// The run's region.
    pub(crate) region: u32,
}

impl RegionRuns {
    /// The runs of the regions of `surface`'s volume: per line of the lattice, or (a
    /// closed domain with many more lines than surfels) per line the surfels touch.
    pub(crate) fn new(surface: &DigitalSurface) -> Self {
        let [_, ny, nz] = surface.dims();
        let sparse = (surface.num_surfels() as u128) * 16 < (ny as u128) * (nz as u128);
        Self::with_layout(surface, sparse)
    }

    /// [`RegionRuns::new`], per touched line if `sparse` and the domain is closed.
    fn with_layout(surface: &DigitalSurface, sparse: bool) -> Self {
        let [nx, ny, nz] = surface.dims();
        let nlines = ny * nz;
        let line = |y: u32, z: u32| y as usize + ny * z as usize;
        let open = surface.open_sides();
        let outside = match surface.regions().background() {
            Some(r) if open.iter().flatten().any(|&o| !o) => r.0,
            _ => VOID,
        };
        let closed = outside != VOID && !open.iter().flatten().any(|&o| o);

        // Surfels perpendicular to x, by line then x: (key, region before, region after).
        let mut crossings: Vec<(u64, u32, u32)> = surface
            .surfels()
            .iter()
            .filter(|s| s.axis == 0)
            .map(|s| {
                let (inner, outer) = (s.regions[0].0, s.regions[1].0);
                // Not flipped: the inner voxel is on the negative side (x - 1).
                let (neg, pos) = if s.flipped { (outer, inner) } else { (inner, outer) };
                (((line(s.cell[1], s.cell[2]) as u64) << 32) | s.cell[0] as u64, neg, pos)
            })
            .collect();
        crossings.sort_unstable_by_key(|c| c.0);
        let dims = [nx as i64, ny as i64, nz as i64];
        if sparse && closed {
            return Self::sparse(surface, dims, outside, open, &crossings);
        }

        // Uniform lines: their region from any surfel perpendicular to y or z touching them.
        let mut uniform = vec![UNKNOWN; nlines];
        for s in surface.surfels().iter().filter(|s| s.axis != 0) {
            let (inner, outer) = (s.regions[0].0, s.regions[1].0);
            let (neg, pos) = if s.flipped { (outer, inner) } else { (inner, outer) };
            let (y, z) = (s.cell[1] as usize, s.cell[2] as usize);
            let (dy, dz) = if s.axis == 1 { (1, 0) } else { (0, 1) };
            if y < ny && z < nz {
                uniform[y + ny * z] = pos;
            }
            if y >= dy && z >= dz {
                uniform[(y - dy) + ny * (z - dz)] = neg;
            }
        }

        let mut offsets = Vec::with_capacity(nlines + 1);
        let mut runs = Vec::with_capacity(nlines + crossings.len());
        let mut crossed = vec![false; nlines];
        let mut next = 0;
        for l in 0..nlines {
            offsets.push(runs.len());
            let first = next;
            while next < crossings.len() && (crossings[next].0 >> 32) as usize == l {
                next += 1;
            }
            let here = &crossings[first..next];
            if here.is_empty() {
                runs.push(Run { start: 0, region: uniform[l] });
                continue;
            }
            crossed[l] = true;
            if here[0].0 as u32 > 0 {
                runs.push(Run { start: 0, region: here[0].1 });
            }
            for &(key, _, pos) in here {
                let x = key as u32 as usize;
                if x < nx {
                    runs.push(Run { start: x as u32, region: pos });
                }
            }
            uniform[l] = runs[offsets[l]].region;
        }
        offsets.push(runs.len());

        // Lines no surfel touches: the region of a neighbouring line (no surfel between).
        let mut queue: VecDeque<usize> = (0..nlines).filter(|&l| uniform[l] != UNKNOWN).collect();
        while let Some(l) = queue.pop_front() {
            let (y, z) = (l % ny, l / ny);
            let region = runs[offsets[l]].region; // the region of voxel (0, y, z)
            let mut visit = |m: usize| {
                if uniform[m] == UNKNOWN && !crossed[m] {
                    uniform[m] = region;
                    runs[offsets[m]].region = region;
                    queue.push_back(m);
                }
            };
            if y > 0 {
                visit(l - 1);
            }
            if y + 1 < ny {
                visit(l + 1);
            }
            if z > 0 {
                visit(l - ny);
            }
            if z + 1 < nz {
                visit(l + ny);
            }
        }
        RegionRuns { dims, outside, open, lines: Lines::Dense { offsets }, runs }
    }

    /// The runs of the lines surfels touch ([`Lines::Sparse`]), from `crossings` (the
    /// surfels perpendicular to x, sorted as in [`RegionRuns::with_layout`]).
    fn sparse(
        surface: &DigitalSurface,
        dims: [i64; 3],
        outside: u32,
        open: [[bool; 2]; 3],
        crossings: &[(u64, u32, u32)],
    ) -> Self {
        let [nx, ny, nz] = dims.map(|d| d as u64);
        // The lines touched by surfels perpendicular to y or z, and their region.
        let mut marks: Vec<(u64, u32)> = Vec::new();
        for s in surface.surfels().iter().filter(|s| s.axis != 0) {
            let (inner, outer) = (s.regions[0].0, s.regions[1].0);
            let (neg, pos) = if s.flipped { (outer, inner) } else { (inner, outer) };
            let (y, z) = (u64::from(s.cell[1]), u64::from(s.cell[2]));
            let (dy, dz) = if s.axis == 1 { (1, 0) } else { (0, 1) };
            if y < ny && z < nz {
                marks.push((y + ny * z, pos));
            }
            if y >= dy && z >= dz {
                marks.push(((y - dy) + ny * (z - dz), neg));
            }
        }
        marks.sort_unstable_by_key(|m| m.0);
        marks.dedup_by_key(|m| m.0);
        let (mut keys, mut offsets, mut runs) = (Vec::new(), Vec::new(), Vec::new());
        let (mut c, mut m) = (0, 0);
        while c < crossings.len() || m < marks.len() {
            let cl = crossings.get(c).map_or(u64::MAX, |x| x.0 >> 32);
            let ml = marks.get(m).map_or(u64::MAX, |x| x.0);
            let l = cl.min(ml);
            keys.push(l);
            offsets.push(runs.len());
            if cl == l {
                let first = c;
                while c < crossings.len() && crossings[c].0 >> 32 == l {
                    c += 1;
                }
                let here = &crossings[first..c];
                if here[0].0 as u32 > 0 {
                    runs.push(Run { start: 0, region: here[0].1 });
                }
                for &(key, _, pos) in here {
                    if u64::from(key as u32) < nx {
                        runs.push(Run { start: key as u32, region: pos });
                    }
                }
            } else {
                runs.push(Run { start: 0, region: marks[m].1 });
            }
            if ml == l {
                m += 1;
            }
        }
        offsets.push(runs.len());
        let regions = surface.regions().len().max(outside as usize + 1);
        let single = (0..regions as u32).map(|region| Run { start: 0, region }).collect();
        RegionRuns { dims, outside, open, lines: Lines::Sparse { keys, offsets, single }, runs }
    }

    /// The region beyond the domain at line `(y, z)`, below it in x (`Some(0)`), above it
    /// (`Some(1)`) or within its x range (`None`): [`VOID`] beyond an open side.
    #[inline]
    fn beyond(&self, y: i64, z: i64, x_side: Option<usize>) -> u32 {
        let [_, ny, nz] = self.dims;
        let open = &self.open;
        let crossed = x_side.is_some_and(|s| open[0][s])
            || (y < 0 && open[1][0])
            || (y >= ny && open[1][1])
            || (z < 0 && open[2][0])
            || (z >= nz && open[2][1]);
        if crossed {
            VOID
        } else {
            self.outside
        }
    }

    /// The runs of line `(y, z)`; `None` when the line lies outside the domain.
    #[inline]
    pub(crate) fn line(&self, y: i64, z: i64) -> Option<&[Run]> {
        let [_, ny, nz] = self.dims;
        if y < 0 || y >= ny || z < 0 || z >= nz {
            return None;
        }
        let l = (y + ny * z) as usize;
        match &self.lines {
            Lines::Dense { offsets } => Some(&self.runs[offsets[l]..offsets[l + 1]]),
            Lines::Sparse { keys, offsets, single } => {
                let i = keys.partition_point(|&k| k < l as u64);
                if keys.get(i) == Some(&(l as u64)) {
                    return Some(&self.runs[offsets[i]..offsets[i + 1]]);
                }
                // Untouched lines down to the nearest touched one, or to the outside: no
                // surfel between any two of them.
                let region = match i.checked_sub(1) {
                    Some(j) if keys[j] >= (ny * z) as u64 => self.runs[offsets[j]].region,
                    _ => self.outside,
                };
                Some(&single[region as usize..=region as usize])
            }
        }
    }

    /// The region of all voxels `a..=b` of line `(y, z)` if they share one (outside the
    /// domain included), by a short linear scan: the fast path of chord sums.
    #[inline]
    pub(crate) fn uniform(&self, y: i64, z: i64, a: i64, b: i64) -> Option<u32> {
        let nx = self.dims[0];
        let Some(runs) = self.line(y, z) else {
            // A line beyond the domain: one region unless the range also crosses an open
            // side in x that the line's own side does not share.
            let mut region = None;
            let mut uniform = true;
            self.beyond_line(y, z, a, b, |_, _, r| {
                uniform = region.is_none();
                region = Some(r);
            });
            return region.filter(|_| uniform);
        };
        if b < 0 {
            return Some(self.beyond(y, z, Some(0)));
        }
        if a >= nx {
            return Some(self.beyond(y, z, Some(1)));
        }
        if a < 0 || b >= nx {
            return None;
        }
        let mut i = 0;
        while i + 1 < runs.len() && i64::from(runs[i + 1].start) <= a {
            i += 1;
        }
        (i + 1 == runs.len() || i64::from(runs[i + 1].start) > b).then_some(runs[i].region)
    }

    /// Calls `f(lo, hi, region)` on the maximal intervals `lo..=hi` of `a..=b` on line
    /// `(y, z)` where the region is constant, in increasing order; voxels outside the
    /// domain count as the background's region, or as [`VOID`] on an open border.
    #[inline]
    pub(crate) fn for_each_run(&self, y: i64, z: i64, a: i64, b: i64, mut f: impl FnMut(i64, i64, u32)) {
        let nx = self.dims[0];
        let runs = match self.line(y, z) {
            Some(runs) if b >= 0 && a < nx => runs,
            Some(_) => return f(a, b, self.beyond(y, z, Some(usize::from(a >= nx)))),
            None => return self.beyond_line(y, z, a, b, f),
        };
        if a < 0 {
            f(a, -1, self.beyond(y, z, Some(0)));
        }
        let (lo, hi) = (a.max(0), b.min(nx - 1));
        // The run holding `lo`: the last one starting at or before it.
        let mut i = runs.partition_point(|r| i64::from(r.start) <= lo) - 1;
        let mut from = lo;
        loop {
            let end = if i + 1 < runs.len() { (i64::from(runs[i + 1].start) - 1).min(hi) } else { hi };
            f(from, end, runs[i].region);
            if end == hi {
                break;
            }
            i += 1;
            from = i64::from(runs[i].start);
        }
        if b >= nx {
            f(nx, b, self.beyond(y, z, Some(1)));
        }
    }

    /// [`RegionRuns::for_each_run`] on a line beyond the domain: up to three pieces
    /// (below, within and above the domain's x range), merged where they agree.
    fn beyond_line(&self, y: i64, z: i64, a: i64, b: i64, mut f: impl FnMut(i64, i64, u32)) {
        let nx = self.dims[0];
        let pieces = [
            (a, b.min(-1), self.beyond(y, z, Some(0))),
            (a.max(0), b.min(nx - 1), self.beyond(y, z, None)),
            (a.max(nx), b, self.beyond(y, z, Some(1))),
        ];
        let mut current: Option<(i64, i64, u32)> = None;
        for (lo, hi, r) in pieces {
            if lo > hi {
                continue;
            }
            current = match current {
                Some((clo, _, cr)) if cr == r => Some((clo, hi, r)),
                Some(c) => {
                    f(c.0, c.1, c.2);
                    Some((lo, hi, r))
                }
                None => Some((lo, hi, r)),
            };
        }
        if let Some(c) = current {
            f(c.0, c.1, c.2);
        }
    }

    /// The region of voxel `[x, y, z]` (`None` outside the domain of an open border).
    #[cfg(test)]
    pub(crate) fn region(&self, v: [i64; 3]) -> Option<u32> {
        let mut out = None;
        self.for_each_run(v[1], v[2], v[0], v[0], |_, _, r| out = Some(r));
        out.filter(|&r| r != VOID)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use voxreg_digisurf::{LabelVolume, RegionMap};
    use voxreg_testkit::Lcg;

    fn check(volume: &LabelVolume, map: &RegionMap) {
        let surface = DigitalSurface::new(volume, map).unwrap();
        for sparse in [false, true] {
            check_layout(volume, &surface, &RegionRuns::with_layout(&surface, sparse));
        }
    }

    fn check_layout(volume: &LabelVolume, surface: &DigitalSurface, runs: &RegionRuns) {
        let [nx, ny, nz] = volume.dims().map(|d| d as i64);
        for z in -1..=nz {
            for y in -1..=ny {
                for x in -1..=nx {
                    let expected = volume.label([x, y, z]).map(|l| surface.regions().region_of(l).unwrap().0);
                    assert_eq!(runs.region([x, y, z]), expected, "voxel {x} {y} {z}");
                }
            }
        }
        // `uniform` agrees with `for_each_run` on every chord of every line.
        for z in -1..=nz {
            for y in -1..=ny {
                for a in -2..=nx + 1 {
                    for b in a..=nx + 1 {
                        let mut pieces = Vec::new();
                        runs.for_each_run(y, z, a, b, |lo, hi, r| pieces.push((lo, hi, r)));
                        assert_eq!(pieces.first().map(|p| p.0), Some(a));
                        assert_eq!(pieces.last().map(|p| p.1), Some(b));
                        let single = (pieces.len() == 1).then(|| pieces[0].2);
                        assert_eq!(runs.uniform(y, z, a, b), single, "line {y} {z}, {a}..={b}: {pieces:?}");
                    }
                }
            }
        }
    }

    #[test]
    fn recovers_random_multi_label_volumes() {
        let mut rng = Lcg::new(7);
        for round in 0..40 {
            let dims = [1 + rng.below(7) as usize, 1 + rng.below(6) as usize, 1 + rng.below(5) as usize];
            let labels = 2 + round as u32 % 3;
            // Sparse labels leave lines no surfel touches.
            let density = [2u32, 5, 20][round % 3];
            let mut label = || if rng.below(density) == 0 { 1 + rng.below(labels) } else { 0 };
            let volume = LabelVolume::from_fn(dims, |_| label());
            if DigitalSurface::from_volume(&volume).is_ok() {
                check(&volume, &RegionMap::per_label());
            }
            let open = volume.clone().with_background(None);
            if DigitalSurface::from_volume(&open).is_ok() {
                check(&open, &RegionMap::per_label());
            }
            // Some sides cut open (a chunk of a larger volume), the others closed.
            let sides = [0, 1, 2].map(|_| [0, 1].map(|_| rng.below(2) == 1));
            let cut = volume.clone().with_open_sides(sides);
            if DigitalSurface::from_volume(&cut).is_ok() {
                check(&cut, &RegionMap::per_label());
            }
        }
    }

    #[test]
    fn recovers_lines_far_from_the_surface() {
        // A small box in a large open volume: most lines touch no surfel.
        let volume = LabelVolume::from_fn([9, 12, 10], |[x, y, z]| 3 + u32::from(x > 4 && y == 6 && z < 3))
            .with_background(None);
        check(&volume, &RegionMap::per_label());
        let volume = LabelVolume::from_fn([9, 12, 10], |[x, y, z]| u32::from(x < 2 && y == 6 && z == 9));
        check(&volume, &RegionMap::per_label());
    }
}
