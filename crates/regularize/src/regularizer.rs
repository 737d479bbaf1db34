//! The front door: [`regularize`] (one shot) and [`Regularizer`] (reusable).

use std::sync::Arc;
use std::time::Instant;

use glam::DVec3;
use voxreg_digisurf::{
    BlockVolume, DigitalSurface, LabelStorage, LabelVolume, RegionMap, SurfaceError, VertexData,
};
use voxreg_normals::{FeatureField, Interrupt, NormalField};

use crate::error::RegularizeError;
use crate::params::Params;
use crate::progress::Progress;
use crate::report::{NormalsReport, Report, StageTimes};
use crate::solver::{Solver, SolverChoice, SolverParams};
use crate::stages::{self, Event, RecentringInputs, Refine, Solve, Stage};

/// The regularized positions and what produced them.
#[derive(Clone, Debug)]
pub struct Output {
    /// The digital surface: the output's combinatorics (one quad per surfel).
    pub surface: Arc<DigitalSurface>,
    /// The regularized positions, one per vertex.
    pub positions: VertexData<DVec3>,
    /// The normal field of the last solve (the initial field without refinement).
    pub normals: NormalField,
    /// The attachment targets of the last solve (the input positions unless re-centred).
    pub targets: VertexData<DVec3>,
    /// The Ambrosio-Tortorelli feature field (per vertex) with [`crate::params::Estimator::At`].
    pub features: Option<FeatureField>,
    /// What was done: parameters, counts, timings, energies, every solve's report.
    pub report: Report,
}

/// Regularizes the digital surface of `volume` with `params`: the one-shot form of
/// [`Regularizer`].
///
/// The run goes on a thread of rayon's pool (where it is called from outside it):
/// [`Regularizer`]'s runs are best called that way too (`rayon::scope`,
/// `ThreadPool::install`), since each of their many parallel passes started from outside
/// the pool wakes a worker and waits for it.
pub fn regularize<S: LabelStorage>(
    volume: &LabelVolume<S>,
    params: &Params,
) -> Result<Output, RegularizeError> {
    let mut regularizer = Regularizer::from_volume(volume, &params.regions)?;
    regularizer.set_keep_normals(false);
    rayon::scope(|_| regularizer.run(params))
}

/// Peak memory per surfel of a run that does not clamp, with a margin: the resident
/// memory a run adds measured at 900 to 1,150 bytes per surfel with every preset and
/// estimator on one- and multi-label surfaces of 68k to 160k surfels, 740 to 790 on
/// tissues of 1.5 and 5.3 million (`tests/memory.rs` keeps the estimate above the
/// measured peak).
pub const BYTES_PER_SURFEL: u64 = 1_400;

/// [`BYTES_PER_SURFEL`] for a run that clamps (the voxel-art preset), whose clamped solve
/// builds a second set of coarse levels for the active-set rounds and updates them between
/// rounds: measured up to about 1,630 bytes per surfel with ii and at normals
/// (`tests/memory.rs`), 1,310 on a 3-million-quad voxel scene.
pub const BYTES_PER_SURFEL_CLAMPED: u64 = 2_100;

/// [`BYTES_PER_SURFEL`] for a run of the sweeps solver (the fast preset), which builds
/// no hierarchy and keeps its work arrays in `f32`: the resident memory a run adds
/// measured at about 400 bytes a surfel (the digital surface included) on tissues of 1.5
/// million surfels, 500 to 610 on surfaces of 80k to 130k (`tests/memory.rs`).
pub const BYTES_PER_SURFEL_SWEEPS: u64 = 700;

/// The part of a run's memory that does not grow with the surface, with a margin (the
/// direct solver's factor budget on small surfaces, the threads' buffers).
pub const BYTES_FIXED: u64 = 32 << 20;

/// An upper estimate of the memory a run of `params` takes on a surface of `surfels`
/// surfels, in bytes: [`BYTES_FIXED`] and [`BYTES_PER_SURFEL`] (or
/// [`BYTES_PER_SURFEL_CLAMPED`], [`BYTES_PER_SURFEL_SWEEPS`]) per surfel for the solver's operator, hierarchy and
/// vectors, the normals and the refinement's work arrays.
pub fn estimated_bytes(surfels: u64, params: &Params) -> u64 {
    let per = if params.clamps() {
        BYTES_PER_SURFEL_CLAMPED
    } else if params.solver.choice == SolverChoice::Sweeps {
        BYTES_PER_SURFEL_SWEEPS
    } else {
        BYTES_PER_SURFEL
    };
    surfels.saturating_mul(per).saturating_add(BYTES_FIXED)
}

/// The most surfels whose run fits in `limit` bytes, `need(surfels)` being the bytes a
/// run on that many takes (nondecreasing, for example [`estimated_bytes`] of the run's
/// parameters): the cap to give [`Regularizer::from_volume_within`].
pub fn max_surfels_within(limit: u64, need: impl Fn(u64) -> u64) -> u64 {
    // No surface has 2^32 surfels (its ids are 32-bit).
    let (mut lo, mut hi) = (0u64, 1u64 << 32);
    if need(0) > limit {
        return 0;
    }
    // need(lo) fits; the largest that fits is in lo..hi.
    while hi - lo > 1 {
        let mid = lo + (hi - lo) / 2;
        if need(mid) <= limit {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    lo
}

/// What a run keeps per `(y, z)` line of a blocks volume's lattice beyond its surface: the
/// integral-invariant normals' runs along x (an offset, a run, a region, a flag and a
/// queue entry per line), unless the lattice holds 16 times more lines than surfels (then
/// only the lines the surfels touch). A dense volume holds more voxels than lines, so its
/// budget leaves them out.
const BYTES_PER_LINE: u64 = 32;

/// The bytes of the lines of a blocks volume's lattice of `ny * nz` lines around `surfels`
/// surfels ([`BYTES_PER_LINE`]).
fn line_bytes(surfels: u64, ny: u64, nz: u64) -> u64 {
    let lines = ny.saturating_mul(nz);
    if u128::from(surfels) * 16 < u128::from(lines) {
        0
    } else {
        lines.saturating_mul(BYTES_PER_LINE)
    }
}

/// What [`Regularizer::from_volume_within_budget`] and
/// [`Regularizer::from_blocks_within_budget`] give.
#[derive(Debug)]
pub enum Budgeted {
    /// A run on the surface fits the budget: the regularizer.
    Fits(Box<Regularizer>),
    /// A run on the surface of `surfels` surfels would need `bytes`, more than the budget.
    TooLarge {
        /// The surface's surfels.
        surfels: u64,
        /// What a run on it needs.
        bytes: u64,
    },
}

/// One run of a [`Regularizer`] ([`Regularizer::run`]): the parameters, and how the run
/// starts and reports. `&Params` converts into a plain run.
#[non_exhaustive]
pub struct Run<'a> {
    /// The parameters.
    pub params: &'a Params,
    /// The initial normal field (one direction per surfel), instead of estimating
    /// `params.normals`. Default: `None`.
    pub initial: Option<&'a NormalField>,
    /// Warm state: solve round `k` starts from `warm[k]` (one position per vertex) where
    /// given, instead of from the input (round 0) or the previous round's result: a re-run
    /// after a small parameter change, from the previous run's solutions (each round's
    /// last iterate, [`Event::iterate`]), takes fewer iterations. The minimizers are the
    /// same (the energy is convex), so the result matches a cold run's within the
    /// solver's tolerance. The iterative solvers use the starts (the bounded one projects
    /// them into its boxes, which may have changed); the direct solver is exact and
    /// ignores them. A started round of the conjugate gradient reports its first iterate
    /// before the new energy's multigrid setup ([`crate::info::CgInfo::quick_start_iterations`]).
    /// Default: none.
    pub warm: &'a [Vec<DVec3>],
    /// Called at each stage and solver iteration. Default: none.
    pub progress: Option<&'a mut dyn FnMut(&Event)>,
    /// The flag this run and the next poll, replacing [`Regularizer::set_interrupt`]'s.
    /// Default: `None` (keep the regularizer's).
    pub interrupt: Option<Interrupt>,
}

impl<'a> Run<'a> {
    /// A plain run of `params`.
    pub fn new(params: &'a Params) -> Self {
        Run { params, initial: None, warm: &[], progress: None, interrupt: None }
    }

    /// Starts from the normal field `initial` (the field `initial`).
    pub fn from_normals(mut self, initial: &'a NormalField) -> Self {
        self.initial = Some(initial);
        self
    }

    /// Starts the solve rounds from `warm` (the field `warm`).
    pub fn warm(mut self, warm: &'a [Vec<DVec3>]) -> Self {
        self.warm = warm;
        self
    }

    /// Reports to `progress` (the field `progress`).
    pub fn progress(mut self, progress: &'a mut dyn FnMut(&Event)) -> Self {
        self.progress = Some(progress);
        self
    }

    /// Polls `interrupt` (the field `interrupt`).
    pub fn interrupt(mut self, interrupt: Interrupt) -> Self {
        self.interrupt = Some(interrupt);
        self
    }
}

impl<'a> From<&'a Params> for Run<'a> {
    fn from(params: &'a Params) -> Self {
        Run::new(params)
    }
}

/// The front door's reusable form: keeps the digital surface, its solver (symbolic
/// analysis, multigrid hierarchy) and the initial normal field across runs, for
/// parameter sweeps and interactive use. A run whose solver settings or initial-normal
/// settings differ from the last run's rebuilds only those.
///
/// A run polls the regularizer's [`Interrupt`] ([`Regularizer::set_interrupt`]) in every
/// stage that takes long (the normal estimators, the refinement's re-centring, the
/// solver's setup and iterations) and returns [`RegularizeError::Interrupted`] soon after
/// it is raised; what the regularizer keeps (the solver, its last multigrid cycle, the
/// initial normals) stays usable by the next run.
///
/// Call its runs from a thread of rayon's pool (`rayon::scope(|_| ...)`,
/// `ThreadPool::install`): each of a run's many parallel passes started from outside the
/// pool wakes a worker and waits for it, about a tenth of a small run's time.
#[derive(Debug)]
pub struct Regularizer {
    surface: Arc<DigitalSurface>,
    surface_seconds: f64,
    solver: Option<(SolverParams, Solver)>,
    normals: Option<(crate::params::NormalsParams, crate::params::EstimatedNormals)>,
    /// The re-centring's inputs that depend on the surface alone (the vertices outside
    /// digital plateaus, the surfels' sample weights, the plateaus' multipliers).
    recentring: Option<RecentringInputs>,
    /// Vertices the re-centring must not measure its drift at (a block's cut sides).
    pub(crate) untrusted: Option<Vec<bool>>,
    interrupt: Interrupt,
    keep_normals: bool,
}

impl Regularizer {
    /// A regularizer of `surface`.
    pub fn new(surface: impl Into<Arc<DigitalSurface>>) -> Self {
        Regularizer {
            surface: surface.into(),
            surface_seconds: 0.0,
            solver: None,
            normals: None,
            recentring: None,
            untrusted: None,
            interrupt: Interrupt::never(),
            keep_normals: true,
        }
    }

    /// Whether a run keeps the initial normal field it estimated for the next runs
    /// (default: `true`). A single run (the command line's) does not need it: not kept,
    /// its 24 bytes per surfel are free for the solves (and the diffused estimate's surfel
    /// graph, 17 bytes a surfel, is let go after the first field where no refinement
    /// round re-estimates).
    pub fn set_keep_normals(&mut self, keep: bool) {
        self.keep_normals = keep;
        if !keep {
            self.normals = None;
        }
    }

    /// A regularizer of `volume`'s digital surface, its labels grouped by `regions`. The
    /// volume may own its labels or borrow them ([`voxreg_digisurf::LabelView`]): they are
    /// read in place, never copied.
    pub fn from_volume<S: LabelStorage>(
        volume: &LabelVolume<S>,
        regions: &RegionMap,
    ) -> Result<Self, RegularizeError> {
        Self::from_volume_within(volume, regions, u64::MAX)
    }

    /// [`Regularizer::from_volume`] for a surface of at most `max_surfels` surfels
    /// ([`max_surfels_within`] a memory budget): refused with
    /// [`SurfaceError::TooManySurfels`](voxreg_digisurf::SurfaceError::TooManySurfels)
    /// as soon as the pass over the voxels finds more, before the surface is built (no cap:
    /// `u64::MAX`). One pass where counting first ([`Regularizer::estimated_bytes_of`])
    /// takes two.
    pub fn from_volume_within<S: LabelStorage>(
        volume: &LabelVolume<S>,
        regions: &RegionMap,
        max_surfels: u64,
    ) -> Result<Self, RegularizeError> {
        let t = Instant::now();
        let surface = DigitalSurface::new_within(volume, regions, max_surfels)?;
        let mut r = Regularizer::new(surface);
        r.surface_seconds = t.elapsed().as_secs_f64();
        Ok(r)
    }

    /// [`Regularizer::from_volume`] when a run on the surface fits `limit` bytes,
    /// `need(surfels)` being what a run on that many takes (nondecreasing, such as
    /// [`estimated_bytes`] of its parameters): the extraction is capped at the most
    /// surfels that fit ([`Regularizer::from_volume_within`]), so that a surface that fits
    /// is built in one pass over the voxels; a refused one is counted to the end (a pass
    /// that stores nothing, [`DigitalSurface::count_surfels`]) so that the caller can name
    /// its size and need.
    pub fn from_volume_within_budget<S: LabelStorage>(
        volume: &LabelVolume<S>,
        regions: &RegionMap,
        limit: u64,
        need: impl Fn(u64) -> u64,
    ) -> Result<Budgeted, RegularizeError> {
        let cap = max_surfels_within(limit, &need);
        match Regularizer::from_volume_within(volume, regions, cap) {
            Ok(r) => Ok(Budgeted::Fits(Box::new(r))),
            Err(RegularizeError::Surface(SurfaceError::TooManySurfels(m))) => {
                let surfels = DigitalSurface::count_surfels(volume, regions)?.max(m + 1);
                Ok(Budgeted::TooLarge { surfels, bytes: need(surfels) })
            }
            Err(e) => Err(e),
        }
    }

    /// A regularizer on the digital surface of the blocks of `volume`
    /// ([`DigitalSurface::from_blocks`]: the surface of the volume made dense, without
    /// the empty space between the blocks), with labels grouped into regions by `regions`.
    pub fn from_blocks(volume: &BlockVolume, regions: &RegionMap) -> Result<Self, RegularizeError> {
        let t = Instant::now();
        let surface = DigitalSurface::from_blocks(volume, regions)?;
        let mut r = Regularizer::new(surface);
        r.surface_seconds = t.elapsed().as_secs_f64();
        Ok(r)
    }

    /// [`Regularizer::from_blocks`] when a run on the surface fits `limit` bytes: `need`
    /// as for [`Regularizer::from_volume_within_budget`], plus what the run keeps per line
    /// of the blocks' lattice. The surfels are counted first (a pass over the blocks that
    /// stores nothing).
    pub fn from_blocks_within_budget(
        volume: &BlockVolume,
        regions: &RegionMap,
        limit: u64,
        need: impl Fn(u64) -> u64,
    ) -> Result<Budgeted, RegularizeError> {
        let surfels = DigitalSurface::count_surfels_of_blocks(volume, regions)?;
        let [_, ny, nz] = volume.dims().map(|d| d as u64);
        let bytes = need(surfels).saturating_add(line_bytes(surfels, ny, nz));
        if bytes > limit {
            return Ok(Budgeted::TooLarge { surfels, bytes });
        }
        Ok(Budgeted::Fits(Box::new(Regularizer::from_blocks(volume, regions)?)))
    }

    /// An upper estimate of the memory a run of `params` takes on this surface, in bytes
    /// ([`estimated_bytes`]), so that a caller can refuse a run that cannot fit before it
    /// starts.
    pub fn estimated_bytes(&self, params: &Params) -> u64 {
        estimated_bytes(self.surface.num_surfels() as u64, params)
    }

    /// The surfels of the regularizer [`Regularizer::from_volume`] would build with
    /// `params.regions`, and [`Regularizer::estimated_bytes`] of a run of `params` on it,
    /// found by counting the surfels in one pass over the voxels, before any of the
    /// surface is built: `(surfels, bytes)`.
    pub fn estimated_bytes_of<S: LabelStorage>(
        volume: &LabelVolume<S>,
        params: &Params,
    ) -> Result<(u64, u64), RegularizeError> {
        let surfels = DigitalSurface::count_surfels(volume, &params.regions)?;
        Ok((surfels, estimated_bytes(surfels, params)))
    }

    /// The digital surface.
    pub fn surface(&self) -> &Arc<DigitalSurface> {
        &self.surface
    }

    /// The flag the next runs poll: once it is raised (from another thread, through a
    /// clone), a run returns [`RegularizeError::Interrupted`] within one chunk of its
    /// current stage's work (a solver iteration, a multigrid level, a diffusion step, a
    /// surfel of a normal estimate). A raised flag stays raised: give each run its own.
    /// Default: [`Interrupt::never`].
    pub fn set_interrupt(&mut self, interrupt: Interrupt) {
        self.interrupt = interrupt;
    }

    /// Runs the pipeline: `run` is a [`Run`] (the parameters, and how the run starts and
    /// reports), or `&Params` for a plain run from the initial normals `params.normals`
    /// describes.
    ///
    /// The stages: the initial normals, one solve of the energy, then `params.refine`
    /// rounds of (refine the normals from the regularized quads, re-centre the attachment
    /// targets, solve), then the finish (fold-free post-condition, energies, report).
    pub fn run<'a>(&mut self, run: impl Into<Run<'a>>) -> Result<Output, RegularizeError> {
        let Run { params, initial, warm, progress, interrupt } = run.into();
        if let Some(i) = interrupt {
            self.interrupt = i;
        }
        match progress {
            Some(p) => self.run_stages(params, initial, warm, p),
            None => self.run_stages(params, initial, warm, &mut |_| {}),
        }
    }

    /// The stages ([`crate::stages`]) in order, each round of the mode's refinement a
    /// refine stage (from the second) and a solve stage.
    fn run_stages(
        &mut self,
        params: &Params,
        initial: Option<&NormalField>,
        warm: &[Vec<DVec3>],
        progress: &mut dyn FnMut(&Event),
    ) -> Result<Output, RegularizeError> {
        params.validate()?;
        if let Some(w) = warm.iter().find(|w| w.len() != self.surface.num_vertices()) {
            return Err(RegularizeError::SizeMismatch(format!(
                "{} start positions for {} vertices",
                w.len(),
                self.surface.num_vertices()
            )));
        }
        let surface = Arc::clone(&self.surface);
        let interrupt = self.interrupt.clone();
        interrupt.check()?;
        let rounds = params.refinement().rounds;
        let stages_total = 1.0 + (rounds as f64) * 2.0 + 1.0;
        let mut times = StageTimes { surface: self.surface_seconds, ..Default::default() };

        let t = Instant::now();
        progress(&Event { stage: Stage::Normals, fraction: 0.0, iteration: None, input: None });
        // The surfel graph depends on the surface alone: a kept sweeps solver lends its
        // own to the diffused estimate, which otherwise builds it for the solver.
        let mut graph = match &mut self.solver {
            Some((_, Solver::Sweeps(s))) => s.take_graph(),
            _ => None,
        };
        let normals = stages::initial_normals(
            &surface,
            &params.normals,
            initial,
            &mut self.normals,
            self.keep_normals,
            &mut graph,
            &interrupt,
        )?;
        times.normals = t.elapsed().as_secs_f64();

        // The solver, kept while its settings do not change. Its setup (the operator's
        // structure, the multigrid hierarchy, the clamping boxes) is the first solve's
        // stage for a progress display, as it is the report's `assemble`, not `normals`.
        interrupt.check()?;
        progress(&Event {
            stage: Stage::Solve { round: 0 },
            fraction: 1.0 / stages_total,
            iteration: None,
            input: None,
        });
        interrupt.check()?;
        let solver_params = params.solver_params();
        if self.solver.as_ref().is_none_or(|(p, _)| *p != solver_params) {
            self.solver = Some((solver_params, Solver::new(&surface, &solver_params)?));
        }
        let solver = &mut self.solver.as_mut().expect("built above").1;
        solver.set_interrupt(interrupt.clone());
        // The surfel graph goes (back) to the sweeps' re-estimates, where a round of this
        // run or a later run may use it; a single run without rounds lets it go before the
        // sweeps (the fast preset's peak).
        if let (Some(g), Solver::Sweeps(s)) = (graph, &mut *solver) {
            if rounds > 0 || self.keep_normals {
                s.set_graph(g);
            }
        }
        // Re-centring is the fidelity mode's, between refinement rounds.
        let sigma = params.mode.fidelity().and_then(|f| f.recentring).map(|r| r.sigma).filter(|_| rounds > 0);
        if sigma.is_some() && self.recentring.is_none() {
            self.recentring = Some(RecentringInputs::new(&surface, self.untrusted.as_deref()));
        }
        let recentring = sigma.and(self.recentring.as_ref());
        let solve = Solve::new(&surface, params, recentring);

        // The input positions are the lattice's, recomputed where needed rather than held
        // through the solves. Finding the thin sheets is timed with the refinement.
        let mut targets = surface.positions();
        let t = Instant::now();
        let mut refine = Refine::new(&surface, &normals.field, *params.refinement(), recentring.zip(sigma));
        times.refine += t.elapsed().as_secs_f64();
        let mut field = normals.field;
        let mut positions = VertexData::default();
        let mut solves = Vec::with_capacity(rounds + 1);
        let mut done = 1.0;
        for round in 0..=rounds {
            if round > 0 {
                let t = Instant::now();
                let stage = Stage::Refine { round };
                progress(&Event { stage, fraction: done / stages_total, iteration: None, input: None });
                match &mut *solver {
                    // The fast pipeline: the cheap re-estimate alone between the batches.
                    Solver::Sweeps(s) => {
                        // Its targets stay the lattice's (no re-centring): let go during
                        // the re-estimate, the pipeline's peak, and made again after it.
                        drop(std::mem::take(&mut targets));
                        refine.diffused(&positions, &mut field, s.graph(&surface), &interrupt)?;
                        targets = surface.positions();
                    }
                    _ => refine.round(round, &positions, &mut field, &mut targets, &interrupt)?,
                }
                times.refine += t.elapsed().as_secs_f64();
                done += 1.0;
            }
            let stage = Stage::Solve { round };
            let base = done / stages_total;
            if round > 0 {
                // The first solve's stage was announced before the solver's setup.
                progress(&Event { stage, fraction: base, iteration: None, input: None });
            }
            let mut report = |p: &Progress| {
                // Iterations close the gap to the tolerance geometrically: show the
                // fraction of the way (in log scale) from the first error estimate.
                let within = (1.0 - 1.0 / (1.0 + p.iteration as f64 / 20.0)).clamp(0.0, 1.0);
                progress(&Event {
                    stage,
                    fraction: base + within / stages_total,
                    iteration: Some(p),
                    input: Some(&targets),
                });
            };
            let (x, info) = solve.round(
                solver,
                round,
                &field,
                &targets,
                &mut positions,
                warm,
                &mut report,
                &interrupt,
            )?;
            let s = info.seconds();
            times.assemble += s.structure + s.assemble;
            times.solve += s.symbolic + s.factor + s.solve;
            positions = x.into();
            solves.push(info);
            done += 1.0;
        }

        interrupt.check()?;
        // The sweeps' work arrays are not read again in this run: let go before the finish,
        // which makes the lattice positions (otherwise the fast pipeline's peak).
        if let Solver::Sweeps(s) = &mut *solver {
            s.release_work();
        }
        let energy = stages::finish(&surface, params, &mut positions, &field, &targets, solve.weights())?;
        let report = Report {
            params: params.clone(),
            counts: surface.counts(),
            normals: NormalsReport {
                estimator: normals.estimator,
                radius: if initial.is_some() { None } else { params.normals.radius_on(&surface) },
                at: normals.at_info,
            },
            stages: times,
            energy,
            solves,
        };
        Ok(Output { surface, positions, normals: field, targets, features: normals.features, report })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_cap_is_the_most_surfels_whose_run_fits() {
        let params = Params::default();
        let need = |s| estimated_bytes(s, &params);
        for limit in [BYTES_FIXED, BYTES_FIXED + 1, 1 << 30, 20 << 30] {
            let cap = max_surfels_within(limit, need);
            assert!(need(cap) <= limit && need(cap + 1) > limit, "{limit}: {cap}");
        }
        assert_eq!(max_surfels_within(BYTES_FIXED - 1, need), 0);
        assert_eq!(max_surfels_within(u64::MAX, |_| 0), u64::from(u32::MAX));
    }

    #[test]
    fn a_capped_extraction_builds_what_fits_and_refuses_the_rest() {
        let v = LabelVolume::from_fn([12, 11, 10], |[x, y, z]| {
            let d = |a: usize, c: usize| (a as i64 - c as i64).pow(2);
            u32::from(d(x, 6) + d(y, 5) + d(z, 5) <= 16) + u32::from(x > 8)
        });
        let map = RegionMap::per_label();
        let whole = Regularizer::from_volume(&v, &map).unwrap();
        let n = whole.surface().num_surfels() as u64;
        let capped = Regularizer::from_volume_within(&v, &map, n).unwrap();
        assert_eq!(capped.surface().as_ref(), whole.surface().as_ref());
        assert_eq!(
            Regularizer::from_volume_within(&v, &map, n - 1).err(),
            Some(RegularizeError::Surface(SurfaceError::TooManySurfels(n - 1)))
        );
        // Within a budget: built where the run fits, else the whole surface's size and need.
        let need = |s: u64| 1000 + 10 * s;
        match Regularizer::from_volume_within_budget(&v, &map, need(n), need).unwrap() {
            Budgeted::Fits(r) => assert_eq!(r.surface().as_ref(), whole.surface().as_ref()),
            b => panic!("{b:?}"),
        }
        for limit in [need(n) - 1, need(n / 2), 999] {
            match Regularizer::from_volume_within_budget(&v, &map, limit, need).unwrap() {
                Budgeted::TooLarge { surfels, bytes } => assert_eq!((surfels, bytes), (n, need(n))),
                b => panic!("{limit}: {b:?}"),
            }
        }
    }

    /// Blocks are counted first, and their budget holds the lattice's lines where the
    /// lattice has fewer than 16 lines a surfel.
    #[test]
    fn blocks_within_a_budget_count_the_lattice_lines() {
        use voxreg_digisurf::{Block, BlockVolume};
        let cube = |offset| Block { offset, labels: ndarray::Array3::from_elem((3, 3, 3), 1) };
        let map = RegionMap::per_label();
        let need = |s: u64| 1000 + 10 * s;
        for (dims, lines) in [([10, 4, 4], 16 * 32), ([10, 40, 40], 1600 * 32), ([10, 50, 50], 0)] {
            let v = BlockVolume::new(dims, vec![cube([0, 0, 0]), cube([6, 0, 0])], 0).unwrap();
            let n = DigitalSurface::from_blocks(&v, &map).unwrap().num_surfels() as u64;
            assert_eq!(n, 108);
            let whole = need(n) + lines;
            match Regularizer::from_blocks_within_budget(&v, &map, whole, need).unwrap() {
                Budgeted::Fits(r) => assert_eq!(r.surface().num_surfels() as u64, n),
                b => panic!("{b:?}"),
            }
            match Regularizer::from_blocks_within_budget(&v, &map, whole - 1, need).unwrap() {
                Budgeted::TooLarge { surfels, bytes } => assert_eq!((surfels, bytes), (n, whole)),
                b => panic!("{b:?}"),
            }
        }
    }
}
