//! Triplanar projection (box mapping with blended seams): what a technical
//! artist does without texture synthesis — a tileable image projected along
//! the three world axes, each projection weighted by how squarely the
//! surface faces its axis. The fast baseline of the surface benchmark, and
//! the artist's alternative every method is measured against.
//!
//! At a surface point `p` with unit normal `n`:
//! - the projection along x reads the image at `(p.z, −p.y)`, along y at
//!   `(p.x, p.z)`, along z at `(p.x, −p.y)` (world units times texels per
//!   unit; image `y` grows downwards, so world `+y` is image-up on the x and
//!   z projections);
//! - the weights are `|n_axis|^sharpness`, normalised to sum to one (the
//!   standard blend; a higher exponent narrows the seams between
//!   projections);
//! - `n` is the smooth normal interpolated across the triangle, split at
//!   creases ([`crease_corner_normals`]): a cube's face is one projection,
//!   a scan's curved surface blends smoothly.

use super::bake::{AtlasFrames, Contribution, ContributionSource, TexelSamples};
use glam::{Vec2, Vec3};

/// The three projections' image coordinates of `p`, in image pixels (pixel
/// centres at `i + 0.5`), at `texels_per_unit`: along x, y and z.
#[inline]
pub fn projections(p: Vec3, texels_per_unit: f32) -> [Vec2; 3] {
    let q = p * texels_per_unit;
    [
        Vec2::new(q.z, -q.y),
        Vec2::new(q.x, q.z),
        Vec2::new(q.x, -q.y),
    ]
}

/// The blend weights of the x, y and z projections for the unit normal `n`:
/// `|n_i|^sharpness`, summing to one (equal thirds for a zero normal).
#[inline]
pub fn weights(n: Vec3, sharpness: f32) -> [f32; 3] {
    let w = n.abs().to_array().map(|a| a.powf(sharpness));
    let sum = w[0] + w[1] + w[2];
    if sum > 0.0 && sum.is_finite() {
        w.map(|x| x / sum)
    } else {
        [1.0 / 3.0; 3]
    }
}

/// Faces whose normals differ by more than this (degrees) do not share a
/// smooth normal at their common vertex (the auto-smooth angle of modelling
/// tools).
pub const CREASE_ANGLE_DEG: f32 = 60.0;

/// Per corner of `tris`, the unit normal of its vertex over the faces
/// around it within [`CREASE_ANGLE_DEG`] of its own face (area-weighted):
/// smooth across gentle bends, split at creases. A degenerate face's
/// corners get the vertex's whole average.
pub fn crease_corner_normals(positions: &[Vec3], tris: &[[u32; 3]]) -> Vec<[Vec3; 3]> {
    let scaled: Vec<Vec3> = tris
        .iter()
        .map(|t| {
            let p = t.map(|v| positions[v as usize]);
            (p[1] - p[0]).cross(p[2] - p[0])
        })
        .collect();
    // Faces around each vertex (CSR).
    let mut start = vec![0u32; positions.len() + 1];
    for t in tris {
        for &v in t {
            start[v as usize + 1] += 1;
        }
    }
    for i in 0..positions.len() {
        start[i + 1] += start[i];
    }
    let mut fill = start.clone();
    let mut faces = vec![0u32; start[positions.len()] as usize];
    for (f, t) in tris.iter().enumerate() {
        for &v in t {
            faces[fill[v as usize] as usize] = f as u32;
            fill[v as usize] += 1;
        }
    }
    let cos_crease = CREASE_ANGLE_DEG.to_radians().cos();
    tris.iter()
        .enumerate()
        .map(|(f, t)| {
            let own = scaled[f].normalize_or_zero();
            t.map(|v| {
                let around = &faces[start[v as usize] as usize..start[v as usize + 1] as usize];
                let sum: Vec3 = around
                    .iter()
                    .map(|&g| scaled[g as usize])
                    .filter(|n| own == Vec3::ZERO || n.normalize_or_zero().dot(own) >= cos_crease)
                    .sum();
                sum.normalize_or_zero()
            })
        })
        .collect()
}

/// Triplanar look-ups for a bake of the original mesh: every texel's point
/// and interpolated vertex normal give three image look-ups (texture 0 of
/// the bake, sampled with `Wrap::Repeat`: the image is a tile).
pub struct TriplanarSource<'a> {
    /// Original-mesh positions.
    pub positions: &'a [Vec3],
    /// Per triangle, its corners' unit normals ([`crease_corner_normals`]).
    pub normals: &'a [[Vec3; 3]],
    /// Its triangles.
    pub tris: &'a [[u32; 3]],
    /// Atlas frames of the original mesh (the projections' angles, for a
    /// normal map baked through the same look-ups).
    pub frames: &'a AtlasFrames,
    /// Image texels per world unit.
    pub texels_per_unit: f32,
    /// The blend exponent.
    pub sharpness: f32,
    /// The image's size, pixels.
    pub image_size: Vec2,
}

impl ContributionSource for TriplanarSource<'_> {
    fn texel(&self, face: u32, b: [f32; 3], out: &mut TexelSamples) {
        let f = face as usize;
        let t = self.tris[f];
        let p: Vec3 = (0..3).map(|k| self.positions[t[k] as usize] * b[k]).sum();
        let n: Vec3 = (0..3).map(|k| self.normals[f][k] * b[k]).sum();
        let n = n.try_normalize().unwrap_or(self.frames.normal[f]);
        let w = weights(n, self.sharpness);
        // Each projection's image x axis in world space.
        let axes = [Vec3::Z, Vec3::X, Vec3::X];
        for (k, q) in projections(p, self.texels_per_unit).into_iter().enumerate() {
            if w[k] <= 0.0 {
                continue;
            }
            out.contribs.push(Contribution {
                uv: q / self.image_size,
                weight: w[k],
                angle: self.frames.angle_to(f, axes[k]),
                texture: 0,
            });
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn weights_sum_to_one_and_favour_the_facing_axis() {
        for (i, n) in [
            Vec3::X,
            Vec3::new(0.3, -0.8, 0.52).normalize(),
            Vec3::new(-1.0, 1.0, 1.0).normalize(),
            Vec3::ZERO,
        ]
        .into_iter()
        .enumerate()
        {
            for s in [1.0, 4.0, 16.0] {
                let w = weights(n, s);
                let sum: f32 = w.iter().sum();
                assert!((sum - 1.0).abs() < 1e-6, "normal {i}, sharpness {s}: {w:?}");
                assert!(w.iter().all(|&x| x >= 0.0));
            }
        }
        assert_eq!(weights(Vec3::Z, 4.0), [0.0, 0.0, 1.0]);
        let w = weights(Vec3::new(0.3, -0.8, 0.52).normalize(), 4.0);
        assert!(w[1] > w[2] && w[2] > w[0], "{w:?}");
        // A sharper blend narrows the seam: the dominant weight grows.
        let n = Vec3::new(0.6, 0.0, 0.8);
        assert!(weights(n, 8.0)[2] > weights(n, 2.0)[2]);
    }

    #[test]
    fn projections_scale_with_texels_per_unit() {
        let p = Vec3::new(1.0, 2.0, 3.0);
        assert_eq!(
            projections(p, 2.0),
            [
                Vec2::new(6.0, -4.0),
                Vec2::new(2.0, 6.0),
                Vec2::new(2.0, -4.0)
            ]
        );
    }
}
