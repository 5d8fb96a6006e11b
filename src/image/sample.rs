//! Bilinear sampling with wrap (toroidal) or clamp addressing.

use super::Image;

/// How coordinates outside the image are mapped back in.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Wrap {
    /// Toroidal: `x` is taken modulo the width (tileable exemplars).
    #[default]
    Repeat,
    /// Coordinates are clamped to the border pixels.
    Clamp,
}

/// `x.floor()` without the library call, exactly: the same value for
/// every `f32` (signed zeros, NaN and infinities included). Below 2²³ in
/// magnitude a truncating cast and a correction; beyond, `x` is already
/// an integer (or not finite). The sign of the result is always `x`'s.
#[inline]
pub fn floor_f32(x: f32) -> f32 {
    if x.abs() < 8_388_608.0 {
        let t = (x as i32) as f32;
        let f = if t > x { t - 1.0 } else { t };
        f.copysign(x)
    } else {
        x
    }
}

#[inline]
fn index(i: i64, n: u32, wrap: Wrap) -> u32 {
    match wrap {
        Wrap::Repeat => i.rem_euclid(n as i64) as u32,
        Wrap::Clamp => i.clamp(0, n as i64 - 1) as u32,
    }
}

impl Image {
    /// The pixel at integer coordinates, addressed with `wrap`.
    #[inline]
    pub fn texel(&self, x: i64, y: i64, wrap: Wrap) -> &[f32] {
        self.pixel(index(x, self.width, wrap), index(y, self.height, wrap))
    }

    /// Bilinear sample at continuous pixel coordinates (pixel centres at
    /// integer + 0.5), written into `out` (`channels` values).
    #[inline]
    pub fn sample_bilinear(&self, x: f32, y: f32, wrap: Wrap, out: &mut [f32]) {
        let fx = x - 0.5;
        let fy = y - 0.5;
        let x0 = floor_f32(fx);
        let y0 = floor_f32(fy);
        let ax = fx - x0;
        let ay = fy - y0;
        let (x0, y0) = (x0 as i64, y0 as i64);
        let c = self.channels as usize;
        let p00 = self.texel(x0, y0, wrap);
        let p10 = self.texel(x0 + 1, y0, wrap);
        let p01 = self.texel(x0, y0 + 1, wrap);
        let p11 = self.texel(x0 + 1, y0 + 1, wrap);
        for i in 0..c.min(out.len()) {
            let top = p00[i] + (p10[i] - p00[i]) * ax;
            let bot = p01[i] + (p11[i] - p01[i]) * ax;
            out[i] = top + (bot - top) * ay;
        }
    }

    /// Bilinear sample at normalised texture coordinates `(u, v)` in `[0, 1]`
    /// (v = 0 at the top row, as image files store it).
    #[inline]
    pub fn sample_uv(&self, u: f32, v: f32, wrap: Wrap, out: &mut [f32]) {
        self.sample_bilinear(u * self.width as f32, v * self.height as f32, wrap, out);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bilinear_hits_pixel_centres_and_midpoints() {
        let img = Image::from_data(2, 1, 1, vec![0.0, 1.0]).unwrap();
        let mut o = [0.0];
        img.sample_bilinear(0.5, 0.5, Wrap::Clamp, &mut o);
        assert_eq!(o[0], 0.0);
        img.sample_bilinear(1.0, 0.5, Wrap::Clamp, &mut o);
        assert!((o[0] - 0.5).abs() < 1e-6);
        img.sample_bilinear(2.0, 0.5, Wrap::Repeat, &mut o);
        assert!((o[0] - 0.5).abs() < 1e-6, "wraps back to pixel 0");
        img.sample_bilinear(2.0, 0.5, Wrap::Clamp, &mut o);
        assert_eq!(o[0], 1.0);
    }
}
