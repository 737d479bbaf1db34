//! A small deterministic software rasterizer for the papers' figures (`cargo xtask figures`).
//!
//! - [`Image`]: an RGB8 canvas with PNG output ([`Image::to_png`], [`Image::write_png`]),
//!   panels ([`Image::blit`], [`Image::fill_rect`]) and captions ([`Image::draw_text`],
//!   with a bundled ASCII subset of DejaVu Sans, [`FONT_TTF`]).
//! - [`Camera`]: a fixed orthographic camera framing a bounding box from a direction, so
//!   that every method's mesh of one shape is seen from exactly the same place.
//! - [`render`]: polygons (fan-triangulated) through a z-buffer, flat or smooth
//!   ([`Shading`]) Lambert shading with two-sided lighting (back faces tinted, which shows
//!   folds), optional polygon wireframe (polygon edges only, not the fan diagonals, hidden
//!   where occluded), per-face colours, supersampled ([`RenderParams`]).
//! - [`viridis`]: a perceptually uniform colour map for scalar fields on faces.
//!
//! Everything is single-threaded plain `f64` arithmetic: the same input gives the same
//! bytes on every run.
//!
//! # Example
//!
//! ```
//! use glam::DVec3;
//! use voxreg_render::{render, Camera, RenderParams};
//!
//! // A unit square facing the camera covers the middle of the image.
//! let positions = [DVec3::new(0., 0., 0.), DVec3::new(1., 0., 0.), DVec3::new(1., 1., 0.), DVec3::new(0., 1., 0.)];
//! let square: &[u32] = &[0, 1, 2, 3];
//! let camera = Camera::fit(DVec3::ZERO, DVec3::ONE, DVec3::new(0., 0., -1.), DVec3::Y);
//! let params = RenderParams { width: 64, height: 64, ..RenderParams::default() };
//! let image = render(&positions, [square], None, &camera, &params);
//! assert_ne!(image.pixel(32, 32), params.background);
//! assert_eq!(image.pixel(1, 1), params.background);
//! ```
//!
//! # Features
//!
//! None.

mod camera;
mod image;
mod raster;

pub use camera::Camera;
pub use image::{viridis, Image, FONT_TTF};
pub use raster::{render, RenderParams, Shading};
