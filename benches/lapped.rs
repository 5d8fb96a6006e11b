//! The full paste loop of lapped textures (Praun et al. 2000 §3): pick a
//! seed, grow, flatten (CG), regrow, update the coverage, until every face
//! is covered — on the shared bunny (3 674 faces) and on a builtin torus
//! knot of 75 000 faces. Global up field, texture patch size 15 % of the
//! bounding-box diagonal, a 128-pixel splotch patch. The paper reports 20 s
//! to 6 min for its ~5 000-face meshes (733 MHz Pentium III).
//!
//! Timed: `paste_until_covered` only; the mesh preparation, the field and
//! the texture patch are built outside the loop. Also timed separately on
//! the bunny: the culling of occluded faces for runtime pasting and the
//! texture atlas (charts, packing, compositing at 1024²).
//!
//! Run: `cargo bench --bench lapped`. Baseline workflow:
//! `cargo bench --bench lapped -- --save-baseline main`, then after a
//! change `cargo bench --bench lapped -- --baseline main`.

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use glam::Vec3;
use std::hint::black_box;
use surfsynth::image::Image;
use surfsynth::image::sample::Wrap;
use surfsynth::kernels::lapped::atlas::{AtlasSettings, build_atlas};
use surfsynth::kernels::lapped::coverage::{CoverageSettings, drawn_faces};
use surfsynth::kernels::lapped::mask::{TexturePatch, splotch_mask};
use surfsynth::kernels::lapped::paste::{PasteSettings, paste_until_covered};
use surfsynth::kernels::lapped::tangent_field::global_up_field;
use surfsynth::kernels::lapped::{FaceField, TriMesh};
use surfsynth::mesh::PolyMesh;
use surfsynth::progress::Progress;

fn bunny() -> PolyMesh {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("data/meshes/bunny_1k8.obj");
    surfsynth::mesh::load_mesh(&path, &Default::default())
        .expect("data/meshes/bunny_1k8.obj")
        .0
}

fn torus_knot_75k() -> PolyMesh {
    let opts = surfsynth::mesh::builtin::BuiltinOptions {
        resolution: [100, 75], // 100 · (p + q) = 500 segments along the knot, 75 around: 75 000 triangles
        ..Default::default()
    };
    surfsynth::mesh::builtin::builtin_mesh("torus_knot", &opts).expect("builtin torus_knot")
}

/// The prepared inputs of one paste loop.
struct Input {
    mesh: TriMesh,
    field: Vec<Vec3>,
    textures: Vec<TexturePatch>,
}

fn prepare(mesh: &PolyMesh) -> Input {
    let tri = TriMesh::new(mesh).expect("a triangle mesh");
    let (lo, hi) = mesh.bounding_box().expect("vertices");
    let field = global_up_field(&tri, Vec3::Y, 0.15 * (hi - lo).length());
    let exemplar = Image::new(128, 128, 3);
    let patch = TexturePatch::cut(
        &exemplar,
        Wrap::Repeat,
        [0, 0],
        &splotch_mask(128, 1),
        3.0,
        16,
        "bench",
    )
    .expect("a splotch");
    Input {
        mesh: tri,
        field,
        textures: vec![patch],
    }
}

fn bench_paste_loop(c: &mut Criterion) {
    let mut group = c.benchmark_group("lapped_paste_loop");
    group.sample_size(10);
    for (name, mesh) in [("bunny", bunny()), ("torus_knot", torus_knot_75k())] {
        let input = prepare(&mesh);
        let settings = PasteSettings {
            seed: 1,
            ..Default::default()
        };
        group.bench_with_input(
            BenchmarkId::new(name, input.mesh.face_count()),
            &input,
            |b, input| {
                b.iter(|| {
                    let field = FaceField {
                        t: &input.field,
                        isotropic: false,
                        scale: 1.0,
                    };
                    let out = paste_until_covered(
                        &input.mesh,
                        field,
                        &input.textures,
                        &settings,
                        &Progress::hidden(),
                    );
                    assert!(out.report.uncovered_faces.is_empty());
                    black_box(out)
                })
            },
        );
    }
    group.finish();
}

fn bench_outputs(c: &mut Criterion) {
    let input = prepare(&bunny());
    let field = FaceField {
        t: &input.field,
        isotropic: false,
        scale: 1.0,
    };
    let settings = PasteSettings {
        seed: 1,
        ..Default::default()
    };
    let out = paste_until_covered(
        &input.mesh,
        field,
        &input.textures,
        &settings,
        &Progress::hidden(),
    );
    let sizes: Vec<usize> = out.pastes.iter().map(|p| p.faces.len()).collect();
    let mut group = c.benchmark_group("lapped_outputs");
    group.sample_size(10);
    group.bench_function("cull_occluded/bunny", |b| {
        b.iter(|| {
            black_box(drawn_faces(
                &out.coverage,
                &sizes,
                &input.textures,
                &CoverageSettings::default(),
            ))
        })
    });
    group.bench_function("atlas_1024/bunny", |b| {
        b.iter(|| {
            black_box(build_atlas(
                &input.mesh,
                &out.coverage,
                &input.textures,
                &AtlasSettings::default(),
            ))
        })
    });
    group.finish();
}

criterion_group!(benches, bench_paste_loop, bench_outputs);
criterion_main!(benches);
