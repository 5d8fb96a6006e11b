//! Material channels that follow one synthesis (issue 7): tangent-space normal
//! encoding, re-orientation of a normal into another tangent frame, and the
//! derivations that make height and normal maps from a colour exemplar.
//!
//! # Tangent-space normal convention
//!
//! A normal-map texel `(r, g, b)` in `[0, 1]` encodes the unit vector
//! `(2r − 1, 2g − 1, 2b − 1)` with **+X to the right and +Y up in the image as
//! displayed** and +Z out of the surface (the OpenGL / glTF convention). The
//! project's images store rows top-down (pixel y grows downwards) and its
//! tangent frames have `s` = texture right and `t` = texture up
//! ([`crate::kernels::surface::frames::TangentFrame`]), so a decoded texel normal
//! `(x, y, z)` copied from the exemplar at a vertex means the world direction
//! `x·s + y·t + z·n` of that vertex's synthesis frame. Moving one pixel down the
//! image (+y in pixels) is moving along −t.
//!
//! # Re-orientation
//!
//! A baked normal map is read in the tangent frame of the atlas (its +X is
//! the direction of increasing atlas u). The synthesis frame's `s` generally
//! differs from it by an angle θ about the normal, so copying the texel raw
//! would turn every bump by θ. [`reorient_normal`] expresses the same world
//! direction in the target frame.

use glam::{Vec2, Vec3};

use crate::image::Image;
use crate::image::sample::Wrap;

/// Decodes a normal-map texel (values in `[0, 1]`) into a unit tangent-space
/// vector (+X right, +Y up as displayed, +Z out). A texel that decodes to a
/// (near) zero vector gives the flat normal `+Z`.
#[inline]
pub fn decode_normal(texel: [f32; 3]) -> Vec3 {
    let v = Vec3::new(
        2.0 * texel[0] - 1.0,
        2.0 * texel[1] - 1.0,
        2.0 * texel[2] - 1.0,
    );
    v.try_normalize().unwrap_or(Vec3::Z)
}

/// Encodes a tangent-space vector as a normal-map texel in `[0, 1]`; the
/// vector is normalised first (a zero vector encodes the flat normal `+Z`).
#[inline]
pub fn encode_normal(n: Vec3) -> [f32; 3] {
    let n = n.try_normalize().unwrap_or(Vec3::Z);
    [
        (0.5 * n.x + 0.5).clamp(0.0, 1.0),
        (0.5 * n.y + 0.5).clamp(0.0, 1.0),
        (0.5 * n.z + 0.5).clamp(0.0, 1.0),
    ]
}

/// Re-expresses a tangent-space normal `tex`, given in the synthesis frame
/// `(s, t, n)`, in a target tangent frame `(x, y, n)` whose x-axis is at
/// `angle` radians from `s`, measured about `n` counter-clockwise (positive
/// from `s` towards `t`; see [`frame_angle`]).
///
/// The world direction is unchanged, so its components rotate the other way:
/// the result is `tex` rotated by **−angle** about +Z. Equivalently, when the
/// synthesis frame is the target frame turned by φ (angle = −φ), the normal
/// map comes out turned by +φ — the texture's bumps follow the orientation
/// field. The Z component is unchanged.
#[inline]
pub fn reorient_normal(tex: Vec3, angle: f32) -> Vec3 {
    let (sin, cos) = angle.sin_cos();
    Vec3::new(cos * tex.x + sin * tex.y, -sin * tex.x + cos * tex.y, tex.z)
}

/// The angle in radians, in `(−π, π]`, from the synthesis frame's `s` axis to a
/// target frame's tangent (x-axis), both projected onto the plane of `normal`,
/// counter-clockwise about `normal` (right-handed). This is the `angle` of
/// [`reorient_normal`]. Returns 0 when either projected vector is degenerate
/// (parallel to the normal or zero).
pub fn frame_angle(s: Vec3, tangent: Vec3, normal: Vec3) -> f32 {
    let Some(n) = normal.try_normalize() else {
        return 0.0;
    };
    let a = s - n * s.dot(n);
    let b = tangent - n * tangent.dot(n);
    if a.length_squared() < 1e-20 || b.length_squared() < 1e-20 {
        return 0.0;
    }
    let sin = a.cross(b).dot(n);
    let cos = a.dot(b);
    sin.atan2(cos)
}

/// A normal-map texel copied from the exemplar at a sample whose synthesis
/// frame has tangent `s`, re-expressed in a target tangent frame with
/// x-axis `tangent` and normal `normal` (right-handed, y = normal × tangent),
/// encoded again: [`decode_normal`], [`reorient_normal`] by
/// [`frame_angle`]`(s, tangent, normal)`, [`encode_normal`]. What a bake
/// writes into a normal-map atlas texel.
pub fn normal_texel_in_frame(texel: [f32; 3], s: Vec3, tangent: Vec3, normal: Vec3) -> [f32; 3] {
    encode_normal(reorient_normal(
        decode_normal(texel),
        frame_angle(s, tangent, normal),
    ))
}

/// Rec. 709 luminance of a pixel's first three channels (the first channel
/// alone for grey images).
#[inline]
pub fn luminance(px: &[f32]) -> f32 {
    match px {
        [r, g, b, ..] => 0.2126 * r + 0.7152 * g + 0.0722 * b,
        [g, ..] => *g,
        [] => 0.0,
    }
}

/// A one-channel image of the luminance of `img` (the `derive:luminance`
/// height and roughness maps).
pub fn luminance_image(img: &Image) -> Image {
    let c = (img.channels as usize).max(1);
    let data = img.data.chunks_exact(c).map(luminance).collect();
    Image {
        width: img.width,
        height: img.height,
        channels: 1,
        data,
    }
}

/// A one-channel image of `1 − luminance(img)`: the `derive:luminance`
/// roughness map (bright texels smooth, dark crevices rough).
pub fn inverted_luminance_image(img: &Image) -> Image {
    let mut out = luminance_image(img);
    for v in &mut out.data {
        *v = (1.0 - *v).clamp(0.0, 1.0);
    }
    out
}

/// A tangent-space normal map (RGB, [`encode_normal`]) from a height map's
/// first channel by the Sobel gradient: with `g_x`, `g_y` the height change
/// per pixel to the right and downwards (Sobel / 8),
/// `n = normalize(−strength·g_x, +strength·g_y, 1)` — +Y is up as displayed,
/// so a height rising downwards in the image tilts the normal up (+Y).
/// `strength` is the relief in pixels that a height difference of 1 spans;
/// 0 gives a flat map. Neighbours beyond the border follow `wrap`.
pub fn normal_from_height(height: &Image, strength: f32, wrap: Wrap) -> Image {
    let (w, h) = (height.width, height.height);
    let mut out = Image::new(w, h, 3);
    if w == 0 || h == 0 {
        return out;
    }
    let at = |x: i64, y: i64| height.texel(x, y, wrap)[0];
    for y in 0..h as i64 {
        for x in 0..w as i64 {
            let gx = (at(x + 1, y - 1) + 2.0 * at(x + 1, y) + at(x + 1, y + 1)
                - at(x - 1, y - 1)
                - 2.0 * at(x - 1, y)
                - at(x - 1, y + 1))
                / 8.0;
            let gy = (at(x - 1, y + 1) + 2.0 * at(x, y + 1) + at(x + 1, y + 1)
                - at(x - 1, y - 1)
                - 2.0 * at(x, y - 1)
                - at(x + 1, y - 1))
                / 8.0;
            let n = Vec3::new(-strength * gx, strength * gy, 1.0);
            out.pixel_mut(x as u32, y as u32)
                .copy_from_slice(&encode_normal(n));
        }
    }
    out
}

/// Mean of a one-channel image's values (0 for an empty image).
pub fn mean_height(height: &Image) -> f32 {
    height.mean().first().copied().unwrap_or(0.0)
}

/// Heights of a one-channel map at per-vertex exemplar coordinates
/// (`SourceTexels`: continuous pixels, centres at `i + 0.5`), bilinear,
/// addressed with `wrap`.
pub fn heights_at_texels(height: &Image, wrap: Wrap, texels: &[Vec2]) -> Vec<f32> {
    use rayon::prelude::*;
    texels
        .par_iter()
        .map(|t| {
            let mut h = [0.0f32];
            height.sample_bilinear(t.x, t.y, wrap, &mut h);
            h[0]
        })
        .collect()
}

/// Per-vertex heights from per-corner texture coordinates (`CornerUvs`,
/// `[0, 1]` units of the exemplar, v = 0 at the top row): each vertex gets the
/// mean of the heights its corners' coordinates address (corners of one
/// vertex may sit in different patches of a jump-map result).
/// `corner_vertices` is the mesh's corner → vertex array (`PolyMesh::corner_vertex`)
/// and `uvs` has one entry per corner. Returns the heights and a mask that
/// is false for vertices without corners (isolated; their height is 0), so
/// the caller can leave them in place.
pub fn heights_at_corner_uvs(
    height: &Image,
    wrap: Wrap,
    vertex_count: usize,
    corner_vertices: &[u32],
    uvs: &[Vec2],
) -> (Vec<f32>, Vec<bool>) {
    let mut sum = vec![0.0f64; vertex_count];
    let mut count = vec![0u32; vertex_count];
    let mut h = [0.0f32];
    for (&v, uv) in corner_vertices.iter().zip(uvs) {
        let Some(s) = sum.get_mut(v as usize) else {
            continue;
        };
        height.sample_uv(uv.x, uv.y, wrap, &mut h);
        *s += h[0] as f64;
        count[v as usize] += 1;
    }
    let heights = sum
        .iter()
        .zip(&count)
        .map(|(s, &c)| if c > 0 { (*s / c as f64) as f32 } else { 0.0 })
        .collect();
    (heights, count.iter().map(|&c| c > 0).collect())
}

/// Moves each vertex along its unit normal by `amplitude · (h − mean)`
/// (the papers' displacement examples): `positions`, `normals` and
/// `heights` are per vertex; vertices whose `moved` entry is false stay.
/// Returns the new positions.
pub fn displace_along_normals(
    positions: &[Vec3],
    normals: &[Vec3],
    heights: &[f32],
    moved: &[bool],
    mean: f32,
    amplitude: f32,
) -> Vec<Vec3> {
    positions
        .iter()
        .enumerate()
        .map(|(v, &p)| {
            let (Some(n), Some(h), Some(true)) = (normals.get(v), heights.get(v), moved.get(v))
            else {
                return p;
            };
            p + *n * (amplitude * (h - mean))
        })
        .collect()
}

/// Smooths per-vertex heights over the mesh: `passes` Jacobi steps, each
/// setting a vertex to the mean of itself and the mean of its neighbours
/// (weights ½, ½). Vertices with `moved[v] == false` neither change nor
/// contribute. The heights are point samples of the map at unrelated texels
/// across patch seams, and of texel-scale speckle; a few passes remove that
/// jitter while keeping features several edges wide.
pub fn smooth_vertex_heights(
    topo: &crate::mesh::Topology,
    heights: &mut Vec<f32>,
    moved: &[bool],
    passes: u32,
) {
    smooth_vertex_heights_with_progress(
        topo,
        heights,
        moved,
        passes,
        &crate::progress::Progress::hidden(),
    );
}

/// [`smooth_vertex_heights`], advancing `progress` by one step per pass.
pub fn smooth_vertex_heights_with_progress(
    topo: &crate::mesh::Topology,
    heights: &mut Vec<f32>,
    moved: &[bool],
    passes: u32,
    progress: &crate::progress::Progress,
) {
    use rayon::prelude::*;
    for _ in 0..passes {
        let h: &[f32] = heights;
        let next: Vec<f32> = (0..h.len())
            .into_par_iter()
            .map(|v| {
                if !moved.get(v).copied().unwrap_or(false) {
                    return h[v];
                }
                let (mut sum, mut n) = (0.0f32, 0u32);
                for &w in topo.neighbours(v as u32) {
                    if moved.get(w as usize).copied().unwrap_or(false) {
                        sum += h[w as usize];
                        n += 1;
                    }
                }
                if n == 0 {
                    h[v]
                } else {
                    0.5 * h[v] + 0.5 * sum / n as f32
                }
            })
            .collect();
        *heights = next;
        progress.inc(1);
    }
}

/// The exemplar coordinates that address a height map, per vertex or per
/// corner ([`displace_by_height_with_progress`]).
#[derive(Clone, Copy, Debug)]
pub enum HeightCoordinates<'a> {
    /// Per-vertex exemplar pixels ([`heights_at_texels`]).
    Texels(&'a [Vec2]),
    /// Per-corner texture coordinates ([`heights_at_corner_uvs`]).
    CornerUvs(&'a [Vec2]),
}

/// A mesh's positions displaced along its normals by a height map.
#[derive(Clone, Debug)]
pub struct Displaced {
    /// The new vertex positions.
    pub positions: Vec<Vec3>,
    /// Per vertex, whether it was displaced (a vertex without corners is
    /// not, under [`HeightCoordinates::CornerUvs`]).
    pub moved: Vec<bool>,
    /// The height map's mean, about which the heights displace.
    pub mean: f32,
    /// The largest distance a vertex moved.
    pub max_offset: f32,
}

/// Steps [`displace_by_height_with_progress`] advances its progress by:
/// sampling, the one-rings and each smoothing pass, normals, displacing.
pub fn displace_progress_steps(smoothing: u32) -> u64 {
    let smoothing_steps = if smoothing > 0 {
        1 + u64::from(smoothing)
    } else {
        0
    };
    3 + smoothing_steps
}

/// Moves every vertex of `mesh` along its area-weighted unit normal by
/// `amplitude · (h − h̄)`: `h` the height map at the vertex's
/// `coordinates` (bilinear, `wrap`), first averaged over one-rings
/// `smoothing` times ([`smooth_vertex_heights`]), `h̄` the map's mean.
/// Advances `progress` by [`displace_progress_steps`].
///
/// Preconditions: `coordinates` has one entry per vertex (`Texels`) or
/// per corner (`CornerUvs`).
pub fn displace_by_height_with_progress(
    mesh: &crate::mesh::PolyMesh,
    height: &Image,
    wrap: Wrap,
    coordinates: HeightCoordinates,
    smoothing: u32,
    amplitude: f32,
    progress: &crate::progress::Progress,
) -> Displaced {
    let nv = mesh.vertex_count();
    progress.set_part("heights");
    let (mut heights, moved) = match coordinates {
        HeightCoordinates::CornerUvs(uvs) => {
            heights_at_corner_uvs(height, wrap, nv, &mesh.corner_vertex, uvs)
        }
        HeightCoordinates::Texels(texels) => {
            (heights_at_texels(height, wrap, texels), vec![true; nv])
        }
    };
    progress.inc(1);
    if smoothing > 0 {
        progress.set_part("smoothing");
        let topo = crate::mesh::Topology::build(mesh);
        progress.inc(1);
        smooth_vertex_heights_with_progress(&topo, &mut heights, &moved, smoothing, progress);
    }
    progress.set_part("normals");
    let mean = mean_height(height);
    let normals = mesh.vertex_normals();
    progress.inc(1);
    progress.set_part("displacing");
    let positions =
        displace_along_normals(&mesh.positions, &normals, &heights, &moved, mean, amplitude);
    let max_offset = mesh
        .positions
        .iter()
        .zip(&positions)
        .map(|(a, b)| (*a - *b).length())
        .fold(0.0f32, f32::max);
    progress.inc(1);
    Displaced {
        positions,
        moved,
        mean,
        max_offset,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f32::consts::{FRAC_PI_2, PI};

    fn close(a: Vec3, b: Vec3, tol: f32) -> bool {
        (a - b).length() < tol
    }

    #[test]
    fn encode_decode_round_trip() {
        for v in [
            Vec3::Z,
            Vec3::new(0.3, -0.4, 0.866),
            Vec3::new(-0.7, 0.1, 0.2),
            Vec3::new(0.0, 1.0, 0.0),
        ] {
            let v = v.normalize();
            let back = decode_normal(encode_normal(v));
            assert!(close(back, v, 1e-5), "{v} -> {back}");
        }
        // The flat texel (0.5, 0.5, 1) is +Z; a zero texel vector falls back to +Z.
        assert!(close(decode_normal([0.5, 0.5, 1.0]), Vec3::Z, 1e-6));
        assert_eq!(decode_normal([0.5, 0.5, 0.5]), Vec3::Z);
        // Texel round trip through 8-bit-like values stays within quantisation.
        let t = [0.25, 0.75, 0.9];
        let e = encode_normal(decode_normal(t));
        let d = decode_normal(t);
        assert!(close(decode_normal(e), d, 1e-5));
    }

    #[test]
    fn reorient_rotates_a_tilted_normal_by_minus_the_angle() {
        let tilted = Vec3::new(0.5, 0.0, 0.866_025_4);
        // Target x-axis at +90° from s (i.e. along t): the normal, tilted
        // along s, is tilted along −y of the target frame.
        let r = reorient_normal(tilted, FRAC_PI_2);
        assert!(close(r, Vec3::new(0.0, -0.5, 0.866_025_4), 1e-6), "{r}");
        for theta in [0.3f32, -1.2, 2.5, PI] {
            let r = reorient_normal(tilted, theta);
            let expected = Vec3::new(0.5 * theta.cos(), -0.5 * theta.sin(), 0.866_025_4);
            assert!(close(r, expected, 1e-6), "θ {theta}: {r} vs {expected}");
            assert!((r.length() - tilted.length()).abs() < 1e-6);
            // Rotating back restores the input.
            assert!(close(reorient_normal(r, -theta), tilted, 1e-6));
        }
    }

    #[test]
    fn reorient_keeps_the_world_direction() {
        // Synthesis frame (s, t, n) and a target frame turned by θ about n:
        // the world vector of the texel normal is the same in both.
        let n = Vec3::new(0.2, 0.3, 0.9).normalize();
        let s = n.any_orthonormal_vector();
        let t = n.cross(s);
        let tex = Vec3::new(0.3, -0.2, 0.93).normalize();
        let world = tex.x * s + tex.y * t + tex.z * n;
        for theta in [0.0f32, 0.7, -2.0] {
            let x = s * theta.cos() + t * theta.sin();
            let y = n.cross(x);
            let angle = frame_angle(s, x, n);
            assert!((angle - theta).abs() < 1e-5, "{angle} vs {theta}");
            let r = reorient_normal(tex, angle);
            let world2 = r.x * x + r.y * y + r.z * n;
            assert!(close(world, world2, 1e-5), "θ {theta}: {world} vs {world2}");
        }
    }

    #[test]
    fn texel_in_a_frame_turned_by_the_field_turns_with_it() {
        // A bump tilted to +X in the exemplar; the synthesis frame's s is the
        // target's x turned by +30° about +Z: the baked normal is tilted 30°
        // counter-clockwise from +X.
        let tex = encode_normal(Vec3::new(0.5, 0.0, 0.866_025_4));
        let phi = 30f32.to_radians();
        let s = Vec3::new(phi.cos(), phi.sin(), 0.0);
        let out = decode_normal(normal_texel_in_frame(tex, s, Vec3::X, Vec3::Z));
        let expected = Vec3::new(0.5 * phi.cos(), 0.5 * phi.sin(), 0.866_025_4);
        assert!(close(out, expected, 1e-5), "{out} vs {expected}");
        // Same frame: unchanged.
        let same = decode_normal(normal_texel_in_frame(tex, Vec3::X, Vec3::X, Vec3::Z));
        assert!(close(same, decode_normal(tex), 1e-6));
    }

    #[test]
    fn frame_angle_on_known_frames() {
        let n = Vec3::Z;
        assert!((frame_angle(Vec3::X, Vec3::Y, n) - FRAC_PI_2).abs() < 1e-6);
        assert!((frame_angle(Vec3::Y, Vec3::X, n) + FRAC_PI_2).abs() < 1e-6);
        assert!((frame_angle(Vec3::X, -Vec3::X, n).abs() - PI).abs() < 1e-6);
        assert!(frame_angle(Vec3::X, Vec3::X, n).abs() < 1e-6);
        // Components along the normal are ignored.
        let a = frame_angle(Vec3::new(1.0, 0.0, 5.0), Vec3::new(1.0, 1.0, -3.0), n);
        assert!((a - PI / 4.0).abs() < 1e-6, "{a}");
        // Flipping the normal flips the sense.
        assert!((frame_angle(Vec3::X, Vec3::Y, -n) + FRAC_PI_2).abs() < 1e-6);
        // Degenerate input gives 0, not NaN.
        assert_eq!(frame_angle(Vec3::Z, Vec3::X, n), 0.0);
        assert_eq!(frame_angle(Vec3::X, Vec3::Y, Vec3::ZERO), 0.0);
    }

    #[test]
    fn sobel_normal_of_a_ramp_tilts_against_the_slope() {
        // Height rising to the right by 0.1 per pixel (clamped, no wrap).
        let mut h = Image::new(8, 8, 1);
        for y in 0..8 {
            for x in 0..8 {
                h.pixel_mut(x, y)[0] = 0.1 * x as f32;
            }
        }
        let n = normal_from_height(&h, 2.0, Wrap::Clamp);
        let c = decode_normal(n.pixel(4, 4).try_into().unwrap());
        let expected = Vec3::new(-0.2, 0.0, 1.0).normalize();
        assert!(close(c, expected, 1e-5), "{c} vs {expected}");
        // Height rising downwards in the image (towards −t) tilts the normal to +Y.
        let mut h2 = Image::new(8, 8, 1);
        for y in 0..8 {
            for x in 0..8 {
                h2.pixel_mut(x, y)[0] = 0.1 * y as f32;
            }
        }
        let n2 = normal_from_height(&h2, 2.0, Wrap::Clamp);
        let c2 = decode_normal(n2.pixel(4, 4).try_into().unwrap());
        assert!(c2.y > 0.19 && c2.x.abs() < 1e-6, "{c2}");
        // Zero strength is flat.
        let flat = normal_from_height(&h, 0.0, Wrap::Clamp);
        assert!(close(
            decode_normal(flat.pixel(3, 3).try_into().unwrap()),
            Vec3::Z,
            1e-6
        ));
    }

    #[test]
    fn smoothing_lowers_height_variance_and_keeps_fixed_vertices() {
        let mesh = crate::mesh::builtin::builtin_mesh(
            "plane",
            &crate::mesh::builtin::BuiltinOptions {
                resolution: [10, 10],
                ..Default::default()
            },
        )
        .unwrap();
        let topo = crate::mesh::Topology::build(&mesh);
        let n = mesh.vertex_count();
        // A checkerboard of heights: the worst aliasing.
        let h0: Vec<f32> = (0..n).map(|v| ((v % 10 + v / 10) % 2) as f32).collect();
        let mut moved = vec![true; n];
        moved[0] = false;
        let var = |h: &[f32]| {
            let m = h.iter().sum::<f32>() / h.len() as f32;
            h.iter().map(|x| (x - m).powi(2)).sum::<f32>() / h.len() as f32
        };
        let mut h = h0.clone();
        smooth_vertex_heights(&topo, &mut h, &moved, 3);
        assert!(var(&h) < 0.25 * var(&h0), "{} vs {}", var(&h), var(&h0));
        assert_eq!(h[0], h0[0], "a fixed vertex keeps its height");
        let mut same = h0.clone();
        smooth_vertex_heights(&topo, &mut same, &moved, 0);
        assert_eq!(same, h0);
    }

    #[test]
    fn luminance_weights_green_most() {
        let img = Image::from_data(3, 1, 3, vec![1., 0., 0., 0., 1., 0., 0., 0., 1.]).unwrap();
        let l = luminance_image(&img);
        assert_eq!(l.channels, 1);
        assert!(l.data[1] > l.data[0] && l.data[0] > l.data[2]);
        let inv = inverted_luminance_image(&img);
        assert!((inv.data[1] - (1.0 - l.data[1])).abs() < 1e-6);
        assert!((mean_height(&l) - (0.2126 + 0.7152 + 0.0722) / 3.0).abs() < 1e-6);
    }
}
