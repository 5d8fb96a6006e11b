//! Stage `jump_surface`: jump-map texture synthesis directly on the surface
//! (Zelinka & Garland 2004 §6). The mesh keeps its vertices; the result is
//! per-corner texture coordinates (one base vertex per face, for OBJ) plus
//! the three base-vertex layers of the §6.5 blend (for previews and bakes).
//! Texture scale is a parameter only: no remeshing.
//!
//! Reads: the active mesh's `Geometry` and `Frames`, `ExemplarJumpMap`, the
//! exemplar, `TextureScale`; with `refine = "seams"` the analysis cache.
//! Writes: on the active mesh `CornerUvs`, `BlendUvs`, `SourceTexels`,
//! `VertexScale`; `TexelSpacing`. The system's phases are in `run.rs`.

mod run;

use run::StageRun;

use crate::config::params::{ParamDoc, ParamRange, StageSettings};
use crate::kernels::jump_maps::jump_surface::corner_side_offsets;
use crate::kernels::jump_maps::vertex_order::VertexOrder;
use crate::kernels::wei_levoy::wl_match::SynthesisLevel;
use crate::stage::memory::{InputSizes, MemoryEstimate};
use crate::stage::{Datum, Stage, StageCtx, SystemResult};
use crate::world::*;
use bevy_ecs::prelude::*;
use bevy_ecs::schedule::ScheduleConfigs;
use bevy_ecs::system::ScheduleSystem;
use glam::{Vec2, Vec3};
use serde::{Deserialize, Serialize};
use std::time::Instant;

/// Settings of `jump_surface`.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct JumpSurfaceSettings {
    /// Exemplar pixels per world unit; 0 = `[input] texture_scale`.
    pub scale: f32,
    /// Scale multipliers at the lowest and highest vertex along `height_axis`.
    pub scale_by_height: [f32; 2],
    /// The axis `scale_by_height` varies along.
    pub height_axis: [f32; 3],
    /// Desired patch size, fraction of the exemplar side.
    pub patch_fraction: f32,
    /// Boundary-avoidance band, fraction of the exemplar size.
    pub boundary_fraction: f32,
    /// Vertex ordering.
    pub order: VertexOrder,
    /// Largest area one patch copies, fraction of the exemplar's area
    /// (extension; 0 = unbounded, the paper).
    pub max_patch_area: f32,
    /// Random starts at pixel centres (extension; false = the paper).
    pub pixel_aligned: bool,
    /// "random" (the paper) or "matched" (extension).
    pub choice: String,
    /// "none" (the paper) or "seams" (extension): coherent correction
    /// passes over the band around the seams.
    pub refine: String,
    /// Read and write the seam refinement's appearance analysis in the
    /// on-disk analysis cache.
    pub cache: bool,
}

/// Default of `max_patch_area`: a quarter of the exemplar, below the third
/// above which a copied region counts as a large verbatim copy (the quality
/// metrics' `large_region_repeats`), and the same bound as one lapped paste
/// (`kernels::lapped::auto_patches`).
pub const MAX_PATCH_AREA: f32 = 0.25;

impl Default for JumpSurfaceSettings {
    fn default() -> Self {
        Self {
            scale: 0.0,
            scale_by_height: [1.0, 1.0],
            height_axis: [0.0, 1.0, 0.0],
            patch_fraction: 0.5,
            boundary_fraction: 0.2,
            order: VertexOrder::EmergingFront,
            max_patch_area: MAX_PATCH_AREA,
            pixel_aligned: true,
            choice: "matched".into(),
            refine: "seams".into(),
            cache: true,
        }
    }
}

impl StageSettings for JumpSurfaceSettings {
    const PARAMS: &'static [ParamDoc] = &[
        ParamDoc {
            name: "scale",
            unit: "pixels per world unit",
            range: ParamRange::Float(0.0, 1e9),
            doc: "texture scale (§6.1); 0 = the run's `[input] texture_scale` (default: the exemplar's width spans half the bounding-box diagonal); a value here overrides it for this stage",
        },
        ParamDoc {
            name: "scale_by_height",
            unit: "factor",
            range: ParamRange::Float(0.01, 100.0),
            doc: "scale multiplier at the lowest and the highest vertex along height_axis, linear between (Fig. 15); [1, 1] = uniform",
        },
        ParamDoc {
            name: "height_axis",
            unit: "world axes",
            range: ParamRange::Float(-1e6, 1e6),
            doc: "direction along which scale_by_height varies (non-zero)",
        },
        ParamDoc {
            name: "patch_fraction",
            unit: "fraction",
            range: ParamRange::Float(0.01, 16.0),
            doc: "desired patch size as a fraction of the exemplar side: patches of about (f·side)² pixels (§5.1; paper 1/3-3/4)",
        },
        ParamDoc {
            name: "boundary_fraction",
            unit: "fraction",
            range: ParamRange::Float(0.0, 0.5),
            doc: "band near the exemplar border where jumps become likelier (§5.2; paper 1/5); inset maps only",
        },
        ParamDoc {
            name: "order",
            unit: "",
            range: ParamRange::OneOf(&["emerging_front", "breadth_first", "random"]),
            doc: "vertex order: emerging front (§6.2, the paper's), or breadth-first / random for comparison",
        },
        ParamDoc {
            name: "max_patch_area",
            unit: "fraction of the exemplar's area",
            range: ParamRange::Float(0.0, 1.0),
            doc: "an extension: once the vertices copied from one jump or random start cover this much texel area, they stop suggesting copies and the next vertex jumps, so no patch copies a large part of the exemplar verbatim again and again; 0 = unbounded (the paper)",
        },
        ParamDoc {
            name: "choice",
            unit: "",
            range: ParamRange::OneOf(&["random", "matched"]),
            doc: "random = the paper's selection table (§6.6); matched = an extension: the paper's draw still decides whether a vertex copies or jumps, but where patches meet, which jump, and where a random start goes, the candidate whose exemplar neighbourhood best matches the vertices already synthesised within four edges wins",
        },
        ParamDoc {
            name: "refine",
            unit: "",
            range: ParamRange::OneOf(&["none", "seams"]),
            doc: "none = the paper's result; seams = an extension (the `coherent` stage's kernel): the vertices next to a seam (an edge between two patches) get up to 3 correction passes that may take any neighbour's shifted address, compared in appearance space over three rings; a vertex that moves puts its neighbours back in the band, so seams move to where the patches agree and the rest of each patch stays as copied. Applies on meshes of 0.5 to 2 exemplar pixels per edge with a uniform scale (scale_by_height [1, 1]); skipped otherwise (metric refine_skipped says why)",
        },
        ParamDoc {
            name: "cache",
            unit: "",
            range: ParamRange::Any("true | false"),
            doc: "read and write the seam refinement's appearance analysis (exemplar only) in the analysis cache, as jump_map's ($SURFSYNTH_CACHE, else $XDG_CACHE_HOME/surfsynth, else ~/.cache/surfsynth); results are the same either way",
        },
        ParamDoc {
            name: "pixel_aligned",
            unit: "",
            range: ParamRange::Any("true | false"),
            doc: "an extension: random starts at exemplar pixel centres; copies and jumps keep a start's sub-pixel phase, so a start between centres blurs its whole patch (bilinear resampling) wherever the mapping is pixel-aligned; false = anywhere (the paper)",
        },
    ];

    fn check(&self) -> Result<(), (String, String)> {
        if Vec3::from(self.height_axis).length_squared() < 1e-12 {
            return Err(("height_axis".into(), "must not be the zero vector".into()));
        }
        Ok(())
    }
}

/// The `jump_surface` stage.
pub struct JumpSurface;

impl Stage for JumpSurface {
    const KIND: &'static str = "jump_surface";
    const SUMMARY: &'static str =
        "jump-map synthesis on the mesh: per-corner texture coordinates with a 3-way blend";
    const PAPER: &'static str = "Zelinka & Garland 2004 §6";
    type Settings = JumpSurfaceSettings;

    /// The per-vertex jumps, the per-corner texture coordinates and the
    /// seam bookkeeping, about 400 bytes a vertex (measured:
    /// `tests/memory_estimates.rs`).
    fn memory_estimate(_settings: &Self::Settings, sizes: &InputSizes) -> Vec<MemoryEstimate> {
        const PER_VERTEX: u64 = 400;
        MemoryEstimate::per_vertex(
            "the per-vertex jumps and per-corner coordinates",
            sizes,
            0,
            PER_VERTEX,
        )
    }
    fn requires(_: &Self::Settings) -> Vec<Datum> {
        vec![Datum::Mesh, Datum::Frames, Datum::JumpMap]
    }
    fn produces(_: &Self::Settings) -> Vec<Datum> {
        vec![Datum::CornerUvs]
    }
    fn systems(settings: Self::Settings, ctx: StageCtx) -> ScheduleConfigs<ScheduleSystem> {
        let synthesize = move |mut commands: Commands,
                               active: Res<ActiveMesh>,
                               seed: Res<RunSeed>,
                               map: Res<ExemplarJumpMap>,
                               exemplar: Res<Exemplar>,
                               texture_scale: Res<TextureScale>,
                               mut spacing: ResMut<TexelSpacing>,
                               mut metrics: ResMut<Metrics>,
                               meshes: Query<(&Geometry, &Frames)>|
              -> SystemResult {
            let Ok((geometry, frames)) = meshes.get(active.0) else {
                return Err("the active mesh has no tangent frames".into());
            };
            let (mesh, frames) = (&geometry.0, &frames.0);
            if frames.len() != mesh.vertex_count() {
                return Err("tangent frames do not match the mesh".into());
            }
            let started = Instant::now();
            let map = &*map.0;
            let mut stage = StageRun::new(&settings, ctx.index, &exemplar, &mut metrics);
            let scales = stage.scales(mesh, texture_scale.texels_per_unit);
            let (topo, offsets) = run::offsets(mesh, frames, &scales);
            let mut out = stage.synthesize(&topo, &offsets, map, seed.derive(ctx.index, 0));
            let synthesis_seconds = started.elapsed().as_secs_f64();
            let band = stage.band(&scales, &offsets, &topo, &out.patch);
            // The per-edge offsets and, after the refinement, the topology
            // (some 180 bytes per vertex together) go before the texture
            // coordinates are made.
            let sides = corner_side_offsets(mesh, &topo, &offsets);
            drop(offsets);
            if let Some(band) = band {
                let level = SynthesisLevel { mesh, frames };
                let scale_seed = (scales[0], seed.derive(ctx.index, 1));
                stage.refine(&level, &topo, scale_seed, &mut out.texel, &band)?;
            }
            drop(topo);
            let (single, blend) = run::uvs(mesh, sides, &out.texel, map);
            let mean_scale = stage.record(&out, &scales, started, synthesis_seconds);
            if mean_scale > 0.0 {
                spacing.0 = 1.0 / mean_scale;
            }
            let mut texels = out.texel;
            for p in &mut texels {
                *p += Vec2::splat(0.5);
            }
            commands.entity(active.0).insert((
                CornerUvs(single),
                BlendUvs(blend),
                SourceTexels(texels),
                VertexScale(scales),
            ));
            Ok(())
        };
        ctx.fallible(Self::KIND, synthesize)
    }
}
