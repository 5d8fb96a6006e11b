//! Mesh levels: the components of a mesh entity (geometry, frames, scales,
//! colours, texture coordinates, the 3-way blend layers), the pyramids the
//! multiresolution stages build (retile levels, the √2 hierarchy), and which
//! mesh the later stages work on ([`ActiveMesh`]). Everything is
//! structure-of-arrays: a vertex is a row (`u32` id) in each per-vertex array.

use crate::kernels::surface::frames::TangentFrame;
use crate::kernels::wei_levoy::relax_orientation::complete_frames;
use crate::mesh::PolyMesh;
use bevy_ecs::prelude::*;
use bevy_ecs::system::SystemParam;
use glam::{Vec2, Vec3};

/// Marks the mesh as loaded from `[input]`; it is never modified, so results
/// can be mapped back onto it.
#[derive(Component, Debug, Default)]
pub struct SourceMesh;

/// Pyramid level of a mesh entity: 0 is the finest.
#[derive(Component, Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub struct MeshLevel(pub u8);

/// Connectivity and positions of a mesh level.
#[derive(Component, Clone, Debug, Default)]
pub struct Geometry(pub PolyMesh);

/// Per-vertex tangent frames (s, t, n).
#[derive(Component, Clone, Debug, Default)]
pub struct Frames(pub Vec<TangentFrame>);

/// Per-vertex texture scale: exemplar texels per world unit.
#[derive(Component, Clone, Debug, Default)]
pub struct VertexScale(pub Vec<f32>);

/// Per-vertex colours, `channels` values per vertex, nominally in `[0, 1]`.
#[derive(Component, Clone, Debug, Default)]
pub struct VertexColours {
    /// Values per vertex (the exemplar's channel count).
    pub channels: usize,
    /// `values[v * channels + c]`.
    pub values: Vec<f32>,
}

/// Per-vertex source coordinate in the exemplar, in pixels (continuous, pixel
/// centres at `i + 0.5`): which exemplar texel each vertex colour came from, so
/// other exemplar channels can follow the same synthesis.
#[derive(Component, Clone, Debug, Default)]
pub struct SourceTexels(pub Vec<Vec2>);

/// Per-corner texture coordinates in `[0, 1]` units of the exemplar (v = 0 at
/// the exemplar's top row; values outside wrap when the exemplar tiles).
#[derive(Component, Clone, Debug, Default)]
pub struct CornerUvs(pub Vec<Vec2>);

/// Per fan triangle of the active mesh (see `PolyMesh::triangulate_corners`),
/// the texture coordinates of its three corners for each of the three choices
/// of base vertex: the 3-way blend of Zelinka & Garland §6.5, stored
/// compactly (per-vertex texels and per-corner side offsets; read through
/// [`BlendUvs::of`]).
#[derive(Component, Clone, Debug, Default)]
pub struct BlendUvs(pub crate::kernels::jump_maps::jump_surface::BlendLayers);

impl BlendUvs {
    /// The layers for `mesh`, or `None` when they were made for another mesh.
    pub fn of<'a>(
        &'a self,
        mesh: &'a crate::mesh::PolyMesh,
    ) -> Option<crate::kernels::jump_maps::jump_surface::Blend<'a>> {
        self.0
            .fits(mesh)
            .then_some(crate::kernels::jump_maps::jump_surface::Blend::Compact {
                layers: &self.0,
                mesh,
            })
    }
}

/// The mesh entity later stages work on and export: the source mesh until a
/// stage (retile, subdivide) makes a new finest level.
#[derive(Resource, Clone, Copy, Debug)]
pub struct ActiveMesh(pub Entity);

/// The entities of the mesh pyramid, finest level first: every entity with a
/// [`MeshLevel`] except the source mesh, or the source mesh alone (a one-level
/// pyramid) when there is no other. `levels` lists `(entity, level, is the
/// source mesh)`.
///
/// # Errors
/// A message naming the problem when the levels are not `0, 1, 2, …` each
/// exactly once.
pub fn pyramid_entities(
    levels: impl IntoIterator<Item = (Entity, MeshLevel, bool)>,
) -> Result<Vec<Entity>, String> {
    let all: Vec<(Entity, MeshLevel, bool)> = levels.into_iter().collect();
    let has_pyramid = all.iter().any(|(_, _, source)| !source);
    let mut chosen: Vec<(MeshLevel, Entity)> = all
        .into_iter()
        .filter(|(_, _, source)| *source != has_pyramid)
        .map(|(e, l, _)| (l, e))
        .collect();
    chosen.sort();
    for (i, (level, _)) in chosen.iter().enumerate() {
        if level.0 as usize != i {
            return Err(format!(
                "the mesh pyramid's levels are {:?}; expected 0, 1, 2, … each once",
                chosen.iter().map(|(l, _)| l.0).collect::<Vec<_>>()
            ));
        }
    }
    if chosen.is_empty() {
        return Err("there is no mesh".into());
    }
    Ok(chosen.into_iter().map(|(_, e)| e).collect())
}

/// The mesh levels a pyramid is picked from ([`pyramid_entities`]).
pub type PyramidLevels<'w, 's> =
    Query<'w, 's, (Entity, &'static MeshLevel, Has<SourceMesh>), With<Geometry>>;

/// What a synthesis stage reads of a mesh level: its geometry, frames,
/// colours and source texels.
pub type LevelFields = (
    &'static Geometry,
    Option<&'static Frames>,
    Option<&'static VertexColours>,
    Option<&'static SourceTexels>,
);

/// The [`LevelFields`] of mesh levels.
pub type LevelData<'w, 's> = Query<'w, 's, LevelFields>;

/// The mesh pyramid as a per-vertex synthesis stage (`match`, `coherent`)
/// reads it: the levels, their data, and the active mesh.
#[derive(SystemParam)]
pub struct Pyramid<'w, 's> {
    active: Res<'w, ActiveMesh>,
    levels: PyramidLevels<'w, 's>,
    /// Each level's data.
    pub data: LevelData<'w, 's>,
}

impl Pyramid<'_, '_> {
    /// The pyramid's levels (finest first, [`pyramid_entities`]) with their
    /// meshes and frames; a level without frames (or with the wrong count)
    /// takes frames transferred from the nearest level that has them, else
    /// from the active mesh when it lies outside the pyramid
    /// ([`complete_frames`]).
    ///
    /// # Errors
    /// As [`pyramid_entities`]; no level and not the active mesh has frames.
    pub fn input(&self) -> Result<PyramidInput<'_>, String> {
        let data = &self.data;
        let entities = pyramid_entities(self.levels.iter().map(|(e, l, s)| (e, *l, s)))?;
        let meshes: Vec<&PolyMesh> = entities
            .iter()
            .filter_map(|&e| data.get(e).ok().map(|d| &d.0.0))
            .collect();
        let given: Vec<Option<&[TangentFrame]>> = entities
            .iter()
            .map(|&e| data.get(e).ok().and_then(|d| d.1).map(|f| &f.0[..]))
            .collect();
        let active = data
            .get(self.active.0)
            .ok()
            .and_then(|(g, f, _, _)| f.map(|f| (&g.0, &f.0[..])))
            .filter(|(g, f)| f.len() == g.vertex_count());
        let frames = complete_frames(&meshes, &given, active)?;
        Ok(PyramidInput {
            entities,
            meshes,
            given,
            frames,
        })
    }
}

/// The levels of a [`Pyramid`]: their entities (finest first), their
/// meshes, the frames they carry and the frames of every level.
pub struct PyramidInput<'a> {
    /// Level entities, finest first.
    pub entities: Vec<Entity>,
    /// Their meshes.
    pub meshes: Vec<&'a PolyMesh>,
    /// Their own frames, where they have them.
    pub given: Vec<Option<&'a [TangentFrame]>>,
    /// Every level's frames: its own, or completed.
    pub frames: Vec<Vec<TangentFrame>>,
}

impl PyramidInput<'_> {
    /// Writes level `l`'s synthesised `colours` and their exemplar `texels`
    /// on its entity, and its completed frames where it had none of its
    /// own.
    pub fn write_level(
        &self,
        commands: &mut Commands,
        l: usize,
        colours: VertexColours,
        texels: Vec<Vec2>,
    ) {
        let mut e = commands.entity(self.entities[l]);
        e.insert((colours, SourceTexels(texels)));
        if self.given[l].is_none() {
            e.insert(Frames(self.frames[l].clone()));
        }
    }
}

/// Per-vertex sweep value (Turk 2001; Bangay & Morkel 2006 §3.1.1): grows
/// along the orientation field from an anchor; sorting by it gives the
/// synthesis order of the coarsest level.
#[derive(Component, Clone, Debug, Default)]
pub struct SweepField(pub Vec<f32>);

/// On a √2 hierarchy level: the parents of each of its vertices in the next
/// coarser level (`MeshLevel(l + 1)`), so attributes travel down the
/// hierarchy. Absent on the coarsest level.
#[derive(Component, Clone, Debug, Default)]
pub struct LevelParents(pub crate::kernels::bangay_morkel::sqrt2::Parents);

/// The √2 mesh hierarchy made by `subdivide_sqrt2`: its level entities,
/// finest first (index `l` holds `MeshLevel(l)`). Vertex ids are shared:
/// vertex `v` of a coarser level is vertex `v` of every finer one.
#[derive(Resource, Clone, Debug, Default)]
pub struct Sqrt2Pyramid(pub Vec<Entity>);

/// The per-face field `T` on a mesh entity (Praun et al. §3.2): in the face
/// plane, direction = texture up, length = world units per texture patch
/// unit (the patch image's larger side).
#[derive(Component, Clone, Debug, Default)]
pub struct FaceField {
    /// One vector per face.
    pub t: Vec<Vec3>,
    /// Isotropic texture: only the lengths matter.
    pub isotropic: bool,
    /// The lengths are world units per exemplar PIXEL (the field follows
    /// `[input] texture_scale`; `lapped_paste` multiplies by the patch
    /// image's side, so the texture shows at that scale whatever the patch
    /// size), rather than per texture patch (an explicit `patch_size`).
    pub per_pixel: bool,
}
