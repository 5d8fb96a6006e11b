//! Logging and tracing: `RUST_LOG` sets verbosity (default `info`), and
//! `--trace FILE` records every span in Chrome's trace format (open it in
//! Perfetto or chrome://tracing).

use std::path::{Path, PathBuf};
use tracing_subscriber::prelude::*;

/// Keeps the trace file open; dropping it flushes the trace and moves the
/// temporary file into place.
pub struct TraceGuard {
    chrome: Option<tracing_chrome::FlushGuard>,
    tmp: PathBuf,
    path: PathBuf,
}

impl TraceGuard {
    /// Flushes and renames the trace file.
    pub fn finish(mut self) -> std::io::Result<()> {
        if let Some(g) = self.chrome.take() {
            drop(g);
            std::fs::rename(&self.tmp, &self.path)?;
        }
        Ok(())
    }
}

/// Installs the global subscriber: human-readable events on stderr filtered by
/// `RUST_LOG`, and a Chrome trace when `trace` is given.
pub fn init(trace: Option<&Path>, quiet: bool) -> Option<TraceGuard> {
    let default = if quiet { "warn" } else { "info" };
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(default));
    let fmt = tracing_subscriber::fmt::layer()
        .with_writer(std::io::stderr)
        .with_target(false)
        .compact()
        .with_filter(filter);
    match trace {
        Some(path) => {
            let name = path
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_else(|| "trace.json".into());
            let tmp = path.with_file_name(format!(".{name}.tmp"));
            if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
                let _ = std::fs::create_dir_all(dir);
            }
            let (chrome, guard) = tracing_chrome::ChromeLayerBuilder::new()
                .file(&tmp)
                .include_args(true)
                .build();
            let _ = tracing_subscriber::registry()
                .with(fmt)
                .with(chrome)
                .try_init();
            Some(TraceGuard {
                chrome: Some(guard),
                tmp,
                path: path.to_path_buf(),
            })
        }
        None => {
            let _ = tracing_subscriber::registry().with(fmt).try_init();
            None
        }
    }
}
