//! The digital surface of a labeled voxel volume, as a cellular complex.
//!
//! A [`LabelVolume`] holds one label per voxel, a voxel spacing and an origin (its labels
//! owned, or borrowed without a copy as a [`LabelView`]). Labels
//! are grouped into regions by a [`RegionMap`] (by default every label is its own
//! region). The [`DigitalSurface`] is the complex of every voxel face (*surfel*)
//! between two face-adjacent voxels of different regions, with
//!
//! - surfels ([`Surfel`]): their two voxels, labels and regions, axis, orientation and
//!   four vertices in a consistent (counter-clockwise) order,
//! - vertices (lattice corners) with physical positions, edge-neighbours, incident
//!   surfels, and rim ("boundary") flags,
//! - edges ([`Edge`]) with their incident surfels: 2 on a manifold edge, up to 4 on a
//!   junction between interfaces or an edge pinch ([`EdgeKind`]),
//! - interfaces ([`Interface`]): the surfels of each unordered region pair.
//!
//! Parts of the surface become meshes of their own as [`Patch`]es: one interface
//! ([`DigitalSurface::interface_patch`]) or the outward-oriented surface of one region
//! ([`DigitalSurface::region_patch`]), optionally made 2-manifold by splitting pinches
//! ([`PatchParams::manifold`]).
//!
//! The crate holds structure only: ids ([`SurfelId`], [`VertexId`], [`EdgeId`],
//! [`InterfaceId`], [`RegionId`]) and incidences. Quantities such as normals and
//! positions live in plain arrays indexed by those ids, in the crates above.
//!
//! **Orientation.** Each surfel's normal points from its lower region to its higher
//! one; the background's region always comes last, so the surface of a solid is
//! oriented outward. **Open surfaces.** A volume with no background
//! ([`LabelVolume::with_background`]`(None)`) has no surfels on the domain border:
//! interfaces end there, and the vertices on that rim are boundary vertices.
//!
//! # Example
//!
//! ```
//! use voxreg_digisurf::{DigitalSurface, LabelVolume};
//!
//! // A 2x1x1 bar of label 1 in a 3x3x3 volume of background 0.
//! let volume = LabelVolume::from_fn([4, 3, 3], |[x, y, z]| {
//!     u32::from((1..3).contains(&x) && y == 1 && z == 1)
//! });
//! let surface = DigitalSurface::from_volume(&volume)?;
//! assert_eq!(surface.num_surfels(), 10);
//! assert_eq!(surface.num_vertices(), 12);
//! assert_eq!(surface.euler_characteristic(), 2); // a sphere
//! # Ok::<(), voxreg_digisurf::SurfaceError>(())
//! ```
//!
//! # Cost
//!
//! Building scans the voxels once, slab by slab (no per-voxel hash map); memory is
//! the current slab plus the complex, proportional to the number of surfels.

mod blocks;
mod csr;
mod data;
mod error;
mod ids;
mod patch;
mod regions;
mod surface;
mod union_find;
mod volume;

pub use blocks::{Block, BlockVolume};
pub use csr::Lists;
pub use data::{EdgeData, Id, IdVec, SurfelData, VertexData};
pub use error::SurfaceError;
pub use ids::{EdgeId, InterfaceId, RegionId, SurfelId, VertexId};
pub use patch::{Patch, PatchParams};
pub use regions::{RegionMap, Regions};
pub use surface::{DigitalSurface, Edge, EdgeKind, Interface, SurfaceCounts, Surfel};
pub use union_find::union_find_root;
pub use volume::{
    checked_origin, checked_spacing, x_fastest_array, LabelStorage, LabelView, LabelVolume, Voxel,
};
