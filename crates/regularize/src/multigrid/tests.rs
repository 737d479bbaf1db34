//! Tests of the multigrid's parts, and the setup counter the solvers' tests read.

thread_local! {
    /// Multigrid setups ([`super::Hierarchy::numeric`]) run on this thread, for the
    /// tests that bound the work before a quick start's first iterate.
    pub(crate) static SETUPS: std::cell::Cell<usize> = const { std::cell::Cell::new(0) };
}

/// The setups run on this thread so far.
pub(crate) fn setups() -> usize {
    SETUPS.with(|c| c.get())
}

use glam::{DVec3, Vec3A};
use voxreg_digisurf::DigitalSurface;
use voxreg_testkit::{digitize, true_normals, Lcg, Torus};

use super::coarse::{full_block, galerkin_from_rows, galerkin_from_stencil, Blocks, Bsr};
use super::face::{face_row_reads, rows_near, SPARSE_CHANGES};
use super::hierarchy::{Hierarchy, MultigridParams};
use super::parts::{Accumulator, Rows};
use crate::energy::{Energy, EnergyParams};
use crate::stencil::{Coefficients, Stencil};
use voxreg_normals::Interrupt;

/// Rows built in several parts (some rows empty) read back and recomputed in place
/// across the parts' boundaries as if they were one array.
#[test]
fn rows_in_parts_read_and_recompute_as_one_array() {
    let n = 9000;
    // Row i: columns i, i + 7 and i * 3 (mod n), except every 13th row, empty;
    // numbers from the row, the column and `s`.
    let f = |s: f64| {
        move |acc: &mut Accumulator<2>, i: usize| {
            if i % 13 != 0 {
                for c in [i, (i + 7) % n, (i * 3) % n] {
                    let e = acc.entry(c as u32);
                    e[0] += s * i as f64 + c as f64;
                    e[1] += 1.0;
                }
            }
        }
    };
    let mut rows = Rows::<2>::build(n, n, f(1.0));
    assert!(rows.vals.parts.len() > 2, "{} parts", rows.vals.parts.len());
    let fresh = Rows::<2>::build(n, n, f(2.0));
    // Every third row, and the rows at the parts' edges, recomputed with `s = 2`.
    let mut dirty: Vec<usize> = (0..n).step_by(3).collect();
    for &k in &rows.vals.starts {
        let row = rows.offsets.partition_point(|&o| o <= k).saturating_sub(1).min(n - 1);
        dirty.extend([row.saturating_sub(1), row, (row + 1).min(n - 1)]);
    }
    dirty.sort_unstable();
    dirty.dedup();
    assert!(rows.recompute(&dirty, f(2.0)));
    let old = Rows::<2>::build(n, n, f(1.0));
    for i in 0..n {
        let want: Vec<_> = if dirty.binary_search(&i).is_ok() { fresh.row(i) } else { old.row(i) }.collect();
        assert_eq!(rows.row(i).collect::<Vec<_>>(), want, "row {i}");
    }
    // Another pattern is refused.
    let shifted = |acc: &mut Accumulator<2>, i: usize| {
        acc.entry(((i + 1) % n) as u32)[0] += 1.0;
    };
    assert!(!rows.recompute(&[1, 5000], shifted));
    // The blocks of a level read the parts in order.
    let flat: Vec<[f32; 2]> = fresh.vals.iter().copied().collect();
    assert_eq!(fresh.vals.map(|v| *v), flat);
    assert_eq!(flat.len(), fresh.nnz());
}

/// A face holding a random fifth of the coordinates.
fn random_face(n: usize, rng: &mut Lcg) -> Vec<Vec3A> {
    (0..n)
        .map(|_| {
            let v = rng.vec3(0.0, 1.0);
            Vec3A::new(f32::from(v.x > 0.2), f32::from(v.y > 0.2), f32::from(v.z > 0.2))
        })
        .collect()
}

/// Runs `test` on the default energy of a digitized torus (its true normals, each
/// moved by up to `noise` per coordinate and normalized when `noise > 0`): the
/// stencil, the coefficients and a hierarchy of at least three levels, with a random
/// generator seeded with `seed`.
fn on_torus(noise: f64, seed: u64, test: impl FnOnce(&Stencil, &Coefficients<'_>, &Hierarchy, &mut Lcg)) {
    let torus = Torus { major: 8.0, minor: 3.0 };
    let s = DigitalSurface::from_volume(&digitize(&torus, 1.0)).unwrap();
    let mut rng = Lcg::new(seed);
    let mut normals = true_normals(&s, &torus);
    if noise > 0.0 {
        normals.iter_mut().for_each(|n| *n = (*n + rng.vec3(-noise, noise)).normalize());
    }
    let normals = voxreg_normals::NormalField::new(normals);
    let input = s.positions();
    let e = Energy::new(&s, &normals, &input, EnergyParams::default()).unwrap();
    let st = Stencil::new(&s, None).unwrap();
    let c = st.coefficients(&e);
    let h = Hierarchy::new(
        &st,
        crate::stencil::lattice_corners(&s),
        &MultigridParams { coarsest_nodes: 20, ..Default::default() },
    );
    assert!(h.levels() > 2);
    test(&st, &c, &h, &mut rng);
}

/// The whole operator's coarse blocks are stored as symmetric blocks: they must be
/// exactly symmetric at every level, and their products those of the full blocks to
/// the bit.
#[test]
fn whole_operator_blocks_are_exactly_symmetric() {
    // Noisy normals: no symmetry from the shape itself.
    on_torus(0.3, 5, |st, c, h, rng| {
        let mut rows = galerkin_from_stencil(st, c, &h.aggregations[0]);
        for agg in &h.aggregations[1..] {
            assert!(rows.vals.iter().all(|b| b[1] == b[3] && b[2] == b[6] && b[5] == b[7]));
            let sym = Bsr::from_rows(&rows);
            assert!(matches!(sym.blocks, Blocks::Sym(_)));
            let full =
                Bsr { blocks: Blocks::Full(rows.vals.iter().map(full_block).collect()), ..sym.clone() };
            let x: Vec<Vec3A> = (0..rows.len()).map(|_| rng.vec3(-1.0, 1.0).as_vec3a()).collect();
            let b: Vec<Vec3A> = (0..rows.len()).map(|_| rng.vec3(-1.0, 1.0).as_vec3a()).collect();
            let (mut ys, mut yf) = (vec![Vec3A::ZERO; rows.len()], vec![Vec3A::ZERO; rows.len()]);
            sym.residual(&x, &b, &mut ys);
            full.residual(&x, &b, &mut yf);
            assert_eq!(ys, yf);
            assert_eq!(full.bytes() - sym.bytes(), 12 * rows.vals.len());
            rows = galerkin_from_rows(&rows, agg);
        }
    });
}

/// A cycle built in the arrays of another energy's cycle (the last solve's, in a
/// refinement loop) is the cycle built anew, to the bit; a cycle of another hierarchy
/// lends nothing.
#[test]
fn a_cycle_built_in_another_ones_arrays_is_the_same() {
    on_torus(0.2, 7, |st, c, h, rng| {
        let other = Coefficients {
            normals: c.normals,
            alpha: c.alpha,
            beta: c.beta,
            fair: c.fair.iter().map(|f| 3.0 * f).collect(),
            face_normals: c.face_normals.iter().map(|m| 0.5 * *m).collect(),
        };
        // The same levels, but another hierarchy's.
        let elsewhere =
            Hierarchy { aggregations: h.aggregations.iter().cloned().collect(), params: h.params };
        let r: Vec<DVec3> = (0..st.len()).map(|_| rng.vec3(-1.0, 1.0)).collect();
        let mut fresh = h.numeric(st, c, &Interrupt::never(), None).unwrap();
        let mut zf = vec![DVec3::ZERO; st.len()];
        fresh.apply(st, &r, &mut zf);
        for old in [
            h.numeric(st, &other, &Interrupt::never(), None),
            elsewhere.numeric(st, &other, &Interrupt::never(), None),
        ] {
            let mut reused = h.numeric(st, c, &Interrupt::never(), Some(Box::new(old.unwrap()))).unwrap();
            assert_eq!(reused.levels.len(), fresh.levels.len());
            for (a, b) in reused.levels.iter().zip(&fresh.levels) {
                assert_eq!((a.n, &a.smoother, a.matrix.bytes()), (b.n, &b.smoother, b.matrix.bytes()));
            }
            let mut z = vec![DVec3::ZERO; st.len()];
            reused.apply(st, &r, &mut z);
            assert_eq!(z, zf);
        }
    });
}

/// The rows found from the changed vertices are those that read one, and a superset
/// of them where a fairness mask cuts neighbours.
#[test]
fn rows_near_the_changes_are_the_rows_that_read_them() {
    let torus = Torus { major: 8.0, minor: 3.0 };
    let s = DigitalSurface::from_volume(&digitize(&torus, 1.0)).unwrap();
    let mut rng = Lcg::new(11);
    let cut: Vec<bool> = (0..s.num_edges()).map(|_| rng.next_f64() < 0.2).collect();
    let mask = crate::FairnessMask::from_cut_edges(&s, &cut).unwrap();
    for m in [None, Some(&mask)] {
        let st = Stencil::new(&s, m).unwrap();
        let params = MultigridParams { coarsest_nodes: 20, ..Default::default() };
        let h = Hierarchy::new(&st, crate::stencil::lattice_corners(&s), &params);
        let agg = &h.aggregations[0];
        for count in [1, 7, 60] {
            let mut changed = vec![false; st.len()];
            for _ in 0..count {
                changed[rng.below(st.len() as u32) as usize] = true;
            }
            let changes: Vec<u32> = (0..st.len() as u32).filter(|&i| changed[i as usize]).collect();
            let near = rows_near(&st, agg, &changes);
            let read: Vec<usize> = (0..agg.len())
                .filter(|&a| agg.members(a).iter().any(|&i| face_row_reads(&st, &changed, i as usize)))
                .collect();
            assert!(!read.is_empty());
            match m {
                None => assert_eq!(near, read),
                Some(_) => {
                    assert!(read.iter().all(|a| near.binary_search(a).is_ok()));
                    assert!(near.len() < 2 * read.len(), "{} rows near, {} read", near.len(), read.len());
                }
            }
        }
    }
}

#[test]
fn updated_face_levels_are_those_built_anew() {
    on_torus(0.0, 3, |st, c, h, rng| {
        let first = random_face(st.len(), rng);
        // The next face: the first one with one vertex, a few (the rows to rewrite found
        // from the changes, or by testing every row), or a third of them changed
        // (updates: a few rows rewritten one by one, or most rows, all rewritten in
        // parallel), then one with most of them changed (built anew).
        let flipped = |step: usize| {
            let mut next = first.clone();
            for i in (0..st.len()).step_by(step) {
                next[i] = Vec3A::new(1.0, 0.0, 1.0) - next[i] * Vec3A::new(1.0, 0.0, 1.0);
            }
            next
        };
        let (one, two, few, third) =
            (flipped(st.len()), flipped(st.len().div_ceil(2)), flipped(37), flipped(3));
        // One and two changes: below the share where the rows are found from the changes.
        assert!(2 * SPARSE_CHANGES < st.len() && st.len() / 37 * SPARSE_CHANGES > st.len());
        let many = random_face(st.len(), rng);
        let r: Vec<DVec3> = (0..st.len()).map(|_| rng.vec3(-1.0, 1.0)).collect();
        for next in [one, two, few, third, many] {
            let mut updated = h.numeric(st, c, &Interrupt::never(), None).unwrap();
            updated.set_face(st, c, &first, false);
            updated.set_face(st, c, &next, true);
            let mut fresh = h.numeric(st, c, &Interrupt::never(), None).unwrap();
            fresh.set_face(st, c, &next, false);
            let (a, b) = (updated.face_levels.as_ref().unwrap(), fresh.face_levels.as_ref().unwrap());
            assert_eq!(a.rows.len(), b.rows.len());
            for (ra, rb) in a.rows.iter().zip(&b.rows) {
                assert_eq!(ra.cols, rb.cols);
                assert_eq!(ra.vals, rb.vals);
            }
            for (la, lb) in a.levels.iter().zip(&b.levels) {
                assert_eq!(la.smoother, lb.smoother);
                assert_eq!(la.matrix.bytes(), lb.matrix.bytes());
            }
            let (mut za, mut zb) = (vec![DVec3::ZERO; st.len()], vec![DVec3::ZERO; st.len()]);
            updated.apply_on_face(st, &r, &mut za, Some(&next));
            fresh.apply_on_face(st, &r, &mut zb, Some(&next));
            assert_eq!(za, zb);
        }
    });
}

/// The cycle with the conjugate gradient's vectors lent (the fine residual and scratch,
/// then the coarse levels' work vectors, in `z` and the spare vector, whatever they
/// held) is the cycle in its own vectors, to the bit; lent, it makes no coarse work
/// vectors of its own.
#[test]
fn a_cycle_in_lent_vectors_is_the_cycle_in_its_own() {
    on_torus(0.2, 11, |st, c, h, rng| {
        let n = st.len();
        for steps in [1, 2] {
            let params =
                MultigridParams { smoothing_steps: steps, coarse_smoothing_steps: steps, ..h.params };
            let h = Hierarchy { aggregations: h.aggregations.clone(), params };
            let r: Vec<DVec3> = (0..n).map(|_| rng.vec3(-1.0, 1.0)).collect();
            let mut own = h.numeric(st, c, &Interrupt::never(), None).unwrap();
            let mut expected = vec![DVec3::ZERO; n];
            own.apply(st, &r, &mut expected);
            let mut lent = h.numeric(st, c, &Interrupt::never(), None).unwrap();
            assert!(lent.lent_fits(n), "the coarse levels fit in the lent vectors");
            for _ in 0..2 {
                let mut z: Vec<DVec3> = (0..n).map(|_| rng.vec3(-9.0, 9.0)).collect();
                let mut spare: Vec<DVec3> = (0..n).map(|_| rng.vec3(-9.0, 9.0)).collect();
                lent.apply_in(st, &r, &mut z, &mut spare);
                assert_eq!(z, expected, "{steps} smoothing steps");
            }
            assert!(lent.works[1..].iter().all(|w| w.r.is_empty() && w.x.is_empty() && w.t.is_empty()));
            assert!(own.works[1..].iter().all(|w| !w.x.is_empty()), "the own cycle made its vectors");
            assert!(
                lent.memory_bytes() + 40 * own.levels.iter().map(|l| l.n).sum::<usize>()
                    <= own.memory_bytes()
            );
        }
    });
}
