//! Stage `relax_orientation`: tangent frames on every level of the mesh
//! pyramid (Wei & Levoy 2001 §3.1, Fig. 3): random, a user direction, or
//! relaxation towards n-way symmetry, coarse to fine. Records the energy
//! after every iteration.

use crate::config::params::{ParamDoc, ParamRange, StageSettings};
use crate::kernels::surface::flatten::TriangleAdjacency;
use crate::kernels::wei_levoy::relax_orientation::{
    OrientationLevel, OrientationMode, RelaxSettings, relax_orientation_with_progress,
};
use crate::mesh::Topology;
use crate::progress::Progress;
use crate::stage::memory::{InputSizes, MemoryEstimate};
use crate::stage::{Datum, Stage, StageCtx, SystemResult};
use crate::world::*;
use bevy_ecs::prelude::*;
use bevy_ecs::schedule::ScheduleConfigs;
use bevy_ecs::system::ScheduleSystem;
use glam::Vec3;
use serde::{Deserialize, Serialize};

/// How directions are chosen.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RelaxMode {
    /// Random on the coarsest level, interpolated and relaxed on finer ones.
    #[default]
    Relax,
    /// A random direction per vertex on every level (isotropic textures).
    Random,
    /// `up` projected onto every tangent plane (a user field).
    User,
}

/// Settings of `relax_orientation`.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RelaxOrientationSettings {
    /// Relax, random or user.
    pub mode: RelaxMode,
    /// Rotational symmetry of the texture: 1, 2 or 4.
    pub symmetry: u32,
    /// Relaxation sweeps per level.
    pub iterations: u32,
    /// User mode: the texture's up direction in world space.
    pub up: [f32; 3],
}

impl Default for RelaxOrientationSettings {
    fn default() -> Self {
        Self {
            mode: RelaxMode::Relax,
            symmetry: 4,
            iterations: 30,
            up: [0.0, 1.0, 0.0],
        }
    }
}

impl StageSettings for RelaxOrientationSettings {
    const PARAMS: &'static [ParamDoc] = &[
        ParamDoc {
            name: "mode",
            unit: "",
            range: ParamRange::OneOf(&["relax", "random", "user"]),
            doc: "relax: random on the coarsest level, then interpolated and relaxed level by level; random: random per vertex; user: `up` projected onto each tangent plane",
        },
        ParamDoc {
            name: "symmetry",
            unit: "",
            range: ParamRange::Int(1, 4),
            doc: "n-way rotational symmetry of the texture (1, 2 or 4): neighbouring s directions are aligned modulo 360/n degrees",
        },
        ParamDoc {
            name: "iterations",
            unit: "sweeps",
            range: ParamRange::Int(0, 1000),
            doc: "relaxation sweeps per pyramid level (the paper uses 30)",
        },
        ParamDoc {
            name: "up",
            unit: "world axes",
            range: ParamRange::Float(-1e6, 1e6),
            doc: "user mode: the texture's up direction (non-zero)",
        },
    ];

    fn check(&self) -> Result<(), (String, String)> {
        if self.symmetry == 3 {
            return Err((
                "symmetry".into(),
                "3 is not allowed; allowed: 1, 2 or 4".into(),
            ));
        }
        if Vec3::from(self.up).length_squared() < 1e-12 {
            return Err(("up".into(), "must not be the zero vector".into()));
        }
        Ok(())
    }
}

/// The `relax_orientation` stage.
pub struct RelaxOrientation;

type LevelQuery<'w, 's> =
    Query<'w, 's, (Entity, &'static MeshLevel, Has<SourceMesh>), With<Geometry>>;

impl Stage for RelaxOrientation {
    const KIND: &'static str = "relax_orientation";
    const SUMMARY: &'static str = "tangent frames on every pyramid level: random, user direction, or n-way symmetric relaxation";
    const PAPER: &'static str = "Wei & Levoy 2001 §3.1, Fig. 3";
    type Settings = RelaxOrientationSettings;

    /// The frames of every pyramid level and the relaxation's per-vertex
    /// arrays, about 600 bytes a vertex of the finest level (the coarser
    /// levels add a third; measured: `tests/memory_estimates.rs`).
    fn memory_estimate(_settings: &Self::Settings, sizes: &InputSizes) -> Vec<MemoryEstimate> {
        const PER_VERTEX: u64 = 600;
        MemoryEstimate::per_vertex(
            "the frames of every level and the relaxation arrays",
            sizes,
            0,
            PER_VERTEX,
        )
    }
    fn requires(_: &Self::Settings) -> Vec<Datum> {
        vec![Datum::Mesh]
    }
    fn produces(_: &Self::Settings) -> Vec<Datum> {
        vec![Datum::Frames]
    }
    fn systems(settings: Self::Settings, ctx: StageCtx) -> ScheduleConfigs<ScheduleSystem> {
        let relax = move |mut commands: Commands,
                          seed: Res<RunSeed>,
                          mut metrics: ResMut<Metrics>,
                          levels: LevelQuery,
                          meshes: Query<&Geometry>|
              -> SystemResult {
            let entities = pyramid_entities(levels.iter().map(|(e, l, s)| (e, *l, s)))?;
            let geometry: Vec<&crate::mesh::PolyMesh> = entities
                .iter()
                .filter_map(|&e| meshes.get(e).ok().map(|g| &g.0))
                .collect();
            let normals: Vec<Vec<Vec3>> = geometry.iter().map(|m| m.vertex_normals()).collect();
            let topology: Vec<Topology> = geometry.iter().map(|m| Topology::build(m)).collect();
            let adjacency: Vec<TriangleAdjacency> =
                geometry.iter().map(|m| TriangleAdjacency::new(m)).collect();
            let views: Vec<OrientationLevel> = (0..geometry.len())
                .map(|l| OrientationLevel {
                    positions: &geometry[l].positions,
                    normals: &normals[l],
                    topology: &topology[l],
                    adjacency: &adjacency[l],
                })
                .collect();
            let mode = match settings.mode {
                RelaxMode::Relax => OrientationMode::Relax,
                RelaxMode::Random => OrientationMode::Random,
                RelaxMode::User => OrientationMode::User {
                    up: Vec3::from(settings.up),
                },
            };
            let progress = Progress::new(0, Self::KIND);
            let _finish = progress.finish_on_drop();
            let result = relax_orientation_with_progress(
                &views,
                &RelaxSettings {
                    mode,
                    symmetry: settings.symmetry,
                    iterations: settings.iterations,
                    seed: seed.derive(ctx.index, 0),
                },
                &progress,
            );
            progress.finish();
            metrics.record(ctx.index, "levels", entities.len());
            metrics.record(ctx.index, "energy_degrees2_per_level", &result.energy);
            if let Some(e) = result.energy.first() {
                metrics.record(ctx.index, "energy_finest_initial", e.first());
                metrics.record(ctx.index, "energy_finest_final", e.last());
            }
            for (e, frames) in entities.iter().zip(result.frames) {
                commands.entity(*e).insert(Frames(frames));
            }
            Ok(())
        };
        ctx.fallible(Self::KIND, relax)
    }
}
