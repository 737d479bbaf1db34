//! Fuzzes `read_mesh_bytes`, the OBJ/PLY reader behind `voxreg check`, and the check
//! itself on what it reads: any input is read or refused, never a panic or an abort.
//! The first byte picks the format (even: OBJ, odd: PLY).
#![no_main]

use std::path::Path;

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&pick, bytes)) = data.split_first() else { return };
    let name = if pick % 2 == 0 { "fuzz.obj" } else { "fuzz.ply" };
    if let Ok(mesh) = voxreg_io::read_mesh_bytes(bytes, Path::new(name)) {
        if mesh.quads.len() <= 4096 {
            let _ = voxreg_quality::check(&mesh.positions, &mesh.quads);
        }
    }
});
