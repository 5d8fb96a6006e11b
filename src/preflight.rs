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
/// exists and lets us create files. An existing path must be a regular file:
/// the trace is written beside it and renamed over it, which would replace
/// a device (`/dev/full`), a pipe or a symlink itself (issue 43).
pub fn check_file_target(path: &Path) -> Result<(), String> {
    if path.is_dir() {
        return Err(format!(
            "{} is a folder; allowed: a file path in an existing, writable folder",
            path.display()
        ));
    }
    if let Ok(meta) = std::fs::symlink_metadata(path)
        && !meta.file_type().is_file()
    {
        let what = if meta.file_type().is_symlink() {
            "a symbolic link"
        } else {
            "not a regular file (a device, pipe or socket)"
        };
        return Err(format!(
            "{} is {what}, which the trace would replace; allowed: a new file or a regular file, in an existing, writable folder",
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
/// folder, is refused; so is a mount point (another file system, or a bind
/// mount of a folder of the same one, as container volumes are), which a
/// run cannot replace by renaming (its result would be lost at the very
/// end). The run stages its files beside the folder, in the same parent,
/// so with these refused the final rename stays on one file system.
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
            "{} is a mount point (a file system or a bind mount of its own), which a run cannot replace as a whole; allowed: a folder inside it",
            target.display()
        ));
    }
    Ok(target)
}

/// Whether `dir` is an existing folder on another device than its parent,
/// or listed as a mount point in `/proc/self/mountinfo` (a bind mount keeps
/// the device number of its source, yet a rename cannot cross it).
#[cfg(unix)]
fn is_mount_point(dir: &Path) -> bool {
    use std::os::unix::fs::MetadataExt;
    let full = std::fs::canonicalize(dir).unwrap_or_else(|_| absolute(dir));
    let (Ok(own), Some(parent)) = (std::fs::metadata(&full), full.parent()) else {
        return false;
    };
    own.is_dir()
        && (std::fs::metadata(parent).is_ok_and(|p| p.dev() != own.dev())
            || mount_points().contains(&full))
}

#[cfg(not(unix))]
fn is_mount_point(_dir: &Path) -> bool {
    false
}

/// The mount points of this process's mount namespace (field 5 of
/// `/proc/self/mountinfo`, with its octal escapes such as `\040` for a
/// space undone); empty where there is no such file.
fn mount_points() -> Vec<PathBuf> {
    let Ok(text) = std::fs::read_to_string("/proc/self/mountinfo") else {
        return Vec::new();
    };
    text.lines()
        .filter_map(|line| line.split(' ').nth(4))
        .map(|field| PathBuf::from(unescape_mountinfo(field)))
        .collect()
}

/// Undoes the `\ooo` octal escapes of a mountinfo field.
fn unescape_mountinfo(field: &str) -> std::ffi::OsString {
    let bytes = field.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        let octal = bytes.get(i + 1..i + 4).and_then(|d| {
            d.iter()
                .all(|b| (b'0'..=b'7').contains(b))
                .then(|| d.iter().fold(0u32, |v, b| v * 8 + u32::from(b - b'0')))
        });
        match (bytes[i], octal) {
            (b'\\', Some(v)) if v <= 0xFF => {
                out.push(v as u8);
                i += 4;
            }
            (b, _) => {
                out.push(b);
                i += 1;
            }
        }
    }
    #[cfg(unix)]
    {
        use std::os::unix::ffi::OsStringExt;
        std::ffi::OsString::from_vec(out)
    }
    #[cfg(not(unix))]
    {
        String::from_utf8_lossy(&out).into_owned().into()
    }
}

/// A folder to be created or filled (`--out DIR`, `[output] dir`, the sweep
/// folder): not an existing file; a new one's nearest existing ancestor
/// lets us create files; an existing one lets us, and so does its parent
/// (a run writes beside it, then deletes the earlier result's files in
/// it). Probed by creating and removing a temporary file: permission bits
/// do not tell about read-only mounts, ACLs or root. The message names
/// `dir`, the folder that refused and why (read-only file system,
/// permission).
pub fn check_folder_target(dir: &Path) -> Result<(), String> {
    let allowed = "allowed: a new folder whose nearest existing parent is writable, or a writable folder in a writable parent";
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
    if ancestor != absolute(dir) {
        return probe_writable(&ancestor).map_err(|e| {
            format!(
                "{} cannot be created: cannot create files in {}, which {}; {allowed}",
                dir.display(),
                ancestor.display(),
                why_unwritable(&e)
            )
        });
    }
    // A run writes into a sibling of the folder (see `output::staging`), so
    // the parent must be writable even when the folder exists; and it
    // deletes the earlier result's files in the folder itself.
    let parent = parent_or_current(&ancestor);
    probe_writable(&parent).map_err(|e| {
        format!(
            "{} cannot be replaced: cannot create files in its parent folder {}, which {}, and a run writes its result there before it moves it into place; {allowed}",
            dir.display(),
            parent.display(),
            why_unwritable(&e)
        )
    })?;
    probe_writable(dir).map_err(|e| {
        format!(
            "{} cannot be replaced: cannot create files in it, as it {}, and a run deletes the earlier result's files in it; {allowed}",
            dir.display(),
            why_unwritable(&e)
        )
    })
}

/// What an error of [`probe_writable`] says about the folder.
fn why_unwritable(e: &std::io::Error) -> String {
    match e.kind() {
        std::io::ErrorKind::ReadOnlyFilesystem => "is on a read-only file system".into(),
        std::io::ErrorKind::PermissionDenied => "is not writable (permission denied)".into(),
        _ => format!("is not writable ({e})"),
    }
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
        // Issue 43: a device or a symlink would be replaced by the trace.
        #[cfg(unix)]
        {
            let e = check_file_target(Path::new("/dev/null")).unwrap_err();
            assert!(
                e.contains("not a regular file") && e.contains("allowed"),
                "{e}"
            );
            let real = dir.join("real.json");
            std::fs::write(&real, "[]").unwrap();
            let link = dir.join("link.json");
            std::os::unix::fs::symlink(&real, &link).unwrap();
            assert!(
                check_file_target(&link)
                    .unwrap_err()
                    .contains("symbolic link")
            );
            assert!(check_file_target(&real).is_ok());
        }
        assert!(check_file_target(&dir.join("none/t.json")).is_err());
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn mountinfo_escapes_are_undone() {
        assert_eq!(unescape_mountinfo("/mnt/a\\040b"), "/mnt/a b");
        assert_eq!(unescape_mountinfo("/x\\134y\\011"), "/x\\y\t");
        assert_eq!(unescape_mountinfo("/plain\\9"), "/plain\\9");
    }
}
