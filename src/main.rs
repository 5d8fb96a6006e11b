//! The `surfsynth` command line: parse, call the library, map errors to exit
//! codes (2: bad input, 1: internal failure).

use clap::{Parser, Subcommand};
use std::path::PathBuf;
use std::process::ExitCode;
use surfsynth::config::ConfigSource;
use surfsynth::pipeline::{Pipeline, PipelineError, RunOptions};

/// Texture synthesis over arbitrary 3D meshes.
#[derive(Parser, Debug)]
#[command(name = "surfsynth", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Runs a pipeline config.
    Run {
        /// The TOML config (see configs/).
        config: PathBuf,
        /// Overrides a value: dotted TOML path, `stage.N` counts from 1
        /// (e.g. --set seed=3 --set stage.2.iterations=50).
        #[arg(long = "set", value_name = "PATH=VALUE")]
        set: Vec<String>,
        /// Output folder (default: `[output].dir` of the config): new, empty,
        /// or an earlier run's, which is replaced as a whole at the end.
        #[arg(long)]
        out: Option<PathBuf>,
        /// Worker threads, 1..=1024 (default: all cores). Results do not
        /// depend on it.
        #[arg(long)]
        threads: Option<usize>,
        /// Writes a Chrome trace of every stage and kernel span to FILE
        /// (its folder must exist).
        #[arg(long, value_name = "FILE")]
        trace: Option<PathBuf>,
        /// Only warnings and errors on stderr, no progress bars.
        #[arg(long, short)]
        quiet: bool,
    },
    /// Lists every stage with its parameters, defaults, units and ranges.
    Stages {
        /// Show only this stage.
        kind: Option<String>,
    },
    /// Prints statistics of a mesh file (counts, boundaries, genus, edge lengths).
    MeshInfo {
        /// Mesh file (.obj .ply .off .stl) or builtin:NAME.
        file: String,
        /// Merge vertices at identical positions first.
        #[arg(long)]
        merge_duplicates: bool,
    },
    /// Runs a config over the cartesian product of --grid overrides, each run
    /// in its own folder, then writes summary.csv, summary.json and index.html.
    Sweep(SweepArgs),
    /// Shows or clears the analysis cache kept between runs (jump maps,
    /// appearance-space levels, texture patches).
    #[command(long_about = CACHE_HELP)]
    Cache {
        #[command(subcommand)]
        action: Option<CacheAction>,
    },
}

/// The long help of `surfsynth cache`.
const CACHE_HELP: &str = "\
Shows or clears the analysis cache kept between runs.

Where: $SURFSYNTH_CACHE, else $XDG_CACHE_HOME/surfsynth, else ~/.cache/surfsynth.

What: one file KIND-HASH.bin per analysis of an exemplar (HASH: of the \
exemplar's pixels and the analysis parameters): `jumpmap` (jump_map stage), \
`appearance` (coherent and jump_surface stages), `patches` (lapped_paste \
stage). Entries are re-validated when read and rebuilt when stale, so deleting \
them is always safe: the next run just analyses again. A stage's \
`cache = false` bypasses it.

Size: after each write the least recently used entries (read or written) are \
deleted while the entries total more than the limit: 1 GiB, or \
$SURFSYNTH_CACHE_LIMIT (bytes, or with suffix K, M, G: binary units, e.g. 500M, \
2G; 0 writes no entry). Other files in the folder are never touched.";

/// What `surfsynth cache` does.
#[derive(Subcommand, Debug)]
enum CacheAction {
    /// Prints the folder, its entries per kind, their total and the limit
    /// (the default).
    Show,
    /// Deletes every cache entry (and temporary files of killed writes);
    /// other files in the folder are kept.
    Clear,
}

/// `surfsynth sweep`: see README "Sweeps".
#[derive(clap::Args, Debug)]
struct SweepArgs {
    /// The base TOML config.
    #[arg(required_unless_present = "summarise")]
    config: Option<PathBuf>,
    /// A swept value list: dotted path as for --set, values split at commas
    /// outside [..], {..} and quotes; `\,` is a literal comma
    /// (e.g. --grid seed=1,2,3 --grid 'stage.2.neighbourhoods=[9,5,3],[7,3]').
    #[arg(long = "grid", value_name = "PATH=V1,V2,...")]
    grid: Vec<String>,
    /// A fixed override shared by every run.
    #[arg(long = "set", value_name = "PATH=VALUE")]
    set: Vec<String>,
    /// The sweep folder (one sub-folder per run).
    #[arg(long, required_unless_present = "summarise")]
    out: Option<PathBuf>,
    /// Runs at a time.
    #[arg(long, default_value_t = 1)]
    jobs: usize,
    /// Worker threads per run, 1..=1024 (default: cores / jobs, at least 1).
    #[arg(long)]
    threads: Option<usize>,
    /// Runs only every N-th run, starting at the I-th (1-based), e.g. 2/4.
    #[arg(long, value_name = "I/N")]
    shard: Option<String>,
    /// Re-runs runs that already hold a complete result.
    #[arg(long)]
    force: bool,
    /// Validates every combination and lists the runs without running them.
    #[arg(long)]
    dry_run: bool,
    /// Kills a run after this many seconds (it is reported as failed).
    #[arg(long, value_name = "SECONDS")]
    timeout: Option<f64>,
    /// Only rebuilds summary.csv, summary.json and index.html of DIR from
    /// the run folders present (e.g. after merging shards).
    #[arg(long, value_name = "DIR", conflicts_with_all = ["config", "grid", "set", "out", "shard", "force", "dry_run"])]
    summarise: Option<PathBuf>,
    /// No progress lines.
    #[arg(long, short)]
    quiet: bool,
}

/// glibc's malloc raises its mmap threshold after every large free (up to
/// 32 MiB), after which large buffers come from the heap arenas and their
/// pages stay resident once freed: a 92 k-vertex Wei–Levoy run peaked at
/// 159 MB resident for a 70 MB live heap. A fixed threshold of 128 KiB
/// keeps large buffers in their own mappings, returned to the system when
/// freed (127 MB resident for that run); results do not change.
///
/// The heap of smaller blocks is trimmed as soon as 128 KiB at its top are
/// free, and every page it grows back into comes zeroed by a page fault:
/// 36 000 faults, about a tenth of the CPU time, in a planar jump-map run.
/// Keeping [`HEAP_TOP_PAD`] at the top, and trimming only beyond twice
/// that, removes up to half of them: planar runs take up to 10 % less CPU
/// for 1–10 MB more resident memory (`docs/notes/whole_run_speed.md`). A
/// pad of 16 MiB saved little more and held 16 MB more at the peak of a
/// 137 k-vertex bake (`tests/it/memory.rs` caught it).
fn tune_allocator() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only sets a malloc parameter; called first thing in
    // main, before any other thread exists.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 128 * 1024);
        libc::mallopt(libc::M_TOP_PAD, HEAP_TOP_PAD);
        libc::mallopt(libc::M_TRIM_THRESHOLD, 2 * HEAP_TOP_PAD);
    }
}

/// Bytes of free heap kept at its top ([`tune_allocator`]).
#[cfg(all(target_os = "linux", target_env = "gnu"))]
const HEAP_TOP_PAD: i32 = 4 << 20;

fn main() -> ExitCode {
    tune_allocator();
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Sweep(args) => return sweep(args),
        Command::Run {
            config,
            set,
            out,
            threads,
            trace,
            quiet,
        } => run(config, set, out, threads, trace, quiet),
        Command::Stages { kind } => stages(kind.as_deref()),
        Command::MeshInfo {
            file,
            merge_duplicates,
        } => mesh_info(&file, merge_duplicates),
        Command::Cache { action } => cache(action.unwrap_or(CacheAction::Show)),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(e.exit_code() as u8)
        }
    }
}

fn run(
    config: PathBuf,
    set: Vec<String>,
    out: Option<PathBuf>,
    threads: Option<usize>,
    trace: Option<PathBuf>,
    quiet: bool,
) -> Result<(), PipelineError> {
    // An earlier result that a run killed in the middle of its commit left
    // set aside goes back first, whatever this run's options and config:
    // a refused run must not leave it hidden (`output::staging::recover`).
    if let Some(o) = &out {
        surfsynth::output::staging::recover(o);
    }
    // Options and paths are checked before any work; `--out` is checked by
    // `pipeline::run` before it loads the inputs.
    let option_err = |key: &str, message: String| {
        PipelineError::Config(surfsynth::config::ConfigError::Value {
            file: "command line".into(),
            key: key.into(),
            message,
        })
    };
    if let Some(n) = threads {
        surfsynth::preflight::check_threads(n).map_err(|m| option_err("--threads", m))?;
    }
    if let Some(t) = &trace {
        surfsynth::preflight::check_file_target(t).map_err(|m| option_err("--trace", m))?;
    }
    cache_limit()?;
    // The config is read before the trace starts: a trace file inside the
    // output folder would be replaced with it when the run commits.
    let mut source = ConfigSource::from_file(&config)?;
    source.apply_overrides(&set)?;
    if out.is_none()
        && let Some(dir) = source
            .text
            .parse::<toml::Table>()
            .ok()
            .and_then(|t| t.get("output")?.get("dir")?.as_str().map(PathBuf::from))
    {
        surfsynth::output::staging::recover(&dir);
    }
    let pipeline = Pipeline::from_source(source)?;
    if let Some(t) = &trace {
        let out_dir = out
            .clone()
            .unwrap_or_else(|| PathBuf::from(&pipeline.output.dir));
        surfsynth::preflight::check_file_outside(t, &out_dir)
            .map_err(|m| option_err("--trace", m))?;
    }
    surfsynth::output::staging::exit_cleanly_on_signals()
        .map_err(|e| PipelineError::Internal(format!("signal handler: {e}")))?;
    let guard = surfsynth::telemetry::init(trace.as_deref(), quiet);
    if quiet {
        surfsynth::progress::set_enabled(false);
    }
    if let Some(n) = threads {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build_global()
            .map_err(|e| PipelineError::Internal(format!("thread pool: {e}")))?;
    }
    let report = surfsynth::pipeline::run(&pipeline, &RunOptions { out_dir: out })?;
    if let Some(g) = guard {
        g.finish()
            .map_err(|e| PipelineError::Internal(format!("trace file: {e}")))?;
    }
    say(format_args!(
        "{}\n",
        surfsynth::pipeline::format_report(&report)
    ));
    Ok(())
}

fn stages(kind: Option<&str>) -> Result<(), PipelineError> {
    let text = surfsynth::pipeline::describe_stages(kind).map_err(|allowed| {
        PipelineError::Config(surfsynth::config::ConfigError::Value {
            file: "command line".into(),
            key: "stages KIND".into(),
            message: format!("no stage {:?}; allowed: {allowed}", kind.unwrap_or("")),
        })
    })?;
    say(format_args!("{text}"));
    Ok(())
}

/// `$SURFSYNTH_CACHE_LIMIT`, checked before any work (exit 2 when malformed).
fn cache_limit() -> Result<u64, PipelineError> {
    surfsynth::preflight::check_cache_limit().map_err(|message| {
        PipelineError::Config(surfsynth::config::ConfigError::Value {
            file: "environment".into(),
            key: surfsynth::cache::LIMIT_VAR.into(),
            message,
        })
    })
}

/// `surfsynth cache [show|clear]`.
fn cache(action: CacheAction) -> Result<(), PipelineError> {
    use surfsynth::cache::{self, format_size};
    let limit = cache_limit()?;
    let Some(dir) = cache::default_dir() else {
        say(format_args!(
            "no cache folder: none of SURFSYNTH_CACHE, XDG_CACHE_HOME, HOME is set\n"
        ));
        return Ok(());
    };
    match action {
        CacheAction::Show => {
            let summary = cache::summary(&dir);
            let missing = if dir.is_dir() {
                ""
            } else {
                " (does not exist yet)"
            };
            say(format_args!("cache folder: {}{missing}\n", dir.display()));
            for (kind, count, bytes) in &summary.kinds {
                let what = cache::KINDS
                    .iter()
                    .find(|(k, _)| k == kind)
                    .map_or(String::new(), |(_, w)| format!(" ({w})"));
                say(format_args!(
                    "  {kind}: {}, {}{what}\n",
                    entries(*count),
                    format_size(*bytes)
                ));
            }
            if summary.stale_tmp.0 > 0 {
                say(format_args!(
                    "  temporary files of killed writes: {}, {}\n",
                    summary.stale_tmp.0,
                    format_size(summary.stale_tmp.1)
                ));
            }
            if summary.other > 0 {
                say(format_args!(
                    "  other files (not the cache's, left alone): {}\n",
                    summary.other
                ));
            }
            let (count, bytes) = summary.total();
            let limit_from = match std::env::var(cache::LIMIT_VAR) {
                Ok(v) if !v.trim().is_empty() => cache::LIMIT_VAR,
                _ => "default; set SURFSYNTH_CACHE_LIMIT to change",
            };
            let off = if limit == 0 {
                ", no entry is written"
            } else {
                ""
            };
            say(format_args!(
                "total: {}, {}\nlimit: {} ({limit_from}{off})\n",
                entries(count),
                format_size(bytes),
                format_size(limit)
            ));
        }
        CacheAction::Clear => {
            let (count, bytes) = cache::clear(&dir);
            say(format_args!(
                "cleared {}: {} deleted, {} freed\n",
                dir.display(),
                files(count),
                format_size(bytes)
            ));
        }
    }
    Ok(())
}

/// `1 entry`, `2 entries`.
fn entries(n: usize) -> String {
    format!("{n} {}", if n == 1 { "entry" } else { "entries" })
}

/// `1 file`, `2 files`.
fn files(n: usize) -> String {
    format!("{n} file{}", if n == 1 { "" } else { "s" })
}

fn mesh_info(file: &str, merge_duplicates: bool) -> Result<(), PipelineError> {
    let (mesh, report) = if let Some(name) = file.strip_prefix("builtin:") {
        let mesh = surfsynth::mesh::builtin::builtin_mesh(name, &Default::default())?;
        (mesh, format!("builtin mesh {name}"))
    } else {
        let options = surfsynth::mesh::LoadOptions {
            merge_duplicates,
            ..Default::default()
        };
        let (mesh, report) = surfsynth::mesh::load_mesh(std::path::Path::new(file), &options)?;
        (mesh, report.summary())
    };
    say(format_args!("{file}\nrepairs: {report}\n"));
    say(format_args!(
        "{}\n",
        surfsynth::mesh::MeshInfo::compute(&mesh)
    ));
    Ok(())
}

fn sweep(args: SweepArgs) -> ExitCode {
    match sweep_inner(args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(e.exit_code() as u8)
        }
    }
}

fn sweep_inner(args: SweepArgs) -> Result<(), surfsynth::sweep::SweepError> {
    use surfsynth::sweep::{SweepError, SweepOptions};
    let _guard = surfsynth::telemetry::init(None, true);
    surfsynth::preflight::check_cache_limit().map_err(|message| SweepError::Option {
        flag: surfsynth::cache::LIMIT_VAR.into(),
        message,
    })?;
    if let Some(dir) = args.summarise {
        for f in surfsynth::sweep::summarise(&dir)? {
            say(format_args!("{}\n", f.display()));
        }
        return Ok(());
    }
    let (Some(config), Some(out)) = (args.config, args.out) else {
        return Err(SweepError::Option {
            flag: "sweep".into(),
            message: "give CONFIG and --out DIR (or --summarise DIR)".into(),
        });
    };
    let exe = std::env::current_exe().map_err(|e| SweepError::Io {
        path: "current executable".into(),
        message: e.to_string(),
    })?;
    let opts = SweepOptions {
        config,
        grid: args.grid,
        fixed: args.set,
        out,
        jobs: args.jobs,
        threads: args.threads,
        shard: args.shard,
        force: args.force,
        dry_run: args.dry_run,
        timeout: args.timeout,
        exe,
        progress: !args.quiet,
    };
    let report = surfsynth::sweep::run_sweep(&opts);
    if let Ok(r) = &report {
        say(format_args!(
            "{}",
            surfsynth::sweep::format_report(&opts, r)
        ));
    }
    report.map(|_| ())
}

/// Writes `text` to standard output. A reader that closed the pipe early
/// (`surfsynth stages | head`) ends the program quietly with success, as
/// command-line tools do, instead of the panic `print!` raises.
fn say(text: std::fmt::Arguments) {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    if let Err(e) = out.write_fmt(text).and_then(|()| out.flush()) {
        if e.kind() == std::io::ErrorKind::BrokenPipe {
            std::process::exit(0);
        }
        eprintln!("error: writing to standard output: {e}");
        std::process::exit(1);
    }
}
