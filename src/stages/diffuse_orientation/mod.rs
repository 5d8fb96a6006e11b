//! Stage `diffuse_orientation`: the orientation field of Bangay & Morkel
//! 2006 §3.1.1 (after Turk 2001). The user gives the texture's up direction
//! at key vertices; repeated passes average neighbours' directions,
//! projected onto each tangent plane and normalised, until every vertex has
//! one. On a √2 hierarchy this runs coarse to fine: the coarsest level is
//! diffused fully, each finer level starts from the values carried down
//! through the √2 parents and is re-diffused for a few passes. The sweep
//! field (a scalar growing along the field from an anchor, Turk 2001) is
//! made the same way and orders the vertices of the first synthesis pass.
//!
//! A connected component that no key is on gets one automatic key
//! (`kernels::surface::component_fallback::fallback_keys`: its vertex nearest its
//! centroid, `fallback_up` projected there) and is diffused from it like
//! any other; its sweep starts at its first key and continues after the
//! values of the components before it. Metric `fallback_components`.
//! Key positions are vertex ids, world points (`at`) or fractions of the
//! coarsest level's bounding box (`at_bbox`, `stages::position`).
//!
//! Writes `Frames` (t = the diffused up direction, s = t × n) and
//! `SweepField` on every level (or on the active mesh without a hierarchy).

use crate::config::params::{ParamDoc, ParamRange, StageSettings};
use crate::kernels::bangay_morkel::diffuse_orientation::diffuse_orientation;
use crate::kernels::bangay_morkel::sweep::{relax_sweep, sweep_field};
use crate::kernels::surface::component_fallback::{
    Components, chain_components, fallback_keys, one_per_component,
};
use crate::kernels::surface::frames::TangentFrame;
use crate::kernels::surface::geodesic::nearest_vertex;
use crate::mesh::Topology;
use crate::progress::{Progress, level_label};
use crate::stage::{Datum, Stage, StageCtx, StageError};
use crate::stages::position;
use crate::stages::subdivide_sqrt2::carry_attribute;
use crate::world::*;
use bevy_ecs::prelude::*;
use bevy_ecs::schedule::ScheduleConfigs;
use bevy_ecs::system::ScheduleSystem;
use glam::Vec3;
use serde::{Deserialize, Serialize};

/// A point on the mesh: a vertex id of the coarsest level (which √2 keeps
/// in every level) or the vertex nearest to a position, in world
/// coordinates or as fractions of the coarsest level's bounding box
/// (`stages::position`). Exactly one of the three.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VertexSpec {
    /// Vertex id on the coarsest level (the input mesh's ids).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub vertex: Option<u32>,
    /// World position; the nearest vertex of the coarsest level is used.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub at: Option<[f32; 3]>,
    /// Position as fractions `[0, 1]` of the coarsest level's bounding box
    /// (0 = minimum, 1 = maximum); the nearest vertex is used.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub at_bbox: Option<[f32; 3]>,
}

/// A key orientation: `{ vertex = 12, up = [0, 1, 0] }`,
/// `{ at = [x, y, z], up = [0, 1, 0] }` or
/// `{ at_bbox = [u, v, w], up = [0, 1, 0] }`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct KeySpec {
    /// Vertex id on the coarsest level.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub vertex: Option<u32>,
    /// World position; the nearest vertex of the coarsest level is used.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub at: Option<[f32; 3]>,
    /// Position as fractions `[0, 1]` of the coarsest level's bounding box;
    /// the nearest vertex is used.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub at_bbox: Option<[f32; 3]>,
    /// The texture's up direction there (projected onto the tangent plane).
    pub up: [f32; 3],
}

/// Settings of `diffuse_orientation`.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DiffuseOrientationSettings {
    /// Key orientations.
    pub keys: Vec<KeySpec>,
    /// Extra passes on the coarsest level once every vertex has a direction.
    pub smoothing_passes: u32,
    /// Passes on each finer level after carrying the directions down.
    pub refine_passes: u32,
    /// Direction of the automatic key placed on each connected component
    /// no key is on (see [`fallback_keys`]).
    pub fallback_up: [f32; 3],
    /// Whether to compute the sweep field too.
    pub sweep: bool,
    /// Where the sweep is 0; the first key when not given. Every other
    /// component starts its sweep at its first key (or automatic key).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sweep_anchor: Option<VertexSpec>,
    /// Relaxation passes of the sweep on the coarsest level.
    pub sweep_iterations: u32,
}

impl Default for DiffuseOrientationSettings {
    fn default() -> Self {
        Self {
            keys: vec![KeySpec {
                vertex: Some(0),
                at: None,
                at_bbox: None,
                up: [0.0, 1.0, 0.0],
            }],
            smoothing_passes: 20,
            refine_passes: 4,
            fallback_up: [0.0, 1.0, 0.0],
            sweep: true,
            sweep_anchor: None,
            sweep_iterations: 30,
        }
    }
}

fn check_point(
    vertex: Option<u32>,
    at: Option<[f32; 3]>,
    at_bbox: Option<[f32; 3]>,
) -> Result<(), String> {
    position::check(at, at_bbox)?;
    match (vertex.is_some(), at.is_some() || at_bbox.is_some()) {
        (true, false) | (false, true) => Ok(()),
        (true, true) => Err("give `vertex` or a position (`at` or `at_bbox`), not both".into()),
        (false, false) => {
            Err("give `vertex = N`, `at = [x, y, z]` or `at_bbox = [u, v, w]`".into())
        }
    }
}

impl StageSettings for DiffuseOrientationSettings {
    const PARAMS: &'static [ParamDoc] = &[
        ParamDoc {
            name: "keys",
            unit: "",
            range: ParamRange::Any(
                "list of { vertex = N | at = [x, y, z] | at_bbox = [u, v, w], up = [x, y, z] }",
            ),
            doc: "texture up direction at key vertices: ids of the coarsest level (= input mesh ids, unless `subdivide_sqrt2` remeshed a dense input — `coarsen_dense_input` — whose ids are the remesh's: name places with `at`/`at_bbox` then), or the vertex nearest a position given in world coordinates (`at`) or as fractions 0..1 of the coarsest level's bounding box (`at_bbox`, 0 = min, 1 = max)",
        },
        ParamDoc {
            name: "smoothing_passes",
            unit: "passes",
            range: ParamRange::Int(0, 100_000),
            doc: "averaging passes on the coarsest level after every vertex has a direction",
        },
        ParamDoc {
            name: "refine_passes",
            unit: "passes",
            range: ParamRange::Int(0, 100_000),
            doc: "averaging passes (and sweep relaxation passes) on each finer level after carrying values down",
        },
        ParamDoc {
            name: "fallback_up",
            unit: "world axes",
            range: ParamRange::Float(-1e6, 1e6),
            doc: "each connected component no key is on gets one automatic key, at its vertex nearest its centroid, with this direction projected onto the tangent plane (the component's principal axis where it is along the normal), and is diffused from it; counted in the metric `fallback_components`",
        },
        ParamDoc {
            name: "sweep",
            unit: "",
            range: ParamRange::Any("true | false"),
            doc: "also compute the sweep field (Turk 2001) that orders the first synthesis pass",
        },
        ParamDoc {
            name: "sweep_anchor",
            unit: "",
            range: ParamRange::Any(
                "{ vertex = N } or { at = [x, y, z] } or { at_bbox = [u, v, w] }",
            ),
            doc: "where the sweep is 0 (default: the first key); a position is in world coordinates (`at`) or fractions 0..1 of the coarsest level's bounding box (`at_bbox`); every other component sweeps from its first key (or automatic key), its values continuing after the previous component's",
        },
        ParamDoc {
            name: "sweep_iterations",
            unit: "passes",
            range: ParamRange::Int(0, 100_000),
            doc: "relaxation passes of the sweep field on the coarsest level",
        },
    ];

    fn check(&self) -> Result<(), (String, String)> {
        if self.keys.is_empty() {
            return Err(("keys".into(), "give at least one key orientation".into()));
        }
        for (i, k) in self.keys.iter().enumerate() {
            check_point(k.vertex, k.at, k.at_bbox)
                .map_err(|m| ("keys".to_string(), format!("key {}: {m}", i + 1)))?;
            if Vec3::from(k.up).length_squared() < 1e-12 {
                return Err((
                    "keys".into(),
                    format!("key {}: `up` is the zero vector", i + 1),
                ));
            }
        }
        if let Some(a) = &self.sweep_anchor {
            check_point(a.vertex, a.at, a.at_bbox).map_err(|m| ("sweep_anchor".to_string(), m))?;
        }
        Ok(())
    }
}

/// The coarsest-level vertex a spec names: its `vertex`, or the vertex
/// nearest its `at` / `at_bbox` (`bbox` is the coarsest level's).
fn resolve(
    positions: &[Vec3],
    bbox: Option<(Vec3, Vec3)>,
    vertex: Option<u32>,
    at: Option<[f32; 3]>,
    at_bbox: Option<[f32; 3]>,
) -> Result<u32, String> {
    match (vertex, position::resolve(at, at_bbox, bbox)?) {
        (Some(v), _) if (v as usize) < positions.len() => Ok(v),
        (Some(v), _) => Err(format!(
            "key vertex {v} does not exist: the coarsest level has {} vertices (ids 0..={})",
            positions.len(),
            positions.len().saturating_sub(1)
        )),
        (None, Some(p)) => {
            nearest_vertex(positions, p).ok_or_else(|| "the mesh has no vertices".into())
        }
        (None, None) => Err("a key needs `vertex`, `at` or `at_bbox`".into()),
    }
}

/// The `diffuse_orientation` stage.
pub struct DiffuseOrientation;

impl Stage for DiffuseOrientation {
    const KIND: &'static str = "diffuse_orientation";
    const SUMMARY: &'static str = "orientation diffused from key vertices, coarse to fine over the √2 hierarchy, plus the sweep field";
    const PAPER: &'static str = "Bangay & Morkel 2006 §3.1.1; Turk 2001";
    type Settings = DiffuseOrientationSettings;

    fn requires(_: &Self::Settings) -> Vec<Datum> {
        vec![Datum::Mesh]
    }
    fn produces(_: &Self::Settings) -> Vec<Datum> {
        vec![Datum::Frames]
    }
    fn systems(settings: Self::Settings, ctx: StageCtx) -> ScheduleConfigs<ScheduleSystem> {
        (move |mut commands: Commands,
               active: Res<ActiveMesh>,
               pyramid: Option<Res<Sqrt2Pyramid>>,
               mut metrics: ResMut<Metrics>,
               mut failure: ResMut<StageFailure>,
               meshes: Query<(&Geometry, Option<&LevelParents>)>| {
            let fail = |failure: &mut StageFailure, message: String| {
                failure.0 = Some(StageError {
                    index: ctx.index + 1,
                    kind: Self::KIND.into(),
                    message,
                });
            };
            // Coarsest first.
            let levels: Vec<Entity> = match pyramid.as_deref() {
                Some(p) if !p.0.is_empty() => p.0.iter().rev().copied().collect(),
                _ => vec![active.0],
            };
            let Ok((coarsest, _)) = meshes.get(levels[0]) else {
                return;
            };
            let positions = &coarsest.0.positions;
            let bbox = coarsest.0.bounding_box();
            let mut keys = Vec::with_capacity(settings.keys.len());
            for (i, k) in settings.keys.iter().enumerate() {
                match resolve(positions, bbox, k.vertex, k.at, k.at_bbox) {
                    Ok(v) => keys.push((v, Vec3::from(k.up))),
                    Err(m) => return fail(&mut failure, format!("keys: key {}: {m}", i + 1)),
                }
            }
            let anchor = match &settings.sweep_anchor {
                Some(a) => match resolve(positions, bbox, a.vertex, a.at, a.at_bbox) {
                    Ok(v) => v,
                    Err(m) => return fail(&mut failure, format!("sweep_anchor: {m}")),
                },
                None => keys[0].0,
            };
            let fallback = Vec3::from(settings.fallback_up);
            // Every connected component no key is on gets one automatic
            // key, so the field is diffused there too; the keys hold on
            // every level (√2 keeps the coarsest level's vertex ids).
            let coarsest_topo = Topology::build(&coarsest.0);
            let coarsest_normals = coarsest.0.vertex_normals();
            let (count, of_vertex) = coarsest_topo.components();
            let user_keys: Vec<u32> = keys.iter().map(|k| k.0).collect();
            let automatic = fallback_keys(
                positions,
                &coarsest_normals,
                Components {
                    count,
                    of_vertex: &of_vertex,
                },
                &user_keys,
                fallback,
            );
            keys.extend(automatic.iter().map(|k| (k.vertex, k.direction)));
            // One sweep start per component: the anchor, else the
            // component's first key (user keys before automatic ones).
            let preferred: Vec<u32> = std::iter::once(anchor)
                .chain(keys.iter().map(|k| k.0))
                .collect();
            let sweep_starts = one_per_component(
                Components {
                    count,
                    of_vertex: &of_vertex,
                },
                &preferred,
            );
            let mut coarsest_cache = Some((coarsest_topo, coarsest_normals));
            let mut directions: Vec<Vec3> = Vec::new();
            let mut sweep: Vec<f32> = Vec::new();
            // Three steps per level: topology, diffusion, sweep (3.5 s a
            // level at a million vertices).
            let progress = Progress::new(3 * levels.len() as u64, Self::KIND);
            let _finish = progress.finish_on_drop();
            for (i, &e) in levels.iter().enumerate() {
                let Ok((geometry, parents)) = meshes.get(e) else {
                    return;
                };
                let mesh = &geometry.0;
                // The pyramid index: the levels run coarsest first.
                let level = levels.len() - 1 - i;
                let _span =
                    tracing::info_span!("diffuse_level", level, vertices = mesh.vertex_count())
                        .entered();
                progress.set_part(&level_label(level, levels.len()));
                let (topo, normals) = match coarsest_cache.take() {
                    Some(cached) if i == 0 => cached,
                    _ => (Topology::build(mesh), mesh.vertex_normals()),
                };
                progress.inc(1);
                let (count, of_vertex) = topo.components();
                let components = Components {
                    count,
                    of_vertex: &of_vertex,
                };
                let carried = match (i, parents) {
                    (0, _) => None,
                    (_, Some(p)) if p.0.len() == mesh.vertex_count() => Some((
                        carry_attribute(&p.0, &directions),
                        carry_attribute(&p.0, &sweep),
                    )),
                    _ => {
                        return fail(
                            &mut failure,
                            "a hierarchy level has no parents in the level above".into(),
                        );
                    }
                };
                let passes = if i == 0 {
                    settings.smoothing_passes
                } else {
                    settings.refine_passes
                };
                let result = diffuse_orientation(
                    &normals,
                    &topo,
                    &keys,
                    carried.as_ref().map(|c| c.0.as_slice()),
                    passes,
                    fallback,
                );
                if i == 0 {
                    metrics.record(ctx.index, "fill_passes", result.fill_passes);
                    metrics.record(ctx.index, "fallback_vertices", result.fallback_vertices);
                    metrics.record(ctx.index, "key_vertices", user_keys.clone());
                    metrics.record(ctx.index, "fallback_components", automatic.len());
                    metrics.record(
                        ctx.index,
                        "fallback_keys",
                        automatic.iter().map(|k| k.vertex).collect::<Vec<_>>(),
                    );
                    metrics.record(ctx.index, "sweep_anchor", anchor);
                }
                progress.inc(1);
                directions = result.directions;
                if settings.sweep {
                    sweep = match carried {
                        None => sweep_field(
                            &mesh.positions,
                            &topo,
                            &directions,
                            &sweep_starts,
                            settings.sweep_iterations,
                        ),
                        Some((_, mut s)) => {
                            let mut fixed = vec![false; s.len()];
                            for &a in &sweep_starts {
                                if let Some(f) = fixed.get_mut(a as usize) {
                                    *f = true;
                                }
                            }
                            relax_sweep(
                                &mesh.positions,
                                &topo,
                                &directions,
                                &fixed,
                                &mut s,
                                settings.refine_passes,
                            );
                            s
                        }
                    };
                    // The anchor's component first, the others continuing
                    // after it (a no-op on a connected mesh).
                    let first = of_vertex.get(anchor as usize).copied();
                    chain_components(&mut sweep, components, first);
                } else {
                    sweep = vec![0.0; mesh.vertex_count()];
                }
                let frames: Vec<TangentFrame> = normals
                    .iter()
                    .zip(&directions)
                    .map(|(&n, &d)| TangentFrame::from_up(n, d))
                    .collect();
                progress.inc(1);
                let mut ec = commands.entity(e);
                ec.insert(Frames(frames));
                if settings.sweep {
                    ec.insert(SweepField(sweep.clone()));
                }
            }
            metrics.record(ctx.index, "levels", levels.len());
        })
        .into_configs()
    }
}
