//! File formats for voxreg: labeled volumes in, quad meshes out.
//!
//! **Reading volumes.** [`read_voxels`] picks the reader by extension and returns
//! [`LoadedVoxels`]: [`Voxels`], either labels (a
//! [`LabelVolume`](voxreg_digisurf::LabelVolume): values that are all integers in
//! `0..=u32::MAX`) or grey levels (a [`GreyVolume`] of `f64`, to
//! [threshold](Voxels::threshold)), with spacing and origin from the header, plus, for
//! MagicaVoxel files, the palette. [`read_volume`] does the same for label data and
//! returns a [`LoadedVolume`].
//!
//! - DGtal `.vol` (versions 2 and 3): [`read_vol`], [`read_vol_bytes`]; one byte per
//!   voxel, label = byte value, background `0`.
//! - DGtal `.longvol` (versions 2 and 3, 64-bit voxels): [`read_longvol`],
//!   [`read_longvol_bytes`].
//! - DGtal `.pgm3d` (`P3D` binary, `P2-3D` ASCII): [`read_pgm3d`], [`read_pgm3d_bytes`].
//! - MagicaVoxel `.vox`: [`read_vox`], [`read_vox_bytes`]; label = colour index
//!   (`1..=255`), background `0`, lattice corners at integer MagicaVoxel coordinates.
//! - NIfTI-1 `.nii`, `.nii.gz`: [`read_nifti`], [`read_nifti_bytes`]; integer and float
//!   types, `scl_slope`/`scl_inter`, spacing and origin from the sform or qform (axis
//!   flips and permutations applied, oblique rotations dropped).
//! - VTK XML image data `.vti`: [`read_vti`], [`read_vti_bytes`]; cell or point data,
//!   ASCII, base64 or appended, raw or zlib-compressed.
//! - NumPy `.npy` (versions 1 to 3): [`read_npy`], [`read_npy_bytes`]; a 3-D array
//!   `a[x, y, z]`, C or Fortran order.
//! - TIFF stacks `.tif`, `.tiff` (multi-page, or a directory or pattern of single-page
//!   slices): [`read_tiff`], [`read_tiff_bytes`], [`read_tiff_slices`]; 8 to 64-bit
//!   integer or float greyscale, spacing and units from OME-TIFF or ImageJ metadata.
//! - NRRD `.nrrd`, `.nhdr` (detached), and 3D Slicer's `.seg.nrrd`: [`read_nrrd`],
//!   [`read_nrrd_bytes`]; raw, gzip or ascii, `space directions`/`space origin`,
//!   `space units`; segment names and colours as the palette (names kept in
//!   [`Palette::names`]).
//! - MRC/CCP4 `.mrc`, `.map`, `.rec`: [`read_mrc`], [`read_mrc_bytes`]; modes 0, 1, 2
//!   and 6, voxel size in ångström from the cell.
//! - Zarr v2 and v3 arrays `.zarr` (directories) and OME-Zarr images (NGFF 0.4, 0.5;
//!   level 0, or a level named by its path, `image.ome.zarr/0`), through `zarrs`:
//!   [`read_zarr`], [`read_zarr_entries`]; blosc, gzip, zstd, sharding; spacing, origin
//!   and units from the OME metadata.
//! - Raw data, whose layout ([`RawSpec`]: dimensions, [`DataType`], [`Endian`],
//!   spacing) the caller gives: [`read_raw`], [`read_raw_bytes`].
//!
//! [`read_input`] reads a volume as a front end's options describe it
//! ([`InputOptions`]: raw layout, spacing, threshold, labels kept, [`Background`]) into
//! an [`Input`]; the CLI and the Python package both read through it.
//!
//! Readers never panic on malformed input: truncated data, bad headers, dimensions that
//! do not match the data, unsupported types and NaN grey levels are [`IoError`]s naming
//! the file, and volumes of more than [`MAX_VOXELS`] voxels, or needing more memory than
//! the budget ([`max_memory`]: half the physical memory unless [`set_max_memory`] says
//! otherwise, never above the address-space or cgroup limit, [`environment_limit`]), are refused before anything is allocated for them; compressed data are
//! never inflated past their declared size. Each `read_*_bytes` entry point is fuzzed (`fuzz/`).
//!
//! **Writing meshes.** A [`QuadMesh`] (positions, quads, `[inner, outer]` labels per
//! face, named [`FaceGroup`]s) is built from a digital surface by
//! [`QuadMesh::from_surface`] and written by [`write_mesh`], which picks the format by
//! extension: ASCII OBJ with one group per interface ([`write_obj`]), binary PLY with
//! per-face labels ([`write_ply`]), glTF ([`write_gltf`]), binary STL ([`write_stl`])
//! or VTK PolyData with per-face labels and colours ([`write_vtp`]); [`write_ply_with_vertex_scalar`] adds one value
//! per vertex (a `float` property and a colour ramp) for inspecting a field such as the
//! AT feature field, and [`write_ply_with_vertex_field`] the same with given colours
//! (geodesic distances with iso-lines); [`PlyParts`] writes the PLY of a mesh larger than
//! memory in parts. Writers go through a temporary file renamed onto
//! the target, so a failed write leaves no partial file. Parts of the surface (one
//! interface, one region's closed surface: a [`Patch`](voxreg_digisurf::Patch)) become
//! meshes by [`QuadMesh::from_patch`], and [`MeshBatch`] writes many into a directory
//! all or nothing. [`Outputs`] stages every file of a run (meshes, batches, reports)
//! and commits them together or none; [`input_files`] lists what an input will read, so
//! that a front end can refuse outputs that would replace it. Temporaries are owned
//! through file locks ([`inflight`]).
//!
//! **Label names.** Where the input names its labels (`.seg.nrrd` segments, `.vox`
//! materials with a `_name`), the [`Palette`] keeps the names ([`Palette::names`]);
//! [`QuadMesh::assign_materials`] lists those of the mesh's labels
//! ([`QuadMesh::named_labels`]), which every writer but STL carries (PLY and OBJ header
//! comments, glTF node names, VTP field data), and [`named_region_name`] /
//! [`named_interface_name`] make file names of them ([`file_name_part`]).
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

mod commit;
mod error;
mod files;
mod gltf;
mod grey;
pub mod inflight;
mod input;
mod input_files;
mod limits;
mod loaded;
mod longvol;
mod material;
mod mesh;
mod mesh_writer;
mod mrc;
mod nifti;
mod npy;
mod nrrd;
mod obj;
mod orient;
mod pgm3d;
mod ply;
mod raw;
mod read_mesh;
mod samples;
mod size;
mod stl;
#[cfg(test)]
mod testing;
mod tiff;
mod vol;
mod volume;
mod vox;
mod vti;
mod vtp;
mod write_volume;
mod zarr;

pub use commit::{MeshBatch, Outputs};
pub use error::IoError;
pub use files::{file_kind, read_input_file, MAX_VOXELS};
pub use gltf::write_gltf;
pub use grey::{GreyVolume, NotALabel, Voxels};
pub use input::{
    read_input, read_input_bytes, read_sparse_input, Background, Input, InputError, InputOptions, SparseInput,
};
pub use input_files::{input_files, same_output, InputFiles};
pub use limits::{
    check_memory, default_max_memory, environment_limit, max_memory, set_max_memory, with_max_memory,
    FALLBACK_MAX_MEMORY,
};
pub use loaded::{LoadedVolume, LoadedVoxels};
pub use longvol::{read_longvol, read_longvol_bytes};
pub use material::{material_name, Material, NamedLabel, Palette};
pub use mesh::{
    file_name_part, interface_name, named_interface_name, named_region_name, region_name,
    write_file_atomically, FaceGroup, QuadMesh,
};
pub use mesh_writer::write_mesh;
pub use mrc::{read_mrc, read_mrc_bytes};
pub use nifti::{read_nifti, read_nifti_bytes};
pub use npy::{read_npy, read_npy_bytes};
pub use nrrd::{read_nrrd, read_nrrd_bytes};
pub use obj::write_obj;
pub use orient::{check_coordinates, COORDINATE_RANGE};
pub use pgm3d::{read_pgm3d, read_pgm3d_bytes};
pub use ply::{scalar_ramp, write_ply, write_ply_with_vertex_field, write_ply_with_vertex_scalar, PlyParts};
pub use raw::{read_raw, read_raw_bytes, RawSpec};
pub use read_mesh::{read_mesh, read_mesh_bytes};
pub use samples::{DataType, Endian};
pub use size::{format_size, parse_size};
pub use stl::write_stl;
pub use tiff::{read_tiff, read_tiff_bytes, read_tiff_slices, tiff_slices};
pub use vol::{read_vol, read_vol_bytes};
pub use volume::{is_voxel_art, read_volume, read_voxels, read_voxels_bytes, read_voxels_with, ReadOptions};
pub use vox::{
    read_vox, read_vox_bytes, read_vox_bytes_with, read_vox_scene_bytes, vox_model_sizes, VoxOptions,
    VoxScene, VOX_MAX_INSTANCES, VOX_MAX_PLACED_VOXELS,
};
pub use vti::{read_vti, read_vti_bytes};
pub use vtp::write_vtp;
pub use write_volume::{write_vol, write_volume, write_volume_blocks, write_vox, VOX_MAX_MODEL};
pub use zarr::{is_zarr, read_zarr, read_zarr_entries};
