//! `vertex_colours_from_corner_uvs`: one colour per vertex of a result that
//! has texture coordinates per corner (jump maps, Zelinka & Garland 2004
//! §6.5; a lapped texture's atlas), for formats that carry colours per
//! vertex only (PLY).

use crate::image::Image;
use crate::image::sample::Wrap;
use crate::mesh::PolyMesh;
use glam::Vec2;

/// The colour at each vertex: the texture sampled (bilinear, `wrap`) at each
/// of the vertex's corners, averaged over those corners.
///
/// - With `blend` (the 3-way blend of §6.5: per fan triangle of
///   [`PolyMesh::triangulate_corners`], the UVs of its three corners for each
///   of its three base corners) a corner is sampled where the preview's blend
///   puts it: at a triangle corner the blend weight of that corner's own base
///   is 1, so the colour there is `texture(blend[t][k][k])`. A polygon's
///   first corner, shared by several fan triangles, is sampled once per fan
///   triangle.
/// - Without `blend`, corner `c` is sampled at `uvs[c]`.
///
/// Colours are averaged after sampling, never the UVs, since the corners of
/// one vertex may address far-apart parts of the texture.
///
/// Preconditions: `uvs` has one entry per corner, `blend` (when given) one
/// per fan triangle; a `blend` of another length is ignored. Returns
/// `(values, channels)` with the texture's channel count (more than 4
/// channels keep the first 3); a vertex without corners gets the texture's
/// mean.
pub fn vertex_colours_from_corner_uvs(
    mesh: &PolyMesh,
    uvs: &[Vec2],
    blend: Option<crate::kernels::jump_maps::jump_surface::Blend<'_>>,
    texture: &Image,
    wrap: Wrap,
) -> (Vec<f32>, usize) {
    let c = texture.channels as usize;
    let out_c = if c <= 4 { c } else { 3 };
    let nv = mesh.vertex_count();
    let mut sum = vec![0.0f64; nv * out_c];
    let mut count = vec![0u32; nv];
    let mut px = vec![0.0f32; c.max(1)];
    let mut add = |v: usize, uv: Vec2, sum: &mut [f64], count: &mut [u32]| {
        if v >= nv {
            return;
        }
        texture.sample_uv(uv.x, uv.y, wrap, &mut px);
        for (s, &x) in sum[v * out_c..(v + 1) * out_c].iter_mut().zip(&px) {
            *s += f64::from(x);
        }
        count[v] += 1;
    };
    let (tris, _) = mesh.triangulate_corners();
    match blend.filter(|b| b.len() == tris.len()) {
        Some(layers) => {
            for (t, tri) in tris.iter().enumerate() {
                let layer = layers.get(t);
                for k in 0..3 {
                    let v = mesh.corner_vertex[tri[k] as usize] as usize;
                    add(v, layer[k][k], &mut sum, &mut count);
                }
            }
        }
        None => {
            for (corner, &uv) in uvs.iter().enumerate().take(mesh.corner_count()) {
                let v = mesh.corner_vertex[corner] as usize;
                add(v, uv, &mut sum, &mut count);
            }
        }
    }
    let mean = texture.mean();
    let mut values = Vec::with_capacity(nv * out_c);
    for v in 0..nv {
        for k in 0..out_c {
            values.push(if count[v] == 0 {
                mean.get(k).copied().unwrap_or(0.0)
            } else {
                (sum[v * out_c + k] / f64::from(count[v])) as f32
            });
        }
    }
    (values, out_c)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    fn two_triangles() -> PolyMesh {
        let p = vec![
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
            Vec3::new(5.0, 5.0, 0.0),
        ];
        PolyMesh::from_polygons(p, [&[0u32, 1, 2][..], &[0, 2, 3][..]])
    }

    #[test]
    fn averages_the_samples_of_each_vertex_corners() {
        let m = two_triangles();
        // A 2 x 1 grey texture: left pixel 0, right pixel 1.
        let tex = Image::from_data(2, 1, 1, vec![0.0, 1.0]).unwrap();
        let left = Vec2::new(0.25, 0.5);
        let right = Vec2::new(0.75, 0.5);
        // Vertex 0 has corners 0 (left) and 3 (right): mean 0.5.
        let uvs = [left, right, right, right, left, left];
        let (c, ch) = vertex_colours_from_corner_uvs(&m, &uvs, None, &tex, Wrap::Clamp);
        assert_eq!(ch, 1);
        assert_eq!(&c[..4], &[0.5, 1.0, 0.5, 0.0]);
        assert_eq!(c[4], 0.5, "a vertex without corners gets the mean");
    }

    #[test]
    fn the_blend_samples_each_corner_at_its_own_base() {
        let m = two_triangles();
        let tex = Image::from_data(2, 1, 1, vec![0.0, 1.0]).unwrap();
        let left = Vec2::new(0.25, 0.5);
        let right = Vec2::new(0.75, 0.5);
        // Base k's own corner k is `right`, every other entry `left`.
        let mut layer = [[left; 3]; 3];
        for (k, l) in layer.iter_mut().enumerate() {
            l[k] = right;
        }
        let uvs = [left; 6];
        let (c, _) = vertex_colours_from_corner_uvs(
            &m,
            &uvs,
            Some((&[layer, layer][..]).into()),
            &tex,
            Wrap::Clamp,
        );
        assert_eq!(&c[..4], &[1.0; 4]);
    }
}
