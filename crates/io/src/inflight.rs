//! Temporary files and staging directories in flight: owned through a lock, so that an
//! interrupted process can remove its own and a later one can remove what a killed one
//! left, and never what a live one is writing.
//!
//! Every temporary name this crate creates starts with [`temp_prefix`],
//! `.voxreg-<pid>.<token>-`, where the token is random per process, so two processes
//! never share a prefix even where they share a process id (another pid namespace,
//! another host on a shared file system). Each entry is locked (`flock`, exclusive) by
//! the process writing it for as long as it exists: a temporary file on its own open
//! descriptor, a staging directory on the `.voxreg-lock` file inside it. The kernel
//! releases the lock when the process dies, however it dies.
//!
//! A program that handles SIGINT or SIGTERM calls [`remove_in_flight`] from its
//! handler: it removes every entry of this process in the directories it wrote to (and
//! the directories a `--split` batch created), and returns a guard under which no new
//! temporary file can be created and no commit can run, so the program can exit with
//! nothing half-written left behind and no all-or-nothing commit cut in two.
//!
//! A process killed outright (SIGKILL, a power cut) cannot clean up; the first time a
//! later process writes into the same directory, it removes the entries of this naming
//! scheme whose lock it can take (their owner is gone). An entry it cannot lock, one
//! without a lock file, or one named otherwise (older versions named theirs
//! `.voxreg-<pid>-*`) is never touched: nothing is removed by guessing from a process id.

use std::fs::File;
use std::io;
use std::path::{Path, PathBuf};
use std::sync::{Mutex, MutexGuard, OnceLock, PoisonError};

/// The name of the lock file inside each staging directory.
pub(crate) const LOCK_FILE: &str = ".voxreg-lock";

#[derive(Default)]
pub(crate) struct InFlight {
    /// Directories this process created temporary entries in.
    dirs: Vec<PathBuf>,
    /// Directories created for a batch that has not committed (removed whole).
    created: Vec<PathBuf>,
}

static IN_FLIGHT: Mutex<InFlight> = Mutex::new(InFlight { dirs: Vec::new(), created: Vec::new() });

/// Held while creating a temporary entry or committing; [`remove_in_flight`] takes it and
/// never gives it back to a process about to exit.
pub(crate) fn lock() -> MutexGuard<'static, InFlight> {
    IN_FLIGHT.lock().unwrap_or_else(PoisonError::into_inner)
}

/// The guard [`remove_in_flight`] returns: while it lives, no temporary entry is created
/// and no commit runs.
#[must_use = "dropping it lets writes resume"]
pub struct Held {
    _guard: MutexGuard<'static, InFlight>,
}

impl std::fmt::Debug for Held {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Held")
    }
}

/// The prefix of this process's temporary files and staging directories:
/// `.voxreg-<pid>.<token>-`, the token 16 hex digits drawn once per process.
pub fn temp_prefix() -> String {
    static TOKEN: OnceLock<u64> = OnceLock::new();
    let token = TOKEN.get_or_init(|| {
        use std::hash::{BuildHasher, Hasher};
        let mut h = std::collections::hash_map::RandomState::new().build_hasher();
        h.write_u32(std::process::id());
        if let Ok(t) = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH) {
            h.write_u128(t.as_nanos());
        }
        h.finish()
    });
    format!(".voxreg-{}.{token:016x}-", std::process::id())
}

/// Whether `name` is a temporary entry of this naming scheme (any process's).
fn is_temporary(name: &str) -> bool {
    let Some(rest) = name.strip_prefix(".voxreg-") else { return false };
    let Some((pid, rest)) = rest.split_once('.') else { return false };
    let Some((token, _)) = rest.split_once('-') else { return false };
    !pid.is_empty()
        && pid.bytes().all(|b| b.is_ascii_digit())
        && token.len() == 16
        && token.bytes().all(|b| b.is_ascii_hexdigit())
}

/// Records `dir` as holding temporary entries of this process; the first time, also
/// removes the entries there whose owner is gone.
pub(crate) fn note_dir(state: &mut InFlight, dir: &Path) {
    if state.dirs.iter().any(|d| d == dir) {
        return;
    }
    remove_stale(dir);
    state.dirs.push(dir.to_path_buf());
}

/// Records (`true`) or forgets (`false`) a directory created for a batch.
pub(crate) fn note_created(state: &mut InFlight, dir: &Path, created: bool) {
    state.created.retain(|d| d != dir);
    if created {
        state.created.push(dir.to_path_buf());
    }
}

/// Removes every temporary file and staging directory of this process, and every
/// directory an uncommitted batch created, then returns a guard: while it lives, no
/// temporary entry is created and no commit runs (they wait). Meant for a signal handler
/// that exits the process right after.
pub fn remove_in_flight() -> Held {
    let guard = lock();
    let prefix = temp_prefix();
    for dir in &guard.dirs {
        remove_entries(dir, |name| name.starts_with(&prefix));
    }
    for dir in &guard.created {
        let _ = std::fs::remove_dir_all(dir);
    }
    Held { _guard: guard }
}

/// Removes the temporary entries in `dir` of other processes whose lock can be taken.
fn remove_stale(dir: &Path) {
    let prefix = temp_prefix();
    let Ok(entries) = std::fs::read_dir(dir) else { return };
    for entry in entries.flatten() {
        let name = entry.file_name();
        let Some(name) = name.to_str().filter(|n| is_temporary(n) && !n.starts_with(&prefix)) else {
            continue;
        };
        let path = dir.join(name);
        let Ok(kind) = entry.file_type() else { continue };
        let lock = if kind.is_dir() { path.join(LOCK_FILE) } else { path.clone() };
        // Held while the entry is removed: its owner is gone, and no other run takes it.
        let Some(_held) = unowned(&lock) else { continue };
        let _ = if kind.is_dir() { std::fs::remove_dir_all(&path) } else { std::fs::remove_file(&path) };
    }
}

/// Opens `path` and takes its lock, if no one holds it: the open file, whose drop releases
/// the lock; `None` if it is locked, missing, not a regular file, or cannot be locked here.
fn unowned(path: &Path) -> Option<File> {
    let meta = std::fs::symlink_metadata(path).ok()?;
    if !meta.is_file() {
        return None;
    }
    let file = File::options().read(true).write(true).open(path).or_else(|_| File::open(path)).ok()?;
    try_lock(&file).ok().map(|()| file)
}

fn remove_entries(dir: &Path, doomed: impl Fn(&str) -> bool) {
    let Ok(entries) = std::fs::read_dir(dir) else { return };
    for entry in entries.flatten() {
        let name = entry.file_name();
        let path = entry.path();
        if !name.to_str().is_some_and(&doomed) {
            continue;
        }
        match entry.file_type() {
            Ok(t) if t.is_dir() => {
                let _ = std::fs::remove_dir_all(&path);
            }
            Ok(_) => {
                let _ = std::fs::remove_file(&path);
            }
            Err(_) => {}
        }
    }
}

/// Takes the exclusive lock of `file` without waiting.
#[cfg(unix)]
fn try_lock(file: &File) -> io::Result<()> {
    rustix::fs::flock(file, rustix::fs::FlockOperation::NonBlockingLockExclusive).map_err(io::Error::from)
}

/// Without `flock`, no lock is ever taken: nothing of another process is removed.
#[cfg(not(unix))]
fn try_lock(_file: &File) -> io::Result<()> {
    Err(io::Error::new(io::ErrorKind::Unsupported, "no file locks here"))
}

/// Creates `path` (which must not exist) and locks it as this module's entries are
/// locked, for as long as the returned file (read and write, mode 0o666 less the umask)
/// stays open: while it does, no run's clean-up removes it. Fails with `AlreadyExists`
/// (so that the caller picks another name) where another process locked or removed it
/// in between.
pub fn create_locked(path: &Path) -> io::Result<File> {
    let mut options = File::options();
    options.read(true).write(true).create_new(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        options.mode(0o666);
    }
    let file = options.open(path)?;
    let owned = match try_lock(&file) {
        Ok(()) => still_there(&file, path),
        // Where locks are not supported the entry is simply not protected.
        Err(e) if e.kind() == io::ErrorKind::Unsupported => true,
        Err(_) => false,
    };
    if !owned {
        // Another run's clean-up took it between the creation and the lock.
        return Err(io::Error::new(io::ErrorKind::AlreadyExists, "taken by another run's clean-up"));
    }
    Ok(file)
}

/// Whether `path` still names the open `file`.
fn still_there(file: &File, path: &Path) -> bool {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        match (file.metadata(), std::fs::symlink_metadata(path)) {
            (Ok(a), Ok(b)) => a.dev() == b.dev() && a.ino() == b.ino(),
            _ => false,
        }
    }
    #[cfg(not(unix))]
    {
        let _ = file;
        path.exists()
    }
}

/// A temporary file of this process in `dir`, named `<prefix>XXXXXX<suffix>`, locked.
pub(crate) fn temp_file(dir: &Path, suffix: &str) -> io::Result<tempfile::NamedTempFile> {
    let prefix = temp_prefix();
    let mut in_flight = lock();
    note_dir(&mut in_flight, dir);
    tempfile::Builder::new().prefix(&prefix).suffix(suffix).make_in(dir, create_locked)
}

/// A staging directory of this process in `dir`, locked through its lock file; removed
/// (with what it holds) when dropped.
pub(crate) struct StagingDir {
    dir: tempfile::TempDir,
    _lock: File,
}

impl std::fmt::Debug for StagingDir {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_tuple("StagingDir").field(&self.dir.path()).finish()
    }
}

impl StagingDir {
    /// Creates one in `dir` (recorded with the in-flight registry held by the caller).
    pub(crate) fn new_in(state: &mut InFlight, dir: &Path) -> io::Result<StagingDir> {
        note_dir(state, dir);
        let prefix = temp_prefix();
        for _ in 0..16 {
            let staging = tempfile::Builder::new().prefix(&prefix).tempdir_in(dir)?;
            match create_locked(&staging.path().join(LOCK_FILE)) {
                Ok(lock) => return Ok(StagingDir { dir: staging, _lock: lock }),
                Err(e) if e.kind() == io::ErrorKind::AlreadyExists => continue,
                Err(e) => return Err(e),
            }
        }
        Err(io::Error::new(io::ErrorKind::AlreadyExists, "cannot create a staging directory"))
    }

    /// Its path.
    pub(crate) fn path(&self) -> &Path {
        self.dir.path()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn temporary_names_are_recognized() {
        assert!(is_temporary(&format!("{}abc.tmp", temp_prefix())));
        assert!(is_temporary(".voxreg-123.0123456789abcdef-x"));
        assert!(!is_temporary(".voxreg-123-abc.tmp"), "an older version's name");
        assert!(!is_temporary(".voxreg-12x.0123456789abcdef-x"));
        assert!(!is_temporary(".voxreg-12.0123-x"));
        assert!(!is_temporary("voxreg-123.0123456789abcdef-x"));
    }

    #[cfg(unix)]
    #[test]
    fn only_unlocked_entries_of_other_processes_are_removed() {
        let dir = tempfile::tempdir().unwrap();
        let other = ".voxreg-7.00000000000000aa-";
        // Unlocked: their owner is gone.
        let dead_file = dir.path().join(format!("{other}x1.tmp"));
        let dead_dir = dir.path().join(format!("{other}x2"));
        std::fs::write(&dead_file, b"partial").unwrap();
        std::fs::create_dir(&dead_dir).unwrap();
        std::fs::write(dead_dir.join(LOCK_FILE), b"").unwrap();
        std::fs::write(dead_dir.join("a.ply"), b"partial").unwrap();
        // Locked by a live owner (another open file description: as another process's).
        let live_file = dir.path().join(format!("{other}y1.tmp"));
        let live_dir = dir.path().join(format!("{other}y2"));
        let _held_file = create_locked(&live_file).unwrap();
        std::fs::create_dir(&live_dir).unwrap();
        let _held_dir = create_locked(&live_dir.join(LOCK_FILE)).unwrap();
        // A directory without a lock file, an older version's entry, this process's own.
        let unlocked_dir = dir.path().join(format!("{other}z"));
        std::fs::create_dir(&unlocked_dir).unwrap();
        let legacy = dir.path().join(".voxreg-999999999-x.tmp");
        std::fs::write(&legacy, b"unknown owner").unwrap();
        let mine = dir.path().join(format!("{}keep.tmp", temp_prefix()));
        std::fs::write(&mine, b"in flight").unwrap();
        remove_stale(dir.path());
        assert!(!dead_file.exists() && !dead_dir.exists(), "unlocked entries are removed");
        assert!(live_file.exists() && live_dir.join("").exists(), "locked entries are kept");
        assert!(unlocked_dir.exists() && legacy.exists() && mine.exists());
    }

    #[cfg(unix)]
    #[test]
    fn a_temporary_file_is_locked_while_it_lives() {
        let dir = tempfile::tempdir().unwrap();
        let tmp = temp_file(dir.path(), ".tmp").unwrap();
        assert!(unowned(tmp.path()).is_none(), "locked by its writer");
        let path = tmp.path().to_path_buf();
        let file = tmp.into_temp_path();
        // The descriptor is closed: the lock is gone with it.
        assert!(unowned(&path).is_some());
        drop(file);
    }
}
