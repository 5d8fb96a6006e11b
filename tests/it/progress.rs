//! Issue 15, progress: off a terminal every long stage logs
//! `<stage> <part>: <pos>/<len> (<pct>%), <eta> left` at most every
//! `SURFSYNTH_PROGRESS_INTERVAL_MS` (10 s by default), nothing with `-q`,
//! and progress never changes a result. Issue 39: a stage that plans its
//! parts says `(<pct>% of the stage)`, and a pyramid level is called the
//! same (`level 2 of 5 (0 = finest)`, the pyramid index) in the progress
//! line as in the `level` field of the stage's log spans.

use crate::common;

use crate::common::methods::{HEADER, method};
use std::path::Path;

/// The methods of `common::methods`, exported to PLY (the bake also to
/// GLB, at the smallest atlas).
fn wei_levoy() -> String {
    format!("{}{EXPORT_PLY}", method("wei_levoy"))
}

fn graph_match() -> String {
    format!("{}{EXPORT_PLY}", method("graph_match"))
}

fn jump_bake() -> String {
    format!(
        "{}size = 256\n[[stage]]\nkind = \"export\"\nformats = [\"ply\", \"glb\"]\n",
        method("bake")
    )
}

const EXPORT_PLY: &str = "[[stage]]\nkind = \"export\"\nformats = [\"ply\"]\n";

/// Height-map displacement with smoothing (needs `height_map` in `[input]`).
const DISPLACE: &str = r#"
[[stage]]
kind = "orientation"
up = [0.0, 0.0, 1.0]
[[stage]]
kind = "init_colours"
[[stage]]
kind = "displace"
smoothing = 2
[[stage]]
kind = "export"
formats = ["ply"]
"#;

/// Runs `surfsynth run` on `HEADER + stages`; see [`run_config`].
fn run(dir: &Path, stages: &str, interval_ms: &str, extra: &[&str]) -> (String, Vec<u8>) {
    run_config(dir, &format!("{HEADER}{stages}"), Some(interval_ms), extra)
}

/// Runs `surfsynth run` on `config` with stderr piped (not a terminal),
/// `RUST_LOG=info` and the given progress interval (the default for
/// `None`); returns the stderr and the bytes of the exported PLY.
fn run_config(
    dir: &Path,
    config: &str,
    interval_ms: Option<&str>,
    extra: &[&str],
) -> (String, Vec<u8>) {
    let path = dir.join("config.toml");
    std::fs::write(&path, config).expect("write config");
    let out = dir.join(format!("out-{interval_ms:?}-{}", extra.len()));
    let mut cmd = common::bin();
    match interval_ms {
        Some(ms) => cmd.env("SURFSYNTH_PROGRESS_INTERVAL_MS", ms),
        None => cmd.env_remove("SURFSYNTH_PROGRESS_INTERVAL_MS"),
    };
    let output = cmd
        .arg("run")
        .arg(&path)
        .arg("--out")
        .arg(&out)
        .args(extra)
        .env("RUST_LOG", "info")
        .env(
            "SURFSYNTH_CACHE",
            Path::new(env!("CARGO_TARGET_TMPDIR")).join("surfsynth-cache"),
        )
        .output()
        .expect("run surfsynth");
    let stderr = String::from_utf8_lossy(&output.stderr).into_owned();
    assert!(output.status.success(), "the run fails: {stderr}");
    let ply = std::fs::read_dir(&out)
        .expect("the output folder")
        .flatten()
        .map(|e| e.path())
        .find(|p| p.extension().is_some_and(|e| e == "ply"))
        .unwrap_or_else(|| panic!("no PLY in {}", out.display()));
    (stderr, std::fs::read(ply).expect("read the PLY"))
}

/// The progress lines of `stderr` (`... (NN%), ... left` or `... (NN% of
/// the stage), ... left`).
fn progress_lines(stderr: &str) -> Vec<&str> {
    stderr
        .lines()
        .filter(|l| l.contains('%') && l.contains("), ") && l.contains(" left"))
        .collect()
}

/// The pyramid level a progress line names (`level N of M (0 = finest)`)
/// and the `level=K` field of the span it was logged in, when it has both.
fn level_pair(line: &str) -> Option<(u32, u32)> {
    let named = line.split("level ").nth(1)?;
    let (n, rest) = named.split_once(' ')?;
    if !rest.starts_with("of ") || !rest.contains("(0 = finest)") {
        return None;
    }
    let field = line.split(" level=").nth(1)?;
    let k: String = field.chars().take_while(char::is_ascii_digit).collect();
    Some((n.parse().ok()?, k.parse().ok()?))
}

/// Checks that every progress line of `stage` naming a level inside a
/// level's span names the span's level, and that there is one.
fn assert_levels_agree(stderr: &str, stage: &str) {
    let pairs: Vec<(u32, u32)> = progress_lines(stderr)
        .into_iter()
        .filter(|l| l.contains(&format!("{stage} level ")))
        .filter_map(level_pair)
        .collect();
    assert!(
        !pairs.is_empty(),
        "no {stage} progress line with a level field:\n{stderr}"
    );
    for (named, field) in pairs {
        assert_eq!(
            named, field,
            "{stage}: the bar says level {named}, the log level={field}"
        );
    }
}

/// Checks that some progress line names `stage` with a part and a percent.
fn assert_logged(stderr: &str, stage: &str, part: &str) {
    let lines = progress_lines(stderr);
    let label = if part.is_empty() {
        format!("{stage}: ")
    } else {
        format!("{stage} {part}")
    };
    assert!(
        lines.iter().any(|l| l.contains(&label) && l.contains('%')),
        "no progress line of {stage} ({part}) in:\n{}",
        lines.join("\n")
    );
}

#[test]
fn long_stages_log_progress_off_a_terminal_and_not_with_quiet() {
    let dir = tempfile::tempdir().expect("a temporary folder");
    let (logged, ply) = run(dir.path(), &wei_levoy(), "0", &[]);
    assert_logged(&logged, "retile", "level 0 of 2 (0 = finest)");
    assert_logged(&logged, "retile", "level 1 of 2 (0 = finest)");
    assert_logged(&logged, "match", "level 1 of 2 (0 = finest)");
    assert_logged(&logged, "map_back", "");
    assert_logged(&logged, "result_metrics", "texture energy");
    assert_logged(&logged, "result_metrics", "quality");
    let (quiet, quiet_ply) = run(dir.path(), &wei_levoy(), "0", &["-q"]);
    assert!(
        progress_lines(&quiet).is_empty(),
        "-q shows no progress: {quiet}"
    );
    assert!(ply == quiet_ply, "progress changes the result");
}

#[test]
fn default_interval_keeps_a_short_run_silent() {
    // No interval override: a line at most every 10 s, and this run takes
    // a second or two.
    let dir = tempfile::tempdir().expect("a temporary folder");
    let started = std::time::Instant::now();
    let (stderr, _) = run_config(dir.path(), &format!("{HEADER}{}", graph_match()), None, &[]);
    if started.elapsed().as_secs() < 9 {
        assert!(
            progress_lines(&stderr).is_empty(),
            "a run shorter than the interval logs no progress: {stderr}"
        );
    }
}

#[test]
fn graph_match_logs_levels_and_passes() {
    let dir = tempfile::tempdir().expect("a temporary folder");
    let (logged, ply) = run(dir.path(), &graph_match(), "0", &[]);
    assert_logged(&logged, "subdivide_sqrt2", "step 1");
    assert_logged(&logged, "diffuse_orientation", "level 0 of ");
    assert_logged(&logged, "graph_match", "level 0 of ");
    assert!(
        progress_lines(&logged)
            .iter()
            .any(|l| l.contains("graph_match level") && l.contains(" pass 1/1:")),
        "{logged}"
    );
    let (quiet, quiet_ply) = run(dir.path(), &graph_match(), "0", &["--quiet"]);
    assert!(progress_lines(&quiet).is_empty(), "{quiet}");
    assert!(ply == quiet_ply, "progress changes the result");
}

#[test]
fn jump_map_bake_and_export_log_their_phases() {
    let dir = tempfile::tempdir().expect("a temporary folder");
    let (logged, ply) = run(dir.path(), &jump_bake(), "0", &[]);
    // One part since issue 43: each block of neighbours is filtered as
    // soon as it is found.
    assert_logged(&logged, "jump_map", "nearest neighbours and filtering");
    assert_logged(&logged, "bake", "atlas");
    assert_logged(&logged, "bake", "texels");
    assert_logged(&logged, "export", "ply");
    let (quiet, quiet_ply) = run(dir.path(), &jump_bake(), "0", &["-q"]);
    assert!(progress_lines(&quiet).is_empty(), "{quiet}");
    assert!(ply == quiet_ply, "progress changes the result");
}

#[test]
fn displace_logs_its_steps() {
    let dir = tempfile::tempdir().expect("a temporary folder");
    // The run needs a height map in `[input]`.
    let header = HEADER.replace(
        "exemplar_wrap",
        "height_map = \"derive:luminance\"\nexemplar_wrap",
    );
    let config = format!("{header}{DISPLACE}");
    let (stderr, _) = run_config(dir.path(), &config, Some("0"), &[]);
    assert_logged(&stderr, "displace", "smoothing");
    assert_logged(&stderr, "displace", "displacing");
}

/// Issue 39: one level numbering. Every progress line of the pyramid stages
/// (`retile`, `match`, `diffuse_orientation`, `graph_match`) logged inside
/// a level's span names the level the span's
/// `level` field does: the pyramid index, 0 the finest.
#[test]
fn level_labels_agree_with_the_log_fields() {
    let dir = tempfile::tempdir().expect("a temporary folder");
    let (wl, _) = run(dir.path(), &wei_levoy(), "0", &[]);
    assert_levels_agree(&wl, "retile");
    assert_levels_agree(&wl, "match");
    let (gm, _) = run(dir.path(), &graph_match(), "0", &[]);
    assert_levels_agree(&gm, "graph_match");
    assert_levels_agree(&gm, "diffuse_orientation");
    // The finest level is level 0 in the text too, and a planned stage
    // reports the share of the whole stage.
    assert!(
        progress_lines(&gm)
            .iter()
            .any(|l| l.contains("graph_match level 0 of ") && l.contains("% of the stage), ")),
        "{gm}"
    );
}
