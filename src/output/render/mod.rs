//! Headless software renderer for result previews.
//!
//! [`render`] draws a [`PolyMesh`] from one [`View`] into an RGB `f32`
//! [`Image`]; [`render_views`] draws the three [`DEFAULT_VIEWS`] and
//! [`write_previews`] saves them as PNG files.
//!
//! Conventions:
//! - Y is up. Azimuth 0, elevation 0 looks at the mesh from the +Z side
//!   (along −Z) with +X to the right of the image; positive azimuth moves the
//!   camera toward +X, positive elevation lifts it.
//! - The camera is a perspective camera (vertical field of view
//!   [`RenderOptions::fov_y_deg`]) aimed at the mesh and pulled back until
//!   the projected mesh fills [`RenderOptions::fill`] of the frame's
//!   half-size in its larger direction, so every view is framed tightly.
//! - Texture coordinates follow [`Image::sample_uv`]: `v = 0` is the image's
//!   top row.
//! - Colours and textures with 1 channel are grey, 2 grey + alpha, 3 RGB,
//!   4 RGBA; more channels use the first three as opaque RGB. Alpha
//!   composites over [`RenderOptions::base_colour`].
//! - Both sides of every triangle are drawn and lit (the normal is flipped
//!   toward the camera), since scans have holes and open boundaries.
//! - The output is bit-identical for any number of rayon threads: the image
//!   is cut into strips of rows, each strip rasterises its triangles in mesh
//!   order into its own z-buffer, and equal depths keep the earlier triangle.
//!
//! The pipeline: fan-triangulate ([`PolyMesh::triangulate_corners`]), project
//! and set up triangles in fixed point (`raster`), bin them into strips, then
//! per strip rasterise a visibility buffer (depth and triangle id per sample),
//! shade every sample once (`shade`: perspective-correct interpolation,
//! surface colour, Lambert with ambient) and box-filter the supersamples.

mod camera;
mod raster;
mod shade;

use crate::image::Image;
use crate::image::sample::Wrap;
use crate::mesh::PolyMesh;
use crate::output::{OutputError, write_png};
use glam::Vec2;
use rayon::prelude::*;
use std::path::{Path, PathBuf};

/// A camera direction, in degrees (see the module conventions).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct View {
    /// Rotation about +Y; 0 looks from +Z, 90 from +X.
    pub azimuth_deg: f32,
    /// Angle above the horizontal plane; 90 looks straight down.
    pub elevation_deg: f32,
}

/// Front-left three-quarter view, right side, and from above (front at the bottom).
pub const DEFAULT_VIEWS: [View; 3] = [
    View {
        azimuth_deg: -35.0,
        elevation_deg: 20.0,
    },
    View {
        azimuth_deg: 90.0,
        elevation_deg: 10.0,
    },
    View {
        azimuth_deg: 20.0,
        elevation_deg: 65.0,
    },
];

/// One paste of a lapped texture: a texture mapped onto some faces.
#[derive(Clone, Copy, Debug)]
pub struct Layer<'a> {
    /// Mesh faces the layer covers (a face may appear in many layers).
    pub faces: &'a [u32],
    /// Texture coordinates of the corners of `faces` only, compactly: the
    /// corners of `faces[0]` in the face's corner order, then those of
    /// `faces[1]`, and so on; `Σ degree(faces[i])` entries. (Compact so that
    /// hundreds of patches do not each hold a whole-mesh array.)
    pub uvs: &'a [Vec2],
    /// The texture; its alpha (channel 2 of 2, or 4 of 4) blends the layer
    /// over the layers below.
    pub texture: &'a Image,
    /// Addressing outside `[0, 1]`.
    pub wrap: Wrap,
}

/// Gathers the compact [`Layer::uvs`] of `faces` from a per-corner array of
/// the whole mesh (`mesh.corner_count()` entries).
///
/// # Panics
/// When a face id or a corner is out of range.
pub fn gather_layer_uvs(mesh: &PolyMesh, faces: &[u32], corner_uvs: &[Vec2]) -> Vec<Vec2> {
    faces
        .iter()
        .flat_map(|&f| corner_uvs[mesh.face_corners(f as usize)].iter().copied())
        .collect()
}

/// What colours the surface.
#[derive(Clone, Copy, Debug)]
pub enum Shading<'a> {
    /// [`RenderOptions::base_colour`] everywhere.
    Plain,
    /// Per-vertex colours, `channels` (1–4) values per vertex, interpolated.
    VertexColours { values: &'a [f32], channels: usize },
    /// A texture mapped with per-corner coordinates (`mesh.corner_count()`
    /// entries).
    CornerUvs {
        uvs: &'a [Vec2],
        texture: &'a Image,
        wrap: Wrap,
    },
    /// The jump-map 3-way blend (Zelinka & Garland 2004 §6.5): for every fan
    /// triangle of [`PolyMesh::triangulate_corners`], the texture coordinates
    /// of its three corners for each choice of base vertex. The three look-ups
    /// are blended with linear alpha ramps (the barycentric coordinate of each
    /// base vertex).
    BlendedUvs {
        layers: crate::kernels::jump_maps::jump_surface::Blend<'a>,
        texture: &'a Image,
        wrap: Wrap,
    },
    /// A per-vertex result read at the exemplar's resolution: at every pixel
    /// each vertex of the triangle continues its source coordinate
    /// (`sources`, exemplar pixels) through its tangent frame to the pixel's
    /// surface point at `texels_per_unit` (one value for all vertices, or
    /// one per vertex), and the three look-ups are blended barycentrically —
    /// what `bake` does with `colours = "coordinates"`.
    Coordinates {
        sources: &'a [Vec2],
        frames: &'a [crate::kernels::surface::frames::TangentFrame],
        texels_per_unit: &'a [f32],
        texture: &'a Image,
        wrap: Wrap,
    },
    /// Lapped-texture layers, composited in order (later ones on top) with
    /// alpha blending over the base colour.
    ///
    /// Praun et al. 2000 draw each patch depth-tested for equality against
    /// the opaque surface. Here a layer contributes to a pixel exactly when
    /// the visible surface at that pixel belongs to one of its faces: the
    /// same result with an exact face match instead of a depth epsilon, so
    /// layers never z-fight and never bleed onto faces they do not cover.
    Layers(&'a [Layer<'a>]),
}

/// How normals are computed for lighting.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Normals {
    /// One normal per face: shows the facets.
    Flat,
    /// Area-weighted per-corner normals averaging only the faces around the
    /// vertex whose normal is within `crease_deg` of the corner's face
    /// normal. 180 averages all faces (plain vertex normals); the default 60
    /// keeps real creases and badly oriented faces sharp.
    Smooth { crease_deg: f32 },
}

/// The image behind the mesh.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Background {
    /// One colour.
    Solid([f32; 3]),
    /// A vertical gradient from the top row to the bottom row.
    Gradient { top: [f32; 3], bottom: [f32; 3] },
}

/// Settings of the preview renderer.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderOptions {
    /// Supersampling factor per axis, 1–4 (values outside are clamped);
    /// default 2 (2×2 samples per pixel, box-filtered).
    pub supersample: u32,
    /// Lighting normals; default smooth with a 60° crease angle.
    pub normals: Normals,
    /// Default: a light grey gradient.
    pub background: Background,
    /// Surface colour under [`Shading::Plain`] and under any alpha; default 0.72 grey.
    pub base_colour: [f32; 3],
    /// Ambient term `a` of the lighting `a + (1 − a)·max(0, n·l)`, in
    /// `[0, 1]`; 1 renders unlit surface colours. Default 0.25.
    pub ambient: f32,
    /// Vertical field of view in degrees; default 35.
    pub fov_y_deg: f32,
    /// Fraction of the frame's half-size that the mesh fills; default 0.85.
    pub fill: f32,
}

impl Default for RenderOptions {
    fn default() -> Self {
        Self {
            supersample: 2,
            normals: Normals::Smooth { crease_deg: 60.0 },
            background: Background::Gradient {
                top: [0.95, 0.95, 0.96],
                bottom: [0.82, 0.82, 0.84],
            },
            base_colour: [0.72, 0.72, 0.72],
            ambient: 0.25,
            fov_y_deg: 35.0,
            fill: 0.85,
        }
    }
}

/// Shading data that does not fit the mesh.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum RenderError {
    /// An attribute array has the wrong length.
    #[error("{what} has {found} entries, expected {expected}")]
    Length {
        what: String,
        expected: usize,
        found: usize,
    },
    /// A channel count outside what the renderer can show.
    #[error("{what} has {channels} channels, expected 1 to 4")]
    Channels { what: String, channels: usize },
    /// A texture whose size or data length is inconsistent.
    #[error("{what} is {width}×{height}×{channels} with {len} values")]
    Texture {
        what: String,
        width: u32,
        height: u32,
        channels: u32,
        len: usize,
    },
    /// A layer names a face the mesh does not have.
    #[error("layer {layer} names face {face}, but the mesh has {face_count} faces")]
    Face {
        layer: usize,
        face: u32,
        face_count: usize,
    },
}

fn check_texture(what: &str, t: &Image) -> Result<(), RenderError> {
    let expected = t.width as usize * t.height as usize * t.channels as usize;
    if t.width == 0 || t.height == 0 || t.channels == 0 || t.data.len() != expected {
        return Err(RenderError::Texture {
            what: what.to_string(),
            width: t.width,
            height: t.height,
            channels: t.channels,
            len: t.data.len(),
        });
    }
    Ok(())
}

fn check_length(what: &str, expected: usize, found: usize) -> Result<(), RenderError> {
    if expected == found {
        Ok(())
    } else {
        Err(RenderError::Length {
            what: what.to_string(),
            expected,
            found,
        })
    }
}

impl Shading<'_> {
    /// Checks that the attribute arrays fit `mesh`; [`render`] panics with
    /// this error's message otherwise.
    pub fn check(&self, mesh: &PolyMesh) -> Result<(), RenderError> {
        match *self {
            Shading::Plain => Ok(()),
            Shading::VertexColours { values, channels } => {
                if !(1..=4).contains(&channels) {
                    return Err(RenderError::Channels {
                        what: "vertex colours".into(),
                        channels,
                    });
                }
                check_length(
                    "vertex colours",
                    mesh.vertex_count() * channels,
                    values.len(),
                )
            }
            Shading::CornerUvs { uvs, texture, .. } => {
                check_texture("texture", texture)?;
                check_length("corner uvs", mesh.corner_count(), uvs.len())
            }
            Shading::Coordinates {
                sources,
                frames,
                texels_per_unit,
                texture,
                ..
            } => {
                check_texture("texture", texture)?;
                check_length("source coordinates", mesh.vertex_count(), sources.len())?;
                check_length("frames", mesh.vertex_count(), frames.len())?;
                if texels_per_unit.len() != 1 {
                    check_length(
                        "texels per unit",
                        mesh.vertex_count(),
                        texels_per_unit.len(),
                    )?;
                }
                Ok(())
            }
            Shading::BlendedUvs {
                layers, texture, ..
            } => {
                check_texture("texture", texture)?;
                let tris: usize = (0..mesh.face_count())
                    .map(|f| mesh.face_corners(f).len().saturating_sub(2))
                    .sum();
                check_length("blend layers (fan triangles)", tris, layers.len())
            }
            Shading::Layers(layers) => {
                for (i, layer) in layers.iter().enumerate() {
                    check_texture(&format!("layer {i} texture"), layer.texture)?;
                    let mut corners = 0;
                    for &f in layer.faces {
                        if f as usize >= mesh.face_count() {
                            return Err(RenderError::Face {
                                layer: i,
                                face: f,
                                face_count: mesh.face_count(),
                            });
                        }
                        corners += mesh.face_corners(f as usize).len();
                    }
                    check_length(&format!("layer {i} uvs"), corners, layer.uvs.len())?;
                }
                Ok(())
            }
        }
    }
}

/// Lower-resolution rows per parallel strip.
const STRIP_ROWS: u32 = 8;

impl shade::Scene<'_> {
    /// Renders one `size`×`size` view.
    fn render(&self, view: &View, size: u32) -> Image {
        let _span = tracing::debug_span!(
            "render_view",
            azimuth = view.azimuth_deg,
            elevation = view.elevation_deg,
            size
        )
        .entered();
        let mut img = Image::new(size, size, 3);
        if size == 0 {
            return img;
        }
        let opts = self.options;
        let ss = opts.supersample.clamp(1, 4);
        let hi = size * ss;
        let camera = camera::Camera::fit(
            &self.mesh.positions,
            view,
            opts.fov_y_deg,
            opts.fill,
            hi,
            hi,
        );
        let light = camera.key_light();
        // Set-up data is not kept for the whole mesh: binning keeps triangle
        // indices, and each strip sets its triangles up again (the same
        // deterministic computation) into scratch reused by its worker.
        let projected = raster::project(&self.mesh.positions, &camera);
        let setup = |t: u32| {
            raster::setup(
                t,
                self.tris.corners(t as usize),
                &projected,
                &self.mesh.positions,
                &self.mesh.corner_vertex,
                &camera,
                hi,
                hi,
            )
        };
        let strip_hi = (STRIP_ROWS * ss) as i32;
        let strips = size.div_ceil(STRIP_ROWS) as usize;
        let (start, items) = raster::bin_strips(
            self.tris.len(),
            |t| setup(t).map(|tri| (tri.bounds[1], tri.bounds[3])),
            strip_hi,
            strips,
        );

        let width = hi as usize;
        let row_len = size as usize * 3;
        let inv_samples = 1.0 / (ss * ss) as f32;
        let background = |y: i32| match opts.background {
            Background::Solid(c) => c,
            Background::Gradient { top, bottom } => {
                let t = (y as f32 + 0.5) / hi as f32;
                [0, 1, 2].map(|i| top[i] + (bottom[i] - top[i]) * t)
            }
        };
        img.data
            .par_chunks_mut(STRIP_ROWS as usize * row_len)
            .enumerate()
            .for_each_init(
                // Scratch z-buffers and set-up triangles, reused across the strips of one worker
                // (`raster_strip` clears them, so reuse cannot change results).
                || (Vec::new(), Vec::new(), Vec::new()),
                |(depth, id, tris), (s, out)| {
                    let rows_lo = out.len() / row_len;
                    let rows_hi = rows_lo * ss as usize;
                    let row0 = s as i32 * strip_hi;
                    depth.resize(rows_hi * width, 0.0f32);
                    id.resize(rows_hi * width, u32::MAX);
                    let bin = &items[start[s] as usize..start[s + 1] as usize];
                    tris.clear();
                    tris.extend(bin.iter().filter_map(|&t| setup(t)));
                    raster::raster_strip(tris, row0, rows_hi as i32, width, depth, id);
                    for ly in 0..rows_lo {
                        for lx in 0..size as usize {
                            let mut acc = [0.0f32; 3];
                            for sy in 0..ss as usize {
                                let hy = ly * ss as usize + sy;
                                let py = row0 + hy as i32;
                                for sx in 0..ss as usize {
                                    let hx = lx * ss as usize + sx;
                                    let t = id[hy * width + hx];
                                    let c = if t == u32::MAX {
                                        background(py)
                                    } else {
                                        self.shade(&tris[t as usize], hx as i32, py, light)
                                    };
                                    for k in 0..3 {
                                        acc[k] += c[k];
                                    }
                                }
                            }
                            let o = ly * row_len + lx * 3;
                            for k in 0..3 {
                                out[o + k] = acc[k] * inv_samples;
                            }
                        }
                    }
                },
            );
        img
    }
}

fn scene<'a>(
    mesh: &'a PolyMesh,
    shading: &'a Shading<'a>,
    options: &'a RenderOptions,
) -> shade::Scene<'a> {
    if let Err(e) = shading.check(mesh) {
        panic!("render: shading does not fit the mesh: {e}");
    }
    shade::Scene::new(mesh, shading, options)
}

/// Renders `mesh` from `view` into a `size`×`size` RGB image (values in `[0, 1]`).
///
/// Degenerate input (no faces, zero-area triangles, a single point) renders
/// the background.
///
/// # Panics
/// When `shading` does not fit `mesh` (see [`Shading::check`]).
pub fn render(
    mesh: &PolyMesh,
    shading: &Shading,
    view: &View,
    size: u32,
    options: &RenderOptions,
) -> Image {
    scene(mesh, shading, options).render(view, size)
}

/// Renders `mesh` from each of the [`DEFAULT_VIEWS`], sharing the per-mesh
/// preparation (triangulation, normals) between views.
///
/// # Panics
/// When `shading` does not fit `mesh` (see [`Shading::check`]).
pub fn render_views(
    mesh: &PolyMesh,
    shading: &Shading,
    size: u32,
    options: &RenderOptions,
) -> Vec<Image> {
    let scene = scene(mesh, shading, options);
    DEFAULT_VIEWS
        .iter()
        .map(|v| scene.render(v, size))
        .collect()
}

/// Writes `images` as `dir/{prefix}_0.png`, `dir/{prefix}_1.png`, … (just
/// `0.png`, … for an empty prefix), creating `dir`, and returns the paths.
/// `write_previews(dir, "preview", &images)` gives `preview_0.png`, ….
pub fn write_previews(
    dir: &Path,
    prefix: &str,
    images: &[Image],
) -> Result<Vec<PathBuf>, OutputError> {
    images
        .iter()
        .enumerate()
        .map(|(i, img)| {
            let name = if prefix.is_empty() {
                format!("{i}.png")
            } else {
                format!("{prefix}_{i}.png")
            };
            let path = dir.join(name);
            write_png(&path, img)?;
            Ok(path)
        })
        .collect()
}
