//! The `plane` format of `export`: the active result sampled into an image
//! at one pixel per pixel over the xy bounding box of a flat mesh
//! ([`PlaneImage`]). Thin over `kernels::atlas::plane_raster` (which
//! triangle holds each pixel centre) and `kernels::atlas::plane_signal`
//! (the signals' own evaluation: vertex colours interpolated, corner UVs
//! blended as the preview renderer does, lapped pastes composited in paste
//! order).

use crate::kernels::atlas::plane_raster::{PlaneGrid, check_planar_xy, snap_source};
use crate::kernels::atlas::plane_signal::{PlanePixels, sample_plane};
use crate::mesh::PolyMesh;
use crate::world::{PlaneImage, SynthesisedImage};
use glam::Vec2;

pub use crate::kernels::atlas::plane_signal::PlaneSignal;

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
///
/// # Errors
/// As [`plane_from_surface`].
pub fn plane_from_surface_at(
    mesh: &PolyMesh,
    signal: &PlaneSignal,
    size: [u32; 2],
    exemplar_size: [u32; 2],
    pixel: f32,
) -> Result<PlaneImage, String> {
    check_planar_xy(&mesh.positions).map_err(|r| planar_message("the active mesh", &r))?;
    let grid = PlaneGrid::at_spacing(&mesh.positions, size[0], size[1], pixel);
    let PlanePixels { image, sources } = sample_plane(mesh, signal, &grid, exemplar_size);
    Ok(PlaneImage {
        image,
        sources,
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
