//! Whole-run atomicity: a run writes every file into a hidden sibling folder
//! `.DIR.tmp-PID.N` and moves it to `DIR` at the end, so a reader sees either
//! the previous complete result or the new one, never a mix, and a run that
//! fails or is killed leaves no folder with final names.
//!
//! When `DIR` already holds an earlier run, the two folders trade places in
//! one step (Linux `renameat2(RENAME_EXCHANGE)`; elsewhere, or on a file
//! system without it, the earlier one is first renamed aside to
//! `.DIR.old-PID.N`), and the earlier result, now under the temporary name,
//! is deleted. A run refuses to replace a folder that does not look like a
//! run's output (see [`check_replaceable`]), so `--out ~/Documents` cannot
//! delete files.
//!
//! One lock orders everything that changes these folders: creating the
//! temporary folder, creating or renaming a file in it
//! ([`guarded`], which [`crate::output::write_atomic`] goes through), the
//! commit with the deletion of the earlier result, and the interrupt
//! handler's clean-up. The handler ([`exit_cleanly_on_signals`]) takes the
//! lock, marks the process interrupted, deletes the temporary folders and
//! exits *holding* it, so no file is created in a folder being deleted, no
//! folder is recreated after it, and no commit moves a half-deleted folder
//! into place: after a signal at any moment there is either the complete
//! new folder or nothing new, beside an untouched earlier result.
//!
//! Stale siblings (the owning process is gone, or started after the folder
//! was last written, so it is a reused PID) are removed when the next run
//! into the same `DIR` begins; a stale `.DIR.old-PID.N` whose `DIR` is
//! missing (the process died between the two renames of the fallback) is
//! renamed back first ([`recover`], which a run calls before it checks
//! anything else, so even a run refused for its config puts it back).

use super::OutputError;
use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

/// Folders to remove when the process is interrupted (see [`abandon_active`]):
/// each active run's temporary folder, then the parents it created. Its lock
/// is the one lock of the module docs.
static ACTIVE: Mutex<Vec<Vec<PathBuf>>> = Mutex::new(Vec::new());

/// Set (under the lock) once the process is interrupted: from then on no
/// file is created or renamed through [`guarded`], and nothing is committed.
static INTERRUPTED: AtomicBool = AtomicBool::new(false);

/// Distinguishes two runs of one process into the same folder.
static SEQUENCE: AtomicU64 = AtomicU64::new(0);

const TMP_TAG: &str = ".tmp-";
const OLD_TAG: &str = ".old-";

/// Longest folder name whose hidden siblings keep it whole: `.` + the
/// name + a tag, a PID (at most 10 digits) and a sequence number (at most
/// 20) stay within NAME_MAX (255 bytes) up to 218 bytes.
const MAX_WHOLE_STEM: usize = 200;

/// The part of a hidden sibling's name that stands for the folder name
/// `name` (`.STEM.tmp-PID.N`): the name itself up to [`MAX_WHOLE_STEM`]
/// bytes; a longer one (file systems allow 255) is cut at a character
/// boundary and followed by `~` and 16 hex digits of its BLAKE3 hash, so
/// that the sibling's name fits and still belongs to that folder alone
/// (issue 43: a 250-byte `--out` failed "File name too long", exit 1).
fn sibling_stem(name: &std::ffi::OsStr) -> OsString {
    if name.len() <= MAX_WHOLE_STEM {
        return name.to_os_string();
    }
    let lossy = name.to_string_lossy();
    let mut keep = MAX_WHOLE_STEM - 17;
    while !lossy.is_char_boundary(keep) {
        keep -= 1;
    }
    let hash = blake3::hash(name.as_encoded_bytes()).to_hex();
    OsString::from(format!("{}~{}", &lossy[..keep], &hash[..16]))
}

/// The output folder of one run while it is being written.
#[derive(Debug)]
pub struct RunFolder {
    final_dir: PathBuf,
    tmp_dir: PathBuf,
    /// Ancestors of `final_dir` this run created, deepest first; removed
    /// again (when empty) if the run does not commit.
    created: Vec<PathBuf>,
    committed: bool,
}

impl RunFolder {
    /// Cleans stale siblings of `dir`, creates its missing parents and the
    /// temporary folder. Fails when `dir` is a file, has no folder name, or
    /// holds something other than an earlier run, when the temporary folder
    /// is on another file system than an existing `dir` (the final move
    /// could not be a rename), or when the process was interrupted.
    pub fn begin(dir: &Path) -> Result<Self, OutputError> {
        let (parent, name) = split(dir)?;
        check_replaceable(dir).map_err(|m| io_error(dir, m))?;
        clean_stale(&parent, &name, dir);
        let pid = std::process::id();
        let seq = SEQUENCE.fetch_add(1, Ordering::Relaxed);
        let mut tmp_name = OsString::from(".");
        tmp_name.push(sibling_stem(&name));
        tmp_name.push(format!("{TMP_TAG}{pid}.{seq}"));
        let tmp_dir = parent.join(tmp_name);
        // Under the lock: an interrupt either comes first (nothing is
        // created) or finds the folder registered (and removes it).
        let mut active = lock_active();
        if INTERRUPTED.load(Ordering::SeqCst) {
            return Err(interrupted_error(dir));
        }
        let created = create_parents(&parent).map_err(|e| OutputError::Io {
            path: parent.clone(),
            source: e,
        })?;
        if let Err(source) = std::fs::create_dir(&tmp_dir) {
            remove_created(&created);
            return Err(OutputError::Io {
                path: tmp_dir,
                source,
            });
        }
        let mut registered = vec![tmp_dir.clone()];
        registered.extend(created.iter().cloned());
        active.push(registered);
        drop(active);
        let folder = Self {
            final_dir: dir.to_path_buf(),
            tmp_dir,
            created,
            committed: false,
        };
        // `preflight` refuses mount points; this catches a library caller
        // (or a mount made meanwhile) before the work, not at the commit.
        same_file_system(&folder.tmp_dir, dir).map_err(|m| io_error(dir, m))?;
        Ok(folder)
    }

    /// Where the run writes its files.
    pub fn path(&self) -> &Path {
        &self.tmp_dir
    }

    /// The folder the files will have once committed.
    pub fn final_dir(&self) -> &Path {
        &self.final_dir
    }

    /// Moves the finished folder into place: it trades places with the
    /// earlier run (if any), which is then deleted. All under the lock, so
    /// an interrupt waits for the whole of it (and the process then exits
    /// with the new folder complete and nothing left beside it).
    pub fn commit(mut self) -> Result<PathBuf, OutputError> {
        let mut active = lock_active();
        if INTERRUPTED.load(Ordering::SeqCst) {
            return Err(interrupted_error(&self.final_dir));
        }
        let io = |path: &Path| {
            let path = path.to_path_buf();
            move |source| OutputError::Io { path, source }
        };
        let earlier = if self.final_dir.exists() {
            match exchange(&self.tmp_dir, &self.final_dir) {
                // The earlier result is now under the temporary name.
                Ok(()) => Some(self.tmp_dir.clone()),
                Err(_) => Some(self.set_aside_and_rename().map_err(io(&self.final_dir))?),
            }
        } else {
            std::fs::rename(&self.tmp_dir, &self.final_dir).map_err(io(&self.final_dir))?;
            None
        };
        self.committed = true;
        if let Some(earlier) = earlier
            && let Err(e) = std::fs::remove_dir_all(&earlier)
        {
            tracing::warn!(
                "the earlier result moved to {} could not be deleted: {e}",
                earlier.display()
            );
        }
        active.retain(|paths| paths.first() != Some(&self.tmp_dir));
        drop(active);
        Ok(self.final_dir.clone())
    }

    /// The two-rename fallback of [`commit`](Self::commit): the earlier
    /// folder to `.DIR.old-PID.N`, the new one to `DIR` (on failure the
    /// earlier one back). Returns where the earlier one is.
    fn set_aside_and_rename(&self) -> std::io::Result<PathBuf> {
        let (parent, name) = split(&self.final_dir).map_err(std::io::Error::other)?;
        let mut old_name = OsString::from(".");
        old_name.push(sibling_stem(&name));
        old_name.push(format!(
            "{OLD_TAG}{}.{}",
            std::process::id(),
            SEQUENCE.fetch_add(1, Ordering::Relaxed)
        ));
        let old = parent.join(old_name);
        std::fs::rename(&self.final_dir, &old)?;
        if let Err(e) = std::fs::rename(&self.tmp_dir, &self.final_dir) {
            let _ = std::fs::rename(&old, &self.final_dir);
            return Err(e);
        }
        Ok(old)
    }
}

impl Drop for RunFolder {
    fn drop(&mut self) {
        if self.committed {
            return;
        }
        let mut active = lock_active();
        remove_all(&self.tmp_dir, &self.created);
        active.retain(|paths| paths.first() != Some(&self.tmp_dir));
    }
}

/// Runs `op` (creating or renaming a file) under the lock of the module
/// docs, unless the process was interrupted: then it fails with
/// [`std::io::ErrorKind::Interrupted`] without running. Keep `op` short:
/// an interrupt waits for it.
pub fn guarded<T>(op: impl FnOnce() -> std::io::Result<T>) -> std::io::Result<T> {
    let _active = lock_active();
    if INTERRUPTED.load(Ordering::SeqCst) {
        return Err(std::io::Error::new(
            std::io::ErrorKind::Interrupted,
            "the run was interrupted",
        ));
    }
    op()
}

/// Marks the process interrupted and removes the temporary folder of every
/// run in progress (and the parents they created); afterwards no file is
/// created through [`guarded`] and no run commits. For an interrupt handler
/// that then exits the process.
pub fn abandon_active() {
    let mut active = lock_active();
    abandon(&mut active);
}

fn abandon(active: &mut Vec<Vec<PathBuf>>) {
    INTERRUPTED.store(true, Ordering::SeqCst);
    for paths in active.drain(..) {
        if let Some((tmp, created)) = paths.split_first() {
            remove_all(tmp, created);
        }
    }
}

/// On SIGINT, SIGTERM and SIGHUP: removes the temporary folders of the runs
/// in progress and exits with 128 + the signal number (130, 143, 129),
/// holding the lock of the module docs until the process is gone (a commit
/// under way finishes first; the new folder is then complete). For the
/// `run` command; a library user installs its own handler and calls
/// [`abandon_active`].
#[cfg(unix)]
pub fn exit_cleanly_on_signals() -> std::io::Result<()> {
    use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM};
    let mut signals = signal_hook::iterator::Signals::new([SIGINT, SIGTERM, SIGHUP])?;
    std::thread::Builder::new()
        .name("signals".into())
        .spawn(move || {
            if let Some(signal) = signals.forever().next() {
                let mut active = lock_active();
                abandon(&mut active);
                // `exit` does not return: the lock stays held, so no other
                // thread creates, renames or commits before the process ends.
                std::process::exit(128 + signal);
            }
        })?;
    Ok(())
}

/// Without Unix signals there is nothing to install; the next run cleans up.
#[cfg(not(unix))]
pub fn exit_cleanly_on_signals() -> std::io::Result<()> {
    Ok(())
}

/// Puts back an earlier result of `dir` that a run which died between the
/// two renames of a commit left set aside, and removes the temporary
/// folders of runs that are gone. A run calls it first, before checking its
/// config and options, so even a run refused for those restores it. A
/// symlink `dir` is followed (also when its folder is the one set aside).
pub fn recover(dir: &Path) {
    let dir = match std::fs::read_link(dir) {
        Ok(to) if to.is_absolute() => to,
        Ok(to) => dir.parent().unwrap_or(Path::new("")).join(to),
        Err(_) => dir.to_path_buf(),
    };
    clean_stale_siblings(&dir);
}

fn interrupted_error(dir: &Path) -> OutputError {
    OutputError::Io {
        path: dir.to_path_buf(),
        source: std::io::Error::new(std::io::ErrorKind::Interrupted, "the run was interrupted"),
    }
}

/// Swaps two existing folders in one step (Linux: `renameat2` with
/// `RENAME_EXCHANGE`). Fails where the system or the file system cannot.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
fn exchange(a: &Path, b: &Path) -> std::io::Result<()> {
    use std::os::unix::ffi::OsStrExt;
    let a = std::ffi::CString::new(a.as_os_str().as_bytes())?;
    let b = std::ffi::CString::new(b.as_os_str().as_bytes())?;
    // SAFETY: both are valid NUL-terminated paths that outlive the call;
    // AT_FDCWD makes relative paths relative to the working folder.
    let r = unsafe {
        libc::renameat2(
            libc::AT_FDCWD,
            a.as_ptr(),
            libc::AT_FDCWD,
            b.as_ptr(),
            libc::RENAME_EXCHANGE,
        )
    };
    if r == 0 {
        Ok(())
    } else {
        Err(std::io::Error::last_os_error())
    }
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
fn exchange(_a: &Path, _b: &Path) -> std::io::Result<()> {
    Err(std::io::ErrorKind::Unsupported.into())
}

/// `Err` naming both when the existing `dir` and the new `tmp` beside it
/// are on different file systems (a bind mount at `dir` has its own device
/// number too), so the final rename would fail.
#[cfg(unix)]
fn same_file_system(tmp: &Path, dir: &Path) -> Result<(), String> {
    use std::os::unix::fs::MetadataExt;
    match (std::fs::metadata(tmp), std::fs::metadata(dir)) {
        (Ok(t), Ok(d)) if t.dev() != d.dev() => Err(format!(
            "{} is on another file system than its parent folder {}, where the run writes before it moves the result into place; allowed: a folder on the same file system as its parent",
            dir.display(),
            tmp.parent().unwrap_or(Path::new("")).display()
        )),
        _ => Ok(()),
    }
}

#[cfg(not(unix))]
fn same_file_system(_tmp: &Path, _dir: &Path) -> Result<(), String> {
    Ok(())
}

/// The file a run writes last into its output folder: the format's name and
/// every file the run wrote. Only a folder it describes is replaced.
pub const RUN_MARKER: &str = "surfsynth_run.json";

/// The `format` field of [`RUN_MARKER`].
const RUN_MARKER_FORMAT: &str = "surfsynth run output";

/// The files a sweep writes into a run's folder around the run
/// (`sweep::execute`): allowed beside a run's output when the folder's
/// `run.json` is a sweep's record.
const SWEEP_FILES: [&str; 4] = ["run.json", "log.txt", "done.json", "failed.json"];

/// Writes [`RUN_MARKER`] into `staged`, listing `files` (paths inside it)
/// and itself; returns its path.
pub fn write_run_marker(
    staged: &Path,
    files: &[PathBuf],
) -> Result<PathBuf, crate::output::OutputError> {
    let mut names: Vec<String> = files
        .iter()
        .filter_map(|f| f.strip_prefix(staged).ok())
        .map(|rel| rel.to_string_lossy().into_owned())
        .collect();
    names.push(RUN_MARKER.to_string());
    names.sort();
    names.dedup();
    let json = serde_json::json!({ "format": RUN_MARKER_FORMAT, "version": 1, "files": names });
    let path = staged.join(RUN_MARKER);
    crate::output::write_bytes_atomic(&path, json.to_string().as_bytes())?;
    Ok(path)
}

/// The files a run's marker in `dir` lists, if it is one.
fn marked_files(dir: &Path) -> Option<Vec<String>> {
    let text = std::fs::read_to_string(dir.join(RUN_MARKER)).ok()?;
    let json: serde_json::Value = serde_json::from_str(&text).ok()?;
    (json["format"] == RUN_MARKER_FORMAT).then(|| {
        json["files"]
            .as_array()
            .map(|a| {
                a.iter()
                    .filter_map(|f| f.as_str().map(String::from))
                    .collect()
            })
            .unwrap_or_default()
    })
}

/// Whether `dir`'s `run.json` is a sweep's record of a run (the folder is
/// then the sweep's, which empties it before the run).
pub fn holds_sweep_record(dir: &Path) -> bool {
    std::fs::read_to_string(dir.join(SWEEP_FILES[0]))
        .ok()
        .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
        .is_some_and(|j| j.get("config_hash").is_some() && j.get("overrides").is_some())
}

/// Whether a run may replace `dir`: it does not exist, is an empty folder,
/// or holds nothing but files an earlier run listed in its [`RUN_MARKER`]
/// (and, in a sweep's run folder, the sweep's own records). Anything else,
/// marker or not, is refused: a run replaces the whole folder.
pub fn check_replaceable(dir: &Path) -> Result<(), String> {
    if !dir.exists() {
        return Ok(());
    }
    if !dir.is_dir() {
        return Err(format!(
            "{} is a file; allowed: a new folder, an empty one, or the folder of an earlier run",
            dir.display()
        ));
    }
    let mut allowed = marked_files(dir).unwrap_or_default();
    if holds_sweep_record(dir) {
        allowed.extend(SWEEP_FILES.map(String::from));
    }
    let entries =
        std::fs::read_dir(dir).map_err(|e| format!("cannot read {}: {e}", dir.display()))?;
    let mut foreign = Vec::new();
    for entry in entries {
        let entry = entry.map_err(|e| format!("cannot read {}: {e}", dir.display()))?;
        let name = entry.file_name().to_string_lossy().into_owned();
        let is_file = entry.file_type().is_ok_and(|t| t.is_file());
        if !(is_file && allowed.contains(&name)) {
            foreign.push(name);
        }
    }
    if !foreign.is_empty() {
        foreign.sort();
        let more = foreign.len().saturating_sub(5);
        foreign.truncate(5);
        let more = if more > 0 {
            format!(" and {more} more")
        } else {
            String::new()
        };
        return Err(format!(
            "{} holds files that are not the output of a run ({}{more}), and a run replaces the whole folder; \
             allowed: a new folder, an empty one, or the folder of an earlier run (which lists its files in {RUN_MARKER}; a folder written by an older surfsynth has none: delete it or choose another)",
            dir.display(),
            foreign.join(", ")
        ));
    }
    Ok(())
}

/// Removes the stale temporary siblings of `dir` now (e.g. after a child run
/// into `dir` was killed), as the next run into `dir` would.
pub fn clean_stale_siblings(dir: &Path) {
    if let Ok((parent, name)) = split(dir) {
        clean_stale(&parent, &name, dir);
    }
}

fn lock_active() -> std::sync::MutexGuard<'static, Vec<Vec<PathBuf>>> {
    ACTIVE.lock().unwrap_or_else(|e| e.into_inner())
}

fn io_error(path: &Path, message: String) -> OutputError {
    OutputError::Io {
        path: path.to_path_buf(),
        source: std::io::Error::other(message),
    }
}

/// The absolute parent and the name of `dir` (`.` and `..` resolved when
/// they exist).
fn split(dir: &Path) -> Result<(PathBuf, OsString), OutputError> {
    let abs = std::path::absolute(dir).map_err(|e| OutputError::Io {
        path: dir.to_path_buf(),
        source: e,
    })?;
    let abs = match abs.canonicalize() {
        Ok(c) => c,
        Err(_) => abs,
    };
    match (abs.parent(), abs.file_name()) {
        (Some(p), Some(n)) => Ok((p.to_path_buf(), n.to_os_string())),
        _ => Err(io_error(
            dir,
            "names no folder; allowed: a path ending in a folder name".into(),
        )),
    }
}

/// `create_dir_all` that returns what it created, deepest first.
fn create_parents(dir: &Path) -> std::io::Result<Vec<PathBuf>> {
    let mut missing = Vec::new();
    let mut p = dir;
    while !p.exists() {
        missing.push(p.to_path_buf());
        match p.parent() {
            Some(q) => p = q,
            None => break,
        }
    }
    std::fs::create_dir_all(dir)?;
    Ok(missing)
}

fn remove_all(tmp: &Path, created: &[PathBuf]) {
    let _ = std::fs::remove_dir_all(tmp);
    remove_created(created);
}

/// Removes the parents a run created, deepest first, each only when empty:
/// another process may have put files there meanwhile.
fn remove_created(created: &[PathBuf]) {
    for dir in created {
        let _ = std::fs::remove_dir(dir);
    }
}

/// Removes the stale temporary and set-aside siblings of `.NAME` in `parent`.
fn clean_stale(parent: &Path, name: &std::ffi::OsStr, dir: &Path) {
    let Ok(entries) = std::fs::read_dir(parent) else {
        return;
    };
    let prefix = format!(".{}", sibling_stem(name).to_string_lossy());
    let mut stale_old = Vec::new();
    for entry in entries.flatten() {
        let file_name = entry.file_name().to_string_lossy().into_owned();
        let Some(rest) = file_name.strip_prefix(&prefix) else {
            continue;
        };
        let (is_old, tail) = if let Some(t) = rest.strip_prefix(TMP_TAG) {
            (false, t)
        } else if let Some(t) = rest.strip_prefix(OLD_TAG) {
            (true, t)
        } else {
            continue;
        };
        let Some(pid) = tail.split('.').next().and_then(|p| p.parse::<u32>().ok()) else {
            continue;
        };
        let path = entry.path();
        if !is_stale(pid, &path) {
            continue;
        }
        if is_old {
            stale_old.push(path);
        } else {
            tracing::info!("removing {}, left by an interrupted run", path.display());
            let _ = std::fs::remove_dir_all(&path);
        }
    }
    for old in stale_old {
        if !dir.exists() && std::fs::rename(&old, dir).is_ok() {
            tracing::info!(
                "restored {} from {}, set aside by an interrupted run",
                dir.display(),
                old.display()
            );
            continue;
        }
        let _ = std::fs::remove_dir_all(&old);
    }
}

/// A sibling is stale when process `pid` is not running, or started after
/// the folder was last modified (its PID was reused). Without `/proc`
/// nothing can be told, and nothing is removed.
fn is_stale(pid: u32, folder: &Path) -> bool {
    if pid == std::process::id() {
        return false;
    }
    if !Path::new("/proc/self").exists() {
        return false;
    }
    let proc_dir = PathBuf::from(format!("/proc/{pid}"));
    if !proc_dir.exists() {
        return true;
    }
    let (Some(started), Ok(modified)) = (
        process_start(pid),
        std::fs::metadata(folder).and_then(|m| m.modified()),
    ) else {
        return false;
    };
    started > modified + std::time::Duration::from_secs(2)
}

/// When process `pid` started (Linux: `/proc/PID/stat` field 22, in clock
/// ticks after boot; `/proc/stat` `btime`, the boot time). The tick is the
/// kernel's fixed user-space `USER_HZ`, 100 on every mainstream architecture.
fn process_start(pid: u32) -> Option<std::time::SystemTime> {
    const USER_HZ: u64 = 100;
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // The command name (field 2) is parenthesised and may hold spaces.
    let after = &stat[stat.rfind(')')? + 1..];
    let ticks: u64 = after.split_whitespace().nth(19)?.parse().ok()?;
    let boot: u64 = std::fs::read_to_string("/proc/stat")
        .ok()?
        .lines()
        .find_map(|l| l.strip_prefix("btime "))?
        .trim()
        .parse()
        .ok()?;
    let millis = boot * 1000 + ticks * 1000 / USER_HZ;
    Some(std::time::UNIX_EPOCH + std::time::Duration::from_millis(millis))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sibling_names_fit_and_stay_apart_for_names_of_any_legal_length() {
        assert_eq!(sibling_stem("out".as_ref()), "out");
        let long = |c: &str| "é".repeat(100) + c + &"n".repeat(54);
        let (a, b) = (long("a"), long("b"));
        assert_eq!(a.len(), 255);
        let (sa, sb) = (sibling_stem(a.as_ref()), sibling_stem(b.as_ref()));
        assert_ne!(sa, sb, "two long names sharing a prefix");
        let worst = format!(
            ".{}{TMP_TAG}{}.{}",
            sa.to_string_lossy(),
            u32::MAX,
            u64::MAX
        );
        assert!(worst.len() <= 255, "{}", worst.len());
    }

    #[test]
    fn this_process_started_before_now_and_after_boot() {
        let started = process_start(std::process::id());
        if Path::new("/proc/self").exists() {
            let s = started.expect("a start time");
            assert!(s <= std::time::SystemTime::now() + std::time::Duration::from_secs(2));
            assert!(s > std::time::UNIX_EPOCH);
        }
    }

    #[test]
    fn a_folder_of_other_files_is_not_replaced() {
        let dir = std::env::temp_dir().join(format!("surfsynth-staging-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        assert!(check_replaceable(&dir).is_ok(), "empty");
        std::fs::write(dir.join("notes.txt"), b"mine").unwrap();
        assert!(
            check_replaceable(&dir)
                .unwrap_err()
                .contains("not the output of a run")
        );
        std::fs::remove_file(dir.join("notes.txt")).unwrap();
        std::fs::write(dir.join("metrics.json"), b"{}").unwrap();
        assert!(
            check_replaceable(&dir).is_err(),
            "a metrics.json alone is not a run's marker (issue 43)"
        );
        write_run_marker(&dir, &[dir.join("metrics.json")]).unwrap();
        assert!(check_replaceable(&dir).is_ok(), "an earlier run");
        std::fs::write(dir.join("notes.txt"), b"mine").unwrap();
        assert!(
            check_replaceable(&dir).unwrap_err().contains("notes.txt"),
            "a run's folder with a file of the user's beside it"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }
}
