//! Exemplar images as `f32` buffers with any channel count, their Gaussian
//! pyramid and stack, and sampling.

pub mod builtin;
mod error;
pub mod io;
pub mod pyramid;
pub mod sample;

pub use builtin::builtin_height;
pub use builtin::{BUILTIN_EXEMPLARS, ExemplarOptions, builtin_exemplar, check_exemplar_size};
pub use error::ImageError;
pub use io::{exemplar_from_spec, load_image};

/// The first three channels of a pixel as RGB, grey (with or without alpha)
/// replicated; black for an empty slice. [`Image::to_rgb`] applies it to
/// every pixel.
#[inline]
pub fn pixel_rgb(px: &[f32]) -> [f32; 3] {
    match px.len() {
        0 => [0.0; 3],
        1 | 2 => [px[0]; 3],
        _ => [px[0], px[1], px[2]],
    }
}

/// A row-major image of `f32` values with interleaved channels, values
/// nominally in `[0, 1]`.
///
/// Architecture invariant: `data.len() == width * height * channels` and all
/// three are at least 1 for an image that came from a loader or a builder.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Image {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Channels per pixel (1 grey, 2 grey+alpha, 3 RGB, 4 RGBA, or any other count).
    pub channels: u32,
    /// Pixel values, `((y * width) + x) * channels + c`.
    pub data: Vec<f32>,
}

impl Image {
    /// A zero-filled image.
    pub fn new(width: u32, height: u32, channels: u32) -> Self {
        Self {
            width,
            height,
            channels,
            data: vec![0.0; width as usize * height as usize * channels as usize],
        }
    }

    /// Wraps existing data; `None` when the length does not match.
    pub fn from_data(width: u32, height: u32, channels: u32, data: Vec<f32>) -> Option<Self> {
        (data.len() == width as usize * height as usize * channels as usize).then_some(Self {
            width,
            height,
            channels,
            data,
        })
    }

    /// Number of pixels.
    #[inline]
    pub fn pixel_count(&self) -> usize {
        self.width as usize * self.height as usize
    }

    /// Offset of pixel `(x, y)`'s first channel in `data`.
    #[inline]
    pub fn offset(&self, x: u32, y: u32) -> usize {
        (y as usize * self.width as usize + x as usize) * self.channels as usize
    }

    /// The channels of pixel `(x, y)`.
    #[inline]
    pub fn pixel(&self, x: u32, y: u32) -> &[f32] {
        let o = self.offset(x, y);
        &self.data[o..o + self.channels as usize]
    }

    /// The channels of pixel `(x, y)`, mutable.
    #[inline]
    pub fn pixel_mut(&mut self, x: u32, y: u32) -> &mut [f32] {
        let o = self.offset(x, y);
        let c = self.channels as usize;
        &mut self.data[o..o + c]
    }

    /// The image with 3 channels: the first three kept, grey (with or without
    /// alpha) replicated ([`pixel_rgb`] of every pixel).
    pub fn to_rgb(&self) -> Image {
        let c = self.channels.max(1) as usize;
        if c == 3 {
            return self.clone();
        }
        let data = self.data.chunks_exact(c).flat_map(pixel_rgb).collect();
        Image {
            width: self.width,
            height: self.height,
            channels: 3,
            data,
        }
    }

    /// Per-channel mean.
    pub fn mean(&self) -> Vec<f32> {
        let c = self.channels as usize;
        let mut sum = vec![0.0f64; c];
        for px in self.data.chunks_exact(c) {
            for (s, v) in sum.iter_mut().zip(px) {
                *s += *v as f64;
            }
        }
        let n = self.pixel_count().max(1) as f64;
        sum.into_iter().map(|s| (s / n) as f32).collect()
    }
}
