//! √2 subdivision of polygon meshes (Li, Ma & Bao 2004) and its adaptive
//! variant, as Bangay & Morkel 2006 §3.2 use it to build the mesh hierarchy.
//!
//! One step inserts a point per face and replaces every edge by a quadrilateral
//! joining the edge's two ends and the two face points beside it (Bangay &
//! Morkel Fig. 4). A regular quad grid becomes the same grid rotated by 45°
//! with twice the vertices; two steps give the grid at half the spacing.
//!
//! ```text
//!   ┌─────────────┐                 F0
//!   │     F0      │               ╱    ╲        F0, F1: face points of the
//!   a ─────────── b       ⇒      a      b       two faces beside edge a–b;
//!   │     F1      │               ╲    ╱        the quad [a, F1, b, F0]
//!   └─────────────┘                 F1          replaces the edge.
//! ```
//!
//! Files, one algorithm each:
//! * [`sqrt2_subdivide`] (`uniform.rs`): one step over the whole mesh, with
//!   the vertex relaxation rule of the approximating scheme.
//! * [`subdivide_to`] (`hierarchy.rs`): repeated steps up to a level count or a
//!   vertex budget, the hierarchy of §3.2.1.
//! * [`adaptive_sqrt2`] (`adaptive.rs`): refines only faces larger than a
//!   factor times the mean area, §3.2.2, with its transition rule.
//! * `carry.rs`: per-vertex attributes carried through [`Parents`]
//!   ([`carry_attribute`], rows, frames).
//! * `on_input.rs`: levels kept on the input surface and its corners
//!   ([`InputSurface`]), uniform steps to a vertex budget
//!   ([`levels_towards`]), and a dense input remeshed coarse first
//!   ([`coarsened_input`]).
//! * `split.rs`: the connectivity shared by both: sides grouped by edge and
//!   the faces each edge turns into.
//!
//! **Vertex ids.** A step never renumbers: the old vertices keep ids `0..V`
//! (the scheme relaxes their positions but they stay the same vertices, so
//! per-vertex attributes carry over, Bangay & Morkel §3.2.1 first bullet), and
//! face points follow. [`Parents`] lists, per new vertex, the parent vertices
//! and weights that [`interpolate_attribute`] uses.

mod adaptive;
mod carry;
mod hierarchy;
mod on_input;
mod split;
mod uniform;

pub use adaptive::{AdaptiveSqrt2, AreaStats, adaptive_sqrt2};
pub use carry::{carry_attribute, carry_frames, carry_rows};
pub use hierarchy::{MAX_HIERARCHY_LEVELS, MAX_HIERARCHY_VERTICES, subdivide_to};
pub use on_input::{COARSEN_STEPS, InputSurface, UniformLevels, coarsened_input, levels_towards};
pub use uniform::{Sqrt2Settings, sqrt2_subdivide, sqrt2_subdivide_with};

use crate::mesh::PolyMesh;
use std::ops::{Add, Mul};

/// One subdivision result: the refined mesh and, per new vertex, where its
/// attributes come from in the source mesh.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Subdivided {
    /// The refined mesh. Vertices `0..source_vertex_count` are the source
    /// mesh's vertices (same ids, possibly relaxed positions); the rest are
    /// face points.
    pub mesh: PolyMesh,
    /// Per vertex of `mesh`: parent vertices in the source mesh and weights.
    pub parents: Parents,
    /// Number of vertices of the source mesh the parents refer to.
    pub source_vertex_count: usize,
}

/// Parents of every new vertex, in CSR form: vertex `v` has the parents
/// `vertex[start[v]..start[v + 1]]` with the weights at the same positions.
/// Weights of one vertex are positive and sum to 1. An old vertex has itself as
/// its only parent with weight exactly 1.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Parents {
    /// CSR offsets, one more entry than there are new vertices.
    pub start: Vec<u32>,
    /// Parent vertex ids (in the source mesh).
    pub vertex: Vec<u32>,
    /// Interpolation weight of each parent.
    pub weight: Vec<f32>,
}

impl Parents {
    /// The identity map over `n` vertices.
    pub fn identity(n: usize) -> Self {
        Self {
            start: (0..=n as u32).collect(),
            vertex: (0..n as u32).collect(),
            weight: vec![1.0; n],
        }
    }

    /// Number of new vertices described.
    pub fn len(&self) -> usize {
        self.start.len().saturating_sub(1)
    }

    /// True when no vertex is described.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Parent ids and weights of new vertex `v`.
    #[inline]
    pub fn of(&self, v: usize) -> (&[u32], &[f32]) {
        let r = self.start[v] as usize..self.start[v + 1] as usize;
        (&self.vertex[r.clone()], &self.weight[r])
    }

    /// The old vertices `0..n` as themselves, then one vertex per face of
    /// `mesh`, with the face's corners as parents, each weighted `1 / degree`.
    pub(crate) fn identity_then_all_faces(n: usize, mesh: &PolyMesh) -> Self {
        let nf = mesh.face_count();
        assert!(
            n + mesh.corner_count() <= u32::MAX as usize,
            "√2 subdivision: {} parent entries exceed the u32 index range",
            n + mesh.corner_count()
        );
        let mut p = Self::identity(n);
        p.start.reserve(nf);
        p.start
            .extend(mesh.face_start.iter().skip(1).map(|&s| s + n as u32));
        p.vertex.extend_from_slice(&mesh.corner_vertex);
        p.weight.reserve(mesh.corner_count());
        for f in 0..nf {
            let k = mesh.face_corners(f).len();
            p.weight.extend(std::iter::repeat_n(1.0 / k as f32, k));
        }
        p
    }

    /// The old vertices `0..n` as themselves, then one vertex per listed face
    /// of `mesh` with the face's corners as parents, each weighted `1 / degree`.
    pub(crate) fn identity_then_faces(n: usize, mesh: &PolyMesh, faces: &[u32]) -> Self {
        let corners: usize = faces
            .iter()
            .map(|&f| mesh.face_corners(f as usize).len())
            .sum();
        assert!(
            n + corners <= u32::MAX as usize,
            "√2 subdivision: {} parent entries exceed the u32 index range",
            n + corners
        );
        let mut p = Self::identity(n);
        p.start.reserve(faces.len());
        p.vertex.reserve(corners);
        p.weight.reserve(corners);
        for &f in faces {
            let face = mesh.face(f as usize);
            let w = 1.0 / face.len() as f32;
            p.vertex.extend_from_slice(face);
            p.weight.extend(std::iter::repeat_n(w, face.len()));
            p.start.push(p.vertex.len() as u32);
        }
        p
    }

    /// Composes two maps: `self` maps new vertices to middle ones, `inner`
    /// maps middle vertices to source ones. Weights of a repeated source
    /// vertex are summed; each list comes out sorted by source id, except that
    /// identity entries are copied as they are.
    pub(crate) fn compose(&self, inner: &Parents) -> Parents {
        let mut out = Parents {
            start: Vec::with_capacity(self.start.len()),
            vertex: Vec::with_capacity(self.vertex.len()),
            weight: Vec::with_capacity(self.weight.len()),
        };
        out.start.push(0);
        let mut buf: Vec<(u32, f32)> = Vec::new();
        for v in 0..self.len() {
            let (pv, pw) = self.of(v);
            if let ([m], [w]) = (pv, pw)
                && *w == 1.0
            {
                let (iv, iw) = inner.of(*m as usize);
                out.vertex.extend_from_slice(iv);
                out.weight.extend_from_slice(iw);
            } else {
                buf.clear();
                for (&m, &w) in pv.iter().zip(pw) {
                    let (iv, iw) = inner.of(m as usize);
                    buf.extend(iv.iter().zip(iw).map(|(&s, &u)| (s, w * u)));
                }
                buf.sort_unstable_by_key(|&(s, _)| s);
                let mut i = 0;
                while i < buf.len() {
                    let s = buf[i].0;
                    let mut w = 0.0;
                    while i < buf.len() && buf[i].0 == s {
                        w += buf[i].1;
                        i += 1;
                    }
                    out.vertex.push(s);
                    out.weight.push(w);
                }
            }
            assert!(
                out.vertex.len() <= u32::MAX as usize,
                "√2 subdivision: composed parent lists exceed the u32 index range"
            );
            out.start.push(out.vertex.len() as u32);
        }
        out
    }
}

/// Carries a per-vertex attribute (colour, scalar, texture coordinate, …) from
/// the source mesh of `sub` to its refined mesh: old vertices keep their value
/// exactly, every face point gets the average of its face's corners (for an
/// adaptive result spanning several passes, the composed weights).
///
/// Positions are not attributes here: the scheme relaxes old vertices, so use
/// `sub.mesh.positions` rather than interpolating positions.
///
/// # Panics
/// When `old.len()` differs from `sub.source_vertex_count` (a caller bug).
pub fn interpolate_attribute<T>(sub: &Subdivided, old: &[T]) -> Vec<T>
where
    T: Copy + Add<Output = T> + Mul<f32, Output = T>,
{
    assert_eq!(
        old.len(),
        sub.source_vertex_count,
        "interpolate_attribute: one value per source vertex expected"
    );
    carry_attribute(&sub.parents, old)
}
