//! Stage `orientation`: tangent frames on the active mesh from a global
//! direction projected onto each tangent plane, or random per vertex
//! (Wei & Levoy 2001 §3.1 "user field" and isotropic modes).

use crate::config::params::{ParamDoc, ParamRange, StageSettings};
use crate::kernels::frames::{frames_from_global_direction, frames_with_angles};
use crate::pipeline::{Datum, Stage, StageCtx};
use crate::stages::world::*;
use bevy_ecs::prelude::*;
use bevy_ecs::schedule::ScheduleConfigs;
use bevy_ecs::system::ScheduleSystem;
use serde::{Deserialize, Serialize};

/// How the frames are chosen.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum OrientationMode {
    /// `direction` projected onto each tangent plane.
    #[default]
    Global,
    /// A uniformly random direction per vertex (isotropic textures).
    Random,
}

/// Settings of `orientation`.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct OrientationSettings {
    /// Global mode or random mode.
    pub mode: OrientationMode,
    /// The texture's x axis in world space, projected per vertex.
    pub direction: [f32; 3],
    /// Extra rotation of every frame about its normal, degrees.
    pub angle: f32,
}

impl Default for OrientationSettings {
    fn default() -> Self {
        Self {
            mode: OrientationMode::Global,
            direction: [1.0, 0.0, 0.0],
            angle: 0.0,
        }
    }
}

impl StageSettings for OrientationSettings {
    const PARAMS: &'static [ParamDoc] = &[
        ParamDoc {
            name: "mode",
            unit: "",
            range: ParamRange::OneOf(&["global", "random"]),
            doc: "global: `direction` projected onto each tangent plane; random: a random direction per vertex (isotropic textures)",
        },
        ParamDoc {
            name: "direction",
            unit: "world axes",
            range: ParamRange::Float(-1e6, 1e6),
            doc: "texture x axis in world space (any non-zero length); where it is parallel to the normal a perpendicular is used",
        },
        ParamDoc {
            name: "angle",
            unit: "degrees",
            range: ParamRange::Float(-360.0, 360.0),
            doc: "rotation of every frame about its normal",
        },
    ];

    fn check(&self) -> Result<(), (String, String)> {
        let d = glam::Vec3::from(self.direction);
        if self.mode == OrientationMode::Global && d.length_squared() < 1e-12 {
            return Err((
                "direction".into(),
                "must not be the zero vector in global mode".into(),
            ));
        }
        Ok(())
    }
}

/// The `orientation` stage.
pub struct Orientation;

impl Stage for Orientation {
    const KIND: &'static str = "orientation";
    const SUMMARY: &'static str =
        "tangent frames: a global direction projected onto the surface, or random per vertex";
    const PAPER: &'static str = "Wei & Levoy 2001 §3.1; Praun et al. 2000 §3.2";
    type Settings = OrientationSettings;

    fn requires(_: &Self::Settings) -> Vec<Datum> {
        vec![]
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
            let normals = geometry.0.vertex_normals();
            let rotation = settings.angle.to_radians();
            let frames = match settings.mode {
                OrientationMode::Global => {
                    let mut f = frames_from_global_direction(&normals, settings.direction.into());
                    if rotation != 0.0 {
                        f.iter_mut().for_each(|fr| *fr = fr.rotated(rotation));
                    }
                    f
                }
                OrientationMode::Random => {
                    let base = seed.derive(ctx.index, 0);
                    frames_with_angles(&normals, |v| {
                        let r = mix(base, v as u64, 0);
                        (r >> 40) as f32 / (1u64 << 24) as f32 * std::f32::consts::TAU
                    })
                }
            };
            commands.entity(active.0).insert(Frames(frames));
        })
        .into_configs()
    }
}
