//! Checks of command-line paths and options made before any work: a run
//! that cannot write its results, its trace, or start its thread pool is
//! refused before it loads a mesh or runs a stage (exit 2), not after.
//!
//! Each check returns the message of the refusal: what is wrong and what is
//! allowed. The caller names the option (`--out`, `--trace`, `--threads`,
//! `output.dir`), or the message names the environment variable
//! (`SURFSYNTH_CACHE_LIMIT`).

use std::path::{Path, PathBuf};

/// The largest `--threads` (of `run` and `sweep`). Results do not depend on
/// the thread count, so more threads than cores only cost memory and
/// start-up time; 1024 is far above any machine this runs on and keeps a
/// mistyped value (`--threads 100000`) from spending a minute creating
/// threads.
pub const MAX_THREADS: usize = 1024;

/// `--threads N`: `1..=MAX_THREADS`.
pub fn check_threads(n: usize) -> Result<(), String> {
    if (1..=MAX_THREADS).contains(&n) {
        Ok(())
    } else {
        Err(format!("{n} is out of range; allowed: 1..={MAX_THREADS}"))
    }
}

/// The analysis cache's size limit, `$SURFSYNTH_CACHE_LIMIT`
/// ([`crate::cache::configured_limit`]): unset, or a size such as `500M`.
/// The library falls back to the default with a warning; the command line
/// refuses a malformed value here, before any work.
pub fn check_cache_limit() -> Result<u64, String> {
    crate::cache::configured_limit()
}

/// A file to be written (`--trace FILE`): not a folder, and its parent folder
/// exists and lets us create files.
pub fn check_file_target(path: &Path) -> Result<(), String> {
    if path.is_dir() {
        return Err(format!(
            "{} is a folder; allowed: a file path in an existing, writable folder",
            path.display()
        ));
    }
    let parent = parent_or_current(path);
    if !parent.is_dir() {
        return Err(format!(
            "folder {} does not exist; allowed: a file path in an existing, writable folder",
            parent.display()
        ));
    }
    probe_writable(&parent).map_err(|e| {
        format!(
            "cannot create files in {} ({e}); allowed: a file path in an existing, writable folder",
            parent.display()
        )
    })
}

/// A file to be written during a run (`--trace FILE`) must not lie inside
/// its output folder `dir`: the run replaces that folder as a whole when it
/// commits, so the file would vanish with the earlier result. Paths are
/// compared absolute, through symlinks where they exist.
pub fn check_file_outside(path: &Path, dir: &Path) -> Result<(), String> {
    let resolve = |p: &Path| std::fs::canonicalize(p).unwrap_or_else(|_| absolute(p));
    let parent = resolve(&parent_or_current(path));
    let dir = resolve(dir);
    if parent.starts_with(&dir) {
        return Err(format!(
            "{} lies inside the output folder {}, which the run replaces as a whole; allowed: a file outside it",
            path.display(),
            dir.display()
        ));
    }
    Ok(())
}

/// The output folder a run really writes: `dir` itself, or, when `dir` is a
/// symlink to a folder, that folder (the run writes through the link,
/// which stays). A symlink to nothing, or to something other than a
/// folder, is refused; so is a mount point, which a run cannot replace by
/// renaming (its result would be lost at the very end).
pub fn resolve_output_folder(dir: &Path) -> Result<PathBuf, String> {
    let allowed = "allowed: a folder (existing or new) whose nearest existing parent is writable, or a symlink to one";
    let Ok(meta) = std::fs::symlink_metadata(dir) else {
        return Ok(dir.to_path_buf());
    };
    let target = if meta.file_type().is_symlink() {
        let to = std::fs::read_link(dir).unwrap_or_default();
        match std::fs::canonicalize(dir) {
            Ok(t) if t.is_dir() => t,
            Ok(t) => {
                return Err(format!(
                    "{} is a symlink to {}, which is not a folder; {allowed}",
                    dir.display(),
                    t.display()
                ));
            }
            Err(_) => {
                return Err(format!(
                    "{} is a symlink to {}, which does not exist; {allowed}",
                    dir.display(),
                    to.display()
                ));
            }
        }
    } else {
        dir.to_path_buf()
    };
    if is_mount_point(&target) {
        return Err(format!(
            "{} is a mount point (a file system of its own), which a run cannot replace as a whole; allowed: a folder inside it",
            target.display()
        ));
    }
    Ok(target)
}

/// Whether `dir` is an existing folder on another device than its parent.
#[cfg(unix)]
fn is_mount_point(dir: &Path) -> bool {
    use std::os::unix::fs::MetadataExt;
    let full = std::fs::canonicalize(dir).unwrap_or_else(|_| absolute(dir));
    let (Ok(own), Some(parent)) = (std::fs::metadata(&full), full.parent()) else {
        return false;
    };
    own.is_dir() && std::fs::metadata(parent).is_ok_and(|p| p.dev() != own.dev())
}

#[cfg(not(unix))]
fn is_mount_point(_dir: &Path) -> bool {
    false
}

/// A folder to be created or filled (`--out DIR`, `[output] dir`, the sweep
/// folder): not an existing file, and its nearest existing ancestor lets us
/// create files (probed by creating and removing a temporary file).
pub fn check_folder_target(dir: &Path) -> Result<(), String> {
    let allowed = "allowed: a folder (existing or new) whose nearest existing parent is writable";
    if dir.exists() && !dir.is_dir() {
        return Err(format!("{} is a file; {allowed}", dir.display()));
    }
    let mut ancestor = absolute(dir);
    while !ancestor.exists() {
        match ancestor.parent() {
            Some(p) => ancestor = p.to_path_buf(),
            None => return Err(format!("no part of {} exists; {allowed}", dir.display())),
        }
    }
    if !ancestor.is_dir() {
        return Err(format!(
            "{} is a file, so {} cannot be created; {allowed}",
            ancestor.display(),
            dir.display()
        ));
    }
    // A run writes into a sibling of the folder (see `output::staging`), so
    // the parent must be writable even when the folder exists.
    let probe_in = if ancestor == absolute(dir) {
        parent_or_current(&ancestor)
    } else {
        ancestor
    };
    probe_writable(&probe_in).map_err(|e| {
        format!(
            "cannot create files in {} ({e}); {allowed}",
            probe_in.display()
        )
    })
}

/// The parent of `path`, `.` for a bare name.
fn parent_or_current(path: &Path) -> PathBuf {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

fn absolute(path: &Path) -> PathBuf {
    std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf())
}

/// Creates and removes a temporary file in `dir`: permission bits do not
/// tell about read-only mounts, ACLs or root, trying does.
fn probe_writable(dir: &Path) -> std::io::Result<()> {
    let probe = dir.join(format!(".surfsynth-probe.{}", std::process::id()));
    std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&probe)?;
    std::fs::remove_file(&probe)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn threads_range_is_inclusive() {
        assert!(check_threads(1).is_ok());
        assert!(check_threads(MAX_THREADS).is_ok());
        assert!(check_threads(0).unwrap_err().contains("1..=1024"));
        assert!(check_threads(MAX_THREADS + 1).is_err());
    }

    #[test]
    fn folder_target_refuses_a_file_and_accepts_a_new_nested_folder() {
        let dir = std::env::temp_dir().join(format!("surfsynth-preflight-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("f");
        std::fs::write(&file, b"x").unwrap();
        assert!(
            check_folder_target(&file)
                .unwrap_err()
                .contains("is a file")
        );
        assert!(check_folder_target(&file.join("sub")).is_err());
        assert!(check_folder_target(&dir.join("a/b/c")).is_ok());
        assert!(check_file_target(&dir).unwrap_err().contains("is a folder"));
        assert!(check_file_target(&dir.join("none/t.json")).is_err());
        let _ = std::fs::remove_dir_all(&dir);
    }
}
