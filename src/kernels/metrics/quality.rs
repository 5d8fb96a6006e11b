//! Image quality measures that see the failures texture energy forgives:
//! completeness (missing exemplar content), sharpness (blur), structure
//! (orientation and scale), verbatim copying (tiling, repetition); and
//! [`image_quality`], every measure of one result image at once.
//!
//! Each measure is a pure function of the images (and the source map), so
//! it is the same for our methods and for the peer.

use rayon::prelude::*;

use super::energy::{ExemplarWindows, image_texture_energy_in};
use super::window_index::{BandedIndex, WindowIndex};
use super::{EnergySettings, histogram_wasserstein_mean, image_texture_energy};
use crate::image::pyramid::gaussian_pyramid;
use crate::image::{Image, sample::Wrap};

/// Stride in exemplar pixels between the exemplar windows whose nearest
/// output window [`completeness`] looks for (the issue asks for ≤ 2).
pub const COMPLETENESS_STRIDE: u32 = 2;

/// Most exemplar windows [`completeness`] compares: beyond this the windows
/// at stride [`COMPLETENESS_STRIDE`] are thinned evenly (every k-th), which
/// keeps the mean unbiased and the cost at most this many exhaustive
/// searches of the result (exemplars up to 128² are measured exactly).
pub const COMPLETENESS_MAX_WINDOWS: usize = 4096;

/// The origins of the exemplar windows completeness compares: stride
/// [`COMPLETENESS_STRIDE`], wholly inside, thinned evenly to at most
/// [`COMPLETENESS_MAX_WINDOWS`].
pub fn completeness_windows(width: u32, height: u32, n: u32) -> Vec<(usize, usize)> {
    let (w, h, n) = (width as usize, height as usize, n as usize);
    if n > w || n > h {
        return Vec::new();
    }
    let stride = COMPLETENESS_STRIDE as usize;
    let all: Vec<(usize, usize)> = (0..=h - n)
        .step_by(stride)
        .flat_map(|y| (0..=w - n).step_by(stride).map(move |x| (x, y)))
        .collect();
    let step = all.len().div_ceil(COMPLETENESS_MAX_WINDOWS).max(1);
    all.into_iter().step_by(step).collect()
}

/// Orientation bins of [`structure_features`] over 180° (22.5° each).
pub const STRUCTURE_ORIENTATIONS: usize = 8;

/// Largest number of scales (pyramid levels) of [`structure_features`].
pub const STRUCTURE_SCALES: usize = 4;

/// Where each pixel of a result came from in the exemplar.
#[derive(Clone, Debug, PartialEq)]
pub struct SourceMap {
    /// Size of the result (pixels).
    pub width: u32,
    pub height: u32,
    /// Per result pixel, row-major: level-0 exemplar pixel coordinates
    /// (x, y), pixel centres at `index + 0.5`; NaN where the source is unknown.
    pub texels: Vec<[f32; 2]>,
}

/// Verbatim-copy statistics of a result with known source coordinates
/// ([`verbatim_copying`]).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct VerbatimStats {
    /// Fraction of exemplar pixels that are the source of at least one result
    /// pixel, in `[0, 1]`. Low when the result repeats a small part of the
    /// exemplar (tiling of one block, a few patches pasted over and over).
    pub source_coverage: f32,
    /// Pixel-weighted mean area of the copied regions (the expected area of
    /// the region a random result pixel lies in), in result pixels. A copied
    /// region is a 4-connected set of result pixels whose sources follow one
    /// constant offset (neighbours' sources one pixel apart in the same
    /// direction, within half a pixel; toroidally).
    pub mean_region_area: f32,
    /// [`Self::mean_region_area`] over the exemplar's area (unitless).
    pub mean_region_fraction: f32,
    /// Area of the largest copied region, in result pixels.
    pub largest_region: u32,
    /// The most times any exemplar pixel is copied by copied regions larger
    /// than a third of the exemplar (counting result pixels, so a region that
    /// wraps around the exemplar repeats it within itself): above 1, a large
    /// piece of the exemplar is repeated verbatim that many times.
    pub large_region_repeats: u32,
}

/// Every quality measure of one result image against its exemplar.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct ImageQuality {
    /// Texture energy (Kwatra et al. 2005): mean over sampled result windows
    /// of the squared distance to the nearest exemplar window, per value
    /// (MSE in `[0, 1]²` units). Sees garbage; rewards blur and flat colour.
    pub coherence_mean: f32,
    /// 90th percentile of the same: sees seams and local garbage.
    pub coherence_p90: f32,
    /// [`completeness`] (same units as coherence): sees missing content.
    pub completeness: f32,
    /// [`sharpness`] (ratio, 1 = as sharp as the exemplar): sees blur.
    pub sharpness: f32,
    /// [`structure_distance`] (in `[0, 1]`): sees wrong orientation or scale.
    pub structure: f32,
    /// Mean over channels of the per-channel Wasserstein-1 distance (value
    /// units, `[0, 1]`): sees colour drift and washed-out contrast.
    pub histogram: f32,
    /// [`verbatim_copying`] when the source coordinates are known.
    pub verbatim: Option<VerbatimStats>,
}

/// Every measure of `output` against `exemplar`: coherence (mean, p90) and
/// completeness with `settings.neighbourhood`-sized windows, coherence over
/// `settings.samples` result pixels drawn with `settings.seed`; sharpness,
/// structure, histogram; verbatim copying when `sources` is given.
///
/// The result is not assumed to tile: its windows are taken inside it
/// (coherence addresses pixels beyond the border by clamping). Deterministic
/// for any number of threads.
///
/// Preconditions: both images have the same channel count and are at least
/// `settings.neighbourhood` pixels wide and high; `sources` (if any) has the
/// output's size.
pub fn image_quality(
    output: &Image,
    exemplar: &Image,
    sources: Option<&SourceMap>,
    settings: &EnergySettings,
) -> ImageQuality {
    image_quality_in(output, exemplar, None, sources, settings)
}

/// [`image_quality`], its texture energy against `windows` when given (the
/// exemplar's windows already indexed, [`ExemplarWindows`]: of `exemplar`
/// or of an image with its values, at `settings.neighbourhood`).
pub fn image_quality_in(
    output: &Image,
    exemplar: &Image,
    windows: Option<&ExemplarWindows>,
    sources: Option<&SourceMap>,
    settings: &EnergySettings,
) -> ImageQuality {
    // Each measure in a span of its own (`--trace`).
    fn timed<T>(span: tracing::Span, f: impl FnOnce() -> T) -> T {
        let _s = span.entered();
        f()
    }
    use tracing::debug_span as span;
    let coherence = timed(span!("image_energy"), || match windows {
        Some(w) => image_texture_energy_in(output, w, settings, Wrap::Clamp),
        None => image_texture_energy(output, exemplar, settings, Wrap::Clamp),
    });
    ImageQuality {
        coherence_mean: coherence.mean,
        coherence_p90: coherence.p90,
        completeness: timed(span!("image_completeness"), || {
            completeness(output, exemplar, settings.neighbourhood)
        }),
        sharpness: timed(span!("image_sharpness"), || sharpness(output, exemplar)),
        structure: timed(span!("image_structure"), || {
            structure_distance(output, exemplar)
        }),
        histogram: timed(span!("image_histogram"), || {
            histogram_wasserstein_mean(output, exemplar)
        }),
        verbatim: timed(span!("image_verbatim"), || {
            sources.map(|s| verbatim_copying(s, exemplar.width, exemplar.height))
        }),
    }
}

/// Completeness, the other half of bidirectional similarity (Simakov et al.
/// 2008): the mean, over the exemplar's `n`×`n` windows at a stride of
/// [`COMPLETENESS_STRIDE`] pixels (windows wholly inside the exemplar; at
/// most [`COMPLETENESS_MAX_WINDOWS`], see [`completeness_windows`]), of the
/// squared distance to the nearest `n`×`n` window wholly inside `output`,
/// divided by `n² · channels` (the units of the texture energy).
///
/// High when the exemplar's content is missing from the result: blur, flat
/// or washed-out colour, one patch repeated. Exact nearest-window search
/// ([`WindowIndex`]), parallel over exemplar windows; deterministic.
///
/// Preconditions: same channel count; `n` odd and no larger than either
/// image.
pub fn completeness(output: &Image, exemplar: &Image, n: u32) -> f32 {
    assert_eq!(output.channels, exemplar.channels, "channel counts differ");
    let (n, ch) = (n as usize, exemplar.channels as usize);
    let columns = output.width as usize - n + 1;
    let search = BandedIndex::new(output.height as usize - n + 1, columns, |rows| {
        WindowIndex::interior(output, n as u32, rows)
    });
    let dim = n * n * ch;
    mean_per_value(
        &search.nearest(&completeness_queries(exemplar, n), dim),
        dim,
    )
}

/// The mean of squared distances between windows of `dim` values, per
/// value (completeness's units).
pub(super) fn mean_per_value(distances: &[f32], dim: usize) -> f32 {
    let sum: f64 = distances.iter().map(|&v| f64::from(v)).sum();
    (sum / distances.len().max(1) as f64 / dim as f64) as f32
}

/// The exemplar windows [`completeness`] compares
/// ([`completeness_windows`]), one after another, `n·n·channels` values each
/// (rows of `n · channels`).
pub fn completeness_queries(exemplar: &Image, n: usize) -> Vec<f32> {
    let ch = exemplar.channels as usize;
    let picks = completeness_windows(exemplar.width, exemplar.height, n as u32);
    let dim = n * n * ch;
    let mut queries = vec![0.0f32; picks.len() * dim];
    queries
        .par_chunks_exact_mut(dim)
        .zip(&picks)
        .for_each(|(query, &(x, y))| {
            for dy in 0..n {
                let row = exemplar.offset(x as u32, (y + dy) as u32);
                query[dy * n * ch..][..n * ch].copy_from_slice(&exemplar.data[row..][..n * ch]);
            }
        });
    queries
}

/// Luma of every pixel: Rec. 601 weights of RGB for 3 or 4 channels, the
/// first channel otherwise (the quality measures' grey; the material
/// channels' [`crate::kernels::atlas::channels::luminance`] is Rec. 709's of one
/// pixel).
pub fn luma(img: &Image) -> Vec<f32> {
    let ch = img.channels as usize;
    img.data
        .chunks_exact(ch)
        .map(|p| {
            if ch >= 3 {
                0.299 * p[0] + 0.587 * p[1] + 0.114 * p[2]
            } else {
                p[0]
            }
        })
        .collect()
}

/// Sobel gradient `(gx, gy)` of a `w`×`h` plane at an interior pixel, each
/// divided by 8 so a unit step per pixel gives 1.
#[inline]
fn sobel(l: &[f32], w: usize, x: usize, y: usize) -> (f32, f32) {
    let at = |dx: isize, dy: isize| l[(y as isize + dy) as usize * w + (x as isize + dx) as usize];
    let gx = (at(1, -1) + 2.0 * at(1, 0) + at(1, 1)) - (at(-1, -1) + 2.0 * at(-1, 0) + at(-1, 1));
    let gy = (at(-1, 1) + 2.0 * at(0, 1) + at(1, 1)) - (at(-1, -1) + 2.0 * at(0, -1) + at(1, -1));
    (gx / 8.0, gy / 8.0)
}

/// Mean Sobel gradient magnitude of the luminance over interior pixels
/// (luminance units per pixel); 0 for images under 3×3.
pub fn mean_gradient(img: &Image) -> f32 {
    let (w, h) = (img.width as usize, img.height as usize);
    if w < 3 || h < 3 {
        return 0.0;
    }
    let l = luma(img);
    let sum: f64 = (1..h - 1)
        .map(|y| {
            (1..w - 1)
                .map(|x| {
                    let (gx, gy) = sobel(&l, w, x, y);
                    (gx * gx + gy * gy).sqrt() as f64
                })
                .sum::<f64>()
        })
        .sum();
    (sum / ((w - 2) * (h - 2)) as f64) as f32
}

/// Sharpness: the result's mean luminance gradient magnitude
/// ([`mean_gradient`]) over the exemplar's. 1 = as sharp as the exemplar;
/// below 1 = blurred (or flattened); well above 1 = noise. NaN when the
/// exemplar is flat.
pub fn sharpness(output: &Image, exemplar: &Image) -> f32 {
    let g = mean_gradient(exemplar);
    if g <= 0.0 {
        return f32::NAN;
    }
    mean_gradient(output) / g
}

/// Orientation/scale energy of a luminance plane: for each scale `s` (level
/// `s` of a Gaussian pyramid) and each of [`STRUCTURE_ORIENTATIONS`] bins of
/// gradient orientation over 180°, the mean squared Sobel gradient magnitude
/// of that level falling in the bin (linear binning between bin centres).
/// Returns `scales × STRUCTURE_ORIENTATIONS` values, scale-major,
/// unnormalised. Orientation is of the gradient modulo 180° (an edge and its
/// reverse are the same structure).
pub fn structure_features(l: &[f32], w: usize, h: usize, scales: usize) -> Vec<f64> {
    let plane = Image::from_data(w as u32, h as u32, 1, l.to_vec()).expect("plane size");
    let levels = gaussian_pyramid(&plane, scales, Wrap::Clamp);
    let bins = STRUCTURE_ORIENTATIONS;
    let mut out = vec![0.0f64; scales * bins];
    for (s, level) in levels.iter().enumerate() {
        let (lw, lh) = (level.width as usize, level.height as usize);
        if lw < 3 || lh < 3 {
            continue;
        }
        let feats = &mut out[s * bins..(s + 1) * bins];
        for y in 1..lh - 1 {
            for x in 1..lw - 1 {
                let (gx, gy) = sobel(&level.data, lw, x, y);
                let e = (gx * gx + gy * gy) as f64;
                if e == 0.0 {
                    continue;
                }
                // Doubled angle: θ and θ + 180° coincide; position in bins.
                let t = (gy as f64)
                    .atan2(gx as f64)
                    .rem_euclid(std::f64::consts::PI)
                    / std::f64::consts::PI
                    * bins as f64
                    - 0.5;
                let t = t.rem_euclid(bins as f64);
                let b0 = t.floor() as usize % bins;
                let f = t - t.floor();
                feats[b0] += e * (1.0 - f);
                feats[(b0 + 1) % bins] += e * f;
            }
        }
        let count = ((lw - 2) * (lh - 2)) as f64;
        for v in feats.iter_mut() {
            *v /= count;
        }
    }
    out
}

/// Number of structure scales two images of these sizes share: pyramid
/// levels whose smaller side stays at least 8 pixels, at most
/// [`STRUCTURE_SCALES`], at least 1.
pub fn structure_scales(a: (u32, u32), b: (u32, u32)) -> usize {
    let side = a.0.min(a.1).min(b.0).min(b.1).max(1);
    let mut scales = 1;
    while scales < STRUCTURE_SCALES && side >> scales >= 8 {
        scales += 1;
    }
    scales
}

/// Total-variation distance between two feature vectors each normalised to
/// sum 1: `½ Σ |a/Σa − b/Σb|`, in `[0, 1]`. 0 when both are empty (flat), 1
/// when exactly one is.
pub fn normalised_l1(a: &[f64], b: &[f64]) -> f32 {
    let (sa, sb): (f64, f64) = (a.iter().sum(), b.iter().sum());
    const FLAT: f64 = 1e-12;
    match (sa > FLAT, sb > FLAT) {
        (false, false) => 0.0,
        (true, false) | (false, true) => 1.0,
        (true, true) => {
            let d: f64 = a.iter().zip(b).map(|(x, y)| (x / sa - y / sb).abs()).sum();
            (0.5 * d) as f32
        }
    }
}

/// Structure distance: how differently the result and the exemplar
/// distribute their gradient energy over orientations and scales
/// ([`structure_features`] over [`structure_scales`] shared levels, each
/// vector normalised to sum 1, total-variation distance), in `[0, 1]`.
///
/// Sees a wrong orientation (a 90°-rotated anisotropic texture moves its
/// energy four bins), a wrong scale (energy moves between levels), lost
/// structure (blur, or mottling, moves energy between scales) and a flat
/// result (distance 1). Contrast alone does not change it (the histogram
/// sees that).
pub fn structure_distance(output: &Image, exemplar: &Image) -> f32 {
    let scales = structure_scales(
        (output.width, output.height),
        (exemplar.width, exemplar.height),
    );
    let fo = structure_features(
        &luma(output),
        output.width as usize,
        output.height as usize,
        scales,
    );
    let fe = structure_features(
        &luma(exemplar),
        exemplar.width as usize,
        exemplar.height as usize,
        scales,
    );
    normalised_l1(&fo, &fe)
}

use crate::mesh::union_find_root as root;

/// Verbatim-copy statistics of a result whose source coordinates are known
/// (see [`VerbatimStats`] for each figure), for an exemplar of
/// `ex_width`×`ex_height` pixels.
///
/// Two 4-neighbours `p` and `p + d` belong to one copied region when both
/// sources are known and `src(p + d) − src(p)` equals `d` within half a pixel
/// per axis, differences taken toroidally (modulo the exemplar size). Linear
/// in the result's pixels.
pub fn verbatim_copying(sources: &SourceMap, ex_width: u32, ex_height: u32) -> VerbatimStats {
    let (w, h) = (sources.width as usize, sources.height as usize);
    assert_eq!(sources.texels.len(), w * h, "one source per pixel");
    let (ew, eh) = (ex_width.max(1) as f32, ex_height.max(1) as f32);
    let ex_area = (ex_width.max(1) * ex_height.max(1)) as usize;
    let known = |s: &[f32; 2]| s[0].is_finite() && s[1].is_finite();
    // Signed toroidal difference in (−size/2, size/2].
    let wrap = |d: f32, size: f32| d - size * (d / size).round();
    let follows = |a: &[f32; 2], b: &[f32; 2], dx: f32, dy: f32| {
        known(a)
            && known(b)
            && (wrap(b[0] - a[0], ew) - dx).abs() <= 0.5
            && (wrap(b[1] - a[1], eh) - dy).abs() <= 0.5
    };
    let texel_index = |s: &[f32; 2]| {
        let x = (s[0].floor() as i64).rem_euclid(ex_width.max(1) as i64) as usize;
        let y = (s[1].floor() as i64).rem_euclid(ex_height.max(1) as i64) as usize;
        y * ex_width.max(1) as usize + x
    };
    let mut parent: Vec<u32> = (0..(w * h) as u32).collect();
    let t = &sources.texels;
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            if x + 1 < w && follows(&t[i], &t[i + 1], 1.0, 0.0) {
                let (a, b) = (root(&mut parent, i as u32), root(&mut parent, i as u32 + 1));
                parent[a.max(b) as usize] = a.min(b);
            }
            if y + 1 < h && follows(&t[i], &t[i + w], 0.0, 1.0) {
                let (a, b) = (
                    root(&mut parent, i as u32),
                    root(&mut parent, (i + w) as u32),
                );
                parent[a.max(b) as usize] = a.min(b);
            }
        }
    }
    let mut area = vec![0u32; w * h];
    let mut used = vec![false; ex_area];
    let mut roots = vec![0u32; w * h];
    for i in 0..w * h {
        if !known(&t[i]) {
            continue;
        }
        let r = root(&mut parent, i as u32);
        roots[i] = r;
        area[r as usize] += 1;
        used[texel_index(&t[i])] = true;
    }
    let (mut sum, mut sum_sq, mut largest) = (0u64, 0u64, 0u32);
    for &a in area.iter().filter(|&&a| a > 0) {
        sum += a as u64;
        sum_sq += a as u64 * a as u64;
        largest = largest.max(a);
    }
    // Repeats of large regions: per exemplar pixel, how many result pixels
    // of large regions copy it (a region wrapping around the exemplar
    // repeats it within itself).
    let large = (ex_area as u32).div_ceil(3);
    let mut repeats = vec![0u32; ex_area];
    let mut most = 0;
    for i in 0..w * h {
        if !known(&t[i]) || area[roots[i] as usize] < large {
            continue;
        }
        let e = texel_index(&t[i]);
        repeats[e] += 1;
        most = most.max(repeats[e]);
    }
    let mean = if sum > 0 {
        sum_sq as f64 / sum as f64
    } else {
        0.0
    };
    VerbatimStats {
        source_coverage: used.iter().filter(|&&u| u).count() as f32 / ex_area as f32,
        mean_region_area: mean as f32,
        mean_region_fraction: (mean / ex_area as f64) as f32,
        largest_region: largest,
        large_region_repeats: most,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn noise(w: u32, h: u32, ch: u32, seed: u32) -> Image {
        let mut s = seed.wrapping_mul(2_654_435_761).wrapping_add(7);
        let data = (0..w * h * ch)
            .map(|_| {
                s ^= s << 13;
                s ^= s >> 17;
                s ^= s << 5;
                (s % 1000) as f32 / 1000.0
            })
            .collect();
        Image::from_data(w, h, ch, data).unwrap()
    }

    fn stripes(w: u32, h: u32, vertical: bool) -> Image {
        let data = (0..w * h)
            .map(|i| {
                let (x, y) = (i % w, i / w);
                let t = if vertical { x } else { y };
                0.5 + 0.5 * (t as f32 * 0.7).sin()
            })
            .collect();
        Image::from_data(w, h, 1, data).unwrap()
    }

    #[test]
    fn completeness_is_zero_for_the_exemplar_and_high_for_a_flat_image() {
        let ex = noise(24, 20, 3, 1);
        assert_eq!(completeness(&ex, &ex, 5), 0.0);
        let flat = Image::from_data(24, 20, 3, [0.5].repeat(24 * 20 * 3)).unwrap();
        assert!(completeness(&flat, &ex, 5) > 0.05);
        // A result made of one quarter of the exemplar misses the rest.
        let mut part = Image::new(24, 20, 3);
        for y in 0..20 {
            for x in 0..24 {
                part.pixel_mut(x, y)
                    .copy_from_slice(ex.pixel(x % 12, y % 10));
            }
        }
        assert!(completeness(&part, &ex, 5) > 0.02);
    }

    #[test]
    fn completeness_windows_are_exact_up_to_128_and_bounded_beyond() {
        assert_eq!(completeness_windows(128, 128, 7).len(), 61 * 61);
        let big = completeness_windows(1024, 768, 7);
        assert!(big.len() <= COMPLETENESS_MAX_WINDOWS && big.len() > COMPLETENESS_MAX_WINDOWS / 2);
        // Spread over the whole exemplar, not only its top rows.
        assert!(big.iter().any(|&(_, y)| y > 700) && big.iter().any(|&(x, _)| x > 1000));
        assert!(completeness_windows(5, 20, 7).is_empty());
    }

    #[test]
    fn sharpness_of_a_copy_is_one_and_of_a_flat_image_zero() {
        let ex = noise(16, 16, 3, 2);
        assert!((sharpness(&ex, &ex) - 1.0).abs() < 1e-6);
        let flat = Image::new(16, 16, 3);
        assert_eq!(sharpness(&flat, &ex), 0.0);
        assert!(sharpness(&ex, &flat).is_nan());
    }

    #[test]
    fn structure_sees_rotation_and_not_translation() {
        let v = stripes(64, 64, true);
        let h = stripes(64, 64, false);
        assert!(structure_distance(&v, &v) < 1e-6);
        assert!(
            structure_distance(&h, &v) > 0.8,
            "{}",
            structure_distance(&h, &v)
        );
        let flat = Image::new(64, 64, 1);
        assert_eq!(structure_distance(&flat, &v), 1.0);
        assert_eq!(structure_scales((64, 64), (128, 16)), 2);
    }

    #[test]
    fn verbatim_of_a_tiling_and_of_scattered_pixels() {
        // A 16×16 result tiled from one 4×4 block of a 16×16 exemplar.
        let tiled = SourceMap {
            width: 16,
            height: 16,
            texels: (0..256)
                .map(|i| [(i % 16 % 4) as f32 + 2.5, (i / 16 % 4) as f32 + 3.5])
                .collect(),
        };
        let v = verbatim_copying(&tiled, 16, 16);
        assert_eq!(v.source_coverage, 16.0 / 256.0);
        assert_eq!((v.largest_region, v.mean_region_area), (16, 16.0));
        // The identity copy is one region covering everything.
        let ident = SourceMap {
            width: 16,
            height: 16,
            texels: (0..256)
                .map(|i| [(i % 16) as f32 + 0.5, (i / 16) as f32 + 0.5])
                .collect(),
        };
        let v = verbatim_copying(&ident, 16, 16);
        assert_eq!((v.source_coverage, v.largest_region), (1.0, 256));
        assert_eq!(v.large_region_repeats, 1);
        // A 32×32 result that is the exemplar four times, each copy large.
        let four = SourceMap {
            width: 32,
            height: 32,
            texels: (0..1024)
                .map(|i| [(i % 32 % 16) as f32 + 0.5, (i / 32 % 16) as f32 + 0.5])
                .collect(),
        };
        // Toroidal differences join the four copies into one region, which
        // repeats every exemplar pixel four times.
        let v = verbatim_copying(&four, 16, 16);
        assert_eq!((v.largest_region, v.large_region_repeats), (1024, 4));
        // Unknown sources count nowhere.
        let none = SourceMap {
            width: 4,
            height: 4,
            texels: vec![[f32::NAN; 2]; 16],
        };
        let v = verbatim_copying(&none, 16, 16);
        assert_eq!((v.source_coverage, v.largest_region), (0.0, 0));
    }
}
