//! The exhaustive search of [`super::best_match`] by FFT correlation,
//! verified exactly: the same winner as scoring every candidate, in a
//! fraction of the time when a region has many terms.
//!
//! The sum at a candidate `Q` expands into correlations with the exemplar:
//!
//! `Σᵢ mᵢ |X(Q + oᵢ) − v̄ᵢ|² = Σₒ M(o) S(Q + o) − 2 Σ_c Σₒ V_c(o) X_c(Q + o) + Σᵢ mᵢ |v̄ᵢ|²`
//!
//! with `S = Σ_c X_c²`, `M(oᵢ) = mᵢ` and `V_c(oᵢ) = mᵢ v̄ᵢ_c` (per level
//! of the samples). Each correlation is one product of spectra, so every
//! candidate's sum costs `O(log N)` instead of `O(terms)`: the exemplar's
//! spectra are computed once per level (`f64`, in [`LevelSpectra`]), the
//! region's kernels are transformed two to a complex FFT, and one inverse
//! FFT gives all sums.
//!
//! Terms on levels with few of them are left out of the transforms
//! ([`levels_to_transform`]): the FFT then gives `P`, the sum of the other
//! terms, at every candidate, and since every term is non-negative `P` is a
//! lower bound of the whole sum `S`.
//!
//! The winner must be exactly the one the scalar search picks: the
//! smallest `f32` sum, computed in `score_tile`'s order, lowest
//! `y · width + x` on ties. The FFT's `F` differs from `P` by at most `E`
//! (a bound on its rounding, far above its actual error), and each `f32`
//! sum `fl(S)` from `S` by a factor of at most `1 ± γ` (`γ = n·u / (1 −
//! n·u)`, `n` the roundings in a chain, all terms non-negative). So
//! `fl(S) ≥ (1 − γ)(F − E)`, and a candidate can only beat (or tie) a
//! candidate already summed, `b`, if `F ≤ fl(S_b)/(1 − γ) + E`. Candidates
//! are summed exactly in `f32`, in increasing `F` from the smallest,
//! until the next one fails that test; the smallest sum (lowest index on
//! ties) wins. On the planar benchmark about 2.7 candidates per search are
//! summed, which costs nothing next to the FFTs.
//!
//! Correlations here are circular (period: the level's size). With
//! `Wrap::Repeat` that is how the exemplar is addressed; with
//! `Wrap::Clamp` candidates are only those whose samples all lie inside
//! (`complete_box`), where circular and clamped addressing agree. Where no
//! candidate is complete on an axis the scalar search is used.

use super::search::{BestMatch, MatchGroups, distance_at};
use super::stack::MatchImages;
use rustfft::num_complex::Complex64;
use rustfft::{Fft, FftPlanner};
use std::cell::RefCell;
use std::sync::Arc;

/// Largest level, in texels, whose spectra are computed (16 bytes a texel
/// per pair of planes, [`LevelSpectra::bytes`]): 8 MiB a level for an RGB
/// 512².
pub(super) const MAX_TEXELS: usize = 1 << 18;

/// Extra values after each column in `Scratch::columns`: a column stride
/// of a power of two (`height` values of 16 bytes) would map every column
/// to the same few cache sets.
const COLUMN_PAD: usize = 4;

/// Safety factor on the FFT's rounding bound (see [`LevelSpectra::error`]).
const FFT_SAFETY: f64 = 64.0;

/// The spectra of one level, with the plans of the level's size. The
/// planes the kernels correlate with are `S = Σ_c X_c²` (against `M`),
/// then `X_c` (against `−2 V_c`); kernels are transformed two at a time as
/// `Z = K_a + i K_b`, and with `P = DFT(X_a + i X_b) / 2` the spectrum of
/// the sum of both correlations is `T + conj(T(−k))`, `T = conj(Z) · P`,
/// whose inverse is `2 Re IDFT(T)`. So a level keeps one `P` per pair, a
/// 2-D DFT stored by rows (index `ky · width + kx`).
///
/// A 2-D DFT here transforms columns first, then rows: a kernel has only
/// a few non-zero columns (its region's width), so only those are
/// gathered and transformed, and the rows are contiguous.
#[derive(Clone)]
pub(super) struct LevelSpectra {
    width: usize,
    height: usize,
    forward_row: Arc<dyn Fft<f64>>,
    forward_col: Arc<dyn Fft<f64>>,
    inverse_row: Arc<dyn Fft<f64>>,
    inverse_col: Arc<dyn Fft<f64>>,
    /// Per pair of planes, `P`.
    pairs: Vec<Vec<Complex64>>,
    /// Per plane (`S`, then `X_c`), its L2 norm (for the error bound).
    norms: Vec<f64>,
}

impl std::fmt::Debug for LevelSpectra {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LevelSpectra")
            .field("width", &self.width)
            .field("height", &self.height)
            .field("pairs", &self.pairs.len())
            .finish()
    }
}

/// Per-thread buffers of a search.
#[derive(Default)]
struct Scratch {
    /// Live columns, each `height` values then [`COLUMN_PAD`].
    columns: Vec<Complex64>,
    /// Per column, its slot in `columns` (`u32::MAX`: none).
    slot: Vec<u32>,
    /// The live columns' `x`, in slot order.
    live: Vec<usize>,
    /// A kernel's spectrum, by rows.
    spectrum: Vec<Complex64>,
    /// `Σ T` over pairs and levels, by rows.
    sum: Vec<Complex64>,
    fft: Vec<Complex64>,
    /// Candidates left to sum exactly: partial sum, x, y.
    left: Vec<(f64, u32, u32)>,
}

thread_local! {
    static SCRATCH: RefCell<Scratch> = RefCell::new(Scratch::default());
}

fn zero() -> Complex64 {
    Complex64::new(0.0, 0.0)
}

impl LevelSpectra {
    /// The spectra of `img`'s channels and of their sum of squares.
    pub(super) fn new(img: &crate::image::Image) -> Self {
        let (width, height) = (img.width as usize, img.height as usize);
        let channels = img.channels as usize;
        let mut planner = FftPlanner::<f64>::new();
        let mut s = Self {
            width,
            height,
            forward_row: planner.plan_fft_forward(width),
            forward_col: planner.plan_fft_forward(height),
            inverse_row: planner.plan_fft_inverse(width),
            inverse_col: planner.plan_fft_inverse(height),
            pairs: Vec::with_capacity((channels + 2) / 2),
            norms: Vec::with_capacity(channels + 1),
        };
        let n = width * height;
        // The planes: S, then each channel.
        let mut planes = vec![vec![0.0f64; n]; channels + 1];
        for (i, px) in img.data.chunks_exact(channels).enumerate() {
            for (c, &v) in px.iter().enumerate() {
                planes[c + 1][i] = v as f64;
                planes[0][i] += v as f64 * v as f64;
            }
        }
        s.norms = planes
            .iter()
            .map(|p| p.iter().map(|v| v * v).sum::<f64>().sqrt())
            .collect();
        let mut scratch = Scratch::default();
        scratch.start(width);
        for x in 0..width {
            scratch.column(x, height);
        }
        for pair in planes.chunks(2) {
            for (j, &x) in scratch.live.iter().enumerate() {
                for y in 0..height {
                    let i = y * width + x;
                    let im = pair.get(1).map_or(0.0, |b| b[i] / 2.0);
                    scratch.columns[j * (height + COLUMN_PAD) + y] =
                        Complex64::new(pair[0][i] / 2.0, im);
                }
            }
            let mut p = vec![zero(); n];
            s.forward(&mut scratch, &mut p);
            s.pairs.push(p);
        }
        s
    }

    /// Bytes held by the spectra of a `width × height` level with
    /// `channels` channels.
    pub(super) fn bytes(width: usize, height: usize, channels: usize) -> u64 {
        ((channels + 2) / 2 * width * height * std::mem::size_of::<Complex64>()) as u64
    }

    /// Bytes of one thread's search buffers for `width × height` levels
    /// (the sums, a kernel's spectrum, the columns), kept by the thread.
    pub(super) fn scratch_bytes(width: usize, height: usize) -> u64 {
        (3 * width * (height + COLUMN_PAD) * std::mem::size_of::<Complex64>()) as u64
    }

    /// The 2-D DFT, by rows into `out`, of the plane whose only non-zero
    /// columns are `scratch`'s live columns. The columns are overwritten.
    fn forward(&self, scratch: &mut Scratch, out: &mut [Complex64]) {
        let (w, h) = (self.width, self.height);
        let cs = h + COLUMN_PAD;
        let len = self
            .forward_row
            .get_inplace_scratch_len()
            .max(self.forward_col.get_inplace_scratch_len());
        scratch.fft.resize(len, zero());
        for column in scratch.columns.chunks_exact_mut(cs) {
            self.forward_col
                .process_with_scratch(&mut column[..h], &mut scratch.fft);
        }
        out.fill(zero());
        for (ky, row) in out.chunks_exact_mut(w).enumerate() {
            for (j, &x) in scratch.live.iter().enumerate() {
                row[x] = scratch.columns[j * cs + ky];
            }
        }
        self.forward_row.process_with_scratch(out, &mut scratch.fft);
    }

    /// The bound `E` on `|F − S|` at any candidate for kernels of the given
    /// L1 norms (`kernels[j]` against plane `j`: `S`, then `X_c`): the
    /// rounding of an FFT of `N` values grows like `log₂ N · u` relative to
    /// the L2 norms of its input; the correlation of two planes through
    /// their spectra errs at most about `√N · log₂ N · u · |K|₁ · |X|₂` at
    /// any point. [`FFT_SAFETY`] covers the constants.
    fn error(&self, kernels: &[f64]) -> f64 {
        let n = (self.width * self.height) as f64;
        let scale = FFT_SAFETY * n.sqrt() * n.log2().max(1.0) * f64::EPSILON;
        scale
            * kernels
                .iter()
                .zip(&self.norms)
                .map(|(k, x)| k * x)
                .sum::<f64>()
    }
}

impl Scratch {
    /// No live column, for planes `width` wide.
    fn start(&mut self, width: usize) {
        self.slot.clear();
        self.slot.resize(width, u32::MAX);
        self.live.clear();
        self.columns.clear();
    }

    /// The slot of column `x`, made live (zero) if it was not.
    fn column(&mut self, x: usize, height: usize) -> usize {
        if self.slot[x] == u32::MAX {
            self.slot[x] = self.live.len() as u32;
            self.live.push(x);
            self.columns
                .resize(self.live.len() * (height + COLUMN_PAD), zero());
        }
        self.slot[x] as usize
    }
}

/// The levels whose terms the spectral search should transform, or none
/// when scoring every candidate term by term is expected to be faster.
/// `terms[l]`: the number of terms on level `l`; `candidates`: texels
/// searched; `texels`: the level's size.
///
/// Measured per search on the planar benchmark (128² exemplar, one
/// thread): tiles cost about 0.028 ns per term, channel and candidate
/// (with their pruning); the spectral search about `0.3 · N log₂ N` ns
/// per transformed level (two forward transforms) and `0.16 · N log₂ N`
/// for the inverse. A level is transformed when that is cheaper than
/// scoring its terms at every candidate; terms left out are only summed
/// at the few candidates the others do not rule out. Every choice gives
/// the same winner; this only picks the faster.
pub(super) fn levels_to_transform(
    terms: &[usize],
    channels: usize,
    candidates: usize,
    texels: usize,
) -> Vec<u32> {
    if texels > MAX_TEXELS || texels == 0 {
        return Vec::new();
    }
    let n = texels as f64;
    let nlogn = n * n.log2().max(1.0);
    let tiles = |g: usize| 0.028 * (g * channels * candidates) as f64;
    let total: usize = terms.iter().sum();
    let mut order: Vec<u32> = (0..terms.len() as u32)
        .filter(|&l| terms[l as usize] > 0)
        .collect();
    order.sort_by_key(|&l| (std::cmp::Reverse(terms[l as usize]), l));
    let mut levels = Vec::new();
    let mut transformed = 0;
    for l in order {
        let g = terms[l as usize];
        if 3 * transformed < 2 * total || tiles(g) > 0.3 * nlogn {
            levels.push(l);
            transformed += g;
        }
    }
    levels.sort_unstable();
    let cost = nlogn * (0.3 * levels.len() as f64 + 0.16);
    if levels.is_empty() || tiles(total) <= cost {
        Vec::new()
    } else {
        levels
    }
}

/// The candidate of smallest `f32` sum in `[xs, ys]` (half-open ranges of
/// level `level`), lowest `y · width + x` on ties — what the scalar search
/// returns. The terms on `transformed` levels (sorted, not empty) are
/// summed at every candidate through the spectra (`spectra(l)`); that
/// partial sum `P` bounds the whole sum from below, so candidates are then
/// summed exactly in `f32` in increasing order of `P`, until `P` rules out
/// every remaining one (see the module docs).
///
/// Preconditions: every candidate of the box reads its samples without
/// wrapping or clamping, or the images repeat.
pub(super) fn best_match<'a>(
    images: &MatchImages,
    level: usize,
    groups: &MatchGroups,
    region: [(usize, usize); 2],
    transformed: &[u32],
    spectra: impl Fn(usize) -> &'a LevelSpectra,
) -> Option<BestMatch> {
    #[cfg(target_arch = "x86_64")]
    {
        if std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma") {
            // SAFETY: the processor supports AVX2 and FMA (checked just
            // above). Fused products only change the FFT sums, which are
            // bounded, never the f32 sums that pick the winner.
            return unsafe { best_match_avx2(images, level, groups, region, transformed, spectra) };
        }
    }
    best_match_generic(images, level, groups, region, transformed, spectra)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn best_match_avx2<'a>(
    images: &MatchImages,
    level: usize,
    groups: &MatchGroups,
    region: [(usize, usize); 2],
    transformed: &[u32],
    spectra: impl Fn(usize) -> &'a LevelSpectra,
) -> Option<BestMatch> {
    best_match_generic(images, level, groups, region, transformed, spectra)
}

#[inline(always)]
fn best_match_generic<'a>(
    images: &MatchImages,
    level: usize,
    groups: &MatchGroups,
    [xs, ys]: [(usize, usize); 2],
    transformed: &[u32],
    spectra: impl Fn(usize) -> &'a LevelSpectra,
) -> Option<BestMatch> {
    let ch = groups.channels();
    let w = images.planes(level).width;
    SCRATCH.with_borrow_mut(|scratch| {
        let first = spectra(transformed[0] as usize);
        let (fw, fh) = (first.width, first.height);
        let n = fw * fh;
        scratch.sum.clear();
        scratch.sum.resize(n, zero());
        let mut spectrum = std::mem::take(&mut scratch.spectrum);
        spectrum.resize(n, zero());
        let mut bound = 0.0f64;
        let mut constant = 0.0f64;
        for &l in transformed {
            let sp = spectra(l as usize);
            debug_assert_eq!((sp.width, sp.height), (fw, fh), "levels of one size");
            // Kernel j against plane j: M against S, then −2 V_c against X_c.
            let mut l1 = vec![0.0f64; ch + 1];
            for (pair, p) in sp.pairs.iter().enumerate() {
                let (a, b) = (2 * pair, 2 * pair + 1);
                scratch.start(fw);
                for (g, s) in groups.samples().iter().enumerate() {
                    if s.level != l {
                        continue;
                    }
                    let m = groups.weight()[g] as f64;
                    let colour = &groups.colour()[g * ch..(g + 1) * ch];
                    let value = |k: usize| match k {
                        0 => m,
                        k if k <= ch => -2.0 * m * colour[k - 1] as f64,
                        _ => 0.0,
                    };
                    let x = s.offset[0].rem_euclid(fw as i32) as usize;
                    let y = s.offset[1].rem_euclid(fh as i32) as usize;
                    let (re, im) = (value(a), value(b));
                    let j = scratch.column(x, fh);
                    scratch.columns[j * (fh + COLUMN_PAD) + y] += Complex64::new(re, im);
                    l1[a] += re.abs();
                    if b <= ch {
                        l1[b] += im.abs();
                    }
                    if pair == 0 {
                        constant += m * colour.iter().map(|&v| v as f64 * v as f64).sum::<f64>();
                    }
                }
                sp.forward(scratch, &mut spectrum);
                for ((t, z), p) in scratch.sum.iter_mut().zip(&spectrum).zip(p) {
                    *t += z.conj() * p;
                }
            }
            bound += sp.error(&l1);
        }
        bound += 1e-12 * constant;
        scratch.spectrum = spectrum;
        // Inverse: rows, then the columns of candidates.
        let len = first
            .inverse_row
            .get_inplace_scratch_len()
            .max(first.inverse_col.get_inplace_scratch_len());
        scratch.fft.resize(len, zero());
        first
            .inverse_row
            .process_with_scratch(&mut scratch.sum, &mut scratch.fft);
        let cols = xs.1 - xs.0;
        let cs = fh + COLUMN_PAD;
        scratch.columns.clear();
        scratch.columns.resize(cols * cs, zero());
        for y in 0..fh {
            let row = &scratch.sum[y * fw + xs.0..y * fw + xs.1];
            for (j, &v) in row.iter().enumerate() {
                scratch.columns[j * cs + y] = v;
            }
        }
        for column in scratch.columns.chunks_exact_mut(cs) {
            first
                .inverse_col
                .process_with_scratch(&mut column[..fh], &mut scratch.fft);
        }
        // The partial sums P (± bound) of column j (x = xs.0 + j) at the
        // candidate rows.
        let scale = 2.0 / n as f64;
        let columns = &scratch.columns;
        let partial = |j: usize| {
            columns[j * cs + ys.0..j * cs + ys.1]
                .iter()
                .map(move |z| z.re * scale + constant)
        };
        // Roundings per f32 sum: per term a difference, a square, the
        // channel sum, the weight and the running sum; all terms ≥ 0, so
        // fl(S) ≥ (1 − γ) S ≥ (1 − γ) P ≥ (1 − γ)(F − bound).
        let chain = (groups.len() + 2 * ch + 8) as f64;
        let u = f32::EPSILON as f64 / 2.0;
        let shrink = 1.0 - chain * u / (1.0 - chain * u);
        let exact = |x: usize, y: usize| (distance_at(images, groups, x, y), (y * w + x) as u32);
        let better = |a: (f32, u32), b: (f32, u32)| a.0 < b.0 || a.0 == b.0 && a.1 < b.1;
        // The candidate of smallest F first: its exact sum sets the first
        // threshold.
        let mut low = (f64::INFINITY, 0, 0);
        for j in 0..cols {
            for (i, f) in partial(j).enumerate() {
                if f < low.0 {
                    low = (f, xs.0 + j, ys.0 + i);
                }
            }
        }
        let mut best = exact(low.1, low.2);
        let threshold = |best: (f32, u32)| best.0 as f64 / shrink + bound;
        let t0 = threshold(best);
        let mut left = std::mem::take(&mut scratch.left);
        left.clear();
        for j in 0..cols {
            for (i, f) in partial(j).enumerate() {
                if f <= t0 {
                    left.push((f, (xs.0 + j) as u32, (ys.0 + i) as u32));
                }
            }
        }
        left.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
        for &(f, x, y) in &left {
            if f > threshold(best) {
                break;
            }
            let e = exact(x as usize, y as usize);
            if better(e, best) {
                best = e;
            }
        }
        scratch.left = left;
        Some(BestMatch {
            x: best.1 % w as u32,
            y: best.1 / w as u32,
            distance: best.0,
        })
    })
}
