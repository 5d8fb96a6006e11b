//! Jump maps (Zelinka & Garland 2004): analysis of a 128² exemplar, image
//! synthesis throughput at 256² and 1024², and surface synthesis throughput
//! at about 10 k, 100 k and 1 M vertices (procedural tori).
//!
//! `cargo bench --bench jump_map`

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use std::path::Path;
use surfsynth::image::load_image;
use surfsynth::kernels::jump_maps::jump_map::{
    Boundary, JumpMapSettings, PixelOrder, PixelSynthesisSettings, analyse, synthesize_sources,
};
use surfsynth::kernels::jump_maps::jump_surface::{
    SurfaceSynthSettings, corner_side_offsets, corner_uvs, edge_offsets, synthesize_surface,
};
use surfsynth::kernels::surface::frames::frames_from_global_direction;
use surfsynth::mesh::Topology;
use surfsynth::mesh::builtin::{BuiltinOptions, builtin_mesh};

fn stones() -> surfsynth::image::Image {
    load_image(&Path::new(env!("CARGO_MANIFEST_DIR")).join("data/textures/stones.png"))
        .expect("shared stones texture")
}

fn jump_maps(c: &mut Criterion) {
    surfsynth::progress::set_enabled(false);
    let ex = stones();
    let settings = JumpMapSettings::default();
    let mut g = c.benchmark_group("jump_map/analysis");
    g.sample_size(10);
    g.bench_function("stones_128", |b| {
        b.iter(|| analyse(&ex, &settings).unwrap())
    });
    g.finish();

    let map = analyse(&ex, &settings).unwrap();
    let mut g = c.benchmark_group("jump_map/image_pixels");
    for side in [256u32, 1024] {
        g.throughput(Throughput::Elements(side as u64 * side as u64));
        let s = PixelSynthesisSettings {
            width: side,
            height: side,
            order: PixelOrder::Hilbert,
            ..Default::default()
        };
        g.bench_with_input(BenchmarkId::from_parameter(side), &s, |b, s| {
            b.iter(|| synthesize_sources(&map, s).unwrap())
        });
    }
    g.finish();

    let mut g = c.benchmark_group("jump_map/surface_vertices");
    g.sample_size(10);
    for (n, res) in [
        (10_000usize, [125u32, 80]),
        (100_000, [400, 250]),
        (1_000_000, [1250, 800]),
    ] {
        let mesh = builtin_mesh(
            "torus",
            &BuiltinOptions {
                resolution: res,
                ..Default::default()
            },
        )
        .unwrap();
        let frames = frames_from_global_direction(&mesh.vertex_normals(), glam::Vec3::Z);
        let scale = vec![2.0 / mesh.average_edge_length(); mesh.vertex_count()];
        let topo = Topology::build(&mesh);
        let offsets = edge_offsets(&mesh.positions, &frames, &scale, &topo);
        let s = SurfaceSynthSettings {
            tileable: map.boundary() == Boundary::Toroidal,
            ..Default::default()
        };
        g.throughput(Throughput::Elements(mesh.vertex_count() as u64));
        g.bench_function(BenchmarkId::new("synthesis_pass", n), |b| {
            b.iter(|| synthesize_surface(&topo, &offsets, &map, &s, &Default::default()))
        });
        g.bench_function(BenchmarkId::new("offsets_synthesis_corner_uvs", n), |b| {
            b.iter(|| {
                let offsets = edge_offsets(&mesh.positions, &frames, &scale, &topo);
                let out = synthesize_surface(&topo, &offsets, &map, &s, &Default::default());
                let sides = corner_side_offsets(&mesh, &topo, &offsets);
                corner_uvs(&mesh, sides, &out.texel, (map.width(), map.height()))
            })
        });
    }
    g.finish();
}

criterion_group!(benches, jump_maps);
criterion_main!(benches);
