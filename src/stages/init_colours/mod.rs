//! Stage `init_colours`: every vertex takes the colour of a random exemplar
//! texel (Wei & Levoy 2001 §3.1, Table 2), remembering which texel. On a mesh
//! pyramid, every level `l` draws from level `l` of the exemplar's Gaussian
//! pyramid ("assigning random colors from the corresponding level in G_a"),
//! which equalises the colour histograms level by level.

use crate::config::params::{ParamDoc, StageSettings};
use crate::stage::{Datum, Stage, StageCtx};
use crate::world::*;
use bevy_ecs::prelude::*;
use bevy_ecs::schedule::ScheduleConfigs;
use bevy_ecs::system::ScheduleSystem;
use glam::Vec2;
use serde::{Deserialize, Serialize};

/// Settings of `init_colours` (none yet).
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct InitColoursSettings {}

impl StageSettings for InitColoursSettings {
    const PARAMS: &'static [ParamDoc] = &[];
}

/// Random exemplar texels for `count` vertices: colours and source texel
/// coordinates. Vertex `v` draws from its own stream `mix(seed, v)`, so the
/// result does not depend on thread count.
pub fn random_texels(
    exemplar: &crate::image::Image,
    count: usize,
    seed: u64,
) -> (VertexColours, SourceTexels) {
    use rayon::prelude::*;
    let c = exemplar.channels as usize;
    let (w, h) = (exemplar.width as u64, exemplar.height as u64);
    let mut values = vec![0.0f32; count * c];
    let mut texels = vec![Vec2::ZERO; count];
    values
        .par_chunks_mut(c)
        .zip(texels.par_iter_mut())
        .enumerate()
        .for_each(|(v, (out, texel))| {
            let r = mix(seed, v as u64, 1);
            let x = ((r >> 32) * w) >> 32;
            let y = ((r & 0xFFFF_FFFF) * h) >> 32;
            out.copy_from_slice(exemplar.pixel(x as u32, y as u32));
            *texel = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
        });
    (
        VertexColours {
            channels: c,
            values,
        },
        SourceTexels(texels),
    )
}

/// The `init_colours` stage.
pub struct InitColours;

impl Stage for InitColours {
    const KIND: &'static str = "init_colours";
    const SUMMARY: &'static str = "every vertex takes a random exemplar texel's colour";
    const PAPER: &'static str = "Wei & Levoy 2001 §3.1";
    type Settings = InitColoursSettings;

    fn requires(_: &Self::Settings) -> Vec<Datum> {
        vec![Datum::Mesh]
    }
    fn produces(_: &Self::Settings) -> Vec<Datum> {
        vec![Datum::Colours]
    }
    fn systems(_settings: Self::Settings, ctx: StageCtx) -> ScheduleConfigs<ScheduleSystem> {
        (move |mut commands: Commands,
               active: Res<ActiveMesh>,
               seed: Res<RunSeed>,
               exemplar: Res<Exemplar>,
               levels: Query<(Entity, &MeshLevel, Has<SourceMesh>), With<Geometry>>,
               meshes: Query<&Geometry>| {
            // Pyramid levels other than the loaded mesh, finest first.
            let pyramid: Vec<Entity> = pyramid_entities(
                levels
                    .iter()
                    .filter(|(_, _, source)| !source)
                    .map(|(e, l, s)| (e, *l, s)),
            )
            .unwrap_or_default();
            let images = crate::image::pyramid::gaussian_pyramid(
                &exemplar.image,
                pyramid.len().max(1),
                exemplar.wrap,
            );
            for (l, &e) in pyramid.iter().enumerate() {
                let Ok(geometry) = meshes.get(e) else {
                    continue;
                };
                let (colours, mut texels) = random_texels(
                    &images[l],
                    geometry.0.vertex_count(),
                    seed.derive(ctx.index, l as u64),
                );
                // Texels in pixels of the exemplar itself (level 0).
                let scale = 2f32.powi(l as i32);
                for t in &mut texels.0 {
                    *t = (*t - Vec2::splat(0.5)) * scale + Vec2::splat(0.5);
                }
                commands.entity(e).insert((colours, texels));
            }
            if !pyramid.contains(&active.0) {
                let Ok(geometry) = meshes.get(active.0) else {
                    return;
                };
                let (colours, texels) = random_texels(
                    &exemplar.image,
                    geometry.0.vertex_count(),
                    seed.derive(ctx.index, 0),
                );
                commands.entity(active.0).insert((colours, texels));
            }
        })
        .into_configs()
    }
}
