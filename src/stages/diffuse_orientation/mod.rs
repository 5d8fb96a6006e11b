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
//! Reads: `Sqrt2Pyramid` (else `ActiveMesh`), each level's `Geometry` and
//! `LevelParents`. Writes `Frames` (t = the diffused up direction, s = t ×
//! n) and `SweepField` on every level (or on the active mesh without a
//! hierarchy), metrics.

use crate::config::params::{ParamDoc, ParamRange, StageSettings};
use crate::kernels::bangay_morkel::diffuse_orientation::{
    CompletedKeys, complete_keys, diffuse_orientation, frames_from_directions, level_sweep,
};
use crate::kernels::surface::geodesic::nearest_vertex;
use crate::mesh::Topology;
use crate::progress::{Progress, level_label};
use crate::stage::memory::{InputSizes, MemoryEstimate};
use crate::stage::{Datum, InputView, Stage, StageCtx, SystemResult};
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
    /// no key is on (see [`crate::kernels::surface::component_fallback::fallback_keys`]).
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

    /// The diffused vectors, the key distances and the smoothing's arrays,
    /// about 224 bytes a vertex (measured: `tests/memory_estimates.rs`).
    fn memory_estimate(_settings: &Self::Settings, sizes: &InputSizes) -> Vec<MemoryEstimate> {
        const PER_VERTEX: u64 = 224;
        MemoryEstimate::per_vertex("the diffused orientation field", sizes, 0, PER_VERTEX)
    }
    fn requires(_: &Self::Settings) -> Vec<Datum> {
        vec![Datum::Mesh]
    }
    fn produces(_: &Self::Settings) -> Vec<Datum> {
        vec![Datum::Frames]
    }
    /// A key or sweep anchor on a vertex id past the input mesh's is
    /// refused before any stage when the ids name the input's vertices
    /// (no stage before remeshes it); otherwise when this stage runs.
    fn check_input(settings: &Self::Settings, input: &InputView) -> Result<(), String> {
        let Some(n) = input.key_vertices else {
            return Ok(());
        };
        let missing = |v: u32| {
            format!(
                "vertex {v} does not exist: the input mesh has {n} vertices (ids 0..={}); allowed: an id of the input mesh, or a position (`at`, `at_bbox`)",
                n.saturating_sub(1)
            )
        };
        for (i, key) in settings.keys.iter().enumerate() {
            if let Some(v) = key.vertex.filter(|&v| u64::from(v) >= n) {
                return Err(format!("`keys`: key {}: {}", i + 1, missing(v)));
            }
        }
        match settings.sweep_anchor.as_ref().and_then(|a| a.vertex) {
            Some(v) if u64::from(v) >= n => Err(format!("`sweep_anchor`: {}", missing(v))),
            _ => Ok(()),
        }
    }
    fn systems(settings: Self::Settings, ctx: StageCtx) -> ScheduleConfigs<ScheduleSystem> {
        let diffuse = move |mut commands: Commands,
                            active: Res<ActiveMesh>,
                            pyramid: Option<Res<Sqrt2Pyramid>>,
                            mut metrics: ResMut<Metrics>,
                            meshes: Query<(&Geometry, Option<&LevelParents>)>|
              -> SystemResult {
            // Coarsest first.
            let levels: Vec<Entity> = match pyramid.as_deref() {
                Some(p) if !p.0.is_empty() => p.0.iter().rev().copied().collect(),
                _ => vec![active.0],
            };
            let Ok((coarsest, _)) = meshes.get(levels[0]) else {
                return Ok(());
            };
            let fallback = Vec3::from(settings.fallback_up);
            let coarsest_topo = Topology::build(&coarsest.0);
            let coarsest_normals = coarsest.0.vertex_normals();
            let (keys, user_count) =
                keys_on(&settings, &coarsest.0, &coarsest_topo, &coarsest_normals)?;
            record_keys(&mut metrics, ctx.index, &keys, user_count);
            let mut coarsest_cache = Some((coarsest_topo, coarsest_normals));
            let mut previous: Option<LevelValues> = None;
            // Three steps per level: topology, diffusion, sweep (3.5 s a
            // level at a million vertices).
            let progress = Progress::new(3 * levels.len() as u64, Self::KIND);
            let _finish = progress.finish_on_drop();
            for (i, &e) in levels.iter().enumerate() {
                let Ok((geometry, parents)) = meshes.get(e) else {
                    return Ok(());
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
                let carried = carry_down(previous.as_ref(), parents, mesh.vertex_count())?;
                let level =
                    orient_level(&settings, mesh, &topo, &normals, &keys, carried, fallback);
                if i == 0 {
                    metrics.record(ctx.index, "fill_passes", level.fill_passes);
                    metrics.record(ctx.index, "fallback_vertices", level.fallback_vertices);
                }
                progress.inc(2);
                let mut ec = commands.entity(e);
                ec.insert(Frames(frames_from_directions(&normals, &level.directions)));
                if settings.sweep {
                    ec.insert(SweepField(level.sweep.clone()));
                }
                previous = Some((level.directions, level.sweep));
            }
            metrics.record(ctx.index, "levels", levels.len());
            Ok(())
        };
        ctx.fallible(Self::KIND, diffuse)
    }
}

/// The user's keys as coarsest-level vertices with their directions, and
/// the sweep anchor (the first key unless given); errors name the key.
fn resolve_keys(
    settings: &DiffuseOrientationSettings,
    coarsest: &crate::mesh::PolyMesh,
) -> Result<(Vec<(u32, Vec3)>, u32), String> {
    let positions = &coarsest.positions;
    let bbox = coarsest.bounding_box();
    let mut keys = Vec::with_capacity(settings.keys.len());
    for (i, k) in settings.keys.iter().enumerate() {
        let v = resolve(positions, bbox, k.vertex, k.at, k.at_bbox)
            .map_err(|m| format!("keys: key {}: {m}", i + 1))?;
        keys.push((v, Vec3::from(k.up)));
    }
    let anchor = match &settings.sweep_anchor {
        Some(a) => resolve(positions, bbox, a.vertex, a.at, a.at_bbox)
            .map_err(|m| format!("sweep_anchor: {m}"))?,
        None => keys[0].0,
    };
    Ok((keys, anchor))
}

/// The user's keys on the coarsest level (how many: the second value),
/// completed: every connected component no key is on gets one automatic
/// key, so the field is diffused there too; the keys hold on every level
/// (√2 keeps the coarsest level's vertex ids).
fn keys_on(
    settings: &DiffuseOrientationSettings,
    coarsest: &crate::mesh::PolyMesh,
    topo: &Topology,
    normals: &[Vec3],
) -> Result<(CompletedKeys, usize), String> {
    let (user_keys, anchor) = resolve_keys(settings, coarsest)?;
    let user_count = user_keys.len();
    let fallback = Vec3::from(settings.fallback_up);
    let keys = complete_keys(
        &coarsest.positions,
        normals,
        topo,
        user_keys,
        anchor,
        fallback,
    );
    Ok((keys, user_count))
}

/// Records the keys: the user's (the first `user_count`), the automatic
/// ones and the sweep anchor.
fn record_keys(metrics: &mut Metrics, index: usize, keys: &CompletedKeys, user_count: usize) {
    let user: Vec<u32> = keys.keys[..user_count].iter().map(|k| k.0).collect();
    metrics.record(index, "key_vertices", user);
    metrics.record(index, "fallback_components", keys.automatic.len());
    let automatic: Vec<u32> = keys.automatic.iter().map(|k| k.vertex).collect();
    metrics.record(index, "fallback_keys", automatic);
    metrics.record(index, "sweep_anchor", keys.anchor);
}

/// A level's directions and sweep values, one per vertex.
type LevelValues = (Vec<Vec3>, Vec<f32>);

/// The directions and sweep of the level above carried down to a level of
/// `vertex_count` vertices through its √2 parents; `None` on the coarsest
/// level (nothing above).
fn carry_down(
    previous: Option<&LevelValues>,
    parents: Option<&LevelParents>,
    vertex_count: usize,
) -> Result<Option<LevelValues>, String> {
    let Some((directions, sweep)) = previous else {
        return Ok(None);
    };
    match parents {
        Some(p) if p.0.len() == vertex_count => Ok(Some((
            carry_attribute(&p.0, directions),
            carry_attribute(&p.0, sweep),
        ))),
        _ => Err("a hierarchy level has no parents in the level above".into()),
    }
}

/// One level's field: the diffused directions and the sweep field (zeros
/// without `sweep`).
struct LevelField {
    directions: Vec<Vec3>,
    sweep: Vec<f32>,
    fill_passes: u32,
    fallback_vertices: usize,
}

/// Diffuses the keys over one level (from the values `carried` down, with
/// `refine_passes`; on the coarsest level with `smoothing_passes`) and
/// grows its sweep field.
fn orient_level(
    settings: &DiffuseOrientationSettings,
    mesh: &crate::mesh::PolyMesh,
    topo: &Topology,
    normals: &[Vec3],
    keys: &CompletedKeys,
    carried: Option<LevelValues>,
    fallback: Vec3,
) -> LevelField {
    let passes = if carried.is_none() {
        settings.smoothing_passes
    } else {
        settings.refine_passes
    };
    let (directions, sweep) = carried.unzip();
    let result = diffuse_orientation(
        normals,
        topo,
        &keys.keys,
        directions.as_deref(),
        passes,
        fallback,
    );
    let sweep = if settings.sweep {
        level_sweep(
            &mesh.positions,
            topo,
            &result.directions,
            keys,
            sweep,
            settings.sweep_iterations,
            settings.refine_passes,
        )
    } else {
        vec![0.0; mesh.vertex_count()]
    };
    LevelField {
        directions: result.directions,
        sweep,
        fill_passes: result.fill_passes,
        fallback_vertices: result.fallback_vertices,
    }
}
