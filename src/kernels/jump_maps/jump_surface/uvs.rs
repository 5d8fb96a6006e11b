//! Per-corner texture coordinates of a jump-map surface result: each
//! face's base vertex plus edge offsets, for every choice of base vertex,
//! so a renderer (or `bake`) can blend the three (Zelinka & Garland §6.5).

use super::*;
use crate::mesh::{PolyMesh, Topology};
use glam::Vec2;
use rayon::prelude::*;

/// The texture-space offset of every face side: entry `c` is the offset of
/// the edge from corner `c`'s vertex to the next corner's (§6.3), taken from
/// `offsets` ([`edge_offsets`]); zero for a side joining a vertex to itself.
/// With these, [`corner_uvs`] needs neither the topology nor the per-edge
/// offsets, which can be dropped first (together some 180 bytes per vertex).
pub fn corner_side_offsets(mesh: &PolyMesh, topo: &Topology, offsets: &[Vec2]) -> Vec<Vec2> {
    let mut out = vec![Vec2::ZERO; mesh.corner_count()];
    fill_by_face(mesh, &mut out, |f, slots| {
        let face = mesh.face(f);
        let k = face.len();
        for (i, slot) in slots.iter_mut().enumerate() {
            *slot = offset_between(topo, offsets, face[i], face[(i + 1) % k]).unwrap_or(Vec2::ZERO);
        }
    });
    out
}

/// Fills `out` (one entry per corner, or per fan triangle when its length is
/// `corners − 2·faces`) in parallel, handing `fill(f, slots)` face `f`'s
/// entries. Exact-size output: no intermediate lists.
fn fill_by_face<T: Send>(mesh: &PolyMesh, out: &mut [T], fill: impl Fn(usize, &mut [T]) + Sync) {
    let per_triangle = out.len() != mesh.corner_count();
    // First entry of face f: its first corner, or its first fan triangle
    // (face_start[f] − 2f: each face of k corners has k − 2 triangles).
    let first = |f: usize| {
        let c = mesh.face_start[f] as usize;
        if per_triangle { c - 2 * f } else { c }
    };
    let nf = mesh.face_count();
    // Faces in chunks of about 4096 entries, cut at face boundaries.
    let mut rest = &mut out[..];
    let mut chunks = Vec::new();
    let mut f = 0;
    while f < nf {
        let mut g = f + 1;
        while g < nf && first(g) - first(f) < 4096 {
            g += 1;
        }
        let len = if g < nf { first(g) } else { first(nf) } - first(f);
        let (head, tail) = rest.split_at_mut(len);
        chunks.push((f..g, head));
        rest = tail;
        f = g;
    }
    chunks.into_par_iter().for_each(|(faces, mut slots)| {
        for f in faces {
            let n = mesh.face_corners(f).len() - if per_triangle { 2 } else { 0 };
            let (mine, more) = std::mem::take(&mut slots).split_at_mut(n);
            fill(f, mine);
            slots = more;
        }
    });
}

/// Address (exemplar pixels, before the half-pixel shift) of face corner `j`
/// seen from base corner `b` of face `f`: the base address plus the edge
/// offsets along the shorter way round the face (for a triangle always the
/// direct edge, which the validity test of §6.5 covers); halfway round a
/// polygon, the mean of both ways. A step backwards subtracts the side's
/// offset: offsets are antisymmetric exactly.
fn walk(mesh: &PolyMesh, sides: &[Vec2], texel: &[Vec2], f: usize, b: usize, j: usize) -> Vec2 {
    let face = mesh.face(f);
    let side = &sides[mesh.face_corners(f)];
    let k = face.len();
    let base = texel[face[b] as usize];
    let fwd = (j + k - b) % k;
    let forward = |count: usize| {
        let mut p = base;
        let mut i = b;
        for _ in 0..count {
            p += side[i];
            i = (i + 1) % k;
        }
        p
    };
    let backward = |count: usize| {
        let mut p = base;
        let mut i = b;
        for _ in 0..count {
            i = (i + k - 1) % k;
            p += -side[i];
        }
        p
    };
    let back = k - fwd;
    if fwd == 0 {
        base
    } else if fwd < back {
        forward(fwd)
    } else if back < fwd {
        backward(back)
    } else {
        (forward(fwd) + backward(back)) * 0.5
    }
}

/// Exemplar pixel address to `[0, 1]` texture coordinates (pixel centres).
#[inline]
fn to_uv(p: Vec2, dims: (u32, u32)) -> Vec2 {
    let inv = Vec2::new(1.0 / dims.0 as f32, 1.0 / dims.1 as f32);
    (p + Vec2::splat(0.5)) * inv
}

/// The three base-vertex layers of the §6.5 blend, compactly: the per-vertex
/// texel addresses and per-corner side offsets they are walked from (8 bytes
/// per vertex + 8 per corner, ~56 bytes per vertex on a triangle mesh,
/// instead of 72 per fan triangle, ~144 per vertex). [`Self::triangle`]
/// makes a fan triangle's layers on request, bit for bit what a full array
/// ([`Self::to_vec`]) holds.
#[derive(Clone, Debug, Default)]
pub struct BlendLayers {
    /// Per vertex, the synthesised exemplar address (pixels).
    pub texel: Vec<Vec2>,
    /// Per corner, the offset to the next corner of its face
    /// ([`corner_side_offsets`]).
    pub sides: Vec<Vec2>,
    /// Exemplar width and height in pixels.
    pub dims: (u32, u32),
}

impl BlendLayers {
    /// Fan triangles of `mesh` (`corners − 2·faces`).
    pub fn triangle_count(mesh: &PolyMesh) -> usize {
        mesh.corner_count().saturating_sub(2 * mesh.face_count())
    }

    /// Whether the layers were made for `mesh`.
    pub fn fits(&self, mesh: &PolyMesh) -> bool {
        self.texel.len() == mesh.vertex_count() && self.sides.len() == mesh.corner_count()
    }

    /// Layers of fan triangle `t` (local corners `0, t + 1, t + 2`) of face
    /// `f`: per base corner, the UVs of the three corners.
    pub fn face_triangle(&self, mesh: &PolyMesh, f: usize, t: usize) -> [[Vec2; 3]; 3] {
        let local = [0, t + 1, t + 2];
        local
            .map(|b| local.map(|j| to_uv(walk(mesh, &self.sides, &self.texel, f, b, j), self.dims)))
    }

    /// Layers of fan triangle `t` of [`PolyMesh::triangulate_corners`]
    /// (its face found by binary search).
    pub fn triangle(&self, mesh: &PolyMesh, t: usize) -> [[Vec2; 3]; 3] {
        // First fan triangle of face f: face_start[f] − 2f. Faces without
        // triangles share their successor's first, so the last face whose
        // first is ≤ t is the one holding t.
        let first = |f: usize| mesh.face_start[f] as usize - 2 * f;
        let (mut lo, mut hi) = (0usize, mesh.face_count());
        while hi - lo > 1 {
            let mid = (lo + hi) / 2;
            if first(mid) <= t {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        self.face_triangle(mesh, lo, t - first(lo))
    }

    /// Every fan triangle's layers (72 bytes each), for tests and small meshes.
    pub fn to_vec(&self, mesh: &PolyMesh) -> Vec<[[Vec2; 3]; 3]> {
        let mut out = vec![[[Vec2::ZERO; 3]; 3]; Self::triangle_count(mesh)];
        fill_by_face(mesh, &mut out, |f, slots| {
            for (t, layers) in slots.iter_mut().enumerate() {
                *layers = self.face_triangle(mesh, f, t);
            }
        });
        out
    }
}

/// Blend layers per fan triangle as the consumers read them: a full array
/// (tests, single-base UVs repeated three times) or [`BlendLayers`] of a mesh.
#[derive(Clone, Copy, Debug)]
pub enum Blend<'a> {
    /// One entry per fan triangle.
    Full(&'a [[[Vec2; 3]; 3]]),
    /// Made on request from the compact form.
    Compact {
        layers: &'a BlendLayers,
        mesh: &'a PolyMesh,
    },
}

impl<'a> From<&'a [[[Vec2; 3]; 3]]> for Blend<'a> {
    fn from(layers: &'a [[[Vec2; 3]; 3]]) -> Self {
        Blend::Full(layers)
    }
}

impl<'a> From<&'a Vec<[[Vec2; 3]; 3]>> for Blend<'a> {
    fn from(layers: &'a Vec<[[Vec2; 3]; 3]>) -> Self {
        Blend::Full(layers)
    }
}

impl Blend<'_> {
    /// Number of fan triangles.
    pub fn len(&self) -> usize {
        match self {
            Blend::Full(l) => l.len(),
            Blend::Compact { mesh, .. } => BlendLayers::triangle_count(mesh),
        }
    }

    /// Whether there are no triangles.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Layers of fan triangle `t`.
    #[inline]
    pub fn get(&self, t: usize) -> [[Vec2; 3]; 3] {
        match self {
            Blend::Full(l) => l[t],
            Blend::Compact { layers, mesh } => layers.triangle(mesh, t),
        }
    }

    /// [`Self::get`] when the caller knows the triangle's face `f` (no search).
    #[inline]
    pub fn get_in_face(&self, t: usize, f: usize) -> [[Vec2; 3]; 3] {
        match self {
            Blend::Full(l) => l[t],
            Blend::Compact { layers, mesh } => {
                layers.face_triangle(mesh, f, t - (mesh.face_start[f] as usize - 2 * f))
            }
        }
    }
}

/// Per-corner texture coordinates (§6.5), in `[0, 1]` units of the exemplar
/// (v down). Returns the single-base UVs (each face's first corner as base),
/// and the blend layers: for every fan triangle of
/// [`PolyMesh::triangulate_corners`] the UVs of its three corners for each
/// of the three base choices (compactly: `sides` and a copy of `texel`).
/// `sides` come from [`corner_side_offsets`].
pub fn corner_uvs(
    mesh: &PolyMesh,
    sides: Vec<Vec2>,
    texel: &[Vec2],
    dims: (u32, u32),
) -> (Vec<Vec2>, BlendLayers) {
    let mut single = vec![Vec2::ZERO; mesh.corner_count()];
    fill_by_face(mesh, &mut single, |f, slots| {
        for (j, uv) in slots.iter_mut().enumerate() {
            *uv = to_uv(walk(mesh, &sides, texel, f, 0, j), dims);
        }
    });
    let blend = BlendLayers {
        texel: texel.to_vec(),
        sides,
        dims,
    };
    (single, blend)
}
