//! Issue 43's weak cases: bad inputs that were refused only once a stage
//! ran (exit 2 after the stages before it), now refused before any stage
//! starts (at validation, or right after the input is loaded), with exit
//! 2, a message naming the key, the file or the value and what is allowed,
//! and no output folder.

use crate::common::run_cli_env;

/// Writes `files` and `config` (as `c.toml`) into a temporary folder and
/// runs it with `--out DIR/out` and the log at `info`: the exit code,
/// stderr, and whether the output folder exists.
fn run_in_temp(config: &str, files: &[(&str, Vec<u8>)]) -> (i32, String, bool) {
    let dir = tempfile::tempdir().expect("a temporary folder");
    for (name, bytes) in files {
        std::fs::write(dir.path().join(name), bytes).expect("the file is written");
    }
    let cfg = dir.path().join("c.toml");
    std::fs::write(&cfg, config).expect("the config is written");
    let out = dir.path().join("out");
    let (code, _, stderr) = run_cli_env(
        &["run", cfg.to_str().unwrap(), "--out", out.to_str().unwrap()],
        &[("RUST_LOG", "info")],
    );
    assert!(!stderr.contains("panicked"), "{stderr}");
    (code, stderr, out.exists())
}

/// [`run_in_temp`], checking exit 2, every needle in stderr, that no stage
/// started and that no output folder was made. Returns stderr.
fn refused_before_any_stage(config: &str, files: &[(&str, Vec<u8>)], needles: &[&str]) -> String {
    let (code, stderr, made_out) = run_in_temp(config, files);
    assert_eq!(code, 2, "{stderr}");
    for n in needles {
        assert!(stderr.contains(n), "stderr should contain {n:?}: {stderr}");
    }
    assert!(
        !stderr.contains(") started"),
        "no stage may start: {stderr}"
    );
    assert!(!made_out, "no output folder");
    stderr
}

/// `[[stage]]` tables, one per entry: its kind, then any parameter lines
/// (`"jump_map\nneighbourhoods = []"`).
fn stages(entries: &[&str]) -> String {
    entries
        .iter()
        .map(|e| {
            let (kind, params) = e.split_once('\n').unwrap_or((e, ""));
            format!("[[stage]]\nkind = \"{kind}\"\n{params}\n\n")
        })
        .collect()
}

/// A PNG of `w × h` noise.
fn png(w: u32, h: u32) -> Vec<u8> {
    let img = image::RgbImage::from_fn(w, h, |x, y| {
        image::Rgb([
            (x * 37 % 256) as u8,
            (y * 91 % 256) as u8,
            ((x ^ y) * 13 % 256) as u8,
        ])
    });
    let mut bytes = std::io::Cursor::new(Vec::new());
    img.write_to(&mut bytes, image::ImageFormat::Png)
        .expect("the PNG is encoded");
    bytes.into_inner()
}

/// A config on the builtin torus (288 vertices) with `input` lines added
/// to `[input]` and `stages` after it.
fn config(input: &str, stages: &str) -> String {
    format!(
        r#"seed = 1
[input]
mesh = "builtin:torus"
texture_scale = 0.5
{input}
[input.mesh_options]
resolution = [24, 12]

{stages}
[[stage]]
kind = "export"
formats = ["ply"]
"#
    )
}

const JUMP: [&str; 3] = ["orientation", "jump_map", "jump_surface"];

#[test]
fn an_exemplar_too_small_for_inset_neighbourhoods_is_refused_before_any_stage() {
    for (w, h) in [(1, 1), (2, 2), (3, 200)] {
        let stderr = refused_before_any_stage(
            &config(
                "exemplar = \"tiny.png\"\nexemplar_wrap = \"clamp\"",
                &stages(&JUMP),
            ),
            &[("tiny.png", png(w, h))],
            &[
                "stage 2 (jump_map)",
                "tiny.png",
                &format!("{w}x{h} pixels"),
                "`neighbourhoods` = [9, 5, 3]",
                "allowed: an exemplar of at least",
            ],
        );
        // The size named is the smallest that works.
        let at = stderr.find("at least ").expect("a size") + "at least ".len();
        let side: u32 = stderr[at..]
            .split('x')
            .next()
            .and_then(|s| s.parse().ok())
            .expect("NxN");
        assert!(side > h.min(w), "{stderr}");
    }
}

#[test]
fn an_exemplar_too_small_for_a_lapped_patch_is_refused_before_any_stage() {
    let lapped = |paste: &str| stages(&["orientation", "tangent_field", paste]);
    refused_before_any_stage(
        &config(
            "exemplar = \"tiny.png\"\nexemplar_wrap = \"clamp\"",
            &lapped("lapped_paste"),
        ),
        &[("tiny.png", png(4, 4))],
        &[
            "stage 3 (lapped_paste)",
            "tiny.png",
            "4x4 pixels",
            "allowed",
        ],
    );
    refused_before_any_stage(
        &config(
            "exemplar = \"small.png\"\nexemplar_wrap = \"clamp\"",
            &lapped("lapped_paste\npatch_pixels = 40"),
        ),
        &[("small.png", png(32, 32))],
        &["`patch_pixels` = 40", "small.png", "at most 32"],
    );
    refused_before_any_stage(
        &config(
            "exemplar = \"builtin:bricks\"",
            &lapped("lapped_paste\npatch_pixels = 3"),
        ),
        &[],
        &[
            "parameter `patch_pixels`",
            "3 is too small",
            "allowed: 0 (automatic) or 8..=4096",
        ],
    );
}

#[test]
fn displace_without_a_height_map_is_refused_at_validation() {
    refused_before_any_stage(
        &config(
            "exemplar = \"builtin:bricks\"",
            &stages(&["orientation", "init_colours", "displace"]),
        ),
        &[],
        &[
            "c.toml:",
            "stage 3 (displace) needs a height map",
            "set input.height_map",
            "derive:luminance",
        ],
    );
}

#[test]
fn empty_neighbourhoods_are_refused_at_validation_under_their_own_name() {
    let stderr = refused_before_any_stage(
        &config(
            "exemplar = \"builtin:bricks\"",
            &stages(&[
                "orientation",
                "jump_map\nneighbourhoods = []",
                "jump_surface",
            ]),
        ),
        &[],
        &[
            "stage 2 (jump_map), parameter `neighbourhoods`",
            "[]",
            "allowed: 1 to 6 odd widths",
        ],
    );
    assert!(!stderr.contains("neighbourhood_widths"), "{stderr}");
}

/// The Bangay–Morkel pipeline with `keys` (and more lines) on its
/// `diffuse_orientation`, after `before`.
fn bangay_morkel(before: &str, keys: &str) -> String {
    stages(&[
        before,
        "subdivide_sqrt2\ntarget_vertices = 1500",
        &format!("diffuse_orientation\nkeys = {keys}"),
        "graph_match\npasses = [1, 1, 1]",
    ])
}

#[test]
fn a_key_on_a_vertex_the_input_lacks_is_refused_before_any_stage() {
    let up = "up = [0.0, 1.0, 0.0]";
    refused_before_any_stage(
        &config(
            "exemplar = \"builtin:bricks\"",
            &bangay_morkel(
                "orientation",
                &format!("[{{ vertex = 0, {up} }}, {{ vertex = 100000000, {up} }}]"),
            ),
        ),
        &[],
        &[
            "stage 3 (diffuse_orientation)",
            "`keys`: key 2: vertex 100000000 does not exist",
            "the input mesh has 288 vertices (ids 0..=287)",
            "allowed",
        ],
    );
    refused_before_any_stage(
        &config(
            "exemplar = \"builtin:bricks\"",
            &bangay_morkel(
                "orientation",
                &format!("[{{ vertex = 1, {up} }}]\nsweep_anchor = {{ vertex = 288 }}"),
            ),
        ),
        &[],
        &["`sweep_anchor`: vertex 288 does not exist"],
    );
}

/// After a retiling the ids name the retiled mesh's vertices, unknown
/// before it runs: the key is then checked when its stage runs.
#[test]
fn a_key_after_a_retiling_is_checked_when_its_stage_runs() {
    let (code, stderr, made_out) = run_in_temp(
        &config(
            "exemplar = \"builtin:bricks\"",
            &bangay_morkel(
                "retile\nvertices = 300\nlevels = 1\niterations = 1",
                "[{ vertex = 100000000, up = [0.0, 1.0, 0.0] }]",
            ),
        ),
        &[],
    );
    assert_eq!(code, 2, "{stderr}");
    assert!(
        stderr.contains("key vertex 100000000 does not exist"),
        "{stderr}"
    );
    assert!(!made_out);
}

/// With `subdivide_sqrt2`'s target derived from the texture scale (its
/// defaults) a coarse input stays the coarsest level: its ids are checked
/// up front too.
#[test]
fn a_key_before_a_derived_subdivision_is_refused_before_any_stage() {
    let derived = stages(&[
        "orientation",
        "subdivide_sqrt2",
        "diffuse_orientation\nkeys = [{ vertex = 300, up = [0.0, 1.0, 0.0] }]",
        "graph_match\npasses = [1, 1, 1]",
    ]);
    refused_before_any_stage(
        &config("exemplar = \"builtin:bricks\"", &derived),
        &[],
        &["`keys`: key 1: vertex 300 does not exist", "288 vertices"],
    );
}
