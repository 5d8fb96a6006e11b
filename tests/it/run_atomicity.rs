//! Issue 16: command-line paths and options are checked before any work
//! (exit 2, naming the option, what is wrong and what is allowed, nothing
//! created), and a run is atomic as a whole: it writes into a sibling
//! temporary folder renamed into place at the end, so a failed, killed or
//! interrupted run never leaves a partial or mixed output folder.

use crate::common::{bin, data_file, files_under, run_cli};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Child, Stdio};
use std::time::{Duration, Instant};

/// A run of a second or less.
const QUICK: &str = r#"
seed = 5
[input]
mesh = "builtin:icosphere"
exemplar = "builtin:bricks"
[input.mesh_options]
subdivisions = 2

[[stage]]
kind = "orientation"
mode = "global"
up = [0.0, 1.0, 0.0]

[[stage]]
kind = "init_colours"

[[stage]]
kind = "export"
formats = ["ply", "preview"]
preview_size = 64
"#;

/// Writes the quick config into `dir`; returns its path.
fn quick_config(dir: &Path) -> PathBuf {
    let cfg = dir.join("quick.toml");
    std::fs::write(&cfg, QUICK).unwrap();
    cfg
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Every file under `dir` with its bytes.
fn snapshot(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    files_under(dir)
        .into_iter()
        .map(|f| {
            let bytes = std::fs::read(&f).unwrap();
            (f, bytes)
        })
        .collect()
}

/// Hidden temporary or set-aside siblings of `dir` (`.NAME.tmp-*`, `.NAME.old-*`).
fn siblings(dir: &Path) -> Vec<PathBuf> {
    let name = dir.file_name().unwrap().to_string_lossy().into_owned();
    let Ok(rd) = std::fs::read_dir(dir.parent().unwrap()) else {
        return Vec::new();
    };
    let mut out: Vec<PathBuf> = rd
        .flatten()
        .map(|e| e.path())
        .filter(|p| {
            let n = p.file_name().unwrap().to_string_lossy();
            n.starts_with(&format!(".{name}.tmp-")) || n.starts_with(&format!(".{name}.old-"))
        })
        .collect();
    out.sort();
    out
}

/// Exit 2, every needle in stderr, no panic, no internal error.
fn assert_refused(code: i32, stderr: &str, needles: &[&str]) {
    assert_eq!(code, 2, "exit code; stderr: {stderr}");
    for n in needles {
        assert!(stderr.contains(n), "stderr should contain {n:?}: {stderr}");
    }
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(!stderr.contains("internal error"), "{stderr}");
}

/// A folder no one may create files in, even root: `/proc` refuses them.
fn unwritable_folder() -> PathBuf {
    PathBuf::from("/proc")
}

#[test]
fn threads_out_of_range_are_refused_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = quick_config(dir.path());
    let out = dir.path().join("out");
    for threads in ["0", "1025", "100000"] {
        let started = Instant::now();
        let (code, _, stderr) = run_cli(&["run", s(&cfg), "--out", s(&out), "--threads", threads]);
        assert_refused(code, &stderr, &["--threads", threads, "allowed: 1..=1024"]);
        assert!(
            started.elapsed() < Duration::from_secs(20),
            "--threads {threads} refused at once, not after creating the threads"
        );
        assert!(!out.exists(), "no output folder for --threads {threads}");
    }
}

#[test]
fn trace_on_a_folder_or_an_unwritable_or_missing_folder_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = quick_config(dir.path());
    let out = dir.path().join("out");
    let cases = [
        (dir.path().to_path_buf(), "is a folder"),
        (dir.path().join("missing/trace.json"), "does not exist"),
        (
            unwritable_folder().join("trace.json"),
            "cannot create files in",
        ),
    ];
    for (trace, what) in cases {
        let (code, _, stderr) = run_cli(&["run", s(&cfg), "--out", s(&out), "--trace", s(&trace)]);
        assert_refused(code, &stderr, &["--trace", what, "allowed:"]);
        assert!(
            !out.exists(),
            "no output folder for --trace {}",
            trace.display()
        );
    }
    assert!(
        !dir.path().join("missing").exists(),
        "no trace folder created"
    );
}

#[test]
fn out_that_is_a_file_unwritable_or_foreign_is_refused_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = quick_config(dir.path());
    let file = dir.path().join("a_file");
    std::fs::write(&file, b"keep me").unwrap();
    let foreign = dir.path().join("documents");
    std::fs::create_dir(&foreign).unwrap();
    std::fs::write(foreign.join("notes.txt"), b"mine").unwrap();
    // Issue 43: a metrics.json (even `{}`) beside the user's own files was
    // taken for an earlier run, and a thesis was deleted with exit 0.
    let thesis = dir.path().join("thesis");
    std::fs::create_dir(&thesis).unwrap();
    std::fs::write(thesis.join("metrics.json"), b"{}").unwrap();
    std::fs::write(thesis.join("thesis.tex"), b"\\documentclass{book}").unwrap();
    let before = snapshot(dir.path());
    let cases = [
        (file.clone(), "is a file"),
        (file.join("sub"), "is a file"),
        (
            unwritable_folder().join("surfsynth-out"),
            "cannot create files in",
        ),
        (foreign.clone(), "not the output of a run"),
        (thesis.clone(), "thesis.tex"),
    ];
    for (out, what) in cases {
        let (code, _, stderr) = run_cli(&["run", s(&cfg), "--out", s(&out)]);
        assert_refused(code, &stderr, &["--out", what, "allowed:"]);
        assert_eq!(
            snapshot(dir.path()),
            before,
            "nothing changed for --out {}",
            out.display()
        );
    }
    // `[output] dir` of the config is checked the same way, and named.
    let (code, _, stderr) = run_cli(&[
        "run",
        s(&cfg),
        "--set",
        &format!("output.dir={}", file.display()),
    ]);
    assert_refused(code, &stderr, &["output.dir", "is a file", "allowed:"]);
    assert_eq!(snapshot(dir.path()), before);
}

#[test]
fn sweep_threads_and_out_are_checked_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = quick_config(dir.path());
    let file = dir.path().join("a_file");
    std::fs::write(&file, b"keep me").unwrap();
    let out = dir.path().join("sweep");
    let (code, _, stderr) = run_cli(&[
        "sweep",
        s(&cfg),
        "--grid",
        "seed=1,2",
        "--out",
        s(&out),
        "--threads",
        "100000",
    ]);
    assert_refused(code, &stderr, &["--threads", "allowed: 1..=1024"]);
    assert!(!out.exists());
    let (code, _, stderr) = run_cli(&["sweep", s(&cfg), "--grid", "seed=1,2", "--out", s(&file)]);
    assert_refused(code, &stderr, &["--out", "is a file", "allowed:"]);
    assert_eq!(std::fs::read(&file).unwrap(), b"keep me");
}

#[test]
fn a_rerun_replaces_the_folder_as_a_whole() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = quick_config(dir.path());
    let out = dir.path().join("out");
    // An earlier run with another format (obj) into the same folder.
    let (code, _, stderr) = run_cli(&[
        "run",
        s(&cfg),
        "--out",
        s(&out),
        "--set",
        r#"stage.3.formats=["ply", "preview", "obj"]"#,
    ]);
    assert_eq!(code, 0, "{stderr}");
    assert!(out.join("result.obj").is_file());
    // Its files must not survive into the new set.
    let (code, stdout, stderr) = run_cli(&["run", s(&cfg), "--out", s(&out)]);
    assert_eq!(code, 0, "{stderr}");
    assert!(
        !out.join("result.obj").exists(),
        "the old folder is replaced, not merged"
    );
    for name in ["config.toml", "metrics.json", "result.ply", "preview_0.png"] {
        assert!(out.join(name).is_file(), "{name} written");
    }
    assert!(
        siblings(&out).is_empty(),
        "no temporaries left: {:?}",
        siblings(&out)
    );
    assert!(
        !stdout.contains(".tmp-"),
        "the report names the final folder: {stdout}"
    );
}

#[test]
fn a_failed_run_leaves_no_output_folder_and_an_earlier_one_untouched() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = quick_config(dir.path());
    let fresh = dir.path().join("nested/fresh");
    // The mesh file is looked for only when the run starts.
    let missing_mesh = format!("input.mesh={}", dir.path().join("no_such.obj").display());
    let (code, _, stderr) = run_cli(&["run", s(&cfg), "--out", s(&fresh), "--set", &missing_mesh]);
    assert_eq!(code, 2, "{stderr}");
    assert!(
        !dir.path().join("nested").exists(),
        "no output folder, nor its parents"
    );
    assert!(siblings(&fresh).is_empty());

    let out = dir.path().join("out");
    let (code, _, stderr) = run_cli(&["run", s(&cfg), "--out", s(&out)]);
    assert_eq!(code, 0, "{stderr}");
    let before = snapshot(&out);
    // A stage refusal found at run time: `plane` export of a sphere.
    let plane = QUICK.replace(r#"formats = ["ply", "preview"]"#, r#"formats = ["plane"]"#);
    let plane_cfg = dir.path().join("plane.toml");
    std::fs::write(&plane_cfg, plane).unwrap();
    let (code, _, stderr) = run_cli(&["run", s(&plane_cfg), "--out", s(&out)]);
    assert_eq!(code, 2, "{stderr}");
    assert_eq!(snapshot(&out), before, "the earlier result is untouched");
    assert!(siblings(&out).is_empty(), "{:?}", siblings(&out));
}

/// Starts the Wei & Levoy plane (several seconds on one thread) into `out`
/// and waits until its temporary folder exists and has been written to.
fn start_slow_run(out: &Path) -> Child {
    let config = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/plane/wei_levoy.toml");
    let mut child = bin()
        .args([
            "run",
            s(&config),
            "--out",
            s(out),
            "--threads",
            "1",
            "--quiet",
        ])
        .arg("--set")
        .arg(format!(
            "input.exemplar={}",
            data_file("textures/stones.png").display()
        ))
        .env("RUST_LOG", "warn")
        .env(
            "SURFSYNTH_CACHE",
            Path::new(env!("CARGO_TARGET_TMPDIR")).join("surfsynth-cache"),
        )
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the binary starts");
    let started = Instant::now();
    while siblings(out).is_empty() {
        assert!(
            child.try_wait().unwrap().is_none(),
            "the slow run ended before its temporary folder appeared"
        );
        assert!(
            started.elapsed() < Duration::from_secs(60),
            "no temporary folder"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    // Into the stages: the inputs are loaded and the pyramid is being built.
    std::thread::sleep(Duration::from_millis(700));
    assert!(
        child.try_wait().unwrap().is_none(),
        "the slow run must still be running when it is killed"
    );
    child
}

fn signal(child: &Child, name: &str) {
    let status = std::process::Command::new("kill")
        .args([&format!("-{name}"), &child.id().to_string()])
        .status()
        .expect("kill runs");
    assert!(status.success());
}

/// A quick complete run into `out`; returns its files.
fn complete_run(cfg: &Path, out: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    let (code, _, stderr) = run_cli(&["run", s(cfg), "--out", s(out)]);
    assert_eq!(code, 0, "{stderr}");
    snapshot(out)
}

#[test]
fn a_killed_run_leaves_the_previous_result_and_the_next_run_cleans_up() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = quick_config(dir.path());
    let out = dir.path().join("out");
    let before = complete_run(&cfg, &out);

    let mut child = start_slow_run(&out);
    child.kill().unwrap();
    let status = child.wait().unwrap();
    assert!(!status.success());
    assert_eq!(
        snapshot(&out),
        before,
        "the previous result is byte-identical"
    );
    let stale = siblings(&out);
    assert_eq!(
        stale.len(),
        1,
        "SIGKILL leaves the temporary folder: {stale:?}"
    );
    assert!(
        !dir.path().join("out").join("plane.png").exists(),
        "no partial final file"
    );

    // The next run removes the stale temporary and succeeds.
    let (code, _, stderr) = run_cli(&["run", s(&cfg), "--out", s(&out)]);
    assert_eq!(code, 0, "{stderr}");
    assert!(
        siblings(&out).is_empty(),
        "stale temporary removed: {:?}",
        siblings(&out)
    );
    assert!(out.join("metrics.json").is_file());

    // A killed first run into a new folder leaves no final folder at all.
    let fresh = dir.path().join("fresh");
    let mut child = start_slow_run(&fresh);
    child.kill().unwrap();
    child.wait().unwrap();
    assert!(!fresh.exists(), "no partial final folder");
}

#[test]
fn sigint_and_sigterm_remove_the_temporary_folder() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = quick_config(dir.path());
    let out = dir.path().join("out");
    let before = complete_run(&cfg, &out);
    for (name, code) in [("INT", 130), ("TERM", 143)] {
        let mut child = start_slow_run(&out);
        signal(&child, name);
        let status = child.wait().unwrap();
        assert_eq!(status.code(), Some(code), "SIG{name} exits {code}");
        assert_eq!(
            snapshot(&out),
            before,
            "SIG{name}: the previous result is untouched"
        );
        assert!(siblings(&out).is_empty(), "SIG{name}: {:?}", siblings(&out));
    }
}

/// Entries of the sweep folder whose names start with a dot.
fn hidden_entries(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with('.'))
        .collect()
}

#[test]
fn sweep_run_folders_stay_complete_and_a_timed_out_run_leaves_no_temporary() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = quick_config(dir.path());
    let out = dir.path().join("sweep");
    let (code, _, stderr) = run_cli(&[
        "sweep",
        s(&cfg),
        "--grid",
        "seed=1,2",
        "--out",
        s(&out),
        "--threads",
        "1",
        "-q",
    ]);
    assert_eq!(code, 0, "{stderr}");
    for run in ["seed=1", "seed=2"] {
        let folder = out.join(run);
        for name in [
            "run.json",
            "log.txt",
            "done.json",
            "metrics.json",
            "result.ply",
        ] {
            assert!(folder.join(name).is_file(), "{run}/{name}");
        }
    }
    assert!(
        hidden_entries(&out).is_empty(),
        "{:?}",
        hidden_entries(&out)
    );

    // A run killed on its timeout after it began writing.
    let slow = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/plane/wei_levoy.toml");
    let exemplar = format!(
        "input.exemplar={}",
        data_file("textures/stones.png").display()
    );
    let out = dir.path().join("slow");
    let (code, _, stderr) = run_cli(&[
        "sweep",
        s(&slow),
        "--grid",
        "seed=1",
        "--set",
        &exemplar,
        "--out",
        s(&out),
        "--threads",
        "1",
        "--timeout",
        "1.5",
        "-q",
    ]);
    assert_eq!(code, 1, "{stderr}");
    assert!(
        hidden_entries(&out).is_empty(),
        "{:?}",
        hidden_entries(&out)
    );
    let failed = std::fs::read_to_string(out.join("seed=1/failed.json")).unwrap();
    assert!(failed.contains("timed out"), "{failed}");
}

/// Issue 43: `--out` as a dangling symlink, or as a mount point, was found
/// only after the computation (exit 1: the final rename failed). Both are
/// refused before any work; a symlink to a folder is written through (the
/// result lands in the folder it points to, the link stays).
#[cfg(unix)]
#[test]
fn out_as_a_symlink_or_a_mount_point_is_written_through_or_refused_up_front() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = quick_config(dir.path());
    let dangling = dir.path().join("dangling");
    std::os::unix::fs::symlink(dir.path().join("nowhere"), &dangling).unwrap();
    let (code, _, stderr) = run_cli(&["run", s(&cfg), "--out", s(&dangling)]);
    assert_refused(
        code,
        &stderr,
        &["--out", "symlink", "does not exist", "allowed:"],
    );
    // /proc is a mount point (its own file system).
    let (code, _, stderr) = run_cli(&["run", s(&cfg), "--out", "/proc"]);
    assert_refused(code, &stderr, &["--out", "mount point", "allowed:"]);
    // A symlink to a folder: written through.
    let target = dir.path().join("target");
    std::fs::create_dir(&target).unwrap();
    let link = dir.path().join("link");
    std::os::unix::fs::symlink(&target, &link).unwrap();
    let (code, _, stderr) = run_cli(&["run", s(&cfg), "--out", s(&link)]);
    assert_eq!(code, 0, "{stderr}");
    assert!(
        std::fs::symlink_metadata(&link)
            .unwrap()
            .file_type()
            .is_symlink(),
        "the link stays a link"
    );
    assert!(
        target.join("metrics.json").is_file(),
        "the result is in the target"
    );
}

/// Issue 43: a run that died between the two renames of its commit left
/// the earlier result set aside (`.out.old-PID.N`) and no `out`; a next run
/// refused for its options or its config left it hidden. Every run into
/// `out` now puts it back first, refused or not.
#[test]
fn a_refused_run_puts_back_an_earlier_result_a_dead_run_set_aside() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = quick_config(dir.path());
    let out = dir.path().join("out");
    let before = complete_run(&cfg, &out);
    // The PID of a process that is gone.
    let mut gone = std::process::Command::new("true").spawn().unwrap();
    let pid = gone.id();
    gone.wait().unwrap();
    let aside = dir.path().join(format!(".out.old-{pid}.0"));
    let bad_cfg = dir.path().join("bad.toml");
    std::fs::write(
        &bad_cfg,
        QUICK.replace("preview_size = 64", "preview_size = 0"),
    )
    .unwrap();
    // Without `--out`: the config's own `[output] dir`.
    let bad_own_dir = dir.path().join("bad_own_dir.toml");
    std::fs::write(
        &bad_own_dir,
        format!(
            "{}\n[output]\ndir = \"{}\"\n",
            QUICK.replace("preview_size = 64", "preview_size = 0"),
            s(&out)
        ),
    )
    .unwrap();
    let cases: [Vec<&str>; 3] = [
        vec!["run", s(&cfg), "--out", s(&out), "--threads", "0"],
        vec!["run", s(&bad_cfg), "--out", s(&out)],
        vec!["run", s(&bad_own_dir)],
    ];
    for args in cases {
        std::fs::rename(&out, &aside).unwrap();
        let (code, _, stderr) = run_cli(&args);
        assert_eq!(code, 2, "{args:?} is refused: {stderr}");
        assert!(
            snapshot(&out) == before,
            "{args:?}: the earlier result is back in place; found {:?} and {:?}",
            files_under(&out),
            siblings(&out)
        );
        assert!(siblings(&out).is_empty(), "{args:?}: {:?}", siblings(&out));
    }
}

/// Runs the CLI as the unprivileged user `nobody` when this test runs as
/// root (whom permission bits do not stop), else as ourselves; `None` when
/// `nobody` cannot run the binary here (its folders are not open to all).
#[cfg(unix)]
fn run_cli_unprivileged(args: &[&str]) -> Option<(i32, String, String)> {
    use std::os::unix::process::CommandExt;
    let as_nobody = |cmd: &mut std::process::Command| {
        // SAFETY: geteuid has no preconditions.
        if unsafe { libc::geteuid() } == 0 {
            cmd.uid(65534).gid(65534);
        }
    };
    let mut probe = bin();
    probe.arg("--version");
    as_nobody(&mut probe);
    if !probe.output().is_ok_and(|o| o.status.success()) {
        return None;
    }
    let mut cmd = bin();
    cmd.args(args).env("RUST_LOG", "warn");
    as_nobody(&mut cmd);
    let out = cmd.output().expect("the surfsynth binary runs");
    Some((
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    ))
}

/// Issue 43: an `--out` the run cannot write is refused before any work,
/// naming the folder. A new folder in a read-only parent was refused
/// naming only the parent; an existing earlier result that is itself
/// read-only was replaced, but its files could not be deleted, so the run
/// exited 0 leaving them in a hidden folder.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
#[test]
fn out_in_a_read_only_folder_or_read_only_itself_is_refused_naming_it() {
    use std::os::unix::fs::PermissionsExt;
    let dir = tempfile::tempdir().unwrap();
    let mode = |p: &Path, m: u32| std::fs::set_permissions(p, std::fs::Permissions::from_mode(m));
    mode(dir.path(), 0o755).unwrap();
    let cfg = quick_config(dir.path());
    mode(&cfg, 0o644).unwrap();
    // A read-only parent: a new folder in it cannot be created.
    let locked = dir.path().join("locked");
    std::fs::create_dir(&locked).unwrap();
    mode(&locked, 0o555).unwrap();
    let new = locked.join("new");
    let Some((code, _, stderr)) = run_cli_unprivileged(&["run", s(&cfg), "--out", s(&new)]) else {
        eprintln!("skipped: the unprivileged user cannot run the binary from here");
        return;
    };
    assert_refused(
        code,
        &stderr,
        &["--out", s(&new), "not writable", "allowed:"],
    );
    assert!(!new.exists());
    // An earlier result, read-only itself, in a writable parent.
    let open = dir.path().join("open");
    std::fs::create_dir(&open).unwrap();
    mode(&open, 0o777).unwrap();
    let earlier = open.join("out");
    let before = complete_run(&cfg, &earlier);
    mode(&earlier, 0o555).unwrap();
    let (code, _, stderr) = run_cli_unprivileged(&["run", s(&cfg), "--out", s(&earlier)]).unwrap();
    assert_refused(
        code,
        &stderr,
        &["--out", s(&earlier), "not writable", "allowed:"],
    );
    assert!(
        snapshot(&earlier) == before,
        "the earlier result is untouched"
    );
    assert!(siblings(&earlier).is_empty(), "{:?}", siblings(&earlier));
}

/// Runs `surfsynth ARGS` in a mount namespace of its own after
/// `mount --bind -o ro SOURCE TARGET`; `None` where that cannot be done
/// (not root, or no `unshare`).
#[cfg(target_os = "linux")]
fn run_cli_over_read_only_bind(
    source: &Path,
    target: &Path,
    args: &[&str],
) -> Option<(i32, String, String)> {
    let shell = r#"mount --bind -o ro "$1" "$2" || exit 99; shift 2; exec "$@""#;
    let mut cmd = std::process::Command::new("unshare");
    cmd.args(["-m", "sh", "-c", shell, "sh", s(source), s(target)])
        .arg(env!("CARGO_BIN_EXE_surfsynth"))
        .args(args)
        .env("RUST_LOG", "warn");
    let out = cmd.output().ok()?;
    let code = out.status.code().unwrap_or(-1);
    if code == 99 || (code == 1 && out.stdout.is_empty() && out.stderr.starts_with(b"unshare")) {
        return None;
    }
    Some((
        code,
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    ))
}

/// Issue 43: `--out` as a read-only mount (a container volume: a bind mount
/// of a folder of the same file system, so the same device number) ran the
/// whole computation and failed at the final rename with exit 1; a folder
/// inside it was refused naming only the mount. Both are refused before
/// any work, naming the `--out` folder. Needs root for the bind mount (in a
/// mount namespace of its own); skipped where that is not possible.
#[cfg(target_os = "linux")]
#[test]
fn out_as_or_inside_a_read_only_bind_mount_is_refused_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = quick_config(dir.path());
    let source = dir.path().join("source");
    let volume = dir.path().join("volume");
    std::fs::create_dir(&source).unwrap();
    std::fs::create_dir(&volume).unwrap();
    let Some((code, _, stderr)) =
        run_cli_over_read_only_bind(&source, &volume, &["run", s(&cfg), "--out", s(&volume)])
    else {
        eprintln!(
            "skipped: no bind mount in a mount namespace of our own (needs root and unshare)"
        );
        return;
    };
    assert_refused(
        code,
        &stderr,
        &["--out", s(&volume), "mount point", "allowed:"],
    );
    let inside = volume.join("run");
    let (code, _, stderr) =
        run_cli_over_read_only_bind(&source, &volume, &["run", s(&cfg), "--out", s(&inside)])
            .unwrap();
    assert_refused(
        code,
        &stderr,
        &["--out", s(&inside), "read-only file system", "allowed:"],
    );
    assert!(files_under(&source).is_empty() && files_under(&volume).is_empty());
    assert_eq!(
        std::fs::read_dir(dir.path()).unwrap().count(),
        3,
        "nothing beside the config, the source and the mount point"
    );
}

/// Issue 43: `--out` as a symlink to a folder on another file system is
/// written through; the run writes beside the folder it points to (on its
/// file system), so the final rename works and nothing is left beside
/// either. Skipped where /dev/shm is not another file system.
#[cfg(target_os = "linux")]
#[test]
fn out_as_a_symlink_to_another_file_system_is_written_there() {
    use std::os::unix::fs::MetadataExt;
    let dir = tempfile::tempdir().unwrap();
    let Ok(other) = tempfile::tempdir_in("/dev/shm") else {
        eprintln!("skipped: no /dev/shm");
        return;
    };
    let dev = |p: &Path| std::fs::metadata(p).unwrap().dev();
    if dev(dir.path()) == dev(other.path()) {
        eprintln!("skipped: /dev/shm is on the same file system");
        return;
    }
    let cfg = quick_config(dir.path());
    let target = other.path().join("result");
    std::fs::create_dir(&target).unwrap();
    let link = dir.path().join("link");
    std::os::unix::fs::symlink(&target, &link).unwrap();
    for round in ["first", "rerun"] {
        let (code, _, stderr) = run_cli(&["run", s(&cfg), "--out", s(&link)]);
        assert_eq!(code, 0, "{round}: {stderr}");
        assert!(target.join("surfsynth_run.json").is_file(), "{round}");
        assert!(
            siblings(&target).is_empty(),
            "{round}: {:?}",
            siblings(&target)
        );
        assert_eq!(
            std::fs::read_dir(other.path()).unwrap().count(),
            1,
            "{round}"
        );
        assert!(siblings(&link).is_empty(), "{round}: {:?}", siblings(&link));
    }
}

/// Issue 43: an `--out` name of up to NAME_MAX (255) bytes runs, also over
/// an earlier result: the hidden staging folder beside it gets a name that
/// fits (it failed "File name too long", exit 1, from 239 bytes on).
#[test]
fn an_out_name_of_any_legal_length_runs_and_reruns() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = quick_config(dir.path());
    for len in [250, 255] {
        let out = dir.path().join("n".repeat(len));
        for round in 0..2 {
            let (code, _, stderr) = run_cli(&["run", s(&cfg), "--out", s(&out)]);
            assert_eq!(code, 0, "{len} bytes, round {round}: {stderr}");
            assert!(out.join("metrics.json").is_file(), "{len}");
            assert!(
                hidden_entries(dir.path()).is_empty(),
                "{len}: {:?}",
                hidden_entries(dir.path())
            );
        }
    }
}
