//! The world model: components of mesh levels, image levels and patches, and
//! the run-wide resources. Everything is structure-of-arrays: a vertex is a
//! row (`u32` id) in each per-vertex array.

use crate::image::{Image, sample::Wrap};
use crate::kernels::frames::TangentFrame;
use crate::mesh::PolyMesh;
use bevy_ecs::prelude::*;
use glam::Vec2;
use rand::SeedableRng;

// ----- mesh levels -----------------------------------------------------------

/// Marks the mesh as loaded from `[input]`; it is never modified, so results
/// can be mapped back onto it.
#[derive(Component, Debug, Default)]
pub struct SourceMesh;

/// Pyramid level of a mesh entity: 0 is the finest.
#[derive(Component, Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub struct MeshLevel(pub u8);

/// Connectivity and positions of a mesh level.
#[derive(Component, Clone, Debug, Default)]
pub struct Geometry(pub PolyMesh);

/// Per-vertex tangent frames (s, t, n).
#[derive(Component, Clone, Debug, Default)]
pub struct Frames(pub Vec<TangentFrame>);

/// Per-vertex texture scale: exemplar texels per world unit.
#[derive(Component, Clone, Debug, Default)]
pub struct VertexScale(pub Vec<f32>);

/// Per-vertex colours, `channels` values per vertex, nominally in `[0, 1]`.
#[derive(Component, Clone, Debug, Default)]
pub struct VertexColours {
    /// Values per vertex (the exemplar's channel count).
    pub channels: usize,
    /// `values[v * channels + c]`.
    pub values: Vec<f32>,
}

/// Per-vertex source coordinate in the exemplar, in pixels (continuous, pixel
/// centres at `i + 0.5`): which exemplar texel each vertex colour came from, so
/// other exemplar channels can follow the same synthesis.
#[derive(Component, Clone, Debug, Default)]
pub struct SourceTexels(pub Vec<Vec2>);

/// Per-corner texture coordinates in `[0, 1]` units of the exemplar (v = 0 at
/// the exemplar's top row; values outside wrap when the exemplar tiles).
#[derive(Component, Clone, Debug, Default)]
pub struct CornerUvs(pub Vec<Vec2>);

// ----- image levels ------------------------------------------------------------

/// Whether an image level belongs to the halving pyramid or the same-size stack.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ImageLevelKind {
    /// Gaussian pyramid: each level half the size of the previous.
    Pyramid,
    /// Gaussian stack: every level the exemplar's size, blur doubling.
    Stack,
}

/// An exemplar pyramid or stack level; 0 is the exemplar itself.
#[derive(Component, Clone, Copy, Debug, PartialEq, Eq)]
pub struct ImageLevel {
    /// Level index, 0 = finest.
    pub level: u8,
    /// Pyramid or stack.
    pub kind: ImageLevelKind,
}

/// The pixels of an image level.
#[derive(Component, Clone, Debug, Default)]
pub struct Pixels(pub Image);

// ----- resources ---------------------------------------------------------------

/// The exemplar image and how it is addressed.
#[derive(Resource, Clone, Debug)]
pub struct Exemplar {
    /// Pixels, f32, the file's channel count.
    pub image: Image,
    /// Display name (`builtin:bricks`, a file path).
    pub name: String,
    /// Toroidal (`Repeat`) for tileable exemplars, `Clamp` otherwise.
    pub wrap: Wrap,
}

/// Extra exemplar maps that follow the colour synthesis (issue 7): each the
/// colour exemplar's size, addressed with the exemplar's wrap, so a vertex's
/// [`SourceTexels`] or a corner's [`CornerUvs`] read them as they read the
/// colours. Always present (all `None` when the config gives no maps).
#[derive(Resource, Clone, Debug, Default)]
pub struct ExemplarChannels {
    /// Tangent-space normal map, RGB (`kernels::channels` convention).
    pub normal: Option<Image>,
    /// Roughness, one channel in `[0, 1]`.
    pub roughness: Option<Image>,
    /// Height (displacement), one channel in `[0, 1]`.
    pub height: Option<Image>,
    /// The exemplar's wrap.
    pub wrap: Wrap,
}

/// The run's seed; every random stream derives from it, the stage index and a
/// stream id, so results never depend on thread count or scheduling.
#[derive(Resource, Clone, Copy, Debug)]
pub struct RunSeed(pub u64);

impl RunSeed {
    /// A seeded generator for one stage and one purpose (or one element).
    pub fn rng(&self, stage: usize, stream: u64) -> rand_pcg::Pcg64Mcg {
        rand_pcg::Pcg64Mcg::seed_from_u64(mix(self.0, stage as u64, stream))
    }

    /// A 64-bit seed for one stage and stream, for kernels that seed their own.
    pub fn derive(&self, stage: usize, stream: u64) -> u64 {
        mix(self.0, stage as u64, stream)
    }
}

pub use crate::kernels::mix;

/// The mesh entity later stages work on and export: the source mesh until a
/// stage (retile, subdivide) makes a new finest level.
#[derive(Resource, Clone, Copy, Debug)]
pub struct ActiveMesh(pub Entity);

/// World units per exemplar texel on the active mesh: the spacing at which
/// quality metrics resample the surface. Stages that set a texture scale update it.
#[derive(Resource, Clone, Copy, Debug)]
pub struct TexelSpacing(pub f32);

/// Exemplar texels per world unit of the run: the texture scale's, else
/// the active mesh's texel spacing inverted.
pub fn run_texels_per_unit(scale: Option<&TextureScale>, spacing: &TexelSpacing) -> f32 {
    scale.map_or(1.0 / spacing.0.max(f32::MIN_POSITIVE), |t| {
        t.texels_per_unit
    })
}

/// The run's one texture scale: `[input] texture_scale` resolved against the
/// input mesh's bounding-box diagonal and the exemplar's width. Every stage
/// whose own scale parameter is left at its default takes its scale from
/// here (jump maps' pixels per unit, Bangay–Morkel's `r_scale`, coherent's
/// scale, lapped patch size, retiling density, √2 depth, bake density).
#[derive(Resource, Clone, Copy, Debug)]
pub struct TextureScale {
    /// Exemplar pixels per world unit.
    pub texels_per_unit: f32,
    /// Bounding-box diagonal of the input mesh, world units.
    pub diagonal: f32,
    /// `[input] texture_scale` as written, for messages.
    pub value: f64,
    /// `[input] texture_scale_unit`.
    pub unit: crate::config::TextureScaleUnit,
}

impl TextureScale {
    /// Resolves `value` in `unit` for an input mesh of bounding-box diagonal
    /// `diagonal` and an exemplar `exemplar_width` pixels wide.
    pub fn resolve(
        value: f64,
        unit: crate::config::TextureScaleUnit,
        exemplar_width: u32,
        diagonal: f64,
    ) -> Self {
        Self {
            texels_per_unit: unit.texels_per_unit(value, exemplar_width, diagonal) as f32,
            diagonal: diagonal as f32,
            value,
            unit,
        }
    }

    /// Exemplar pixels per bounding-box diagonal of the input mesh.
    pub fn texels_per_diagonal(&self) -> f32 {
        self.texels_per_unit * self.diagonal
    }

    /// Vertices a surface of `area` square world units needs for one vertex
    /// per exemplar pixel² (a vertex spacing √(2 · mean triangle area) of one
    /// exemplar pixel: the resolution of the per-vertex methods).
    pub fn vertices_for_area(&self, area: f64) -> f64 {
        area * f64::from(self.texels_per_unit).powi(2)
    }

    /// [`Self::vertices_for_area`], checked before any remeshing: at least
    /// `MIN_DERIVED_VERTICES` and at most `max` (the stage's own range; its
    /// memory estimate refused a count over the memory limit before the
    /// run), else a message naming the scale, the count it asks for, and the
    /// two ways out (`[input] texture_scale` or the stage's own `key`).
    pub fn derived_vertices(&self, area: f64, key: &str, max: usize) -> Result<usize, String> {
        let n = self.vertices_for_area(area);
        if n.is_finite() && (MIN_DERIVED_VERTICES as f64..=max as f64).contains(&n) {
            return Ok(n.round() as usize);
        }
        Err(format!(
            "[input] texture_scale = {} ({:?}) is {} exemplar pixels per world unit, which asks for {n:.0} vertices on this surface of area {area:.4e} (one per exemplar pixel²); allowed {MIN_DERIVED_VERTICES}..={max}: {} texture_scale, or set `{key}`",
            self.value,
            self.unit,
            self.texels_per_unit,
            match (n < MIN_DERIVED_VERTICES as f64, self.unit) {
                (true, crate::config::TextureScaleUnit::PixelsPerUnit) => "raise",
                (true, _) => "lower",
                (false, crate::config::TextureScaleUnit::PixelsPerUnit) => "lower",
                (false, _) => "raise",
            }
        ))
    }

    /// A human-readable line for logs: the scale and where it comes from.
    pub fn describe(&self) -> String {
        format!(
            "texture scale {} exemplar pixels per world unit ({} per bounding-box diagonal)",
            self.texels_per_unit,
            self.texels_per_diagonal()
        )
    }
}

/// Fewest vertices a texture scale may ask of a remeshing or subdivision
/// stage (below it there is no texture to speak of).
pub const MIN_DERIVED_VERTICES: usize = 12;

/// Checks an explicit vertex count of a remeshing or subdivision stage:
/// 0 (derive it from the texture scale) or [`MIN_DERIVED_VERTICES`]..=`max`
/// (the upper bound is the parameter's range); the message for a count in
/// between.
pub fn check_vertex_count(value: u64, max: u64) -> Result<(), String> {
    if (1..MIN_DERIVED_VERTICES as u64).contains(&value) {
        return Err(format!(
            "{value} is too few; allowed: 0 (derived from [input] texture_scale) or {MIN_DERIVED_VERTICES}..={max}"
        ));
    }
    Ok(())
}

/// Per-stage metrics, written to `metrics.json` under `stages[i].metrics`.
#[derive(Resource, Debug, Default)]
pub struct Metrics {
    /// One JSON object per stage, in stage order.
    pub stages: Vec<serde_json::Map<String, serde_json::Value>>,
    /// Metrics of the whole result (texture energy, histogram distance).
    pub result: serde_json::Map<String, serde_json::Value>,
}

impl Metrics {
    /// Records `key = value` for stage `index` (0-based); floats are kept
    /// shortest ([`crate::config::params::to_json`]).
    pub fn record(&mut self, index: usize, key: &str, value: impl serde::Serialize) {
        if self.stages.len() <= index {
            self.stages.resize_with(index + 1, Default::default);
        }
        let v = crate::config::params::to_json(&value);
        self.stages[index].insert(key.to_string(), v);
    }
}

/// Wall time of one stage.
#[derive(Clone, Debug, serde::Serialize)]
pub struct StageTiming {
    /// 1-based stage number.
    pub index: usize,
    /// Stage kind.
    pub kind: String,
    /// Wall time in seconds.
    pub seconds: f64,
}

/// Stage timings, in order.
#[derive(Resource, Debug, Default)]
pub struct StageTimings(pub Vec<StageTiming>);

/// The first failure of a stage; later stages do not run.
#[derive(Resource, Debug, Default)]
pub struct StageFailure(pub Option<crate::pipeline::PipelineError>);

/// What the `export` stage asks the runner to write (systems do no file I/O).
/// The entity whose arrays an [`ExportJob`] writes, and which of them.
#[derive(Clone, Debug)]
pub struct ExportSource {
    /// The active mesh at export time.
    pub entity: Entity,
    /// The export stage's position in the pipeline (1-based, for errors).
    pub stage: usize,
    /// Its `VertexColours` go to the files.
    pub colours: bool,
    /// Which texture coordinates go to the OBJ.
    pub uvs: ExportUvs,
    /// Its lapped pastes go to the files (format `pastes`), with these
    /// texture patches.
    pub pastes: Option<Vec<Image>>,
    /// The export system's tick: a later change of these components is an
    /// error (the previews would not show what the files hold).
    pub tick: bevy_ecs::change_detection::Tick,
}

/// The texture coordinates an export writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ExportUvs {
    /// None.
    None,
    /// `CornerUvs`, addressing the exemplar.
    Corner,
    /// The `AtlasTexture`'s coordinates and image (lapped textures).
    Atlas,
}

#[derive(Resource, Debug, Default)]
pub struct ExportJob {
    /// Requested formats (`ply`, `obj`, `preview`).
    pub formats: Vec<String>,
    /// File name stem of the mesh outputs.
    pub stem: String,
    /// Where `mesh`, `colours` and `uvs` come from: the export stage names
    /// the entity, and [`crate::stages::export::finish_export_job`] fills
    /// them at the end of the run (moved out of the world by
    /// `pipeline::run`, which drops the world next, so a million-vertex
    /// mesh and its coordinates are never held twice).
    pub source: Option<ExportSource>,
    /// The result mesh.
    pub mesh: PolyMesh,
    /// Its vertex colours, if the result has them.
    pub colours: Option<VertexColours>,
    /// Its per-corner texture coordinates and the texture they address.
    pub uvs: Option<(Vec<Vec2>, Image)>,
    /// For a result without vertex colours but with per-corner texture
    /// coordinates (jump maps, a lapped atlas): the colour at each vertex,
    /// sampled as the preview blends it and averaged over the vertex's
    /// corners, for `result.ply` (format `ply`).
    pub corner_colours: Option<VertexColours>,
    /// Rendered preview images.
    pub previews: Vec<Image>,
    /// Further images to write as PNG, by file name (`jump_image.png`, ...).
    pub images: Vec<(String, Image)>,
    /// The result baked into a per-triangle atlas image; the writer makes
    /// the triangulated mesh and its atlas coordinates from `mesh`
    /// (`output::export::baked_mesh`).
    pub baked: Option<Image>,
    /// Format `obj` writes `baked` as `<stem>.obj` and the raw per-corner
    /// texture coordinates as `<stem>_corner_uvs.obj`: set for a result
    /// whose look needs the jump-map 3-way blend, which an OBJ cannot
    /// express (its per-corner coordinates alone break at every patch
    /// boundary in Blender or MeshLab).
    pub obj_blended: bool,
    /// Lapped-texture pastes for runtime pasting (format `pastes`).
    pub pastes: Option<PasteExport>,
    /// The `bake` stage's atlas of the original mesh (formats `glb`,
    /// `baked_obj`), filled from the world's [`BakedAsset`] by
    /// [`crate::stages::export::finish_export_job`] when
    /// `take_baked_asset` is set (not copied by the export system: at a
    /// million vertices it is ~130 MB the run would hold twice).
    pub baked_asset: Option<BakedAsset>,
    /// The export asked for the baked asset.
    pub take_baked_asset: bool,
    /// The result mapped back onto the original input mesh (`map_back`):
    /// the input mesh, its vertex colours and its preview renders, written as
    /// `<stem>_original.ply` and `original_preview_*.png`.
    pub original: Option<(PolyMesh, VertexColours, Vec<Image>)>,
    /// The result as a planar image (format `plane`), written as `plane.png`
    /// and `plane_sources.png`.
    pub plane: Option<PlaneImage>,
}

/// A triplanar projection (stage `triplanar`): `image` repeated along the
/// three world axes at `texels_per_unit`, blended by `|n_axis|^sharpness`
/// ([`crate::kernels::triplanar`]). `bake` evaluates it per texel.
#[derive(Resource, Clone, Debug)]
pub struct TriplanarProjection {
    /// The projected image (a tile).
    pub image: Image,
    /// Image pixels per world unit.
    pub texels_per_unit: f32,
    /// The blend exponent.
    pub sharpness: f32,
}

/// The result as an image (the `export` format `plane`): the active result
/// sampled at one pixel per pixel over the xy bounding box of a mesh that is
/// flat in xy, or a `jump_image` result itself. Inserted by the `export`
/// stage (its position in the config, before the result metrics run) when
/// its `formats` include `plane`; absent otherwise.
///
/// - Pixel `(i, j)` (column `i`, row `j`, row 0 at the top) samples the xy
///   point `(min.x + i / (width − 1) · Δx, max.y − j / (height − 1) · Δy)`
///   of the mesh's xy bounding box (pixel centres span the box edge to
///   edge): image-up is `+y` (`kernels::plane_raster`). On the configs'
///   `N × N`-vertex planes of side `N − 1` every pixel centre is a vertex.
/// - Vertex colours are interpolated barycentrically on the triangle that
///   contains the pixel centre; per-corner UVs are blended 3 ways as the
///   preview renderer does (or read directly without blend layers); lapped
///   pastes are composited in paste order over the exemplar's mean colour.
/// - Pixels outside every triangle are black, with unknown sources.
#[derive(Resource, Clone, Debug)]
pub struct PlaneImage {
    /// RGB, f32, nominally in `[0, 1]` (grey exemplars replicated, alpha and
    /// extra channels dropped); `width × height` of the export's `plane_size`.
    pub image: Image,
    /// Per pixel (row-major, as `image`), the exemplar pixel the colour was
    /// copied from: level-0 exemplar pixel coordinates `x, y`, always an
    /// integer index `+ 0.5`, wrapped into `[0, width) × [0, height)` of the
    /// exemplar; `[NaN, NaN]` where unknown (outside the mesh, under no
    /// opaque paste). Vertex colours take the source of the vertex with the
    /// largest barycentric weight (sources are not interpolated); corner UVs
    /// the dominant blend layer's interpolated UV; lapped pastes the topmost
    /// paste with alpha ≥ 0.5 (its patch UV plus the texture patch's exemplar
    /// origin); `jump_image` its exact source map. `None` when the result
    /// records no sources (vertex colours without `SourceTexels`).
    pub sources: Option<Vec<[f32; 2]>>,
    /// The exemplar's width and height in pixels (the range of `sources`).
    pub exemplar_size: [u32; 2],
}

/// A synthesised image (`jump_image`): the image at one exemplar pixel per
/// pixel and, per pixel, its source in exemplar pixel coordinates (as the
/// method returns them: integer indices for pixel and patch synthesis,
/// continuous for controlled synthesis). The `export` format `plane` writes
/// it when the active mesh carries no result.
#[derive(Resource, Clone, Debug)]
pub struct SynthesisedImage {
    /// The image, the exemplar's channel count.
    pub image: Image,
    /// Row-major per-pixel source coordinates.
    pub sources: Vec<[f32; 2]>,
}

/// Per fan triangle of the active mesh (see `PolyMesh::triangulate_corners`),
/// the texture coordinates of its three corners for each of the three choices
/// of base vertex: the 3-way blend of Zelinka & Garland §6.5, stored
/// compactly (per-vertex texels and per-corner side offsets; read through
/// [`BlendUvs::of`]).
#[derive(Component, Clone, Debug, Default)]
pub struct BlendUvs(pub crate::kernels::jump_surface::BlendLayers);

impl BlendUvs {
    /// The layers for `mesh`, or `None` when they were made for another mesh.
    pub fn of<'a>(
        &'a self,
        mesh: &'a crate::mesh::PolyMesh,
    ) -> Option<crate::kernels::jump_surface::Blend<'a>> {
        self.0
            .fits(mesh)
            .then_some(crate::kernels::jump_surface::Blend::Compact {
                layers: &self.0,
                mesh,
            })
    }
}

/// The exemplar's jump map (Zelinka & Garland 2004 §4), made by `jump_map`.
#[derive(Resource, Clone, Debug)]
pub struct ExemplarJumpMap(pub std::sync::Arc<crate::kernels::jump_map::JumpMap>);

/// Records a stage failure (the first one wins); later stages do not run.
pub fn fail(failure: &mut StageFailure, index: usize, kind: &str, message: impl Into<String>) {
    if failure.0.is_none() {
        failure.0 = Some(crate::pipeline::PipelineError::Stage {
            index: index + 1,
            kind: kind.to_string(),
            message: message.into(),
        });
    }
}

// ----- mesh pyramid ------------------------------------------------------------

/// The entities of the mesh pyramid, finest level first: every entity with a
/// [`MeshLevel`] except the source mesh, or the source mesh alone (a one-level
/// pyramid) when there is no other. `levels` lists `(entity, level, is the
/// source mesh)`.
///
/// # Errors
/// A message naming the problem when the levels are not `0, 1, 2, …` each
/// exactly once.
pub fn pyramid_entities(
    levels: impl IntoIterator<Item = (Entity, MeshLevel, bool)>,
) -> Result<Vec<Entity>, String> {
    let all: Vec<(Entity, MeshLevel, bool)> = levels.into_iter().collect();
    let has_pyramid = all.iter().any(|(_, _, source)| !source);
    let mut chosen: Vec<(MeshLevel, Entity)> = all
        .into_iter()
        .filter(|(_, _, source)| *source != has_pyramid)
        .map(|(e, l, _)| (l, e))
        .collect();
    chosen.sort();
    for (i, (level, _)) in chosen.iter().enumerate() {
        if level.0 as usize != i {
            return Err(format!(
                "the mesh pyramid's levels are {:?}; expected 0, 1, 2, … each once",
                chosen.iter().map(|(l, _)| l.0).collect::<Vec<_>>()
            ));
        }
    }
    if chosen.is_empty() {
        return Err("there is no mesh".into());
    }
    Ok(chosen.into_iter().map(|(_, e)| e).collect())
}

/// A lapped texture for runtime pasting (Praun et al. 2000 §4): the texture
/// patches and, in paste order, each paste's faces (those not hidden by
/// later pastes) with their corners' texture coordinates.
#[derive(Clone, Debug, Default)]
pub struct PasteExport {
    /// RGBA texture patches.
    pub textures: Vec<Image>,
    /// The pastes, in drawing order.
    pub pastes: Vec<PasteRecord>,
}

/// One paste of a [`PasteExport`].
#[derive(Clone, Debug, Default)]
pub struct PasteRecord {
    /// Index into [`PasteExport::textures`].
    pub texture: u32,
    /// Mesh faces to draw.
    pub faces: Vec<u32>,
    /// Texture coordinates of their corners, compactly (the corners of
    /// `faces[0]`, then of `faces[1]`, ...), `v = 0` at the top row.
    pub uvs: Vec<Vec2>,
}

// ----- √2 hierarchy (Bangay & Morkel) --------------------------------------------

/// Per-vertex sweep value (Turk 2001; Bangay & Morkel 2006 §3.1.1): grows
/// along the orientation field from an anchor; sorting by it gives the
/// synthesis order of the coarsest level.
#[derive(Component, Clone, Debug, Default)]
pub struct SweepField(pub Vec<f32>);

/// On a √2 hierarchy level: the parents of each of its vertices in the next
/// coarser level (`MeshLevel(l + 1)`), so attributes travel down the
/// hierarchy. Absent on the coarsest level.
#[derive(Component, Clone, Debug, Default)]
pub struct LevelParents(pub crate::kernels::sqrt2::Parents);

/// The √2 mesh hierarchy made by `subdivide_sqrt2`: its level entities,
/// finest first (index `l` holds `MeshLevel(l)`). Vertex ids are shared:
/// vertex `v` of a coarser level is vertex `v` of every finer one.
#[derive(Resource, Clone, Debug, Default)]
pub struct Sqrt2Pyramid(pub Vec<Entity>);

// ----- bake (issue 7) -------------------------------------------------------------

/// The result baked into a UV atlas of the ORIGINAL mesh by the `bake`
/// stage; the `export` formats `glb` and `baked_obj` write it.
#[derive(Resource, Clone, Debug, Default)]
pub struct BakedAsset {
    /// The original mesh, fan-triangulated (vertices unchanged); empty
    /// while [`BakedAsset::on_source`].
    pub mesh: PolyMesh,
    /// Per corner of `mesh`, its atlas coordinates (`v = 0` at the top row).
    pub uvs: Vec<Vec2>,
    /// The baked colour (RGB).
    pub colour: Image,
    /// Further baked exemplar maps by role (`normal`: tangent-space RGB,
    /// `roughness`, `height`: one channel), in that order when present.
    pub maps: Vec<(String, Image)>,
    /// The asset's mesh is the source mesh as the world holds it (a
    /// triangle mesh is its own fan triangulation) and `mesh` is empty:
    /// the export's previews read the world's, and `finish_export_job`
    /// copies it in once the previews and the result metrics are done, so
    /// the run does not hold a second copy of the mesh at its peak (44
    /// bytes per vertex). See [`BakedAsset::mesh_or`].
    pub on_source: bool,
}

impl BakedAsset {
    /// The asset's mesh: `source` (the source mesh's geometry) while
    /// [`BakedAsset::on_source`], else its own.
    pub fn mesh_or<'a>(&'a self, source: &'a PolyMesh) -> &'a PolyMesh {
        if self.on_source { source } else { &self.mesh }
    }
}
