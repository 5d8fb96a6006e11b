//! Baking a synthesis result into an atlas of the original mesh.
//!
//! Every atlas texel is a weighted sum of *contributions*: an exemplar (or
//! lapped patch) coordinate, a weight, and the angle of the synthesis frame
//! relative to the atlas tangent frame at that texel. A channel — colour,
//! normal, roughness, height — is one image sampled through the same
//! contributions, so every exemplar map follows one synthesis; tangent-space
//! normals are rotated by each contribution's angle before they are summed.
//! Colour may also come *directly* (vertex colours, a lapped base colour)
//! with its own weight.
//!
//! Sources of contributions ([`ContributionSource`]):
//! - [`VertexColourSource`]: a retiled or subdivided result: the texel's
//!   surface point on the original mesh is projected onto the result mesh
//!   (closest point facing the same way) and the result triangle's vertex
//!   colours (and source texels, when recorded) are interpolated
//!   barycentrically;
//! - [`BlendUvSource`]: per-corner UVs on the original mesh, with the
//!   jump-map 3-way blend (Zelinka & Garland 2004 §6.5) when given;
//! - [`LappedSource`]: lapped-texture pastes composited in paste order
//!   (Praun et al. 2000), "over" on a base colour.
//!
//! Rows are baked in parallel; every texel depends only on its inputs, so
//! the result is the same at any thread count.

use super::autocorrelation::Autocorrelation;
use super::raster::barycentric;
use crate::image::{Image, pixel_rgb, sample::Wrap};
use crate::kernels::atlas::channels::{decode_normal, encode_normal, reorient_normal};
use crate::kernels::jump_maps::jump_surface::Blend;
use crate::kernels::wei_levoy::retile::SurfaceProjector;
use crate::progress::Progress;
use glam::{Vec2, Vec3};
use rayon::prelude::*;

/// One exemplar look-up feeding a texel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Contribution {
    /// Texture coordinates (`[0, 1]`, `v = 0` at the top row) in
    /// `texture`.
    pub uv: Vec2,
    /// Weight of the look-up.
    pub weight: f32,
    /// Angle (radians, counter-clockwise seen from outside) from the atlas
    /// tangent frame's `s` axis to the synthesis frame's at this texel.
    pub angle: f32,
    /// 0: the exemplar (and its channel maps); `k + 1`: lapped patch `k`
    /// (colour only).
    pub texture: u32,
}

/// Everything that makes one texel.
#[derive(Clone, Debug, Default)]
pub struct TexelSamples {
    /// The exemplar look-ups.
    pub contribs: Vec<Contribution>,
    /// A colour not from a look-up (RGB).
    pub direct: [f32; 3],
    /// Its weight.
    pub direct_weight: f32,
    /// When true the colour channel is `direct` alone (vertex colours);
    /// the contributions then serve the other channels.
    pub colour_direct_only: bool,
    /// When set, `(mean, gain)`: the look-ups' blended colour `c` (weights
    /// summing to `total`) becomes `mean·total + (c − mean·total)·gain`,
    /// restoring the exemplar's contrast ([`AgreeingLookups::preserve_variance`]).
    pub variance: Option<([f32; 3], f32)>,
    /// The last face's blend layers ([`BlendUvSource`] makes them from the
    /// compact form; neighbouring texels mostly share a face). Kept by
    /// `clear`.
    pub layers: Option<(u32, [[Vec2; 3]; 3])>,
    /// The last texel's original triangle and the result triangle it
    /// projected onto, where the next texel on the same original triangle
    /// starts its walk ([`VertexColourSource`]). Kept by `clear`; each atlas
    /// row starts without one, so the bake is the same at any thread count.
    pub hint: Option<(u32, u32)>,
}

impl TexelSamples {
    fn clear(&mut self) {
        self.contribs.clear();
        self.direct = [0.0; 3];
        self.direct_weight = 0.0;
        self.colour_direct_only = false;
        self.variance = None;
    }
}

/// Fills the samples of a texel on triangle `face` of the original mesh at
/// barycentric coordinates `bary`.
pub trait ContributionSource: Sync {
    /// Fills `out` (cleared by the caller).
    fn texel(&self, face: u32, bary: [f32; 3], out: &mut TexelSamples);
}

/// Per triangle of the original mesh: its unit normal and the unit atlas
/// tangent `s` (the direction in which the atlas `u` grows).
#[derive(Clone, Debug, Default)]
pub struct AtlasFrames {
    /// Unit normals (zero for a degenerate triangle).
    pub normal: Vec<Vec3>,
    /// Unit atlas `s` axes.
    pub s: Vec<Vec3>,
}

/// Gradient over the 3-D triangle `p` of the linear function with corner
/// values `f`.
pub fn gradient(p: [Vec3; 3], f: [f32; 3]) -> Vec3 {
    let n2 = (p[1] - p[0]).cross(p[2] - p[0]);
    let a2 = n2.length_squared();
    if a2 <= 0.0 {
        return Vec3::ZERO;
    }
    (0..3)
        .map(|k| n2.cross(p[(k + 2) % 3] - p[(k + 1) % 3]) * f[k])
        .sum::<Vec3>()
        / a2
}

impl AtlasFrames {
    /// The frames of `tris` over `positions` with per-triangle atlas
    /// coordinates `uvs`.
    pub fn new(positions: &[Vec3], tris: &[[u32; 3]], uvs: &[[Vec2; 3]]) -> Self {
        let (normal, s) = tris
            .par_iter()
            .zip(uvs)
            .map(|(t, uv)| {
                let p = t.map(|v| positions[v as usize]);
                let n = (p[1] - p[0]).cross(p[2] - p[0]).normalize_or_zero();
                (n, gradient(p, uv.map(|q| q.x)).normalize_or_zero())
            })
            .unzip();
        Self { normal, s }
    }

    /// Angle from the atlas `s` axis of triangle `f` to the world direction
    /// `dir`, around the triangle normal.
    #[inline]
    pub fn angle_to(&self, f: usize, dir: Vec3) -> f32 {
        let (n, s) = (self.normal[f], self.s[f]);
        n.dot(s.cross(dir)).atan2(s.dot(dir))
    }
}

/// What a channel holds, which decides how look-ups are combined.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ChannelKind {
    /// Colour (RGB): a weighted sum.
    Colour,
    /// A tangent-space normal map (`kernels::atlas::channels` convention): look-ups
    /// are decoded, re-oriented from their synthesis frame into the atlas
    /// frame (`reorient_normal`), summed, renormalised and encoded.
    Normal,
    /// A scalar map (roughness, height): a weighted sum of the first channel.
    Scalar,
}

/// An exemplar map to bake.
#[derive(Clone, Copy, Debug)]
pub struct ChannelMap<'a> {
    /// The map, the exemplar's size.
    pub image: &'a Image,
    /// How to combine look-ups.
    pub kind: ChannelKind,
}

/// The atlas geometry a bake writes into.
#[derive(Clone, Copy, Debug)]
pub struct BakeTarget<'a> {
    /// Per triangle of the original mesh, its corners' atlas coordinates.
    pub corner_uvs: &'a [[Vec2; 3]],
    /// Which triangle covers each texel centre (`u32::MAX`: gutter).
    pub texel_face: &'a [u32],
    /// Side of the atlas, texels.
    pub size: u32,
    /// Gutter texels to dilate into.
    pub padding_px: u32,
}

/// A row index, its colour row and its row of every map.
type RowSlices<'r> = (usize, &'r mut [f32], Vec<&'r mut [f32]>);

/// The pastes of a lapped texture in order: per paste its patch index and,
/// per face it holds, the face and its corners' coordinates in the patch.
pub type PasteFaces = (u32, Vec<(u32, [Vec2; 3])>);

/// Bakes the colour channel (RGB, through `textures`: 0 the exemplar,
/// `k + 1` lapped patch `k`) and every map of `maps` (through texture 0
/// only — see [`bake_channels_with_patches`] for lapped patches; RGB for colour and normal maps, one channel for scalar ones), then
/// dilates them into the gutters.
pub fn bake_channels(
    target: &BakeTarget,
    source: &dyn ContributionSource,
    textures: &[&Image],
    wrap: Wrap,
    maps: &[ChannelMap],
) -> (Image, Vec<Image>) {
    bake_channels_with_patches(target, source, textures, wrap, maps, &[])
}

/// Where lapped patch `k` (texture `k + 1`) lies in the exemplar: a patch
/// coordinate `uv` is exemplar coordinate `offset + uv · scale` (both in
/// exemplar `[0, 1]` units), so exemplar maps follow lapped pastes too.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PatchPlacement {
    /// Exemplar coordinate of the patch's `(0, 0)` corner.
    pub offset: Vec2,
    /// Patch size over exemplar size, per axis.
    pub scale: Vec2,
}

/// [`bake_channels`], with the maps also sampled through lapped-patch
/// look-ups: contribution texture `k + 1` reads the maps at
/// `patches[k].offset + uv · patches[k].scale` (a patch without a
/// placement feeds the colour only).
pub fn bake_channels_with_patches(
    target: &BakeTarget,
    source: &dyn ContributionSource,
    textures: &[&Image],
    wrap: Wrap,
    maps: &[ChannelMap],
    patches: &[PatchPlacement],
) -> (Image, Vec<Image>) {
    bake_channels_with_progress(
        target,
        source,
        textures,
        wrap,
        maps,
        patches,
        &Progress::hidden(),
    )
}

/// [`bake_channels_with_patches`], reporting to `progress` as the part
/// `"texels"`, one step per atlas row baked, then `"gutters"`, one step per
/// output padded.
pub fn bake_channels_with_progress(
    target: &BakeTarget,
    source: &dyn ContributionSource,
    textures: &[&Image],
    wrap: Wrap,
    maps: &[ChannelMap],
    patches: &[PatchPlacement],
    progress: &Progress,
) -> (Image, Vec<Image>) {
    progress.start_part("texels", u64::from(target.size));
    let _span =
        tracing::info_span!("bake_channels", size = target.size, maps = maps.len()).entered();
    let s = target.size as usize;
    let mut colour = Image::new(target.size, target.size, 3);
    let mut outs: Vec<Image> = maps
        .iter()
        .map(|m| {
            let c = if m.kind == ChannelKind::Scalar { 1 } else { 3 };
            Image::new(target.size, target.size, c)
        })
        .collect();
    let widths: Vec<usize> = outs.iter().map(|o| o.channels as usize * s).collect();
    // Split every output into rows, then hand each worker one row of each.
    let mut rows: Vec<RowSlices> = colour
        .data
        .chunks_mut(3 * s)
        .enumerate()
        .map(|(y, r)| (y, r, Vec::with_capacity(maps.len())))
        .collect();
    for (out, &w) in outs.iter_mut().zip(&widths) {
        for (row, chunk) in rows.iter_mut().zip(out.data.chunks_mut(w)) {
            row.2.push(chunk);
        }
    }
    let max_c = textures
        .iter()
        .map(|t| t.channels)
        .chain(maps.iter().map(|m| m.image.channels))
        .max()
        .unwrap_or(4) as usize;
    rows.par_iter_mut().for_each(|(y, crow, mrows)| {
        let mut samples = TexelSamples::default();
        let mut px = vec![0.0f32; max_c];
        for x in 0..s {
            let f = target.texel_face[*y * s + x];
            if f == u32::MAX {
                continue;
            }
            let t = target.corner_uvs[f as usize].map(|p| p * target.size as f32);
            let b = barycentric(&t, Vec2::new(x as f32 + 0.5, *y as f32 + 0.5));
            let b = b.map(|v| v.max(0.0));
            let sum = (b[0] + b[1] + b[2]).max(1e-12);
            let b = b.map(|v| v / sum);
            samples.clear();
            source.texel(f, b, &mut samples);
            // Colour.
            let mut c = samples.direct.map(|v| v * samples.direct_weight);
            if !samples.colour_direct_only {
                for k in &samples.contribs {
                    let Some(tex) = textures.get(k.texture as usize) else {
                        continue;
                    };
                    let w = if k.texture == 0 { wrap } else { Wrap::Clamp };
                    let buf = &mut px[..tex.channels as usize];
                    tex.sample_uv(k.uv.x, k.uv.y, w, buf);
                    let rgb = pixel_rgb(buf);
                    for i in 0..3 {
                        c[i] += k.weight * rgb[i];
                    }
                }
                if let Some((mean, gain)) = samples.variance {
                    let total: f32 = samples.contribs.iter().map(|k| k.weight).sum();
                    for i in 0..3 {
                        let m = mean[i] * total;
                        c[i] = (m + (c[i] - m) * gain).clamp(0.0, total);
                    }
                }
            }
            crow[3 * x..3 * x + 3].copy_from_slice(&c);
            // Maps, through the exemplar's look-ups only.
            for (m, row) in maps.iter().zip(mrows.iter_mut()) {
                let buf = &mut px[..m.image.channels as usize];
                let mut acc = Vec3::ZERO;
                let mut wsum = 0.0f32;
                for k in &samples.contribs {
                    let uv = match k.texture {
                        0 => k.uv,
                        t => match patches.get(t as usize - 1) {
                            Some(p) => p.offset + k.uv * p.scale,
                            None => continue,
                        },
                    };
                    m.image.sample_uv(uv.x, uv.y, wrap, buf);
                    let rgb = pixel_rgb(buf);
                    let v = match m.kind {
                        // The synthesis frame is the atlas frame turned by
                        // `angle`: in `reorient_normal`'s terms the atlas
                        // x-axis is at −angle from the synthesis `s`.
                        ChannelKind::Normal => reorient_normal(decode_normal(rgb), -k.angle),
                        _ => Vec3::from(rgb),
                    };
                    acc += v * k.weight;
                    wsum += k.weight;
                }
                match m.kind {
                    ChannelKind::Scalar => {
                        row[x] = if wsum > 0.0 { acc.x / wsum } else { 0.5 };
                    }
                    ChannelKind::Colour => {
                        let v = if wsum > 0.0 {
                            acc / wsum
                        } else {
                            Vec3::splat(0.5)
                        };
                        row[3 * x..3 * x + 3].copy_from_slice(&v.to_array());
                    }
                    ChannelKind::Normal => {
                        row[3 * x..3 * x + 3].copy_from_slice(&encode_normal(acc));
                    }
                }
            }
        }
        progress.inc(1);
    });
    drop(rows);
    // The gutters of every output, one step each.
    progress.start_part("gutters", 1 + maps.len() as u64);
    let filled: Vec<bool> = target.texel_face.iter().map(|&f| f != u32::MAX).collect();
    let mut mask = filled.clone();
    super::raster::dilate(
        &mut colour.data,
        3,
        target.size,
        &mut mask,
        target.padding_px,
    );
    fill_background(&mut colour.data, 3, &mask, None);
    progress.inc(1);
    for (out, m) in outs.iter_mut().zip(maps) {
        let mut mask = filled.clone();
        let c = out.channels as usize;
        super::raster::dilate(&mut out.data, c, target.size, &mut mask, target.padding_px);
        // Beyond the gutters: a flat normal, or the mean, so the coarsest
        // mip levels stay neutral instead of darkening chart borders.
        let neutral = matches!(m.kind, ChannelKind::Normal).then_some([0.5, 0.5, 1.0]);
        fill_background(&mut out.data, c, &mask, neutral.as_ref().map(|v| &v[..]));
        progress.inc(1);
    }
    (colour, outs)
}

/// Sets every texel outside `filled` to `value` (or, without one, to the
/// mean of the filled texels).
fn fill_background(data: &mut [f32], channels: usize, filled: &[bool], value: Option<&[f32]>) {
    let c = channels.max(1);
    let mut fill = vec![0.0f32; c];
    match value {
        Some(v) => fill.iter_mut().zip(v).for_each(|(f, v)| *f = *v),
        None => {
            let mut sum = vec![0.0f64; c];
            let mut n = 0usize;
            for (px, _) in data.chunks_exact(c).zip(filled).filter(|(_, f)| **f) {
                sum.iter_mut().zip(px).for_each(|(s, v)| *s += *v as f64);
                n += 1;
            }
            if n == 0 {
                return;
            }
            fill.iter_mut()
                .zip(&sum)
                .for_each(|(f, s)| *f = (*s / n as f64) as f32);
        }
    }
    for (px, _) in data.chunks_exact_mut(c).zip(filled).filter(|(_, f)| !**f) {
        px.copy_from_slice(&fill);
    }
}

// ----- sources ------------------------------------------------------------------

/// Per-corner UVs on the original mesh, optionally blended 3 ways.
pub struct BlendUvSource<'a> {
    /// Per triangle, for each base vertex `b`, the corners' exemplar UVs
    /// (the compact form makes them on request). Without a blend the three
    /// layers are equal.
    pub layers: Blend<'a>,
    /// Per triangle and layer, the synthesis frame's angle to the atlas
    /// frame (see [`BlendUvSource::new`]); empty when no normal map is
    /// baked (only normal maps turn with the frame: the angles are then 0).
    pub angles: Vec<[f32; 3]>,
}

impl<'a> BlendUvSource<'a> {
    /// Prepares the source: the angle of each layer's exemplar `s` axis
    /// (the gradient of its `u`) to the atlas `s` axis.
    pub fn new(
        positions: &[Vec3],
        tris: &[[u32; 3]],
        frames: &AtlasFrames,
        layers: impl Into<Blend<'a>>,
    ) -> Self {
        let layers = layers.into();
        let angles = tris
            .par_iter()
            .enumerate()
            .take(layers.len())
            .map(|(f, t)| {
                let p = t.map(|v| positions[v as usize]);
                layers
                    .get(f)
                    .map(|uv| frames.angle_to(f, gradient(p, uv.map(|q| q.x))))
            })
            .collect();
        Self { layers, angles }
    }

    /// The source without angles, for a bake of colour, roughness or height
    /// only (none of them turns with the synthesis frame): no frames and no
    /// per-triangle array beside the layers.
    pub fn without_angles(layers: impl Into<Blend<'a>>) -> Self {
        Self {
            layers: layers.into(),
            angles: Vec::new(),
        }
    }
}

impl ContributionSource for BlendUvSource<'_> {
    fn texel(&self, face: u32, b: [f32; 3], out: &mut TexelSamples) {
        let f = face as usize;
        if f >= self.layers.len() || (!self.angles.is_empty() && f >= self.angles.len()) {
            return;
        }
        let layers = match out.layers {
            Some((g, l)) if g == face => l,
            _ => {
                let l = self.layers.get(f);
                out.layers = Some((face, l));
                l
            }
        };
        let angles = self.angles.get(f).copied().unwrap_or([0.0; 3]);
        let same = layers[0] == layers[1] && layers[1] == layers[2];
        for (base, uvs) in layers.iter().enumerate() {
            let uv = uvs[0] * b[0] + uvs[1] * b[1] + uvs[2] * b[2];
            let weight = if same { 1.0 } else { b[base] };
            out.contribs.push(Contribution {
                uv,
                weight,
                angle: angles[base],
                texture: 0,
            });
            if same {
                break;
            }
        }
    }
}

/// Vertex colours on a result mesh other than the original (retiled,
/// subdivided).
pub struct VertexColourSource<'a> {
    /// Original-mesh positions.
    pub positions: &'a [Vec3],
    /// Original-mesh triangles.
    pub tris: &'a [[u32; 3]],
    /// Atlas frames of the original mesh.
    pub frames: &'a AtlasFrames,
    /// Closest points on the result mesh.
    pub projector: &'a SurfaceProjector,
    /// The result's triangles (vertex ids), as the projector numbers them.
    pub result_tris: &'a [[u32; 3]],
    /// Result vertex colours, `channels` per vertex.
    pub colours: &'a [f32],
    /// Values per vertex in `colours`.
    pub channels: usize,
    /// Per result vertex, its exemplar coordinate (`[0, 1]`), when the
    /// method recorded it.
    pub source_uv: Option<&'a [Vec2]>,
    /// Per result vertex, its synthesis frame's `s` axis, when known.
    pub frame_s: Option<&'a [Vec3]>,
}

impl VertexColourSource<'_> {
    /// The result triangle (vertex ids) under the texel at barycentric `b`
    /// of original triangle `face`, and the barycentric coordinates of the
    /// texel's closest point on it (facing the same way).
    fn result_point(
        &self,
        face: u32,
        b: [f32; 3],
        hint: &mut Option<(u32, u32)>,
    ) -> Option<([u32; 3], [f32; 3])> {
        let f = face as usize;
        let t = self.tris[f];
        let p = self.positions[t[0] as usize] * b[0]
            + self.positions[t[1] as usize] * b[1]
            + self.positions[t[2] as usize] * b[2];
        let normal = self.frames.normal[f];
        let hit = if normal == Vec3::ZERO {
            self.projector.project(p)
        } else {
            match *hint {
                Some((on, near)) if on == face => {
                    self.projector.project_facing_local(p, normal, near)
                }
                _ => self.projector.project_facing(p, normal, u32::MAX),
            }
        }?;
        *hint = Some((face, hit.face));
        let rt = self.result_tris.get(hit.face as usize)?;
        Some((*rt, hit.bary.to_array()))
    }
}

impl ContributionSource for VertexColourSource<'_> {
    fn texel(&self, face: u32, b: [f32; 3], out: &mut TexelSamples) {
        let f = face as usize;
        let Some((rt, w)) = self.result_point(face, b, &mut out.hint) else {
            return;
        };
        let rt = &rt;
        let c = self.channels;
        let mut rgb = [0.0f32; 3];
        for (k, &v) in rt.iter().enumerate() {
            let vals = &self.colours[v as usize * c..v as usize * c + c];
            let px = pixel_rgb(vals);
            for i in 0..3 {
                rgb[i] += w[k] * px[i];
            }
        }
        out.direct = rgb;
        out.direct_weight = 1.0;
        out.colour_direct_only = true;
        if let Some(uvs) = self.source_uv {
            for (k, &v) in rt.iter().enumerate() {
                let angle = self
                    .frame_s
                    .map_or(0.0, |s| self.frames.angle_to(f, s[v as usize]));
                out.contribs.push(Contribution {
                    uv: uvs[v as usize],
                    weight: w[k],
                    angle,
                    texture: 0,
                });
            }
        }
    }
}

/// A per-vertex result read at the exemplar's own resolution: every texel
/// looks the exemplar up where each vertex of the result triangle under it
/// puts it — the vertex's source texel continued through its tangent frame
/// to the texel's point at the synthesis scale — and blends the three
/// look-ups barycentrically (coordinates synthesised coarse, colours read
/// fine: Lefebvre & Hoppe 2005). Where the three vertices continue one
/// another (a coherent patch) the texel is the exemplar itself, sharp at any
/// atlas resolution; vertex-colour interpolation
/// ([`VertexColourSource`]) is bounded by the vertex density instead.
pub struct CoordinateSource<'a> {
    /// The result surface and the projection onto it (its colours unused).
    pub surface: VertexColourSource<'a>,
    /// Result-mesh positions.
    pub result_positions: &'a [Vec3],
    /// Per result vertex, its source coordinate in exemplar pixels
    /// (`SourceTexels`).
    pub sources: &'a [Vec2],
    /// Per result vertex, its synthesis frame.
    pub synthesis_frames: &'a [crate::kernels::surface::frames::TangentFrame],
    /// Exemplar texels per world unit: one per result vertex, or one for
    /// all.
    pub texels_per_unit: &'a [f32],
    /// The exemplar's size, pixels.
    pub exemplar_size: Vec2,
}

impl ContributionSource for CoordinateSource<'_> {
    fn texel(&self, face: u32, b: [f32; 3], out: &mut TexelSamples) {
        let Some((rt, w)) = self.surface.result_point(face, b, &mut out.hint) else {
            return;
        };
        let p: Vec3 = rt
            .iter()
            .zip(w)
            .map(|(&v, w)| self.result_positions[v as usize] * w)
            .sum();
        for (k, &v) in rt.iter().enumerate() {
            let v = v as usize;
            let frame = &self.synthesis_frames[v];
            let q = crate::kernels::surface::frames::continued_source(
                self.sources,
                self.synthesis_frames,
                self.texels_per_unit,
                self.result_positions,
                v,
                p,
            );
            out.contribs.push(Contribution {
                uv: q / self.exemplar_size,
                weight: w[k],
                angle: self.surface.frames.angle_to(face as usize, frame.s),
                texture: 0,
            });
        }
    }
}

/// Blends the exemplar look-ups of a texel sharply. Those that agree are
/// read as one: the look-ups
/// of `inner` on the exemplar (texture 0) whose coordinates lie within
/// `within` exemplar pixels of one another are each moved to the weighted
/// mean of those they agree with, fading back to their own coordinate
/// between `within` and `2 · within` (a smoothstep), so the decision is
/// continuous across the atlas.
///
/// Blending the colours of look-ups that nearly agree — the three vertices
/// of a coherent patch continued through slightly different frames, or
/// sources rounded to whole pixels — draws every feature two or three
/// times, a pixel apart: a blur. Blending their coordinates draws it once,
/// sharp. Look-ups that disagree (a jump, a patch seam) keep the colour
/// blend of the source (Zelinka & Garland 2004 §6.5; Lefebvre & Hoppe 2005
/// §7), which hides the seam — optionally preserving the exemplar's
/// contrast there ([`AgreeingLookups::preserve_variance`]). With `within`
/// 0 nothing is merged.
pub struct AgreeingLookups<'a> {
    /// The source whose look-ups are merged.
    pub inner: &'a dyn ContributionSource,
    /// The exemplar's size, pixels.
    pub exemplar_size: Vec2,
    /// Agreement distance, exemplar pixels (0: none merged).
    pub within: f32,
    /// The exemplar's addressing: with `Repeat`, coordinates a whole
    /// exemplar apart are the same place.
    pub wrap: Wrap,
    /// The exemplar's mean colour and luminance autocorrelation, when the
    /// colours of the look-ups are blended preserving their variance
    /// (Heitz & Neyret 2018; Burley 2019): `mean + Σ wᵢ (cᵢ − mean) / s`
    /// with `s² = Σᵢⱼ wᵢ wⱼ ρ(qᵢ − qⱼ)` the blend's variance over the
    /// exemplar's for look-ups at coordinates `qᵢ` — `√Σ wᵢ²` for unrelated
    /// look-ups, `Σ wᵢ` (no change) for one place — so a cross-fade keeps
    /// the exemplar's contrast instead of washing out towards the mean.
    pub preserve_variance: Option<([f32; 3], &'a Autocorrelation)>,
}

impl AgreeingLookups<'_> {
    /// The shortest lag equivalent to `d` (pixels): modulo the exemplar
    /// when it repeats.
    fn lag(&self, d: Vec2) -> Vec2 {
        if self.wrap == Wrap::Repeat {
            d - (d / self.exemplar_size).round() * self.exemplar_size
        } else {
            d
        }
    }
}

/// Most exemplar look-ups of one texel that [`AgreeingLookups`] merges
/// (the sources make three).
const MAX_MERGED: usize = 8;

impl ContributionSource for AgreeingLookups<'_> {
    fn texel(&self, face: u32, b: [f32; 3], out: &mut TexelSamples) {
        self.inner.texel(face, b, out);
        let mut idx = [0usize; MAX_MERGED];
        let mut n = 0;
        for (i, c) in out.contribs.iter().enumerate() {
            if c.texture == 0 && c.weight > 0.0 && n < MAX_MERGED {
                idx[n] = i;
                n += 1;
            }
        }
        if n < 2 {
            return;
        }
        let size = self.exemplar_size;
        let q: [Vec2; MAX_MERGED] = std::array::from_fn(|k| {
            if k < n {
                out.contribs[idx[k]].uv * size
            } else {
                Vec2::ZERO
            }
        });
        let w: [f32; MAX_MERGED] = std::array::from_fn(|k| {
            if k < n {
                out.contribs[idx[k]].weight
            } else {
                0.0
            }
        });
        let (lo, hi) = (self.within, 2.0 * self.within);
        let mut moved = q;
        let within = self.within > 0.0;
        for k in (0..n).filter(|_| within) {
            let (mut shift, mut total) = (Vec2::ZERO, w[k]);
            for j in (0..n).filter(|&j| j != k) {
                let d = self.lag(q[j] - q[k]);
                let t = ((d.length() - lo) / (hi - lo)).clamp(0.0, 1.0);
                let agree = 1.0 - t * t * (3.0 - 2.0 * t);
                shift += d * (agree * w[j]);
                total += agree * w[j];
            }
            moved[k] = q[k] + shift / total;
        }
        for k in 0..n {
            out.contribs[idx[k]].uv = moved[k] / size;
        }
        // Look-ups now at one coordinate are read once, their weights summed.
        for a in 0..n {
            for b in a + 1..n {
                let (ia, ib) = (idx[a], idx[b]);
                if out.contribs[ib].weight > 0.0
                    && self.lag(moved[a] - moved[b]).length_squared() < 1e-6
                {
                    out.contribs[ia].weight += out.contribs[ib].weight;
                    out.contribs[ib].weight = 0.0;
                }
            }
        }
        if let Some((mean, rho)) = self.preserve_variance {
            let (mut total, mut var) = (0.0f32, 0.0f32);
            for a in 0..n {
                total += w[a];
                var += w[a] * w[a];
                for b in a + 1..n {
                    var += 2.0 * w[a] * w[b] * rho.at(self.lag(moved[b] - moved[a]));
                }
            }
            if var > 0.0 {
                out.variance = Some((mean, total / var.sqrt()));
            }
        }
        out.contribs.retain(|c| c.weight > 0.0);
    }
}

/// One paste's layer on a face of a lapped texture.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PasteLayer {
    /// Lapped patch index.
    pub patch: u32,
    /// The face's corners' coordinates in the patch.
    pub uv: [Vec2; 3],
    /// The patch frame's angle to the atlas frame on this face.
    pub angle: f32,
}

/// Lapped-texture pastes on the original mesh, composited in paste order.
pub struct LappedSource<'a> {
    /// CSR offsets: layers of face `f` are `layers[start[f]..start[f + 1]]`,
    /// in paste order.
    pub start: Vec<u32>,
    /// The layers.
    pub layers: Vec<PasteLayer>,
    /// RGBA patches (straight alpha).
    pub patches: &'a [Image],
    /// Colour under every paste.
    pub base: [f32; 3],
}

impl<'a> LappedSource<'a> {
    /// Collects per face, in paste order, the layers of `pastes`: each a
    /// patch index and, per face it holds, the face and its corners' UVs.
    pub fn new(
        positions: &[Vec3],
        tris: &[[u32; 3]],
        frames: &AtlasFrames,
        pastes: &[PasteFaces],
        patches: &'a [Image],
    ) -> Self {
        let fc = tris.len();
        let mut count = vec![0u32; fc + 1];
        for (_, faces) in pastes {
            for &(f, _) in faces {
                if (f as usize) < fc {
                    count[f as usize + 1] += 1;
                }
            }
        }
        for i in 0..fc {
            count[i + 1] += count[i];
        }
        let start = count.clone();
        let mut fill = count;
        let mut layers = vec![
            PasteLayer {
                patch: 0,
                uv: [Vec2::ZERO; 3],
                angle: 0.0,
            };
            start[fc] as usize
        ];
        for (patch, faces) in pastes {
            for &(f, uv) in faces {
                let fi = f as usize;
                if fi >= fc {
                    continue;
                }
                let p = tris[fi].map(|v| positions[v as usize]);
                layers[fill[fi] as usize] = PasteLayer {
                    patch: *patch,
                    uv,
                    angle: frames.angle_to(fi, gradient(p, uv.map(|q| q.x))),
                };
                fill[fi] += 1;
            }
        }
        // The base: the alpha-weighted mean colour of the first patch.
        let base = patches.first().map_or([0.5; 3], |t| {
            let (mut sum, mut w) = ([0.0f64; 3], 0.0f64);
            for px in t.data.chunks_exact(t.channels.max(1) as usize) {
                let a = if px.len() >= 4 { px[3] as f64 } else { 1.0 };
                let rgb = pixel_rgb(px);
                for k in 0..3 {
                    sum[k] += rgb[k] as f64 * a;
                }
                w += a;
            }
            sum.map(|v| (v / w.max(1e-12)) as f32)
        });
        Self {
            start,
            layers,
            patches,
            base,
        }
    }
}

impl ContributionSource for LappedSource<'_> {
    fn texel(&self, face: u32, b: [f32; 3], out: &mut TexelSamples) {
        let f = face as usize;
        if f + 1 >= self.start.len() {
            return;
        }
        let layers = &self.layers[self.start[f] as usize..self.start[f + 1] as usize];
        // Back to front: weight_i = α_i Π_{j > i} (1 − α_j).
        let mut remaining = 1.0f32;
        let first = out.contribs.len();
        for layer in layers.iter().rev() {
            let Some(patch) = self.patches.get(layer.patch as usize) else {
                continue;
            };
            let uv = layer.uv[0] * b[0] + layer.uv[1] * b[1] + layer.uv[2] * b[2];
            let alpha = if patch.channels >= 4 {
                let mut px = [0.0f32; 4];
                patch.sample_uv(
                    uv.x,
                    uv.y,
                    Wrap::Clamp,
                    &mut px[..patch.channels.min(4) as usize],
                );
                px[3].clamp(0.0, 1.0)
            } else {
                1.0
            };
            if alpha > 0.0 {
                out.contribs.push(Contribution {
                    uv,
                    weight: alpha * remaining,
                    angle: layer.angle,
                    texture: layer.patch + 1,
                });
            }
            remaining *= 1.0 - alpha;
            if remaining <= 0.0 {
                break;
            }
        }
        out.contribs[first..].reverse();
        out.direct = self.base;
        out.direct_weight = remaining;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Three fixed look-ups (exemplar pixels, weights), as a source.
    struct Fixed([(Vec2, f32); 3]);

    impl ContributionSource for Fixed {
        fn texel(&self, _: u32, _: [f32; 3], out: &mut TexelSamples) {
            for (q, w) in self.0 {
                out.contribs.push(Contribution {
                    uv: q / 64.0,
                    weight: w,
                    angle: 0.0,
                    texture: 0,
                });
            }
        }
    }

    /// White noise in `[0.3, 0.7]` (a restored blend stays inside `[0, 1]`).
    fn noise(seed: u64) -> Image {
        let mut img = Image::new(64, 64, 1);
        let mut s = seed;
        for v in img.data.iter_mut() {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            *v = 0.3 + 0.4 * (s >> 40) as f32 / (1u64 << 24) as f32;
        }
        img
    }

    fn merged(source: &Fixed, within: f32, rho: Option<&Autocorrelation>) -> TexelSamples {
        let lookups = AgreeingLookups {
            inner: source,
            exemplar_size: Vec2::splat(64.0),
            within,
            wrap: Wrap::Repeat,
            preserve_variance: rho.map(|r| ([0.5; 3], r)),
        };
        let mut out = TexelSamples::default();
        lookups.texel(0, [1.0 / 3.0; 3], &mut out);
        out
    }

    #[test]
    fn look_ups_that_agree_are_read_once_at_their_mean() {
        let near = Fixed([
            (Vec2::new(10.0, 10.0), 0.5),
            (Vec2::new(10.6, 10.0), 0.25),
            (Vec2::new(10.0, 10.8), 0.25),
        ]);
        let out = merged(&near, 2.0, None);
        assert_eq!(out.contribs.len(), 1, "{:?}", out.contribs);
        let mean = Vec2::new(10.15, 10.2) / 64.0;
        assert!((out.contribs[0].uv - mean).length() < 1e-5);
        assert!((out.contribs[0].weight - 1.0).abs() < 1e-6);
        // Across the repeat: 63.5 and 0.3 are 0.8 pixel apart.
        let wrapped = Fixed([
            (Vec2::new(63.5, 5.0), 0.5),
            (Vec2::new(0.3, 5.0), 0.5),
            (Vec2::new(30.0, 30.0), 0.0),
        ]);
        let out = merged(&wrapped, 2.0, None);
        assert_eq!(out.contribs.len(), 1, "{:?}", out.contribs);
        let x = (out.contribs[0].uv.x * 64.0).rem_euclid(64.0);
        assert!((x - 63.9).abs() < 1e-3, "{x}");
    }

    #[test]
    fn look_ups_that_disagree_keep_their_places() {
        let far = Fixed([
            (Vec2::new(10.0, 10.0), 0.5),
            (Vec2::new(30.0, 12.0), 0.25),
            (Vec2::new(50.0, 40.0), 0.25),
        ]);
        let out = merged(&far, 2.0, None);
        assert_eq!(out.contribs.len(), 3);
        for (c, (q, w)) in out.contribs.iter().zip(far.0) {
            assert!((c.uv - q / 64.0).length() < 1e-6 && c.weight == w);
        }
        assert!(out.variance.is_none());
        // Between 2 and 4 pixels apart the merge fades out continuously.
        let at = |d: f32| {
            let two = Fixed([
                (Vec2::new(10.0, 10.0), 0.5),
                (Vec2::new(10.0 + d, 10.0), 0.5),
                (Vec2::new(40.0, 40.0), 0.0),
            ]);
            merged(&two, 2.0, None).contribs[0].uv.x * 64.0 - 10.0
        };
        // At 3 pixels each agrees half: moved to (1·q + ½·q')/(1 + ½).
        assert!((at(3.0) - 1.0).abs() < 1e-4, "{}", at(3.0));
        assert!(at(4.0).abs() < 1e-5 && at(5.0).abs() < 1e-5);
    }

    #[test]
    fn variance_gain_is_one_for_one_place_and_restores_unrelated_blends() {
        let img = noise(7);
        let rho = Autocorrelation::of_luminance(&img, 8, Wrap::Repeat);
        // Unrelated look-ups, equal weights: gain √3.
        let far = Fixed([
            (Vec2::new(10.0, 10.0), 1.0 / 3.0),
            (Vec2::new(30.0, 12.0), 1.0 / 3.0),
            (Vec2::new(50.0, 40.0), 1.0 / 3.0),
        ]);
        let (_, gain) = merged(&far, 0.0, Some(&rho)).variance.unwrap();
        assert!((gain - 3f32.sqrt()).abs() < 0.1, "{gain}");
        // One place, unmerged: no change.
        let same = Fixed([(Vec2::new(20.0, 20.0), 1.0 / 3.0); 3]);
        let (_, gain) = merged(&same, 0.0, Some(&rho)).variance.unwrap();
        assert!((gain - 1.0).abs() < 1e-5, "{gain}");
    }

    /// Blending unrelated noise linearly shrinks its spread to `√Σw²` of
    /// the exemplar's; preserving variance keeps it.
    #[test]
    fn a_variance_preserving_blend_keeps_the_exemplar_contrast() {
        let img = noise(11);
        let rho = Autocorrelation::of_luminance(&img, 8, Wrap::Repeat);
        let tris = [[Vec2::ZERO, Vec2::X, Vec2::Y]];
        let size = 64u32;
        let texel_face = vec![0u32; (size * size) as usize];
        let target = BakeTarget {
            corner_uvs: &tris,
            texel_face: &texel_face,
            size,
            padding_px: 0,
        };
        /// Three look-ups per texel at unrelated places that move with it.
        struct Spread;
        impl ContributionSource for Spread {
            fn texel(&self, _: u32, b: [f32; 3], out: &mut TexelSamples) {
                let p = Vec2::new(b[1], b[2]) * 64.0;
                for (k, o) in [(0.0, 0.0), (17.0, 5.0), (33.0, 41.0)].iter().enumerate() {
                    out.contribs.push(Contribution {
                        uv: (p + Vec2::new(o.0, o.1)) / 64.0,
                        weight: [0.5, 0.3, 0.2][k],
                        angle: 0.0,
                        texture: 0,
                    });
                }
            }
        }
        let spread_of = |rho: Option<&Autocorrelation>| {
            let m = img.mean()[0];
            let src = AgreeingLookups {
                inner: &Spread,
                exemplar_size: Vec2::splat(64.0),
                within: 0.0,
                wrap: Wrap::Repeat,
                preserve_variance: rho.map(|r| ([m; 3], r)),
            };
            let (baked, _) = bake_channels(&target, &src, &[&img], Wrap::Repeat, &[]);
            // The texels inside the triangle.
            let v: Vec<f32> = baked
                .data
                .chunks_exact(3)
                .enumerate()
                .filter(|(i, _)| i % 64 + i / 64 + 1 < 64)
                .map(|(_, p)| p[0])
                .collect();
            let mean = v.iter().sum::<f32>() / v.len() as f32;
            (v.iter().map(|x| (x - mean).powi(2)).sum::<f32>() / v.len() as f32).sqrt()
        };
        let ex_mean = img.mean()[0];
        let ex = (img.data.iter().map(|x| (x - ex_mean).powi(2)).sum::<f32>()
            / img.data.len() as f32)
            .sqrt();
        let (linear, kept) = (spread_of(None), spread_of(Some(&rho)));
        let expected_linear = ex * (0.25f32 + 0.09 + 0.04).sqrt();
        assert!(
            (linear / expected_linear - 1.0).abs() < 0.1,
            "{linear} vs {expected_linear}"
        );
        assert!((kept / ex - 1.0).abs() < 0.1, "{kept} vs {ex}");
    }
}
