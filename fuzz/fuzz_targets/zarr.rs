//! Fuzzes `read_zarr_entries`: any store is read or refused with an error, never a panic.
//!
//! The input is a packed store: entries `key\n<bytes>` joined by `\n%%\n` (metadata
//! documents such as `zarr.json`, `.zarray`, `.zattrs`, `0/.zarray`, and chunks); the
//! seeds are the samples of `data/formats/*.zarr` packed so.
#![no_main]

use std::path::Path;

use libfuzzer_sys::fuzz_target;

const SEPARATOR: &[u8] = b"\n%%\n";

fuzz_target!(|data: &[u8]| {
    // The reader turns a panic inside the zarrs decoder into an error (a corrupt shard
    // index makes it slice out of range); libFuzzer's hook would abort on that caught
    // panic, so it is replaced by one that only prints. A panic that escapes the reader
    // still aborts (the harness catches it).
    static QUIET: std::sync::Once = std::sync::Once::new();
    QUIET.call_once(|| std::panic::set_hook(Box::new(|info| eprintln!("{info}"))));
    let mut entries = Vec::new();
    let mut rest = data;
    loop {
        let end = rest.windows(SEPARATOR.len()).position(|w| w == SEPARATOR);
        let entry = &rest[..end.unwrap_or(rest.len())];
        let key_end = entry.iter().position(|&b| b == b'\n').unwrap_or(entry.len());
        if let Ok(key) = std::str::from_utf8(&entry[..key_end]) {
            entries.push((key, entry.get(key_end + 1..).unwrap_or(&[])));
        }
        match end {
            Some(e) => rest = &rest[e + SEPARATOR.len()..],
            None => break,
        }
    }
    // A 1 GiB budget: well under libFuzzer's 2 GiB RSS limit.
    let _ = voxreg_io::with_max_memory(1 << 30, || {
        voxreg_io::read_zarr_entries(&entries, Path::new("fuzz.zarr"))
    });
});
