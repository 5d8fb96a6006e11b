//! Lapped textures (Praun, Finkelstein & Hoppe, SIGGRAPH 2000): cover a
//! surface with overlapping, alpha-blended pastes of a texture patch, each
//! pasted onto a surface patch grown and parametrised to follow a tangential
//! vector field.
//!
//! One algorithm per file:
//!
//! - [`mask`] — texture patches: an exemplar region with an alpha mask that
//!   falls off near its boundary (§3.1): circle, seeded splotch, user mask.
//! - [`cut`] — cutting the texture patches out of the exemplar: a user
//!   mask, or seeded shapes at seeded places (§3.1); [`patch_cache`] — their
//!   entries in the analysis cache.
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
//! - [`choice`] — the matched choice of a paste's texture patch (an
//!   extension: the one that best continues the pastes under its edge).
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
pub mod choice;
pub mod coverage;
pub mod cut;
pub mod grow;
pub mod hull;
pub mod mask;
pub mod param;
pub mod paste;
pub mod patch_cache;
pub mod tangent_field;

// For the quality metrics of `result_metrics`.
pub mod composite;

use crate::mesh::PolyMesh;
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
        Self::check(mesh)?;
        let tris = (0..mesh.face_count())
            .map(|f| {
                let v = mesh.face(f);
                [v[0], v[1], v[2]]
            })
            .collect();
        Ok(Self::from_parts(mesh.positions.clone(), tris))
    }

    /// [`TriMesh::new`] taking `mesh`'s positions and corners instead of
    /// copying them (36 bytes per vertex at the paste loop's peak); give
    /// them back with [`TriMesh::into_poly_mesh`]. On an error the mesh is
    /// returned unchanged.
    ///
    /// # Errors
    /// As [`TriMesh::new`].
    #[allow(clippy::result_large_err)]
    pub fn from_owned(mesh: PolyMesh) -> Result<Self, (PolyMesh, LappedError)> {
        if let Err(e) = Self::check(&mesh) {
            return Err((mesh, e));
        }
        let fc = mesh.face_count();
        let PolyMesh {
            positions,
            mut corner_vertex,
            ..
        } = mesh;
        // Every face has three corners, so face `f` is corners `3f..3f + 3`;
        // corners past the last face belong to no face.
        corner_vertex.truncate(3 * fc);
        // The corners of a triangle mesh are its triangles, three at a time
        // (same alignment; only a capacity that is not a multiple of three
        // makes the cast copy).
        let tris: Vec<[u32; 3]> = bytemuck::allocation::try_cast_vec(corner_vertex)
            .unwrap_or_else(|(_, c)| bytemuck::cast_slice(&c).to_vec());
        Ok(Self::from_parts(positions, tris))
    }

    /// The positions and triangles as the mesh [`TriMesh::from_owned`] took
    /// them from (every face a triangle, in order).
    pub fn into_poly_mesh(self) -> PolyMesh {
        let face_start = (0..=self.tris.len() as u32).map(|f| 3 * f).collect();
        PolyMesh {
            positions: self.positions,
            face_start,
            corner_vertex: bytemuck::allocation::cast_vec(self.tris),
        }
    }

    /// Refuses what the kernels cannot work on (as [`TriMesh::new`]).
    ///
    /// # Errors
    /// As [`TriMesh::new`].
    pub fn check(mesh: &PolyMesh) -> Result<(), LappedError> {
        if mesh.face_count() == 0 {
            return Err(LappedError::NoFaces);
        }
        if let Some(face) = (0..mesh.face_count()).find(|&f| mesh.face_corners(f).len() != 3) {
            return Err(LappedError::NotTriangles {
                face,
                corners: mesh.face_corners(face).len(),
            });
        }
        Ok(())
    }

    /// The adjacency of `tris` over `positions`.
    fn from_parts(positions: Vec<Vec3>, tris: Vec<[u32; 3]>) -> Self {
        // Faces around each vertex, then the face across each edge from
        // them: no full `Topology` (~140 bytes per vertex, and a sort of
        // 16 bytes per corner) is built for what is read here.
        let (vertex_face_start, vertex_face_list) = vertex_faces(&tris, positions.len());
        let neighbours = face_neighbours(&tris, &vertex_face_start, &vertex_face_list);
        Self {
            positions,
            tris,
            neighbours,
            vertex_face_start,
            vertex_face_list,
        }
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

    /// The area vector of face `f` (length twice the area), computed by
    /// the polygon mesh's own function, not stored: normals and areas were
    /// 16 bytes per face.
    #[inline]
    fn normal_scaled(&self, f: usize) -> Vec3 {
        crate::mesh::area_vector(&self.positions, &self.tris[f])
    }

    /// Unit normal of face `f` (zero for a degenerate face), exactly
    /// [`PolyMesh::face_normal`].
    #[inline]
    pub fn normal(&self, f: usize) -> Vec3 {
        self.normal_scaled(f).normalize_or_zero()
    }

    /// Area of face `f`, exactly [`PolyMesh::face_area`].
    #[inline]
    pub fn area(&self, f: usize) -> f32 {
        0.5 * self.normal_scaled(f).length()
    }

    /// The centroid of face `f` (computed, not stored: 24 bytes per face
    /// saved).
    #[inline]
    pub fn centroid(&self, f: usize) -> Vec3 {
        let p = &self.positions;
        let t = self.tris[f];
        (p[t[0] as usize] + p[t[1] as usize] + p[t[2] as usize]) / 3.0
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
        self.gradients_and_normal(f).0
    }

    /// [`TriMesh::barycentric_gradients`] and [`TriMesh::normal`] of face
    /// `f` from one area vector (each would compute it again; the grower
    /// asks for both per face and growth step).
    #[inline]
    pub fn gradients_and_normal(&self, f: usize) -> ([Vec3; 3], Vec3) {
        let x = self.corners(f);
        let scaled = self.normal_scaled(f);
        let n = scaled.normalize_or_zero();
        // The same expression as `2.0 * self.area(f)`: the same bits.
        let twice_area = 2.0 * (0.5 * scaled.length());
        if twice_area <= f32::MIN_POSITIVE || n == Vec3::ZERO {
            return ([Vec3::ZERO; 3], n);
        }
        let grad = [0, 1, 2].map(|i| n.cross(x[(i + 2) % 3] - x[(i + 1) % 3]) / twice_area);
        (grad, n)
    }

    /// The tangent `v` of face `f` carried across its edge to the face `g`
    /// by unfolding (a rotation about the shared edge): the discrete
    /// parallel transport the initial parametrisation of §3.3 follows.
    /// Without a shared edge, `v` is projected onto `g`'s plane.
    pub fn transport(&self, v: Vec3, f: usize, g: usize) -> Vec3 {
        let edge = (0..3).find(|&i| self.neighbours[f][i] == g as u32);
        let (nf, ng) = (self.normal(f), self.normal(g));
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

/// Faces around each vertex as CSR (offsets, list): in increasing order, a
/// face once however often the vertex occurs in it (as
/// `Topology::vertex_faces`).
fn vertex_faces(tris: &[[u32; 3]], vertex_count: usize) -> (Vec<u32>, Vec<u32>) {
    // The corners that are the first of their vertex in their face.
    let firsts = |t: &[u32; 3]| {
        [
            (t[0], true),
            (t[1], t[1] != t[0]),
            (t[2], t[2] != t[0] && t[2] != t[1]),
        ]
    };
    let mut start = vec![0u32; vertex_count + 1];
    for (v, first) in tris.iter().flat_map(firsts) {
        start[v as usize + 1] += u32::from(first);
    }
    for v in 0..vertex_count {
        start[v + 1] += start[v];
    }
    let mut next = start.clone();
    let mut list = vec![0u32; start[vertex_count] as usize];
    for (f, t) in tris.iter().enumerate() {
        for (v, first) in firsts(t) {
            if first {
                list[next[v as usize] as usize] = f as u32;
                next[v as usize] += 1;
            }
        }
    }
    (start, list)
}

/// Per face, the face across each of its edges: across the edge `{a, b}`
/// of face `f` when exactly two sides of all faces lie on that edge and the
/// other one is not `f`'s, else [`NO_FACE`] (a boundary, a non-manifold
/// edge, or a face folded onto itself). The faces with a side on `{a, b}`
/// are all among `a`'s faces (`vertex_face_*`, a face listed once per
/// vertex).
fn face_neighbours(
    tris: &[[u32; 3]],
    vertex_face_start: &[u32],
    vertex_face_list: &[u32],
) -> Vec<[u32; 3]> {
    use rayon::prelude::*;
    tris.par_iter()
        .enumerate()
        .map(|(f, t)| {
            [0, 1, 2].map(|i| {
                let (a, b) = (t[i], t[(i + 1) % 3]);
                let around = &vertex_face_list[vertex_face_start[a as usize] as usize
                    ..vertex_face_start[a as usize + 1] as usize];
                let (mut sides, mut other) = (0, NO_FACE);
                for &g in around {
                    let u = tris[g as usize];
                    for j in 0..3 {
                        let (x, y) = (u[j], u[(j + 1) % 3]);
                        if (x == a && y == b) || (x == b && y == a) {
                            sides += 1;
                            if g as usize != f {
                                other = g;
                            }
                        }
                    }
                }
                if sides == 2 { other } else { NO_FACE }
            })
        })
        .collect()
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
    /// Factor applied to `t` as it is read ([`FaceField::at`]): the stage
    /// passes the field in world units per pixel with the patch's pixels
    /// per unit here instead of a scaled copy (24 bytes per face). 1 for a
    /// field already in patch units (`x · 1` is exact).
    pub scale: f32,
}

impl FaceField<'_> {
    /// `T` of face `f` times [`FaceField::scale`].
    #[inline]
    pub fn at(&self, f: usize) -> Vec3 {
        self.t[f] * self.scale
    }

    /// The mean length of `T` over the faces ([`FaceField::at`]).
    pub fn mean_length(&self) -> f64 {
        (0..self.t.len())
            .map(|f| self.at(f).length() as f64)
            .sum::<f64>()
            / self.t.len().max(1) as f64
    }
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
    use crate::mesh::Topology;

    #[test]
    fn an_owned_mesh_gives_the_same_adjacency_and_comes_back_whole() {
        for mesh in [test_meshes::grid(5, 0.5), test_meshes::sphere(2)] {
            let copied = TriMesh::new(&mesh).unwrap();
            let owned = TriMesh::from_owned(mesh.clone()).unwrap();
            assert_eq!(owned.positions, copied.positions);
            assert_eq!(owned.tris, copied.tris);
            assert_eq!(owned.neighbours, copied.neighbours);
            assert_eq!(owned.vertex_face_list, copied.vertex_face_list);
            for f in 0..mesh.face_count() {
                // Computed when read, bit for bit the polygon mesh's.
                assert_eq!(owned.normal(f).to_array(), mesh.face_normal(f).to_array());
                assert_eq!(owned.area(f).to_bits(), mesh.face_area(f).to_bits());
            }
            assert_eq!(owned.into_poly_mesh(), mesh);
        }
        // A polygon is refused and the mesh handed back untouched.
        let mut quad = PolyMesh::new();
        quad.positions = vec![Vec3::ZERO, Vec3::X, Vec3::ONE, Vec3::Y];
        quad.push_face(&[0, 1, 2, 3]);
        let (back, e) = TriMesh::from_owned(quad.clone()).unwrap_err();
        assert_eq!(back, quad);
        assert!(matches!(
            e,
            LappedError::NotTriangles {
                face: 0,
                corners: 4
            }
        ));
    }

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

    /// The neighbours as the full topology gives them (the former
    /// construction): the face across each side's edge when the edge has
    /// exactly two sides and the other is another face.
    fn neighbours_from_topology(mesh: &PolyMesh) -> Vec<[u32; 3]> {
        let topo = Topology::build(mesh);
        (0..mesh.face_count())
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
            .collect()
    }

    #[test]
    fn neighbours_equal_the_full_topology_s() {
        // A grid with a fin (a third face on an edge), a face folded back
        // onto its neighbour's edge, a face with a repeated vertex and an
        // isolated triangle.
        let grid = test_meshes::grid(6, 1.0);
        let mut p = grid.positions.clone();
        let mut tris: Vec<[u32; 3]> = (0..grid.face_count())
            .map(|f| {
                let v = grid.face(f);
                [v[0], v[1], v[2]]
            })
            .collect();
        p.push(Vec3::new(0.5, 0.5, 1.0));
        let apex = (p.len() - 1) as u32;
        tris.push([0, 1, apex]);
        tris.push([7, 8, 14]);
        tris.push([20, 20, 21]);
        p.extend([
            Vec3::splat(9.0),
            Vec3::new(10.0, 9.0, 9.0),
            Vec3::new(9.0, 10.0, 9.0),
        ]);
        let n = p.len() as u32;
        tris.push([n - 3, n - 2, n - 1]);
        for mesh in [
            PolyMesh::from_triangles(p, &tris),
            test_meshes::sphere(2),
            grid,
        ] {
            let m = TriMesh::new(&mesh).unwrap();
            assert_eq!(m.neighbours, neighbours_from_topology(&mesh));
            let topo = Topology::build(&mesh);
            assert_eq!(m.vertex_face_start, topo.vertex_face_start);
            assert_eq!(m.vertex_face_list, topo.vertex_face_list);
        }
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
