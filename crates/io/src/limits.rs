//! The memory budget: what a reader (or a later stage) may allocate, checked from the
//! sizes a file declares before anything is allocated for them.

use std::cell::Cell;
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};

use crate::IoError;

/// The budget in bytes; `0` until set, meaning [`default_max_memory`].
static MAX_MEMORY: AtomicU64 = AtomicU64::new(0);

/// The default budget when `/proc/meminfo` cannot be read: 8 GiB.
pub const FALLBACK_MAX_MEMORY: u64 = 8 << 30;

thread_local! {
    /// A budget for this thread only ([`with_max_memory`]); `0` when none.
    static SCOPED: Cell<u64> = const { Cell::new(0) };
}

/// The memory budget in bytes that readers check declared sizes against: the one of
/// [`with_max_memory`] on this thread, else the value of [`set_max_memory`], else
/// [`default_max_memory`].
pub fn max_memory() -> u64 {
    match (SCOPED.with(Cell::get), MAX_MEMORY.load(Ordering::Relaxed)) {
        (0, 0) => default_max_memory(),
        (0, n) | (n, _) => n,
    }
}

/// Runs `f` with a budget of `bytes` on this thread only (tests, fuzzing), restoring
/// the previous one afterwards.
pub fn with_max_memory<R>(bytes: u64, f: impl FnOnce() -> R) -> R {
    struct Restore(u64);
    impl Drop for Restore {
        fn drop(&mut self) {
            SCOPED.with(|s| s.set(self.0));
        }
    }
    let _restore = Restore(SCOPED.with(|s| s.replace(bytes)));
    f()
}

/// Sets the memory budget for the whole process (e.g. from `voxreg --max-memory`);
/// `0` restores the default.
pub fn set_max_memory(bytes: u64) {
    MAX_MEMORY.store(bytes, Ordering::Relaxed);
}

/// Half the physical memory (`MemTotal` of `/proc/meminfo` on Linux), else
/// [`FALLBACK_MAX_MEMORY`].
pub fn default_max_memory() -> u64 {
    std::fs::read_to_string("/proc/meminfo")
        .ok()
        .and_then(|text| mem_total(&text))
        .map_or(FALLBACK_MAX_MEMORY, |total| (total / 2).max(1 << 20))
}

/// `MemTotal` of a `/proc/meminfo` text, in bytes.
fn mem_total(meminfo: &str) -> Option<u64> {
    let line = meminfo.lines().find(|l| l.starts_with("MemTotal:"))?;
    let mut words = line["MemTotal:".len()..].split_whitespace();
    let value = words.next()?.parse::<u64>().ok()?;
    match words.next() {
        Some("kB") | None => value.checked_mul(1024),
        _ => None,
    }
}

/// Parses a size such as `4G`, `512M`, `100k` or `1000000` (bytes; binary multiples
/// `k`, `M`, `G`, `T`, optionally followed by `i`, `B` or `iB`). `None` if malformed,
/// zero or overflowing.
pub fn parse_size(text: &str) -> Option<u64> {
    let t = text.trim();
    let t = t.strip_suffix('B').or_else(|| t.strip_suffix('b')).unwrap_or(t);
    let t = t.strip_suffix('i').unwrap_or(t);
    let (digits, shift) = match t.char_indices().last()? {
        (i, 'k' | 'K') => (&t[..i], 10),
        (i, 'm' | 'M') => (&t[..i], 20),
        (i, 'g' | 'G') => (&t[..i], 30),
        (i, 't' | 'T') => (&t[..i], 40),
        _ => (t, 0),
    };
    let value = digits.trim().parse::<f64>().ok().filter(|v| v.is_finite() && *v > 0.0)?;
    let bytes = value * (1u64 << shift) as f64;
    (bytes >= 1.0 && bytes < u64::MAX as f64).then_some(bytes as u64)
}

/// A size in bytes for messages: `1.5 GiB`, `12 MiB`, `300 bytes`.
pub fn format_size(bytes: u64) -> String {
    const UNITS: [(&str, u32); 4] = [("TiB", 40), ("GiB", 30), ("MiB", 20), ("KiB", 10)];
    for (unit, shift) in UNITS {
        if bytes >= 1 << shift {
            let v = bytes as f64 / (1u64 << shift) as f64;
            return if v >= 10.0 { format!("{v:.0} {unit}") } else { format!("{v:.1} {unit}") };
        }
    }
    format!("{bytes} bytes")
}

/// Refuses with [`IoError::OverBudget`] when `bytes` (what `what` needs) exceed
/// [`max_memory`].
pub fn check_memory(path: &Path, what: &str, bytes: u128) -> Result<(), IoError> {
    let limit = max_memory();
    if bytes > u128::from(limit) {
        return Err(IoError::OverBudget {
            path: path.to_path_buf(),
            what: what.to_string(),
            bytes: u64::try_from(bytes).unwrap_or(u64::MAX),
            limit,
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_parse_and_format() {
        assert_eq!(parse_size("4G"), Some(4 << 30));
        assert_eq!(parse_size("512M"), Some(512 << 20));
        assert_eq!(parse_size("512MiB"), Some(512 << 20));
        assert_eq!(parse_size("1.5k"), Some(1536));
        assert_eq!(parse_size("1000"), Some(1000));
        for bad in ["", "G", "-1G", "0", "1X", "nanG", "1e30T"] {
            assert_eq!(parse_size(bad), None, "{bad}");
        }
        assert_eq!(format_size(3 << 30), "3.0 GiB");
        assert_eq!(format_size(12 << 20), "12 MiB");
        assert_eq!(format_size(300), "300 bytes");
    }

    #[test]
    fn meminfo() {
        assert_eq!(mem_total("MemTotal:       16318712 kB\nMemFree: 1 kB\n"), Some(16318712 * 1024));
        assert_eq!(mem_total("nothing"), None);
        assert!(default_max_memory() >= 1 << 20);
        with_max_memory(1000, || {
            assert_eq!(max_memory(), 1000);
            assert!(check_memory(Path::new("a.vol"), "the volume", 1001).is_err());
            assert!(check_memory(Path::new("a.vol"), "the volume", 1000).is_ok());
        });
        assert_ne!(max_memory(), 1000);
    }
}
