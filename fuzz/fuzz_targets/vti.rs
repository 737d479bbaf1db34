//! Fuzzes `read_vti_bytes`: any input is read or refused with an error, never a panic.
#![no_main]

use std::path::Path;

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = voxreg_io::read_vti_bytes(data, Path::new("fuzz.vti"));
});
