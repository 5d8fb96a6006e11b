//! Helpers shared by the integration tests.
#![allow(dead_code)]

pub mod gates;
pub mod methods;
pub mod peer;

use std::path::{Path, PathBuf};
use std::process::Command;

/// The built CLI binary.
pub fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_surfsynth"))
}

/// Path of a test data file under the repository's `data/` folder
/// (`data/meshes/...`, `data/textures/...`; sources and licences in
/// `data/README.md`).
pub fn data_file(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("data").join(rel)
}

/// Runs the CLI, returning (exit code, stdout, stderr).
pub fn run_cli(args: &[&str]) -> (i32, String, String) {
    run_cli_env(args, &[])
}

/// [`run_cli`] with extra environment variables.
pub fn run_cli_env(args: &[&str], env: &[(&str, &str)]) -> (i32, String, String) {
    let out = bin()
        .args(args)
        .env("RUST_LOG", "warn")
        .env(
            "SURFSYNTH_CACHE",
            Path::new(env!("CARGO_TARGET_TMPDIR")).join("surfsynth-cache"),
        )
        // The caller's variables last: they may name a cache of their own.
        .envs(env.iter().copied())
        .output()
        .expect("the surfsynth binary runs");
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// Files (recursively) under `dir`, empty when it does not exist.
pub fn files_under(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let Ok(rd) = std::fs::read_dir(dir) else {
        return out;
    };
    for e in rd.flatten() {
        let p = e.path();
        if p.is_dir() {
            out.extend(files_under(&p));
        } else {
            out.push(p);
        }
    }
    out.sort();
    out
}

/// Writes `config` into a temp dir, runs it with `--out DIR/out` and `extra`,
/// and checks exit 2, that stderr contains every `needles` and no panic, and
/// that no output folder was created.
pub fn expect_refused(config: &str, extra: &[&str], needles: &[&str]) {
    expect_refused_env(config, extra, &[], needles);
}

/// [`expect_refused`] with extra environment variables; returns stderr.
pub fn expect_refused_env(
    config: &str,
    extra: &[&str],
    env: &[(&str, &str)],
    needles: &[&str],
) -> String {
    let dir = tempfile::tempdir().expect("a temporary folder");
    let cfg = dir.path().join("bad.toml");
    std::fs::write(&cfg, config).expect("the config is written");
    let out = dir.path().join("out");
    let mut args = vec!["run", cfg.to_str().unwrap(), "--out", out.to_str().unwrap()];
    args.extend_from_slice(extra);
    let (code, _stdout, stderr) = run_cli_env(&args, env);
    assert_eq!(code, 2, "exit code for {needles:?}; stderr: {stderr}");
    for n in needles {
        assert!(stderr.contains(n), "stderr should contain {n:?}: {stderr}");
    }
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(
        !out.exists(),
        "no output folder may be created: {:?}",
        files_under(&out)
    );
    let left: Vec<_> = std::fs::read_dir(dir.path())
        .expect("the temporary folder")
        .flatten()
        .map(|e| e.file_name())
        .filter(|n| n != "bad.toml")
        .collect();
    assert!(left.is_empty(), "nothing else is left behind: {left:?}");
    stderr
}
pub mod messy;

/// Runs the pipeline of `source` in-process, after `edit` changed its loaded
/// input (the mesh, say), and returns the world with every stage's output.
pub fn world_from_source(
    source: surfsynth::config::ConfigSource,
    edit: impl FnOnce(&mut surfsynth::pipeline::LoadedInput),
) -> Result<bevy_ecs::world::World, surfsynth::pipeline::PipelineError> {
    use surfsynth::pipeline::{Pipeline, load_input, run_in_world};
    let p = Pipeline::from_source(source)?;
    let mut input = load_input(&p.input, &p.source.base_dir, &p.source.file)?;
    edit(&mut input);
    let mut world = bevy_ecs::world::World::new();
    run_in_world(&p, &mut world, input).map(|()| world)
}

/// [`world_from_source`] for a config text (relative paths against the
/// current directory), after `edit` changed its loaded input.
pub fn world_with(
    text: &str,
    edit: impl FnOnce(&mut surfsynth::pipeline::LoadedInput),
) -> Result<bevy_ecs::world::World, surfsynth::pipeline::PipelineError> {
    world_from_source(
        surfsynth::config::ConfigSource::from_text("test.toml", text),
        edit,
    )
}

/// [`world_with`] without an edit.
pub fn world_for(text: &str) -> Result<bevy_ecs::world::World, surfsynth::pipeline::PipelineError> {
    world_with(text, |_| {})
}

/// Two unit cubes, [0,1]³ and [1,2]×[1,2]×[0,1], sharing one edge (x = y = 1;
/// four triangles meet on it, two vertices are shared), as 14 vertices and
/// 24 outward-facing triangles in an order shuffled by `seed` (0: as built).
pub fn two_cubes_sharing_an_edge(seed: u64) -> (Vec<glam::Vec3>, Vec<[u32; 3]>) {
    let mut positions: Vec<glam::Vec3> = Vec::new();
    let mut triangles = Vec::new();
    // Corner k of a cube is at offset (k >> 2 & 1, k >> 1 & 1, k & 1).
    let quads = [
        [0, 1, 3, 2],
        [4, 6, 7, 5],
        [0, 4, 5, 1],
        [2, 3, 7, 6],
        [0, 2, 6, 4],
        [1, 5, 7, 3],
    ];
    for origin in [glam::Vec3::ZERO, glam::Vec3::new(1.0, 1.0, 0.0)] {
        let mut id = |k: u32| {
            let p =
                origin + glam::Vec3::new((k >> 2 & 1) as f32, (k >> 1 & 1) as f32, (k & 1) as f32);
            match positions.iter().position(|&q| q == p) {
                Some(i) => i as u32,
                None => {
                    positions.push(p);
                    positions.len() as u32 - 1
                }
            }
        };
        for q in quads {
            let [a, b, c, d] = q.map(&mut id);
            triangles.push([a, b, c]);
            triangles.push([a, c, d]);
        }
    }
    // Fisher–Yates with a small LCG.
    let mut state = seed;
    for i in (1..triangles.len()).rev() {
        state = state
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        let j = (state >> 33) as usize % (i + 1);
        if seed != 0 {
            triangles.swap(i, j);
        }
    }
    (positions, triangles)
}

/// `positions` and `triangles` as OBJ text.
pub fn triangles_obj(positions: &[glam::Vec3], triangles: &[[u32; 3]]) -> String {
    let mut text = String::new();
    for p in positions {
        text.push_str(&format!("v {} {} {}\n", p.x, p.y, p.z));
    }
    for t in triangles {
        text.push_str(&format!("f {} {} {}\n", t[0] + 1, t[1] + 1, t[2] + 1));
    }
    text
}
