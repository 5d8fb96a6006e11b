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

use crate::config::params::{ParamDoc, ParamRange, StageSettings};
use crate::kernels::atlas::channels::{
    displace_along_normals, heights_at_corner_uvs, heights_at_texels, mean_height,
    smooth_vertex_heights_with_progress,
};
use crate::progress::Progress;
use crate::stage::{Datum, Stage, StageCtx};
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

    fn requires(_: &Self::Settings) -> Vec<Datum> {
        vec![Datum::Mesh]
    }
    fn produces(_: &Self::Settings) -> Vec<Datum> {
        Vec::new()
    }
    fn plane_role(_: &Self::Settings) -> crate::stage::PlaneRole {
        crate::stage::PlaneRole::DeformsMesh
    }
    fn systems(settings: Self::Settings, ctx: StageCtx) -> ScheduleConfigs<ScheduleSystem> {
        (move |mut commands: Commands,
               mut active: ResMut<ActiveMesh>,
               channels: Res<ExemplarChannels>,
               spacing: Res<TexelSpacing>,
               mut metrics: ResMut<Metrics>,
               mut failure: ResMut<StageFailure>,
               meshes: ActiveQuery| {
            let mut fail_with = |message: String| fail(&mut failure, ctx.index, Self::KIND, message);
            let Some(height) = channels.height.as_ref() else {
                return fail_with(
                    "no height map: set input.height_map (a file the exemplar's size, \"derive:luminance\" or \"derive:builtin\")".into(),
                );
            };
            let Ok((geometry, texels, uvs, is_source)) = meshes.get(active.0) else {
                return fail_with("there is no active mesh".into());
            };
            let mesh = &geometry.0;
            let nv = mesh.vertex_count();
            let texels = texels.filter(|t| t.0.len() == nv);
            let uvs = uvs.filter(|u| u.0.len() == mesh.corner_count());
            let use_uvs = match settings.coordinates {
                HeightCoordinates::Auto => uvs.is_some(),
                HeightCoordinates::CornerUvs => true,
                HeightCoordinates::SourceTexels => false,
            };
            // Coarse steps: sampling, the one-rings and each smoothing pass,
            // normals, displacing (seconds at a million vertices).
            let smoothing_steps = if settings.smoothing > 0 {
                1 + u64::from(settings.smoothing)
            } else {
                0
            };
            let progress = Progress::new(3 + smoothing_steps, Self::KIND);
            let _finish = progress.finish_on_drop();
            progress.set_part("heights");
            let (mut heights, moved) = if use_uvs {
                let Some(uvs) = uvs else {
                    return fail_with(
                        "coordinates = \"corner_uvs\" but the active mesh has no per-corner texture coordinates; run jump_surface first or use \"source_texels\"".into(),
                    );
                };
                heights_at_corner_uvs(height, channels.wrap, nv, &mesh.corner_vertex, &uvs.0)
            } else {
                let Some(texels) = texels else {
                    return fail_with(
                        "the active mesh has no recorded exemplar coordinates (SourceTexels); run a synthesis stage (init_colours, match, graph_match, jump_surface) before displace".into(),
                    );
                };
                (heights_at_texels(height, channels.wrap, &texels.0), vec![true; nv])
            };
            progress.inc(1);
            if settings.smoothing > 0 {
                progress.set_part("smoothing");
                let topo = crate::mesh::Topology::build(mesh);
                progress.inc(1);
                smooth_vertex_heights_with_progress(
                    &topo,
                    &mut heights,
                    &moved,
                    settings.smoothing,
                    &progress,
                );
            }
            progress.set_part("normals");
            let mean = mean_height(height);
            let normals = mesh.vertex_normals();
            progress.inc(1);
            progress.set_part("displacing");
            let amplitude = match settings.amplitude_unit {
                AmplitudeUnit::World => settings.amplitude as f32,
                AmplitudeUnit::Texels => settings.amplitude as f32 * spacing.0,
            };
            metrics.record(ctx.index, "amplitude_world", amplitude);
            let positions =
                displace_along_normals(&mesh.positions, &normals, &heights, &moved, mean, amplitude);
            let max_offset = mesh
                .positions
                .iter()
                .zip(&positions)
                .map(|(a, b)| (*a - *b).length())
                .fold(0.0f32, f32::max);
            let mut displaced = mesh.clone();
            displaced.positions = positions;
            progress.inc(1);
            progress.finish();
            metrics.record(ctx.index, "vertices", nv);
            metrics.record(ctx.index, "vertices_moved", moved.iter().filter(|&&m| m).count());
            metrics.record(
                ctx.index,
                "coordinates",
                if use_uvs { "corner_uvs" } else { "source_texels" },
            );
            metrics.record(ctx.index, "coordinates_setting", settings.coordinates.name());
            metrics.record(ctx.index, "height_mean", mean);
            metrics.record(ctx.index, "max_offset", max_offset);
            if is_source {
                // The loaded mesh stays as loaded: displace a copy (with every
                // cloneable attribute) and make it the active mesh.
                let copy = commands
                    .entity(active.0)
                    .clone_and_spawn_with_opt_out(|b| {
                        b.deny::<SourceMesh>();
                    })
                    .insert(Geometry(displaced))
                    .id();
                active.0 = copy;
            } else {
                commands.entity(active.0).insert(Geometry(displaced));
            }
        })
        .into_configs()
    }
}
