//! Gaussian pyramid (each level half the size) and Gaussian stack (same size,
//! growing blur; Bangay & Morkel 2006 §3.3.1, after Lefebvre & Hoppe 2005).

use super::{Image, sample::Wrap};

/// The 5-tap binomial kernel (1 4 6 4 1)/16, a standard Gaussian approximation
/// with σ ≈ 1 pixel.
const BINOMIAL5: [f32; 5] = [1.0 / 16.0, 4.0 / 16.0, 6.0 / 16.0, 4.0 / 16.0, 1.0 / 16.0];

/// Blurs `img` separably with the binomial kernel dilated by `step` pixels
/// (taps at -2·step..=2·step), addressing borders with `wrap`.
pub fn blur_binomial(img: &Image, step: u32, wrap: Wrap) -> Image {
    let c = img.channels as usize;
    let (w, h) = (img.width as i64, img.height as i64);
    let step = step.max(1) as i64;
    let mut tmp = Image::new(img.width, img.height, img.channels);
    for y in 0..h {
        for x in 0..w {
            let o = tmp.offset(x as u32, y as u32);
            for (k, wt) in BINOMIAL5.iter().enumerate() {
                let px = img.texel(x + (k as i64 - 2) * step, y, wrap);
                for (acc, v) in tmp.data[o..o + c].iter_mut().zip(px) {
                    *acc += wt * v;
                }
            }
        }
    }
    let mut out = Image::new(img.width, img.height, img.channels);
    for y in 0..h {
        for x in 0..w {
            let o = out.offset(x as u32, y as u32);
            for (k, wt) in BINOMIAL5.iter().enumerate() {
                let px = tmp.texel(x, y + (k as i64 - 2) * step, wrap);
                for (acc, v) in out.data[o..o + c].iter_mut().zip(px) {
                    *acc += wt * v;
                }
            }
        }
    }
    out
}

/// Gaussian pyramid: level 0 is `img`; level `l + 1` is level `l` blurred and
/// subsampled by two (sizes rounded up, never below 1×1). Returns `levels`
/// images (at least one).
pub fn gaussian_pyramid(img: &Image, levels: usize, wrap: Wrap) -> Vec<Image> {
    let mut out = vec![img.clone()];
    while out.len() < levels.max(1) {
        let prev = out.last().expect("pyramid has a level");
        let blurred = blur_binomial(prev, 1, wrap);
        let w = prev.width.div_ceil(2).max(1);
        let h = prev.height.div_ceil(2).max(1);
        let mut next = Image::new(w, h, prev.channels);
        for y in 0..h {
            for x in 0..w {
                let src = blurred.pixel((2 * x).min(prev.width - 1), (2 * y).min(prev.height - 1));
                next.pixel_mut(x, y).copy_from_slice(src);
            }
        }
        out.push(next);
    }
    out
}

/// Gaussian stack: every level has the size of `img`; level `l` has the blur
/// of pyramid level `l` (σ doubling per level), made with the à-trous scheme
/// (the binomial kernel dilated by 2^(l-1)). Returns `levels` images.
pub fn gaussian_stack(img: &Image, levels: usize, wrap: Wrap) -> Vec<Image> {
    let mut out = vec![img.clone()];
    while out.len() < levels.max(1) {
        let l = out.len() as u32;
        let prev = out.last().expect("stack has a level");
        out.push(blur_binomial(prev, 1 << (l - 1), wrap));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn noise(w: u32, h: u32) -> Image {
        let mut s = 12345u32;
        let data = (0..w * h)
            .map(|_| {
                s = s.wrapping_mul(1664525).wrapping_add(1013904223);
                (s >> 8) as f32 / (1u32 << 24) as f32
            })
            .collect();
        Image::from_data(w, h, 1, data).unwrap()
    }

    fn energy(img: &Image) -> f32 {
        let m = img.mean()[0];
        img.data.iter().map(|v| (v - m) * (v - m)).sum::<f32>() / img.data.len() as f32
    }

    #[test]
    fn pyramid_halves_sizes_rounding_up() {
        let p = gaussian_pyramid(&noise(37, 20), 4, Wrap::Repeat);
        let sizes: Vec<_> = p.iter().map(|i| (i.width, i.height)).collect();
        assert_eq!(sizes, vec![(37, 20), (19, 10), (10, 5), (5, 3)]);
    }

    #[test]
    fn stack_keeps_size_and_blur_lowers_energy_but_keeps_mean() {
        let img = noise(32, 32);
        let s = gaussian_stack(&img, 4, Wrap::Repeat);
        assert!(s.iter().all(|l| l.width == 32 && l.height == 32));
        for w in s.windows(2) {
            assert!(
                energy(&w[1]) < 0.7 * energy(&w[0]),
                "each level is smoother"
            );
            assert!(
                (w[1].mean()[0] - w[0].mean()[0]).abs() < 1e-4,
                "toroidal blur keeps the mean"
            );
        }
    }
}
