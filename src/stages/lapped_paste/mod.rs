//! Stage `lapped_paste`: lapped textures (Praun, Finkelstein & Hoppe 2000).
//! Texture patches are cut from the exemplar with an alpha mask (§3.1) and
//! pasted onto surface patches grown on the active mesh (§3.3) and
//! parametrised along the `tangent_field` (§3.4), until every face is
//! covered (§3.6). Each paste becomes an entity (the components of
//! `world::lapped`); faces that later pastes hide completely are dropped
//! from it for runtime pasting (§4), and optionally the pastes are
//! composited into a texture atlas (§4).
//!
//! Extension (issue 13): with `[input] texture_scale` the texture patches
//! are automatic ([`auto_patches`]): several patches of at most 3/4 of the
//! exemplar's side cut at random places, enough to cover it, so pastes show
//! the exemplar's variety without copying more than about a quarter of it
//! at once. On the planar benchmark this halves the coherence error and
//! the structure distance on planks (docs/notes/lapped_planar.md, "Lapped
//! textures: the automatic texture patches"). The paper's single patch is
//! `patches = 1` with `patch_pixels` the exemplar's side.
//!
//! Reads: the active mesh's `Geometry` and `FaceField`, the exemplar; the
//! analysis cache (`cache = true`). Writes: paste entities, the
//! `TexturePatches` and `TexturePatchOrigins` resources, an `AtlasTexture`
//! on the mesh (with `atlas_size > 0`), `TexelSpacing`.
//!
//! Files: this one (settings, the stage and its system); `sizes.rs` (the
//! automatic patch size and count, the progress plan, the memory
//! estimate); `run.rs` (the system's phases around the kernels: the paste
//! loop on the mesh, the atlas, the paste entities, the metrics). Cutting
//! the patches and their cache entries are kernels
//! (`kernels::lapped::cut`, `kernels::lapped::patch_cache`).

mod run;
mod sizes;

pub use crate::kernels::lapped::cut::MaskKind;
pub use sizes::{
    ATLAS_BYTES_PER_TEXEL, ATLAS_BYTES_PER_TRIANGLE, AUTO_PATCH_COVER, AUTO_PATCH_DIAGONAL,
    AUTO_PATCH_MIN_PIXELS, AUTO_PATCH_SIDE_FRACTION, AUTO_PATCHES_MAX, BYTES_PER_PATCH_PIXEL,
    LAYERS_PER_FACE, MATCHED_PATCH_PIXELS, MATCHED_PATCHES, PASTE_BYTES_PER_FACE, SPLOTCH_FILL,
    auto_patches,
};

use crate::config::params::{ParamDoc, ParamRange, StageSettings};
use crate::kernels::lapped::atlas::{AtlasSettings, atlas_layout};
use crate::kernels::lapped::coverage::CoverageSettings;
use crate::kernels::lapped::cut::{CutSettings, MIN_PATCH_PIXELS};
use crate::kernels::lapped::grow::GrowSettings;
use crate::kernels::lapped::param::SolveSettings;
use crate::kernels::lapped::paste::PasteSettings;
use crate::progress::Progress;
use crate::stage::memory::{InputSizes, MemoryEstimate};
use crate::stage::{Datum, InputView, Stage, StageCtx, SystemResult};
use crate::world::*;
use bevy_ecs::prelude::*;
use bevy_ecs::schedule::ScheduleConfigs;
use bevy_ecs::system::ScheduleSystem;
use run::release_freed_memory;
use serde::{Deserialize, Serialize};
use sizes::{PatchPlan, atlas_bytes, paste_bytes};
use std::path::Path;

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
        if (1..MIN_PATCH_PIXELS).contains(&self.patch_pixels) {
            return Err((
                "patch_pixels".into(),
                format!(
                    "{} is too small; allowed: 0 (automatic) or {MIN_PATCH_PIXELS}..=4096",
                    self.patch_pixels
                ),
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
    /// What cutting the texture patches reads.
    pub fn cut_settings(&self) -> CutSettings {
        CutSettings {
            mask: self.mask,
            patches: self.patches,
            patch_pixels: self.patch_pixels,
            falloff: self.falloff,
            hull_vertices: self.hull_vertices,
        }
    }

    /// The atlas kernel's settings.
    pub fn atlas_settings(&self) -> AtlasSettings {
        AtlasSettings {
            size: self.atlas_size,
            normal_cone_deg: self.atlas_normal_cone,
            padding_px: self.atlas_padding,
        }
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
    /// A predefined patch shape is cut from a square of the exemplar: its
    /// side (`patch_pixels`, or at most the exemplar's smaller side when
    /// automatic) must fit the exemplar and be at least
    /// [`MIN_PATCH_PIXELS`].
    fn check_input(settings: &Self::Settings, input: &InputView) -> Result<(), String> {
        let s = input.sizes;
        if settings.mask == MaskKind::Image || s.exemplar_pixels() == 0 {
            return Ok(());
        }
        let (w, h, name) = (s.exemplar_width, s.exemplar_height, input.exemplar);
        let side = w.min(h);
        if settings.patch_pixels > side && !s.exemplar_repeats {
            return Err(format!(
                "`patch_pixels` = {} exceeds the smaller side of the exemplar {name} ({w}x{h} pixels); allowed: at most {side}, or input.exemplar_wrap = \"repeat\" (a tileable exemplar)",
                settings.patch_pixels
            ));
        }
        if settings.patch_pixels == 0 && side < MIN_PATCH_PIXELS {
            return Err(format!(
                "the exemplar {name} is {w}x{h} pixels, too small for a texture patch (`patch_pixels` = 0 takes at most its smaller side, and a patch needs at least {MIN_PATCH_PIXELS}x{MIN_PATCH_PIXELS}); allowed: an exemplar of at least {MIN_PATCH_PIXELS}x{MIN_PATCH_PIXELS} pixels, or `patch_pixels` >= {MIN_PATCH_PIXELS} with input.exemplar_wrap = \"repeat\""
            ));
        }
        Ok(())
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
        let paste = move |mut commands: Commands,
                          active: Res<ActiveMesh>,
                          exemplar: Res<Exemplar>,
                          seed: Res<RunSeed>,
                          mut spacing: ResMut<TexelSpacing>,
                          mut metrics: ResMut<Metrics>,
                          mut meshes: Query<(&mut Geometry, &FaceField)>,
                          old: Query<(Entity, &PasteOf)>|
              -> SystemResult {
            let Ok((mut geometry, field)) = meshes.get_mut(active.0) else {
                return Err(
                    "the active mesh has no tangent field; add `tangent_field` right before".into(),
                );
            };
            let idx = ctx.index;
            let (w, h) = (exemplar.image.width, exemplar.image.height);
            let plan = PatchPlan::new(&settings, &geometry.0, field, (w, h));
            // One bar for the stage: its parts weighed by their work, the
            // pastes' count estimated from a patch's size on the surface.
            let progress = Progress::new(0, Self::KIND);
            let _finish = progress.finish_on_drop();
            progress.plan(plan.progress_parts(settings.atlas_size));
            // The atlas layout depends on the mesh alone: it is made first,
            // while nothing else of this stage is held (the shared atlas
            // kernel needs ~300 bytes per vertex while it runs).
            let atlas = settings.atlas_settings();
            let layout =
                (settings.atlas_size > 0).then(|| atlas_layout(&geometry.0, &atlas, &progress));
            release_freed_memory();
            run::check_fit(&geometry.0, field)?;
            let mask = mask_image.as_ref().map_err(Clone::clone)?.as_ref();
            let settings = plan.settings(&settings, &mut metrics, idx);
            let textures = run::cut_textures(&exemplar, &settings, mask, seed.derive(idx, 1))?;
            let mut paste_settings = settings.paste_settings(seed.derive(idx, 0));
            paste_settings.expected_pastes = plan.expected_pastes();
            let mesh = &mut geometry.bypass_change_detection().0;
            let (pasted, texel_spacing) =
                run::paste(mesh, field, &textures, &paste_settings, &progress)?;
            run::record_metrics(&mut metrics, idx, &pasted, &textures);
            spacing.0 = texel_spacing;
            release_freed_memory();
            let texture = run::composite(layout, &pasted, &textures, &atlas, &mut metrics, idx);
            if let Some(texture) = texture {
                commands.entity(active.0).insert(texture);
            }
            progress.inc(1);
            release_freed_memory();
            run::spawn_pastes(&mut commands, active.0, &old, pasted.pastes, textures);
            Ok(())
        };
        ctx.fallible(Self::KIND, paste)
    }
}
