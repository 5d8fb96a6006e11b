//! The shared UV atlas: chart segmentation, low-distortion flattening,
//! packing into a square texture, rasterisation and gutter dilation. Used by
//! the `bake` stage (an atlas of the original mesh) and by lapped textures'
//! atlas output (Praun et al. 2000 §4).
//!
//! 1. **Charts** ([`segment_charts`]): faces grow from the flattest
//!    unassigned seed across manifold, consistently oriented edges while
//!    their normal stays within [`AtlasSettings::normal_cone_deg`] of the
//!    seed's. Non-manifold edges, boundaries and orientation flips end a
//!    chart, so any triangle soup is accepted.
//! 2. **Flattening** ([`lscm`]): least-squares conformal maps (Lévy et al.
//!    2002) solved by preconditioned conjugate gradients from the projection
//!    onto the seed's tangent plane, in coordinates relative to a corner of
//!    the chart (f32 coordinates far from the origin would round shared
//!    edges apart and fail every large chart of a scan). A chart whose map
//!    flips or overlaps a face falls back to the projection; if that fails
//!    too it is split in two (by growth order) and each part is flattened
//!    again, down to single triangles, which never fail. Every chart is
//!    then scaled to its 3-D area, so texel density is the same on average
//!    in every chart.
//! 3. **Small charts** ([`merge`]): a chart of at most
//!    [`merge::SMALL_CHART_FACES`] faces (single faces left by noise, the
//!    faces of a small component) is unfolded face by face into the
//!    neighbouring chart it shares the longest edges with, wherever that
//!    neither flips nor overlaps; grown charts are rescaled to their area.
//! 4. **Packing** ([`pack`]): each chart turned to its minimum-area
//!    rectangle; at a trial scale its footprint (texel rows per texel
//!    column, grown by [`AtlasSettings::padding_px`] texels of gutter) is
//!    placed, tallest first and in the best of four quarter turns, where it
//!    sits lowest, so charts nest into each other's outlines instead of
//!    their bounding rectangles; a bisection finds the largest common scale
//!    that fits, first on a column skyline, then a few steps further with
//!    charts also settling into gaps under other charts' outlines and
//!    inside ring-shaped charts (a scan's holes).
//! 5. **Texels** ([`raster`]): which face covers each texel centre, and
//!    dilation of chart texels into the gutters so bilinear filtering and
//!    mipmaps do not bleed the background in.

pub mod autocorrelation;
pub mod bake;
pub mod bake_layout;
pub mod bake_triangles;
pub mod channels;
pub mod lscm;
pub mod merge;
pub mod pack;
pub mod plane_raster;
pub mod plane_signal;
pub mod raster;
pub mod segment;
pub mod triplanar;
pub mod vertex_colours_from_uvs;

pub use pack::{pack_charts, skyline_pack};
pub use raster::{dilate, rasterise_faces};
pub use segment::{segment_charts, segment_charts_with_progress};

use crate::progress::Progress;
use glam::{Vec2, Vec3};

/// Settings of an atlas.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AtlasSettings {
    /// Side of the square atlas image, pixels. Default 1024.
    pub size: u32,
    /// Largest angle between a chart face's normal and the chart seed's,
    /// degrees (below 90 so that the projection fallback never flips).
    /// Default 60.
    pub normal_cone_deg: f32,
    /// Gutter around each chart, pixels. Default 2.
    pub padding_px: u32,
}

impl Default for AtlasSettings {
    fn default() -> Self {
        Self {
            size: 1024,
            normal_cone_deg: 60.0,
            padding_px: 2,
        }
    }
}

/// A segmentation of a triangle mesh into flattened charts.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Charts {
    /// Number of charts.
    pub count: usize,
    /// Chart of each face.
    pub chart_of_face: Vec<u32>,
    /// Per face, its corners' chart coordinates (world units, `t` up,
    /// counter-clockwise faces counter-clockwise).
    pub corner_st: Vec<[Vec2; 3]>,
}

/// A packed UV atlas of a triangle mesh.
#[derive(Clone, Debug, Default)]
pub struct UvAtlas {
    /// The charts.
    pub charts: Charts,
    /// Per face, its corners' atlas coordinates (`[0, 1]`, `v = 0` at the
    /// top row).
    pub corner_uvs: Vec<[Vec2; 3]>,
    /// Atlas texels per world unit.
    pub texels_per_unit: f32,
    /// Fraction of the atlas covered by chart faces.
    pub fill: f32,
}

/// Why an atlas cannot be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum AtlasError {
    /// No triangles.
    #[error("the mesh has no faces to lay out in an atlas")]
    NoFaces,
    /// A triangle names a vertex that does not exist.
    #[error("triangle {face} names vertex {vertex}, but the mesh has {vertices} vertices")]
    BadVertex {
        /// The triangle.
        face: usize,
        /// The vertex it names.
        vertex: u32,
        /// Vertex count.
        vertices: usize,
    },
    /// The charts' gutters alone do not fit.
    #[error(
        "{charts} charts with {padding} px of gutter each do not fit in a {size}×{size} atlas; raise the size or lower the padding"
    )]
    DoesNotFit {
        /// Chart count.
        charts: usize,
        /// Gutter, pixels.
        padding: u32,
        /// Atlas side, pixels.
        size: u32,
    },
}

/// Builds a packed UV atlas of the triangles `tris` over `positions`.
///
/// # Errors
/// [`AtlasError`] for an empty mesh, a bad vertex index, or charts that do
/// not fit at any scale.
pub fn build_uv_atlas(
    positions: &[Vec3],
    tris: &[[u32; 3]],
    settings: &AtlasSettings,
) -> Result<UvAtlas, AtlasError> {
    build_uv_atlas_with_progress(positions, tris, settings, &Progress::hidden())
}

/// [`build_uv_atlas`], reporting to `progress` as the part `"atlas"`: one
/// step per face, taken when its chart is flattened.
///
/// # Errors
/// As [`build_uv_atlas`].
pub fn build_uv_atlas_with_progress(
    positions: &[Vec3],
    tris: &[[u32; 3]],
    settings: &AtlasSettings,
    progress: &Progress,
) -> Result<UvAtlas, AtlasError> {
    let _span = tracing::info_span!("build_uv_atlas", faces = tris.len()).entered();
    if tris.is_empty() {
        return Err(AtlasError::NoFaces);
    }
    for (face, t) in tris.iter().enumerate() {
        if let Some(&vertex) = t.iter().find(|&&v| v as usize >= positions.len()) {
            return Err(AtlasError::BadVertex {
                face,
                vertex,
                vertices: positions.len(),
            });
        }
    }
    progress.start_part("atlas", tris.len() as u64);
    let charts = segment_charts_with_progress(positions, tris, settings, progress);
    let (corner_uvs, texels_per_unit) = pack_charts(&charts, settings.size, settings.padding_px)
        .ok_or(AtlasError::DoesNotFit {
            charts: charts.count,
            padding: settings.padding_px,
            size: settings.size,
        })?;
    let fill: f32 = corner_uvs
        .iter()
        .map(|t| 0.5 * raster::signed_area2(t).abs())
        .sum();
    Ok(UvAtlas {
        charts,
        corner_uvs,
        texels_per_unit,
        fill,
    })
}

/// The singular values (σ₁ ≥ σ₂) of the linear map taking the 3-D triangle
/// `p` to the flat triangle `q`; `None` for a degenerate 3-D triangle.
pub fn singular_values(p: [Vec3; 3], q: &[Vec2; 3]) -> Option<(f32, f32)> {
    let (e1, e2) = (p[1] - p[0], p[2] - p[0]);
    let n = e1.cross(e2);
    let n2 = n.length_squared();
    if n2.is_nan() || n2 <= 0.0 {
        return None;
    }
    // The face's own orthonormal frame.
    let x = e1.normalize();
    let y = n.cross(e1).normalize();
    let (a1, a2) = (Vec2::new(e1.length(), 0.0), Vec2::new(e2.dot(x), e2.dot(y)));
    let (b1, b2) = (q[1] - q[0], q[2] - q[0]);
    let det = a1.x * a2.y - a2.x * a1.y;
    // J · [a1 a2] = [b1 b2]  →  J = [b1 b2] · [a1 a2]⁻¹.
    let inv = [[a2.y / det, -a2.x / det], [-a1.y / det, a1.x / det]];
    let j = [
        [
            b1.x * inv[0][0] + b2.x * inv[1][0],
            b1.x * inv[0][1] + b2.x * inv[1][1],
        ],
        [
            b1.y * inv[0][0] + b2.y * inv[1][0],
            b1.y * inv[0][1] + b2.y * inv[1][1],
        ],
    ];
    let fro2 = j[0][0].powi(2) + j[0][1].powi(2) + j[1][0].powi(2) + j[1][1].powi(2);
    let d = (j[0][0] * j[1][1] - j[0][1] * j[1][0]).abs();
    let disc = (fro2 * fro2 - 4.0 * d * d).max(0.0).sqrt();
    let s1 = (0.5 * (fro2 + disc)).sqrt();
    let s2 = (0.5 * (fro2 - disc)).max(0.0).sqrt();
    (s1.is_finite() && s2.is_finite()).then_some((s1, s2))
}

/// Distortion of an atlas, per face and per chart.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct AtlasDistortion {
    /// Per chart, texels per world unit (square root of atlas area over
    /// surface area), charts with no area skipped.
    pub chart_density: Vec<f32>,
    /// Area-weighted mean over faces of the conformal stretch σ₁/σ₂ (1 for a
    /// similarity).
    pub mean_stretch: f32,
    /// Area-weighted 95th percentile over faces of the ratio of the face's
    /// texel density to the mean density (≥ 1, symmetric: max(r, 1/r)).
    pub density_ratio_p95: f32,
}

/// Measures the distortion of per-face atlas coordinates `uvs` of `tris`.
pub fn distortion(
    positions: &[Vec3],
    tris: &[[u32; 3]],
    charts: &Charts,
    uvs: &[[Vec2; 3]],
) -> AtlasDistortion {
    let mut chart_area = vec![(0.0f64, 0.0f64); charts.count];
    let mut faces: Vec<(f32, f32, f32)> = Vec::with_capacity(tris.len()); // (area, density², stretch)
    for (f, t) in tris.iter().enumerate() {
        let p = t.map(|v| positions[v as usize]);
        let (e1, e2) = (p[1] - p[0], p[2] - p[0]);
        let area3 = 0.5 * e1.cross(e2).length();
        let q = uvs[f];
        let area2 = 0.5 * raster::signed_area2(&q).abs();
        // Degenerate faces only: an absolute threshold would drop every
        // face of a mesh in small units (a 1 mm triangle in metres).
        if !(area3 > 0.0 && area2 > 0.0) {
            continue;
        }
        let Some((s1, s2)) = singular_values(p, &q) else {
            continue;
        };
        let c = charts.chart_of_face[f] as usize;
        chart_area[c].0 += area3 as f64;
        chart_area[c].1 += area2 as f64;
        let stretch = if s2 > 0.0 { s1 / s2 } else { f32::INFINITY };
        faces.push((area3, area2 / area3, stretch));
    }
    let total: f64 = faces.iter().map(|f| f.0 as f64).sum::<f64>().max(1e-30);
    let mean_density2: f64 = faces.iter().map(|f| (f.0 * f.1) as f64).sum::<f64>() / total;
    let mean_stretch = (faces
        .iter()
        .map(|f| (f.0 * f.2.min(1e6)) as f64)
        .sum::<f64>()
        / total) as f32;
    let mut ratios: Vec<(f32, f32)> = faces
        .iter()
        .map(|f| {
            let r = ((f.1 as f64 / mean_density2).sqrt()) as f32;
            (r.max(1.0 / r.max(1e-12)), f.0)
        })
        .collect();
    ratios.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut acc = 0.0f64;
    let mut p95 = 1.0f32;
    for (r, a) in &ratios {
        acc += *a as f64;
        p95 = *r;
        if acc >= 0.95 * total {
            break;
        }
    }
    AtlasDistortion {
        chart_density: chart_area
            .iter()
            .filter(|c| c.0 > 0.0 && c.1 > 0.0)
            .map(|c| (c.1 / c.0).sqrt() as f32)
            .collect(),
        mean_stretch,
        density_ratio_p95: p95,
    }
}
