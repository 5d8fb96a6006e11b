//! Boykov–Kolmogorov max-flow on texture-seam-like 4-connected grid graphs.
//!
//! Each n-link is weighted like a Kwatra et al. 2003 seam, the colour
//! mismatch of the two overlapping patches at both ends,
//! `M(s, t) = |A(s) − B(s)| + |A(t) − B(t)|`, with a per-pixel mismatch made
//! of a smooth low-frequency term plus the noise of random RGB values
//! (seeded). The left column is tied to the source and the right column to
//! the sink with infinite weight (Bangay & Morkel 2006 §3.4 tie vertices to
//! the terminals the same way). Two shapes:
//!
//! * `square/N`: a `side × side` grid (10^4 and ~10^5 nodes), the worst case
//!   for BK: augmenting paths cross the whole grid;
//! * `band/N`: a 32-pixel-wide overlap band of ~10^5 nodes, the usual shape
//!   of a seam between two patches;
//! * `patch/N`: the per-vertex graph of Bangay & Morkel §3.4 (Fig. 9, eq. 1)
//!   on a 33 × 33 texel neighbourhood: the centre tied to the texture
//!   terminal (source) and the border ring to the surface terminal (sink),
//!   n-links `M(A, B) · exp(−(x_A² + x_B²) / (σ r²))` with σ = 1, r = 33;
//! * `segmentation/N`: a 317 × 317 grid with t-links on every node (the data
//!   term of a noisy two-level image) and contrast-weighted n-links, the
//!   usual vision benchmark shape, where augmenting paths are short.
//!
//! The square seam is BK's hard case, not a defect of this implementation:
//! Kolmogorov's own maxflow v3 (the C++ code behind PyMaxflow 1.3.2), fed
//! the same graph (same weight distribution, double capacities), took
//! 30 s for `square/100489` and 5.3 s for `band/100000` on the machine and
//! load where this kernel took a few seconds; both solve `segmentation`
//! in well under a tenth of a second.
//!
//! Only `max_flow` is timed; graphs are built and cloned outside the loop.
//!
//! Run: `cargo bench --bench max_flow`. Baseline workflow:
//! `cargo bench --bench max_flow -- --save-baseline main`, then after a
//! change `cargo bench --bench max_flow -- --baseline main`.

use criterion::{BatchSize, BenchmarkId, Criterion, criterion_group, criterion_main};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;
use std::hint::black_box;
use surfsynth::kernels::bangay_morkel::max_flow::FlowGraph;

#[path = "common/transfer_patch.rs"]
mod transfer;
use transfer::transfer_patch;

/// The seam graph of a `width × height` grid (node `y * width + x`),
/// seeded; the terminals are tied to columns 0 and `width - 1`.
fn seam_grid(width: u32, height: u32, seed: u64) -> FlowGraph {
    let mut rng = Pcg64::seed_from_u64(seed);
    let n = (width * height) as usize;
    let mismatch: Vec<f64> = (0..n as u32)
        .map(|p| {
            let (x, y) = (f64::from(p % width), f64::from(p / width));
            let smooth = 0.5 + 0.5 * (x * 0.05).sin() * (y * 0.07).cos();
            let noise: f64 = (0..3)
                .map(|_| (rng.random::<f64>() - rng.random::<f64>()).abs())
                .sum();
            smooth + noise
        })
        .collect();
    let mut g = FlowGraph::with_capacity(n, 2 * n);
    for y in 0..height {
        for x in 0..width {
            let v = y * width + x;
            if x + 1 < width {
                let c = mismatch[v as usize] + mismatch[v as usize + 1];
                g.add_edge(v, v + 1, c, c);
            }
            if y + 1 < height {
                let c = mismatch[v as usize] + mismatch[(v + width) as usize];
                g.add_edge(v, v + width, c, c);
            }
        }
        g.add_terminal_weights(y * width, f64::INFINITY, 0.0);
        g.add_terminal_weights(y * width + width - 1, 0.0, f64::INFINITY);
    }
    g
}

/// A vision-style segmentation grid (`side × side`), seeded: t-links on
/// every node from a noisy two-level image, contrast-weighted n-links.
fn segmentation_grid(side: u32, seed: u64) -> FlowGraph {
    let mut rng = Pcg64::seed_from_u64(seed);
    let n = (side * side) as usize;
    let image: Vec<f64> = (0..n as u32)
        .map(|p| {
            let (x, y) = (f64::from(p % side), f64::from(p / side));
            let blob = (0.5 + 0.5 * (x * 0.11).sin() * (y * 0.13).cos() > 0.5) as u8;
            (0.3 + 0.4 * f64::from(blob) + rng.random_range(-0.25..0.25)).clamp(0.0, 1.0)
        })
        .collect();
    let mut g = FlowGraph::with_capacity(n, 2 * n);
    for y in 0..side {
        for x in 0..side {
            let v = y * side + x;
            let i = image[v as usize];
            g.add_terminal_weights(v, 10.0 * (i - 0.3).powi(2), 10.0 * (i - 0.7).powi(2));
            for u in [
                (x + 1 < side).then_some(v + 1),
                (y + 1 < side).then_some(v + side),
            ]
            .into_iter()
            .flatten()
            {
                let d = i - image[u as usize];
                let c = 2.0 * (-d * d / 0.02).exp();
                g.add_edge(v, u, c, c);
            }
        }
    }
    g
}

fn bench_segmentation(c: &mut Criterion) {
    let graph = segmentation_grid(317, 42);
    let mut group = c.benchmark_group("max_flow_bk");
    group.sample_size(10);
    group.bench_with_input(
        BenchmarkId::new("segmentation", graph.num_nodes()),
        &graph,
        |b, graph| {
            b.iter_batched(
                || graph.clone(),
                |mut g| black_box(g.max_flow()),
                BatchSize::LargeInput,
            )
        },
    );
    group.finish();
}

fn bench_patch(c: &mut Criterion) {
    let graph = transfer_patch(33, 42);
    c.bench_with_input(
        BenchmarkId::new("max_flow_bk/patch", graph.num_nodes()),
        &graph,
        |b, graph| {
            b.iter_batched(
                || graph.clone(),
                |mut g| black_box(g.max_flow()),
                BatchSize::SmallInput,
            )
        },
    );
}

fn bench_grids(c: &mut Criterion) {
    let mut group = c.benchmark_group("max_flow_bk");
    group.sample_size(10);
    for (shape, width, height) in [
        ("square", 100u32, 100u32),
        ("square", 317, 317),
        ("band", 32, 3125),
    ] {
        let graph = seam_grid(width, height, 42);
        group.bench_with_input(
            BenchmarkId::new(shape, width * height),
            &graph,
            |b, graph| {
                b.iter_batched(
                    || graph.clone(),
                    |mut g| black_box(g.max_flow()),
                    BatchSize::LargeInput,
                )
            },
        );
    }
    group.finish();
}

criterion_group!(benches, bench_patch, bench_segmentation, bench_grids);
criterion_main!(benches);
