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
use crate::output::html_escape as escape;
use std::io::{Read, Write};
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
    let mut out =
        Vec::with_capacity(TEMPLATE.len() + THREE_BUNDLE.len() + glb.len() / 3 * 4 + 4096);
    let mut reader = glb;
    stream_view(&mut out, &mut reader, glb.len() as u64, glb_name, title)
        .expect("writing into memory");
    String::from_utf8(out).expect("the page is UTF-8")
}

/// Writes `dir/view.html` for the GLB at `glb_path`, atomically, reading
/// the GLB as it goes: neither the GLB nor the page (a third larger) is
/// ever whole in memory, so a dense scan's export peaks no higher; returns
/// its path.
pub fn write_view(dir: &Path, glb_path: &Path, title: &str) -> Result<PathBuf, OutputError> {
    let io_err = |source| OutputError::Io {
        path: glb_path.to_path_buf(),
        source,
    };
    let file = std::fs::File::open(glb_path).map_err(io_err)?;
    let len = file.metadata().map_err(io_err)?.len();
    let name = glb_path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "result.glb".into());
    let path = dir.join(VIEW_FILE);
    let mut glb = std::io::BufReader::new(file);
    super::write_atomic(&path, |w| stream_view(w, &mut glb, len, &name, title))?;
    Ok(path)
}

/// Writes the page: the template with its fields filled, the `glb_len`
/// bytes of `glb` as base64 when at most [`MAX_EMBEDDED_GLB`].
pub fn stream_view(
    w: &mut dyn Write,
    glb: &mut dyn Read,
    glb_len: u64,
    glb_name: &str,
    title: &str,
) -> std::io::Result<()> {
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
    let embedded = glb_len <= MAX_EMBEDDED_GLB as u64;
    let settings = serde_json::json!({
        "title": title,
        "glb_bytes": glb_len,
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
    fill_template(w, TEMPLATE, |key, w| match key {
        "TITLE" => w.write_all(escape(title).as_bytes()),
        "GLB_NAME" => w.write_all(escape(glb_name).as_bytes()),
        "BACKGROUND_TOP" => w.write_all(css(top).as_bytes()),
        "BACKGROUND_BOTTOM" => w.write_all(css(bottom).as_bytes()),
        "THREE_REVISION" => w.write_all(THREE_REVISION.as_bytes()),
        "SETTINGS_JSON" => w.write_all(settings.as_bytes()),
        "GLB_BASE64" if embedded => stream_base64(w, glb),
        "GLB_BASE64" => Ok(()),
        "THREE_BUNDLE" => w.write_all(THREE_BUNDLE.as_bytes()),
        _ => unreachable!("view.html names an unknown field @@{key}@@"),
    })
}

/// Copies `template` into `w`, replacing each `@@KEY@@` by what `field`
/// writes for `KEY`. Only the template is scanned, so a value holding `@@`
/// (the bundle, say) is never substituted again.
fn fill_template(
    w: &mut dyn Write,
    template: &str,
    mut field: impl FnMut(&str, &mut dyn Write) -> std::io::Result<()>,
) -> std::io::Result<()> {
    let mut rest = template;
    while let Some(start) = rest.find("@@") {
        w.write_all(&rest.as_bytes()[..start])?;
        let after = &rest[start + 2..];
        let end = after.find("@@").expect("view.html: an unclosed @@ field");
        field(&after[..end], w)?;
        rest = &after[end + 2..];
    }
    w.write_all(rest.as_bytes())
}

/// Writes standard base64 (RFC 4648, padded) of everything `r` holds, in
/// lines of 76 characters, between two newlines.
fn stream_base64(w: &mut dyn Write, r: &mut dyn Read) -> std::io::Result<()> {
    const ALPHABET: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    // 57 bytes make one 76-character line; a whole number of lines a read.
    const LINE: usize = 57;
    let mut buf = vec![0u8; LINE * 1024];
    let mut text = Vec::with_capacity(buf.len() / 3 * 4 + buf.len() / LINE + 1);
    w.write_all(b"\n")?;
    loop {
        let mut filled = 0;
        while filled < buf.len() {
            match r.read(&mut buf[filled..]) {
                Ok(0) => break,
                Ok(n) => filled += n,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => return Err(e),
            }
        }
        text.clear();
        for line in buf[..filled].chunks(LINE) {
            for chunk in line.chunks(3) {
                let b = [
                    chunk[0],
                    chunk.get(1).copied().unwrap_or(0),
                    chunk.get(2).copied().unwrap_or(0),
                ];
                let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
                let sextet = |k: u32| ALPHABET[((n >> (18 - 6 * k)) & 63) as usize];
                text.push(sextet(0));
                text.push(sextet(1));
                text.push(if chunk.len() > 1 { sextet(2) } else { b'=' });
                text.push(if chunk.len() > 2 { sextet(3) } else { b'=' });
            }
            text.push(b'\n');
        }
        w.write_all(&text)?;
        if filled < buf.len() {
            return Ok(());
        }
    }
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
            let mut out = Vec::new();
            stream_base64(&mut out, &mut input.as_bytes()).unwrap();
            assert_eq!(String::from_utf8(out).unwrap().trim(), expected);
        }
    }

    #[test]
    fn base64_lines_hold_76_characters_across_reads() {
        let bytes: Vec<u8> = (0..200_000u32).map(|i| (i * 7 % 251) as u8).collect();
        let mut out = Vec::new();
        stream_base64(&mut out, &mut bytes.as_slice()).unwrap();
        let text = String::from_utf8(out).unwrap();
        let lines: Vec<&str> = text.trim().lines().collect();
        assert_eq!(lines.len(), bytes.len().div_ceil(57));
        assert!(lines[..lines.len() - 1].iter().all(|l| l.len() == 76));
        assert_eq!(
            text.trim().replace('\n', "").len(),
            bytes.len().div_ceil(3) * 4
        );
    }

    #[test]
    fn a_glb_too_large_to_embed_is_named_not_embedded() {
        let mut page = Vec::new();
        let len = MAX_EMBEDDED_GLB as u64 + 1;
        // The reader is never read: nothing to embed.
        stream_view(&mut page, &mut std::io::empty(), len, "result.glb", "big").unwrap();
        let page = String::from_utf8(page).unwrap();
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
