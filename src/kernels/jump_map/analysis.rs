//! Jump map analysis (Zelinka & Garland 2004, §4): neighbourhood vectors,
//! PCA, approximate nearest neighbours, Poisson-disc filtering and weight
//! normalisation, giving a [`JumpMap`].

use rayon::prelude::*;

use super::ann::all_knn_with_progress;
use super::map::JumpMapParts;
use super::neighbourhoods::{neighbourhood_vectors, source_region, vector_len, wrap_for};
use super::normalise::normalise_weights;
use super::pca;
use super::poisson::PoissonDisc;
use super::{Boundary, Jump, JumpMap, JumpMapError, JumpMapSettings, TexelCoord};
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

/// Builds the jump map of `exemplar` (any channel count; all channels are
/// compared). See [`analyse_with_stats`].
///
/// # Errors
/// As [`analyse_with_stats`].
pub fn analyse(exemplar: &Image, settings: &JumpMapSettings) -> Result<JumpMap, JumpMapError> {
    analyse_with_stats(exemplar, settings).map(|(m, _)| m)
}

/// The per-pixel result before normalisation.
struct PixelJumps {
    count: u8,
    to: [TexelCoord; 16],
    diff: [f32; 16],
    disc: f32,
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

/// [`analyse_with_stats`], reporting to `progress`: two steps per source
/// pixel (its nearest neighbours, then their filtering), the neighbourhood
/// vectors and the PCA fit as parts without steps.
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
    progress.set_part("neighbourhoods");

    let vectors = {
        let _s = tracing::info_span!("neighbourhoods").entered();
        let pyramid = gaussian_pyramid(exemplar, widths.len(), wrap_for(boundary));
        neighbourhood_vectors(&pyramid, widths, region, wrap_for(boundary))
    };
    progress.set_part("pca");
    let (pca, projected) = {
        let _s = tracing::info_span!("pca").entered();
        let pca = pca::fit(
            &vectors,
            dim,
            settings.pca_sample_fraction,
            settings.pca_variance,
            settings.max_components as usize,
            settings.seed,
        )?;
        let projected = pca.project(&vectors);
        (pca, projected)
    };
    drop(vectors);

    let k = settings.jumps_per_pixel as usize;
    let m = k * settings.candidate_factor as usize + 1;
    let eps = settings.ann_epsilon;
    let disc = PoissonDisc {
        k,
        diameter: settings.effective_disc_diameter(),
        min_diameter: settings.min_disc_diameter,
        width: w,
        height: h,
        boundary,
    };
    let rw = region.width();
    let coord = |i: usize| TexelCoord::new(region.x0 + i as u32 % rw, region.y0 + i as u32 / rw);
    let per_pixel: Vec<PixelJumps> = {
        let _s = tracing::info_span!("nearest_neighbours").entered();
        progress.set_part("nearest neighbours");
        let nbrs = all_knn_with_progress(
            &projected,
            pca.components,
            m,
            eps,
            settings.ann_search,
            progress,
        );
        let m = m.min(region.width() as usize * region.height() as usize);
        progress.set_part("filtering");
        nbrs.par_chunks(m)
            .enumerate()
            .inspect(|_| progress.inc(1))
            .map_init(
                || (Vec::<(TexelCoord, f32)>::new(), Vec::<usize>::new()),
                |(cands, acc), (i, nbrs)| {
                    cands.clear();
                    cands.extend(
                        nbrs.iter()
                            .map(|n| (coord(n.index as usize), n.dist2.max(0.0).sqrt()))
                            .filter(|(c, _)| destinations.contains(c.x, c.y)),
                    );
                    let source = coord(i);
                    let d = disc.filter(source, cands, acc);
                    let mut r = PixelJumps {
                        count: acc.len() as u8,
                        to: [TexelCoord::default(); 16],
                        diff: [0.0; 16],
                        disc: d,
                    };
                    for (j, &a) in acc.iter().enumerate() {
                        r.to[j] = cands[a].0;
                        r.diff[j] = cands[a].1;
                    }
                    r
                },
            )
            .collect()
    };

    let n = w as usize * h as usize;
    let mut counts = vec![0u8; n];
    let mut discs = vec![0.0f32; n];
    let mut diffs = vec![0.0f32; n * k];
    let mut dests = vec![TexelCoord::default(); n * k];
    let initial = disc.diameter.max(disc.min_diameter);
    let (mut total, mut full, mut halved) = (0usize, 0usize, 0usize);
    for (i, r) in per_pixel.iter().enumerate() {
        let c = coord(i);
        let p = (c.y * w + c.x) as usize;
        counts[p] = r.count;
        discs[p] = r.disc;
        let nj = r.count as usize;
        diffs[p * k..][..nj].copy_from_slice(&r.diff[..nj]);
        dests[p * k..][..nj].copy_from_slice(&r.to[..nj]);
        total += nj;
        full += usize::from(nj == k);
        halved += usize::from(r.disc < initial);
    }
    let weights = normalise_weights(&diffs, &counts, k, settings.alpha);
    let slots = dests
        .iter()
        .zip(&weights)
        .map(|(&to, &weight)| Jump { to, weight })
        .collect();
    let src = per_pixel.len().max(1) as f64;
    let stats = AnalysisStats {
        vector_len: dim,
        components: pca.components,
        explained_variance: pca.explained,
        pca_sample_size: pca.sample_size,
        source_pixels: per_pixel.len(),
        mean_jumps: total as f64 / src,
        full_fraction: full as f64 / src,
        halved_fraction: halved as f64 / src,
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
