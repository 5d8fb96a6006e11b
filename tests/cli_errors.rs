//! Bad input never panics: every user error is a clear message naming what is
//! wrong, exit code 2, and no output file left behind.

mod common;
use common::*;

const BASE: &str = r#"
seed = 1
[input]
mesh = "builtin:icosphere"
exemplar = "builtin:bricks"
[input.mesh_options]
subdivisions = 2

[[stage]]
kind = "orientation"

[[stage]]
kind = "init_colours"

[[stage]]
kind = "export"
"#;

/// Writes `config` into a temp dir, runs it with `--out`, and checks exit 2,
/// that stderr contains every `needles`, and that no output file exists.
fn expect_bad(config: &str, extra: &[&str], needles: &[&str]) {
    let dir = tempfile::tempdir().unwrap();
    let cfg = dir.path().join("bad.toml");
    std::fs::write(&cfg, config).unwrap();
    let out = dir.path().join("out");
    let mut args = vec!["run", cfg.to_str().unwrap(), "--out", out.to_str().unwrap()];
    args.extend_from_slice(extra);
    let (code, _stdout, stderr) = run_cli(&args);
    assert_eq!(code, 2, "exit code for {needles:?}; stderr: {stderr}");
    for n in needles {
        assert!(stderr.contains(n), "stderr should contain {n:?}: {stderr}");
    }
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(
        files_under(&out).is_empty(),
        "no output may be left behind: {:?}",
        files_under(&out)
    );
}

#[test]
fn unknown_config_key_names_key_and_line() {
    expect_bad(
        &BASE.replace(
            "[[stage]]\nkind = \"init_colours\"",
            "[[stage]]\nkind = \"init_colours\"\nbogus = 3",
        ),
        &[],
        &["bad.toml:14", "bogus", "unknown parameter"],
    );
    expect_bad(
        &format!("colour = 1\n{BASE}"),
        &[],
        &["colour", "unknown field"],
    );
}

#[test]
fn wrong_type_names_parameter() {
    expect_bad(
        &BASE.replace(
            "kind = \"orientation\"",
            "kind = \"orientation\"\nangle = \"ten\"",
        ),
        &[],
        &["bad.toml:11", "angle", "orientation"],
    );
}

#[test]
fn out_of_range_value_names_range() {
    expect_bad(
        BASE,
        &["--set", "stage.3.preview_size=10"],
        &["preview_size", "64..=4096"],
    );
}

#[test]
fn unknown_stage_lists_allowed() {
    expect_bad(
        &BASE.replace("kind = \"init_colours\"", "kind = \"init_colors\""),
        &[],
        &["init_colors", "allowed", "init_colours"],
    );
}

#[test]
fn missing_files_are_named() {
    expect_bad(
        BASE,
        &[
            "--set",
            "input.mesh=/nonexistent/x.obj",
            "--set",
            "input.mesh_options={}",
        ],
        &["/nonexistent/x.obj"],
    );
    expect_bad(
        BASE,
        &["--set", "input.exemplar=/nonexistent/t.png"],
        &["/nonexistent/t.png"],
    );
    let (code, _, stderr) = run_cli(&["run", "/nonexistent/config.toml"]);
    assert_eq!(code, 2, "{stderr}");
    assert!(stderr.contains("/nonexistent/config.toml"), "{stderr}");
}

fn mesh_case(name: &str, content: &str, needles: &[&str]) {
    let dir = tempfile::tempdir().unwrap();
    let mesh = dir.path().join(name);
    std::fs::write(&mesh, content).unwrap();
    let set_mesh = format!("input.mesh={}", mesh.display());
    let mut all = vec![name];
    all.extend_from_slice(needles);
    expect_bad(
        BASE,
        &["--set", &set_mesh, "--set", "input.mesh_options={}"],
        &all,
    );
}

#[test]
fn bad_meshes_are_refused_with_what_and_where() {
    mesh_case(
        "nan.obj",
        "v 0 0 0\nv 1 0 nan\nv 0 1 0\nf 1 2 3\n",
        &["vertex 1"],
    );
    mesh_case(
        "range.obj",
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n",
        &["face 0"],
    );
    mesh_case("empty.obj", "", &["no faces"]);
    mesh_case("trunc.off", "OFF\n4 2 0\n0 0 0\n1 0 0\n", &["trunc.off"]);
    mesh_case(
        "trunc.obj",
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nv 1 1",
        &["line 5", "truncated"],
    );
    mesh_case("mesh.xyz", "1 2 3\n", &[".obj"]);
}

#[test]
fn zero_threads_is_refused() {
    expect_bad(BASE, &["--threads", "0"], &["--threads"]);
}

#[test]
fn missing_stage_input_says_what_to_add() {
    let no_mesh = BASE
        .replace("mesh = \"builtin:icosphere\"\n", "")
        .replace("[input.mesh_options]\nsubdivisions = 2\n", "");
    expect_bad(
        &no_mesh,
        &[],
        &[
            "stage 1 (orientation)",
            "needs a mesh",
            "set `mesh` in [input]",
        ],
    );
}
