//! Exhaustive region/neighbourhood matching (Bangay & Morkel 2006 §3.3.1,
//! Algorithm 1) with the oversampling reduction of §3.3.3.

use super::spectral;
use super::stack::{MatchImages, TILE};
use crate::image::sample::Wrap;
use rayon::prelude::*;
use std::sync::atomic::{AtomicU32, Ordering};

/// Where one coloured region vertex reads the exemplar: a level and an
/// integer texel offset from the candidate, already reduced with
/// [`MatchImages::reduce_offset`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Sample {
    /// Image level.
    pub level: u32,
    /// Reduced texel offset `(x, y)` on that level.
    pub offset: [i32; 2],
}

/// The terms of the matching sum for one region: each term is one texel
/// (level and offset), the mean colour of the region vertices that read it
/// and their number `mᵢ`.
///
/// With oversampling averaging (§3.3.3) vertices reading the same texel
/// share a term: `Σᵢ Σⱼ |vᵢⱼ − wᵢ|² = Σᵢ mᵢ |wᵢ − v̄ᵢ|² + C`, with `C`
/// independent of the candidate, so the best candidate is the same and
/// there are fewer terms. Without it every vertex is its own term.
#[derive(Clone, Debug, Default)]
pub struct MatchGroups {
    channels: usize,
    samples: Vec<Sample>,
    weight: Vec<f32>,
    colour: Vec<f32>,
    order: Vec<u32>,
    sum: Vec<f64>,
}

impl MatchGroups {
    /// Empty groups; buffers grow on first use.
    pub fn new() -> Self {
        Self::default()
    }

    /// Number of terms (the "vertex comparisons" per candidate of Table 1).
    pub fn len(&self) -> usize {
        self.samples.len()
    }

    /// True when there is nothing to compare (no coloured region vertex).
    pub fn is_empty(&self) -> bool {
        self.samples.is_empty()
    }

    /// Values per colour.
    pub(super) fn channels(&self) -> usize {
        self.channels
    }

    /// Per term, the texel it reads.
    pub(super) fn samples(&self) -> &[Sample] {
        &self.samples
    }

    /// Per term, its weight `mᵢ`.
    pub(super) fn weight(&self) -> &[f32] {
        &self.weight
    }

    /// Per term, its colour `v̄ᵢ` (`channels` values).
    pub(super) fn colour(&self) -> &[f32] {
        &self.colour
    }

    /// Builds the terms from `samples` and their colours (`channels`
    /// values each, `colours.len() == samples.len() · channels`).
    ///
    /// With `averaging`, samples reading the same texel become one term
    /// weighted by their count with their mean colour, ordered heaviest
    /// first (ties by level and offset), so partial sums grow fast; without
    /// it, one term of weight 1 per sample, in the given order.
    pub fn build(&mut self, samples: &[Sample], colours: &[f32], channels: usize, averaging: bool) {
        assert_eq!(
            colours.len(),
            samples.len() * channels,
            "one colour per sample"
        );
        self.channels = channels;
        self.samples.clear();
        self.weight.clear();
        self.colour.clear();
        if !averaging {
            self.samples.extend_from_slice(samples);
            self.weight.resize(samples.len(), 1.0);
            self.colour.extend_from_slice(colours);
            return;
        }
        self.order.clear();
        self.order.extend(0..samples.len() as u32);
        self.order
            .sort_unstable_by_key(|&i| (samples[i as usize], i));
        let mut i = 0;
        let mut groups: Vec<(u32, Sample, usize)> = Vec::new();
        self.sum.clear();
        while i < self.order.len() {
            let s = samples[self.order[i] as usize];
            let first = i;
            let base = self.sum.len();
            self.sum.resize(base + channels, 0.0);
            while i < self.order.len() && samples[self.order[i] as usize] == s {
                let k = self.order[i] as usize;
                for c in 0..channels {
                    self.sum[base + c] += colours[k * channels + c] as f64;
                }
                i += 1;
            }
            groups.push(((i - first) as u32, s, base));
        }
        groups.sort_by(|a, b| b.0.cmp(&a.0).then(a.1.cmp(&b.1)));
        for (m, s, base) in groups {
            self.samples.push(s);
            self.weight.push(m as f32);
            for c in 0..channels {
                self.colour.push((self.sum[base + c] / m as f64) as f32);
            }
        }
    }
}

/// The best candidate of a search.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BestMatch {
    /// Candidate texel on the searched level.
    pub x: u32,
    /// Candidate texel row on the searched level.
    pub y: u32,
    /// Its weighted sum of squared differences (without the constant `C`
    /// of §3.3.3 when the terms were averaged).
    pub distance: f32,
}

/// Relative slack of the pruning test, so rounding can never prune the
/// candidate that would win.
const PRUNE_SLACK: f32 = 1.0 + 1e-5;

/// The candidate texel `Q` on level `level` minimising
/// `Σ mᵢ |colour(level(i), Q + offsetᵢ) − v̄ᵢ|²` over every texel of the
/// level (exhaustive, Algorithm 1) — with a clamped exemplar, every texel
/// whose samples all lie inside it (`complete_box`); ties go to the
/// lowest `y · width + x`.
/// `None` when `groups` is empty.
///
/// Candidates are scored 32 adjacent texels of a row at a time, a tight
/// loop over contiguous floats (compiled for AVX2 too when the processor
/// has it; both builds do the same IEEE operations in the same order, so
/// results are identical). A tile is dropped as soon as all its partial
/// sums exceed the best full sum found so far (sums only grow), which
/// never changes the result; `seeds` (texels on `level`, any integers,
/// reduced like offsets) are scored first to make that bound tight.
/// `parallel` spreads tiles over rayon's pool; the result does not depend
/// on it or on the thread count.
///
/// Regions with many terms are searched through FFT correlations instead
/// ([`spectral`]): the sums of the terms on the levels worth transforming
/// at every candidate at once, then exact `f32` sums, as above, at the few
/// candidates those do not rule out. The winner and its sum are the same
/// bit for bit (tested against the tiles); on the planar benchmark the
/// stage takes about 30 % less time.
pub fn best_match(
    images: &MatchImages,
    level: usize,
    groups: &MatchGroups,
    seeds: &[[i32; 2]],
    parallel: bool,
) -> Option<BestMatch> {
    best_match_by(images, level, groups, seeds, parallel, Search::Auto)
}

/// How [`best_match_by`] scores the candidates; the winner is the same.
/// (Public for the roofline bench, which times the tiles and the search
/// as run.)
#[doc(hidden)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Search {
    /// Spectral where [`spectral::levels_to_transform`] expects it to be
    /// faster, else tiles.
    Auto,
    /// Every candidate term by term, 32 at a time, with pruning.
    Tiles,
    /// FFT correlation verified exactly ([`spectral`]) wherever it
    /// applies, transforming the terms of every level (`None`) or of one
    /// (the others summed only where needed).
    Spectral(Option<u32>),
}

/// [`best_match`] with the scoring chosen by `search`.
#[doc(hidden)]
pub fn best_match_by(
    images: &MatchImages,
    level: usize,
    groups: &MatchGroups,
    seeds: &[[i32; 2]],
    parallel: bool,
    search: Search,
) -> Option<BestMatch> {
    if groups.is_empty() {
        return None;
    }
    let ([xs, ys], inside) = complete_box(images, level, groups);
    if inside && search != Search::Tiles {
        let planes = images.planes(level);
        let texels = planes.width * planes.height;
        let mut terms = vec![0usize; images.levels()];
        for s in &groups.samples {
            terms[s.level as usize] += 1;
        }
        let transformed = match search {
            Search::Spectral(only) if texels <= spectral::MAX_TEXELS => (0..terms.len() as u32)
                .filter(|&l| terms[l as usize] > 0 && only.is_none_or(|o| o == l))
                .collect(),
            _ => spectral::levels_to_transform(
                &terms,
                groups.channels,
                (xs.1 - xs.0) * (ys.1 - ys.0),
                texels,
            ),
        };
        if !transformed.is_empty() {
            return spectral::best_match(images, level, groups, [xs, ys], &transformed, |l| {
                images.spectra(l)
            });
        }
    }
    let w = images.planes(level).width;
    let bound = AtomicU32::new(f32::INFINITY.to_bits());
    for &s in seeds {
        let [x, y] = images.reduce_offset(level, s);
        let (x, y) = (
            x.clamp(xs.0 as i32, xs.1 as i32 - 1) as usize,
            y.clamp(ys.0 as i32, ys.1 as i32 - 1) as usize,
        );
        let d = distance_at(images, groups, x, y);
        bound.fetch_min(d.to_bits(), Ordering::Relaxed);
    }
    let first_tile = xs.0 / TILE;
    let tiles_per_row = xs.1.div_ceil(TILE) - first_tile;
    let tiles = tiles_per_row * (ys.1 - ys.0);
    let score = |t: usize| {
        let y = ys.0 + t / tiles_per_row;
        let x0 = (first_tile + t % tiles_per_row) * TILE;
        score_tile(images, groups, y, x0, w, xs, &bound)
    };
    let key = |a: &(f32, u32), b: &(f32, u32)| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1));
    let best = if parallel {
        (0..tiles).into_par_iter().filter_map(score).min_by(key)
    } else {
        (0..tiles).filter_map(score).min_by(key)
    }?;
    Some(BestMatch {
        x: best.1 % w as u32,
        y: best.1 / w as u32,
        distance: best.0,
    })
}

/// The texel among `candidates` (texels of level `level`, each marked when
/// it is a jump) with the smallest sum of [`best_match`], a jump's sum
/// scaled by `jump_factor`; ties go to the lowest `y · width + x`. `None`
/// when `groups` or `candidates` is empty. The distance returned is the
/// unscaled sum.
pub fn best_candidate(
    images: &MatchImages,
    level: usize,
    groups: &MatchGroups,
    candidates: &[([u32; 2], bool)],
    jump_factor: f32,
) -> Option<BestMatch> {
    best_candidate_with(images, level, groups, candidates, jump_factor, 0.0, |_| 0.0)
}

/// [`best_candidate`] with an occurrence penalty: each candidate also costs
/// `spread × load(texel) × mean`, where `mean` is the mean sum over the
/// candidates (so the penalty is in the sums' units and vanishes where every
/// candidate matches exactly) and `load` how far the candidate's part of the
/// exemplar is over-used (0 = at most an even share). `spread = 0` is
/// [`best_candidate`].
pub fn best_candidate_with(
    images: &MatchImages,
    level: usize,
    groups: &MatchGroups,
    candidates: &[([u32; 2], bool)],
    jump_factor: f32,
    spread: f32,
    load: impl Fn([u32; 2]) -> f32,
) -> Option<BestMatch> {
    if groups.is_empty() || candidates.is_empty() {
        return None;
    }
    let w = images.planes(level).width as u32;
    let sum = |[x, y]: [u32; 2]| distance_at(images, groups, x as usize, y as usize);
    // The penalty's unit: the mean of the candidates' sums (0, and no
    // second pass over the candidates, when off or not finite).
    let weight = if spread > 0.0 {
        let mean = candidates.iter().map(|&(c, _)| sum(c)).sum::<f32>() / candidates.len() as f32;
        let weight = spread * mean;
        if weight.is_finite() { weight } else { 0.0 }
    } else {
        0.0
    };
    candidates
        .iter()
        .map(|&(c, jump)| {
            let d = sum(c);
            let mut cost = if jump { d * jump_factor } else { d };
            if weight > 0.0 {
                let l = load(c);
                if l > 0.0 {
                    cost += weight * l;
                }
            }
            (cost, c[1] * w + c[0], d)
        })
        .min_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)))
        .map(|(_, i, distance)| BestMatch {
            x: i % w,
            y: i / w,
            distance,
        })
}

/// The candidates `[x range, y range]` (half-open) of level `level` whose
/// every sample lies inside the exemplar. With `Wrap::Repeat` that is every
/// texel. With `Wrap::Clamp` a sample beyond the edge would read the edge
/// texel repeated, a flat streak that matches smooth, blurred
/// neighbourhoods better than any real texel does: searched over every
/// texel, Bangay–Morkel took 27 % of the planar brick's pixels from within
/// 2 texels of the exemplar's border (6 % of its texels). So only complete
/// neighbourhoods compete, as in Wei & Levoy's image synthesis. On an axis
/// where the samples span the whole exemplar no candidate is complete, and
/// every texel on that axis competes. The flag: whether every candidate
/// reads its samples without clamping (always with `Repeat`).
fn complete_box(
    images: &MatchImages,
    level: usize,
    groups: &MatchGroups,
) -> ([(usize, usize); 2], bool) {
    let planes = images.planes(level);
    let size = [planes.width, planes.height];
    let full = size.map(|n| (0, n));
    if images.wrap() == Wrap::Repeat {
        return (full, true);
    }
    let mut inside = true;
    let boxed = std::array::from_fn(|axis| {
        let (lo, hi) = groups.samples.iter().fold((0, 0), |(lo, hi), s| {
            (lo.min(s.offset[axis]), hi.max(s.offset[axis]))
        });
        let first = (-lo) as usize;
        let end = (size[axis] as i64 - hi as i64).max(0) as usize;
        if first < end {
            (first, end)
        } else {
            inside = false;
            full[axis]
        }
    });
    (boxed, inside)
}

/// The sum at one candidate, with exactly the operations of `score_tile`.
pub(super) fn distance_at(images: &MatchImages, groups: &MatchGroups, x: usize, y: usize) -> f32 {
    let ch = groups.channels;
    let mut acc = 0.0f32;
    for (g, s) in groups.samples.iter().enumerate() {
        let p = images.planes(s.level as usize);
        let mut t = 0.0f32;
        for c in 0..ch {
            let d = p.data[p.index(c, x, y, s.offset[0], s.offset[1])] - groups.colour[g * ch + c];
            t += d * d;
        }
        acc += groups.weight[g] * t;
    }
    acc
}

fn score_tile(
    images: &MatchImages,
    groups: &MatchGroups,
    y: usize,
    x0: usize,
    width: usize,
    xs: (usize, usize),
    bound: &AtomicU32,
) -> Option<(f32, u32)> {
    #[cfg(target_arch = "x86_64")]
    {
        if std::is_x86_feature_detected!("avx2") {
            // SAFETY: the processor supports AVX2 (checked just above).
            return unsafe { score_tile_avx2(images, groups, y, x0, width, xs, bound) };
        }
    }
    score_tile_generic(images, groups, y, x0, width, xs, bound)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn score_tile_avx2(
    images: &MatchImages,
    groups: &MatchGroups,
    y: usize,
    x0: usize,
    width: usize,
    xs: (usize, usize),
    bound: &AtomicU32,
) -> Option<(f32, u32)> {
    score_tile_generic(images, groups, y, x0, width, xs, bound)
}

#[inline(always)]
fn score_tile_generic(
    images: &MatchImages,
    groups: &MatchGroups,
    y: usize,
    x0: usize,
    width: usize,
    xs: (usize, usize),
    bound: &AtomicU32,
) -> Option<(f32, u32)> {
    let ch = groups.channels;
    let mut acc = [0.0f32; TILE];
    // Lanes `skip..live` are candidates; the rest start at infinity.
    let skip = xs.0.saturating_sub(x0).min(TILE);
    let live = (xs.1 - x0).min(TILE);
    acc[..skip].fill(f32::INFINITY);
    acc[live..].fill(f32::INFINITY);
    for (g, s) in groups.samples.iter().enumerate() {
        let p = images.planes(s.level as usize);
        let colour = &groups.colour[g * ch..(g + 1) * ch];
        let mut t = [0.0f32; TILE];
        for (c, &v) in colour.iter().enumerate() {
            let base = p.index(c, x0, y, s.offset[0], s.offset[1]);
            let row: &[f32; TILE] = p.data[base..base + TILE]
                .try_into()
                .expect("padded planes hold a whole tile");
            for i in 0..TILE {
                let d = row[i] - v;
                t[i] += d * d;
            }
        }
        let m = groups.weight[g];
        for i in 0..TILE {
            acc[i] += m * t[i];
        }
        // After every term: is any lane still within the bound? Written as
        // an OR of compares, which vectorises (a running minimum does not).
        let limit = f32::from_bits(bound.load(Ordering::Relaxed)) * PRUNE_SLACK;
        if !acc.iter().fold(false, |alive, &a| alive | (a <= limit)) {
            return None;
        }
    }
    let mut best = (acc[skip], skip);
    for (i, &a) in acc.iter().enumerate().take(live).skip(skip + 1) {
        if a < best.0 {
            best = (a, i);
        }
    }
    bound.fetch_min(best.0.to_bits(), Ordering::Relaxed);
    Some((best.0, (y * width + x0 + best.1) as u32))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::{Image, sample::Wrap};
    use crate::kernels::bangay_morkel::graph_match::stack::ImageLevels;

    fn noise(w: u32, h: u32, c: u32, seed: u32) -> Image {
        let mut s = seed;
        let data = (0..w * h * c)
            .map(|_| {
                s = s.wrapping_mul(1664525).wrapping_add(1013904223);
                (s >> 8) as f32 / (1u32 << 24) as f32
            })
            .collect();
        Image::from_data(w, h, c, data).unwrap()
    }

    /// The `(2r + 1)²` window of `img` around `q` as level-0 samples, each
    /// offset repeated `copies(dx, dy)` times, with its colours.
    fn window(
        img: &Image,
        images: &MatchImages,
        q: [i32; 2],
        r: i32,
        wrap: Wrap,
        copies: impl Fn(i32, i32) -> u32,
    ) -> (Vec<Sample>, Vec<f32>) {
        let mut samples = Vec::new();
        let mut colours = Vec::new();
        for dy in -r..=r {
            for dx in -r..=r {
                for _ in 0..copies(dx, dy) {
                    samples.push(Sample {
                        level: 0,
                        offset: images.reduce_offset(0, [dx, dy]),
                    });
                    colours.extend_from_slice(img.texel(
                        (q[0] + dx) as i64,
                        (q[1] + dy) as i64,
                        wrap,
                    ));
                }
            }
        }
        (samples, colours)
    }

    /// Groups reading `n` random texels within `radius` of the candidate on
    /// random levels below `levels`, some texels read several times, with
    /// the colours of the window at `q` (so `q` is near the best) perturbed
    /// by `noise` (0: `q` matches exactly).
    #[allow(clippy::too_many_arguments)]
    fn random_groups(
        images: &MatchImages,
        q: [i32; 2],
        n: usize,
        radius: i32,
        levels: u32,
        noise: f32,
        averaging: bool,
        seed: u32,
    ) -> MatchGroups {
        let mut s = seed.wrapping_mul(2654435761).wrapping_add(1);
        let mut next = move |m: u32| {
            s ^= s << 13;
            s ^= s >> 17;
            s ^= s << 5;
            s % m
        };
        let ch = images.channels();
        let mut samples = Vec::new();
        let mut colours = Vec::new();
        for _ in 0..n {
            let level = next(levels);
            let o = [
                next(2 * radius as u32 + 1) as i32 - radius,
                next(2 * radius as u32 + 1) as i32 - radius,
            ];
            let img = images.image(level as usize);
            let px = img.texel((q[0] + o[0]) as i64, (q[1] + o[1]) as i64, images.wrap());
            for _ in 0..1 + next(3) {
                samples.push(Sample {
                    level,
                    offset: images.reduce_offset(level as usize, o),
                });
                for &v in px.iter().take(ch) {
                    colours.push(v + noise * (next(1000) as f32 / 1000.0 - 0.5));
                }
            }
        }
        let mut g = MatchGroups::new();
        g.build(&samples, &colours, ch, averaging);
        g
    }

    /// The FFT search returns exactly the tile search's winner and sum (bit
    /// for bit), over exemplar sizes that are not powers of two, both
    /// addressings, samples on several stack levels, with and without
    /// averaging, from an exact copy (sum 0) to far from any.
    #[test]
    fn spectral_search_picks_the_tile_search_winner() {
        let mut checked = 0;
        for (w, h, c) in [(45u32, 37u32, 3u32), (64, 48, 3), (33, 50, 1), (40, 30, 4)] {
            for wrap in [Wrap::Repeat, Wrap::Clamp] {
                let img = noise(w, h, c, w + h + c);
                let images = MatchImages::new(&img, ImageLevels::Stack, 3, wrap);
                for (i, noise) in [0.0f32, 0.05, 0.4, 2.0].into_iter().enumerate() {
                    for averaging in [true, false] {
                        let seed = i as u32 * 7 + averaging as u32 + w;
                        let q = [(seed % w) as i32, (seed * 3 % h) as i32];
                        let g = random_groups(&images, q, 60, 5, 3, noise, averaging, seed);
                        let t = best_match_by(&images, 0, &g, &[], false, Search::Tiles).unwrap();
                        // Every level transformed, or one (the others
                        // summed at the candidates it does not rule out).
                        for only in [None, Some(0), Some(2)] {
                            let s =
                                best_match_by(&images, 0, &g, &[], false, Search::Spectral(only));
                            let s = s.unwrap();
                            assert_eq!(
                                (t.x, t.y, t.distance.to_bits()),
                                (s.x, s.y, s.distance.to_bits()),
                                "{w}x{h}x{c} {wrap:?} noise {noise} averaging {averaging} {only:?}"
                            );
                            checked += 1;
                        }
                    }
                }
            }
        }
        assert_eq!(checked, 192);
    }

    /// On an exemplar made of one 8 × 8 tile repeated, a window copied from
    /// it matches exactly (sum 0) at every repeat: both searches return
    /// the same one, the lowest `y · width + x`, so exact ties fall as the
    /// tile search breaks them. On a pyramid, a search on level 1 with
    /// samples on level 1 agrees too.
    #[test]
    fn spectral_search_breaks_exact_ties_like_the_tile_search() {
        let tile = noise(8, 8, 3, 5);
        let (w, h) = (48u32, 40u32);
        let mut data = Vec::new();
        for y in 0..h {
            for x in 0..w {
                data.extend_from_slice(tile.texel(x as i64 % 8, y as i64 % 8, Wrap::Repeat));
            }
        }
        let img = Image::from_data(w, h, 3, data).unwrap();
        for wrap in [Wrap::Repeat, Wrap::Clamp] {
            let images = MatchImages::new(&img, ImageLevels::Stack, 1, wrap);
            let g = random_groups(&images, [29, 21], 40, 3, 1, 0.0, true, 9);
            let t = best_match_by(&images, 0, &g, &[], false, Search::Tiles).unwrap();
            let s = best_match_by(&images, 0, &g, &[], false, Search::Spectral(None)).unwrap();
            assert_eq!(t.distance, 0.0);
            assert_eq!((t.x, t.y, t.distance), (s.x, s.y, s.distance), "{wrap:?}");
            // The lowest of the exact copies (29 − 8·3, 21 − 8·2 with
            // repeat; with clamp the first complete one).
            assert!(t.x < 8 + 3 && t.y < 8 + 3, "({}, {})", t.x, t.y);
        }
        let images = MatchImages::new(&noise(64, 64, 3, 8), ImageLevels::Pyramid, 3, Wrap::Repeat);
        let mut g = random_groups(&images, [11, 20], 30, 2, 1, 0.1, true, 4);
        // Move every sample to level 1 (32 × 32).
        let samples: Vec<Sample> = g
            .samples()
            .iter()
            .map(|s| Sample {
                level: 1,
                offset: images.reduce_offset(1, s.offset),
            })
            .collect();
        let colours = g.colour().to_vec();
        let weights: Vec<f32> = g.weight().to_vec();
        let mut expanded = Vec::new();
        let mut expanded_colours = Vec::new();
        for (i, s) in samples.iter().enumerate() {
            for _ in 0..weights[i] as usize {
                expanded.push(*s);
                expanded_colours.extend_from_slice(&colours[i * 3..i * 3 + 3]);
            }
        }
        g.build(&expanded, &expanded_colours, 3, true);
        let t = best_match_by(&images, 1, &g, &[], false, Search::Tiles).unwrap();
        let s = best_match_by(&images, 1, &g, &[], false, Search::Spectral(None)).unwrap();
        assert_eq!((t.x, t.y, t.distance), (s.x, s.y, s.distance));
        assert!(t.x < 32 && t.y < 32);
    }

    /// A repeating 40 × 30 noise exemplar and the groups of its own 3 × 3
    /// window at (17, 9) (sum 0 there).
    fn window_at_17_9() -> (MatchImages, MatchGroups) {
        let img = noise(40, 30, 3, 3);
        let images = MatchImages::new(&img, ImageLevels::Stack, 1, Wrap::Repeat);
        let (samples, colours) = window(&img, &images, [17, 9], 1, Wrap::Repeat, |_, _| 1);
        let mut g = MatchGroups::new();
        g.build(&samples, &colours, 3, true);
        (images, g)
    }

    #[test]
    fn best_candidate_prefers_shifts_by_the_jump_factor() {
        let (images, g) = window_at_17_9();
        let exact = best_match(&images, 0, &g, &[], false).unwrap();
        assert_eq!((exact.x, exact.y), (17, 9));
        let other = [3u32, 4];
        let d_other = best_candidate(&images, 0, &g, &[(other, false)], 1.0)
            .unwrap()
            .distance;
        assert!(d_other > 0.0);
        // The window itself (sum 0) wins even as a jump.
        let both = [([17u32, 9u32], true), (other, false)];
        let b = best_candidate(&images, 0, &g, &both, 1.0).unwrap();
        assert_eq!((b.x, b.y, b.distance), (17, 9, 0.0));
        // A jump whose sum is above a shift's never wins; one below it wins
        // only when below by more than the factor.
        let (near, far) = ([18u32, 9u32], [16u32, 9u32]);
        let d = |c: [u32; 2]| {
            best_candidate(&images, 0, &g, &[(c, false)], 1.0)
                .unwrap()
                .distance
        };
        let (lo, hi) = if d(near) < d(far) {
            (near, far)
        } else {
            (far, near)
        };
        let ratio = d(hi) / d(lo);
        assert!(ratio > 1.0);
        let pick = |f: f32| {
            let b = best_candidate(&images, 0, &g, &[(hi, false), (lo, true)], f).unwrap();
            [b.x, b.y]
        };
        assert_eq!(pick(1.0), lo);
        assert_eq!(pick(ratio * 1.01), hi);
        assert!(best_candidate(&images, 0, &g, &[], 1.0).is_none());
    }

    #[test]
    fn an_over_used_candidate_loses_by_the_occurrence_penalty() {
        let (images, g) = window_at_17_9();
        let (exact, other) = ([17u32, 9u32], [3u32, 4u32]);
        let cands = [(exact, false), (other, false)];
        let pick = |spread: f32, load_exact: f32| {
            let b = best_candidate_with(&images, 0, &g, &cands, 1.0, spread, |c| {
                if c == exact { load_exact } else { 0.0 }
            })
            .unwrap();
            [b.x, b.y]
        };
        // Off, or not over-used: the exact window (sum 0) wins.
        assert_eq!(pick(0.0, 10.0), exact);
        assert_eq!(pick(1.0, 0.0), exact);
        // Its penalty is spread · load · (mean of the two sums) = 1.5 × the
        // other's sum: the other wins; at 0.5 × it does not.
        assert_eq!(pick(1.0, 3.0), other);
        assert_eq!(pick(1.0, 1.0), exact);
        // spread 0 is `best_candidate`.
        let b = best_candidate(&images, 0, &g, &cands, 1.0).unwrap();
        assert_eq!([b.x, b.y], exact);
    }

    #[test]
    fn finds_a_copied_window_with_and_without_averaging_and_pruning() {
        for wrap in [Wrap::Repeat, Wrap::Clamp] {
            let img = noise(45, 37, 3, 7);
            let images = MatchImages::new(&img, ImageLevels::Stack, 1, wrap);
            let (samples, colours) = window(&img, &images, [40, 3], 2, wrap, |dx, dy| {
                1 + (dx + dy).unsigned_abs() % 3
            });
            for averaging in [false, true] {
                let mut g = MatchGroups::new();
                g.build(&samples, &colours, 3, averaging);
                assert_eq!(g.len(), if averaging { 25 } else { samples.len() });
                for (seeds, parallel) in [
                    (vec![], false),
                    (vec![[1, 1]], true),
                    (vec![[40, 3]], false),
                ] {
                    let b = best_match(&images, 0, &g, &seeds, parallel).unwrap();
                    assert_eq!((b.x, b.y), (40, 3), "{wrap:?} averaging {averaging}");
                    assert!(b.distance < 1e-6);
                }
            }
        }
    }

    /// With `Clamp`, a candidate whose samples would leave the exemplar
    /// does not compete, even when the edge texel repeated matches exactly:
    /// the winner is the best complete neighbourhood, found by brute force
    /// over the texels where every sample is inside. With `Repeat` every
    /// texel competes, and there the edge streak does not exist.
    #[test]
    fn clamped_candidates_compete_only_with_complete_neighbourhoods() {
        let (w, h) = (45u32, 37u32);
        let mut img = noise(w, h, 3, 11);
        // The last column is one flat colour, which the clamp repeats.
        let flat = [0.25f32, 0.5, 0.75];
        for y in 0..h {
            let i = ((y * w + w - 1) * 3) as usize;
            img.data[i..i + 3].copy_from_slice(&flat);
        }
        let images = MatchImages::new(&img, ImageLevels::Stack, 1, Wrap::Clamp);
        // A row of 4 samples, offsets 0..=3, all of the flat colour: at
        // x = w − 1 the clamp reads the flat colour 4 times, a sum of 0.
        let samples: Vec<Sample> = (0..4)
            .map(|dx| Sample {
                level: 0,
                offset: images.reduce_offset(0, [dx, 0]),
            })
            .collect();
        let colours: Vec<f32> = (0..4).flat_map(|_| flat).collect();
        let mut g = MatchGroups::new();
        g.build(&samples, &colours, 3, true);
        assert_eq!(distance_at(&images, &g, w as usize - 1, 5), 0.0);
        let b = best_match(&images, 0, &g, &[[w as i32 - 1, 5]], false).unwrap();
        assert!(b.x + 3 < w, "x = {} leaves the exemplar", b.x);
        let mut brute = (f32::INFINITY, 0, 0);
        for y in 0..h as usize {
            for x in 0..(w - 3) as usize {
                let d = distance_at(&images, &g, x, y);
                if d < brute.0 {
                    brute = (d, x as u32, y as u32);
                }
            }
        }
        assert_eq!((b.distance, b.x, b.y), brute);
        // Offsets spanning more than the exemplar's width (−(w − 1) and
        // +1): no candidate is complete on x, so every column competes
        // again (the brute-force minimum over every texel).
        let wide = [[1, 0], [-(w as i32 - 1), 0]].map(|o| Sample {
            level: 0,
            offset: images.reduce_offset(0, o),
        });
        let mut g = MatchGroups::new();
        g.build(&wide, &[flat, flat].concat(), 3, true);
        let b = best_match(&images, 0, &g, &[], true).unwrap();
        let mut brute = (f32::INFINITY, 0, 0);
        for y in 0..h as usize {
            for x in 0..w as usize {
                let d = distance_at(&images, &g, x, y);
                if d < brute.0 {
                    brute = (d, x as u32, y as u32);
                }
            }
        }
        assert_eq!((b.distance, b.x, b.y), brute);
    }
}
