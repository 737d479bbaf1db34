//! File formats for voxreg: labeled volumes in, quad meshes out.
//!
//! **Reading volumes.** [`read_volume`] picks the reader by extension and returns a
//! [`LoadedVolume`]: a [`LabelVolume`](voxreg_digisurf::LabelVolume) plus, for
//! MagicaVoxel files, the palette.
//!
//! - DGtal `.vol` (versions 2 and 3): [`read_vol`], [`read_vol_bytes`]; one byte per
//!   voxel, label = byte value, background `0`.
//! - MagicaVoxel `.vox`: [`read_vox`], [`read_vox_bytes`]; label = colour index
//!   (`1..=255`), background `0`, lattice corners at integer MagicaVoxel coordinates.
//!
//! Readers never panic on malformed input: truncated data, bad headers and dimensions
//! that do not match the data are [`IoError`]s naming the file, and volumes of more
//! than [`MAX_VOXELS`] voxels are refused before anything is allocated for them.
//!
//! **Writing meshes.** A [`QuadMesh`] (positions, quads, `[inner, outer]` labels per
//! face, named [`FaceGroup`]s) is built from a digital surface by
//! [`QuadMesh::from_surface`] and written by [`write_mesh`], which picks the format by
//! extension: ASCII OBJ with one group per interface ([`write_obj`]) or binary PLY with
//! per-face labels ([`write_ply`]). Writers go through a temporary file renamed onto
//! the target, so a failed write leaves no partial file.
//!
//! # Example
//!
//! ```
//! use voxreg_digisurf::{DigitalSurface, LabelVolume};
//! use voxreg_io::{write_mesh, QuadMesh};
//!
//! // One voxel of label 1 in background 0: a cube of 6 quads on 8 vertices.
//! let volume = LabelVolume::from_fn([3, 3, 3], |p| u32::from(p == [1, 1, 1]));
//! let surface = DigitalSurface::from_volume(&volume)?;
//! let mesh = QuadMesh::from_surface(&surface, &surface.positions());
//!
//! let dir = tempfile::tempdir()?;
//! let path = dir.path().join("cube.obj");
//! write_mesh(&path, &mesh)?;
//! let text = std::fs::read_to_string(&path)?;
//! assert_eq!(text.lines().filter(|l| l.starts_with("v ")).count(), 8);
//! assert_eq!(text.lines().filter(|l| l.starts_with("f ")).count(), 6);
//! assert!(text.contains("\ng interface_1_0\n"));
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! # Features
//!
//! None.

mod error;
mod mesh;
mod obj;
mod ply;
mod vol;
mod volume;
mod vox;

pub use error::IoError;
pub use mesh::{write_mesh, FaceGroup, QuadMesh};
pub use obj::write_obj;
pub use ply::write_ply;
pub use vol::{read_vol, read_vol_bytes};
pub use volume::{read_volume, LoadedVolume, MAX_VOXELS};
pub use vox::{read_vox, read_vox_bytes};
