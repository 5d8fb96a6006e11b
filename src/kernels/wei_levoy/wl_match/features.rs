//! Multi-resolution neighbourhood vectors of the exemplar pyramid (the
//! `BuildImageNeighborhood` of Wei & Levoy 2001 Table 3, noncausal) in the
//! layout the surface queries use.
//!
//! A neighbourhood is a list of [`Part`]s, one per pyramid level it reads:
//! part `j` is a `size`×`size` template on level `L + j`, points one pixel of
//! that level apart, centred where level `L`'s pixel sits on level `L + j`.
//! Level `L`'s pixel `(x, y)` (centre at `x + ½`) sits at continuous
//! coordinate `x / 2^j + ½` of level `L + j` (coarse pixel `X` is the blurred
//! fine pixel `2X`, see [`crate::image::pyramid::gaussian_pyramid`]), so the
//! coarser parts are sampled bilinearly between pixels for odd `x`, exactly as
//! the surface side interpolates between coarse vertices.
//!
//! Values are laid out part by part, template points row-major (image x
//! within a row, rows downwards), channels interleaved.

use rayon::prelude::*;

use crate::image::{Image, sample::Wrap};

/// One level's template of a neighbourhood.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Part {
    /// Pyramid levels above the synthesised one (0: the level itself).
    pub level_offset: u32,
    /// Template points per side (odd).
    pub size: u32,
}

impl Part {
    /// Values this part contributes for `channels` channels.
    #[inline]
    pub fn values(&self, channels: usize) -> usize {
        (self.size * self.size) as usize * channels
    }
}

/// Rows of equal-length vectors, row-major.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FeatureMatrix {
    /// Values per row.
    pub dim: usize,
    /// `rows · dim` values.
    pub data: Vec<f32>,
}

impl FeatureMatrix {
    /// Number of rows.
    #[inline]
    pub fn rows(&self) -> usize {
        self.data.len().checked_div(self.dim).unwrap_or(0)
    }

    /// Row `i`.
    #[inline]
    pub fn row(&self, i: usize) -> &[f32] {
        &self.data[i * self.dim..(i + 1) * self.dim]
    }
}

/// The neighbourhood vectors of every pixel of level `level` of `pyramid`
/// (row `y · width + x`), reading `parts`, with pixels outside an image
/// addressed by `wrap`.
///
/// Preconditions: `pyramid` has every level `level + part.level_offset`; all
/// levels have the same channel count.
pub fn exemplar_features(
    pyramid: &[Image],
    level: usize,
    parts: &[Part],
    wrap: Wrap,
) -> FeatureMatrix {
    let base = &pyramid[level];
    let ch = base.channels as usize;
    let dim: usize = parts.iter().map(|p| p.values(ch)).sum();
    let (w, h) = (base.width as usize, base.height as usize);
    let mut data = vec![0.0f32; w * h * dim];
    if dim == 0 {
        return FeatureMatrix { dim, data };
    }
    data.par_chunks_mut(dim).enumerate().for_each(|(i, row)| {
        let (x, y) = ((i % w) as i64, (i / w) as i64);
        let mut o = 0;
        for part in parts {
            let img = &pyramid[level + part.level_offset as usize];
            let half = (part.size / 2) as i64;
            let n = part.size as i64;
            if part.level_offset == 0 {
                for dy in 0..n {
                    for dx in 0..n {
                        let px = img.texel(x + dx - half, y + dy - half, wrap);
                        row[o..o + ch].copy_from_slice(px);
                        o += ch;
                    }
                }
            } else {
                let f = (1u64 << part.level_offset) as f32;
                let (cx, cy) = (x as f32 / f + 0.5, y as f32 / f + 0.5);
                for dy in 0..n {
                    for dx in 0..n {
                        img.sample_bilinear(
                            cx + (dx - half) as f32,
                            cy + (dy - half) as f32,
                            wrap,
                            &mut row[o..o + ch],
                        );
                        o += ch;
                    }
                }
            }
        }
    });
    FeatureMatrix { dim, data }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::pyramid::gaussian_pyramid;

    #[test]
    fn parts_read_their_levels_in_image_order() {
        let img = Image::from_data(8, 8, 1, (0..64).map(|i| i as f32).collect()).unwrap();
        let pyr = gaussian_pyramid(&img, 2, Wrap::Repeat);
        let parts = [
            Part {
                level_offset: 0,
                size: 3,
            },
            Part {
                level_offset: 1,
                size: 3,
            },
        ];
        let f = exemplar_features(&pyr, 0, &parts, Wrap::Repeat);
        assert_eq!((f.dim, f.rows()), (18, 64));
        // Pixel (3, 2): its 3×3 window, then level 1 around (1.5, 1) + ½.
        let row = f.row(2 * 8 + 3);
        assert_eq!(&row[..3], &[10.0, 11.0, 12.0]);
        assert_eq!(&row[6..9], &[26.0, 27.0, 28.0]);
        let c = &pyr[1];
        let mid = 0.5 * (c.pixel(1, 1)[0] + c.pixel(2, 1)[0]);
        assert!((row[9 + 4] - mid).abs() < 1e-5, "{} vs {mid}", row[13]);
        // Even pixels read coarse pixels exactly.
        let row = f.row(2 * 8 + 2);
        assert!((row[9 + 4] - c.pixel(1, 1)[0]).abs() < 1e-5);
    }
}
