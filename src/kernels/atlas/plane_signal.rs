//! A result sampled into an image over the xy bounding box of a flat mesh
//! (the `plane` output of `export`): per pixel, the triangle under its
//! centre ([`super::plane_raster`]) and the signal evaluated there: vertex
//! colours interpolated, exemplar coordinates continued through their
//! frames, corner UVs blended as the preview renderer does, lapped pastes
//! composited in paste order ([`crate::kernels::lapped::composite`]); with
//! each pixel's exemplar source where the signal knows it.

use super::plane_raster::{PixelHit, PlaneGrid, dominant_corner, rasterise_xy, snap_source};
use crate::image::sample::Wrap;
use crate::image::{Image, pixel_rgb};
use crate::kernels::lapped::composite::LappedComposite;
use crate::kernels::surface::frames::{TangentFrame, continued_source};
use crate::mesh::PolyMesh;
use glam::{Vec2, Vec3};
use rayon::prelude::*;

/// The result a plane image is drawn from.
pub enum PlaneSignal<'a> {
    /// Per-vertex colours and, when recorded, per-vertex exemplar sources
    /// (level-0 pixels).
    Colours {
        /// `values[v * channels + c]`.
        values: &'a [f32],
        /// Values per vertex.
        channels: usize,
        /// Per-vertex source coordinates (`SourceTexels`).
        sources: Option<&'a [Vec2]>,
    },
    /// Per-vertex exemplar coordinates rendered at the exemplar's own
    /// resolution (`plane_colours = "sources"`): each corner `v` of the
    /// pixel's triangle continues its source across the triangle,
    /// `sources[v] + frames[v].texel_offset(p − pos(v), scale(v))`, and the
    /// exemplar sampled there is blended with the barycentric weights (the
    /// 3-way blend of jump maps, Zelinka & Garland §4). Where neighbouring
    /// sources agree (a copied patch) the pixel is the exemplar's pixel;
    /// interpolating vertex colours would resample it through the mesh's
    /// lattice instead.
    Coordinates {
        /// Per-vertex source coordinates, level-0 pixels (`SourceTexels`).
        sources: &'a [Vec2],
        /// Per-vertex tangent frames (`Frames`).
        frames: &'a [TangentFrame],
        /// Texels per world unit, one per vertex or one for all.
        scale: &'a [f32],
        /// The exemplar.
        texture: &'a Image,
        /// Its wrap.
        wrap: Wrap,
    },
    /// Per-corner UVs into the exemplar, optionally with the 3-way blend
    /// layers per fan triangle (`BlendUvs`).
    Uvs {
        /// Per mesh corner.
        uvs: &'a [Vec2],
        /// Per fan triangle, per base corner, the three corners' UVs.
        blend: Option<crate::kernels::jump_maps::jump_surface::Blend<'a>>,
        /// The exemplar.
        texture: &'a Image,
        /// Its wrap.
        wrap: Wrap,
    },
    /// Lapped pastes, composited; `origins[k]` is texture patch `k`'s
    /// exemplar pixel (top-left), `textures` the RGBA patches.
    Lapped {
        /// The pastes indexed per face (RGB background).
        composite: LappedComposite<'a>,
        /// RGBA texture patches.
        textures: &'a [Image],
        /// Per texture patch, its top-left exemplar pixel.
        origins: &'a [[i64; 2]],
    },
}

/// A plane image: RGB pixels and, per pixel, the exemplar pixel it was
/// copied from (NaN where unknown or nothing is drawn).
pub struct PlanePixels {
    /// `grid.width × grid.height`, RGB.
    pub image: Image,
    /// Per pixel, its exemplar source snapped to a pixel centre; `None`
    /// when the signal records no sources.
    pub sources: Option<Vec<[f32; 2]>>,
}

/// Samples `signal` on `mesh` (flat in xy: [`super::plane_raster::check_planar_xy`]) at
/// the pixel centres of `grid`; sources are snapped to the pixels of an
/// exemplar of `exemplar_size`. Pixels outside the mesh stay black.
pub fn sample_plane(
    mesh: &PolyMesh,
    signal: &PlaneSignal,
    grid: &PlaneGrid,
    exemplar_size: [u32; 2],
) -> PlanePixels {
    let (corner_tris, face_of) = mesh.triangulate_corners();
    let vertex_tris: Vec<[u32; 3]> = corner_tris
        .iter()
        .map(|t| t.map(|c| mesh.corner_vertex[c as usize]))
        .collect();
    let hits = rasterise_xy(&mesh.positions, &vertex_tris, grid);
    let mut image = Image::new(grid.width, grid.height, 3);
    let unknown = [f32::NAN; 2];
    let mut sources = vec![unknown; hits.len()];
    let [ew, eh] = exemplar_size;
    let tris = Triangles {
        mesh,
        vertex_tris: &vertex_tris,
        corner_tris: &corner_tris,
        face_of: &face_of,
        exemplar_size: Vec2::new(ew as f32, eh as f32),
    };
    let has_sources = !matches!(signal, PlaneSignal::Colours { sources: None, .. });
    let row = grid.width as usize;
    image
        .data
        .par_chunks_mut(3 * row)
        .zip(sources.par_chunks_mut(row))
        .zip(hits.par_chunks(row))
        .for_each(|((colours, srcs), hits)| {
            for ((c, s), hit) in colours.chunks_exact_mut(3).zip(srcs).zip(hits) {
                if let Some(hit) = hit {
                    let (rgb, src) = tris.pixel(signal, hit);
                    c.copy_from_slice(&rgb);
                    if let Some(p) = src {
                        *s = snap_source(p, ew, eh);
                    }
                }
            }
        });
    PlanePixels {
        image,
        sources: has_sources.then_some(sources),
    }
}

/// The fan triangles of the sampled mesh, by vertex and by corner, with
/// the face each comes from.
struct Triangles<'a> {
    mesh: &'a PolyMesh,
    vertex_tris: &'a [[u32; 3]],
    corner_tris: &'a [[u32; 3]],
    face_of: &'a [u32],
    /// The exemplar's size, pixels.
    exemplar_size: Vec2,
}

impl Triangles<'_> {
    /// The RGB colour of `signal` at `hit` and the exemplar pixel it came
    /// from, when known.
    fn pixel(&self, signal: &PlaneSignal, hit: &PixelHit) -> ([f32; 3], Option<Vec2>) {
        let t = hit.triangle as usize;
        let b = hit.weights;
        match signal {
            PlaneSignal::Colours {
                values,
                channels,
                sources,
            } => {
                let mut c = [0.0f32; 3];
                for (k, &v) in self.vertex_tris[t].iter().enumerate() {
                    let s = v as usize * channels;
                    let px = pixel_rgb(values.get(s..s + channels).unwrap_or(&[]));
                    for i in 0..3 {
                        c[i] += b[k] * px[i];
                    }
                }
                let near = self.vertex_tris[t][dominant_corner(b)];
                (c, sources.and_then(|s| s.get(near as usize).copied()))
            }
            PlaneSignal::Coordinates {
                sources,
                frames,
                scale,
                texture,
                wrap,
            } => {
                let tri = self.vertex_tris[t];
                let positions = &self.mesh.positions;
                let p: Vec3 = tri
                    .iter()
                    .zip(b)
                    .map(|(&v, w)| positions[v as usize] * w)
                    .sum();
                let near = dominant_corner(b);
                let mut out = vec![0.0f32; texture.channels as usize];
                let mut c = [0.0f32; 3];
                let mut near_src = Vec2::ZERO;
                for (k, &v) in tri.iter().enumerate() {
                    let q = continued_source(sources, frames, scale, positions, v as usize, p);
                    texture.sample_bilinear(q.x, q.y, *wrap, &mut out);
                    let px = pixel_rgb(&out);
                    for i in 0..3 {
                        c[i] += b[k] * px[i];
                    }
                    if k == near {
                        near_src = q;
                    }
                }
                (c, Some(near_src))
            }
            PlaneSignal::Uvs {
                uvs,
                blend,
                texture,
                wrap,
            } => {
                let layers: [[Vec2; 3]; 3] = match blend {
                    Some(l) => l.get(t),
                    None => [self.corner_tris[t].map(|c| uvs[c as usize]); 3],
                };
                let mut out = vec![0.0f32; texture.channels as usize];
                let mut c = [0.0f32; 3];
                for (base, l) in layers.iter().enumerate() {
                    let uv = l[0] * b[0] + l[1] * b[1] + l[2] * b[2];
                    texture.sample_uv(uv.x, uv.y, *wrap, &mut out);
                    let px = pixel_rgb(&out);
                    for i in 0..3 {
                        c[i] += b[base] * px[i];
                    }
                }
                let l = layers[dominant_corner(b)];
                let uv = l[0] * b[0] + l[1] * b[1] + l[2] * b[2];
                (c, Some(uv * self.exemplar_size))
            }
            PlaneSignal::Lapped {
                composite,
                textures,
                origins,
            } => lapped_pixel(composite, textures, origins, self.face_of[t] as usize, b),
        }
    }
}

/// The composited colour of face `f` at barycentric `b` and the exemplar
/// pixel of its topmost opaque paste (alpha ≥ ½), when that patch's
/// origin is known.
fn lapped_pixel(
    composite: &LappedComposite,
    textures: &[Image],
    origins: &[[i64; 2]],
    f: usize,
    b: [f32; 3],
) -> ([f32; 3], Option<Vec2>) {
    let mut c = [0.0f32; 3];
    composite.eval_face(f, b, &mut c);
    let mut px = [0.0f32; 4];
    let src = composite.face_layers(f).iter().rev().find_map(|(tex, l)| {
        let texture = textures.get(*tex as usize)?;
        let uv = l[0] * b[0] + l[1] * b[1] + l[2] * b[2];
        texture.sample_uv(uv.x, uv.y, Wrap::Clamp, &mut px);
        let o = origins.get(*tex as usize)?;
        (px[3] >= 0.5).then(|| {
            Vec2::new(o[0] as f32, o[1] as f32)
                + uv * Vec2::new(texture.width as f32, texture.height as f32)
        })
    });
    (c, src)
}
