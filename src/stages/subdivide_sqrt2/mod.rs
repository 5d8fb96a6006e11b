//! Stage `subdivide_sqrt2`: the √2 mesh hierarchy of Bangay & Morkel 2006
//! §3.2, built from the active (coarse) mesh upward: optional adaptive
//! passes that even out face areas (§3.2.2), then uniform √2 steps up to a
//! level count or a vertex budget (§3.2.1).
//!
//! Each level becomes an entity with `MeshLevel(l)` (0 = finest, as Wei &
//! Levoy's pyramid), its `Geometry` and `LevelParents` (parents in the next
//! coarser level); the `Sqrt2Pyramid` resource lists them and `ActiveMesh`
//! moves to the finest. Every per-vertex attribute of the active mesh
//! (`Frames`, `VertexColours`, `SourceTexels`, `SweepField`, `VertexScale`)
//! carries over to every level: old vertices keep their values bit for bit
//! (the scheme keeps vertices, §3.2.1 first bullet), face points get their
//! face's average. Per-corner data (UVs) does not carry over.
//!
//! Reads: the active mesh's `Geometry` and per-vertex attributes,
//! `TextureScale`. Writes: the level entities (`MeshLevel`, `Geometry`,
//! `LevelParents`, the carried attributes), `Sqrt2Pyramid`, `ActiveMesh`.
//! The attributes and the level entities are in `levels.rs`.

mod levels;

/// Carrying attributes through √2 parents, for stages that build on the
/// hierarchy (`diffuse_orientation`).
pub use crate::kernels::bangay_morkel::sqrt2::carry_attribute;

use crate::config::params::{ParamDoc, ParamRange, StageSettings};
use crate::kernels::bangay_morkel::sqrt2::{
    InputSurface, MAX_HIERARCHY_LEVELS, MAX_HIERARCHY_VERTICES, Sqrt2Settings, UniformLevels,
};
use crate::mesh::PolyMesh;
use crate::stage::memory::{InputSizes, MemoryEstimate};
use crate::stage::{Datum, Stage, StageCtx, SystemResult};
use crate::world::*;
use bevy_ecs::prelude::*;
use bevy_ecs::schedule::ScheduleConfigs;
use bevy_ecs::system::ScheduleSystem;
use levels::{Attributes, coarsen_dense, coarsest, record_levels, spawn_levels, uniform_levels};
use serde::{Deserialize, Serialize};

/// Settings of `subdivide_sqrt2`.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SubdivideSqrt2Settings {
    /// Uniform √2 steps; 0 = as many as `target_vertices` needs.
    pub levels: u32,
    /// Vertices the finest level should have (the level closest to it in
    /// ratio is the finest); 0 = with `levels` = 0, derived from `[input]
    /// texture_scale`; with `levels` > 0, no budget.
    pub target_vertices: u64,
    /// Adaptive passes on the coarse mesh before the uniform steps (§3.2.2).
    pub adaptive_passes: u32,
    /// Faces with area above this factor times the mean are refined in an
    /// adaptive pass (`f` of §3.2.2; the paper finds 1.5 good).
    pub adaptive_factor: f32,
    /// Weight of the neighbour average in the vertex rule of a uniform step
    /// (0 keeps old positions: an interpolating variant).
    pub vertex_relaxation: f32,
    /// Put every vertex of every level back on the input surface (the
    /// closest point on an input triangle facing the same way), so thin
    /// walls and sharp edges keep their shape; false = the subdivision
    /// surface itself (the paper's, which rounds edges and shrinks thin
    /// parts level by level).
    pub on_input_surface: bool,
    /// When the input is denser than the target (more than twice its
    /// vertices), start from the input remeshed coarse instead of a
    /// one-level hierarchy.
    pub coarsen_dense_input: bool,
}

impl Default for SubdivideSqrt2Settings {
    fn default() -> Self {
        Self {
            levels: 0,
            target_vertices: 0,
            adaptive_passes: 0,
            adaptive_factor: 1.5,
            vertex_relaxation: 0.5,
            on_input_surface: true,
            coarsen_dense_input: true,
        }
    }
}

impl StageSettings for SubdivideSqrt2Settings {
    const PARAMS: &'static [ParamDoc] = &[
        ParamDoc {
            name: "levels",
            unit: "steps",
            range: ParamRange::Int(0, MAX_HIERARCHY_LEVELS as i64),
            doc: "uniform √2 steps (each about doubles the vertices); 0 = as many as target_vertices (or the texture scale) needs",
        },
        ParamDoc {
            name: "target_vertices",
            unit: "vertices",
            range: ParamRange::Int(0, MAX_HIERARCHY_VERTICES as i64),
            doc: "vertices of the finest level: steps stop at the level closest to it in ratio (within √2); 0 = with levels = 0, surface area × (exemplar pixels per unit at [input] texture_scale)², one vertex per exemplar pixel²; with levels > 0, no budget",
        },
        ParamDoc {
            name: "adaptive_passes",
            unit: "passes",
            range: ParamRange::Int(0, 64),
            doc: "adaptive √2 passes on the coarse mesh before the uniform steps, refining faces larger than adaptive_factor × mean area (Bangay & Morkel §3.2.2)",
        },
        ParamDoc {
            name: "adaptive_factor",
            unit: "× mean face area",
            range: ParamRange::Float(1.0, 1000.0),
            doc: "area threshold f of an adaptive pass (≈ 1.5 for most models)",
        },
        ParamDoc {
            name: "vertex_relaxation",
            unit: "",
            range: ParamRange::Float(0.0, 1.0),
            doc: "weight of the neighbour average in the uniform step's vertex rule (0.5 = the box-spline rule; 0 keeps old positions)",
        },
        ParamDoc {
            name: "on_input_surface",
            unit: "",
            range: ParamRange::Any("true | false"),
            doc: "put every subdivided vertex back on the input surface (closest point on an input triangle facing the same way) and keep the input's corners (3+ face-normal directions over 30° apart) where they are: thin walls and sharp edges keep their shape (tests/it/subdivision.rs, perforated plate, 0.1 walls, four steps: two-sided Hausdorff 0.083 / 0.050 against 0.133 / 0.376 for the paper's surface); false = the paper's approximating surface, which rounds edges and shrinks thin parts",
        },
        ParamDoc {
            name: "coarsen_dense_input",
            unit: "",
            range: ParamRange::Any("true | false"),
            doc: "when the input has more than twice the target's vertices (a dense scan), the coarsest level is the input remeshed evenly (retile's remesher) to target / 2^s vertices (s ≤ 6, fewer when the input's pieces need more vertices), and √2 steps refine it back to the target on the input surface: synthesis runs at the texture's density, in time linear in the texture's area, and `map_back` then colours the input mesh; the input's vertex ids and attributes are not kept on the levels (key orientations by `at`/`at_bbox`). false = a one-level hierarchy on the input (the paper assumes a coarse input)",
        },
    ];

    fn check(&self) -> Result<(), (String, String)> {
        check_vertex_count(self.target_vertices, MAX_HIERARCHY_VERTICES as u64)
            .map_err(|m| ("target_vertices".into(), m))
    }
}

impl SubdivideSqrt2Settings {
    /// Most uniform steps: `levels`, or as many as the budget allows.
    fn max_steps(&self) -> u32 {
        if self.levels > 0 {
            self.levels.min(MAX_HIERARCHY_LEVELS)
        } else {
            MAX_HIERARCHY_LEVELS
        }
    }

    /// The finest level's vertex budget (0: none): `target_vertices`, or
    /// with `levels = 0` the `coarse` mesh's area at the texture scale
    /// (recorded).
    fn target(
        &self,
        texture_scale: &TextureScale,
        coarse: &PolyMesh,
        metrics: &mut Metrics,
        idx: usize,
    ) -> Result<usize, String> {
        Ok(match (self.levels, self.target_vertices) {
            (_, t) if t > 0 => t as usize,
            (0, _) => {
                let n = texture_scale.derived_vertices(
                    f64::from(coarse.area()),
                    "subdivide_sqrt2.target_vertices",
                    MAX_HIERARCHY_VERTICES,
                )?;
                metrics.record(idx, "target_vertices_from_texture_scale", n);
                n
            }
            _ => 0,
        })
    }
}

/// Bytes per finest vertex of the hierarchy at the stage's peak
/// (measured 218-220 from 10 000 to 160 000 vertices).
pub const BYTES_PER_VERTEX: u64 = 220;

/// The `subdivide_sqrt2` stage.
pub struct SubdivideSqrt2;

type SourceQuery<'w, 's> = Query<
    'w,
    's,
    (
        LevelFields,
        Option<&'static SweepField>,
        Option<&'static VertexScale>,
    ),
>;

impl Stage for SubdivideSqrt2 {
    const KIND: &'static str = "subdivide_sqrt2";
    const SUMMARY: &'static str = "√2-subdivision mesh hierarchy (adaptive passes, then uniform steps); attributes carry over";
    const PAPER: &'static str = "Bangay & Morkel 2006 §3.2; Li, Ma & Bao 2004";
    type Settings = SubdivideSqrt2Settings;

    fn requires(_: &Self::Settings) -> Vec<Datum> {
        vec![Datum::Mesh]
    }
    fn produces(_: &Self::Settings) -> Vec<Datum> {
        vec![Datum::MeshPyramid]
    }
    /// The hierarchy per finest vertex: `target_vertices`, derived from the
    /// texture scale (0 with `levels = 0`), or about the input's vertices
    /// doubled per level.
    fn memory_estimate(settings: &Self::Settings, sizes: &InputSizes) -> Vec<MemoryEstimate> {
        let Some(Finest {
            param,
            vertices,
            derived,
        }) = finest(settings, sizes)
        else {
            return Vec::new();
        };
        let bytes = |v: u64| v.saturating_mul(BYTES_PER_VERTEX);
        let what = "the √2 hierarchy's levels and parent links per finest vertex";
        if param == "levels" {
            let input = sizes.vertices;
            return vec![MemoryEstimate::growing(
                "levels",
                what,
                u64::from(settings.levels),
                (1, u64::from(MAX_HIERARCHY_LEVELS)),
                move |l| bytes(input.saturating_mul(1u64 << l.min(40))),
                |l| l.to_string(),
            )];
        }
        let mut e = MemoryEstimate::growing(
            "target_vertices",
            what,
            vertices,
            (MIN_DERIVED_VERTICES as u64, MAX_HIERARCHY_VERTICES as u64),
            bytes,
            |v| v.to_string(),
        );
        if derived {
            e.value = format!(
                "0, derived from [input] texture_scale: {vertices} (lower the vertex count by the texture scale, or set subdivide_sqrt2.target_vertices)"
            );
        }
        vec![e]
    }
    /// The finest level's vertices, as the estimate counts them.
    fn sizes_after(settings: &Self::Settings, sizes: &InputSizes) -> InputSizes {
        finest(settings, sizes).map_or(*sizes, |f| sizes.with_mesh(f.vertices))
    }
    /// The coarsest level is the input itself, ids and all, unless
    /// adaptive passes refine it or a dense input is remeshed
    /// (`levels::coarsen_dense`: more than twice the target's vertices).
    /// A target derived from the texture scale is computed in `f32` when
    /// the stage runs: within 1 % of the threshold the ids count as not
    /// kept.
    fn keeps_vertex_ids(settings: &Self::Settings, sizes: &InputSizes) -> bool {
        if settings.adaptive_passes > 0 {
            return false;
        }
        match (settings.levels, settings.target_vertices) {
            _ if !settings.coarsen_dense_input => true,
            (_, t) if t > 0 => sizes.vertices <= t.saturating_mul(2),
            (0, _) => (sizes.vertices as f64) < 1.98 * sizes.vertices_for_area(sizes.area),
            _ => true,
        }
    }
    fn systems(settings: Self::Settings, ctx: StageCtx) -> ScheduleConfigs<ScheduleSystem> {
        let subdivide = move |mut commands: Commands,
                              mut active: ResMut<ActiveMesh>,
                              texture_scale: Res<TextureScale>,
                              seed: Res<RunSeed>,
                              mut metrics: ResMut<Metrics>,
                              meshes: SourceQuery|
              -> SystemResult {
            let Ok(((geometry, frames, colours, texels), sweep, scale)) = meshes.get(active.0)
            else {
                return Ok(());
            };
            let input = &geometry.0;
            if input.face_count() == 0 {
                return Err("the mesh has no faces to subdivide".into());
            }
            let (idx, m) = (ctx.index, &mut *metrics);
            let nv = input.vertex_count();
            let mut attrs = Attributes::of(nv, frames, colours, texels, sweep, scale);
            // The input surface every level is put back on, with its corners.
            let surface = settings.on_input_surface.then(|| InputSurface::new(input));
            let surface = surface.as_ref();
            let mut coarse = coarsest(&settings, input, surface, &mut attrs, m, idx);
            let target = settings.target(&texture_scale, &coarse, m, idx)?;
            let seed = seed.derive(idx, 0xC0A5);
            coarsen_dense(&settings, &mut coarse, &mut attrs, target, seed, m, idx);
            // Uniform steps (§3.2.1), coarse to fine.
            let uniform = UniformLevels {
                step: Sqrt2Settings {
                    vertex_relaxation: settings.vertex_relaxation,
                },
                max_steps: settings.max_steps(),
                target,
            };
            let levels = uniform_levels(coarse, &uniform, surface);
            record_levels(&levels, target, m, idx);
            let entities = spawn_levels(&mut commands, levels, attrs);
            active.0 = entities[0];
            commands.insert_resource(Sqrt2Pyramid(entities));
            Ok(())
        };
        ctx.fallible(Self::KIND, subdivide)
    }
}
/// The finest level's vertex count as the settings decide it.
struct Finest {
    /// The parameter that decides it.
    param: &'static str,
    vertices: u64,
    /// Derived from the texture scale (`target_vertices = 0`).
    derived: bool,
}

/// `target_vertices`, derived from the texture scale (`levels = 0`), or the
/// input's vertices doubled per level; `None` while the input's sizes are
/// unknown.
fn finest(settings: &SubdivideSqrt2Settings, sizes: &InputSizes) -> Option<Finest> {
    let (param, vertices, derived) = match (settings.levels, settings.target_vertices) {
        (_, t) if t > 0 => ("target_vertices", t, false),
        _ if !sizes.loaded => return None,
        (0, _) => (
            "target_vertices",
            sizes.vertices_for_area(sizes.area) as u64,
            true,
        ),
        (l, _) => (
            "levels",
            sizes
                .vertices
                .saturating_mul(1u64 << l.min(MAX_HIERARCHY_LEVELS).min(40)),
            false,
        ),
    };
    Some(Finest {
        param,
        vertices,
        derived,
    })
}
