//! Reading an input file safely, and the checks every reader shares: regular files only,
//! within the memory budget, voxel counts bounded, names printable.

use std::path::Path;

use crate::error::IoError;

/// The largest number of voxels a reader accepts: `2^31`.
///
/// A file declaring more is refused with [`IoError::TooLarge`] before anything is
/// allocated for it. (At the limit, a volume takes 8 GiB of `u32` labels.)
pub const MAX_VOXELS: u64 = 1 << 31;

/// `text` with its control characters (terminal escape sequences, newlines) written as
/// escapes (`\u{1b}`), other characters kept: names and units read from a file are
/// printed, and a file must not drive the terminal.
pub(crate) fn printable(text: &str) -> String {
    text.chars()
        .map(|c| if c.is_control() { c.escape_unicode().to_string() } else { c.to_string() })
        .collect()
}

/// The extension of `path`, lower-cased, if it has one.
pub(crate) fn lowercase_extension(path: &Path) -> Option<String> {
    path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase)
}

/// The number of voxels of `dims`, or [`IoError::TooLarge`] above [`MAX_VOXELS`]
/// (also when the product overflows), or [`IoError::OverBudget`] when reading them takes
/// more than the memory budget at `bytes_per_voxel` (the reader's peak: the file's
/// samples, decompressed, plus the volume made of them).
pub(crate) fn checked_voxel_count(
    path: &Path,
    dims: [u64; 3],
    bytes_per_voxel: u64,
) -> Result<usize, IoError> {
    // Checked: three declared dimensions of up to 2^64 can overflow even a u128 (and a
    // product that wrapped to a small count would pass the limits).
    let count = dims.iter().try_fold(1u128, |a, &d| a.checked_mul(u128::from(d)));
    let Some(count) = count.filter(|&c| c <= u128::from(MAX_VOXELS)) else {
        return Err(IoError::TooLarge { path: path.to_path_buf(), dims, limit: MAX_VOXELS });
    };
    let what = format!("a volume of {}x{}x{} voxels", dims[0], dims[1], dims[2]);
    crate::limits::check_memory(path, &what, count * u128::from(bytes_per_voxel))?;
    usize::try_from(count).map_err(|_| IoError::TooLarge {
        path: path.to_path_buf(),
        dims,
        limit: MAX_VOXELS,
    })
}

/// Reads a whole input file into memory, as every reader does, if it is a regular file (a link is followed)
/// whose size is within the memory budget: a FIFO (which would block), a device
/// (`/dev/zero` never ends) or a socket is refused before it is opened, and a file too
/// large for the budget before it is read. At most the size the file had when it was
/// examined is read (files of `/proc` read as empty).
pub fn read_input_file(path: &Path) -> Result<Vec<u8>, IoError> {
    use std::io::Read as _;
    let len = regular_file_len(path)?;
    crate::limits::check_memory(path, "the file", u128::from(len))?;
    let file = std::fs::File::open(path).map_err(|e| IoError::io(path, e))?;
    let mut bytes = Vec::with_capacity(usize::try_from(len).unwrap_or(0));
    file.take(len).read_to_end(&mut bytes).map_err(|e| IoError::io(path, e))?;
    Ok(bytes)
}

pub(crate) use read_input_file as read_file;

/// The size of `path` when it is a regular file (after links), else the error saying
/// what it is.
pub(crate) fn regular_file_len(path: &Path) -> Result<u64, IoError> {
    let meta = std::fs::metadata(path).map_err(|e| IoError::io(path, e))?;
    let t = meta.file_type();
    if t.is_file() {
        return Ok(meta.len());
    }
    let mut what = if t.is_dir() { "a directory" } else { "a special file" };
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt as _;
        if t.is_fifo() {
            what = "a FIFO";
        } else if t.is_char_device() || t.is_block_device() {
            what = "a device";
        } else if t.is_socket() {
            what = "a socket";
        }
    }
    Err(IoError::format(path, format!("{what}, not a regular file: inputs are read from regular files")))
}

/// What the file of `meta` (from [`std::fs::symlink_metadata`]) is, for error messages:
/// "a device", "a FIFO", "a socket", "a symbolic link", "a directory", "a regular file"
/// or "a special file".
pub fn file_kind(meta: &std::fs::Metadata) -> &'static str {
    let t = meta.file_type();
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if t.is_char_device() || t.is_block_device() {
            return "a device";
        }
        if t.is_fifo() {
            return "a FIFO";
        }
        if t.is_socket() {
            return "a socket";
        }
    }
    if t.is_symlink() {
        "a symbolic link"
    } else if t.is_dir() {
        "a directory"
    } else if t.is_file() {
        "a regular file"
    } else {
        "a special file"
    }
}
