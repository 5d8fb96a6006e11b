//! What the `bake` stage prepares around [`super::bake`]: the atlas a mesh
//! is baked into ([`lay_out_with_progress`]: charts, packing, distortion,
//! the face of every texel), the progress plan of a bake, and the inputs
//! of the contribution sources made from a result's arrays: per-corner
//! UVs as blend layers ([`single_layers`]), the triangles of a lapped
//! paste ([`paste_triangles`]) and where each patch lies in the exemplar
//! ([`patch_placements`]), and the variance-preserving blend of agreeing
//! look-ups ([`blend_statistics`], [`merge_lookups`]).

use super::autocorrelation::Autocorrelation;
use super::bake::{AgreeingLookups, ContributionSource, PatchPlacement};
use super::{AtlasDistortion, AtlasError, AtlasSettings, UvAtlas};
use super::{build_uv_atlas_with_progress, distortion, rasterise_faces};
use crate::image::Image;
use crate::image::sample::Wrap;
use crate::mesh::PolyMesh;
use crate::progress::Progress;
use glam::{Vec2, Vec3};

/// Lags up to this many exemplar pixels enter the variance-preserving
/// blend's autocorrelation; look-ups farther apart count as unrelated.
pub const AUTOCORRELATION_RADIUS: u32 = 64;

/// The vertex triples of `mesh`'s fan triangulation
/// ([`PolyMesh::triangulate_corners`]), one per triangle.
pub fn fan_triangles(mesh: &PolyMesh) -> Vec<[u32; 3]> {
    mesh.triangulate_corners()
        .0
        .iter()
        .map(|t| t.map(|c| mesh.corner_vertex[c as usize]))
        .collect()
}

/// A bake's parts and their work, for one progress bar: `"atlas"` (per
/// face, and packing per atlas texel), `"texels"` (per texel, more with
/// each exemplar map) and `"gutters"` (padding each output). In
/// microseconds as measured on the bunny (`configs/41_…` at 3072², 3 674
/// faces, three maps: 1.2 s of atlas, mostly packing, 12.5 s of texels,
/// 1.3 s of gutters; packing took 0.3 µs a texel at 1024² in
/// `lapped_paste`, 0.12 at 3072²).
pub fn progress_plan(faces: usize, size: u32, maps: usize) -> [(&'static str, f64); 3] {
    let texels = f64::from(size) * f64::from(size);
    let outputs = 1.0 + maps as f64;
    [
        ("atlas", 6.0 * faces as f64 + 0.15 * texels),
        ("texels", 0.35 * outputs * texels),
        ("gutters", 0.03 * outputs * texels),
    ]
}

/// The atlas of a mesh, ready to bake into.
#[derive(Clone, Debug)]
pub struct AtlasLayout {
    /// The atlas (its per-triangle chart arrays already released).
    pub atlas: UvAtlas,
    /// Its distortion.
    pub distortion: AtlasDistortion,
    /// Per texel (row-major, `size²`), the triangle covering its centre,
    /// `u32::MAX` for none ([`rasterise_faces`]).
    pub texel_face: Vec<u32>,
}

/// Lays the triangles `tris` of `positions` out in an atlas of
/// `settings.size` ([`build_uv_atlas_with_progress`]), measures its
/// distortion and rasterises which triangle covers each texel. Memory
/// (issue 15): each per-triangle array of the charts goes as soon as
/// nothing reads it, the distortion measured first.
///
/// # Errors
/// As [`build_uv_atlas_with_progress`].
pub fn lay_out_with_progress(
    positions: &[Vec3],
    tris: &[[u32; 3]],
    settings: &AtlasSettings,
    progress: &Progress,
) -> Result<AtlasLayout, AtlasError> {
    let mut atlas = build_uv_atlas_with_progress(positions, tris, settings, progress)?;
    atlas.charts.corner_st = Vec::new();
    let distortion = distortion(positions, tris, &atlas.charts, &atlas.corner_uvs);
    atlas.charts.chart_of_face = Vec::new();
    let texel_face = rasterise_faces(&atlas.corner_uvs, settings.size);
    Ok(AtlasLayout {
        atlas,
        distortion,
        texel_face,
    })
}

/// Single-base per-corner UVs (one per corner of `mesh`) as three equal
/// blend layers per fan triangle.
pub fn single_layers(mesh: &PolyMesh, uvs: &[Vec2]) -> Vec<[[Vec2; 3]; 3]> {
    mesh.triangulate_corners()
        .0
        .iter()
        .map(|t| [t.map(|c| uvs[c as usize]); 3])
        .collect()
}

/// The faces of one lapped paste with their corners' patch coordinates
/// (three per face, in order); `None` when the counts do not match.
pub fn paste_triangles(faces: &[u32], uvs: &[Vec2]) -> Option<Vec<(u32, [Vec2; 3])>> {
    (uvs.len() == 3 * faces.len()).then(|| {
        faces
            .iter()
            .enumerate()
            .map(|(i, &f)| (f, [uvs[3 * i], uvs[3 * i + 1], uvs[3 * i + 2]]))
            .collect()
    })
}

/// Where each lapped patch lies in an exemplar of `exemplar_size` pixels:
/// patch pixel (x, y) is exemplar pixel `origin + (x, y)`, so the maps
/// follow the pastes through the same look-ups. Empty unless every patch
/// has an origin.
pub fn patch_placements(
    patches: &[Image],
    origins: &[[i64; 2]],
    exemplar_size: (u32, u32),
) -> Vec<PatchPlacement> {
    if origins.len() != patches.len() {
        return Vec::new();
    }
    let (ew, eh) = (exemplar_size.0.max(1) as f32, exemplar_size.1.max(1) as f32);
    patches
        .iter()
        .zip(origins)
        .map(|(p, o)| PatchPlacement {
            offset: Vec2::new(o[0] as f32 / ew, o[1] as f32 / eh),
            scale: Vec2::new(p.width as f32 / ew, p.height as f32 / eh),
        })
        .collect()
}

/// The exemplar's mean colour and luminance autocorrelation (lags up to
/// [`AUTOCORRELATION_RADIUS`]), which the variance-preserving blend
/// needs; `None` when it does not preserve variance.
pub fn blend_statistics(
    preserve_variance: bool,
    exemplar: &Image,
    wrap: Wrap,
) -> Option<([f32; 3], Autocorrelation)> {
    preserve_variance.then(|| {
        let m = exemplar.to_rgb().mean();
        let rho = Autocorrelation::of_luminance(exemplar, AUTOCORRELATION_RADIUS, wrap);
        ([m[0], m[1], m[2]], rho)
    })
}

/// `source` with its agreeing exemplar look-ups merged (`within > 0`) and
/// the others blended with `statistics` (variance-preserving); `None` for
/// the papers' blend. `exemplar` is the exemplar's size and addressing.
pub fn merge_lookups<'a>(
    source: &'a dyn ContributionSource,
    within: f32,
    statistics: Option<&'a ([f32; 3], Autocorrelation)>,
    exemplar: (&Image, Wrap),
) -> Option<AgreeingLookups<'a>> {
    let (image, wrap) = exemplar;
    (within > 0.0 || statistics.is_some()).then(|| AgreeingLookups {
        inner: source,
        exemplar_size: Vec2::new(image.width as f32, image.height as f32),
        within,
        wrap,
        preserve_variance: statistics.map(|(m, rho)| (*m, rho)),
    })
}
