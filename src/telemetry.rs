//! Logging and tracing: `RUST_LOG` sets verbosity (default `info`), and
//! `--trace FILE` records every span in Chrome's trace format (open it in
//! Perfetto or chrome://tracing).
//!
//! Log lines are coloured only when stderr is a terminal and `NO_COLOR` is
//! unset or empty (<https://no-color.org>), so piped logs and the `log.txt`
//! of a sweep hold no escape codes. In the trace, the span of a stage is
//! named after its kind (`stage:graph_match`): tracing's span names are
//! static, so [`StageKindLayer`] remembers each stage span's `kind` field and
//! the Chrome layer names the span from it.

use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use tracing::field::{Field, Visit};
use tracing_subscriber::layer::Context;
use tracing_subscriber::prelude::*;
use tracing_subscriber::registry::LookupSpan;

/// The name of the span every stage runs in (`pipeline::build_schedule`);
/// its `kind` field names the stage in the trace.
pub const STAGE_SPAN: &str = "stage";

/// Whether log lines get ANSI colours: only on a terminal, and never when
/// `NO_COLOR` is set to a non-empty value.
pub fn use_colour(stderr_is_terminal: bool, no_color: Option<&std::ffi::OsStr>) -> bool {
    stderr_is_terminal && no_color.is_none_or(|v| v.is_empty())
}

/// The `kind` of a stage span, kept in the span's extensions.
struct StageKind(String);

/// Records the `kind` field of every [`STAGE_SPAN`] span.
struct StageKindLayer;

struct KindVisitor(Option<String>);

impl Visit for KindVisitor {
    fn record_str(&mut self, field: &Field, value: &str) {
        if field.name() == "kind" {
            self.0 = Some(value.to_string());
        }
    }
    fn record_debug(&mut self, field: &Field, value: &dyn std::fmt::Debug) {
        if field.name() == "kind" && self.0.is_none() {
            self.0 = Some(format!("{value:?}"));
        }
    }
}

impl<S> tracing_subscriber::Layer<S> for StageKindLayer
where
    S: tracing::Subscriber + for<'a> LookupSpan<'a>,
{
    fn on_new_span(
        &self,
        attrs: &tracing::span::Attributes<'_>,
        id: &tracing::span::Id,
        ctx: Context<'_, S>,
    ) {
        if attrs.metadata().name() != STAGE_SPAN {
            return;
        }
        let mut visitor = KindVisitor(None);
        attrs.record(&mut visitor);
        if let (Some(kind), Some(span)) = (visitor.0, ctx.span(id)) {
            span.extensions_mut().insert(StageKind(kind));
        }
    }
}

/// The trace name of a span or event: `stage:<kind>` for stage spans, the
/// static name otherwise.
fn trace_name<S>(item: &tracing_chrome::EventOrSpan<'_, '_, S>) -> String
where
    S: tracing::Subscriber + for<'a> LookupSpan<'a> + Send + Sync,
{
    match item {
        tracing_chrome::EventOrSpan::Event(e) => e.metadata().name().to_string(),
        tracing_chrome::EventOrSpan::Span(s) => match s.extensions().get::<StageKind>() {
            Some(StageKind(kind)) => format!("{STAGE_SPAN}:{kind}"),
            None => s.metadata().name().to_string(),
        },
    }
}

/// Keeps the trace file open; dropping it flushes the trace and moves the
/// temporary file into place.
pub struct TraceGuard {
    chrome: Option<tracing_chrome::FlushGuard>,
    tmp: PathBuf,
    path: PathBuf,
}

impl TraceGuard {
    /// Flushes and renames the trace file.
    ///
    /// # Errors
    /// When the trace could not be written whole (the writer drops its
    /// errors, e.g. a full disk: a complete trace ends its JSON array with
    /// `]`), or renamed; the partial file is removed.
    pub fn finish(mut self) -> std::io::Result<()> {
        if let Some(g) = self.chrome.take() {
            drop(g);
            let bytes = {
                use std::io::{Read, Seek, SeekFrom};
                let mut f = std::fs::File::open(&self.tmp)?;
                let len = f.metadata()?.len();
                f.seek(SeekFrom::Start(len.saturating_sub(64)))?;
                let mut tail = Vec::new();
                f.read_to_end(&mut tail)?;
                tail
            };
            let end = bytes.iter().rev().find(|b| !b.is_ascii_whitespace());
            if end != Some(&b']') {
                let _ = std::fs::remove_file(&self.tmp);
                return Err(std::io::Error::other(format!(
                    "the trace could not be written whole to {} (is the disk full?)",
                    self.tmp.display()
                )));
            }
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
        .with_writer(crate::progress::stderr_above_bars)
        .with_target(false)
        .with_ansi(use_colour(
            std::io::stderr().is_terminal(),
            std::env::var_os("NO_COLOR").as_deref(),
        ))
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
                .name_fn(Box::new(trace_name))
                .build();
            // The kind layer sits below the Chrome layer, so a stage span has
            // its kind recorded before the Chrome layer names it.
            let _ = tracing_subscriber::registry()
                .with(fmt)
                .with(StageKindLayer)
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
