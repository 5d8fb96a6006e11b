//! Polygon meshes: connectivity as compact `u32` arrays, every attribute apart.
//!
//! A [`PolyMesh`] holds positions and polygon faces (triangles, quads, any
//! polygon) in CSR form: face `f` owns the corners `face_start[f]..face_start[f+1]`
//! and `corner_vertex[c]` is the vertex of corner `c`. Per-corner attributes
//! (texture coordinates) are arrays indexed by corner. Derived connectivity
//! (edges, one-rings, boundaries, components) lives in [`Topology`], computed on
//! request and rebuilt after the mesh changes.

pub mod builtin;
mod error;
pub mod info;
pub mod io;
pub mod repair;
mod topology;

pub use error::MeshError;
pub use info::MeshInfo;
pub use io::{LoadOptions, load_mesh};
pub use repair::LoadReport;
pub use topology::{Topology, edge_key, union_find_join, union_find_root};

use glam::Vec3;
use std::ops::Range;

/// A polygon mesh: positions plus faces in CSR form.
///
/// Architecture invariant: `face_start` is non-decreasing, starts at 0, ends at
/// `corner_vertex.len()`, every face has at least 3 corners, and every entry of
/// `corner_vertex` is `< positions.len()`. Loaders and builders establish it;
/// kernels may rely on it.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PolyMesh {
    /// Vertex positions, one row per vertex.
    pub positions: Vec<Vec3>,
    /// CSR offsets into `corner_vertex`; `face_count() + 1` entries.
    pub face_start: Vec<u32>,
    /// The vertex of each corner.
    pub corner_vertex: Vec<u32>,
}

/// Area-weighted normal of the polygon `corners` over `positions` by
/// Newell's method, its length twice the area, with corners taken relative
/// to the first one (see [`PolyMesh::face_normal_scaled`], which is this
/// for a face; meshes that store triangles differently call it too, so
/// their normals and areas are the same bits).
#[inline]
pub fn area_vector(positions: &[Vec3], corners: &[u32]) -> Vec3 {
    let Some(&first) = corners.first() else {
        return Vec3::ZERO;
    };
    let origin = positions[first as usize];
    let mut n = Vec3::ZERO;
    for w in corners.windows(2).skip(1) {
        let p = positions[w[0] as usize] - origin;
        let q = positions[w[1] as usize] - origin;
        n += p.cross(q);
    }
    n
}

impl PolyMesh {
    /// An empty mesh (no vertices, no faces).
    pub fn new() -> Self {
        Self {
            positions: Vec::new(),
            face_start: vec![0],
            corner_vertex: Vec::new(),
        }
    }

    /// Builds a triangle mesh. Indices are trusted (use the loaders for user data).
    pub fn from_triangles(positions: Vec<Vec3>, triangles: &[[u32; 3]]) -> Self {
        let mut mesh = Self {
            positions,
            face_start: Vec::with_capacity(triangles.len() + 1),
            corner_vertex: Vec::with_capacity(triangles.len() * 3),
        };
        mesh.face_start.push(0);
        for t in triangles {
            mesh.push_face(t);
        }
        mesh
    }

    /// Builds a polygon mesh from any faces. Indices are trusted.
    pub fn from_polygons<'a>(
        positions: Vec<Vec3>,
        faces: impl IntoIterator<Item = &'a [u32]>,
    ) -> Self {
        let mut mesh = Self {
            positions,
            ..Self::new()
        };
        for f in faces {
            mesh.push_face(f);
        }
        mesh
    }

    /// Appends a face given by its vertex ids, in counter-clockwise order.
    pub fn push_face(&mut self, vertices: &[u32]) {
        if self.face_start.is_empty() {
            self.face_start.push(0);
        }
        self.corner_vertex.extend_from_slice(vertices);
        self.face_start.push(self.corner_vertex.len() as u32);
    }

    /// Number of vertices.
    #[inline]
    pub fn vertex_count(&self) -> usize {
        self.positions.len()
    }

    /// Number of faces.
    #[inline]
    pub fn face_count(&self) -> usize {
        self.face_start.len().saturating_sub(1)
    }

    /// Number of corners (sum of face degrees).
    #[inline]
    pub fn corner_count(&self) -> usize {
        self.corner_vertex.len()
    }

    /// The corner range of face `f`.
    #[inline]
    pub fn face_corners(&self, f: usize) -> Range<usize> {
        self.face_start[f] as usize..self.face_start[f + 1] as usize
    }

    /// The vertex ids of face `f`.
    #[inline]
    pub fn face(&self, f: usize) -> &[u32] {
        &self.corner_vertex[self.face_corners(f)]
    }

    /// Iterates over faces as vertex-id slices.
    pub fn faces(&self) -> impl ExactSizeIterator<Item = &[u32]> + '_ {
        (0..self.face_count()).map(move |f| self.face(f))
    }

    /// True when every face is a triangle.
    pub fn is_triangle_mesh(&self) -> bool {
        self.face_start.windows(2).all(|w| w[1] - w[0] == 3)
    }

    /// Area-weighted normal of face `f` by Newell's method; its length is
    /// twice the area. Corners are taken relative to the first one, so a
    /// mesh far from the origin (a scan at z = -1000) loses no precision to
    /// cancellation: the result depends only on the face's shape.
    #[inline]
    pub fn face_normal_scaled(&self, f: usize) -> Vec3 {
        area_vector(&self.positions, self.face(f))
    }

    /// Unit normal of face `f` (zero for a degenerate face).
    #[inline]
    pub fn face_normal(&self, f: usize) -> Vec3 {
        self.face_normal_scaled(f).normalize_or_zero()
    }

    /// Area of face `f` (planar projection along its Newell normal).
    #[inline]
    pub fn face_area(&self, f: usize) -> f32 {
        0.5 * self.face_normal_scaled(f).length()
    }

    /// Centroid of the corners of face `f`.
    pub fn face_centroid(&self, f: usize) -> Vec3 {
        let face = self.face(f);
        face.iter()
            .map(|&v| self.positions[v as usize])
            .sum::<Vec3>()
            / face.len() as f32
    }

    /// All face areas.
    pub fn face_areas(&self) -> Vec<f32> {
        (0..self.face_count()).map(|f| self.face_area(f)).collect()
    }

    /// All unit face normals.
    pub fn face_normals(&self) -> Vec<Vec3> {
        (0..self.face_count())
            .map(|f| self.face_normal(f))
            .collect()
    }

    /// Area-weighted unit vertex normals; an isolated vertex gets +Z.
    pub fn vertex_normals(&self) -> Vec<Vec3> {
        let mut normals = vec![Vec3::ZERO; self.vertex_count()];
        for f in 0..self.face_count() {
            let n = self.face_normal_scaled(f);
            for &v in self.face(f) {
                normals[v as usize] += n;
            }
        }
        for n in &mut normals {
            *n = n.try_normalize().unwrap_or(Vec3::Z);
        }
        normals
    }

    /// Total surface area.
    pub fn area(&self) -> f32 {
        (0..self.face_count()).map(|f| self.face_area(f)).sum()
    }

    /// Axis-aligned bounding box `(min, max)`; `None` for a mesh without vertices.
    pub fn bounding_box(&self) -> Option<(Vec3, Vec3)> {
        let first = *self.positions.first()?;
        Some(
            self.positions
                .iter()
                .fold((first, first), |(lo, hi), &p| (lo.min(p), hi.max(p))),
        )
    }

    /// Mean length of the face edges (each face side counted once per face).
    pub fn average_edge_length(&self) -> f32 {
        let (sum, n) = self.face_sides().fold((0.0f64, 0usize), |(s, n), (a, b)| {
            (
                s + (self.positions[a as usize] - self.positions[b as usize]).length() as f64,
                n + 1,
            )
        });
        if n == 0 { 0.0 } else { (sum / n as f64) as f32 }
    }

    /// Iterates over the directed sides `(a, b)` of every face.
    pub fn face_sides(&self) -> impl Iterator<Item = (u32, u32)> + '_ {
        self.faces().flat_map(|face| {
            let n = face.len();
            (0..n).map(move |i| (face[i], face[(i + 1) % n]))
        })
    }

    /// Fan-triangulates every face. Returns, per triangle, its three corner
    /// indices (so per-corner attributes carry over) and the face it came from.
    /// The fan covers a face once when it is convex, as every face the
    /// loaders return is (they cut non-convex ones,
    /// [`repair::triangulate_faces`]).
    pub fn triangulate_corners(&self) -> (Vec<[u32; 3]>, Vec<u32>) {
        // A face of k corners gives k − 2 triangles.
        let count = self.corner_count().saturating_sub(2 * self.face_count());
        let mut tris = Vec::with_capacity(count);
        let mut face_of = Vec::with_capacity(count);
        for f in 0..self.face_count() {
            let r = self.face_corners(f);
            let c0 = r.start as u32;
            for c in (r.start + 1)..(r.end - 1) {
                tris.push([c0, c as u32, c as u32 + 1]);
                face_of.push(f as u32);
            }
        }
        (tris, face_of)
    }

    /// The mesh with every face fan-triangulated (vertices unchanged).
    pub fn triangulated(&self) -> PolyMesh {
        let (tris, _) = self.triangulate_corners();
        let tris: Vec<[u32; 3]> = tris
            .iter()
            .map(|t| t.map(|c| self.corner_vertex[c as usize]))
            .collect();
        PolyMesh::from_triangles(self.positions.clone(), &tris)
    }
}
