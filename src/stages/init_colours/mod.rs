//! Stage `init_colours`: every vertex takes the colour of a random exemplar
//! texel (Wei & Levoy 2001 §3.1, Table 2), remembering which texel. On a mesh
//! pyramid, every level `l` draws from level `l` of the exemplar's Gaussian
//! pyramid ("assigning random colors from the corresponding level in G_a"),
//! which equalises the colour histograms level by level.
//!
//! Reads: `ActiveMesh` and the mesh pyramid's geometry, `Exemplar`,
//! `RunSeed`. Writes: `VertexColours` and `SourceTexels` on every pyramid
//! level (or the active mesh).

use crate::config::params::{ParamDoc, StageSettings};
use crate::kernels::wei_levoy::random_texels::{random_texels, texels_to_level_zero};
use crate::stage::memory::{InputSizes, MemoryEstimate};
use crate::stage::{Datum, Stage, StageCtx};
use crate::world::*;
use bevy_ecs::prelude::*;
use bevy_ecs::schedule::ScheduleConfigs;
use bevy_ecs::system::ScheduleSystem;
use serde::{Deserialize, Serialize};

/// Settings of `init_colours` (none yet).
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct InitColoursSettings {}

impl StageSettings for InitColoursSettings {
    const PARAMS: &'static [ParamDoc] = &[];
}

/// Random exemplar texels for `count` vertices as components
/// ([`random_texels`]).
fn random_components(
    exemplar: &crate::image::Image,
    count: usize,
    seed: u64,
) -> (VertexColours, SourceTexels) {
    let (values, texels) = random_texels(exemplar, count, seed);
    let colours = VertexColours {
        channels: exemplar.channels as usize,
        values,
    };
    (colours, SourceTexels(texels))
}

/// The `init_colours` stage.
pub struct InitColours;

impl Stage for InitColours {
    const KIND: &'static str = "init_colours";
    const SUMMARY: &'static str = "every vertex takes a random exemplar texel's colour";
    const PAPER: &'static str = "Wei & Levoy 2001 §3.1";
    type Settings = InitColoursSettings;

    /// The colours and source texels of every level, about 28 bytes a
    /// vertex of the finest level, and the exemplar's Gaussian pyramid,
    /// about 32 bytes an exemplar pixel (measured:
    /// `tests/memory_estimates.rs`).
    fn memory_estimate(_settings: &Self::Settings, sizes: &InputSizes) -> Vec<MemoryEstimate> {
        const PER_VERTEX: u64 = 28;
        MemoryEstimate::per_vertex(
            "the colours of every level and the exemplar pyramid",
            sizes,
            sizes.exemplar_pixels() * 32,
            PER_VERTEX,
        )
    }
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
                let (colours, mut texels) = random_components(
                    &images[l],
                    geometry.0.vertex_count(),
                    seed.derive(ctx.index, l as u64),
                );
                // Texels in pixels of the exemplar itself (level 0).
                texels_to_level_zero(&mut texels.0, l);
                commands.entity(e).insert((colours, texels));
            }
            if !pyramid.contains(&active.0) {
                let Ok(geometry) = meshes.get(active.0) else {
                    return;
                };
                let (colours, texels) = random_components(
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
