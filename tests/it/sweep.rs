//! `surfsynth sweep`: the grid becomes one folder per run, shards split it
//! without overlap, a failing run leaves the others complete, re-runs skip
//! complete runs, and bad arguments are refused before anything runs.

use crate::common::*;
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

/// Jump maps on a small torus, 3 previews of 64², no cache: well under a
/// second per run.
const TINY: &str = r#"
seed = 1
[input]
mesh = "builtin:torus"
exemplar = "builtin:bricks"
exemplar_wrap = "repeat"
[input.mesh_options]
resolution = [24, 12]
[input.exemplar_options]
size = 32

[[stage]]
kind = "orientation"
mode = "global"
up = [0.0, 0.0, 1.0]

[[stage]]
kind = "jump_map"
cache = false

[[stage]]
kind = "jump_surface"
scale = 30.0

[[stage]]
kind = "export"
formats = ["preview"]
preview_size = 64
"#;

struct Sweep {
    _tmp: tempfile::TempDir,
    config: PathBuf,
    out: PathBuf,
}

impl Sweep {
    fn new() -> Self {
        let tmp = tempfile::tempdir().unwrap();
        let config = tmp.path().join("tiny.toml");
        std::fs::write(&config, TINY).unwrap();
        let out = tmp.path().join("sweep");
        Self {
            _tmp: tmp,
            config,
            out,
        }
    }

    /// Runs `surfsynth sweep CONFIG --out OUT ARGS...`.
    fn run(&self, args: &[&str]) -> (i32, String, String) {
        let mut all = vec![
            "sweep",
            self.config.to_str().unwrap(),
            "--out",
            self.out.to_str().unwrap(),
            "--threads",
            "1",
        ];
        all.extend_from_slice(args);
        let (code, stdout, stderr) = run_cli(&all);
        assert!(!stderr.contains("panicked"), "{stderr}");
        (code, stdout, stderr)
    }

    /// Names of the run folders (those with a run.json).
    fn run_folders(&self) -> BTreeSet<String> {
        std::fs::read_dir(&self.out)
            .into_iter()
            .flatten()
            .flatten()
            .filter(|e| e.path().join("run.json").is_file())
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .collect()
    }

    fn csv(&self) -> Vec<Vec<String>> {
        let text = std::fs::read_to_string(self.out.join("summary.csv")).unwrap();
        text.lines().map(csv_fields).collect()
    }

    fn summary_json(&self) -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(self.out.join("summary.json")).unwrap())
            .unwrap()
    }
}

/// The fields of one CSV line (quoted fields may hold commas and `""`).
fn csv_fields(line: &str) -> Vec<String> {
    let mut fields = vec![String::new()];
    let mut quoted = false;
    let mut chars = line.chars().peekable();
    while let Some(c) = chars.next() {
        let cur = fields.last_mut().unwrap();
        match (c, quoted) {
            ('"', true) if chars.peek() == Some(&'"') => {
                cur.push('"');
                chars.next();
            }
            ('"', _) => quoted = !quoted,
            (',', false) => fields.push(String::new()),
            _ => cur.push(c),
        }
    }
    fields
}

fn column(csv: &[Vec<String>], name: &str) -> Vec<String> {
    let i = csv[0].iter().position(|c| c == name).unwrap_or_else(|| {
        panic!("no column {name} in {:?}", csv[0]);
    });
    csv[1..].iter().map(|r| r[i].clone()).collect()
}

/// `src="..."` attributes of an HTML page, percent-decoded.
fn image_sources(html: &str) -> Vec<String> {
    html.split("src=\"")
        .skip(1)
        .filter_map(|s| s.split('"').next())
        .map(|s| {
            let mut out = Vec::new();
            let b = s.as_bytes();
            let mut i = 0;
            while i < b.len() {
                if b[i] == b'%' && i + 2 < b.len() {
                    out.push(u8::from_str_radix(&s[i + 1..i + 3], 16).unwrap());
                    i += 3;
                } else {
                    out.push(b[i]);
                    i += 1;
                }
            }
            String::from_utf8(out).unwrap()
        })
        .collect()
}

fn mtime(p: &Path) -> std::time::SystemTime {
    std::fs::metadata(p).unwrap().modified().unwrap()
}

#[test]
fn grid_2x2_gives_four_folders_a_csv_of_four_rows_and_a_page_with_their_previews() {
    let s = Sweep::new();
    let (code, stdout, stderr) = s.run(&[
        "--grid",
        "seed=1,2",
        "--grid",
        "stage.3.scale=20,40.5",
        "--jobs",
        "2",
    ]);
    assert_eq!(code, 0, "{stdout}\n{stderr}");
    let expected: BTreeSet<String> = [
        "seed=1__stage.3.scale=20",
        "seed=1__stage.3.scale=40.5",
        "seed=2__stage.3.scale=20",
        "seed=2__stage.3.scale=40.5",
    ]
    .map(String::from)
    .into();
    assert_eq!(s.run_folders(), expected);
    for name in &expected {
        let dir = s.out.join(name);
        for f in ["done.json", "log.txt", "metrics.json", "preview_0.png"] {
            assert!(dir.join(f).is_file(), "{name}/{f} missing");
        }
    }
    assert_eq!(stderr.matches("] ok ").count(), 4, "{stderr}");
    assert!(stdout.contains("sweep overhead per run"), "{stdout}");

    let csv = s.csv();
    assert_eq!(csv.len(), 5, "header + 4 rows: {csv:?}");
    assert_eq!(column(&csv, "status"), ["ok"; 4]);
    assert_eq!(column(&csv, "exit_code"), ["0"; 4]);
    assert_eq!(column(&csv, "seed"), ["1", "1", "2", "2"], "run order");
    assert_eq!(column(&csv, "stage.3.scale"), ["20", "40.5", "20", "40.5"]);
    // The runs really got their overrides: the scale reported by the stage.
    let scales: Vec<f64> = column(&csv, "s3.jump_surface.mean_scale_pixels_per_unit")
        .iter()
        .map(|v| v.parse().unwrap())
        .collect();
    assert_eq!(scales, [20.0, 40.5, 20.0, 40.5]);
    for energy in column(&csv, "quality.texture_energy.mean") {
        assert!(energy.parse::<f64>().unwrap() > 0.0);
    }
    for c in [
        "run_seconds",
        "peak_rss_mib",
        "time.s2.jump_map",
        "input.vertices",
    ] {
        assert!(
            column(&csv, c).iter().all(|v| v.parse::<f64>().is_ok()),
            "{c}"
        );
    }
    // Different seeds give different results.
    let a = std::fs::read(s.out.join("seed=1__stage.3.scale=20/preview_0.png")).unwrap();
    let b = std::fs::read(s.out.join("seed=2__stage.3.scale=20/preview_0.png")).unwrap();
    assert_ne!(a, b);

    let json = s.summary_json();
    assert_eq!(json["runs"].as_array().unwrap().len(), 4);
    assert_eq!(json["sweep"]["total_runs"], 4);

    let html = std::fs::read_to_string(s.out.join("index.html")).unwrap();
    let sources = image_sources(&html);
    for name in &expected {
        let previews: Vec<&String> = sources
            .iter()
            .filter(|p| p.starts_with(&format!("{name}/preview")))
            .collect();
        assert!(!previews.is_empty(), "no preview of {name} in the page");
        for p in previews {
            assert!(s.out.join(p).is_file(), "{p} referenced but missing");
        }
    }
    let exemplars: Vec<&String> = sources
        .iter()
        .filter(|p| p.starts_with("exemplar"))
        .collect();
    assert_eq!(exemplars.len(), 1, "{sources:?}");
    assert!(s.out.join(exemplars[0]).is_file());
    assert_eq!(html.matches("<tr class=\"ok\"").count(), 4);
    assert!(
        html.contains("sweep overhead"),
        "timing of the invocation shown"
    );
    assert_eq!(json["sweep"]["last_invocation"]["ran"], 4);
    assert!(!html.contains("http://") && !html.contains("https://"));
    // Quality columns come before time columns; no run has a 3D viewer yet.
    let at = |key: &str| html.find(&format!("data-key=\"{key}\"")).unwrap();
    assert!(at("quality.coherence.mean") < at("run_seconds"));
    assert!(!html.contains("class=\"v3d\""));

    // A run folder holding view.html gets a 3D link in the rebuilt page.
    std::fs::write(
        s.out.join("seed=2__stage.3.scale=20/view.html"),
        "<!DOCTYPE html>",
    )
    .unwrap();
    let (code, _, stderr) = run_cli(&["sweep", "--summarise", s.out.to_str().unwrap()]);
    assert_eq!(code, 0, "{stderr}");
    let html = std::fs::read_to_string(s.out.join("index.html")).unwrap();
    assert_eq!(html.matches("class=\"v3d\"").count(), 1);
    assert!(html.contains("class=\"v3d\" href=\"seed%3D2__stage.3.scale%3D20/view.html\""));
    assert_eq!(
        s.summary_json()["runs"][2]["viewer"],
        "seed=2__stage.3.scale=20/view.html"
    );
}

#[test]
fn shards_one_and_two_of_two_cover_the_grid_exactly_once_and_merge_their_summary() {
    let s = Sweep::new();
    let grid = ["--grid", "seed=1,2,3", "--grid", "stage.3.scale=20,40"];
    let mut args = grid.to_vec();
    args.extend(["--shard", "1/2"]);
    let (code, _, stderr) = s.run(&args);
    assert_eq!(code, 0, "{stderr}");
    let first = s.run_folders();
    assert_eq!(first.len(), 3, "{first:?}");
    let marker = |n: &String| s.out.join(n).join("done.json");
    let times: Vec<_> = first.iter().map(|n| mtime(&marker(n))).collect();

    let mut args = grid.to_vec();
    args.extend(["--shard", "2/2"]);
    let (code, stdout, stderr) = s.run(&args);
    assert_eq!(code, 0, "{stderr}");
    assert!(stdout.contains("3 ran, 0 skipped"), "{stdout}");
    let all = s.run_folders();
    assert_eq!(all.len(), 6, "{all:?}");
    let second: BTreeSet<_> = all.difference(&first).cloned().collect();
    assert_eq!(second.len(), 3, "the shards overlap");
    assert_eq!(
        first.iter().map(|n| mtime(&marker(n))).collect::<Vec<_>>(),
        times,
        "shard 2 touched shard 1's runs"
    );
    // The summary after the second shard covers both.
    let csv = s.csv();
    assert_eq!(csv.len(), 7);
    assert_eq!(column(&csv, "status"), ["ok"; 6]);
    // --summarise rebuilds the same table from the folders.
    let before = std::fs::read_to_string(s.out.join("summary.csv")).unwrap();
    std::fs::remove_file(s.out.join("summary.csv")).unwrap();
    std::fs::remove_file(s.out.join("index.html")).unwrap();
    let (code, _, stderr) = run_cli(&["sweep", "--summarise", s.out.to_str().unwrap()]);
    assert_eq!(code, 0, "{stderr}");
    assert_eq!(
        std::fs::read_to_string(s.out.join("summary.csv")).unwrap(),
        before
    );
    assert!(s.out.join("index.html").is_file());
    // A folder that holds no sweep is refused, and nothing is written there.
    let empty = tempfile::tempdir().unwrap();
    let (code, _, stderr) = run_cli(&["sweep", "--summarise", empty.path().to_str().unwrap()]);
    assert_eq!(code, 2, "{stderr}");
    assert!(stderr.contains("holds no sweep"), "{stderr}");
    assert_eq!(std::fs::read_dir(empty.path()).unwrap().count(), 0);
}

#[test]
fn a_failing_run_leaves_the_others_complete_and_is_in_the_summary() {
    let s = Sweep::new();
    // A key on vertex 100000000 is a valid config, but after a retiling the
    // ids are the retiled mesh's, known only when the key's stage runs:
    // that run fails then (exit 2). (A bad input, such as a torus of 2
    // vertices around, is refused before any run since issue 43.)
    std::fs::write(&s.config, retiled_keys()).unwrap();
    let keys = "stage.2.keys=[{vertex=0,up=[0,0,1]}],[{vertex=100000000,up=[0,0,1]}]";
    let (code, _stdout, stderr) = s.run(&["--grid", "seed=1,2", "--grid", keys, "--jobs", "2"]);
    assert_eq!(code, 1, "{stderr}");
    assert!(stderr.contains("2 of 4 runs failed"), "{stderr}");
    assert!(
        stderr.contains("FAILED") && stderr.contains("does not exist"),
        "{stderr}"
    );
    let folders = s.run_folders();
    assert_eq!(folders.len(), 4);
    for name in &folders {
        let dir = s.out.join(name);
        if name.contains("100000000") {
            assert!(!dir.join("done.json").exists(), "{name}");
            let failed: serde_json::Value =
                serde_json::from_str(&std::fs::read_to_string(dir.join("failed.json")).unwrap())
                    .unwrap();
            assert_eq!(failed["exit_code"], 2, "{failed}");
            let log = std::fs::read_to_string(dir.join("log.txt")).unwrap();
            assert!(
                log.contains("does not exist") && log.contains("exit 2"),
                "{log}"
            );
        } else {
            assert!(dir.join("done.json").is_file(), "{name}");
            assert!(dir.join("preview_0.png").is_file(), "{name}");
        }
    }
    let csv = s.csv();
    assert_eq!(csv.len(), 5);
    let status = column(&csv, "status");
    let codes = column(&csv, "exit_code");
    let key = column(&csv, "stage.2.keys");
    let errors = column(&csv, "error");
    for i in 0..4 {
        let bad = key[i].contains("100000000");
        assert_eq!(status[i], if bad { "failed" } else { "ok" });
        assert_eq!(codes[i], if bad { "2" } else { "0" });
        assert_eq!(
            errors[i].contains("key vertex 100000000 does not exist"),
            bad,
            "{}",
            errors[i]
        );
    }
    let html = std::fs::read_to_string(s.out.join("index.html")).unwrap();
    assert_eq!(html.matches("<tr class=\"failed\"").count(), 2);
    // Re-running retries only the failed runs.
    let (code, _, stderr) = s.run(&["--grid", "seed=1,2", "--grid", keys]);
    assert_eq!(code, 1);
    assert_eq!(stderr.matches("skip ").count(), 2, "{stderr}");
    assert_eq!(stderr.matches("FAILED").count(), 2, "{stderr}");
}

/// [`TINY`] with its orientation from keys diffused over a retiled mesh.
fn retiled_keys() -> String {
    let orientation = "kind = \"orientation\"\nmode = \"global\"\nup = [0.0, 0.0, 1.0]\n";
    assert!(TINY.contains(orientation));
    TINY.replace(
        orientation,
        "kind = \"retile\"\nvertices = 300\nlevels = 1\niterations = 1\n\n[[stage]]\n\
         kind = \"diffuse_orientation\"\nkeys = [{ vertex = 0, up = [0.0, 0.0, 1.0] }]\n",
    )
}

#[test]
fn rerun_skips_complete_runs_redoes_incomplete_ones_and_force_redoes_all() {
    let s = Sweep::new();
    let grid = ["--grid", "seed=1,2"];
    let (code, stdout, stderr) = s.run(&grid);
    assert_eq!(code, 0, "{stderr}");
    assert!(stdout.contains("2 ran, 0 skipped"), "{stdout}");
    let done1 = s.out.join("seed=1/done.json");
    let t1 = mtime(&done1);

    // seed=2 interrupted: no marker, a stale file left over.
    std::fs::remove_file(s.out.join("seed=2/done.json")).unwrap();
    std::fs::write(s.out.join("seed=2/stale.txt"), "old").unwrap();
    let (code, stdout, stderr) = s.run(&grid);
    assert_eq!(code, 0, "{stderr}");
    assert!(stdout.contains("1 ran, 1 skipped"), "{stdout}");
    assert!(stderr.contains("skip    seed=1"), "{stderr}");
    assert_eq!(mtime(&done1), t1, "a complete run was redone");
    assert!(s.out.join("seed=2/done.json").is_file());
    assert!(
        !s.out.join("seed=2/stale.txt").exists(),
        "stale contents kept"
    );

    // A changed config is not "complete": its runs are redone.
    let (code, stdout, _) = s.run(&["--grid", "seed=1,2", "--set", "stage.3.scale=35"]);
    assert_eq!(code, 0);
    assert!(stdout.contains("2 ran, 0 skipped"), "{stdout}");

    let (code, stdout, _) = s.run(&["--grid", "seed=1,2", "--set", "stage.3.scale=35", "--force"]);
    assert_eq!(code, 0);
    assert!(stdout.contains("2 ran, 0 skipped"), "{stdout}");
    let (code, stdout, _) = s.run(&["--grid", "seed=1,2", "--set", "stage.3.scale=35"]);
    assert_eq!(code, 0);
    assert!(stdout.contains("0 ran, 2 skipped"), "{stdout}");
}

#[test]
fn bad_arguments_exit_2_naming_the_problem_before_any_run() {
    let s = Sweep::new();
    let cases: &[(&[&str], &[&str])] = &[
        (&["--grid", "seed"], &["--grid seed", "PATH=V1,V2"]),
        (&["--grid", "seed=1,,2"], &["value 2 is empty"]),
        (
            &["--grid", "stage.2.neighbourhoods=[9,5"],
            &["unclosed '['"],
        ),
        (
            &["--grid", "seed=1,2", "--shard", "3/2"],
            &["--shard 3/2", "1..=2"],
        ),
        (
            &["--grid", "seed=1,2", "--shard", "x"],
            &["--shard x", "I/N"],
        ),
        (
            &["--grid", "seed=1,2", "--jobs", "0"],
            &["--jobs", "at least 1"],
        ),
        (&[], &["at least one --grid"]),
        // Valid syntax, but one combination is an invalid config.
        (
            &["--grid", "seed=1,2", "--grid", "stage.3.scale=30,-5"],
            &["run seed=1__stage.3.scale=-5", "scale"],
        ),
        (&["--grid", "stage.9.x=1,2"], &["stage 9 does not exist"]),
        // Issue 43: a grid file that does not exist is found before any run.
        (
            &["--grid", "input.exemplar=builtin:bricks,no_such_photo.png"],
            &["no_such_photo.png", "does not exist", "input.exemplar"],
        ),
        (&["--grid", "stage.2.bogus=1,2"], &["bogus"]),
        // Issue 43: an input that does not load, before any run.
        (
            &["--grid", "input.mesh_options.resolution=[24,12],[2,12]"],
            &[
                "--set input.mesh_options.resolution=[2,12]",
                "resolution[0] = 2",
            ],
        ),
    ];
    for (args, needles) in cases {
        let (code, _, stderr) = s.run(args);
        assert_eq!(code, 2, "{args:?}: {stderr}");
        for n in *needles {
            assert!(stderr.contains(n), "{args:?}: want {n:?} in {stderr}");
        }
        assert!(
            files_under(&s.out).is_empty(),
            "{args:?} left files: {:?}",
            files_under(&s.out)
        );
    }
}

#[test]
fn dry_run_lists_the_shard_and_writes_nothing() {
    let s = Sweep::new();
    let (code, stdout, stderr) = s.run(&[
        "--grid",
        "seed=1,2,3",
        "--grid",
        "stage.2.neighbourhoods=[9,5,3],[5,3]",
        "--shard",
        "2/2",
        "--dry-run",
    ]);
    assert_eq!(code, 0, "{stderr}");
    assert!(
        stdout.contains("6 runs in the grid, 3 in this shard"),
        "{stdout}"
    );
    assert!(
        stdout.contains("--set seed=1 --set stage.2.neighbourhoods=[5,3]"),
        "{stdout}"
    );
    assert_eq!(stdout.matches("[would run]").count(), 3, "{stdout}");
    assert!(!s.out.exists());
}

#[test]
fn a_run_over_the_timeout_is_killed_and_reported() {
    let s = Sweep::new();
    // No run of this binary (process start included) finishes in 1 ms.
    let (code, _, stderr) = s.run(&["--grid", "seed=1,2", "--timeout", "0.001"]);
    assert_eq!(code, 1, "{stderr}");
    assert_eq!(
        stderr.matches("timed out after 0.001 s").count(),
        2,
        "{stderr}"
    );
    let csv = s.csv();
    assert_eq!(column(&csv, "status"), ["failed"; 2]);
    assert_eq!(column(&csv, "exit_code"), ["", ""]);
    assert!(!s.out.join("seed=1/done.json").exists());
    let (code, _, stderr) = s.run(&["--grid", "seed=1,2", "--timeout", "0"]);
    assert_eq!(code, 2, "{stderr}");
    assert!(stderr.contains("--timeout: 0 is not allowed"), "{stderr}");
    // Too long for a Duration: refused, not a panic.
    for t in ["1e300", "1e20"] {
        let (code, _, stderr) = s.run(&["--grid", "seed=1,2", "--timeout", t, "--dry-run"]);
        assert_eq!(code, 2, "{t}: {stderr}");
        assert!(
            stderr.contains("--timeout") && !stderr.contains("panicked"),
            "{stderr}"
        );
    }
}

/// Issue 43 (the hostile catalogue): `--out` naming a folder that holds the
/// user's own `index.html` and `summary.csv`, and no sweep of ours, is
/// refused before any run; the files are untouched. It overwrote them,
/// exit 0.
#[test]
fn a_folder_holding_someone_elses_summary_files_is_refused_and_untouched() {
    let s = Sweep::new();
    std::fs::create_dir_all(&s.out).unwrap();
    std::fs::write(s.out.join("index.html"), "mine").unwrap();
    std::fs::write(s.out.join("summary.csv"), "my,data").unwrap();
    let (code, _, stderr) = s.run(&["--grid", "seed=1,2"]);
    assert_eq!(code, 2, "{stderr}");
    for n in ["index.html", "summary.csv", "sweep.json", "allowed"] {
        assert!(stderr.contains(n), "want {n:?} in {stderr}");
    }
    assert_eq!(
        std::fs::read_to_string(s.out.join("index.html")).unwrap(),
        "mine"
    );
    assert_eq!(
        std::fs::read_to_string(s.out.join("summary.csv")).unwrap(),
        "my,data"
    );
    assert!(s.run_folders().is_empty());
    // A folder of the user's other files is fine: the sweep writes beside them.
    std::fs::remove_file(s.out.join("index.html")).unwrap();
    std::fs::remove_file(s.out.join("summary.csv")).unwrap();
    std::fs::write(s.out.join("notes.txt"), "notes").unwrap();
    let (code, _, stderr) = s.run(&["--grid", "seed=1,2"]);
    assert_eq!(code, 0, "{stderr}");
    assert_eq!(
        std::fs::read_to_string(s.out.join("notes.txt")).unwrap(),
        "notes"
    );
}

/// Issue 43: a grid exemplar that is not an image, and a run folder whose
/// name is taken by a user's file or folder, are refused before any run
/// (exit 2, naming the run, the key or the folder, and the path); nothing
/// is written and the user's files are untouched. (The garbage exemplar
/// ran the other runs and exited 1; the taken name failed its run, and a
/// user's folder of that name was emptied by the sweep.)
#[test]
fn a_garbage_grid_exemplar_or_a_taken_run_folder_is_refused_before_any_run() {
    let s = Sweep::new();
    std::fs::write(
        &s.config,
        TINY.replace("[input.exemplar_options]\nsize = 32\n", ""),
    )
    .unwrap();
    let junk = s.config.with_file_name("junk.png");
    std::fs::write(&junk, "this is not a PNG").unwrap();
    let grid = format!("input.exemplar=builtin:bricks,{}", junk.display());
    let (code, _, stderr) = s.run(&["--grid", &grid]);
    assert_eq!(code, 2, "{stderr}");
    for n in ["run input.exemplar=", "junk.png", "input.exemplar"] {
        assert!(stderr.contains(n), "want {n:?} in {stderr}");
    }
    assert!(files_under(&s.out).is_empty(), "{:?}", files_under(&s.out));

    std::fs::create_dir_all(&s.out).unwrap();
    std::fs::write(s.out.join("seed=2"), "mine").unwrap();
    let (code, _, stderr) = s.run(&["--grid", "seed=1,2"]);
    assert_eq!(code, 2, "{stderr}");
    for n in ["run seed=2", "seed=2", "is a file", "allowed"] {
        assert!(stderr.contains(n), "want {n:?} in {stderr}");
    }
    assert_eq!(files_under(&s.out), vec![s.out.join("seed=2")]);
    std::fs::remove_file(s.out.join("seed=2")).unwrap();
    std::fs::create_dir(s.out.join("seed=2")).unwrap();
    std::fs::write(s.out.join("seed=2/thesis.tex"), "mine").unwrap();
    let (code, _, stderr) = s.run(&["--grid", "seed=1,2"]);
    assert_eq!(code, 2, "{stderr}");
    assert!(stderr.contains("thesis.tex"), "{stderr}");
    assert_eq!(
        std::fs::read_to_string(s.out.join("seed=2/thesis.tex")).unwrap(),
        "mine"
    );
    assert_eq!(files_under(&s.out).len(), 1, "{:?}", files_under(&s.out));
}
