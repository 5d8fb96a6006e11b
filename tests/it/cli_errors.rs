//! Bad input never panics: every user error is a clear message naming what is
//! wrong, exit code 2, and no output file left behind.

use crate::common;
use crate::common::*;

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

#[test]
fn unknown_config_key_names_key_and_line() {
    common::expect_refused(
        &BASE.replace(
            "[[stage]]\nkind = \"init_colours\"",
            "[[stage]]\nkind = \"init_colours\"\nbogus = 3",
        ),
        &[],
        &["bad.toml:14", "bogus", "unknown parameter"],
    );
    common::expect_refused(
        &format!("colour = 1\n{BASE}"),
        &[],
        &["colour", "unknown field"],
    );
}

#[test]
fn wrong_type_names_parameter() {
    common::expect_refused(
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
    common::expect_refused(
        BASE,
        &["--set", "stage.3.preview_size=10"],
        &["preview_size", "64..=4096"],
    );
}

#[test]
fn unknown_stage_lists_allowed() {
    common::expect_refused(
        &BASE.replace("kind = \"init_colours\"", "kind = \"init_colors\""),
        &[],
        &["init_colors", "allowed", "init_colours"],
    );
}

#[test]
fn missing_files_are_named() {
    common::expect_refused(
        BASE,
        &[
            "--set",
            "input.mesh=/nonexistent/x.obj",
            "--set",
            "input.mesh_options={}",
        ],
        &["/nonexistent/x.obj"],
    );
    common::expect_refused(
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
    common::expect_refused(
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
    common::expect_refused(BASE, &["--threads", "0"], &["--threads"]);
}

#[test]
fn missing_stage_input_says_what_to_add() {
    let no_mesh = BASE
        .replace("mesh = \"builtin:icosphere\"\n", "")
        .replace("[input.mesh_options]\nsubdivisions = 2\n", "");
    common::expect_refused(
        &no_mesh,
        &[],
        &[
            "stage 1 (orientation)",
            "needs a mesh",
            "set `mesh` in [input]",
        ],
    );
}

/// Issue 39: every export format's input is checked with the config, so a
/// format that cannot be written is refused (exit 2, naming the stage to
/// add, no output folder) before the synthesis runs, not after it. The
/// jump map of a 512² exemplar before the export would take seconds; the
/// refusal names the config line, which only validation knows.
#[test]
fn export_formats_that_cannot_be_written_are_refused_up_front() {
    let pipeline = |formats: &str| {
        format!(
            "seed = 1\n[input]\nmesh = \"builtin:icosphere\"\nexemplar = \"builtin:noise\"\n\
             [input.exemplar_options]\nsize = 512\n\n\
             [[stage]]\nkind = \"orientation\"\n\n\
             [[stage]]\nkind = \"jump_map\"\ncache = false\n\n\
             [[stage]]\nkind = \"jump_surface\"\n\n\
             [[stage]]\nkind = \"export\"\nformats = {formats}\n"
        )
    };
    for (formats, needles) in [
        (
            r#"["obj", "glb"]"#,
            &[
                "bad.toml:19:",
                "stage 4 (export)",
                "`bake` stage's atlas",
                "add `bake` before it",
            ][..],
        ),
        (
            r#"["baked_obj"]"#,
            &["stage 4 (export)", "add `bake` before it"][..],
        ),
        (
            r#"["pastes"]"#,
            &[
                "stage 4 (export)",
                "lapped-texture pastes",
                "add `lapped_paste` before it",
            ][..],
        ),
    ] {
        common::expect_refused(&pipeline(formats), &[], needles);
    }
    // `baked` needs per-corner texture coordinates: a vertex-colour result
    // has none.
    let colours = BASE.replace(
        "[[stage]]\nkind = \"export\"",
        "[[stage]]\nkind = \"export\"\nformats = [\"baked\"]",
    );
    assert_ne!(colours, BASE, "the base config has an export stage");
    common::expect_refused(&colours, &[], &["per-corner texture coordinates"]);
}

/// Issue 43: `--trace` inside the `--out` folder of an earlier run was
/// found only after the new result was committed (the run replaces the
/// folder the trace file was open in: exit 1, "internal error"). It is
/// refused before any work, and the earlier result is untouched.
#[test]
fn a_trace_inside_the_output_folder_is_refused_up_front() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = dir.path().join("c.toml");
    std::fs::write(&cfg, BASE).unwrap();
    let out = dir.path().join("out");
    let args = |extra: &[&str]| {
        let mut a = vec!["run", cfg.to_str().unwrap(), "--out", out.to_str().unwrap()];
        a.extend_from_slice(extra);
        a.iter().map(|s| s.to_string()).collect::<Vec<_>>()
    };
    let first = args(&[]);
    let first: Vec<&str> = first.iter().map(String::as_str).collect();
    let (code, _, stderr) = run_cli(&first);
    assert_eq!(code, 0, "{stderr}");
    let before = std::fs::read(out.join("metrics.json")).unwrap();
    let trace = out.join("trace.json");
    let second = args(&["--trace", trace.to_str().unwrap()]);
    let second: Vec<&str> = second.iter().map(String::as_str).collect();
    let (code, _, stderr) = run_cli(&second);
    assert_eq!(code, 2, "{stderr}");
    assert!(
        stderr.contains("--trace") && stderr.contains("output folder"),
        "{stderr}"
    );
    assert_eq!(
        std::fs::read(out.join("metrics.json")).unwrap(),
        before,
        "earlier result kept"
    );
    assert!(
        !trace.exists(),
        "no trace file was created in the earlier result"
    );
}

/// Issue 43: memory grew with the square of the stage count (10,000
/// stages reached 24 GB); the count is capped up front, naming the count
/// and the limit.
#[test]
fn too_many_stages_are_refused_up_front() {
    let many = format!(
        "{BASE}{}",
        "\n[[stage]]\nkind = \"orientation\"\n".repeat(300)
    );
    common::expect_refused(&many, &[], &["303 stages", "at most 256"]);
}

/// A reader that closes the pipe early (`surfsynth stages | head`) ends the
/// program quietly with success, not with a panic.
#[test]
fn a_closed_output_pipe_is_not_a_panic() {
    for args in [&["stages"][..], &["mesh-info", "builtin:torus"][..]] {
        let mut child = common::bin()
            .args(args)
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .expect("the binary starts");
        // Close the read end before the program writes.
        drop(child.stdout.take());
        let out = child.wait_with_output().expect("it ends");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!stderr.contains("panicked"), "{args:?}: {stderr}");
        assert_eq!(out.status.code(), Some(0), "{args:?}: {stderr}");
    }
}
