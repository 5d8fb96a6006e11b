//! Exporters: meshes (PLY, OBJ+MTL+PNG), images, the preview renderer, metrics,
//! contact sheets, the 3D view page (`view.html`).
//!
//! Architecture invariant: every file is written through [`write_atomic`], to a
//! temporary name in the destination folder and renamed, so a failed run never
//! leaves a half-written file that looks complete.

mod bitmap_font;
pub mod contact_sheet;
pub mod decimal;
mod error;
pub mod export;
pub mod gltf;
pub mod obj;
pub mod ply;
pub mod render;
pub mod staging;
pub mod viewer;

pub use error::OutputError;

use std::io::Write;
use std::path::Path;

/// Writes `path` atomically: the closure writes into a temporary file next to
/// `path`, which is renamed over `path` only when the closure succeeded.
pub fn write_atomic(
    path: &Path,
    write: impl FnOnce(&mut dyn Write) -> std::io::Result<()>,
) -> Result<(), OutputError> {
    let io_err = |source| OutputError::Io {
        path: path.to_path_buf(),
        source,
    };
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => std::path::PathBuf::from("."),
    };
    let file_name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "output".to_string());
    let tmp = dir.join(format!(".{file_name}.{}.tmp", std::process::id()));
    // Creating and renaming go through the staging lock, so an interrupt
    // never deletes a run's folder while a file appears in it, nor lets a
    // write recreate it afterwards (`staging` module docs).
    let result = (|| {
        let file = staging::guarded(|| {
            std::fs::create_dir_all(&dir)?;
            std::fs::File::create(&tmp)
        })?;
        let mut buf = std::io::BufWriter::new(file);
        write(&mut buf)?;
        let file = buf.into_inner().map_err(|e| e.into_error())?;
        let _span = tracing::debug_span!("sync_file").entered();
        file.sync_all()?;
        staging::guarded(|| std::fs::rename(&tmp, path))
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result.map_err(io_err)
}

/// Writes bytes atomically.
pub fn write_bytes_atomic(path: &Path, bytes: &[u8]) -> Result<(), OutputError> {
    write_atomic(path, |w| w.write_all(bytes))
}

/// Encodes an image (values clamped to `[0, 1]`, 1–4 channels; more are cut to
/// the first three) as 8-bit PNG bytes.
pub fn encode_png(img: &crate::image::Image) -> Result<Vec<u8>, OutputError> {
    use image::ImageEncoder;
    let c = img.channels as usize;
    let (out_c, color) = match c {
        1 => (1, image::ExtendedColorType::L8),
        2 => (2, image::ExtendedColorType::La8),
        3 => (3, image::ExtendedColorType::Rgb8),
        4 => (4, image::ExtendedColorType::Rgba8),
        _ => (3, image::ExtendedColorType::Rgb8),
    };
    let mut bytes = Vec::with_capacity(img.pixel_count() * out_c);
    for px in img.data.chunks_exact(c.max(1)) {
        for v in &px[..out_c] {
            bytes.push((v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8);
        }
    }
    let mut out = Vec::new();
    image::codecs::png::PngEncoder::new(&mut out)
        .write_image(&bytes, img.width, img.height, color)
        .map_err(|e| OutputError::Encode {
            what: "PNG".into(),
            message: e.to_string(),
        })?;
    Ok(out)
}

/// Writes an image as an 8-bit PNG, atomically.
pub fn write_png(path: &Path, img: &crate::image::Image) -> Result<(), OutputError> {
    let bytes = encode_png(img)?;
    write_bytes_atomic(path, &bytes)
}

/// Encodes 16-bit RGB PNG bytes from `width × height` pixels of three `u16`
/// values each (row-major).
pub fn encode_png_rgb16(width: u32, height: u32, rgb: &[[u16; 3]]) -> Result<Vec<u8>, OutputError> {
    use image::ImageEncoder;
    // PNG stores 16-bit samples big-endian; the encoder takes native-endian bytes.
    let bytes: Vec<u8> = rgb
        .iter()
        .flat_map(|px| px.iter().flat_map(|v| v.to_ne_bytes()))
        .collect();
    let mut out = Vec::new();
    image::codecs::png::PngEncoder::new(&mut out)
        .write_image(&bytes, width, height, image::ExtendedColorType::Rgb16)
        .map_err(|e| OutputError::Encode {
            what: "16-bit PNG".into(),
            message: e.to_string(),
        })?;
    Ok(out)
}

/// The source map of a plane image as 16-bit RGB pixels: R, G = the exemplar
/// pixel index `x`, `y` (`floor` of the source coordinate), B = 65535 where
/// the source is known, all 0 where not (or when the result has no sources).
pub fn plane_source_pixels(plane: &crate::world::PlaneImage) -> Vec<[u16; 3]> {
    let n = plane.image.pixel_count();
    match &plane.sources {
        Some(s) => s
            .iter()
            .map(|p| {
                if p[0].is_finite() && p[1].is_finite() {
                    let q = |v: f32| v.floor().clamp(0.0, 65535.0) as u16;
                    [q(p[0]), q(p[1]), u16::MAX]
                } else {
                    [0; 3]
                }
            })
            .collect(),
        None => vec![[0; 3]; n],
    }
}

/// Escapes text for HTML element content and quoted attribute values.
pub fn html_escape(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            _ => out.push(c),
        }
    }
    out
}
