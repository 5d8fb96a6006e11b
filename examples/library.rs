//! Using surfsynth as a library: a pipeline from a TOML string (a builtin
//! mesh and exemplar, so no files are read), run into a temporary folder,
//! then the metrics read back from the report.
//!
//!     cargo run --release --example library

use std::error::Error;
use std::path::Path;
use surfsynth::config::ConfigSource;
use surfsynth::pipeline::{Pipeline, RunOptions, RunReport};

/// The config: random exemplar colours on a builtin icosphere, written as PLY.
/// Any config of `configs/` works the same way.
pub const CONFIG: &str = r#"
seed = 3

[input]
mesh = "builtin:icosphere"
exemplar = "builtin:bricks"
[input.exemplar_options]
size = 32

[[stage]]
kind = "orientation"

[[stage]]
kind = "init_colours"

[[stage]]
kind = "export"
formats = ["ply"]

[output]
dir = "out/library_example"
"#;

/// Validates [`CONFIG`], runs it into `out_dir` and returns the report (its
/// `metrics` are what `metrics.json` holds).
pub fn run_config(out_dir: &Path) -> Result<RunReport, Box<dyn Error>> {
    let source = ConfigSource::from_text("examples/library.rs", CONFIG);
    let pipeline = Pipeline::from_source(source)?;
    let options = RunOptions {
        out_dir: Some(out_dir.to_path_buf()),
    };
    Ok(surfsynth::pipeline::run(&pipeline, &options)?)
}

fn main() -> Result<(), Box<dyn Error>> {
    let dir = tempfile::tempdir()?;
    let report = run_config(dir.path())?;
    let quality = &report.metrics["result"]["quality"];
    println!("completeness: {}", quality["completeness"]);
    println!("coherence (mean): {}", quality["coherence"]["mean"]);
    for t in &report.timings {
        println!("stage {} {}: {:.3} s", t.index, t.kind, t.seconds);
    }
    println!(
        "files: {}",
        report
            .files
            .iter()
            .filter_map(|f| f.file_name())
            .map(|n| n.to_string_lossy())
            .collect::<Vec<_>>()
            .join(", ")
    );
    Ok(())
}
