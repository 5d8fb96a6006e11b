//! The quality measures of [`super::quality`] on a surface: completeness,
//! sharpness and structure from tangent-plane resampled templates (as the
//! surface texture energy), verbatim copying from per-vertex source texels
//! over mesh edges.
//!
//! Templates are `n`×`n` (completeness, sharpness; `n` the metric
//! neighbourhood) or [`STRUCTURE_TEMPLATE`]-wide (structure) grids of points
//! one exemplar pixel apart in each sampled vertex's frame, so every measure
//! is in the same units as on an image. Only templates the faces cover
//! wholly (completeness, sharpness) or to [`STRUCTURE_MIN_COVERAGE`]
//! (structure) count, so boundaries and holes do not read as blur.

use rayon::prelude::*;

use super::energy::SampledTemplates;
use super::quality::{
    VerbatimStats, completeness_queries, luma, mean_gradient, mean_per_value, normalised_l1,
    structure_features, structure_scales,
};
use super::window_index::WindowIndex;
use super::{EnergySettings, SurfaceSignal};
use crate::image::Image;
use crate::image::sample::floor_f32;
use crate::kernels::surface::frames::TangentFrame;
use crate::mesh::{PolyMesh, Topology};

/// Side of the structure templates (points one exemplar pixel apart), or the
/// exemplar's smaller side when that is less.
pub const STRUCTURE_TEMPLATE: u32 = 32;

/// Sharpness templates sample the result this many times denser than one
/// exemplar pixel, and the exemplar is read the same way (its bilinear
/// interpolant): the sharpness is then that of the continuous texture,
/// whatever the turn and sub-pixel shift of the measuring lattice against
/// the result's pixels. At one sample per pixel a copy of the exemplar read
/// between its pixels measured as blurred (0.81-0.94 by alignment).
pub const SHARPNESS_OVERSAMPLING: u32 = 3;

/// Smallest covered fraction of a structure template (uncovered points take
/// the exemplar's mean colour).
pub const STRUCTURE_MIN_COVERAGE: f32 = 0.9;

/// Most structure templates resampled (they are 16–64× larger than the
/// energy's).
pub const STRUCTURE_SAMPLES: usize = 256;

/// Quality measures of a surface result (see [`super::ImageQuality`] for
/// their meaning and units). A measure is NaN when no template qualified.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct SurfaceQuality {
    /// Mean over exemplar windows (stride [`super::quality::COMPLETENESS_STRIDE`]) of the
    /// squared distance per value to the nearest resampled result template
    /// among the sampled vertices. With fewer candidate templates than an
    /// image has windows it reads higher than on an image: compare surface
    /// results at equal `samples`.
    pub completeness: f32,
    /// Mean Sobel gradient magnitude of the resampled templates' luminance
    /// over the exemplar's (1 = as sharp).
    pub sharpness: f32,
    /// Structure distance between the resampled templates' and the exemplar
    /// windows' orientation/scale energy, in `[0, 1]`.
    pub structure: f32,
    /// Templates that entered completeness and sharpness / structure.
    pub templates: usize,
    pub structure_templates: usize,
    /// Verbatim copying from the per-vertex source texels, when known.
    pub verbatim: Option<VerbatimStats>,
}

/// Inputs shared by the surface measures: the mesh with its topology, a frame
/// per vertex, the world distance of one exemplar pixel, and the signal.
#[derive(Clone, Copy)]
pub struct SurfaceResult<'a> {
    pub mesh: &'a PolyMesh,
    pub topo: &'a Topology,
    pub frames: &'a [TangentFrame],
    /// World units per exemplar pixel at the synthesis scale.
    pub spacing: f32,
    pub signal: &'a SurfaceSignal<'a>,
}

/// Resamples `size`×`size` templates at `picks`, keeping those covered at
/// least `min_cover` (fraction); returns them flattened.
fn templates(
    r: &SurfaceResult,
    picks: &[u32],
    size: u32,
    min_cover: f32,
    default: &[f32],
) -> Vec<f32> {
    let min_covered = ((min_cover * (size * size) as f32).ceil() as usize).max(1);
    SampledTemplates::at(
        r.mesh,
        r.topo,
        r.frames,
        r.spacing,
        r.signal,
        default,
        picks.to_vec(),
        size as usize,
    )
    .kept(min_covered)
}

/// Mean Sobel gradient magnitude, per pixel, of the luminance of `img`'s
/// bilinear interpolant sampled `k` times per pixel over its interior
/// (the exemplar read as [`SHARPNESS_OVERSAMPLING`]-dense templates read a
/// result). 0 for images under 2×2.
pub fn continuous_mean_gradient(img: &Image, k: u32) -> f32 {
    let (w, h) = (img.width as usize, img.height as usize);
    if w < 2 || h < 2 || k == 0 {
        return 0.0;
    }
    let l = luma(img);
    // Sample j of a row sits (j + ½) / k pixels in: half a step off the
    // pixel centres, where a template at a random shift sits on average
    // (a Sobel step straddles a pixel boundary — a kink of the
    // interpolant — as often).
    let kf = k as f32;
    let (fw, fh) = ((w - 1) * k as usize, (h - 1) * k as usize);
    let lerp_at = |f: usize, n: usize| -> (usize, usize, f32) {
        let t = (f as f32 + 0.5) / kf;
        let i = (floor_f32(t) as usize).min(n - 2);
        (i, i + 1, t - i as f32)
    };
    // The interpolant along x, once per column: its pixels and weight.
    let columns: Vec<(usize, usize, f32)> = (0..fw).map(|fx| lerp_at(fx, w)).collect();
    // Row `fy` of the dense grid into `out`.
    let dense_row = |fy: usize, out: &mut Vec<f32>| {
        let (y, y1, ty) = lerp_at(fy, h);
        out.clear();
        out.extend(columns.iter().map(|&(x, x1, tx)| {
            let top = l[y * w + x] * (1.0 - tx) + l[y * w + x1] * tx;
            let bottom = l[y1 * w + x] * (1.0 - tx) + l[y1 * w + x1] * tx;
            top * (1.0 - ty) + bottom * ty
        }));
    };
    let sum: f64 = (1..fh - 1)
        .into_par_iter()
        .map_init(
            || [Vec::new(), Vec::new(), Vec::new()],
            |[up, mid, down], y| {
                dense_row(y - 1, up);
                dense_row(y, mid);
                dense_row(y + 1, down);
                let mut row = 0.0f64;
                for x in 1..fw - 1 {
                    let gx = (up[x + 1] + 2.0 * mid[x + 1] + down[x + 1])
                        - (up[x - 1] + 2.0 * mid[x - 1] + down[x - 1]);
                    let gy = (down[x - 1] + 2.0 * down[x] + down[x + 1])
                        - (up[x - 1] + 2.0 * up[x] + up[x + 1]);
                    row += f64::from((gx * gx + gy * gy).sqrt() / 8.0);
                }
                row
            },
        )
        .sum();
    (sum / ((fw - 2) * (fh - 2)) as f64 * f64::from(kf)) as f32
}

/// Every surface measure of a result. Samples the same vertices as the
/// surface texture energy (`settings.samples` vertices with faces, drawn
/// with `settings.seed`); `sources` are per-vertex level-0 exemplar pixel
/// coordinates (NaN where unknown). Deterministic for any number of threads.
///
/// Preconditions: as [`super::surface_texture_energy`]; the exemplar is at
/// least `settings.neighbourhood` pixels on each side.
pub fn surface_quality(
    r: &SurfaceResult,
    exemplar: &Image,
    settings: &EnergySettings,
    sources: Option<&[glam::Vec2]>,
) -> SurfaceQuality {
    let small = SampledTemplates::for_energy(
        r.mesh, r.topo, r.frames, r.spacing, r.signal, exemplar, settings,
    );
    surface_quality_of(r, exemplar, settings, sources, &small)
}

/// [`surface_quality`] at the vertices of `small` (the
/// `settings.neighbourhood` templates the texture energy resampled there:
/// [`SampledTemplates`], `settings.samples` vertices with faces drawn with
/// `settings.seed`); `sources` are per-vertex level-0 exemplar pixel
/// coordinates (NaN where unknown). Deterministic for any number of threads.
///
/// Preconditions: as [`super::surface_texture_energy`]; the exemplar is at
/// least `settings.neighbourhood` pixels on each side; `small` was resampled
/// from `r` with the exemplar's mean as the default.
pub fn surface_quality_of(
    r: &SurfaceResult,
    exemplar: &Image,
    settings: &EnergySettings,
    sources: Option<&[glam::Vec2]>,
    small: &SampledTemplates,
) -> SurfaceQuality {
    let ch = exemplar.channels as usize;
    assert_eq!(
        r.signal.channels(),
        ch,
        "signal and exemplar channels differ"
    );
    assert_eq!(small.n as u32, settings.neighbourhood, "template size");
    let default = exemplar.mean();
    let picks = &small.vertices;
    let n = settings.neighbourhood;
    let span = tracing::debug_span!("completeness").entered();
    // The templates the faces cover wholly.
    let small = small.kept(small.n * small.n);
    let count = small.len() / ((n * n) as usize * ch).max(1);

    // Completeness: each exemplar window against every kept template.
    let completeness = if count == 0 {
        f32::NAN
    } else {
        completeness_against(&small, n as usize, exemplar)
    };
    drop(span);

    // Sharpness: the continuous texture's gradient, from templates sampled
    // SHARPNESS_OVERSAMPLING times denser over the same footprint.
    let span = tracing::debug_span!("sharpness").entered();
    let sharpness = if count == 0 {
        f32::NAN
    } else {
        let k = SHARPNESS_OVERSAMPLING;
        let side = (n - 1) * k + 1;
        let dense = SurfaceResult {
            spacing: r.spacing / k as f32,
            ..*r
        };
        let fine = templates(&dense, picks, side, 1.0, &default);
        let per = (side * side) as usize * ch;
        let fcount = fine.len() / per.max(1);
        let g_ex = continuous_mean_gradient(exemplar, k);
        if fcount == 0 || g_ex <= 0.0 {
            f32::NAN
        } else {
            let sum: f64 = fine
                .chunks_exact(per)
                .map(|t| {
                    let img =
                        Image::from_data(side, side, ch as u32, t.to_vec()).expect("template size");
                    f64::from(mean_gradient(&img)) * f64::from(k)
                })
                .sum();
            (sum / fcount as f64) as f32 / g_ex
        }
    };

    drop(span);
    // Structure: larger templates against exemplar windows of the same size.
    let span = tracing::debug_span!("structure").entered();
    let side = STRUCTURE_TEMPLATE.min(exemplar.width).min(exemplar.height);
    let spicks: Vec<u32> = picks.iter().take(STRUCTURE_SAMPLES).copied().collect();
    let large = templates(r, &spicks, side, STRUCTURE_MIN_COVERAGE, &default);
    let per = (side * side) as usize * ch;
    let scount = large.len() / per.max(1);
    let structure = if scount == 0 {
        f32::NAN
    } else {
        let scales = structure_scales((side, side), (side, side));
        let sum_features = |windows: &mut dyn Iterator<Item = Image>| {
            let mut acc = vec![0.0f64; 0];
            for w in windows {
                let f = structure_features(&luma(&w), side as usize, side as usize, scales);
                if acc.is_empty() {
                    acc = f;
                } else {
                    acc.iter_mut().zip(&f).for_each(|(a, b)| *a += b);
                }
            }
            acc
        };
        let f_out = sum_features(&mut (0..scount).map(|t| {
            Image::from_data(
                side,
                side,
                ch as u32,
                large[t * per..(t + 1) * per].to_vec(),
            )
            .expect("template size")
        }));
        let step = (side / 2).max(1) as usize;
        let (ew, eh) = (exemplar.width as usize, exemplar.height as usize);
        let s = side as usize;
        let origins: Vec<(usize, usize)> = (0..=eh - s)
            .step_by(step)
            .flat_map(|y| (0..=ew - s).step_by(step).map(move |x| (x, y)))
            .collect();
        let f_ex = sum_features(&mut origins.iter().map(|&(x0, y0)| {
            let mut w = Image::new(side, side, ch as u32);
            for y in 0..s {
                for x in 0..s {
                    w.pixel_mut(x as u32, y as u32)
                        .copy_from_slice(exemplar.pixel((x0 + x) as u32, (y0 + y) as u32));
                }
            }
            w
        }));
        normalised_l1(&f_out, &f_ex)
    };
    drop(span);

    let _span = tracing::debug_span!("verbatim").entered();
    let verbatim = sources.map(|s| surface_verbatim(r, s, exemplar.width, exemplar.height));
    SurfaceQuality {
        completeness,
        sharpness,
        structure,
        templates: count,
        structure_templates: scount,
        verbatim,
    }
}

/// Mean over the exemplar's `n`×`n` windows (stride [`super::quality::COMPLETENESS_STRIDE`])
/// of the smallest squared distance per value to any of `templates` (each
/// `n·n·channels` values, the exemplar's layout). Exact nearest-window
/// search ([`WindowIndex`]); parallel over exemplar windows.
fn completeness_against(templates: &[f32], n: usize, exemplar: &Image) -> f32 {
    let ch = exemplar.channels as usize;
    let per = n * n * ch;
    let search = WindowIndex::vectors(templates.to_vec(), n as u32, ch as u32);
    let queries = completeness_queries(exemplar, n);
    let mut values = vec![f32::INFINITY; queries.len() / per];
    search.lower_all(&queries, &mut values);
    mean_per_value(&values, per)
}

/// Verbatim copying on a surface: vertices `a`, `b` joined by an edge belong
/// to one copied region when their sources differ by the edge's texel offset
/// (the mean of both endpoint frames' offsets at `1 / spacing` pixels per
/// unit) within `max(0.5, 0.1 · |offset|)` pixels per axis, toroidally.
/// Region areas are the vertices' areas (a third of each incident
/// triangle's, fan-triangulated) in exemplar pixels²; coverage counts the
/// exemplar pixels some vertex's source lies in; repeats count, per exemplar
/// pixel, the distinct large regions (over a third of the exemplar) copying
/// it.
pub fn surface_verbatim(
    r: &SurfaceResult,
    sources: &[glam::Vec2],
    ex_width: u32,
    ex_height: u32,
) -> VerbatimStats {
    let nv = r.mesh.vertex_count();
    assert_eq!(sources.len(), nv, "one source per vertex");
    let (ew, eh) = (ex_width.max(1) as f32, ex_height.max(1) as f32);
    let ex_area = (ex_width.max(1) * ex_height.max(1)) as usize;
    let scale = 1.0 / r.spacing;
    let known = |s: glam::Vec2| s.x.is_finite() && s.y.is_finite();
    let wrap = |d: f32, size: f32| d - size * (d / size).round();
    let mut parent: Vec<u32> = (0..nv as u32).collect();
    use crate::mesh::union_find_root as root;
    for &[a, b] in &r.topo.edges {
        let (sa, sb) = (sources[a as usize], sources[b as usize]);
        if !known(sa) || !known(sb) {
            continue;
        }
        let d = r.mesh.positions[b as usize] - r.mesh.positions[a as usize];
        let e = 0.5
            * (r.frames[a as usize].texel_offset(d, scale)
                + r.frames[b as usize].texel_offset(d, scale));
        let tol = (0.1 * e.length()).max(0.5);
        if (wrap(sb.x - sa.x, ew) - e.x).abs() <= tol && (wrap(sb.y - sa.y, eh) - e.y).abs() <= tol
        {
            let (ra, rb) = (root(&mut parent, a), root(&mut parent, b));
            parent[ra.max(rb) as usize] = ra.min(rb);
        }
    }
    // Vertex areas in exemplar pixels².
    let mut varea = vec![0.0f64; nv];
    for f in 0..r.mesh.face_count() {
        let face = r.mesh.face(f);
        for k in 1..face.len().saturating_sub(1) {
            let (a, b, c) = (face[0] as usize, face[k] as usize, face[k + 1] as usize);
            let p = &r.mesh.positions;
            let area =
                0.5 * (p[b] - p[a]).cross(p[c] - p[a]).length() as f64 * (scale * scale) as f64;
            for v in [a, b, c] {
                varea[v] += area / 3.0;
            }
        }
    }
    let texel = |s: glam::Vec2| {
        let x = (s.x.floor() as i64).rem_euclid(ex_width.max(1) as i64) as usize;
        let y = (s.y.floor() as i64).rem_euclid(ex_height.max(1) as i64) as usize;
        y * ex_width.max(1) as usize + x
    };
    let mut area = vec![0.0f64; nv];
    let mut roots = vec![u32::MAX; nv];
    let mut used = vec![false; ex_area];
    for v in 0..nv {
        if !known(sources[v]) || r.topo.vertex_faces(v as u32).is_empty() {
            continue;
        }
        let rt = root(&mut parent, v as u32);
        roots[v] = rt;
        area[rt as usize] += varea[v];
        used[texel(sources[v])] = true;
    }
    let (mut sum, mut sum_sq, mut largest) = (0.0f64, 0.0f64, 0.0f64);
    for &a in area.iter().filter(|&&a| a > 0.0) {
        sum += a;
        sum_sq += a * a;
        largest = largest.max(a);
    }
    let large = ex_area as f64 / 3.0;
    let mut repeats = vec![0u32; ex_area];
    let mut last = vec![u32::MAX; ex_area];
    let mut most = 0;
    for v in 0..nv {
        if roots[v] == u32::MAX || area[roots[v] as usize] < large {
            continue;
        }
        let e = texel(sources[v]);
        if last[e] != roots[v] {
            last[e] = roots[v];
            repeats[e] += 1;
            most = most.max(repeats[e]);
        }
    }
    let mean = if sum > 0.0 { sum_sq / sum } else { 0.0 };
    VerbatimStats {
        source_coverage: used.iter().filter(|&&u| u).count() as f32 / ex_area as f32,
        mean_region_area: mean as f32,
        mean_region_fraction: (mean / ex_area as f64) as f32,
        largest_region: largest.round() as u32,
        large_region_repeats: most,
    }
}
