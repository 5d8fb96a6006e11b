//! Issue 43, "signals without leftovers": SIGINT, SIGTERM or SIGHUP at any
//! moment of a run's export phase leaves either the complete new output
//! folder or nothing new (an earlier result untouched, byte for byte), and
//! never a hidden temporary or set-aside folder. Before the fix, the signal
//! handler deleted the temporary folder while the export went on writing
//! into it (so it was recreated, or only half deleted), and it released its
//! lock before the process exited, so `commit()` could move a half-deleted
//! folder into place.
//!
//! A seeded loop of runs of the real binary, each signalled at a random
//! moment after its export began writing.

#![cfg(all(target_os = "linux", target_env = "gnu"))]

mod common;

use common::{bin, files_under};
use std::collections::BTreeMap;
use std::os::unix::process::ExitStatusExt;
use std::path::{Path, PathBuf};
use std::process::Stdio;
use std::time::{Duration, Instant};

/// A run of well under a second whose export writes seven files.
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
formats = ["ply", "obj", "preview"]
preview_size = 64
"#;

/// The files that differ between two runs of the same config (timings).
const VARYING: [&str; 1] = ["metrics.json"];

/// SplitMix64: the test's own seeded random numbers.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Every file under `dir` (relative name) with its bytes.
fn snapshot(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    files_under(dir)
        .into_iter()
        .map(|f| {
            let name = f.strip_prefix(dir).unwrap().to_string_lossy().into_owned();
            let bytes = std::fs::read(&f).unwrap();
            (name, bytes)
        })
        .collect()
}

/// The snapshot without the files whose bytes vary between runs.
fn stable(snap: &BTreeMap<String, Vec<u8>>) -> BTreeMap<String, Vec<u8>> {
    snap.iter()
        .filter(|(k, _)| !VARYING.contains(&k.as_str()))
        .map(|(k, v)| (k.clone(), v.clone()))
        .collect()
}

/// Entries of `parent` other than the expected output folder (`keep`):
/// temporary or set-aside folders, probes, anything a run left behind.
fn leftovers(parent: &Path, keep: &[&str]) -> Vec<String> {
    let mut out: Vec<String> = std::fs::read_dir(parent)
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| !keep.contains(&n.as_str()))
        .collect();
    out.sort();
    out
}

/// Whether `dir` holds a hidden entry (a temporary file of the run).
fn has_entry(dir: &Path) -> bool {
    std::fs::read_dir(dir).is_ok_and(|mut rd| rd.next().is_some())
}

/// The run's temporary folder in `parent`, once it exists.
fn temporary(parent: &Path) -> Option<PathBuf> {
    std::fs::read_dir(parent)
        .ok()?
        .flatten()
        .map(|e| e.path())
        .find(|p| p.file_name().unwrap().to_string_lossy().contains(".tmp-"))
}

/// Starts a run of `cfg` into `out`.
fn start(cfg: &Path, out: &Path) -> std::process::Child {
    bin()
        .args(["run", s(cfg), "--out", s(out), "--threads", "1", "--quiet"])
        .env("RUST_LOG", "error")
        .env(
            "SURFSYNTH_CACHE",
            Path::new(env!("CARGO_TARGET_TMPDIR")).join("surfsynth-cache"),
        )
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("the binary starts")
}

/// Waits until the run's temporary folder holds a first file (the export
/// began writing) or the run ended; returns when that was.
fn wait_for_export(child: &mut std::process::Child, parent: &Path) -> Instant {
    let started = Instant::now();
    loop {
        if temporary(parent).is_some_and(|t| has_entry(&t)) {
            return Instant::now();
        }
        if child.try_wait().unwrap().is_some() {
            return Instant::now();
        }
        assert!(
            started.elapsed() < Duration::from_secs(30),
            "the run neither wrote nor ended"
        );
        std::thread::sleep(Duration::from_micros(200));
    }
}

#[test]
fn a_signal_at_any_moment_of_the_export_leaves_a_complete_folder_or_none() {
    const RUNS: usize = 120;
    let dir = tempfile::tempdir().unwrap();
    let cfg = dir.path().join("quick.toml");
    std::fs::write(&cfg, QUICK).unwrap();
    let parent = dir.path().join("runs");
    std::fs::create_dir(&parent).unwrap();
    let out = parent.join("out");

    // A complete result, and how long the export takes from its first file
    // to the end of the process (the window the signals are sent in; the
    // shortest of three warm runs, so that a slow one does not send most
    // signals after the end).
    let mut write_time = Duration::MAX;
    let mut complete = BTreeMap::new();
    for calibration in 0..4 {
        let mut child = start(&cfg, &out);
        let writing = wait_for_export(&mut child, &parent);
        let status = child.wait().unwrap();
        if calibration > 0 {
            write_time = write_time.min(writing.elapsed());
        }
        assert_eq!(status.code(), Some(0));
        complete = snapshot(&out);
    }
    assert!(complete.contains_key("surfsynth_run.json"), "{complete:?}");
    let complete_stable = stable(&complete);
    let window_us = (write_time.as_micros() as u64 * 3 / 2).max(1000);

    let signals = [
        (libc::SIGINT, "SIGINT"),
        (libc::SIGTERM, "SIGTERM"),
        (libc::SIGHUP, "SIGHUP"),
    ];
    let mut rng = Rng(43);
    let (mut interrupted, mut finished, mut interrupted_complete) = (0, 0, 0);
    let loop_started = Instant::now();
    for run in 0..RUNS {
        // Every other run has an earlier result to replace.
        let earlier = if run % 2 == 0 {
            let snap = snapshot(&out);
            if snap.is_empty() {
                let status = start(&cfg, &out).wait().unwrap();
                assert_eq!(status.code(), Some(0));
            }
            Some(snapshot(&out))
        } else {
            if out.exists() {
                std::fs::remove_dir_all(&out).unwrap();
            }
            None
        };
        let (signal, name) = signals[rng.below(3) as usize];
        let delay = Duration::from_micros(rng.below(window_us));
        let mut child = start(&cfg, &out);
        let writing = wait_for_export(&mut child, &parent);
        while writing.elapsed() < delay {
            std::hint::spin_loop();
        }
        // SAFETY: kill sends a signal to our own child (still unreaped, so
        // its PID cannot have been reused).
        unsafe {
            libc::kill(child.id() as libc::pid_t, signal);
        }
        let status = child.wait().unwrap();
        let what = format!(
            "run {run}: {name} {} µs after the export began, {} earlier result; exit {status:?}",
            delay.as_micros(),
            if earlier.is_some() {
                "with an"
            } else {
                "without"
            }
        );
        assert_eq!(status.signal(), None, "{what}: killed by the signal");
        let code = status.code().unwrap_or(-1);
        assert!(
            code == 0 || code == 128 + signal,
            "{what}: exit 0 or {}",
            128 + signal
        );
        assert_eq!(
            leftovers(&parent, &["out"]),
            Vec::<String>::new(),
            "{what}: left behind"
        );
        let now = snapshot(&out);
        let is_complete =
            !now.is_empty() && stable(&now) == complete_stable && now.keys().eq(complete.keys());
        if code == 0 {
            finished += 1;
            assert!(is_complete, "{what}: exit 0 with {:?}", now.keys());
        } else {
            interrupted += 1;
            interrupted_complete += usize::from(is_complete);
            match &earlier {
                Some(before) => assert!(
                    &now == before || is_complete,
                    "{what}: neither the earlier result nor a complete new one: {:?}",
                    now.keys()
                ),
                None => assert!(
                    !out.exists() || is_complete,
                    "{what}: a partial folder: {:?}",
                    now.keys()
                ),
            }
        }
    }
    eprintln!(
        "{RUNS} runs in {:.1} s: {interrupted} interrupted ({interrupted_complete} of them after \
         the final move, with the new folder complete), {finished} finished before the signal",
        loop_started.elapsed().as_secs_f64()
    );
    assert!(
        interrupted >= RUNS / 5,
        "most signals must land inside the run: {interrupted} of {RUNS}"
    );
}
