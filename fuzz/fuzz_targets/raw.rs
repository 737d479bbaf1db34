//! Fuzzes `read_raw_bytes`: the first 8 bytes choose the layout (dimensions below 64,
//! zero included; type; byte order; spacing, zero included), the rest is the data.
#![no_main]

use std::path::Path;

use glam::DVec3;
use libfuzzer_sys::fuzz_target;
use voxreg_io::{DataType, Endian, RawSpec};

fuzz_target!(|data: &[u8]| {
    let Some((head, rest)) = data.split_first_chunk::<8>() else { return };
    let spec = RawSpec {
        dims: [head[0], head[1], head[2]].map(|d| u64::from(d % 64)),
        dtype: DataType::ALL[usize::from(head[3]) % DataType::ALL.len()],
        endian: if head[4] % 2 == 0 { Endian::Little } else { Endian::Big },
        spacing: DVec3::new(f64::from(head[5]), f64::from(head[6]), f64::from(head[7])) / 16.0,
    };
    // A 1 GiB budget: well under libFuzzer's 2 GiB RSS limit.
    let _ =
        voxreg_io::with_max_memory(1 << 30, || voxreg_io::read_raw_bytes(rest, Path::new("fuzz.raw"), &spec));
});
