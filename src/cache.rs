//! The on-disk cache of analysis results, keyed by a hash of the exemplar
//! pixels and the analysis parameters.
//!
//! # Where it is
//!
//! One flat folder ([`default_dir`]): `$SURFSYNTH_CACHE`, else
//! `$XDG_CACHE_HOME/surfsynth`, else `~/.cache/surfsynth`. It is created on
//! the first write.
//!
//! # What it holds
//!
//! One file per entry, named `KIND-HASH.bin` (`HASH`: 64 lowercase hex digits
//! of the BLAKE3 key), of the kinds in [`KINDS`]:
//!
//! * `jumpmap`: jump maps of the `jump_map` stage (Zelinka & Garland 2004 §4),
//! * `appearance`: appearance-space levels of the `coherent` stage and of
//!   the `jump_surface` stage's seam refinement,
//! * `patches`: texture patches of the `lapped_paste` stage.
//!
//! A cache entry is only a hint: the reader re-validates it (magic, version,
//! key, checksum) and rebuilds on any mismatch, so a stale or corrupt file is
//! never trusted. Entries are written atomically (through a temporary
//! `.KIND-HASH.bin.PID.tmp` next to the entry, renamed into place), so a
//! folder may briefly hold such a temporary file of a running write. Every
//! stage that uses the cache has a `cache` parameter to turn it off.
//!
//! # Its size
//!
//! The folder is bounded, least recently used first: a read of an entry sets
//! its modification time to now, so the time is its last use (read or
//! written); after every write the oldest entries (ties by name) are deleted
//! while the entries total more than the limit ([`limit`]): 1 GiB, or
//! `$SURFSYNTH_CACHE_LIMIT` ([`parse_limit`]: bytes, or with suffix `K`, `M`,
//! `G`; `0` writes no entry). The entry just written is never evicted, and an
//! entry larger than the limit is not written. Only files named like entries
//! are counted or deleted, plus temporary files of ours older than
//! [`STALE_TMP`] (left by a killed run); anything else in the folder is left
//! alone. Several processes may share the folder: an eviction that finds an
//! entry gone, or cannot delete it, carries on.
//!
//! `surfsynth cache` shows the folder and what it holds; `surfsynth cache
//! clear` empties it ([`summary`], [`clear`]).

use crate::cache_format::AnalysisStore;
use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime};

/// The kinds of entries this version writes, with what they hold.
pub const KINDS: [(&str, &str); 3] = [
    ("jumpmap", "jump maps of the jump_map stage"),
    (
        "appearance",
        "appearance-space levels of the coherent and jump_surface stages",
    ),
    ("patches", "texture patches of the lapped_paste stage"),
];

/// The environment variable of the size limit.
pub const LIMIT_VAR: &str = "SURFSYNTH_CACHE_LIMIT";

/// The size limit when [`LIMIT_VAR`] is not set: 1 GiB.
pub const DEFAULT_LIMIT: u64 = 1 << 30;

/// The allowed form of [`LIMIT_VAR`], for messages.
pub const LIMIT_FORM: &str = "a whole number of bytes, optionally followed by K, M or G \
     (KiB, MiB, GiB; e.g. 500M, 2G); 0 writes no cache entry";

/// Temporary files of our atomic writes older than this are leftovers of a
/// killed run (a live write takes well under a second) and are deleted by
/// eviction and by [`clear`].
pub const STALE_TMP: Duration = Duration::from_secs(3600);

/// Where cache files live: `$SURFSYNTH_CACHE`, else `$XDG_CACHE_HOME/surfsynth`,
/// else `$HOME/.cache/surfsynth`; `None` when none is set.
pub fn default_dir() -> Option<PathBuf> {
    if let Some(d) = std::env::var_os("SURFSYNTH_CACHE") {
        return Some(PathBuf::from(d));
    }
    if let Some(d) = std::env::var_os("XDG_CACHE_HOME") {
        return Some(PathBuf::from(d).join("surfsynth"));
    }
    std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cache").join("surfsynth"))
}

/// The file of a cache entry.
pub fn entry_path(dir: &Path, kind: &str, key: &[u8; 32]) -> PathBuf {
    let hex: String = key.iter().map(|b| format!("{b:02x}")).collect();
    dir.join(format!("{kind}-{hex}.bin"))
}

/// The kind of an entry's file name `KIND-HASH.bin` (`KIND`: lowercase
/// letters, digits and `_`; `HASH`: 64 lowercase hex digits), `None` for any
/// other name.
pub fn entry_kind(name: &str) -> Option<&str> {
    let stem = name.strip_suffix(".bin")?;
    let (kind, hex) = stem.rsplit_once('-')?;
    let kind_ok = !kind.is_empty()
        && kind
            .bytes()
            .all(|b| b.is_ascii_lowercase() || b.is_ascii_digit() || b == b'_');
    let hex_ok = hex.len() == 64 && hex.bytes().all(|b| matches!(b, b'0'..=b'9' | b'a'..=b'f'));
    (kind_ok && hex_ok).then_some(kind)
}

/// Whether `name` is a temporary file of an atomic write of an entry
/// (`.KIND-HASH.bin.PID.tmp`, see [`crate::output::write_atomic`]).
fn is_entry_tmp(name: &str) -> bool {
    name.strip_prefix('.')
        .and_then(|n| n.strip_suffix(".tmp"))
        .and_then(|n| n.rsplit_once('.'))
        .is_some_and(|(entry, pid)| {
            !pid.is_empty()
                && pid.bytes().all(|b| b.is_ascii_digit())
                && entry_kind(entry).is_some()
        })
}

/// Whether `path` could be an entry this cache wrote: only a regular file,
/// no larger than a non-zero limit; anything else (a symlink, a device such
/// as /dev/zero) is a miss, decided before a byte is read.
fn could_be_entry(path: &Path) -> bool {
    let limit = limit();
    std::fs::symlink_metadata(path)
        .is_ok_and(|meta| meta.file_type().is_file() && (limit == 0 || meta.len() <= limit))
}

/// Reads an entry's bytes, if the file exists and is readable, and sets its
/// modification time to now: the time is the entry's last use, which
/// eviction goes by.
pub fn read(dir: &Path, kind: &str, key: &[u8; 32]) -> Option<Vec<u8>> {
    let path = entry_path(dir, kind, key);
    if !could_be_entry(&path) {
        return None;
    }
    let bytes = std::fs::read(&path).ok()?;
    if let Err(e) = set_last_use(&path, SystemTime::now()) {
        tracing::debug!("could not refresh the time of {}: {e}", path.display());
    }
    Some(bytes)
}

/// Whether `dir` holds an entry of `kind` under `key` that starts with
/// `header` (its magic, version and key): read from its first bytes only,
/// and only from a regular file within the limit, as [`read`] would take
/// it. The rest is checked when the entry is read.
pub fn holds(dir: &Path, kind: &str, key: &[u8; 32], header: &[u8]) -> bool {
    use std::io::Read;
    let path = entry_path(dir, kind, key);
    if !could_be_entry(&path) {
        return false;
    }
    let mut start = vec![0u8; header.len()];
    std::fs::File::open(&path)
        .and_then(|mut f| f.read_exact(&mut start))
        .is_ok_and(|()| start == header)
}

/// Sets the last use of a cache file (its modification time), which
/// eviction goes by. Opens it read-only: the owner may set its times.
pub fn set_last_use(path: &Path, time: SystemTime) -> std::io::Result<()> {
    std::fs::File::open(path)?.set_modified(time)
}

/// Writes an entry atomically, then evicts the least recently used entries
/// over the size limit ([`limit`]). A failure only costs the next run a
/// rebuild, so it is logged, not returned.
pub fn write(dir: &Path, kind: &str, key: &[u8; 32], bytes: &[u8]) {
    write_with_limit(dir, kind, key, bytes, limit());
}

/// [`write`] with the size limit given: an entry larger than `limit` is not
/// written (so `0` writes nothing); after writing, [`evict`] keeps the
/// folder's entries within `limit`.
pub fn write_with_limit(dir: &Path, kind: &str, key: &[u8; 32], bytes: &[u8], limit: u64) {
    let path = entry_path(dir, kind, key);
    if bytes.len() as u64 > limit {
        tracing::debug!(
            "cache entry {} ({}) not written: over the cache limit of {} ({LIMIT_VAR})",
            path.display(),
            format_size(bytes.len() as u64),
            format_size(limit)
        );
        return;
    }
    if let Err(e) = crate::output::write_bytes_atomic(&path, bytes) {
        tracing::warn!("could not write cache entry {}: {e}", path.display());
        return;
    }
    evict(dir, limit, &path);
}

/// A file of the cache folder.
#[derive(Clone, Debug)]
pub struct Entry {
    /// The file.
    pub path: PathBuf,
    /// Its kind (`jumpmap`, ...).
    pub kind: String,
    /// Its length in bytes.
    pub size: u64,
    /// Its last use.
    pub modified: SystemTime,
}

/// The files of `dir` in the cache's care: the entries, and the temporary
/// files of entry writes older than [`STALE_TMP`]. Unreadable files are
/// passed over; a missing folder has none.
fn scan(dir: &Path) -> (Vec<Entry>, Vec<Entry>, usize) {
    let (mut entries, mut stale, mut other) = (Vec::new(), Vec::new(), 0);
    let Ok(read_dir) = std::fs::read_dir(dir) else {
        return (entries, stale, other);
    };
    let now = SystemTime::now();
    for item in read_dir.flatten() {
        let name = item.file_name();
        let name = name.to_string_lossy();
        let Ok(meta) = item.metadata() else { continue };
        let modified = meta.modified().unwrap_or(SystemTime::UNIX_EPOCH);
        let entry = |kind: &str| Entry {
            path: item.path(),
            kind: kind.to_string(),
            size: meta.len(),
            modified,
        };
        match entry_kind(&name) {
            Some(kind) if meta.is_file() => entries.push(entry(kind)),
            _ if meta.is_file() && is_entry_tmp(&name) => {
                if now
                    .duration_since(modified)
                    .is_ok_and(|age| age > STALE_TMP)
                {
                    stale.push(entry("tmp"));
                }
            }
            _ => other += 1,
        }
    }
    (entries, stale, other)
}

/// Deletes `files`, ignoring (and logging at debug) what cannot be deleted,
/// e.g. because another process deleted it first. Returns the count and
/// bytes deleted.
fn remove_all<'a>(files: impl IntoIterator<Item = &'a Entry>) -> (usize, u64) {
    let (mut count, mut bytes) = (0, 0);
    for f in files {
        match std::fs::remove_file(&f.path) {
            Ok(()) => {
                count += 1;
                bytes += f.size;
            }
            Err(e) => tracing::debug!("cache eviction: {}: {e}", f.path.display()),
        }
    }
    (count, bytes)
}

/// Deletes the least recently used entries of `dir` (oldest modification
/// time first, ties by name) while the entries total more than `limit`,
/// never `keep` (the entry just written), and stale temporary files of ours.
/// Every file-system error is ignored. Returns the count and bytes of the
/// entries deleted.
pub fn evict(dir: &Path, limit: u64, keep: &Path) -> (usize, u64) {
    let (mut entries, stale, _) = scan(dir);
    remove_all(&stale);
    let mut total: u64 = entries.iter().map(|e| e.size).sum();
    if total <= limit {
        return (0, 0);
    }
    entries.sort_by(|a, b| (a.modified, &a.path).cmp(&(b.modified, &b.path)));
    let mut victims = Vec::new();
    for e in entries.iter().filter(|e| e.path != keep) {
        if total <= limit {
            break;
        }
        total -= e.size;
        victims.push(e);
    }
    let (count, bytes) = remove_all(victims);
    tracing::debug!(
        "cache eviction in {}: {count} entries, {} freed",
        dir.display(),
        format_size(bytes)
    );
    (count, bytes)
}

/// What the cache folder holds.
#[derive(Clone, Debug, Default)]
pub struct Summary {
    /// Per kind (sorted by name): entry count and bytes.
    pub kinds: Vec<(String, usize, u64)>,
    /// Stale temporary files of ours: count and bytes.
    pub stale_tmp: (usize, u64),
    /// Files and folders that are not the cache's (left alone).
    pub other: usize,
}

impl Summary {
    /// Entry count and bytes over every kind.
    pub fn total(&self) -> (usize, u64) {
        self.kinds
            .iter()
            .fold((0, 0), |(n, b), (_, kn, kb)| (n + kn, b + kb))
    }
}

/// What `dir` holds; empty when it does not exist.
pub fn summary(dir: &Path) -> Summary {
    let (entries, stale, other) = scan(dir);
    let mut kinds: std::collections::BTreeMap<String, (usize, u64)> = Default::default();
    for e in &entries {
        let k = kinds.entry(e.kind.clone()).or_default();
        k.0 += 1;
        k.1 += e.size;
    }
    Summary {
        kinds: kinds.into_iter().map(|(k, (n, b))| (k, n, b)).collect(),
        stale_tmp: (stale.len(), stale.iter().map(|e| e.size).sum()),
        other,
    }
}

/// Deletes every entry of `dir` and the stale temporary files of ours;
/// nothing else. Returns the count and bytes deleted (entries and stale
/// temporary files together). Files that cannot be deleted are passed over.
pub fn clear(dir: &Path) -> (usize, u64) {
    let (entries, stale, _) = scan(dir);
    remove_all(entries.iter().chain(&stale))
}

/// Parses a size limit: a whole number of bytes, optionally followed by `K`,
/// `M` or `G` (binary: KiB, MiB, GiB; either case). Surrounding blanks are
/// ignored. The error is the allowed form.
pub fn parse_limit(text: &str) -> Result<u64, String> {
    let t = text.trim();
    let (digits, shift) = match t.as_bytes().last() {
        Some(b'k' | b'K') => (&t[..t.len() - 1], 10),
        Some(b'm' | b'M') => (&t[..t.len() - 1], 20),
        Some(b'g' | b'G') => (&t[..t.len() - 1], 30),
        _ => (t, 0),
    };
    let malformed = || format!("{text:?} is not a size; allowed: {LIMIT_FORM}");
    if digits.is_empty() || !digits.bytes().all(|b| b.is_ascii_digit()) {
        return Err(malformed());
    }
    digits
        .parse::<u64>()
        .ok()
        .and_then(|n| n.checked_mul(1 << shift))
        .ok_or_else(|| format!("{text:?} is too large; allowed: {LIMIT_FORM}"))
}

/// The size limit set by the environment: [`LIMIT_VAR`] parsed by
/// [`parse_limit`], [`DEFAULT_LIMIT`] when it is unset or empty. The error
/// names the value and the allowed form (the caller names the variable).
pub fn configured_limit() -> Result<u64, String> {
    match std::env::var(LIMIT_VAR) {
        Err(std::env::VarError::NotPresent) => Ok(DEFAULT_LIMIT),
        Err(std::env::VarError::NotUnicode(v)) => {
            Err(format!("{v:?} is not a size; allowed: {LIMIT_FORM}"))
        }
        Ok(v) if v.trim().is_empty() => Ok(DEFAULT_LIMIT),
        Ok(v) => parse_limit(&v),
    }
}

/// The size limit of [`write`]: [`configured_limit`], or [`DEFAULT_LIMIT`]
/// with a warning (once per process) when the variable is malformed. The
/// command line refuses a malformed value before any work
/// ([`crate::preflight::check_cache_limit`]).
pub fn limit() -> u64 {
    configured_limit().unwrap_or_else(|m| {
        static WARNED: std::sync::Once = std::sync::Once::new();
        WARNED.call_once(|| {
            tracing::warn!(
                "{LIMIT_VAR}: {m}; using the default of {}",
                format_size(DEFAULT_LIMIT)
            );
        });
        DEFAULT_LIMIT
    })
}

/// A byte count for people: `512 B`, `48.2 MiB`, `1.0 GiB` (binary units).
pub fn format_size(bytes: u64) -> String {
    const UNITS: [&str; 4] = ["KiB", "MiB", "GiB", "TiB"];
    if bytes < 1024 {
        return format!("{bytes} B");
    }
    let mut v = bytes as f64 / 1024.0;
    let mut unit = 0;
    while v >= 1024.0 && unit + 1 < UNITS.len() {
        v /= 1024.0;
        unit += 1;
    }
    format!("{v:.1} {}", UNITS[unit])
}

/// The on-disk cache in `dir`, as the [`AnalysisStore`] a kernel reads
/// and writes its analyses through: the stage decides whether there is one
/// and where; the kernel stays free of disk and environment.
#[derive(Clone, Debug)]
pub struct DiskCache(pub PathBuf);

impl DiskCache {
    /// The default folder's cache ([`default_dir`]) when `enabled`.
    pub fn if_enabled(enabled: bool) -> Option<Self> {
        enabled.then(default_dir).flatten().map(Self)
    }
}

impl AnalysisStore for DiskCache {
    fn read(&self, kind: &str, key: &[u8; 32]) -> Option<Vec<u8>> {
        read(&self.0, kind, key)
    }

    fn write(&self, kind: &str, key: &[u8; 32], bytes: &[u8]) {
        write(&self.0, kind, key, bytes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Issue 43: an entry that is not a regular file of ours (a symlink, to
    /// a valid entry or to `/dev/zero`, or a device) is a miss, not read:
    /// a symlink to `/dev/zero` was read to 2 GB before it was rejected.
    #[cfg(unix)]
    #[test]
    fn an_entry_that_is_not_a_regular_file_is_a_miss_and_is_not_read() {
        let dir = tempfile::tempdir().unwrap();
        let key = [7u8; 32];
        let real = dir.path().join("elsewhere.bin");
        std::fs::write(&real, b"bytes of a valid-looking entry").unwrap();
        std::os::unix::fs::symlink(&real, entry_path(dir.path(), "jumpmap", &key)).unwrap();
        assert_eq!(
            read(dir.path(), "jumpmap", &key),
            None,
            "a symlink is not an entry"
        );
        let zero_key = [8u8; 32];
        std::os::unix::fs::symlink("/dev/zero", entry_path(dir.path(), "jumpmap", &zero_key))
            .unwrap();
        assert_eq!(read(dir.path(), "jumpmap", &zero_key), None);
    }
    use std::time::UNIX_EPOCH;

    const KIB: usize = 1024;

    fn key(i: u8) -> [u8; 32] {
        [i; 32]
    }

    /// Sets the last use of `path` to `secs` after the epoch.
    fn stage_time(path: &Path, secs: u64) {
        set_last_use(path, UNIX_EPOCH + Duration::from_secs(secs)).unwrap();
    }

    /// A `KIB`-kibibyte entry of `key(i)`, last used at `1_000_000 + i` s.
    fn staged_entry(dir: &Path, i: u8, kib: usize) -> PathBuf {
        let path = entry_path(dir, "jumpmap", &key(i));
        std::fs::write(&path, vec![i; kib * KIB]).unwrap();
        stage_time(&path, 1_000_000 + u64::from(i));
        path
    }

    fn total(dir: &Path) -> u64 {
        summary(dir).total().1
    }

    #[test]
    fn entry_names_are_recognised_and_nothing_else() {
        let hex = "0123456789abcdef".repeat(4);
        assert_eq!(entry_kind(&format!("jumpmap-{hex}.bin")), Some("jumpmap"));
        assert_eq!(entry_kind(&format!("my_kind2-{hex}.bin")), Some("my_kind2"));
        for bad in [
            format!("-{hex}.bin"),
            format!("jumpmap-{hex}.bin.bak"),
            format!("jumpmap-{}.bin", &hex[1..]),
            format!("jumpmap-{}.bin", hex.to_uppercase()),
            format!("Jumpmap-{hex}.bin"),
            format!("jump map-{hex}.bin"),
            format!(".jumpmap-{hex}.bin.12.tmp"),
            "notes.txt".into(),
        ] {
            assert_eq!(entry_kind(&bad), None, "{bad}");
        }
        assert!(is_entry_tmp(&format!(".jumpmap-{hex}.bin.12.tmp")));
        assert!(!is_entry_tmp(&format!(".jumpmap-{hex}.bin.tmp")));
        assert!(!is_entry_tmp(".notes.txt.12.tmp"));
        // The temporary name is the one `write_atomic` uses.
        let dir = tempfile::tempdir().unwrap();
        let path = entry_path(dir.path(), "jumpmap", &key(1));
        crate::output::write_atomic(&path, |w| {
            let names: Vec<String> = std::fs::read_dir(dir.path())
                .unwrap()
                .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                .collect();
            assert_eq!(names.len(), 1);
            assert!(is_entry_tmp(&names[0]), "{names:?}");
            w.write_all(b"x")
        })
        .unwrap();
    }

    #[test]
    fn limit_sizes_parse_with_binary_suffixes() {
        assert_eq!(parse_limit("2G"), Ok(2 << 30));
        assert_eq!(parse_limit("500M"), Ok(500 << 20));
        assert_eq!(parse_limit("500m"), Ok(500 << 20));
        assert_eq!(parse_limit("64K"), Ok(64 << 10));
        assert_eq!(parse_limit("1024"), Ok(1024));
        assert_eq!(parse_limit(" 7 "), Ok(7));
        assert_eq!(parse_limit("0"), Ok(0));
        for bad in ["-1", "abc", "1T", "1.5G", "G", "", "1 G", "1GB", "+5"] {
            let e = parse_limit(bad).unwrap_err();
            assert!(e.contains(&format!("{bad:?}")), "{e}");
            assert!(e.contains("K, M or G"), "{e}");
        }
        assert!(
            parse_limit("99999999999999G")
                .unwrap_err()
                .contains("too large")
        );
    }

    #[test]
    fn a_write_evicts_the_least_recently_used_entries_over_the_limit() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        // Ten 10 KiB entries, used at times 1..=10 (entry 1 the oldest).
        let staged: Vec<PathBuf> = (1..=10).map(|i| staged_entry(d, i, 10)).collect();
        let foreign = d.join("notes.txt");
        std::fs::write(&foreign, vec![0; 200 * KIB]).unwrap();
        stage_time(&foreign, 1);
        let limit = 65 * KIB as u64;
        write_with_limit(d, "jumpmap", &key(99), &vec![9; 10 * KIB], limit);
        let new = entry_path(d, "jumpmap", &key(99));
        assert!(new.exists(), "the entry just written stays");
        // 110 KiB of entries must shrink to <= 65: the five oldest go.
        for (i, p) in staged.iter().enumerate() {
            assert_eq!(p.exists(), i >= 5, "entry {}", i + 1);
        }
        assert!(total(d) <= limit);
        assert_eq!(std::fs::read(&foreign).unwrap().len(), 200 * KIB);
        assert_eq!(summary(d).other, 1);
    }

    #[test]
    fn ties_go_by_name_and_the_new_entry_is_never_evicted() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let a = staged_entry(d, 1, 10);
        let b = staged_entry(d, 2, 10);
        stage_time(&a, 5);
        stage_time(&b, 5);
        // The new entry is the oldest in time, yet kept; of the tie, the
        // first name goes.
        let new = staged_entry(d, 3, 10);
        stage_time(&new, 1);
        assert_eq!(evict(d, 20 * KIB as u64, &new), (1, 10 * KIB as u64));
        assert!(!a.exists() && b.exists() && new.exists());
    }

    #[test]
    fn a_cache_hit_refreshes_the_entry_so_eviction_spares_it() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let read_one = staged_entry(d, 1, 10); // written first ...
        let unread = staged_entry(d, 2, 10); // ... then this one
        assert_eq!(read(d, "jumpmap", &key(1)).unwrap(), vec![1; 10 * KIB]);
        let age = SystemTime::now()
            .duration_since(std::fs::metadata(&read_one).unwrap().modified().unwrap())
            .unwrap_or_default();
        assert!(age < Duration::from_secs(60), "{age:?}");
        write_with_limit(d, "jumpmap", &key(3), &vec![3; 10 * KIB], 20 * KIB as u64);
        assert!(read_one.exists(), "the entry read survives");
        assert!(!unread.exists(), "the unread one goes");
        assert_eq!(read(d, "jumpmap", &key(2)), None);
    }

    #[test]
    fn a_zero_or_too_small_limit_writes_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path().join("new");
        write_with_limit(&d, "jumpmap", &key(1), b"abc", 0);
        assert!(!d.exists());
        write_with_limit(&d, "jumpmap", &key(1), &[0; 100], 99);
        assert!(!d.exists());
        write_with_limit(&d, "jumpmap", &key(1), &[0; 100], 100);
        assert_eq!(read(&d, "jumpmap", &key(1)).unwrap().len(), 100);
    }

    #[test]
    fn stale_temporaries_go_fresh_ones_and_foreign_files_stay() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let entry_name = |i| {
            entry_path(d, "patches", &key(i))
                .file_name()
                .unwrap()
                .to_string_lossy()
                .into_owned()
        };
        let stale = d.join(format!(".{}.42.tmp", entry_name(1)));
        let fresh = d.join(format!(".{}.43.tmp", entry_name(2)));
        let foreign_tmp = d.join(".notes.txt.44.tmp");
        for p in [&stale, &fresh, &foreign_tmp] {
            std::fs::write(p, b"partial").unwrap();
        }
        stage_time(&stale, 1);
        stage_time(&foreign_tmp, 1);
        std::fs::create_dir(d.join(entry_name(3))).unwrap();
        let s = summary(d);
        assert_eq!(s.stale_tmp, (1, 7));
        assert_eq!(s.other, 2, "the foreign temporary and the folder");
        write_with_limit(d, "patches", &key(4), b"entry", DEFAULT_LIMIT);
        assert!(!stale.exists() && fresh.exists() && foreign_tmp.exists());
        assert!(d.join(entry_name(3)).is_dir());
    }

    #[test]
    fn summary_and_clear_touch_only_entries() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        assert_eq!(summary(&d.join("none")).total(), (0, 0));
        assert_eq!(clear(&d.join("none")), (0, 0));
        staged_entry(d, 1, 2);
        staged_entry(d, 2, 3);
        std::fs::write(entry_path(d, "appearance", &key(3)), [0; 10]).unwrap();
        std::fs::write(d.join("keep.bin"), b"mine").unwrap();
        let s = summary(d);
        assert_eq!(
            s.kinds,
            vec![
                ("appearance".to_string(), 1, 10),
                ("jumpmap".to_string(), 2, 5 * KIB as u64)
            ]
        );
        assert_eq!(s.total(), (3, 5 * KIB as u64 + 10));
        assert_eq!(clear(d), (3, 5 * KIB as u64 + 10));
        assert_eq!(summary(d).total(), (0, 0));
        assert_eq!(std::fs::read(d.join("keep.bin")).unwrap(), b"mine");
    }

    #[test]
    fn sizes_read_in_binary_units() {
        assert_eq!(format_size(0), "0 B");
        assert_eq!(format_size(1023), "1023 B");
        assert_eq!(format_size(1024), "1.0 KiB");
        assert_eq!(format_size(48 * (1 << 20) + (1 << 18)), "48.2 MiB");
        assert_eq!(format_size(DEFAULT_LIMIT), "1.0 GiB");
    }
}
