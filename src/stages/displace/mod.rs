//! Stage `displace`: the height map follows the synthesis and displaces the
//! mesh (issue 7; the displacement examples of Bangay & Morkel 2006 §4, the
//! luggage and donkey of Fig. 10c,f, and the mannequin of Wei & Levoy 2001
//! Fig. 9).
//!
//! Each vertex of the active mesh moves along its area-weighted unit normal
//! by `amplitude · (h − h̄)`, where `h` is `[input] height_map` sampled
//! (bilinear, the exemplar's wrap) at the exemplar coordinate the vertex's
//! colour came from and `h̄` is the map's mean, so the surface keeps its
//! average position. The coordinate is the vertex's `SourceTexels` (written
//! by `init_colours`, `match`, `graph_match`, `jump_surface`) or, for a
//! per-corner texture result (`jump_surface`), the mean height over the
//! vertex's corners' `CornerUvs`. Colours, frames and texture coordinates are
//! kept. With `smoothing > 0` the sampled heights are first averaged over
//! one-rings (texel-scale speckle and seams between matched patches would
//! otherwise read as spikes). The loaded source mesh is never modified: when it is the active mesh
//! the stage displaces a copy, which becomes the active mesh.
//!
//! Reads: `ExemplarChannels` (the height map), `ActiveMesh` (`Geometry`,
//! `SourceTexels`, `CornerUvs`), `TexelSpacing`. Writes: `Geometry` of the
//! active mesh (or of its copy, which becomes `ActiveMesh`), metrics. The
//! work is [`crate::kernels::atlas::channels::displace_by_height_with_progress`].

use crate::config::params::{ParamDoc, ParamRange, StageSettings};
use crate::kernels::atlas::channels::{
    Displaced, HeightCoordinates as ChannelCoordinates, displace_by_height_with_progress,
    displace_progress_steps,
};
use crate::progress::Progress;
use crate::stage::memory::{InputSizes, MemoryEstimate};
use crate::stage::{Datum, Stage, StageCtx, SystemResult};
use crate::world::*;
use bevy_ecs::prelude::*;
use bevy_ecs::schedule::ScheduleConfigs;
use bevy_ecs::system::ScheduleSystem;
use serde::{Deserialize, Serialize};

/// Which recorded exemplar coordinates address the height map.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum HeightCoordinates {
    /// `CornerUvs` when the active mesh has them (what the result shows),
    /// otherwise `SourceTexels`.
    #[default]
    Auto,
    /// The per-vertex `SourceTexels`.
    SourceTexels,
    /// The per-corner `CornerUvs`, averaged per vertex.
    CornerUvs,
}

impl HeightCoordinates {
    fn name(self) -> &'static str {
        match self {
            Self::Auto => "auto",
            Self::SourceTexels => "source_texels",
            Self::CornerUvs => "corner_uvs",
        }
    }
}

/// Unit of `displace.amplitude`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AmplitudeUnit {
    /// World units per exemplar pixel at the scale the result was
    /// synthesised (so relief keeps its proportion to the texture on a mesh
    /// of any size).
    #[default]
    Texels,
    /// World (model) units.
    World,
}

/// Settings of `displace`.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DisplaceSettings {
    /// Displacement per unit of height, in `amplitude_unit`.
    pub amplitude: f64,
    /// Unit of `amplitude`.
    pub amplitude_unit: AmplitudeUnit,
    /// Which recorded coordinates address the height map.
    pub coordinates: HeightCoordinates,
    /// Passes of one-ring averaging of the sampled heights.
    pub smoothing: u32,
}

impl Default for DisplaceSettings {
    fn default() -> Self {
        Self {
            amplitude: 4.0,
            amplitude_unit: AmplitudeUnit::Texels,
            coordinates: HeightCoordinates::Auto,
            smoothing: 0,
        }
    }
}

impl StageSettings for DisplaceSettings {
    const PARAMS: &'static [ParamDoc] = &[
        ParamDoc {
            name: "amplitude",
            unit: "amplitude_unit",
            range: ParamRange::Float(-1000.0, 1000.0),
            doc: "offset along the normal per unit of height above the map's mean (negative carves in); a few texel spacings reads as relief (default 4 texels)",
        },
        ParamDoc {
            name: "amplitude_unit",
            unit: "",
            range: ParamRange::OneOf(&["texels", "world"]),
            doc: "unit of amplitude: texels = world units per exemplar pixel at the scale the result was synthesised (scale-free), world = model units",
        },
        ParamDoc {
            name: "coordinates",
            unit: "",
            range: ParamRange::OneOf(&["auto", "source_texels", "corner_uvs"]),
            doc: "exemplar coordinates that address the height map: auto = per-corner UVs when the result has them, else per-vertex source texels",
        },
        ParamDoc {
            name: "smoothing",
            unit: "passes",
            range: ParamRange::Int(0, 100),
            doc: "one-ring averaging passes over the sampled heights before displacing; removes spikes from texel-scale speckle and patch seams",
        },
    ];
}

/// The `displace` stage.
pub struct Displace;

type ActiveQuery<'w, 's> = Query<
    'w,
    's,
    (
        &'static Geometry,
        Option<&'static SourceTexels>,
        Option<&'static CornerUvs>,
        Has<SourceMesh>,
    ),
>;

impl Stage for Displace {
    const KIND: &'static str = "displace";
    const SUMMARY: &'static str = "moves vertices along their normals by the height map at their recorded exemplar coordinates";
    const PAPER: &'static str =
        "Bangay & Morkel 2006 §4, Fig. 10c,f; Wei & Levoy 2001 Fig. 9 (displacement)";
    type Settings = DisplaceSettings;

    /// The sampled and smoothed heights, the normals and the displaced copy
    /// of the geometry, about 240 bytes a vertex (measured:
    /// `tests/memory_estimates.rs`).
    fn memory_estimate(_settings: &Self::Settings, sizes: &InputSizes) -> Vec<MemoryEstimate> {
        const PER_VERTEX: u64 = 240;
        MemoryEstimate::per_vertex(
            "the heights, normals and displaced positions",
            sizes,
            0,
            PER_VERTEX,
        )
    }
    fn requires(_: &Self::Settings) -> Vec<Datum> {
        vec![Datum::Mesh, Datum::HeightMap]
    }
    fn produces(_: &Self::Settings) -> Vec<Datum> {
        Vec::new()
    }
    fn plane_role(_: &Self::Settings) -> crate::stage::PlaneRole {
        crate::stage::PlaneRole::DeformsMesh
    }
    fn systems(settings: Self::Settings, ctx: StageCtx) -> ScheduleConfigs<ScheduleSystem> {
        let displace = move |mut commands: Commands,
                             mut active: ResMut<ActiveMesh>,
                             channels: Res<ExemplarChannels>,
                             spacing: Res<TexelSpacing>,
                             mut metrics: ResMut<Metrics>,
                             meshes: ActiveQuery|
              -> SystemResult {
            let height = channels.height.as_ref().ok_or(
                "no height map: set input.height_map (a file the exemplar's size, \"derive:luminance\" or \"derive:builtin\")",
            )?;
            let Ok((geometry, texels, uvs, is_source)) = meshes.get(active.0) else {
                return Err("there is no active mesh".into());
            };
            let mesh = &geometry.0;
            let coordinates = height_coordinates(mesh, texels, uvs, settings.coordinates)?;
            let progress = Progress::new(displace_progress_steps(settings.smoothing), Self::KIND);
            let _finish = progress.finish_on_drop();
            let amplitude = match settings.amplitude_unit {
                AmplitudeUnit::World => settings.amplitude as f32,
                AmplitudeUnit::Texels => settings.amplitude as f32 * spacing.0,
            };
            metrics.record(ctx.index, "amplitude_world", amplitude);
            let displaced = displace_by_height_with_progress(
                mesh,
                height,
                channels.wrap,
                coordinates,
                settings.smoothing,
                amplitude,
                &progress,
            );
            progress.finish();
            record_metrics(&mut metrics, ctx.index, &settings, coordinates, &displaced);
            let mut mesh = mesh.clone();
            mesh.positions = displaced.positions;
            if is_source {
                // The loaded mesh stays as loaded: displace a copy (with every
                // cloneable attribute) and make it the active mesh.
                let copy = commands
                    .entity(active.0)
                    .clone_and_spawn_with_opt_out(|b| {
                        b.deny::<SourceMesh>();
                    })
                    .insert(Geometry(mesh))
                    .id();
                active.0 = copy;
            } else {
                commands.entity(active.0).insert(Geometry(mesh));
            }
            Ok(())
        };
        ctx.fallible(Self::KIND, displace)
    }
}

/// The active mesh's exemplar coordinates the heights are read at, as
/// `setting` asks: its per-corner UVs or its per-vertex source texels
/// (`auto`: the UVs where it has them); errors say which stage records
/// them.
fn height_coordinates<'a>(
    mesh: &crate::mesh::PolyMesh,
    texels: Option<&'a SourceTexels>,
    uvs: Option<&'a CornerUvs>,
    setting: HeightCoordinates,
) -> Result<ChannelCoordinates<'a>, String> {
    let texels = texels.filter(|t| t.0.len() == mesh.vertex_count());
    let uvs = uvs.filter(|u| u.0.len() == mesh.corner_count());
    let use_uvs = match setting {
        HeightCoordinates::Auto => uvs.is_some(),
        HeightCoordinates::CornerUvs => true,
        HeightCoordinates::SourceTexels => false,
    };
    if use_uvs {
        let uvs = uvs.ok_or(
            "coordinates = \"corner_uvs\" but the active mesh has no per-corner texture coordinates; run jump_surface first or use \"source_texels\"",
        )?;
        Ok(ChannelCoordinates::CornerUvs(&uvs.0))
    } else {
        let texels = texels.ok_or(
            "the active mesh has no recorded exemplar coordinates (SourceTexels); run a synthesis stage (init_colours, match, graph_match, jump_surface) before displace",
        )?;
        Ok(ChannelCoordinates::Texels(&texels.0))
    }
}

/// Records what the displacement read and did.
fn record_metrics(
    metrics: &mut Metrics,
    index: usize,
    settings: &DisplaceSettings,
    coordinates: ChannelCoordinates,
    displaced: &Displaced,
) {
    metrics.record(index, "vertices", displaced.moved.len());
    let moved = displaced.moved.iter().filter(|&&m| m).count();
    metrics.record(index, "vertices_moved", moved);
    let read = match coordinates {
        ChannelCoordinates::CornerUvs(_) => "corner_uvs",
        ChannelCoordinates::Texels(_) => "source_texels",
    };
    metrics.record(index, "coordinates", read);
    metrics.record(index, "coordinates_setting", settings.coordinates.name());
    metrics.record(index, "height_mean", displaced.mean);
    metrics.record(index, "max_offset", displaced.max_offset);
}
