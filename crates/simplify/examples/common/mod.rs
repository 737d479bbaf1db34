//! What the examples share: the regularized surface of a volume file, as a mesh.

use std::time::Instant;

use voxreg_io::{LoadedVolume, QuadMesh};

/// The volume at `path`, the default run's surface of it as a mesh, and the seconds the
/// regularization took; exits with the error on a file that cannot be read or solved.
pub(crate) fn regularized_mesh(path: &str) -> (LoadedVolume, QuadMesh, f64) {
    let loaded = voxreg_io::read_volume(std::path::Path::new(path)).unwrap_or_else(|e| {
        eprintln!("{path}: {e}");
        std::process::exit(1);
    });
    let t0 = Instant::now();
    let out = voxreg_regularize::regularize(&loaded.volume, &voxreg_regularize::Params::default())
        .unwrap_or_else(|e| {
            eprintln!("{path}: {e}");
            std::process::exit(1);
        });
    let seconds = t0.elapsed().as_secs_f64();
    let mesh = QuadMesh::from_surface(&out.surface, &out.positions);
    (loaded, mesh, seconds)
}
