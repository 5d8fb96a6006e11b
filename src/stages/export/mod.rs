//! Stage `export`: prepares the result for writing (mesh, colours or UVs,
//! rendered previews). The runner writes the files after the schedule, so
//! systems never touch the file system.
//!
//! Reads: `ActiveMesh` (`Geometry`, `VertexColours`, `CornerUvs`,
//! `BlendUvs`, `AtlasTexture`, `SourceTexels`, `Frames`, `VertexScale`,
//! lapped pastes), `TexturePatches`, `TexturePatchOrigins`,
//! `SynthesisedImage`, `BakedAsset`, the `SourceMesh` (its colours after
//! `map_back`), `Exemplar`, `TextureScale`. Writes: `ExportJob` (the parts
//! of `prepare.rs`; the arrays follow in [`finish_export_job`], after the
//! schedule), `PlaneImage` (format `plane`).

use crate::config::params::{ParamDoc, ParamRange, StageSettings};
use crate::stage::memory::{InputSizes, MemoryEstimate};
use crate::stage::{Datum, Stage, StageCtx, SystemResult};
use crate::world::*;
use bevy_ecs::prelude::*;
use bevy_ecs::query::ROQueryItem;
use bevy_ecs::schedule::ScheduleConfigs;
use bevy_ecs::system::ScheduleSystem;
use prepare::{ActiveResult, files, original, plane_image};
use serde::{Deserialize, Serialize};

mod finish;
pub mod plane;
mod prepare;

pub use finish::{Transfer, finish_export_job};

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

impl ExportSettings {
    /// Whether `format` is among the formats asked for.
    pub fn wants(&self, format: &str) -> bool {
        self.formats.iter().any(|f| f == format)
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

/// What the export reads of the active mesh.
type ExportData = (
    &'static Geometry,
    Option<&'static VertexColours>,
    Option<&'static CornerUvs>,
    Option<&'static BlendUvs>,
    Option<&'static AtlasTexture>,
    Option<&'static SourceTexels>,
    Option<&'static Frames>,
    Option<&'static VertexScale>,
);

/// The mesh entities the export reads.
type ExportQuery<'w, 's> = Query<'w, 's, ExportData>;

/// One item of [`ExportQuery`].
type ExportItem<'a> = ROQueryItem<'a, 'a, ExportData>;

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
        let export = move |mut commands: Commands,
                           active: Res<ActiveMesh>,
                           baked_asset: Option<Res<BakedAsset>>,
                           exemplar: Res<Exemplar>,
                           mut job: ResMut<ExportJob>,
                           meshes: ExportQuery,
                           pastes: Query<PasteQuery>,
                           patches: PatchResources,
                           texture_scale: Option<Res<TextureScale>>,
                           originals: Originals,
                           sources: Query<&Geometry, With<SourceMesh>>,
                           ticks: bevy_ecs::system::SystemChangeTick|
              -> SystemResult {
            let Ok(item) = meshes.get(active.0) else {
                return Ok(());
            };
            // The `bake` stage's asset (formats glb, baked_obj).
            let wants_asset = settings.wants("glb") || settings.wants("baked_obj");
            if wants_asset && baked_asset.is_none() {
                return Err("formats `glb` and `baked_obj` write the `bake` stage's atlas: add a `bake` stage before `export`".into());
            }
            let (patch_textures, patch_origins, synthesised) = patches;
            let run_scale = texture_scale.as_deref().map(|t| [t.texels_per_unit]);
            let r = active_result(
                item,
                &pastes,
                active.0,
                patch_textures.as_deref().map_or(&[], |t| t.0.as_slice()),
                run_scale.as_ref().map(|s| s.as_slice()),
            );
            let origins = patch_origins.as_deref().map_or(&[][..], |o| o.0.as_slice());
            let plane = settings
                .wants("plane")
                .then(|| plane_image(&settings, &r, &exemplar, origins, synthesised.as_deref()))
                .transpose()?;
            if let Some(p) = &plane {
                commands.insert_resource(p.clone());
            }
            let images = std::mem::take(&mut job.images);
            let source = sources.iter().next().map(|g| &g.0);
            let asset = baked_asset.as_deref();
            let mut prepared = files(&settings, &r, &exemplar, asset, source, images);
            prepared.source = Some(ExportSource {
                entity: active.0,
                stage: ctx.index + 1,
                colours: r.colours.is_some(),
                uvs: r.export_uvs(),
                // The pastes themselves are taken by `finish_export_job`.
                pastes: (r.lapped_ok && settings.wants("pastes"))
                    .then(|| r.patch_textures.to_vec()),
                tick: ticks.this_run(),
            });
            prepared.take_baked_asset = wants_asset;
            prepared.original = original(&settings, originals.single().ok(), active.0);
            prepared.plane = plane;
            *job = prepared;
            Ok(())
        };
        ctx.fallible(Self::KIND, export)
    }
}

/// The input mesh with its colours (a `map_back` result).
type Originals<'w, 's> =
    Query<'w, 's, (Entity, &'static Geometry, &'static VertexColours), With<SourceMesh>>;

/// The lapped texture patches, where each lies in the exemplar, and a
/// `jump_image` result.
type PatchResources<'w> = (
    Option<Res<'w, TexturePatches>>,
    Option<Res<'w, TexturePatchOrigins>>,
    Option<Res<'w, SynthesisedImage>>,
);

/// The active result as the export reads it: `item` of the active mesh
/// `entity` and its pastes (in paste order); `run_scale`, the run's texels
/// per unit, for a result that records no per-vertex scale.
fn active_result<'a>(
    item: ExportItem<'a>,
    pastes: &'a Query<PasteQuery>,
    entity: Entity,
    patch_textures: &'a [crate::image::Image],
    run_scale: Option<&'a [f32]>,
) -> ActiveResult<'a> {
    let (geometry, colours, uvs, blend, atlas, source_texels, frames, vertex_scale) = item;
    let mesh = &geometry.0;
    let mut lapped: Vec<_> = pastes.iter().filter(|p| p.0.0 == entity).collect();
    lapped.sort_by_key(|p| *p.1);
    let lapped_ok = !lapped.is_empty()
        && lapped
            .iter()
            .all(|p| (p.2.0 as usize) < patch_textures.len());
    let n = mesh.vertex_count();
    let coordinates = match (source_texels, frames) {
        (Some(st), Some(f)) if st.0.len() == n && f.0.len() == n => {
            let scale: Option<&[f32]> = match vertex_scale {
                Some(s) if s.0.len() == n => Some(&s.0),
                _ => run_scale,
            };
            scale.map(|scale| (st.0.as_slice(), f.0.as_slice(), scale))
        }
        _ => None,
    };
    ActiveResult {
        mesh,
        colours,
        uvs,
        blend: blend.and_then(|b| b.of(mesh)),
        atlas,
        source_texels,
        coordinates,
        lapped,
        patch_textures,
        lapped_ok,
    }
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
