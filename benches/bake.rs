//! The `bake` stage's kernels at 2048² on a ~37 k-vertex mesh (a builtin
//! torus of 272 × 136 = 36 992 vertices, 73 984 triangles):
//! - `atlas/torus37k`: charts, LSCM flattening, packing;
//! - `vertex_colours/torus37k`: baking vertex colours of a different
//!   tessellation of the same torus (256 × 128, 32 768 vertices): one
//!   closest-point query per texel plus barycentric interpolation;
//! - `jump_uvs/torus37k`: baking per-corner UVs with the 3-way blend (three
//!   exemplar look-ups per texel).
//!
//! Rasterisation and dilation (padding 4) are included in both bakes.
//!
//! Run: `cargo bench --bench bake`.

use criterion::{Criterion, criterion_group, criterion_main};
use glam::Vec2;
use std::hint::black_box;
use surfsynth::image::Image;
use surfsynth::image::sample::Wrap;
use surfsynth::kernels::atlas::bake::{
    AtlasFrames, BakeTarget, BlendUvSource, VertexColourSource, bake_channels,
};
use surfsynth::kernels::atlas::{AtlasSettings, build_uv_atlas, rasterise_faces};
use surfsynth::kernels::wei_levoy::retile::SurfaceProjector;
use surfsynth::mesh::PolyMesh;
use surfsynth::mesh::builtin::{BuiltinOptions, builtin_mesh};

fn torus(u: u32, v: u32) -> PolyMesh {
    let opts = BuiltinOptions {
        resolution: [u, v],
        ..Default::default()
    };
    builtin_mesh("torus", &opts)
        .expect("builtin torus")
        .triangulated()
}

fn tris(m: &PolyMesh) -> Vec<[u32; 3]> {
    m.faces().map(|f| [f[0], f[1], f[2]]).collect()
}

fn bench(c: &mut Criterion) {
    let size = 2048u32;
    let mesh = torus(272, 136);
    let t = tris(&mesh);
    eprintln!(
        "torus: {} vertices, {} triangles",
        mesh.vertex_count(),
        t.len()
    );
    let settings = AtlasSettings {
        size,
        padding_px: 4,
        ..Default::default()
    };
    let mut group = c.benchmark_group("bake");
    group.sample_size(10);
    group.bench_function("atlas/torus37k", |b| {
        b.iter(|| black_box(build_uv_atlas(&mesh.positions, &t, &settings).unwrap()))
    });
    let atlas = build_uv_atlas(&mesh.positions, &t, &settings).unwrap();
    eprintln!(
        "atlas: {} charts, fill {:.2}",
        atlas.charts.count, atlas.fill
    );
    let texel_face = rasterise_faces(&atlas.corner_uvs, size);
    let frames = AtlasFrames::new(&mesh.positions, &t, &atlas.corner_uvs);
    let target = BakeTarget {
        corner_uvs: &atlas.corner_uvs,
        texel_face: &texel_face,
        size,
        padding_px: 4,
    };
    let exemplar: Image = surfsynth::image::builtin_exemplar(
        "bricks",
        &surfsynth::image::ExemplarOptions {
            size: 128,
            ..Default::default()
        },
    )
    .expect("builtin bricks");

    let result = torus(256, 128);
    let rt = tris(&result);
    let colours: Vec<f32> = result
        .positions
        .iter()
        .flat_map(|p| [p.x.fract().abs(), p.y.fract().abs(), p.z.fract().abs()])
        .collect();
    let projector = SurfaceProjector::new(&result);
    group.bench_function("vertex_colours/torus37k", |b| {
        b.iter(|| {
            let src = VertexColourSource {
                positions: &mesh.positions,
                tris: &t,
                frames: &frames,
                projector: &projector,
                result_tris: &rt,
                colours: &colours,
                channels: 3,
                source_uv: None,
                frame_s: None,
            };
            black_box(bake_channels(
                &target,
                &src,
                &[&exemplar],
                Wrap::Repeat,
                &[],
            ))
        })
    });

    // Three slightly different UV layers per triangle, as the jump-map blend.
    let layers: Vec<[[Vec2; 3]; 3]> = t
        .iter()
        .map(|tri| {
            let uv = tri.map(|v| {
                let p = mesh.positions[v as usize];
                Vec2::new(p.x * 0.7 + p.z * 0.3, p.y * 0.9)
            });
            [
                uv,
                uv.map(|q| q + Vec2::new(0.13, 0.0)),
                uv.map(|q| q + Vec2::new(0.0, 0.29)),
            ]
        })
        .collect();
    group.bench_function("jump_uvs/torus37k", |b| {
        b.iter(|| {
            let src = BlendUvSource::new(&mesh.positions, &t, &frames, &layers);
            black_box(bake_channels(
                &target,
                &src,
                &[&exemplar],
                Wrap::Repeat,
                &[],
            ))
        })
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
