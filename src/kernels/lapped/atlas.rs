//! The texture-atlas representation of a lapped texture (Praun et al. 2000
//! §4, "Rendering with a texture atlas").
//!
//! Charts, flattening, packing, rasterisation and gutter dilation are the
//! shared atlas kernel ([`crate::kernels::atlas`]), the same one the `bake`
//! stage uses for the original mesh: charts are grown under a normal cone as
//! in the paper and flattened by least-squares conformal maps; instead of
//! the paper's manual layout they are packed automatically. What is
//! specific to lapped textures is the compositing: every atlas texel inside
//! a face takes the face's pastes composited in paste order (alpha "over",
//! on the texture's mean colour); the gutters are then filled by dilation.

use super::TriMesh;
use super::composite::{PasteIndex, PasteRecord};
use super::coverage::Coverage;
use super::mask::TexturePatch;
use crate::image::Image;
use crate::image::sample::Wrap;
use crate::kernels::atlas::raster::{barycentric, signed_area2};
pub use crate::kernels::atlas::{
    AtlasSettings, Charts, pack_charts, rasterise_faces, skyline_pack,
};
use crate::mesh::PolyMesh;
use crate::progress::Progress;
use glam::{Vec2, Vec3};
use rayon::prelude::*;

/// A texture atlas of a lapped texture.
#[derive(Clone, Debug, Default)]
pub struct Atlas {
    /// The charts.
    pub charts: Charts,
    /// Per face, its corners' atlas coordinates (`[0, 1]`, `v = 0` at the
    /// top row).
    pub corner_uvs: Vec<[Vec2; 3]>,
    /// Atlas texels per world unit.
    pub texels_per_unit: f32,
    /// Fraction of the atlas covered by chart faces.
    pub fill: f32,
    /// The composited RGB atlas image.
    pub image: Image,
}

/// Segments the mesh into flattened charts with the shared atlas kernel
/// ([`crate::kernels::atlas::segment_charts`]).
pub fn segment_charts(mesh: &TriMesh, settings: &AtlasSettings) -> Charts {
    crate::kernels::atlas::segment_charts(&mesh.positions, &mesh.tris, settings)
}

/// Appends the layers of face `f` to `out`, in paste order: texture patch
/// and corner texture coordinates.
pub type FaceLayersFn<'a> = dyn Fn(usize, &mut Vec<(u32, [Vec2; 3])>) + Sync + 'a;

/// Composites every face's pastes into the atlas (step 3 of the module
/// docs): RGB, `size × size`, gutters dilated by `padding_px` texels.
pub fn composite_atlas(
    corner_uvs: &[[Vec2; 3]],
    coverage: &Coverage,
    textures: &[TexturePatch],
    size: u32,
    padding_px: u32,
) -> Image {
    composite_atlas_with(
        corner_uvs,
        &|f, out| out.extend(coverage.layers(f).map(|l| (l.texture, l.uv))),
        textures,
        size,
        padding_px,
    )
}

/// [`composite_atlas`] of the layers `layers(f, out)` appends to `out` for
/// face `f` (texture patch, corner texture coordinates; in paste order).
pub fn composite_atlas_with(
    corner_uvs: &[[Vec2; 3]],
    layers: &FaceLayersFn<'_>,
    textures: &[TexturePatch],
    size: u32,
    padding_px: u32,
) -> Image {
    let _span = tracing::debug_span!("composite_atlas", size).entered();
    let s = size as usize;
    let id = rasterise_faces(corner_uvs, size);
    // The base colour: the alpha-weighted mean of the first texture patch.
    let base = textures.first().map_or([0.5; 3], |t| {
        let (mut sum, mut w) = ([0.0f64; 3], 0.0f64);
        for px in t.image.data.chunks_exact(4) {
            let a = px[3] as f64;
            for k in 0..3 {
                sum[k] += px[k] as f64 * a;
            }
            w += a;
        }
        sum.map(|v| (v / w.max(1e-12)) as f32)
    });
    let mut image = Image::new(size, size, 3);
    image
        .data
        .par_chunks_mut(3 * s)
        .enumerate()
        .for_each(|(y, row)| {
            let mut rgba = [0.0f32; 4];
            let mut held = Vec::new();
            for x in 0..s {
                let f = id[y * s + x];
                if f == u32::MAX {
                    continue;
                }
                let t = corner_uvs[f as usize].map(|p| p * size as f32);
                let b = barycentric(&t, Vec2::new(x as f32 + 0.5, y as f32 + 0.5));
                let b = b.map(|v| v.max(0.0));
                let sum = (b[0] + b[1] + b[2]).max(1e-12);
                let b = b.map(|v| v / sum);
                let mut colour = base;
                held.clear();
                layers(f as usize, &mut held);
                for (texture, uv) in &held {
                    let uv = uv[0] * b[0] + uv[1] * b[1] + uv[2] * b[2];
                    textures[*texture as usize]
                        .image
                        .sample_uv(uv.x, uv.y, Wrap::Clamp, &mut rgba);
                    let a = rgba[3].clamp(0.0, 1.0);
                    for k in 0..3 {
                        colour[k] += (rgba[k] - colour[k]) * a;
                    }
                }
                row[3 * x..3 * x + 3].copy_from_slice(&colour);
            }
        });
    // Gutters: grow the charts outwards one texel per pass.
    let mut filled: Vec<bool> = id.iter().map(|&f| f != u32::MAX).collect();
    crate::kernels::atlas::dilate(&mut image.data, 3, size, &mut filled, padding_px);
    image
}

/// Builds the atlas of a lapped texture: charts, packing, compositing.
/// Errs with the UV atlas's message (e.g. the charts do not fit the size).
pub fn build_atlas(
    mesh: &TriMesh,
    coverage: &Coverage,
    textures: &[TexturePatch],
    settings: &AtlasSettings,
) -> Result<Atlas, String> {
    build_atlas_with(
        &mesh.positions,
        &mesh.tris,
        &|f, out| out.extend(coverage.layers(f).map(|l| (l.texture, l.uv))),
        textures,
        settings,
    )
}

/// [`build_atlas`] of the triangles `tris` over `positions`, compositing
/// the layers `layers(f, out)` appends for face `f` (see
/// [`composite_atlas_with`]).
pub fn build_atlas_with(
    positions: &[Vec3],
    tris: &[[u32; 3]],
    layers: &FaceLayersFn<'_>,
    textures: &[TexturePatch],
    settings: &AtlasSettings,
) -> Result<Atlas, String> {
    let _span = tracing::info_span!("build_atlas").entered();
    let uv = crate::kernels::atlas::build_uv_atlas(positions, tris, settings)
        .map_err(|e| e.to_string())?;
    let (charts, corner_uvs, texels_per_unit) = (uv.charts, uv.corner_uvs, uv.texels_per_unit);
    let image = composite_atlas_with(
        &corner_uvs,
        layers,
        textures,
        settings.size,
        settings.padding_px,
    );
    let area: f32 = corner_uvs.iter().map(|t| 0.5 * signed_area2(t).abs()).sum();
    Ok(Atlas {
        charts,
        corner_uvs,
        texels_per_unit,
        fill: area,
        image,
    })
}

/// The texture atlas's charts and coordinates, before the pastes exist.
#[derive(Clone, Debug, Default)]
pub struct AtlasLayout {
    /// Number of charts.
    pub charts: usize,
    /// Per face, its corners' atlas coordinates.
    pub corner_uvs: Vec<[Vec2; 3]>,
    /// Atlas texels per world unit.
    pub texels_per_unit: f32,
    /// Fraction of the atlas covered by chart faces.
    pub fill: f32,
}

/// Lays out the atlas of `mesh` (triangles only; the paste loop reports
/// any other face) with the shared atlas kernel. Laying out a
/// million-vertex scan takes tens of seconds: it is the part `"atlas"` of
/// `progress`.
///
/// # Errors
/// A face that is not a triangle, or the UV atlas's message.
pub fn atlas_layout(
    mesh: &PolyMesh,
    settings: &AtlasSettings,
    progress: &Progress,
) -> Result<AtlasLayout, String> {
    let tris: Vec<[u32; 3]> = (0..mesh.face_count())
        .map(|f| match mesh.face(f) {
            &[a, b, c] => Ok([a, b, c]),
            _ => Err(format!("face {f} is not a triangle")),
        })
        .collect::<Result<_, _>>()?;
    let uv = crate::kernels::atlas::build_uv_atlas_with_progress(
        &mesh.positions,
        &tris,
        settings,
        progress,
    )
    .map_err(|e| e.to_string())?;
    Ok(AtlasLayout {
        charts: uv.charts.count,
        corner_uvs: uv.corner_uvs,
        texels_per_unit: uv.texels_per_unit,
        fill: uv.fill,
    })
}

/// Composites `pastes` (in paste order) into an atlas of `layout`'s
/// coordinates (see [`composite_atlas_with`]).
///
/// # Errors
/// As [`PasteIndex::new`] (a paste names a face the layout does not have).
pub fn composite_pastes(
    layout: &AtlasLayout,
    pastes: &[PasteRecord<'_>],
    textures: &[TexturePatch],
    size: u32,
    padding_px: u32,
) -> Result<Image, String> {
    let index = PasteIndex::new(layout.corner_uvs.len(), pastes)?;
    Ok(composite_atlas_with(
        &layout.corner_uvs,
        &|f, out| out.extend(index.layers(f).map(|(_, t, uv)| (t, uv))),
        textures,
        size,
        padding_px,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kernels::lapped::test_meshes::sphere;

    #[test]
    fn sphere_charts_are_flat_disjoint_and_cover_every_face() {
        let mesh = sphere(3);
        let m = TriMesh::new(&mesh).unwrap();
        let charts = segment_charts(&m, &AtlasSettings::default());
        assert!(charts.count >= 4 && charts.count < 60, "{}", charts.count);
        assert!(
            charts
                .chart_of_face
                .iter()
                .all(|&c| (c as usize) < charts.count)
        );
        let (uvs, scale) = pack_charts(&charts, 512, 2).unwrap();
        assert!(scale > 10.0, "{scale}");
        for t in &uvs {
            assert!(signed_area2(t).abs() > 0.0);
            assert!(
                t.iter()
                    .all(|p| p.x > 0.0 && p.y > 0.0 && p.x < 1.0 && p.y < 1.0)
            );
        }
        // No texel centre lies strictly inside two faces.
        let size = 512usize;
        let mut count = vec![0u8; size * size];
        for uv in &uvs {
            let t = uv.map(|p| p * size as f32);
            let lo = t[0].min(t[1]).min(t[2]);
            let hi = t[0].max(t[1]).max(t[2]);
            for y in lo.y.floor() as usize..=(hi.y.ceil() as usize).min(size - 1) {
                for x in lo.x.floor() as usize..=(hi.x.ceil() as usize).min(size - 1) {
                    let b = barycentric(&t, Vec2::new(x as f32 + 0.5, y as f32 + 0.5));
                    if b.iter().all(|&v| v > 1e-4) {
                        count[y * size + x] += 1;
                    }
                }
            }
        }
        let doubles = count.iter().filter(|&&c| c > 1).count();
        let covered = count.iter().filter(|&&c| c > 0).count();
        assert_eq!(doubles, 0, "of {covered} covered texels");
        assert!(covered > size * size / 5, "fill {covered}");
    }
}
