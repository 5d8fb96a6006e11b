//! One √2 subdivision step (and one adaptive pass) on meshes of about 10 k,
//! 100 k and 1 M vertices.
//!
//! Run with `cargo bench --bench subdivision`; keep a baseline with
//! `cargo bench --bench subdivision -- --save-baseline main` and compare a
//! change with `-- --baseline main`.

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use glam::Vec3;
use std::hint::black_box;
use surfsynth::kernels::bangay_morkel::sqrt2::{adaptive_sqrt2, sqrt2_subdivide};
use surfsynth::mesh::PolyMesh;

/// A flat `n × n` quad grid: `(n + 1)²` vertices.
fn quad_grid(n: usize) -> PolyMesh {
    let positions = (0..=n)
        .flat_map(|j| (0..=n).map(move |i| Vec3::new(i as f32, j as f32, 0.0)))
        .collect();
    let v = |i: usize, j: usize| (j * (n + 1) + i) as u32;
    let faces: Vec<[u32; 4]> = (0..n)
        .flat_map(|j| (0..n).map(move |i| [v(i, j), v(i + 1, j), v(i + 1, j + 1), v(i, j + 1)]))
        .collect();
    PolyMesh::from_polygons(positions, faces.iter().map(|f| f.as_slice()))
}

/// A closed quad sphere: an outward cube subdivided by √2 steps until it has
/// at least `vertices` vertices, projected onto the unit sphere.
fn sphere(vertices: usize) -> PolyMesh {
    let p: Vec<Vec3> = (0..8)
        .map(|i| {
            Vec3::new(
                if i & 1 == 0 { -1.0 } else { 1.0 },
                if i & 2 == 0 { -1.0 } else { 1.0 },
                if i & 4 == 0 { -1.0 } else { 1.0 },
            )
        })
        .collect();
    let faces: [&[u32]; 6] = [
        &[0, 2, 3, 1],
        &[4, 5, 7, 6],
        &[0, 1, 5, 4],
        &[2, 6, 7, 3],
        &[0, 4, 6, 2],
        &[1, 3, 7, 5],
    ];
    let mut m = PolyMesh::from_polygons(p, faces);
    while m.vertex_count() < vertices {
        m = sqrt2_subdivide(&m).mesh;
        for q in &mut m.positions {
            *q = q.normalize();
        }
    }
    m
}

fn bench_step(c: &mut Criterion) {
    let mut group = c.benchmark_group("sqrt2_step");
    for (label, n) in [("10k", 100), ("100k", 316), ("1M", 1000)] {
        let grid = quad_grid(n);
        group.throughput(Throughput::Elements(grid.vertex_count() as u64));
        if grid.vertex_count() > 500_000 {
            group.sample_size(10);
        }
        group.bench_with_input(BenchmarkId::new("grid", label), &grid, |b, m| {
            b.iter(|| black_box(sqrt2_subdivide(black_box(m))))
        });
    }
    for (label, v) in [("10k", 10_000), ("100k", 100_000), ("1M", 1_000_000)] {
        let s = sphere(v);
        group.throughput(Throughput::Elements(s.vertex_count() as u64));
        group.sample_size(if s.vertex_count() > 500_000 { 10 } else { 50 });
        group.bench_with_input(BenchmarkId::new("sphere", label), &s, |b, m| {
            b.iter(|| black_box(sqrt2_subdivide(black_box(m))))
        });
    }
    group.finish();
}

fn bench_adaptive(c: &mut Criterion) {
    let mut group = c.benchmark_group("adaptive_sqrt2_pass");
    group.sample_size(10);
    for (label, n) in [("100k", 316), ("1M", 1000)] {
        // Stretch one half of the grid so about half the faces are selected.
        let mut grid = quad_grid(n);
        let half = n as f32 / 2.0;
        for p in &mut grid.positions {
            if p.x > half {
                p.x = half + (p.x - half) * 4.0;
            }
        }
        group.throughput(Throughput::Elements(grid.vertex_count() as u64));
        group.bench_with_input(BenchmarkId::new("grid", label), &grid, |b, m| {
            b.iter(|| black_box(adaptive_sqrt2(black_box(m), 1.5, 1)))
        });
    }
    group.finish();
}

criterion_group!(benches, bench_step, bench_adaptive);
criterion_main!(benches);
