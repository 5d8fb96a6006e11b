//! Exhaustive nearest-neighbourhood search over every toroidal position of an
//! exemplar, vectorised over eight horizontally adjacent positions at a time.

use wide::f32x8;

use crate::image::Image;

/// An exemplar laid out for the search: one plane per channel, extended
/// toroidally by `n - 1` rows and columns (and to a multiple of 16 columns),
/// so the `n`×`n` window of every position is a plain rectangle of each plane
/// and eight adjacent positions read eight contiguous values.
#[derive(Clone, Debug)]
pub struct ExemplarNeighbourhoods {
    planes: Vec<f32>,
    /// Padded plane width and height.
    pw: usize,
    ph: usize,
    /// Exemplar height (rows of positions).
    height: usize,
    /// Column blocks of 16 positions per row.
    blocks: usize,
    n: usize,
    channels: usize,
}

/// Value of the padding columns of [`ExemplarNeighbourhoods::interior`]: a
/// window touching it is at squared distance ≥ 10⁴ per value from any query
/// in `[0, 1]`, so it never wins.
const PAD: f32 = 100.0;

/// One term of a query: plane offset relative to the window origin, and value.
#[derive(Clone, Copy, Debug)]
struct Tap {
    offset: usize,
    value: f32,
}

/// Reusable buffers of a query, one per thread.
#[derive(Clone, Debug, Default)]
pub struct QueryScratch {
    taps: Vec<Tap>,
    /// Tap index where each neighbourhood row ends (for early exit).
    row_ends: Vec<usize>,
}

impl ExemplarNeighbourhoods {
    /// Prepares the `n`×`n` windows of `exemplar`, addressed toroidally.
    ///
    /// Preconditions: `n >= 1`; the exemplar has at least one pixel.
    pub fn new(exemplar: &Image, n: u32) -> Self {
        let n = n.max(1) as usize;
        let (w, h) = (exemplar.width as usize, exemplar.height as usize);
        let channels = exemplar.channels as usize;
        let w16 = w.div_ceil(16) * 16;
        let pw = w16 + n - 1;
        let ph = h + n - 1;
        let plane = pw * ph;
        let mut planes = vec![0.0f32; plane * channels];
        for y in 0..ph {
            for x in 0..pw {
                let px = exemplar.pixel((x % w) as u32, (y % h) as u32);
                for (c, &v) in px.iter().enumerate() {
                    planes[c * plane + y * pw + x] = v;
                }
            }
        }
        Self {
            planes,
            pw,
            ph,
            height: h,
            blocks: w16 / 16,
            n,
            channels,
        }
    }

    /// Prepares the `n`×`n` windows of `image` that lie wholly inside it (no
    /// wrap-around): `(w − n + 1) × (h − n + 1)` positions. Used where the
    /// searched image is a synthesis result, whose opposite borders do not
    /// meet. Padding positions hold a value far outside `[0, 1]` so they are
    /// never the nearest (queries are assumed to have values in `[0, 1]`).
    ///
    /// Preconditions: `1 <= n <= min(width, height)`.
    pub fn interior(image: &Image, n: u32) -> Self {
        let n = n.max(1) as usize;
        let (w, h) = (image.width as usize, image.height as usize);
        assert!(n <= w && n <= h, "window larger than the image");
        let channels = image.channels as usize;
        let cols = w - n + 1;
        let w16 = cols.div_ceil(16) * 16;
        let pw = w16 + n - 1;
        let ph = h;
        let plane = pw * ph;
        let mut planes = vec![PAD; plane * channels];
        for y in 0..h {
            for x in 0..w {
                let px = image.pixel(x as u32, y as u32);
                for (c, &v) in px.iter().enumerate() {
                    planes[c * plane + y * pw + x] = v;
                }
            }
        }
        Self {
            planes,
            pw,
            ph,
            height: h - n + 1,
            blocks: w16 / 16,
            n,
            channels,
        }
    }

    /// Window side.
    pub fn n(&self) -> usize {
        self.n
    }

    /// Channels per pixel.
    pub fn channels(&self) -> usize {
        self.channels
    }

    /// Smallest sum of squared differences between `query` and any exemplar
    /// window, over the pixels where `mask` is true (all when `None`).
    ///
    /// `query` holds `n·n·channels` values, row-major with interleaved
    /// channels (value `c` of window pixel `(dx, dy)` at
    /// `(dy·n + dx)·channels + c`); `mask` holds `n·n` flags in the same
    /// pixel order. Returns 0 when the mask is all false.
    ///
    /// Partial-distance early exit: a block of positions is abandoned after a
    /// window row once all its partial sums reach the best so far. The sums
    /// only grow, so the result equals the exhaustive minimum exactly.
    pub fn nearest_sq_distance(
        &self,
        query: &[f32],
        mask: Option<&[bool]>,
        scratch: &mut QueryScratch,
    ) -> f32 {
        let (n, ch) = (self.n, self.channels);
        assert_eq!(query.len(), n * n * ch, "query size");
        let plane = self.pw * self.ph;
        scratch.taps.clear();
        scratch.row_ends.clear();
        for dy in 0..n {
            for c in 0..ch {
                for dx in 0..n {
                    if mask.is_some_and(|m| !m[dy * n + dx]) {
                        continue;
                    }
                    scratch.taps.push(Tap {
                        offset: c * plane + dy * self.pw + dx,
                        value: query[(dy * n + dx) * ch + c],
                    });
                }
            }
            if scratch.row_ends.last() != Some(&scratch.taps.len()) {
                scratch.row_ends.push(scratch.taps.len());
            }
        }
        if scratch.taps.is_empty() {
            return 0.0;
        }
        let planes = &self.planes[..];
        let load = |i: usize| -> f32x8 {
            let a: [f32; 8] = planes[i..i + 8].try_into().expect("8 values");
            f32x8::new(a)
        };
        let mut best = f32::INFINITY;
        for y in 0..self.height {
            for b in 0..self.blocks {
                let base = y * self.pw + b * 16;
                // Two blocks of eight positions, two independent sums each.
                let mut acc_a = f32x8::ZERO;
                let mut acc_b = f32x8::ZERO;
                let mut start = 0;
                let mut pruned = false;
                for &end in &scratch.row_ends {
                    for tap in &scratch.taps[start..end] {
                        let q = f32x8::splat(tap.value);
                        let da = load(base + tap.offset) - q;
                        let db = load(base + tap.offset + 8) - q;
                        acc_a += da * da;
                        acc_b += db * db;
                    }
                    start = end;
                    let bound = f32x8::splat(best);
                    if acc_a.simd_ge(bound).all() && acc_b.simd_ge(bound).all() {
                        pruned = true;
                        break;
                    }
                }
                if !pruned {
                    let m = acc_a.min(acc_b).to_array();
                    best = m.iter().fold(best, |x, &y| x.min(y));
                }
            }
        }
        best
    }
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;

    /// Straightforward scalar search, for comparison.
    fn brute(ex: &Image, n: usize, query: &[f32], mask: Option<&[bool]>) -> f32 {
        let ch = ex.channels as usize;
        let mut best = f32::INFINITY;
        for y in 0..ex.height as i64 {
            for x in 0..ex.width as i64 {
                let mut d = 0.0;
                for dy in 0..n {
                    for dx in 0..n {
                        if mask.is_some_and(|m| !m[dy * n + dx]) {
                            continue;
                        }
                        let p = ex.texel(
                            x + dx as i64,
                            y + dy as i64,
                            crate::image::sample::Wrap::Repeat,
                        );
                        for c in 0..ch {
                            let e = p[c] - query[(dy * n + dx) * ch + c];
                            d += e * e;
                        }
                    }
                }
                best = best.min(d);
            }
        }
        best
    }

    /// Values in `[0, 1)` from a xorshift stream seeded with `seed`.
    pub(in crate::kernels::metrics) fn pseudo_random(len: usize, seed: u32) -> Vec<f32> {
        let mut s = seed.wrapping_mul(2_654_435_761).wrapping_add(1);
        (0..len)
            .map(|_| {
                s ^= s << 13;
                s ^= s >> 17;
                s ^= s << 5;
                (s % 1000) as f32 / 1000.0
            })
            .collect()
    }

    #[test]
    fn matches_brute_force_on_odd_sizes_with_and_without_mask() {
        for (w, h, ch, n) in [(13u32, 7u32, 3u32, 5usize), (20, 19, 1, 3), (3, 4, 2, 7)] {
            let ex = Image::from_data(w, h, ch, pseudo_random((w * h * ch) as usize, w)).unwrap();
            let search = ExemplarNeighbourhoods::new(&ex, n as u32);
            let mut scratch = QueryScratch::default();
            for k in 0..5 {
                let q = pseudo_random(n * n * ch as usize, 100 + k);
                let mask: Vec<bool> = (0..n * n)
                    .map(|i| !(i + k as usize).is_multiple_of(3))
                    .collect();
                for m in [None, Some(&mask[..])] {
                    let fast = search.nearest_sq_distance(&q, m, &mut scratch);
                    let slow = brute(&ex, n, &q, m);
                    assert!(
                        (fast - slow).abs() <= 1e-4 * slow.max(1.0),
                        "{w}x{h}x{ch} n{n}: {fast} vs {slow}"
                    );
                }
            }
            // A window cut from the exemplar (across the wrap) is found exactly.
            let mut q = vec![0.0; n * n * ch as usize];
            for dy in 0..n {
                for dx in 0..n {
                    let p = ex.texel(
                        w as i64 - 2 + dx as i64,
                        1 + dy as i64,
                        crate::image::sample::Wrap::Repeat,
                    );
                    q[(dy * n + dx) * ch as usize..][..ch as usize].copy_from_slice(p);
                }
            }
            assert_eq!(search.nearest_sq_distance(&q, None, &mut scratch), 0.0);
        }
    }

    /// Scalar search over the windows wholly inside the image.
    fn brute_interior(img: &Image, n: usize, query: &[f32]) -> f32 {
        let ch = img.channels as usize;
        let mut best = f32::INFINITY;
        for y in 0..=(img.height as usize - n) {
            for x in 0..=(img.width as usize - n) {
                let mut d = 0.0;
                for dy in 0..n {
                    for dx in 0..n {
                        let p = img.pixel((x + dx) as u32, (y + dy) as u32);
                        for c in 0..ch {
                            let e = p[c] - query[(dy * n + dx) * ch + c];
                            d += e * e;
                        }
                    }
                }
                best = best.min(d);
            }
        }
        best
    }

    #[test]
    fn interior_windows_match_brute_force_and_never_wrap() {
        for (w, h, ch, n) in [(23u32, 9u32, 3u32, 5usize), (17, 17, 1, 3), (7, 8, 2, 7)] {
            let img = Image::from_data(w, h, ch, pseudo_random((w * h * ch) as usize, h)).unwrap();
            let search = ExemplarNeighbourhoods::interior(&img, n as u32);
            let mut scratch = QueryScratch::default();
            for k in 0..5 {
                let q = pseudo_random(n * n * ch as usize, 200 + k);
                let fast = search.nearest_sq_distance(&q, None, &mut scratch);
                let slow = brute_interior(&img, n, &q);
                assert!(
                    (fast - slow).abs() <= 1e-4 * slow.max(1.0),
                    "{w}x{h}x{ch} n{n}: {fast} vs {slow}"
                );
            }
        }
    }
}
