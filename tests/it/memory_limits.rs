//! Memory estimates against the memory actually available (issue 43): the
//! limit is the smallest of the cgroup limit, `RLIMIT_AS` and the physical
//! memory, or `$SURFSYNTH_MEMORY_LIMIT`; every allocation the issue found
//! aborting a run inside the documented limits is refused up front (exit 2,
//! no output folder) naming the stage, the parameter, the estimate, the
//! limit and the largest value that fits; the largest value named does fit
//! and the next one does not.

use crate::common;

use std::path::Path;
use surfsynth::config::ConfigSource;
use surfsynth::pipeline::memory_budget::check_stages;
use surfsynth::pipeline::memory_limit::{LIMIT_VAR, LimitSource, MemoryLimit};
use surfsynth::pipeline::{Pipeline, load_input};
use surfsynth::stage::memory::InputSizes;

const ONE_GIB: &[(&str, &str)] = &[(LIMIT_VAR, "1G")];

const JUMP_IMAGE: &str = r#"
seed = 1
[input]
exemplar = "builtin:bricks"

[[stage]]
kind = "jump_map"

[[stage]]
kind = "jump_image"
width = 8192
height = 8192
"#;

const BAKE: &str = r#"
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
kind = "bake"
size = 8192

[[stage]]
kind = "export"
formats = ["glb"]
"#;

const LAPPED: &str = r#"
seed = 1
[input]
mesh = "builtin:icosphere"
exemplar = "builtin:noise"
[input.mesh_options]
subdivisions = 2

[[stage]]
kind = "tangent_field"

[[stage]]
kind = "lapped_paste"
atlas_size = 16384

[[stage]]
kind = "export"
formats = ["obj"]
"#;

const EXPORT_BAKED: &str = r#"
seed = 1
[input]
mesh = "builtin:icosphere"
exemplar = "builtin:bricks"
[input.mesh_options]
subdivisions = 2

[[stage]]
kind = "orientation"

[[stage]]
kind = "jump_map"

[[stage]]
kind = "jump_surface"

[[stage]]
kind = "export"
formats = ["baked"]
bake_size = 16384
"#;

/// A jump map of `exemplar` with `neighbourhoods`.
fn jump_map(exemplar: &str, neighbourhoods: &str) -> String {
    format!(
        r#"
seed = 1
[input]
exemplar = "{exemplar}"

[[stage]]
kind = "jump_map"
cache = false
neighbourhoods = {neighbourhoods}

[[stage]]
kind = "jump_image"
width = 64
height = 64
"#
    )
}

/// A smooth RGB gradient PNG of `side²` pixels (a few KB: it compresses).
fn gradient_png(dir: &Path, side: u32) -> String {
    let path = dir.join(format!("gradient_{side}.png"));
    let img = image::RgbImage::from_fn(side, side, |x, y| {
        image::Rgb([(x * 255 / side) as u8, (y * 255 / side) as u8, 128])
    });
    img.save(&path).expect("the PNG is written");
    path.display().to_string()
}

/// The value after `the largest that fits: PARAM = ` in `message`.
fn largest(message: &str, param: &str) -> String {
    let key = format!("the largest that fits: {param} = ");
    let at = message
        .find(&key)
        .unwrap_or_else(|| panic!("{key:?} in {message}"));
    let rest = &message[at + key.len()..];
    let end = rest.find([',', '\n']).unwrap_or(rest.len());
    let end = if rest.starts_with('[') {
        rest.find(']').map_or(end, |e| e + 1)
    } else {
        end
    };
    rest[..end].trim().to_string()
}

#[test]
fn jump_image_at_8192_is_refused_before_work() {
    let stderr = common::expect_refused_env(
        JUMP_IMAGE,
        &[],
        ONE_GIB,
        &[
            "stage 2 (jump_image) width x height",
            "`width x height` = 8192x8192 needs an estimated",
            "GiB of memory",
            "over the memory limit of 1.00 GiB (SURFSYNTH_MEMORY_LIMIT)",
            "the largest that fits: width x height = ",
        ],
    );
    let fit = largest(&stderr, "width x height");
    let (w, h) = fit.split_once('x').expect("WxH");
    assert_eq!(w, h, "a square stays square: {fit}");
}

#[test]
fn bake_at_its_largest_size_is_refused_under_one_gib() {
    common::expect_refused_env(
        BAKE,
        &[],
        ONE_GIB,
        &[
            "stage 3 (bake) size",
            "`size` = 8192 needs an estimated",
            "memory limit of 1.00 GiB",
            "the largest that fits: size = ",
        ],
    );
}

#[test]
fn lapped_atlas_at_16384_is_refused() {
    common::expect_refused_env(
        LAPPED,
        &[],
        ONE_GIB,
        &[
            "stage 2 (lapped_paste) atlas_size",
            "`atlas_size` = 16384 needs an estimated",
            "the largest that fits: atlas_size = ",
        ],
    );
}

#[test]
fn export_bake_size_and_plane_size_at_16384_are_refused() {
    common::expect_refused_env(
        EXPORT_BAKED,
        &[],
        ONE_GIB,
        &[
            "stage 4 (export) bake_size",
            "`bake_size` = 16384 needs an estimated",
            "the largest that fits: bake_size = ",
        ],
    );
    let plane = BAKE
        .replace("kind = \"bake\"\nsize = 8192\n\n[[stage]]\n", "")
        .replace(
            "formats = [\"glb\"]",
            "formats = [\"plane\"]\nplane_size = [16384, 16384]",
        );
    common::expect_refused_env(
        &plane,
        &[],
        ONE_GIB,
        &[
            "stage 3 (export) plane_size",
            "`plane_size` = 16384x16384",
            "the largest that fits: plane_size = ",
        ],
    );
}

#[test]
fn jump_map_neighbourhoods_31_on_a_1024_png_are_refused_after_loading_before_work() {
    let dir = tempfile::tempdir().unwrap();
    let png = gradient_png(dir.path(), 1024);
    let stderr = common::expect_refused_env(
        &jump_map(&png, "[31, 31, 31]"),
        &[],
        ONE_GIB,
        &[
            "stage 1 (jump_map)",
            "`neighbourhoods` = [31, 31, 31] needs an estimated",
            "memory limit of 1.00 GiB",
            "the largest that fits: neighbourhoods = [",
        ],
    );
    assert!(!stderr.contains("panicked") && !stderr.contains("memory allocation"));
}

#[test]
fn jump_map_analysis_of_the_largest_exemplars_is_refused_under_one_gib() {
    // 2048² (builtin) and 4096² (a PNG at the documented cap) with the
    // paper's neighbourhoods: 5.8 and 23 GB of neighbourhood vectors in one
    // piece before issue 43.
    let dir = tempfile::tempdir().unwrap();
    let png = gradient_png(dir.path(), 4096);
    common::expect_refused_env(
        &jump_map(&png, "[9, 5, 3]"),
        &[],
        ONE_GIB,
        &[
            "stage 1 (jump_map)",
            "needs an estimated",
            "largest that fits",
        ],
    );
    let builtin = jump_map("builtin:noise", "[9, 5, 3]").replace(
        "exemplar = \"builtin:noise\"",
        "exemplar = \"builtin:noise\"\n[input.exemplar_options]\nsize = 2048",
    );
    common::expect_refused_env(
        &builtin,
        &[],
        ONE_GIB,
        &[
            "stage 1 (jump_map)",
            "needs an estimated",
            "largest that fits",
        ],
    );
}

#[test]
fn a_malformed_limit_is_refused_naming_the_variable() {
    for bad in ["lots", "1.5G", "0", "-3", "12T"] {
        let stderr = common::expect_refused_env(
            JUMP_IMAGE,
            &[],
            &[(LIMIT_VAR, bad)],
            &[LIMIT_VAR, "allowed", "K, M or G"],
        );
        assert!(stderr.contains(&format!("{bad:?}")), "{stderr}");
    }
}

/// Runs a small config (jump map and a 64² image) and returns its
/// metrics.json, with `env`, under `ulimit -v KB` when given.
fn small_run_metrics(env: &[(&str, &str)], ulimit_kb: Option<u64>) -> serde_json::Value {
    let dir = tempfile::tempdir().unwrap();
    let cfg = dir.path().join("small.toml");
    std::fs::write(&cfg, jump_map("builtin:bricks", "[9, 5, 3]")).unwrap();
    let out = dir.path().join("out");
    let bin = env!("CARGO_BIN_EXE_surfsynth");
    let run = match ulimit_kb {
        Some(kb) => {
            let mut c = std::process::Command::new("sh");
            c.arg("-c")
                .arg(format!(
                    "ulimit -v {kb} && exec \"$0\" run \"$1\" --out \"$2\" -q"
                ))
                .arg(bin)
                .arg(&cfg)
                .arg(&out);
            c
        }
        None => {
            let mut c = common::bin();
            c.arg("run").arg(&cfg).arg("--out").arg(&out).arg("-q");
            c
        }
    }
    .envs(env.iter().copied())
    .env_remove_if_absent(env)
    .output()
    .expect("the binary runs");
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    serde_json::from_str(&std::fs::read_to_string(out.join("metrics.json")).unwrap()).unwrap()
}

/// Removes [`LIMIT_VAR`] from a child's environment unless `env` sets it, so
/// a variable set around the test run does not leak into detection tests.
trait RemoveLimit {
    fn env_remove_if_absent(&mut self, env: &[(&str, &str)]) -> &mut Self;
}

impl RemoveLimit for std::process::Command {
    fn env_remove_if_absent(&mut self, env: &[(&str, &str)]) -> &mut Self {
        if !env.iter().any(|(k, _)| *k == LIMIT_VAR) {
            self.env_remove(LIMIT_VAR);
        }
        self
    }
}

#[test]
fn metrics_report_the_limit_used_and_where_it_came_from() {
    let m = small_run_metrics(&[(LIMIT_VAR, "3G")], None);
    assert_eq!(m["memory"]["limit_bytes"], 3u64 << 30, "{}", m["memory"]);
    assert_eq!(m["memory"]["limit_source"], LIMIT_VAR);
    assert!(m["memory"]["input_bytes"].as_u64().unwrap() > 0);
    // Each estimating stage records its estimate.
    let jm = &m["stages"][0]["metrics"]["memory_estimate_bytes"];
    assert!(
        jm["neighbourhoods"].as_u64().unwrap() > 0,
        "{}",
        m["stages"][0]
    );
    let ji = &m["stages"][1]["metrics"]["memory_estimate_bytes"];
    assert!(
        ji["width x height"].as_u64().unwrap() > 0,
        "{}",
        m["stages"][1]
    );
    // Under `ulimit -v` without the variable: the address-space limit less
    // what the process maps already and the reserve for thread stacks and
    // arenas, unless a cgroup or the machine has less.
    let kb = 3u64 << 20; // 3 GiB
    let m = small_run_metrics(&[], Some(kb));
    let source = m["memory"]["limit_source"].as_str().unwrap().to_string();
    let bytes = m["memory"]["limit_bytes"].as_u64().unwrap();
    let reserve = surfsynth::pipeline::memory_limit::ADDRESS_SPACE_RESERVE;
    assert!(bytes <= kb * 1024 - reserve, "{source} {bytes}");
    assert!(
        ["RLIMIT_AS", "cgroup", "physical"]
            .iter()
            .any(|s| source.contains(s)),
        "{source}"
    );
    if !source.contains("cgroup") && !source.contains("physical") {
        assert!(bytes > kb * 1024 / 2, "{source} {bytes}");
    }
}

#[test]
fn under_an_address_space_cap_jump_image_at_8192_is_refused_naming_rlimit_as() {
    // The issue's case: `ulimit -v` 4 GB, no variable; it aborted after 22 s.
    let dir = tempfile::tempdir().unwrap();
    let cfg = dir.path().join("big.toml");
    std::fs::write(&cfg, JUMP_IMAGE).unwrap();
    let out = dir.path().join("out");
    let run = std::process::Command::new("sh")
        .arg("-c")
        .arg("ulimit -v 4000000 && exec \"$0\" run \"$1\" --out \"$2\" -q")
        .arg(env!("CARGO_BIN_EXE_surfsynth"))
        .arg(&cfg)
        .arg(&out)
        .env_remove(LIMIT_VAR)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("stage 2 (jump_image)") && stderr.contains("largest that fits"),
        "{stderr}"
    );
    if !stderr.contains("cgroup") {
        assert!(stderr.contains("RLIMIT_AS"), "{stderr}");
    }
    assert!(!out.exists());
}

fn limit(bytes: u64) -> MemoryLimit {
    MemoryLimit {
        bytes,
        source: LimitSource::Environment,
    }
}

/// Refused under `bytes`, the largest value named fits and one step more
/// does not: `with(value)` is the config with the parameter set to a value
/// as the message writes it, `next(value)` one step larger.
fn largest_fits(
    config: &str,
    param: &str,
    bytes: u64,
    with: impl Fn(&str) -> String,
    next: impl Fn(&str) -> String,
) {
    let sizes_of = |text: &str| {
        let p = Pipeline::from_source(ConfigSource::from_text("t.toml", text))
            .unwrap_or_else(|e| panic!("{e}"));
        let input = load_input(&p.input, &p.source.base_dir, &p.source.file).unwrap();
        let sizes = InputSizes::of(&input, &p.input);
        (p, sizes)
    };
    let (p, sizes) = sizes_of(config);
    let refusal = check_stages(&p.stages, &sizes, &limit(bytes), &[]).expect_err("refused");
    assert_eq!(refusal.param, param);
    let value = largest(&refusal.message, param);
    let (p, sizes) = sizes_of(&with(&value));
    check_stages(&p.stages, &sizes, &limit(bytes), &[])
        .unwrap_or_else(|r| panic!("{value} should fit: {}", r.message));
    let bigger = next(&value);
    let (p, sizes) = sizes_of(&with(&bigger));
    assert!(
        check_stages(&p.stages, &sizes, &limit(bytes), &[]).is_err(),
        "{value} is the largest, {bigger} should not fit"
    );
}

#[test]
fn the_largest_value_named_fits_and_one_more_does_not() {
    let mib = 1u64 << 20;
    // jump_image: 2048² under 64 MiB.
    let ji = JUMP_IMAGE.replace("8192", "2048");
    largest_fits(
        &ji,
        "width x height",
        64 * mib,
        |v| {
            let (w, h) = v.split_once('x').unwrap();
            ji.replace("width = 2048", &format!("width = {w}"))
                .replace("height = 2048", &format!("height = {h}"))
        },
        |v| {
            let (w, _) = v.split_once('x').unwrap();
            let w: u32 = w.parse().unwrap();
            format!("{}x{}", w + 1, w + 1)
        },
    );
    // bake: 4096 under 128 MiB.
    let bake = BAKE.replace("size = 8192", "size = 4096");
    largest_fits(
        &bake,
        "size",
        128 * mib,
        |v| bake.replace("size = 4096", &format!("size = {v}")),
        |v| (v.parse::<u32>().unwrap() + 1).to_string(),
    );
    // lapped atlas: 4096 under 128 MiB.
    let lapped = LAPPED.replace("atlas_size = 16384", "atlas_size = 4096");
    largest_fits(
        &lapped,
        "atlas_size",
        128 * mib,
        |v| lapped.replace("atlas_size = 4096", &format!("atlas_size = {v}")),
        |v| (v.parse::<u32>().unwrap() + 1).to_string(),
    );
    // jump_map: [31, 31, 31] on a 256² exemplar under 256 MiB; the next
    // larger value widens every level by 2.
    let jm = jump_map("builtin:noise", "[31, 31, 31]").replace(
        "exemplar = \"builtin:noise\"",
        "exemplar = \"builtin:noise\"\n[input.exemplar_options]\nsize = 256",
    );
    largest_fits(
        &jm,
        "neighbourhoods",
        256 * mib,
        |v| jm.replace("[31, 31, 31]", v),
        |v| {
            let widths: Vec<u32> = v
                .trim_matches(['[', ']'])
                .split(',')
                .map(|w| w.trim().parse().unwrap())
                .collect();
            let cap = widths.iter().max().unwrap() + 2;
            format!(
                "[{}]",
                [31u32, 31, 31]
                    .iter()
                    .map(|w| w.min(&cap).to_string())
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        },
    );
}

/// Issue 43: a jump map already in the analysis cache is read, not
/// analysed, so a limit that refuses its analysis does not refuse the run
/// (it was estimated as if analysed).
#[test]
fn a_cached_jump_map_is_not_refused_for_the_analysis_it_skips() {
    let dir = tempfile::tempdir().unwrap();
    let png = gradient_png(dir.path(), 384);
    let config = jump_map(&png, "[9, 5, 3]").replace("cache = false\n", "");
    let cache = dir.path().join("cache");
    let cache = cache.to_str().unwrap();
    let low: &[(&str, &str)] = &[(LIMIT_VAR, "64M"), ("SURFSYNTH_CACHE", cache)];
    common::expect_refused_env(
        &config,
        &[],
        low,
        &[
            "stage 1 (jump_map)",
            "needs an estimated",
            "largest that fits",
        ],
    );
    let cfg = dir.path().join("j.toml");
    std::fs::write(&cfg, &config).unwrap();
    let run = |env: &[(&str, &str)], out: &str| {
        let out = dir.path().join(out);
        let (code, _, stderr) = common::run_cli_env(
            &["run", cfg.to_str().unwrap(), "--out", out.to_str().unwrap()],
            env,
        );
        (code, stderr, out)
    };
    let (code, stderr, _) = run(&[("SURFSYNTH_CACHE", cache)], "first");
    assert_eq!(code, 0, "{stderr}");
    let (code, stderr, out) = run(low, "second");
    assert_eq!(
        code, 0,
        "the cached map is read under the low limit: {stderr}"
    );
    let metrics = std::fs::read_to_string(out.join("metrics.json")).unwrap();
    assert!(metrics.contains("\"cache_hit\": true"), "{metrics}");
}

/// Issue 43: the stages after a retiling see the retiled mesh's size, not
/// the input's, in their estimates.
#[test]
fn stages_after_a_retiling_are_estimated_on_the_retiled_mesh() {
    let text = r#"
seed = 1
[input]
mesh = "builtin:icosphere"
exemplar = "builtin:noise"
[input.mesh_options]
subdivisions = 1
[[stage]]
kind = "retile"
vertices = 50000
[[stage]]
kind = "subdivide_sqrt2"
levels = 2
"#;
    let p = Pipeline::from_source(ConfigSource::from_text("t.toml", text)).unwrap();
    let input = load_input(&p.input, &p.source.base_dir, &p.source.file).unwrap();
    let sizes = InputSizes::of(&input, &p.input);
    let seen = surfsynth::pipeline::memory_budget::stage_sizes(&p.stages, &sizes);
    assert_eq!(seen[0].vertices, sizes.vertices);
    assert_eq!(seen[1].vertices, 50_000);
    let input_only = p.stages[1].memory_estimate(&sizes)[0].bytes;
    let after = p.stages[1].memory_estimate(&seen[1])[0].bytes;
    assert!(after > 100 * input_only, "{after} vs {input_only}");
}

/// Issue 43: the per-vertex synthesis stages estimate their arrays from the
/// vertices of the mesh they work on; over the limit, the run is refused
/// after loading, before work, naming the vertex count that fits.
#[test]
fn a_per_vertex_stage_over_the_limit_is_refused_naming_the_vertices_that_fit() {
    let text = r#"
seed = 1
[input]
mesh = "builtin:icosphere"
exemplar = "builtin:noise"
[input.mesh_options]
subdivisions = 6
[[stage]]
kind = "diffuse_orientation"
keys = [{ at_bbox = [0.5, 0.5, 1.0], up = [0.0, 1.0, 0.0] }]
"#;
    let stderr = common::expect_refused_env(
        text,
        &[],
        &[(LIMIT_VAR, "8M")],
        &[
            "stage 1 (diffuse_orientation): `vertices` = 40962",
            "needs an estimated",
            "the diffused orientation field",
            "over the memory limit of 8.0 MiB (SURFSYNTH_MEMORY_LIMIT)",
        ],
    );
    let fit: u64 = largest(&stderr, "vertices").parse().expect("a count");
    assert!((1000..40962).contains(&fit), "{fit}: {stderr}");
}

/// The result metrics follow every pipeline; their sampled windows grow
/// with `output.metric_samples` (up to 100,000 of 15×15 windows with their
/// dense sharpness templates: about 7 GB). Over the limit, the run is
/// refused once the input is loaded (the metrics sample vertices, each at
/// most once), before the first stage, naming the samples that fit.
#[test]
fn result_metrics_over_the_limit_are_refused_naming_the_samples_that_fit() {
    let text = r#"
seed = 1
[input]
mesh = "builtin:icosphere"
exemplar = "builtin:noise"
[input.mesh_options]
subdivisions = 6
[[stage]]
kind = "orientation"
[output]
metric_samples = 100000
metric_neighbourhood = 15
"#;
    let stderr = common::expect_refused_env(
        text,
        &[],
        &[(LIMIT_VAR, "256M")],
        &[
            "output.metric_samples",
            "`output.metric_samples` = 100000 needs an estimated",
            "the result metrics",
            "over the memory limit of 256.0 MiB (SURFSYNTH_MEMORY_LIMIT)",
        ],
    );
    let fit: u64 = largest(&stderr, "output.metric_samples")
        .parse()
        .expect("a count");
    assert!((10..100_000).contains(&fit), "{fit}: {stderr}");
}

/// Issue 43: the largest value a validation-time refusal offers is one the
/// run then accepts: it allows for the loaded input (the exemplar, the
/// mesh, the texture patches cut from the exemplar), which validation
/// alone does not know. (`atlas_size` = 16384 was refused offering a
/// value that was refused in turn once the input was loaded, 24 KiB over.)
#[test]
fn the_atlas_size_a_refusal_offers_is_accepted() {
    let env: &[(&str, &str)] = &[(LIMIT_VAR, "64M")];
    let stderr =
        common::expect_refused_env(LAPPED, &[], env, &["stage 2 (lapped_paste) atlas_size"]);
    let offer = largest(&stderr, "atlas_size");
    let dir = tempfile::tempdir().unwrap();
    let cfg = dir.path().join("lapped.toml");
    std::fs::write(
        &cfg,
        LAPPED.replace("atlas_size = 16384", &format!("atlas_size = {offer}")),
    )
    .unwrap();
    let out = dir.path().join("out");
    let (code, _, stderr) = common::run_cli_env(
        &["run", cfg.to_str().unwrap(), "--out", out.to_str().unwrap()],
        env,
    );
    assert_eq!(code, 0, "atlas_size = {offer}: {stderr}");
}
