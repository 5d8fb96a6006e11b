//! The system that follows every pipeline: texture energy (Kwatra et al.
//! 2005) and histogram distance of the result against the exemplar, written
//! to `metrics.json` under `result.quality`.

use crate::image::Image;
use crate::kernels::frames::frames_from_global_direction;
use crate::kernels::metrics::{
    EnergySettings, SurfaceSignal, histogram_wasserstein, surface_texture_energy,
};
use crate::mesh::Topology;
use crate::stages::world::*;
use bevy_ecs::prelude::*;
use bevy_ecs::schedule::ScheduleConfigs;
use bevy_ecs::system::ScheduleSystem;

type ResultQuery<'w, 's> = Query<
    'w,
    's,
    (
        &'static Geometry,
        Option<&'static Frames>,
        Option<&'static VertexColours>,
        Option<&'static CornerUvs>,
    ),
>;

/// The result-metrics system with its settings.
pub fn system(settings: EnergySettings) -> ScheduleConfigs<ScheduleSystem> {
    (move |active: Res<ActiveMesh>,
           exemplar: Res<Exemplar>,
           spacing: Res<TexelSpacing>,
           mut metrics: ResMut<Metrics>,
           meshes: ResultQuery| {
        let _span = tracing::info_span!("result_metrics").entered();
        let Ok((geometry, frames, colours, uvs)) = meshes.get(active.0) else {
            return;
        };
        let mesh = &geometry.0;
        let n = settings.neighbourhood;
        if exemplar.image.width < n || exemplar.image.height < n {
            metrics.result.insert(
                "texture_energy".into(),
                serde_json::Value::String(format!(
                    "skipped: exemplar smaller than the {n}x{n} metric neighbourhood"
                )),
            );
            return;
        }
        let signal = match (uvs, colours) {
            (Some(uv), _) => SurfaceSignal::CornerUvs {
                uvs: &uv.0,
                texture: &exemplar.image,
                wrap: exemplar.wrap,
            },
            (None, Some(c)) => SurfaceSignal::VertexColours {
                values: &c.values,
                channels: c.channels,
            },
            (None, None) => return,
        };
        let owned_frames;
        let frames = match frames {
            Some(f) if f.0.len() == mesh.vertex_count() => &f.0,
            _ => {
                owned_frames = frames_from_global_direction(&mesh.vertex_normals(), glam::Vec3::X);
                &owned_frames
            }
        };
        let topo = Topology::build(mesh);
        let stats = surface_texture_energy(
            mesh,
            &topo,
            frames,
            spacing.0,
            &signal,
            &exemplar.image,
            &settings,
        );
        metrics.result.insert(
            "texture_energy".into(),
            serde_json::json!({
                "mean": stats.mean, "p90": stats.p90, "samples": stats.samples,
                "neighbourhood": n, "spacing_world_units": spacing.0,
            }),
        );
        if let Some(c) = colours {
            let as_image = Image::from_data(
                (c.values.len() / c.channels.max(1)) as u32,
                1,
                c.channels as u32,
                c.values.clone(),
            );
            if let Some(img) = as_image {
                let w = histogram_wasserstein(&img, &exemplar.image);
                metrics
                    .result
                    .insert("histogram_wasserstein".into(), serde_json::json!(w));
            }
        }
    })
    .into_configs()
}
