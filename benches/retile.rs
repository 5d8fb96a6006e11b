//! Benchmarks of the Wei–Levoy retiling kernel
//! ([`surfsynth::kernels::wei_levoy::retile::retile`]): a four-level pyramid over the
//! builtin icosphere (642 vertices) and the shared Stanford bunny (1,839
//! vertices), at about 6k and 24k vertices on level 0.
//!
//! Workflow: `cargo bench --bench retile -- --save-baseline main` on the
//! base commit, then `cargo bench --bench retile -- --baseline main` on the
//! change to compare. The bunny cases are skipped when `data` is
//! missing.

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use std::hint::black_box;
use std::path::Path;
use std::time::Duration;
use surfsynth::kernels::wei_levoy::retile::{RetileSettings, retile};
use surfsynth::mesh::builtin::{BuiltinOptions, builtin_mesh};
use surfsynth::mesh::{LoadOptions, PolyMesh, load_mesh};

/// The benchmark inputs, by name.
fn inputs() -> Vec<(&'static str, PolyMesh)> {
    let mut out = vec![(
        "icosphere",
        builtin_mesh("icosphere", &BuiltinOptions::default()).expect("builtin icosphere"),
    )];
    let bunny = Path::new(env!("CARGO_MANIFEST_DIR")).join("data/meshes/bunny_1k8.obj");
    if let Ok((mesh, _)) = load_mesh(&bunny, &LoadOptions::default()) {
        out.push(("bunny", mesh));
    }
    out
}

fn bench_retile(c: &mut Criterion) {
    let mut group = c.benchmark_group("retile");
    group.sample_size(10);
    group.measurement_time(Duration::from_secs(15));
    for (name, mesh) in inputs() {
        for vertices in [6_144u32, 24_576] {
            let settings = RetileSettings::with_vertices(vertices);
            group.bench_with_input(BenchmarkId::new(name, vertices), &settings, |b, s| {
                b.iter(|| retile(black_box(&mesh), s).expect("retile succeeds"))
            });
        }
    }
    group.finish();
}

criterion_group!(benches, bench_retile);
criterion_main!(benches);
