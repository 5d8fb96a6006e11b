//! One region-matching pass (Bangay & Morkel 2006 §3.3) at fixed resolution
//! on a 66 049-vertex quad grid, the setting of the paper's Table 1: the
//! donkey row has 65 858 vertices, `r_scale = 30`, `1/ē = 110`, and 3×3-texel
//! neighbourhoods, i.e. `k = 7` (113-vertex regions), one texel per about
//! 13 vertices; the paper reports 8876 s without and 752 s with
//! oversampling averaging on a 3 GHz Pentium 4.
//!
//! Here: the same geometry (a 256×256-quad grid with edge 1/110), the 128×128
//! `water.png` exemplar (Gaussian stack), every vertex already coloured by a
//! previous pass, one pass in a random order, with and without averaging;
//! plus one pass with graph-cut transfer.
//!
//! Run with `cargo bench --bench graph_match`; keep a baseline with
//! `cargo bench --bench graph_match -- --save-baseline main` and compare a
//! change with `-- --baseline main`. Needs `data/textures/water.png`
//! (falls back to the builtin `noise` exemplar when it is missing).

use criterion::{BatchSize, Criterion, criterion_group, criterion_main};
use glam::Vec3;
use rand::{SeedableRng, seq::SliceRandom};
use std::hint::black_box;
use std::time::Duration;
use surfsynth::image::{Image, sample::Wrap};
use surfsynth::kernels::bangay_morkel::graph_match::{
    BatchRule, GraphMatchSettings, ImageLevels, LevelMesh, MatchImages, SynthesisState, match_pass,
    mean_edge_lengths,
};
use surfsynth::kernels::surface::frames::TangentFrame;
use surfsynth::mesh::{PolyMesh, Topology};

/// A flat `n × n` quad grid with edge length `edge`: `(n + 1)²` vertices.
fn quad_grid(n: usize, edge: f32) -> PolyMesh {
    let positions = (0..=n)
        .flat_map(|j| (0..=n).map(move |i| Vec3::new(i as f32, j as f32, 0.0) * edge))
        .collect();
    let v = |i: usize, j: usize| (j * (n + 1) + i) as u32;
    let faces: Vec<[u32; 4]> = (0..n)
        .flat_map(|j| (0..n).map(move |i| [v(i, j), v(i + 1, j), v(i + 1, j + 1), v(i, j + 1)]))
        .collect();
    PolyMesh::from_polygons(positions, faces.iter().map(|f| f.as_slice()))
}

fn exemplar() -> Image {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("data/textures/water.png");
    surfsynth::image::load_image(&path).unwrap_or_else(|_| {
        surfsynth::image::builtin_exemplar("noise", &Default::default()).expect("builtin exemplar")
    })
}

fn bench_pass(c: &mut Criterion) {
    let mesh = quad_grid(256, 1.0 / 110.0);
    let topo = Topology::build(&mesh);
    let nv = mesh.vertex_count();
    let frames = vec![TangentFrame::from_up(Vec3::Z, Vec3::Y); nv];
    let mean_edge = mean_edge_lengths(&mesh.positions, &topo);
    let level = LevelMesh {
        positions: &mesh.positions,
        topo: &topo,
        frames: &frames,
        mean_edge: &mean_edge,
    };
    let ex = exemplar();
    let images = MatchImages::new(&ex, ImageLevels::Stack, 5, Wrap::Repeat);
    let base = GraphMatchSettings {
        r_scale: 30.0,
        region_texels: 3.0,
        k_min: 1,
        k_max: 16,
        averaging: true,
        graph_cut: false,
        cut_sigma: 0.15,
        candidates: Default::default(),
        jump_cost: 0.0,
        spread: 0.0,
        density_invariant: false,
    };
    let mut order: Vec<u32> = (0..nv as u32).collect();
    order.shuffle(&mut rand_pcg::Pcg64Mcg::seed_from_u64(1));
    // The starting state: one pass over an uncoloured grid in sweep-like
    // (row) order, so every vertex has a colour and a source texel.
    let mut start = SynthesisState::uncoloured(nv, ex.channels as usize);
    let rows: Vec<u32> = (0..nv as u32).collect();
    let stats = match_pass(
        &level,
        &images,
        &base,
        &rows,
        BatchRule::Exact,
        7,
        &mut start,
    );
    eprintln!("start state: {stats:?}");

    // Table 1's three donkey rows (r_scale 30, 100, 200 at 1/ē = 110), one
    // timed pass each, for the record: comparisons with and without
    // averaging and the wall time of each variant.
    for r_scale in [30.0f32, 100.0, 200.0] {
        for averaging in [true, false] {
            let settings = GraphMatchSettings {
                r_scale,
                averaging,
                ..base
            };
            let mut st = start.clone();
            let t = std::time::Instant::now();
            let s = match_pass(
                &level,
                &images,
                &settings,
                &order,
                BatchRule::Relaxed,
                9,
                &mut st,
            );
            eprintln!(
                "table1 r_scale {r_scale:>5}: averaging {averaging:<5} comparisons plain {:>9} averaged {:>9} | {:>7.2} s",
                s.comparisons_plain,
                s.comparisons_averaged,
                t.elapsed().as_secs_f64()
            );
        }
    }

    let mut group = c.benchmark_group("graph_match_pass_66k");
    group.sample_size(10);
    group.measurement_time(Duration::from_secs(20));
    for (label, settings) in [
        ("with_averaging", base),
        (
            "without_averaging",
            GraphMatchSettings {
                averaging: false,
                ..base
            },
        ),
        (
            "with_averaging_graph_cut",
            GraphMatchSettings {
                graph_cut: true,
                ..base
            },
        ),
    ] {
        group.bench_function(label, |b| {
            b.iter_batched(
                || start.clone(),
                |mut st| {
                    black_box(match_pass(
                        &level,
                        &images,
                        &settings,
                        &order,
                        BatchRule::Relaxed,
                        9,
                        &mut st,
                    ))
                },
                BatchSize::LargeInput,
            )
        });
    }
    group.finish();
}

criterion_group!(benches, bench_pass);
criterion_main!(benches);
