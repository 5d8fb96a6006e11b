//! Issue 16, logs and library use: no colour codes in piped logs, one log
//! line per stage start and end, trace spans named after the stage kind,
//! floats printed shortest in `stages`, the resolved config and
//! `metrics.json`, and the
//! library example and the Python driver running as documented.

use std::path::Path;
use std::process::{Command, Output};
use surfsynth::config::ConfigSource;
use surfsynth::pipeline::Pipeline;

#[path = "../../examples/library.rs"]
#[allow(dead_code)]
mod library;

/// A quick run: three stages on a small icosphere. `normal_strength` is an
/// `f32` of `[input]` whose widening to `f64` prints as 0.20000000298023224.
const RUN: &str = r#"
seed = 1
[input]
mesh = "builtin:icosphere"
exemplar = "builtin:bricks"
normal_strength = 0.2
[input.exemplar_options]
size = 32

[[stage]]
kind = "orientation"

[[stage]]
kind = "init_colours"

[[stage]]
kind = "export"
formats = ["ply"]
"#;

const RUN_KINDS: [&str; 3] = ["orientation", "init_colours", "export"];

/// Stages with `f32` fractions (0.1, 0.97, 0.2, 0.3 by default), validated
/// only: a resolved config is text, no run is needed.
const FRACTIONS: &str = r#"
seed = 1
[input]
mesh = "builtin:icosphere"
exemplar = "builtin:bricks"
normal_strength = 0.2

[[stage]]
kind = "orientation"

[[stage]]
kind = "jump_map"
pca_sample = 0.2

[[stage]]
kind = "jump_surface"
patch_fraction = 0.3

[[stage]]
kind = "export"
"#;

/// Runs `surfsynth run` on `config` (written to `dir`) with stderr piped.
fn run_cli(dir: &Path, config: &str, extra: &[&str], env: &[(&str, &str)]) -> Output {
    let path = dir.join("config.toml");
    std::fs::write(&path, config).expect("write config");
    let out = dir.join("out");
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_surfsynth"));
    cmd.arg("run")
        .arg(&path)
        .arg("--out")
        .arg(&out)
        .args(extra)
        .env_remove("NO_COLOR");
    for (k, v) in env {
        cmd.env(k, v);
    }
    let output = cmd.output().expect("run surfsynth");
    assert!(
        output.status.success(),
        "surfsynth run failed: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    output
}

/// A decimal with seven or more digits after the point: the long form of a
/// widened `f32` (`0.20000000298023224`, `0.9700000286102295`).
fn long_floats(text: &str) -> Vec<String> {
    text.split(|c: char| !(c.is_ascii_digit() || c == '.' || c == '-' || c == 'e'))
        .filter(|w| {
            w.split_once('.')
                .is_some_and(|(_, frac)| frac.chars().take_while(char::is_ascii_digit).count() >= 7)
        })
        .map(str::to_string)
        .collect()
}

#[test]
fn piped_stderr_has_no_colour_codes() {
    let dir = tempfile::tempdir().expect("temp dir");
    let output = run_cli(dir.path(), RUN, &[], &[("RUST_LOG", "info")]);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("started"),
        "no log lines on stderr:\n{stderr}"
    );
    assert!(
        !stderr.contains("\x1b["),
        "ANSI escape codes in piped stderr:\n{stderr:?}"
    );
}

#[test]
fn colour_only_on_a_terminal_without_no_color() {
    use std::ffi::OsStr;
    use surfsynth::telemetry::use_colour;
    assert!(
        use_colour(true, None),
        "a terminal without NO_COLOR is coloured"
    );
    assert!(
        use_colour(true, Some(OsStr::new(""))),
        "an empty NO_COLOR does not count (no-color.org)"
    );
    assert!(
        !use_colour(true, Some(OsStr::new("1"))),
        "NO_COLOR=1 is honoured"
    );
    assert!(!use_colour(false, None), "a pipe is never coloured");
}

#[test]
fn each_stage_logs_one_start_and_one_end_line() {
    let dir = tempfile::tempdir().expect("temp dir");
    let output = run_cli(dir.path(), RUN, &[], &[("RUST_LOG", "info")]);
    let stderr = String::from_utf8_lossy(&output.stderr);
    for (i, kind) in RUN_KINDS.iter().enumerate() {
        let start = format!("stage {} ({kind}) started", i + 1);
        let end = format!("stage {} ({kind}) done in", i + 1);
        for needle in [&start, &end] {
            let lines: Vec<&str> = stderr.lines().filter(|l| l.contains(needle)).collect();
            assert_eq!(lines.len(), 1, "{needle:?} should be one line:\n{stderr}");
            assert_eq!(
                lines[0].matches(kind).count(),
                1,
                "the line repeats the stage kind: {:?}",
                lines[0]
            );
        }
    }
}

#[test]
fn trace_names_stage_spans_after_their_kind() {
    let dir = tempfile::tempdir().expect("temp dir");
    let trace = dir.path().join("trace.json");
    let trace_arg = trace.to_string_lossy().into_owned();
    run_cli(dir.path(), RUN, &["--trace", &trace_arg, "--quiet"], &[]);
    let text = std::fs::read_to_string(&trace).expect("trace written");
    let events: Vec<serde_json::Value> = serde_json::from_str(&text).expect("trace is JSON");
    let names: Vec<&str> = events.iter().filter_map(|e| e["name"].as_str()).collect();
    for kind in RUN_KINDS {
        let name = format!("stage:{kind}");
        assert!(
            names.contains(&name.as_str()),
            "no trace event named {name:?}; names: {names:?}"
        );
    }
}

#[test]
fn stages_prints_floats_shortest() {
    let output = Command::new(env!("CARGO_BIN_EXE_surfsynth"))
        .arg("stages")
        .output()
        .expect("run surfsynth stages");
    assert!(output.status.success());
    let text = String::from_utf8_lossy(&output.stdout);
    let long = long_floats(&text);
    assert!(long.is_empty(), "long floats in `stages`: {long:?}");
    for line in [
        "boundary_fraction      = 0.2 [fraction]",
        "pca_variance           = 0.97 [fraction]",
    ] {
        assert!(text.contains(line), "`stages` lacks {line:?}");
    }
}

/// Every float under `value`, with its path.
fn floats(value: &serde_json::Value, path: &str, out: &mut Vec<(String, f64)>) {
    match value {
        serde_json::Value::Number(n) if n.is_f64() => out.push((path.into(), n.as_f64().unwrap())),
        serde_json::Value::Array(a) => a
            .iter()
            .enumerate()
            .for_each(|(i, v)| floats(v, &format!("{path}[{i}]"), out)),
        serde_json::Value::Object(m) => m
            .iter()
            .for_each(|(k, v)| floats(v, &format!("{path}.{k}"), out)),
        _ => {}
    }
}

#[test]
fn metrics_json_prints_f32_metrics_shortest() {
    let dir = tempfile::tempdir().expect("temp dir");
    run_cli(dir.path(), RUN, &["--quiet"], &[]);
    let text = std::fs::read_to_string(dir.path().join("out/metrics.json")).expect("metrics");
    let metrics: serde_json::Value = serde_json::from_str(&text).expect("JSON");
    // The result measures are `f32`s: each is written as the `f32`'s own
    // shortest text (0.2, not the 0.20000000298023224 of its widening).
    let mut found = Vec::new();
    floats(&metrics["result"]["quality"], "result.quality", &mut found);
    assert!(
        found
            .iter()
            .any(|(p, _)| p.ends_with("texture_energy.spacing_world_units")),
        "{found:?}"
    );
    // An `f32`'s shortest text has at most 9 significant digits; its
    // widening to `f64` needs 16 or 17.
    for (path, x) in &found {
        let text = x.to_string();
        let mantissa = text.split('e').next().unwrap_or_default();
        let digits = mantissa
            .chars()
            .filter(char::is_ascii_digit)
            .skip_while(|&c| c == '0')
            .count();
        assert!(digits <= 9, "{path} = {text}: written as a widened f32");
    }
}

#[test]
fn resolved_config_prints_floats_shortest_and_reloads_to_the_same_values() {
    let pipeline =
        Pipeline::from_source(ConfigSource::from_text("fractions", FRACTIONS)).expect("valid");
    let resolved = pipeline.resolved_toml();
    let long = long_floats(&resolved);
    assert!(
        long.is_empty(),
        "long floats in the resolved config: {long:?}\n{resolved}"
    );
    for line in [
        "normal_strength = 0.2",
        "pca_sample = 0.2",
        "patch_fraction = 0.3",
    ] {
        assert!(resolved.contains(line), "no {line:?} in:\n{resolved}");
    }
    let reloaded = Pipeline::from_source(ConfigSource::from_text("resolved", &resolved))
        .expect("the resolved config loads");
    assert_eq!(
        reloaded.input.normal_strength,
        pipeline.input.normal_strength
    );
    for (a, b) in pipeline.stages.iter().zip(&reloaded.stages) {
        assert_eq!(
            a.resolved(),
            b.resolved(),
            "stage {} changed on reload",
            a.kind()
        );
    }
    let body = |text: &str| text.split_once("\n\n").map(|(_, b)| b.to_string());
    assert_eq!(
        body(&reloaded.resolved_toml()),
        body(&resolved),
        "resolving is a fixed point (below the header naming the source)"
    );

    // The file the CLI writes into the output folder is the same text.
    let dir = tempfile::tempdir().expect("temp dir");
    run_cli(dir.path(), RUN, &["--quiet"], &[]);
    let written = std::fs::read_to_string(dir.path().join("out/config.toml")).expect("config");
    assert!(written.contains("normal_strength = 0.2"), "{written}");
    assert!(long_floats(&written).is_empty(), "{written}");
}

#[test]
fn library_example_runs_and_reports_metrics() {
    let dir = tempfile::tempdir().expect("temp dir");
    let report = library::run_config(dir.path()).expect("the example's config runs");
    let completeness = report.metrics["result"]["quality"]["completeness"].as_f64();
    assert!(
        completeness.is_some_and(|c| (0.0..=1.0).contains(&c)),
        "completeness {completeness:?}"
    );
    assert_eq!(report.timings.len(), 3);
    assert!(dir.path().join("metrics.json").is_file());
    assert!(dir.path().join("result.ply").is_file());
}

#[test]
fn python_example_drives_the_cli_and_reads_metrics() {
    let python = Command::new("python3").arg("--version").output();
    if !python.is_ok_and(|o| o.status.success()) {
        println!("skipped: python3 is not on PATH");
        return;
    }
    let dir = tempfile::tempdir().expect("temp dir");
    let config = dir.path().join("config.toml");
    std::fs::write(&config, RUN).expect("write config");
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/run_from_python.py");
    let output = Command::new("python3")
        .arg(&script)
        .arg(&config)
        .arg("seed=2")
        .env("SURFSYNTH", env!("CARGO_BIN_EXE_surfsynth"))
        .output()
        .expect("run python3");
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(
        output.status.success(),
        "the Python example failed:\n{stdout}\n{}",
        String::from_utf8_lossy(&output.stderr)
    );
    assert!(stdout.contains("completeness: 0."), "{stdout}");
    assert!(stdout.contains("stage 2 init_colours:"), "{stdout}");
}
