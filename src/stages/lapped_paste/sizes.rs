//! How large and how many the texture patches are when `[input]
//! texture_scale` sets them ([`auto_patches`]), and what the stage plans
//! from them: its progress parts, the pastes expected, its memory.

use super::LappedPasteSettings;
use crate::kernels::lapped::cut::MIN_PATCH_PIXELS;
use crate::mesh::PolyMesh;
use crate::stage::memory::InputSizes;
use crate::world::{FaceField, Metrics};
use glam::Vec3;

/// Largest share of the mesh's bounding-box diagonal a texture patch spans
/// when its size follows `[input] texture_scale` (the default of an explicit
/// `patch_size` in diagonals before the shared scale existed).
pub const AUTO_PATCH_DIAGONAL: f32 = 0.3;

/// Smallest side of a texture patch chosen automatically, pixels.
pub const AUTO_PATCH_MIN_PIXELS: u32 = 16;

/// Most texture patches chosen automatically.
pub const AUTO_PATCHES_MAX: u32 = 16;

/// Largest side of a texture patch chosen automatically, as a fraction of
/// the exemplar's smaller side. A splotch fills about 47 % of its square
/// (radius 55–100 % of the largest, [`splotch_mask`]), so one paste of a
/// patch of 3/4 of the side shows about a quarter of the exemplar: below
/// a third, the verbatim bound of the quality metrics
/// (`large_region_repeats`). On the planar benchmark whole-exemplar
/// patches copied regions of 45 % of the exemplar 4 times; 3/4 copied at
/// most 25 %, none larger than a third.
pub const AUTO_PATCH_SIDE_FRACTION: f32 = 0.75;

/// Share of its square a splotch fills on average (see
/// [`AUTO_PATCH_SIDE_FRACTION`]); sets the automatic patch count.
pub const SPLOTCH_FILL: f64 = 0.47;

/// Share of the exemplar the automatic texture patches cover together
/// (each at a random place), so a lapped texture shows the exemplar's
/// variety rather than a few regions of it.
pub const AUTO_PATCH_COVER: f64 = 0.95;

/// Texture patches chosen automatically with `choice = "matched"`: more
/// candidates for each paste to choose from. On the planar benchmark
/// (seeds 1–3, five photos, 96-pixel patches) 10 patches (the cover rule)
/// left brick coherence at 0.98 × the peer's and planks completeness at
/// 0.74 ×; 32 met issue 13's gates in 12 of 15 cases, 48 in 13 (brick
/// completeness and planks p90 miss at one seed each); 64 cost a third
/// more time for no further gain.
pub const MATCHED_PATCHES: u32 = 48;

/// Most pixels of all automatic texture patches together (RGBA and alpha,
/// 20 bytes a pixel: 80 MB), so that a large exemplar gets fewer matched
/// candidates instead of gigabytes of patches.
pub const MATCHED_PATCH_PIXELS: u64 = 1 << 22;

/// Mean exemplar pixels per world unit of a per-pixel field (lengths are
/// world units per pixel).
fn field_pixels_per_unit(t: &[Vec3]) -> f32 {
    let mean = t.iter().map(|v| v.length() as f64).sum::<f64>() / t.len().max(1) as f64;
    (1.0 / mean.max(f64::MIN_POSITIVE)) as f32
}

/// The texture patches' size and count and the stage's work, planned from
/// the mesh, the field and the exemplar before anything is cut.
pub(super) struct PatchPlan {
    /// `(patch_pixels, patches)` from the texture scale, with a field in
    /// world units per pixel ([`auto_patches`]).
    auto: Option<(u32, u32)>,
    /// A patch's side on the surface, world units: the field's length is
    /// world units per pixel, or per patch.
    side_world: f64,
    /// The mesh's faces.
    faces: usize,
    /// The mesh's area.
    area: f64,
}

impl PatchPlan {
    /// The plan for `mesh` with the tangent field `field` and an exemplar
    /// of `exemplar` pixels.
    pub fn new(
        settings: &LappedPasteSettings,
        mesh: &PolyMesh,
        field: &FaceField,
        exemplar: (u32, u32),
    ) -> Self {
        // With a field in world units per pixel (`[input] texture_scale`)
        // the patch size and count follow the mesh (`auto_patches`).
        let pixels_per_unit = field_pixels_per_unit(&field.t);
        let auto = field.per_pixel.then(|| {
            let diagonal = mesh
                .bounding_box()
                .map_or(0.0, |(lo, hi)| (hi - lo).length());
            auto_patches(settings, exemplar, pixels_per_unit, diagonal)
        });
        let mean_t = 1.0 / f64::from(pixels_per_unit);
        Self {
            auto,
            side_world: auto.map_or(mean_t, |(pixels, _)| f64::from(pixels) * mean_t),
            faces: mesh.face_count(),
            area: f64::from(mesh.area()),
        }
    }

    /// `settings` with the planned patch size and count: the automatic
    /// ones (recorded as metrics of stage `index`), else at least one
    /// patch.
    pub fn settings(
        &self,
        settings: &LappedPasteSettings,
        metrics: &mut Metrics,
        index: usize,
    ) -> LappedPasteSettings {
        let mut settings = settings.clone();
        if let Some((pixels, patches)) = self.auto {
            metrics.record(index, "patch_pixels", pixels);
            metrics.record(index, "patches", patches);
            (settings.patch_pixels, settings.patches) = (pixels, patches);
        } else if settings.patches == 0 {
            settings.patches = 1;
        }
        settings
    }

    /// The stage's progress parts ([`progress_plan`]).
    pub fn progress_parts(&self, atlas_size: u32) -> Vec<(&'static str, f64)> {
        progress_plan(self.faces, self.area, self.side_world, atlas_size)
    }

    /// The pastes expected ([`expected_pastes`]).
    pub fn expected_pastes(&self) -> f64 {
        expected_pastes(self.faces, self.area, self.side_world)
    }
}

/// `patch_pixels` and `patches` when they are 0 and the field follows the
/// texture scale: a patch spans at most [`AUTO_PATCH_DIAGONAL`] of the
/// diagonal and at most [`AUTO_PATCH_SIDE_FRACTION`] of the exemplar's
/// smaller side (at least [`AUTO_PATCH_MIN_PIXELS`]), and enough patches
/// are cut at random places that their splotches cover
/// [`AUTO_PATCH_COVER`] of the exemplar: `n` with `(1 − a)ⁿ ≤ 1 −
/// AUTO_PATCH_COVER` for the share `a` of the exemplar one splotch fills
/// (at most [`AUTO_PATCHES_MAX`]). With `choice = "matched"` at least
/// [`MATCHED_PATCHES`], as far as [`MATCHED_PATCH_PIXELS`] allows.
pub fn auto_patches(
    settings: &LappedPasteSettings,
    (w, h): (u32, u32),
    pixels_per_unit: f32,
    diagonal: f32,
) -> (u32, u32) {
    let side = w.min(h);
    let pixels = if settings.patch_pixels > 0 {
        settings.patch_pixels
    } else {
        // Never below the smallest patch the cutter takes (an exemplar of
        // 8 to 10 pixels a side would otherwise get a patch it refuses).
        let cap = ((AUTO_PATCH_SIDE_FRACTION * side as f32).floor() as u32)
            .max(MIN_PATCH_PIXELS.min(side))
            .max(1);
        let fit = (AUTO_PATCH_DIAGONAL * diagonal * pixels_per_unit).round();
        (fit.clamp(0.0, cap as f32) as u32).clamp(AUTO_PATCH_MIN_PIXELS.min(cap), cap)
    };
    let patches = if settings.patches > 0 {
        settings.patches
    } else {
        let p = f64::from(pixels.max(1));
        let a = (SPLOTCH_FILL * p * p / (f64::from(w) * f64::from(h))).min(0.999);
        let need = (1.0 - AUTO_PATCH_COVER).ln() / (1.0 - a).ln();
        // A float-to-int cast saturates (an infinite `need` for a tiny
        // patch becomes u32::MAX before the clamp).
        let cover = (need.ceil() as u32).clamp(1, AUTO_PATCHES_MAX);
        if settings.choice == "matched" {
            let budget = (MATCHED_PATCH_PIXELS / (p * p) as u64).min(u64::from(MATCHED_PATCHES));
            cover.max(budget as u32)
        } else {
            cover
        }
    };
    (pixels, patches)
}

/// How many times over the pastes cover the surface: the bunny took 3.2 and
/// 3.7 times the pastes its area over a splotch's gives (2 949 at
/// `texture_scale = 0.06`, 305 at 0.2).
const PASTE_OVERLAP: f64 = 3.4;

/// The stage's parts and their work, for one progress bar: `"atlas"` (when
/// there is one), `"pasting"` and `"drawing"` (the drawn faces and the
/// atlas's compositing). In microseconds as measured on the bunny at
/// `texture_scale = 0.06` (3 674 faces, 2 949 pastes, a 1024² atlas: 0.34 s
/// atlas, mostly packing; 2.5 to 5 s pasting, 0.8 to 1.7 ms a paste; 0.9 s drawing and
/// compositing); the pastes are estimated as the surface's area over the
/// area a patch's splotch covers (`side_world` a side of a patch, world
/// units) times [`PASTE_OVERLAP`], as a smaller texture scale makes them
/// many and small.
fn progress_plan(
    faces: usize,
    area: f64,
    side_world: f64,
    atlas_size: u32,
) -> Vec<(&'static str, f64)> {
    let pastes = expected_pastes(faces, area, side_world);
    let faces = faces as f64;
    let texels = f64::from(atlas_size) * f64::from(atlas_size);
    let mut parts = Vec::with_capacity(3);
    if atlas_size > 0 {
        parts.push(("atlas", 6.0 * faces + 0.15 * texels));
    }
    parts.push(("pasting", 1200.0 * pastes + 10.0 * faces));
    parts.push(("drawing", 50.0 * faces + 0.6 * texels));
    parts
}

/// The pastes expected on a surface of `area` with patches of side
/// `side_world` (world units): the area over a splotch's, times
/// [`PASTE_OVERLAP`], within 1 and the kernel's cap of `4 × faces + 64`.
fn expected_pastes(faces: usize, area: f64, side_world: f64) -> f64 {
    let splotch = (side_world * side_world * SPLOTCH_FILL).max(f64::MIN_POSITIVE);
    (PASTE_OVERLAP * area / splotch).clamp(1.0, 4.0 * faces as f64 + 64.0)
}

/// Bytes per texture-patch pixel: RGBA colours (16) and alpha (4).
pub const BYTES_PER_PATCH_PIXEL: u64 = 20;

/// Bytes per face of the pasting's per-face state beside the layer pool
/// (coverage, levels, seeds, drawn flags; measured about 110).
pub const PASTE_BYTES_PER_FACE: u64 = 150;

/// Layers per face the pool is assumed to hold at once.
pub const LAYERS_PER_FACE: u64 = 5;

/// Bytes per atlas texel (RGBA `f32`) and per triangle of the atlas layout.
pub const ATLAS_BYTES_PER_TEXEL: u64 = 16;
/// See [`ATLAS_BYTES_PER_TEXEL`].
pub const ATLAS_BYTES_PER_TRIANGLE: u64 = 150;

/// The texture patches and the pasting of `settings` on an input of
/// `sizes`: the patches' pixels as [`auto_patches`] chooses them at the
/// run's texture scale (or as set), and the pasting's layer pool chunks and
/// per-face state.
pub(super) fn paste_bytes(settings: &LappedPasteSettings, sizes: &InputSizes) -> (u64, u64) {
    let (w, h) = (sizes.exemplar_width, sizes.exemplar_height);
    let (pixels, patches) = if settings.patches == 0 && settings.patch_pixels == 0 {
        auto_patches(
            settings,
            (w.max(1), h.max(1)),
            sizes.texels_per_unit as f32,
            sizes.diagonal as f32,
        )
    } else if settings.patch_pixels == 0 {
        (w.min(h), settings.patches.max(1))
    } else {
        (settings.patch_pixels, settings.patches.max(1))
    };
    let patch_bytes =
        u64::from(patches) * u64::from(pixels) * u64::from(pixels) * BYTES_PER_PATCH_PIXEL;
    let chunks = (LAYERS_PER_FACE * sizes.triangles)
        .div_ceil(crate::kernels::lapped::coverage::POOL_CHUNK_NODES)
        .max(1);
    let pasting = chunks * crate::kernels::lapped::coverage::POOL_CHUNK_BYTES
        + PASTE_BYTES_PER_FACE * sizes.triangles;
    (patch_bytes, pasting)
}

/// The atlas of side `size` (0: none) on `triangles`.
pub(super) fn atlas_bytes(size: u64, triangles: u64) -> u64 {
    if size == 0 {
        return 0;
    }
    (size * size)
        .saturating_mul(ATLAS_BYTES_PER_TEXEL)
        .saturating_add(ATLAS_BYTES_PER_TRIANGLE * triangles)
}
