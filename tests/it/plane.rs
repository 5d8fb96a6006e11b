//! The planar benchmark (`configs/plane/*.toml`) and the `plane` export
//! format: every method's result as an image, with its source map.
//!
//! The configs run through the CLI at 64 × 64 (their 256 × 256 default is
//! the benchmark; the sizes here keep the file fast) on the shared stones
//! photo.

use crate::common;
use crate::common::*;
use std::path::{Path, PathBuf};
use surfsynth::mesh::builtin::{BuiltinOptions, builtin_mesh};
use surfsynth::stages::export::plane::{PlaneSignal, plane_from_surface, plane_from_surface_at};

const STONES: &str = "textures/stones.png";

/// `--set` overrides that shrink each config to a 64 × 64 plane image at one
/// exemplar pixel per pixel.
fn small(method: &str) -> Vec<String> {
    let v: &[&str] = match method {
        "jump_pixel" | "jump_patch" => &[
            "stage.2.width=64",
            "stage.2.height=64",
            "stage.3.plane_size=[64,64]",
        ],
        "jump_surface" => &[
            "input.mesh_options.resolution=[64,64]",
            "input.mesh_options.size=63.0",
            "stage.4.plane_size=[64,64]",
        ],
        "lapped" => &[
            "input.mesh_options.resolution=[17,17]",
            "input.mesh_options.size=63.0",
            "stage.3.plane_size=[64,64]",
        ],
        "wei_levoy" => &[
            "stage.1.resolution=[64,64]",
            "stage.1.size=63.0",
            "stage.5.plane_size=[64,64]",
        ],
        "jump_surface_coherent" => &[
            "input.mesh_options.resolution=[64,64]",
            "input.mesh_options.size=63.0",
            "stage.5.plane_size=[64,64]",
        ],
        "coherent" => &[
            "stage.1.resolution=[64,64]",
            "stage.1.size=63.0",
            "stage.4.plane_size=[64,64]",
        ],
        // A 5 x 5 quad grid of side 64 refined to a 65 x 65 grid of
        // spacing 1 (≥ 4096 vertices): one vertex per pixel.
        _ => &[
            "input.mesh_options.resolution=[5,5]",
            "input.mesh_options.size=64.0",
            "stage.1.target_vertices=4096",
            "stage.4.plane_size=[64,64]",
        ],
    };
    v.iter().map(|s| s.to_string()).collect()
}

const METHODS: [&str; 10] = [
    "jump_pixel",
    "jump_patch",
    "jump_surface",
    "jump_surface_coherent",
    "lapped",
    "wei_levoy",
    "coherent",
    "bangay_morkel",
    "bangay_morkel_no_cut",
    "bangay_morkel_coherent",
];

/// Runs `configs/plane/METHOD.toml` small on stones into `out`; returns the folder.
fn run_small(method: &str, out: &Path, extra: &[&str]) -> PathBuf {
    let config = Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("configs/plane/{method}.toml"));
    let exemplar = format!("input.exemplar={}", data_file(STONES).display());
    let mut args: Vec<String> = vec![
        "run".into(),
        config.display().to_string(),
        "--out".into(),
        out.display().to_string(),
        "--set".into(),
        exemplar,
    ];
    for s in small(method) {
        args.push("--set".into());
        args.push(s);
    }
    args.extend(extra.iter().map(|s| s.to_string()));
    let refs: Vec<&str> = args.iter().map(String::as_str).collect();
    let (code, _, stderr) = run_cli(&refs);
    assert_eq!(code, 0, "{method}: {stderr}");
    out.to_path_buf()
}

/// `plane.png` as 8-bit RGB and `plane_sources.png` as 16-bit RGB.
fn read_outputs(
    dir: &Path,
) -> (
    image::RgbImage,
    image::ImageBuffer<image::Rgb<u16>, Vec<u16>>,
) {
    let plane = image::open(dir.join("plane.png")).expect("plane.png");
    let sources = image::open(dir.join("plane_sources.png")).expect("plane_sources.png");
    assert!(
        matches!(sources, image::DynamicImage::ImageRgb16(_)),
        "plane_sources.png is 16-bit RGB, got {:?}",
        sources.color()
    );
    (plane.to_rgb8(), sources.to_rgb16())
}

/// Fraction of pixels with a known source whose exemplar pixel at that source
/// is within `tol` (of 255, every channel) of the plane pixel; and the
/// fraction of pixels with a known source.
fn agreement(dir: &Path, tol: u8) -> (f64, f64) {
    let exemplar = image::open(data_file(STONES)).unwrap().to_rgb8();
    let (plane, sources) = read_outputs(dir);
    let (mut known, mut close) = (0usize, 0usize);
    for (p, s) in plane.pixels().zip(sources.pixels()) {
        if s[2] != u16::MAX {
            continue;
        }
        known += 1;
        let e = exemplar.get_pixel(s[0] as u32, s[1] as u32);
        if (0..3).all(|c| p[c].abs_diff(e[c]) <= tol) {
            close += 1;
        }
    }
    let n = plane.pixels().len() as f64;
    (close as f64 / known.max(1) as f64, known as f64 / n)
}

#[test]
fn every_plane_config_writes_plane_png_and_sources_of_the_requested_size() {
    let dir = tempfile::tempdir().unwrap();
    for method in METHODS {
        let out = run_small(method, &dir.path().join(method), &[]);
        let (plane, sources) = read_outputs(&out);
        assert_eq!(plane.dimensions(), (64, 64), "{method}: plane.png size");
        // Every plane config synthesises at one exemplar pixel per world unit
        // (a 64-pixel plane of side 63), and metrics.json says so for every
        // method on a mesh (issue 14: the effective scale, comparable across
        // methods); the jump-map image methods have no mesh scale.
        let metrics: serde_json::Value =
            serde_json::from_slice(&std::fs::read(out.join("metrics.json")).unwrap()).unwrap();
        let scale = metrics["result"]["scale"]["texels_per_world_unit"].as_f64();
        eprintln!("{method}: texels per world unit {scale:?}");
        if !matches!(method, "jump_pixel" | "jump_patch") {
            let scale =
                scale.unwrap_or_else(|| panic!("{method}: no result.scale.texels_per_world_unit"));
            assert!(
                (scale - 1.0).abs() <= 0.05,
                "{method}: {scale} texels per world unit, want 1"
            );
        }
        assert_eq!(
            sources.dimensions(),
            (64, 64),
            "{method}: plane_sources.png size"
        );
        // The source map is inside the 128² exemplar wherever it is known.
        for s in sources.pixels().filter(|s| s[2] == u16::MAX) {
            assert!(
                s[0] < 128 && s[1] < 128,
                "{method}: source {s:?} outside the exemplar"
            );
        }
        // Tolerances (of 255, every channel), each with the reason:
        // - jump_pixel, jump_patch copy exemplar pixels: exact;
        // - Wei–Levoy and Bangay–Morkel copy a texel per vertex, and every
        //   pixel centre is (close to) a vertex, but Bangay–Morkel's √2
        //   vertices are not on the pixel grid, so a pixel blends up to three
        //   vertices: 40 for ≥ 90 %;
        // - jump_surface addresses are continuous (the exemplar is sampled
        //   bilinearly between the texel recorded by `floor` and its
        //   neighbours) and blended 3 ways: 40 for ≥ 90 %;
        // - lapped pastes composite with alpha over lower pastes: 60 for ≥ 90 %.
        let (tol, want) = match method {
            "jump_pixel" | "jump_patch" => (0, 1.0),
            "wei_levoy" => (0, 0.99),
            "lapped" => (60, 0.9),
            _ => (40, 0.9),
        };
        let (close, known) = agreement(&out, tol);
        assert!(
            close >= want,
            "{method}: {:.1} % of known pixels within {tol}/255 of their source, want {:.0} %",
            100.0 * close,
            100.0 * want
        );
        assert!(
            known >= 0.95,
            "{method}: only {:.1} % of pixels have a source",
            100.0 * known
        );
    }
}

/// `export.plane_pixel`: on a grid of vertices one unit apart whose box is
/// one unit wider than the image (what eight √2 steps of a 17 × 17 quad
/// grid of side 256 give for a 256² image), pixels one unit apart from the
/// box's top-left corner are each exactly one vertex's colour; spanning
/// the box instead puts most pixel centres between vertices, which blends
/// neighbours. Pixels beyond the mesh stay unknown.
#[test]
fn plane_pixel_puts_a_vertex_at_every_pixel_centre_of_a_wider_grid() {
    // 17 × 17 vertices of side 16 (spacing 1), centred on the origin.
    let opts = BuiltinOptions {
        resolution: [17, 17],
        size: 16.0,
        ..Default::default()
    };
    let mesh = builtin_mesh("plane", &opts).unwrap();
    // A colour no interpolation reproduces: hashed per vertex.
    let colour = |x: f32, y: f32| {
        let h = ((x + 8.0) as u32 * 7919 + (y + 8.0) as u32 * 104_729) % 1000;
        [h as f32 / 1000.0, 0.5, 1.0 - h as f32 / 1000.0]
    };
    let values: Vec<f32> = mesh
        .positions
        .iter()
        .flat_map(|p| colour(p.x, p.y))
        .collect();
    let signal = PlaneSignal::Colours {
        values: &values,
        channels: 3,
        sources: None,
    };
    let exact = plane_from_surface_at(&mesh, &signal, [16, 16], [8, 8], 1.0).unwrap();
    let spanning = plane_from_surface(&mesh, &signal, [16, 16], [8, 8]).unwrap();
    let (mut worst_exact, mut mean_spanning) = (0.0f32, 0.0f32);
    for j in 0..16u32 {
        for i in 0..16u32 {
            let want = colour(-8.0 + i as f32, 8.0 - j as f32);
            let err = |got: &[f32]| (0..3).map(|c| (got[c] - want[c]).abs()).fold(0.0, f32::max);
            worst_exact = worst_exact.max(err(exact.image.pixel(i, j)));
            mean_spanning += err(spanning.image.pixel(i, j)) / 256.0;
        }
    }
    assert!(worst_exact < 1e-6, "plane_pixel = 1: worst {worst_exact}");
    assert!(
        mean_spanning > 0.05,
        "spanning the box: mean {mean_spanning}"
    );
    // A 20 × 20 image at 1 unit reaches past the mesh on the right and the
    // bottom: those pixels are black.
    let past = plane_from_surface_at(&mesh, &signal, [20, 20], [8, 8], 1.0).unwrap();
    assert_eq!(past.image.pixel(19, 19), &[0.0, 0.0, 0.0]);
    assert!(
        past.image.pixel(16, 16)[1] > 0.0,
        "the last vertex is inside"
    );
}

#[test]
fn vertex_colours_that_are_a_smooth_function_of_position_are_reproduced_at_pixel_centres() {
    // A jittered plane (irregular triangles) of side 2 centred on the origin,
    // coloured r = linear, g = linear, b = a smooth non-linear function.
    let opts = BuiltinOptions {
        resolution: [33, 33],
        size: 2.0,
        ..Default::default()
    };
    let mesh = builtin_mesh("jittered_plane", &opts).unwrap();
    let f = |x: f32, y: f32| {
        [
            0.5 + 0.25 * x,
            0.5 - 0.2 * y + 0.1 * x,
            0.5 + 0.3 * (1.5 * x).sin() * (1.5 * y).cos(),
        ]
    };
    let values: Vec<f32> = mesh.positions.iter().flat_map(|p| f(p.x, p.y)).collect();
    let signal = PlaneSignal::Colours {
        values: &values,
        channels: 3,
        sources: None,
    };
    let plane = plane_from_surface(&mesh, &signal, [50, 40], [8, 8]).unwrap();
    assert_eq!((plane.image.width, plane.image.height), (50, 40));
    assert!(plane.sources.is_none(), "no SourceTexels, no sources");
    // Pixel centres span the box edge to edge, row 0 at max y.
    let (mut worst_linear, mut worst_smooth) = (0.0f32, 0.0f32);
    for j in 0..40u32 {
        for i in 0..50u32 {
            let x = -1.0 + 2.0 * i as f32 / 49.0;
            let y = 1.0 - 2.0 * j as f32 / 39.0;
            let want = f(x, y);
            let got = plane.image.pixel(i, j);
            worst_linear = worst_linear
                .max((got[0] - want[0]).abs())
                .max((got[1] - want[1]).abs());
            worst_smooth = worst_smooth.max((got[2] - want[2]).abs());
        }
    }
    // Linear functions interpolate exactly (float rounding only); the
    // sinusoid's interpolation error is below h² · max|f''| / 2 with
    // h = 2/32 · 1.25 (jittered cells) and |f''| ≤ 0.3 · 1.5² · 2.
    assert!(worst_linear < 1e-4, "linear channels off by {worst_linear}");
    let h = 2.0f32 / 32.0 * 1.25;
    let bound = h * h * 0.3 * 1.5 * 1.5 * 2.0 / 2.0;
    assert!(
        worst_smooth < bound,
        "smooth channel off by {worst_smooth}, bound {bound}"
    );
}

#[test]
fn plane_on_a_non_planar_mesh_is_refused_before_the_run_naming_the_mesh() {
    let dir = tempfile::tempdir().unwrap();
    let config = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/plane/jump_surface.toml");
    let out = dir.path().join("out");
    let exemplar = format!("input.exemplar={}", data_file(STONES).display());
    let (code, _, stderr) = run_cli(&[
        "run",
        config.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--set",
        &exemplar,
        "--set",
        "input.mesh=builtin:icosphere",
    ]);
    assert_eq!(code, 2, "{stderr}");
    for needle in [
        "builtin:icosphere",
        "flat in the xy plane",
        "z spans",
        "allowed",
    ] {
        assert!(
            stderr.contains(needle),
            "stderr should name {needle:?}: {stderr}"
        );
    }
    assert!(
        files_under(&out).is_empty(),
        "nothing written: {:?}",
        files_under(&out)
    );

    // A `plane` request with no result to draw is a config error.
    let cfg = dir.path().join("nothing.toml");
    std::fs::write(
        &cfg,
        "[input]\nmesh = \"builtin:plane\"\nexemplar = \"builtin:bricks\"\n[[stage]]\nkind = \"export\"\nformats = [\"plane\"]\n",
    )
    .unwrap();
    let (code, _, stderr) =
        run_cli(&["run", cfg.to_str().unwrap(), "--out", out.to_str().unwrap()]);
    assert_eq!(code, 2, "{stderr}");
    assert!(
        stderr.contains("a result to draw for format `plane`"),
        "{stderr}"
    );
    assert!(files_under(&out).is_empty());
}

#[test]
fn plane_outputs_are_the_same_bytes_at_one_and_two_threads() {
    let dir = tempfile::tempdir().unwrap();
    let one = run_small("wei_levoy", &dir.path().join("t1"), &["--threads", "1"]);
    let two = run_small("wei_levoy", &dir.path().join("t2"), &["--threads", "2"]);
    for name in ["plane.png", "plane_sources.png"] {
        let a = std::fs::read(one.join(name)).unwrap();
        let b = std::fs::read(two.join(name)).unwrap();
        assert!(a == b, "{name} differs between 1 and 2 threads");
    }
}

/// The shared photos the planar gates run on.
const SHARED_TEXTURES: [&str; 5] = ["brick", "grass", "planks", "stones", "water"];

/// Runs `configs/plane/METHOD.toml` at its own (the benchmark's) size on
/// the shared `texture` into `dir/texture`, with the `--set` overrides
/// `sets`; returns that folder.
fn run_at_benchmark_size(method: &str, texture: &str, dir: &Path, sets: &[&str]) -> PathBuf {
    let config = Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("configs/plane/{method}.toml"));
    let out = dir.join(texture);
    let exemplar = data_file(&format!("textures/{texture}.png"));
    let input = format!("input.exemplar={}", exemplar.display());
    let mut args = vec![
        "run",
        config.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--set",
        &input,
        "-q",
    ];
    for set in sets {
        args.extend(["--set", set]);
    }
    let (code, _, stderr) = run_cli(&args);
    assert_eq!(code, 0, "{method} on {texture} ({sets:?}): {stderr}");
    out
}

/// Issue 13's repeat gate for `jump_surface` on a regular grid plane: no
/// verbatim region larger than a third of the exemplar is repeated more
/// than twice (`result.quality.verbatim.large_region_repeats`, the
/// verbatim-copy metric of `kernels::metrics::quality`, whose unit tests
/// show it counting a tiled block 4 times). At the benchmark's size (256²
/// from the 128² shared photos), where four copies of the exemplar would
/// fit. Measured: 0 on every shared texture (largest copied region about
/// 3 000 px, under a fifth of the exemplar), because a patch stops copying
/// at a quarter of the exemplar (`max_patch_area`). With the paper's
/// unbounded patches the count was 2 at this seed and 4–5 at others
/// (seed 5: brick 4, grass 5, stones 5), with copied regions of 79 % of
/// the exemplar: near-whole copies side by side.
#[test]
fn jump_surface_on_a_grid_plane_repeats_no_large_region_more_than_twice() {
    let dir = tempfile::tempdir().unwrap();
    for texture in SHARED_TEXTURES {
        let out = run_at_benchmark_size("jump_surface", texture, dir.path(), &[]);
        let m: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("metrics.json")).unwrap())
                .unwrap();
        let v = &m["result"]["quality"]["verbatim"];
        let repeats = v["large_region_repeats"]
            .as_u64()
            .expect("verbatim metrics");
        println!(
            "{texture}: large_region_repeats {repeats}, largest region {}, mean region fraction {}",
            v["largest_region"], v["mean_region_fraction"]
        );
        assert!(
            repeats <= 2,
            "{texture}: a verbatim region larger than a third of the exemplar is repeated {repeats} times"
        );
    }
}

/// `jump_surface` on the planar benchmark (256² from the 128² shared
/// photos, `configs/plane/jump_surface.toml` with the stage's defaults:
/// pixel-aligned starts, patches capped at a quarter of the exemplar, the
/// matched choice over four rings and the seam refinement) against the
/// peer, on issue 13's whole gate ([`common::gates::ISSUE_13`]): coherence
/// p90 and completeness at most the peer's, coherence mean ≤ 1.1 ×,
/// sharpness ≥ 0.9, structure ≤ the peer's + 0.05, histogram, and no
/// verbatim region larger than a third of the exemplar repeated more than
/// twice. Against the paper's behaviour (the four options off, same seed,
/// same measure) the coherence mean must fall on every texture. Measured
/// (every window, stop 30) at seeds 1–3: coherence mean 0.64–0.82 × the
/// peer's, p90 0.27–0.97 × (15 of 15 cells meet the gate; with the matched
/// choice over two rings planks p90 at seed 1 was 1.10 × and water at seed
/// 3 1.001 ×); with the paper's behaviour 1.19–1.62 × and 0.80–1.64 ×
/// (1000 windows), and sharpness 0.87–0.89 on grass, planks and water
/// (every patch resampled at its start's sub-pixel phase).
#[test]
fn jump_surface_on_the_plane_meets_issue_13s_gate_and_beats_the_papers_behaviour() {
    let gate = common::gates::ISSUE_13;
    let results = planar_results_without_large_repeats("jump_surface");
    let dir = tempfile::tempdir().unwrap();
    for (texture, ours, peer) in &results {
        let paper = variant_beside(
            "jump_surface",
            "paper's",
            &[
                "stage.3.choice=random",
                "stage.3.refine=none",
                "stage.3.max_patch_area=0",
                "stage.3.pixel_aligned=false",
            ],
            (texture, ours, peer),
            dir.path(),
        );
        assert!(
            ours.coherence_mean < paper.coherence_mean,
            "{texture}: coherence mean {} vs the paper's behaviour {}",
            ours.coherence_mean,
            paper.coherence_mean
        );
    }
    common::gates::assert_all_near_peer(&results, &gate);
}

/// Lapped textures on the planar benchmark (256² from the 128² shared
/// photos, `configs/plane/lapped.toml` with its automatic texture patches:
/// 3/4 of the exemplar's side, 48 of them for the matched choice; vertices
/// on the output's pixel centres and pixel-aligned pastes) against the
/// peer, on issue 13's whole gate ([`common::gates::ISSUE_13`]): coherence
/// p90 and completeness at most the peer's, coherence mean ≤ 1.1 ×,
/// sharpness ≥ 0.9, structure ≤ the peer's + 0.05, and no verbatim region
/// larger than a third of the exemplar repeated more than twice. Against
/// the paper's random draw of the texture patch (same seed, same patches,
/// same measure) the coherence p90 must fall on the structured photos
/// (brick, planks: with the draw p90 was 1.44 × and 1.36 × the peer's,
/// courses and plank lines cut at paste edges) and stay within 5 % on the
/// stochastic ones, where there is no structure to continue (grass at
/// seed 1: 0.00781 against the draw's 0.00779, both under the peer's
/// 0.00917). Over seeds 1–6 (exact measure) the matched choice, ranked on
/// the flattened parametrisation with shrunk band errors
/// (`kernels::lapped::choice::PRIOR_WEIGHT_SHARE`) and shifted by up to 2
/// whole pixels (`match_shift`), meets the gate in 30 of 30 texture × seed
/// cases (28 before the shift: planks p90 1.07 × at seed 5, sharpness
/// 0.896 at seed 6); the config's seed is 1.
#[test]
fn lapped_on_the_plane_meets_issue_13s_gate_and_beats_the_random_draw() {
    let results = planar_results_without_large_repeats("lapped");
    let dir = tempfile::tempdir().unwrap();
    for (texture, ours, peer) in &results {
        let random = variant_beside(
            "lapped",
            "random draw",
            &["stage.2.choice=random"],
            (texture, ours, peer),
            dir.path(),
        );
        let bound = if matches!(texture.as_str(), "brick" | "planks") {
            random.coherence_p90
        } else {
            1.05 * random.coherence_p90
        };
        assert!(
            ours.coherence_p90 < bound,
            "{texture}: coherence p90 {} vs the random draw's {}",
            ours.coherence_p90,
            random.coherence_p90
        );
    }
    common::gates::assert_all_near_peer(&results, &common::gates::ISSUE_13);
}

/// Jump-map pixels on the planar benchmark (`configs/plane/jump_pixel.toml`
/// with the stage's defaults: the matched choice over every synthesised
/// neighbour's jumps, then `refine = "aligned_seams"`: whole copied regions
/// moved into line, the seam passes, and the regions aligned again) meet
/// issue 13's whole gate ([`common::gates::ISSUE_13`]) on every shared
/// texture, planks' coherence p90 included (0.857 × the peer's at seed 1,
/// exact measure; 1.13 × with the seam passes alone, lines that step where
/// a jump lands at another plank's phase). Against the paper's random
/// choice with the same refinement (same seed, same measure) the coherence
/// p90 must fall on brick and planks, where the random choice tears courses
/// and lines, and stay within 5 % on the stochastic photos; against the
/// seam passes alone (`refine = "seams"`) it must fall on brick and planks,
/// where the alignment is for.
#[test]
fn jump_pixel_on_the_plane_meets_issue_13s_gate_and_beats_the_random_choice_and_the_seams_alone() {
    let results = planar_results_without_large_repeats("jump_pixel");
    let dir = tempfile::tempdir().unwrap();
    for (texture, ours, peer) in &results {
        let random = variant_beside(
            "jump_pixel",
            "random choice",
            &["stage.2.choice=random"],
            (texture, ours, peer),
            &dir.path().join("random"),
        );
        // Structured photos (courses, plank lines) are where the random
        // choice tears; on the stochastic ones both are within noise.
        let structured = matches!(texture.as_str(), "brick" | "planks");
        let bound = if structured {
            random.coherence_p90
        } else {
            1.05 * random.coherence_p90
        };
        assert!(
            ours.coherence_p90 < bound,
            "{texture}: coherence p90 {} vs the random choice's {}",
            ours.coherence_p90,
            random.coherence_p90
        );
        if structured {
            let seams = variant_beside(
                "jump_pixel",
                "seams alone",
                &["stage.2.refine=\"seams\""],
                (texture, ours, peer),
                &dir.path().join("seams"),
            );
            assert!(
                ours.coherence_p90 < seams.coherence_p90,
                "{texture}: coherence p90 {} aligned vs {} with the seam passes alone",
                ours.coherence_p90,
                seams.coherence_p90
            );
        }
    }
    common::gates::assert_all_near_peer(&results, &common::gates::ISSUE_13);
}

/// `configs/plane/METHOD.toml` with the overrides `sets` (a variant, e.g.
/// the paper's behaviour) on `texture` at the benchmark's size, measured
/// with the gate's measure and printed beside `ours` and the peer's.
fn variant_beside(
    method: &str,
    label: &str,
    sets: &[&str],
    (texture, ours, peer): (
        &str,
        &surfsynth::kernels::metrics::ImageQuality,
        &surfsynth::kernels::metrics::ImageQuality,
    ),
    dir: &Path,
) -> surfsynth::kernels::metrics::ImageQuality {
    let out = run_at_benchmark_size(method, texture, dir, sets);
    let ex = surfsynth::image::load_image(&data_file(&format!("textures/{texture}.png"))).unwrap();
    let (img, sources) = common::gates::plane_result(&out);
    let variant = common::gates::quality_of(&img, Some(&sources), &ex);
    println!(
        "{method} on {texture}: coherence mean {:.6} ({label} {:.6}, peer {:.6}), p90 {:.5} ({label} {:.5}, peer {:.5})",
        ours.coherence_mean,
        variant.coherence_mean,
        peer.coherence_mean,
        ours.coherence_p90,
        variant.coherence_p90,
        peer.coherence_p90
    );
    variant
}

/// `configs/plane/METHOD.toml` at the benchmark's size on every shared
/// texture, measured with the peer's synthesis of the same exemplar beside
/// it; asserts on the way that no verbatim region larger than a third of
/// the exemplar is repeated more than twice (issue 13).
fn planar_results_without_large_repeats(
    method: &str,
) -> Vec<(
    String,
    surfsynth::kernels::metrics::ImageQuality,
    surfsynth::kernels::metrics::ImageQuality,
)> {
    let dir = tempfile::tempdir().unwrap();
    let mut results = Vec::new();
    for texture in SHARED_TEXTURES {
        let out = run_at_benchmark_size(method, texture, dir.path(), &[]);
        let exemplar =
            surfsynth::image::load_image(&data_file(&format!("textures/{texture}.png"))).unwrap();
        let (img, sources) = common::gates::plane_result(&out);
        let ours = common::gates::quality_of(&img, Some(&sources), &exemplar);
        let verbatim = ours
            .verbatim
            .expect("the planar configs write source texels");
        println!(
            "{method} on {texture}: largest copied region {} px, large_region_repeats {}",
            verbatim.largest_region, verbatim.large_region_repeats
        );
        assert!(
            verbatim.large_region_repeats <= 2,
            "{method} on {texture}: a verbatim region larger than a third of the exemplar is repeated {} times",
            verbatim.large_region_repeats
        );
        let peer = common::gates::peer_quality(&exemplar, img.width, img.height);
        results.push((texture.to_string(), ours, peer));
    }
    results
}

/// Issue 13's gate for `jump_patch` (quilted patches, the default seams):
/// the planar benchmark config at its size (256² from the 128² shared
/// photos) against the peer's 256² synthesis, on every shared texture:
/// coherence p90 and completeness at most the peer's, coherence mean
/// ≤ 1.1 ×, sharpness ≥ 0.9, structure ≤ the peer's + 0.05
/// ([`common::gates::ISSUE_13`]), and no verbatim region larger than a third
/// of the exemplar repeated more than twice. With the paper's straight
/// patch edges p90 was up to 1.40 × the peer's and completeness 1.15 ×.
#[test]
fn jump_patch_on_the_plane_meets_issue_13s_gate_against_the_peer() {
    let results = planar_results_without_large_repeats("jump_patch");
    common::gates::assert_all_near_peer(&results, &common::gates::ISSUE_13);
}

/// Issue 12's gate for paper-faithful Bangay–Morkel with its stage
/// defaults (`configs/plane/bangay_morkel.toml`: exhaustive search, graph
/// cut on, a vertex at every pixel centre) against paper-faithful
/// Wei–Levoy (`configs/plane/wei_levoy.toml`), both at the benchmark's size
/// and their configs' seeds, on every shared texture: Bangay–Morkel no
/// worse on every measure (coherence mean and p90, completeness, structure
/// and histogram at most Wei–Levoy's, sharpness at least). No peer is
/// needed: the gate compares the two papers. About 3 minutes on 2 cores
/// (161 s measured; Bangay–Morkel takes 13–23 s per photo).
///
/// Ignored because it fails today; the figures (stop 37, B&M vs WL) are in
/// the ignore text, and ARCHITECTURE.md ("Bangay–Morkel: complete
/// neighbourhoods, a vertex per pixel, the cut by default") has the whole
/// table. Run by hand with
/// `cargo test --release --test it -- --ignored plane::bangay_morkel --nocapture`.
#[test]
#[ignore = "fails today (issue 12), B&M vs WL at the configs' seeds, 6 of 30 cells, all coherence: grass p90 0.00908 vs 0.00758; planks p90 0.00224 vs 0.00160; stones mean 0.00561 vs 0.00479, p90 0.0112 vs 0.0084; water mean 0.00290 vs 0.00222, p90 0.00631 vs 0.00428 (B&M is no worse on the other 24 cells, sharpness 0.81-0.98 vs 0.53-0.82); blocked: blur lowers these cells, and `coherent`, at the peer's quality, fails grass and planks p90 against WL too (ARCHITECTURE.md, \"what the last six cells measure\")"]
fn bangay_morkel_defaults_are_no_worse_than_wei_levoy_on_every_measure() {
    let dir = tempfile::tempdir().unwrap();
    let mut failures = Vec::new();
    for texture in SHARED_TEXTURES {
        let exemplar =
            surfsynth::image::load_image(&data_file(&format!("textures/{texture}.png"))).unwrap();
        let measure = |method: &str| {
            let out = run_at_benchmark_size(method, texture, &dir.path().join(method), &[]);
            let (img, sources) = common::gates::plane_result(&out);
            common::gates::quality_of(&img, Some(&sources), &exemplar)
        };
        let bm = measure("bangay_morkel");
        let wl = measure("wei_levoy");
        // (measure, B&M, WL, whether B&M is no worse)
        let rows = [
            (
                "coherence mean",
                bm.coherence_mean,
                wl.coherence_mean,
                bm.coherence_mean <= wl.coherence_mean,
            ),
            (
                "coherence p90",
                bm.coherence_p90,
                wl.coherence_p90,
                bm.coherence_p90 <= wl.coherence_p90,
            ),
            (
                "completeness",
                bm.completeness,
                wl.completeness,
                bm.completeness <= wl.completeness,
            ),
            (
                "sharpness",
                bm.sharpness,
                wl.sharpness,
                bm.sharpness >= wl.sharpness,
            ),
            (
                "structure",
                bm.structure,
                wl.structure,
                bm.structure <= wl.structure,
            ),
            (
                "histogram",
                bm.histogram,
                wl.histogram,
                bm.histogram <= wl.histogram,
            ),
        ];
        for (name, b, w, ok) in rows {
            println!("{texture}: Bangay–Morkel vs Wei–Levoy on {name}: {b:.6} vs {w:.6}");
            if !ok {
                failures.push(format!("{texture} {name}: {b:.6} vs {w:.6}"));
            }
        }
    }
    assert!(
        failures.is_empty(),
        "Bangay–Morkel defaults are worse than Wei–Levoy on: {}",
        failures.join("; ")
    );
}

/// `plane_colours = "sources"` (`PlaneSignal::Coordinates`): where the
/// vertices' sources agree (one copied patch, source = position × scale +
/// a shift), the image is the exemplar itself at the exemplar's resolution,
/// even on a mesh four times coarser than the pixels; interpolating the
/// vertex colours resamples it through the mesh and loses that detail.
#[test]
fn coordinates_continued_through_frames_give_the_exemplar_at_its_resolution_on_a_coarse_mesh() {
    use surfsynth::kernels::surface::frames::TangentFrame;
    // A jittered plane of side 63 (one world unit per output pixel at
    // 64 × 64) with 17 × 17 vertices: about 4 pixels per edge.
    let opts = BuiltinOptions {
        resolution: [17, 17],
        size: 63.0,
        ..Default::default()
    };
    let mesh = builtin_mesh("jittered_plane", &opts).unwrap();
    // A 128² random exemplar (every pixel unlike its neighbours).
    let mut rng = 12345u64;
    let mut next = || {
        rng = rng
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (rng >> 40) as f32 / (1u64 << 24) as f32
    };
    let exemplar = surfsynth::image::Image::from_data(
        128,
        128,
        3,
        (0..128 * 128 * 3).map(|_| next()).collect(),
    )
    .unwrap();
    // s = +x, t = +y; the texel offset of d is (d.x, −d.y) at 1 texel per
    // unit. The box's min corner is (−31.5, −31.5): pixel (i, j) is at
    // x = −31.5 + i, y = 31.5 − j, and should show exemplar pixel
    // (i + 20, j + 30), whose centre is (i + 20.5, j + 30.5).
    let frame = TangentFrame::from_direction(glam::Vec3::Z, glam::Vec3::X);
    let frames = vec![frame; mesh.positions.len()];
    let sources: Vec<glam::Vec2> = mesh
        .positions
        .iter()
        .map(|p| glam::Vec2::new(p.x + 31.5 + 20.5, 31.5 - p.y + 30.5))
        .collect();
    let colours: Vec<f32> = sources
        .iter()
        .flat_map(|s| {
            let mut out = [0.0f32; 3];
            exemplar.sample_bilinear(s.x, s.y, surfsynth::image::sample::Wrap::Clamp, &mut out);
            out
        })
        .collect();
    let coordinates = PlaneSignal::Coordinates {
        sources: &sources,
        frames: &frames,
        scale: &[1.0],
        texture: &exemplar,
        wrap: surfsynth::image::sample::Wrap::Clamp,
    };
    let vertex = PlaneSignal::Colours {
        values: &colours,
        channels: 3,
        sources: Some(&sources),
    };
    let error = |signal: &PlaneSignal| {
        let plane = plane_from_surface(&mesh, signal, [64, 64], [128, 128]).unwrap();
        let mut worst = 0.0f32;
        let mut sum = 0.0f32;
        for j in 0..64u32 {
            for i in 0..64u32 {
                let want = exemplar.pixel(i + 20, j + 30);
                let got = plane.image.pixel(i, j);
                for c in 0..3 {
                    let e = (got[c] - want[c]).abs();
                    worst = worst.max(e);
                    sum += e;
                }
            }
        }
        (worst, sum / (64.0 * 64.0 * 3.0))
    };
    let (worst, _) = error(&coordinates);
    assert!(
        worst < 1e-3,
        "continued coordinates off the exemplar by {worst}"
    );
    let (_, mean_vertex) = error(&vertex);
    assert!(
        mean_vertex > 0.1,
        "vertex colours on a coarse mesh should lose the exemplar's detail: mean error {mean_vertex}"
    );
}
