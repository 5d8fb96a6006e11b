//! Baking a per-corner-UV texture, including the jump-map 3-way blend
//! (Zelinka & Garland 2004 §6.5), into a texture atlas of one cell per pair
//! of triangles, so any OBJ/glTF viewer shows the blended result.
//!
//! The atlas is a grid of square cells; each cell holds two fan triangles,
//! one in its lower-left half and one in its upper-right half. Every texel of
//! a half cell is filled (barycentric coordinates clamped into the triangle),
//! so the texture has no gaps and bilinear filtering never reads unfilled
//! texels. It is the simplest valid atlas (no overlap, every face inside
//! [0, 1]); a chart atlas with less seam length is the `bake` stage's job.

use crate::image::{Image, sample::Wrap};
use glam::Vec2;
use rayon::prelude::*;

/// Atlas texture coordinates of the three corners of fan triangle `t` out of
/// `count`, for an atlas of `size`² texels; v = 0 at the top row.
pub fn atlas_corner_uvs(t: usize, count: usize, size: u32) -> [Vec2; 3] {
    let cells = (count.div_ceil(2) as f64).sqrt().ceil().max(1.0) as usize;
    let cell = t / 2;
    let (cx, cy) = ((cell % cells) as f32, (cell / cells) as f32);
    let w = 1.0 / cells as f32;
    // Half a texel of margin keeps neighbouring cells apart under bilinear look-ups.
    let m = 0.5 / size as f32;
    let (x0, y0, x1, y1) = (
        cx * w + m,
        cy * w + m,
        (cx + 1.0) * w - m,
        (cy + 1.0) * w - m,
    );
    if t.is_multiple_of(2) {
        [Vec2::new(x0, y1), Vec2::new(x1, y1), Vec2::new(x0, y0)]
    } else {
        [Vec2::new(x1, y0), Vec2::new(x0, y0), Vec2::new(x1, y1)]
    }
}

/// Bakes the blended texture of `layers` (per fan triangle, the corner UVs
/// for each base vertex) into a `size`² atlas. The colour at a point is
/// Σ_b λ_b · texture(Σ_k λ_k · uv[b][k]), λ the barycentric coordinates.
pub fn bake_blended(
    layers: crate::kernels::jump_maps::jump_surface::Blend<'_>,
    texture: &Image,
    wrap: Wrap,
    size: u32,
) -> Image {
    let c = texture.channels as usize;
    let count = layers.len();
    let cells = (count.div_ceil(2) as f64).sqrt().ceil().max(1.0) as usize;
    let mut out = Image::new(size, size, texture.channels);
    let row_len = size as usize * c;
    out.data
        .par_chunks_mut(row_len)
        .enumerate()
        .for_each(|(y, row)| {
            let mut px = vec![0.0f32; c];
            let v = (y as f32 + 0.5) / size as f32;
            let cy = ((v * cells as f32) as usize).min(cells - 1);
            for x in 0..size as usize {
                let u = (x as f32 + 0.5) / size as f32;
                let cx = ((u * cells as f32) as usize).min(cells - 1);
                // Local coordinates in the cell, (0,0) top-left.
                let lx = u * cells as f32 - cx as f32;
                let ly = v * cells as f32 - cy as f32;
                // The diagonal runs from the cell's top-left to its bottom-right:
                // the even triangle holds the lower-left half (y down).
                let lower = ly >= lx;
                let t = (cy * cells + cx) * 2 + usize::from(!lower);
                if t >= count {
                    continue;
                }
                let tri = atlas_corner_uvs(t, count, size);
                let p = Vec2::new(u, v);
                let b = barycentric_clamped(p, tri);
                let dst = &mut row[x * c..(x + 1) * c];
                dst.fill(0.0);
                for (base, uvs) in layers.get(t).iter().enumerate() {
                    let uv = uvs[0] * b[0] + uvs[1] * b[1] + uvs[2] * b[2];
                    texture.sample_uv(uv.x, uv.y, wrap, &mut px);
                    for (d, s) in dst.iter_mut().zip(&px) {
                        *d += b[base] * s;
                    }
                }
            }
        });
    out
}

/// Barycentric coordinates of `p` in triangle `t`, clamped into the triangle.
fn barycentric_clamped(p: Vec2, t: [Vec2; 3]) -> [f32; 3] {
    let den = (t[1] - t[0]).perp_dot(t[2] - t[0]);
    if den.abs() < 1e-20 {
        return [1.0 / 3.0; 3];
    }
    let b1 = ((p - t[0]).perp_dot(t[2] - t[0]) / den).clamp(0.0, 1.0);
    let b2 = ((t[1] - t[0]).perp_dot(p - t[0]) / den).clamp(0.0, 1.0);
    let s = b1 + b2;
    let (b1, b2) = if s > 1.0 { (b1 / s, b2 / s) } else { (b1, b2) };
    [1.0 - b1 - b2, b1, b2]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cells_do_not_overlap_and_stay_inside() {
        let n = 37;
        let size = 256;
        let mut owner = vec![usize::MAX; (size * size) as usize];
        for t in 0..n {
            let tri = atlas_corner_uvs(t, n, size);
            for uv in tri {
                assert!(uv.cmpge(Vec2::ZERO).all() && uv.cmple(Vec2::ONE).all());
            }
            // Rasterise texel centres strictly inside.
            for y in 0..size {
                for x in 0..size {
                    let p = Vec2::new(
                        (x as f32 + 0.5) / size as f32,
                        (y as f32 + 0.5) / size as f32,
                    );
                    let den = (tri[1] - tri[0]).perp_dot(tri[2] - tri[0]);
                    let b1 = (p - tri[0]).perp_dot(tri[2] - tri[0]) / den;
                    let b2 = (tri[1] - tri[0]).perp_dot(p - tri[0]) / den;
                    if b1 > 1e-4 && b2 > 1e-4 && b1 + b2 < 1.0 - 1e-4 {
                        let o = &mut owner[(y * size + x) as usize];
                        assert_eq!(*o, usize::MAX, "texel ({x}, {y}) covered twice");
                        *o = t;
                    }
                }
            }
        }
    }

    #[test]
    fn each_half_cell_shows_its_own_triangle() {
        // Triangle t samples a texture column of value t / 4.
        let tex = Image::from_data(5, 1, 1, (0..5).map(|i| i as f32 / 4.0).collect()).unwrap();
        let layers: Vec<[[Vec2; 3]; 3]> = (0..5)
            .map(|t| [[Vec2::new((t as f32 + 0.5) / 5.0, 0.5); 3]; 3])
            .collect();
        let size = 64;
        let baked = bake_blended((&layers[..]).into(), &tex, Wrap::Clamp, size);
        for t in 0..5 {
            let tri = atlas_corner_uvs(t, 5, size);
            let c = (tri[0] + tri[1] + tri[2]) / 3.0;
            let v = baked.pixel((c.x * size as f32) as u32, (c.y * size as f32) as u32)[0];
            assert!((v - t as f32 / 4.0).abs() < 1e-5, "triangle {t}: {v}");
        }
    }

    #[test]
    fn equal_layers_bake_the_texture_unblended() {
        // One triangle whose three layers agree: the bake equals a plain look-up.
        let tex = Image::from_data(2, 2, 1, vec![0.0, 1.0, 1.0, 0.0]).unwrap();
        let uv = [
            Vec2::new(0.25, 0.25),
            Vec2::new(0.75, 0.25),
            Vec2::new(0.25, 0.75),
        ];
        let baked = bake_blended((&[[uv; 3]][..]).into(), &tex, Wrap::Clamp, 32);
        // The triangle's first corner sits at the cell's bottom-left.
        let tri = atlas_corner_uvs(0, 1, 32);
        let p = tri[0] * 0.6 + tri[1] * 0.2 + tri[2] * 0.2;
        let (x, y) = ((p.x * 32.0) as u32, (p.y * 32.0) as u32);
        let mut expect = [0.0];
        let b = barycentric_clamped(
            Vec2::new((x as f32 + 0.5) / 32.0, (y as f32 + 0.5) / 32.0),
            tri,
        );
        let q = uv[0] * b[0] + uv[1] * b[1] + uv[2] * b[2];
        tex.sample_uv(q.x, q.y, Wrap::Clamp, &mut expect);
        assert!((baked.pixel(x, y)[0] - expect[0]).abs() < 1e-5);
    }
}
