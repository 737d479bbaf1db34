//! What the iterative solvers share: the matrix-free operator's connectivity, the
//! preconditioners, and the memory-traffic model.

use std::time::Instant;

use glam::{DVec3, Vec3A};
use rayon::prelude::*;

use crate::energy::Energy;
use crate::error::RegularizeError;
use crate::info::{Preconditioner, SolveTimings};
use crate::multigrid::{Hierarchy, MultigridParams, Vcycle};
use crate::stencil::{Coefficients, MatrixFreeOperator, Stencil, CHUNK};
use crate::vecops::{sym_inverse, sym_mul};
use crate::weights::FairnessMask;
use voxreg_normals::Interrupt;

/// The structure an iterative solver keeps across solves on one surface.
#[derive(Debug)]
pub(crate) struct Setup {
    pub(crate) stencil: Stencil,
    mask: Option<FairnessMask>,
    hierarchy: Option<Hierarchy>,
    preconditioner: Preconditioner,
    multigrid: MultigridParams,
    /// The smallest voxel spacing: the unit of tolerances.
    pub(crate) spacing: f64,
    /// The voxel spacing per axis: the unit of boxes.
    pub(crate) voxel: DVec3,
    /// Seconds spent on structure (connectivity, hierarchy) not yet reported by a solve.
    pub(crate) structure_seconds: f64,
    /// The last solve's multigrid cycle ([`Setup::keep`]), which a quick start's first
    /// iterations use ([`Setup::prepare`]).
    kept: Option<Box<Vcycle>>,
}

/// One energy's numbers and preconditioner, ready to iterate.
pub(crate) struct Prepared<'a> {
    pub(crate) coef: Coefficients<'a>,
    pub(crate) pre: Pre,
    pub(crate) assemble_seconds: f64,
    pub(crate) factor_seconds: f64,
    /// Whether `pre` is the previous solve's cycle with its fine level refreshed (a quick
    /// start), to be replaced by this energy's own ([`Setup::renew`]).
    pub(crate) stale: bool,
}

impl Setup {
    pub(crate) fn new(
        operator: MatrixFreeOperator,
        preconditioner: Preconditioner,
        multigrid: MultigridParams,
    ) -> Result<Self, RegularizeError> {
        let t = Instant::now();
        let MatrixFreeOperator { stencil, spacing, build_seconds, corners } = operator;
        let hierarchy = match preconditioner {
            Preconditioner::Multigrid => Some(Hierarchy::new(&stencil, corners, &multigrid)),
            _ => None,
        };
        Ok(Setup {
            stencil,
            mask: None,
            hierarchy,
            preconditioner,
            multigrid,
            spacing: spacing.min_element(),
            voxel: spacing,
            structure_seconds: build_seconds + t.elapsed().as_secs_f64(),
            kept: None,
        })
    }

    /// The seconds of a solve of `prepared` whose iterations took `solve` seconds; the
    /// structure's seconds go to the first solve that built it (later ones report `0`).
    pub(crate) fn timings(&mut self, prepared: &Prepared<'_>, solve: f64) -> SolveTimings {
        SolveTimings {
            structure: std::mem::take(&mut self.structure_seconds),
            symbolic: 0.0,
            assemble: prepared.assemble_seconds,
            factor: prepared.factor_seconds,
            solve,
        }
    }

    /// Number of multigrid levels (1 without multigrid).
    pub(crate) fn levels(&self) -> usize {
        self.hierarchy.as_ref().map_or(1, Hierarchy::levels)
    }

    /// Checks that `energy` is on this surface, rebuilds the connectivity if its fairness
    /// mask changed, and computes its coefficients and preconditioner.
    ///
    /// With `quick`, and a multigrid cycle kept from the last solve on this connectivity
    /// ([`Setup::keep`]), the preconditioner is that cycle with its fine level put on the
    /// new operator ([`Vcycle::refresh_fine`]: O(n), no Galerkin products or coarse
    /// factorization), marked `stale`: the solver iterates at once and builds the
    /// energy's own cycle later ([`Setup::renew`]). Any symmetric positive definite
    /// preconditioner leaves the conjugate gradient's minimizer unchanged; only its rate
    /// depends on how far the energy moved. Otherwise the new cycle is built in a kept
    /// cycle's arrays ([`Hierarchy::numeric`]: one in memory at a time, no fresh
    /// memory faulted in). The multigrid setup polls `interrupt` between levels.
    pub(crate) fn prepare<'a>(
        &mut self,
        energy: &Energy<'a>,
        quick: bool,
        interrupt: &Interrupt,
    ) -> Result<Prepared<'a>, RegularizeError> {
        let surface = energy.surface();
        let n = self.stencil.len();
        if energy.input().len() != n || surface.num_vertices() != n {
            return Err(RegularizeError::SizeMismatch("the energy is not on this solver's surface".into()));
        }
        let mask = energy.weights().and_then(|w| w.fairness.as_ref());
        if mask != self.mask.as_ref() {
            let t = Instant::now();
            self.stencil = Stencil::new(surface, mask)?;
            self.mask = mask.cloned();
            self.kept = None;
            self.structure_seconds += t.elapsed().as_secs_f64();
        }
        let t = Instant::now();
        if let Some(v) = self.kept.as_mut() {
            v.release_shared();
        }
        let coef = self.stencil.coefficients(energy);
        let kept = match self.kept.take() {
            Some(mut v) if quick && self.preconditioner == Preconditioner::Multigrid => {
                v.refresh_fine(&self.stencil, &coef);
                return Ok(Prepared {
                    coef,
                    pre: Pre::Multigrid(v),
                    assemble_seconds: t.elapsed().as_secs_f64(),
                    factor_seconds: 0.0,
                    stale: true,
                });
            }
            kept => kept,
        };
        let pre = match self.preconditioner {
            Preconditioner::Identity => Pre::Identity,
            Preconditioner::Jacobi => Pre::Jacobi(
                self.stencil
                    .diagonal(&coef)
                    .iter()
                    .map(|d| DVec3::new(1.0 / d[0], 1.0 / d[1], 1.0 / d[2]))
                    .collect(),
            ),
            Preconditioner::BlockJacobi => {
                Pre::Block(self.stencil.diagonal(&coef).iter().map(sym_inverse).collect())
            }
            Preconditioner::Multigrid => {
                let h = self.hierarchy.get_or_insert_with(|| {
                    Hierarchy::new(&self.stencil, crate::stencil::lattice_corners(surface), &self.multigrid)
                });
                // The kept cycle's arrays become the new one's.
                Pre::Multigrid(Box::new(h.numeric(&self.stencil, &coef, interrupt, kept)?))
            }
        };
        let factor_seconds = match &pre {
            Pre::Multigrid(v) => v.factor_seconds,
            _ => 0.0,
        };
        Ok(Prepared {
            coef,
            pre,
            assemble_seconds: t.elapsed().as_secs_f64() - factor_seconds,
            factor_seconds,
            stale: false,
        })
    }

    /// Replaces a quick start's stale cycle by `prepared`'s energy's own (the setup
    /// [`Setup::prepare`] deferred), its seconds added to `prepared`'s; built in the
    /// stale cycle's arrays.
    pub(crate) fn renew(
        &self,
        prepared: &mut Prepared<'_>,
        interrupt: &Interrupt,
    ) -> Result<(), RegularizeError> {
        let Some(h) = self.hierarchy.as_ref().filter(|_| prepared.stale) else {
            return Ok(());
        };
        let t = Instant::now();
        let stale = match std::mem::replace(&mut prepared.pre, Pre::Identity) {
            Pre::Multigrid(v) => Some(v),
            _ => None,
        };
        let v = h.numeric(&self.stencil, &prepared.coef, interrupt, stale)?;
        prepared.factor_seconds += v.factor_seconds;
        prepared.assemble_seconds += t.elapsed().as_secs_f64() - v.factor_seconds;
        prepared.pre = Pre::Multigrid(Box::new(v));
        prepared.stale = false;
        Ok(())
    }

    /// Drops the cycle kept for a quick start (the next solve builds its own anyway).
    pub(crate) fn forget_kept(&mut self) {
        self.kept = None;
    }

    /// Keeps `prepared`'s multigrid cycle for the next solve's quick start.
    pub(crate) fn keep(&mut self, prepared: Prepared<'_>) {
        if let Pre::Multigrid(v) = prepared.pre {
            self.kept = Some(v);
        }
    }

    /// Bytes of the connectivity and per-solve numbers (normals borrowed, not counted).
    pub(crate) fn memory_bytes(&self, prepared: &Prepared<'_>) -> usize {
        self.stencil.bytes() + 8 * self.stencil.len() + prepared.pre.memory_bytes()
    }

    /// A model of the bytes one iteration moves between memory and the cores: `products`
    /// products by `H` (connectivity, normals and 5 vectors), `streams` other vector
    /// passes over `n` 3-vectors, and the preconditioner.
    pub(crate) fn traffic_model(&self, prepared: &Prepared<'_>, products: usize, streams: usize) -> usize {
        let n = self.stencil.len();
        let product = self.stencil.bytes() + prepared.coef.face_normals.len() * 24 + 8 * n + 5 * 24 * n;
        products * product + streams * 24 * n + prepared.pre.traffic(self.stencil.bytes(), n)
    }
}

/// A preconditioner with its numbers: `z = M^-1 r`.
pub(crate) enum Pre {
    Identity,
    Jacobi(Vec<DVec3>),
    Block(Vec<[f64; 6]>),
    Multigrid(Box<Vcycle>),
}

impl Pre {
    pub(crate) fn apply(&mut self, stencil: &Stencil, r: &[DVec3], z: &mut [DVec3]) {
        match self {
            Pre::Identity => z.copy_from_slice(r),
            Pre::Jacobi(d) => {
                z.par_chunks_mut(CHUNK).zip(r.par_chunks(CHUNK)).zip(d.par_chunks(CHUNK)).for_each(
                    |((z, r), d)| {
                        for i in 0..z.len() {
                            z[i] = r[i] * d[i];
                        }
                    },
                )
            }
            Pre::Block(d) => {
                z.par_chunks_mut(CHUNK).zip(r.par_chunks(CHUNK)).zip(d.par_chunks(CHUNK)).for_each(
                    |((z, r), d)| {
                        for i in 0..z.len() {
                            z[i] = sym_mul(&d[i], r[i]);
                        }
                    },
                )
            }
            Pre::Multigrid(v) => v.apply(stencil, r, z),
        }
    }

    /// [`Pre::apply`] where `spare` (one vector of the solver's) is free during the
    /// application: the multigrid cycle keeps its fine level's work in it and in `z`
    /// ([`Vcycle::apply_in`]), the same result with less memory held.
    pub(crate) fn apply_in(&mut self, stencil: &Stencil, r: &[DVec3], z: &mut [DVec3], spare: &mut [DVec3]) {
        match self {
            Pre::Multigrid(v) => v.apply_in(stencil, r, z, spare),
            _ => self.apply(stencil, r, z),
        }
    }

    /// Prepares [`Pre::apply_on_face`] for a new face; with `update`, the multigrid
    /// updates the coarse levels of the last face where the face changed
    /// ([`crate::multigrid::Vcycle::set_face`]).
    pub(crate) fn set_face(
        &mut self,
        stencil: &Stencil,
        coef: &Coefficients<'_>,
        face: &[Vec3A],
        update: bool,
    ) {
        if let Pre::Multigrid(v) = self {
            v.set_face(stencil, coef, face, update);
        }
    }

    /// Drops what [`Pre::set_face`] built (the multigrid's face levels).
    pub(crate) fn forget_face(&mut self) {
        if let Pre::Multigrid(v) = self {
            v.forget_face();
        }
    }

    /// `z = M_F^-1 r` on the face where `face` is 1 (0 on the held coordinates): the
    /// multigrid cycle of the face's operator ([`Vcycle::apply_on_face`]); the others
    /// (point or block diagonal) applied to the masked `r`, their result masked. `r`
    /// need not be masked.
    pub(crate) fn apply_on_face(&mut self, stencil: &Stencil, r: &[DVec3], z: &mut [DVec3], face: &[Vec3A]) {
        let each = |z: &mut [DVec3], f: &(dyn Fn(usize, DVec3) -> DVec3 + Sync)| {
            z.par_chunks_mut(CHUNK)
                .zip(r.par_chunks(CHUNK))
                .zip(face.par_chunks(CHUNK))
                .enumerate()
                .for_each(|(k, ((z, r), m))| {
                    for i in 0..z.len() {
                        let m = m[i].as_dvec3();
                        z[i] = f(k * CHUNK + i, r[i] * m) * m;
                    }
                });
        };
        match self {
            Pre::Identity => each(z, &|_, r| r),
            Pre::Jacobi(d) => each(z, &|i, r| r * d[i]),
            Pre::Block(d) => each(z, &|i, r| sym_mul(&d[i], r)),
            // The cycle masks its input and every value it writes.
            Pre::Multigrid(v) => v.apply_on_face(stencil, r, z, Some(face)),
        }
    }

    fn memory_bytes(&self) -> usize {
        match self {
            Pre::Identity => 0,
            Pre::Jacobi(d) => 24 * d.len(),
            Pre::Block(d) => 48 * d.len(),
            Pre::Multigrid(v) => v.memory_bytes(),
        }
    }

    /// Bytes moved by one application (`connectivity`: bytes of the stencil's
    /// connectivity).
    fn traffic(&self, connectivity: usize, n: usize) -> usize {
        match self {
            Pre::Identity => 48 * n,
            Pre::Jacobi(_) => 72 * n,
            Pre::Block(_) => 96 * n,
            Pre::Multigrid(v) => v.traffic(connectivity, n),
        }
    }
}
