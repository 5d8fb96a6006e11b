//! Every shipped config that synthesises on a mesh runs unchanged on a mesh
//! it was not written for (issue 14): its texture scale follows the new
//! mesh (`[input] texture_scale` is relative to the bounding-box diagonal),
//! so the effective texels per diagonal stay the config's, and the texture
//! quality stays within stated bounds of the config's own mesh:
//!
//! - coherence error (texture energy, mean) at most 1.5 × its own mesh's,
//! - completeness at most 2 × its own mesh's (a different surface shows a
//!   different amount of the exemplar, but not a collapse to a few texels),
//! - sharpness at least 0.7 × its own mesh's,
//! - effective texels per bounding-box diagonal within 10 % of its own
//!   mesh's; where the config varies the scale over the surface by design
//!   (`scale_by_height`, constraint `scale`s), the effective scale within
//!   the range the config declares.
//!
//! The full check (every config on the knot and on the mushroom) takes
//! about ten minutes: `cargo test --release --test it -- --ignored
//! configs_on_other_meshes::`. The suite runs three quick configs on the
//! mushroom: the default (a builtin torus with `mesh_options`, which
//! `--set input.mesh` drops with a warning), Bangay–Morkel and lapped
//! textures.

use crate::common;

use std::path::{Path, PathBuf};

/// The quality and scale a run reports.
#[derive(Debug, Clone, Copy)]
struct Measured {
    coherence: f64,
    completeness: f64,
    sharpness: f64,
    texels_per_diagonal: f64,
    /// Effective over requested texels per world unit.
    over_requested: f64,
}

fn run(config: &Path, mesh: Option<&Path>) -> Measured {
    let dir = tempfile::tempdir().unwrap();
    let mut args = vec![
        "run".to_string(),
        config.to_str().unwrap().to_string(),
        "--out".into(),
        dir.path().join("out").to_str().unwrap().to_string(),
    ];
    if let Some(m) = mesh {
        args.push("--set".into());
        args.push(format!("input.mesh={}", m.display()));
    }
    let refs: Vec<&str> = args.iter().map(String::as_str).collect();
    let (code, _, stderr) = common::run_cli(&refs);
    assert_eq!(
        code,
        0,
        "{} on {:?} fails:\n{stderr}",
        config.display(),
        mesh
    );
    let text = std::fs::read_to_string(dir.path().join("out/metrics.json")).unwrap();
    let m: serde_json::Value = serde_json::from_str(&text).unwrap();
    let q = &m["result"]["quality"];
    let num = |v: &serde_json::Value, what: &str| {
        v.as_f64()
            .unwrap_or_else(|| panic!("{}: no {what} in {}", config.display(), m["result"]))
    };
    Measured {
        coherence: num(&q["coherence"]["mean"], "coherence"),
        completeness: num(&q["completeness"], "completeness"),
        sharpness: num(&q["sharpness"], "sharpness"),
        texels_per_diagonal: num(
            &m["result"]["scale"]["texels_per_bbox_diagonal"],
            "texels_per_bbox_diagonal",
        ),
        over_requested: num(
            &m["result"]["scale"]["effective_over_requested"],
            "effective_over_requested",
        ),
    }
}

/// The shipped configs that synthesise a texture on their `[input] mesh`
/// (not the planar ones, not the pyramid-of-builtins ones, not previews).
fn mesh_configs() -> Vec<PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs");
    let mut out: Vec<PathBuf> = std::fs::read_dir(&root)
        .unwrap()
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .filter(|p| {
            let v: toml::Value = toml::from_str(&std::fs::read_to_string(p).unwrap()).unwrap();
            let kinds: Vec<&str> = v
                .get("stage")
                .and_then(|s| s.as_array())
                .map(|a| a.iter().filter_map(|s| s.get("kind")?.as_str()).collect())
                .unwrap_or_default();
            let has_mesh = v.get("input").and_then(|i| i.get("mesh")).is_some();
            let synthesises = kinds.iter().any(|k| {
                matches!(
                    *k,
                    "jump_surface" | "match" | "graph_match" | "coherent" | "lapped_paste"
                )
            });
            has_mesh && synthesises && !kinds.contains(&"builtin_pyramid")
        })
        .collect();
    out.sort();
    out
}

/// The range of texels per unit, as multiples of the requested scale, that
/// a config asks for by design when its scale varies over the surface
/// (`jump_surface` `scale_by_height`, `tangent_field` constraints with a
/// `scale`); `None` for a uniform scale.
fn declared_range(config: &Path) -> Option<(f64, f64)> {
    let v: toml::Value = toml::from_str(&std::fs::read_to_string(config).unwrap()).unwrap();
    let mut range: Option<(f64, f64)> = None;
    let mut widen = |a: f64, b: f64| {
        let (lo, hi) = range.unwrap_or((1.0, 1.0));
        range = Some((lo.min(a).min(b), hi.max(a).max(b)));
    };
    for stage in v
        .get("stage")
        .and_then(|s| s.as_array())
        .into_iter()
        .flatten()
    {
        if let Some(r) = stage.get("scale_by_height").and_then(|r| r.as_array()) {
            let f: Vec<f64> = r.iter().filter_map(|x| x.as_float()).collect();
            widen(f[0], f[1]);
        }
        for c in stage
            .get("constraints")
            .and_then(|c| c.as_array())
            .into_iter()
            .flatten()
        {
            // A constraint's scale multiplies the patch size: texels per
            // unit divide by it.
            if let Some(s) = c.get("scale").and_then(|s| s.as_float()) {
                widen(1.0 / s, 1.0);
            }
        }
    }
    range
}

fn check(config: &Path, other: &Path) -> Result<String, String> {
    let own = run(config, None);
    let got = run(config, Some(other));
    let name = format!(
        "{} on {}",
        config.file_name().unwrap().to_string_lossy(),
        other.file_name().unwrap().to_string_lossy()
    );
    let line = format!(
        "{name}: coherence {:.4} vs own {:.4}, completeness {:.4} vs {:.4}, sharpness {:.3} vs {:.3}, texels/diagonal {:.1} vs {:.1}",
        got.coherence,
        own.coherence,
        got.completeness,
        own.completeness,
        got.sharpness,
        own.sharpness,
        got.texels_per_diagonal,
        own.texels_per_diagonal
    );
    // A uniform scale follows the mesh within 10 %; a scale that varies by
    // design stays within the range the config declares (its mean depends
    // on the shape).
    let scale_ok = match declared_range(config) {
        None => (got.texels_per_diagonal / own.texels_per_diagonal - 1.0).abs() <= 0.10,
        Some((lo, hi)) => got.over_requested >= lo && got.over_requested <= hi,
    };
    let ok = got.coherence <= 1.5 * own.coherence
        && got.completeness <= 2.0 * own.completeness
        && got.sharpness >= 0.7 * own.sharpness
        && scale_ok;
    if ok { Ok(line) } else { Err(line) }
}

fn check_all(configs: &[PathBuf], meshes: &[PathBuf]) {
    let mut lines = Vec::new();
    let mut failures = Vec::new();
    for c in configs {
        for m in meshes {
            match check(c, m) {
                Ok(l) => lines.push(l),
                Err(l) => failures.push(l),
            }
        }
    }
    eprintln!("{}", lines.join("\n"));
    assert!(
        failures.is_empty(),
        "out of bounds:\n{}",
        failures.join("\n")
    );
}

#[test]
fn quick_configs_run_on_the_mushroom_within_bounds() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs");
    let configs: Vec<PathBuf> = [
        "00_default.toml",
        "20_bm_eight_water.toml",
        "30_lapped_bunny_isotropic.toml",
    ]
    .iter()
    .map(|c| root.join(c))
    .collect();
    check_all(&configs, &[common::data_file("meshes/mushroom.off")]);
}

#[test]
#[ignore = "about ten minutes: every shipped mesh config on the knot and the mushroom"]
fn every_shipped_config_runs_on_the_knot_and_the_mushroom_within_bounds() {
    let mut configs = mesh_configs();
    assert!(configs.len() >= 20, "{configs:?}");
    // SURFSYNTH_CONFIGS=05,32 checks only the configs with those prefixes.
    if let Ok(only) = std::env::var("SURFSYNTH_CONFIGS") {
        let prefixes: Vec<&str> = only.split(',').map(str::trim).collect();
        configs.retain(|c| {
            let name = c.file_name().unwrap().to_string_lossy().to_string();
            prefixes.iter().any(|p| name.starts_with(p))
        });
    }
    check_all(
        &configs,
        &[
            common::data_file("meshes/knot.off"),
            common::data_file("meshes/mushroom.off"),
        ],
    );
}
