//! What the export system prepares from the active result, part by part:
//! the plane image, the preview renders, the baked atlas of a per-corner-UV
//! result, the per-vertex colours of a PLY, the mapped-back original.

use super::plane::{self, PlaneSignal};
use super::{ExportSettings, PasteQuery, PlaneColours};
use crate::image::Image;
use crate::image::sample::Wrap;
use crate::kernels::atlas::bake_layout::single_layers;
use crate::kernels::atlas::bake_triangles::bake_blended;
use crate::kernels::atlas::vertex_colours_from_uvs::vertex_colours_from_corner_uvs;
use crate::kernels::jump_maps::jump_surface::Blend;
use crate::kernels::lapped::composite::{LappedComposite, PasteRecord};
use crate::kernels::surface::frames::TangentFrame;
use crate::mesh::PolyMesh;
use crate::output::render::{Layer, RenderOptions, Shading, render_views};
use crate::world::*;
use bevy_ecs::entity::Entity;
use bevy_ecs::query::ROQueryItem;
use glam::Vec2;

/// One item of a query of [`PasteQuery`].
pub(super) type PasteItem<'a> = ROQueryItem<'a, 'a, PasteQuery>;

/// The active result as the export reads it.
pub(super) struct ActiveResult<'a> {
    pub mesh: &'a PolyMesh,
    pub colours: Option<&'a VertexColours>,
    pub uvs: Option<&'a CornerUvs>,
    /// The jump-map blend layers, when made for this mesh.
    pub blend: Option<Blend<'a>>,
    pub atlas: Option<&'a AtlasTexture>,
    pub source_texels: Option<&'a SourceTexels>,
    /// A per-vertex result's exemplar coordinates, frames and scale
    /// (texels per unit: per vertex, or the run's), where recorded.
    pub coordinates: Option<(&'a [Vec2], &'a [TangentFrame], &'a [f32])>,
    /// Lapped-texture pastes on the mesh, in paste order.
    pub lapped: Vec<PasteItem<'a>>,
    pub patch_textures: &'a [Image],
    /// The pastes are the result: some exist and every one names a patch.
    pub lapped_ok: bool,
}

impl ActiveResult<'_> {
    /// The texture coordinates the OBJ writes.
    pub fn export_uvs(&self) -> ExportUvs {
        match (self.uvs, self.atlas) {
            (Some(_), _) => ExportUvs::Corner,
            (None, Some(_)) => ExportUvs::Atlas,
            (None, None) => ExportUvs::None,
        }
    }
}

/// The export job of the result's files: the previews (added to the
/// further `images`), the baked atlas of a per-corner-UV result (`baked`,
/// or its `obj`), a PLY's per-vertex colours; the entity to read the
/// rest from, the `bake` stage's asset, the original and the plane image
/// are left for the caller.
pub(super) fn files(
    settings: &ExportSettings,
    r: &ActiveResult,
    exemplar: &Exemplar,
    baked_asset: Option<&BakedAsset>,
    source: Option<&PolyMesh>,
    mut images: Vec<(String, Image)>,
) -> ExportJob {
    let previews = if settings.wants("preview") {
        previews(settings, r, exemplar, baked_asset, source, &mut images)
    } else {
        Vec::new()
    };
    // A blended per-corner-UV result's `result.obj` is the baked one, so
    // that it looks like its preview in any OBJ reader.
    let obj_blended = settings.wants("obj") && r.uvs.is_some() && r.blend.is_some();
    let baked = (obj_blended || settings.wants("baked"))
        .then(|| bake(r, exemplar, settings.bake_size))
        .flatten();
    let corner_colours = settings
        .wants("ply")
        .then(|| corner_colours(r, exemplar))
        .flatten();
    ExportJob {
        formats: settings.formats.clone(),
        stem: settings.name.clone(),
        corner_colours,
        previews,
        images,
        baked,
        obj_blended,
        ..Default::default()
    }
}

/// The plane image of the result (format `plane`).
///
/// # Errors
/// When the result cannot be drawn in the plane: no result, a mesh not
/// flat in xy, pastes that do not composite, a `jump_image` of another
/// size.
pub(super) fn plane_image(
    settings: &ExportSettings,
    r: &ActiveResult,
    exemplar: &Exemplar,
    origins: &[[i64; 2]],
    synthesised: Option<&SynthesisedImage>,
) -> Result<PlaneImage, String> {
    let _span = tracing::info_span!("plane_image").entered();
    let ex = &exemplar.image;
    let ex_size = [ex.width, ex.height];
    let records: Vec<PasteRecord> = r
        .lapped
        .iter()
        .map(|p| PasteRecord {
            texture: p.2.0,
            faces: &p.3.0,
            uvs: &p.4.0,
        })
        .collect();
    let background = crate::image::pixel_rgb(&ex.mean());
    let wants_sources = settings.plane_colours == PlaneColours::Sources;
    let coordinates = r
        .coordinates
        .filter(|_| wants_sources)
        .map(|(sources, frames, scale)| PlaneSignal::Coordinates {
            sources,
            frames,
            scale,
            texture: ex,
            wrap: exemplar.wrap,
        });
    let signal = match (r.uvs, r.colours) {
        (Some(u), _) => Some(Ok(PlaneSignal::Uvs {
            uvs: &u.0,
            blend: r.blend,
            texture: ex,
            wrap: exemplar.wrap,
        })),
        (None, Some(_)) if coordinates.is_some() => coordinates.map(Ok),
        (None, Some(c)) => Some(Ok(PlaneSignal::Colours {
            values: &c.values,
            channels: c.channels,
            sources: r
                .source_texels
                .map(|s| s.0.as_slice())
                .filter(|s| s.len() == r.mesh.vertex_count()),
        })),
        (None, None) if r.lapped_ok => Some(
            LappedComposite::new(r.mesh, &records, r.patch_textures, &background).map(
                |composite| PlaneSignal::Lapped {
                    composite,
                    textures: r.patch_textures,
                    origins,
                },
            ),
        ),
        (None, None) => None,
    };
    match (signal, synthesised) {
        (Some(Ok(signal)), _) => plane::plane_from_surface_at(
            r.mesh,
            &signal,
            settings.plane_size,
            ex_size,
            settings.plane_pixel,
        ),
        (Some(Err(e)), _) => Err(format!("format `plane`: the lapped pastes: {e}")),
        (None, Some(img)) => plane::plane_from_image(img, settings.plane_size, ex_size),
        (None, None) => Err("format `plane` needs a result: vertex colours, per-corner texture coordinates, lapped pastes or a `jump_image`; none exists".into()),
    }
}

/// The three preview views of the result (format `preview`); the views of
/// a lapped result's atlas (`atlas_preview_*.png`) and of the `bake`
/// stage's asset on `source` (`bake_preview_*.png`) go to `images`.
fn previews(
    settings: &ExportSettings,
    r: &ActiveResult,
    exemplar: &Exemplar,
    baked_asset: Option<&BakedAsset>,
    source: Option<&PolyMesh>,
    images: &mut Vec<(String, Image)>,
) -> Vec<Image> {
    let _span = tracing::info_span!("render_previews").entered();
    let layers: Vec<Layer> = if r.lapped_ok {
        r.lapped
            .iter()
            .map(|p| Layer {
                faces: &p.3.0,
                uvs: &p.4.0,
                texture: &r.patch_textures[p.2.0 as usize],
                wrap: Wrap::Clamp,
            })
            .collect()
    } else {
        Vec::new()
    };
    let options = RenderOptions::default();
    let size = settings.preview_size;
    let views = render_views(r.mesh, &shading(r, exemplar, &layers), size, &options);
    if let (true, Some(a)) = (r.lapped_ok, r.atlas) {
        let atlas_shading = Shading::CornerUvs {
            uvs: &a.uvs,
            texture: &a.image,
            wrap: Wrap::Clamp,
        };
        let atlas_views = render_views(r.mesh, &atlas_shading, size, &options);
        for (i, img) in atlas_views.into_iter().enumerate() {
            images.push((format!("atlas_preview_{i}.png"), img));
        }
    }
    if let Some(asset) = baked_asset {
        // The original mesh through the baked atlas.
        let baked_shading = Shading::CornerUvs {
            uvs: &asset.uvs,
            texture: &asset.colour,
            wrap: Wrap::Clamp,
        };
        let empty = PolyMesh::new();
        let source = source.unwrap_or(&empty);
        let baked_views = render_views(asset.mesh_or(source), &baked_shading, size, &options);
        for (i, img) in baked_views.into_iter().enumerate() {
            images.push((format!("bake_preview_{i}.png"), img));
        }
    }
    views
}

/// How the previews draw the result: lapped `layers`, blended or plain
/// per-corner UVs, a lapped atlas, exemplar coordinates, vertex colours.
fn shading<'a>(
    r: &'a ActiveResult<'_>,
    exemplar: &'a Exemplar,
    layers: &'a [Layer<'_>],
) -> Shading<'a> {
    let coordinate_shading =
        r.coordinates
            .map(|(sources, frames, texels_per_unit)| Shading::Coordinates {
                sources,
                frames,
                texels_per_unit,
                texture: &exemplar.image,
                wrap: exemplar.wrap,
            });
    match (r.uvs, r.colours, r.atlas) {
        _ if r.lapped_ok => Shading::Layers(layers),
        _ if r.blend.is_some() => Shading::BlendedUvs {
            layers: r.blend.unwrap_or(Blend::Full(&[])),
            texture: &exemplar.image,
            wrap: exemplar.wrap,
        },
        (Some(uv), _, _) => Shading::CornerUvs {
            uvs: &uv.0,
            texture: &exemplar.image,
            wrap: exemplar.wrap,
        },
        (None, _, Some(a)) => Shading::CornerUvs {
            uvs: &a.uvs,
            texture: &a.image,
            wrap: Wrap::Clamp,
        },
        // A per-vertex result with exemplar coordinates is drawn at the
        // exemplar's resolution, as `bake` reads it.
        (None, Some(_), None) if coordinate_shading.is_some() => {
            coordinate_shading.unwrap_or(Shading::Plain)
        }
        (None, Some(c), None) => Shading::VertexColours {
            values: &c.values,
            channels: c.channels,
        },
        (None, None, None) => Shading::Plain,
    }
}

/// Bakes per-corner UVs (blended when blend layers exist) into a
/// per-triangle atlas image; `None` when the result has no UVs. The
/// triangulated mesh and its atlas coordinates are made when the file is
/// written ([`crate::output::export::baked_mesh`]), not held meanwhile.
fn bake(r: &ActiveResult, exemplar: &Exemplar, size: u32) -> Option<Image> {
    let _span = tracing::info_span!("bake").entered();
    // The compact blend layers are read in place, not expanded.
    let single: Vec<[[Vec2; 3]; 3]>;
    let layers = match (r.blend, r.uvs) {
        (Some(b), _) => b,
        (_, Some(u)) if u.0.len() == r.mesh.corner_count() => {
            single = single_layers(r.mesh, &u.0);
            (&single).into()
        }
        _ => return None,
    };
    Some(bake_blended(layers, &exemplar.image, exemplar.wrap, size))
}

/// PLY carries colours per vertex only: a per-corner-UV result (or a
/// lapped atlas) gets the colour its preview shows at each vertex; `None`
/// for a result with vertex colours or without coordinates.
fn corner_colours(r: &ActiveResult, exemplar: &Exemplar) -> Option<VertexColours> {
    if r.colours.is_some() {
        return None;
    }
    let (uvs, blend, texture, wrap) = match (r.uvs, r.atlas) {
        (Some(u), _) => (u.0.as_slice(), r.blend, &exemplar.image, exemplar.wrap),
        (None, Some(a)) => (a.uvs.as_slice(), None, &a.image, Wrap::Clamp),
        (None, None) => return None,
    };
    let (values, channels) = vertex_colours_from_corner_uvs(r.mesh, uvs, blend, texture, wrap);
    Some(VertexColours { channels, values })
}

/// The result mapped back onto the input mesh (`map_back`): the mesh, its
/// colours and, with format `preview`, their views; `None` unless the
/// input mesh is not the active one and has a colour per vertex.
pub(super) fn original(
    settings: &ExportSettings,
    input: Option<(Entity, &Geometry, &VertexColours)>,
    active: Entity,
) -> Option<(PolyMesh, VertexColours, Vec<Image>)> {
    let (_, g, c) = input
        .filter(|(e, g, c)| *e != active && c.values.len() == g.0.vertex_count() * c.channels)?;
    let previews = if settings.wants("preview") {
        let shading = Shading::VertexColours {
            values: &c.values,
            channels: c.channels,
        };
        render_views(
            &g.0,
            &shading,
            settings.preview_size,
            &RenderOptions::default(),
        )
    } else {
        Vec::new()
    };
    Some((g.0.clone(), c.clone(), previews))
}
