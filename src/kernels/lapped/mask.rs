//! Texture patches (Praun et al. 2000 §3.1): a region of the exemplar with
//! an alpha mask that falls off near the region's boundary, so that pastes
//! blend into each other.
//!
//! Masks are boolean images (inside / outside). Predefined shapes are a
//! circle and a seeded irregular "splotch" (for homogeneous and stochastic
//! textures); a user mask is an image of the exemplar's size whose white
//! pixels are inside (for structured textures whose patch outline follows
//! features such as the grout between bricks). The alpha of an inside pixel
//! is its Euclidean distance to the nearest outside pixel divided by the
//! falloff (default 3 pixels), clamped to 1.

use super::LappedError;
use super::hull::{Hull, mask_hull};
use crate::image::Image;
use crate::image::sample::Wrap;
use glam::Vec2;
use rand::{Rng, SeedableRng};

/// A boolean mask: `inside[y * width + x]`.
#[derive(Clone, Debug, PartialEq)]
pub struct Mask {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Row-major inside flags.
    pub inside: Vec<bool>,
}

impl Mask {
    /// Whether pixel `(x, y)` is inside; pixels off the image are outside.
    #[inline]
    pub fn at(&self, x: i64, y: i64) -> bool {
        x >= 0
            && y >= 0
            && x < self.width as i64
            && y < self.height as i64
            && self.inside[(y * self.width as i64 + x) as usize]
    }

    /// Number of inside pixels.
    pub fn count(&self) -> usize {
        self.inside.iter().filter(|&&b| b).count()
    }
}

/// A star-shaped mask of side `size` whose radius at angle `θ` is
/// `radius(θ)` pixels around the centre (pixel centres are tested).
fn star_mask(size: u32, radius: impl Fn(f32) -> f32) -> Mask {
    star_mask_within(size, (0.0, f32::INFINITY), radius)
}

/// [`star_mask`] for an outline known to lie within `bounds = (lo, hi)`
/// pixels of the centre: a pixel nearer than `lo` is inside and one
/// farther than `hi` outside without evaluating `radius` (its angle and
/// harmonics are the cost), the same mask as [`star_mask`].
fn star_mask_within(size: u32, bounds: (f32, f32), radius: impl Fn(f32) -> f32) -> Mask {
    let c = size as f32 / 2.0;
    let inside = (0..size * size)
        .map(|i| {
            let d = Vec2::new((i % size) as f32 + 0.5 - c, (i / size) as f32 + 0.5 - c);
            let len = d.length();
            if len < bounds.0 {
                true
            } else if len > bounds.1 {
                false
            } else {
                len <= radius(d.y.atan2(d.x))
            }
        })
        .collect();
    Mask {
        width: size,
        height: size,
        inside,
    }
}

/// A disc filling a `size × size` square, leaving a one-pixel transparent
/// border (so clamped texture look-ups outside the patch are transparent).
pub fn circle_mask(size: u32) -> Mask {
    let r = size as f32 / 2.0 - 1.0;
    star_mask(size, |_| r)
}

/// A seeded irregular blob ("splotch", §3.1) in a `size × size` square: a
/// star-shaped outline whose radius is a sum of a few random low-frequency
/// harmonics, between about 55 % and 100 % of the largest radius that keeps
/// a one-pixel transparent border.
pub fn splotch_mask(size: u32, seed: u64) -> Mask {
    splotch(size, seed, true)
}

/// [`splotch_mask`], with (`bounded`) or without the radii that spare most
/// pixels the outline's evaluation (the same mask either way).
fn splotch(size: u32, seed: u64, bounded: bool) -> Mask {
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(seed);
    let harmonics: Vec<(f32, f32, f32)> = (2..=6)
        .map(|k| {
            let amplitude = rng.random_range(0.3..1.0f32) / k as f32;
            let phase = rng.random_range(0.0..std::f32::consts::TAU);
            (k as f32, amplitude, phase)
        })
        .collect();
    let shape = |theta: f32| -> f32 {
        harmonics
            .iter()
            .map(|&(k, a, p)| a * (k * theta + p).cos())
            .sum()
    };
    // Normalise the shape to [0.55, 1] of the largest radius.
    let samples: Vec<f32> = (0..720)
        .map(|i| shape(i as f32 / 720.0 * std::f32::consts::TAU))
        .collect();
    let lo = samples.iter().copied().fold(f32::INFINITY, f32::min);
    let hi = samples.iter().copied().fold(f32::NEG_INFINITY, f32::max);
    let span = (hi - lo).max(1e-6);
    let r_max = size as f32 / 2.0 - 1.0;
    // Between two of the 720 samples the shape moves at most
    // `Σ k·a_k · (half a step)` from the nearer one, so the outline lies
    // within these radii (with a margin for rounding).
    let slope: f32 = harmonics.iter().map(|&(k, a, _)| k * a).sum();
    let drift = slope * std::f32::consts::TAU / 720.0 / 2.0;
    let bounds = if bounded {
        (
            r_max * (0.55 - 0.45 * drift / span) * (1.0 - 1e-3) - 1e-3,
            r_max * (1.0 + 0.45 * drift / span) * (1.0 + 1e-3) + 1e-3,
        )
    } else {
        (0.0, f32::INFINITY)
    };
    star_mask_within(size, bounds, |theta| {
        r_max * (0.55 + 0.45 * (shape(theta) - lo) / span)
    })
}

/// The mask of a user image: pixels whose mean channel value is at least
/// 0.5 are inside (white = inside). Alpha, when present, is ignored.
pub fn mask_from_image(img: &Image) -> Mask {
    let c = img.channels as usize;
    let grey = if c >= 3 { 3 } else { 1 };
    let inside = img
        .data
        .chunks_exact(c.max(1))
        .map(|px| px[..grey].iter().sum::<f32>() / grey as f32 >= 0.5)
        .collect();
    Mask {
        width: img.width,
        height: img.height,
        inside,
    }
}

/// Squared Euclidean distance from each pixel centre to the nearest outside
/// pixel centre (0 outside), treating everything off the image as outside.
/// Exact, by the separable transform of Felzenszwalb & Huttenlocher (2012).
pub fn distance_to_outside_sq(mask: &Mask) -> Vec<f32> {
    let (w, h) = (mask.width as usize, mask.height as usize);
    // Pad by one outside pixel on every side so the image border counts.
    let (pw, ph) = (w + 2, h + 2);
    let big = ((pw * pw + ph * ph) as f32) * 4.0;
    let mut f = vec![0.0f32; pw * ph];
    for y in 0..h {
        for x in 0..w {
            if mask.inside[y * w + x] {
                f[(y + 1) * pw + x + 1] = big;
            }
        }
    }
    let mut column = vec![0.0f32; ph.max(pw)];
    let mut out = vec![0.0f32; ph.max(pw)];
    for x in 0..pw {
        for y in 0..ph {
            column[y] = f[y * pw + x];
        }
        edt_1d(&column[..ph], &mut out[..ph]);
        for y in 0..ph {
            f[y * pw + x] = out[y];
        }
    }
    for y in 0..ph {
        column[..pw].copy_from_slice(&f[y * pw..(y + 1) * pw]);
        edt_1d(&column[..pw], &mut out[..pw]);
        f[y * pw..(y + 1) * pw].copy_from_slice(&out[..pw]);
    }
    let mut d = vec![0.0f32; w * h];
    for y in 0..h {
        for x in 0..w {
            d[y * w + x] = f[(y + 1) * pw + x + 1];
        }
    }
    d
}

/// One-dimensional squared distance transform of sampled function `f`
/// (lower envelope of parabolas).
fn edt_1d(f: &[f32], d: &mut [f32]) {
    let n = f.len();
    let mut v = vec![0usize; n];
    let mut z = vec![0.0f32; n + 1];
    let mut k = 0usize;
    z[0] = f32::NEG_INFINITY;
    z[1] = f32::INFINITY;
    for q in 1..n {
        loop {
            let p = v[k];
            let s = ((f[q] + (q * q) as f32) - (f[p] + (p * p) as f32)) / (2.0 * (q - p) as f32);
            if s <= z[k] && k > 0 {
                k -= 1;
            } else {
                k += 1;
                v[k] = q;
                z[k] = s;
                z[k + 1] = f32::INFINITY;
                break;
            }
        }
    }
    k = 0;
    for (q, out) in d.iter_mut().enumerate() {
        while z[k + 1] < q as f32 {
            k += 1;
        }
        let p = v[k];
        let dq = q as f32 - p as f32;
        *out = dq * dq + f[p];
    }
}

/// Alpha of each mask pixel: distance to the outside over `falloff` pixels,
/// clamped to `[0, 1]`; a falloff of 0 gives a hard mask.
pub fn alpha_from_mask(mask: &Mask, falloff: f32) -> Vec<f32> {
    alpha_from_distances(mask, &distance_to_outside_sq(mask), falloff)
}

/// [`alpha_from_mask`] from the mask's [`distance_to_outside_sq`].
fn alpha_from_distances(mask: &Mask, d2: &[f32], falloff: f32) -> Vec<f32> {
    d2.iter()
        .zip(&mask.inside)
        .map(|(&d2, &inside)| {
            if !inside {
                0.0
            } else if falloff <= 0.0 {
                1.0
            } else {
                (d2.sqrt() / falloff).min(1.0)
            }
        })
        .collect()
}

/// A texture patch ready for pasting.
#[derive(Clone, Debug)]
pub struct TexturePatch {
    /// The patch colours with alpha: RGBA, straight (not premultiplied).
    pub image: Image,
    /// Its alpha channel on its own (for the coverage rasteriser).
    pub alpha: Vec<f32>,
    /// The patch centre in pixels (x right, y down): the inside point
    /// farthest from the outside, so the paste's seed point is opaque.
    pub centre_px: Vec2,
    /// The conservative polygonal hull of the non-transparent pixels, in
    /// patch units around the centre (§3.3).
    pub hull: Hull,
    /// The exemplar pixel of the patch's top-left pixel (before wrapping):
    /// patch pixel `(x, y)` is exemplar texel `origin + (x, y)`, so other
    /// exemplar channels can follow a paste (issue 7).
    pub origin: [i64; 2],
}

/// The RGBA image of a `w × h` texture patch whose top-left pixel is
/// exemplar texel `origin` (addressed with `wrap`; grey repeated), with
/// `alpha` (row-major, `w · h`) as its alpha channel.
pub fn patch_image(
    exemplar: &Image,
    wrap: Wrap,
    origin: [i64; 2],
    w: u32,
    h: u32,
    alpha: &[f32],
) -> Image {
    let mut image = Image::new(w, h, 4);
    let c = exemplar.channels as usize;
    for y in 0..h {
        for x in 0..w {
            let src = exemplar.texel(origin[0] + x as i64, origin[1] + y as i64, wrap);
            let rgb = match c {
                1 | 2 => [src[0]; 3],
                _ => [src[0], src[1], src[2]],
            };
            let a = alpha[(y * w + x) as usize];
            image
                .pixel_mut(x, y)
                .copy_from_slice(&[rgb[0], rgb[1], rgb[2], a]);
        }
    }
    image
}

impl TexturePatch {
    /// Cuts a texture patch out of `exemplar`: the `mask.width ×
    /// mask.height` region whose top-left pixel is `origin` (addressed with
    /// `wrap`, so a tileable exemplar may be cut across its border), with
    /// the mask's alpha (see [`alpha_from_mask`]). `hull_vertices` bounds
    /// the hull's vertex count.
    ///
    /// # Errors
    /// [`LappedError::EmptyMask`] when the mask has no inside pixel.
    pub fn cut(
        exemplar: &Image,
        wrap: Wrap,
        origin: [i64; 2],
        mask: &Mask,
        falloff: f32,
        hull_vertices: usize,
        what: &str,
    ) -> Result<Self, LappedError> {
        if mask.count() == 0 {
            return Err(LappedError::EmptyMask { what: what.into() });
        }
        let (w, h) = (mask.width, mask.height);
        let d2 = distance_to_outside_sq(mask);
        let alpha = alpha_from_distances(mask, &d2, falloff);
        let image = patch_image(exemplar, wrap, origin, w, h, &alpha);
        // The centre: the mean of the pixels farthest from the outside.
        let best = d2.iter().copied().fold(0.0f32, f32::max);
        let (mut sum, mut n) = (Vec2::ZERO, 0.0f32);
        for (i, &d) in d2.iter().enumerate() {
            if d == best {
                sum += Vec2::new((i as u32 % w) as f32 + 0.5, (i as u32 / w) as f32 + 0.5);
                n += 1.0;
            }
        }
        let mut centre_px = sum / n;
        // A non-convex set of farthest pixels could average to an outside
        // point: then take the first farthest pixel.
        if !mask.at(centre_px.x as i64, centre_px.y as i64) {
            let i = d2.iter().position(|&d| d == best).unwrap_or(0) as u32;
            centre_px = Vec2::new((i % w) as f32 + 0.5, (i / w) as f32 + 0.5);
        }
        let visible = Mask {
            width: w,
            height: h,
            inside: alpha.iter().map(|&a| a > 0.0).collect(),
        };
        let unit = w.max(h) as f32;
        let hull = mask_hull(&visible, centre_px, unit, hull_vertices);
        Ok(Self {
            image,
            alpha,
            centre_px,
            hull,
            origin,
        })
    }

    /// Pixels per patch unit: `max(width, height)`.
    #[inline]
    pub fn unit_px(&self) -> f32 {
        self.image.width.max(self.image.height) as f32
    }

    /// Texture coordinates (`[0, 1]` over the patch image, `v = 0` at the top
    /// row) of the patch-unit point `st` (`s` right, `t` up, origin at the
    /// centre).
    #[inline]
    pub fn uv_of(&self, st: Vec2) -> Vec2 {
        let unit = self.unit_px();
        Vec2::new(
            (self.centre_px.x + st.x * unit) / self.image.width as f32,
            (self.centre_px.y - st.y * unit) / self.image.height as f32,
        )
    }

    /// The patch-unit shift (less than half a pixel per axis) that moves
    /// `st` onto the nearest pixel centre of the patch image.
    pub fn pixel_phase_shift(&self, st: Vec2) -> Vec2 {
        let unit = self.unit_px();
        let px = Vec2::new(
            self.centre_px.x + st.x * unit,
            self.centre_px.y - st.y * unit,
        ) - Vec2::splat(0.5);
        let d = px.round() - px;
        Vec2::new(d.x / unit, -d.y / unit)
    }

    /// Alpha at texture coordinates `uv`, bilinear, transparent outside.
    #[inline]
    pub fn alpha_at(&self, uv: Vec2) -> f32 {
        let (w, h) = (self.image.width as i64, self.image.height as i64);
        let fx = uv.x * w as f32 - 0.5;
        let fy = uv.y * h as f32 - 0.5;
        if !(fx > -1.0 && fy > -1.0 && fx < w as f32 && fy < h as f32) {
            return 0.0;
        }
        let (x0, y0) = (crate::kernels::floor_f32(fx), crate::kernels::floor_f32(fy));
        let (ax, ay) = (fx - x0, fy - y0);
        let (x0, y0) = (x0 as i64, y0 as i64);
        let a = |x: i64, y: i64| -> f32 {
            if x < 0 || y < 0 || x >= w || y >= h {
                0.0
            } else {
                self.alpha[(y * w + x) as usize]
            }
        };
        let top = a(x0, y0) + (a(x0 + 1, y0) - a(x0, y0)) * ax;
        let bottom = a(x0, y0 + 1) + (a(x0 + 1, y0 + 1) - a(x0, y0 + 1)) * ax;
        top + (bottom - top) * ay
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn distance_transform_matches_brute_force() {
        let m = splotch_mask(40, 3);
        let d2 = distance_to_outside_sq(&m);
        for y in 0..40i64 {
            for x in 0..40i64 {
                let mut best = f32::INFINITY;
                for oy in -1..=40i64 {
                    for ox in -1..=40i64 {
                        if !m.at(ox, oy) {
                            let d = ((ox - x).pow(2) + (oy - y).pow(2)) as f32;
                            best = best.min(d);
                        }
                    }
                }
                assert_eq!(d2[(y * 40 + x) as usize], best, "({x}, {y})");
            }
        }
    }

    #[test]
    fn alpha_falls_off_over_three_pixels_and_borders_are_clear() {
        let m = circle_mask(64);
        let a = alpha_from_mask(&m, 3.0);
        // The border row is transparent, the centre opaque.
        assert!((0..64).all(|x| a[x] == 0.0 && a[63 * 64 + x] == 0.0));
        assert_eq!(a[32 * 64 + 32], 1.0);
        // Along the middle row, alpha rises 1/3, 2/3, 1 from the edge inwards.
        let row: Vec<f32> = (0..6).map(|x| a[32 * 64 + x]).collect();
        let first = row.iter().position(|&v| v > 0.0).unwrap();
        assert!((row[first] - 1.0 / 3.0).abs() < 1e-6, "{row:?}");
        assert!((row[first + 1] - 2.0 / 3.0).abs() < 1e-6, "{row:?}");
        assert_eq!(row[first + 2], 1.0, "{row:?}");
    }

    #[test]
    fn splotch_bounds_change_no_pixel() {
        for seed in 0..40u64 {
            for size in [8u32, 17, 32, 96, 161] {
                assert_eq!(
                    splotch(size, seed, true).inside,
                    splotch(size, seed, false).inside,
                    "seed {seed}, size {size}"
                );
            }
        }
    }

    #[test]
    fn splotch_is_seeded_irregular_and_connected() {
        let a = splotch_mask(64, 1);
        let b = splotch_mask(64, 2);
        assert_ne!(a, b);
        assert_eq!(a, splotch_mask(64, 1));
        let circle = circle_mask(64).count();
        assert!(a.count() < circle && a.count() > circle / 4);
    }

    #[test]
    fn user_mask_white_is_inside_and_patch_centre_is_opaque() {
        let mut img = Image::new(16, 8, 3);
        for y in 2..6 {
            for x in 3..13 {
                img.pixel_mut(x, y).copy_from_slice(&[1.0, 1.0, 1.0]);
            }
        }
        let m = mask_from_image(&img);
        assert_eq!(m.count(), 40);
        let ex = Image::new(16, 8, 3);
        let p = TexturePatch::cut(&ex, Wrap::Repeat, [0, 0], &m, 1.0, 8, "test").unwrap();
        assert_eq!(p.alpha_at(p.uv_of(Vec2::ZERO)), 1.0);
        assert_eq!(p.alpha_at(Vec2::new(-0.5, 0.5)), 0.0);
        let empty = Mask {
            width: 4,
            height: 4,
            inside: vec![false; 16],
        };
        assert!(TexturePatch::cut(&ex, Wrap::Repeat, [0, 0], &empty, 1.0, 8, "e").is_err());
    }
}
