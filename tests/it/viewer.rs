//! `view.html`, the 3D view beside `result.glb`: every run that writes the
//! GLB writes the page and lists it, a run without the GLB does not; the
//! page names `result.glb`, embeds its exact bytes and the three.js bundle,
//! and loads nothing from any address.

use std::path::Path;
use std::process::Command;
use surfsynth::output::viewer::THREE_BUNDLE;

/// A small jump-map pipeline on a builtin mesh, baked into a 256² atlas (the smallest) and
/// exported as `formats`.
fn config(formats: &str) -> String {
    format!(
        r#"
seed = 3
[input]
mesh = "builtin:torus"
exemplar = "builtin:bricks"
[input.exemplar_options]
size = 32
[[stage]]
kind = "orientation"
mode = "global"
up = [0.0, 1.0, 0.0]
[[stage]]
kind = "jump_map"
[[stage]]
kind = "jump_surface"
[[stage]]
kind = "bake"
size = 256
[[stage]]
kind = "export"
formats = [{formats}]
preview_size = 64
"#
    )
}

/// Runs the CLI on `config` into `dir/out`; returns its stdout.
fn run(dir: &Path, config: &str) -> String {
    let path = dir.join("viewer.toml");
    std::fs::write(&path, config).expect("write config");
    let output = Command::new(env!("CARGO_BIN_EXE_surfsynth"))
        .arg("run")
        .arg(&path)
        .arg("--out")
        .arg(dir.join("out"))
        .output()
        .expect("run surfsynth");
    assert!(
        output.status.success(),
        "surfsynth run failed: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    String::from_utf8_lossy(&output.stdout).into_owned()
}

/// Decodes standard base64, skipping whitespace.
fn base64_decode(text: &str) -> Vec<u8> {
    let value = |c: u8| match c {
        b'A'..=b'Z' => c - b'A',
        b'a'..=b'z' => c - b'a' + 26,
        b'0'..=b'9' => c - b'0' + 52,
        b'+' => 62,
        b'/' => 63,
        _ => panic!("not base64: {:?}", c as char),
    };
    let clean: Vec<u8> = text.bytes().filter(|c| !c.is_ascii_whitespace()).collect();
    assert_eq!(clean.len() % 4, 0, "base64 length");
    let mut out = Vec::with_capacity(clean.len() / 4 * 3);
    for quad in clean.chunks(4) {
        let pad = quad.iter().filter(|&&c| c == b'=').count();
        let n = quad
            .iter()
            .map(|&c| if c == b'=' { 0 } else { u32::from(value(c)) })
            .fold(0u32, |n, v| (n << 6) | v);
        out.extend_from_slice(&n.to_be_bytes()[1..4 - pad]);
    }
    out
}

/// The text between `start` and the next `end` after it.
fn between<'a>(text: &'a str, start: &str, end: &str) -> &'a str {
    let from = text.find(start).unwrap_or_else(|| panic!("no {start}")) + start.len();
    let len = text[from..].find(end).unwrap_or_else(|| panic!("no {end}"));
    &text[from..from + len]
}

/// What follows each `token` in `page` up to where a URL would end (a
/// quoted value: its closing quote; else a delimiter), for every token
/// that can make a browser load something.
fn loaded_values(page: &str) -> Vec<(String, String)> {
    let mut found = Vec::new();
    for token in ["src=", "href=", "url(", "import", "fetch(", "@import"] {
        for (at, _) in page.match_indices(token) {
            let rest = page[at + token.len()..].trim_start_matches([' ', '(']);
            let value = match rest.chars().next() {
                // `import x from "…"`: the statement.
                _ if token == "import" => rest.split([';', '\n']).next().unwrap_or(""),
                Some(q @ ('"' | '\'' | '`')) => rest[1..].split(q).next().unwrap_or(""),
                _ => rest
                    .split(|c: char| c.is_whitespace() || "<>);,{}".contains(c))
                    .next()
                    .unwrap_or(""),
            };
            found.push((token.to_string(), value.chars().take(200).collect()));
        }
    }
    found
}

#[test]
fn a_run_that_writes_the_glb_writes_its_view_and_one_without_does_not() {
    let dir = tempfile::tempdir().expect("temp dir");
    let stdout = run(dir.path(), &config(r#""glb", "preview""#));
    let out = dir.path().join("out");
    let glb = std::fs::read(out.join("result.glb")).expect("result.glb");
    let page = std::fs::read_to_string(out.join("view.html")).expect("view.html beside result.glb");
    assert!(
        stdout.lines().any(|l| l.trim() == "view.html"),
        "the run's list of outputs names view.html:\n{stdout}"
    );
    let leftovers: Vec<_> = std::fs::read_dir(&out)
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with('.'))
        .collect();
    assert!(leftovers.is_empty(), "temporary files left: {leftovers:?}");

    // It names the GLB: a relative download link and the view's data-glb.
    assert!(page.contains(r#"data-glb="result.glb""#));
    assert!(page.contains(r#"href="result.glb""#));
    // It embeds the GLB's exact bytes, and the three.js bundle whole.
    let embedded = between(
        &page,
        r#"<script type="application/octet-stream" id="glb">"#,
        "</script>",
    );
    assert!(
        base64_decode(embedded) == glb,
        "the embedded GLB differs from result.glb"
    );
    assert!(page.contains(THREE_BUNDLE), "the three.js bundle");
    assert!(THREE_BUNDLE.starts_with("/* three.js r179 (three@0.179.1)"));
    for name in ["WebGLRenderer:", "GLTFLoader:", "OrbitControls:"] {
        assert!(THREE_BUNDLE.contains(name), "the bundle exports {name}");
    }
    // Its own scripts are inline and classic: nothing to fetch from file://.
    assert!(!page.contains("<script src"), "a script loaded from a file");
    assert!(!page.contains(r#"type="module""#), "a module script");

    // Nothing the page could load names an address.
    for (token, value) in loaded_values(&page) {
        let v = value.to_ascii_lowercase();
        assert!(
            !(v.contains("http:")
                || v.contains("https:")
                || v.starts_with("//")
                || v.contains("\"//")),
            "{token} loads {value:?}"
        );
    }
    // Outside the bundle (three's own code) the page names no address at all.
    let own = page.replace(THREE_BUNDLE, "");
    assert!(!own.contains("http:") && !own.contains("https:"));

    // The same pipeline without `glb` (the bake still runs): no page.
    let dir = tempfile::tempdir().expect("temp dir");
    let stdout = run(dir.path(), &config(r#""baked_obj""#));
    let out = dir.path().join("out");
    assert!(out.join("result_atlas.obj").is_file());
    assert!(!out.join("result.glb").exists());
    assert!(!out.join("view.html").exists(), "view.html without a GLB");
    assert!(!stdout.contains("view.html"));
}

#[test]
fn the_url_scan_sees_loads() {
    // The scanner itself: it finds what a page could load from outside.
    let bad = [
        r#"<script src="https://cdn.example/three.js"></script>"#,
        r#"<a href='//cdn.example/x'>"#,
        "body { background: url(http://example.org/a.png) }",
        r#"import * as T from "https://cdn.example/three.module.js";"#,
        r#"fetch("http://example.org/result.glb")"#,
    ];
    for page in bad {
        let hit = loaded_values(page).into_iter().any(|(_, v)| {
            let v = v.to_ascii_lowercase();
            v.contains("http:") || v.contains("https:") || v.starts_with("//")
        });
        assert!(hit, "missed in {page}");
    }
    assert!(
        loaded_values(r#"<a href="result.glb" download>"#)
            .iter()
            .all(|(_, v)| v == "result.glb")
    );
}
