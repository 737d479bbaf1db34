//! Fuzzes `read_mrc_bytes`: any input is read or refused with an error, never a panic.
#![no_main]

use std::path::Path;

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    // A 1 GiB budget: well under libFuzzer's 2 GiB RSS limit.
    let _ = voxreg_io::with_max_memory(1 << 30, || voxreg_io::read_mrc_bytes(data, Path::new("fuzz.mrc")));
});
