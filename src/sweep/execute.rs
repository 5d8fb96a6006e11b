//! Running the runs: a pool of `jobs` workers pulls runs from a queue; each
//! run is a child process (`surfsynth run ... --out DIR/<name>`), so a crash
//! in one cannot take the sweep down. Its stdout and stderr are captured
//! into `log.txt`; the completion marker `done.json` is written last, only
//! after the child exited 0.

use super::ValidRun;
use serde::{Deserialize, Serialize};
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// How children are started.
#[derive(Clone, Debug)]
pub struct ChildSpec {
    /// The `surfsynth` executable.
    pub exe: PathBuf,
    /// The base config.
    pub config: PathBuf,
    /// `--set` overrides shared by every run.
    pub fixed: Vec<String>,
    /// The sweep folder.
    pub sweep_dir: PathBuf,
    /// `--threads` of each run.
    pub threads: usize,
    /// Kill a run after this long.
    pub timeout: Option<Duration>,
    /// Re-run complete runs.
    pub force: bool,
    /// Print a line per finished run on stderr.
    pub progress: bool,
}

/// What happened to one run.
#[derive(Clone, Debug, PartialEq)]
pub enum RunStatus {
    /// The child exited 0; `done.json` written.
    Ok,
    /// A complete result was already there.
    Skipped,
    /// The child exited non-zero, was killed, timed out, or could not start.
    Failed {
        /// Its exit code, when it exited.
        exit_code: Option<i32>,
        /// `exit 2`, `killed by signal 9`, `timed out after 5 s`, ...
        reason: String,
    },
}

impl RunStatus {
    /// Whether the run failed.
    pub fn is_failure(&self) -> bool {
        matches!(self, RunStatus::Failed { .. })
    }
}

/// The result of one run.
#[derive(Clone, Debug)]
pub struct Outcome {
    /// Folder name.
    pub name: String,
    /// Index in the full run list.
    pub index: usize,
    /// What happened.
    pub status: RunStatus,
    /// Wall time of the child as measured by the sweep (0 when skipped).
    pub wall_seconds: f64,
    /// The run's own `total_seconds` from its `metrics.json`.
    pub run_seconds: Option<f64>,
    /// Last lines of the log (failures).
    pub log_tail: Vec<String>,
}

/// `run.json`: what a run folder holds, written before the child starts and
/// again after it exits (a successful child replaces the folder).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct RunRecord {
    /// Folder name.
    pub name: String,
    /// Index in the full run list.
    pub index: usize,
    /// `[path, value]` per grid axis.
    pub overrides: Vec<(String, String)>,
    /// `--set` overrides shared by every run.
    pub fixed: Vec<String>,
    /// The base config as given.
    pub config: String,
    /// blake3 of the resolved config.
    pub config_hash: String,
    /// The child's command line.
    pub command: Vec<String>,
}

/// `done.json` (exit 0) or `failed.json`: how a run ended.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Completion {
    /// Folder name.
    pub name: String,
    /// `[path, value]` per grid axis.
    pub overrides: Vec<(String, String)>,
    /// blake3 of the resolved config.
    pub config_hash: String,
    /// The child's exit code (`None`: killed or not started).
    pub exit_code: Option<i32>,
    /// `ok`, `exit 2`, `killed by signal 9`, `timed out after 5 s`, ...
    pub status: String,
    /// Wall time of the child, seconds.
    pub wall_seconds: f64,
    /// Last lines of the log.
    #[serde(default)]
    pub log_tail: Vec<String>,
}

/// File names inside a run folder.
pub const RUN_RECORD: &str = "run.json";
/// The completion marker, written last.
pub const DONE: &str = "done.json";
/// Written when a run failed.
pub const FAILED: &str = "failed.json";
/// The captured output of the child.
pub const LOG: &str = "log.txt";

/// Lines of the log kept in `failed.json` and the progress line.
const TAIL_LINES: usize = 6;

/// Whether `dir` holds a complete result of the run with `config_hash`.
pub fn is_complete(dir: &Path, config_hash: &str) -> bool {
    std::fs::read_to_string(dir.join(DONE))
        .ok()
        .and_then(|t| serde_json::from_str::<Completion>(&t).ok())
        .is_some_and(|c| c.exit_code == Some(0) && c.config_hash == config_hash)
}

/// Runs `runs` with `jobs` at a time; returns their outcomes in run order.
pub fn execute(spec: &ChildSpec, runs: &[ValidRun], jobs: usize) -> Vec<Outcome> {
    let total = runs.len();
    let mut outcomes = Vec::with_capacity(total);
    let mut queue = Vec::new();
    for r in runs {
        let dir = spec.sweep_dir.join(&r.run.name);
        if !spec.force && is_complete(&dir, &r.config_hash) {
            outcomes.push(Outcome {
                name: r.run.name.clone(),
                index: r.run.index,
                status: RunStatus::Skipped,
                wall_seconds: 0.0,
                run_seconds: None,
                log_tail: Vec::new(),
            });
        } else {
            queue.push(r.clone());
        }
    }
    if spec.progress && !outcomes.is_empty() {
        for o in &outcomes {
            eprintln!("skip    {} (complete; --force re-runs it)", o.name);
        }
    }
    let skipped = outcomes.len();
    let (job_tx, job_rx) = crossbeam::channel::unbounded::<ValidRun>();
    let (res_tx, res_rx) = crossbeam::channel::unbounded::<Outcome>();
    for r in queue {
        // The receiver lives until the end of this function.
        let _ = job_tx.send(r);
    }
    drop(job_tx);
    std::thread::scope(|s| {
        for _ in 0..jobs.max(1) {
            let rx = job_rx.clone();
            let tx = res_tx.clone();
            s.spawn(move || {
                for r in rx {
                    let _span = tracing::info_span!("sweep_run", name = %r.run.name).entered();
                    if tx.send(run_one(spec, &r)).is_err() {
                        break;
                    }
                }
            });
        }
        drop(res_tx);
        let mut finished = skipped;
        for o in res_rx {
            finished += 1;
            if spec.progress {
                eprintln!("{}", progress_line(&o, finished, total));
            }
            outcomes.push(o);
        }
    });
    outcomes.sort_by_key(|o| o.index);
    outcomes
}

fn progress_line(o: &Outcome, finished: usize, total: usize) -> String {
    let width = total.to_string().len();
    match &o.status {
        RunStatus::Ok => format!(
            "[{finished:>width$}/{total}] ok      {}  ({:.2} s)",
            o.name, o.wall_seconds
        ),
        RunStatus::Skipped => format!("[{finished:>width$}/{total}] skip    {}", o.name),
        RunStatus::Failed { reason, .. } => {
            let mut s = format!(
                "[{finished:>width$}/{total}] FAILED  {}  ({reason}, {:.2} s)",
                o.name, o.wall_seconds
            );
            for l in &o.log_tail {
                s.push_str("\n    | ");
                s.push_str(l);
            }
            s
        }
    }
}

fn failed_outcome(
    r: &ValidRun,
    reason: String,
    wall_seconds: f64,
    log_tail: Vec<String>,
) -> Outcome {
    Outcome {
        name: r.run.name.clone(),
        index: r.run.index,
        status: RunStatus::Failed {
            exit_code: None,
            reason,
        },
        wall_seconds,
        run_seconds: None,
        log_tail,
    }
}

/// Prepares the folder, runs the child, writes the log and the marker.
fn run_one(spec: &ChildSpec, r: &ValidRun) -> Outcome {
    let dir = spec.sweep_dir.join(&r.run.name);
    if let Err(e) = prepare_dir(&dir) {
        return failed_outcome(
            r,
            format!("cannot prepare the folder: {e}"),
            0.0,
            Vec::new(),
        );
    }
    let mut args: Vec<String> = vec!["run".into(), spec.config.display().to_string()];
    for a in spec.fixed.iter().cloned().chain(r.run.assignments()) {
        args.push("--set".into());
        args.push(a);
    }
    args.extend([
        "--out".into(),
        dir.display().to_string(),
        "--quiet".into(),
        "--threads".into(),
        spec.threads.to_string(),
    ]);
    let mut command = vec![spec.exe.display().to_string()];
    command.extend(args.iter().cloned());
    let record = RunRecord {
        name: r.run.name.clone(),
        index: r.run.index,
        overrides: r.run.overrides.clone(),
        fixed: spec.fixed.clone(),
        config: spec.config.display().to_string(),
        config_hash: r.config_hash.clone(),
        command: command.clone(),
    };
    if let Err(e) = write_json(&dir.join(RUN_RECORD), &record) {
        return failed_outcome(
            r,
            format!("cannot write {RUN_RECORD}: {e}"),
            0.0,
            Vec::new(),
        );
    }

    let started = Instant::now();
    let result = run_child(&spec.exe, &args, spec.timeout);
    let wall_seconds = started.elapsed().as_secs_f64();
    // A run killed on timeout leaves its temporary sibling folder.
    crate::output::staging::clean_stale_siblings(&dir);
    // A successful run replaces its whole folder (see `output::staging`), so
    // the record written before it started is written again.
    if let Err(e) = write_json(&dir.join(RUN_RECORD), &record) {
        return failed_outcome(
            r,
            format!("cannot write {RUN_RECORD}: {e}"),
            wall_seconds,
            Vec::new(),
        );
    }
    let (exit_code, status, stdout, stderr) = match result {
        Ok(c) => (c.exit_code, c.status, c.stdout, c.stderr),
        Err(e) => (
            None,
            format!("could not start {}: {e}", spec.exe.display()),
            Vec::new(),
            Vec::new(),
        ),
    };
    let mut log = String::new();
    log.push_str("$ ");
    log.push_str(&shell_words(&command));
    log.push_str("\n--- stdout ---\n");
    log.push_str(&String::from_utf8_lossy(&stdout));
    log.push_str("\n--- stderr ---\n");
    log.push_str(&String::from_utf8_lossy(&stderr));
    log.push_str(&format!("\n--- {status} after {wall_seconds:.3} s ---\n"));
    let log_tail = tail(
        &String::from_utf8_lossy(&stderr),
        &String::from_utf8_lossy(&stdout),
    );
    let log_written = crate::output::write_bytes_atomic(&dir.join(LOG), log.as_bytes());

    let ok = exit_code == Some(0);
    let completion = Completion {
        name: r.run.name.clone(),
        overrides: r.run.overrides.clone(),
        config_hash: r.config_hash.clone(),
        exit_code,
        status: status.clone(),
        wall_seconds,
        log_tail: if ok { Vec::new() } else { log_tail.clone() },
    };
    if ok {
        if let Err(e) = log_written {
            return failed_outcome(
                r,
                format!("cannot write {LOG}: {e}"),
                wall_seconds,
                Vec::new(),
            );
        }
        // The marker goes last: a folder without it is re-run.
        if let Err(e) = write_json(&dir.join(DONE), &completion) {
            return failed_outcome(
                r,
                format!("cannot write {DONE}: {e}"),
                wall_seconds,
                Vec::new(),
            );
        }
        return Outcome {
            name: r.run.name.clone(),
            index: r.run.index,
            status: RunStatus::Ok,
            wall_seconds,
            run_seconds: read_run_seconds(&dir),
            log_tail: Vec::new(),
        };
    }
    if let Err(e) = write_json(&dir.join(FAILED), &completion) {
        tracing::warn!("cannot write {FAILED} of {}: {e}", r.run.name);
    }
    Outcome {
        name: r.run.name.clone(),
        index: r.run.index,
        status: RunStatus::Failed {
            exit_code,
            reason: status,
        },
        wall_seconds,
        run_seconds: None,
        log_tail,
    }
}

/// Empties (or creates) a run folder: stale contents of an incomplete or
/// forced run must not mix with the new ones.
fn prepare_dir(dir: &Path) -> Result<(), String> {
    if dir.exists() {
        std::fs::remove_dir_all(dir).map_err(|e| e.to_string())?;
    }
    std::fs::create_dir_all(dir).map_err(|e| e.to_string())
}

fn write_json<T: Serialize>(path: &Path, value: &T) -> Result<(), String> {
    let text = serde_json::to_string_pretty(value).map_err(|e| e.to_string())?;
    crate::output::write_bytes_atomic(path, text.as_bytes()).map_err(|e| e.to_string())
}

fn read_run_seconds(dir: &Path) -> Option<f64> {
    let text = std::fs::read_to_string(dir.join("metrics.json")).ok()?;
    let v: serde_json::Value = serde_json::from_str(&text).ok()?;
    v["total_seconds"].as_f64()
}

/// The last non-empty lines of stderr (else stdout).
fn tail(stderr: &str, stdout: &str) -> Vec<String> {
    let text = if stderr.trim().is_empty() {
        stdout
    } else {
        stderr
    };
    let lines: Vec<&str> = text.lines().filter(|l| !l.trim().is_empty()).collect();
    lines[lines.len().saturating_sub(TAIL_LINES)..]
        .iter()
        .map(|l| l.chars().take(300).collect())
        .collect()
}

fn shell_words(words: &[String]) -> String {
    words
        .iter()
        .map(|w| {
            if !w.is_empty()
                && w.chars()
                    .all(|c| c.is_ascii_alphanumeric() || "._-/=:+,".contains(c))
            {
                w.clone()
            } else {
                format!("'{}'", w.replace('\'', r"'\''"))
            }
        })
        .collect::<Vec<_>>()
        .join(" ")
}

struct ChildResult {
    exit_code: Option<i32>,
    status: String,
    stdout: Vec<u8>,
    stderr: Vec<u8>,
}

/// Runs the child with captured output, killing it after `timeout`.
fn run_child(
    exe: &Path,
    args: &[String],
    timeout: Option<Duration>,
) -> std::io::Result<ChildResult> {
    let mut child = Command::new(exe)
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()?;
    let reader = |pipe: Option<Box<dyn Read + Send>>| {
        std::thread::spawn(move || {
            let mut buf = Vec::new();
            if let Some(mut p) = pipe {
                let _ = p.read_to_end(&mut buf);
            }
            buf
        })
    };
    let out = reader(
        child
            .stdout
            .take()
            .map(|p| Box::new(p) as Box<dyn Read + Send>),
    );
    let err = reader(
        child
            .stderr
            .take()
            .map(|p| Box::new(p) as Box<dyn Read + Send>),
    );
    let mut timed_out = None;
    let status = match timeout {
        None => child.wait()?,
        Some(limit) => {
            let started = Instant::now();
            loop {
                if let Some(s) = child.try_wait()? {
                    break s;
                }
                if started.elapsed() >= limit {
                    let _ = child.kill();
                    timed_out = Some(limit);
                    break child.wait()?;
                }
                std::thread::sleep(Duration::from_millis(5));
            }
        }
    };
    let stdout = out.join().unwrap_or_default();
    let stderr = err.join().unwrap_or_default();
    let exit_code = if timed_out.is_some() {
        None
    } else {
        status.code()
    };
    let text = match (timed_out, status.code()) {
        (Some(limit), _) => format!("timed out after {} s", limit.as_secs_f64()),
        (None, Some(0)) => "ok".to_string(),
        (None, Some(c)) => format!("exit {c}"),
        (None, None) => signal_text(&status),
    };
    Ok(ChildResult {
        exit_code,
        status: text,
        stdout,
        stderr,
    })
}

#[cfg(unix)]
fn signal_text(status: &std::process::ExitStatus) -> String {
    use std::os::unix::process::ExitStatusExt;
    match status.signal() {
        Some(s) => format!("killed by signal {s}"),
        None => format!("{status}"),
    }
}

#[cfg(not(unix))]
fn signal_text(status: &std::process::ExitStatus) -> String {
    format!("{status}")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tail_prefers_stderr_and_keeps_the_last_lines() {
        let err = (1..=10).map(|i| format!("e{i}\n")).collect::<String>();
        assert_eq!(tail(&err, "out"), ["e5", "e6", "e7", "e8", "e9", "e10"]);
        assert_eq!(tail("  \n", "a\n\nb\n"), ["a", "b"]);
    }

    #[test]
    fn shell_words_quote_what_a_shell_would_split() {
        let w = ["surfsynth".to_string(), "x=[1, 2]".into(), "it's".into()];
        assert_eq!(shell_words(&w), r"surfsynth 'x=[1, 2]' 'it'\''s'");
    }

    #[test]
    fn completion_marker_needs_exit_zero_and_the_same_config() {
        let dir = tempfile::tempdir().unwrap();
        let mut c = Completion {
            name: "seed=1".into(),
            overrides: vec![("seed".into(), "1".into())],
            config_hash: "abc".into(),
            exit_code: Some(0),
            status: "ok".into(),
            wall_seconds: 0.1,
            log_tail: Vec::new(),
        };
        assert!(!is_complete(dir.path(), "abc"));
        write_json(&dir.path().join(DONE), &c).unwrap();
        assert!(is_complete(dir.path(), "abc"));
        assert!(!is_complete(dir.path(), "other"));
        c.exit_code = Some(2);
        write_json(&dir.path().join(DONE), &c).unwrap();
        assert!(!is_complete(dir.path(), "abc"));
    }
}
