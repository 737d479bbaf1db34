//! voxreg: regularize voxel data into smooth, faithful quad meshes.
//!
//! The front door is re-exported here: [`regularize()`] (a labelled volume in, regularized
//! positions and a serializable [`Report`] out), [`Regularizer`] (the same, reusable
//! across runs) and [`Params`] with its presets ([`Params::default`],
//! [`Params::papers`], [`Params::voxel_art`]). The workspace's crates follow, in the order
//! data flows through them:
//!
//! - [`digisurf`]: labeled volumes and their digital surface (surfels, edges, vertices,
//!   interfaces between labels).
//! - [`normals`]: normal estimators on the digital surface.
//! - [`regularize`](mod@regularize): the quadratic energy of the papers, its solvers and
//!   the front door.
//! - [`io`]: volume readers and mesh writers.
//!
//! # Example
//!
//! ```
//! use voxreg::digisurf::LabelVolume;
//! use voxreg::{regularize, Params};
//!
//! let volume = LabelVolume::from_fn([6, 6, 6], |[x, y, z]| {
//!     u32::from([x, y, z].iter().all(|c| (1..5).contains(c)))
//! });
//! let out = regularize(&volume, &Params::default())?;
//! assert_eq!(out.positions.len(), out.surface.num_vertices()); // same combinatorics
//! assert!(out.report.energy.after.total < out.report.energy.before.total);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub use voxreg_digisurf as digisurf;
pub use voxreg_io as io;
pub use voxreg_normals as normals;
pub use voxreg_regularize as regularize;
pub use voxreg_regularize::{regularize, Output, Params, Regularizer, Report};

/// The README's library example, compiled and run as a doctest.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
mod readme {}
