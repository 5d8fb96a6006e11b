//! The `plane` format of `export`: the active result sampled into an image
//! at one pixel per pixel over the xy bounding box of a flat mesh
//! ([`PlaneImage`]). Thin over `kernels::atlas::plane_raster` (which triangle holds
//! each pixel centre) and the signals' own evaluation: vertex colours
//! interpolated, corner UVs blended as the preview renderer does, lapped
//! pastes composited in paste order (`kernels::lapped::composite`).

use crate::image::sample::Wrap;
use crate::image::{Image, pixel_rgb};
use crate::kernels::atlas::plane_raster::{
    PixelHit, PlaneGrid, check_planar_xy, dominant_corner, rasterise_xy, snap_source,
};
use crate::kernels::lapped::composite::LappedComposite;
use crate::kernels::surface::frames::TangentFrame;
use crate::mesh::PolyMesh;
use crate::world::{PlaneImage, SynthesisedImage};
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

/// Why a mesh cannot give a plane image, as the message of a stage failure.
pub fn planar_message(what: &str, reason: &str) -> String {
    format!(
        "format `plane` samples the result over the xy bounding box of a mesh flat in the xy plane, but {what} is not: {reason}; allowed: a planar mesh in z = const (e.g. `builtin:plane`, or `builtin_pyramid` with mesh = \"plane\"), or a `jump_image` result"
    )
}

/// The plane image of a surface result on `mesh` (`width × height`).
///
/// # Errors
/// A message naming what is wrong when `mesh` is not flat in xy.
pub fn plane_from_surface(
    mesh: &PolyMesh,
    signal: &PlaneSignal,
    size: [u32; 2],
    exemplar_size: [u32; 2],
) -> Result<PlaneImage, String> {
    plane_from_surface_at(mesh, signal, size, exemplar_size, 0.0)
}

/// [`plane_from_surface`] with pixels `pixel` world units apart from the
/// box's top-left corner ([`PlaneGrid::at_spacing`]); `pixel = 0` spans the
/// bounding box ([`PlaneGrid::over`]).
pub fn plane_from_surface_at(
    mesh: &PolyMesh,
    signal: &PlaneSignal,
    size: [u32; 2],
    exemplar_size: [u32; 2],
    pixel: f32,
) -> Result<PlaneImage, String> {
    check_planar_xy(&mesh.positions).map_err(|r| planar_message("the active mesh", &r))?;
    let [w, h] = size;
    let grid = PlaneGrid::at_spacing(&mesh.positions, w, h, pixel);
    let (corner_tris, face_of) = mesh.triangulate_corners();
    let vertex_tris: Vec<[u32; 3]> = corner_tris
        .iter()
        .map(|t| t.map(|c| mesh.corner_vertex[c as usize]))
        .collect();
    let hits = rasterise_xy(&mesh.positions, &vertex_tris, &grid);
    let mut image = Image::new(w, h, 3);
    let unknown = [f32::NAN; 2];
    let mut sources = vec![unknown; hits.len()];
    let [ew, eh] = exemplar_size;
    let ex = Vec2::new(ew as f32, eh as f32);
    let has_sources = !matches!(signal, PlaneSignal::Colours { sources: None, .. });
    let pixel = |hit: &PixelHit| -> ([f32; 3], Option<Vec2>) {
        let t = hit.triangle as usize;
        let b = hit.weights;
        let near = dominant_corner(b);
        match signal {
            PlaneSignal::Colours {
                values,
                channels,
                sources,
            } => {
                let mut c = [0.0f32; 3];
                for (k, &v) in vertex_tris[t].iter().enumerate() {
                    let s = v as usize * channels;
                    let px = pixel_rgb(values.get(s..s + channels).unwrap_or(&[]));
                    for i in 0..3 {
                        c[i] += b[k] * px[i];
                    }
                }
                let src = sources.and_then(|s| s.get(vertex_tris[t][near] as usize).copied());
                (c, src)
            }
            PlaneSignal::Coordinates {
                sources,
                frames,
                scale,
                texture,
                wrap,
            } => {
                let tri = vertex_tris[t];
                let p: Vec3 = tri
                    .iter()
                    .zip(b)
                    .map(|(&v, w)| mesh.positions[v as usize] * w)
                    .sum();
                let mut out = vec![0.0f32; texture.channels as usize];
                let mut c = [0.0f32; 3];
                let mut near_src = Vec2::ZERO;
                for (k, &v) in tri.iter().enumerate() {
                    let v = v as usize;
                    let q = crate::kernels::surface::frames::continued_source(
                        sources,
                        frames,
                        scale,
                        &mesh.positions,
                        v,
                        p,
                    );
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
                    None => [corner_tris[t].map(|c| uvs[c as usize]); 3],
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
                let l = layers[near];
                let uv = l[0] * b[0] + l[1] * b[1] + l[2] * b[2];
                (c, Some(uv * ex))
            }
            PlaneSignal::Lapped {
                composite,
                textures,
                origins,
            } => {
                let f = face_of[t] as usize;
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
        }
    };
    let row = w as usize;
    image
        .data
        .par_chunks_mut(3 * row)
        .zip(sources.par_chunks_mut(row))
        .zip(hits.par_chunks(row))
        .for_each(|((colours, srcs), hits)| {
            for ((c, s), hit) in colours.chunks_exact_mut(3).zip(srcs).zip(hits) {
                if let Some(hit) = hit {
                    let (rgb, src) = pixel(hit);
                    c.copy_from_slice(&rgb);
                    if let Some(p) = src {
                        *s = snap_source(p, ew, eh);
                    }
                }
            }
        });
    Ok(PlaneImage {
        image,
        sources: has_sources.then_some(sources),
        exemplar_size,
    })
}

/// The plane image of a `jump_image` result: the image itself (RGB) and its
/// source map snapped to pixel centres.
///
/// # Errors
/// A message when its size is not `size`.
pub fn plane_from_image(
    synth: &SynthesisedImage,
    size: [u32; 2],
    exemplar_size: [u32; 2],
) -> Result<PlaneImage, String> {
    let img = &synth.image;
    if [img.width, img.height] != size {
        return Err(size_message(img.width, img.height, size));
    }
    let image = img.to_rgb();
    let [ew, eh] = exemplar_size;
    let sources = synth
        .sources
        .iter()
        .map(|s| snap_source(Vec2::new(s[0], s[1]), ew, eh))
        .collect();
    Ok(PlaneImage {
        image,
        sources: Some(sources),
        exemplar_size,
    })
}

/// The message when a `jump_image` result and `plane_size` disagree.
pub fn size_message(width: u32, height: u32, size: [u32; 2]) -> String {
    format!(
        "format `plane` writes a `jump_image` result as it is ({width} × {height} pixels), but plane_size is {} × {}; allowed: plane_size equal to jump_image's width and height",
        size[0], size[1]
    )
}
