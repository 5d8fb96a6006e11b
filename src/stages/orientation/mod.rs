//! Stage `orientation`: tangent frames (s = texture right, t = texture up) on
//! the active mesh. Modes: a global up direction projected onto each tangent
//! plane (Wei & Levoy 2001 §3.1 user field; Praun et al. 2000 §3.2), random
//! per vertex (isotropic textures), or a field interpolated from anchor
//! vectors plus sources and sinks (Zelinka & Garland 2004 §6.1); all with a
//! global rotation angle.

use crate::config::params::{ParamDoc, ParamRange, StageSettings};
use crate::kernels::frames::{TangentFrame, frames_from_global_direction, frames_with_angles};
use crate::kernels::orientation_field::{Anchor, Singularity, up_field};
use crate::mesh::Topology;
use crate::pipeline::{Datum, Stage, StageCtx};
use crate::stages::world::*;
use bevy_ecs::prelude::*;
use bevy_ecs::schedule::ScheduleConfigs;
use bevy_ecs::system::ScheduleSystem;
use glam::Vec3;
use serde::{Deserialize, Serialize};

/// How the frames are chosen.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum OrientationMode {
    /// `up` projected onto each tangent plane.
    #[default]
    Global,
    /// A uniformly random direction per vertex (isotropic textures).
    Random,
    /// Interpolated `anchors` plus `singularities`.
    Field,
}

/// An anchor in the config: `{ at = [x, y, z], up = [x, y, z] }`.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AnchorSpec {
    /// World position; the nearest vertex takes the anchor.
    pub at: [f32; 3],
    /// Texture up direction there.
    pub up: [f32; 3],
}

/// Whether a singularity is a source or a sink.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SingularityKind {
    /// The up direction points away from it.
    Source,
    /// The up direction points toward it.
    Sink,
}

/// A singularity in the config: `{ at = [x, y, z], kind = "source", strength = 1.0 }`.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SingularitySpec {
    /// World position.
    pub at: [f32; 3],
    /// Source or sink.
    pub kind: SingularityKind,
    /// Relative strength (default 1).
    #[serde(default = "one")]
    pub strength: f32,
}

fn one() -> f32 {
    1.0
}

/// Settings of `orientation`.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct OrientationSettings {
    /// Global, random or field.
    pub mode: OrientationMode,
    /// The texture's up direction in world space (global mode, and the
    /// fallback where a field vanishes).
    pub up: [f32; 3],
    /// Extra rotation of every frame about its normal, degrees.
    pub angle: f32,
    /// Field mode: anchor vectors to interpolate.
    pub anchors: Vec<AnchorSpec>,
    /// Field mode: sources and sinks.
    pub singularities: Vec<SingularitySpec>,
}

impl Default for OrientationSettings {
    fn default() -> Self {
        Self {
            mode: OrientationMode::Global,
            up: [0.0, 1.0, 0.0],
            angle: 0.0,
            anchors: Vec::new(),
            singularities: Vec::new(),
        }
    }
}

impl StageSettings for OrientationSettings {
    const PARAMS: &'static [ParamDoc] = &[
        ParamDoc {
            name: "mode",
            unit: "",
            range: ParamRange::OneOf(&["global", "random", "field"]),
            doc: "global: `up` projected onto each tangent plane; random: a random direction per vertex (isotropic textures); field: interpolated `anchors` plus `singularities`",
        },
        ParamDoc {
            name: "up",
            unit: "world axes",
            range: ParamRange::Float(-1e6, 1e6),
            doc: "texture up direction in world space (non-zero); where it is parallel to the normal a perpendicular is used",
        },
        ParamDoc {
            name: "angle",
            unit: "degrees",
            range: ParamRange::Float(-360.0, 360.0),
            doc: "rotation of every frame about its normal (Zelinka & Garland Fig. 11)",
        },
        ParamDoc {
            name: "anchors",
            unit: "",
            range: ParamRange::Any("list of { at = [x, y, z], up = [x, y, z] }"),
            doc: "field mode: up vectors at points, blended by inverse squared edge-path distance",
        },
        ParamDoc {
            name: "singularities",
            unit: "",
            range: ParamRange::Any(
                "list of { at = [x, y, z], kind = \"source\" | \"sink\", strength = 1.0 }",
            ),
            doc: "field mode: points the up field flows out of (source) or into (sink)",
        },
    ];

    fn check(&self) -> Result<(), (String, String)> {
        if Vec3::from(self.up).length_squared() < 1e-12 {
            return Err(("up".into(), "must not be the zero vector".into()));
        }
        if self.mode == OrientationMode::Field
            && self.anchors.is_empty()
            && self.singularities.is_empty()
        {
            return Err((
                "mode".into(),
                "field mode needs at least one entry in `anchors` or `singularities`".into(),
            ));
        }
        if let Some(a) = self
            .anchors
            .iter()
            .find(|a| Vec3::from(a.up).length_squared() < 1e-12)
        {
            return Err((
                "anchors".into(),
                format!("anchor at {:?} has a zero `up` vector", a.at),
            ));
        }
        Ok(())
    }
}

/// Computes the frames of `settings` for a mesh.
pub fn orientation_frames(
    mesh: &crate::mesh::PolyMesh,
    settings: &OrientationSettings,
    seed: u64,
) -> Vec<TangentFrame> {
    let normals = mesh.vertex_normals();
    let up = Vec3::from(settings.up);
    let mut frames = match settings.mode {
        OrientationMode::Global => frames_from_global_direction(&normals, up),
        OrientationMode::Random => frames_with_angles(&normals, |v| {
            let r = mix(seed, v as u64, 0);
            (r >> 40) as f32 / (1u64 << 24) as f32 * std::f32::consts::TAU
        }),
        OrientationMode::Field => {
            let topo = Topology::build(mesh);
            let anchors: Vec<Anchor> = settings
                .anchors
                .iter()
                .map(|a| Anchor {
                    at: a.at.into(),
                    up: a.up.into(),
                })
                .collect();
            let singularities: Vec<Singularity> = settings
                .singularities
                .iter()
                .map(|s| Singularity {
                    at: s.at.into(),
                    sign: if s.kind == SingularityKind::Source {
                        1.0
                    } else {
                        -1.0
                    },
                    strength: s.strength,
                })
                .collect();
            up_field(
                &mesh.positions,
                &normals,
                &topo,
                &anchors,
                &singularities,
                up,
            )
        }
    };
    let rotation = settings.angle.to_radians();
    if rotation != 0.0 {
        frames.iter_mut().for_each(|f| *f = f.rotated(rotation));
    }
    frames
}

/// The `orientation` stage.
pub struct Orientation;

impl Stage for Orientation {
    const KIND: &'static str = "orientation";
    const SUMMARY: &'static str =
        "tangent frames: global up, random, or a field from anchors, sources and sinks";
    const PAPER: &'static str =
        "Wei & Levoy 2001 §3.1; Zelinka & Garland 2004 §6.1; Praun et al. 2000 §3.2";
    type Settings = OrientationSettings;

    fn requires(_: &Self::Settings) -> Vec<Datum> {
        vec![Datum::Mesh]
    }
    fn produces(_: &Self::Settings) -> Vec<Datum> {
        vec![Datum::Frames]
    }
    fn systems(settings: Self::Settings, ctx: StageCtx) -> ScheduleConfigs<ScheduleSystem> {
        (move |mut commands: Commands,
               active: Res<ActiveMesh>,
               seed: Res<RunSeed>,
               meshes: Query<&Geometry>| {
            let Ok(geometry) = meshes.get(active.0) else {
                return;
            };
            let frames = orientation_frames(&geometry.0, &settings, seed.derive(ctx.index, 0));
            commands.entity(active.0).insert(Frames(frames));
        })
        .into_configs()
    }
}
