//! Stage `builtin_pyramid`: a mesh pyramid of procedural meshes, each level
//! with about a quarter of the vertices of the next finer one (icospheres
//! and cubes one subdivision apart; planes, tori and uv spheres at half the
//! resolution). A stand-in for `retile` (Wei & Levoy 2001 §3.1) on shapes
//! whose uniform tessellations are known, and a fixed pyramid for tests and
//! benches. The input mesh is left as it is; level 0 becomes the active mesh.
//!
//! Reads: nothing but its settings. Writes: the level entities
//! (`MeshLevel`, `Geometry`), `ActiveMesh`, `TexelSpacing`.

use crate::config::params::{ParamDoc, ParamRange, StageSettings};
use crate::kernels::surface::flatten::{mean_fan_triangle_area, template_spacing};
use crate::mesh::PolyMesh;
use crate::mesh::builtin::{BuiltinOptions, builtin_mesh};
use crate::stage::memory::{BYTES_PER_MESH_VERTEX, InputSizes, MemoryEstimate};
use crate::stage::{Datum, Stage, StageCtx, SystemResult};
use crate::world::*;
use bevy_ecs::prelude::*;
use bevy_ecs::schedule::ScheduleConfigs;
use bevy_ecs::system::ScheduleSystem;
use serde::{Deserialize, Serialize};

/// Settings of `builtin_pyramid`.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BuiltinPyramidSettings {
    /// The builtin mesh: icosphere, cube, plane, torus or uv_sphere.
    pub mesh: String,
    /// Pyramid levels.
    pub levels: u32,
    /// icosphere, cube: subdivisions of the finest level.
    pub subdivisions: u32,
    /// plane, torus, uv_sphere: resolution of the finest level.
    pub resolution: [u32; 2],
    /// Quads instead of triangles where the mesh offers both.
    pub quads: bool,
    /// plane: side length; cube: edge length.
    pub size: f32,
    /// icosphere, uv_sphere, torus: radius.
    pub radius: f32,
    /// torus: tube radius.
    pub minor_radius: f32,
}

impl Default for BuiltinPyramidSettings {
    fn default() -> Self {
        let b = BuiltinOptions::default();
        Self {
            mesh: "icosphere".into(),
            levels: 4,
            subdivisions: 5,
            resolution: [65, 65],
            quads: false,
            size: b.size,
            radius: b.radius,
            minor_radius: b.minor_radius,
        }
    }
}

impl StageSettings for BuiltinPyramidSettings {
    const PARAMS: &'static [ParamDoc] = &[
        ParamDoc {
            name: "mesh",
            unit: "",
            range: ParamRange::OneOf(&["icosphere", "cube", "plane", "torus", "uv_sphere"]),
            doc: "the builtin mesh of every level",
        },
        ParamDoc {
            name: "levels",
            unit: "",
            range: ParamRange::Int(1, 8),
            doc: "pyramid levels, each with about a quarter of the vertices of the finer one",
        },
        ParamDoc {
            name: "subdivisions",
            unit: "",
            range: ParamRange::Int(0, 8),
            doc: "icosphere, cube: subdivisions of the finest level (coarser levels one fewer each)",
        },
        ParamDoc {
            name: "resolution",
            unit: "vertices",
            range: ParamRange::Int(2, 4096),
            doc: "plane, torus, uv_sphere: [u, v] of the finest level; coarser levels halve it (planes keep (r-1)/2+1 so grid lines coincide)",
        },
        ParamDoc {
            name: "quads",
            unit: "",
            range: ParamRange::Any("true or false"),
            doc: "quads instead of triangle pairs (plane, torus, uv_sphere)",
        },
        ParamDoc {
            name: "size",
            unit: "world units",
            range: ParamRange::Float(1e-6, 1e6),
            doc: "plane: longer side; cube: edge",
        },
        ParamDoc {
            name: "radius",
            unit: "world units",
            range: ParamRange::Float(1e-6, 1e6),
            doc: "icosphere, uv_sphere: radius; torus: distance from the axis to the tube centre",
        },
        ParamDoc {
            name: "minor_radius",
            unit: "world units",
            range: ParamRange::Float(1e-6, 1e6),
            doc: "torus: tube radius",
        },
    ];

    fn check(&self) -> Result<(), (String, String)> {
        let coarsest = self.levels.saturating_sub(1);
        let [u, v] = self.resolution;
        let (name, ok, need) = match self.mesh.as_str() {
            "icosphere" | "cube" => (
                "subdivisions",
                self.subdivisions >= coarsest,
                format!("at least {coarsest}"),
            ),
            "plane" => (
                "resolution",
                (u.max(1) - 1) >> coarsest >= 1 && (v.max(1) - 1) >> coarsest >= 1,
                format!("at least {} per side", (1u32 << coarsest) + 1),
            ),
            _ => (
                "resolution",
                u >> coarsest >= 3 && v >> coarsest >= 3,
                format!("at least {} per side", 3u32 << coarsest),
            ),
        };
        if ok {
            Ok(())
        } else {
            Err((
                name.into(),
                format!("{} levels of {} need {name} {need}", self.levels, self.mesh),
            ))
        }
    }
}

/// The levels of the pyramid, finest first.
///
/// # Errors
/// A message naming the option when a level cannot be built (too few
/// subdivisions or too low a resolution for the number of levels).
pub fn builtin_pyramid(settings: &BuiltinPyramidSettings) -> Result<Vec<PolyMesh>, String> {
    (0..settings.levels)
        .map(|l| {
            let mut o = BuiltinOptions {
                quads: settings.quads,
                size: settings.size,
                radius: settings.radius,
                minor_radius: settings.minor_radius,
                ..Default::default()
            };
            match settings.mesh.as_str() {
                "icosphere" | "cube" => {
                    o.subdivisions = settings.subdivisions.checked_sub(l).ok_or_else(|| {
                        format!(
                            "{} levels need subdivisions >= {} (got {})",
                            settings.levels,
                            settings.levels - 1,
                            settings.subdivisions
                        )
                    })?;
                }
                "plane" => o.resolution = settings.resolution.map(|r| ((r - 1) >> l) + 1),
                _ => o.resolution = settings.resolution.map(|r| r >> l),
            }
            builtin_mesh(&settings.mesh, &o).map_err(|e| format!("level {l}: {e}"))
        })
        .collect()
}

/// The `builtin_pyramid` stage.
pub struct BuiltinPyramid;

impl Stage for BuiltinPyramid {
    const KIND: &'static str = "builtin_pyramid";
    const SUMMARY: &'static str = "a pyramid of procedural meshes, 1/4 of the vertices per coarser level (stand-in for retile)";
    const PAPER: &'static str = "Wei & Levoy 2001 §3.1 (mesh pyramid)";
    type Settings = BuiltinPyramidSettings;

    fn requires(_: &Self::Settings) -> Vec<Datum> {
        vec![]
    }
    fn produces(_: &Self::Settings) -> Vec<Datum> {
        vec![Datum::MeshPyramid]
    }
    /// A grid's `resolution` (plane, torus, uv_sphere) at the finest
    /// level, at the coarse whole-pipeline bound per vertex
    /// (`memory_budget::BYTES_PER_MESH_VERTEX`): the mesh it makes is what
    /// every later stage works on.
    fn memory_estimate(settings: &Self::Settings, _sizes: &InputSizes) -> Vec<MemoryEstimate> {
        if !matches!(settings.mesh.as_str(), "plane" | "torus" | "uv_sphere") {
            return Vec::new();
        }
        let [u, v] = settings.resolution;
        vec![MemoryEstimate::image(
            "resolution",
            "the finest level's vertices over the whole pipeline",
            (u, v),
            4096,
            |a, b| (a * b).saturating_mul(BYTES_PER_MESH_VERTEX),
        )]
    }
    /// The finest level: a `resolution` grid, or an icosphere or cube of
    /// `subdivisions`.
    fn sizes_after(settings: &Self::Settings, sizes: &InputSizes) -> InputSizes {
        finest_vertices(settings).map_or(*sizes, |v| sizes.with_mesh(v))
    }
    /// The builtin mesh replaces the input.
    fn keeps_vertex_ids(_: &Self::Settings, _: &InputSizes) -> bool {
        false
    }
    fn plane_role(settings: &Self::Settings) -> crate::stage::PlaneRole {
        crate::stage::PlaneRole::ReplacesMesh {
            planar: settings.mesh == "plane",
            what: format!("the builtin_pyramid mesh `{}`", settings.mesh),
        }
    }
    fn systems(settings: Self::Settings, ctx: StageCtx) -> ScheduleConfigs<ScheduleSystem> {
        let build = move |mut commands: Commands,
                          mut metrics: ResMut<Metrics>,
                          mut spacing: ResMut<TexelSpacing>|
              -> SystemResult {
            let meshes = builtin_pyramid(&settings)?;
            let counts: Vec<usize> = meshes.iter().map(PolyMesh::vertex_count).collect();
            metrics.record(ctx.index, "vertices_per_level", &counts);
            if let Some(m) = meshes.first() {
                let a = mean_fan_triangle_area(m);
                spacing.0 = template_spacing(a).max(f32::MIN_POSITIVE);
            }
            let mut finest = None;
            for (l, m) in meshes.into_iter().enumerate() {
                let e = commands.spawn((MeshLevel(l as u8), Geometry(m))).id();
                finest.get_or_insert(e);
            }
            if let Some(e) = finest {
                commands.insert_resource(ActiveMesh(e));
            }
            Ok(())
        };
        ctx.fallible(Self::KIND, build)
    }
}

/// Vertices of the finest level: `u·v` for a grid of `resolution`,
/// `10·4^s + 2` for an icosphere and `6·4^s + 2` for a cube of `s`
/// subdivisions (`None`: an unknown mesh name, refused by validation).
fn finest_vertices(settings: &BuiltinPyramidSettings) -> Option<u64> {
    let quarters = 1u64 << (2 * settings.subdivisions.min(20));
    match settings.mesh.as_str() {
        "plane" | "torus" | "uv_sphere" => {
            let [u, v] = settings.resolution;
            Some(u64::from(u) * u64::from(v))
        }
        "icosphere" => Some(10 * quarters + 2),
        "cube" => Some(6 * quarters + 2),
        _ => None,
    }
}
