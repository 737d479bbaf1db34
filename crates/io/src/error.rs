//! Errors of this crate.

use std::path::PathBuf;

use voxreg_digisurf::SurfaceError;

/// What can go wrong when reading a volume or writing a mesh.
///
/// Every variant names the file it is about, and its message starts with that path.
#[derive(Debug, thiserror::Error)]
pub enum IoError {
    /// The operating system failed to read, create, write or rename the file.
    #[error("{}: {source}", .path.display())]
    Io {
        /// The file being read or written.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// The file is not a well-formed file of its format (bad magic, malformed header,
    /// truncated or excess data, dimensions that do not match the data).
    #[error("{}: {message}", .path.display())]
    Format {
        /// The file being read.
        path: PathBuf,
        /// What is wrong with it.
        message: String,
    },
    /// The file is well-formed but uses a feature this crate does not read (e.g. a
    /// `.vol` file with several bytes per voxel, or rotated MagicaVoxel models).
    #[error("{}: unsupported: {message}", .path.display())]
    Unsupported {
        /// The file being read.
        path: PathBuf,
        /// The feature that is not supported.
        message: String,
    },
    /// The volume has more voxels than [`MAX_VOXELS`](crate::files::MAX_VOXELS); refused before
    /// anything is allocated for it.
    #[error(
        "{}: volume of {}x{}x{} voxels exceeds the limit of {limit} voxels",
        .path.display(), .dims[0], .dims[1], .dims[2]
    )]
    TooLarge {
        /// The file being read.
        path: PathBuf,
        /// The dimensions the file declares.
        dims: [u64; 3],
        /// The largest number of voxels accepted.
        limit: u64,
    },
    /// What the file declares would need more memory than the budget
    /// ([`max_memory`](crate::limits::max_memory)); refused before anything is allocated for it.
    #[error(
        "{}: {what} needs {}, over the memory limit of {} (raise it with --max-memory)",
        .path.display(), crate::size::format_size(*.bytes), crate::size::format_size(*.limit)
    )]
    OverBudget {
        /// The file being read (or written).
        path: PathBuf,
        /// What needs the memory, e.g. `a volume of 700x700x700 voxels`.
        what: String,
        /// The bytes it needs.
        bytes: u64,
        /// The budget.
        limit: u64,
    },
    /// The file name has no extension, or one this crate does not know.
    #[error("{}: unknown file extension (expected {expected})", .path.display())]
    UnsupportedExtension {
        /// The file name given.
        path: PathBuf,
        /// The extensions that are known, e.g. `.vol or .vox`.
        expected: &'static str,
    },
    /// The mesh given to a writer is inconsistent (an index out of range, a label that
    /// does not fit the format, an invalid group name).
    #[error("{}: invalid mesh: {message}", .path.display())]
    InvalidMesh {
        /// The file that was to be written (it is left untouched).
        path: PathBuf,
        /// What is wrong with the mesh.
        message: String,
    },
    /// The data read does not make a valid [`LabelVolume`](voxreg_digisurf::LabelVolume).
    #[error("{}: {source}", .path.display())]
    Volume {
        /// The file being read.
        path: PathBuf,
        /// The error from building the volume.
        source: SurfaceError,
    },
}

/// The `path` field of an [`IoError`] (every variant has one), borrowed as `$error` is.
macro_rules! path_field {
    ($error:expr) => {
        match $error {
            IoError::Io { path, .. }
            | IoError::Format { path, .. }
            | IoError::Unsupported { path, .. }
            | IoError::TooLarge { path, .. }
            | IoError::OverBudget { path, .. }
            | IoError::UnsupportedExtension { path, .. }
            | IoError::InvalidMesh { path, .. }
            | IoError::Volume { path, .. } => path,
        }
    };
}

impl IoError {
    /// The file the error is about.
    pub fn path(&self) -> &std::path::Path {
        path_field!(self)
    }

    /// The same error, said of the file under `to` where it was about one under `from`
    /// (a staged file, for the file it stands for).
    pub(crate) fn relocated(mut self, from: &std::path::Path, to: &std::path::Path) -> Self {
        let path = path_field!(&mut self);
        if let Ok(rest) = path.strip_prefix(from) {
            *path = to.join(rest);
        }
        self
    }

    pub(crate) fn io(path: &std::path::Path, source: std::io::Error) -> Self {
        IoError::Io { path: path.to_path_buf(), source }
    }

    pub(crate) fn format(path: &std::path::Path, message: impl Into<String>) -> Self {
        IoError::Format { path: path.to_path_buf(), message: message.into() }
    }

    pub(crate) fn unsupported(path: &std::path::Path, message: impl Into<String>) -> Self {
        IoError::Unsupported { path: path.to_path_buf(), message: message.into() }
    }
}
