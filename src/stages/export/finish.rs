//! After the schedule: the arrays the `export` stage named move (or are
//! copied) out of the world into the export job, once it is checked that
//! no later stage changed them.

use super::Export;
use crate::stage::{Stage, StageError};
use crate::world::*;
use bevy_ecs::prelude::*;

/// How [`finish_export_job`] gets the arrays out of the world.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Transfer {
    /// Copies them: the world stays whole (tests read it after a run).
    Copy,
    /// Moves them out, leaving empty components: for a runner that drops
    /// the world before writing files.
    Move,
}

/// Fills the export job's mesh, colours and texture coordinates from the
/// entity the `export` stage named ([`ExportSource`]). The export system
/// does not copy them: at a million vertices they are ~100 bytes per vertex
/// the run would otherwise hold twice through the result metrics.
///
/// # Errors
/// When a stage after `export` changed the exported mesh, colours or
/// coordinates (the previews show the state at export time, the files would
/// not): put `export` last.
pub fn finish_export_job(world: &mut World, transfer: Transfer) -> Result<(), StageError> {
    if world.resource::<ExportJob>().take_baked_asset {
        if transfer == Transfer::Copy {
            // The world stays whole for its readers: its asset gets the
            // mesh it refers to.
            fill_asset_mesh(world);
        }
        let asset = match transfer {
            Transfer::Copy => world.get_resource::<BakedAsset>().cloned(),
            Transfer::Move => world.remove_resource::<BakedAsset>(),
        };
        let mut job = world.resource_mut::<ExportJob>();
        job.baked_asset = asset;
        job.take_baked_asset = false;
    }
    let Some(source) = world.resource::<ExportJob>().source.clone() else {
        asset_mesh_from_source(world);
        return Ok(());
    };
    let e = source.entity;
    let now = world.read_change_tick();
    let entity = world.get_entity(e).map_err(|_| StageError {
        index: source.stage,
        kind: Export::KIND.into(),
        message:
            "the exported mesh entity is gone: a stage after `export` removed it; put `export` last"
                .into(),
    })?;
    let changed = |t: Option<bevy_ecs::change_detection::Tick>| {
        t.is_some_and(|t| t.is_newer_than(source.tick, now))
    };
    if changed(entity.get_ref::<Geometry>().map(|r| r.last_changed()))
        || changed(entity.get_ref::<VertexColours>().map(|r| r.last_changed()))
        || changed(entity.get_ref::<CornerUvs>().map(|r| r.last_changed()))
        || changed(entity.get_ref::<AtlasTexture>().map(|r| r.last_changed()))
    {
        return Err(StageError {
            index: source.stage,
            kind: Export::KIND.into(),
            message: "a stage after `export` changed the mesh it exports; put `export` last".into(),
        });
    }
    // The pastes are read here, not at export time: one a later stage made
    // or changed would be written but not previewed.
    if source.pastes.is_some() {
        let mut q = world.query::<(
            &PasteOf,
            bevy_ecs::change_detection::Ref<PatchFaces>,
            bevy_ecs::change_detection::Ref<PatchUvs>,
        )>();
        if q.iter(world).any(|(of, faces, uvs)| {
            of.0 == e && (changed(Some(faces.last_changed())) || changed(Some(uvs.last_changed())))
        }) {
            return Err(StageError {
                index: source.stage,
                kind: Export::KIND.into(),
                message: "a stage after `export` changed the pastes it exports; put `export` last"
                    .into(),
            });
        }
    }
    fn get<T: Component<Mutability = bevy_ecs::component::Mutable> + Clone + Default>(
        world: &mut World,
        e: Entity,
        transfer: Transfer,
    ) -> Option<T> {
        match transfer {
            Transfer::Copy => world.get::<T>(e).cloned(),
            Transfer::Move => world.get_mut::<T>(e).map(|mut c| std::mem::take(&mut *c)),
        }
    }
    let mesh = get::<Geometry>(world, e, transfer).unwrap_or_default().0;
    let colours = if source.colours {
        get::<VertexColours>(world, e, transfer)
    } else {
        None
    };
    let uvs = match source.uvs {
        ExportUvs::None => None,
        ExportUvs::Corner => get::<CornerUvs>(world, e, transfer)
            .map(|u| (u.0, world.resource::<Exemplar>().image.clone())),
        ExportUvs::Atlas => get::<AtlasTexture>(world, e, transfer).map(|a| (a.uvs, a.image)),
    };
    let pastes = source.pastes.map(|textures| PasteExport {
        pastes: runtime_pastes(world, e, &mesh, transfer),
        textures,
    });
    let mut job = world.resource_mut::<ExportJob>();
    job.mesh = mesh;
    job.pastes = pastes;
    job.colours = colours;
    job.uvs = uvs;
    job.source = None;
    // Last, when the mesh may have moved into the job: the asset's copy.
    asset_mesh_from_source(world);
    Ok(())
}

/// Gives the world's [`BakedAsset`] the source mesh it refers to.
fn fill_asset_mesh(world: &mut World) {
    if !world
        .get_resource::<BakedAsset>()
        .is_some_and(|a| a.on_source)
    {
        return;
    }
    let mesh = source_geometry(world).unwrap_or_default();
    let mut asset = world.resource_mut::<BakedAsset>();
    asset.mesh = mesh;
    asset.on_source = false;
}

/// Gives the export job's asset the source mesh it refers to: the job's
/// mesh when the source mesh was exported (and so moved into the job),
/// else the world's.
fn asset_mesh_from_source(world: &mut World) {
    if !world
        .resource::<ExportJob>()
        .baked_asset
        .as_ref()
        .is_some_and(|a| a.on_source)
    {
        return;
    }
    let from_world = source_geometry(world).filter(|m| m.face_count() > 0);
    let mut job = world.resource_mut::<ExportJob>();
    let mesh = from_world.unwrap_or_else(|| job.mesh.clone());
    if let Some(asset) = job.baked_asset.as_mut() {
        asset.mesh = mesh;
        asset.on_source = false;
    }
}

/// A copy of the source mesh's geometry.
fn source_geometry(world: &mut World) -> Option<crate::mesh::PolyMesh> {
    let mut q = world.query_filtered::<&Geometry, With<SourceMesh>>();
    q.iter(world).next().map(|g| g.0.clone())
}

/// The runtime-pasting export of the pastes of `mesh_entity` (Praun et al.
/// §4), in paste order: per paste, only the faces still drawn, with their
/// corners' texture coordinates. With [`Transfer::Move`] the paste entities'
/// arrays are moved out (the lapped stage keeps only drawn faces, so they
/// are the records as they are), not copied: at a million vertices they
/// are ~80 bytes per vertex that were held twice through the result
/// metrics.
fn runtime_pastes(
    world: &mut World,
    mesh_entity: Entity,
    mesh: &crate::mesh::PolyMesh,
    transfer: Transfer,
) -> Vec<PasteRecord> {
    let mut query = world.query::<(Entity, &PasteOf, &PasteOrder)>();
    let mut order: Vec<(u32, Entity)> = query
        .iter(world)
        .filter(|(_, of, _)| of.0 == mesh_entity)
        .map(|(e, _, o)| (o.0, e))
        .collect();
    order.sort_unstable();
    order
        .into_iter()
        .filter_map(|(_, e)| {
            let mut paste = world.get_entity_mut(e).ok()?;
            let texture = paste.get::<TexturePatchIndex>()?.0;
            let drawn = paste.get::<PatchDrawn>()?.0.clone();
            let (faces, uvs) = match transfer {
                Transfer::Copy => (
                    paste.get::<PatchFaces>()?.0.clone(),
                    paste.get::<PatchUvs>()?.0.clone(),
                ),
                Transfer::Move => (
                    std::mem::take(&mut paste.get_mut::<PatchFaces>()?.0),
                    std::mem::take(&mut paste.get_mut::<PatchUvs>()?.0),
                ),
            };
            if drawn.iter().all(|&d| d) {
                return Some(PasteRecord {
                    texture,
                    faces,
                    uvs,
                });
            }
            let mut record = PasteRecord {
                texture,
                ..Default::default()
            };
            let mut offset = 0usize;
            for (&f, &draw) in faces.iter().zip(&drawn) {
                let n = mesh.face_corners(f as usize).len();
                if draw {
                    record.faces.push(f);
                    record.uvs.extend_from_slice(&uvs[offset..offset + n]);
                }
                offset += n;
            }
            Some(record)
        })
        .collect()
}
