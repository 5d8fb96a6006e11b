//! Stage `orientation`: tangent frames (s = texture right, t = texture up) on
//! the active mesh. Modes: a global up direction projected onto each tangent
//! plane (Wei & Levoy 2001 §3.1 user field; Praun et al. 2000 §3.2), random
//! per vertex (isotropic textures), or a field interpolated from anchor
//! vectors plus sources and sinks (Zelinka & Garland 2004 §6.1); all with a
//! global rotation angle.
//!
//! Anchor and singularity positions are world points (`at`) or fractions of
//! the active mesh's bounding box (`at_bbox`, [`crate::stages::position`]).
//! In field mode, a connected component that no anchor is on gets one
//! automatic anchor (`kernels::surface::orientation_field::up_field_with_fallback`:
//! at its vertex nearest its centroid, `up` projected there), since the
//! anchors blend by edge-path distance and never reach it; metric
//! `fallback_components`. Singularities act through space and reach every
//! component.
//!
//! Reads: `ActiveMesh` geometry, `RunSeed`. Writes: `Frames` on the active
//! mesh, metrics.

use crate::config::params::{ParamDoc, ParamRange, StageSettings};
use crate::kernels::surface::frames::{
    TangentFrame, frames_from_global_direction, frames_with_angles,
};
use crate::kernels::surface::orientation_field::{Anchor, Singularity, up_field_with_fallback};
use crate::mesh::Topology;
use crate::stage::memory::{InputSizes, MemoryEstimate};
use crate::stage::{Datum, Stage, StageCtx, SystemResult};
use crate::stages::position;
use crate::world::*;
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

/// An anchor in the config: `{ at = [x, y, z], up = [x, y, z] }` or
/// `{ at_bbox = [u, v, w], up = [x, y, z] }` (exactly one of `at` and
/// `at_bbox`).
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AnchorSpec {
    /// World position; the nearest vertex takes the anchor.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub at: Option<[f32; 3]>,
    /// Position as fractions `[0, 1]` of the active mesh's bounding box
    /// (0 = minimum, 1 = maximum); the nearest vertex takes the anchor.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub at_bbox: Option<[f32; 3]>,
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

/// A singularity in the config: `{ at = [x, y, z], kind = "source", strength = 1.0 }`
/// (or `at_bbox = [u, v, w]` instead of `at`).
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SingularitySpec {
    /// World position.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub at: Option<[f32; 3]>,
    /// Position as fractions `[0, 1]` of the active mesh's bounding box.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub at_bbox: Option<[f32; 3]>,
    /// Source or sink.
    pub kind: SingularityKind,
    /// Relative strength (default 1): at a distance of `strength` bounding-box
    /// diagonals its pull equals one anchor's.
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
    /// The texture's up direction in world space (global mode, the
    /// automatic anchor of a component without one, and the fallback
    /// where a field vanishes).
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
            doc: "texture up direction in world space (non-zero); where it is parallel to the normal a perpendicular is used; field mode: the direction of the automatic anchor each connected component without an anchor gets (at its vertex nearest its centroid; metric `fallback_components`)",
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
            range: ParamRange::Any(
                "list of { at = [x, y, z] | at_bbox = [u, v, w], up = [x, y, z] }",
            ),
            doc: "field mode: up vectors at points (world coordinates `at`, or `at_bbox` = fractions 0..1 of the mesh's bounding box, 0 = min, 1 = max; the nearest vertex takes it), blended by inverse squared edge-path distance; a component no anchor is on gets an automatic one",
        },
        ParamDoc {
            name: "singularities",
            unit: "",
            range: ParamRange::Any(
                "list of { at = [x, y, z] | at_bbox = [u, v, w], kind = \"source\" | \"sink\", strength = 1.0 }",
            ),
            doc: "field mode: points (world `at` or bounding-box fractions `at_bbox`) the up field flows out of (source) or into (sink); the pull falls off as 1 / distance and equals one anchor's at `strength` bounding-box diagonals",
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
        for (i, a) in self.anchors.iter().enumerate() {
            let what = format!("anchor {}", i + 1);
            check_position(a.at, a.at_bbox)
                .map_err(|m| ("anchors".to_string(), format!("{what}: {m}")))?;
            if Vec3::from(a.up).length_squared() < 1e-12 {
                return Err((
                    "anchors".into(),
                    format!(
                        "{what} ({}) has a zero `up` vector",
                        position::describe(a.at, a.at_bbox)
                    ),
                ));
            }
        }
        for (i, s) in self.singularities.iter().enumerate() {
            let what = format!("singularity {}", i + 1);
            check_position(s.at, s.at_bbox)
                .map_err(|m| ("singularities".to_string(), format!("{what}: {m}")))?;
            if !s.strength.is_finite() {
                return Err((
                    "singularities".into(),
                    format!("{what}: `strength` = {} must be finite", s.strength),
                ));
            }
        }
        Ok(())
    }
}

/// Exactly one of `at` and `at_bbox`, each valid ([`position::check`]).
fn check_position(at: Option<[f32; 3]>, at_bbox: Option<[f32; 3]>) -> Result<(), String> {
    position::check(at, at_bbox)?;
    if at.is_none() && at_bbox.is_none() {
        return Err("give `at = [x, y, z]` or `at_bbox = [u, v, w]`".into());
    }
    Ok(())
}

/// The world point of a spec's `at` / `at_bbox` on a mesh with bounding
/// box `bbox`.
fn point(
    at: Option<[f32; 3]>,
    at_bbox: Option<[f32; 3]>,
    bbox: Option<(Vec3, Vec3)>,
) -> Result<Vec3, String> {
    position::resolve(at, at_bbox, bbox)?
        .ok_or_else(|| "give `at = [x, y, z]` or `at_bbox = [u, v, w]`".into())
}

/// The frames of [`orientation_frames`] and what it did.
#[derive(Clone, Debug)]
pub struct OrientationResult {
    /// One frame per vertex.
    pub frames: Vec<TangentFrame>,
    /// Field mode: connected components that got an automatic anchor.
    pub fallback_components: usize,
}

/// Computes the frames of `settings` for a mesh.
///
/// # Errors
/// A message naming the anchor or singularity whose position cannot be
/// resolved (`at_bbox` on a mesh without vertices).
pub fn orientation_frames(
    mesh: &crate::mesh::PolyMesh,
    settings: &OrientationSettings,
    seed: u64,
) -> Result<OrientationResult, String> {
    let mut fallback_components = 0;
    let normals = mesh.vertex_normals();
    let up = Vec3::from(settings.up);
    let mut frames = match settings.mode {
        OrientationMode::Global => frames_from_global_direction(&normals, up),
        OrientationMode::Random => frames_with_angles(&normals, |v| {
            let r = mix(seed, v as u64, 0);
            (r >> 40) as f32 / (1u64 << 24) as f32 * std::f32::consts::TAU
        }),
        OrientationMode::Field => {
            let (anchors, singularities) = field_points(settings, mesh.bounding_box())?;
            let topo = Topology::build(mesh);
            let (frames, fallback) = up_field_with_fallback(
                &mesh.positions,
                &normals,
                &topo,
                &anchors,
                &singularities,
                up,
            );
            fallback_components = fallback;
            frames
        }
    };
    let rotation = settings.angle.to_radians();
    if rotation != 0.0 {
        frames.iter_mut().for_each(|f| *f = f.rotated(rotation));
    }
    Ok(OrientationResult {
        frames,
        fallback_components,
    })
}

/// The anchors and singularities of `settings` at their world points on a
/// mesh with bounding box `bbox`; errors name the entry.
fn field_points(
    settings: &OrientationSettings,
    bbox: Option<(Vec3, Vec3)>,
) -> Result<(Vec<Anchor>, Vec<Singularity>), String> {
    let mut anchors = Vec::with_capacity(settings.anchors.len());
    for (i, a) in settings.anchors.iter().enumerate() {
        anchors.push(Anchor {
            at: point(a.at, a.at_bbox, bbox)
                .map_err(|m| format!("anchors: anchor {}: {m}", i + 1))?,
            up: a.up.into(),
        });
    }
    let mut singularities = Vec::with_capacity(settings.singularities.len());
    for (i, s) in settings.singularities.iter().enumerate() {
        singularities.push(Singularity {
            at: point(s.at, s.at_bbox, bbox)
                .map_err(|m| format!("singularities: singularity {}: {m}", i + 1))?,
            sign: if s.kind == SingularityKind::Source {
                1.0
            } else {
                -1.0
            },
            strength: s.strength,
        });
    }
    Ok((anchors, singularities))
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

    /// The tangent frames, about 48 bytes a vertex, and in field mode the
    /// edge graph and the anchors' path distances over it, about 205
    /// (measured: `tests/memory_estimates.rs`).
    fn memory_estimate(settings: &Self::Settings, sizes: &InputSizes) -> Vec<MemoryEstimate> {
        let per_vertex = match settings.mode {
            OrientationMode::Field => 205,
            OrientationMode::Global | OrientationMode::Random => 48,
        };
        MemoryEstimate::per_vertex("the tangent frames of every vertex", sizes, 0, per_vertex)
    }
    fn requires(_: &Self::Settings) -> Vec<Datum> {
        vec![Datum::Mesh]
    }
    fn produces(_: &Self::Settings) -> Vec<Datum> {
        vec![Datum::Frames]
    }
    fn systems(settings: Self::Settings, ctx: StageCtx) -> ScheduleConfigs<ScheduleSystem> {
        let orient = move |mut commands: Commands,
                           active: Res<ActiveMesh>,
                           seed: Res<RunSeed>,
                           mut metrics: ResMut<Metrics>,
                           meshes: Query<&Geometry>|
              -> SystemResult {
            let Ok(geometry) = meshes.get(active.0) else {
                return Ok(());
            };
            let result = orientation_frames(&geometry.0, &settings, seed.derive(ctx.index, 0))?;
            if settings.mode == OrientationMode::Field {
                metrics.record(ctx.index, "fallback_components", result.fallback_components);
            }
            commands.entity(active.0).insert(Frames(result.frames));
            Ok(())
        };
        ctx.fallible(Self::KIND, orient)
    }
}
