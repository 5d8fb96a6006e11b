//! The memory a run may plan for (issue 43): the smallest of the cgroup's
//! memory limit (v2 `memory.max`, v1 `memory.limit_in_bytes`, of the
//! process's own cgroup and its ancestors), the address-space limit
//! `RLIMIT_AS` (less the address space the process maps already and
//! [`ADDRESS_SPACE_RESERVE`]) and the physical memory (`/proc/meminfo`
//! `MemTotal`, else `sysconf`), or `$SURFSYNTH_MEMORY_LIMIT` when set (bytes, or with suffix
//! `K`, `M`, `G`: binary units). The up-front estimates
//! ([`super::memory_budget`]) are checked against it.
//!
//! The limit only decides whether a run is refused before its work; it
//! never changes what a run computes, so outputs stay the same on every
//! machine. Tests set the variable for refusals that must not depend on the
//! machine.

use std::fmt;
use std::path::{Path, PathBuf};

/// The environment variable that overrides the detected limit.
pub const LIMIT_VAR: &str = "SURFSYNTH_MEMORY_LIMIT";

/// The allowed form of [`LIMIT_VAR`], for messages.
pub const LIMIT_FORM: &str = "a whole number of bytes greater than 0, optionally followed by K, M or G (KiB, MiB, GiB; e.g. 512M, 6G), or unset to use the detected limit";

/// The limit when nothing could be detected (no cgroup limit, no
/// `RLIMIT_AS`, no physical-memory figure): 8 GiB, the former fixed budget.
pub const FALLBACK_LIMIT: u64 = 8 << 30;

/// Address space kept out of an `RLIMIT_AS` limit for what no estimate
/// counts: thread stacks and the allocator's per-thread arenas (glibc
/// reserves 64 MiB of address space for each). Under `ulimit -v 4000000` a
/// `jump_image` estimated at 3.75 GiB of a 3.81 GiB limit aborted.
pub const ADDRESS_SPACE_RESERVE: u64 = 512 << 20;

/// A cgroup limit at or above this is "no limit" (v1 writes
/// `9223372036854771712`, v2 `max`).
const UNLIMITED: u64 = 1 << 60;

/// Where a limit comes from.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum LimitSource {
    /// `$SURFSYNTH_MEMORY_LIMIT`.
    Environment,
    /// A cgroup's memory limit: the file it was read from.
    Cgroup(PathBuf),
    /// The address-space limit `RLIMIT_AS` (`ulimit -v`).
    AddressSpace,
    /// The machine's physical memory.
    Physical,
    /// Nothing detected: [`FALLBACK_LIMIT`].
    Fallback,
}

impl fmt::Display for LimitSource {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            LimitSource::Environment => write!(f, "{LIMIT_VAR}"),
            LimitSource::Cgroup(path) => write!(f, "cgroup limit {}", path.display()),
            LimitSource::AddressSpace => write!(f, "RLIMIT_AS, ulimit -v"),
            LimitSource::Physical => write!(f, "physical memory"),
            LimitSource::Fallback => write!(f, "no limit detected: the 8 GiB default"),
        }
    }
}

/// The memory a run may plan for, and where the figure comes from.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct MemoryLimit {
    /// Bytes.
    pub bytes: u64,
    /// Where it comes from.
    pub source: LimitSource,
}

impl MemoryLimit {
    /// The limit of this process: [`LIMIT_VAR`] when set (and not empty),
    /// else the smallest of the detected limits ([`probe`]).
    ///
    /// # Errors
    /// A malformed [`LIMIT_VAR`]: the message names the value and the
    /// allowed form (the caller names the variable).
    pub fn detect() -> Result<MemoryLimit, String> {
        let var = match std::env::var(LIMIT_VAR) {
            Ok(v) => Some(v),
            Err(std::env::VarError::NotPresent) => None,
            Err(std::env::VarError::NotUnicode(v)) => {
                return Err(format!("{v:?} is not a size; allowed: {LIMIT_FORM}"));
            }
        };
        choose(var.as_deref(), &probe())
    }
}

/// The limits found on this machine, each `None` when absent or unlimited.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Probes {
    /// The smallest cgroup memory limit on the way to the root, and its file.
    pub cgroup: Option<(u64, PathBuf)>,
    /// `RLIMIT_AS` (soft limit) less the address space mapped already and
    /// [`ADDRESS_SPACE_RESERVE`], bytes.
    pub address_space: Option<u64>,
    /// Physical memory, bytes.
    pub physical: Option<u64>,
}

/// Parses [`LIMIT_VAR`]'s value: a whole number of bytes (> 0), optionally
/// followed by `K`, `M` or `G` (binary units, either case); blanks around it
/// are ignored.
///
/// # Errors
/// The value and the allowed form.
pub fn parse_limit(text: &str) -> Result<u64, String> {
    let bytes = crate::cache::parse_limit(text)
        .map_err(|_| format!("{text:?} is not a size; allowed: {LIMIT_FORM}"))?;
    if bytes == 0 {
        return Err(format!(
            "{text:?} leaves no memory for anything; allowed: {LIMIT_FORM}"
        ));
    }
    Ok(bytes)
}

/// The limit from the variable's value `var` (unset: `None`; empty counts as
/// unset) or else the smallest of `probes` (ties: the first of cgroup,
/// address space, physical memory).
///
/// # Errors
/// As [`parse_limit`].
pub fn choose(var: Option<&str>, probes: &Probes) -> Result<MemoryLimit, String> {
    if let Some(v) = var.filter(|v| !v.trim().is_empty()) {
        return Ok(MemoryLimit {
            bytes: parse_limit(v)?,
            source: LimitSource::Environment,
        });
    }
    let candidates = [
        probes
            .cgroup
            .as_ref()
            .map(|(b, p)| (*b, LimitSource::Cgroup(p.clone()))),
        probes.address_space.map(|b| (b, LimitSource::AddressSpace)),
        probes.physical.map(|b| (b, LimitSource::Physical)),
    ];
    let best = candidates
        .into_iter()
        .flatten()
        .fold(None::<(u64, LimitSource)>, |best, (b, s)| match best {
            Some((bb, _)) if bb <= b => best,
            _ => Some((b, s)),
        });
    Ok(match best {
        Some((bytes, source)) => MemoryLimit { bytes, source },
        None => MemoryLimit {
            bytes: FALLBACK_LIMIT,
            source: LimitSource::Fallback,
        },
    })
}

/// Reads the machine's limits.
pub fn probe() -> Probes {
    Probes {
        cgroup: std::fs::read_to_string("/proc/self/cgroup")
            .ok()
            .and_then(|text| {
                cgroup_limit(&text, Path::new("/sys/fs/cgroup"), &|p| {
                    std::fs::read_to_string(p).ok()
                })
            }),
        address_space: address_space_limit(),
        physical: physical_memory(),
    }
}

/// A cgroup limit file's value: `None` for `max`, a value at or above
/// [`UNLIMITED`], or anything unreadable.
fn limit_value(text: &str) -> Option<u64> {
    let v: u64 = text.trim().parse().ok()?;
    (v < UNLIMITED).then_some(v)
}

/// The smallest memory limit of the cgroups in `proc_cgroup` (the text of
/// `/proc/self/cgroup`) and their ancestors, under the cgroup file systems
/// mounted at `root`: v2 (`0::PATH`: `root/PATH/memory.max`, also under
/// `root/unified` on hybrid systems) and v1 (`N:…memory…:PATH`:
/// `root/memory/PATH/memory.limit_in_bytes`). `read` reads a file.
pub fn cgroup_limit(
    proc_cgroup: &str,
    root: &Path,
    read: &dyn Fn(&Path) -> Option<String>,
) -> Option<(u64, PathBuf)> {
    let mut files: Vec<PathBuf> = Vec::new();
    let mut with_ancestors = |base: PathBuf, path: &str, file: &str| {
        let mut dir = PathBuf::from(path.trim_start_matches('/'));
        loop {
            files.push(base.join(&dir).join(file));
            if !dir.pop() {
                break;
            }
        }
    };
    for line in proc_cgroup.lines() {
        let mut parts = line.splitn(3, ':');
        let (Some(_id), Some(controllers), Some(path)) = (parts.next(), parts.next(), parts.next())
        else {
            continue;
        };
        if controllers.is_empty() {
            with_ancestors(root.to_path_buf(), path, "memory.max");
            with_ancestors(root.join("unified"), path, "memory.max");
        } else if controllers.split(',').any(|c| c == "memory") {
            with_ancestors(root.join("memory"), path, "memory.limit_in_bytes");
        }
    }
    files
        .into_iter()
        .filter_map(|f| read(&f).and_then(|t| limit_value(&t)).map(|v| (v, f)))
        .min_by_key(|(v, _)| *v)
}

/// `RLIMIT_AS`'s soft limit less the process's mapped address space
/// (`VmSize`) and [`ADDRESS_SPACE_RESERVE`]; `None` when unlimited or
/// unknown.
fn address_space_limit() -> Option<u64> {
    #[cfg(unix)]
    {
        let mut rl = libc::rlimit {
            rlim_cur: 0,
            rlim_max: 0,
        };
        // SAFETY: getrlimit writes the limit into the struct we pass.
        let ok = unsafe { libc::getrlimit(libc::RLIMIT_AS, &mut rl) } == 0;
        if ok && rl.rlim_cur != libc::RLIM_INFINITY {
            let mapped = std::fs::read_to_string("/proc/self/status")
                .ok()
                .and_then(|t| status_kb(&t, "VmSize:"))
                .unwrap_or(0);
            // `rlim_t` is `u64` on Linux, not everywhere.
            #[allow(clippy::unnecessary_cast)]
            let soft = rl.rlim_cur as u64;
            return Some(
                soft.saturating_sub(mapped)
                    .saturating_sub(ADDRESS_SPACE_RESERVE),
            );
        }
        None
    }
    #[cfg(not(unix))]
    {
        None
    }
}

/// `MemTotal` of `/proc/meminfo` (kB), else `sysconf` pages × page size.
fn physical_memory() -> Option<u64> {
    if let Some(kb) = std::fs::read_to_string("/proc/meminfo")
        .ok()
        .and_then(|t| meminfo_total(&t))
    {
        return Some(kb);
    }
    #[cfg(unix)]
    {
        // SAFETY: sysconf only reads system configuration values.
        let (pages, size) = unsafe {
            (
                libc::sysconf(libc::_SC_PHYS_PAGES),
                libc::sysconf(libc::_SC_PAGESIZE),
            )
        };
        if pages > 0 && size > 0 {
            return Some(pages as u64 * size as u64);
        }
    }
    None
}

/// `MemTotal` in bytes from the text of `/proc/meminfo`.
pub fn meminfo_total(text: &str) -> Option<u64> {
    status_kb(text, "MemTotal:")
}

/// The value of a `KEY: N kB` line (`/proc/meminfo`, `/proc/self/status`)
/// in bytes.
fn status_kb(text: &str, key: &str) -> Option<u64> {
    let line = text.lines().find(|l| l.starts_with(key))?;
    let mut words = line.split_whitespace().skip(1);
    let n: u64 = words.next()?.parse().ok()?;
    match words.next() {
        Some("kB") | None => n.checked_mul(1024),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_variable_takes_bytes_and_binary_suffixes() {
        assert_eq!(parse_limit("1048576"), Ok(1 << 20));
        assert_eq!(parse_limit(" 512M "), Ok(512 << 20));
        assert_eq!(parse_limit("6g"), Ok(6 << 30));
        assert_eq!(parse_limit("64K"), Ok(64 << 10));
        for bad in [
            "",
            "lots",
            "1.5G",
            "-1",
            "12T",
            "0",
            "0G",
            "99999999999999999999",
        ] {
            let e = parse_limit(bad).unwrap_err();
            assert!(
                e.contains(&format!("{bad:?}")) && e.contains("allowed"),
                "{e}"
            );
        }
    }

    #[test]
    fn the_smallest_probe_wins_unless_the_variable_is_set() {
        let probes = Probes {
            cgroup: Some((6 << 30, PathBuf::from("/sys/fs/cgroup/memory.max"))),
            address_space: Some(4 << 30),
            physical: Some(16 << 30),
        };
        let l = choose(None, &probes).unwrap();
        assert_eq!((l.bytes, l.source), (4 << 30, LimitSource::AddressSpace));
        let l = choose(Some("1G"), &probes).unwrap();
        assert_eq!((l.bytes, l.source), (1 << 30, LimitSource::Environment));
        // An empty variable counts as unset; a malformed one is an error.
        assert_eq!(choose(Some(" "), &probes).unwrap().bytes, 4 << 30);
        assert!(choose(Some("much"), &probes).is_err());
        let only_physical = Probes {
            physical: Some(3 << 30),
            ..Probes::default()
        };
        let l = choose(None, &only_physical).unwrap();
        assert_eq!((l.bytes, l.source), (3 << 30, LimitSource::Physical));
        let l = choose(None, &Probes::default()).unwrap();
        assert_eq!((l.bytes, l.source), (FALLBACK_LIMIT, LimitSource::Fallback));
    }

    #[test]
    fn cgroup_limits_are_read_for_the_process_cgroup_and_its_ancestors() {
        let root = Path::new("/cg");
        let files = |entries: &'static [(&'static str, &'static str)]| {
            move |p: &Path| {
                entries
                    .iter()
                    .find(|(f, _)| Path::new(f) == p)
                    .map(|(_, v)| v.to_string())
            }
        };
        // v2: the parent's limit is the smaller one.
        let v2 = files(&[
            ("/cg/a/b/memory.max", "max\n"),
            ("/cg/a/memory.max", "2147483648\n"),
            ("/cg/memory.max", "8589934592\n"),
        ]);
        assert_eq!(
            cgroup_limit("0::/a/b\n", root, &v2),
            Some((2 << 30, PathBuf::from("/cg/a/memory.max")))
        );
        // v1 (hybrid): the memory controller's line; "unlimited" is ignored.
        let v1 = files(&[
            ("/cg/memory/job/memory.limit_in_bytes", "1073741824"),
            ("/cg/memory/memory.limit_in_bytes", "9223372036854771712"),
        ]);
        assert_eq!(
            cgroup_limit("4:memory:/job\n1:cpu,cpuacct:/\n0::/\n", root, &v1),
            Some((
                1 << 30,
                PathBuf::from("/cg/memory/job/memory.limit_in_bytes")
            ))
        );
        assert_eq!(cgroup_limit("0::/\n", root, &files(&[])), None);
    }

    #[test]
    fn meminfo_total_is_read_in_bytes() {
        let text = "MemTotal:       24683772 kB\nMemFree:  100 kB\n";
        assert_eq!(meminfo_total(text), Some(24683772 * 1024));
        assert_eq!(meminfo_total("MemFree: 1 kB\n"), None);
    }

    #[test]
    fn the_detected_limit_is_at_most_the_physical_memory() {
        let probes = probe();
        let l = choose(None, &probes).unwrap();
        if let Some(p) = probes.physical {
            assert!(l.bytes <= p, "{l:?} {probes:?}");
        }
        assert!(l.bytes > 0);
    }
}
