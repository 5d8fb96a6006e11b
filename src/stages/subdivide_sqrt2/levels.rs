//! The world side of the `subdivide_sqrt2` system: the per-vertex
//! attributes a level carries (read from the active mesh, carried through
//! each level's parents), the coarsest level (adaptive passes or a dense
//! input remeshed coarse), and the level entities.

use super::{SubdivideSqrt2, SubdivideSqrt2Settings};
use crate::kernels::bangay_morkel::sqrt2::{
    AreaStats, InputSurface, MAX_HIERARCHY_VERTICES, Parents, UniformLevels, adaptive_sqrt2,
    carry_attribute, carry_frames, carry_rows, coarsened_input, levels_towards,
};
use crate::kernels::surface::frames::TangentFrame;
use crate::mesh::PolyMesh;
use crate::progress::Progress;
use crate::stage::Stage;
use crate::world::*;
use bevy_ecs::prelude::*;
use glam::Vec2;

/// The per-vertex attributes a level carries.
#[derive(Clone, Debug, Default)]
pub(super) struct Attributes {
    frames: Option<Vec<TangentFrame>>,
    colours: Option<VertexColours>,
    texels: Option<Vec<Vec2>>,
    sweep: Option<Vec<f32>>,
    scale: Option<Vec<f32>>,
}

impl Attributes {
    /// The attributes of a mesh of `nv` vertices that fit it.
    pub fn of(
        nv: usize,
        frames: Option<&Frames>,
        colours: Option<&VertexColours>,
        texels: Option<&SourceTexels>,
        sweep: Option<&SweepField>,
        scale: Option<&VertexScale>,
    ) -> Self {
        let fits = |n: usize| n == nv;
        Self {
            frames: frames.map(|f| f.0.clone()).filter(|f| fits(f.len())),
            colours: colours
                .cloned()
                .filter(|c| fits(c.values.len() / c.channels.max(1))),
            texels: texels.map(|t| t.0.clone()).filter(|t| fits(t.len())),
            sweep: sweep.map(|s| s.0.clone()).filter(|s| fits(s.len())),
            scale: scale.map(|s| s.0.clone()).filter(|s| fits(s.len())),
        }
    }

    /// The attributes of the level refined from this one's through `parents`.
    pub fn carried(&self, parents: &Parents, mesh: &PolyMesh) -> Self {
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

/// The coarsest level: `input` after the adaptive passes (§3.2.2; put back
/// on `surface` when given, `attrs` carried), or `input` itself. Records
/// the face-area spread.
pub(super) fn coarsest(
    settings: &SubdivideSqrt2Settings,
    input: &PolyMesh,
    surface: Option<&InputSurface>,
    attrs: &mut Attributes,
    metrics: &mut Metrics,
    idx: usize,
) -> PolyMesh {
    if settings.adaptive_passes == 0 {
        let stats = AreaStats::of(input);
        metrics.record(idx, "area_std_percent_before", stats.std_percent_of_mean);
        return input.clone();
    }
    let mut a = adaptive_sqrt2(input, settings.adaptive_factor, settings.adaptive_passes);
    if let Some(surface) = surface {
        surface.project(&mut a.subdivided.mesh);
    }
    metrics.record(idx, "area_std_percent_before", a.before.std_percent_of_mean);
    metrics.record(idx, "area_std_percent_after", a.after.std_percent_of_mean);
    metrics.record(idx, "adaptive_refined_per_pass", &a.refined_per_pass);
    *attrs = attrs.carried(&a.subdivided.parents, &a.subdivided.mesh);
    a.subdivided.mesh
}

/// A dense `coarse` input (more than twice the `target`, with
/// `coarsen_dense_input` and no adaptive passes) remeshed coarse first, so
/// the hierarchy refines at the texture's density; its attributes are then
/// not kept (the remesh has other vertices).
pub(super) fn coarsen_dense(
    settings: &SubdivideSqrt2Settings,
    coarse: &mut PolyMesh,
    attrs: &mut Attributes,
    target: usize,
    seed: u64,
    metrics: &mut Metrics,
    idx: usize,
) {
    if !(settings.coarsen_dense_input
        && settings.adaptive_passes == 0
        && target > 0
        && coarse.vertex_count() > 2 * target)
    {
        return;
    }
    let progress = Progress::new(0, "subdivide_sqrt2 (remeshing the dense input)");
    let _finish = progress.finish_on_drop();
    match coarsened_input(coarse, target, seed, &progress) {
        Some((mesh, steps)) => {
            progress.finish();
            metrics.record(idx, "coarsened_input_vertices", coarse.vertex_count());
            metrics.record(idx, "coarsened_to", mesh.vertex_count());
            tracing::info!(
                "subdivide_sqrt2: the input has {} vertices for a target of {target}: remeshed to {} vertices, refined in about {steps} steps",
                coarse.vertex_count(),
                mesh.vertex_count()
            );
            *coarse = mesh;
            *attrs = Attributes::default();
        }
        None => tracing::warn!(
            "subdivide_sqrt2: the dense input could not be remeshed coarser (too many small pieces for {target} vertices); synthesising on the input itself"
        ),
    }
}

/// The levels of `uniform` steps from `coarse` ([`levels_towards`]) on one
/// progress bar, counted in vertices of the finest level: a step costs
/// about what it adds (V' = V + F, about 2V).
pub(super) fn uniform_levels(
    coarse: PolyMesh,
    uniform: &UniformLevels,
    surface: Option<&InputSurface>,
) -> Vec<(PolyMesh, Option<Parents>)> {
    let start_vertices = coarse.vertex_count();
    let expected = if uniform.target > 0 {
        uniform.target
    } else {
        start_vertices.saturating_mul(1 << uniform.max_steps.min(30))
    }
    .min(MAX_HIERARCHY_VERTICES)
    .max(start_vertices);
    let progress = Progress::new((expected - start_vertices) as u64, SubdivideSqrt2::KIND);
    let _finish = progress.finish_on_drop();
    let levels = levels_towards(coarse, uniform, surface, &progress);
    progress.finish();
    levels
}

/// Records the hierarchy's figures (`levels` coarse to fine), with a
/// warning when a `target` left it one level.
pub(super) fn record_levels(
    levels: &[(PolyMesh, Option<Parents>)],
    target: usize,
    metrics: &mut Metrics,
    idx: usize,
) {
    if target > 0 && levels.len() == 1 {
        let n = levels[0].0.vertex_count();
        tracing::warn!(
            "subdivide_sqrt2: the mesh already has {n} vertices for a target of {target}: the hierarchy has one level (no coarse-to-fine synthesis); give `levels` to force steps, or a smaller texture scale"
        );
        metrics.record(
            idx,
            "warning",
            format!("one-level hierarchy: {n} vertices for a target of {target}"),
        );
    }
    let sizes: Vec<usize> = levels.iter().map(|l| l.0.vertex_count()).collect();
    metrics.record(idx, "uniform_steps", levels.len() - 1);
    metrics.record(idx, "level_vertices_coarse_to_fine", &sizes);
    if let Some((finest, _)) = levels.last() {
        metrics.record(idx, "finest_faces", finest.face_count());
        metrics.record(
            idx,
            "finest_area_std_percent",
            AreaStats::of(finest).std_percent_of_mean,
        );
    }
}

/// Spawns the level entities (`levels` coarse to fine; `MeshLevel` 0 the
/// finest), each with its parents and the attributes carried down from
/// `attrs` (the coarsest level's); returns them finest first.
pub(super) fn spawn_levels(
    commands: &mut Commands,
    levels: Vec<(PolyMesh, Option<Parents>)>,
    attrs: Attributes,
) -> Vec<Entity> {
    let mut carried: Vec<Attributes> = Vec::with_capacity(levels.len());
    let mut first = Some(attrs);
    for (mesh, parents) in &levels {
        let a = match (parents, carried.last()) {
            (Some(p), Some(previous)) => previous.carried(p, mesh),
            _ => first.take().unwrap_or_default(),
        };
        carried.push(a);
    }
    let count = levels.len();
    let mut entities = vec![Entity::PLACEHOLDER; count];
    for (i, ((mesh, parents), attrs)) in levels.into_iter().zip(carried).enumerate() {
        let level = (count - 1 - i) as u8;
        let mut e = commands.spawn((MeshLevel(level), Geometry(mesh)));
        if let Some(p) = parents {
            e.insert(LevelParents(p));
        }
        attrs.insert(&mut e);
        entities[level as usize] = e.id();
    }
    entities
}
