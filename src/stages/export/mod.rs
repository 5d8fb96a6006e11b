//! Stage `export`: prepares the result for writing (mesh, colours or UVs,
//! rendered previews). The runner writes the files after the schedule, so
//! systems never touch the file system.

use crate::config::params::{ParamDoc, ParamRange, StageSettings};
use crate::output::render::{RenderOptions, Shading, render_views};
use crate::pipeline::{Datum, Stage, StageCtx};
use crate::stages::world::*;
use bevy_ecs::prelude::*;
use bevy_ecs::schedule::ScheduleConfigs;
use bevy_ecs::system::ScheduleSystem;
use serde::{Deserialize, Serialize};

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
}

impl Default for ExportSettings {
    fn default() -> Self {
        Self {
            formats: vec!["ply".into(), "obj".into(), "preview".into()],
            preview_size: 512,
            name: "result".into(),
            bake_size: 1024,
        }
    }
}

impl StageSettings for ExportSettings {
    const PARAMS: &'static [ParamDoc] = &[
        ParamDoc {
            name: "formats",
            unit: "",
            range: ParamRange::OneOf(&["ply", "obj", "preview", "baked"]),
            doc: "ply: binary PLY with vertex colours; obj: OBJ+MTL+PNG (per-corner UVs and the texture when the result has them, else vertex colours); preview: 3 shaded PNG views; baked: OBJ+MTL+PNG with the per-corner-UV result (incl. the jump-map 3-way blend) baked into a per-triangle atlas",
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
/// per-triangle atlas; `None` when the result has no UVs.
fn bake(
    mesh: &crate::mesh::PolyMesh,
    uvs: Option<&CornerUvs>,
    blend: Option<&BlendUvs>,
    exemplar: &Exemplar,
    size: u32,
) -> Option<(crate::mesh::PolyMesh, Vec<glam::Vec2>, crate::image::Image)> {
    use crate::kernels::bake_triangles::{atlas_corner_uvs, bake_blended};
    let (tris, _) = mesh.triangulate_corners();
    let layers: Vec<[[glam::Vec2; 3]; 3]> = match (blend, uvs) {
        (Some(b), _) if b.0.len() == tris.len() => b.0.clone(),
        (_, Some(u)) if u.0.len() == mesh.corner_count() => tris
            .iter()
            .map(|t| {
                let l = t.map(|c| u.0[c as usize]);
                [l; 3]
            })
            .collect(),
        _ => return None,
    };
    let image = bake_blended(&layers, &exemplar.image, exemplar.wrap, size);
    let triangles: Vec<[u32; 3]> = tris
        .iter()
        .map(|t| t.map(|c| mesh.corner_vertex[c as usize]))
        .collect();
    let tri_mesh = crate::mesh::PolyMesh::from_triangles(mesh.positions.clone(), &triangles);
    let atlas_uvs: Vec<glam::Vec2> = (0..tris.len())
        .flat_map(|t| atlas_corner_uvs(t, tris.len(), size))
        .collect();
    Some((tri_mesh, atlas_uvs, image))
}

type ExportQuery<'w, 's> = Query<
    'w,
    's,
    (
        &'static Geometry,
        Option<&'static VertexColours>,
        Option<&'static CornerUvs>,
        Option<&'static BlendUvs>,
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

    fn requires(_: &Self::Settings) -> Vec<Datum> {
        vec![]
    }
    fn produces(_: &Self::Settings) -> Vec<Datum> {
        vec![]
    }
    fn systems(settings: Self::Settings, _ctx: StageCtx) -> ScheduleConfigs<ScheduleSystem> {
        (move |active: Res<ActiveMesh>,
               exemplar: Res<Exemplar>,
               mut job: ResMut<ExportJob>,
               meshes: ExportQuery| {
            let Ok((geometry, colours, uvs, blend)) = meshes.get(active.0) else {
                return;
            };
            let mesh = &geometry.0;
            let previews = if settings.formats.iter().any(|f| f == "preview") {
                let _span = tracing::info_span!("render_previews").entered();
                let shading = match (blend, uvs, colours) {
                    (Some(b), _, _)
                        if b.0.len()
                            == mesh.corner_count().saturating_sub(2 * mesh.face_count()) =>
                    {
                        Shading::BlendedUvs {
                            layers: &b.0,
                            texture: &exemplar.image,
                            wrap: exemplar.wrap,
                        }
                    }
                    (_, Some(uv), _) => Shading::CornerUvs {
                        uvs: &uv.0,
                        texture: &exemplar.image,
                        wrap: exemplar.wrap,
                    },
                    (_, None, Some(c)) => Shading::VertexColours {
                        values: &c.values,
                        channels: c.channels,
                    },
                    (_, None, None) => Shading::Plain,
                };
                render_views(
                    mesh,
                    &shading,
                    settings.preview_size,
                    &RenderOptions::default(),
                )
            } else {
                Vec::new()
            };
            let images = std::mem::take(&mut job.images);
            let baked = if settings.formats.iter().any(|f| f == "baked") {
                let _span = tracing::info_span!("bake").entered();
                bake(mesh, uvs, blend, &exemplar, settings.bake_size)
            } else {
                None
            };
            *job = ExportJob {
                formats: settings.formats.clone(),
                stem: settings.name.clone(),
                mesh: mesh.clone(),
                colours: colours.cloned(),
                uvs: uvs.map(|u| (u.0.clone(), exemplar.image.clone())),
                previews,
                images,
                baked,
            };
        })
        .into_configs()
    }
}
