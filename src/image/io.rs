//! Loading exemplar images from files (PNG, JPEG, BMP, TGA) and resolving an
//! exemplar spec (`builtin:NAME` or a path) into an [`Image`].
//!
//! Architecture invariant: this is the only place in `image/` that touches the
//! file system.

use std::path::Path;

use image::DynamicImage;

use super::builtin::{BUILTIN_PREFIX, ExemplarOptions, builtin_exemplar};
use super::{Image, ImageError};

/// Largest width or height of an exemplar or material map file, pixels.
pub const MAX_IMAGE_SIDE: u32 = 8192;

/// Largest pixel count of an exemplar or material map file: 4096² (16.8 M).
///
/// Why: a loaded image is `f32` per channel (up to 16 bytes a pixel), and the
/// heaviest analyses multiply that: the Gaussian stack of `match` and
/// `graph_match` keeps `4 × levels` planes (13 levels at 4096: ≈ 830 bytes a
/// pixel), the jump-map analysis a neighbourhood vector and 16 jumps per
/// pixel (≈ 500 bytes). At 4096² pixels that is ≈ 13 GiB worst case for the
/// stack, which already needs a large machine; past it, runs abort.
pub const MAX_IMAGE_PIXELS: u64 = 4096 * 4096;

/// Most memory the decoder may allocate, bytes: the largest allowed image
/// at 16-bit RGBA (8 bytes a pixel).
const MAX_DECODE_ALLOC: u64 = MAX_IMAGE_PIXELS * 8;

/// Loads an image file into an [`Image`] with values in `[0, 1]`.
///
/// PNG, JPEG, BMP and TGA are decoded with the `image` crate; the format is
/// guessed from the file contents, so a misnamed extension still loads. 8-bit
/// and 16-bit samples are divided by 255 and 65535. The channel count of the
/// file is kept: 1 (grey), 2 (grey + alpha), 3 (RGB) or 4 (RGBA); colour
/// values stay in the file's encoding (sRGB for ordinary images), with no
/// gamma conversion and no alpha premultiplication.
///
/// # Errors
///
/// [`ImageError::Load`] naming `path` when the file is missing, unreadable or
/// not a decodable image (corrupt, truncated — a JPEG without its end-of-image
/// marker counts — or an unsupported format);
/// [`ImageError::TooLarge`] when its header declares more than
/// [`MAX_IMAGE_SIDE`] pixels a side or [`MAX_IMAGE_PIXELS`] in all (checked
/// before any pixel is decoded);
/// [`ImageError::Invalid`] when it decodes to zero width or height.
pub fn load_image(path: &Path) -> Result<Image, ImageError> {
    let load_err = |message: String| ImageError::Load {
        path: path.to_path_buf(),
        message,
    };
    let open = || -> Result<image::ImageReader<std::io::BufReader<std::fs::File>>, ImageError> {
        let reader = image::ImageReader::open(path).map_err(|e| {
            load_err(match e.kind() {
                std::io::ErrorKind::NotFound => "file not found".to_string(),
                _ => e.to_string(),
            })
        })?;
        let reader = reader
            .with_guessed_format()
            .map_err(|e| load_err(e.to_string()))?;
        if reader.format().is_none() {
            return Err(load_err(
                "not a recognised image format (PNG, JPEG, BMP or TGA expected)".to_string(),
            ));
        }
        Ok(reader)
    };
    // The header first: a small file may declare a huge image.
    let (width, height) = open()?
        .into_dimensions()
        .map_err(|e| load_err(e.to_string()))?;
    if width > MAX_IMAGE_SIDE
        || height > MAX_IMAGE_SIDE
        || width as u64 * height as u64 > MAX_IMAGE_PIXELS
    {
        return Err(ImageError::TooLarge {
            path: path.to_path_buf(),
            width,
            height,
            max_side: MAX_IMAGE_SIDE,
            max_pixels: MAX_IMAGE_PIXELS,
            why: "the Gaussian stack and jump-map analysis of a larger exemplar outgrow memory"
                .into(),
        });
    }
    let mut reader = open()?;
    if reader.format() == Some(image::ImageFormat::Jpeg) {
        check_jpeg_complete(path)?;
    }
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(MAX_IMAGE_SIDE);
    limits.max_image_height = Some(MAX_IMAGE_SIDE);
    limits.max_alloc = Some(MAX_DECODE_ALLOC);
    reader.limits(limits);
    let decoded = reader.decode().map_err(|e| load_err(e.to_string()))?;
    if decoded.width() == 0 || decoded.height() == 0 {
        return Err(ImageError::Invalid {
            path: path.to_path_buf(),
            message: format!(
                "image has zero size ({}x{} pixels)",
                decoded.width(),
                decoded.height()
            ),
        });
    }
    Ok(dynamic_to_image(decoded))
}

/// Refuses a JPEG whose last scan is not followed by an end-of-image marker
/// (`FF D9`): the decoder fills a cut-off file with grey and reports nothing.
/// Inside entropy-coded data every `FF` byte is followed by `00` or a restart
/// marker, so the last start-of-scan (`FF DA`) is the main image's last scan
/// (an embedded EXIF thumbnail comes earlier), and a complete file has
/// `FF D9` after it; bytes after the marker are allowed.
fn check_jpeg_complete(path: &Path) -> Result<(), ImageError> {
    let bytes = std::fs::read(path).map_err(|e| ImageError::Load {
        path: path.to_path_buf(),
        message: e.to_string(),
    })?;
    let marker = |m: u8| move |w: &[u8]| w[0] == 0xFF && w[1] == m;
    let last_scan = bytes.windows(2).rposition(marker(0xDA));
    let complete = last_scan.is_some_and(|s| bytes[s..].windows(2).any(marker(0xD9)));
    if complete {
        return Ok(());
    }
    Err(ImageError::Load {
        path: path.to_path_buf(),
        message: format!(
            "truncated JPEG: no end-of-image marker (FF D9) after the last scan ({} bytes read); the file is incomplete",
            bytes.len()
        ),
    })
}

/// Converts a decoded image to `f32` values in `[0, 1]`, keeping its channels.
fn dynamic_to_image(img: DynamicImage) -> Image {
    let (width, height) = (img.width(), img.height());
    let scale8 = |v: &[u8]| v.iter().map(|&x| x as f32 / 255.0).collect::<Vec<f32>>();
    let scale16 = |v: &[u16]| v.iter().map(|&x| x as f32 / 65535.0).collect::<Vec<f32>>();
    let (channels, data) = match img {
        DynamicImage::ImageLuma8(b) => (1, scale8(b.as_raw())),
        DynamicImage::ImageLumaA8(b) => (2, scale8(b.as_raw())),
        DynamicImage::ImageRgb8(b) => (3, scale8(b.as_raw())),
        DynamicImage::ImageRgba8(b) => (4, scale8(b.as_raw())),
        DynamicImage::ImageLuma16(b) => (1, scale16(b.as_raw())),
        DynamicImage::ImageLumaA16(b) => (2, scale16(b.as_raw())),
        DynamicImage::ImageRgb16(b) => (3, scale16(b.as_raw())),
        DynamicImage::ImageRgba16(b) => (4, scale16(b.as_raw())),
        DynamicImage::ImageRgb32F(b) => (3, b.into_raw()),
        // Float RGBA and any layout a future `image` version adds.
        other => (4, other.into_rgba32f().into_raw()),
    };
    Image {
        width,
        height,
        channels,
        data,
    }
}

/// Resolves an exemplar spec into an image and a display name.
///
/// `spec` is either `builtin:NAME` (one of
/// [`BUILTIN_EXEMPLARS`](super::builtin::BUILTIN_EXEMPLARS), generated with
/// `options`; the display name is the spec) or a path to an image file, which
/// is resolved against `base_dir` when relative (the display name is the
/// spec as written). `options` only applies to builtins.
///
/// # Errors
///
/// [`ImageError::Builtin`] for an unknown builtin name or options out of
/// range; the errors of [`load_image`] for a file.
pub fn exemplar_from_spec(
    spec: &str,
    base_dir: &Path,
    options: &ExemplarOptions,
) -> Result<(Image, String), ImageError> {
    let spec = spec.trim();
    if let Some(name) = spec.strip_prefix(BUILTIN_PREFIX) {
        let img = builtin_exemplar(name.trim(), options)?;
        return Ok((img, format!("{BUILTIN_PREFIX}{}", name.trim())));
    }
    let path = Path::new(spec);
    let full = if path.is_absolute() {
        path.to_path_buf()
    } else {
        base_dir.join(path)
    };
    let img = load_image(&full)?;
    Ok((img, spec.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::{ImageBuffer, LumaA, Rgb};

    #[test]
    fn sixteen_bit_rgb_png_keeps_precision_and_channels() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("deep.png");
        let buf: ImageBuffer<Rgb<u16>, Vec<u16>> =
            ImageBuffer::from_fn(3, 2, |x, y| Rgb([x as u16 * 1000, y as u16 * 65535, 12345]));
        buf.save(&path).unwrap();
        let img = load_image(&path).unwrap();
        assert_eq!((img.width, img.height, img.channels), (3, 2, 3));
        let px = img.pixel(2, 1);
        assert!((px[0] - 2000.0 / 65535.0).abs() < 1e-7, "{px:?}");
        assert_eq!(px[1], 1.0);
        assert!((px[2] - 12345.0 / 65535.0).abs() < 1e-7);
    }

    #[test]
    fn grey_alpha_png_loads_two_channels() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("ga.png");
        let buf: ImageBuffer<LumaA<u8>, Vec<u8>> =
            ImageBuffer::from_fn(4, 5, |x, y| LumaA([(x * 50) as u8, (y * 60) as u8]));
        buf.save(&path).unwrap();
        let img = load_image(&path).unwrap();
        assert_eq!((img.width, img.height, img.channels), (4, 5, 2));
        assert_eq!(img.pixel(3, 4), &[150.0 / 255.0, 240.0 / 255.0]);
        assert_eq!(img.pixel(0, 0), &[0.0, 0.0]);
    }

    #[test]
    fn other_formats_load() {
        let dir = tempfile::tempdir().unwrap();
        let buf: ImageBuffer<Rgb<u8>, Vec<u8>> =
            ImageBuffer::from_fn(8, 8, |x, y| Rgb([(x * 30) as u8, (y * 30) as u8, 77]));
        for ext in ["bmp", "tga", "jpg"] {
            let path = dir.path().join(format!("im.{ext}"));
            buf.save(&path).unwrap();
            let img = load_image(&path).unwrap();
            assert_eq!((img.width, img.height, img.channels), (8, 8, 3), "{ext}");
            let tol = if ext == "jpg" { 0.1 } else { 1e-6 };
            assert!((img.pixel(7, 2)[0] - 210.0 / 255.0).abs() < tol, "{ext}");
            assert!((img.pixel(7, 2)[1] - 60.0 / 255.0).abs() < tol, "{ext}");
        }
    }

    #[test]
    fn missing_corrupt_and_truncated_files_name_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let missing = dir.path().join("nope.png");
        let e = load_image(&missing).unwrap_err().to_string();
        assert!(e.contains("nope.png") && e.contains("not found"), "{e}");

        let corrupt = dir.path().join("corrupt.png");
        std::fs::write(&corrupt, b"this is not an image at all").unwrap();
        let e = load_image(&corrupt).unwrap_err().to_string();
        assert!(e.contains("corrupt.png"), "{e}");

        let good = dir.path().join("good.png");
        let buf: ImageBuffer<Rgb<u8>, Vec<u8>> =
            ImageBuffer::from_fn(32, 32, |x, _| Rgb([x as u8; 3]));
        buf.save(&good).unwrap();
        let bytes = std::fs::read(&good).unwrap();
        let truncated = dir.path().join("truncated.png");
        std::fs::write(&truncated, &bytes[..bytes.len() / 2]).unwrap();
        let e = load_image(&truncated).unwrap_err().to_string();
        assert!(e.contains("truncated.png"), "{e}");
    }

    #[test]
    fn truncated_jpeg_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let good = dir.path().join("good.jpg");
        let buf: ImageBuffer<Rgb<u8>, Vec<u8>> =
            ImageBuffer::from_fn(64, 64, |x, y| Rgb([(x * 4) as u8, (y * 4) as u8, 9]));
        buf.save(&good).unwrap();
        assert!(load_image(&good).is_ok());
        let bytes = std::fs::read(&good).unwrap();
        let cut = dir.path().join("cut.jpg");
        std::fs::write(&cut, &bytes[..bytes.len() * 2 / 3]).unwrap();
        let e = load_image(&cut).unwrap_err().to_string();
        assert!(e.contains("cut.jpg") && e.contains("truncated"), "{e}");
        // Trailing bytes after the end-of-image marker are fine.
        let padded = dir.path().join("padded.jpg");
        std::fs::write(&padded, [&bytes[..], b"trailer"].concat()).unwrap();
        assert!(load_image(&padded).is_ok());
    }

    #[test]
    fn spec_resolves_builtins_and_relative_paths() {
        let dir = tempfile::tempdir().unwrap();
        let opts = ExemplarOptions::default();
        let (img, name) = exemplar_from_spec("builtin:checker", dir.path(), &opts).unwrap();
        assert_eq!(name, "builtin:checker");
        assert_eq!((img.width, img.channels), (64, 3));
        let e = exemplar_from_spec("builtin:plaid", dir.path(), &opts)
            .unwrap_err()
            .to_string();
        assert!(e.contains("plaid") && e.contains("bricks"), "{e}");

        let buf: ImageBuffer<Rgb<u8>, Vec<u8>> = ImageBuffer::from_fn(5, 6, |_, _| Rgb([1, 2, 3]));
        std::fs::create_dir(dir.path().join("tex")).unwrap();
        buf.save(dir.path().join("tex/a.png")).unwrap();
        let (img, name) = exemplar_from_spec("tex/a.png", dir.path(), &opts).unwrap();
        assert_eq!(name, "tex/a.png");
        assert_eq!((img.width, img.height), (5, 6));
        let e = exemplar_from_spec("tex/b.png", dir.path(), &opts)
            .unwrap_err()
            .to_string();
        assert!(e.contains("b.png"), "{e}");
    }
}
