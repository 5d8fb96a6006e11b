//! The result of jump map image synthesis: for every output pixel the exemplar
//! pixel it copies (§3: synthesis works on addresses only), the colours
//! gathered from those addresses, and the patch visualisation of Fig. 5.

use super::{JumpMapError, TexelCoord};
use crate::image::Image;

/// Per output pixel, the exemplar pixel it came from.
#[derive(Clone, Debug, PartialEq)]
pub struct SourceMap {
    /// Output width in pixels.
    pub width: u32,
    /// Output height in pixels.
    pub height: u32,
    /// Exemplar width in pixels.
    pub exemplar_width: u32,
    /// Exemplar height in pixels.
    pub exemplar_height: u32,
    /// Row-major, `width · height` addresses.
    pub texels: Vec<TexelCoord>,
}

/// What image synthesis returns.
#[derive(Clone, Debug, PartialEq)]
pub struct SynthesisOutput {
    /// The synthesized image (the exemplar's channel count).
    pub image: Image,
    /// Where each output pixel came from.
    pub sources: SourceMap,
}

impl SourceMap {
    /// The source of output pixel `(x, y)`. Precondition: inside the output.
    #[inline]
    pub fn get(&self, x: u32, y: u32) -> TexelCoord {
        self.texels[(y * self.width + x) as usize]
    }

    /// The output image: each pixel copies its source's colour.
    ///
    /// # Errors
    /// [`JumpMapError::ExemplarMismatch`] when `exemplar` is not the size the
    /// map addresses.
    pub fn gather(&self, exemplar: &Image) -> Result<Image, JumpMapError> {
        if exemplar.width != self.exemplar_width || exemplar.height != self.exemplar_height {
            return Err(JumpMapError::ExemplarMismatch {
                map_width: self.exemplar_width,
                map_height: self.exemplar_height,
                width: exemplar.width,
                height: exemplar.height,
            });
        }
        let c = exemplar.channels as usize;
        let mut out = Image::new(self.width, self.height, exemplar.channels);
        let ew = exemplar.width as usize;
        if c == 3 {
            // The common case, with the channel loop unrolled.
            for (o, t) in out.data.chunks_exact_mut(3).zip(&self.texels) {
                let s = (t.y as usize * ew + t.x as usize) * 3;
                o.copy_from_slice(&exemplar.data[s..s + 3]);
            }
        } else {
            for (o, t) in out.data.chunks_exact_mut(c).zip(&self.texels) {
                let s = (t.y as usize * ew + t.x as usize) * c;
                o.copy_from_slice(&exemplar.data[s..s + c]);
            }
        }
        Ok(out)
    }

    /// The patch visualisation of Fig. 5 (and Fig. 3): an RGB image where each
    /// pixel shows where it came from, red = source x / (exemplar width − 1),
    /// green = source y / (exemplar height − 1), blue 0. Colour
    /// discontinuities are patch boundaries.
    pub fn patch_visualisation(&self) -> Image {
        let sx = 1.0 / (self.exemplar_width.max(2) - 1) as f32;
        let sy = 1.0 / (self.exemplar_height.max(2) - 1) as f32;
        let mut out = Image::new(self.width, self.height, 3);
        for (o, t) in out.data.chunks_exact_mut(3).zip(&self.texels) {
            o[0] = t.x as f32 * sx;
            o[1] = t.y as f32 * sy;
        }
        out
    }

    /// Number of 4-neighbour pairs of output pixels whose sources are not the
    /// same offset apart as the pixels (toroidally, on the exemplar): the
    /// total length of patch boundaries, in pixel edges.
    pub fn seam_edges(&self) -> usize {
        let (ew, eh) = (self.exemplar_width, self.exemplar_height);
        let step = |a: TexelCoord, b: TexelCoord, dx: u32, dy: u32| {
            (a.x + dx) % ew == b.x && (a.y + dy) % eh == b.y
        };
        let mut n = 0;
        for y in 0..self.height {
            for x in 0..self.width {
                let a = self.get(x, y);
                if x + 1 < self.width && !step(a, self.get(x + 1, y), 1, 0) {
                    n += 1;
                }
                if y + 1 < self.height && !step(a, self.get(x, y + 1), 0, 1) {
                    n += 1;
                }
            }
        }
        n
    }
}
