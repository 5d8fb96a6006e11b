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
        /// Output folder (default: `[output].dir` of the config).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Worker threads (default: all cores). Results do not depend on it.
        #[arg(long)]
        threads: Option<usize>,
        /// Writes a Chrome trace of every stage and kernel span to FILE.
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
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
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
    let guard = surfsynth::telemetry::init(trace.as_deref(), quiet);
    if quiet {
        surfsynth::progress::set_enabled(false);
    }
    if let Some(n) = threads {
        if n == 0 {
            return Err(PipelineError::Config(
                surfsynth::config::ConfigError::Value {
                    file: "command line".into(),
                    key: "--threads".into(),
                    message: "must be at least 1".into(),
                },
            ));
        }
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build_global()
            .map_err(|e| PipelineError::Internal(format!("thread pool: {e}")))?;
    }
    let mut source = ConfigSource::from_file(&config)?;
    source.apply_overrides(&set)?;
    let pipeline = Pipeline::from_source(source)?;
    let report = surfsynth::pipeline::run(&pipeline, &RunOptions { out_dir: out })?;
    if let Some(g) = guard {
        g.finish()
            .map_err(|e| PipelineError::Internal(format!("trace file: {e}")))?;
    }
    println!("{}", surfsynth::pipeline::format_report(&report));
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
    print!("{text}");
    Ok(())
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
    println!("{file}\nrepairs: {report}");
    println!("{}", surfsynth::mesh::MeshInfo::compute(&mesh));
    Ok(())
}
