//! Experiment sweeps (`surfsynth sweep`): the cartesian product of `--grid`
//! overrides, each run a child process into its own folder, then a summary
//! (`summary.csv`, `summary.json`) and a self-contained `index.html` over
//! every run present in the sweep folder.
//!
//! * [`plan`]: grid parsing, the run list, folder names, shards.
//! * [`execute`]: the worker pool of child processes, completion markers.
//! * [`summary`]: reading the run folders back, flattening `metrics.json`.
//! * [`columns`]: each column's unit, direction and group on the page.
//! * [`html`]: the report page.
//!
//! Layout of a sweep folder `DIR`:
//!
//! ```text
//! DIR/sweep.json              config, grid, fixed overrides, exemplars, last invocation's timing
//! DIR/exemplar_<hash>.png     each distinct exemplar of the sweep
//! DIR/summary.csv|json        one row per run folder present
//! DIR/index.html              previews + sortable metrics table
//! DIR/<name>/run.json         what the run is (written before it starts)
//! DIR/<name>/log.txt          the child's command line, stdout, stderr, exit status
//! DIR/<name>/done.json        completion marker, written last (exit 0 only)
//! DIR/<name>/failed.json      exit status and log tail of a failed run
//! DIR/<name>/...              the run's own outputs (metrics.json, preview_*.png, view.html linked from the page, ...)
//! ```

pub mod columns;
pub mod execute;
pub mod html;
pub mod plan;
pub mod summary;

pub use execute::{Outcome, RunStatus};
pub use plan::{GridAxis, PlannedRun, Shard, parse_grid};

/// Longest `--timeout` accepted (about 31 700 years), far inside `Duration`.
const MAX_TIMEOUT_SECONDS: f64 = 1e12;

use crate::config::{ConfigError, ConfigSource};
use crate::output::OutputError;
use crate::pipeline::Pipeline;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// Everything that can go wrong in a sweep, with its exit code.
#[derive(Debug, thiserror::Error)]
pub enum SweepError {
    /// A `--grid` argument is malformed (exit 2).
    #[error("--grid {arg}: {message}")]
    Grid { arg: String, message: String },
    /// A `--shard` argument is malformed (exit 2).
    #[error("--shard {arg}: {message}")]
    Shard { arg: String, message: String },
    /// Another command-line option is wrong (exit 2).
    #[error("{flag}: {message}")]
    Option { flag: String, message: String },
    /// The config cannot be read or parsed (exit 2).
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// One combination of the grid gives an invalid config (exit 2); no run
    /// was started.
    #[error("run {run} (--set {assignments}): {source}")]
    InvalidRun {
        run: String,
        assignments: String,
        #[source]
        source: Box<ConfigError>,
    },
    /// One combination's input (mesh, exemplar, maps) cannot be loaded,
    /// or its run folder is taken by someone else's files (exit 2); no run
    /// was started.
    #[error("run {run} (--set {assignments}): {source}")]
    InvalidInput {
        run: String,
        assignments: String,
        #[source]
        source: Box<crate::pipeline::PipelineError>,
    },
    /// A sweep file could not be read or written (exit 1).
    #[error(transparent)]
    Output(#[from] OutputError),
    /// The sweep folder or a run folder could not be prepared or read (exit 1).
    #[error("{path}: {message}")]
    Io { path: PathBuf, message: String },
    /// Some runs failed; the summary was written and names them (exit 1).
    #[error("{failed} of {total} runs failed; see {summary}")]
    RunsFailed {
        failed: usize,
        total: usize,
        summary: PathBuf,
    },
}

impl SweepError {
    /// 2 for anything the user can fix on the command line or in the config,
    /// 1 for failed runs and file-system failures.
    pub fn exit_code(&self) -> i32 {
        match self {
            SweepError::Grid { .. }
            | SweepError::Shard { .. }
            | SweepError::Option { .. }
            | SweepError::Config(_)
            | SweepError::InvalidRun { .. } => 2,
            SweepError::InvalidInput { source, .. } => source.exit_code(),
            SweepError::Output(_) | SweepError::Io { .. } | SweepError::RunsFailed { .. } => 1,
        }
    }
}

pub(crate) fn io_err(path: &Path) -> impl Fn(std::io::Error) -> SweepError + '_ {
    move |e| SweepError::Io {
        path: path.to_path_buf(),
        message: e.to_string(),
    }
}

/// What `surfsynth sweep` was asked to do.
#[derive(Clone, Debug)]
pub struct SweepOptions {
    /// The base config.
    pub config: PathBuf,
    /// `--grid PATH=V1,V2,...` arguments, outermost first.
    pub grid: Vec<String>,
    /// `--set PATH=VALUE` overrides shared by every run.
    pub fixed: Vec<String>,
    /// The sweep folder.
    pub out: PathBuf,
    /// Runs at a time (at least 1).
    pub jobs: usize,
    /// Worker threads per run; default: cores / jobs, at least 1.
    pub threads: Option<usize>,
    /// `--shard I/N` as given.
    pub shard: Option<String>,
    /// Re-run completed runs too.
    pub force: bool,
    /// Only validate and list the runs.
    pub dry_run: bool,
    /// Kill a run after this long (seconds).
    pub timeout: Option<f64>,
    /// The executable that runs one config (`surfsynth`, normally
    /// `std::env::current_exe()`).
    pub exe: PathBuf,
    /// A progress line per finished run on stderr.
    pub progress: bool,
}

/// A validated run: its plan entry and the hash of its resolved config.
#[derive(Clone, Debug)]
pub struct ValidRun {
    /// Name, index and overrides.
    pub run: PlannedRun,
    /// blake3 of the resolved config (every default filled in); a completed
    /// run is only skipped when it matches.
    pub config_hash: String,
}

/// `DIR/sweep.json`: what the sweep is, for `--summarise` and readers.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct SweepRecord {
    /// The base config as given.
    pub config: String,
    /// The `--grid` arguments.
    pub grid: Vec<String>,
    /// The `--set` overrides shared by all runs.
    pub fixed: Vec<String>,
    /// Number of runs in the full (unsharded) grid.
    pub total_runs: usize,
    /// Exemplar images written into the folder.
    pub exemplars: Vec<ExemplarRecord>,
    /// Timing of the most recent invocation that ran anything.
    pub last_invocation: Option<InvocationStats>,
}

/// One exemplar picture of the report.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ExemplarRecord {
    /// File name inside the sweep folder.
    pub file: String,
    /// `[input].exemplar` as written.
    pub spec: String,
    /// `[input].exemplar_options` as TOML text (empty when none).
    pub options: String,
}

/// Timing of one invocation: where the time outside the runs went.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct InvocationStats {
    /// `I/N` or `1/1`.
    pub shard: String,
    /// Runs started by this invocation.
    pub ran: usize,
    /// Runs skipped as complete.
    pub skipped: usize,
    /// Runs that failed.
    pub failed: usize,
    /// Parallel runs.
    pub jobs: usize,
    /// Threads per run.
    pub threads: usize,
    /// Wall time of the whole invocation (validation to summary), seconds.
    pub wall_seconds: f64,
    /// Validating every combination, seconds.
    pub validate_seconds: f64,
    /// Sum of the runs' own `total_seconds` (from their `metrics.json`; a
    /// failed run counts its child wall time).
    pub sum_run_seconds: f64,
    /// Sum of the child processes' wall times as the sweep measured them.
    pub sum_child_seconds: f64,
    /// `(wall_seconds × min(jobs, ran) − sum_run_seconds) / ran`: the
    /// worker-slot time per run not spent inside the run itself (process
    /// start, folder preparation, logs, markers, validation, summary).
    pub overhead_per_run_seconds: Option<f64>,
    /// `(sum_child_seconds − sum_run_seconds) / ran`: process start-up and
    /// exit per run.
    pub process_overhead_per_run_seconds: Option<f64>,
}

/// What a sweep did.
#[derive(Clone, Debug)]
pub struct SweepReport {
    /// Every validated run of the full grid, in order.
    pub runs: Vec<ValidRun>,
    /// The runs of this shard, in order.
    pub selected: Vec<usize>,
    /// What happened to each selected run (empty for a dry run).
    pub outcomes: Vec<Outcome>,
    /// Timing (None for a dry run).
    pub stats: Option<InvocationStats>,
    /// `summary.csv`, `summary.json`, `index.html` (empty for a dry run).
    pub files: Vec<PathBuf>,
}

/// Files a sweep writes at the top of its folder (beside `exemplar_*.png`).
const SUMMARY_FILES: [&str; 4] = ["sweep.json", "summary.csv", "summary.json", "index.html"];

/// A folder without a sweep's record (`sweep.json`) that holds files of
/// the names a sweep writes at its top is someone else's: refused, since
/// the sweep would overwrite them (issue 43). Other files beside a sweep
/// are never touched.
fn check_not_someone_elses(out: &Path) -> Result<(), String> {
    if out.join("sweep.json").is_file() {
        return Ok(());
    }
    let Ok(entries) = std::fs::read_dir(out) else {
        return Ok(());
    };
    let mut taken: Vec<String> = entries
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| {
            SUMMARY_FILES.contains(&n.as_str())
                || (n.starts_with("exemplar_") && n.ends_with(".png"))
        })
        .collect();
    if taken.is_empty() {
        return Ok(());
    }
    taken.sort();
    Err(format!(
        "{} holds {} but no sweep.json, so it is not a sweep's folder, and a sweep would overwrite them; allowed: a new folder, one without those names, or the --out folder of an earlier sweep",
        out.display(),
        taken.join(", ")
    ))
}

/// The sweep's own options (`--jobs`, `--threads`, `--out`, `--timeout`,
/// `--shard`), checked before any config is read.
fn check_options(opts: &SweepOptions) -> Result<(Option<Duration>, Shard), SweepError> {
    if opts.jobs == 0 {
        return Err(SweepError::Option {
            flag: "--jobs".into(),
            message: "must be at least 1".into(),
        });
    }
    if let Some(n) = opts.threads {
        crate::preflight::check_threads(n).map_err(|message| SweepError::Option {
            flag: "--threads".into(),
            message,
        })?;
    }
    if !opts.dry_run {
        crate::preflight::check_folder_target(&opts.out)
            .and_then(|()| check_not_someone_elses(&opts.out))
            .map_err(|message| SweepError::Option {
                flag: "--out".into(),
                message,
            })?;
    }
    let timeout = match opts.timeout {
        None => None,
        Some(t) if t.is_finite() && t > 0.0 && t <= MAX_TIMEOUT_SECONDS => {
            Some(Duration::from_secs_f64(t))
        }
        Some(t) => {
            return Err(SweepError::Option {
                flag: "--timeout".into(),
                message: format!(
                    "{t} is not allowed; allowed: seconds in (0, {MAX_TIMEOUT_SECONDS:e}]"
                ),
            });
        }
    };
    let shard = match &opts.shard {
        Some(s) => Shard::parse(s)?,
        None => Shard { index: 1, count: 1 },
    };
    Ok((timeout, shard))
}

/// Every planned run's config, validated as `run` would (settings, order,
/// input files, each distinct input loaded once), with its resolved
/// config's hash; and the distinct
/// exemplars of the grid (key, report file name, options) with an input
/// that names each.
struct Validated {
    runs: Vec<ValidRun>,
    exemplars: Vec<(String, String, String)>,
    /// An `[input]` naming each exemplar, and the folder its path
    /// resolves against.
    exemplar_inputs: Vec<(crate::config::RawInput, PathBuf)>,
}

/// [`Validated`] for the `planned` runs of `opts`.
fn validate(opts: &SweepOptions, planned: Vec<plan::PlannedRun>) -> Result<Validated, SweepError> {
    let base = ConfigSource::from_file(&opts.config)?;
    // The fixed overrides alone, so that a bad one is named as such.
    base.clone().apply_overrides(&opts.fixed)?;
    let mut runs = Vec::with_capacity(planned.len());
    let mut exemplars: Vec<(String, String, String)> = Vec::new();
    let mut exemplar_inputs = Vec::new();
    // Each distinct input is loaded once, as its runs will load it, so
    // that a file that is not a mesh or an image is refused before any
    // run (issue 43: a garbage grid exemplar ran the other runs first).
    let mut loaded_inputs: Vec<String> = Vec::new();
    for run in planned {
        let mut source = base.clone();
        let mut assignments = opts.fixed.clone();
        assignments.extend(run.assignments());
        let invalid = |source: ConfigError| SweepError::InvalidRun {
            run: run.name.clone(),
            assignments: run.assignments().join(" --set "),
            source: Box::new(source),
        };
        source.apply_overrides(&assignments).map_err(invalid)?;
        let pipeline = Pipeline::from_source(source).map_err(invalid)?;
        // Input files too (a grid over exemplars or meshes), as `run` checks
        // them before it loads anything.
        crate::pipeline::check_input_files(&pipeline.input, &pipeline.source).map_err(invalid)?;
        let input_key = input_key(&pipeline);
        if !loaded_inputs.contains(&input_key) {
            crate::pipeline::load_input_from(&pipeline.input, &pipeline.source).map_err(|e| {
                SweepError::InvalidInput {
                    run: run.name.clone(),
                    assignments: run.assignments().join(" --set "),
                    source: Box::new(e),
                }
            })?;
            loaded_inputs.push(input_key);
        }
        let config_hash = blake3::hash(pipeline.resolved_toml().as_bytes())
            .to_hex()
            .to_string();
        let options = if pipeline.input.exemplar_options.is_empty() {
            String::new()
        } else {
            toml::to_string(&pipeline.input.exemplar_options).unwrap_or_default()
        };
        let key = format!("{}\n{}", pipeline.input.exemplar, options);
        if !exemplars.iter().any(|(k, _, _)| *k == key) {
            let file = format!(
                "exemplar_{}.png",
                &blake3::hash(key.as_bytes()).to_hex()[..8]
            );
            exemplars.push((key, file, options));
            exemplar_inputs.push((
                pipeline.input.clone(),
                pipeline.source.base_dir_for("input.exemplar").to_path_buf(),
            ));
        }
        runs.push(ValidRun { run, config_hash });
    }
    Ok(Validated {
        runs,
        exemplars,
        exemplar_inputs,
    })
}

/// What decides how a run loads its input: `[input]` and the folders its
/// paths resolve against (the config's, or the current one for `--set`).
fn input_key(pipeline: &Pipeline) -> String {
    let table = crate::config::params::to_table(&pipeline.input);
    let dirs: Vec<&Path> = crate::pipeline::INPUT_FILE_KEYS
        .iter()
        .map(|key| pipeline.source.base_dir_for(key))
        .collect();
    format!("{table}{dirs:?}")
}

/// Refuses a selected run whose folder is not the sweep's (no sweep record
/// `run.json`) and holds files that are not a run's (a user's file or
/// folder of that name): its run would fail, or the folder be emptied,
/// after the runs before it.
fn check_run_folders(out: &Path, runs: &[ValidRun], selected: &[usize]) -> Result<(), SweepError> {
    use crate::output::staging::{check_replaceable, holds_sweep_record};
    for r in selected.iter().map(|&i| &runs[i].run) {
        let dir = out.join(&r.name);
        if dir.is_dir() && holds_sweep_record(&dir) {
            continue;
        }
        check_replaceable(&dir).map_err(|message| SweepError::InvalidInput {
            run: r.name.clone(),
            assignments: r.assignments().join(" --set "),
            source: Box::new(
                ConfigError::Value {
                    file: "command line".into(),
                    key: "--out".into(),
                    message: format!("the run's folder: {message}"),
                }
                .into(),
            ),
        })?;
    }
    Ok(())
}

/// The timing of this invocation's runs, for `sweep.json` and the report.
fn invocation_stats(
    outcomes: &[Outcome],
    shard: &Shard,
    jobs: usize,
    threads: usize,
    wall_seconds: f64,
    validate_seconds: f64,
) -> InvocationStats {
    let ran: Vec<&Outcome> = outcomes
        .iter()
        .filter(|o| o.status != RunStatus::Skipped)
        .collect();
    let failed = outcomes.iter().filter(|o| o.status.is_failure()).count();
    // A failed run has no metrics.json: its child wall time counts as its own.
    let sum_run_seconds: f64 = ran
        .iter()
        .map(|o| o.run_seconds.unwrap_or(o.wall_seconds))
        .sum();
    let sum_child_seconds: f64 = ran.iter().map(|o| o.wall_seconds).sum();
    let n = ran.len();
    InvocationStats {
        shard: format!("{}/{}", shard.index, shard.count),
        ran: n,
        skipped: outcomes.len() - n,
        failed,
        jobs,
        threads,
        wall_seconds,
        validate_seconds,
        sum_run_seconds,
        sum_child_seconds,
        overhead_per_run_seconds: (n > 0)
            .then(|| (wall_seconds * jobs.min(n) as f64 - sum_run_seconds) / n as f64),
        process_overhead_per_run_seconds: (n > 0)
            .then(|| (sum_child_seconds - sum_run_seconds) / n as f64),
    }
}

/// Validates every combination, then runs this shard's runs and writes the
/// summary. Returns [`SweepError::RunsFailed`] (after writing the summary)
/// when any run failed.
pub fn run_sweep(opts: &SweepOptions) -> Result<SweepReport, SweepError> {
    let started = Instant::now();
    let (timeout, shard) = check_options(opts)?;
    let axes = opts
        .grid
        .iter()
        .map(|g| parse_grid(g))
        .collect::<Result<Vec<_>, _>>()?;
    let planned = plan::plan(&axes, &opts.fixed)?;

    // Validate every combination before anything runs.
    let Validated {
        runs,
        exemplars,
        exemplar_inputs,
    } = validate(opts, planned)?;
    let validate_seconds = started.elapsed().as_secs_f64();
    let selected: Vec<usize> = (0..runs.len()).filter(|&i| shard.contains(i)).collect();
    if opts.dry_run {
        return Ok(SweepReport {
            runs,
            selected,
            outcomes: Vec::new(),
            stats: None,
            files: Vec::new(),
        });
    }

    check_run_folders(&opts.out, &runs, &selected)?;
    std::fs::create_dir_all(&opts.out).map_err(io_err(&opts.out))?;
    let mut record = SweepRecord {
        config: opts.config.display().to_string(),
        grid: opts.grid.clone(),
        fixed: opts.fixed.clone(),
        total_runs: runs.len(),
        exemplars: Vec::new(),
        last_invocation: read_record(&opts.out).and_then(|r| r.last_invocation),
    };
    for ((_, file, options), (input, base_dir)) in exemplars.iter().zip(&exemplar_inputs) {
        match write_exemplar(&opts.out.join(file), input, base_dir) {
            Ok(()) => record.exemplars.push(ExemplarRecord {
                file: file.clone(),
                spec: input.exemplar.clone(),
                options: options.clone(),
            }),
            Err(e) => tracing::warn!("exemplar {} not shown in the report: {e}", input.exemplar),
        }
    }
    write_record(&opts.out, &record)?;

    let threads = opts.threads.unwrap_or_else(|| {
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        (cores / opts.jobs).max(1)
    });
    let spec = execute::ChildSpec {
        exe: opts.exe.clone(),
        config: opts.config.clone(),
        fixed: opts.fixed.clone(),
        sweep_dir: opts.out.clone(),
        threads,
        timeout,
        force: opts.force,
        progress: opts.progress,
    };
    let jobs: Vec<ValidRun> = selected.iter().map(|&i| runs[i].clone()).collect();
    let outcomes = execute::execute(&spec, &jobs, opts.jobs);

    let n = outcomes
        .iter()
        .filter(|o| o.status != RunStatus::Skipped)
        .count();
    let failed = outcomes.iter().filter(|o| o.status.is_failure()).count();
    let summary_rows = summary::collect(&opts.out)?;
    let mut files = summary::write_all(&opts.out, &summary_rows, Some(&record))?;
    let stats = invocation_stats(
        &outcomes,
        &shard,
        opts.jobs,
        threads,
        started.elapsed().as_secs_f64(),
        validate_seconds,
    );
    if n > 0 {
        // Once more with this invocation's timing in sweep.json, summary.json
        // and index.html (the first write is part of the time measured).
        record.last_invocation = Some(stats.clone());
        write_record(&opts.out, &record)?;
        files = summary::write_all(&opts.out, &summary_rows, Some(&record))?;
    }
    if failed > 0 {
        return Err(SweepError::RunsFailed {
            failed,
            total: outcomes.len(),
            summary: opts.out.join("index.html"),
        });
    }
    Ok(SweepReport {
        runs,
        selected,
        outcomes,
        stats: Some(stats),
        files,
    })
}

/// Rebuilds `summary.csv`, `summary.json` and `index.html` from the run
/// folders present in `dir` (e.g. after the shards of a sweep ran on several
/// machines into copies of one folder that were merged).
pub fn summarise(dir: &Path) -> Result<Vec<PathBuf>, SweepError> {
    if !dir.is_dir() {
        return Err(SweepError::Option {
            flag: "--summarise".into(),
            message: format!("{} is not a folder", dir.display()),
        });
    }
    let rows = summary::collect(dir)?;
    let record = read_record(dir);
    if rows.is_empty() && record.is_none() {
        return Err(SweepError::Option {
            flag: "--summarise".into(),
            message: format!(
                "{} holds no sweep (no sweep.json and no run folders with run.json); give the --out folder of a sweep",
                dir.display()
            ),
        });
    }
    summary::write_all(dir, &rows, record.as_ref())
}

fn read_record(dir: &Path) -> Option<SweepRecord> {
    let text = std::fs::read_to_string(dir.join("sweep.json")).ok()?;
    serde_json::from_str(&text).ok()
}

fn write_record(dir: &Path, record: &SweepRecord) -> Result<(), SweepError> {
    let text = serde_json::to_string_pretty(record).map_err(|e| SweepError::Io {
        path: dir.join("sweep.json"),
        message: e.to_string(),
    })?;
    crate::output::write_bytes_atomic(&dir.join("sweep.json"), text.as_bytes())?;
    Ok(())
}

fn write_exemplar(
    path: &Path,
    input: &crate::config::RawInput,
    base_dir: &Path,
) -> Result<(), String> {
    let options: crate::image::ExemplarOptions = input
        .exemplar_options
        .clone()
        .try_into()
        .map_err(|e: toml::de::Error| e.message().to_string())?;
    let (img, _) = crate::image::exemplar_from_spec(&input.exemplar, base_dir, &options)
        .map_err(|e| e.to_string())?;
    crate::output::write_png(path, &img).map_err(|e| e.to_string())
}

/// The text `surfsynth sweep` prints at the end: the run list of a dry run,
/// else the counts, the timing and where the report is.
pub fn format_report(opts: &SweepOptions, report: &SweepReport) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let Some(stats) = &report.stats else {
        let _ = writeln!(
            s,
            "{} runs in the grid, {} in this shard (all configs valid):",
            report.runs.len(),
            report.selected.len()
        );
        for &i in &report.selected {
            let r = &report.runs[i];
            let dir = opts.out.join(&r.run.name);
            let state = if !opts.force && execute::is_complete(&dir, &r.config_hash) {
                "complete, would skip"
            } else {
                "would run"
            };
            let _ = writeln!(
                s,
                "{:>5}  {}  [{state}]\n       --set {}",
                r.run.index + 1,
                r.run.name,
                r.run.assignments().join(" --set ")
            );
        }
        return s;
    };
    let _ = writeln!(
        s,
        "sweep {}: {} runs in shard {}: {} ran, {} skipped (complete), {} failed",
        opts.out.display(),
        report.selected.len(),
        stats.shard,
        stats.ran,
        stats.skipped,
        stats.failed
    );
    let _ = writeln!(
        s,
        "wall {:.2} s ({} jobs x {} threads); runs' own time {:.2} s; validation {:.3} s",
        stats.wall_seconds,
        stats.jobs,
        stats.threads,
        stats.sum_run_seconds,
        stats.validate_seconds
    );
    if let (Some(o), Some(p)) = (
        stats.overhead_per_run_seconds,
        stats.process_overhead_per_run_seconds,
    ) {
        let _ = writeln!(
            s,
            "sweep overhead per run: {:.1} ms (of which process start/exit {:.1} ms)",
            o * 1000.0,
            p * 1000.0
        );
    }
    for f in &report.files {
        let _ = writeln!(s, "  {}", f.display());
    }
    s
}
