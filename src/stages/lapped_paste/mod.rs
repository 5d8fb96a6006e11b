//! Stage `lapped_paste`: lapped textures (Praun, Finkelstein & Hoppe 2000).
//! Texture patches are cut from the exemplar with an alpha mask (§3.1) and
//! pasted onto surface patches grown on the active mesh (§3.3) and
//! parametrised along the `tangent_field` (§3.4), until every face is
//! covered (§3.6). Each paste becomes an entity (see [`components`]);
//! faces that later pastes hide completely are flagged for runtime pasting
//! (§4), and optionally the pastes are composited into a texture atlas (§4).
//!
//! Extension (issue 13): with `[input] texture_scale` the texture patches
//! are automatic ([`auto_patches`]): several patches of at most 3/4 of the
//! exemplar's side cut at random places, enough to cover it, so pastes show
//! the exemplar's variety without copying more than about a quarter of it
//! at once. On the planar benchmark this halves the coherence error and
//! the structure distance on planks (ARCHITECTURE.md, "Lapped textures:
//! the automatic texture patches"). The paper's single patch is
//! `patches = 1` with `patch_pixels` the exemplar's side.
//!
//! Reads: the active mesh's `Geometry` and `FaceField`, the exemplar.
//! Writes: paste entities, the `TexturePatches` resource, an
//! `AtlasTexture` on the mesh (with `atlas_size > 0`), `TexelSpacing`.

use crate::config::params::{ParamDoc, ParamRange, StageSettings};
use crate::image::Image;
use crate::image::sample::Wrap;
use crate::kernels::lapped::FaceField as FieldView;
use crate::kernels::lapped::TriMesh;
use crate::kernels::lapped::atlas::{AtlasSettings, composite_atlas_with};
use crate::kernels::lapped::composite::{PasteIndex, PasteRecord};
use crate::kernels::lapped::coverage::{CoverageSettings, drawn_faces};
use crate::kernels::lapped::grow::GrowSettings;
use crate::kernels::lapped::hull::Hull;
use crate::kernels::lapped::mask::{
    Mask, TexturePatch, circle_mask, mask_from_image, patch_image, splotch_mask,
};
use crate::kernels::lapped::param::SolveSettings;
use crate::kernels::lapped::paste::{
    LappedTexture, PASTING_PROGRESS_STEPS, PasteSettings, paste_until_covered,
};
use crate::mesh::PolyMesh;
use crate::progress::Progress;
use crate::stage::memory::{InputSizes, MemoryEstimate};
use crate::stage::{Datum, Stage, StageCtx, StageError};
use crate::world::FaceField;
use crate::world::*;
use bevy_ecs::prelude::*;
use bevy_ecs::schedule::ScheduleConfigs;
use bevy_ecs::system::ScheduleSystem;
use glam::{Vec2, Vec3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::path::Path;

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

/// Settings of `lapped_paste`.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LappedPasteSettings {
    /// Shape of the texture patches.
    pub mask: MaskKind,
    /// The user mask for `mask = "image"`.
    pub mask_image: String,
    /// Number of texture patches (predefined shapes).
    pub patches: u32,
    /// Side of the square exemplar region each texture patch is cut from.
    pub patch_pixels: u32,
    /// Width of the alpha falloff.
    pub falloff: f32,
    /// Vertex budget of each patch's polygonal hull.
    pub hull_vertices: u32,
    /// Largest distortion of a face joining a surface patch (f64 so that
    /// the default prints as written).
    pub max_distortion: f64,
    /// Scale of the distortion measure, texels (0 = per face).
    pub distortion_texels: f32,
    /// Largest growth distance, in hull radii.
    pub max_reach: f32,
    /// Growth rounds after optimisations.
    pub regrow_rounds: u32,
    /// Fraction of a face's samples that must be covered.
    pub coverage_threshold: f32,
    /// Extra seed weight of difficult faces early on.
    pub difficult_first: f32,
    /// Covered fraction of faces until which difficult faces are favoured.
    pub difficult_until: f32,
    /// Paste budget (0 = 4 × faces + 64).
    pub max_pastes: u32,
    /// Seeds per face before it is given up.
    pub max_seeds_per_face: u32,
    /// Side of the texture atlas (0 = no atlas).
    pub atlas_size: u32,
    /// Normal cone of atlas charts.
    pub atlas_normal_cone: f32,
    /// Gutter around atlas charts.
    pub atlas_padding: u32,
    /// Pastes shifted by under a pixel onto pixel centres (extension).
    pub pixel_aligned: bool,
    /// "random" (the paper) or "matched" (extension): how a paste's
    /// texture patch is chosen.
    pub choice: String,
    /// With the matched choice, whole-pixel shifts of the chosen texture
    /// patch tried in each direction (extension; 0 = none).
    pub match_shift: u32,
    /// Read and write the cut texture patches in the on-disk analysis cache.
    pub cache: bool,
}

impl Default for LappedPasteSettings {
    fn default() -> Self {
        let paste = PasteSettings::default();
        let atlas = AtlasSettings::default();
        Self {
            mask: MaskKind::Splotch,
            mask_image: String::new(),
            patches: 0,
            patch_pixels: 0,
            falloff: 3.0,
            hull_vertices: 16,
            max_distortion: 0.6,
            distortion_texels: paste.distortion_texels,
            max_reach: paste.grow.max_reach,
            regrow_rounds: paste.regrow_rounds,
            coverage_threshold: paste.coverage.threshold,
            difficult_first: paste.difficult_first,
            difficult_until: paste.difficult_until,
            max_pastes: 0,
            max_seeds_per_face: paste.max_seeds_per_face,
            atlas_size: 0,
            atlas_normal_cone: atlas.normal_cone_deg,
            atlas_padding: atlas.padding_px,
            pixel_aligned: true,
            choice: "matched".into(),
            match_shift: 2,
            cache: true,
        }
    }
}

impl StageSettings for LappedPasteSettings {
    const PARAMS: &'static [ParamDoc] = &[
        ParamDoc {
            name: "mask",
            unit: "",
            range: ParamRange::OneOf(&["splotch", "circle", "image"]),
            doc: "texture patch shape: a seeded irregular splotch, a circle, or `mask_image` (Praun et al. §3.1)",
        },
        ParamDoc {
            name: "mask_image",
            unit: "",
            range: ParamRange::Any("an image path"),
            doc: "mask = \"image\": a mask of the exemplar's size, white = inside the texture patch",
        },
        ParamDoc {
            name: "patches",
            unit: "",
            range: ParamRange::Int(0, 64),
            doc: "number of texture patches (each paste draws one at random, or with choice = \"matched\" takes the best-matching one); extra ones are cut at random places with their own splotch, and from a clamped exemplar may hang over its border by a third of their side (the outside masked out) so that the exemplar's corners and edges appear; 0 = 1 with an explicit tangent_field patch_size, else enough that their splotches (about 47 % of their squares) cover 95 % of the exemplar at random places, at most 16, and with choice = \"matched\" at least 48 while all patches together hold at most 4 M pixels",
        },
        ParamDoc {
            name: "patch_pixels",
            unit: "pixels",
            range: ParamRange::Int(0, 4096),
            doc: "side of the square exemplar region of a predefined shape; 0 = the exemplar's smaller side with an explicit tangent_field patch_size, else the pixels spanning 0.3 of the mesh's bounding-box diagonal at the texture scale (patches small against the object, as Praun et al. paste), clamped to 16..=3/4 of the smaller side (so one paste copies about a quarter of the exemplar, below the verbatim bound of a third)",
        },
        ParamDoc {
            name: "falloff",
            unit: "pixels",
            range: ParamRange::Float(0.0, 64.0),
            doc: "alpha falls from 1 to 0 over this distance to the patch boundary",
        },
        ParamDoc {
            name: "hull_vertices",
            unit: "",
            range: ParamRange::Int(3, 1024),
            doc: "vertex budget of the conservative polygonal hull that bounds patch growth",
        },
        ParamDoc {
            name: "max_distortion",
            unit: "",
            range: ParamRange::Float(0.0, 1e6),
            doc: "largest (|d_S|² + |d_T|²)/2 of a face joining a patch under its initial parametrisation (0.6 ≈ 47° of rotation), measured at the scale `distortion_texels`",
        },
        ParamDoc {
            name: "distortion_texels",
            unit: "texels",
            range: ParamRange::Float(0.0, 1024.0),
            doc: "scale of the distortion measure: each face's Jacobian is averaged along the growth front over this many texels of the texture patch, so roughness finer than the texture shows (scanner noise) does not stop growth while a fold or field turn at this scale does; where faces are larger it is the per-face measure. 0 = Praun et al.'s per-face rule",
        },
        ParamDoc {
            name: "max_reach",
            unit: "hull radii",
            range: ParamRange::Float(0.5, 1e6),
            doc: "patches grow at most this far from their seed (keeps regrowing bounded where the field cannot be integrated and the parametrisation shrinks)",
        },
        ParamDoc {
            name: "regrow_rounds",
            unit: "",
            range: ParamRange::Int(0, 16),
            doc: "times a patch grows again where the optimisation uncovered the texture patch",
        },
        ParamDoc {
            name: "coverage_threshold",
            unit: "fraction",
            range: ParamRange::Float(0.01, 1.0),
            doc: "a face is covered when this fraction of its texel samples is opaque",
        },
        ParamDoc {
            name: "difficult_first",
            unit: "",
            range: ParamRange::Float(0.0, 1e3),
            doc: "extra seed weight of high-curvature faces and field discontinuities early on (0 = uniform by area)",
        },
        ParamDoc {
            name: "difficult_until",
            unit: "fraction",
            range: ParamRange::Float(0.0, 1.0),
            doc: "difficult faces are favoured while fewer than this fraction of faces is covered",
        },
        ParamDoc {
            name: "max_pastes",
            unit: "",
            range: ParamRange::Int(0, 10_000_000),
            doc: "paste budget; 0 = 4 × faces + 64",
        },
        ParamDoc {
            name: "max_seeds_per_face",
            unit: "",
            range: ParamRange::Int(1, 10_000),
            doc: "pastes seeded on one face before it is reported as not coverable",
        },
        ParamDoc {
            name: "pixel_aligned",
            unit: "",
            range: ParamRange::Any("true | false"),
            doc: "an extension: each paste is shifted by under a pixel so that its seed face's first vertex samples a texture pixel centre; where the parametrisation is one pixel per unit without rotation and the vertices sit on the output's pixel centres (the planar benchmark) every pixel is then an exemplar pixel, not a bilinear mix (sharpness 0.82–0.99 → 1.00–1.14 there); elsewhere a sub-pixel shift; false = the paper (the seed point maps to the patch centre)",
        },
        ParamDoc {
            name: "choice",
            unit: "",
            range: ParamRange::OneOf(&["random", "matched"]),
            doc: "how a paste's texture patch is chosen: \"random\" = the paper's draw; \"matched\" (an extension, image quilting's choice step on the surface) = after growing the surface patch, each texture patch is laid on it and the one whose colours best continue the pastes already under its falloff band (mean squared difference weighted by alpha·(1 − alpha)) wins, and the patch grows on over its hull (the random draw is kept where nothing is pasted under it yet); with automatic patches 48 candidates (fewer for very large patches); only differs with more than one texture patch. Planar benchmark: coherence p90 on brick 1.44 → 0.68 × the peer's, planks 1.36 → 0.91 ×; the texture patches are ranked on the flattened parametrisation the paste keeps (ranked before the flattening, the band moved by pixels on curved surfaces and brick courses broke at paste edges)",
        },
        ParamDoc {
            name: "match_shift",
            unit: "pixels",
            range: ParamRange::Int(0, 8),
            doc: "an extension, with choice = \"matched\" and more than one texture patch: the chosen texture patch is also laid shifted by up to this many whole exemplar pixels in each direction ((2r + 1)² placements, one pass over the band) and the paste keeps the placement whose band continues the pastes under it best (a strictly lower mean error than unshifted); whole pixels keep the planar benchmark's pixel alignment. 0 = only the patch's own placement. Planar benchmark, seeds 1–6, five photos, issue 13's gate: 28 → 30 of 30 cells met at 2 (planks p90 at seed 5 1.07 → 0.89 × the peer's, brick p90 0.73–0.99 → 0.68–0.81 ×; at 1, 4 of the 12 brick and planks cells fail); about 10 ms per planar run",
        },
        ParamDoc {
            name: "cache",
            unit: "",
            range: ParamRange::Any("true | false"),
            doc: "read and write the texture patches cut from the exemplar (splotch or circle masks; they depend only on the exemplar, the patch settings and the seed) in the analysis cache, as jump_map's ($SURFSYNTH_CACHE, else $XDG_CACHE_HOME/surfsynth, else ~/.cache/surfsynth); results are the same either way",
        },
        ParamDoc {
            name: "atlas_size",
            unit: "pixels",
            range: ParamRange::Int(0, 16384),
            doc: "side of the texture atlas the pastes are composited into (Praun et al. §4); 0 = no atlas",
        },
        ParamDoc {
            name: "atlas_normal_cone",
            unit: "degrees",
            range: ParamRange::Float(1.0, 89.0),
            doc: "atlas charts keep every face normal within this angle of the chart seed's",
        },
        ParamDoc {
            name: "atlas_padding",
            unit: "pixels",
            range: ParamRange::Int(0, 64),
            doc: "gutter around each atlas chart, filled by dilation",
        },
    ];

    fn check(&self) -> Result<(), (String, String)> {
        if self.mask == MaskKind::Image {
            if self.mask_image.is_empty() {
                return Err((
                    "mask_image".into(),
                    "mask = \"image\" needs a mask image path".into(),
                ));
            }
            crate::image::load_image(Path::new(&self.mask_image))
                .map_err(|e| ("mask_image".to_string(), e.to_string()))?;
        } else if !self.mask_image.is_empty() {
            return Err((
                "mask_image".into(),
                "only used with mask = \"image\"".into(),
            ));
        }
        Ok(())
    }
}

impl LappedPasteSettings {
    /// The kernel settings.
    pub fn paste_settings(&self, seed: u64) -> PasteSettings {
        PasteSettings {
            grow: GrowSettings {
                max_distortion: self.max_distortion as f32,
                max_reach: self.max_reach,
                ..Default::default()
            },
            distortion_texels: self.distortion_texels,
            solve: SolveSettings::default(),
            regrow_rounds: self.regrow_rounds,
            coverage: CoverageSettings {
                threshold: self.coverage_threshold,
                ..Default::default()
            },
            difficult_first: self.difficult_first,
            difficult_until: self.difficult_until,
            max_pastes: self.max_pastes as usize,
            max_seeds_per_face: self.max_seeds_per_face,
            seed,
            pixel_aligned: self.pixel_aligned,
            matched: self.choice == "matched",
            match_shift: self.match_shift,
            expected_pastes: 0.0,
        }
    }
}

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
        let cap = ((AUTO_PATCH_SIDE_FRACTION * side as f32).floor() as u32).max(1);
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

/// Version of the texture patches' cache entries: bump it whenever
/// [`texture_patches`] would cut anything else for the same inputs.
const PATCH_CACHE_VERSION: u32 = 1;

/// First bytes of a texture-patch cache entry.
const PATCH_CACHE_MAGIC: [u8; 8] = *b"SSPATCHS";

/// [`texture_patches`] through the on-disk analysis cache in `dir`
/// (`None`: no cache; a user mask image is never cached): a valid entry
/// for the same exemplar, settings and seed is read instead of cutting
/// (the same values, bit for bit); a missing, stale or corrupt one is
/// rebuilt and written.
///
/// # Errors
/// As [`texture_patches`].
pub fn texture_patches_cached(
    exemplar: &Image,
    wrap: Wrap,
    settings: &LappedPasteSettings,
    mask: Option<&Image>,
    seed: u64,
    dir: Option<&std::path::Path>,
) -> Result<Vec<TexturePatch>, String> {
    let dir = match dir {
        Some(d) if settings.mask != MaskKind::Image => d,
        _ => return texture_patches(exemplar, wrap, settings, mask, seed),
    };
    let key = patch_cache_key(exemplar, wrap, settings, seed);
    if let Some(patches) = crate::cache::read(dir, "patches", &key)
        .and_then(|bytes| patches_from_bytes(&bytes, &key, exemplar, wrap))
    {
        return Ok(patches);
    }
    let patches = texture_patches(exemplar, wrap, settings, mask, seed)?;
    crate::cache::write(dir, "patches", &key, &patches_to_bytes(&patches, &key));
    Ok(patches)
}

/// The cache key of the texture patches: a BLAKE3 hash of the version, the
/// exemplar (size, channels, every value's bits), its addressing, every
/// setting [`texture_patches`] reads and the seed.
fn patch_cache_key(
    exemplar: &Image,
    wrap: Wrap,
    settings: &LappedPasteSettings,
    seed: u64,
) -> [u8; 32] {
    let mut h = crate::cache_format::key_hasher(&PATCH_CACHE_MAGIC, PATCH_CACHE_VERSION, exemplar);
    h.update(&[
        match wrap {
            Wrap::Repeat => 0u8,
            Wrap::Clamp => 1,
        },
        match settings.mask {
            MaskKind::Splotch => 0u8,
            MaskKind::Circle => 1,
            MaskKind::Image => 2,
        },
    ]);
    for v in [
        settings.patches,
        settings.patch_pixels,
        settings.hull_vertices,
    ] {
        h.update(&v.to_le_bytes());
    }
    h.update(&settings.falloff.to_bits().to_le_bytes());
    h.update(&seed.to_le_bytes());
    *h.finalize().as_bytes()
}

/// A cache entry of `patches`: what cutting computes (alpha, centre, hull,
/// origin); the colours are copied from the exemplar again when read.
fn patches_to_bytes(patches: &[TexturePatch], key: &[u8; 32]) -> Vec<u8> {
    let mut b = crate::cache_format::entry_header(&PATCH_CACHE_MAGIC, PATCH_CACHE_VERSION, key);
    b.extend_from_slice(&(patches.len() as u32).to_le_bytes());
    let f32s = |b: &mut Vec<u8>, v: &[f32]| {
        for x in v {
            b.extend_from_slice(&x.to_le_bytes());
        }
    };
    for p in patches {
        for v in [p.image.width, p.image.height] {
            b.extend_from_slice(&v.to_le_bytes());
        }
        b.extend_from_slice(&(p.hull.vertices.len() as u32).to_le_bytes());
        f32s(&mut b, &p.alpha);
        f32s(&mut b, &[p.centre_px.x, p.centre_px.y]);
        for v in &p.hull.vertices {
            f32s(&mut b, &[v.x, v.y]);
        }
        for o in p.origin {
            b.extend_from_slice(&o.to_le_bytes());
        }
    }
    crate::cache_format::seal(b)
}

/// The patches of an entry written by [`patches_to_bytes`] with `key`, their
/// colours copied from `exemplar` (the key's); `None` for any other bytes.
fn patches_from_bytes(
    bytes: &[u8],
    key: &[u8; 32],
    exemplar: &Image,
    wrap: Wrap,
) -> Option<Vec<TexturePatch>> {
    let body = crate::cache_format::payload(bytes, &PATCH_CACHE_MAGIC, PATCH_CACHE_VERSION, key)?;
    let mut at = 0usize;
    let mut take = |n: usize| -> Option<&[u8]> {
        let s = body.get(at..at.checked_add(n)?)?;
        at += n;
        Some(s)
    };
    let u32_of = |s: &[u8]| u32::from_le_bytes([s[0], s[1], s[2], s[3]]);
    let f32s_of = |s: &[u8]| -> Vec<f32> {
        s.chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect()
    };
    let count = u32_of(take(4)?) as usize;
    let mut patches = Vec::with_capacity(count.min(1024));
    for _ in 0..count {
        let (w, h) = (u32_of(take(4)?), u32_of(take(4)?));
        let hull_n = u32_of(take(4)?) as usize;
        let pixels = (w as usize).checked_mul(h as usize)?;
        let alpha = f32s_of(take(pixels.checked_mul(4)?)?);
        let centre = f32s_of(take(8)?);
        let hull = f32s_of(take(hull_n.checked_mul(8)?)?);
        let mut origin = [0i64; 2];
        for o in origin.iter_mut() {
            let s = take(8)?;
            *o = i64::from_le_bytes(s.try_into().ok()?);
        }
        if w == 0 || h == 0 {
            return None;
        }
        patches.push(TexturePatch {
            image: patch_image(exemplar, wrap, origin, w, h, &alpha),
            alpha,
            centre_px: Vec2::new(centre[0], centre[1]),
            hull: Hull::new(
                hull.chunks_exact(2)
                    .map(|v| Vec2::new(v[0], v[1]))
                    .collect(),
            ),
            origin,
        });
    }
    (at == body.len()).then_some(patches)
}

/// Cuts the texture patches of `settings` out of the exemplar. `mask` is
/// the user mask for `mask = "image"`. Errors name what to fix.
pub fn texture_patches(
    exemplar: &Image,
    wrap: Wrap,
    settings: &LappedPasteSettings,
    mask: Option<&Image>,
    seed: u64,
) -> Result<Vec<TexturePatch>, String> {
    let (w, h) = (exemplar.width, exemplar.height);
    let hull_vertices = settings.hull_vertices as usize;
    if settings.mask == MaskKind::Image {
        let img = mask.ok_or("mask = \"image\" needs `mask_image`")?;
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
        let patch = TexturePatch::cut(
            exemplar,
            wrap,
            [x0 - 1, y0 - 1],
            &cropped,
            settings.falloff,
            hull_vertices,
            "mask_image",
        )
        .map_err(|e| e.to_string())?;
        return Ok(vec![patch]);
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
    if side < 8 {
        return Err(format!(
            "patch_pixels = {side} is too small; use at least 8"
        ));
    }
    // Each patch from its own seed stream: cut in parallel, in order.
    (0..settings.patches)
        .into_par_iter()
        .map(|k| {
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
                hull_vertices,
                "predefined",
            )
            .map_err(|e| e.to_string())
        })
        .collect()
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

/// Records the paste loop's results as metrics of stage `index`.
fn record_metrics(
    metrics: &mut Metrics,
    index: usize,
    out: &LappedTexture,
    draws_per_face: f64,
    textures: &[TexturePatch],
) {
    let r = &out.report;
    metrics.record(index, "pastes", r.pastes);
    metrics.record(index, "mean_pastes_per_face", r.mean_pastes_per_face);
    metrics.record(index, "mean_draws_per_face", draws_per_face);
    metrics.record(index, "mean_faces_per_paste", r.mean_faces_per_paste);
    metrics.record(index, "mean_held_per_face", r.mean_held_per_face);
    metrics.record(index, "max_held_per_face", r.max_held_per_face);
    metrics.record(index, "uncovered_faces", r.uncovered_faces.len());
    metrics.record(
        index,
        "uncovered_face_ids",
        r.uncovered_faces.iter().take(100).collect::<Vec<_>>(),
    );
    metrics.record(index, "regrown_faces", r.regrown_faces);
    metrics.record(index, "rechosen_pastes", r.rechosen_pastes);
    metrics.record(index, "shifted_pastes", r.shifted_pastes);
    metrics.record(index, "cg_iterations", r.cg_iterations);
    metrics.record(index, "unconverged_solves", r.unconverged_solves);
    metrics.record(index, "direct_solves", r.direct_solves);
    metrics.record(index, "texture_patches", textures.len());
    metrics.record(
        index,
        "hull_vertices",
        textures
            .iter()
            .map(|t| t.hull.vertices.len())
            .collect::<Vec<_>>(),
    );
}

/// The texture atlas's charts and coordinates, before the pastes exist.
struct AtlasLayout {
    charts: usize,
    corner_uvs: Vec<[Vec2; 3]>,
    texels_per_unit: f32,
    fill: f32,
}

/// Lays out the atlas of `mesh` (triangles only; the paste loop reports
/// any other face) with the shared atlas kernel.
/// Laying out a million-vertex scan takes tens of seconds: it is the part
/// `"atlas"` of the stage's `progress`.
fn atlas_layout(
    mesh: &PolyMesh,
    settings: &AtlasSettings,
    progress: &Progress,
) -> Result<AtlasLayout, String> {
    let tris: Vec<[u32; 3]> = (0..mesh.face_count())
        .map(|f| match mesh.face(f) {
            &[a, b, c] => Ok([a, b, c]),
            _ => Err(format!("face {f} is not a triangle")),
        })
        .collect::<Result<_, _>>()?;
    let uv = crate::kernels::atlas::build_uv_atlas_with_progress(
        &mesh.positions,
        &tris,
        settings,
        progress,
    )
    .map_err(|e| e.to_string())?;
    Ok(AtlasLayout {
        charts: uv.charts.count,
        corner_uvs: uv.corner_uvs,
        texels_per_unit: uv.texels_per_unit,
        fill: uv.fill,
    })
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
fn paste_bytes(settings: &LappedPasteSettings, sizes: &InputSizes) -> (u64, u64) {
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
fn atlas_bytes(size: u64, triangles: u64) -> u64 {
    if size == 0 {
        return 0;
    }
    (size * size)
        .saturating_mul(ATLAS_BYTES_PER_TEXEL)
        .saturating_add(ATLAS_BYTES_PER_TRIANGLE * triangles)
}

/// Returns the heap pages freed so far to the system (glibc's
/// `malloc_trim`). Measured before `main` fixed glibc's mmap threshold: the
/// paste loop's per-face arrays were freed in the middle of the heap, where
/// glibc kept their pages resident, and the atlas kernel allocates blocks
/// too large to reuse those holes, so the process peaked ~200 MB higher at
/// 901 k vertices. With the fixed threshold large buffers go back by
/// themselves; this still returns the loop's many small allocations
/// (per-paste lists, coverage-test scratch) and the atlas kernel's.
fn release_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: `malloc_trim` only releases free pages of the allocator's own
    // heaps; it is thread-safe and takes no pointer.
    unsafe {
        libc::malloc_trim(0);
    }
}

/// The `lapped_paste` stage.
pub struct LappedPaste;

impl Stage for LappedPaste {
    const KIND: &'static str = "lapped_paste";
    const SUMMARY: &'static str = "lapped textures: paste alpha-masked texture patches along the tangent field until the mesh is covered; optional atlas";
    const PAPER: &'static str = "Praun, Finkelstein & Hoppe 2000 §3, §4";
    type Settings = LappedPasteSettings;

    fn requires(_: &Self::Settings) -> Vec<Datum> {
        vec![Datum::Mesh, Datum::FaceField]
    }
    fn produces(_: &Self::Settings) -> Vec<Datum> {
        vec![Datum::Patches]
    }
    /// The texture patches, then the larger of the pasting (the layer
    /// pool and per-face state) and the atlas (`atlas_size`: RGBA per
    /// texel and the layout per triangle).
    fn memory_estimate(settings: &Self::Settings, sizes: &InputSizes) -> Vec<MemoryEstimate> {
        if settings.atlas_size == 0 && !sizes.loaded {
            return Vec::new();
        }
        let (patches, pasting) = paste_bytes(settings, sizes);
        let triangles = sizes.triangles;
        vec![MemoryEstimate::growing(
            "atlas_size",
            "the texture patches, the pasting's layers and the RGBA atlas",
            u64::from(settings.atlas_size),
            (0, 16384),
            move |s| patches + pasting.max(atlas_bytes(s, triangles)),
            |s| s.to_string(),
        )]
    }
    fn systems(settings: Self::Settings, ctx: StageCtx) -> ScheduleConfigs<ScheduleSystem> {
        // The user mask is read when the schedule is built (systems do no
        // file I/O); it was already checked when the config was loaded.
        let mask_image = (settings.mask == MaskKind::Image)
            .then(|| crate::image::load_image(Path::new(&settings.mask_image)))
            .transpose()
            .map_err(|e| e.to_string());
        (move |mut commands: Commands,
               active: Res<ActiveMesh>,
               exemplar: Res<Exemplar>,
               seed: Res<RunSeed>,
               mut spacing: ResMut<TexelSpacing>,
               mut metrics: ResMut<Metrics>,
               mut failure: ResMut<StageFailure>,
               mut meshes: Query<(&mut Geometry, &FaceField)>,
               old: Query<(Entity, &PasteOf)>| {
            let fail = |message: String| StageError {
                index: ctx.index + 1,
                kind: Self::KIND.into(),
                message,
            };
            let Ok((mut geometry, field)) = meshes.get_mut(active.0) else {
                failure.0 = Some(fail(
                    "the active mesh has no tangent field; add `tangent_field` right before".into(),
                ));
                return;
            };
            // One bar for the stage: its parts weighed by their work, the
            // pastes' count estimated from a patch's size on the surface.
            let progress = Progress::new(0, Self::KIND);
            let _finish = progress.finish_on_drop();
            // With a field in world units per pixel (`[input] texture_scale`)
            // the patch size and count follow the mesh (`auto_patches`).
            let pixels_per_unit = field_pixels_per_unit(&field.t);
            let auto = field.per_pixel.then(|| {
                let diagonal = geometry
                    .0
                    .bounding_box()
                    .map_or(0.0, |(lo, hi)| (hi - lo).length());
                auto_patches(
                    &settings,
                    (exemplar.image.width, exemplar.image.height),
                    pixels_per_unit,
                    diagonal,
                )
            });
            // A patch's side on the surface: the field's length is world
            // units per pixel, or per patch.
            let mean_t = 1.0 / f64::from(pixels_per_unit);
            let side_world = auto.map_or(mean_t, |(pixels, _)| f64::from(pixels) * mean_t);
            progress.plan(progress_plan(
                geometry.0.face_count(),
                f64::from(geometry.0.area()),
                side_world,
                settings.atlas_size,
            ));
            // The atlas layout depends on the mesh alone: it is made first,
            // while nothing else of this stage is held (the shared atlas
            // kernel needs ~300 bytes per vertex while it runs).
            let atlas_settings = AtlasSettings {
                size: settings.atlas_size,
                normal_cone_deg: settings.atlas_normal_cone,
                padding_px: settings.atlas_padding,
            };
            let layout = (settings.atlas_size > 0)
                .then(|| atlas_layout(&geometry.0, &atlas_settings, &progress));
            release_freed_memory();
            let fits = match TriMesh::check(&geometry.0) {
                Ok(()) => field.t.len() == geometry.0.face_count(),
                Err(e) => {
                    failure.0 = Some(fail(e.to_string()));
                    return;
                }
            };
            if !fits {
                failure.0 = Some(fail(
                    "the tangent field does not fit the mesh; run `tangent_field` after the last stage that changes the mesh".into(),
                ));
                return;
            }
            let mask = match &mask_image {
                Ok(m) => m.as_ref(),
                Err(e) => {
                    failure.0 = Some(fail(e.clone()));
                    return;
                }
            };
            // With a field in world units per pixel the patch size and count
            // follow the mesh (`auto`, above); T is then scaled by the patch
            // image's side, below.
            let mut settings = settings.clone();
            if let Some((pixels, patches)) = auto {
                metrics.record(ctx.index, "patch_pixels", pixels);
                metrics.record(ctx.index, "patches", patches);
                (settings.patch_pixels, settings.patches) = (pixels, patches);
            } else if settings.patches == 0 {
                settings.patches = 1;
            }
            let texture_span = tracing::info_span!("texture_patches").entered();
            let cache_dir = settings.cache.then(crate::cache::default_dir).flatten();
            let textures = match texture_patches_cached(
                &exemplar.image,
                exemplar.wrap,
                &settings,
                mask,
                seed.derive(ctx.index, 1),
                cache_dir.as_deref(),
            ) {
                Ok(t) => t,
                Err(message) => {
                    failure.0 = Some(fail(message));
                    return;
                }
            };
            drop(texture_span);
            let mut paste_settings = settings.paste_settings(seed.derive(ctx.index, 0));
            paste_settings.expected_pastes = expected_pastes(
                geometry.0.face_count(),
                f64::from(geometry.0.area()),
                side_world,
            );
            let unit_px = textures.iter().map(TexturePatch::unit_px).fold(1.0f32, f32::max);
            // A field in world units per pixel is read in patch units
            // (scaled as it is read, not copied).
            let view = FieldView {
                t: &field.t,
                isotropic: field.isotropic,
                scale: if field.per_pixel { unit_px } else { 1.0 },
            };
            // The loop takes the mesh's positions and corners instead of
            // copying them; they go back right after it, unchanged (so
            // change detection is bypassed: the mesh is the same).
            let tri = match TriMesh::from_owned(std::mem::take(
                &mut geometry.bypass_change_detection().0,
            )) {
                Ok(t) => t,
                Err((mesh, e)) => {
                    geometry.bypass_change_detection().0 = mesh;
                    failure.0 = Some(fail(e.to_string()));
                    return;
                }
            };
            progress.start_part("pasting", PASTING_PROGRESS_STEPS);
            let out = paste_until_covered(&tri, view, &textures, &paste_settings, &progress);
            progress.start_part("drawing", 2);
            let drawn_span = tracing::info_span!("drawn_faces").entered();
            let sizes: Vec<usize> = out.pastes.iter().map(|p| p.faces.len()).collect();
            let drawn = drawn_faces(&out.coverage, &sizes, &textures, &paste_settings.coverage);
            let draws: usize = drawn.iter().map(|d| d.iter().filter(|&&x| x).count()).sum();
            let draws_per_face = draws as f64 / tri.face_count().max(1) as f64;
            drop(drawn_span);
            progress.inc(1);
            record_metrics(&mut metrics, ctx.index, &out, draws_per_face, &textures);

            // World units per exemplar texel, for the quality metrics.
            let mean_scale = (0..view.t.len())
                .map(|f| view.at(f).length() as f64)
                .sum::<f64>()
                / view.t.len().max(1) as f64;
            spacing.0 = (mean_scale as f32 / unit_px).max(f32::MIN_POSITIVE);

            // Only the faces runtime pasting draws are kept (§4): the
            // hidden ones were ~3/4 of all layers on a scan. The coverage
            // and the adjacency go before the atlas is composited.
            let LappedTexture {
                pastes, coverage, ..
            } = out;
            drop(coverage);
            geometry.bypass_change_detection().0 = tri.into_poly_mesh();
            let kept: Vec<(u32, Vec<u32>, Vec<Vec2>)> = pastes
                .into_iter()
                .zip(&drawn)
                .map(|(paste, drawn)| {
                    let n = drawn.iter().filter(|&&d| d).count();
                    let mut faces = Vec::with_capacity(n);
                    let mut uvs = Vec::with_capacity(3 * n);
                    for ((&f, uv), &d) in paste.faces.iter().zip(&paste.uvs).zip(drawn) {
                        if d {
                            faces.push(f);
                            uvs.extend_from_slice(uv);
                        }
                    }
                    (paste.texture, faces, uvs)
                })
                .collect();
            drop(drawn);
            release_freed_memory();

            match layout {
                Some(Ok(layout)) => {
                    let records: Vec<PasteRecord> = kept
                        .iter()
                        .map(|(texture, faces, uvs)| PasteRecord {
                            texture: *texture,
                            faces,
                            uvs,
                        })
                        .collect();
                    match PasteIndex::new(layout.corner_uvs.len(), &records) {
                        Ok(index) => {
                            let image = composite_atlas_with(
                                &layout.corner_uvs,
                                &|f, out| out.extend(index.layers(f).map(|(_, t, uv)| (t, uv))),
                                &textures,
                                atlas_settings.size,
                                atlas_settings.padding_px,
                            );
                            metrics.record(ctx.index, "atlas_charts", layout.charts);
                            metrics.record(ctx.index, "atlas_fill", layout.fill);
                            metrics.record(
                                ctx.index,
                                "atlas_texels_per_unit",
                                layout.texels_per_unit,
                            );
                            commands.entity(active.0).insert(AtlasTexture {
                                uvs: layout.corner_uvs.into_flattened(),
                                image,
                            });
                        }
                        Err(reason) => metrics.record(
                            ctx.index,
                            "atlas",
                            format!("skipped: {reason}"),
                        ),
                    }
                }
                Some(Err(reason)) => {
                    metrics.record(ctx.index, "atlas", format!("skipped: {reason}"))
                }
                None => {}
            }
            progress.inc(1);

            release_freed_memory();
            for (entity, of) in &old {
                if of.0 == active.0 {
                    commands.entity(entity).despawn();
                }
            }
            for (i, (texture, faces, uvs)) in kept.into_iter().enumerate() {
                let n = faces.len();
                commands.spawn((
                    PasteOf(active.0),
                    PasteOrder(i as u32),
                    TexturePatchIndex(texture),
                    PatchFaces(faces),
                    PatchUvs(uvs),
                    PatchDrawn(vec![true; n]),
                ));
            }
            commands.insert_resource(TexturePatchOrigins(
                textures.iter().map(|t| t.origin).collect(),
            ));
            commands.insert_resource(TexturePatches(
                textures.into_iter().map(|t| t.image).collect(),
            ));
        })
        .into_configs()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn exemplar() -> Image {
        let data = (0..48 * 40 * 3)
            .map(|i| ((i * 37) % 101) as f32 / 100.0)
            .collect();
        Image::from_data(48, 40, 3, data).expect("size matches")
    }

    #[test]
    fn texture_patch_cache_round_trips_and_rejects_other_keys_and_damage() {
        let ex = exemplar();
        let settings = LappedPasteSettings {
            patches: 3,
            patch_pixels: 24,
            ..Default::default()
        };
        let cut = texture_patches(&ex, Wrap::Clamp, &settings, None, 7).expect("cut");
        let key = patch_cache_key(&ex, Wrap::Clamp, &settings, 7);
        let bytes = patches_to_bytes(&cut, &key);
        let back = patches_from_bytes(&bytes, &key, &ex, Wrap::Clamp).expect("round trip");
        assert_eq!(back.len(), cut.len());
        for (a, b) in cut.iter().zip(&back) {
            assert_eq!(a.image, b.image);
            assert_eq!(a.alpha, b.alpha);
            assert_eq!(a.centre_px, b.centre_px);
            assert_eq!(a.hull.vertices, b.hull.vertices);
            assert_eq!(a.hull.bounds, b.hull.bounds);
            assert_eq!(a.origin, b.origin);
        }
        // Another seed or setting is another key.
        assert_ne!(key, patch_cache_key(&ex, Wrap::Clamp, &settings, 8));
        let other = LappedPasteSettings {
            falloff: 2.0,
            ..settings.clone()
        };
        assert_ne!(key, patch_cache_key(&ex, Wrap::Clamp, &other, 7));
        let mut bad = bytes.clone();
        bad[60] ^= 1;
        assert!(patches_from_bytes(&bad, &key, &ex, Wrap::Clamp).is_none());
        assert!(patches_from_bytes(&bytes[..bytes.len() - 3], &key, &ex, Wrap::Clamp).is_none());
        // Through a cache folder: cut and written first, read second.
        let dir = tempfile::tempdir().expect("temp dir");
        let first = texture_patches_cached(&ex, Wrap::Clamp, &settings, None, 7, Some(dir.path()))
            .expect("cut");
        assert_eq!(std::fs::read_dir(dir.path()).expect("dir").count(), 1);
        let second = texture_patches_cached(&ex, Wrap::Clamp, &settings, None, 7, Some(dir.path()))
            .expect("read");
        assert_eq!(first.len(), second.len());
        for (a, b) in first.iter().zip(&second) {
            assert_eq!(a.image, b.image);
            assert_eq!(a.hull.vertices, b.hull.vertices);
        }
    }
}
