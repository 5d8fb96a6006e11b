//! Lapped textures (Praun, Finkelstein & Hoppe, SIGGRAPH 2000): cover a
//! surface with overlapping, alpha-blended pastes of a texture patch, each
//! pasted onto a surface patch grown and parametrised to follow a tangential
//! vector field.
//!
//! One algorithm per file:
//!
//! - [`mask`] — texture patches: an exemplar region with an alpha mask that
//!   falls off near its boundary (§3.1): circle, seeded splotch, user mask.
//! - [`hull`] — the conservative polygonal hull of a mask (§3.3, Fig. 4).
//! - [`tangent_field`] — the per-face field `T` (§3.2): global up, Gaussian
//!   RBF interpolation of constraints over geodesic distance, isotropic scale.
//! - [`grow`] — growing a disc-shaped surface patch with its initial
//!   parametrisation (§3.3).
//! - [`param`] — the least-squares parametrisation aligned to the field (§3.4).
//! - [`coverage`] — face coverage by rasterisation (§3.6) and the culling of
//!   occluded faces for runtime pasting (§4).
//! - [`composite`] — the pastes composited in order at any surface point
//!   (for quality metrics).
//! - [`paste`] — the paste loop of §3 (until every face is covered).
//! - [`atlas`] — the texture atlas representation (§4).
//!
//! Conventions: a surface patch is parametrised in *patch units* `(s, t)`:
//! the origin is the texture patch centre, `s` points right and `t` up, and
//! one unit is `max(width, height)` pixels of the texture patch image. The
//! field's `T` has length "world units per patch unit", so `φ(T) = (0, 1)` and
//! `φ(S) = (1, 0)` with `S = T × N`. Texture coordinates handed to the
//! renderer are `[0, 1]` over the texture patch image with `v = 0` at its top
//! row ([`mask::TexturePatch::uv_of`]).

pub mod atlas;
pub mod coverage;
pub mod grow;
pub mod hull;
pub mod mask;
pub mod param;
pub mod paste;
pub mod tangent_field;

// For the quality metrics of `result_metrics`.
pub mod composite;

use crate::mesh::{PolyMesh, Topology};
use glam::Vec3;

/// "No face" in [`TriMesh::neighbours`].
pub const NO_FACE: u32 = u32::MAX;

/// Errors of the lapped-texture kernels, naming what to fix.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum LappedError {
    /// The kernels work on triangles only.
    #[error("face {face} has {corners} corners; lapped textures need a triangle mesh")]
    NotTriangles { face: usize, corners: usize },
    /// Nothing to texture.
    #[error("the mesh has no faces")]
    NoFaces,
    /// A mask with no inside pixel.
    #[error("the texture patch mask {what} has no inside pixel (white = inside)")]
    EmptyMask { what: String },
    /// A field constraint that names a face the mesh does not have.
    #[error("field constraint {index} names face {face}, but the mesh has {face_count} faces")]
    ConstraintFace {
        index: usize,
        face: u32,
        face_count: usize,
    },
}

/// A triangle mesh with the adjacency the lapped kernels need, built once.
///
/// Face `f`'s edge `i` joins corners `i` and `i + 1 (mod 3)`;
/// `neighbours[f][i]` is the face across it, or [`NO_FACE`] on a boundary or
/// a non-manifold edge (patches never grow across those).
#[derive(Clone, Debug)]
pub struct TriMesh {
    /// Vertex positions.
    pub positions: Vec<Vec3>,
    /// Triangles, counter-clockwise seen from outside.
    pub tris: Vec<[u32; 3]>,
    /// Unit face normals (zero for a degenerate face).
    pub normals: Vec<Vec3>,
    /// Face areas.
    pub areas: Vec<f32>,
    /// Face centroids.
    pub centroids: Vec<Vec3>,
    /// Face across each edge.
    pub neighbours: Vec<[u32; 3]>,
    /// CSR offsets into `vertex_face_list`.
    pub vertex_face_start: Vec<u32>,
    /// Faces around each vertex.
    pub vertex_face_list: Vec<u32>,
}

impl TriMesh {
    /// Prepares `mesh`.
    ///
    /// # Errors
    /// [`LappedError::NotTriangles`] for a polygon with more than three
    /// corners, [`LappedError::NoFaces`] for an empty mesh.
    pub fn new(mesh: &PolyMesh) -> Result<Self, LappedError> {
        if mesh.face_count() == 0 {
            return Err(LappedError::NoFaces);
        }
        if let Some(face) = (0..mesh.face_count()).find(|&f| mesh.face_corners(f).len() != 3) {
            return Err(LappedError::NotTriangles {
                face,
                corners: mesh.face_corners(face).len(),
            });
        }
        let topo = Topology::build(mesh);
        let fc = mesh.face_count();
        let tris: Vec<[u32; 3]> = (0..fc)
            .map(|f| {
                let v = mesh.face(f);
                [v[0], v[1], v[2]]
            })
            .collect();
        let neighbours: Vec<[u32; 3]> = (0..fc)
            .map(|f| {
                let mut across = [NO_FACE; 3];
                for (i, c) in mesh.face_corners(f).enumerate() {
                    let faces = topo.edge_faces(topo.corner_edge[c]);
                    if faces.len() == 2 {
                        let other = if faces[0] as usize == f {
                            faces[1]
                        } else {
                            faces[0]
                        };
                        if other as usize != f {
                            across[i] = other;
                        }
                    }
                }
                across
            })
            .collect();
        let p = &mesh.positions;
        let normals: Vec<Vec3> = (0..fc).map(|f| mesh.face_normal(f)).collect();
        let areas: Vec<f32> = (0..fc).map(|f| mesh.face_area(f)).collect();
        let centroids: Vec<Vec3> = tris
            .iter()
            .map(|t| (p[t[0] as usize] + p[t[1] as usize] + p[t[2] as usize]) / 3.0)
            .collect();
        Ok(Self {
            positions: mesh.positions.clone(),
            tris,
            normals,
            areas,
            centroids,
            neighbours,
            vertex_face_start: topo.vertex_face_start,
            vertex_face_list: topo.vertex_face_list,
        })
    }

    /// Number of faces.
    #[inline]
    pub fn face_count(&self) -> usize {
        self.tris.len()
    }

    /// Faces around vertex `v`.
    #[inline]
    pub fn vertex_faces(&self, v: u32) -> &[u32] {
        let v = v as usize;
        &self.vertex_face_list
            [self.vertex_face_start[v] as usize..self.vertex_face_start[v + 1] as usize]
    }

    /// The three corner positions of face `f`.
    #[inline]
    pub fn corners(&self, f: usize) -> [Vec3; 3] {
        self.tris[f].map(|v| self.positions[v as usize])
    }

    /// The point with barycentric coordinates `b` on face `f`.
    #[inline]
    pub fn point(&self, f: usize, b: [f32; 3]) -> Vec3 {
        let c = self.corners(f);
        c[0] * b[0] + c[1] * b[1] + c[2] * b[2]
    }

    /// Gradients of the three barycentric coordinates of face `f` (zero for a
    /// degenerate face). `∇λ_i · v` is the `i`-th coefficient of the tangent
    /// vector `v` written as a zero-sum combination of the corners (§3.4,
    /// footnote 1).
    #[inline]
    pub fn barycentric_gradients(&self, f: usize) -> [Vec3; 3] {
        let x = self.corners(f);
        let n = self.normals[f];
        let twice_area = 2.0 * self.areas[f];
        if twice_area <= f32::MIN_POSITIVE || n == Vec3::ZERO {
            return [Vec3::ZERO; 3];
        }
        [0, 1, 2].map(|i| n.cross(x[(i + 2) % 3] - x[(i + 1) % 3]) / twice_area)
    }

    /// The tangent `v` of face `f` carried across its edge to the face `g`
    /// by unfolding (a rotation about the shared edge): the discrete
    /// parallel transport the initial parametrisation of §3.3 follows.
    /// Without a shared edge, `v` is projected onto `g`'s plane.
    pub fn transport(&self, v: Vec3, f: usize, g: usize) -> Vec3 {
        let edge = (0..3).find(|&i| self.neighbours[f][i] == g as u32);
        let (nf, ng) = (self.normals[f], self.normals[g]);
        match edge {
            Some(i) => {
                let t = self.tris[f];
                let e = (self.positions[t[(i + 1) % 3] as usize] - self.positions[t[i] as usize])
                    .normalize_or_zero();
                let a = v.dot(e);
                let b = v.dot(nf.cross(e));
                a * e + b * ng.cross(e)
            }
            None => v - ng * ng.dot(v),
        }
    }
}

/// The per-face tangent field of §3.2 as the kernels read it.
#[derive(Clone, Copy, Debug)]
pub struct FaceField<'a> {
    /// Per face, the texture "up" vector `T` in the face plane; its length is
    /// the local texture scale in world units per patch unit.
    pub t: &'a [Vec3],
    /// Isotropic textures: only `‖T‖` is used; the orientation is propagated
    /// during patch growth (§3.2, last paragraph).
    pub isotropic: bool,
}

#[cfg(test)]
pub(crate) mod test_meshes {
    //! Meshes built in code for the kernel tests.
    use crate::mesh::PolyMesh;
    use glam::Vec3;

    /// An `n × n` vertex grid of unit squares in the z = 0 plane, each split
    /// into two counter-clockwise triangles (seen from +z).
    pub fn grid(n: usize, spacing: f32) -> PolyMesh {
        let p = (0..n * n)
            .map(|i| Vec3::new((i % n) as f32 * spacing, (i / n) as f32 * spacing, 0.0))
            .collect();
        let mut tris = Vec::new();
        for y in 0..n - 1 {
            for x in 0..n - 1 {
                let i = (y * n + x) as u32;
                let n = n as u32;
                tris.push([i, i + 1, i + n + 1]);
                tris.push([i, i + n + 1, i + n]);
            }
        }
        PolyMesh::from_triangles(p, &tris)
    }

    /// A UV sphere-like closed mesh: an icosphere from the builtin meshes.
    pub fn sphere(subdivisions: u32) -> PolyMesh {
        let opts = crate::mesh::builtin::BuiltinOptions {
            subdivisions,
            ..Default::default()
        };
        crate::mesh::builtin::builtin_mesh("icosphere", &opts).expect("builtin icosphere")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_adjacency_and_gradients() {
        let m = TriMesh::new(&test_meshes::grid(3, 1.0)).unwrap();
        assert_eq!(m.face_count(), 8);
        // Face 0 = [0, 1, 4]: edge 2 (4 -> 0) is shared with face 1 = [0, 4, 3].
        assert_eq!(m.neighbours[0][2], 1);
        assert_eq!(m.neighbours[0][0], NO_FACE);
        let g = m.barycentric_gradients(0);
        // λ_0 falls along +x on face [0,1,4] (x0=(0,0), x1=(1,0), x2=(1,1)).
        assert!((g[0] - Vec3::new(-1.0, 0.0, 0.0)).length() < 1e-6, "{g:?}");
        let sum = g[0] + g[1] + g[2];
        assert!(sum.length() < 1e-6);
        // Transport on a flat mesh is the identity.
        let v = Vec3::new(0.3, 0.7, 0.0);
        assert!((m.transport(v, 0, 1) - v).length() < 1e-6);
    }

    #[test]
    fn polygons_are_rejected() {
        let p = vec![Vec3::ZERO, Vec3::X, Vec3::ONE, Vec3::Y];
        let m = PolyMesh::from_polygons(p, [&[0u32, 1, 2, 3][..]]);
        assert_eq!(
            TriMesh::new(&m).unwrap_err(),
            LappedError::NotTriangles {
                face: 0,
                corners: 4
            }
        );
    }
}
