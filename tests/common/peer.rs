//! The peer of the quality benchmark and of the quality gates: Embark
//! Studios' `texture-synthesis` 0.8 (pinned at 0.8.2 in `Cargo.lock`), run on
//! our exemplar at our output size and seed.
//!
//! Used by the integration tests as `common::peer` and by
//! `benches/quality.rs` through `#[path = "../tests/common/peer.rs"] mod peer;`.
//!
//! Every generator parameter except the output size, the seed and the
//! thread count is Embark's default (as of 0.8.2: 50 nearest neighbours, 50
//! random sample locations, Cauchy dispersion 1.0, backtrack 50 % over 5
//! stages, no tiling, no guides, no input resize).
//!
//! Determinism (checked by `tests/it/peer.rs`): with a fixed seed and one thread
//! the output and its source map are identical from run to run (Embark
//! documents this for `max_thread_count(1)`; `one_thread_same_seed_same_result`
//! asserts it). With more than one thread the workers race for pixels
//! (crossbeam scoped threads, not rayon, so a rayon pool does not limit them;
//! only `max_thread_count` does) and the result depends on the scheduling:
//! measured on a 64² stones crop → 96², seed 1 (`report_thread_count_dependence`),
//! about 12 % of the pixels differ between 1 and 2 threads and about 10 %
//! between two 2-thread runs. Gates must therefore compute the peer at one
//! thread.

use std::time::Instant;

use surfsynth::image::Image;
use texture_synthesis as ts;

pub use surfsynth::kernels::metrics::SourceMap;

/// Embark's result, in our types.
#[derive(Clone, Debug)]
pub struct PeerResult {
    /// The synthesised image, RGB (3 channels), values `k / 255`.
    pub image: Image,
    /// Per output pixel, the exemplar pixel it was copied from (`index + 0.5`).
    pub sources: SourceMap,
    /// Wall seconds of building and running Embark's session (not counting
    /// the conversion of the exemplar and of the result).
    pub seconds: f64,
}

/// Runs Embark's `texture-synthesis` on `exemplar` (any channel count, values
/// in `[0, 1]`; quantised to 8-bit RGBA, grey replicated, alpha 255 when
/// absent) into a `width` × `height` image with `seed`, on at most `threads`
/// threads (at least 1).
///
/// # Errors
///
/// Embark's own error when it refuses the parameters or the image.
pub fn try_peer_synthesis(
    exemplar: &Image,
    width: u32,
    height: u32,
    seed: u64,
    threads: usize,
) -> Result<PeerResult, ts::Error> {
    peer_session(exemplar, width, height, seed, threads, false)
}

/// [`try_peer_synthesis`] in Embark's tiling mode: the output repeats
/// seamlessly (what an artist makes for a triplanar or box projection).
pub fn try_peer_tile(
    exemplar: &Image,
    width: u32,
    height: u32,
    seed: u64,
    threads: usize,
) -> Result<PeerResult, ts::Error> {
    peer_session(exemplar, width, height, seed, threads, true)
}

fn peer_session(
    exemplar: &Image,
    width: u32,
    height: u32,
    seed: u64,
    threads: usize,
    tiling: bool,
) -> Result<PeerResult, ts::Error> {
    let example = ts::image::DynamicImage::ImageRgba8(to_rgba8(exemplar));
    let started = Instant::now();
    let generated = ts::Session::builder()
        .add_example(example)
        .output_size(ts::Dims::new(width, height))
        .seed(seed)
        .tiling_mode(tiling)
        .max_thread_count(threads.max(1))
        .build()?
        .run(None);
    let seconds = started.elapsed().as_secs_f64();
    let sources = parse_transform(&generated.get_coordinate_transform(), width, height);
    let rgba = generated.into_image().into_rgba8();
    let data = rgba
        .as_raw()
        .chunks_exact(4)
        .flat_map(|p| p[..3].iter().map(|&v| f32::from(v) / 255.0))
        .collect();
    let image = Image::from_data(rgba.width(), rgba.height(), 3, data)
        .expect("Embark returns width × height RGBA pixels");
    Ok(PeerResult {
        image,
        sources,
        seconds,
    })
}

/// [`try_peer_synthesis`], panicking with Embark's error (tests).
pub fn peer_synthesis(
    exemplar: &Image,
    width: u32,
    height: u32,
    seed: u64,
    threads: usize,
) -> PeerResult {
    try_peer_synthesis(exemplar, width, height, seed, threads)
        .unwrap_or_else(|e| panic!("Embark's texture-synthesis failed: {e}"))
}

/// Our image as Embark's `image` 0.23 RGBA8 buffer.
fn to_rgba8(img: &Image) -> ts::image::RgbaImage {
    let c = img.channels.max(1) as usize;
    let q = |v: f32| (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8;
    let mut raw = Vec::with_capacity(img.pixel_count() * 4);
    for px in img.data.chunks_exact(c) {
        let rgba = match c {
            1 => [px[0], px[0], px[0], 1.0],
            2 => [px[0], px[0], px[0], px[1]],
            3 => [px[0], px[1], px[2], 1.0],
            _ => [px[0], px[1], px[2], px[3]],
        };
        raw.extend(rgba.map(q));
    }
    ts::image::RgbaImage::from_raw(img.width, img.height, raw).expect("width × height × 4 bytes")
}

/// Reads Embark's coordinate transform: its `write` gives a header of four
/// native-endian `u32` (magic, width, height, map count), then one
/// (width, height) pair per example, then per output pixel (row-major)
/// the source x, y and example index.
fn parse_transform(transform: &ts::CoordinateTransform, width: u32, height: u32) -> SourceMap {
    let mut bytes = Vec::new();
    transform
        .write(&mut bytes)
        .expect("writing into a Vec does not fail");
    let words: Vec<u32> = bytes
        .chunks_exact(4)
        .map(|b| u32::from_ne_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    assert!(
        words.len() >= 4 && words[1] == width && words[2] == height,
        "Embark's coordinate transform header {:?} is not for {width}x{height}",
        &words[..words.len().min(4)]
    );
    let maps = words[3] as usize;
    let pixels = &words[4 + 2 * maps..];
    assert_eq!(pixels.len(), (width * height) as usize * 3);
    let texels = pixels
        .chunks_exact(3)
        .map(|p| [p[0] as f32 + 0.5, p[1] as f32 + 0.5])
        .collect();
    SourceMap {
        width,
        height,
        texels,
    }
}
