//! The peer of the quality gates: Embark Studios' `texture-synthesis` 0.8.
//!
//! Stand-in with the API of the wrapper written on another branch (it
//! replaces this file at merge): the stand-in of `tests/quality_metrics.rs`,
//! timed.

use surfsynth::image::Image;
use surfsynth::kernels::metrics::SourceMap;

/// The peer's synthesis of an exemplar.
pub struct PeerResult {
    /// RGB, values in `[0, 1]`.
    pub image: Image,
    /// The peer's coordinate transform: the exemplar pixel each output pixel copies.
    pub sources: SourceMap,
    /// Wall time of the synthesis.
    pub seconds: f64,
}

/// Synthesises a `width`×`height` image from an RGB `exemplar` with the
/// peer's default settings, `seed` and at most `threads` threads.
pub fn peer_synthesis(
    exemplar: &Image,
    width: u32,
    height: u32,
    seed: u64,
    threads: usize,
) -> PeerResult {
    let start = std::time::Instant::now();
    let rgba: Vec<u8> = exemplar
        .data
        .chunks_exact(3)
        .flat_map(|p| [p[0], p[1], p[2], 1.0].map(|v| (v * 255.0).round().clamp(0.0, 255.0) as u8))
        .collect();
    let buf = texture_synthesis::image::RgbaImage::from_raw(exemplar.width, exemplar.height, rgba)
        .unwrap();
    let session = texture_synthesis::Session::builder()
        .add_example(texture_synthesis::image::DynamicImage::ImageRgba8(buf))
        .output_size(texture_synthesis::Dims::new(width, height))
        .seed(seed)
        .max_thread_count(threads)
        .build()
        .unwrap();
    let out = session.run(None);
    let mut bytes = Vec::new();
    out.get_coordinate_transform().write(&mut bytes).unwrap();
    let words: Vec<u32> = bytes
        .chunks_exact(4)
        .map(|b| u32::from_le_bytes(b.try_into().unwrap()))
        .collect();
    let maps = words[3] as usize;
    let coords = &words[4 + 2 * maps..];
    let texels = coords
        .chunks_exact(3)
        .map(|c| [c[0] as f32 + 0.5, c[1] as f32 + 0.5])
        .collect();
    let img = out.into_image().to_rgba8();
    let data = img
        .pixels()
        .flat_map(|p| [p[0], p[1], p[2]].map(|v| v as f32 / 255.0))
        .collect();
    PeerResult {
        image: Image::from_data(width, height, 3, data).unwrap(),
        sources: SourceMap {
            width,
            height,
            texels,
        },
        seconds: start.elapsed().as_secs_f64(),
    }
}
