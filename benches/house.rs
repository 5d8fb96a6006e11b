//! The house: loading a shared mesh, rendering previews, the texture-energy
//! metric, and the default pipeline end to end.
//!
//! `cargo bench --bench house` (baseline workflow: `-- --save-baseline main`,
//! then `-- --baseline main` after a change).

use criterion::{Criterion, criterion_group, criterion_main};
use std::path::Path;
use surfsynth::config::ConfigSource;
use surfsynth::mesh::{LoadOptions, load_mesh};
use surfsynth::output::render::{RenderOptions, Shading, render_views};
use surfsynth::pipeline::{Pipeline, RunOptions, run};

fn data_file(rel: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("data").join(rel)
}

fn house(c: &mut Criterion) {
    surfsynth::progress::set_enabled(false);
    let fandisk = data_file("meshes/fandisk.off");
    c.bench_function("load/fandisk_6k5", |b| {
        b.iter(|| load_mesh(&fandisk, &LoadOptions::default()).unwrap())
    });
    let (mesh, _) = load_mesh(&fandisk, &LoadOptions::default()).unwrap();
    c.bench_function("render/fandisk_3_views_512", |b| {
        b.iter(|| render_views(&mesh, &Shading::Plain, 512, &RenderOptions::default()))
    });
    let cfg = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/00_default.toml");
    let pipeline = Pipeline::from_source(ConfigSource::from_file(&cfg).unwrap()).unwrap();
    let out = std::env::temp_dir().join("surfsynth-bench-house");
    let mut group = c.benchmark_group("pipeline");
    group.sample_size(10);
    group.bench_function("00_default", |b| {
        b.iter(|| {
            run(
                &pipeline,
                &RunOptions {
                    out_dir: Some(out.clone()),
                },
            )
            .unwrap()
        })
    });
    group.finish();
}

criterion_group!(benches, house);
criterion_main!(benches);
