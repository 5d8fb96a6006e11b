//! Multi-resolution neighbourhood vectors (Zelinka & Garland 2004, §4.1–§4.3).
//!
//! The vector of exemplar pixel `(x, y)` concatenates, for each pyramid level
//! `l`, the `n_l × n_l` pixels (all channels) of level `l` centred on the
//! pixel's position there, `(x, y) / 2^l`. Level `l` pixel `i` lies over level
//! 0 pixel `2^l·i` (the pyramid keeps every second blurred pixel), so the
//! centre generally falls between coarse pixels and coarse taps are read
//! bilinearly. Each entry of level `l` is scaled by `1 / n_l`, so every level
//! adds the same total weight to a squared distance (§4.3: "a coarser level
//! with half as many pixels gives each twice the weight").

use rayon::prelude::*;

use super::{Boundary, JumpMapError, TexelRect};
use crate::image::{Image, sample::Wrap};

/// Length of one neighbourhood vector: `channels · Σ n_l²`.
pub fn vector_len(widths: &[u32], channels: u32) -> usize {
    widths.iter().map(|&n| (n * n) as usize).sum::<usize>() * channels as usize
}

/// The per-entry scale of each level, `1 / n_l` (§4.3).
pub fn level_scales(widths: &[u32]) -> Vec<f32> {
    widths.iter().map(|&n| 1.0 / n as f32).collect()
}

/// Pyramid wrap mode used for a boundary mode.
pub fn wrap_for(boundary: Boundary) -> Wrap {
    match boundary {
        Boundary::Toroidal => Wrap::Repeat,
        Boundary::Inset => Wrap::Clamp,
    }
}

/// The valid interval `[lo, hi)` along one axis of `size` pixels: positions
/// whose neighbourhood at every level lies inside that level (no clamping).
fn axis_interval(size: u32, widths: &[u32]) -> (u32, u32) {
    let mut sizes = vec![size];
    for _ in 1..widths.len() {
        let s = *sizes.last().expect("one level");
        sizes.push(s.div_ceil(2).max(1));
    }
    let ok = |x: u32| {
        widths.iter().enumerate().all(|(l, &n)| {
            let r = n / 2;
            let lo = x >> l;
            let hi = lo + u32::from(x & ((1 << l) - 1) != 0);
            lo >= r && hi + r < sizes[l]
        })
    };
    match (0..size).find(|&x| ok(x)) {
        Some(lo) => {
            let hi = (lo..size).rev().find(|&x| ok(x)).expect("lo is valid") + 1;
            (lo, hi)
        }
        None => (size, size),
    }
}

/// Pixels the inset region needs along each axis, so that destinations
/// (the region shrunk by one pixel) are not empty.
const MIN_INSET_REGION: u32 = 3;

/// The largest exemplar side a jump map addresses.
const LARGEST_SIDE: u32 = 1 << 16;

/// The smallest exemplar side (along either axis) whose inset region for
/// neighbourhoods of `widths` is wide enough ([`source_region`]).
pub fn min_inset_side(widths: &[u32]) -> u32 {
    let (border, _) = axis_interval(LARGEST_SIDE, widths);
    (2 * border + MIN_INSET_REGION..=LARGEST_SIDE)
        .find(|&side| {
            let (lo, hi) = axis_interval(side, widths);
            hi.saturating_sub(lo) >= MIN_INSET_REGION
        })
        .unwrap_or(LARGEST_SIDE)
}

/// The pixels that get neighbourhood vectors and jump lists: the whole
/// exemplar when toroidal; when inset, the pixels whose neighbourhoods at all
/// levels lie fully inside the pyramid (§4.2).
///
/// # Errors
/// [`JumpMapError::ExemplarTooSmall`] when the inset region is empty.
pub fn source_region(
    width: u32,
    height: u32,
    widths: &[u32],
    boundary: Boundary,
) -> Result<TexelRect, JumpMapError> {
    match boundary {
        Boundary::Toroidal => Ok(TexelRect {
            x0: 0,
            y0: 0,
            x1: width,
            y1: height,
        }),
        Boundary::Inset => {
            let (x0, x1) = axis_interval(width, widths);
            let (y0, y1) = axis_interval(height, widths);
            let r = TexelRect { x0, y0, x1, y1 };
            // Two pixels wide at least, so that destinations (the region shrunk
            // by one pixel) are not empty.
            if r.width() < MIN_INSET_REGION || r.height() < MIN_INSET_REGION {
                let (mx, _) = axis_interval(LARGEST_SIDE, widths);
                return Err(JumpMapError::ExemplarTooSmall {
                    width,
                    height,
                    margin: mx + 1,
                    min_side: min_inset_side(widths),
                });
            }
            Ok(r)
        }
    }
}

/// The neighbourhood vector of any exemplar pixel, one at a time: the
/// analysis computes them in blocks ([`Neighbourhoods::rows`]) and for its
/// PCA sample ([`Neighbourhoods::pixels`]) instead of holding all of them
/// (issue 43: 5.8 GB at a 2048² exemplar, 36 GB with 31-pixel
/// neighbourhoods at 1024²).
pub struct Neighbourhoods<'a> {
    pyramid: &'a [Image],
    widths: &'a [u32],
    scales: Vec<f32>,
    wrap: Wrap,
    dim: usize,
    channels: usize,
}

impl<'a> Neighbourhoods<'a> {
    /// Preconditions: `pyramid` has at least `widths.len()` levels built
    /// from the exemplar with `wrap` ([`wrap_for`]); with [`Wrap::Clamp`]
    /// the pixels asked for lie within [`source_region`] (else border pixels
    /// are repeated).
    pub fn new(pyramid: &'a [Image], widths: &'a [u32], wrap: Wrap) -> Self {
        Self {
            pyramid,
            widths,
            scales: level_scales(widths),
            wrap,
            dim: vector_len(widths, pyramid[0].channels),
            channels: pyramid[0].channels as usize,
        }
    }

    /// Length of one vector ([`vector_len`]).
    pub fn dim(&self) -> usize {
        self.dim
    }

    /// The vector of pixel `(x, y)` into `v` ([`Self::dim`] long).
    pub fn vector(&self, x: u32, y: u32, v: &mut [f32]) {
        let (c, wrap) = (self.channels, self.wrap);
        let mut at = 0;
        for (l, (&n, &s)) in self.widths.iter().zip(&self.scales).enumerate() {
            let img = &self.pyramid[l];
            let r = (n / 2) as i64;
            if l == 0 {
                for dy in -r..=r {
                    for dx in -r..=r {
                        let px = img.texel(x as i64 + dx, y as i64 + dy, wrap);
                        for (o, p) in v[at..at + c].iter_mut().zip(px) {
                            *o = p * s;
                        }
                        at += c;
                    }
                }
            } else {
                let step = (1u32 << l) as f32;
                let cx = x as f32 / step;
                let cy = y as f32 / step;
                let (bx, by) = (cx.floor(), cy.floor());
                let (ax, ay) = (cx - bx, cy - by);
                let (bx, by) = (bx as i64, by as i64);
                let w = [
                    (1.0 - ax) * (1.0 - ay),
                    ax * (1.0 - ay),
                    (1.0 - ax) * ay,
                    ax * ay,
                ];
                for dy in -r..=r {
                    for dx in -r..=r {
                        let (tx, ty) = (bx + dx, by + dy);
                        let p00 = img.texel(tx, ty, wrap);
                        let p10 = img.texel(tx + 1, ty, wrap);
                        let p01 = img.texel(tx, ty + 1, wrap);
                        let p11 = img.texel(tx + 1, ty + 1, wrap);
                        for i in 0..c {
                            v[at + i] =
                                (w[0] * p00[i] + w[1] * p10[i] + w[2] * p01[i] + w[3] * p11[i]) * s;
                        }
                        at += c;
                    }
                }
            }
        }
        debug_assert_eq!(at, self.dim);
    }

    /// The vectors of pixels `first..first + count` of `region` (row-major
    /// over the region), in one flat buffer; filled in parallel, the same
    /// for any thread count.
    pub fn rows(&self, region: TexelRect, first: usize, count: usize) -> Vec<f32> {
        let rw = region.width() as usize;
        let mut out = vec![0.0f32; count * self.dim];
        out.par_chunks_mut(self.dim.max(1))
            .enumerate()
            .for_each(|(j, v)| {
                let i = first + j;
                self.vector(region.x0 + (i % rw) as u32, region.y0 + (i / rw) as u32, v);
            });
        out
    }

    /// The vectors of the pixels of `region` at the row-major indices
    /// `indices`, in their order.
    pub fn pixels(&self, region: TexelRect, indices: &[u32]) -> Vec<f32> {
        let rw = region.width();
        let mut out = vec![0.0f32; indices.len() * self.dim];
        out.par_chunks_mut(self.dim.max(1))
            .zip(indices)
            .for_each(|(v, &i)| self.vector(region.x0 + i % rw, region.y0 + i / rw, v));
        out
    }
}

/// Neighbourhood vectors of every pixel of `region`, row-major over the
/// region, each [`vector_len`] long, in one flat buffer.
///
/// Preconditions: `pyramid` has at least `widths.len()` levels built from the
/// exemplar with `wrap` ([`wrap_for`]); when `wrap` is [`Wrap::Clamp`],
/// `region` lies within [`source_region`] (else border pixels are repeated).
/// Rows are filled in parallel; the result does not depend on the thread count.
pub fn neighbourhood_vectors(
    pyramid: &[Image],
    widths: &[u32],
    region: TexelRect,
    wrap: Wrap,
) -> Vec<f32> {
    let n = region.width() as usize * region.height() as usize;
    if n == 0 {
        return Vec::new();
    }
    Neighbourhoods::new(pyramid, widths, wrap).rows(region, 0, n)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_smallest_inset_side_fits_and_one_less_does_not() {
        for widths in [vec![9, 5, 3], vec![3], vec![31, 31, 31], vec![1]] {
            let side = min_inset_side(&widths);
            assert!(
                source_region(side, side, &widths, Boundary::Inset).is_ok(),
                "{widths:?}: {side}"
            );
            let e = source_region(side - 1, side, &widths, Boundary::Inset)
                .expect_err("one pixel less")
                .to_string();
            assert!(e.contains(&format!("at least {side}x{side}")), "{e}");
        }
    }
}
