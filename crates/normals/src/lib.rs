//! Normal estimators on digital surfaces.
//!
//! A [`NormalField`] holds one unit direction per surfel of a
//! [`DigitalSurface`](voxreg_digisurf::DigitalSurface). Estimators implement the small
//! [`NormalEstimator`] trait so callers (the CLI, xtask) can loop over them:
//!
//! - [`Trivial`]: the surfel's own axis, oriented from its lower region to its higher one.
//! - [`AmbrosioTortorelli`]: piecewise-smooth regularization of an initial field by the
//!   Ambrosio-Tortorelli functional (ref. \[42\]), smooth except across sharp features,
//!   which it returns as a per-vertex [`FeatureField`].
//! - [`IntegralInvariant`]: the eigenvector of the smallest eigenvalue of the covariance of
//!   a ball intersected with the surfel's region (digital integral invariants, ref. \[53\]);
//!   multigrid convergent, error `O(h^{2/3})` with the default radius
//!   [`multigrid_radius`] `= 3 h^{1/3}`. Exact digital moments in `O(r^2)` per surfel.
//! - [`ConvolvedTrivial`]: trivial normals averaged over a geodesic disc of the surface.
//! - [`Refined`]: normals re-estimated from given vertex positions (the front door's
//!   refinement rounds).
//! - [`Diffused`]: the same from the quads' vector areas diffused over each interface's
//!   surfel graph ([`QuadGraph`]), the fast pipeline's cheap re-estimate;
//!   [`DiffusedStaircase`], the same from the staircase's own faces (the `fast` preset's
//!   field).
//!
//! [`NormalEstimator::estimate_interruptible`] stops an estimate early when the caller
//! raises an [`Interrupt`] (an interactive front end replacing a run).
//!
//! On multi-label volumes the ball-based and convolution estimators follow the paper's
//! sec. 3.1: each surfel is estimated once from each of its two regions, treated as the
//! shape, and the two directions are averaged (orientation forgotten). Estimators read the
//! regions from the surface alone; no volume is needed.
//!
//! The regularization energy only uses each normal's *direction*: orientation is
//! kept for display and export.
//!
//! # Example
//!
//! ```
//! use voxreg_digisurf::{DigitalSurface, LabelVolume};
//! use voxreg_normals::{NormalEstimator, Trivial};
//!
//! let volume = LabelVolume::from_fn([3, 3, 3], |p| u32::from(p == [1, 1, 1]));
//! let surface = DigitalSurface::from_volume(&volume)?;
//! let normals = Trivial.estimate(&surface)?;
//! assert_eq!(normals.len(), 6);
//! // Normals of a solid point outward: the +x face of the voxel has normal +x.
//! let s = surface.surfels().iter().position(|s| s.axis == 0 && s.cell[0] == 2).unwrap();
//! assert_eq!(normals.as_slice()[s], glam::DVec3::X);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod at;
mod convolved;
mod diffused;
mod eigen;
mod error;
mod estimator;
mod field;
mod ii;
mod interrupt;
mod refined;
mod runs;
mod sides;
mod trivial;

pub use at::{AmbrosioTortorelli, AtInfo, AtLinearSolver, AtParams, AtSolver, FeatureField};
pub use convolved::ConvolvedTrivial;
pub use diffused::{Diffused, DiffusedStaircase, QuadGraph};
pub use error::NormalError;
pub use estimator::NormalEstimator;
pub use field::NormalField;
pub use ii::{default_radius, multigrid_radius, IntegralInvariant, MAX_DEFAULT_RADIUS_VOXELS};
pub use interrupt::Interrupt;
pub use refined::{
    anisotropic_fit_weight, FeatureRamp, ProbeHints, Refined, FEATURE_RAMP_DEG, JUNCTION_DISC_FACTOR,
};
pub use trivial::Trivial;
