//! Stage `retile`: re-tiles the input mesh so its vertices are uniformly
//! distributed at a chosen density and builds the Wei & Levoy 2001 §3.1 mesh
//! pyramid (each coarser level a quarter of the vertices). Level entities get
//! `MeshLevel(l)` (0 finest) and a `SourceCorrespondence` to map results back
//! onto the input; the finest level becomes the active mesh.
//!
//! Reads: the `SourceMesh`'s `Geometry`, `TextureScale`. Writes: the level
//! entities (`MeshLevel`, `Geometry`, `SourceCorrespondence`; the source
//! mesh loses its `MeshLevel`), `ActiveMesh`, `TexelSpacing`.

use crate::config::params::{ParamDoc, ParamRange, StageSettings};
use crate::kernels::wei_levoy::retile::{
    InputReport, RetileSettings, RetileTarget, RetiledLevel, edge_length_cv, retile_with_progress,
};
use crate::mesh::PolyMesh;
use crate::progress::Progress;
use crate::stage::memory::{Fit, InputSizes, MemoryEstimate};
use crate::stage::{Datum, Stage, StageCtx, SystemResult};
use crate::world::*;
use bevy_ecs::prelude::*;
use bevy_ecs::schedule::ScheduleConfigs;
use bevy_ecs::system::ScheduleSystem;
use serde::{Deserialize, Serialize};

/// Largest `vertices` (explicit or derived from the texture scale).
pub const MAX_VERTICES: u64 = 50_000_000;

/// Bytes per finest-level vertex of the retiled pyramid at the stage's
/// peak (measured 360-700 from 4 000 to 64 000 vertices: growing arrays
/// hold spare capacity).
pub const BYTES_PER_VERTEX: u64 = 500;

/// Bytes per input triangle (the projection tree and the prepared input).
pub const BYTES_PER_INPUT_TRIANGLE: u64 = 120;

/// Settings of `retile`.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RetileStageSettings {
    /// Vertices of the finest level (used when `edge_length` is 0); 0 = one
    /// per exemplar pixel² of surface at `[input] texture_scale`.
    pub vertices: u32,
    /// Target edge length of the finest level, world units; 0 = use `vertices`.
    pub edge_length: f32,
    /// Pyramid levels.
    pub levels: u32,
    /// Remeshing iterations per level.
    pub iterations: u32,
    /// Exemplar texels (pixel²) per finest vertex when `vertices` is derived.
    pub texels_per_vertex: f64,
}

impl Default for RetileStageSettings {
    fn default() -> Self {
        Self {
            vertices: 0,
            edge_length: 0.0,
            levels: 4,
            iterations: 10,
            texels_per_vertex: 1.0,
        }
    }
}

impl StageSettings for RetileStageSettings {
    const PARAMS: &'static [ParamDoc] = &[
        ParamDoc {
            name: "vertices",
            unit: "vertices",
            range: ParamRange::Int(0, MAX_VERTICES as i64),
            doc: "vertices of the finest level (the density sets the texture scale of `match`, Wei & Levoy Fig. 2); 0 = derived from `[input] texture_scale`: surface area × (exemplar pixels per unit)², one exemplar pixel per finest vertex spacing; 1..=11 is refused",
        },
        ParamDoc {
            name: "texels_per_vertex",
            unit: "exemplar pixels² per vertex",
            range: ParamRange::Float(1.0, 1024.0),
            doc: "with `vertices` derived (0): surface area × (exemplar pixels per unit)² / texels_per_vertex vertices. 1 = one vertex per exemplar pixel, Wei & Levoy's density, which per-vertex colours need; a method that records exemplar coordinates (coherent) and is baked or previewed through them keeps the exemplar's resolution at 16 (one vertex per 4 × 4 pixels) for a 16th of the vertices",
        },
        ParamDoc {
            name: "edge_length",
            unit: "world units",
            range: ParamRange::Float(0.0, 1e9),
            doc: "target edge length of the finest level instead of a vertex count; 0 = use `vertices`",
        },
        ParamDoc {
            name: "levels",
            unit: "",
            range: ParamRange::Int(1, 8),
            doc: "pyramid levels; each coarser level has a quarter of the vertices (paper: 4)",
        },
        ParamDoc {
            name: "iterations",
            unit: "",
            range: ParamRange::Int(1, 100),
            doc: "isotropic remeshing iterations per level (split, collapse, flip, relax, project)",
        },
    ];

    fn check(&self) -> Result<(), (String, String)> {
        check_vertex_count(u64::from(self.vertices), MAX_VERTICES)
            .map_err(|m| ("vertices".into(), m))
    }
}

/// Where each vertex of a retiled level lies on the input surface: a face
/// of the triangulated input and barycentric coordinates in it.
#[derive(Component, Clone, Debug, Default)]
pub struct SourceCorrespondence {
    /// Face of `input.triangulated()`.
    pub face: Vec<u32>,
    /// Barycentric coordinates in that face.
    pub bary: Vec<glam::Vec3>,
}

impl RetileStageSettings {
    /// What the finest level aims at: `edge_length`, `vertices`, or the
    /// vertices the `source` mesh's area needs at the texture scale
    /// (recorded and logged).
    fn target(
        &self,
        source: &PolyMesh,
        texture_scale: &TextureScale,
        metrics: &mut Metrics,
        index: usize,
    ) -> Result<RetileTarget, String> {
        if self.edge_length > 0.0 {
            return Ok(RetileTarget::EdgeLength(self.edge_length));
        }
        if self.vertices > 0 {
            return Ok(RetileTarget::Vertices(self.vertices));
        }
        let area = f64::from(source.area()) / self.texels_per_vertex;
        let n = texture_scale.derived_vertices(area, "retile.vertices", MAX_VERTICES as usize)?;
        metrics.record(index, "vertices_from_texture_scale", n);
        tracing::info!(
            "retile: {} vertices for the {}",
            n,
            texture_scale.describe()
        );
        Ok(RetileTarget::Vertices(n as u32))
    }
}

/// Records what preparing a messy input changed, for the user.
fn record_input(metrics: &mut Metrics, index: usize, r: &InputReport) {
    metrics.record(index, "input_components", r.components);
    metrics.record(index, "input_boundary_loops", r.boundary_loops);
    metrics.record(index, "input_cut_nonmanifold_edges", r.cut_edges);
    metrics.record(
        index,
        "input_split_vertices",
        r.split_vertices + r.cut_vertices,
    );
    metrics.record(
        index,
        "input_dropped_degenerate_triangles",
        r.dropped_degenerate_triangles,
    );
    if r.cut_edges > 0 {
        tracing::info!(
            "retile: cut {} non-manifold edge(s) of the input into manifold pieces",
            r.cut_edges
        );
    }
}

/// Spawns the retiled levels (finest first) with their correspondence to
/// the input and records their figures; returns the finest level's entity
/// and mean edge length.
fn spawn_levels(
    commands: &mut Commands,
    levels: Vec<RetiledLevel>,
    metrics: &mut Metrics,
    index: usize,
) -> Option<(Entity, f32)> {
    let mut finest = None;
    let mut counts = Vec::new();
    let mut targets = Vec::new();
    let mut cvs = Vec::new();
    for (l, level) in levels.into_iter().enumerate() {
        counts.push(level.mesh.vertex_count());
        targets.push(level.target_vertices);
        cvs.push(edge_length_cv(&level.mesh));
        let edge = level.mesh.average_edge_length();
        let e = commands
            .spawn((
                MeshLevel(l as u8),
                Geometry(level.mesh),
                SourceCorrespondence {
                    face: level.source_face,
                    bary: level.source_bary,
                },
            ))
            .id();
        finest.get_or_insert((e, edge));
    }
    metrics.record(index, "level_vertices", &counts);
    metrics.record(index, "level_targets", &targets);
    metrics.record(index, "level_edge_length_cv", &cvs);
    finest
}

/// Vertices per unit² of equilateral triangles of side 1: 2 / √3 (side e:
/// divide by e²).
const EQUILATERAL_VERTICES_PER_AREA: f64 = 1.154_700_538_379_251_7;

/// The finest level's vertex count the settings ask for on an input of
/// `sizes`: from `edge_length`, derived from the texture scale, or
/// `vertices` as given; `None` when it depends on an input not yet loaded.
fn finest_vertices(settings: &RetileStageSettings, sizes: &InputSizes) -> Option<u64> {
    if settings.edge_length > 0.0 {
        let e = f64::from(settings.edge_length);
        let count = EQUILATERAL_VERTICES_PER_AREA * sizes.area / (e * e);
        sizes.loaded.then(|| count.min(u64::MAX as f64) as u64)
    } else if settings.vertices == 0 {
        sizes
            .loaded
            .then(|| sizes.vertices_for_area(sizes.area / settings.texels_per_vertex) as u64)
    } else {
        Some(u64::from(settings.vertices))
    }
}

/// The `retile` stage.
pub struct Retile;

impl Stage for Retile {
    const KIND: &'static str = "retile";
    const SUMMARY: &'static str = "uniform re-tiling at a chosen density and the mesh pyramid (isotropic remeshing onto the input)";
    const PAPER: &'static str = "Wei & Levoy 2001 §3.1";
    type Settings = RetileStageSettings;

    fn requires(_: &Self::Settings) -> Vec<Datum> {
        vec![Datum::Mesh]
    }
    fn produces(_: &Self::Settings) -> Vec<Datum> {
        vec![Datum::MeshPyramid]
    }
    /// The remeshed pyramid and the remesher's work per finest vertex, and
    /// the input's projection tree per input triangle. The finest count is
    /// `vertices`, or derived from the texture scale (`vertices = 0`) or from
    /// `edge_length` and the input's area (then known only once it loads).
    fn memory_estimate(settings: &Self::Settings, sizes: &InputSizes) -> Vec<MemoryEstimate> {
        let input = BYTES_PER_INPUT_TRIANGLE * sizes.triangles;
        let bytes = move |v: u64| v.saturating_mul(BYTES_PER_VERTEX).saturating_add(input);
        let what =
            "the retiled pyramid and the remesher's work per vertex, the input's projection tree";
        if settings.edge_length > 0.0 {
            if !sizes.loaded {
                return Vec::new();
            }
            let per_area = EQUILATERAL_VERTICES_PER_AREA;
            let area = sizes.area;
            let count = finest_vertices(settings, sizes).unwrap_or(0);
            return vec![MemoryEstimate {
                param: "edge_length",
                value: format!("{} ({count} vertices on this input)", settings.edge_length),
                what: what.into(),
                bytes: bytes(count),
                fits: vec![Fit::with("edge_length", move |budget| {
                    let v = budget.saturating_sub(input) / BYTES_PER_VERTEX;
                    (v > 0).then(|| format!("{:.6} or more", (per_area * area / v as f64).sqrt()))
                })],
            }];
        }
        let derived = settings.vertices == 0;
        let Some(vertices) = finest_vertices(settings, sizes) else {
            return Vec::new();
        };
        let mut e = MemoryEstimate::growing(
            "vertices",
            what,
            vertices,
            (MIN_DERIVED_VERTICES as u64, MAX_VERTICES),
            bytes,
            |v| v.to_string(),
        );
        if derived {
            e.value = format!(
                "0, derived from [input] texture_scale: {vertices} (lower the vertex count by the texture scale, or set retile.vertices)"
            );
        }
        vec![e]
    }
    /// The finest level's vertices, as the estimate counts them.
    fn sizes_after(settings: &Self::Settings, sizes: &InputSizes) -> InputSizes {
        finest_vertices(settings, sizes).map_or(*sizes, |v| sizes.with_mesh(v))
    }
    /// The retiled mesh has vertices of its own.
    fn keeps_vertex_ids(_: &Self::Settings, _: &InputSizes) -> bool {
        false
    }
    fn systems(settings: Self::Settings, ctx: StageCtx) -> ScheduleConfigs<ScheduleSystem> {
        let retile = move |mut commands: Commands,
                           mut active: ResMut<ActiveMesh>,
                           seed: Res<RunSeed>,
                           texture_scale: Res<TextureScale>,
                           mut spacing: ResMut<TexelSpacing>,
                           mut metrics: ResMut<Metrics>,
                           sources: Query<(Entity, &Geometry), With<SourceMesh>>|
              -> SystemResult {
            let Ok((source_entity, source)) = sources.single() else {
                return Err("no input mesh to retile".into());
            };
            let target = settings.target(&source.0, &texture_scale, &mut metrics, ctx.index)?;
            let rs = RetileSettings {
                target,
                levels: settings.levels,
                iterations: settings.iterations,
                seed: seed.derive(ctx.index, 0),
            };
            let progress = Progress::new(0, Self::KIND);
            let _finish = progress.finish_on_drop();
            let pyramid = retile_with_progress(&source.0, &rs, &progress);
            progress.finish();
            let pyramid = pyramid.map_err(|e| e.to_string())?;
            record_input(&mut metrics, ctx.index, &pyramid.input);
            // The input is no longer a pyramid level: the retiled levels are.
            commands.entity(source_entity).remove::<MeshLevel>();
            if let Some((finest, edge)) =
                spawn_levels(&mut commands, pyramid.levels, &mut metrics, ctx.index)
            {
                spacing.0 = edge.max(f32::MIN_POSITIVE);
                active.0 = finest;
            }
            Ok(())
        };
        ctx.fallible(Self::KIND, retile)
    }
}
