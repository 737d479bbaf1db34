//! Errors of this crate.

/// What can go wrong when building a digital surface.
#[derive(Debug, thiserror::Error, Clone, PartialEq, Eq)]
pub enum SurfaceError {
    /// The volume is malformed (dimensions, spacing, origin).
    #[error("invalid volume: {0}")]
    InvalidVolume(String),
    /// The region map is malformed or does not cover a label.
    #[error("invalid regions: {0}")]
    InvalidRegions(String),
    /// No surfel separates two regions: there is no surface to extract.
    #[error("the digital surface is empty: no two face-adjacent voxels belong to different regions")]
    Empty,
    /// The surface does not fit the 32-bit ids of the complex.
    #[error("volume too large: {0}")]
    TooLarge(String),
    /// The surface has more surfels than the cap of [`crate::DigitalSurface::new_within`]
    /// (the cap, which the count passed).
    #[error("more than {0} surfels")]
    TooManySurfels(u64),
}
