//! voxreg: regularize voxel data into smooth, faithful quad meshes.
//!
//! This facade re-exports the workspace's crates, in the order data flows through them:
//!
//! - [`digisurf`]: labeled volumes and their digital surface (surfels, edges, vertices,
//!   interfaces between labels).
//! - [`normals`]: normal estimators on the digital surface.
//! - [`regularize`]: the quadratic energy of the papers and its solvers.
//! - [`io`]: volume readers and mesh writers.
//!
//! # Example
//!
//! ```
//! use voxreg::digisurf::{DigitalSurface, LabelVolume};
//! use voxreg::normals::{NormalEstimator, Trivial};
//! use voxreg::regularize::{regularize, EnergyParams};
//!
//! let volume = LabelVolume::from_fn([6, 6, 6], |[x, y, z]| u32::from((1..5).contains(&x) && (1..5).contains(&y) && (1..5).contains(&z)));
//! let surface = DigitalSurface::from_volume(&volume)?;
//! let normals = Trivial.estimate(&surface)?;
//! let result = regularize(&surface, &normals, EnergyParams::default())?;
//! assert_eq!(result.positions.len(), surface.num_vertices()); // same combinatorics
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub use voxreg_digisurf as digisurf;
pub use voxreg_io as io;
pub use voxreg_normals as normals;
pub use voxreg_regularize as regularize;
