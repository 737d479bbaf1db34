//! What a reader returns: the voxels (or labels) with what the file says about them.

use voxreg_digisurf::LabelVolume;

use crate::grey::Voxels;
use crate::material::Palette;

/// A volume read from a file, with what the file says about its labels.
#[derive(Clone, Debug, PartialEq)]
pub struct LoadedVolume {
    /// The labeled voxels, spacing and origin.
    pub volume: LabelVolume,
    /// Colours and materials indexed by label, for formats that have a palette
    /// (MagicaVoxel `.vox`: 256 entries, entry 0, the background, transparent); `None`
    /// for formats without (`.vol`).
    pub palette: Option<Palette>,
    /// The unit of the spacing and origin, where the file names one (`mm`, `µm`, `nm`,
    /// `Å`...).
    pub units: Option<String>,
}

/// The voxels read from a file (labels or grey levels), with its palette if any.
#[derive(Clone, Debug, PartialEq)]
pub struct LoadedVoxels {
    /// The voxels, spacing and origin.
    pub voxels: Voxels,
    /// As [`LoadedVolume::palette`].
    pub palette: Option<Palette>,
    /// As [`LoadedVolume::units`].
    pub units: Option<String>,
}
