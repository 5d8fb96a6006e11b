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
}

impl Default for ExportSettings {
    fn default() -> Self {
        Self {
            formats: vec!["ply".into(), "obj".into(), "preview".into()],
            preview_size: 512,
            name: "result".into(),
        }
    }
}

impl StageSettings for ExportSettings {
    const PARAMS: &'static [ParamDoc] = &[
        ParamDoc {
            name: "formats",
            unit: "",
            range: ParamRange::OneOf(&["ply", "obj", "preview"]),
            doc: "ply: binary PLY with vertex colours; obj: OBJ+MTL+PNG (per-corner UVs and the texture when the result has them, else vertex colours); preview: 3 shaded PNG views",
        },
        ParamDoc {
            name: "preview_size",
            unit: "pixels",
            range: ParamRange::Int(64, 4096),
            doc: "width and height of each preview image",
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
            *job = ExportJob {
                formats: settings.formats.clone(),
                stem: settings.name.clone(),
                mesh: mesh.clone(),
                colours: colours.cloned(),
                uvs: uvs.map(|u| (u.0.clone(), exemplar.image.clone())),
                previews,
                images,
            };
        })
        .into_configs()
    }
}
