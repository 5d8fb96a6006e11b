//! Roofline of the hot kernels (issue 42, part 1): each kernel's achieved
//! rate beside the machine's limit for its kind of work, GFLOP/s against
//! faer's sgemm or GB/s against memory bandwidth, on one thread.
//!
//! First the ceilings, measured here: faer f32 matrix products (`Par::Seq`)
//! square and at the shapes the kernels use, f32 multiply-add throughput in
//! registers and a dot product in L1 (AVX-512 and AVX2 when the processor
//! has them, and the `wide::f32x8` loop as the crate is compiled: baseline
//! x86-64, SSE2, no FMA), and memory bandwidth (a 64 MiB copy, a 3 × 32 MiB
//! triad, a 128 KiB copy in L2). Then each kernel on a realistic small
//! input: the shared 128² `stones.png`, a 256² result quilted from it
//! (32² blocks at seeded offsets), fixed seeds.
//!
//! Counting: a FLOP count is 2 per value compared per candidate (one
//! multiply-add: what the dense-product form `|p|² − 2 q·p` performs, and
//! what sgemm's rate counts), analytic, not counted in the code. Where a
//! kernel prunes (partial-distance exits, lower bounds) the count is that
//! of the exhaustive search it replaces ("equivalent"), so its rate can
//! exceed the ceiling; where the work done is known it is given as well
//! ("actual"). Bytes are the kernel's data read or written once (a lower
//! bound of its traffic). Times are the fastest of repeated calls: the
//! machine is shared, and other work only ever adds time.
//!
//! Everything runs in a one-thread rayon pool. Run with
//! `cargo bench --bench roofline` (about 35 s after the build); the table
//! and what it says are in `docs/notes/roofline.md`.

use std::hint::black_box;
use std::path::Path;
use std::time::{Duration, Instant};

use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, MatMut, MatRef, Par};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;
use wide::f32x8;

use surfsynth::image::pyramid::gaussian_pyramid;
use surfsynth::image::sample::Wrap;
use surfsynth::image::{Image, load_image};
use surfsynth::kernels::bangay_morkel::graph_match::{
    ImageLevels, MatchGroups, MatchImages, Sample, Search, best_match_by,
};
use surfsynth::kernels::bangay_morkel::max_flow::FlowGraph;

#[path = "common/transfer_patch.rs"]
mod transfer;
use surfsynth::kernels::coherent::appearance::{AppearanceSpec, appearance_level};
use surfsynth::kernels::jump_maps::jump_map::ann::{AnnSearch, POINT_TILE, all_knn};
use surfsynth::kernels::jump_maps::jump_map::neighbourhoods::{
    Neighbourhoods, source_region, vector_len, wrap_for,
};
use surfsynth::kernels::jump_maps::jump_map::{JumpMapSettings, pca};
use surfsynth::kernels::metrics::quality::{completeness, completeness_queries};
use surfsynth::kernels::metrics::window_index::{AXES, BOX_AXES, LEAF, WindowIndex};
use surfsynth::kernels::metrics::{ExemplarNeighbourhoods, QueryScratch};
use surfsynth::kernels::wei_levoy::wl_match::features::{FeatureMatrix, exemplar_features};
use surfsynth::kernels::wei_levoy::wl_match::search::pca_kdtree::{fit, project};
use surfsynth::kernels::wei_levoy::wl_match::search::{Match, SearchKind, build_search};
use surfsynth::kernels::wei_levoy::wl_match::{PAPER_NEIGHBOURHOODS, neighbourhood_parts};
use transfer::transfer_patch;

/// Time each measurement is repeated for (after one warm-up call).
const BUDGET: Duration = Duration::from_millis(1500);

/// The fastest of repeated calls of `f`: one warm-up call, then calls until
/// `budget` has passed (at least 3, at most 10 000).
fn fastest<R>(budget: Duration, mut f: impl FnMut() -> R) -> Duration {
    black_box(f());
    let start = Instant::now();
    let mut best = Duration::MAX;
    let mut calls = 0;
    while calls < 3 || (start.elapsed() < budget && calls < 10_000) {
        let t = Instant::now();
        black_box(f());
        best = best.min(t.elapsed());
        calls += 1;
    }
    best
}

/// A machine limit: its name and rate (GFLOP/s or GB/s).
#[derive(Clone, Copy)]
struct Ceiling {
    name: &'static str,
    rate: f64,
}

/// One row of the kernel table.
struct Row {
    kernel: &'static str,
    /// `compute` or `memory`.
    kind: &'static str,
    /// What one call does, in words.
    call: String,
    /// FLOPs or bytes of one call, as counted (see the module docs).
    work: f64,
    /// Other work figures shown beside it (e.g. "actual ≥ …").
    extra: String,
    time: Duration,
    ceiling: Ceiling,
    limit: &'static str,
}

impl Row {
    fn unit(&self) -> (&'static str, &'static str) {
        match self.kind {
            "memory" => ("B", "GB/s"),
            _ => ("FLOP", "GFLOP/s"),
        }
    }

    fn achieved(&self) -> f64 {
        self.work / self.time.as_secs_f64() / 1e9
    }
}

/// `x` with an SI prefix (k, M, G, T) and `unit`.
fn si(x: f64, unit: &str) -> String {
    let (v, p) = if x >= 1e12 {
        (x / 1e12, "T")
    } else if x >= 1e9 {
        (x / 1e9, "G")
    } else if x >= 1e6 {
        (x / 1e6, "M")
    } else if x >= 1e3 {
        (x / 1e3, "k")
    } else {
        (x, "")
    };
    format!("{v:.3} {p}{unit}")
}

fn ms(d: Duration) -> String {
    let s = d.as_secs_f64();
    if s >= 0.1 {
        format!("{:.0} ms", s * 1e3)
    } else if s >= 1e-3 {
        format!("{:.2} ms", s * 1e3)
    } else {
        format!("{:.1} µs", s * 1e6)
    }
}

fn stones() -> Image {
    load_image(&Path::new(env!("CARGO_MANIFEST_DIR")).join("data/textures/stones.png"))
        .expect("the shared data/textures/stones.png")
}

/// A 256² result quilted from `ex`: 8 × 8 blocks of 32² copied from
/// seeded offsets (what a patch-based synthesis gives, seams included).
fn quilted(ex: &Image) -> Image {
    let mut rng = Pcg64::seed_from_u64(42);
    let mut out = Image::new(256, 256, ex.channels);
    for by in 0..8u32 {
        for bx in 0..8u32 {
            let (sx, sy) = (
                rng.random_range(0..=ex.width - 32),
                rng.random_range(0..=ex.height - 32),
            );
            for y in 0..32 {
                for x in 0..32 {
                    out.pixel_mut(bx * 32 + x, by * 32 + y)
                        .copy_from_slice(ex.pixel(sx + x, sy + y));
                }
            }
        }
    }
    out
}

/// `n`×`n` windows of `img` wholly inside it at `count` seeded positions,
/// one after another (rows of `n · channels`).
fn windows(img: &Image, n: u32, count: usize, seed: u64) -> Vec<f32> {
    let mut rng = Pcg64::seed_from_u64(seed);
    let ch = img.channels as usize;
    let mut out = Vec::with_capacity(count * (n * n) as usize * ch);
    for _ in 0..count {
        let (x, y) = (
            rng.random_range(0..=img.width - n),
            rng.random_range(0..=img.height - n),
        );
        for dy in 0..n {
            let o = img.offset(x, y + dy);
            out.extend_from_slice(&img.data[o..o + n as usize * ch]);
        }
    }
    out
}

// ---------------------------------------------------------------- ceilings

/// GFLOP/s of faer's f32 product `lhs (m × k, row-major) · rhs (n × k,
/// row-major)ᵀ` on this thread: the layout of the kernels' products.
fn sgemm_rate(m: usize, k: usize, n: usize, repeat: usize) -> f64 {
    let lhs: Vec<f32> = (0..m * k).map(|i| (i % 17) as f32 * 0.01).collect();
    let rhs: Vec<f32> = (0..n * k).map(|i| (i % 13) as f32 * 0.01).collect();
    let mut dst = vec![0.0f32; m * n];
    let t = fastest(BUDGET, || {
        for _ in 0..repeat {
            let a = MatRef::from_row_major_slice(&lhs, m, k);
            let b = MatRef::from_row_major_slice(&rhs, n, k);
            let c = MatMut::from_row_major_slice_mut(&mut dst, m, n);
            matmul(c, Accum::Replace, a, b.transpose(), 1.0f32, Par::Seq);
            surfsynth::kernels::simd_state::after_faer();
        }
        dst[0]
    });
    (2 * m * k * n * repeat) as f64 / t.as_secs_f64() / 1e9
}

/// GFLOP/s of a square faer product (column-major, as faer prefers).
fn sgemm_square(n: usize) -> f64 {
    let a = Mat::<f32>::from_fn(n, n, |i, j| ((i * 7 + j * 13) % 17) as f32 * 0.01);
    let b = Mat::<f32>::from_fn(n, n, |i, j| ((i * 5 + j * 3) % 11) as f32 * 0.01);
    let mut c = Mat::<f32>::zeros(n, n);
    let t = fastest(BUDGET, || {
        matmul(
            c.as_mut(),
            Accum::Replace,
            a.as_ref(),
            b.as_ref(),
            1.0f32,
            Par::Seq,
        );
        surfsynth::kernels::simd_state::after_faer();
        c[(0, 0)]
    });
    (2 * n * n * n) as f64 / t.as_secs_f64() / 1e9
}

#[cfg(target_arch = "x86_64")]
mod x86 {
    use std::arch::x86_64::*;

    /// `iters` rounds of 16 independent 16-lane multiply-adds in registers.
    #[target_feature(enable = "avx512f")]
    pub fn fma_avx512(iters: usize) -> f32 {
        let (a, b) = (_mm512_set1_ps(0.999_9), _mm512_set1_ps(1.0e-4));
        let (a, b) = (std::hint::black_box(a), std::hint::black_box(b));
        let mut acc = std::hint::black_box([_mm512_setzero_ps(); 16]);
        for _ in 0..std::hint::black_box(iters) {
            for x in acc.iter_mut() {
                *x = _mm512_fmadd_ps(*x, a, b);
            }
        }
        let s = acc
            .iter()
            .fold(_mm512_setzero_ps(), |s, &x| _mm512_add_ps(s, x));
        _mm512_reduce_add_ps(s)
    }

    /// `iters` rounds of 16 independent 8-lane multiply-adds in registers.
    #[target_feature(enable = "avx2,fma")]
    pub fn fma_avx2(iters: usize) -> f32 {
        let (a, b) = (_mm256_set1_ps(0.999_9), _mm256_set1_ps(1.0e-4));
        let (a, b) = (std::hint::black_box(a), std::hint::black_box(b));
        let mut acc = std::hint::black_box([_mm256_setzero_ps(); 16]);
        for _ in 0..std::hint::black_box(iters) {
            for x in acc.iter_mut() {
                *x = _mm256_fmadd_ps(*x, a, b);
            }
        }
        let s = acc
            .iter()
            .fold(_mm256_setzero_ps(), |s, &x| _mm256_add_ps(s, x));
        let mut out = [0.0f32; 8];
        // SAFETY: `out` holds 8 floats.
        unsafe { _mm256_storeu_ps(out.as_mut_ptr(), s) };
        out.iter().sum()
    }

    /// Dot product of `a` and `b` (lengths a multiple of 128), eight
    /// 16-lane accumulators.
    #[target_feature(enable = "avx512f")]
    pub fn dot_avx512(a: &[f32], b: &[f32]) -> f32 {
        let mut acc = [_mm512_setzero_ps(); 8];
        for (ca, cb) in a.chunks_exact(128).zip(b.chunks_exact(128)) {
            for (k, x) in acc.iter_mut().enumerate() {
                // SAFETY: each chunk holds 128 floats, so 16 from 16·k.
                let (va, vb) = unsafe {
                    (
                        _mm512_loadu_ps(ca.as_ptr().add(16 * k)),
                        _mm512_loadu_ps(cb.as_ptr().add(16 * k)),
                    )
                };
                *x = _mm512_fmadd_ps(va, vb, *x);
            }
        }
        let s = acc
            .iter()
            .fold(_mm512_setzero_ps(), |s, &x| _mm512_add_ps(s, x));
        _mm512_reduce_add_ps(s)
    }
}

/// The `wide::f32x8` sum of squared differences as the crate compiles it
/// (no target features: two SSE halves, multiply then add), four
/// accumulators: the inner loop of the metrics' direct searches.
fn ssd_wide(a: &[f32], b: &[f32]) -> f32 {
    let mut acc = [f32x8::ZERO; 4];
    for (ca, cb) in a.chunks_exact(32).zip(b.chunks_exact(32)) {
        for (k, x) in acc.iter_mut().enumerate() {
            let va = f32x8::new(ca[8 * k..8 * k + 8].try_into().expect("8"));
            let vb = f32x8::new(cb[8 * k..8 * k + 8].try_into().expect("8"));
            let d = va - vb;
            *x += d * d;
        }
    }
    (acc[0] + acc[1] + acc[2] + acc[3]).reduce_add()
}

/// The ceilings, named; printed as the first table.
struct Ceilings {
    sgemm: Ceiling,
    sgemm_wl: Ceiling,
    sgemm_ann: Ceiling,
    sgemm_project: Ceiling,
    ssd_wide: Ceiling,
    dram: Ceiling,
    l2: Ceiling,
    table: Vec<CeilingRow>,
}

/// A row of the ceilings table: name, shape, rate, unit.
type CeilingRow = (String, String, f64, &'static str);

fn ceilings(ann_dim: usize, wl_dim: usize, app_dim: usize, app_dims: usize) -> Ceilings {
    let mut table = Vec::new();
    let mut add = |name: String, shape: String, rate: f64, unit: &'static str| {
        eprintln!("ceiling {name} {shape}: {rate:.1} {unit}");
        table.push((name, shape, rate, unit));
        rate
    };
    let square = add(
        "sgemm (faer, Par::Seq)".into(),
        "1024 × 1024 · 1024 × 1024".into(),
        sgemm_square(1024),
        "GFLOP/s",
    );
    let wl = add(
        "sgemm, Wei–Levoy exhaustive's shape".into(),
        format!("64 × {wl_dim} · {wl_dim} × 1024"),
        sgemm_rate(64, wl_dim, 1024, 16),
        "GFLOP/s",
    );
    let ann = add(
        "sgemm, jump-map all-kNN's shape".into(),
        format!("256 × {ann_dim} · {ann_dim} × {POINT_TILE}"),
        sgemm_rate(256, ann_dim, POINT_TILE, 16),
        "GFLOP/s",
    );
    let proj = add(
        "sgemm, appearance projection as a product".into(),
        format!("256 × {app_dim} · {app_dim} × {app_dims}"),
        sgemm_rate(256, app_dim, app_dims, 64),
        "GFLOP/s",
    );
    #[cfg(target_arch = "x86_64")]
    {
        let iters = 1 << 20;
        if std::is_x86_feature_detected!("avx512f") {
            let t = fastest(BUDGET, || {
                // SAFETY: AVX-512F is present (checked above).
                unsafe { x86::fma_avx512(iters) }
            });
            add(
                "f32 FMA in registers, AVX-512".into(),
                "16 independent chains".into(),
                (iters * 16 * 16 * 2) as f64 / t.as_secs_f64() / 1e9,
                "GFLOP/s",
            );
            let (a, b) = (vec![0.5f32; 4096], vec![0.25f32; 4096]);
            let t = fastest(BUDGET, || {
                let mut s = 0.0;
                for _ in 0..256 {
                    // SAFETY: AVX-512F is present (checked above).
                    s += unsafe { x86::dot_avx512(black_box(&a), black_box(&b)) };
                }
                s
            });
            add(
                "f32 dot product in L1, AVX-512".into(),
                "2 × 16 KiB".into(),
                (256 * 4096 * 2) as f64 / t.as_secs_f64() / 1e9,
                "GFLOP/s",
            );
        }
        if std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma") {
            let t = fastest(BUDGET, || {
                // SAFETY: AVX2 and FMA are present (checked above).
                unsafe { x86::fma_avx2(iters) }
            });
            add(
                "f32 FMA in registers, AVX2".into(),
                "16 independent chains".into(),
                (iters * 16 * 8 * 2) as f64 / t.as_secs_f64() / 1e9,
                "GFLOP/s",
            );
        }
    }
    let (a, b) = (vec![0.5f32; 4096], vec![0.25f32; 4096]);
    let t = fastest(BUDGET, || {
        let mut s = 0.0;
        for _ in 0..256 {
            s += ssd_wide(black_box(&a), black_box(&b));
        }
        s
    });
    let ssd = add(
        "f32 squared differences in L1, `wide::f32x8` as built".into(),
        "2 × 16 KiB (2 FLOP counted per value)".into(),
        (256 * 4096 * 2) as f64 / t.as_secs_f64() / 1e9,
        "GFLOP/s",
    );
    // Memory: beyond the 32 MiB L3.
    let n = 16 << 20; // floats: 64 MiB
    let src = vec![1.0f32; n];
    let mut dst = vec![0.0f32; n];
    let t = fastest(BUDGET, || {
        dst.copy_from_slice(black_box(&src));
        dst[n / 2]
    });
    add(
        "memory copy".into(),
        "64 MiB → 64 MiB".into(),
        (2 * 4 * n) as f64 / t.as_secs_f64() / 1e9,
        "GB/s",
    );
    drop((src, dst));
    let n = 8 << 20; // floats: 32 MiB each
    let (b, c) = (vec![1.0f32; n], vec![2.0f32; n]);
    let mut a = vec![0.0f32; n];
    let t = fastest(BUDGET, || {
        for ((x, y), z) in a.iter_mut().zip(black_box(&b)).zip(black_box(&c)) {
            *x = y + 3.0 * z;
        }
        a[n / 2]
    });
    let dram = add(
        "memory triad a = b + s·c".into(),
        "3 × 32 MiB (write-allocate not counted)".into(),
        (3 * 4 * n) as f64 / t.as_secs_f64() / 1e9,
        "GB/s",
    );
    drop((a, b, c));
    let n = 32 << 10; // floats: 128 KiB
    let src = vec![1.0f32; n];
    let mut dst = vec![0.0f32; n];
    let t = fastest(BUDGET, || {
        for _ in 0..64 {
            dst.copy_from_slice(black_box(&src));
            black_box(&mut dst);
        }
        dst[n / 2]
    });
    let l2 = add(
        "copy in L2".into(),
        "128 KiB → 128 KiB".into(),
        (64 * 2 * 4 * n) as f64 / t.as_secs_f64() / 1e9,
        "GB/s",
    );
    let c = |name, rate| Ceiling { name, rate };
    Ceilings {
        sgemm: c("sgemm 1024²", square),
        sgemm_wl: c("sgemm at its shape", wl),
        sgemm_ann: c("sgemm at its shape", ann),
        sgemm_project: c("sgemm at its shape", proj),
        ssd_wide: c("f32x8 as built", ssd),
        dram: c("DRAM triad", dram),
        l2: c("L2 copy", l2),
        table,
    }
}

// ----------------------------------------------------------------- kernels

/// The jump-map analysis' points: the stones' neighbourhood vectors over
/// the source region projected on their PCA (default settings), and the
/// settings.
fn jump_map_points(ex: &Image) -> (Vec<f32>, usize, JumpMapSettings) {
    let s = JumpMapSettings::default();
    let widths = &s.neighbourhood_widths;
    let region = source_region(ex.width, ex.height, widths, s.boundary).expect("region");
    let pyramid = gaussian_pyramid(ex, widths.len(), wrap_for(s.boundary));
    let hoods = Neighbourhoods::new(&pyramid, widths, wrap_for(s.boundary));
    let dim = vector_len(widths, ex.channels);
    let n = (region.width() * region.height()) as usize;
    let rows = pca::sample_rows(n, s.pca_sample_fraction, s.seed);
    let fitted = pca::fit_sample(
        &hoods.pixels(region, &rows),
        dim,
        s.pca_variance,
        s.max_components as usize,
    )
    .expect("PCA");
    let points = fitted.project(&hoods.rows(region, 0, n));
    (points, fitted.components, s)
}

/// The Wei–Levoy database of the finest level (7×7 on level 0 plus 5×5 on
/// level 1, RGB) over the whole exemplar, and `nq` queries: its rows with
/// a little seeded noise.
fn wei_levoy_data(ex: &Image, nq: usize) -> (FeatureMatrix, Vec<f32>) {
    let pyramid = gaussian_pyramid(ex, 4, Wrap::Repeat);
    let parts = neighbourhood_parts(PAPER_NEIGHBOURHOODS[3], 4);
    let db = exemplar_features(&pyramid, 0, &parts, Wrap::Repeat);
    let mut rng = Pcg64::seed_from_u64(7);
    let (rows, dim) = (db.rows(), db.dim);
    let mut queries = Vec::with_capacity(nq * dim);
    for _ in 0..nq {
        let r = rng.random_range(0..rows);
        queries.extend(db.row(r).iter().map(|v| v + rng.random_range(-0.05..0.05)));
    }
    (db, queries)
}

/// The coherent stage's appearance rows at its defaults (window 5, spacing
/// one pixel, 8 components) over every pixel of `ex`: the 5×5 windows,
/// toroidal, Gaussian-weighted as the analysis weights them.
fn appearance_rows(ex: &Image) -> FeatureMatrix {
    let (w, h, ch) = (ex.width as i64, ex.height as i64, ex.channels as usize);
    let weight = |d: i64| (-(d * d) as f32 / 8.0).exp();
    let mut data = Vec::with_capacity((w * h) as usize * 25 * ch);
    for y in 0..h {
        for x in 0..w {
            for dy in -2..=2i64 {
                for dx in -2..=2i64 {
                    let p = ex.texel(x + dx, y + dy, Wrap::Repeat);
                    data.extend(p.iter().map(|v| v * weight(dx) * weight(dy)));
                }
            }
        }
    }
    FeatureMatrix { dim: 25 * ch, data }
}

/// A lower bound of the full window distances the completeness index
/// computes, from a model of its pruning: the same principal axes (the
/// covariance of the same evenly spaced sample of at most 4096 windows,
/// eigen-decomposed in `f64`), and for each query the windows whose
/// projected distance is below the exact minimum (`best`): those it can
/// never skip, whatever order it visits them in. Returns their number.
fn index_full_distances_at_least(output: &Image, n: usize, queries: &[f32], best: &[f32]) -> u64 {
    let (w, h, ch) = (
        output.width as usize,
        output.height as usize,
        output.channels as usize,
    );
    let dim = n * n * ch;
    let window = |x: usize, y: usize, out: &mut Vec<f32>| {
        out.clear();
        for r in 0..n {
            let o = output.offset(x as u32, (y + r) as u32);
            out.extend_from_slice(&output.data[o..o + n * ch]);
        }
    };
    let origins: Vec<(usize, usize)> = (0..=h - n)
        .flat_map(|y| (0..=w - n).map(move |x| (x, y)))
        .collect();
    let step = origins.len().div_ceil(4096).max(1);
    let sample: Vec<(usize, usize)> = origins.iter().step_by(step).copied().collect();
    let mut buf = Vec::new();
    let mut rows = Mat::<f64>::zeros(sample.len(), dim);
    for (i, &(x, y)) in sample.iter().enumerate() {
        window(x, y, &mut buf);
        for (j, &v) in buf.iter().enumerate() {
            rows[(i, j)] = f64::from(v);
        }
    }
    let m = sample.len() as f64;
    for j in 0..dim {
        let mean = (0..sample.len()).map(|i| rows[(i, j)]).sum::<f64>() / m;
        for i in 0..sample.len() {
            rows[(i, j)] -= mean;
        }
    }
    let mut cov = Mat::<f64>::zeros(dim, dim);
    matmul(
        cov.as_mut(),
        Accum::Replace,
        rows.transpose(),
        rows.as_ref(),
        1.0 / m,
        Par::Seq,
    );
    let eigen = cov.self_adjoint_eigen(faer::Side::Lower).expect("eigen");
    surfsynth::kernels::simd_state::after_faer();
    let axes = AXES.min(dim);
    let u = eigen.U();
    let basis = Mat::<f32>::from_fn(dim, axes, |j, a| u[(j, dim - 1 - a)] as f32);
    let mut windows = Mat::<f32>::zeros(origins.len(), dim);
    for (i, &(x, y)) in origins.iter().enumerate() {
        window(x, y, &mut buf);
        for (j, &v) in buf.iter().enumerate() {
            windows[(i, j)] = v;
        }
    }
    let nq = queries.len() / dim;
    let qm = Mat::<f32>::from_fn(nq, dim, |i, j| queries[i * dim + j]);
    let mut pw = Mat::<f32>::zeros(origins.len(), axes);
    let mut pq = Mat::<f32>::zeros(nq, axes);
    matmul(
        pw.as_mut(),
        Accum::Replace,
        windows.as_ref(),
        basis.as_ref(),
        1.0,
        Par::Seq,
    );
    matmul(
        pq.as_mut(),
        Accum::Replace,
        qm.as_ref(),
        basis.as_ref(),
        1.0,
        Par::Seq,
    );
    surfsynth::kernels::simd_state::after_faer();
    let pw: Vec<[f32; 16]> = (0..origins.len())
        .map(|i| std::array::from_fn(|a| if a < axes { pw[(i, a)] } else { 0.0 }))
        .collect();
    let mut count = 0u64;
    for (q, &b) in best.iter().enumerate() {
        let p: [f32; 16] = std::array::from_fn(|a| if a < axes { pq[(q, a)] } else { 0.0 });
        // Below the exact minimum less a margin for rounding: surely computed.
        let limit = b * (1.0 - 1.0e-3) - 1.0e-4;
        count += pw
            .iter()
            .filter(|v| {
                v.iter()
                    .zip(&p)
                    .map(|(x, y)| (x - y) * (x - y))
                    .sum::<f32>()
                    < limit
            })
            .count() as u64;
    }
    count
}

fn kernels(ex: &Image) -> (Vec<CeilingRow>, Vec<Row>, Vec<String>) {
    let mut notes = Vec::new();
    // Inputs first: the ceilings are measured at the kernels' shapes.
    let (points, components, jm) = jump_map_points(ex);
    let (db, wl_queries) = wei_levoy_data(ex, 1024);
    let app = appearance_rows(ex);
    let app_dims = 8usize;
    let cl = ceilings(components + 1, db.dim + 1, app.dim, app_dims);
    let mut rows = Vec::new();

    // Jump-map all-kNN, exhaustive.
    let np = points.len() / components;
    let m = (jm.jumps_per_pixel * jm.candidate_factor + 1) as usize;
    let t = fastest(BUDGET, || {
        all_knn(
            &points,
            components,
            m,
            jm.ann_epsilon,
            AnnSearch::Exhaustive,
        )
    });
    rows.push(Row {
        kernel: "jump-map all-kNN, exhaustive (`ann.rs`)",
        kind: "compute",
        call: format!("{np} points × {np}, {components} PCA dims, k = {m}"),
        work: 2.0 * (np * np * (components + 1)) as f64,
        extra: String::new(),
        time: t,
        ceiling: cl.sgemm_ann,
        limit: "faer products of 256 × 256 tiles, then a scan of every score",
    });

    // Wei–Levoy exhaustive.
    let (wl_rows, wl_dim) = (db.rows(), db.dim);
    let nq = wl_queries.len() / wl_dim;
    let exhaustive = build_search(SearchKind::Exhaustive, db.clone(), 0);
    let mut out = vec![
        Match {
            index: 0,
            distance: 0.0
        };
        nq
    ];
    let t = fastest(BUDGET, || exhaustive.search(&wl_queries, &mut out));
    rows.push(Row {
        kernel: "Wei–Levoy exhaustive search",
        kind: "compute",
        call: format!("{nq} queries × {wl_rows} rows, {wl_dim} values"),
        work: 2.0 * (nq * wl_rows * (wl_dim + 1)) as f64,
        extra: String::new(),
        time: t,
        ceiling: cl.sgemm_wl,
        limit: "faer products of 64 × 1024 tiles; the keep-4 scan and re-rank",
    });
    drop(exhaustive);

    // Wei–Levoy PCA + kd-tree: the queries; the build reported apart.
    let kind = SearchKind::PcaKdTree {
        dims: 8,
        candidates: 16,
    };
    let tb = fastest(BUDGET, || build_search(kind, db.clone(), 0));
    let kd = build_search(kind, db.clone(), 0);
    let t = fastest(BUDGET, || kd.search(&wl_queries, &mut out));
    let actual = (nq * (2 * 8 * wl_dim + 16 * 2 * wl_dim)) as f64;
    rows.push(Row {
        kernel: "Wei–Levoy PCA + kd-tree search (8 dims, 16 candidates)",
        kind: "compute",
        call: format!("{nq} queries, approximate"),
        work: actual,
        extra: format!(
            "equivalent exhaustive {}",
            si(2.0 * (nq * wl_rows * (wl_dim + 1)) as f64, "FLOP")
        ),
        time: t,
        ceiling: cl.sgemm,
        limit: "kd-tree descent (branches, dependent loads), not arithmetic",
    });
    notes.push(format!(
        "Wei–Levoy PCA + kd-tree build (SVD of 4096 rows, projection, tree): {}",
        ms(tb)
    ));
    drop(kd);

    // Metrics: the exhaustive nearest-window search (texture energy).
    let result = quilted(ex);
    let n = 7u32;
    let dim = (n * n * ex.channels) as usize;
    let hoods = ExemplarNeighbourhoods::new(ex, n);
    let energy_queries = windows(&result, n, 256, 3);
    let mut scratch = QueryScratch::default();
    let t = fastest(BUDGET, || {
        energy_queries
            .chunks_exact(dim)
            .map(|q| hoods.nearest_sq_distance(q, None, &mut scratch))
            .sum::<f32>()
    });
    let positions = (ex.width * ex.height) as usize;
    rows.push(Row {
        kernel: "metrics: exhaustive nearest window (`nearest.rs`, energy)",
        kind: "compute",
        call: format!("256 result windows × {positions} exemplar windows, {dim} values"),
        work: 2.0 * (256 * positions * dim) as f64,
        extra: format!(
            "equivalent (partial-distance exits skip some); {:.0} % of the as-built f32x8 rate",
            100.0 * 2.0 * (256 * positions * dim) as f64 / t.as_secs_f64() / 1e9 / cl.ssd_wide.rate
        ),
        time: t,
        ceiling: cl.sgemm,
        limit: "`wide::f32x8` built for baseline x86-64: SSE halves, no FMA; 2 loads per 2 FLOP",
    });

    // Metrics: completeness of the 256² result through the window index.
    let cq = completeness_queries(ex, n as usize);
    let ncq = cq.len() / dim;
    let windows_in = (256 - n as usize + 1) * (256 - n as usize + 1);
    let t = fastest(BUDGET, || completeness(&result, ex, n));
    let tb = fastest(BUDGET, || {
        WindowIndex::interior(&result, n, 0..256 - n as usize + 1)
    });
    let index = WindowIndex::interior(&result, n, 0..256 - n as usize + 1);
    let mut s = Default::default();
    let best: Vec<f32> = cq
        .chunks_exact(dim)
        .map(|q| index.nearest_sq_distance(q, &mut s))
        .collect();
    let computed = index_full_distances_at_least(&result, n as usize, &cq, &best);
    let axes = AXES.min(dim);
    // Leaves of the index: median halves until at most LEAF windows.
    fn leaves(n: usize) -> usize {
        if n <= LEAF {
            1
        } else {
            leaves(n / 2) + leaves(n - n / 2)
        }
    }
    // Build: covariance of ≤ 4096 windows (f64), every window projected;
    // queries: projected, the distance to every leaf's box (3 FLOP an
    // axis), then at least `computed` full distances.
    let build = 2.0 * (4096 * dim * dim) as f64 + 2.0 * (windows_in * axes * dim) as f64;
    let query = 2.0 * (ncq * axes * dim) as f64
        + 3.0 * (ncq * leaves(windows_in) * BOX_AXES) as f64
        + 2.0 * computed as f64 * dim as f64;
    let equivalent = 2.0 * (ncq * windows_in * dim) as f64;
    rows.push(Row {
        kernel: "metrics: completeness via `WindowIndex` (exact)",
        kind: "compute",
        call: format!("{ncq} exemplar windows × {windows_in} result windows, {dim} values"),
        work: equivalent,
        extra: format!(
            "equivalent; actual ≥ {} ({:.1} GFLOP/s): build {} + queries {}",
            si(build + query, "FLOP"),
            (build + query) / t.as_secs_f64() / 1e9,
            si(build, "FLOP"),
            si(query, "FLOP"),
        ),
        time: t,
        ceiling: cl.sgemm,
        limit: "build (PCA, projections, splits) then per query a few leaves: branchy, latency-bound",
    });
    notes.push(format!(
        "completeness: index build alone {} of {}, so {:.1} µs a query; {} leaves; full window distances per query ≥ {:.1} of {windows_in} (a model of its pruning)",
        ms(tb),
        ms(t),
        (t.saturating_sub(tb)).as_secs_f64() * 1e6 / ncq as f64,
        leaves(windows_in),
        computed as f64 / ncq as f64
    ));

    // Bangay–Morkel best_match: 16 targets, radius-8 diamond regions on
    // level 0 of a clamped stack, one seed texel near each target.
    let images = MatchImages::new(
        ex,
        ImageLevels::Stack,
        MatchImages::default_levels(ex),
        Wrap::Clamp,
    );
    let r = 8i32;
    let mut rng = Pcg64::seed_from_u64(11);
    let targets: Vec<(MatchGroups, [i32; 2])> = (0..16)
        .map(|_| {
            let (x, y) = (rng.random_range(r..128 - r), rng.random_range(r..128 - r));
            let mut samples = Vec::new();
            let mut colours = Vec::new();
            for dy in -r..=r {
                for dx in -r..=r {
                    if dx.abs() + dy.abs() > r {
                        continue;
                    }
                    samples.push(Sample {
                        level: 0,
                        offset: images.reduce_offset(0, [dx, dy]),
                    });
                    let p = ex.pixel((x + dx) as u32, (y + dy) as u32);
                    colours.extend(p.iter().map(|v| v + rng.random_range(-0.03..0.03)));
                }
            }
            let mut g = MatchGroups::new();
            g.build(&samples, &colours, ex.channels as usize, true);
            (g, [x + 3, y - 2])
        })
        .collect();
    let terms = targets[0].0.len();
    let candidates = (128 - 2 * r as usize) * (128 - 2 * r as usize);
    let search = |how: Search| {
        fastest(BUDGET, || {
            targets
                .iter()
                .filter_map(|(g, seed)| best_match_by(&images, 0, g, &[*seed], false, how))
                .map(|b| b.distance)
                .sum::<f32>()
        })
    };
    let work = 2.0 * (16 * candidates * terms * ex.channels as usize) as f64;
    let call = format!(
        "16 regions × {candidates} candidates, {terms} terms × {} channels",
        ex.channels
    );
    rows.push(Row {
        kernel: "Bangay–Morkel `best_match`, tiles (exhaustive, pruned)",
        kind: "compute",
        call: call.clone(),
        work,
        extra: "equivalent (tiles dropped once past the bound)".into(),
        time: search(Search::Tiles),
        ceiling: cl.sgemm,
        limit: "32-candidate tiles with AVX2, a bound test after every term",
    });
    rows.push(Row {
        kernel: "Bangay–Morkel `best_match`, as run (FFT search for these regions)",
        kind: "compute",
        call,
        work,
        extra: "equivalent (the same winners, by FFT correlation verified exactly)".into(),
        time: search(Search::Auto),
        ceiling: cl.sgemm,
        limit: "f64 FFTs of the 128² level: two forward per level, one inverse",
    });

    // Coherent appearance projection (pca_kdtree::project).
    let (mean, basis) = fit(&app, app_dims, 0);
    let npx = app.rows();
    let t = fastest(BUDGET, || {
        app.data
            .chunks_exact(app.dim)
            .map(|row| project(row, &mean, &basis, app_dims)[0])
            .sum::<f32>()
    });
    let spec = AppearanceSpec {
        window: 5,
        spacing: 1.0,
        dims: app_dims,
        k: 4,
        seed: 0,
        wrap: Wrap::Repeat,
    };
    let ta = fastest(BUDGET, || appearance_level(ex, &spec));
    notes.push(format!(
        "coherent appearance analysis of level 0 (`appearance_level`: bilinear windows, fit, projection, k-coherence sets), defaults: {}",
        ms(ta)
    ));
    rows.push(Row {
        kernel: "coherent appearance projection (`pca_kdtree::project`)",
        kind: "compute",
        call: format!("{npx} pixels × {} values → {app_dims}", app.dim),
        work: 2.0 * (npx * app.dim * app_dims) as f64,
        extra: String::new(),
        time: t,
        ceiling: cl.sgemm_project,
        limit: "one row at a time, scalar-order sums across 8 components (baseline SSE)",
    });

    // Max-flow on the §3.4 transfer graph of a 33 × 33 neighbourhood.
    let graph = transfer_patch(33, 42);
    let (nodes, edges) = (graph.num_nodes(), 2 * 33 * 32);
    // Input edges (ends 8 B, capacities 16 B), terminal capacities (16 B a
    // node); the residual graph it builds: two 16-byte arcs per edge, per
    // node a 16-byte tree record, its t-link residual (8 B) and first arc
    // (4 B).
    let bytes = (edges * (24 + 32) + nodes * (16 + 16 + 8 + 4)) as f64;
    let copies = 64;
    let mut batch: Vec<FlowGraph> = Vec::new();
    let mut best = Duration::MAX;
    let start = Instant::now();
    while start.elapsed() < BUDGET || best == Duration::MAX {
        batch.clear();
        batch.extend((0..copies).map(|_| graph.clone()));
        let t0 = Instant::now();
        for g in &mut batch {
            black_box(g.max_flow());
        }
        best = best.min(t0.elapsed() / copies as u32);
    }
    rows.push(Row {
        kernel: "Boykov–Kolmogorov max-flow (§3.4 transfer graph)",
        kind: "memory",
        call: format!("{nodes} nodes, {edges} edges (33 × 33)"),
        work: bytes,
        extra: format!(
            "{:.0} % of the L2 copy rate; working set fits L2",
            100.0 * bytes / best.as_secs_f64() / 1e9 / cl.l2.rate
        ),
        time: best,
        ceiling: cl.dram,
        limit: "pointer chasing over the search trees (latency), not bandwidth",
    });
    (cl.table, rows, notes)
}

fn main() {
    surfsynth::progress::set_enabled(false);
    let started = Instant::now();
    let ex = stones();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("a one-thread pool");
    let (ceilings, rows, notes) = pool.install(|| kernels(&ex));

    println!("\n## Ceilings (one thread)\n");
    println!("| ceiling | shape | rate |");
    println!("|---|---|---|");
    for (name, shape, rate, unit) in &ceilings {
        println!("| {name} | {shape} | {rate:.1} {unit} |");
    }
    println!("\n## Kernels (one thread)\n");
    println!(
        "| kernel | kind | work per call | time | achieved | ceiling | % of ceiling | what limits it |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for r in &rows {
        let (unit, rate) = r.unit();
        let extra = if r.extra.is_empty() {
            String::new()
        } else {
            format!("; {}", r.extra)
        };
        println!(
            "| {} | {} | {}: {}{} | {} | {:.1} {rate} | {:.1} {rate} ({}) | {:.0} % | {} |",
            r.kernel,
            r.kind,
            r.call,
            si(r.work, unit),
            extra,
            ms(r.time),
            r.achieved(),
            r.ceiling.rate,
            r.ceiling.name,
            100.0 * r.achieved() / r.ceiling.rate,
            r.limit,
        );
    }
    println!();
    for n in &notes {
        println!("- {n}");
    }
    println!("\nwhole bench: {:.0} s", started.elapsed().as_secs_f64());
}
