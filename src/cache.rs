//! The on-disk cache of analysis results (jump maps), keyed by a hash of the
//! exemplar pixels and the analysis parameters.
//!
//! A cache entry is only a hint: the reader re-validates it (magic, version,
//! key, checksum) and rebuilds on any mismatch, so a stale or corrupt file is
//! never trusted. Entries are written atomically.

use std::path::{Path, PathBuf};

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

/// Reads an entry's bytes, if the file exists and is readable.
pub fn read(dir: &Path, kind: &str, key: &[u8; 32]) -> Option<Vec<u8>> {
    std::fs::read(entry_path(dir, kind, key)).ok()
}

/// Writes an entry atomically. A failure only costs the next run a rebuild,
/// so it is logged, not returned.
pub fn write(dir: &Path, kind: &str, key: &[u8; 32], bytes: &[u8]) {
    let path = entry_path(dir, kind, key);
    if let Err(e) = crate::output::write_bytes_atomic(&path, bytes) {
        tracing::warn!("could not write cache entry {}: {e}", path.display());
    }
}
