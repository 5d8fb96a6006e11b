//! Jump map analysis (Zelinka & Garland 2004, §4): neighbourhood vectors,
//! PCA, approximate nearest neighbours, Poisson-disc filtering and weight
//! normalisation, giving a [`JumpMap`].

use rayon::prelude::*;

use super::ann::{AnnSearch, KD_MIN_POINTS, KnnSearch, Neighbour};
use super::map::JumpMapParts;
use super::neighbourhoods::{Neighbourhoods, source_region, vector_len, wrap_for};
use super::normalise::normalise_weights;
use super::pca;
use super::poisson::PoissonDisc;
use super::{Boundary, Jump, JumpMap, JumpMapError, JumpMapSettings, TexelCoord, TexelRect};
use crate::image::{Image, pyramid::gaussian_pyramid};
use crate::progress::Progress;

/// Facts about one analysis run, for reports and tuning.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct AnalysisStats {
    /// Length of the raw multi-resolution neighbourhood vectors.
    pub vector_len: usize,
    /// Principal components kept.
    pub components: usize,
    /// Fraction of the PCA sample's variance they explain.
    pub explained_variance: f64,
    /// Neighbourhoods in the PCA sample.
    pub pca_sample_size: usize,
    /// Pixels with a jump list (the source region).
    pub source_pixels: usize,
    /// Mean number of jumps per source pixel.
    pub mean_jumps: f64,
    /// Fraction of source pixels that got all `k` jumps.
    pub full_fraction: f64,
    /// Fraction of source pixels whose disc had to be halved at least once.
    pub halved_fraction: f64,
}

/// Checks that an exemplar can be analysed.
///
/// # Errors
/// [`JumpMapError::BadExemplar`] or [`JumpMapError::ExemplarTooLarge`].
pub fn check_exemplar(exemplar: &Image) -> Result<(), JumpMapError> {
    let bad = |message| JumpMapError::BadExemplar {
        width: exemplar.width,
        height: exemplar.height,
        channels: exemplar.channels,
        len: exemplar.data.len(),
        message,
    };
    if exemplar.width == 0 || exemplar.height == 0 || exemplar.channels == 0 {
        return Err(bad("it has no pixels or no channels"));
    }
    if exemplar.data.len() != exemplar.pixel_count() * exemplar.channels as usize {
        return Err(bad("the data length is not width x height x channels"));
    }
    if exemplar.data.iter().any(|v| !v.is_finite()) {
        return Err(bad("it holds a NaN or infinite value"));
    }
    if exemplar.width > 65535 || exemplar.height > 65535 {
        return Err(JumpMapError::ExemplarTooLarge {
            width: exemplar.width,
            height: exemplar.height,
        });
    }
    Ok(())
}

/// Pixels whose neighbourhood vectors are computed and projected at once:
/// a multiple of the projection's chunk (so blocks give the result of one
/// whole buffer) of about [`PROJECTION_BLOCK_BYTES`].
pub fn projection_block(dim: usize) -> usize {
    let chunk = pca::PROJECT_CHUNK;
    ((PROJECTION_BLOCK_BYTES / (4 * dim.max(1))) / chunk).max(1) * chunk
}

/// Bytes of neighbourhood vectors computed at once (see
/// [`projection_block`]).
pub const PROJECTION_BLOCK_BYTES: usize = 32 << 20;

/// Estimated peak bytes of [`analyse_with_stats`] for a `width × height`
/// exemplar of `channels` (issue 43), the largest of its phases:
///
/// - PCA: the Gaussian pyramid, the sample's neighbourhood vectors (`f32`)
///   and [`pca::fit_bytes`] (the sample in `f64`, faer's SVD workspace);
/// - projection: the pyramid, the projected vectors of every source pixel
///   (`4 · components` bytes, components bounded by `max_components`) and
///   one block of vectors ([`projection_block`]);
/// - nearest neighbours: the projected vectors, the per-source-pixel jump
///   lists (`5 + 12k` bytes), the kd-tree (72 bytes a point, when the search
///   may use it) and the blocks' neighbour lists;
/// - the map: per-pixel lists at the exemplar's size and the source
///   region's, then the weights and slots (`5 + 24k` bytes a pixel), then
///   the map and its cache bytes.
///
/// 0 for settings or an exemplar the analysis refuses.
pub fn analysis_bytes(width: u32, height: u32, channels: u32, settings: &JumpMapSettings) -> u64 {
    let widths = &settings.neighbourhood_widths;
    if settings.validate().is_err() || width == 0 || height == 0 || channels == 0 {
        return 0;
    }
    let Ok(region) = source_region(width, height, widths, settings.boundary) else {
        return 0;
    };
    let big_n = u64::from(width) * u64::from(height);
    let n = u64::from(region.width()) * u64::from(region.height());
    let c = u64::from(channels);
    let dim = vector_len(widths, channels) as u64;
    let (mut pyramid, mut lw, mut lh) = (0u64, u64::from(width), u64::from(height));
    for _ in 0..widths.len() {
        pyramid += lw * lh * c * 4;
        (lw, lh) = (lw.div_ceil(2).max(1), lh.div_ceil(2).max(1));
    }
    // Building a level blurs the one above: one more image of the finest size.
    pyramid += big_n * c * 4;
    let ms = pca::sample_size(n as usize, settings.pca_sample_fraction) as u64;
    let components = u64::from(settings.max_components).clamp(1, ms.min(dim).max(1));
    let pca = (n * 4)
        .max(ms * 4 + ms * dim * 4)
        .saturating_add(pca::fit_bytes(ms as usize, dim as usize));
    let block = (projection_block(dim as usize) as u64).min(n);
    let chunk = pca::PROJECT_CHUNK as u64;
    let projection =
        n * components * 4 + block * (dim + components) * 4 + ESTIMATE_THREADS * chunk * dim * 4;
    let k = u64::from(settings.jumps_per_pixel);
    let m = (k * u64::from(settings.candidate_factor) + 1).min(n);
    let per_source = 5 + 12 * k;
    let may_use_tree = match settings.ann_search {
        AnnSearch::Auto => n >= KD_MIN_POINTS as u64,
        AnnSearch::KdTree => true,
        AnnSearch::Exhaustive => false,
    };
    let tree = if may_use_tree { 72 * n } else { 0 };
    let q = KnnSearch::BLOCK as u64;
    let tile = super::ann::POINT_TILE as u64;
    let per_thread = q * m * 8 * 5 + (q + tile) * (components + 1) * 4 + q * tile * 4;
    // The points' squared norms of the exhaustive search (4 bytes each).
    let norms = if may_use_tree { 0 } else { 4 * n };
    let neighbours =
        n * components * 4 + n * per_source + tree + norms + ESTIMATE_THREADS * per_thread;
    let map = (big_n * per_source + n * per_source)
        .max(big_n * (5 + 24 * k))
        .max(2 * big_n * per_source);
    (pyramid.saturating_add(pca.max(projection)))
        .max(neighbours)
        .max(map)
}

/// Worker threads whose scratch an estimate allows for: a constant, so an
/// estimate (and a refusal) never depends on the thread count.
pub const ESTIMATE_THREADS: u64 = 4;

/// Builds the jump map of `exemplar` (any channel count; all channels are
/// compared). See [`analyse_with_stats`].
///
/// # Errors
/// As [`analyse_with_stats`].
pub fn analyse(exemplar: &Image, settings: &JumpMapSettings) -> Result<JumpMap, JumpMapError> {
    analyse_with_stats(exemplar, settings).map(|(m, _)| m)
}

/// Builds the jump map of `exemplar` under `settings` and reports statistics.
///
/// Steps: Gaussian pyramid and multi-resolution neighbourhood vectors over the
/// source region (§4.1–4.3, [`super::neighbourhoods`]); PCA of a random sample
/// ([`super::pca`]); for each source pixel the `k·s + 1` approximate nearest
/// neighbours in PCA space ([`super::ann`], the `+ 1` being the pixel itself),
/// those outside the destination region dropped, Poisson-disc filtered to at
/// most `k` ([`super::poisson`]); weights normalised ([`super::normalise`]).
/// Neighbourhood differences are L2 distances in PCA space. The per-pixel work
/// runs in parallel on the current rayon pool and involves no randomness, so
/// the map is identical for any thread count; the PCA sample is drawn from
/// `settings.seed`.
///
/// # Errors
/// [`JumpMapError::InvalidSetting`], [`JumpMapError::BadExemplar`],
/// [`JumpMapError::ExemplarTooLarge`], [`JumpMapError::ExemplarTooSmall`]
/// (inset region empty) or [`JumpMapError::Pca`].
pub fn analyse_with_stats(
    exemplar: &Image,
    settings: &JumpMapSettings,
) -> Result<(JumpMap, AnalysisStats), JumpMapError> {
    analyse_with_progress(exemplar, settings, &Progress::hidden())
}

/// The neighbourhood vectors of the source `region`, projected on the PCA
/// fitted to a sample of them: `components` values per source pixel, row
/// by row over the region.
///
/// The vectors are never all held (issue 43: 4 · dim bytes a pixel, 23 GB
/// at 4096²): the PCA sample's are computed for the sample, then the rest a
/// block at a time, projected and dropped. The blocks start at multiples of
/// the projection's chunk, so the result is the same as projecting one
/// buffer of all of them.
fn projected_neighbourhoods(
    exemplar: &Image,
    settings: &JumpMapSettings,
    region: TexelRect,
    progress: &Progress,
) -> Result<(Vec<f32>, pca::Pca), JumpMapError> {
    let widths = &settings.neighbourhood_widths;
    let boundary = settings.boundary;
    let dim = vector_len(widths, exemplar.channels);
    let n_src = region.width() as usize * region.height() as usize;
    let pyramid = {
        let _s = tracing::info_span!("pyramid").entered();
        gaussian_pyramid(exemplar, widths.len(), wrap_for(boundary))
    };
    let hoods = Neighbourhoods::new(&pyramid, widths, wrap_for(boundary));
    progress.set_part("pca");
    let pca = {
        let _s = tracing::info_span!("pca").entered();
        let rows = pca::sample_rows(n_src, settings.pca_sample_fraction, settings.seed);
        let sample = hoods.pixels(region, &rows);
        drop(rows);
        pca::fit_sample(
            &sample,
            dim,
            settings.pca_variance,
            settings.max_components as usize,
        )?
    };
    progress.set_part("projection");
    let _s = tracing::info_span!("neighbourhoods").entered();
    let block = projection_block(dim);
    let mut projected = Vec::with_capacity(n_src * pca.components);
    for first in (0..n_src).step_by(block) {
        let vectors = hoods.rows(region, first, block.min(n_src - first));
        projected.extend_from_slice(&pca.project(&vectors));
    }
    Ok((projected, pca))
}

/// Per source pixel (row by row over the region): its jump count, its
/// final disc diameter, and `k` differences and destinations.
struct RegionJumps {
    counts: Vec<u8>,
    discs: Vec<f32>,
    diffs: Vec<f32>,
    dests: Vec<TexelCoord>,
}

/// Each source pixel's `k·s + 1` approximate nearest neighbours in PCA
/// space (itself among them), those outside `destinations` dropped,
/// Poisson-disc filtered to at most `k`. Each block of queries' neighbours
/// is filtered as soon as it is found, in parallel.
fn nearest_and_filtered(
    projected: &[f32],
    components: usize,
    settings: &JumpMapSettings,
    disc: &PoissonDisc,
    region: TexelRect,
    destinations: TexelRect,
    progress: &Progress,
) -> RegionJumps {
    let k = disc.k;
    let n_src = region.width() as usize * region.height() as usize;
    let m = k * settings.candidate_factor as usize + 1;
    let rw = region.width();
    let coord = |i: usize| TexelCoord::new(region.x0 + i as u32 % rw, region.y0 + i as u32 / rw);
    let mut r_counts = vec![0u8; n_src];
    let mut r_discs = vec![0.0f32; n_src];
    let mut r_diffs = vec![0.0f32; n_src * k];
    let mut r_dests = vec![TexelCoord::default(); n_src * k];
    let _s = tracing::info_span!("nearest_neighbours").entered();
    progress.set_part("nearest neighbours and filtering");
    let knn = KnnSearch::new(
        projected,
        components,
        m,
        settings.ann_epsilon,
        settings.ann_search,
    );
    let m = knn.m();
    let b = KnnSearch::BLOCK;
    r_counts
        .par_chunks_mut(b)
        .zip(r_discs.par_chunks_mut(b))
        .zip(r_diffs.par_chunks_mut(b * k))
        .zip(r_dests.par_chunks_mut(b * k))
        .enumerate()
        .for_each_init(
            || {
                (
                    Vec::<Neighbour>::new(),
                    Vec::<(TexelCoord, f32)>::new(),
                    Vec::<usize>::new(),
                )
            },
            |(nbrs, cands, acc), (block, (((counts, discs), diffs), dests))| {
                let qn = counts.len();
                nbrs.clear();
                nbrs.resize(
                    qn * m,
                    Neighbour {
                        index: 0,
                        dist2: 0.0,
                    },
                );
                knn.block(block, nbrs);
                progress.inc(qn as u64);
                for q in 0..qn {
                    let row = &nbrs[q * m..][..m];
                    cands.clear();
                    cands.extend(
                        row.iter()
                            .map(|n| (coord(n.index as usize), n.dist2.max(0.0).sqrt()))
                            .filter(|(c, _)| destinations.contains(c.x, c.y)),
                    );
                    let source = coord(block * b + q);
                    discs[q] = disc.filter(source, cands, acc);
                    counts[q] = acc.len() as u8;
                    for (j, &a) in acc.iter().enumerate() {
                        dests[q * k + j] = cands[a].0;
                        diffs[q * k + j] = cands[a].1;
                    }
                }
                progress.inc(qn as u64);
            },
        );
    RegionJumps {
        counts: r_counts,
        discs: r_discs,
        diffs: r_diffs,
        dests: r_dests,
    }
}

/// The region's jump lists placed at their pixels of the `w × h` exemplar,
/// with normalised weights (`alpha`): per pixel its count and disc, and `k`
/// jump slots. Also returns the jumps in all, the pixels with a full list
/// and those whose disc was halved.
#[allow(clippy::type_complexity)] // the map's parts, as `JumpMapParts` takes them
fn scatter_to_exemplar(
    found: RegionJumps,
    disc: &PoissonDisc,
    region: TexelRect,
    w: u32,
    h: u32,
    alpha: f32,
) -> (Vec<u8>, Vec<f32>, Vec<Jump>, (usize, usize, usize)) {
    let k = disc.k;
    let rw = region.width();
    let n_src = region.width() as usize * region.height() as usize;
    let coord = |i: usize| TexelCoord::new(region.x0 + i as u32 % rw, region.y0 + i as u32 / rw);
    let n = w as usize * h as usize;
    let mut counts = vec![0u8; n];
    let mut discs = vec![0.0f32; n];
    let mut diffs = vec![0.0f32; n * k];
    let mut dests = vec![TexelCoord::default(); n * k];
    let initial = disc.diameter.max(disc.min_diameter);
    let (mut total, mut full, mut halved) = (0usize, 0usize, 0usize);
    for i in 0..n_src {
        let c = coord(i);
        let p = (c.y * w + c.x) as usize;
        counts[p] = found.counts[i];
        discs[p] = found.discs[i];
        let nj = found.counts[i] as usize;
        diffs[p * k..][..nj].copy_from_slice(&found.diffs[i * k..][..nj]);
        dests[p * k..][..nj].copy_from_slice(&found.dests[i * k..][..nj]);
        total += nj;
        full += usize::from(nj == k);
        halved += usize::from(found.discs[i] < initial);
    }
    drop(found);
    let weights = normalise_weights(&diffs, &counts, k, alpha);
    drop(diffs);
    let slots = dests
        .iter()
        .zip(&weights)
        .map(|(&to, &weight)| Jump { to, weight })
        .collect();
    (counts, discs, slots, (total, full, halved))
}

/// [`analyse_with_stats`], reporting to `progress`: two steps per source
/// pixel in the part "nearest neighbours and filtering" (a block's
/// neighbours, then their filtering), the PCA fit of the sample and the
/// projection of the neighbourhood vectors as parts without steps.
///
/// # Errors
/// As [`analyse_with_stats`].
pub fn analyse_with_progress(
    exemplar: &Image,
    settings: &JumpMapSettings,
    progress: &Progress,
) -> Result<(JumpMap, AnalysisStats), JumpMapError> {
    let _span =
        tracing::info_span!("jump_map_analysis", w = exemplar.width, h = exemplar.height).entered();
    settings.validate()?;
    check_exemplar(exemplar)?;
    let (w, h) = (exemplar.width, exemplar.height);
    let widths = &settings.neighbourhood_widths;
    let boundary = settings.boundary;
    let region = source_region(w, h, widths, boundary)?;
    let destinations = match boundary {
        Boundary::Toroidal => region,
        Boundary::Inset => region.eroded(1),
    };
    let dim = vector_len(widths, exemplar.channels);
    let pixels = region.width() as u64 * region.height() as u64;
    progress.set_length(2 * pixels);

    let (projected, pca) = projected_neighbourhoods(exemplar, settings, region, progress)?;
    let k = settings.jumps_per_pixel as usize;
    let disc = PoissonDisc {
        k,
        diameter: settings.effective_disc_diameter(),
        min_diameter: settings.min_disc_diameter,
        width: w,
        height: h,
        boundary,
    };
    let found = nearest_and_filtered(
        &projected,
        pca.components,
        settings,
        &disc,
        region,
        destinations,
        progress,
    );
    drop(projected);
    let (counts, discs, slots, totals) =
        scatter_to_exemplar(found, &disc, region, w, h, settings.alpha);
    let src = (pixels as usize).max(1) as f64;
    let stats = AnalysisStats {
        vector_len: dim,
        components: pca.components,
        explained_variance: pca.explained,
        pca_sample_size: pca.sample_size,
        source_pixels: pixels as usize,
        mean_jumps: totals.0 as f64 / src,
        full_fraction: totals.1 as f64 / src,
        halved_fraction: totals.2 as f64 / src,
    };
    let map = JumpMap::from_parts(JumpMapParts {
        width: w,
        height: h,
        boundary,
        k: k as u32,
        sources: region,
        destinations,
        counts,
        discs,
        slots,
        key: settings.cache_key(exemplar),
    })?;
    Ok((map, stats))
}
