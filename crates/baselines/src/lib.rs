//! Baselines and metrics for comparing voxreg's regularized surfaces with other ways of
//! meshing voxels (section 4.2 of the paper), shared by tests and `cargo xtask compare`.
//!
//! **Meshes.** Every method returns a [`Mesh`]: positions and polygon faces (triangles,
//! quads or general polygons), counter-clockwise around the outward normal, with topology
//! checks ([`Mesh::is_closed`], [`Mesh::is_consistently_oriented`],
//! [`Mesh::euler_characteristic`]). [`Mesh::from_surface`] wraps a digital surface or a
//! regularized one.
//!
//! **Baselines.**
//!
//! - [`marching_cubes`] on a [`ScalarGrid`] (or [`marching_cubes_volume`] on a label
//!   volume at iso-value 0.5): tables derived at first use from one face rule that
//!   separates inside corners on ambiguous faces, so surfaces are closed and oriented.
//! - [`laplacian_smooth`] and [`taubin_smooth`]: the mesh-denoising stand-in.
//! - [`dual_contour`] from Hermite data of the binary map or of an implicit function
//!   [`quantize`]d to a few bits (supplementary Figs. 3-4).
//! - [`shrouds`]: one vertex per surfel on its dual edge, slice-wise squared-curvature
//!   minimization (supplementary section 1; closed surfaces only).
//!
//! **Metrics.**
//!
//! - [`accuracy`] against an analytic [`Implicit`] shape: vertex distance (mean, max,
//!   signed mean = bias) and area-weighted face-normal error.
//! - [`quality`]: aspect ratio as in the paper's Fig. 9 ([`face_aspect_ratio`]), scaled
//!   Jacobian ([`face_scaled_jacobian`]), face-area distribution, degenerate and folded
//!   faces.
//! - [`distance_to`] a surface indexed by a [`TriangleIndex`] (e.g. the input digital
//!   surface: Proposition 1 bounds the mean by `O(h)`), and [`displacement`] between two
//!   embeddings of the same vertices.
//!
//! **Shapes.** Metrics take the small [`Implicit`] trait (value, gradient, projection),
//! not the dev-only test kit's `Shape`: this crate depends on `voxreg-digisurf` only, and
//! the test kit implements [`Implicit`] for its shapes.
//!
//! # Example
//!
//! ```
//! use glam::DVec3;
//! use voxreg_baselines::{accuracy, marching_cubes_volume, Ball, Implicit};
//! use voxreg_digisurf::LabelVolume;
//!
//! // A digital ball of radius 6 around voxel (8, 8, 8).
//! let ball = Ball { centre: DVec3::splat(8.0), radius: 6.0 };
//! let volume = LabelVolume::from_fn([17, 17, 17], |[x, y, z]| {
//!     u32::from(ball.value(DVec3::new(x as f64, y as f64, z as f64)) <= 0.0)
//! });
//! let mesh = marching_cubes_volume(&volume, |label| label == 1);
//! assert!(mesh.is_closed() && mesh.is_consistently_oriented());
//! assert_eq!(mesh.euler_characteristic(), 2);
//! let acc = accuracy(&mesh, &ball);
//! assert!(acc.distance_mean < 0.3 && acc.bias.abs() < 0.1);
//! ```

mod dc;
mod distance;
mod grid;
mod implicit;
mod linalg;
mod mc;
mod mesh;
mod metrics;
mod shrouds;
mod smooth;

pub use dc::{dual_contour, quantize, DcParams};
pub use distance::TriangleIndex;
pub use grid::ScalarGrid;
pub use implicit::{newton_project, Ball, Implicit};
pub use mc::{marching_cubes, marching_cubes_volume};
pub use mesh::Mesh;
pub use metrics::{
    accuracy, displacement, distance_to, face_aspect_ratio, face_scaled_jacobian, quality, Accuracy,
    DistanceStats, Quality, QualityParams,
};
pub use shrouds::{shrouds, ShroudsInfo, ShroudsParams};
pub use smooth::{laplacian_smooth, taubin_smooth, LaplacianParams, TaubinParams};

/// What can go wrong in this crate.
#[derive(Debug, thiserror::Error, Clone, PartialEq, Eq)]
pub enum BaselineError {
    /// An input is inconsistent (sizes, embedding).
    #[error("invalid input: {0}")]
    InvalidInput(String),
    /// The method does not handle this input (e.g. shrouds on a non-manifold surface).
    #[error("unsupported input: {0}")]
    Unsupported(String),
}
