//! The texture-atlas representation of a lapped texture (Praun et al. 2000
//! §4, "Rendering with a texture atlas").
//!
//! 1. **Charts.** The mesh is segmented into charts grown with the patch
//!    growth of §3.3 for isotropic textures (unit scale, so charts are
//!    flattened in world units) under two extra constraints, as in the
//!    paper: every face normal lies within [`AtlasSettings::normal_cone_deg`]
//!    of the chart's seed face normal, and no face may overlap the chart
//!    already flattened (a spatial hash of the chart's triangles) or be
//!    flipped. Each chart is then relaxed with the least-squares
//!    parametrisation of §3.4; when relaxing would create an overlap or a
//!    flip, the grown (unfolded) parametrisation is kept.
//! 2. **Packing.** Instead of the paper's manual layout, charts are packed
//!    automatically: each is turned to its minimum-area bounding rectangle
//!    (lying flat), and the rectangles, sorted by height, are placed by a
//!    bottom-left skyline packer into the square atlas; a binary search
//!    finds the largest common scale (texels per world unit) at which all of
//!    them fit with a gutter of [`AtlasSettings::padding_px`] pixels.
//! 3. **Compositing.** Every atlas texel inside a face takes the face's
//!    pastes composited in paste order (alpha "over", on the texture's mean
//!    colour); the gutters are filled by dilating the charts outwards.

use super::coverage::Coverage;
use super::grow::{GrowSettings, Grower};
use super::mask::TexturePatch;
use super::param::{SolveSettings, optimise_parametrisation};
use super::{FaceField, TriMesh};
use crate::image::Image;
use crate::image::sample::Wrap;
use glam::{DVec2, Vec2};
use rayon::prelude::*;
use std::collections::HashMap;

/// Settings of the atlas.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AtlasSettings {
    /// Side of the square atlas image, pixels. Default 1024.
    pub size: u32,
    /// Largest angle between a chart face's normal and the chart seed's,
    /// degrees. Default 60.
    pub normal_cone_deg: f32,
    /// Gutter around each chart, pixels. Default 2.
    pub padding_px: u32,
    /// Largest distortion of a face joining a chart (see
    /// [`GrowSettings::max_distortion`]). Default 0.1.
    pub max_distortion: f32,
}

impl Default for AtlasSettings {
    fn default() -> Self {
        Self {
            size: 1024,
            normal_cone_deg: 60.0,
            padding_px: 2,
            max_distortion: 0.1,
        }
    }
}

/// A segmentation of the mesh into flattened charts.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Charts {
    /// Number of charts.
    pub count: usize,
    /// Chart of each face.
    pub chart_of_face: Vec<u32>,
    /// Per face, its corners' chart coordinates (world units, `t` up).
    pub corner_st: Vec<[Vec2; 3]>,
}

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

#[inline]
fn signed_area2(t: &[Vec2; 3]) -> f32 {
    (t[1] - t[0]).perp_dot(t[2] - t[0])
}

/// Whether two triangles' interiors overlap (separating axes, after
/// shrinking both slightly so that shared edges and corners do not count).
fn triangles_overlap(a: &[Vec2; 3], b: &[Vec2; 3]) -> bool {
    let shrink = |t: &[Vec2; 3]| {
        let c = (t[0] + t[1] + t[2]) / 3.0;
        t.map(|p| c + (p - c) * (1.0 - 1e-4))
    };
    let (a, b) = (shrink(a), shrink(b));
    for tri in [&a, &b] {
        for i in 0..3 {
            let axis = (tri[(i + 1) % 3] - tri[i]).perp();
            let project = |t: &[Vec2; 3]| {
                t.iter()
                    .map(|p| p.dot(axis))
                    .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), v| {
                        (lo.min(v), hi.max(v))
                    })
            };
            let (a0, a1) = project(&a);
            let (b0, b1) = project(&b);
            if a1 <= b0 || b1 <= a0 {
                return false;
            }
        }
    }
    true
}

/// A uniform-grid spatial hash of 2-D triangles.
struct TriangleHash {
    cell: f32,
    cells: HashMap<(i32, i32), Vec<u32>>,
    tris: Vec<[Vec2; 3]>,
    seen: Vec<u32>,
    stamp: u32,
}

impl TriangleHash {
    fn new(cell: f32) -> Self {
        Self {
            cell: cell.max(1e-12),
            cells: HashMap::new(),
            tris: Vec::new(),
            seen: Vec::new(),
            stamp: 0,
        }
    }

    fn cell_range(&self, t: &[Vec2; 3]) -> (i32, i32, i32, i32) {
        let lo = t[0].min(t[1]).min(t[2]) / self.cell;
        let hi = t[0].max(t[1]).max(t[2]) / self.cell;
        (
            lo.x.floor() as i32,
            lo.y.floor() as i32,
            hi.x.floor() as i32,
            hi.y.floor() as i32,
        )
    }

    fn overlaps(&mut self, t: &[Vec2; 3]) -> bool {
        let (x0, y0, x1, y1) = self.cell_range(t);
        // Triangles are at most a few cells across; a degenerate huge one is
        // refused rather than scanned.
        if (x1 - x0) as i64 * (y1 - y0) as i64 > 4096 {
            return true;
        }
        self.stamp += 1;
        for y in y0..=y1 {
            for x in x0..=x1 {
                let Some(list) = self.cells.get(&(x, y)) else {
                    continue;
                };
                for &i in list {
                    if self.seen[i as usize] == self.stamp {
                        continue;
                    }
                    self.seen[i as usize] = self.stamp;
                    if triangles_overlap(t, &self.tris[i as usize]) {
                        return true;
                    }
                }
            }
        }
        false
    }

    fn insert(&mut self, t: [Vec2; 3]) {
        let i = self.tris.len() as u32;
        let (x0, y0, x1, y1) = self.cell_range(&t);
        for y in y0..=y1 {
            for x in x0..=x1 {
                self.cells.entry((x, y)).or_default().push(i);
            }
        }
        self.tris.push(t);
        self.seen.push(0);
    }
}

/// Whether the triangles are all counter-clockwise and pairwise disjoint.
fn flat_and_disjoint(tris: &[[Vec2; 3]], cell: f32) -> bool {
    let mut hash = TriangleHash::new(cell);
    for t in tris {
        if signed_area2(t) <= 0.0 || hash.overlaps(t) {
            return false;
        }
        hash.insert(*t);
    }
    true
}

/// Segments the mesh into flattened charts (step 1 of the module docs).
/// Seeds are taken flattest first (least bent to their neighbours).
pub fn segment_charts(mesh: &TriMesh, settings: &AtlasSettings) -> Charts {
    let _span = tracing::debug_span!("segment_charts").entered();
    let fc = mesh.face_count();
    // A unit isotropic field: charts are flattened in world units.
    let unit: Vec<glam::Vec3> = (0..fc)
        .map(|f| mesh.normals[f].any_orthonormal_vector())
        .collect();
    let field = FaceField {
        t: &unit,
        isotropic: true,
    };
    let mut grower = Grower::new(
        mesh,
        field,
        GrowSettings {
            max_distortion: settings.max_distortion,
            max_reach: f32::INFINITY,
            max_faces: usize::MAX,
        },
    );
    let cell = {
        let total: f32 = mesh.areas.iter().sum();
        (2.0 * total / fc.max(1) as f32).sqrt()
    };
    let cos_cone = settings.normal_cone_deg.to_radians().cos();
    let mut chart_of_face = vec![u32::MAX; fc];
    let mut corner_st = vec![[Vec2::ZERO; 3]; fc];
    let mut count = 0u32;
    // Flattest faces seed first: their charts spread widest before the
    // normal cone stops them, leaving fewer small charts at creases.
    let bend: Vec<f32> = (0..fc)
        .map(|f| {
            mesh.neighbours[f]
                .iter()
                .filter(|&&g| g != super::NO_FACE)
                .map(|&g| 1.0 - mesh.normals[f].dot(mesh.normals[g as usize]))
                .sum()
        })
        .collect();
    let mut seeds: Vec<u32> = (0..fc as u32).collect();
    seeds.sort_by(|&a, &b| bend[a as usize].total_cmp(&bend[b as usize]).then(a.cmp(&b)));
    for seed in seeds {
        if chart_of_face[seed as usize] != u32::MAX {
            continue;
        }
        let mut patch = grower.start(seed, [1.0 / 3.0; 3], 0.0);
        let n0 = mesh.normals[seed as usize];
        let mut hash = TriangleHash::new(cell);
        hash.insert(patch.tris[0].map(|v| patch.st[v as usize]));
        grower.grow_with(&mut patch, f32::INFINITY, &|_, _| true, &mut |g, st| {
            let ok = chart_of_face[g as usize] == u32::MAX
                && mesh.normals[g as usize].dot(n0) >= cos_cone
                && signed_area2(&st) > 0.0
                && !hash.overlaps(&st);
            if ok {
                hash.insert(st);
            }
            ok
        });
        // Relax (§3.4); keep the unfolding when relaxing breaks the chart.
        let unfolded = patch.st.clone();
        optimise_parametrisation(mesh, &mut patch, &SolveSettings::default());
        let relaxed: Vec<[Vec2; 3]> = patch
            .tris
            .iter()
            .map(|t| t.map(|v| patch.st[v as usize]))
            .collect();
        if !flat_and_disjoint(&relaxed, cell) {
            patch.st = unfolded;
        }
        for (lf, &f) in patch.faces.iter().enumerate() {
            chart_of_face[f as usize] = count;
            corner_st[f as usize] = patch.tris[lf].map(|v| patch.st[v as usize]);
        }
        count += 1;
    }
    Charts {
        count: count as usize,
        chart_of_face,
        corner_st,
    }
}

/// Counter-clockwise convex hull (Andrew's monotone chain).
fn convex_hull(mut pts: Vec<DVec2>) -> Vec<DVec2> {
    pts.sort_by(|a, b| a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y)));
    pts.dedup();
    if pts.len() < 3 {
        return pts;
    }
    let mut hull: Vec<DVec2> = Vec::with_capacity(2 * pts.len());
    for pass in 0..2 {
        let start = hull.len();
        let iter: Box<dyn Iterator<Item = &DVec2>> = if pass == 0 {
            Box::new(pts.iter())
        } else {
            Box::new(pts.iter().rev())
        };
        for &p in iter {
            while hull.len() >= start + 2
                && (hull[hull.len() - 1] - hull[hull.len() - 2]).perp_dot(p - hull[hull.len() - 2])
                    <= 0.0
            {
                hull.pop();
            }
            hull.push(p);
        }
        hull.pop();
    }
    hull
}

/// The rotation (cos, sin) that turns `pts` to their minimum-area bounding
/// rectangle lying flat (width ≥ height).
fn flat_min_area_rotation(pts: &[DVec2]) -> DVec2 {
    let hull = convex_hull(pts.to_vec());
    let extent = |rot: DVec2| {
        let (mut lo, mut hi) = (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY));
        for p in &hull {
            let q = DVec2::new(rot.x * p.x - rot.y * p.y, rot.y * p.x + rot.x * p.y);
            lo = lo.min(q);
            hi = hi.max(q);
        }
        hi - lo
    };
    let mut best = (f64::INFINITY, DVec2::X);
    for i in 0..hull.len() {
        let e = hull[(i + 1) % hull.len()] - hull[i];
        let Some(dir) = e.try_normalize() else {
            continue;
        };
        // Rotate the edge onto the x axis.
        let rot = DVec2::new(dir.x, -dir.y);
        let size = extent(rot);
        if size.x * size.y < best.0 - 1e-12 {
            best = (size.x * size.y, rot);
        }
    }
    let rot = best.1;
    let size = extent(rot);
    if size.y > size.x {
        // A further quarter turn lays it flat.
        DVec2::new(-rot.y, rot.x)
    } else {
        rot
    }
}

/// Bottom-left skyline packing of `rects` (width, height) into a square of
/// side `size`, in the given order. Returns top-left positions (y down), or
/// `None` when they do not fit.
pub fn skyline_pack(rects: &[(u32, u32)], size: u32) -> Option<Vec<(u32, u32)>> {
    // Segments (x, y, width): the height reached over [x, x + width).
    let mut sky: Vec<(u32, u32, u32)> = vec![(0, 0, size)];
    let mut out = Vec::with_capacity(rects.len());
    for &(w, h) in rects {
        if w > size || h > size {
            return None;
        }
        let mut best: Option<(u32, u32)> = None;
        for i in 0..sky.len() {
            let x = sky[i].0;
            if x + w > size {
                break;
            }
            let mut y = 0;
            for seg in &sky[i..] {
                if seg.0 >= x + w {
                    break;
                }
                y = y.max(seg.1);
            }
            if y + h > size {
                continue;
            }
            if best.is_none_or(|(bx, by)| (y, x) < (by, bx)) {
                best = Some((x, y));
            }
        }
        let (x, y) = best?;
        out.push((x, y));
        // Raise the skyline over [x, x + w).
        let mut next: Vec<(u32, u32, u32)> = Vec::with_capacity(sky.len() + 2);
        for &(sx, sy, sw) in &sky {
            let end = sx + sw;
            if end <= x || sx >= x + w {
                next.push((sx, sy, sw));
                continue;
            }
            if sx < x {
                next.push((sx, sy, x - sx));
            }
            if end > x + w {
                next.push((x + w, sy, end - (x + w)));
            }
        }
        next.push((x, y + h, w));
        next.sort_unstable();
        sky.clear();
        for seg in next {
            match sky.last_mut() {
                Some(last) if last.1 == seg.1 && last.0 + last.2 == seg.0 => last.2 += seg.2,
                _ => sky.push(seg),
            }
        }
    }
    Some(out)
}

/// Packs the charts into a `size × size` atlas (step 2 of the module docs):
/// returns per-face corner atlas coordinates and the scale in texels per
/// world unit. `None` when even the gutters alone do not fit.
pub fn pack_charts(charts: &Charts, size: u32, padding_px: u32) -> Option<(Vec<[Vec2; 3]>, f32)> {
    let _span = tracing::debug_span!("pack_charts", charts = charts.count).entered();
    let n = charts.count;
    let mut points: Vec<Vec<DVec2>> = vec![Vec::new(); n];
    for (f, st) in charts.corner_st.iter().enumerate() {
        let c = charts.chart_of_face[f] as usize;
        points[c].extend(st.iter().map(|p| p.as_dvec2()));
    }
    // Turn every chart flat and move it to the origin.
    let mut placed: Vec<(DVec2, DVec2, DVec2)> = Vec::with_capacity(n); // (rot, min, size)
    for pts in &points {
        let rot = flat_min_area_rotation(pts);
        let (mut lo, mut hi) = (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY));
        for p in pts {
            let q = DVec2::new(rot.x * p.x - rot.y * p.y, rot.y * p.x + rot.x * p.y);
            lo = lo.min(q);
            hi = hi.max(q);
        }
        placed.push((rot, lo, (hi - lo).max(DVec2::ZERO)));
    }
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&a, &b| {
        placed[b]
            .2
            .y
            .total_cmp(&placed[a].2.y)
            .then(placed[b].2.x.total_cmp(&placed[a].2.x))
            .then(a.cmp(&b))
    });
    let pad = 2 * padding_px;
    let rects_at = |scale: f64| -> Vec<(u32, u32)> {
        order
            .iter()
            .map(|&c| {
                let s = placed[c].2 * scale;
                (s.x.ceil() as u32 + pad + 1, s.y.ceil() as u32 + pad + 1)
            })
            .collect()
    };
    let largest = placed
        .iter()
        .map(|p| p.2.x.max(p.2.y))
        .fold(0.0f64, f64::max)
        .max(1e-12);
    let (mut lo, mut hi) = (0.0f64, size as f64 / largest);
    let mut best = skyline_pack(&rects_at(lo), size).map(|p| (lo, p))?;
    for _ in 0..40 {
        let mid = 0.5 * (lo + hi);
        match skyline_pack(&rects_at(mid), size) {
            Some(p) => {
                lo = mid;
                best = (mid, p);
            }
            None => hi = mid,
        }
    }
    let (scale, positions) = best;
    let mut corner = vec![DVec2::ZERO; n];
    for (k, &c) in order.iter().enumerate() {
        corner[c] = DVec2::new(positions[k].0 as f64, positions[k].1 as f64);
    }
    let inv = 1.0 / size as f64;
    let uvs = charts
        .corner_st
        .iter()
        .enumerate()
        .map(|(f, st)| {
            let c = charts.chart_of_face[f] as usize;
            let (rot, min, extent) = placed[c];
            st.map(|p| {
                let p = p.as_dvec2();
                let q = DVec2::new(rot.x * p.x - rot.y * p.y, rot.y * p.x + rot.x * p.y) - min;
                // t up in the chart is up in the image (y down).
                let px = corner[c].x + padding_px as f64 + 0.5 + q.x * scale;
                let py = corner[c].y + padding_px as f64 + 0.5 + (extent.y - q.y) * scale;
                Vec2::new((px * inv) as f32, (py * inv) as f32)
            })
        })
        .collect();
    Some((uvs, scale as f32))
}

/// Barycentric coordinates of `p` in the 2-D triangle `t`.
#[inline]
fn barycentric(t: &[Vec2; 3], p: Vec2) -> [f32; 3] {
    let inv = 1.0 / signed_area2(t);
    let b0 = (t[1] - p).perp_dot(t[2] - p) * inv;
    let b1 = (t[2] - p).perp_dot(t[0] - p) * inv;
    [b0, b1, 1.0 - b0 - b1]
}

/// Which face covers each texel centre of a `size × size` atlas
/// (`u32::MAX` for none; the first face in face order wins a shared edge).
pub fn rasterise_faces(corner_uvs: &[[Vec2; 3]], size: u32) -> Vec<u32> {
    let s = size as usize;
    let mut id = vec![u32::MAX; s * s];
    for (f, uv) in corner_uvs.iter().enumerate() {
        let t = uv.map(|p| p * size as f32);
        if signed_area2(&t).abs() < 1e-12 {
            continue;
        }
        let lo = t[0].min(t[1]).min(t[2]);
        let hi = t[0].max(t[1]).max(t[2]);
        let (x0, y0) = (
            (lo.x - 0.5).ceil().max(0.0) as usize,
            (lo.y - 0.5).ceil().max(0.0) as usize,
        );
        let x1 = ((hi.x - 0.5).floor() as i64).min(s as i64 - 1);
        let y1 = ((hi.y - 0.5).floor() as i64).min(s as i64 - 1);
        for y in y0 as i64..=y1 {
            for x in x0 as i64..=x1 {
                let p = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
                let b = barycentric(&t, p);
                if b.iter().all(|&v| v >= -1e-5) {
                    let cell = &mut id[y as usize * s + x as usize];
                    if *cell == u32::MAX {
                        *cell = f as u32;
                    }
                }
            }
        }
    }
    id
}

/// Composites every face's pastes into the atlas (step 3 of the module
/// docs): RGB, `size × size`, gutters dilated by `padding_px` texels.
pub fn composite_atlas(
    corner_uvs: &[[Vec2; 3]],
    coverage: &Coverage,
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
                for layer in &coverage.layers[f as usize] {
                    let uv = layer.uv[0] * b[0] + layer.uv[1] * b[1] + layer.uv[2] * b[2];
                    textures[layer.texture as usize].image.sample_uv(
                        uv.x,
                        uv.y,
                        Wrap::Clamp,
                        &mut rgba,
                    );
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
    for _ in 0..padding_px {
        let before = filled.clone();
        let snapshot = image.data.clone();
        for y in 0..s {
            for x in 0..s {
                if before[y * s + x] {
                    continue;
                }
                let mut sum = [0.0f32; 3];
                let mut n = 0.0f32;
                for (dx, dy) in [(-1i64, 0i64), (1, 0), (0, -1), (0, 1)] {
                    let (nx, ny) = (x as i64 + dx, y as i64 + dy);
                    if nx < 0 || ny < 0 || nx >= s as i64 || ny >= s as i64 {
                        continue;
                    }
                    let j = ny as usize * s + nx as usize;
                    if before[j] {
                        for k in 0..3 {
                            sum[k] += snapshot[3 * j + k];
                        }
                        n += 1.0;
                    }
                }
                if n > 0.0 {
                    let o = 3 * (y * s + x);
                    for (out, v) in image.data[o..o + 3].iter_mut().zip(sum) {
                        *out = v / n;
                    }
                    filled[y * s + x] = true;
                }
            }
        }
    }
    image
}

/// Builds the atlas of a lapped texture: charts, packing, compositing.
/// `None` when the charts cannot be packed into the atlas size.
pub fn build_atlas(
    mesh: &TriMesh,
    coverage: &Coverage,
    textures: &[TexturePatch],
    settings: &AtlasSettings,
) -> Option<Atlas> {
    let _span = tracing::info_span!("build_atlas").entered();
    let charts = segment_charts(mesh, settings);
    let (corner_uvs, texels_per_unit) = pack_charts(&charts, settings.size, settings.padding_px)?;
    let image = composite_atlas(
        &corner_uvs,
        coverage,
        textures,
        settings.size,
        settings.padding_px,
    );
    let area: f32 = corner_uvs.iter().map(|t| 0.5 * signed_area2(t).abs()).sum();
    Some(Atlas {
        charts,
        corner_uvs,
        texels_per_unit,
        fill: area,
        image,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kernels::lapped::test_meshes::sphere;

    #[test]
    fn skyline_places_without_overlap() {
        let rects = [(50, 40), (30, 30), (30, 20), (60, 10), (10, 10), (20, 5)];
        let pos = skyline_pack(&rects, 100).unwrap();
        for i in 0..rects.len() {
            let (xi, yi) = pos[i];
            assert!(xi + rects[i].0 <= 100 && yi + rects[i].1 <= 100);
            for j in i + 1..rects.len() {
                let (xj, yj) = pos[j];
                let apart = xi + rects[i].0 <= xj
                    || xj + rects[j].0 <= xi
                    || yi + rects[i].1 <= yj
                    || yj + rects[j].1 <= yi;
                assert!(apart, "{i} and {j} overlap");
            }
        }
        assert!(skyline_pack(&[(60, 60), (60, 60)], 100).is_none());
    }

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
