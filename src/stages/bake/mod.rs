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
//! `SourceTexels`, `Frames`, `CornerUvs`, `BlendUvs`, lapped pastes),
//! `Exemplar`. Writes: the `BakedAsset` resource, metrics.

use crate::config::params::{ParamDoc, ParamRange, StageSettings, to_json};
use crate::image::Image;
use crate::kernels::atlas::autocorrelation::Autocorrelation;
use crate::kernels::atlas::bake::{
    AgreeingLookups, AtlasFrames, BakeTarget, BlendUvSource, ChannelKind, ChannelMap,
    ContributionSource, CoordinateSource, LappedSource, PatchPlacement, VertexColourSource,
    bake_channels_with_progress,
};
use crate::kernels::atlas::triplanar::TriplanarSource;
use crate::kernels::atlas::{
    AtlasSettings, build_uv_atlas_with_progress, distortion, rasterise_faces,
};
use crate::kernels::jump_maps::jump_surface::Blend;
use crate::kernels::wei_levoy::retile::SurfaceProjector;
use crate::mesh::PolyMesh;
use crate::progress::Progress;
use crate::stage::memory::{InputSizes, MemoryEstimate};
use crate::stage::{Datum, Stage, StageCtx};
use crate::world::*;
use bevy_ecs::prelude::*;
use bevy_ecs::schedule::ScheduleConfigs;
use bevy_ecs::system::ScheduleSystem;
use glam::{Vec2, Vec3};
use serde::{Deserialize, Serialize};

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

/// Lags up to this many exemplar pixels enter the variance-preserving
/// blend's autocorrelation; look-ups farther apart count as unrelated.
pub const AUTOCORRELATION_RADIUS: u32 = 64;

/// The exemplar's mean colour and autocorrelation for `blend`, when it
/// preserves variance.
fn blend_statistics(blend: BakeBlend, exemplar: &Exemplar) -> Option<([f32; 3], Autocorrelation)> {
    (blend == BakeBlend::PreserveVariance).then(|| {
        let m = exemplar.image.to_rgb().mean();
        let rho =
            Autocorrelation::of_luminance(&exemplar.image, AUTOCORRELATION_RADIUS, exemplar.wrap);
        ([m[0], m[1], m[2]], rho)
    })
}

/// `source` with its agreeing exemplar look-ups merged (`within > 0`) and
/// the others blended with `statistics` (variance-preserving); `None` for
/// the papers' blend.
fn merge<'a>(
    source: &'a dyn ContributionSource,
    within: f32,
    statistics: Option<&'a ([f32; 3], Autocorrelation)>,
    exemplar: &Exemplar,
) -> Option<AgreeingLookups<'a>> {
    (within > 0.0 || statistics.is_some()).then(|| AgreeingLookups {
        inner: source,
        exemplar_size: Vec2::new(exemplar.image.width as f32, exemplar.image.height as f32),
        within,
        wrap: exemplar.wrap,
        preserve_variance: statistics.map(|(m, rho)| (*m, rho)),
    })
}

/// What the bake reads of a mesh entity.
type MeshQuery<'w, 's> = Query<
    'w,
    's,
    (
        &'static Geometry,
        Option<&'static VertexColours>,
        Option<&'static CornerUvs>,
        Option<&'static BlendUvs>,
        Option<&'static SourceTexels>,
        Option<&'static Frames>,
        Option<&'static VertexScale>,
    ),
>;

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
        (move |mut commands: Commands,
               active: Res<ActiveMesh>,
               exemplar: Res<Exemplar>,
               spacing: Res<TexelSpacing>,
               texture_scale: Option<Res<TextureScale>>,
               triplanar: Option<Res<TriplanarProjection>>,
               mut metrics: ResMut<Metrics>,
               mut failure: ResMut<StageFailure>,
               sources: Query<Entity, With<SourceMesh>>,
               meshes: MeshQuery,
               pastes: Query<PasteQuery>,
               patch_textures: Option<Res<TexturePatches>>,
               patch_origins: Option<Res<TexturePatchOrigins>>,
               channels: Option<Res<ExemplarChannels>>| {
            let mut fail = |message: String| fail(&mut failure, ctx.index, Self::KIND, message);
            let Some(source) = sources.iter().next() else {
                fail("there is no source mesh to bake onto".into());
                return;
            };
            let Ok((geometry, ..)) = meshes.get(source) else {
                fail("the source mesh has no geometry".into());
                return;
            };
            let patches = patch_textures
                .as_deref()
                .map(|t| t.0.as_slice())
                .unwrap_or(&[]);
            let origins = patch_origins
                .as_deref()
                .map(|o| o.0.as_slice())
                .unwrap_or(&[]);
            let inputs = BakeInputs {
                exemplar: &exemplar,
                channels: channels.as_deref(),
                patches,
                origins,
                triplanar: triplanar.as_deref(),
                texels_per_unit: run_texels_per_unit(texture_scale.as_deref(), &spacing),
            };
            let mut settings = settings.clone();
            if settings.size == 0 {
                let texels_per_unit = 1.0 / f64::from(spacing.0.max(f32::MIN_POSITIVE));
                settings.size = auto_atlas_size(texels_per_unit, f64::from(geometry.0.area()));
                metrics.record(ctx.index, "size_from_texture_scale", settings.size);
            }
            match bake_world(
                &settings,
                source,
                active.0,
                &inputs,
                &geometry.0,
                &meshes,
                &pastes,
            ) {
                Ok((asset, record)) => {
                    for (k, v) in record {
                        metrics.record(ctx.index, k, v);
                    }
                    commands.insert_resource(asset);
                }
                Err(message) => fail(message),
            }
        })
        .into_configs()
    }
}

/// Metrics of the bake, by name.
type MetricList = Vec<(&'static str, serde_json::Value)>;

/// The images a bake samples.
struct BakeInputs<'a> {
    exemplar: &'a Exemplar,
    channels: Option<&'a ExemplarChannels>,
    patches: &'a [Image],
    /// Per patch, the exemplar pixel of its top-left pixel (lapped).
    origins: &'a [[i64; 2]],
    /// A triplanar projection (stage `triplanar`), baked before any other
    /// result.
    triplanar: Option<&'a TriplanarProjection>,
    /// The run's exemplar texels per world unit, for coordinates of a
    /// result that records no per-vertex scale.
    texels_per_unit: f32,
}

/// The bake's parts and their work, for one progress bar: `"atlas"` (per
/// face, and packing per atlas texel), `"texels"` (per texel, more with
/// each exemplar map) and `"gutters"` (padding each output). In
/// microseconds as measured on the bunny (`configs/41_…` at 3072², 3 674
/// faces, three maps: 1.2 s of atlas, mostly packing, 12.5 s of texels,
/// 1.3 s of gutters; packing took 0.3 µs a texel at 1024² in
/// `lapped_paste`, 0.12 at 3072²).
fn progress_plan(faces: usize, size: u32, maps: usize) -> [(&'static str, f64); 3] {
    let texels = f64::from(size) * f64::from(size);
    let outputs = 1.0 + maps as f64;
    [
        ("atlas", 6.0 * faces as f64 + 0.15 * texels),
        ("texels", 0.35 * outputs * texels),
        ("gutters", 0.03 * outputs * texels),
    ]
}

/// Builds the atlas of `mesh` (the source mesh) and bakes the result.
fn bake_world(
    settings: &BakeSettings,
    source: Entity,
    active: Entity,
    inputs: &BakeInputs,
    mesh: &PolyMesh,
    meshes: &MeshQuery,
    pastes: &Query<PasteQuery>,
) -> Result<(BakedAsset, MetricList), String> {
    let (exemplar, patches) = (inputs.exemplar, inputs.patches);
    let _span = tracing::info_span!("bake", size = settings.size).entered();
    let tris: Vec<[u32; 3]> = mesh
        .triangulate_corners()
        .0
        .iter()
        .map(|t| t.map(|c| mesh.corner_vertex[c as usize]))
        .collect();
    let atlas_settings = AtlasSettings {
        size: settings.size,
        normal_cone_deg: settings.normal_cone as f32,
        padding_px: settings.padding,
    };
    let progress = Progress::new(0, Bake::KIND);
    let _finish = progress.finish_on_drop();
    progress.plan(progress_plan(
        tris.len(),
        settings.size,
        inputs.channels.map_or(0, |ch| {
            [
                ch.normal.is_some(),
                ch.roughness.is_some(),
                ch.height.is_some(),
            ]
            .iter()
            .filter(|&&m| m)
            .count()
        }),
    ));
    let mut atlas =
        build_uv_atlas_with_progress(&mesh.positions, &tris, &atlas_settings, &progress)
            .map_err(|e| e.to_string())?;
    // Memory (issue 15): each per-triangle array goes as soon as nothing
    // reads it; the metrics of the layout are measured first.
    atlas.charts.corner_st = Vec::new();
    let d = distortion(&mesh.positions, &tris, &atlas.charts, &atlas.corner_uvs);
    atlas.charts.chart_of_face = Vec::new();
    let texel_face = rasterise_faces(&atlas.corner_uvs, settings.size);
    // Atlas frames (24 bytes per triangle) serve the angles of normal maps
    // and the vertex-colour and lapped sources; a blend baking no normal
    // map reads none.
    let has_normal_map = inputs.channels.is_some_and(|ch| ch.normal.is_some());
    let frames = || AtlasFrames::new(&mesh.positions, &tris, &atlas.corner_uvs);
    let target = BakeTarget {
        corner_uvs: &atlas.corner_uvs,
        texel_face: &texel_face,
        size: settings.size,
        padding_px: settings.padding,
    };
    let Ok((result, colours, uvs, blend, source_texels, result_frames, vertex_scale)) =
        meshes.get(active)
    else {
        return Err("the active mesh has no geometry".into());
    };
    let on_source = active == source;
    let mut lapped: Vec<_> = pastes.iter().filter(|p| p.0.0 == active).collect();
    lapped.sort_by_key(|p| *p.1);
    let textures: Vec<&Image> = std::iter::once(&exemplar.image).chain(patches).collect();
    // Every exemplar map present goes through the same contributions.
    let mut roles: Vec<&'static str> = Vec::new();
    let mut maps: Vec<ChannelMap> = Vec::new();
    if let Some(ch) = inputs.channels {
        for (role, img, kind) in [
            ("normal", &ch.normal, ChannelKind::Normal),
            ("roughness", &ch.roughness, ChannelKind::Scalar),
            ("height", &ch.height, ChannelKind::Scalar),
        ] {
            if let Some(image) = img {
                roles.push(role);
                maps.push(ChannelMap { image, kind });
            }
        }
    }
    // Maps need exemplar coordinates: lapped patches and vertex colours
    // without recorded source texels have none.
    let mut maps_note = "";
    let method;
    let (colour, baked_maps) = if let Some(tp) = inputs.triplanar {
        method = "triplanar";
        let frames = frames();
        let normals =
            crate::kernels::atlas::triplanar::crease_corner_normals(&mesh.positions, &tris);
        let src = TriplanarSource {
            positions: &mesh.positions,
            normals: &normals,
            tris: &tris,
            frames: &frames,
            texels_per_unit: tp.texels_per_unit,
            sharpness: tp.sharpness,
            image_size: Vec2::new(tp.image.width as f32, tp.image.height as f32),
        };
        // The exemplar's maps follow only a projection of the exemplar
        // itself (the same pixels).
        let same_image = tp.image.width == exemplar.image.width
            && tp.image.height == exemplar.image.height
            && tp.image.data == exemplar.image.data;
        if !maps.is_empty() && !same_image {
            maps_note = "the triplanar image is not the exemplar: maps are not baked";
            maps.clear();
            roles.clear();
        }
        bake_channels_with_progress(
            &target,
            &src as &dyn ContributionSource,
            &[&tp.image],
            crate::image::sample::Wrap::Repeat,
            &maps,
            &[],
            &progress,
        )
    } else if !lapped.is_empty() {
        if !on_source {
            return Err("the lapped pastes lie on a mesh other than the loaded one; bake needs them on the original mesh (no retile before lapped_paste)".into());
        }
        if !mesh.is_triangle_mesh() {
            return Err("lapped pastes need a triangle mesh".into());
        }
        let mut records = Vec::with_capacity(lapped.len());
        for (_, _, texture, faces, puvs) in &lapped {
            if puvs.0.len() != 3 * faces.0.len() {
                return Err("a paste's texture coordinates do not match its faces".into());
            }
            let list: Vec<(u32, [Vec2; 3])> = faces
                .0
                .iter()
                .enumerate()
                .map(|(i, &f)| (f, [puvs.0[3 * i], puvs.0[3 * i + 1], puvs.0[3 * i + 2]]))
                .collect();
            records.push((texture.0, list));
        }
        let frames = frames();
        let src = LappedSource::new(&mesh.positions, &tris, &frames, &records, patches);
        method = "lapped_pastes";
        // Patch pixel (x, y) is exemplar pixel origin + (x, y): maps follow
        // the pastes through the same look-ups.
        let (ew, eh) = (
            exemplar.image.width.max(1) as f32,
            exemplar.image.height.max(1) as f32,
        );
        let placements: Vec<PatchPlacement> = if inputs.origins.len() == patches.len() {
            patches
                .iter()
                .zip(inputs.origins)
                .map(|(p, o)| PatchPlacement {
                    offset: Vec2::new(o[0] as f32 / ew, o[1] as f32 / eh),
                    scale: Vec2::new(p.width as f32 / ew, p.height as f32 / eh),
                })
                .collect()
        } else {
            Vec::new()
        };
        if !maps.is_empty() && placements.is_empty() {
            maps_note = "lapped patches record no exemplar origin: maps are flat/neutral";
        }
        bake_channels_with_progress(
            &target,
            &src as &dyn ContributionSource,
            &textures,
            exemplar.wrap,
            &maps,
            &placements,
            &progress,
        )
    } else if blend.is_some() || uvs.is_some() {
        if !on_source {
            return Err("the per-corner UVs lie on a mesh other than the loaded one; bake needs them on the original mesh".into());
        }
        // Single-base UVs as three equal layers; the compact blend layers
        // are read in place (72 bytes per triangle expanded).
        let single: Vec<[[Vec2; 3]; 3]>;
        let layers: Blend = match (blend, uvs) {
            (Some(b), _) if b.0.fits(mesh) => {
                method = "jump_map_blend";
                Blend::Compact { layers: &b.0, mesh }
            }
            (_, Some(u)) if u.0.len() == mesh.corner_count() => {
                method = "corner_uvs";
                single = mesh
                    .triangulate_corners()
                    .0
                    .iter()
                    .map(|t| [t.map(|c| u.0[c as usize]); 3])
                    .collect();
                (&single).into()
            }
            _ => return Err("the result's UVs do not match the mesh's corners".into()),
        };
        let src = if has_normal_map {
            BlendUvSource::new(&mesh.positions, &tris, &frames(), layers)
        } else {
            BlendUvSource::without_angles(layers)
        };
        let statistics = blend_statistics(settings.blend, exemplar);
        let merged = merge(&src, settings.merge_within, statistics.as_ref(), exemplar);
        bake_channels_with_progress(
            &target,
            merged
                .as_ref()
                .map_or(&src as &dyn ContributionSource, |m| m),
            &textures,
            exemplar.wrap,
            &maps,
            &[],
            &progress,
        )
    } else if let Some(c) = colours {
        if c.channels == 0 || c.values.len() != c.channels * result.0.vertex_count() {
            return Err("the result's vertex colours do not match its vertices".into());
        }
        // Neighbouring texels project near one another: walk from the last.
        let projector = SurfaceProjector::with_adjacency(&result.0);
        let result_tris: Vec<[u32; 3]> = result
            .0
            .triangulated()
            .faces()
            .map(|f| [f[0], f[1], f[2]])
            .collect();
        let size = Vec2::new(exemplar.image.width as f32, exemplar.image.height as f32);
        let source_uv: Option<Vec<Vec2>> = source_texels
            .filter(|t| t.0.len() == result.0.vertex_count())
            .map(|t| t.0.iter().map(|p| *p / size).collect());
        let frame_s: Option<Vec<Vec3>> = result_frames
            .filter(|f| f.0.len() == result.0.vertex_count())
            .map(|f| f.0.iter().map(|fr| fr.s).collect());
        let frames = frames();
        let src = VertexColourSource {
            positions: &mesh.positions,
            tris: &tris,
            frames: &frames,
            projector: &projector,
            result_tris: &result_tris,
            colours: &c.values,
            channels: c.channels,
            source_uv: source_uv.as_deref(),
            frame_s: frame_s.as_deref(),
        };
        // The exemplar coordinates, continued per texel, where recorded.
        let n = result.0.vertex_count();
        let coordinates = match (source_texels, result_frames) {
            (Some(t), Some(f)) if t.0.len() == n && f.0.len() == n => Some((&t.0, &f.0)),
            _ => None,
        };
        let one_scale = [inputs.texels_per_unit];
        let texels_per_unit: &[f32] = match vertex_scale {
            Some(s) if s.0.len() == n => &s.0,
            _ => &one_scale,
        };
        let source: Box<dyn ContributionSource + '_> = match (settings.colours, coordinates) {
            (BakeColours::Vertex, _) | (BakeColours::Auto, None) => {
                method = "vertex_colours";
                if !maps.is_empty() && source_uv.is_none() {
                    maps_note = "the result records no source texels: maps are flat/neutral";
                }
                Box::new(src)
            }
            (BakeColours::Coordinates, None) => {
                return Err("colours = \"coordinates\" needs the exemplar coordinate and tangent frame of every result vertex, which this result does not record; allowed here: \"vertex\" or \"auto\"".into());
            }
            (_, Some((sources, synthesis_frames))) => {
                method = "coordinates";
                Box::new(CoordinateSource {
                    surface: src,
                    result_positions: &result.0.positions,
                    sources,
                    synthesis_frames,
                    texels_per_unit,
                    exemplar_size: size,
                })
            }
        };
        let statistics = blend_statistics(settings.blend, exemplar);
        let merged = merge(
            source.as_ref(),
            settings.merge_within,
            statistics.as_ref(),
            exemplar,
        );
        bake_channels_with_progress(
            &target,
            merged.as_ref().map_or(source.as_ref(), |m| m),
            &textures,
            exemplar.wrap,
            &maps,
            &[],
            &progress,
        )
    } else {
        return Err("the result has nothing to bake: no vertex colours, per-corner UVs, lapped pastes or triplanar projection; put `bake` after a synthesis stage or `triplanar`".into());
    };
    progress.finish();
    drop(texel_face);
    let record = vec![
        ("bake_method", to_json(&method)),
        ("atlas_charts", to_json(&atlas.charts.count)),
        ("atlas_fill", to_json(&atlas.fill)),
        ("atlas_texels_per_unit", to_json(&atlas.texels_per_unit)),
        ("atlas_mean_stretch", to_json(&d.mean_stretch)),
        ("atlas_density_ratio_p95", to_json(&d.density_ratio_p95)),
        ("baked_maps", to_json(&roles)),
    ];
    let mut record = record;
    if !maps_note.is_empty() {
        record.push(("baked_maps_note", to_json(&maps_note)));
    }
    // A triangle mesh is its own fan triangulation: the asset refers to
    // the world's (`BakedAsset::on_source`) instead of holding a copy.
    let (tri_mesh, on_source) = if mesh.is_triangle_mesh() {
        drop(tris);
        (PolyMesh::new(), true)
    } else {
        (
            PolyMesh::from_triangles(mesh.positions.clone(), &tris),
            false,
        )
    };
    let asset = BakedAsset {
        mesh: tri_mesh,
        on_source,
        // In place: the per-triangle array becomes the per-corner one.
        uvs: atlas.corner_uvs.into_flattened(),
        colour,
        maps: roles
            .iter()
            .zip(baked_maps)
            .map(|(role, img)| (role.to_string(), img))
            .collect(),
    };
    Ok((asset, record))
}
