//! A run's outputs written to staging directories, then committed together or not at all.

use std::io;
use std::path::{Path, PathBuf};

use crate::error::IoError;
use crate::files::file_kind;
use crate::inflight::{StagingDir, LOCK_FILE};
use crate::mesh::QuadMesh;
use crate::mesh_writer::write_mesh;

/// Where files replaced by a commit are moved aside, inside each staging directory.
const REPLACED: &str = ".voxreg-replaced";

/// A staging directory and the directory its files are committed to.
#[derive(Debug)]
pub(crate) struct Stage {
    /// Where the files go.
    pub(crate) target: PathBuf,
    pub(crate) staging: StagingDir,
}

impl Stage {
    /// A new staging directory in `target` (an existing directory).
    pub(crate) fn new(target: &Path) -> Result<Stage, IoError> {
        let mut in_flight = crate::inflight::lock();
        let staging = StagingDir::new_in(&mut in_flight, target).map_err(|e| IoError::io(target, e))?;
        Ok(Stage { target: target.to_path_buf(), staging })
    }

    /// The files staged so far, by name (not the lock file, not the files moved aside).
    fn staged(&self) -> Result<Vec<std::ffi::OsString>, IoError> {
        let mut names: Vec<_> = std::fs::read_dir(self.staging.path())
            .and_then(|entries| entries.map(|e| e.map(|e| e.file_name())).collect::<io::Result<Vec<_>>>())
            .map_err(|e| IoError::io(&self.target, e))?
            .into_iter()
            .filter(|n| n != LOCK_FILE && n != REPLACED)
            .collect();
        names.sort();
        Ok(names)
    }

    /// `e` about a staged file, said of the file it stands for.
    pub(crate) fn relocate(&self, e: IoError) -> IoError {
        e.relocated(self.staging.path(), &self.target)
    }
}

/// Moves every staged file of `stages` onto its target, replacing files of the same
/// names; all or nothing. Returns the paths written. The caller holds the in-flight
/// registry, so that an interruption cannot cut the commit in two.
///
/// Refused before anything moves: two stages naming the same target, a target that
/// exists and is not a regular file (a directory, a symbolic link, a device, a FIFO, a
/// socket). Files being replaced are first moved aside into their staging directory;
/// if a rename fails, every file already moved in is taken out again and the replaced
/// ones are put back.
pub(crate) fn commit_stages(stages: &[&Stage]) -> Result<Vec<PathBuf>, IoError> {
    let mut moves: Vec<(PathBuf, PathBuf, PathBuf)> = Vec::new();
    for stage in stages {
        for name in stage.staged()? {
            let target = stage.target.join(&name);
            let aside = stage.staging.path().join(REPLACED).join(&name);
            moves.push((stage.staging.path().join(&name), target, aside));
        }
    }
    for (k, (_, target, _)) in moves.iter().enumerate() {
        if moves[..k].iter().any(|(_, t, _)| t == target) {
            return Err(IoError::io(target, io::Error::other("two outputs of the run name this file")));
        }
        if let Ok(meta) = std::fs::symlink_metadata(target) {
            if !meta.is_file() {
                let what = file_kind(&meta);
                return Err(IoError::io(
                    target,
                    io::Error::other(format!("{what} is in the way of the file")),
                ));
            }
        }
    }
    let mut moved_aside = Vec::new();
    let mut moved_in = Vec::new();
    let mut failure = None;
    for (file, target, aside) in &moves {
        if target.exists() {
            let moved = aside
                .parent()
                .map_or(Ok(()), |d| if d.is_dir() { Ok(()) } else { std::fs::create_dir(d) })
                .and_then(|()| std::fs::rename(target, aside));
            if let Err(e) = moved {
                failure = Some(IoError::io(target, e));
                break;
            }
            moved_aside.push((aside, target));
        }
        if let Err(e) = std::fs::rename(file, target) {
            failure = Some(IoError::io(target, e));
            break;
        }
        moved_in.push(target);
    }
    if let Some(e) = failure {
        for target in moved_in {
            let _ = std::fs::remove_file(target);
        }
        for (aside, target) in moved_aside {
            let _ = std::fs::rename(aside, target);
        }
        return Err(e);
    }
    Ok(moves.into_iter().map(|(_, target, _)| target).collect())
}

/// Writes several meshes into one directory, all or nothing.
///
/// [`MeshBatch::write`] writes each mesh (any format of [`write_mesh`]) into a hidden
/// staging directory inside the target directory, locked by this process (see
/// [`inflight`](crate::inflight)); [`MeshBatch::commit`] then renames every file into
/// place. Dropping the batch before `commit` (after an error, say) removes the staging
/// directory and everything in it, and the directories the batch created, so a failed
/// run leaves no partial output. Renames within one directory are atomic per file;
/// should one of them fail (a full disk cannot cause it), `commit` takes back what it
/// moved and reports which file. A batch can also be committed with a run's other files
/// ([`Outputs::add_batch`]).
#[derive(Debug)]
pub struct MeshBatch {
    dir: std::path::PathBuf,
    /// `None` once dropped.
    stage: Option<Stage>,
    names: Vec<String>,
    /// The outermost directory this batch created, removed again (with what it holds)
    /// unless the batch is committed.
    created: Option<std::path::PathBuf>,
}

impl Drop for MeshBatch {
    fn drop(&mut self) {
        drop(self.stage.take());
        if let Some(created) = self.created.take() {
            let mut in_flight = crate::inflight::lock();
            let _ = std::fs::remove_dir_all(&created);
            crate::inflight::note_created(&mut in_flight, &created, false);
        }
    }
}

impl MeshBatch {
    /// Starts a batch writing into `dir`, created (with its parents) if missing; if the
    /// batch is not committed, what it created is removed again.
    pub fn new(dir: &Path) -> Result<MeshBatch, IoError> {
        let created = dir
            .ancestors()
            .take_while(|a| !a.as_os_str().is_empty() && !a.exists())
            .last()
            .map(Path::to_path_buf);
        let mut in_flight = crate::inflight::lock();
        std::fs::create_dir_all(dir).map_err(|e| IoError::io(dir, e))?;
        if let Some(c) = &created {
            crate::inflight::note_created(&mut in_flight, c, true);
        }
        let staging = crate::inflight::StagingDir::new_in(&mut in_flight, dir).map_err(|e| {
            if let Some(c) = &created {
                let _ = std::fs::remove_dir_all(c);
                crate::inflight::note_created(&mut in_flight, c, false);
            }
            IoError::io(dir, e)
        })?;
        let stage = Stage { target: dir.to_path_buf(), staging };
        Ok(MeshBatch { dir: dir.to_path_buf(), stage: Some(stage), names: Vec::new(), created })
    }

    pub(crate) fn stage(&self) -> Option<&Stage> {
        self.stage.as_ref()
    }

    /// The names of the meshes written so far, in order.
    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// Writes `mesh` as `name` (a plain file name with a mesh extension) in the staging
    /// directory; errors name the final path.
    pub fn write(&mut self, name: &str, mesh: &QuadMesh) -> Result<(), IoError> {
        let target = self.dir.join(name);
        let plain = Path::new(name).file_name().map(|n| n.to_string_lossy()) == Some(name.into());
        let Some(stage) = self.stage.as_ref().filter(|_| plain && name != crate::inflight::LOCK_FILE) else {
            return Err(IoError::InvalidMesh {
                path: target,
                message: format!("'{name}' is not a plain file name"),
            });
        };
        write_mesh(&stage.staging.path().join(name), mesh).map_err(|e| stage.relocate(e))?;
        self.names.push(name.to_string());
        Ok(())
    }

    /// Once committed: the directories the batch created stay.
    pub(crate) fn committed(&mut self, in_flight: &mut crate::inflight::InFlight) {
        if let Some(created) = self.created.take() {
            crate::inflight::note_created(in_flight, &created, false);
        }
    }

    /// Moves every file written so far (and companions such as `.mtl` libraries) into
    /// the target directory, replacing files of the same names, and removes the
    /// staging directory. Returns the paths written.
    ///
    /// All or nothing: a target that exists and is not a regular file (a directory, a
    /// symbolic link, a device...) is refused before anything moves; files being replaced
    /// are first moved aside into the staging directory, and if a rename fails, every
    /// file already moved in is taken out again and the replaced ones are put back.
    pub fn commit(mut self) -> Result<Vec<std::path::PathBuf>, IoError> {
        // Not cut in two by an interruption (see `remove_in_flight`).
        let mut in_flight = crate::inflight::lock();
        let stages: Vec<&Stage> = self.stage.iter().collect();
        let written = commit_stages(&stages)?;
        self.committed(&mut in_flight);
        Ok(written)
    }
}

/// The outputs of one run, committed together or not at all.
///
/// [`Outputs::write`] has a writer write each file under its own name in a hidden
/// staging directory (`.voxreg-<pid>.<token>-*`, see [`inflight`](crate::inflight)) inside
/// the directory of its target, companions included (the `.mtl` beside an OBJ);
/// [`Outputs::add_batch`] adds a [`MeshBatch`]; [`Outputs::commit`] then renames every
/// staged file onto its target as one all-or-nothing step. Dropping the outputs before
/// the commit (after an error, say) removes every staging directory, and the directories
/// the batches created, so a failed run changes no file.
#[derive(Debug, Default)]
pub struct Outputs {
    stages: Vec<Stage>,
    batches: Vec<MeshBatch>,
}

impl Outputs {
    /// No outputs yet.
    pub fn new() -> Outputs {
        Outputs::default()
    }

    /// Has `write` write the file `target` at the path it returns: the same file name in
    /// a staging directory beside `target` (whose directory must exist). Errors about the
    /// staged file name `target` instead. Fails if the run already staged a file of that
    /// name there.
    pub fn write<T>(
        &mut self,
        target: &Path,
        write: impl FnOnce(&Path) -> Result<T, IoError>,
    ) -> Result<T, IoError> {
        let Some(name) = target.file_name().filter(|n| *n != LOCK_FILE && *n != REPLACED) else {
            return Err(IoError::io(target, io::Error::other("not a file name voxreg can write")));
        };
        let dir = match target.parent() {
            Some(dir) if !dir.as_os_str().is_empty() => dir,
            _ => Path::new("."),
        };
        let k = match self.stages.iter().position(|s| s.target == dir) {
            Some(k) => k,
            None => {
                self.stages.push(Stage::new(dir)?);
                self.stages.len() - 1
            }
        };
        let stage = &self.stages[k];
        let staged = stage.staging.path().join(name);
        if staged.exists() {
            return Err(IoError::io(target, io::Error::other("two outputs of the run name this file")));
        }
        write(&staged).map_err(|e| stage.relocate(e))
    }

    /// Adds a batch of meshes, committed with the rest.
    pub fn add_batch(&mut self, batch: MeshBatch) {
        self.batches.push(batch);
    }

    /// Renames every staged file onto its target, all or nothing (see
    /// [`MeshBatch::commit`]), and keeps the directories the batches created. Returns the
    /// paths written. On failure nothing is replaced, and everything staged is removed.
    pub fn commit(mut self) -> Result<Vec<PathBuf>, IoError> {
        let mut in_flight = crate::inflight::lock();
        let mut stages: Vec<&Stage> = self.stages.iter().collect();
        stages.extend(self.batches.iter().filter_map(MeshBatch::stage));
        let written = commit_stages(&stages)?;
        for batch in &mut self.batches {
            batch.committed(&mut in_flight);
        }
        Ok(written)
    }
}

#[cfg(test)]
mod tests {
    use voxreg_testkit::dir_names;

    use super::*;

    fn text(outputs: &mut Outputs, target: &Path, text: &str) -> Result<(), IoError> {
        outputs.write(target, |p| crate::mesh::write_file_atomically(p, |w| w.write_all(text.as_bytes())))
    }

    #[test]
    fn files_in_several_directories_are_committed_together() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::create_dir(dir.path().join("sub")).unwrap();
        let (a, b) = (dir.path().join("a.json"), dir.path().join("sub/b.json"));
        std::fs::write(&a, b"old").unwrap();
        let mut outputs = Outputs::new();
        text(&mut outputs, &a, "new a").unwrap();
        text(&mut outputs, &b, "new b").unwrap();
        assert_eq!(std::fs::read(&a).unwrap(), b"old", "nothing replaced before the commit");
        assert!(!b.exists());
        let written = outputs.commit().unwrap();
        assert_eq!(written.len(), 2);
        assert_eq!(std::fs::read(&a).unwrap(), b"new a");
        assert_eq!(std::fs::read(&b).unwrap(), b"new b");
        assert_eq!(dir_names(dir.path()), ["a.json", "sub"], "staging directories left");
        assert_eq!(dir_names(&dir.path().join("sub")), ["b.json"]);
    }

    #[test]
    fn a_failed_write_or_a_target_in_the_way_changes_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let (a, b) = (dir.path().join("a.json"), dir.path().join("b.json"));
        std::fs::write(&a, b"old").unwrap();
        // A write that fails: the outputs are dropped, the staged file with them.
        let mut outputs = Outputs::new();
        text(&mut outputs, &a, "new a").unwrap();
        let e = outputs
            .write(&b, |p| crate::mesh::write_file_atomically(p, |_| Err(std::io::Error::other("disk full"))))
            .unwrap_err();
        assert_eq!(e.path(), b, "the error names the target, not the staged file");
        drop(outputs);
        assert_eq!(std::fs::read(&a).unwrap(), b"old");
        assert_eq!(dir_names(dir.path()), ["a.json"]);
        // A directory in the way of the second file: refused before the first moves.
        std::fs::create_dir(&b).unwrap();
        let mut outputs = Outputs::new();
        text(&mut outputs, &a, "new a").unwrap();
        text(&mut outputs, &b, "new b").unwrap();
        let e = outputs.commit().unwrap_err();
        assert!(e.to_string().contains("a directory is in the way"), "{e}");
        assert_eq!(std::fs::read(&a).unwrap(), b"old");
        assert_eq!(dir_names(dir.path()), ["a.json", "b.json"]);
        // The same file twice.
        let mut outputs = Outputs::new();
        text(&mut outputs, &a, "one").unwrap();
        assert!(text(&mut outputs, &dir.path().join("a.json"), "two").is_err());
    }
}
