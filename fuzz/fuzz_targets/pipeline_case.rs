//! Decodes fuzzer bytes into a tiny label volume and front-door parameters, for the
//! `pipeline` fuzz target and the test that replays its seeds
//! (`crates/regularize/tests/energy.rs`).
//!
//! Byte 0: dims (2 bits per axis, 1 to 4 voxels); byte 1: preset (default, papers,
//! voxel art), estimator, solver, refinement rounds; byte 2: clamping and a scaled
//! alpha/beta/gamma; then one byte per voxel, its label modulo 4 (0 is the background).

use voxreg_digisurf::LabelVolume;
use voxreg_regularize::{Estimator, Params, SolverChoice};

/// The volume and parameters `data` encodes, `None` when it is too short.
pub(crate) fn case(data: &[u8]) -> Option<(LabelVolume, Params)> {
    let [shape, choices, numbers, voxels @ ..] = data else { return None };
    let dims = [0, 2, 4].map(|s| 1 + usize::from((shape >> s) & 3));
    let n = dims[0] * dims[1] * dims[2];
    if voxels.len() < n {
        return None;
    }
    let volume =
        LabelVolume::from_fn(dims, |[x, y, z]| u32::from(voxels[x + dims[0] * (y + dims[1] * z)] % 4));
    let mut params = match choices % 3 {
        0 => Params::default(),
        1 => Params::papers(),
        _ => Params::voxel_art(),
    };
    params.normals.estimator = match (choices / 3) % 4 {
        0 => Estimator::Trivial,
        1 => Estimator::Convolved,
        2 => Estimator::Ii,
        _ => Estimator::At,
    };
    params.solver.choice = match (choices / 12) % 4 {
        0 => SolverChoice::Auto,
        1 => SolverChoice::Direct,
        2 => SolverChoice::Cg,
        _ => SolverChoice::Bounded,
    };
    params.refinement_mut().rounds = usize::from(choices / 48) % 3;
    if numbers & 1 == 1 {
        params.mode = params.mode.with_margin(0.01 + f64::from(numbers >> 5) * 0.05);
    }
    let scale = 10f64.powi(i32::from((numbers >> 1) & 15) - 8);
    params.energy.alpha *= scale;
    Some((volume, params))
}
