//! Stage `bake`: lays the ORIGINAL mesh out in a UV atlas and bakes the
//! active result into it, so the synthesis becomes a textured asset of the
//! loaded mesh (exported by `export` as `glb` or `baked_obj`).
//!
//! What is baked, by what the result holds (first match):
//! 0. a triplanar projection (stage `triplanar`) — evaluated per texel;
//! 1. lapped-texture pastes on the original mesh — composited in paste order;
//! 2. per-corner UVs on the original mesh — with the jump-map 3-way blend
//!    when `jump_surface` made blend layers;
//! 3. vertex colours on the active mesh (retiled, subdivided, or the
//!    original) — each texel's surface point is projected onto the result
//!    mesh and its colours interpolated barycentrically.
//!
//! Reads: `SourceMesh` geometry, `ActiveMesh` (`VertexColours`,
//! `SourceTexels`, `Frames`, `VertexScale`, `CornerUvs`, `BlendUvs`,
//! lapped pastes), `TriplanarProjection`, `TexturePatches`,
//! `TexturePatchOrigins`, `Exemplar`, `ExemplarChannels`, `TextureScale`,
//! `TexelSpacing`. Writes: the `BakedAsset` resource, metrics. `run.rs`
//! does the bake; the atlas and the sources' inputs are
//! `kernels::atlas::bake_layout`, the texels `kernels::atlas::bake`.

use crate::config::params::{ParamDoc, ParamRange, StageSettings};
use crate::stage::memory::{InputSizes, MemoryEstimate};
use crate::stage::{Datum, Stage, StageCtx, SystemResult};
use crate::world::*;
use bevy_ecs::prelude::*;
use bevy_ecs::schedule::ScheduleConfigs;
use bevy_ecs::system::ScheduleSystem;
use run::{BakeInputs, bake_world};
use serde::{Deserialize, Serialize};

mod run;

/// Settings of `bake`.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BakeSettings {
    /// Side of the square atlas texture, pixels; 0 = from the texture scale
    /// ([`auto_atlas_size`]).
    pub size: u32,
    /// Gutter around every chart, pixels.
    pub padding: u32,
    /// Normal cone of a chart, degrees.
    pub normal_cone: f64,
    /// How a per-vertex result's colour reaches the texels.
    pub colours: BakeColours,
    /// Exemplar look-ups of a texel within this many exemplar pixels of
    /// one another are read as one ([`AgreeingLookups`]); 0 = the colours
    /// are always blended.
    pub merge_within: f32,
    /// How look-ups that still differ are blended.
    pub blend: BakeBlend,
}

/// How `bake` blends the exemplar look-ups of a texel that disagree (the
/// jump-map 3-way blend, the coordinate bake's three vertices).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum BakeBlend {
    /// `mean + Σ wᵢ (cᵢ − mean) / √Σ wᵢ²` about the exemplar's mean colour
    /// (Heitz & Neyret 2018; Burley 2019): a cross-fade keeps the
    /// exemplar's contrast.
    #[default]
    PreserveVariance,
    /// `Σ wᵢ cᵢ`, as the papers draw it: a cross-fade of unrelated texture
    /// washes out towards the mean.
    Linear,
}

/// How `bake` reads a per-vertex result (vertex colours on a retiled or
/// subdivided mesh).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum BakeColours {
    /// `coordinates` where the result records them (source texels and
    /// frames: Wei–Levoy, Bangay–Morkel, coherent), else `vertex`.
    #[default]
    Auto,
    /// Every texel looks the exemplar up through the exemplar coordinates of
    /// the result triangle's vertices, continued through their tangent
    /// frames ([`CoordinateSource`]): the exemplar's own resolution.
    Coordinates,
    /// The vertex colours, interpolated across each result triangle:
    /// detail bounded by the vertex density.
    Vertex,
}

impl Default for BakeSettings {
    fn default() -> Self {
        Self {
            size: 0,
            padding: 4,
            normal_cone: 60.0,
            colours: BakeColours::Auto,
            merge_within: 2.0,
            blend: BakeBlend::PreserveVariance,
        }
    }
}

impl StageSettings for BakeSettings {
    const PARAMS: &'static [ParamDoc] = &[
        ParamDoc {
            name: "size",
            unit: "pixels",
            range: ParamRange::Int(0, 8192),
            doc: "side of the square atlas texture the result is baked into (256..=8192); 0 = about one atlas texel per exemplar pixel at the scale the result was synthesised (its texels per world unit × √(area / 0.5), the next power of two in 256..=8192)",
        },
        ParamDoc {
            name: "padding",
            unit: "pixels (texels)",
            range: ParamRange::Int(0, 64),
            doc: "gutter kept around every chart and filled by dilating the chart's texels, so bilinear filtering and mipmaps do not bleed",
        },
        ParamDoc {
            name: "normal_cone",
            unit: "degrees",
            range: ParamRange::Float(5.0, 85.0),
            doc: "largest angle between a chart face's normal and its chart seed's: smaller gives more, flatter charts (less distortion, more seams)",
        },
        ParamDoc {
            name: "colours",
            unit: "",
            range: ParamRange::OneOf(&["auto", "coordinates", "vertex"]),
            doc: "how a per-vertex result (vertex colours on a retiled or subdivided mesh) reaches the texels: coordinates = each texel looks the exemplar up where the exemplar coordinates of the result triangle's three vertices, continued through their tangent frames at the synthesis scale, put it, blended barycentrically (the exemplar's own resolution whatever the vertex density; needs source texels and frames, which Wei–Levoy, Bangay–Morkel and coherent record); vertex = the vertex colours interpolated across each triangle (detail bounded by the vertex density; the only choice for a result without coordinates); auto = coordinates where recorded, else vertex. Per-corner UVs and lapped pastes are always read at full resolution",
        },
        ParamDoc {
            name: "merge_within",
            unit: "exemplar pixels",
            range: ParamRange::Float(0.0, 16.0),
            doc: "the look-ups of one texel (the jump-map 3-way blend, the coordinate bake's three vertices) whose exemplar coordinates lie within this distance of one another are read once, at their weighted mean coordinate, fading back to the colour blend between this distance and twice it: features the look-ups nearly agree on are drawn once, sharp, instead of two or three times a pixel apart; look-ups that disagree (jumps, patch seams) keep the colour blend. 0 = always blend the colours (with `blend = \"linear\"`, the papers' blend: Zelinka & Garland 2004 §6.5, Lefebvre & Hoppe 2005 §7). Per-vertex colours, lapped pastes and triplanar projections are not affected",
        },
        ParamDoc {
            name: "blend",
            unit: "",
            range: ParamRange::OneOf(&["preserve_variance", "linear"]),
            doc: "how the colours of a texel's look-ups that disagree are blended: preserve_variance = about the exemplar's mean colour with the deviation scaled by Σw/√Σw² (Heitz & Neyret 2018, Burley 2019), so a cross-fade of unrelated texture keeps the exemplar's contrast (it assumes the blended look-ups unrelated, which merge_within > 0 ensures: with merge_within = 0 it over-boosts where they agree); linear = the weighted mean, as the papers draw it, which washes blend zones out towards the mean colour. Colour only: normal, roughness and height maps are blended linearly",
        },
    ];

    fn check(&self) -> Result<(), (String, String)> {
        if !(0.0..=16.0).contains(&self.merge_within) {
            return Err((
                "merge_within".into(),
                format!(
                    "{} is out of range; allowed: 0.0..=16.0 exemplar pixels",
                    self.merge_within
                ),
            ));
        }
        if (1..256).contains(&self.size) {
            return Err((
                "size".into(),
                format!(
                    "{} is too small; allowed: 0 (from the texture scale) or 256..=8192",
                    self.size
                ),
            ));
        }
        Ok(())
    }
}

/// Bytes per atlas texel at the stage's peak (measured: 18.1 at 512² to
/// 2048²): the RGB colour (12), the texel's face (4) and the kernels'
/// buffers; each exemplar map channel adds 4.
pub const BYTES_PER_TEXEL: u64 = 18;

/// Bytes per triangle of the source mesh for the atlas layout (charts,
/// flattening, corner UVs, frames; measured 40-55).
pub const BYTES_PER_TRIANGLE: u64 = 60;

/// Share of the atlas the charts are assumed to fill when the size is
/// derived (the packer reaches 0.5-0.7 on closed meshes).
pub const ASSUMED_ATLAS_FILL: f64 = 0.5;

/// Atlas side for `texels_per_unit` (exemplar pixels per world unit) on a
/// surface of `area`: one atlas texel per exemplar pixel at
/// [`ASSUMED_ATLAS_FILL`], rounded up to a power of two in 256..=8192.
pub fn auto_atlas_size(texels_per_unit: f64, area: f64) -> u32 {
    let side = texels_per_unit * (area / ASSUMED_ATLAS_FILL).sqrt();
    if !side.is_finite() {
        return 8192;
    }
    (side.clamp(256.0, 8192.0).ceil() as u32)
        .next_power_of_two()
        .min(8192)
}

/// What the bake reads of a mesh entity.
type MeshData = (
    &'static Geometry,
    Option<&'static VertexColours>,
    Option<&'static CornerUvs>,
    Option<&'static BlendUvs>,
    Option<&'static SourceTexels>,
    Option<&'static Frames>,
    Option<&'static VertexScale>,
);

/// The mesh entities the bake reads.
type MeshQuery<'w, 's> = Query<'w, 's, MeshData>;

/// What the bake reads of a paste entity.
type PasteQuery = (
    &'static PasteOf,
    &'static PasteOrder,
    &'static TexturePatchIndex,
    &'static PatchFaces,
    &'static PatchUvs,
);

/// The `bake` stage.
pub struct Bake;

impl Stage for Bake {
    const KIND: &'static str = "bake";
    const SUMMARY: &'static str = "UV atlas of the original mesh (charts, conformal flattening, packing, dilated gutters) and the result baked into it: vertex colours, jump-map UVs (3-way blend) or lapped pastes";
    const PAPER: &'static str =
        "Lévy et al. 2002 (LSCM); Zelinka & Garland 2004 §6.5; Praun et al. 2000 §4";
    type Settings = BakeSettings;

    fn requires(_: &Self::Settings) -> Vec<Datum> {
        vec![Datum::Mesh]
    }
    fn produces(_: &Self::Settings) -> Vec<Datum> {
        vec![Datum::BakedAtlas]
    }
    /// The atlas (`size`, or the size the texture scale gives): colour,
    /// the exemplar's maps and the texel-to-face map per texel, and the
    /// layout per triangle of the source mesh.
    fn memory_estimate(settings: &Self::Settings, sizes: &InputSizes) -> Vec<MemoryEstimate> {
        let derived = settings.size == 0;
        if derived && !sizes.loaded {
            return Vec::new();
        }
        let size = if derived {
            auto_atlas_size(sizes.texels_per_unit, sizes.area)
        } else {
            settings.size
        };
        let per_texel = BYTES_PER_TEXEL + 4 * u64::from(sizes.map_channels);
        let per_mesh = BYTES_PER_TRIANGLE * sizes.triangles;
        let mut e = MemoryEstimate::growing(
            "size",
            "the baked atlas: colour, maps and texel-to-face map per texel, the layout per triangle",
            u64::from(size),
            (256, 8192),
            move |s| (s * s).saturating_mul(per_texel).saturating_add(per_mesh),
            |s| s.to_string(),
        );
        if derived {
            e.value = format!(
                "0, derived from [input] texture_scale: {size} (set bake.size to choose it)"
            );
        }
        vec![e]
    }
    fn systems(settings: Self::Settings, ctx: StageCtx) -> ScheduleConfigs<ScheduleSystem> {
        let bake = move |mut commands: Commands,
                         active: Res<ActiveMesh>,
                         exemplar: Res<Exemplar>,
                         spacing: Res<TexelSpacing>,
                         texture_scale: Option<Res<TextureScale>>,
                         triplanar: Option<Res<TriplanarProjection>>,
                         mut metrics: ResMut<Metrics>,
                         sources: Query<Entity, With<SourceMesh>>,
                         meshes: MeshQuery,
                         pastes: Query<PasteQuery>,
                         patch_textures: Option<Res<TexturePatches>>,
                         patch_origins: Option<Res<TexturePatchOrigins>>,
                         channels: Option<Res<ExemplarChannels>>|
              -> SystemResult {
            let source = sources
                .iter()
                .next()
                .ok_or("there is no source mesh to bake onto")?;
            let Ok((geometry, ..)) = meshes.get(source) else {
                return Err("the source mesh has no geometry".into());
            };
            let inputs = BakeInputs {
                exemplar: &exemplar,
                channels: channels.as_deref(),
                patches: patch_textures.as_deref().map_or(&[], |t| t.0.as_slice()),
                origins: patch_origins.as_deref().map_or(&[], |o| o.0.as_slice()),
                triplanar: triplanar.as_deref(),
                texels_per_unit: run_texels_per_unit(texture_scale.as_deref(), &spacing),
            };
            let mut settings = settings.clone();
            if settings.size == 0 {
                let texels_per_unit = 1.0 / f64::from(spacing.0.max(f32::MIN_POSITIVE));
                settings.size = auto_atlas_size(texels_per_unit, f64::from(geometry.0.area()));
                metrics.record(ctx.index, "size_from_texture_scale", settings.size);
            }
            let (asset, record) = bake_world(
                &settings,
                source,
                active.0,
                &inputs,
                &geometry.0,
                &meshes,
                &pastes,
            )?;
            for (k, v) in record {
                metrics.record(ctx.index, k, v);
            }
            commands.insert_resource(asset);
            Ok(())
        };
        ctx.fallible(Self::KIND, bake)
    }
}
