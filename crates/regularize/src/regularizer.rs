//! The front door: [`regularize`] (one shot) and [`Regularizer`] (reusable).

use std::sync::Arc;
use std::time::Instant;

use glam::DVec3;
use voxreg_digisurf::{BlockVolume, DigitalSurface, LabelStorage, LabelVolume, RegionMap, VertexData};
use voxreg_normals::{
    anisotropic_fit_weight, Diffused, FeatureField, Interrupt, NormalField, ProbeHints, Refined,
};

use crate::energy::Energy;
use crate::error::RegularizeError;
use crate::params::Params;
use crate::pipeline::{
    crease_weights, hold_thin_sheets, informative_vertices, plateau_weights, relaxed_normals, sagitta_lift,
    sample_weights, surfel_drift, thin_sheets, trusted_drift,
};
use crate::progress::Progress;
use crate::report::{EnergyReport, NormalsReport, Report, StageTimes};
use crate::solver::{SolveRequest, SolveStart, Solver, SolverParams};
use crate::weights::{FairnessMask, Weights};

/// A stage of the front door's work, for progress displays.
#[derive(Copy, Clone, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Stage {
    /// Estimating the initial normal field.
    Normals,
    /// Solve number `round` (0 is the first; `1..=refine` follow refinements).
    Solve {
        /// The round.
        round: usize,
    },
    /// Refining the normals and re-centring the targets before solve `round`.
    Refine {
        /// The round of the solve that follows.
        round: usize,
    },
}

impl Stage {
    /// A short label: `"normals"`, `"solve 2/4"`, `"refine 1/3"`.
    pub fn label(&self, params: &Params) -> String {
        match self {
            Stage::Normals => "normals".into(),
            Stage::Solve { round } => format!("solve {}/{}", round + 1, params.refine + 1),
            Stage::Refine { round } => format!("refine {round}/{}", params.refine),
        }
    }
}

/// What a progress callback receives.
#[derive(Copy, Clone, Debug)]
pub struct Event<'a> {
    /// The stage under way.
    pub stage: Stage,
    /// An estimate of the fraction of the whole run done, in `[0, 1]` (stages are
    /// weighted equally; iterations advance it within a solve).
    pub fraction: f64,
    /// The latest iteration of an iterative solver, within [`Stage::Solve`].
    pub iteration: Option<&'a Progress<'a>>,
    /// With `iteration`: the solve's input positions (its attachment targets), which
    /// the iterate is displaced from; see [`Event::iterate`].
    pub input: Option<&'a [DVec3]>,
}

impl Event<'_> {
    /// The current iterate of the solve under way, one position per vertex: `input +
    /// displacement` (`None` between iterations, and for the direct solver).
    pub fn iterate(&self) -> Option<Vec<DVec3>> {
        let (p, input) = (self.iteration?, self.input?);
        Some(input.iter().zip(p.displacement).map(|(x, d)| *x + *d).collect())
    }
}

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
    /// The Ambrosio-Tortorelli feature field (per vertex) with [`crate::Estimator::At`].
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

/// The part of a run's memory that does not grow with the surface, with a margin (the
/// direct solver's factor budget on small surfaces, the threads' buffers).
pub const BYTES_FIXED: u64 = 32 << 20;

/// An upper estimate of the memory a run of `params` takes on a surface of `surfels`
/// surfels, in bytes: [`BYTES_FIXED`] and [`BYTES_PER_SURFEL`] (or
/// [`BYTES_PER_SURFEL_CLAMPED`]) per surfel for the solver's operator, hierarchy and
/// vectors, the normals and the refinement's work arrays.
pub fn estimated_bytes(surfels: u64, params: &Params) -> u64 {
    let per = if params.clamps() { BYTES_PER_SURFEL_CLAMPED } else { BYTES_PER_SURFEL };
    surfels.saturating_mul(per).saturating_add(BYTES_FIXED)
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
    /// before the new energy's multigrid setup ([`crate::CgInfo::quick_start_iterations`]).
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
    normals: Option<(crate::NormalsParams, crate::params::EstimatedNormals)>,
    /// The re-centring's inputs that depend on the surface alone: the vertices outside
    /// digital plateaus ([`informative_vertices`]), the surfels' sample weights
    /// ([`sample_weights`]) and the plateaus' multipliers ([`plateau_weights`]).
    recentring: Option<Recentring>,
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
    /// its 24 bytes per surfel are free for the solves.
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
        let t = Instant::now();
        let surface = DigitalSurface::new(volume, regions)?;
        let mut r = Regularizer::new(surface);
        r.surface_seconds = t.elapsed().as_secs_f64();
        Ok(r)
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
        let stages_total = 1.0 + (params.refine as f64) * 2.0 + 1.0;
        let mut times = StageTimes { surface: self.surface_seconds, ..Default::default() };

        // Initial normals.
        let t = Instant::now();
        progress(&Event { stage: Stage::Normals, fraction: 0.0, iteration: None, input: None });
        let (start, features, at_info, estimator) = match initial {
            Some(field) => {
                if field.len() != surface.num_surfels() {
                    return Err(RegularizeError::SizeMismatch(format!(
                        "{} normals for {} surfels",
                        field.len(),
                        surface.num_surfels()
                    )));
                }
                (field.clone(), None, None, "given")
            }
            None => {
                let cached = self.normals.as_ref().filter(|(p, _)| *p == params.normals);
                if cached.is_none() {
                    let estimated = params.normals.estimate_interruptible(&surface, &interrupt)?;
                    self.normals = Some((params.normals.clone(), estimated));
                }
                let name = params.normals.estimator.name();
                if self.keep_normals {
                    let (_, n) = self.normals.as_ref().expect("estimated above");
                    (n.field.clone(), n.features.clone(), n.at_info.clone(), name)
                } else {
                    let (_, n) = self.normals.take().expect("estimated above");
                    (n.field, n.features, n.at_info, name)
                }
            }
        };
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
        if self.solver.as_ref().is_none_or(|(p, _)| *p != params.solver) {
            self.solver = Some((params.solver, Solver::new(&surface, &params.solver)?));
        }
        let solver = &mut self.solver.as_mut().expect("built above").1;
        solver.set_interrupt(interrupt.clone());
        let clamps = solver.clamp().is_some();
        let recentre = params.preserve_size && !clamps && params.refine > 0;
        if recentre && self.recentring.is_none() {
            let informative = informative_vertices(&surface);
            let plateaus = plateau_weights(&surface, &informative);
            let mut trusted = informative;
            if let Some(untrusted) = &self.untrusted {
                trusted.iter_mut().zip(untrusted).for_each(|(t, u)| *t &= !*u);
            }
            self.recentring = Some(Recentring { trusted, samples: sample_weights(&surface), plateaus });
        }
        let recentring = if recentre { self.recentring.as_ref() } else { None };
        let texture = params.texture_aware.then(|| FairnessMask::texture_aware(&surface));
        let junction = (params.junction_fairness && surface.interfaces().len() > 1)
            .then(|| FairnessMask::junction_curves(&surface))
            .filter(|m| m.num_affected_vertices() > 0);
        let fairness = match (texture, junction) {
            (Some(t), Some(j)) => Some(t.and(&j)),
            (t, j) => t.or(j),
        };
        let (alpha, beta) = match recentring.and_then(|r| r.plateaus.as_ref()) {
            Some((a, b)) => (Some(a.clone().into()), Some(b.clone().into())),
            None => (None, None),
        };
        let weights = Weights { fairness, alpha, beta, ..Default::default() };
        let weights = (weights != Weights::default()).then_some(weights);
        // The sagitta lift, blended in with the anisotropy like the refinement's fit
        // (0 on cubic voxels).
        let lift_weight = anisotropic_fit_weight(surface.spacing());

        // The input positions are the lattice's, recomputed where needed rather than held
        // through the solves.
        let mut targets = surface.positions();
        // The thin sheets' quads, with their shares and the normals they keep from the
        // first refinement round on (timed with the refinement).
        let t = Instant::now();
        let mut held: Vec<(u32, DVec3, f64)> = if params.refine > 0 {
            thin_sheets(&surface, &start, params.sheet_thickness)
                .into_iter()
                .map(|(s, share)| (s, DVec3::ZERO, share))
                .collect()
        } else {
            Vec::new()
        };
        times.refine += t.elapsed().as_secs_f64();
        let mut field = start;
        let mut positions = VertexData::default();
        let mut solves = Vec::with_capacity(params.refine + 1);
        let mut done = 1.0;
        // Each quad's last change of normal, for the relaxation of the next round's.
        let mut change = None;
        // Which quads' wide junction discs the last round found in use (see `Refined`).
        let mut hints = ProbeHints::default();
        for round in 0..=params.refine {
            if round > 0 {
                let t = Instant::now();
                progress(&Event {
                    stage: Stage::Refine { round },
                    fraction: done / stages_total,
                    iteration: None,
                    input: None,
                });
                if let Solver::Sweeps(s) = &mut *solver {
                    // The fast pipeline: the cheap re-estimate alone between the batches.
                    let diffused =
                        Diffused { positions: &positions, previous: &field, radius: params.refine_radius };
                    field = diffused.estimate_on(&surface, s.graph(&surface), &interrupt)?;
                } else {
                    let estimate = Refined {
                        positions: &positions,
                        previous: &field,
                        radius: params.refine_radius,
                        feature_angle_deg: params.feature_angle_deg,
                    }
                    .estimate_with_hints(&surface, &interrupt, &mut hints)?;
                    // Thin sheets keep the first round's normals.
                    let estimate = if round == 1 {
                        held.iter_mut().for_each(|h| h.1 = estimate.as_slice()[h.0 as usize]);
                        estimate
                    } else {
                        hold_thin_sheets(estimate, &held)
                    };
                    field = relaxed_normals(&field, estimate, &mut change);
                }
                if let Some(r) = recentring {
                    let lift = (lift_weight > 0.0).then(|| {
                        let mut lift = sagitta_lift(&surface, &positions, &field);
                        lift.iter_mut().for_each(|l| *l *= lift_weight);
                        lift
                    });
                    let (drift, sampled) = surfel_drift(
                        &surface,
                        &positions,
                        &surface.positions(),
                        r.samples.as_deref(),
                        lift.as_deref(),
                    );
                    let weight: Vec<f64> =
                        sampled.iter().zip(&r.trusted).map(|(w, &t)| if t { *w } else { 0.0 }).collect();
                    let drift = trusted_drift(&surface, &drift, &weight, params.recentre_sigma, &interrupt)?;
                    targets.iter_mut().zip(&drift).for_each(|(t, d)| *t -= *d);
                }
                times.refine += t.elapsed().as_secs_f64();
                done += 1.0;
            }
            interrupt.check()?;
            let creased = (params.refine > 0 && params.crease_alignment < 1.0).then(|| {
                let crease = crease_weights(
                    &surface,
                    &field,
                    params.crease_angle_deg,
                    params.crease_alignment,
                    params.crease_dilation,
                );
                let mut w = weights.clone().unwrap_or_default();
                w.beta = Some(match w.beta {
                    Some(b) => b.iter().zip(&crease).map(|(b, c)| b * c).collect(),
                    None => crease.into(),
                });
                w
            });
            interrupt.check()?;
            let energy = Energy::new(&surface, &field, &targets, params.energy)?;
            let energy = match creased.as_ref().or(weights.as_ref()) {
                Some(w) => energy.with_weights(w)?,
                None => energy,
            };
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
            // Refinement rounds start from the last solution (or the round's given start):
            // the minimizer moves little when the normals and targets do, so CG needs
            // fewer iterations to the same tolerance. The solves before the last only
            // feed the refinement: a looser tolerance.
            let last = round == params.refine;
            let factor = if last { 1.0 } else { params.intermediate_tolerance };
            // The bounded solver's refinement rounds start as its first does (a cold run's
            // results stay those its measurements describe); given starts it takes.
            let chained = round > 0 && !matches!(solver, Solver::Bounded(_));
            let start = match warm.get(round) {
                Some(start) => SolveStart::Given(start),
                None if chained => SolveStart::Owned(std::mem::take(&mut positions).into_vec()),
                None => SolveStart::Input,
            };
            // A next round without a given start builds its own cycle: this one's memory
            // goes to the refinement first (the last solve's is kept for a next run).
            let keep_cycle = last || warm.get(round + 1).is_some();
            let request = SolveRequest {
                start,
                tolerance: Some(params.solver.cg.tolerance * factor),
                quick_start: warm.get(round).is_some(),
                keep_cycle,
                progress: Some(&mut report),
            };
            let (x, info) = solver.solve(&energy, request)?;
            if !info.relative_gradient().is_finite() || x.iter().any(|p| !p.is_finite()) {
                let h = surface.spacing();
                return Err(RegularizeError::NotFinite(format!(
                    "solve {} gave non-finite positions or residuals (alpha {:e}, beta {:e}, gamma {:e}, \
                     voxel spacing {:e} {:e} {:e}): the weights or the spacing are out of range for \
                     double precision",
                    round + 1,
                    params.energy.alpha,
                    params.energy.beta,
                    params.energy.gamma,
                    h.x,
                    h.y,
                    h.z
                )));
            }
            let s = info.seconds();
            times.assemble += s.structure + s.assemble;
            times.solve += s.symbolic + s.factor + s.solve;
            positions = x.into();
            solves.push(info);
            done += 1.0;
        }

        interrupt.check()?;
        // The lattice positions: the targets themselves where no round re-centred them.
        let staircase = if params.refine == 0 {
            std::borrow::Cow::Borrowed(targets.as_slice())
        } else {
            std::borrow::Cow::Owned(surface.positions().into_vec())
        };
        if params.fold_free {
            crate::unfold::unfold(&surface, &staircase, &mut positions);
        }

        // The energy of the last round (its normals and targets, without crease weights),
        // before and after.
        let energy = Energy::new(&surface, &field, &targets, params.energy)?;
        let energy = match weights.as_ref() {
            Some(w) => energy.with_weights(w)?,
            None => energy,
        };
        let (before, after) = (energy.terms(&staircase), energy.terms(&positions));
        drop(staircase);
        if !(before.total.is_finite() && after.total.is_finite()) {
            return Err(RegularizeError::NotFinite(format!(
                "the energy is not finite ({} -> {}): the weights or the spacing are out of range",
                before.total, after.total
            )));
        }
        let report = Report {
            params: params.clone(),
            counts: surface.counts(),
            normals: NormalsReport {
                estimator,
                radius: if initial.is_some() { None } else { params.normals.radius_on(&surface) },
                at: at_info,
            },
            stages: times,
            energy: EnergyReport { before, after },
            solves,
        };
        Ok(Output { surface, positions, normals: field, targets, features, report })
    }
}

/// What the re-centring reads from the surface alone, kept across runs.
#[derive(Debug)]
struct Recentring {
    /// Per vertex, whether the drift is measured there (outside digital plateaus and a
    /// block's cut sides).
    trusted: Vec<bool>,
    /// Per surfel, the weight of its centre as a sample ([`sample_weights`]; `None`: all 1).
    samples: Option<Vec<f64>>,
    /// The plateaus' attachment and alignment multipliers ([`plateau_weights`]; `None`:
    /// all 1).
    plateaus: Option<(Vec<f64>, Vec<f64>)>,
}
