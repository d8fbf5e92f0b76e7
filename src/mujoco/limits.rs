//! The memory this process may still take, from Linux's `/proc` and cgroup files: the memory
//! the machine has available (`MemAvailable`), the address-space limit (`RLIMIT_AS`, as
//! `prlimit --as` sets it) less the address space in use (`VmSize`), and the cgroup's
//! `memory.max` less its `memory.current`. MuJoCo's allocations and Mesa's GL contexts fail
//! (Mesa by crashing) beyond them, so the layers above check first. Everything is read from
//! text files; where one does not exist (not Linux, no cgroup v2), that bound is unknown.

use std::path::Path;

/// One bound on the memory left: how many bytes and which limit it is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Headroom {
    /// Bytes left under the limit.
    pub bytes: u64,
    /// The limit, for messages (`"MemAvailable in /proc/meminfo"`, ...).
    pub source: &'static str,
}

/// The field `key` (e.g. `"MemAvailable:"`) of a `/proc/meminfo`- or `/proc/self/status`-like
/// text, in bytes (the value must be given in kB).
pub(crate) fn kb_field(text: &str, key: &str) -> Option<u64> {
    let line = text.lines().find(|l| l.starts_with(key))?;
    let mut it = line[key.len()..].split_whitespace();
    let kb: u64 = it.next()?.parse().ok()?;
    match it.next() {
        Some("kB") => kb.checked_mul(1024),
        _ => None,
    }
}

/// The soft `Max address space` limit of a `/proc/self/limits` text (bytes); None when
/// unlimited or absent.
pub(crate) fn address_space_limit(limits: &str) -> Option<u64> {
    let line = limits
        .lines()
        .find(|l| l.starts_with("Max address space"))?;
    line["Max address space".len()..]
        .split_whitespace()
        .next()?
        .parse()
        .ok()
}

/// `MemAvailable` of `/proc/meminfo`.
pub fn mem_available() -> Option<Headroom> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    Some(Headroom {
        bytes: kb_field(&text, "MemAvailable:")?,
        source: "MemAvailable in /proc/meminfo",
    })
}

/// The address space left under `RLIMIT_AS`: the soft limit less `VmSize`; None without a
/// limit.
pub fn address_space() -> Option<Headroom> {
    let limit = address_space_limit(&std::fs::read_to_string("/proc/self/limits").ok()?)?;
    let used = kb_field(
        &std::fs::read_to_string("/proc/self/status").ok()?,
        "VmSize:",
    )?;
    Some(Headroom {
        bytes: limit.saturating_sub(used),
        source: "the address-space limit (RLIMIT_AS, ulimit -v) less the address space in use",
    })
}

/// The memory left in this process's cgroup (v2): `memory.max` less `memory.current`; None
/// without a limit ("max") or without cgroup v2.
pub fn cgroup() -> Option<Headroom> {
    let line = std::fs::read_to_string("/proc/self/cgroup").ok()?;
    // cgroup v2: the one line "0::/path".
    let rel = line.lines().find_map(|l| l.strip_prefix("0::"))?.trim();
    let dir = Path::new("/sys/fs/cgroup").join(rel.trim_start_matches('/'));
    let read = |f: &str| std::fs::read_to_string(dir.join(f)).ok();
    let max: u64 = read("memory.max")?.trim().parse().ok()?;
    let current: u64 = read("memory.current")?.trim().parse().ok()?;
    Some(Headroom {
        bytes: max.saturating_sub(current),
        source: "the cgroup's memory.max less its memory.current",
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn proc_texts_are_read_in_bytes() {
        let meminfo = "MemTotal:       24684032 kB\nMemAvailable:   22212608 kB\n";
        assert_eq!(kb_field(meminfo, "MemAvailable:"), Some(22_212_608 * 1024));
        assert_eq!(kb_field("MemAvailable: lots\n", "MemAvailable:"), None);
        assert_eq!(kb_field("MemAvailable: 5 MB\n", "MemAvailable:"), None);
        let limits = "Limit                     Soft Limit           Hard Limit           Units\n\
                      Max stack size            8388608              unlimited            bytes\n\
                      Max address space         2000000000           unlimited            bytes\n";
        assert_eq!(address_space_limit(limits), Some(2_000_000_000));
        let unlimited =
            "Max address space         unlimited            unlimited            bytes\n";
        assert_eq!(address_space_limit(unlimited), None);
    }
}
