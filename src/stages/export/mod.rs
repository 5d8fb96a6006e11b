//! Stage `export`: prepares the result for writing (mesh, colours or UVs,
//! rendered previews). The runner writes the files after the schedule, so
//! systems never touch the file system.

use crate::config::params::{ParamDoc, ParamRange, StageSettings};
use crate::kernels::jump_maps::jump_surface::Blend;
use crate::output::render::{Layer, RenderOptions, Shading, render_views};
use crate::stage::memory::{InputSizes, MemoryEstimate};
use crate::stage::{Datum, Stage, StageCtx, StageError};
use crate::world::*;
use bevy_ecs::prelude::*;
use bevy_ecs::schedule::ScheduleConfigs;
use bevy_ecs::system::ScheduleSystem;
use serde::{Deserialize, Serialize};

pub mod plane;

/// Bytes per preview pixel of the three views together (measured 36.5 at
/// 512² and 1024², 73 when a `bake` before adds its three views of the
/// baked asset): each view's colour, depth and shading buffers.
pub const BYTES_PER_PREVIEW_PIXEL: u64 = 45;

/// Bytes per texel of format `baked` (measured 12 in the stage): the RGB
/// atlas, then its 8-bit copy and the encoder's buffers when written.
pub const BYTES_PER_BAKED_TEXEL: u64 = 16;

/// Bytes per pixel of format `plane` (measured 40-43 at 256² and 1024²):
/// the pixel hits, the RGB image and its sources, the 16-bit source map
/// and the encoded copies.
pub const BYTES_PER_PLANE_PIXEL: u64 = 44;

/// Settings of `export`.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ExportSettings {
    /// Output formats.
    pub formats: Vec<String>,
    /// Preview image size, pixels.
    pub preview_size: u32,
    /// File name stem of the mesh files.
    pub name: String,
    /// Side of the baked atlas texture, pixels.
    pub bake_size: u32,
    /// Width and height of `plane.png` (format `plane`), pixels.
    pub plane_size: [u32; 2],
    /// How `plane.png` draws a per-vertex result.
    pub plane_colours: PlaneColours,
    /// World units between `plane.png`'s pixel centres; 0 = they span the
    /// mesh's bounding box.
    pub plane_pixel: f32,
}

/// How the `plane` format draws a per-vertex result.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PlaneColours {
    /// Each vertex's exemplar coordinate continued across its triangles
    /// through its tangent frame, the exemplar sampled there and blended
    /// (`plane::PlaneSignal::Coordinates`); vertex colours where the result
    /// records no coordinates or frames.
    Sources,
    /// The vertex colours, interpolated across each triangle.
    #[default]
    Vertex,
}

impl Default for ExportSettings {
    fn default() -> Self {
        Self {
            formats: vec!["ply".into(), "obj".into(), "preview".into()],
            preview_size: 512,
            name: "result".into(),
            bake_size: 1024,
            plane_size: [256, 256],
            plane_colours: PlaneColours::Vertex,
            plane_pixel: 0.0,
        }
    }
}

impl StageSettings for ExportSettings {
    const PARAMS: &'static [ParamDoc] = &[
        ParamDoc {
            name: "formats",
            unit: "",
            range: ParamRange::OneOf(&[
                "ply",
                "obj",
                "preview",
                "baked",
                "pastes",
                "glb",
                "baked_obj",
                "plane",
            ]),
            doc: "glb: glTF 2.0 binary of the ORIGINAL mesh with the `bake` stage's atlas (textures embedded; needs `bake` before `export`), plus view.html beside it (the result in 3D, self-contained, opens offline); baked_obj: the same as OBJ+MTL+PNG (STEM_atlas.*); ply: binary PLY with vertex normals and colours (per-corner-UV results such as jump maps: the preview's blended colour at each vertex, averaged over its corners); obj: OBJ+MTL+PNG (per-corner UVs and the texture, or a lapped texture's atlas, when the result has them, else vertex colours; a jump-map result, whose look needs the 3-way blend an OBJ cannot express, is written baked into a per-triangle atlas of bake_size as in `baked`, so it looks like its preview in any OBJ reader, and its raw per-corner UVs as STEM_corner_uvs.*); preview: 3 shaded PNG views (jump-map UVs blended 3 ways; lapped pastes composited in order, with an atlas also atlas_preview_*.png); baked: OBJ+MTL+PNG with the per-corner-UV result (incl. the jump-map 3-way blend) baked into a per-triangle atlas; pastes: lapped-texture runtime pasting, OBJ with one group per paste in paste order + MTL + RGBA patch PNGs; plane: the result as an image, plane.png (8-bit RGB, plane_size) sampled over the xy bounding box of a mesh flat in xy (row 0 = max y, so image-up is +y) or a jump_image result as it is, plus plane_sources.png (16-bit RGB: R, G = the exemplar pixel x, y each pixel was copied from, B = 65535 where known, else 0)",
        },
        ParamDoc {
            name: "preview_size",
            unit: "pixels",
            range: ParamRange::Int(64, 4096),
            doc: "width and height of each preview image",
        },
        ParamDoc {
            name: "bake_size",
            unit: "pixels",
            range: ParamRange::Int(64, 16384),
            doc: "side of the baked atlas texture (format `baked`)",
        },
        ParamDoc {
            name: "plane_size",
            unit: "pixels",
            range: ParamRange::Int(1, 16384),
            doc: "[width, height] of plane.png and plane_sources.png (format `plane`); pixel centres span the mesh's xy bounding box edge to edge (pixel (i, j) at min.x + i/(width−1)·Δx, max.y − j/(height−1)·Δy; row 0 = max y), so for one exemplar pixel per output pixel use a box of (width−1) × (height−1) world units at 1 texel per unit, e.g. a 256 × 256-vertex plane of side 255; a jump_image result must be this size",
        },
        ParamDoc {
            name: "plane_colours",
            unit: "",
            range: ParamRange::OneOf(&["sources", "vertex"]),
            doc: "how format `plane` draws a per-vertex result: vertex (default) interpolates the vertex colours (what a PLY viewer shows), which resamples the result through the mesh's vertex lattice; sources continues each vertex's exemplar coordinate (`SourceTexels`) across its triangles through its tangent frame at the result's texels per unit and blends the three corners' exemplar samples, so the image has the exemplar's resolution wherever neighbouring sources agree. Results without source coordinates or frames are drawn from their vertex colours either way; on a grid with a vertex at every pixel centre both are the same",
        },
        ParamDoc {
            name: "plane_pixel",
            unit: "world units",
            range: ParamRange::Float(0.0, 1e9),
            doc: "distance between plane.png's pixel centres; 0 (default) = they span the mesh's xy bounding box edge to edge (see plane_size); > 0 = pixel (i, j) at (min.x + i·plane_pixel, max.y − j·plane_pixel), from the box's top-left corner whatever its size (pixels beyond the mesh stay black, sources unknown), e.g. 1 on a 257 × 257-vertex grid of side 256 puts a vertex at every pixel centre of a 256 × 256 image (what a √2 hierarchy of a 17 × 17 quad grid reaches)",
        },
        ParamDoc {
            name: "name",
            unit: "",
            range: ParamRange::Any("a file name stem without folders"),
            doc: "stem of the mesh files (`result.ply`, `result.obj`)",
        },
    ];

    fn check(&self) -> Result<(), (String, String)> {
        if self.name.is_empty() || self.name.contains(['/', '\\']) || self.name.starts_with('.') {
            return Err((
                "name".into(),
                format!(
                    "{:?} is not a plain file name stem (no folders, not empty, no leading dot)",
                    self.name
                ),
            ));
        }
        Ok(())
    }
}

/// Bakes per-corner UVs (blended when blend layers exist) into a
/// per-triangle atlas image; `None` when the result has no UVs. The
/// triangulated mesh and its atlas coordinates are made when the file is
/// written ([`crate::output::export::baked_mesh`]), not held meanwhile.
fn bake(
    mesh: &crate::mesh::PolyMesh,
    uvs: Option<&CornerUvs>,
    blend: Option<&BlendUvs>,
    exemplar: &Exemplar,
    size: u32,
) -> Option<crate::image::Image> {
    use crate::kernels::atlas::bake_triangles::bake_blended;
    // The compact blend layers are read in place, not expanded.
    let single: Vec<[[glam::Vec2; 3]; 3]>;
    let layers = match (blend.and_then(|b| b.of(mesh)), uvs) {
        (Some(b), _) => b,
        (_, Some(u)) if u.0.len() == mesh.corner_count() => {
            single = mesh
                .triangulate_corners()
                .0
                .iter()
                .map(|t| {
                    let l = t.map(|c| u.0[c as usize]);
                    [l; 3]
                })
                .collect();
            (&single).into()
        }
        _ => return None,
    };
    Some(bake_blended(layers, &exemplar.image, exemplar.wrap, size))
}

type ExportQuery<'w, 's> = Query<
    'w,
    's,
    (
        &'static Geometry,
        Option<&'static VertexColours>,
        Option<&'static CornerUvs>,
        Option<&'static BlendUvs>,
        Option<&'static AtlasTexture>,
        Option<&'static SourceTexels>,
        Option<&'static Frames>,
        Option<&'static VertexScale>,
    ),
>;

/// The `export` stage.
pub struct Export;

impl Stage for Export {
    const KIND: &'static str = "export";
    const SUMMARY: &'static str =
        "writes the result mesh (PLY, OBJ+MTL+PNG) and preview renders into the output folder";
    const PAPER: &'static str = "-";
    type Settings = ExportSettings;

    /// Each format's input, so that a format that cannot be written is
    /// refused with the config, before any work: `glb` and `baked_obj` need
    /// the `bake` stage's atlas, `pastes` lapped pastes, `baked` per-corner
    /// texture coordinates (`plane` is checked through [`Self::plane_role`]).
    fn requires(settings: &Self::Settings) -> Vec<Datum> {
        let mut needs = Vec::new();
        for format in &settings.formats {
            let need = match format.as_str() {
                "glb" | "baked_obj" => Datum::BakedAtlas,
                "pastes" => Datum::Patches,
                "baked" => Datum::CornerUvs,
                _ => continue,
            };
            if !needs.contains(&need) {
                needs.push(need);
            }
        }
        needs
    }
    fn produces(_: &Self::Settings) -> Vec<Datum> {
        vec![]
    }
    /// Per format asked for: the preview views (`preview_size`), the
    /// baked atlas (`baked`: `bake_size`) and the plane image (`plane`:
    /// `plane_size`). An `obj` of a jump-map result is baked at
    /// `bake_size` too; that result is only known at run time, so it is not
    /// estimated here.
    fn memory_estimate(settings: &Self::Settings, _sizes: &InputSizes) -> Vec<MemoryEstimate> {
        let has = |f: &str| settings.formats.iter().any(|g| g == f);
        let side = |param: &'static str, what: &str, value: u32, range: (u64, u64), per: u64| {
            MemoryEstimate::growing(
                param,
                what,
                u64::from(value),
                range,
                move |s| (s * s).saturating_mul(per),
                |s| s.to_string(),
            )
        };
        let mut out = Vec::new();
        if has("preview") {
            out.push(side(
                "preview_size",
                "the three preview views and their renderer buffers",
                settings.preview_size,
                (64, 4096),
                BYTES_PER_PREVIEW_PIXEL,
            ));
        }
        if has("baked") {
            out.push(side(
                "bake_size",
                "the baked per-triangle atlas and its written copy",
                settings.bake_size,
                (64, 16384),
                BYTES_PER_BAKED_TEXEL,
            ));
        }
        if has("plane") {
            let [w, h] = settings.plane_size;
            out.push(MemoryEstimate::image(
                "plane_size",
                "plane.png and plane_sources.png: pixel hits, colours, sources and encoded copies",
                (w, h),
                16384,
                |a, b| (a * b).saturating_mul(BYTES_PER_PLANE_PIXEL),
            ));
        }
        out
    }
    fn plane_role(settings: &Self::Settings) -> crate::stage::PlaneRole {
        if settings.formats.iter().any(|f| f == "plane") {
            crate::stage::PlaneRole::Request {
                width: settings.plane_size[0],
                height: settings.plane_size[1],
            }
        } else {
            crate::stage::PlaneRole::Keeps
        }
    }
    fn systems(settings: Self::Settings, ctx: StageCtx) -> ScheduleConfigs<ScheduleSystem> {
        (move |mut commands: Commands,
               active: Res<ActiveMesh>,
               baked_asset: Option<Res<BakedAsset>>,
               mut failure: ResMut<StageFailure>,
               exemplar: Res<Exemplar>,
               mut job: ResMut<ExportJob>,
               meshes: ExportQuery,
               pastes: Query<PasteQuery>,
               patch_textures: Option<Res<TexturePatches>>,
               (patch_origins, synthesised): (
            Option<Res<TexturePatchOrigins>>,
            Option<Res<SynthesisedImage>>,
        ),
               texture_scale: Option<Res<TextureScale>>,
               originals: Query<(Entity, &Geometry, &VertexColours), With<SourceMesh>>,
               sources: Query<&Geometry, With<SourceMesh>>,
               ticks: bevy_ecs::system::SystemChangeTick| {
            let Ok((geometry, colours, uvs, blend, atlas, source_texels, frames, vertex_scale)) =
                meshes.get(active.0)
            else {
                return;
            };
            // The `bake` stage's asset (formats glb, baked_obj).
            let wants_asset = settings
                .formats
                .iter()
                .any(|f| f == "glb" || f == "baked_obj");
            if wants_asset && baked_asset.is_none() {
                fail(
                    &mut failure,
                    ctx.index,
                    Self::KIND,
                    "formats `glb` and `baked_obj` write the `bake` stage's atlas: add a `bake` stage before `export`",
                );
                return;
            }
            let mesh = &geometry.0;
            // Lapped-texture pastes on the active mesh, in paste order.
            let mut lapped: Vec<_> = pastes.iter().filter(|p| p.0.0 == active.0).collect();
            lapped.sort_by_key(|p| *p.1);
            let patch_textures = patch_textures
                .as_deref()
                .map(|t| t.0.as_slice())
                .unwrap_or(&[]);
            let lapped_ok = !lapped.is_empty()
                && lapped
                    .iter()
                    .all(|p| (p.2.0 as usize) < patch_textures.len());
            // A per-vertex result's exemplar coordinates, frames and scale
            // (texels per unit: per vertex, or the run's), where recorded.
            let n = mesh.vertex_count();
            let run_scale = texture_scale.as_deref().map(|t| [t.texels_per_unit]);
            let coordinates = match (source_texels, frames) {
                (Some(st), Some(f)) if st.0.len() == n && f.0.len() == n => {
                    let scale: Option<&[f32]> = match vertex_scale {
                        Some(s) if s.0.len() == n => Some(&s.0),
                        _ => run_scale.as_ref().map(|s| s.as_slice()),
                    };
                    scale.map(|scale| (st.0.as_slice(), f.0.as_slice(), scale))
                }
                _ => None,
            };
            let plane_image = if settings.formats.iter().any(|f| f == "plane") {
                let _span = tracing::info_span!("plane_image").entered();
                let ex = &exemplar.image;
                let ex_size = [ex.width, ex.height];
                let records: Vec<crate::kernels::lapped::composite::PasteRecord> = lapped
                    .iter()
                    .map(|p| crate::kernels::lapped::composite::PasteRecord {
                        texture: p.2.0,
                        faces: &p.3.0,
                        uvs: &p.4.0,
                    })
                    .collect();
                let background = crate::image::pixel_rgb(&ex.mean());
                let wants_sources = settings.plane_colours == PlaneColours::Sources;
                let coordinates = coordinates.filter(|_| wants_sources).map(
                    |(sources, frames, scale)| plane::PlaneSignal::Coordinates {
                        sources,
                        frames,
                        scale,
                        texture: ex,
                        wrap: exemplar.wrap,
                    },
                );
                let signal = match (uvs, colours) {
                    (Some(u), _) => Some(Ok(plane::PlaneSignal::Uvs {
                        uvs: &u.0,
                        blend: blend.and_then(|b| b.of(mesh)),
                        texture: ex,
                        wrap: exemplar.wrap,
                    })),
                    (None, Some(_)) if coordinates.is_some() => coordinates.map(Ok),
                    (None, Some(c)) => Some(Ok(plane::PlaneSignal::Colours {
                        values: &c.values,
                        channels: c.channels,
                        sources: source_texels
                            .map(|s| s.0.as_slice())
                            .filter(|s| s.len() == mesh.vertex_count()),
                    })),
                    (None, None) if lapped_ok => Some(
                        crate::kernels::lapped::composite::LappedComposite::new(
                            mesh,
                            &records,
                            patch_textures,
                            &background,
                        )
                        .map(|composite| plane::PlaneSignal::Lapped {
                            composite,
                            textures: patch_textures,
                            origins: patch_origins.as_deref().map(|o| o.0.as_slice()).unwrap_or(&[]),
                        }),
                    ),
                    (None, None) => None,
                };
                let result = match (signal, synthesised.as_deref()) {
                    (Some(Ok(signal)), _) => plane::plane_from_surface_at(
                        mesh,
                        &signal,
                        settings.plane_size,
                        ex_size,
                        settings.plane_pixel,
                    ),
                    (Some(Err(e)), _) => Err(format!("format `plane`: the lapped pastes: {e}")),
                    (None, Some(img)) => plane::plane_from_image(img, settings.plane_size, ex_size),
                    (None, None) => Err("format `plane` needs a result: vertex colours, per-corner texture coordinates, lapped pastes or a `jump_image`; none exists".into()),
                };
                match result {
                    Ok(p) => Some(p),
                    Err(e) => {
                        fail(&mut failure, ctx.index, Self::KIND, e);
                        return;
                    }
                }
            } else {
                None
            };
            if let Some(p) = &plane_image {
                commands.insert_resource(p.clone());
            }
            let mut images = std::mem::take(&mut job.images);
            let previews = if settings.formats.iter().any(|f| f == "preview") {
                let _span = tracing::info_span!("render_previews").entered();
                let layers: Vec<Layer> = if lapped_ok {
                    lapped
                        .iter()
                        .map(|p| Layer {
                            faces: &p.3.0,
                            uvs: &p.4.0,
                            texture: &patch_textures[p.2.0 as usize],
                            wrap: crate::image::sample::Wrap::Clamp,
                        })
                        .collect()
                } else {
                    Vec::new()
                };
                let blend_layers = blend.and_then(|b| b.of(mesh));
                let coordinate_shading =
                    coordinates.map(|(sources, frames, texels_per_unit)| Shading::Coordinates {
                        sources,
                        frames,
                        texels_per_unit,
                        texture: &exemplar.image,
                        wrap: exemplar.wrap,
                    });
                let shading = match (uvs, colours, atlas) {
                    _ if lapped_ok => Shading::Layers(&layers),
                    _ if blend_layers.is_some() => Shading::BlendedUvs {
                        layers: blend_layers.unwrap_or(Blend::Full(&[])),
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
                        wrap: crate::image::sample::Wrap::Clamp,
                    },
                    // A per-vertex result with exemplar coordinates is
                    // drawn at the exemplar's resolution, as `bake` reads it.
                    (None, Some(_), None) if coordinate_shading.is_some() => {
                        coordinate_shading.unwrap_or(Shading::Plain)
                    }
                    (None, Some(c), None) => Shading::VertexColours {
                        values: &c.values,
                        channels: c.channels,
                    },
                    (None, None, None) => Shading::Plain,
                };
                let options = RenderOptions::default();
                let views = render_views(mesh, &shading, settings.preview_size, &options);
                if let (true, Some(a)) = (lapped_ok, atlas) {
                    let atlas_shading = Shading::CornerUvs {
                        uvs: &a.uvs,
                        texture: &a.image,
                        wrap: crate::image::sample::Wrap::Clamp,
                    };
                    let atlas_views =
                        render_views(mesh, &atlas_shading, settings.preview_size, &options);
                    for (i, img) in atlas_views.into_iter().enumerate() {
                        images.push((format!("atlas_preview_{i}.png"), img));
                    }
                }
                if let Some(asset) = baked_asset.as_deref() {
                    // The original mesh through the baked atlas.
                    let baked_shading = Shading::CornerUvs {
                        uvs: &asset.uvs,
                        texture: &asset.colour,
                        wrap: crate::image::sample::Wrap::Clamp,
                    };
                    let empty = crate::mesh::PolyMesh::new();
                    let source = sources.iter().next().map_or(&empty, |g| &g.0);
                    let baked_views = render_views(
                        asset.mesh_or(source),
                        &baked_shading,
                        settings.preview_size,
                        &options,
                    );
                    for (i, img) in baked_views.into_iter().enumerate() {
                        images.push((format!("bake_preview_{i}.png"), img));
                    }
                }
                views
            } else {
                Vec::new()
            };
            // A blended per-corner-UV result's `result.obj` is the baked
            // one, so that it looks like its preview in any OBJ reader.
            let obj_blended = settings.formats.iter().any(|f| f == "obj")
                && uvs.is_some()
                && blend.and_then(|b| b.of(mesh)).is_some();
            let baked = if obj_blended || settings.formats.iter().any(|f| f == "baked") {
                let _span = tracing::info_span!("bake").entered();
                bake(mesh, uvs, blend, &exemplar, settings.bake_size)
            } else {
                None
            };
            // The pastes themselves are taken by `finish_export_job`.
            let paste_textures = (lapped_ok && settings.formats.iter().any(|f| f == "pastes"))
                .then(|| patch_textures.to_vec());
            let export_uvs = match (uvs, atlas) {
                (Some(_), _) => ExportUvs::Corner,
                (None, Some(_)) => ExportUvs::Atlas,
                (None, None) => ExportUvs::None,
            };
            // PLY carries colours per vertex only: a per-corner-UV result
            // gets the colour its preview shows at each vertex.
            let corner_colours = if colours.is_none() && settings.formats.iter().any(|f| f == "ply")
            {
                let source = match (uvs, atlas) {
                    (Some(u), _) => Some((
                        u.0.as_slice(),
                        blend.and_then(|b| b.of(mesh)),
                        &exemplar.image,
                        exemplar.wrap,
                    )),
                    (None, Some(a)) => Some((
                        a.uvs.as_slice(),
                        None,
                        &a.image,
                        crate::image::sample::Wrap::Clamp,
                    )),
                    (None, None) => None,
                };
                source.map(|(uvs, blend, texture, wrap)| {
                    let (values, channels) =
                        crate::kernels::atlas::vertex_colours_from_uvs::vertex_colours_from_corner_uvs(
                            mesh, uvs, blend, texture, wrap,
                        );
                    VertexColours { channels, values }
                })
            } else {
                None
            };
            // The result mapped back onto the input mesh (`map_back`).
            let original = originals
                .single()
                .ok()
                .filter(|(e, g, c)| {
                    *e != active.0 && c.values.len() == g.0.vertex_count() * c.channels
                })
                .map(|(_, g, c)| {
                    let previews = if settings.formats.iter().any(|f| f == "preview") {
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
                    (g.0.clone(), c.clone(), previews)
                });
            *job = ExportJob {
                formats: settings.formats.clone(),
                stem: settings.name.clone(),
                source: Some(ExportSource {
                    entity: active.0,
                    stage: ctx.index + 1,
                    colours: colours.is_some(),
                    uvs: export_uvs,
                    pastes: paste_textures,
                    tick: ticks.this_run(),
                }),
                mesh: Default::default(),
                colours: None,
                uvs: None,
                corner_colours,
                previews,
                images,
                baked,
                obj_blended,
                pastes: None,
                baked_asset: None,
                take_baked_asset: wants_asset,
                original,
                plane: plane_image,
            };
        })
        .into_configs()
    }
}

/// How [`finish_export_job`] gets the arrays out of the world.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Transfer {
    /// Copies them: the world stays whole (tests read it after a run).
    Copy,
    /// Moves them out, leaving empty components: for a runner that drops
    /// the world before writing files.
    Move,
}

/// Fills the export job's mesh, colours and texture coordinates from the
/// entity the `export` stage named ([`ExportSource`]). The export system
/// does not copy them: at a million vertices they are ~100 bytes per vertex
/// the run would otherwise hold twice through the result metrics.
///
/// # Errors
/// When a stage after `export` changed the exported mesh, colours or
/// coordinates (the previews show the state at export time, the files would
/// not): put `export` last.
pub fn finish_export_job(world: &mut World, transfer: Transfer) -> Result<(), StageError> {
    if world.resource::<ExportJob>().take_baked_asset {
        if transfer == Transfer::Copy {
            // The world stays whole for its readers: its asset gets the
            // mesh it refers to.
            fill_asset_mesh(world);
        }
        let asset = match transfer {
            Transfer::Copy => world.get_resource::<BakedAsset>().cloned(),
            Transfer::Move => world.remove_resource::<BakedAsset>(),
        };
        let mut job = world.resource_mut::<ExportJob>();
        job.baked_asset = asset;
        job.take_baked_asset = false;
    }
    let Some(source) = world.resource::<ExportJob>().source.clone() else {
        asset_mesh_from_source(world);
        return Ok(());
    };
    let e = source.entity;
    let now = world.read_change_tick();
    let entity = world.get_entity(e).map_err(|_| StageError {
        index: source.stage,
        kind: Export::KIND.into(),
        message:
            "the exported mesh entity is gone: a stage after `export` removed it; put `export` last"
                .into(),
    })?;
    let changed = |t: Option<bevy_ecs::change_detection::Tick>| {
        t.is_some_and(|t| t.is_newer_than(source.tick, now))
    };
    if changed(entity.get_ref::<Geometry>().map(|r| r.last_changed()))
        || changed(entity.get_ref::<VertexColours>().map(|r| r.last_changed()))
        || changed(entity.get_ref::<CornerUvs>().map(|r| r.last_changed()))
        || changed(entity.get_ref::<AtlasTexture>().map(|r| r.last_changed()))
    {
        return Err(StageError {
            index: source.stage,
            kind: Export::KIND.into(),
            message: "a stage after `export` changed the mesh it exports; put `export` last".into(),
        });
    }
    // The pastes are read here, not at export time: one a later stage made
    // or changed would be written but not previewed.
    if source.pastes.is_some() {
        let mut q = world.query::<(
            &PasteOf,
            bevy_ecs::change_detection::Ref<PatchFaces>,
            bevy_ecs::change_detection::Ref<PatchUvs>,
        )>();
        if q.iter(world).any(|(of, faces, uvs)| {
            of.0 == e && (changed(Some(faces.last_changed())) || changed(Some(uvs.last_changed())))
        }) {
            return Err(StageError {
                index: source.stage,
                kind: Export::KIND.into(),
                message: "a stage after `export` changed the pastes it exports; put `export` last"
                    .into(),
            });
        }
    }
    fn get<T: Component<Mutability = bevy_ecs::component::Mutable> + Clone + Default>(
        world: &mut World,
        e: Entity,
        transfer: Transfer,
    ) -> Option<T> {
        match transfer {
            Transfer::Copy => world.get::<T>(e).cloned(),
            Transfer::Move => world.get_mut::<T>(e).map(|mut c| std::mem::take(&mut *c)),
        }
    }
    let mesh = get::<Geometry>(world, e, transfer).unwrap_or_default().0;
    let colours = if source.colours {
        get::<VertexColours>(world, e, transfer)
    } else {
        None
    };
    let uvs = match source.uvs {
        ExportUvs::None => None,
        ExportUvs::Corner => get::<CornerUvs>(world, e, transfer)
            .map(|u| (u.0, world.resource::<Exemplar>().image.clone())),
        ExportUvs::Atlas => get::<AtlasTexture>(world, e, transfer).map(|a| (a.uvs, a.image)),
    };
    let pastes = source.pastes.map(|textures| PasteExport {
        pastes: runtime_pastes(world, e, &mesh, transfer),
        textures,
    });
    let mut job = world.resource_mut::<ExportJob>();
    job.mesh = mesh;
    job.pastes = pastes;
    job.colours = colours;
    job.uvs = uvs;
    job.source = None;
    // Last, when the mesh may have moved into the job: the asset's copy.
    asset_mesh_from_source(world);
    Ok(())
}

/// Gives the world's [`BakedAsset`] the source mesh it refers to.
fn fill_asset_mesh(world: &mut World) {
    if !world
        .get_resource::<BakedAsset>()
        .is_some_and(|a| a.on_source)
    {
        return;
    }
    let mesh = source_geometry(world).unwrap_or_default();
    let mut asset = world.resource_mut::<BakedAsset>();
    asset.mesh = mesh;
    asset.on_source = false;
}

/// Gives the export job's asset the source mesh it refers to: the job's
/// mesh when the source mesh was exported (and so moved into the job),
/// else the world's.
fn asset_mesh_from_source(world: &mut World) {
    if !world
        .resource::<ExportJob>()
        .baked_asset
        .as_ref()
        .is_some_and(|a| a.on_source)
    {
        return;
    }
    let from_world = source_geometry(world).filter(|m| m.face_count() > 0);
    let mut job = world.resource_mut::<ExportJob>();
    let mesh = from_world.unwrap_or_else(|| job.mesh.clone());
    if let Some(asset) = job.baked_asset.as_mut() {
        asset.mesh = mesh;
        asset.on_source = false;
    }
}

/// A copy of the source mesh's geometry.
fn source_geometry(world: &mut World) -> Option<crate::mesh::PolyMesh> {
    let mut q = world.query_filtered::<&Geometry, With<SourceMesh>>();
    q.iter(world).next().map(|g| g.0.clone())
}

/// What the export reads of a paste entity.
type PasteQuery = (
    &'static PasteOf,
    &'static PasteOrder,
    &'static TexturePatchIndex,
    &'static PatchFaces,
    &'static PatchUvs,
    &'static PatchDrawn,
);

/// The runtime-pasting export of the pastes of `mesh_entity` (Praun et al.
/// §4), in paste order: per paste, only the faces still drawn, with their
/// corners' texture coordinates. With [`Transfer::Move`] the paste entities'
/// arrays are moved out (the lapped stage keeps only drawn faces, so they
/// are the records as they are), not copied: at a million vertices they
/// are ~80 bytes per vertex that were held twice through the result
/// metrics.
fn runtime_pastes(
    world: &mut World,
    mesh_entity: Entity,
    mesh: &crate::mesh::PolyMesh,
    transfer: Transfer,
) -> Vec<PasteRecord> {
    let mut query = world.query::<(Entity, &PasteOf, &PasteOrder)>();
    let mut order: Vec<(u32, Entity)> = query
        .iter(world)
        .filter(|(_, of, _)| of.0 == mesh_entity)
        .map(|(e, _, o)| (o.0, e))
        .collect();
    order.sort_unstable();
    order
        .into_iter()
        .filter_map(|(_, e)| {
            let mut paste = world.get_entity_mut(e).ok()?;
            let texture = paste.get::<TexturePatchIndex>()?.0;
            let drawn = paste.get::<PatchDrawn>()?.0.clone();
            let (faces, uvs) = match transfer {
                Transfer::Copy => (
                    paste.get::<PatchFaces>()?.0.clone(),
                    paste.get::<PatchUvs>()?.0.clone(),
                ),
                Transfer::Move => (
                    std::mem::take(&mut paste.get_mut::<PatchFaces>()?.0),
                    std::mem::take(&mut paste.get_mut::<PatchUvs>()?.0),
                ),
            };
            if drawn.iter().all(|&d| d) {
                return Some(PasteRecord {
                    texture,
                    faces,
                    uvs,
                });
            }
            let mut record = PasteRecord {
                texture,
                ..Default::default()
            };
            let mut offset = 0usize;
            for (&f, &draw) in faces.iter().zip(&drawn) {
                let n = mesh.face_corners(f as usize).len();
                if draw {
                    record.faces.push(f);
                    record.uvs.extend_from_slice(&uvs[offset..offset + n]);
                }
                offset += n;
            }
            Some(record)
        })
        .collect()
}
