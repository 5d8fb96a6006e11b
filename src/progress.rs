//! Progress of long work: a bar with an ETA on a terminal, a log line at most
//! every [`DEFAULT_LOG_INTERVAL_MS`] otherwise (a pipe, a sweep's `log.txt`),
//! nothing with `--quiet`.
//!
//! Kernels take a `&Progress` and call [`Progress::inc`]; the handle is cheap
//! to clone and thread-safe, so rayon workers can tick it. Off a terminal,
//! `inc` is one atomic add, one clock read and one atomic load; only the
//! thread that wins the compare-exchange on the next-line time writes a line,
//! so the lines are rate limited however many threads tick. Progress never
//! changes a result: kernels only report to it.
//!
//! A stage of several phases (pyramid levels, passes) labels the current one
//! with [`Progress::set_part`] (`"level 2/4"`) and, when each phase is
//! counted on its own, restarts the count with [`Progress::set_length`] and
//! [`Progress::set_position`].

use std::io::IsTerminal;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

static ENABLED: AtomicBool = AtomicBool::new(true);

/// The least time between two progress log lines off a terminal.
pub const DEFAULT_LOG_INTERVAL_MS: u64 = 10_000;

/// The environment variable that overrides [`DEFAULT_LOG_INTERVAL_MS`]
/// (milliseconds; tests set it to 0 or 1 to see lines from short stages).
pub const INTERVAL_ENV: &str = "SURFSYNTH_PROGRESS_INTERVAL_MS";

/// Turns all progress bars and progress log lines off (tests, `--quiet`) or
/// back on.
pub fn set_enabled(on: bool) {
    ENABLED.store(on, Ordering::Relaxed);
}

/// Whether progress is shown at all (false after `set_enabled(false)`).
pub fn enabled() -> bool {
    ENABLED.load(Ordering::Relaxed)
}

/// The log interval: [`INTERVAL_ENV`] when it holds a whole number, else the
/// default.
fn log_interval() -> Duration {
    let ms = std::env::var(INTERVAL_ENV)
        .ok()
        .and_then(|v| v.trim().parse::<u64>().ok())
        .unwrap_or(DEFAULT_LOG_INTERVAL_MS);
    Duration::from_millis(ms)
}

/// A progress handle; a no-op when hidden.
#[derive(Clone, Debug, Default)]
pub struct Progress(Option<Sink>);

#[derive(Clone, Debug)]
enum Sink {
    /// A terminal: indicatif draws and rate-limits itself.
    Bar(indicatif::ProgressBar, Arc<str>),
    /// Not a terminal: rate-limited `tracing::info!` lines.
    Log(Arc<LogState>),
}

/// The counters of a logged progress; times are milliseconds since `start`.
#[derive(Debug)]
struct LogState {
    what: String,
    part: Mutex<String>,
    start: Instant,
    interval_ms: u64,
    pos: AtomicU64,
    len: AtomicU64,
    /// When the next line may be written.
    next_ms: AtomicU64,
    /// Where and when the current phase began, for the ETA.
    phase_pos: AtomicU64,
    phase_ms: AtomicU64,
}

impl LogState {
    fn new(len: u64, what: &str, interval: Duration) -> Self {
        let interval_ms = u64::try_from(interval.as_millis()).unwrap_or(u64::MAX);
        Self {
            what: what.to_string(),
            part: Mutex::new(String::new()),
            start: Instant::now(),
            interval_ms,
            pos: AtomicU64::new(0),
            len: AtomicU64::new(len),
            next_ms: AtomicU64::new(interval_ms),
            phase_pos: AtomicU64::new(0),
            phase_ms: AtomicU64::new(0),
        }
    }

    fn now_ms(&self) -> u64 {
        u64::try_from(self.start.elapsed().as_millis()).unwrap_or(u64::MAX)
    }

    /// Claims the right to write a line at `now`: true for exactly one caller
    /// per interval.
    fn claim(&self, now: u64) -> bool {
        let next = self.next_ms.load(Ordering::Relaxed);
        now >= next
            && self
                .next_ms
                .compare_exchange(
                    next,
                    now.saturating_add(self.interval_ms),
                    Ordering::Relaxed,
                    Ordering::Relaxed,
                )
                .is_ok()
    }

    fn restart_phase(&self) {
        self.phase_pos
            .store(self.pos.load(Ordering::Relaxed), Ordering::Relaxed);
        self.phase_ms.store(self.now_ms(), Ordering::Relaxed);
    }

    /// The log line at `now`: `what part: pos/len (pct%), eta left`.
    fn line(&self, now: u64) -> String {
        let pos = self.pos.load(Ordering::Relaxed);
        let len = self.len.load(Ordering::Relaxed);
        let done = pos.saturating_sub(self.phase_pos.load(Ordering::Relaxed));
        let spent = now.saturating_sub(self.phase_ms.load(Ordering::Relaxed));
        let part = self.part.lock().map(|p| p.clone()).unwrap_or_default();
        format_line(&self.what, &part, pos, len, done, spent)
    }
}

/// `what part: pos/len (pct%), eta left`, the ETA extrapolated from `done`
/// steps in `spent_ms` of the current phase ("?" before any step).
fn format_line(what: &str, part: &str, pos: u64, len: u64, done: u64, spent_ms: u64) -> String {
    let pct = if len == 0 {
        100.0
    } else {
        100.0 * pos.min(len) as f64 / len as f64
    };
    let eta = if done == 0 {
        "?".to_string()
    } else {
        let left_ms = len.saturating_sub(pos) as f64 * spent_ms as f64 / done as f64;
        format_duration(Duration::from_millis(left_ms as u64))
    };
    let sep = if part.is_empty() { "" } else { " " };
    format!("{what}{sep}{part}: {pos}/{len} ({pct:.0}%), {eta} left")
}

/// `1h02m`, `3m05s`, `12s`.
fn format_duration(d: Duration) -> String {
    let s = d.as_secs();
    if s >= 3600 {
        format!("{}h{:02}m", s / 3600, (s % 3600) / 60)
    } else if s >= 60 {
        format!("{}m{:02}s", s / 60, s % 60)
    } else {
        format!("{s}s")
    }
}

impl Progress {
    /// A progress of `len` steps labelled `what` (the stage kind): a bar on
    /// a terminal, log lines otherwise, hidden after `set_enabled(false)`.
    pub fn new(len: u64, what: &str) -> Self {
        if !enabled() {
            return Self(None);
        }
        if std::io::stderr().is_terminal() {
            Self::bar(len, what)
        } else {
            Self::logged(len, what, log_interval())
        }
    }

    fn bar(len: u64, what: &str) -> Self {
        let bar = indicatif::ProgressBar::new(len);
        if let Ok(style) =
            indicatif::ProgressStyle::with_template("{msg:>24} [{bar:40}] {pos}/{len} ({eta} left)")
        {
            bar.set_style(style.progress_chars("=> "));
        }
        bar.set_message(what.to_string());
        Self(Some(Sink::Bar(bar, Arc::from(what))))
    }

    /// A progress that logs a line at most every `interval`, whatever the
    /// terminal (tests).
    pub fn logged(len: u64, what: &str, interval: Duration) -> Self {
        Self(Some(Sink::Log(Arc::new(LogState::new(
            len, what, interval,
        )))))
    }

    /// A handle that shows nothing.
    pub fn hidden() -> Self {
        Self(None)
    }

    /// Advances by `n` steps.
    #[inline]
    pub fn inc(&self, n: u64) {
        match &self.0 {
            None => {}
            Some(Sink::Bar(b, _)) => b.inc(n),
            Some(Sink::Log(s)) => {
                s.pos.fetch_add(n, Ordering::Relaxed);
                let now = s.now_ms();
                if s.claim(now) {
                    tracing::info!("{}", s.line(now));
                }
            }
        }
    }

    /// Labels the current phase, e.g. `"level 2/4"` (shown after the stage
    /// name).
    pub fn set_part(&self, part: &str) {
        match &self.0 {
            None => {}
            Some(Sink::Bar(b, what)) => b.set_message(format!("{what} {part}")),
            Some(Sink::Log(s)) => {
                if let Ok(mut p) = s.part.lock() {
                    *p = part.to_string();
                }
            }
        }
    }

    /// Sets the number of steps (the position is kept) and restarts the ETA.
    pub fn set_length(&self, len: u64) {
        self.restart(
            |b| b.set_length(len),
            |s| s.len.store(len, Ordering::Relaxed),
        );
    }

    /// Moves to step `pos` (e.g. 0 at the start of a phase counted on its
    /// own) and restarts the ETA.
    pub fn set_position(&self, pos: u64) {
        self.restart(
            |b| b.set_position(pos),
            |s| s.pos.store(pos, Ordering::Relaxed),
        );
    }

    /// Applies a change to the bar or the logged counters, then restarts
    /// the ETA from here.
    fn restart(&self, bar: impl FnOnce(&indicatif::ProgressBar), log: impl FnOnce(&LogState)) {
        match &self.0 {
            None => {}
            Some(Sink::Bar(b, _)) => {
                bar(b);
                b.reset_eta();
            }
            Some(Sink::Log(s)) => {
                log(s);
                s.restart_phase();
            }
        }
    }

    /// Starts a phase counted on its own: label `part`, `len` steps, from 0.
    pub fn start_part(&self, part: &str, len: u64) {
        self.set_part(part);
        self.set_length(len);
        self.set_position(0);
    }

    /// Removes the bar (a logged progress writes nothing more).
    pub fn finish(&self) {
        if let Some(Sink::Bar(b, _)) = &self.0 {
            b.finish_and_clear();
        }
    }

    /// A guard that [`finish`](Self::finish)es this progress when it is
    /// dropped: a stage that returns early (an error, nothing to measure)
    /// does not leave its bar standing on the terminal.
    pub fn finish_on_drop(&self) -> FinishOnDrop<'_> {
        FinishOnDrop(self)
    }

    /// The line a logged progress would write now (tests).
    pub fn current_line(&self) -> Option<String> {
        match &self.0 {
            Some(Sink::Log(s)) => Some(s.line(s.now_ms())),
            _ => None,
        }
    }
}

/// Finishes a [`Progress`] when dropped ([`Progress::finish_on_drop`]).
#[must_use = "the progress is finished when the guard is dropped"]
#[derive(Debug)]
pub struct FinishOnDrop<'a>(&'a Progress);

impl Drop for FinishOnDrop<'_> {
    fn drop(&mut self) {
        self.0.finish();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_guard_finishes_the_bar_on_an_early_return() {
        let bar = indicatif::ProgressBar::hidden();
        bar.set_length(5);
        let progress = Progress(Some(Sink::Bar(bar.clone(), Arc::from("stage"))));
        let stage = |early: bool| {
            let _finish = progress.finish_on_drop();
            progress.inc(1);
            if early {
                return;
            }
            progress.inc(4);
        };
        stage(true);
        assert!(bar.is_finished(), "finished after an early return");
        // Without the guard the bar would stay at 1 of 5.
        let other = indicatif::ProgressBar::hidden();
        other.set_length(5);
        other.inc(1);
        assert!(!other.is_finished());
    }

    #[test]
    fn one_line_per_interval_however_many_ticks() {
        let s = LogState::new(100, "retile", Duration::from_millis(50));
        // Before the first interval nothing is claimed.
        assert!(!s.claim(0));
        assert!(!s.claim(49));
        // Exactly one claim per interval, even when many threads ask.
        assert!(s.claim(50));
        assert!(!s.claim(50));
        assert!(!s.claim(99));
        assert!(s.claim(100));
        let claims = std::thread::scope(|scope| {
            let handles: Vec<_> = (0..8)
                .map(|_| scope.spawn(|| (0..1000).filter(|_| s.claim(200)).count()))
                .collect();
            handles
                .into_iter()
                .map(|h| h.join().unwrap_or(0))
                .sum::<usize>()
        });
        assert_eq!(claims, 1, "one line for eight threads at the same time");
    }

    #[test]
    fn zero_interval_claims_every_tick() {
        let s = LogState::new(10, "x", Duration::ZERO);
        assert!(s.claim(0));
        assert!(s.claim(0));
        assert!(s.claim(1));
    }

    #[test]
    fn a_sparse_ticker_still_logs() {
        // One tick per phase (a pyramid level): each tick after the interval
        // writes a line, with no stride that would skip rare ticks.
        let s = LogState::new(4, "retile", Duration::from_millis(10));
        assert!(s.claim(10));
        assert!(s.claim(25));
        assert!(s.claim(1000));
    }

    #[test]
    fn line_names_stage_part_percent_and_eta() {
        assert_eq!(
            format_line("retile", "level 2/4", 25, 100, 25, 10_000),
            "retile level 2/4: 25/100 (25%), 30s left"
        );
        assert_eq!(
            format_line("bake", "", 0, 10, 0, 0),
            "bake: 0/10 (0%), ? left"
        );
        assert_eq!(format_line("x", "", 5, 0, 5, 1), "x: 5/0 (100%), 0s left");
        assert_eq!(format_duration(Duration::from_secs(185)), "3m05s");
        assert_eq!(format_duration(Duration::from_secs(3720)), "1h02m");
    }

    #[test]
    fn phases_restart_the_count_and_the_eta() {
        let p = Progress::logged(10, "graph_match", Duration::from_secs(3600));
        p.inc(10);
        p.start_part("level 2/2", 40);
        p.inc(10);
        let line = p.current_line().unwrap_or_default();
        assert!(
            line.starts_with("graph_match level 2/2: 10/40 (25%), "),
            "{line}"
        );
        // A hidden handle takes every call and shows nothing.
        let h = Progress::hidden();
        h.inc(1);
        h.start_part("a", 2);
        h.finish();
        assert!(h.current_line().is_none());
    }
}
