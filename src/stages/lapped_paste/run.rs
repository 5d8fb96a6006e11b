//! The phases of the `lapped_paste` system around its kernels: the check
//! of the mesh and field, the paste loop on the mesh lent as a triangle
//! mesh, the atlas's compositing, the paste entities; and its metrics.

use super::LappedPasteSettings;
use crate::image::Image;
use crate::kernels::lapped::FaceField as FieldView;
use crate::kernels::lapped::TriMesh;
use crate::kernels::lapped::atlas::{AtlasLayout, AtlasSettings, composite_pastes};
use crate::kernels::lapped::composite::PasteRecord;
use crate::kernels::lapped::mask::TexturePatch;
use crate::kernels::lapped::paste::{DrawnPaste, PasteSettings, RuntimePastes, paste_for_runtime};
use crate::kernels::lapped::patch_cache::texture_patches_cached;
use crate::mesh::PolyMesh;
use crate::progress::Progress;
use crate::world::*;
use bevy_ecs::prelude::*;

/// Refuses a mesh the paste loop cannot work on (triangles only), or a
/// field that does not fit it.
pub(super) fn check_fit(mesh: &PolyMesh, field: &FaceField) -> Result<(), String> {
    TriMesh::check(mesh).map_err(|e| e.to_string())?;
    if field.t.len() != mesh.face_count() {
        return Err(
            "the tangent field does not fit the mesh; run `tangent_field` after the last stage that changes the mesh".into(),
        );
    }
    Ok(())
}

/// Pastes `textures` onto `mesh` along `field` until it is covered, keeping
/// the faces runtime pasting draws ([`paste_for_runtime`]); with the
/// result's texel spacing (world units per exemplar texel, for the quality
/// metrics).
///
/// The loop takes the mesh's positions and corners instead of copying them
/// (callers pass the mesh without change detection); they go back right
/// after it, unchanged, and on an error.
pub(super) fn paste(
    mesh: &mut PolyMesh,
    field: &FaceField,
    textures: &[TexturePatch],
    settings: &PasteSettings,
    progress: &Progress,
) -> Result<(RuntimePastes, f32), String> {
    let unit_px = textures
        .iter()
        .map(TexturePatch::unit_px)
        .fold(1.0f32, f32::max);
    // A field in world units per pixel is read in patch units (scaled as
    // it is read, not copied).
    let view = FieldView {
        t: &field.t,
        isotropic: field.isotropic,
        scale: if field.per_pixel { unit_px } else { 1.0 },
    };
    let tri = match TriMesh::from_owned(std::mem::take(mesh)) {
        Ok(t) => t,
        Err((given, e)) => {
            *mesh = given;
            return Err(e.to_string());
        }
    };
    let out = paste_for_runtime(&tri, view, textures, settings, progress);
    *mesh = tri.into_poly_mesh();
    let spacing = (view.mean_length() as f32 / unit_px).max(f32::MIN_POSITIVE);
    Ok((out, spacing))
}

/// The texture patches of `settings` cut from the exemplar, through the
/// analysis cache when `cache` is on (a user `mask` is never cached).
pub(super) fn cut_textures(
    exemplar: &Exemplar,
    settings: &LappedPasteSettings,
    mask: Option<&Image>,
    seed: u64,
) -> Result<Vec<TexturePatch>, String> {
    let _span = tracing::info_span!("texture_patches").entered();
    let store = crate::cache::DiskCache::if_enabled(settings.cache);
    texture_patches_cached(
        &exemplar.image,
        exemplar.wrap,
        &settings.cut_settings(),
        mask,
        seed,
        store.as_ref().map(|s| s as _),
    )
}

/// Composites the `pasted` pastes into the atlas laid out before the paste
/// loop (Praun et al. §4), if there is one, and records the atlas's
/// metrics; a layout or a compositing that failed is recorded as skipped
/// (no atlas).
pub(super) fn composite(
    layout: Option<Result<AtlasLayout, String>>,
    pasted: &RuntimePastes,
    textures: &[TexturePatch],
    settings: &AtlasSettings,
    metrics: &mut Metrics,
    index: usize,
) -> Option<AtlasTexture> {
    let composited = layout?.and_then(|layout| {
        let records: Vec<PasteRecord> = pasted.pastes.iter().map(DrawnPaste::record).collect();
        let image = composite_pastes(
            &layout,
            &records,
            textures,
            settings.size,
            settings.padding_px,
        )?;
        Ok((layout, image))
    });
    match composited {
        Ok((layout, image)) => {
            metrics.record(index, "atlas_charts", layout.charts);
            metrics.record(index, "atlas_fill", layout.fill);
            metrics.record(index, "atlas_texels_per_unit", layout.texels_per_unit);
            Some(AtlasTexture {
                uvs: layout.corner_uvs.into_flattened(),
                image,
            })
        }
        Err(reason) => {
            metrics.record(index, "atlas", format!("skipped: {reason}"));
            None
        }
    }
}

/// Replaces the paste entities of `mesh` by `pastes` (in paste order) and
/// puts the texture patches in the world.
pub(super) fn spawn_pastes(
    commands: &mut Commands,
    mesh: Entity,
    old: &Query<(Entity, &PasteOf)>,
    pastes: Vec<DrawnPaste>,
    textures: Vec<TexturePatch>,
) {
    for (entity, of) in old {
        if of.0 == mesh {
            commands.entity(entity).despawn();
        }
    }
    for (i, paste) in pastes.into_iter().enumerate() {
        let n = paste.faces.len();
        commands.spawn((
            PasteOf(mesh),
            PasteOrder(i as u32),
            TexturePatchIndex(paste.texture),
            PatchFaces(paste.faces),
            PatchUvs(paste.uvs),
            PatchDrawn(vec![true; n]),
        ));
    }
    commands.insert_resource(TexturePatchOrigins(
        textures.iter().map(|t| t.origin).collect(),
    ));
    commands.insert_resource(TexturePatches(
        textures.into_iter().map(|t| t.image).collect(),
    ));
}

/// Records the paste loop's results as metrics of stage `index`.
pub(super) fn record_metrics(
    metrics: &mut Metrics,
    index: usize,
    out: &RuntimePastes,
    textures: &[TexturePatch],
) {
    let r = &out.report;
    metrics.record(index, "pastes", r.pastes);
    metrics.record(index, "mean_pastes_per_face", r.mean_pastes_per_face);
    metrics.record(index, "mean_draws_per_face", out.draws_per_face);
    metrics.record(index, "mean_faces_per_paste", r.mean_faces_per_paste);
    metrics.record(index, "mean_held_per_face", r.mean_held_per_face);
    metrics.record(index, "max_held_per_face", r.max_held_per_face);
    metrics.record(index, "uncovered_faces", r.uncovered_faces.len());
    metrics.record(
        index,
        "uncovered_face_ids",
        r.uncovered_faces.iter().take(100).collect::<Vec<_>>(),
    );
    metrics.record(index, "regrown_faces", r.regrown_faces);
    metrics.record(index, "rechosen_pastes", r.rechosen_pastes);
    metrics.record(index, "shifted_pastes", r.shifted_pastes);
    metrics.record(index, "cg_iterations", r.cg_iterations);
    metrics.record(index, "unconverged_solves", r.unconverged_solves);
    metrics.record(index, "direct_solves", r.direct_solves);
    metrics.record(index, "texture_patches", textures.len());
    metrics.record(
        index,
        "hull_vertices",
        textures
            .iter()
            .map(|t| t.hull.vertices.len())
            .collect::<Vec<_>>(),
    );
}

/// Returns the heap pages freed so far to the system (glibc's
/// `malloc_trim`). Measured before `main` fixed glibc's mmap threshold: the
/// paste loop's per-face arrays were freed in the middle of the heap, where
/// glibc kept their pages resident, and the atlas kernel allocates blocks
/// too large to reuse those holes, so the process peaked ~200 MB higher at
/// 901 k vertices. With the fixed threshold large buffers go back by
/// themselves; this still returns the loop's many small allocations
/// (per-paste lists, coverage-test scratch) and the atlas kernel's.
pub(super) fn release_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: `malloc_trim` only releases free pages of the allocator's own
    // heaps; it is thread-safe and takes no pointer.
    unsafe {
        libc::malloc_trim(0);
    }
}
