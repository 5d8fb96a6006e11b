//! System and end-to-end tests of the house: a World and Schedule built from a
//! config, components checked after each stage; whole runs; determinism.

use crate::common::*;
use bevy_ecs::prelude::*;
use surfsynth::config::ConfigSource;
use surfsynth::pipeline::{Pipeline, RunOptions, load_input, run_in_world};
use surfsynth::world::*;

const CONFIG: &str = r#"
seed = 5
[input]
mesh = "builtin:icosphere"
exemplar = "builtin:bricks"
[input.mesh_options]
subdivisions = 3

[[stage]]
kind = "orientation"
mode = "global"
up = [0.0, 1.0, 0.0]

[[stage]]
kind = "init_colours"

[[stage]]
kind = "export"
formats = ["ply", "preview"]
preview_size = 128
"#;

fn pipeline_with_stages(n: usize) -> Pipeline {
    // Keep only the first `n` [[stage]] blocks.
    let mut parts: Vec<&str> = CONFIG.split("[[stage]]").collect();
    parts.truncate(n + 1);
    let text = parts.join("[[stage]]");
    Pipeline::from_source(ConfigSource::from_text("test.toml", &text)).expect("valid config")
}

fn world_after(n: usize) -> World {
    let p = pipeline_with_stages(n);
    let input = load_input(&p.input, &p.source.base_dir, &p.source.file).unwrap();
    let mut world = World::new();
    run_in_world(&p, &mut world, input).expect("pipeline runs");
    world
}

#[test]
fn components_after_each_stage() {
    // After orientation: orthonormal frames whose t follows +Y where possible.
    let w = world_after(1);
    let active = w.resource::<ActiveMesh>().0;
    let nv = w.get::<Geometry>(active).unwrap().0.vertex_count();
    let frames = &w.get::<Frames>(active).expect("orientation adds Frames").0;
    assert_eq!(frames.len(), nv);
    for f in frames {
        assert!((f.s.length() - 1.0).abs() < 1e-4 && f.s.dot(f.n).abs() < 1e-4);
        // t (texture up) is the projection of +Y: never pointing down.
        assert!(f.t.y >= -1e-4, "t follows the global up: {:?}", f.t);
    }
    assert!(w.get::<VertexColours>(active).is_none());
    assert_eq!(w.resource::<StageTimings>().0.len(), 1);

    // After init_colours: every vertex colour is an exemplar texel, recorded.
    let mut w = world_after(2);
    let active = w.resource::<ActiveMesh>().0;
    let ex = w.resource::<Exemplar>().image.clone();
    let mut q = w.query::<(&VertexColours, &SourceTexels)>();
    let (colours, texels) = q.get(&w, active).expect("init_colours adds colours");
    assert_eq!(colours.values.len(), nv * ex.channels as usize);
    for (v, t) in texels.0.iter().enumerate() {
        let px = ex.pixel(t.x as u32, t.y as u32);
        assert_eq!(
            &colours.values[v * px.len()..(v + 1) * px.len()],
            px,
            "vertex {v} has its texel's colour"
        );
    }

    // After export: the job holds the mesh and 3 previews.
    let w = world_after(3);
    let job = w.resource::<ExportJob>();
    assert_eq!(job.mesh.vertex_count(), nv);
    assert_eq!(job.previews.len(), 3);
    assert!(job.previews.iter().all(|p| p.width == 128));
}

#[test]
fn run_writes_all_outputs_and_metrics() {
    let dir = tempfile::tempdir().unwrap();
    let p = pipeline_with_stages(3);
    let report = surfsynth::pipeline::run(
        &p,
        &RunOptions {
            out_dir: Some(dir.path().to_path_buf()),
        },
    )
    .unwrap();
    for name in ["config.toml", "result.ply", "preview_0.png", "metrics.json"] {
        assert!(dir.path().join(name).is_file(), "{name} written");
    }
    let m = &report.metrics;
    assert_eq!(m["stages"].as_array().unwrap().len(), 3);
    assert!(
        m["result"]["quality"]["texture_energy"]["mean"]
            .as_f64()
            .is_some()
    );
    assert!(m["peak_rss_bytes"].as_u64().unwrap() > 0);
    // The resolved config runs again as it is.
    let resolved = std::fs::read_to_string(dir.path().join("config.toml")).unwrap();
    Pipeline::from_source(ConfigSource::from_text("resolved.toml", &resolved))
        .expect("the resolved config is valid");
    // No temporary files remain.
    assert!(
        files_under(dir.path())
            .iter()
            .all(|f| !f.to_string_lossy().ends_with(".tmp"))
    );
}

#[test]
fn same_seed_same_bytes_at_one_and_two_threads() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = dir.path().join("c.toml");
    std::fs::write(&cfg, CONFIG).unwrap();
    let mut outs = Vec::new();
    for threads in ["1", "2"] {
        let out = dir.path().join(format!("t{threads}"));
        let (code, _, stderr) = run_cli(&[
            "run",
            cfg.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--threads",
            threads,
        ]);
        assert_eq!(code, 0, "{stderr}");
        outs.push(out);
    }
    for name in [
        "result.ply",
        "preview_0.png",
        "preview_1.png",
        "preview_2.png",
        "config.toml",
    ] {
        let a = std::fs::read(outs[0].join(name)).unwrap();
        let b = std::fs::read(outs[1].join(name)).unwrap();
        assert!(a == b, "{name} differs between 1 and 2 threads");
    }
}

#[test]
fn default_config_runs() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/00_default.toml");
    let (code, stdout, stderr) = run_cli(&[
        "run",
        cfg.to_str().unwrap(),
        "--out",
        dir.path().to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{stderr}");
    assert!(stdout.contains("total"), "time table printed: {stdout}");
    assert!(dir.path().join("metrics.json").is_file());
    let glb = std::fs::read(dir.path().join("result.glb")).expect("the default writes result.glb");
    assert_eq!(&glb[..4], b"glTF", "a binary glTF header");
    assert!(dir.path().join("result_atlas.png").is_file());
}

#[test]
fn trace_file_is_chrome_json() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = dir.path().join("c.toml");
    std::fs::write(&cfg, CONFIG).unwrap();
    let trace = dir.path().join("trace.json");
    let (code, _, stderr) = run_cli(&[
        "run",
        cfg.to_str().unwrap(),
        "--out",
        dir.path().join("o").to_str().unwrap(),
        "--trace",
        trace.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{stderr}");
    let text = std::fs::read_to_string(&trace).unwrap();
    let v: serde_json::Value = serde_json::from_str(&text).expect("valid JSON");
    let events = v.as_array().expect("an array of trace events");
    assert!(
        events
            .iter()
            .any(|e| e["name"].as_str().is_some_and(|n| n.starts_with("stage:"))),
        "stage spans recorded, named stage:<kind>"
    );
}
