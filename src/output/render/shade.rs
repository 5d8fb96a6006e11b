//! Per-sample shading: perspective-correct attribute interpolation, surface
//! colour from the [`Shading`], layer compositing and Lambert lighting.

use super::raster::Tri;
use super::{Normals, RenderOptions, Shading};
use crate::mesh::PolyMesh;
use glam::{Vec2, Vec3};
use rayon::prelude::*;

/// Mesh data derived once and shared by every view.
pub(crate) struct Scene<'a> {
    pub mesh: &'a PolyMesh,
    pub shading: &'a Shading<'a>,
    pub options: &'a RenderOptions,
    /// Fan triangulation as mesh corner triples, with the face of each.
    pub tris: FanTriangles,
    /// Corner normals for smooth shading; `None` for flat shading (unit
    /// face normals, made when needed).
    pub normals: Option<SmoothNormals>,
    /// For [`Shading::Layers`]: per face, the layers that cover it.
    pub layers: LayerIndex,
}

/// The fan triangles of a mesh's faces as corner triples, with the face of
/// each. A mesh of triangles is its own triangulation (triangle `t` is
/// corners `3t..3t+3` of face `t`), so nothing is stored for it: on a
/// million-vertex scan the two lists were 32 bytes per vertex at the
/// preview's peak.
pub(crate) enum FanTriangles {
    /// Every face is a triangle.
    Faces(usize),
    /// Polygons, fan-triangulated by [`PolyMesh::triangulate_corners`].
    Fans {
        tris: Vec<[u32; 3]>,
        face_of: Vec<u32>,
    },
}

impl FanTriangles {
    pub fn of(mesh: &PolyMesh) -> Self {
        if mesh.is_triangle_mesh() {
            Self::Faces(mesh.face_count())
        } else {
            let (tris, face_of) = mesh.triangulate_corners();
            Self::Fans { tris, face_of }
        }
    }

    #[inline]
    pub fn len(&self) -> usize {
        match self {
            Self::Faces(n) => *n,
            Self::Fans { tris, .. } => tris.len(),
        }
    }

    /// Triangle `t`'s corners.
    #[inline]
    pub fn corners(&self, t: usize) -> [u32; 3] {
        match self {
            Self::Faces(_) => {
                let c = 3 * t as u32;
                [c, c + 1, c + 2]
            }
            Self::Fans { tris, .. } => tris[t],
        }
    }

    /// The face triangle `t` lies in.
    #[inline]
    pub fn face(&self, t: usize) -> usize {
        match self {
            Self::Faces(_) => t,
            Self::Fans { face_of, .. } => face_of[t] as usize,
        }
    }
}

/// Per face, the `(layer, offset of the face's first corner in layer.uvs)`
/// pairs that cover it, in layer order (CSR).
#[derive(Default)]
pub(crate) struct LayerIndex {
    start: Vec<u32>,
    entries: Vec<(u32, u32)>,
}

impl LayerIndex {
    fn new(mesh: &PolyMesh, shading: &Shading) -> Self {
        let Shading::Layers(layers) = shading else {
            return Self::default();
        };
        let fc = mesh.face_count();
        let mut start = vec![0u32; fc + 1];
        for layer in layers.iter() {
            for &f in layer.faces {
                start[f as usize + 1] += 1;
            }
        }
        for f in 0..fc {
            start[f + 1] += start[f];
        }
        let mut fill = start.clone();
        let mut entries = vec![(0u32, 0u32); start[fc] as usize];
        // Layers in the outer loop keep each face's list in layer order.
        for (li, layer) in layers.iter().enumerate() {
            let mut offset = 0u32;
            for &f in layer.faces {
                let f = f as usize;
                entries[fill[f] as usize] = (li as u32, offset);
                fill[f] += 1;
                offset += mesh.face_corners(f).len() as u32;
            }
        }
        Self { start, entries }
    }

    #[inline]
    fn of_face(&self, f: usize) -> &[(u32, u32)] {
        &self.entries[self.start[f] as usize..self.start[f + 1] as usize]
    }
}

/// Area-weighted per-corner normals that only average faces whose unit
/// normal lies within `crease_deg` of the corner's own face normal, so
/// smooth surfaces shade smoothly while creases (and faces whose orientation
/// disagrees with their neighbours') stay sharp.
///
/// Stored per vertex where every corner of the vertex gets the same normal
/// (all its faces within the crease angle of each other: the common case),
/// and per corner only where a crease splits the vertex: 12 bytes per vertex
/// plus 16 per split corner instead of 12 per corner. [`Self::corner`]
/// returns exactly the value a per-corner array would hold.
pub(crate) struct SmoothNormals {
    /// The normal of every unsplit corner of the vertex.
    vertex: Vec<Vec3>,
    /// `(corner, normal)` of the split corners, sorted by corner.
    split: Vec<(u32, Vec3)>,
}

/// A face around a vertex while its normals are made: the vertex's corner
/// in it, its area vector and its unit normal.
type AroundFace = (u32, Vec3, Vec3);

impl SmoothNormals {
    pub fn new(mesh: &PolyMesh, crease_deg: f32) -> Self {
        let nv = mesh.vertex_count();
        let fc = mesh.face_count();
        // Corners around each vertex, in corner order (so their faces come in
        // face order), and the face of each corner.
        let mut start = vec![0u32; nv + 1];
        for &v in &mesh.corner_vertex {
            start[v as usize + 1] += 1;
        }
        for v in 0..nv {
            start[v + 1] += start[v];
        }
        let mut fill = start.clone();
        let mut incident = vec![0u32; mesh.corner_count()];
        for f in 0..fc {
            for c in mesh.face_corners(f) {
                let v = mesh.corner_vertex[c] as usize;
                incident[fill[v] as usize] = c as u32;
                fill[v] += 1;
            }
        }
        drop(fill);
        let face_of = |c: u32| mesh.face_start.partition_point(|&s| s <= c) - 1;
        let cos = crease_deg.clamp(0.0, 180.0).to_radians().cos();
        let mut vertex = vec![Vec3::ZERO; nv];
        // Each vertex's faces' area vectors and unit normals are computed
        // in a scratch its worker reuses, not stored per face and per
        // corner (72 bytes per vertex at the export's peak); a face is
        // computed once per corner, by the same function, so the values
        // are the same.
        let mut split: Vec<(u32, Vec3)> = vertex
            .par_iter_mut()
            .enumerate()
            .fold(
                || (Vec::new(), Vec::new()),
                |(mut split, mut local): (Vec<(u32, Vec3)>, Vec<AroundFace>), (v, out)| {
                    let around = &incident[start[v] as usize..start[v + 1] as usize];
                    local.clear();
                    local.extend(around.iter().map(|&c| {
                        let scaled = mesh.face_normal_scaled(face_of(c));
                        (c, scaled, scaled.normalize_or_zero())
                    }));
                    let mut full = Vec3::ZERO;
                    for &(_, scaled, _) in &local {
                        full += scaled;
                    }
                    let shared = full.try_normalize();
                    *out = shared.unwrap_or(Vec3::ZERO);
                    for &(c, _, own) in &local {
                        let mut n = Vec3::ZERO;
                        let mut all = true;
                        for &(_, scaled, unit) in &local {
                            if unit.dot(own) >= cos {
                                n += scaled;
                            } else {
                                all = false;
                            }
                        }
                        if !(all && shared.is_some()) {
                            split.push((c, n.try_normalize().unwrap_or(own)));
                        }
                    }
                    (split, local)
                },
            )
            .map(|(split, _)| split)
            .reduce(Vec::new, |mut a, mut b| {
                a.append(&mut b);
                a
            });
        split.par_sort_unstable_by_key(|e| e.0);
        split.shrink_to_fit();
        Self { vertex, split }
    }

    /// The normal of corner `c`.
    #[inline]
    pub fn corner(&self, mesh: &PolyMesh, c: usize) -> Vec3 {
        match self.split.binary_search_by_key(&(c as u32), |e| e.0) {
            Ok(i) => self.split[i].1,
            Err(_) => self.vertex[mesh.corner_vertex[c] as usize],
        }
    }
}

/// Interprets 1 (grey), 2 (grey, alpha), 3 (RGB) or 4 (RGBA) channel values
/// as RGBA; with more channels the first three are RGB and it is opaque.
#[inline]
fn to_rgba(v: &[f32], channels: usize) -> [f32; 4] {
    match channels {
        1 => [v[0], v[0], v[0], 1.0],
        2 => [v[0], v[0], v[0], v[1]],
        3 => [v[0], v[1], v[2], 1.0],
        4 => [v[0], v[1], v[2], v[3]],
        _ => [v[0], v[1], v[2], 1.0],
    }
}

/// `top` over `under` with straight (non-premultiplied) alpha.
#[inline]
fn over(under: [f32; 3], top: [f32; 4]) -> [f32; 3] {
    let a = top[3].clamp(0.0, 1.0);
    [0, 1, 2].map(|i| under[i] + (top[i] - under[i]) * a)
}

#[inline]
fn sample(texture: &crate::image::Image, uv: Vec2, wrap: crate::image::sample::Wrap) -> [f32; 4] {
    let mut out = [0.0f32; 4];
    texture.sample_uv(uv.x, uv.y, wrap, &mut out);
    to_rgba(&out, texture.channels as usize)
}

impl<'a> Scene<'a> {
    /// Derives triangles, normals and the layer index. Inputs must have been
    /// checked with [`Shading::check`].
    pub fn new(mesh: &'a PolyMesh, shading: &'a Shading<'a>, options: &'a RenderOptions) -> Self {
        // Normals first: their scratch is gone before the triangles exist.
        let normals = match options.normals {
            Normals::Flat => None,
            Normals::Smooth { crease_deg } => Some(SmoothNormals::new(mesh, crease_deg)),
        };
        Self {
            mesh,
            shading,
            options,
            layers: LayerIndex::new(mesh, shading),
            tris: FanTriangles::of(mesh),
            normals,
        }
    }

    /// The lit colour of the sample at pixel `(px, py)` covered by `t`;
    /// `light` is the unit direction toward the key light.
    #[inline]
    pub fn shade(&self, t: &Tri, px: i32, py: i32, light: Vec3) -> [f32; 3] {
        // Perspective-correct barycentrics: screen-space weights over depth.
        let w = t.weights(px, py);
        let q = [0, 1, 2].map(|i| w[i].max(0) as f32 * t.inv_w[i]);
        let sum = q[0] + q[1] + q[2];
        let b = if sum > 0.0 {
            q.map(|v| v / sum)
        } else {
            [1.0 / 3.0; 3]
        };
        let face = self.tris.face(t.source as usize);
        let c = t.corners.map(|c| c as usize);

        let mut n = match &self.normals {
            None => self.mesh.face_normal(face),
            Some(normals) => {
                let m = c.map(|c| normals.corner(self.mesh, c));
                (m[0] * b[0] + m[1] * b[1] + m[2] * b[2]).normalize_or_zero()
            }
        };
        if n == Vec3::ZERO {
            // A degenerate polygon: fall back to the triangle's own normal in
            // its original winding (fan triangles are `[c0, c, c + 1]`; setup
            // may have swapped the last two), which `t.back` refers to.
            let (c1, c2) = (c[1].min(c[2]), c[1].max(c[2]));
            let p =
                [c[0], c1, c2].map(|c| self.mesh.positions[self.mesh.corner_vertex[c] as usize]);
            n = (p[1] - p[0]).cross(p[2] - p[0]).normalize_or_zero();
        }
        // Two-sided lighting: a triangle seen from behind is lit on its back.
        if t.back {
            n = -n;
        }

        let opts = self.options;
        let base = opts.base_colour;
        let albedo = match *self.shading {
            Shading::Plain => base,
            Shading::VertexColours { values, channels } => {
                let mut rgba = [0.0f32; 4];
                for i in 0..3 {
                    let v = self.mesh.corner_vertex[c[i]] as usize * channels;
                    let col = to_rgba(&values[v..v + channels], channels);
                    for k in 0..4 {
                        rgba[k] += b[i] * col[k];
                    }
                }
                over(base, rgba)
            }
            Shading::CornerUvs { uvs, texture, wrap } => {
                let uv = uvs[c[0]] * b[0] + uvs[c[1]] * b[1] + uvs[c[2]] * b[2];
                over(base, sample(texture, uv, wrap))
            }
            Shading::Coordinates {
                sources,
                frames,
                texels_per_unit,
                texture,
                wrap,
            } => {
                let v = c.map(|c| self.mesh.corner_vertex[c] as usize);
                let p: Vec3 = (0..3).map(|i| self.mesh.positions[v[i]] * b[i]).sum();
                let size = Vec2::new(texture.width as f32, texture.height as f32);
                let mut rgba = [0.0f32; 4];
                for i in 0..3 {
                    let q = crate::kernels::surface::frames::continued_source(
                        sources,
                        frames,
                        texels_per_unit,
                        &self.mesh.positions,
                        v[i],
                        p,
                    );
                    let col = sample(texture, q / size, wrap);
                    for k in 0..4 {
                        rgba[k] += b[i] * col[k];
                    }
                }
                over(base, rgba)
            }
            Shading::BlendedUvs {
                layers,
                texture,
                wrap,
            } => {
                // Map the drawn corners back to the fan triangle's order
                // (setup may have swapped two of them).
                let orig = self.tris.corners(t.source as usize);
                let pos = t
                    .corners
                    .map(|c| orig.iter().position(|&o| o == c).unwrap_or(0));
                let mut bo = [0.0f32; 3];
                for i in 0..3 {
                    bo[pos[i]] += b[i];
                }
                let layer = layers.get_in_face(t.source as usize, face);
                let mut rgba = [0.0f32; 4];
                for (base_corner, uvs) in layer.iter().enumerate() {
                    let uv = uvs[0] * bo[0] + uvs[1] * bo[1] + uvs[2] * bo[2];
                    let col = sample(texture, uv, wrap);
                    for k in 0..4 {
                        rgba[k] += bo[base_corner] * col[k];
                    }
                }
                over(base, rgba)
            }
            Shading::Layers(layers) => {
                let first = self.mesh.face_start[face] as usize;
                let mut colour = base;
                for &(li, offset) in self.layers.of_face(face) {
                    let layer = &layers[li as usize];
                    let uv_of = |corner: usize| layer.uvs[offset as usize + corner - first];
                    let uv = uv_of(c[0]) * b[0] + uv_of(c[1]) * b[1] + uv_of(c[2]) * b[2];
                    colour = over(colour, sample(layer.texture, uv, layer.wrap));
                }
                colour
            }
        };
        let light = opts.ambient + (1.0 - opts.ambient) * n.dot(light).max(0.0);
        albedo.map(|a| a * light)
    }
}
