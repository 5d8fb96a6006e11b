//! Cutting the texture patches of a lapped texture out of the exemplar
//! (Praun et al. 2000 §3.1): one patch from a user mask, or several
//! predefined shapes (seeded splotches, discs) at seeded places. Extension
//! (issue 13): patches after the first may hang over a clamped exemplar's
//! border ([`PATCH_OVERHANG`]) so that their opaque cores reach its corners.

use super::mask::{Mask, TexturePatch, circle_mask, mask_from_image, splotch_mask};
use crate::image::Image;
use crate::image::sample::Wrap;
use crate::kernels::mix;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// The smallest side of the square exemplar region a predefined patch
/// shape is cut from, pixels: a splotch or circle needs a few pixels to
/// have a shape at all.
pub const MIN_PATCH_PIXELS: u32 = 8;

/// The shape of the texture patches.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MaskKind {
    /// A seeded irregular blob, different for every texture patch.
    #[default]
    Splotch,
    /// A disc.
    Circle,
    /// A user mask image (`mask_image`, the exemplar's size, white = inside).
    Image,
}

/// What [`texture_patches`] cuts.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CutSettings {
    /// Shape of the texture patches.
    pub mask: MaskKind,
    /// Number of texture patches (predefined shapes).
    pub patches: u32,
    /// Side of the square exemplar region each patch is cut from (0 = the
    /// exemplar's smaller side).
    pub patch_pixels: u32,
    /// Width of the alpha falloff, pixels.
    pub falloff: f32,
    /// Vertex budget of each patch's polygonal hull.
    pub hull_vertices: u32,
}

/// How far a texture patch after the first may hang over a clamped
/// (non-tileable) exemplar's border, as a fraction of its side; the part
/// outside the exemplar is masked out. Inside the exemplar a patch's centre
/// stays half a side from the border, and a splotch's opaque core (radius
/// about 0.39 of the side) then never reaches the exemplar's corners and
/// edges: on the planar benchmark completeness was 1.15–2.5 × the peer's.
/// With a third of the side the centre comes within a sixth of the side of
/// the border: completeness 0.45–1.13 ×, coherence unchanged (0.67–1.31 ×).
/// A quarter left it 0.77–1.68 ×; half (centres on the border) gave
/// 0.24–0.52 × but raised p90 on brick and planks to 1.57–1.67 × (more
/// straight clipped edges).
pub const PATCH_OVERHANG: f32 = 1.0 / 3.0;

/// Cuts the texture patches of `settings` out of the exemplar. `mask` is
/// the user mask for `mask = "image"`. Errors name what to fix.
pub fn texture_patches(
    exemplar: &Image,
    wrap: Wrap,
    settings: &CutSettings,
    mask: Option<&Image>,
    seed: u64,
) -> Result<Vec<TexturePatch>, String> {
    let (w, h) = (exemplar.width, exemplar.height);
    if settings.mask == MaskKind::Image {
        let img = mask.ok_or("mask = \"image\" needs `mask_image`")?;
        return Ok(vec![user_mask_patch(exemplar, wrap, settings, img)?]);
    }
    let side = if settings.patch_pixels == 0 {
        w.min(h)
    } else {
        settings.patch_pixels
    };
    if side > w.min(h) && wrap == Wrap::Clamp {
        return Err(format!(
            "patch_pixels = {side} exceeds the exemplar's smaller side {} (a larger region needs exemplar_wrap = \"repeat\")",
            w.min(h)
        ));
    }
    if side < MIN_PATCH_PIXELS {
        return Err(format!(
            "patch_pixels = {side} is too small; use at least {MIN_PATCH_PIXELS}"
        ));
    }
    // Each patch from its own seed stream: cut in parallel, in order.
    (0..settings.patches)
        .into_par_iter()
        .map(|k| predefined_patch(exemplar, wrap, settings, side, seed, k))
        .collect()
}

/// The one texture patch of a user mask `img` (the exemplar's size, white
/// = inside): cropped to the inside pixels plus a one-pixel transparent
/// border.
fn user_mask_patch(
    exemplar: &Image,
    wrap: Wrap,
    settings: &CutSettings,
    img: &Image,
) -> Result<TexturePatch, String> {
    let (w, h) = (exemplar.width, exemplar.height);
    if (img.width, img.height) != (w, h) {
        return Err(format!(
            "mask_image is {}x{}, but the exemplar is {w}x{h}; they must match",
            img.width, img.height
        ));
    }
    let full = mask_from_image(img);
    // Crop to the inside pixels plus a one-pixel transparent border.
    let (mut x0, mut y0, mut x1, mut y1) = (i64::MAX, i64::MAX, i64::MIN, i64::MIN);
    for y in 0..h as i64 {
        for x in 0..w as i64 {
            if full.at(x, y) {
                (x0, y0, x1, y1) = (x0.min(x), y0.min(y), x1.max(x), y1.max(y));
            }
        }
    }
    if x0 > x1 {
        return Err("mask_image has no white (inside) pixel".into());
    }
    let (cw, ch) = ((x1 - x0 + 3) as u32, (y1 - y0 + 3) as u32);
    let mut inside = vec![false; (cw * ch) as usize];
    for y in 0..ch as i64 {
        for x in 0..cw as i64 {
            inside[(y * cw as i64 + x) as usize] = full.at(x0 - 1 + x, y0 - 1 + y);
        }
    }
    let cropped = Mask {
        width: cw,
        height: ch,
        inside,
    };
    TexturePatch::cut(
        exemplar,
        wrap,
        [x0 - 1, y0 - 1],
        &cropped,
        settings.falloff,
        settings.hull_vertices as usize,
        "mask_image",
    )
    .map_err(|e| e.to_string())
}

/// Predefined texture patch `k` of side `side`: the first centred, the
/// others at places of their own seed stream, each with its own splotch (or
/// the disc).
fn predefined_patch(
    exemplar: &Image,
    wrap: Wrap,
    settings: &CutSettings,
    side: u32,
    seed: u64,
    k: u32,
) -> Result<TexturePatch, String> {
    let (w, h) = (exemplar.width, exemplar.height);
    let stream = mix(seed, k as u64, 1);
    // Patches after the first may hang over a clamped exemplar's
    // border (the part outside is masked out), so their opaque
    // cores reach its corners too.
    let overhang = match wrap {
        Wrap::Clamp => (side as f32 * PATCH_OVERHANG) as i64,
        Wrap::Repeat => 0,
    };
    let origin = if k == 0 {
        [(w as i64 - side as i64) / 2, (h as i64 - side as i64) / 2]
    } else {
        let span = |n: u32| match wrap {
            Wrap::Repeat => n as u64,
            Wrap::Clamp => (n - side.min(n)) as u64 + 1 + 2 * overhang as u64,
        };
        [
            (stream % span(w)) as i64 - overhang,
            ((stream >> 32) % span(h)) as i64 - overhang,
        ]
    };
    let mut mask = match settings.mask {
        MaskKind::Circle => circle_mask(side),
        _ => splotch_mask(side, mix(seed, k as u64, 2)),
    };
    if overhang > 0 && k > 0 {
        for y in 0..mask.height {
            for x in 0..mask.width {
                let (ex, ey) = (origin[0] + x as i64, origin[1] + y as i64);
                if ex < 0 || ey < 0 || ex >= w as i64 || ey >= h as i64 {
                    mask.inside[(y * mask.width + x) as usize] = false;
                }
            }
        }
    }
    TexturePatch::cut(
        exemplar,
        wrap,
        origin,
        &mask,
        settings.falloff,
        settings.hull_vertices as usize,
        "predefined",
    )
    .map_err(|e| e.to_string())
}
