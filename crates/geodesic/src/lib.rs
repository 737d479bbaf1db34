//! Geodesic distances on triangle and quad meshes (papers: section 4.5, Fig. 12).
//!
//! Distances measured on a digital surface are anisotropic: a path along the staircase is
//! longer in some directions than in others. The regularized surface has the same quads,
//! so distances computed on it (the smooth proxy) map back onto the digital surface
//! vertex by vertex and quad by quad. This crate works on any mesh given as positions and
//! polygons, not only voxreg's.
//!
//! - [`GeodesicMesh`]: the triangles of the polygons (quads split along their shorter
//!   diagonal) and their connectivity; [`GeodesicMesh::nearest_point`] places a source
//!   on the surface ([`SurfacePoint`], on a triangle) and [`GeodesicMesh::nearest_vertex`]
//!   at a vertex,
//!   [`GeodesicMesh::polygon_values`] maps per-vertex distances onto the polygons.
//! - [`exact_distances`]: exact polyhedral geodesics by window propagation (the improved
//!   Chen-Han algorithm), from one or several source vertices; [`exact_distances_from`]
//!   from points anywhere on the surface.
//! - [`HeatSolver`]: the heat method (cotan Laplacian, one backward Euler step, Poisson
//!   solve), both sparse Cholesky factorizations kept for further sources.
//! - [`distances`], [`distances_from`]: either method in one call ([`Method`]).
//!
//! # Example
//!
//! ```
//! use glam::DVec3;
//! use voxreg_geodesic::{distances, GeodesicMesh, Method};
//!
//! // A unit square folded along x = 1 into an L: the geodesic unfolds it.
//! let p = |x: f64, z: f64| if x <= 1.0 { DVec3::new(x, 0.0, z) } else { DVec3::new(1.0, x - 1.0, z) };
//! let positions = [p(0.0, 0.0), p(1.0, 0.0), p(2.0, 0.0), p(0.0, 1.0), p(1.0, 1.0), p(2.0, 1.0)];
//! let quads = [[0u32, 1, 4, 3], [1, 2, 5, 4]];
//! let mesh = GeodesicMesh::new(&positions, &quads)?;
//! let d = distances(&mesh, &[0], Method::Exact)?;
//! assert!((d[5] - 5f64.sqrt()).abs() < 1e-12);
//! # Ok::<(), voxreg_geodesic::GeodesicError>(())
//! ```

mod exact;
mod heat;
mod mesh;

pub use exact::{exact_distances, exact_distances_from, exact_estimated_bytes, ExactInfo};
pub use heat::{HeatParams, HeatSolver};
pub use mesh::{GeodesicMesh, SurfacePoint};

/// How distances are computed.
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq)]
pub enum Method {
    /// Exact polyhedral geodesics ([`exact_distances`]). The default.
    #[default]
    Exact,
    /// The heat method with default [`HeatParams`] ([`HeatSolver`]): approximate, a few
    /// percent, but two sparse solves per source set once factored.
    Heat,
}

/// What can go wrong.
#[derive(Debug, thiserror::Error, Clone, PartialEq, Eq)]
pub enum GeodesicError {
    /// The positions or polygons are not a mesh.
    #[error("invalid mesh: {0}")]
    InvalidMesh(String),
    /// No source was given.
    #[error("no source point")]
    NoSource,
    /// A source is not a vertex of the mesh.
    #[error("invalid source: {0}")]
    InvalidSource(String),
    /// A parameter is out of range.
    #[error("invalid parameter: {0}")]
    InvalidParams(String),
    /// A sparse factorization failed (a degenerate mesh).
    #[error("factorization failed: {0}")]
    Factorization(String),
}

/// Geodesic distance from the nearest of `sources` (vertex indices) at every vertex of
/// `mesh`, by `method`; `f64::INFINITY` on the components no source reaches.
pub fn distances(mesh: &GeodesicMesh, sources: &[u32], method: Method) -> Result<Vec<f64>, GeodesicError> {
    match method {
        Method::Exact => Ok(exact_distances(mesh, sources)?.0),
        Method::Heat => HeatSolver::new(mesh.clone(), &HeatParams::default())?.distances(sources),
    }
}

/// Geodesic distance from the nearest of `sources` (points anywhere on the surface,
/// such as [`GeodesicMesh::nearest_point`] gives) at every vertex of `mesh`, by
/// `method`; `f64::INFINITY` on the components no source reaches.
pub fn distances_from(
    mesh: &GeodesicMesh,
    sources: &[SurfacePoint],
    method: Method,
) -> Result<Vec<f64>, GeodesicError> {
    match method {
        Method::Exact => Ok(exact_distances_from(mesh, sources)?.0),
        Method::Heat => HeatSolver::new(mesh.clone(), &HeatParams::default())?.distances_from(sources),
    }
}
