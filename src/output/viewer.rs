//! `view.html`: a self-contained page that shows a run's GLB in 3D (orbit,
//! zoom, pan, a light that follows the camera), written beside every
//! `result.glb`.
//!
//! The page opens offline from `file://`: browsers block `fetch()` of a
//! sibling file and ES-module imports there, so it carries everything
//! inline: three.js (core, `GLTFLoader`, `OrbitControls`; r179, MIT, see
//! `viewer/THREE_LICENSE`) as one classic script, bundled by
//! `scripts/viewer/build_three_bundle.sh`, and the GLB's bytes as base64,
//! parsed with `GLTFLoader.parse`. It still names the GLB (a download link
//! and `data-glb` on the view), and loads nothing from anywhere.
//!
//! The initial view is preview 0's camera ([`DEFAULT_VIEWS`]`[0]`, the
//! renderer's field of view and framing, `render/camera.rs`), so a
//! screenshot of the page compares with `preview_0.png`
//! (`scripts/viewer/screenshot.sh`).

use super::OutputError;
use super::render::{Background, DEFAULT_VIEWS, RenderOptions};
use crate::sweep::html::escape;
use std::path::{Path, PathBuf};

/// three.js r179 (npm `three@0.179.1`): core, `GLTFLoader`, `OrbitControls`,
/// one minified IIFE that sets the global `THREE`.
pub const THREE_BUNDLE: &str = include_str!("viewer/three_bundle.min.js");

/// The three.js revision in [`THREE_BUNDLE`].
pub const THREE_REVISION: &str = "179";

/// The page's file name.
pub const VIEW_FILE: &str = "view.html";

/// The largest GLB embedded: its base64 (4/3 of it) must fit a browser's
/// longest string (V8: 2²⁹ − 24 characters, 512 MiB), with room to decode.
/// A larger GLB gets a page that says so and links to it.
pub const MAX_EMBEDDED_GLB: usize = 256 << 20;

/// Intensity of the hemisphere (sky/ground) light.
const FILL_LIGHT: f32 = 0.10;

/// Intensity of the directional light that follows the camera.
const KEY_LIGHT: f32 = 2.3;

const TEMPLATE: &str = include_str!("viewer/view.html");

/// The page showing `glb` (the bytes of the file `glb_name` beside it),
/// captioned `title` (e.g. the run's config). A GLB over
/// [`MAX_EMBEDDED_GLB`] is not embedded: the page says so.
pub fn view_html(glb: &[u8], glb_name: &str, title: &str) -> String {
    let options = RenderOptions::default();
    let view = DEFAULT_VIEWS[0];
    let (top, bottom) = match options.background {
        Background::Solid(c) => (c, c),
        Background::Gradient { top, bottom } => (top, bottom),
    };
    // The preview lights sRGB albedo as `a + (1 − a)·max(0, n·l)` (a =
    // 0.25); the page lights linear albedo (three.js: diffuse = albedo ·
    // intensity · n·l / π) and encodes sRGB, which lifts dim light. These
    // intensities were fitted with `scripts/viewer/screenshot.py` on
    // configs/40_bake_bunny.toml: the object's mean brightness within 1 %
    // of preview_0.png's, the unlit side a little lighter than there.
    let (fill, key) = (FILL_LIGHT, KEY_LIGHT);
    let light = {
        let (right, up, forward) = (-0.25f32, 0.35f32, 1.0f32);
        let n = (right * right + up * up + forward * forward).sqrt();
        [right / n, up / n, forward / n]
    };
    let embedded = glb.len() <= MAX_EMBEDDED_GLB;
    let settings = serde_json::json!({
        "title": title,
        "glb_bytes": glb.len(),
        "embedded": embedded,
        "glb": glb_name,
        "azimuth_deg": view.azimuth_deg,
        "elevation_deg": view.elevation_deg,
        "fov_y_deg": options.fov_y_deg,
        "fill": options.fill,
        "fill_light": fill,
        "key_light": key,
        // Camera space (x right, y up, z toward the viewer), as
        // `Camera::key_light`: from the camera, raised and to the left.
        "key_light_camera": light,
    });
    let settings = serde_json::to_string(&settings)
        .unwrap_or_else(|_| "{}".into())
        // Inside <script>: no "</script>" or "<!--" from the title.
        .replace('<', "\\u003c");
    let css = |c: [f32; 3]| {
        let b = |v: f32| (v.clamp(0.0, 1.0) * 255.0).round() as u8;
        format!("rgb({}, {}, {})", b(c[0]), b(c[1]), b(c[2]))
    };
    let mut out =
        String::with_capacity(TEMPLATE.len() + THREE_BUNDLE.len() + glb.len() / 3 * 4 + 4096);
    fill_template(&mut out, TEMPLATE, |key, out| match key {
        "TITLE" => out.push_str(&escape(title)),
        "GLB_NAME" => out.push_str(&escape(glb_name)),
        "BACKGROUND_TOP" => out.push_str(&css(top)),
        "BACKGROUND_BOTTOM" => out.push_str(&css(bottom)),
        "THREE_REVISION" => out.push_str(THREE_REVISION),
        "SETTINGS_JSON" => out.push_str(&settings),
        "GLB_BASE64" if embedded => base64_into(out, glb),
        "GLB_BASE64" => {}
        "THREE_BUNDLE" => out.push_str(THREE_BUNDLE),
        _ => unreachable!("view.html names an unknown field @@{key}@@"),
    });
    out
}

/// Writes `dir/view.html` for the GLB at `glb_path` (read back from disk:
/// the GLB is streamed when written), atomically; returns its path.
pub fn write_view(dir: &Path, glb_path: &Path, title: &str) -> Result<PathBuf, OutputError> {
    let glb = std::fs::read(glb_path).map_err(|source| OutputError::Io {
        path: glb_path.to_path_buf(),
        source,
    })?;
    let name = glb_path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "result.glb".into());
    let page = view_html(&glb, &name, title);
    drop(glb);
    let path = dir.join(VIEW_FILE);
    super::write_bytes_atomic(&path, page.as_bytes())?;
    Ok(path)
}

/// Copies `template` into `out`, replacing each `@@KEY@@` by what `field`
/// appends for `KEY`. Only the template is scanned, so a value holding
/// `@@` (the bundle, say) is never substituted again.
fn fill_template(out: &mut String, template: &str, mut field: impl FnMut(&str, &mut String)) {
    let mut rest = template;
    while let Some(start) = rest.find("@@") {
        out.push_str(&rest[..start]);
        let after = &rest[start + 2..];
        let end = after.find("@@").expect("view.html: an unclosed @@ field");
        field(&after[..end], out);
        rest = &after[end + 2..];
    }
    out.push_str(rest);
}

/// Appends standard base64 (RFC 4648, padded) of `bytes`, in lines of 76
/// characters.
fn base64_into(out: &mut String, bytes: &[u8]) {
    const ALPHABET: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    out.reserve(bytes.len().div_ceil(3) * 4 + bytes.len() / 57 + 2);
    out.push('\n');
    for (i, chunk) in bytes.chunks(3).enumerate() {
        if i > 0 && i % 19 == 0 {
            out.push('\n');
        }
        let b = [
            chunk[0],
            chunk.get(1).copied().unwrap_or(0),
            chunk.get(2).copied().unwrap_or(0),
        ];
        let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        let sextet = |k: u32| ALPHABET[((n >> (18 - 6 * k)) & 63) as usize] as char;
        out.push(sextet(0));
        out.push(sextet(1));
        out.push(if chunk.len() > 1 { sextet(2) } else { '=' });
        out.push(if chunk.len() > 2 { sextet(3) } else { '=' });
    }
    out.push('\n');
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_matches_rfc_4648_vectors() {
        for (input, expected) in [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foob", "Zm9vYg=="),
            ("fooba", "Zm9vYmE="),
            ("foobar", "Zm9vYmFy"),
        ] {
            let mut out = String::new();
            base64_into(&mut out, input.as_bytes());
            assert_eq!(out.trim(), expected);
        }
    }

    #[test]
    fn a_glb_too_large_to_embed_is_named_not_embedded() {
        let glb = vec![7u8; MAX_EMBEDDED_GLB + 1];
        let page = view_html(&glb, "result.glb", "big");
        assert!(page.len() < THREE_BUNDLE.len() + 64 * 1024);
        assert!(page.contains("\"embedded\":false"));
        assert!(page.contains("data-glb=\"result.glb\""));
    }

    #[test]
    fn the_page_fills_every_field_and_escapes_the_title() {
        let page = view_html(b"glTF", "result.glb", "a <b> & \"c\"</script>");
        assert!(!page.contains("@@"), "a field left unfilled");
        assert!(page.contains("a &lt;b&gt; &amp; &quot;c&quot;&lt;/script&gt;"));
        assert_eq!(
            page.matches("</script>").count(),
            4,
            "only the page's own scripts close"
        );
        assert!(page.contains("data-glb=\"result.glb\""));
        assert!(page.contains("Z2xURg=="));
    }
}
