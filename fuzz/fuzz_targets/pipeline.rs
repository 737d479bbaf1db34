//! Fuzzes the whole front door on tiny volumes (`pipeline_case` decodes the bytes): any
//! volume and parameter combination gives finite positions or an error, never a panic.
#![no_main]

use libfuzzer_sys::fuzz_target;

mod pipeline_case;

fuzz_target!(|data: &[u8]| {
    if let Some((volume, params)) = pipeline_case::case(data) {
        if let Ok(out) = voxreg_regularize::regularize(&volume, &params) {
            assert!(out.positions.as_slice().iter().all(|p| p.is_finite()), "non-finite positions");
        }
    }
});
