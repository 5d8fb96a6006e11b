//! Exact k nearest neighbours in 8 dimensions (`kernels/knn.rs`), the
//! candidate search of Wei–Levoy's `pca_kdtree` and of coherent's
//! k-coherence sets: 16,384 points (a 128² exemplar's pixels) whose
//! coordinates spread like the leading principal components of texture
//! neighbourhoods (standard deviation `1 / (1 + axis)`), queried by 4,096
//! points near them (a data point plus noise of a tenth of its spread, as
//! a synthesised neighbourhood is near an exemplar one) for their 16
//! nearest, and by every point for its 9 nearest (the k-coherence sets).
//!
//! Run: `cargo bench --bench knn`.

use criterion::{Criterion, criterion_group, criterion_main};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;
use std::hint::black_box;
use surfsynth::kernels::knn::{Knn, KnnScratch};

const POINTS: usize = 16_384;

fn gaussian(rng: &mut Pcg64) -> f32 {
    // Sum of four uniforms: close enough to a normal for a spread.
    (0..4).map(|_| rng.random::<f32>() - 0.5).sum::<f32>() * 1.7
}

fn points(rng: &mut Pcg64, n: usize) -> Vec<[f32; 8]> {
    (0..n)
        .map(|_| std::array::from_fn(|a| gaussian(rng) / (1.0 + a as f32)))
        .collect()
}

fn bench_knn(c: &mut Criterion) {
    let mut rng = Pcg64::seed_from_u64(7);
    let data = points(&mut rng, POINTS);
    let index = Knn::new(&data);
    let queries: Vec<[f32; 8]> = (0..4096)
        .map(|_| {
            let p = data[rng.random_range(0..POINTS)];
            std::array::from_fn(|a| p[a] + 0.1 * gaussian(&mut rng) / (1.0 + a as f32))
        })
        .collect();
    let mut group = c.benchmark_group("knn");
    group.sample_size(20);
    group.bench_function("near_queries_k16", |b| {
        let mut scratch = KnnScratch::default();
        b.iter(|| {
            let mut sum = 0.0f32;
            for q in &queries {
                sum += index.nearest(q, 16, &mut scratch)[15].0;
            }
            black_box(sum)
        })
    });
    group.bench_function("all_points_k9", |b| {
        let mut scratch = KnnScratch::default();
        b.iter(|| {
            let mut sum = 0.0f32;
            for q in &data {
                sum += index.nearest(q, 9, &mut scratch)[8].0;
            }
            black_box(sum)
        })
    });
    group.bench_function("build", |b| b.iter(|| black_box(Knn::new(&data))));
    group.finish();
}

criterion_group!(benches, bench_knn);
criterion_main!(benches);
