//! What the `export` stage asks the writer to write: the [`ExportJob`] (the
//! result mesh, its colours or coordinates, previews, images), the planar
//! image of a flat result ([`PlaneImage`]) and the `bake` stage's atlas of
//! the original mesh ([`BakedAsset`]). Systems do no file I/O; `output`
//! writes these after the run.

use super::lapped::PasteExport;
use super::mesh::VertexColours;
use crate::image::Image;
use crate::mesh::PolyMesh;
use bevy_ecs::prelude::*;
use glam::Vec2;

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

/// What the `export` stage asks the runner to write (systems do no file I/O).
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

/// The result as an image (the `export` format `plane`): the active result
/// sampled at one pixel per pixel over the xy bounding box of a mesh that is
/// flat in xy, or a `jump_image` result itself. Inserted by the `export`
/// stage (its position in the config, before the result metrics run) when
/// its `formats` include `plane`; absent otherwise.
///
/// - Pixel `(i, j)` (column `i`, row `j`, row 0 at the top) samples the xy
///   point `(min.x + i / (width − 1) · Δx, max.y − j / (height − 1) · Δy)`
///   of the mesh's xy bounding box (pixel centres span the box edge to
///   edge): image-up is `+y` (`kernels::atlas::plane_raster`). On the configs'
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
