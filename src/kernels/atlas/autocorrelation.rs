//! The normalised autocovariance of an exemplar's luminance over a window
//! of lags: how alike the texture is to itself moved by `d` pixels. The
//! bake's variance-preserving blend reads it to know how related two
//! look-ups at coordinates `d` apart are.

use crate::image::Image;
use crate::image::sample::Wrap;
use glam::Vec2;
use rayon::prelude::*;

/// Most pixel products summed per lag window (all lags together); larger
/// exemplars are read at a pixel stride, so the cost stays bounded.
const MAX_PRODUCTS: usize = 1 << 28;

/// `ρ(d)` for integer lags `|dx|, |dy| ≤ radius`, row-major over
/// `(2·radius + 1)²`, `ρ(0) = 1`, clamped to `[0, 1]` (anti-correlation —
/// half a period of a regular texture — is read as unrelated).
#[derive(Clone, Debug)]
pub struct Autocorrelation {
    radius: i32,
    rho: Vec<f32>,
}

impl Autocorrelation {
    /// Of `img`'s luminance (Rec. 601) about its mean, over lags up to
    /// `radius` pixels (at most half the smaller side). `wrap`: with
    /// `Repeat` lags wrap around (a tileable exemplar), otherwise only pixel
    /// pairs both inside count. A flat image is unrelated at every lag but 0.
    pub fn of_luminance(img: &Image, radius: u32, wrap: Wrap) -> Self {
        let (w, h) = (img.width as usize, img.height as usize);
        let radius = (radius as usize).min(w / 2).min(h / 2) as i32;
        let side = (2 * radius + 1) as usize;
        let mut l = crate::kernels::metrics::quality::luma(img);
        let mean = l.iter().map(|&v| f64::from(v)).sum::<f64>() / l.len().max(1) as f64;
        l.iter_mut().for_each(|v| *v -= mean as f32);
        let lags = side * side;
        let stride = ((w * h * lags) as f64 / MAX_PRODUCTS as f64)
            .sqrt()
            .ceil()
            .max(1.0) as usize;
        // Index `i` moved into `0..n`, or `None` off a clamped image.
        let place = |i: i32, n: usize| -> Option<usize> {
            match wrap {
                Wrap::Repeat => Some(i.rem_euclid(n as i32) as usize),
                Wrap::Clamp => (0..n as i32).contains(&i).then_some(i as usize),
            }
        };
        let cov = |dx: i32, dy: i32| -> f64 {
            let (mut sum, mut n) = (0.0f64, 0usize);
            for y in (0..h).step_by(stride) {
                let Some(yy) = place(y as i32 + dy, h) else {
                    continue;
                };
                let (row, other) = (&l[y * w..(y + 1) * w], &l[yy * w..(yy + 1) * w]);
                let mut acc = 0.0f32;
                for x in (0..w).step_by(stride) {
                    if let Some(xx) = place(x as i32 + dx, w) {
                        acc += row[x] * other[xx];
                        n += 1;
                    }
                }
                sum += f64::from(acc);
            }
            if n == 0 { 0.0 } else { sum / n as f64 }
        };
        let var = cov(0, 0);
        let rho: Vec<f32> = (0..lags)
            .into_par_iter()
            .map(|i| {
                let (dx, dy) = ((i % side) as i32 - radius, (i / side) as i32 - radius);
                if dx == 0 && dy == 0 {
                    1.0
                } else if var <= 0.0 {
                    0.0
                } else {
                    (cov(dx, dy) / var).clamp(0.0, 1.0) as f32
                }
            })
            .collect();
        Self { radius, rho }
    }

    /// `ρ(d)` at a real lag `d` (pixels), bilinear between integer lags; 0
    /// beyond the window.
    pub fn at(&self, d: Vec2) -> f32 {
        let r = self.radius as f32;
        if !(d.x.abs() <= r && d.y.abs() <= r) {
            return 0.0;
        }
        let side = (2 * self.radius + 1) as usize;
        let (x, y) = (d.x + r, d.y + r);
        let (x0, y0) = (
            x.floor().min(2.0 * r - 1.0).max(0.0),
            y.floor().min(2.0 * r - 1.0).max(0.0),
        );
        if self.radius == 0 {
            return if d == Vec2::ZERO { 1.0 } else { 0.0 };
        }
        let (fx, fy) = (x - x0, y - y0);
        let (i, j) = (x0 as usize, y0 as usize);
        let v = |a: usize, b: usize| self.rho[b * side + a];
        (v(i, j) * (1.0 - fx) + v(i + 1, j) * fx) * (1.0 - fy)
            + (v(i, j + 1) * (1.0 - fx) + v(i + 1, j + 1) * fx) * fy
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stripes_are_related_along_and_unrelated_half_a_period_across() {
        // Vertical stripes of period 8: alike along y, opposite at dx = 4.
        let mut img = Image::new(64, 64, 1);
        for y in 0..64 {
            for x in 0..64 {
                img.pixel_mut(x, y)[0] = if (x / 4) % 2 == 0 { 1.0 } else { 0.0 };
            }
        }
        let a = Autocorrelation::of_luminance(&img, 16, Wrap::Repeat);
        assert_eq!(a.at(Vec2::ZERO), 1.0);
        assert!((a.at(Vec2::new(0.0, 7.0)) - 1.0).abs() < 1e-5);
        assert!((a.at(Vec2::new(8.0, 3.0)) - 1.0).abs() < 1e-5);
        assert_eq!(a.at(Vec2::new(4.0, 0.0)), 0.0);
        assert!((a.at(Vec2::new(2.0, 0.0)) - 0.0).abs() < 1e-5);
        assert!((a.at(Vec2::new(1.0, 0.0)) - 0.5).abs() < 1e-5);
        assert_eq!(a.at(Vec2::new(40.0, 0.0)), 0.0);
    }

    #[test]
    fn white_noise_is_unrelated_off_zero() {
        let mut img = Image::new(96, 96, 1);
        let mut s = 12345u64;
        for v in img.data.iter_mut() {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            *v = (s >> 40) as f32 / (1u64 << 24) as f32;
        }
        let a = Autocorrelation::of_luminance(&img, 8, Wrap::Clamp);
        for d in [
            Vec2::new(1.0, 0.0),
            Vec2::new(0.0, 3.0),
            Vec2::new(-5.0, 2.0),
        ] {
            assert!(a.at(d) < 0.05, "{d}: {}", a.at(d));
        }
        // Half a pixel: half related (bilinear between lags 0 and 1).
        assert!((a.at(Vec2::new(0.5, 0.0)) - 0.5).abs() < 0.05);
    }
}
