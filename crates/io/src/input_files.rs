//! The files an input will read, listed before it is read: what a run must never write.

use std::io::Read;
use std::path::{Path, PathBuf};

use crate::files::lowercase_extension;

/// The most bytes of a NRRD file read to find its `data file` field.
const NRRD_HEADER_BYTES: u64 = 1 << 20;

/// The files and directories reading an input touches (see [`input_files`]).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct InputFiles {
    /// Files read: the input itself, a detached header's data file, the TIFF slices of a
    /// directory or pattern.
    pub files: Vec<PathBuf>,
    /// Directories read as a whole (Zarr stores): every path inside one is the input's.
    pub dirs: Vec<PathBuf>,
}

/// Lists what reading `path` reads, cheaply and without reading the volume: the input
/// itself; for NRRD (`.nhdr`, `.nrrd`, not `raw`) the data file its header names, found
/// with the reader's own header parser in the first MiB; for a directory or pattern of
/// TIFF slices, the directory or pattern and each slice; for a Zarr store, the store
/// directory as a whole (and, for a level `image.ome.zarr/0`, the image around it).
/// `raw`: the input is raw data (no header), read as one file.
///
/// Only regular files are opened (a FIFO is never waited on); whatever cannot be listed
/// (a missing file, a malformed header) is left out, since reading it fails before any
/// output is written.
pub fn input_files(path: &Path, raw: bool) -> InputFiles {
    let mut out = InputFiles { files: vec![path.to_path_buf()], dirs: Vec::new() };
    if raw {
        return out;
    }
    let name = path.file_name().map(|n| n.to_string_lossy()).unwrap_or_default();
    if lowercase_extension(path).as_deref() == Some("zarr") || crate::zarr::is_zarr(path) {
        out.dirs.push(path.to_path_buf());
        if let Some(parent) = path.parent().filter(|p| crate::zarr::is_zarr(p)) {
            out.dirs.push(parent.to_path_buf());
        }
        return out;
    }
    if path.is_dir() || name.contains(['*', '?']) {
        out.files.extend(crate::tiff::tiff_slices(path).unwrap_or_default());
        return out;
    }
    if matches!(lowercase_extension(path).as_deref(), Some("nrrd" | "nhdr")) {
        out.files.extend(nrrd_data_file(path));
    }
    out
}

/// The data file a NRRD header names, relative to the header's directory.
fn nrrd_data_file(path: &Path) -> Option<PathBuf> {
    if !std::fs::metadata(path).ok()?.is_file() {
        return None;
    }
    let mut bytes = Vec::new();
    std::fs::File::open(path).ok()?.take(NRRD_HEADER_BYTES).read_to_end(&mut bytes).ok()?;
    let header = crate::nrrd::Header::parse(&bytes, path).ok()?;
    let file = header.data_file?;
    Some(path.parent().unwrap_or(Path::new("")).join(file))
}

/// A path as the file system resolves it: canonical where it exists; else its
/// directory's canonical path and its name; else as given, made absolute.
fn resolve(path: &Path) -> PathBuf {
    if let Ok(p) = path.canonicalize() {
        return p;
    }
    if let (Some(dir), Some(name)) = (path.parent(), path.file_name()) {
        let dir = if dir.as_os_str().is_empty() { Path::new(".") } else { dir };
        if let Ok(d) = dir.canonicalize() {
            return d.join(name);
        }
    }
    std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf())
}

/// Whether `a` and `b` both exist and are the same file (device and inode on Unix).
fn same_inode(a: &Path, b: &Path) -> bool {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        matches!(
            (std::fs::metadata(a), std::fs::metadata(b)),
            (Ok(x), Ok(y)) if x.dev() == y.dev() && x.ino() == y.ino()
        )
    }
    #[cfg(not(unix))]
    {
        let _ = (a, b);
        false
    }
}

/// Whether paths `a` and `b` resolve to the same file: the same canonical path (the
/// name of a new file in the same directory), or the same existing file (a hard link).
pub fn same_output(a: &Path, b: &Path) -> bool {
    a == b || resolve(a) == resolve(b) || same_inode(a, b)
}

impl InputFiles {
    /// The input file or directory that writing `output` would replace or write into, if
    /// any: `output` resolves to one of [`InputFiles::files`] (the same canonical path,
    /// or the same file by device and inode), or lies inside one of
    /// [`InputFiles::dirs`].
    pub fn clash(&self, output: &Path) -> Option<&Path> {
        let resolved = resolve(output);
        if let Some(f) = self.files.iter().find(|f| resolve(f) == resolved || same_inode(f, output)) {
            return Some(f);
        }
        self.dirs.iter().find(|d| resolved.starts_with(resolve(d))).map(PathBuf::as_path)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_detached_header_lists_its_data_file() {
        let dir = tempfile::tempdir().unwrap();
        let header = dir.path().join("v.nhdr");
        std::fs::write(
            &header,
            "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 2 2\nencoding: raw\ndata file: sub/v.raw\n",
        )
        .unwrap();
        std::fs::create_dir(dir.path().join("sub")).unwrap();
        std::fs::write(dir.path().join("sub/v.raw"), [0u8; 8]).unwrap();
        let files = input_files(&header, false);
        assert_eq!(files.files, [header.clone(), dir.path().join("sub/v.raw")]);
        assert!(files.clash(&dir.path().join("sub/../sub/v.raw")).is_some());
        assert!(files.clash(&dir.path().join("v.nhdr")).is_some());
        assert!(files.clash(&dir.path().join("other.raw")).is_none());
        // As raw data, the header is one file.
        assert_eq!(input_files(&header, true).files, [header]);
    }

    #[test]
    fn slices_and_stores_are_listed() {
        let dir = tempfile::tempdir().unwrap();
        let slices = dir.path().join("slices");
        std::fs::create_dir(&slices).unwrap();
        for name in ["b.tif", "a.tif", "notes.txt"] {
            std::fs::write(slices.join(name), b"").unwrap();
        }
        let files = input_files(&slices, false);
        assert_eq!(files.files, [slices.clone(), slices.join("a.tif"), slices.join("b.tif")]);
        assert!(files.clash(&slices.join("a.tif")).is_some());
        assert!(files.clash(&slices.join("notes.txt")).is_none());

        let store = dir.path().join("s.zarr");
        std::fs::create_dir(&store).unwrap();
        std::fs::write(store.join("zarr.json"), b"{}").unwrap();
        let files = input_files(&store, false);
        assert_eq!(files.dirs, std::slice::from_ref(&store));
        assert!(files.clash(&store.join("zarr.json")).is_some());
        assert!(files.clash(&store.join("c/new")).is_some(), "new paths inside the store too");
        assert!(files.clash(&dir.path().join("s.json")).is_none());
    }

    #[cfg(unix)]
    #[test]
    fn hard_links_and_symbolic_links_resolve_to_the_input() {
        let dir = tempfile::tempdir().unwrap();
        let input = dir.path().join("v.vol");
        std::fs::write(&input, b"x").unwrap();
        std::fs::hard_link(&input, dir.path().join("hard")).unwrap();
        std::os::unix::fs::symlink(&input, dir.path().join("soft")).unwrap();
        let files = input_files(&dir.path().join("soft"), false);
        assert!(files.clash(&input).is_some());
        assert!(files.clash(&dir.path().join("hard")).is_some());
    }
}
