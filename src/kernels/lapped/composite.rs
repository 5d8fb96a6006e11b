//! The lapped texture as a signal over the surface, for quality metrics:
//! the pastes composited in paste order with straight alpha over a
//! background colour at any surface point — the compositing the preview
//! renderer does per pixel (Praun et al. 2000 §4, runtime pasting) — plus
//! the tangent frames the texture follows and colour samples for histograms.
//!
//! [`LappedComposite::eval_corners`] plugs into
//! [`crate::kernels::surface::surface_sample::SurfaceSignal::Corners`], so the texture
//! energy of `kernels::metrics` measures a lapped result like any other.

use crate::image::Image;
use crate::image::sample::Wrap;
use crate::kernels::surface::frames::TangentFrame;
use crate::mesh::PolyMesh;
use glam::{Vec2, Vec3};

/// One paste as recorded by `lapped_paste`: the texture patch index, the
/// faces, and their corners' texture coordinates compactly (three per
/// face, in the face's corner order; `[0, 1]` over the patch image, `v = 0`
/// at the top row).
#[derive(Clone, Copy, Debug)]
pub struct PasteRecord<'a> {
    /// Texture patch index.
    pub texture: u32,
    /// Mesh faces of the surface patch.
    pub faces: &'a [u32],
    /// `3 · faces.len()` texture coordinates.
    pub uvs: &'a [Vec2],
}

/// Per face, the pastes holding it, in paste order: an index into paste
/// records (8 bytes a layer, 4 a face) rather than a copy of their
/// coordinates (32 bytes a layer), built by counting.
#[derive(Clone, Debug)]
pub struct PasteIndex<'a> {
    /// The records, in paste order.
    pastes: Vec<PasteRecord<'a>>,
    /// CSR offsets of each face's layers (`face_count + 1`).
    start: Vec<u32>,
    /// Per layer: the paste and the face's position in its list.
    layer: Vec<(u32, u32)>,
}

impl<'a> PasteIndex<'a> {
    /// Indexes `pastes` (in paste order) over `face_count` faces.
    ///
    /// # Errors
    /// A message naming the first record with a uv count that is not three
    /// per face or a face id out of range.
    pub fn new(face_count: usize, pastes: &[PasteRecord<'a>]) -> Result<Self, String> {
        let fc = face_count;
        let mut start = vec![0u32; fc + 1];
        for (k, p) in pastes.iter().enumerate() {
            if p.uvs.len() != 3 * p.faces.len() {
                return Err(format!(
                    "paste {k} has {} texture coordinates for {} faces; 3 per face expected",
                    p.uvs.len(),
                    p.faces.len()
                ));
            }
            for &f in p.faces {
                if f as usize >= fc {
                    return Err(format!(
                        "paste {k} holds face {f}, but the mesh has {fc} faces"
                    ));
                }
                start[f as usize + 1] += 1;
            }
        }
        for f in 0..fc {
            start[f + 1] += start[f];
        }
        let mut fill = start.clone();
        let mut layer = vec![(0u32, 0u32); start[fc] as usize];
        for (k, p) in pastes.iter().enumerate() {
            for (i, &f) in p.faces.iter().enumerate() {
                let slot = &mut fill[f as usize];
                layer[*slot as usize] = (k as u32, i as u32);
                *slot += 1;
            }
        }
        Ok(Self {
            pastes: pastes.to_vec(),
            start,
            layer,
        })
    }

    /// Number of faces.
    pub fn face_count(&self) -> usize {
        self.start.len() - 1
    }

    /// The records.
    pub fn pastes(&self) -> &[PasteRecord<'a>] {
        &self.pastes
    }

    /// The layers of face `f` in paste order: (paste, texture patch, corner
    /// texture coordinates).
    #[inline]
    pub fn layers(
        &self,
        f: usize,
    ) -> impl DoubleEndedIterator<Item = (u32, u32, [Vec2; 3])> + ExactSizeIterator + '_ {
        self.layer[self.start[f] as usize..self.start[f + 1] as usize]
            .iter()
            .map(|&(k, i)| {
                let p = &self.pastes[k as usize];
                let i = 3 * i as usize;
                (k, p.texture, [p.uvs[i], p.uvs[i + 1], p.uvs[i + 2]])
            })
    }
}

/// Per-face layer lists of a lapped texture, ready to evaluate.
#[derive(Clone, Debug)]
pub struct LappedComposite<'a> {
    /// Per face, its first corner (the mesh's; a corner's face is found by
    /// binary search, not stored per corner).
    face_start: &'a [u32],
    /// The pastes of each face.
    index: PasteIndex<'a>,
    /// RGBA texture patches (straight alpha).
    textures: &'a [Image],
    /// RGB colour under the first paste.
    background: [f32; 3],
    /// Output channel count (1 = grey, ≥ 3 = RGB then `extra`).
    channels: usize,
    /// Values of channels 3.. (e.g. an exemplar's alpha mean).
    extra: Vec<f32>,
}

impl<'a> LappedComposite<'a> {
    /// Indexes `pastes` (in paste order, later on top) over `mesh`.
    /// `background` is the colour under the pastes, with `channels` values
    /// (the exemplar's channel count: 1 grey, 2 grey + alpha, 3 RGB, more:
    /// RGB then the background's values for the rest).
    ///
    /// # Errors
    /// A message naming the first inconsistency: a face that is not a
    /// triangle, a face id out of range, a uv count that is not three per
    /// face, a texture index out of range, a texture that is not RGBA, or a
    /// background of the wrong length.
    pub fn new(
        mesh: &'a PolyMesh,
        pastes: &[PasteRecord<'a>],
        textures: &'a [Image],
        background: &[f32],
    ) -> Result<Self, String> {
        let fc = mesh.face_count();
        let channels = background.len();
        if channels == 0 {
            return Err("the background colour has no channel".into());
        }
        if let Some(f) = (0..fc).find(|&f| mesh.face_corners(f).len() != 3) {
            return Err(format!(
                "face {f} has {} corners; lapped pastes are on triangles",
                mesh.face_corners(f).len()
            ));
        }
        if let Some(t) = textures.iter().position(|t| t.channels != 4) {
            return Err(format!(
                "texture patch {t} has {} channels; RGBA expected",
                textures[t].channels
            ));
        }
        // Face ids and coordinate counts are checked by the index.
        for (k, p) in pastes.iter().enumerate() {
            if p.texture as usize >= textures.len() {
                return Err(format!(
                    "paste {k} uses texture patch {}, but there are {}",
                    p.texture,
                    textures.len()
                ));
            }
        }
        let index = PasteIndex::new(fc, pastes)?;
        let rgb = match channels {
            1 | 2 => [background[0]; 3],
            _ => [background[0], background[1], background[2]],
        };
        Ok(Self {
            face_start: &mesh.face_start,
            index,
            textures,
            background: rgb,
            channels,
            extra: background.get(3..).unwrap_or(&[]).to_vec(),
        })
    }

    /// Output values per sample.
    pub fn channels(&self) -> usize {
        self.channels
    }

    /// The layers of face `f`, in paste order: texture patch and corner
    /// texture coordinates.
    pub fn face_layers(&self, f: usize) -> Vec<(u32, [Vec2; 3])> {
        self.index.layers(f).map(|(_, t, uv)| (t, uv)).collect()
    }

    /// The composite at barycentric point `b` of face `f` (weights of its
    /// corners in corner order) into `out` (`channels()` values): every
    /// layer's texture sampled bilinearly (clamped) and laid over the colour
    /// so far with its alpha.
    pub fn eval_face(&self, f: usize, b: [f32; 3], out: &mut [f32]) {
        let mut c = self.background;
        let mut px = [0.0f32; 4];
        for (_, tex, uv) in self.index.layers(f) {
            let p = uv[0] * b[0] + uv[1] * b[1] + uv[2] * b[2];
            self.textures[tex as usize].sample_uv(p.x, p.y, Wrap::Clamp, &mut px);
            let a = px[3].clamp(0.0, 1.0);
            for i in 0..3 {
                c[i] += (px[i] - c[i]) * a;
            }
        }
        match self.channels {
            1 => out[0] = (c[0] + c[1] + c[2]) / 3.0,
            2 => {
                out[0] = (c[0] + c[1] + c[2]) / 3.0;
                out[1] = 1.0;
            }
            _ => {
                out[..3].copy_from_slice(&c);
                out[3..].copy_from_slice(&self.extra);
            }
        }
    }

    /// [`Self::eval_face`] at a fan triangle `[c0, c, c + 1]` of mesh
    /// corners with barycentric weights `w` (the calling convention of
    /// `SurfaceSignal::Corners`).
    pub fn eval_corners(&self, corners: [u32; 3], w: [f32; 3], out: &mut [f32]) {
        let f = self
            .face_start
            .partition_point(|&s| s <= corners[0])
            .saturating_sub(1);
        let start = self.face_start[f];
        let mut b = [0.0f32; 3];
        for k in 0..3 {
            b[((corners[k] - start) as usize).min(2)] += w[k];
        }
        self.eval_face(f, b, out);
    }

    /// Per vertex, the tangent frame of the texture on top there: of the
    /// layers of the vertex's faces, the one pasted last, with `s` along
    /// the direction its image x grows (and `t = n × s`, its image up).
    /// Vertices without a layer get `s` from `fallback` projected.
    pub fn frames(&self, mesh: &PolyMesh, fallback: Vec3) -> Vec<TangentFrame> {
        let normals = mesh.vertex_normals();
        // Per vertex: (paste index, face) of the latest top layer among
        // its faces.
        let mut best: Vec<Option<(u32, u32)>> = vec![None; mesh.vertex_count()];
        for f in 0..mesh.face_count() {
            let Some((paste, _, _)) = self.index.layers(f).next_back() else {
                continue;
            };
            for &v in mesh.face(f) {
                let slot = &mut best[v as usize];
                if slot.is_none_or(|(p, _)| paste > p) {
                    *slot = Some((paste, f as u32));
                }
            }
        }
        (0..mesh.vertex_count())
            .map(|v| {
                let n = normals[v];
                let dir = match best[v] {
                    Some((_, f)) => self.image_x_direction(mesh, f as usize),
                    None => fallback,
                };
                let dir = if dir.cross(n).length_squared() > 1e-12 {
                    dir
                } else {
                    fallback
                };
                TangentFrame::from_direction(n, dir)
            })
            .collect()
    }

    /// The world direction in which the top layer's image x grows on face
    /// `f`.
    fn image_x_direction(&self, mesh: &PolyMesh, f: usize) -> Vec3 {
        let vs = mesh.face(f);
        let x = [0, 1, 2].map(|i| mesh.positions[vs[i] as usize]);
        let n = (x[1] - x[0]).cross(x[2] - x[0]);
        let twice_area_sq = n.length_squared();
        if twice_area_sq <= f32::MIN_POSITIVE {
            return Vec3::ZERO;
        }
        let Some((_, _, uv)) = self.index.layers(f).next_back() else {
            return Vec3::ZERO;
        };
        // ∇λ_i = n × (x_{i+2} − x_{i+1}) / |n|², ∇u = Σ u_i ∇λ_i.
        (0..3)
            .map(|i| n.cross(x[(i + 2) % 3] - x[(i + 1) % 3]) * uv[i].x)
            .sum::<Vec3>()
            / twice_area_sq
    }

    /// Composite colours at about `per_area` samples per unit of world area
    /// (at least one per face with layers, at most 64 per face), on the
    /// lattice of each face's `k × k` subdivision; `channels()` values each,
    /// in face order. For histogram distances.
    pub fn sample_colours(&self, mesh: &PolyMesh, per_area: f32) -> Vec<f32> {
        let ch = self.channels;
        let mut out = Vec::new();
        let mut px = vec![0.0f32; ch];
        for f in 0..mesh.face_count() {
            if self.index.layers(f).len() == 0 {
                continue;
            }
            let k = super::coverage::lattice_level(mesh.face_area(f), per_area);
            for b in super::coverage::lattice_samples(k) {
                self.eval_face(f, b, &mut px);
                out.extend_from_slice(&px);
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rgba(w: u32, h: u32, f: impl Fn(u32, u32) -> [f32; 4]) -> Image {
        let mut img = Image::new(w, h, 4);
        for y in 0..h {
            for x in 0..w {
                img.pixel_mut(x, y).copy_from_slice(&f(x, y));
            }
        }
        img
    }

    #[test]
    fn later_pastes_are_laid_over_earlier_ones_with_alpha() {
        // Two triangles (a unit square), red opaque paste on both, then a
        // half-transparent blue paste on face 1 only.
        let mesh = PolyMesh::from_triangles(
            vec![Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y],
            &[[0, 1, 2], [0, 2, 3]],
        );
        let textures = [
            rgba(4, 4, |_, _| [1.0, 0.0, 0.0, 1.0]),
            rgba(4, 4, |_, _| [0.0, 0.0, 1.0, 0.5]),
        ];
        let uv = [Vec2::splat(0.5); 6];
        let pastes = [
            PasteRecord {
                texture: 0,
                faces: &[0, 1],
                uvs: &uv,
            },
            PasteRecord {
                texture: 1,
                faces: &[1],
                uvs: &uv[..3],
            },
        ];
        let c = LappedComposite::new(&mesh, &pastes, &textures, &[0.2, 0.2, 0.2]).unwrap();
        let mut out = [0.0f32; 3];
        c.eval_corners([0, 1, 2], [0.3, 0.3, 0.4], &mut out);
        assert_eq!(out, [1.0, 0.0, 0.0]);
        c.eval_corners([3, 4, 5], [0.3, 0.3, 0.4], &mut out);
        assert_eq!(out, [0.5, 0.0, 0.5]);
        // Reversed order: the opaque red hides the blue.
        let reversed = [pastes[1], pastes[0]];
        let c = LappedComposite::new(&mesh, &reversed, &textures, &[0.2, 0.2, 0.2]).unwrap();
        c.eval_corners([3, 4, 5], [0.3, 0.3, 0.4], &mut out);
        assert_eq!(out, [1.0, 0.0, 0.0]);
        // Bad records are named.
        let bad = [PasteRecord {
            texture: 2,
            faces: &[0],
            uvs: &uv[..3],
        }];
        let e = LappedComposite::new(&mesh, &bad, &textures, &[0.0; 3]).unwrap_err();
        assert!(e.contains("texture patch 2"), "{e}");
    }

    #[test]
    fn frames_follow_the_image_x_axis() {
        // One face whose texture x runs along world +y.
        let mesh = PolyMesh::from_triangles(vec![Vec3::ZERO, Vec3::X, Vec3::Y], &[[0, 1, 2]]);
        let textures = [rgba(2, 2, |_, _| [0.5; 4])];
        // u grows with world y, v with world x (mirror-free: v down = −t).
        let uvs = [
            Vec2::new(0.0, 0.0),
            Vec2::new(0.0, 1.0),
            Vec2::new(1.0, 0.0),
        ];
        let pastes = [PasteRecord {
            texture: 0,
            faces: &[0],
            uvs: &uvs,
        }];
        let c = LappedComposite::new(&mesh, &pastes, &textures, &[0.0; 3]).unwrap();
        for f in c.frames(&mesh, Vec3::X) {
            assert!((f.s - Vec3::Y).length() < 1e-5, "{f:?}");
        }
    }
}
