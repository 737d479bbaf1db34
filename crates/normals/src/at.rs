//! The Ambrosio-Tortorelli (AT) piecewise-smooth normal estimator (ref. \[42\] of the
//! multi-label paper: Coeurjolly, Foare, Gueth, Lachaud, "Piecewise smooth
//! reconstruction of normal vector field on digital data", Pacific Graphics 2016).
//!
//! The functional, its discretization and the solver are documented on
//! [`AmbrosioTortorelli`]; the linear systems and their solvers are in `linear.rs`.

use std::fmt;
use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;
use voxreg_digisurf::{DigitalSurface, EdgeId, SurfelId, VertexData};

use crate::error::NormalError;
use crate::estimator::NormalEstimator;
use crate::field::NormalField;
use crate::ii::IntegralInvariant;
use crate::interrupt::Interrupt;

mod linear;

use linear::{SolveStats, SpdSystem};

/// How the two sparse SPD systems of each alternation are solved.
#[derive(Copy, Clone, Debug, PartialEq, serde::Serialize)]
pub enum AtLinearSolver {
    /// faer's sparse Cholesky: AMD ordering and symbolic analysis once per surface and
    /// system, a numeric factorization and triangular solves per solve: exact to machine
    /// precision, and several times slower than the default on large surfaces.
    Cholesky,
    /// Jacobi-preconditioned conjugate gradients, warm-started from the previous
    /// alternation's solution, until the relative residual `|b - A x| / |b|` of every
    /// right-hand side is at most `tolerance`; after `max_iterations` without converging,
    /// the system is solved by Cholesky instead.
    ConjugateGradient {
        /// Relative residual to reach.
        tolerance: f64,
        /// CG iterations before falling back to Cholesky.
        max_iterations: usize,
    },
}

impl Default for AtLinearSolver {
    /// Conjugate gradients to a relative residual of `1e-5`, at most 1000 iterations: far
    /// below the change of `v` between alternations, so the fields read as with exact
    /// solves (see docs/design/at-linear-solver.md).
    fn default() -> Self {
        AtLinearSolver::ConjugateGradient { tolerance: 1e-5, max_iterations: 1000 }
    }
}

/// Parameters of the Ambrosio-Tortorelli functional and of its minimization.
///
/// Lengths (`epsilons`) are in units of the grid step `h`, the cube root of the voxel
/// volume; `alpha` and `lambda` are DGtal's `at-alpha` and `at-lambda` in those units.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct AtParams {
    /// Weight of the data term `|u - g|^2`: the smaller, the smoother `u`. Default `0.1`.
    pub alpha: f64,
    /// Weight of the discontinuity length: the smaller, the more discontinuities.
    /// Default `0.025`.
    pub lambda: f64,
    /// The decreasing widths `eps` of the discontinuity zones, in grid steps, solved in
    /// turn (Gamma-convergence). Default `[2.0, 1.0, 0.5, 0.25]`.
    pub epsilons: Vec<f64>,
    /// Most alternations (u-solve then v-solve) per `eps`. Default `10`.
    pub max_iterations: usize,
    /// Stop the alternations of one `eps` when `max |v^{k+1} - v^k|` is below this.
    /// Default `1e-4`.
    pub tolerance: f64,
    /// How the linear systems are solved. Default: conjugate gradients to a relative
    /// residual of `1e-5` ([`AtLinearSolver::default`]).
    pub linear_solver: AtLinearSolver,
    /// Most alternations of the sharpening stage run after the last `eps` (see
    /// [`AmbrosioTortorelli`], "Sharpening"); `0` skips the stage (the plain AT of ref.
    /// \[42\]). Default `10`.
    pub sharpen_iterations: usize,
    /// The sharpening stage's threshold `tau` on `v`: a surfel keeps its full data weight
    /// when `v >= tau` at its four corners, and `(min v / tau)^2` of it below. Default `0.4`.
    pub sharpen_threshold: f64,
}

impl Default for AtParams {
    fn default() -> Self {
        AtParams {
            alpha: 0.1,
            lambda: 0.025,
            epsilons: vec![2.0, 1.0, 0.5, 0.25],
            max_iterations: 10,
            tolerance: 1e-4,
            linear_solver: AtLinearSolver::default(),
            sharpen_iterations: 10,
            sharpen_threshold: 0.4,
        }
    }
}

impl AtParams {
    /// Checks every field's range.
    pub fn validate(&self) -> Result<(), NormalError> {
        let positive = |x: f64| x.is_finite() && x > 0.0;
        let invalid = |what: String| Err(NormalError::InvalidParameter(what));
        if !positive(self.alpha) {
            return invalid(format!("AT alpha must be positive, got {}", self.alpha));
        }
        if !positive(self.lambda) {
            return invalid(format!("AT lambda must be positive, got {}", self.lambda));
        }
        if self.epsilons.is_empty() || !self.epsilons.iter().all(|&e| positive(e)) {
            return invalid(format!("AT epsilons must be positive numbers, got {:?}", self.epsilons));
        }
        if !positive(self.sharpen_threshold) {
            return invalid(format!("AT sharpen_threshold must be positive, got {}", self.sharpen_threshold));
        }
        if self.max_iterations == 0 {
            return invalid("AT max_iterations must be at least 1".into());
        }
        if self.tolerance.is_nan() || self.tolerance < 0.0 {
            return invalid(format!("AT tolerance must be non-negative, got {}", self.tolerance));
        }
        if let AtLinearSolver::ConjugateGradient { tolerance, .. } = self.linear_solver {
            if !positive(tolerance) {
                return invalid(format!("AT CG tolerance must be positive, got {tolerance}"));
            }
        }
        Ok(())
    }
}

/// The discontinuity field `v` of Ambrosio-Tortorelli: one value per vertex, indexed by
/// [`VertexId`](voxreg_digisurf::VertexId).
///
/// Values lie (approximately) in `[0, 1]`: close to 1 where the normal field is smooth,
/// low (towards 0) along sharp features, in a band about `eps` wide.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct FeatureField {
    values: VertexData<f64>,
}

impl FeatureField {
    /// Wraps one value per vertex.
    pub fn new(values: Vec<f64>) -> Self {
        FeatureField { values: values.into() }
    }

    /// Number of values (vertices).
    pub fn len(&self) -> usize {
        self.values.len()
    }

    /// Whether the field is empty.
    pub fn is_empty(&self) -> bool {
        self.values.is_empty()
    }

    /// The values, in vertex order.
    pub fn as_slice(&self) -> &[f64] {
        &self.values
    }

    /// `v` averaged on each edge of `surface` (DGtal's `M01 v`), in edge order.
    pub fn on_edges(&self, surface: &DigitalSurface) -> Vec<f64> {
        surface
            .edges()
            .iter()
            .map(|e| 0.5 * (self.values[e.vertices[0]] + self.values[e.vertices[1]]))
            .collect()
    }

    /// `v` averaged over the four corners of each surfel of `surface`, in surfel order.
    pub fn on_surfels(&self, surface: &DigitalSurface) -> Vec<f64> {
        surface
            .surfels()
            .iter()
            .map(|s| s.vertices.iter().map(|&v| self.values[v]).sum::<f64>() / 4.0)
            .collect()
    }
}

/// What an Ambrosio-Tortorelli run did.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct AtInfo {
    /// Alternations run for each `eps`, in the order of [`AtParams::epsilons`].
    pub iterations: Vec<usize>,
    /// `max |v^{k+1} - v^k|` after the last alternation of each `eps`.
    pub v_change: Vec<f64>,
    /// Alternations of the sharpening stage (0 when skipped).
    pub sharpen_iterations: usize,
    /// Conjugate-gradient iterations, all solves together.
    pub cg_iterations: usize,
    /// Numeric Cholesky factorizations.
    pub factorizations: usize,
    /// Seconds spent by the initial estimator (zero when the input field was given).
    pub input_seconds: f64,
    /// Seconds spent on the complex's weights and sparsity patterns.
    pub setup_seconds: f64,
    /// Seconds spent assembling the matrices and right-hand sides.
    pub assemble_seconds: f64,
    /// Seconds spent in Cholesky factorizations, symbolic analyses included.
    pub factor_seconds: f64,
    /// Seconds spent in conjugate gradients and triangular solves.
    pub solve_seconds: f64,
}

impl AtInfo {
    fn add(&mut self, stats: SolveStats) {
        self.cg_iterations += stats.cg_iterations;
        self.factorizations += stats.factorizations;
        self.factor_seconds += stats.factor_seconds;
        self.solve_seconds += stats.solve_seconds;
    }
}

/// The Ambrosio-Tortorelli piecewise-smooth normal estimator (ref. \[42\]).
///
/// Regularizes the field of an initial estimator (`initial`, integral invariants by
/// default) into a field that is smooth except across sharp features, which it locates
/// with the discontinuity field `v` ([`FeatureField`], see
/// [`AmbrosioTortorelli::estimate_with_features`]). [`AtSolver`] is the reusable form
/// (one surface, many input fields or parameters).
///
/// # The functional (the spec)
///
/// Given an input unit normal field `g` (one vector per surfel), AT looks for a
/// regularized field `u` (per surfel: a primal 2-form, three of them, one per
/// coordinate) and a discontinuity field `v` (per vertex: a primal 0-form) minimizing
///
/// ```text
/// AT_eps(u, v) = alpha |u - g|^2 + |v grad u|^2 + lambda eps |grad v|^2 + lambda / (4 eps) |1 - v|^2
/// ```
///
/// discretized on the digital surface with a diagonal-Hodge discrete exterior calculus,
/// all lengths measured in units of the grid step `h` (the cube root of the voxel
/// volume, so isotropic grids reproduce DGtal's unit-metric `ATSolver2D` up to the
/// vertex areas, and anisotropic spacing changes the relative weights):
///
/// ```text
/// AT_eps(u, v) = alpha  sum_f  A_f |u_f - g_f|^2
///              + sum_l  w_l ((v_a + v_b) / 2)^2 |u_f - u_f'|^2        l = (f, f') across edge ab
///              + lambda eps  sum_e  w*_e (v_a - v_b)^2                   e = ab
///              + lambda / (4 eps)  sum_v  A_v (1 - v_v)^2
/// ```
///
/// - `A_f`: surfel area; `A_v = sum_{f ∋ v} A_f / 4`: the vertex's dual area
///   (the Hodge star of 2-forms and of 0-forms);
/// - `l`: a *dual edge*, a pair of surfels `f, f'` of the same interface sharing the edge
///   `ab` (the only pair on a manifold edge; on junction and pinch edges, each pair of
///   perpendicular surfels of one interface, i.e. each pair sharing a voxel). `u_f - u_f'`
///   is the dual derivative (DGtal's `primal_AD2`) and `w_l = |e| / |e*|` its 1-form Hodge
///   weight, `|e*|` the length from `f`'s centre to `f'`'s through the edge midpoint;
/// - `(v_a + v_b) / 2` is `v` averaged from the vertices to the edge (DGtal's `M01`);
/// - `w*_e = (sum_{f ∋ e} d(c_f, m_e)) / |e|`: the primal 1-form Hodge weight of `d0 v`
///   (the dual edge length summed over the incident surfels, over the edge length).
///
/// # The solver
///
/// Alternate minimization, each step an exact SPD solve: with `v` fixed,
///
/// ```text
/// (alpha A_2 + AD2^T diag(w (M01 v)^2) AD2) u = alpha A_2 g      (one matrix, 3 right-hand sides)
/// ```
///
/// then `u` is renormalized per surfel, and with `u` fixed,
///
/// ```text
/// (lambda / (4 eps) A_0 + lambda eps d0^T W* d0 + M01^T diag(sum_l w_l |AD2 u|^2) M01) v
///     = lambda / (4 eps) A_0 1
/// ```
///
/// repeated until `max |v^{k+1} - v^k| < tolerance` (or `max_iterations`), for each `eps`
/// of a decreasing sequence (Gamma-convergence).
///
/// # Sharpening (after the last `eps`)
///
/// From integral-invariant input, plain AT settles in a local minimum that keeps a
/// one-surfel chamfer along a digitized cube's edges (`v` low on two vertex rows, the edge
/// row coupled to neither face). So, once the `eps` sequence is done, the data term is
/// re-weighted by how much AT trusts the input there, and the alternations continue at
/// the last `eps` (at most [`AtParams::sharpen_iterations`], same tolerance), minimizing
///
/// ```text
/// alpha sum_f c_f A_f |u_f - g_f|^2 + (the other three terms, unchanged)
/// c_f = max(1e-3, min(1, min_{v in f} v / tau)^2)      from the v of the last eps, frozen
/// ```
///
/// `tau` is [`AtParams::sharpen_threshold`] (default 0.4). Where `v >= tau` at a surfel's
/// four corners (everywhere on smooth parts: on a sphere of radius `R` voxels `v` is about
/// `1 / (1 + 1 / (lambda R^2))`) the functional is unchanged; in the discontinuity zone the
/// biased input stops pulling and `u` follows its neighbours on its own side. Each
/// alternation still decreases this (frozen-weight) energy. On curved creases the rows
/// next to the crease keep a bias away from it (one-sided smoothing where `v` cuts the
/// coupling). The choice of `tau` and the corrections tried are in
/// docs/design/at-sharpening.md.
///
/// # Solvers
///
/// Both matrices keep their sparsity pattern through the run. Each system is solved by
/// [`AtLinearSolver`]: by default Jacobi-preconditioned conjugate gradients (one fused
/// pass per iteration, Chronopoulos-Gear form), warm-started from the previous
/// alternation's solution, to a relative residual of `1e-5`, falling back to Cholesky if
/// CG stalls; or faer's sparse Cholesky (AMD ordering and symbolic analysis once per
/// surface, a numeric factorization per solve). On large surfaces the alternations
/// decrease the energy monotonically but slowly and may not reach the tolerance on `v`
/// before [`AtParams::max_iterations`]. Why CG, and the speed-ups tried: see
/// docs/design/at-linear-solver.md.
///
/// # Example
///
/// ```
/// use voxreg_digisurf::{DigitalSurface, LabelVolume};
/// use voxreg_normals::{AmbrosioTortorelli, NormalEstimator};
///
/// let volume = LabelVolume::from_fn([8, 8, 8], |p| u32::from(p.iter().all(|&c| (1..7).contains(&c))));
/// let surface = DigitalSurface::from_volume(&volume)?;
/// let (normals, features) = AmbrosioTortorelli::default().estimate_with_features(&surface)?;
/// assert_eq!(normals.len(), surface.num_surfels());
/// assert_eq!(features.len(), surface.num_vertices());
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub struct AmbrosioTortorelli {
    /// The functional's parameters.
    pub params: AtParams,
    /// The estimator of the input field `g`. Default: [`IntegralInvariant::default`]
    /// (ball radius `3 h^{1/3}`).
    pub initial: Box<dyn NormalEstimator + Send + Sync>,
}

impl Default for AmbrosioTortorelli {
    fn default() -> Self {
        AmbrosioTortorelli { params: AtParams::default(), initial: Box::new(IntegralInvariant::default()) }
    }
}

impl fmt::Debug for AmbrosioTortorelli {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("AmbrosioTortorelli")
            .field("params", &self.params)
            .field("initial", &self.initial.name())
            .finish()
    }
}

impl AmbrosioTortorelli {
    /// AT with `params` on the field of `initial`.
    pub fn new(params: AtParams, initial: Box<dyn NormalEstimator + Send + Sync>) -> Self {
        AmbrosioTortorelli { params, initial }
    }

    /// The regularized unit normals `u` and the discontinuity field `v` (low on sharp
    /// features).
    pub fn estimate_with_features(
        &self,
        surface: &DigitalSurface,
    ) -> Result<(NormalField, FeatureField), NormalError> {
        self.estimate_with_info(surface).map(|(u, v, _)| (u, v))
    }

    /// As [`AmbrosioTortorelli::estimate_with_features`], with iteration counts and timings.
    pub fn estimate_with_info(
        &self,
        surface: &DigitalSurface,
    ) -> Result<(NormalField, FeatureField, AtInfo), NormalError> {
        self.estimate_with_info_interruptible(surface, &Interrupt::never())
    }

    /// [`AmbrosioTortorelli::estimate_with_info`], returning [`NormalError::Interrupted`]
    /// soon after `interrupt` is raised: it is polled by the initial estimator and between
    /// alternations ([`AtSolver::solve_interruptible`]).
    pub fn estimate_with_info_interruptible(
        &self,
        surface: &DigitalSurface,
        interrupt: &Interrupt,
    ) -> Result<(NormalField, FeatureField, AtInfo), NormalError> {
        self.params.validate()?;
        let t = Instant::now();
        let input = self.initial.estimate_interruptible(surface, interrupt)?;
        let input_seconds = t.elapsed().as_secs_f64();
        interrupt.check()?;
        let mut solver = AtSolver::new(surface)?;
        let (u, v, mut info) = solver.solve_interruptible(&input, &self.params, interrupt)?;
        info.input_seconds = input_seconds;
        Ok((u, v, info))
    }
}

impl NormalEstimator for AmbrosioTortorelli {
    fn name(&self) -> &'static str {
        "at"
    }

    fn estimate(&self, surface: &DigitalSurface) -> Result<NormalField, NormalError> {
        self.estimate_with_features(surface).map(|(u, _)| u)
    }

    fn estimate_interruptible(
        &self,
        surface: &DigitalSurface,
        interrupt: &Interrupt,
    ) -> Result<NormalField, NormalError> {
        self.estimate_with_info_interruptible(surface, interrupt).map(|(u, _, _)| u)
    }
}

/// A dual edge: two surfels sharing a primal edge, with the 1-form Hodge weight.
#[derive(Copy, Clone, Debug)]
struct Link {
    /// The two surfels, lower id first.
    surfels: [u32; 2],
    /// The primal edge they share.
    edge: u32,
    /// `|e| / |e*|`.
    weight: f64,
}

/// The fields of one AT run between alternations.
struct AtState {
    /// The last u-solve's solution before normalization, the warm start of the next.
    u_raw: Vec<[f64; 3]>,
    u_rhs: Vec<[f64; 3]>,
    /// `u_raw` normalized.
    u: Vec<DVec3>,
    v: Vec<[f64; 1]>,
    v_rhs: Vec<[f64; 1]>,
}

/// A reusable Ambrosio-Tortorelli solver for one surface.
///
/// [`AtSolver::new`] computes the discrete operators' weights and the two systems'
/// sparsity patterns once (and the symbolic Cholesky analyses on the first direct
/// solve); each [`AtSolver::solve`] (any input field, any parameters) redoes numeric work
/// only.
#[derive(Debug)]
pub struct AtSolver {
    /// Surfel areas `A_f`, in grid units.
    surfel_area: Vec<f64>,
    /// Vertex dual areas `A_v`, in grid units.
    vertex_area: Vec<f64>,
    /// Edge end points.
    edge_ends: Vec<[u32; 2]>,
    /// The 1-form Hodge weights `w*_e` of `d0 v`.
    edge_weight: Vec<f64>,
    /// Dual edges, sorted by primal edge.
    links: Vec<Link>,
    /// Links of edge `e`: `links[edge_links[e]..edge_links[e + 1]]`.
    edge_links: Vec<usize>,
    /// The four vertices of each surfel.
    surfel_vertices: Vec<[u32; 4]>,
    /// The u-system (on surfels; its off-diagonal pairs are the links).
    u_system: SpdSystem,
    /// The v-system (on vertices; its off-diagonal pairs are the edges).
    v_system: SpdSystem,
    setup_seconds: f64,
}

impl AtSolver {
    /// Builds the discrete operators of `surface` and the sparsity patterns of its systems.
    pub fn new(surface: &DigitalSurface) -> Result<Self, NormalError> {
        let t = Instant::now();
        let h = surface.spacing().element_product().cbrt();
        let positions: Vec<DVec3> = surface.positions().into_iter().map(|p| p / h).collect();
        let surfels = surface.surfels();
        let ns = surfels.len();
        let nv = surface.num_vertices();
        let ne = surface.num_edges();

        // Per surfel: area and, for each of its 4 edges, the distance from its centre to
        // the edge midpoint (half its dual edge).
        let (surfel_area, half_dual): (Vec<f64>, Vec<[f64; 4]>) = surfels
            .par_iter()
            .map(|s| {
                let p = s.vertices.map(|v| positions[v.index()]);
                let area = 0.5 * (p[2] - p[0]).cross(p[3] - p[1]).length();
                let c = (p[0] + p[1] + p[2] + p[3]) / 4.0;
                let half = std::array::from_fn(|i| (c - 0.5 * (p[i] + p[(i + 1) % 4])).length());
                (area, half)
            })
            .unzip();
        let mut vertex_area = vec![0.0; nv];
        for (s, a) in surfels.iter().zip(&surfel_area) {
            for v in s.vertices {
                vertex_area[v.index()] += a / 4.0;
            }
        }
        let edge_ends: Vec<[u32; 2]> = surface.edges().iter().map(|e| e.vertices.map(|v| v.0)).collect();
        let half_dual_at = |f: SurfelId, e: usize| -> f64 {
            let i = surface.surfel_edges(f).iter().position(|x| x.index() == e).unwrap_or(0);
            half_dual[f.index()][i]
        };
        // Per edge: its Laplacian weight and its dual edges.
        let per_edge: Vec<(f64, Vec<Link>)> = (0..ne)
            .into_par_iter()
            .map(|e| {
                let [a, b] = edge_ends[e];
                let length = (positions[a as usize] - positions[b as usize]).length();
                let incident = surface.edge_surfels(EdgeId(e as u32));
                let halves: Vec<f64> = incident.iter().map(|&f| half_dual_at(f, e)).collect();
                let weight = halves.iter().sum::<f64>() / length;
                let mut links = Vec::new();
                for i in 0..incident.len() {
                    for j in i + 1..incident.len() {
                        let (fi, fj) = (surface.surfel(incident[i]), surface.surfel(incident[j]));
                        if fi.interface != fj.interface {
                            continue;
                        }
                        // On a manifold edge the pair is the dual edge; around a junction or
                        // a pinch, only perpendicular surfels (sharing a voxel) are coupled.
                        let [vi, vj] = [fi.voxels(), fj.voxels()];
                        if incident.len() > 2 && !vi.iter().any(|x| vj.contains(x)) {
                            continue;
                        }
                        let (p, q) = (incident[i].0, incident[j].0);
                        links.push(Link {
                            surfels: [p.min(q), p.max(q)],
                            edge: e as u32,
                            weight: length / (halves[i] + halves[j]),
                        });
                    }
                }
                (weight, links)
            })
            .collect();
        let mut edge_weight = Vec::with_capacity(ne);
        let mut links = Vec::with_capacity(ne);
        let mut edge_links = Vec::with_capacity(ne + 1);
        edge_links.push(0);
        for (w, l) in per_edge {
            edge_weight.push(w);
            links.extend(l);
            edge_links.push(links.len());
        }
        let u_system = SpdSystem::new(ns, links.iter().map(|l| l.surfels));
        let v_system = SpdSystem::new(nv, edge_ends.iter().copied());
        Ok(AtSolver {
            surfel_vertices: surfels.iter().map(|s| s.vertices.map(|v| v.0)).collect(),
            surfel_area,
            vertex_area,
            edge_ends,
            edge_weight,
            links,
            edge_links,
            u_system,
            v_system,
            setup_seconds: t.elapsed().as_secs_f64(),
        })
    }

    /// Number of dual edges (coupled surfel pairs).
    pub fn num_links(&self) -> usize {
        self.links.len()
    }

    /// Regularizes `input` (one normal per surfel of this solver's surface): returns the
    /// unit field `u`, the discontinuity field `v` and the run's [`AtInfo`].
    pub fn solve(
        &mut self,
        input: &NormalField,
        params: &AtParams,
    ) -> Result<(NormalField, FeatureField, AtInfo), NormalError> {
        self.solve_interruptible(input, params, &Interrupt::never())
    }

    /// [`AtSolver::solve`], returning [`NormalError::Interrupted`] soon after `interrupt`
    /// is raised: it is polled before each alternation (two linear solves).
    pub fn solve_interruptible(
        &mut self,
        input: &NormalField,
        params: &AtParams,
        interrupt: &Interrupt,
    ) -> Result<(NormalField, FeatureField, AtInfo), NormalError> {
        params.validate()?;
        let ns = self.surfel_area.len();
        if input.len() != ns {
            return Err(NormalError::InvalidParameter(format!(
                "the input field has {} normals for {ns} surfels",
                input.len()
            )));
        }
        let mut info = AtInfo { setup_seconds: self.setup_seconds, ..AtInfo::default() };
        // A fixed split of the work, whatever the thread count: the same bits at every
        // thread count.
        let par = faer::Par::rayon(4);
        let (cg_tolerance, cg_iterations) = match params.linear_solver {
            AtLinearSolver::Cholesky => (None, 0),
            AtLinearSolver::ConjugateGradient { tolerance, max_iterations } => {
                (Some(tolerance), max_iterations)
            }
        };
        let g = input.as_slice();
        let mut state = AtState {
            u_raw: g.iter().map(|n| n.to_array()).collect(),
            u_rhs: vec![[0.0; 3]; ns],
            u: g.to_vec(),
            v: vec![[1.0]; self.vertex_area.len()],
            v_rhs: vec![[0.0]; self.vertex_area.len()],
        };
        let cg = (cg_tolerance, cg_iterations, par);
        for &eps in &params.epsilons {
            let mut iterations = 0;
            let mut change = f64::INFINITY;
            while iterations < params.max_iterations {
                interrupt.check()?;
                iterations += 1;
                change = self.alternate(g, &mut state, params, eps, None, cg, &mut info)?;
                if change < params.tolerance {
                    break;
                }
            }
            info.iterations.push(iterations);
            info.v_change.push(change);
        }
        if params.sharpen_iterations > 0 {
            let eps = *params.epsilons.last().expect("validated: at least one eps");
            let weight = self.sharpen_weights(&state.v, params.sharpen_threshold);
            while info.sharpen_iterations < params.sharpen_iterations {
                interrupt.check()?;
                info.sharpen_iterations += 1;
                let change = self.alternate(g, &mut state, params, eps, Some(&weight), cg, &mut info)?;
                if change < params.tolerance {
                    break;
                }
            }
        }
        let AtState { u, v, .. } = state;
        Ok((NormalField::new(u), FeatureField::new(v.into_iter().map(|[x]| x).collect()), info))
    }

    /// One alternation at width `eps`: the u-solve (data term weighted by `weight` if any),
    /// normalization, then the v-solve. Returns `max |v^{k+1} - v^k|`.
    #[allow(clippy::too_many_arguments)]
    fn alternate(
        &mut self,
        g: &[DVec3],
        state: &mut AtState,
        params: &AtParams,
        eps: f64,
        weight: Option<&[f64]>,
        (cg_tolerance, cg_iterations, par): (Option<f64>, usize, faer::Par),
        info: &mut AtInfo,
    ) -> Result<f64, NormalError> {
        let t = Instant::now();
        self.assemble_u(g, &state.v, params.alpha, weight, &mut state.u_rhs);
        info.assemble_seconds += t.elapsed().as_secs_f64();
        info.add(self.u_system.solve(&state.u_rhs, &mut state.u_raw, cg_tolerance, cg_iterations, par)?);
        let t = Instant::now();
        state.u.par_iter_mut().zip(&state.u_raw).for_each(|(n, raw)| {
            let raw = DVec3::from_array(*raw);
            *n = raw.try_normalize().unwrap_or(raw);
        });
        self.assemble_v(&state.u, params.lambda, eps, &mut state.v_rhs);
        info.assemble_seconds += t.elapsed().as_secs_f64();
        let v_old = state.v.clone();
        info.add(self.v_system.solve(&state.v_rhs, &mut state.v, cg_tolerance, cg_iterations, par)?);
        Ok(state.v.par_iter().zip(&v_old).map(|(a, b)| (a[0] - b[0]).abs()).reduce(|| 0.0, f64::max))
    }

    /// Fills the u-system `alpha A_2 + AD2^T diag(w (M01 v)^2) AD2` and its three
    /// right-hand sides `alpha A_2 g`.
    fn assemble_u(
        &mut self,
        g: &[DVec3],
        v: &[[f64; 1]],
        alpha: f64,
        weight: Option<&[f64]>,
        rhs: &mut [[f64; 3]],
    ) {
        let edge_ends = &self.edge_ends;
        let coef: Vec<f64> = self
            .links
            .par_iter()
            .map(|l| {
                let [a, b] = edge_ends[l.edge as usize];
                let m = 0.5 * (v[a as usize][0] + v[b as usize][0]);
                l.weight * m * m
            })
            .collect();
        let (diag, pair_slot, values) = self.u_system.values_mut();
        let data = |f: usize| alpha * self.surfel_area[f] * weight.map_or(1.0, |w| w[f]);
        for (f, slot) in diag.iter().enumerate() {
            values[*slot] = data(f);
        }
        for ((l, c), slot) in self.links.iter().zip(&coef).zip(pair_slot) {
            values[diag[l.surfels[0] as usize]] += c;
            values[diag[l.surfels[1] as usize]] += c;
            values[*slot] = -c;
        }
        rhs.par_iter_mut().zip(g.par_iter()).enumerate().for_each(|(f, (r, gf))| {
            *r = (data(f) * *gf).to_array();
        });
    }

    /// The sharpening stage's data weights `c_f = max(1e-3, min(1, min_{v in f} v / tau)^2)`
    /// (see [`AmbrosioTortorelli`], "Sharpening"); the floor keeps the u-system
    /// well-conditioned where `v` vanishes on every edge of a surfel.
    fn sharpen_weights(&self, v: &[[f64; 1]], tau: f64) -> Vec<f64> {
        self.surfel_vertices
            .par_iter()
            .map(|vs| {
                let low = vs.iter().map(|&i| v[i as usize][0]).fold(f64::INFINITY, f64::min);
                (low / tau).clamp(0.0, 1.0).powi(2).max(1e-3)
            })
            .collect()
    }

    /// Fills the v-system `lambda/(4 eps) A_0 + lambda eps d0^T W* d0 + M01^T diag(s) M01`,
    /// `s_e = sum_{l on e} w_l |u_f - u_f'|^2`, and its right-hand side
    /// `lambda/(4 eps) A_0 1`.
    fn assemble_v(&mut self, u: &[DVec3], lambda: f64, eps: f64, rhs: &mut [[f64; 1]]) {
        let (edge_links, links) = (&self.edge_links, &self.links);
        let s: Vec<f64> = (0..self.edge_ends.len())
            .into_par_iter()
            .map(|e| {
                links[edge_links[e]..edge_links[e + 1]]
                    .iter()
                    .map(|l| {
                        l.weight * (u[l.surfels[0] as usize] - u[l.surfels[1] as usize]).length_squared()
                    })
                    .sum()
            })
            .collect();
        let (data, smooth) = (lambda / (4.0 * eps), lambda * eps);
        let (diag, pair_slot, values) = self.v_system.values_mut();
        for (slot, a) in diag.iter().zip(&self.vertex_area) {
            values[*slot] = data * a;
        }
        for (([a, b], (w, s)), slot) in
            self.edge_ends.iter().zip(self.edge_weight.iter().zip(&s)).zip(pair_slot)
        {
            values[diag[*a as usize]] += smooth * w + 0.25 * s;
            values[diag[*b as usize]] += smooth * w + 0.25 * s;
            values[*slot] = -smooth * w + 0.25 * s;
        }
        rhs.par_iter_mut().zip(&self.vertex_area).for_each(|(x, a)| *x = [data * a]);
    }

    /// The discrete AT energy of `(u, v)` at `eps` for the input `g` (in grid units): the
    /// functional each alternation decreases, for tests and diagnostics.
    pub fn energy(&self, g: &NormalField, u: &[DVec3], v: &[f64], params: &AtParams, eps: f64) -> f64 {
        let g = g.as_slice();
        let data: f64 = (0..u.len()).map(|f| self.surfel_area[f] * (u[f] - g[f]).length_squared()).sum();
        let coupling: f64 = self
            .links
            .iter()
            .map(|l| {
                let [a, b] = self.edge_ends[l.edge as usize];
                let m = 0.5 * (v[a as usize] + v[b as usize]);
                l.weight * m * m * (u[l.surfels[0] as usize] - u[l.surfels[1] as usize]).length_squared()
            })
            .sum();
        let gradient: f64 = self
            .edge_ends
            .iter()
            .zip(&self.edge_weight)
            .map(|([a, b], w)| w * (v[*a as usize] - v[*b as usize]).powi(2))
            .sum();
        let away: f64 = v.iter().zip(&self.vertex_area).map(|(x, a)| a * (1.0 - x).powi(2)).sum();
        params.alpha * data + coupling + params.lambda * eps * gradient + params.lambda / (4.0 * eps) * away
    }
}

#[cfg(test)]
mod tests;
