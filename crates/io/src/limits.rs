//! The memory budget: what a reader (or a later stage) may allocate, checked from the
//! sizes a file declares before anything is allocated for them.

use std::cell::Cell;
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};

use crate::error::IoError;

/// The budget in bytes; `0` until set, meaning [`default_max_memory`].
static MAX_MEMORY: AtomicU64 = AtomicU64::new(0);

/// The default budget when `/proc/meminfo` cannot be read: 8 GiB.
pub const FALLBACK_MAX_MEMORY: u64 = 8 << 30;

thread_local! {
    /// A budget for this thread only ([`with_max_memory`]); `0` when none.
    static SCOPED: Cell<u64> = const { Cell::new(0) };
}

/// The memory budget in bytes that readers check declared sizes against: the one of
/// [`with_max_memory`] on this thread (taken as is), else the least of the value of
/// [`set_max_memory`] (by default half the physical memory) and what the environment
/// leaves the process ([`environment_limit`]: the address-space limit and the cgroup's
/// memory limit), so that a size within the budget is never one the process cannot get.
pub fn max_memory() -> u64 {
    match (SCOPED.with(Cell::get), MAX_MEMORY.load(Ordering::Relaxed)) {
        (0, 0) => default_max_memory(),
        (0, n) => environment_limit().map_or(n, |e| e.min(n)),
        (n, _) => n,
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
/// `0` restores the default. [`max_memory`] never exceeds [`environment_limit`],
/// whatever is set here.
pub fn set_max_memory(bytes: u64) {
    MAX_MEMORY.store(bytes, Ordering::Relaxed);
}

/// The default budget: the least of half the physical memory (`MemTotal` of
/// `/proc/meminfo` on Linux, else [`FALLBACK_MAX_MEMORY`]) and [`environment_limit`].
pub fn default_max_memory() -> u64 {
    let half = std::fs::read_to_string("/proc/meminfo")
        .ok()
        .and_then(|text| mem_total(&text))
        .map_or(FALLBACK_MAX_MEMORY, |total| (total / 2).max(1 << 20));
    environment_limit().map_or(half, |e| e.min(half))
}

/// Address space kept for what the budget does not count: each thread's stack and
/// allocator arena (glibc reserves 64 MiB of address space per arena), plus the code.
fn address_space_reserve() -> u64 {
    let threads = std::thread::available_parallelism().map_or(1, usize::from) as u64 + 1;
    (64 << 20) + threads * (66 << 20)
}

/// Head room kept below a cgroup's memory limit, for what the budget does not count.
const CGROUP_RESERVE: u64 = 64 << 20;

/// What the environment lets this process allocate, where it sets a limit (Linux): the
/// least of the address-space limit (`RLIMIT_AS`, `ulimit -v`, from `/proc/self/limits`)
/// less the address space already mapped and a reserve (`address_space_reserve`) for
/// threads, and the memory limit of the process's cgroup (v2 `memory.max` or v1
/// `memory.limit_in_bytes`, of its cgroup and every ancestor, through
/// `/proc/self/cgroup`) less what the process already holds; at least 1 MiB. `None` when
/// neither is set (or readable). Batch schedulers set both: a budget above them is an
/// allocation failure, an abort, instead of a one-line error.
pub fn environment_limit() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    let address_space = std::fs::read_to_string("/proc/self/limits")
        .ok()
        .and_then(|t| address_space_limit(&t))
        .map(|limit| {
            limit
                .saturating_sub(status_kb(&status, "VmSize:").unwrap_or(0))
                .saturating_sub(address_space_reserve())
        });
    let cgroup = std::fs::read_to_string("/proc/self/cgroup")
        .ok()
        .and_then(|t| cgroup_limit(&t, Path::new("/sys/fs/cgroup"), &|p| std::fs::read_to_string(p).ok()))
        .map(|limit| {
            limit.saturating_sub(status_kb(&status, "VmRSS:").unwrap_or(0)).saturating_sub(CGROUP_RESERVE)
        });
    match (address_space, cgroup) {
        (None, None) => None,
        (a, c) => Some(a.unwrap_or(u64::MAX).min(c.unwrap_or(u64::MAX)).max(1 << 20)),
    }
}

/// The soft `Max address space` of a `/proc/self/limits` text, in bytes; `None` when
/// unlimited.
fn address_space_limit(limits: &str) -> Option<u64> {
    let line = limits.lines().find(|l| l.starts_with("Max address space"))?;
    line["Max address space".len()..].split_whitespace().next()?.parse::<u64>().ok()
}

/// A `kB` field of `/proc/self/status` (`VmSize:`, `VmRSS:`), in bytes.
fn status_kb(status: &str, key: &str) -> Option<u64> {
    let line = status.lines().find(|l| l.starts_with(key))?;
    line[key.len()..].split_whitespace().next()?.parse::<u64>().ok()?.checked_mul(1024)
}

/// The least memory limit of the cgroups a `/proc/self/cgroup` text names, and of their
/// ancestors, under the cgroup file system mounted at `root` (`read` reads a file):
/// v2 (`0::/path`, `root/path/memory.max`) or v1 (`N:...memory...:/path`,
/// `root/memory/path/memory.limit_in_bytes`). A path not found under the mount (a
/// container sees its own cgroup as the root) is tried at the mount's root. `None`
/// when no limit is set.
fn cgroup_limit(cgroups: &str, root: &Path, read: &dyn Fn(&Path) -> Option<String>) -> Option<u64> {
    let mut least: Option<u64> = None;
    for line in cgroups.lines() {
        let mut parts = line.splitn(3, ':');
        let (Some(_), Some(controllers), Some(path)) = (parts.next(), parts.next(), parts.next()) else {
            continue;
        };
        let (base, file) = if controllers.is_empty() {
            (root.to_path_buf(), "memory.max")
        } else if controllers.split(',').any(|c| c == "memory") {
            (root.join("memory"), "memory.limit_in_bytes")
        } else {
            continue;
        };
        let relative = Path::new(path.trim_start_matches('/'));
        for dir in relative.ancestors() {
            let value = read(&base.join(dir).join(file)).and_then(|t| t.trim().parse::<u64>().ok());
            // v1 writes "no limit" as a number near 2^63; v2 as `max` (not a number).
            if let Some(v) = value.filter(|&v| v < 1 << 62) {
                least = Some(least.map_or(v, |l| l.min(v)));
            }
        }
    }
    least
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

    #[test]
    fn address_space_and_cgroup_limits() {
        let limits = "Limit                     Soft Limit           Hard Limit           Units\n\
                      Max address space         4294967296           unlimited            bytes\n";
        assert_eq!(address_space_limit(limits), Some(4 << 30));
        assert_eq!(address_space_limit("Max address space  unlimited  unlimited  bytes"), None);
        assert_eq!(status_kb("Name: x\nVmSize:\t  2048 kB\n", "VmSize:"), Some(2 << 20));
        let files = |p: &Path| -> Option<String> {
            match p.to_str()? {
                "/cg/a/b/memory.max" => Some("max\n".into()),
                "/cg/a/memory.max" => Some("3000000000\n".into()),
                "/cg/memory/job/memory.limit_in_bytes" => Some("1000000000\n".into()),
                "/cg/memory/memory.limit_in_bytes" => Some("9223372036854771712\n".into()),
                _ => None,
            }
        };
        let root = Path::new("/cg");
        assert_eq!(cgroup_limit("0::/a/b\n", root, &files), Some(3_000_000_000));
        assert_eq!(cgroup_limit("4:cpu,memory:/job\n0::/\n", root, &files), Some(1_000_000_000));
        assert_eq!(cgroup_limit("4:memory:/\n0::/elsewhere\n", root, &files), None);
        // Never above what the environment leaves, when it sets a limit.
        if let Some(e) = environment_limit() {
            assert!(default_max_memory() <= e);
        }
    }
}
