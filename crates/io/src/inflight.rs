//! Temporary files and staging directories in flight, so that an interrupted process can
//! remove them and a later one can remove what a killed one left.
//!
//! Every temporary name this crate creates starts with [`temp_prefix`],
//! `.voxreg-<pid>-`, and is created in a directory recorded here. A program that handles
//! SIGINT or SIGTERM calls [`remove_in_flight`] from its handler: it removes every entry of
//! this process in those directories (and the directories a `--split` batch created), and
//! returns a guard under which no new temporary file can be created and no batch can
//! commit, so the program can exit with nothing half-written left behind and no
//! all-or-nothing commit cut in two.
//!
//! A process killed outright (SIGKILL, a power cut) cannot clean up; the next process that
//! writes into the same directory removes entries whose process id is no longer running
//! (where the system can tell: `/proc` on Linux).

use std::path::{Path, PathBuf};
use std::sync::{Mutex, MutexGuard, PoisonError};

#[derive(Default)]
pub(crate) struct InFlight {
    /// Directories this process created temporary entries in.
    dirs: Vec<PathBuf>,
    /// Directories created for a batch that has not committed (removed whole).
    created: Vec<PathBuf>,
}

static IN_FLIGHT: Mutex<InFlight> = Mutex::new(InFlight { dirs: Vec::new(), created: Vec::new() });

/// Held while creating a temporary entry or committing a batch; [`remove_in_flight`] takes
/// it and never gives it back to a process about to exit.
pub(crate) fn lock() -> MutexGuard<'static, InFlight> {
    IN_FLIGHT.lock().unwrap_or_else(PoisonError::into_inner)
}

/// The guard [`remove_in_flight`] returns: while it lives, no temporary entry is created
/// and no batch commits.
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
/// `.voxreg-<pid>-`.
pub fn temp_prefix() -> String {
    format!(".voxreg-{}-", std::process::id())
}

/// Records `dir` as holding temporary entries of this process; the first time, also
/// removes the leftovers of dead processes there.
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
/// temporary entry is created and no batch commits (they wait). Meant for a signal
/// handler that exits the process right after.
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

/// Removes `.voxreg-<pid>-*` entries in `dir` whose process is no longer running.
fn remove_stale(dir: &Path) {
    remove_entries(dir, |name| owner(name).is_some_and(|pid| !is_running(pid)));
}

fn remove_entries(dir: &Path, doomed: impl Fn(&str) -> bool) {
    let Ok(entries) = std::fs::read_dir(dir) else { return };
    for entry in entries.flatten() {
        let name = entry.file_name();
        if !name.to_str().is_some_and(&doomed) {
            continue;
        }
        let path = entry.path();
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

/// The process id in a `.voxreg-<pid>-...` name.
fn owner(name: &str) -> Option<u32> {
    let rest = name.strip_prefix(".voxreg-")?;
    let (pid, _) = rest.split_once('-')?;
    pid.parse().ok()
}

/// Whether process `pid` runs; `true` where the system cannot tell (nothing is removed).
fn is_running(pid: u32) -> bool {
    if pid == std::process::id() {
        return true;
    }
    let proc = Path::new("/proc");
    if !proc.join("self").exists() {
        return true;
    }
    proc.join(pid.to_string()).exists()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn owners_are_read_from_names() {
        assert_eq!(owner(".voxreg-123-abc.tmp"), Some(123));
        assert_eq!(owner(".voxreg-abc.tmp"), None);
        assert_eq!(owner(".voxreg-12x-abc"), None);
        assert_eq!(owner("voxreg-123-abc"), None);
    }

    #[test]
    fn leftovers_of_dead_processes_are_removed_and_live_ones_kept() {
        let dir = tempfile::tempdir().unwrap();
        // Linux pids stay below 2^22, so 999999999 never runs.
        let dead_file = dir.path().join(".voxreg-999999999-x1.tmp");
        let dead_dir = dir.path().join(".voxreg-999999999-x2");
        let mine = dir.path().join(format!("{}keep.tmp", temp_prefix()));
        let foreign = dir.path().join(".voxreg-legacy.tmp");
        std::fs::write(&dead_file, b"partial").unwrap();
        std::fs::create_dir(&dead_dir).unwrap();
        std::fs::write(dead_dir.join("a.ply"), b"partial").unwrap();
        std::fs::write(&mine, b"in flight").unwrap();
        std::fs::write(&foreign, b"unknown owner").unwrap();
        remove_stale(dir.path());
        if Path::new("/proc/self").exists() {
            assert!(!dead_file.exists() && !dead_dir.exists());
        }
        assert!(mine.exists(), "this process's own entry is in flight");
        assert!(foreign.exists(), "an entry with no process id is never touched");
    }
}
