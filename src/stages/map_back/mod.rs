//! Stage `map_back`: maps the result synthesised on a retiled (or
//! subdivided) surface back onto the ORIGINAL input mesh (Wei & Levoy 2001
//! §5: "mapped back onto the original model in a post-process by
//! resampling"). Each vertex of the `SourceMesh` entity takes the closest
//! point of the result surface (the active mesh) and interpolates its vertex
//! colours barycentrically; it also takes the matched exemplar texel
//! (`SourceTexels`) and the tangent frame (`Frames`, turned into its own
//! tangent plane) of that triangle's corner with the largest weight. The
//! components go onto the source entity; the active mesh does not change.
//! `export` then also writes `<name>_original.ply` (format `ply`) and
//! `original_preview_*.png` (format `preview`).
//!
//! Reads: `ActiveMesh` (`Geometry`, `VertexColours`, `SourceTexels`,
//! `Frames`), the `SourceMesh` geometry, `TexelSpacing`. Writes:
//! `VertexColours`, `SourceTexels` and `Frames` on the `SourceMesh`
//! entity, metrics.

use crate::config::params::{ParamDoc, StageSettings};
use crate::kernels::wei_levoy::retile::{ResultAttributes, map_back_with_progress};
use crate::progress::Progress;
use crate::stage::memory::{InputSizes, MemoryEstimate};
use crate::stage::{Datum, Stage, StageCtx, SystemResult};
use crate::world::*;
use bevy_ecs::prelude::*;
use bevy_ecs::schedule::ScheduleConfigs;
use bevy_ecs::system::ScheduleSystem;
use serde::{Deserialize, Serialize};

/// Settings of `map_back` (none).
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MapBackSettings {}

impl StageSettings for MapBackSettings {
    const PARAMS: &'static [ParamDoc] = &[];
}

type ResultQuery<'w, 's> = Query<
    'w,
    's,
    (
        &'static Geometry,
        Option<&'static VertexColours>,
        Option<&'static SourceTexels>,
        Option<&'static Frames>,
    ),
>;

/// The `map_back` stage.
pub struct MapBack;

impl Stage for MapBack {
    const KIND: &'static str = "map_back";
    const SUMMARY: &'static str = "maps the result's colours, matched texels and frames back onto the original input mesh by closest-point resampling";
    const PAPER: &'static str = "Wei & Levoy 2001 §5";
    type Settings = MapBackSettings;

    /// The closest-point tree over the result's triangles and the
    /// resampled attributes, about 270 bytes a vertex of the result
    /// (measured: `tests/memory_estimates.rs`).
    fn memory_estimate(_settings: &Self::Settings, sizes: &InputSizes) -> Vec<MemoryEstimate> {
        const PER_VERTEX: u64 = 270;
        MemoryEstimate::per_vertex(
            "the closest-point tree over the result",
            sizes,
            0,
            PER_VERTEX,
        )
    }
    fn requires(_: &Self::Settings) -> Vec<Datum> {
        vec![Datum::Mesh, Datum::Colours]
    }
    fn produces(_: &Self::Settings) -> Vec<Datum> {
        vec![]
    }
    fn systems(_settings: Self::Settings, ctx: StageCtx) -> ScheduleConfigs<ScheduleSystem> {
        let map = move |mut commands: Commands,
                        active: Res<ActiveMesh>,
                        spacing: Res<TexelSpacing>,
                        mut metrics: ResMut<Metrics>,
                        sources: Query<Entity, With<SourceMesh>>,
                        meshes: ResultQuery|
              -> SystemResult {
            let _span = tracing::info_span!("map_back").entered();
            let source = sources
                .single()
                .map_err(|_| "there is no input mesh to map the result back onto")?;
            if source == active.0 {
                // The result already lives on the input mesh.
                metrics.record(ctx.index, "mapped", false);
                return Ok(());
            }
            let (Ok((original, ..)), Ok((result, colours, texels, frames))) =
                (meshes.get(source), meshes.get(active.0))
            else {
                return Err("the input or the result mesh is missing".into());
            };
            let colours = colours.ok_or(
                "the result has no vertex colours: put `match` (or `init_colours`) before `map_back`",
            )?;
            let attributes = ResultAttributes {
                colours: &colours.values,
                channels: colours.channels,
                texels: texels.map(|t| t.0.as_slice()),
                frames: frames.map(|f| f.0.as_slice()),
            };
            let normals = original.0.vertex_normals();
            let progress = Progress::new(0, Self::KIND);
            let _finish = progress.finish_on_drop();
            let mapped = map_back_with_progress(
                &result.0,
                &attributes,
                &original.0.positions,
                &normals,
                &progress,
            );
            progress.finish();
            let mapped = mapped.map_err(|e| e.to_string())?;
            record_distances(&mut metrics, ctx.index, &mapped.distance, spacing.0);
            let mut entity = commands.entity(source);
            entity.insert(VertexColours {
                channels: colours.channels,
                values: mapped.colours,
            });
            if let Some(t) = mapped.texels {
                entity.insert(SourceTexels(t));
            }
            if let Some(f) = mapped.frames {
                entity.insert(Frames(f));
            }
            Ok(())
        };
        ctx.fallible(Self::KIND, map)
    }
}

/// Records that the result was mapped and how far each input vertex
/// lies from the result surface: mean and largest (also in texels of
/// `spacing` world units).
fn record_distances(metrics: &mut Metrics, index: usize, distances: &[f32], spacing: f32) {
    let n = distances.len().max(1) as f64;
    let mean = distances.iter().map(|&d| d as f64).sum::<f64>() / n;
    let max = distances.iter().copied().fold(0.0f32, f32::max);
    metrics.record(index, "mapped", true);
    metrics.record(index, "vertices", distances.len());
    metrics.record(index, "mean_distance", mean);
    metrics.record(index, "max_distance", max);
    let texels = max / spacing.max(f32::MIN_POSITIVE);
    metrics.record(index, "max_distance_texels", texels);
}
