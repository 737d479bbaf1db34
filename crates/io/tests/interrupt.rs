//! What an interrupted process can remove (`voxreg_io::inflight`). A test binary of its
//! own: `remove_in_flight` removes every temporary entry of the process, which would
//! break the other tests' writes running beside it.

use std::path::Path;

use voxreg_digisurf::{DigitalSurface, LabelVolume};
use voxreg_io::inflight::{remove_in_flight, temp_prefix};
use voxreg_io::{write_file_atomically, MeshBatch, QuadMesh};

fn ours(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with(&temp_prefix()))
        .collect()
}

#[test]
fn an_interruption_removes_temporary_files_staging_and_created_directories() {
    let dir = tempfile::tempdir().unwrap();

    // A file being written: its temporary file is removed, the target never appears.
    let target = dir.path().join("m.json");
    let written = write_file_atomically(&target, |w| {
        assert_eq!(ours(dir.path()).len(), 1, "the temporary file exists while writing");
        let held = remove_in_flight();
        assert!(ours(dir.path()).is_empty(), "removed: {:?}", ours(dir.path()));
        drop(held);
        w.write_all(b"{}")
    });
    assert!(written.is_err(), "the rename of a removed temporary file fails");
    assert!(!target.exists());

    // A batch into a new directory: the staging directory and the created directory go.
    let volume = LabelVolume::from_fn([3, 3, 3], |p| u32::from(p == [1, 1, 1]));
    let surface = DigitalSurface::from_volume(&volume).unwrap();
    let mesh = QuadMesh::from_surface(&surface, &surface.positions());
    let out = dir.path().join("new").join("parts");
    let mut batch = MeshBatch::new(&out).unwrap();
    batch.write("a.ply", &mesh).unwrap();
    assert_eq!(ours(&out).len(), 1, "the staging directory");
    drop(remove_in_flight());
    assert!(!dir.path().join("new").exists(), "the directory the batch created is removed");
    drop(batch);

    // Once released, writing works again.
    write_file_atomically(&target, |w| w.write_all(b"{}")).unwrap();
    assert!(target.exists() && ours(dir.path()).is_empty());
}
