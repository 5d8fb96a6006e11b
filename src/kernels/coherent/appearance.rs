//! Appearance space (Lefebvre & Hoppe 2006 §3): every exemplar pixel of one
//! synthesis level becomes a short vector, the leading principal components
//! of its Gaussian-weighted `w × w` neighbourhood in the level's Gaussian
//! stack image, so comparing two pixels' vectors compares whole
//! neighbourhoods. Each pixel also keeps its `k` most similar pixels
//! (k-coherence, Tong et al. 2002): the jumps a coherent synthesis may take
//! when shifting a neighbour's source is not good enough.

use crate::kernels::knn::{Knn, KnnScratch};
use rayon::prelude::*;

use crate::cache_format::AnalysisStore;
use crate::image::{Image, sample::Wrap};
use crate::kernels::wei_levoy::wl_match::features::FeatureMatrix;
use crate::kernels::wei_levoy::wl_match::search::pca_kdtree::{TREE_DIMS, fit, project};

/// Values of an appearance vector (zero padded beyond the kept components).
pub const APPEARANCE_DIMS: usize = TREE_DIMS;

/// Rows the principal components are fitted on at most.
const FIT_SAMPLE: usize = 4096;

/// Bytes the appearance analysis of one level of an exemplar of `pixels`
/// pixels of `channels` channels holds at its peak, for an appearance
/// window of `window` points per side and `k` similar pixels: the fitted
/// sample (`4·dim` bytes a row, at most 4096 rows) with the PCA fit, the
/// appearance vectors (32 bytes a pixel), their kd-tree (about as much
/// again) and the k-coherence sets (`4·k`).
pub fn appearance_bytes(pixels: u64, channels: u32, window: u32, k: u32) -> u64 {
    let window = u64::from(window.max(1) | 1);
    let dim = window * window * u64::from(channels);
    let sample = pixels.min(FIT_SAMPLE as u64);
    sample * dim * 4
        + crate::kernels::jump_maps::jump_map::pca::fit_bytes(sample as usize, dim as usize)
        + pixels * (2 * 4 * APPEARANCE_DIMS as u64 + 4 * u64::from(k))
}

/// One level's appearance vectors and k-coherence sets.
#[derive(Clone, Debug)]
pub struct AppearanceLevel {
    /// Exemplar width in pixels.
    pub width: u32,
    /// Exemplar height in pixels.
    pub height: u32,
    /// Per pixel (row-major), its appearance vector.
    pub vectors: Vec<[f32; APPEARANCE_DIMS]>,
    /// Similar pixels kept per pixel.
    pub k: usize,
    /// Per pixel, `k` pixel indices of similar appearance at least
    /// `min_separation` pixels away (fewer are padded with the pixel itself).
    pub similar: Vec<u32>,
}

impl AppearanceLevel {
    /// The similar pixels of pixel index `p`.
    #[inline]
    pub fn similar_of(&self, p: u32) -> &[u32] {
        &self.similar[p as usize * self.k..(p as usize + 1) * self.k]
    }
}

/// What [`appearance_level`] reads.
#[derive(Clone, Copy, Debug)]
pub struct AppearanceSpec {
    /// Window points per side (odd).
    pub window: u32,
    /// Distance between window points, in exemplar pixels (the level's
    /// vertex spacing in exemplar pixels).
    pub spacing: f32,
    /// Principal components kept, `1..=8`.
    pub dims: usize,
    /// Similar pixels per pixel.
    pub k: usize,
    /// Seed of the fitting sample.
    pub seed: u64,
    /// Exemplar addressing.
    pub wrap: Wrap,
}

/// The Gaussian weights of a `window × window` neighbourhood
/// (σ = half the window), row by row.
fn window_weights(window: u32) -> Vec<f32> {
    let h = (window / 2) as i32;
    let sigma = (h.max(1)) as f32;
    (-h..=h)
        .flat_map(|dy| (-h..=h).map(move |dx| (dx, dy)))
        .map(|(dx, dy)| (-((dx * dx + dy * dy) as f32) / (2.0 * sigma * sigma)).exp())
        .collect()
}

/// The neighbourhood of pixel `(x, y)`: `window²` bilinear samples of
/// `image` spaced `spacing` apart, each times its weight of `weights`
/// ([`window_weights`]), written into `out`.
fn neighbourhood(
    image: &Image,
    x: u32,
    y: u32,
    spec: &AppearanceSpec,
    weights: &[f32],
    out: &mut [f32],
) {
    let ch = image.channels as usize;
    let h = (spec.window / 2) as i32;
    let mut i = 0;
    for dy in -h..=h {
        for dx in -h..=h {
            let w = weights[i];
            let px = x as f32 + 0.5 + dx as f32 * spec.spacing;
            let py = y as f32 + 0.5 + dy as f32 * spec.spacing;
            let o = &mut out[i * ch..(i + 1) * ch];
            image.sample_bilinear(px, py, spec.wrap, o);
            o.iter_mut().for_each(|v| *v *= w);
            i += 1;
        }
    }
}

/// Appearance vectors and k-coherence sets of every pixel of `image` (the
/// level's Gaussian stack image, exemplar size).
pub fn appearance_level(image: &Image, spec: &AppearanceSpec) -> AppearanceLevel {
    let (width, height) = (image.width, image.height);
    let pixels = (width * height) as usize;
    let window = spec.window.max(1) | 1;
    let spec = AppearanceSpec { window, ..*spec };
    let dim = (window * window) as usize * image.channels as usize;
    let weights = window_weights(window);
    // Fit on an evenly strided sample (deterministic, spread over the image).
    let stride = pixels.div_ceil(FIT_SAMPLE).max(1);
    let sample: Vec<u32> = (0..pixels as u32).step_by(stride).collect();
    let mut data = vec![0.0f32; sample.len() * dim];
    data.par_chunks_mut(dim)
        .zip(&sample)
        .for_each(|(row, &p)| neighbourhood(image, p % width, p / width, &spec, &weights, row));
    let fitted = FeatureMatrix { dim, data };
    let components = spec.dims.clamp(1, APPEARANCE_DIMS).min(dim);
    let (mean, basis) = fit(&fitted, components, spec.seed);
    let vectors: Vec<[f32; APPEARANCE_DIMS]> = (0..pixels as u32)
        .into_par_iter()
        .map_init(
            || vec![0.0f32; dim],
            |row, p| {
                neighbourhood(image, p % width, p / width, &spec, &weights, row);
                project(row, &mean, &basis, components)
            },
        )
        .collect();
    let k = spec.k;
    let similar = similar_sets(&vectors, width, k, 2.0 * spec.spacing.max(1.0));
    AppearanceLevel {
        width,
        height,
        vectors,
        k,
        similar,
    }
}

/// Version of the appearance analysis and of its cache entries: bump it
/// whenever [`appearance_level`] would compute anything else for the same
/// image and spec, so that older entries no longer match.
const CACHE_VERSION: u32 = 1;

/// First bytes of a cache entry.
const CACHE_MAGIC: [u8; 8] = *b"SSAPPEAR";

/// Cache entry kind (file name prefix in the cache folder).
const CACHE_KIND: &str = "appearance";

/// The cache key of `image` analysed with `spec`: a BLAKE3 hash of the
/// version, the image (size, channels, every value's bits) and every field
/// of the spec.
pub fn cache_key(image: &Image, spec: &AppearanceSpec) -> [u8; 32] {
    let mut h = crate::cache_format::key_hasher(&CACHE_MAGIC, CACHE_VERSION, image);
    h.update(&spec.window.to_le_bytes());
    h.update(&spec.spacing.to_bits().to_le_bytes());
    h.update(&(spec.dims as u64).to_le_bytes());
    h.update(&(spec.k as u64).to_le_bytes());
    h.update(&spec.seed.to_le_bytes());
    h.update(&[match spec.wrap {
        Wrap::Repeat => 0u8,
        Wrap::Clamp => 1,
    }]);
    *h.finalize().as_bytes()
}

impl AppearanceLevel {
    /// The level as a cache entry: magic, version, `key`, sizes, the
    /// vectors' and similar sets' raw little-endian values, and a BLAKE3
    /// checksum of everything before it.
    pub fn to_bytes(&self, key: &[u8; 32]) -> Vec<u8> {
        let mut b = Vec::with_capacity(
            64 + self.vectors.len() * APPEARANCE_DIMS * 4 + self.similar.len() * 4 + 32,
        );
        b.extend_from_slice(&crate::cache_format::entry_header(
            &CACHE_MAGIC,
            CACHE_VERSION,
            key,
        ));
        b.extend_from_slice(&self.width.to_le_bytes());
        b.extend_from_slice(&self.height.to_le_bytes());
        b.extend_from_slice(&(self.k as u32).to_le_bytes());
        for v in self.vectors.iter().flatten() {
            b.extend_from_slice(&v.to_le_bytes());
        }
        for s in &self.similar {
            b.extend_from_slice(&s.to_le_bytes());
        }
        crate::cache_format::seal(b)
    }

    /// The level of a cache entry written by [`Self::to_bytes`] with `key`;
    /// `None` for any other bytes (wrong magic, version or key, truncated,
    /// checksum mismatch, sizes that do not add up).
    pub fn from_bytes(bytes: &[u8], key: &[u8; 32]) -> Option<Self> {
        let body = crate::cache_format::payload(bytes, &CACHE_MAGIC, CACHE_VERSION, key)?;
        const HEAD: usize = 12;
        let u32_at = |i: usize| -> Option<u32> {
            Some(u32::from_le_bytes(body.get(i..i + 4)?.try_into().ok()?))
        };
        let (width, height, k) = (u32_at(0)?, u32_at(4)?, u32_at(8)? as usize);
        let pixels = (width as usize).checked_mul(height as usize)?;
        let vector_bytes = pixels.checked_mul(APPEARANCE_DIMS * 4)?;
        let similar_bytes = pixels.checked_mul(k)?.checked_mul(4)?;
        if body.len() != HEAD.checked_add(vector_bytes)?.checked_add(similar_bytes)? {
            return None;
        }
        let values = &body[HEAD..HEAD + vector_bytes];
        let vectors = values
            .chunks_exact(APPEARANCE_DIMS * 4)
            .map(|c| {
                let mut v = [0.0f32; APPEARANCE_DIMS];
                for (o, b) in v.iter_mut().zip(c.chunks_exact(4)) {
                    *o = f32::from_le_bytes([b[0], b[1], b[2], b[3]]);
                }
                v
            })
            .collect();
        let similar = body[HEAD + vector_bytes..]
            .chunks_exact(4)
            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect();
        Some(Self {
            width,
            height,
            vectors,
            k,
            similar,
        })
    }
}

/// [`appearance_level`] through an analysis `store` (the on-disk cache;
/// `None`: none): a valid entry for the same image and spec is read instead
/// of analysing (the same values, bit for bit); a missing, stale or corrupt
/// one is rebuilt and written. Returns the level and whether it came from
/// the store.
pub fn appearance_level_cached(
    image: &Image,
    spec: &AppearanceSpec,
    store: Option<&dyn AnalysisStore>,
) -> (AppearanceLevel, bool) {
    let Some(store) = store else {
        return (appearance_level(image, spec), false);
    };
    let key = cache_key(image, spec);
    if let Some(level) = store
        .read(CACHE_KIND, &key)
        .and_then(|bytes| AppearanceLevel::from_bytes(&bytes, &key))
    {
        return (level, true);
    }
    let level = appearance_level(image, spec);
    store.write(CACHE_KIND, &key, &level.to_bytes(&key));
    (level, false)
}

/// For every pixel, its `k` nearest pixels in appearance space that lie at
/// least `min_separation` pixels away in the image (Chebyshev distance), so
/// the set offers other places rather than the pixel's own surroundings.
fn similar_sets(
    vectors: &[[f32; APPEARANCE_DIMS]],
    width: u32,
    k: usize,
    min_separation: f32,
) -> Vec<u32> {
    if k == 0 || vectors.is_empty() {
        return Vec::new();
    }
    let index = Knn::new(vectors);
    // Near pixels look alike; ask for enough to skip the pixel's own surroundings.
    let ask = (4 * k + 8).min(vectors.len());
    let sep = min_separation.ceil() as i64;
    let mut out = vec![0u32; vectors.len() * k];
    out.par_chunks_mut(k)
        .enumerate()
        .for_each_init(KnnScratch::default, |scratch, (p, slot)| {
            let (px, py) = ((p as u32 % width) as i64, (p as u32 / width) as i64);
            let mut n = 0;
            for &(_, q) in index.nearest(&vectors[p], ask, scratch) {
                let (qx, qy) = ((q % width) as i64, (q / width) as i64);
                if (qx - px).abs().max((qy - py).abs()) < sep {
                    continue;
                }
                slot[n] = q;
                n += 1;
                if n == k {
                    break;
                }
            }
            slot[n..].fill(p as u32);
        });
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn stripes(w: u32, h: u32) -> Image {
        let data = (0..w * h)
            .map(|i| {
                if ((i % w) / 4).is_multiple_of(2) {
                    0.1
                } else {
                    0.9
                }
            })
            .collect();
        Image::from_data(w, h, 1, data).expect("size matches")
    }

    fn spec() -> AppearanceSpec {
        AppearanceSpec {
            window: 5,
            spacing: 1.0,
            dims: 8,
            k: 3,
            seed: 1,
            wrap: Wrap::Repeat,
        }
    }

    #[test]
    fn cache_entries_round_trip_and_reject_other_keys_and_damage() {
        let img = stripes(16, 8);
        let spec = spec();
        let level = appearance_level(&img, &spec);
        let key = cache_key(&img, &spec);
        let bytes = level.to_bytes(&key);
        let back = AppearanceLevel::from_bytes(&bytes, &key).expect("round trip");
        assert_eq!(back.vectors, level.vectors);
        assert_eq!(back.similar, level.similar);
        assert_eq!((back.width, back.height, back.k), (16, 8, 3));
        // Another spec is another key.
        let other = cache_key(
            &img,
            &AppearanceSpec {
                spacing: 1.5,
                ..spec
            },
        );
        assert_ne!(other, key);
        assert!(AppearanceLevel::from_bytes(&bytes, &other).is_none());
        // A flipped bit or a truncated file is rejected.
        let mut bad = bytes.clone();
        bad[70] ^= 1;
        assert!(AppearanceLevel::from_bytes(&bad, &key).is_none());
        assert!(AppearanceLevel::from_bytes(&bytes[..bytes.len() - 5], &key).is_none());
        // Through a cache folder: written on the first call, read on the second.
        let dir = tempfile::tempdir().expect("temp dir");
        let store = crate::cache::DiskCache(dir.path().to_path_buf());
        let (a, hit_a) = appearance_level_cached(&img, &spec, Some(&store));
        let (b, hit_b) = appearance_level_cached(&img, &spec, Some(&store));
        assert!(!hit_a && hit_b);
        assert_eq!(a.vectors, b.vectors);
        assert_eq!(a.similar, b.similar);
    }

    #[test]
    fn pixels_of_the_same_phase_have_the_same_appearance_and_are_similar() {
        let img = stripes(32, 32);
        let level = appearance_level(&img, &spec());
        let d = |a: usize, b: usize| -> f32 {
            level.vectors[a]
                .iter()
                .zip(&level.vectors[b])
                .map(|(x, y)| (x - y) * (x - y))
                .sum()
        };
        // Period 8 in x; rows are all alike.
        assert!(d(0, 8) < 1e-6, "same phase differs: {}", d(0, 8));
        assert!(d(0, 5 * 32) < 1e-6);
        assert!(d(0, 2) > 0.1, "different phase looks alike: {}", d(0, 2));
        // Every similar pixel has the same phase and lies away from the pixel.
        for p in [0usize, 37, 500] {
            for &q in level.similar_of(p as u32) {
                assert_eq!((q % 32) % 8, (p as u32 % 32) % 8, "pixel {p} got {q}");
                let (dx, dy) = (
                    (q % 32) as i64 - (p % 32) as i64,
                    (q / 32) as i64 - (p / 32) as i64,
                );
                assert!(dx.abs().max(dy.abs()) >= 2);
            }
        }
    }
}
