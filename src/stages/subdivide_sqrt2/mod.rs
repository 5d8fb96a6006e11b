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

use crate::config::params::{ParamDoc, ParamRange, StageSettings};
use crate::kernels::bangay_morkel::sqrt2::{
    AreaStats, MAX_HIERARCHY_LEVELS, MAX_HIERARCHY_VERTICES, Parents, Sqrt2Settings,
    adaptive_sqrt2, sqrt2_subdivide_with,
};
use crate::kernels::surface::frames::TangentFrame;
use crate::progress::Progress;
use crate::stage::memory::{InputSizes, MemoryEstimate};
use crate::stage::{Datum, Stage, StageCtx};
use crate::world::*;
use bevy_ecs::prelude::*;
use bevy_ecs::schedule::ScheduleConfigs;
use bevy_ecs::system::ScheduleSystem;
use glam::{Vec2, Vec3};
use serde::{Deserialize, Serialize};
use std::ops::{Add, Mul};

/// Moves every vertex of `mesh` to the closest point of the input surface
/// on a triangle facing the same way as the vertex normal (so a point near
/// a thin wall is not snapped onto its far side). Parallel, deterministic.
fn onto_surface(
    projector: &crate::kernels::wei_levoy::retile::SurfaceProjector,
    mesh: &mut crate::mesh::PolyMesh,
) {
    use rayon::prelude::*;
    let normals = mesh.vertex_normals();
    mesh.positions
        .par_iter_mut()
        .zip(normals.par_iter())
        .for_each(|(p, &n)| {
            if let Some(hit) = projector.project_facing(*p, n, u32::MAX) {
                *p = hit.point;
            }
        });
}

/// Angle between two faces' normals above which their shared vertex is on
/// a feature of the input: 30°.
const FEATURE_COS: f32 = 0.866;

/// A position's exact bits, to find a vertex again by where it is.
fn position_key(p: Vec3) -> [u32; 3] {
    [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()]
}

/// The positions (as [`position_key`]s) of the input's corners: vertices
/// whose incident faces' normals fall into three or more directions more
/// than 30° apart (a box corner; a crease has two). Degenerate faces are
/// ignored.
fn corner_keys(mesh: &crate::mesh::PolyMesh) -> std::collections::HashSet<[u32; 3]> {
    let normals = mesh.face_normals();
    // Per vertex, up to three directions found so far.
    let mut around = vec![([Vec3::ZERO; 3], 0u8); mesh.vertex_count()];
    for (f, face) in mesh.faces().enumerate() {
        let n = normals[f];
        if !n.is_finite() || n.length_squared() < 0.5 {
            continue;
        }
        for &v in face {
            let (dirs, count) = &mut around[v as usize];
            if *count < 3
                && dirs[..*count as usize]
                    .iter()
                    .all(|c| c.dot(n) < FEATURE_COS)
            {
                dirs[*count as usize] = n;
                *count += 1;
            }
        }
    }
    around
        .iter()
        .zip(&mesh.positions)
        .filter(|((_, count), _)| *count >= 3)
        .map(|(_, &p)| position_key(p))
        .collect()
}

/// Puts the vertices of `after` that sat on one of `corners` in `before`
/// (the same ids: a √2 step keeps its old vertices' ids) back on it: the
/// vertex rule and the projection would move a corner along the surface,
/// rounding it off.
fn keep_corners(
    corners: &std::collections::HashSet<[u32; 3]>,
    before: &crate::mesh::PolyMesh,
    after: &mut crate::mesh::PolyMesh,
) {
    if corners.is_empty() {
        return;
    }
    for (v, &p) in before.positions.iter().enumerate() {
        if corners.contains(&position_key(p)) {
            after.positions[v] = p;
        }
    }
}

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

/// Most uniform steps above a coarsened input: its remesh has at least
/// `target / 2^COARSEN_STEPS` vertices.
const COARSEN_STEPS: u32 = 6;

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

/// `input` remeshed evenly (one level of `retile`'s isotropic remesher) to
/// `target / 2^s` vertices for the largest `s ≤ COARSEN_STEPS` whose count
/// the input's connected pieces allow (at least 12 vertices), with `s`;
/// `None` when not even `target / 2` is possible. When the pieces need more
/// vertices than asked, retile names the floor, and the next try starts at
/// the first count above it rather than one step finer.
fn coarsened(
    input: &crate::mesh::PolyMesh,
    target: usize,
    seed: u64,
) -> Option<(crate::mesh::PolyMesh, u32)> {
    use crate::kernels::wei_levoy::retile::{RetileError, RetileSettings, retile_with_progress};
    let progress = Progress::new(0, "subdivide_sqrt2 (remeshing the dense input)");
    let _finish = progress.finish_on_drop();
    let mut at_least = RetileSettings::MIN_LEVEL_VERTICES as usize;
    for steps in (1..=COARSEN_STEPS).rev() {
        let n = target >> steps;
        if (n as f64) * (1.0 + RetileSettings::COUNT_TOLERANCE) < at_least as f64 {
            continue;
        }
        let settings = RetileSettings {
            levels: 1,
            seed,
            ..RetileSettings::with_vertices(n as u32)
        };
        match retile_with_progress(input, &settings, &progress) {
            Ok(mut p) => {
                let level = p.levels.swap_remove(0);
                // The surface's thin parts kept it above its target: try a
                // finer base.
                if (level.mesh.vertex_count() as f64)
                    > (1.0 + RetileSettings::COUNT_TOLERANCE) * level.target_vertices as f64
                {
                    continue;
                }
                progress.finish();
                return Some((level.mesh, steps));
            }
            // Too many pieces for so few vertices: a base above their floor.
            Err(RetileError::TooManyComponents { floor, .. }) => at_least = floor,
            Err(_) => return None,
        }
    }
    None
}

/// Carries a per-vertex attribute to a refined level: identity parents copy
/// the value exactly, others take the weighted sum of their parents.
pub fn carry_attribute<T>(parents: &Parents, old: &[T]) -> Vec<T>
where
    T: Copy + Add<Output = T> + Mul<f32, Output = T>,
{
    (0..parents.len())
        .map(|v| {
            let (pv, pw) = parents.of(v);
            match (pv, pw) {
                ([s], [w]) if *w == 1.0 => old[*s as usize],
                _ => {
                    let mut acc = old[pv[0] as usize] * pw[0];
                    for (&s, &w) in pv.iter().zip(pw).skip(1) {
                        acc = acc + old[s as usize] * w;
                    }
                    acc
                }
            }
        })
        .collect()
}

/// [`carry_attribute`] for rows of `channels` values (colours).
pub fn carry_rows(parents: &Parents, old: &[f32], channels: usize) -> Vec<f32> {
    let mut out = vec![0.0f32; parents.len() * channels];
    for (v, row) in out.chunks_exact_mut(channels.max(1)).enumerate() {
        let (pv, pw) = parents.of(v);
        match (pv, pw) {
            ([s], [w]) if *w == 1.0 => {
                let s = *s as usize;
                row.copy_from_slice(&old[s * channels..(s + 1) * channels]);
            }
            _ => {
                for (&s, &w) in pv.iter().zip(pw) {
                    let s = s as usize;
                    for (o, &x) in row.iter_mut().zip(&old[s * channels..(s + 1) * channels]) {
                        *o += x * w;
                    }
                }
            }
        }
    }
    out
}

/// Carries frames: old vertices keep theirs exactly; a new vertex takes its
/// parents' mean up direction on its own normal.
pub fn carry_frames(
    parents: &Parents,
    old: &[TangentFrame],
    normals: &[Vec3],
) -> Vec<TangentFrame> {
    let ups: Vec<Vec3> = old.iter().map(|f| f.t).collect();
    let carried = carry_attribute(parents, &ups);
    (0..parents.len())
        .map(|v| match parents.of(v) {
            ([s], [w]) if *w == 1.0 => old[*s as usize],
            _ => TangentFrame::from_up(normals[v], carried[v]),
        })
        .collect()
}

/// The per-vertex attributes a level carries.
#[derive(Clone, Debug, Default)]
struct Attributes {
    frames: Option<Vec<TangentFrame>>,
    colours: Option<VertexColours>,
    texels: Option<Vec<Vec2>>,
    sweep: Option<Vec<f32>>,
    scale: Option<Vec<f32>>,
}

impl Attributes {
    fn carried(&self, parents: &Parents, mesh: &crate::mesh::PolyMesh) -> Self {
        Self {
            frames: self
                .frames
                .as_ref()
                .map(|f| carry_frames(parents, f, &mesh.vertex_normals())),
            colours: self.colours.as_ref().map(|c| VertexColours {
                channels: c.channels,
                values: carry_rows(parents, &c.values, c.channels),
            }),
            texels: self.texels.as_ref().map(|t| carry_attribute(parents, t)),
            sweep: self.sweep.as_ref().map(|s| carry_attribute(parents, s)),
            scale: self.scale.as_ref().map(|s| carry_attribute(parents, s)),
        }
    }

    fn insert(self, e: &mut EntityCommands) {
        if let Some(f) = self.frames {
            e.insert(Frames(f));
        }
        if let Some(c) = self.colours {
            e.insert(c);
        }
        if let Some(t) = self.texels {
            e.insert(SourceTexels(t));
        }
        if let Some(s) = self.sweep {
            e.insert(SweepField(s));
        }
        if let Some(s) = self.scale {
            e.insert(VertexScale(s));
        }
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
        &'static Geometry,
        Option<&'static Frames>,
        Option<&'static VertexColours>,
        Option<&'static SourceTexels>,
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
        let (param, vertices, derived) = match (settings.levels, settings.target_vertices) {
            (_, t) if t > 0 => ("target_vertices", t, false),
            (0, _) if sizes.loaded => (
                "target_vertices",
                sizes.vertices_for_area(sizes.area) as u64,
                true,
            ),
            (0, _) => return Vec::new(),
            (l, _) if sizes.loaded => (
                "levels",
                sizes
                    .vertices
                    .saturating_mul(1u64 << l.min(MAX_HIERARCHY_LEVELS).min(40)),
                false,
            ),
            _ => return Vec::new(),
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
    fn systems(settings: Self::Settings, ctx: StageCtx) -> ScheduleConfigs<ScheduleSystem> {
        (move |mut commands: Commands,
               mut active: ResMut<ActiveMesh>,
               texture_scale: Res<TextureScale>,
               seed: Res<RunSeed>,
               mut metrics: ResMut<Metrics>,
               mut failure: ResMut<StageFailure>,
               meshes: SourceQuery| {
            let Ok((geometry, frames, colours, texels, sweep, scale)) = meshes.get(active.0) else {
                return;
            };
            let input = &geometry.0;
            if input.face_count() == 0 {
                failure.0 = Some(crate::stage::StageError {
                    index: ctx.index + 1,
                    kind: Self::KIND.into(),
                    message: "the mesh has no faces to subdivide".into(),
                });
                return;
            }
            let nv = input.vertex_count();
            let fits = |n: usize| n == nv;
            let mut attrs = Attributes {
                frames: frames.map(|f| f.0.clone()).filter(|f| fits(f.len())),
                colours: colours
                    .cloned()
                    .filter(|c| fits(c.values.len() / c.channels.max(1))),
                texels: texels.map(|t| t.0.clone()).filter(|t| fits(t.len())),
                sweep: sweep.map(|s| s.0.clone()).filter(|s| fits(s.len())),
                scale: scale.map(|s| s.0.clone()).filter(|s| fits(s.len())),
            };
            let idx = ctx.index;
            // The input surface every level is put back on.
            let projector = settings
                .on_input_surface
                .then(|| crate::kernels::wei_levoy::retile::SurfaceProjector::new(input));
            // Its corners, which every level keeps where it has them.
            let corners = if settings.on_input_surface {
                corner_keys(input)
            } else {
                Default::default()
            };
            // Adaptive passes make the coarsest level (§3.2.2).
            let coarse = if settings.adaptive_passes > 0 {
                let mut a =
                    adaptive_sqrt2(input, settings.adaptive_factor, settings.adaptive_passes);
                if let Some(projector) = &projector {
                    onto_surface(projector, &mut a.subdivided.mesh);
                }
                metrics.record(idx, "area_std_percent_before", a.before.std_percent_of_mean);
                metrics.record(idx, "area_std_percent_after", a.after.std_percent_of_mean);
                metrics.record(idx, "adaptive_refined_per_pass", &a.refined_per_pass);
                attrs = attrs.carried(&a.subdivided.parents, &a.subdivided.mesh);
                a.subdivided.mesh
            } else {
                let stats = AreaStats::of(input);
                metrics.record(idx, "area_std_percent_before", stats.std_percent_of_mean);
                input.clone()
            };
            // Uniform steps (§3.2.1), coarse to fine.
            let step_settings = Sqrt2Settings {
                vertex_relaxation: settings.vertex_relaxation,
            };
            let max_steps = if settings.levels > 0 {
                settings.levels.min(MAX_HIERARCHY_LEVELS)
            } else {
                MAX_HIERARCHY_LEVELS
            };
            let target = match (settings.levels, settings.target_vertices) {
                (_, t) if t > 0 => t as usize,
                (0, _) => {
                    let area = f64::from(coarse.area());
                    match texture_scale.derived_vertices(
                        area,
                        "subdivide_sqrt2.target_vertices",
                        MAX_HIERARCHY_VERTICES,
                    ) {
                        Ok(n) => {
                            metrics.record(idx, "target_vertices_from_texture_scale", n);
                            n
                        }
                        Err(message) => {
                            failure.0 = Some(crate::stage::StageError {
                                index: ctx.index + 1,
                                kind: Self::KIND.into(),
                                message,
                            });
                            return;
                        }
                    }
                }
                _ => 0,
            };
            // A dense input (more than twice the target) is remeshed coarse
            // first, so the hierarchy refines at the texture's density.
            let mut coarse = coarse;
            if settings.coarsen_dense_input
                && settings.adaptive_passes == 0
                && target > 0
                && coarse.vertex_count() > 2 * target
            {
                match coarsened(&coarse, target, seed.derive(idx, 0xC0A5)) {
                    Some((mesh, steps)) => {
                        metrics.record(idx, "coarsened_input_vertices", coarse.vertex_count());
                        metrics.record(idx, "coarsened_to", mesh.vertex_count());
                        tracing::info!(
                            "subdivide_sqrt2: the input has {} vertices for a target of {target}: remeshed to {} vertices, refined in about {steps} steps",
                            coarse.vertex_count(),
                            mesh.vertex_count()
                        );
                        coarse = mesh;
                        attrs = Attributes::default();
                    }
                    None => tracing::warn!(
                        "subdivide_sqrt2: the dense input could not be remeshed coarser (too many small pieces for {target} vertices); synthesising on the input itself"
                    ),
                }
            }
            // Counted in vertices of the finest level: a step costs about
            // what it adds (V' = V + F, about 2V).
            let start_vertices = coarse.vertex_count();
            let expected = if target > 0 {
                target
            } else {
                start_vertices.saturating_mul(1 << max_steps.min(30))
            }
            .min(MAX_HIERARCHY_VERTICES)
            .max(start_vertices);
            let progress = Progress::new((expected - start_vertices) as u64, Self::KIND);
            let _finish = progress.finish_on_drop();
            let mut levels: Vec<(crate::mesh::PolyMesh, Option<Parents>, Attributes)> =
                vec![(coarse, None, attrs)];
            for step in 0..max_steps {
                let (current, _, current_attrs) = levels.last().expect("one level at least");
                let (nv, nf) = (current.vertex_count(), current.face_count());
                if (target > 0 && nv >= target) || nf == 0 || nv + nf > MAX_HIERARCHY_VERTICES {
                    break;
                }
                progress.set_part(&format!("step {}", step + 1));
                let mut sub = sqrt2_subdivide_with(current, &step_settings);
                if let Some(projector) = &projector {
                    onto_surface(projector, &mut sub.mesh);
                    keep_corners(&corners, current, &mut sub.mesh);
                }
                let next_attrs = current_attrs.carried(&sub.parents, &sub.mesh);
                progress.inc(sub.mesh.vertex_count().saturating_sub(nv) as u64);
                levels.push((sub.mesh, Some(sub.parents), next_attrs));
            }
            progress.finish();
            // The finest level is the one closest to the target in ratio: the
            // step past it may overshoot by up to 2x (V' = V + F).
            if target > 0 && levels.len() >= 2 {
                let n = |i: usize| levels[i].0.vertex_count() as f64;
                let (last, prev) = (n(levels.len() - 1), n(levels.len() - 2));
                if last >= target as f64 && last / target as f64 > target as f64 / prev {
                    levels.pop();
                }
            }
            if target > 0 && levels.len() == 1 {
                let n = levels[0].0.vertex_count();
                tracing::warn!(
                    "subdivide_sqrt2: the mesh already has {n} vertices for a target of {target}: the hierarchy has one level (no coarse-to-fine synthesis); give `levels` to force steps, or a smaller texture scale"
                );
                metrics.record(idx, "warning", format!("one-level hierarchy: {n} vertices for a target of {target}"));
            }
            let count = levels.len();
            let sizes: Vec<usize> = levels.iter().map(|l| l.0.vertex_count()).collect();
            metrics.record(idx, "uniform_steps", count - 1);
            metrics.record(idx, "level_vertices_coarse_to_fine", &sizes);
            if let Some((finest, _, _)) = levels.last() {
                metrics.record(idx, "finest_faces", finest.face_count());
                metrics.record(
                    idx,
                    "finest_area_std_percent",
                    AreaStats::of(finest).std_percent_of_mean,
                );
            }
            let mut entities = vec![Entity::PLACEHOLDER; count];
            for (i, (mesh, parents, attrs)) in levels.into_iter().enumerate() {
                let level = (count - 1 - i) as u8;
                let mut e = commands.spawn((MeshLevel(level), Geometry(mesh)));
                if let Some(p) = parents {
                    e.insert(LevelParents(p));
                }
                attrs.insert(&mut e);
                entities[level as usize] = e.id();
            }
            active.0 = entities[0];
            commands.insert_resource(Sqrt2Pyramid(entities));
        })
        .into_configs()
    }
}
