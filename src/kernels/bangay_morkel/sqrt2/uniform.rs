//! One uniform √2 subdivision step (Li, Ma & Bao 2004; Bangay & Morkel 2006
//! §3.2.1, Fig. 4).

use super::split::{SideBuckets, assemble, connect};
use super::{Parents, Subdivided};
use crate::mesh::PolyMesh;
use glam::Vec3;
use rayon::prelude::*;

/// Geometric rule of a √2 step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sqrt2Settings {
    /// Weight α of the neighbour average in the vertex rule
    /// `p'_v = (1 − α) p_v + α · mean(p_w, w ∈ N(v))`. Unitless, in `[0, 1]`;
    /// default `0.5`, the regular-case weight (see [`sqrt2_subdivide`]).
    /// `0` keeps every old position: an interpolating variant.
    pub vertex_relaxation: f32,
}

impl Default for Sqrt2Settings {
    fn default() -> Self {
        Self {
            vertex_relaxation: 0.5,
        }
    }
}

/// One step of √2 subdivision with the default rule. See [`sqrt2_subdivide_with`].
pub fn sqrt2_subdivide(mesh: &PolyMesh) -> Subdivided {
    sqrt2_subdivide_with(mesh, &Sqrt2Settings::default())
}

/// One step of √2 subdivision (Li, Ma & Bao 2004, as used by Bangay & Morkel
/// 2006 §3.2.1 and Fig. 4) over a triangle, quad or mixed polygon mesh.
///
/// **Connectivity.** Face `f` gets a face point with id `V + f`; old vertices
/// keep ids `0..V`. Every interior edge `a–b` (two faces, F0 holding the side
/// `a → b`) becomes the quad `[a, F1, b, F0]`; every boundary edge becomes the
/// triangle `[a, b, F0]`, so boundary loops keep their vertices and the
/// faces along them are triangles (§3.2.1: "except for triangles which can
/// occur on boundaries"). A non-manifold edge (three or more faces) becomes one
/// triangle `[a, b, F]` per incident face: the edge and its face count
/// survive, no new non-manifold edge appears, and nothing panics. New faces
/// inherit the orientation of the faces they come from, so outward normals
/// of a closed oriented mesh stay outward. On a closed mesh `V' = V + F`,
/// `F' = E`, `E' = 2E` and `V − E + F` is unchanged.
///
/// **Geometry (the approximating rule).** Face points are face centroids, from
/// the old positions. Each old vertex `v` whose edges are all interior edges
/// is relaxed with its old edge neighbours `N(v)`:
/// `p'_v = (1 − α) p_v + α · (1/|N(v)|) Σ_{w ∈ N(v)} p_w`, `α = 1/2` by default.
/// On a regular quad lattice these two rules are exactly one √2 refinement of
/// the four-direction box spline with every direction doubled (M₂₂₂₂, C⁴):
/// its refinement mask over the two diagonals `d₁, d₂` of the new lattice is
/// `(1 + z^{d₁})² (1 + z^{d₂})² / 8`, whose face-point taps are ¼ on the four
/// corners and whose vertex taps are ½ on the vertex and ⅛ on each edge
/// neighbour; two steps compose to its dyadic mask. That is the regular case
/// of 4-8 subdivision (Velho & Zorin 2001), which Li et al. extend, and the C⁴
/// regular behaviour Li et al. report. Li et al. also give valence-dependent
/// weights at extraordinary vertices; that table is not reproduced here (the
/// paper is not among the four this project reproduces), so `α = 1/2` is used at every valence:
/// the surface near extraordinary vertices differs from theirs, but planes stay
/// planes and a regular grid stays regular. Vertices on a boundary or
/// non-manifold edge, and isolated vertices, keep their position: √2 never
/// refines a boundary, so smoothing it would only shrink it.
///
/// Attributes carry over through [`Subdivided::parents`] (old vertices keep
/// their values; face point = average of the face's corners), see
/// [`super::interpolate_attribute`]. Output is deterministic; work is
/// spread over rayon's pool.
///
/// # Panics
/// When `V + F` or the output corner count exceeds the `u32` index range.
pub fn sqrt2_subdivide_with(mesh: &PolyMesh, settings: &Sqrt2Settings) -> Subdivided {
    let _span = tracing::debug_span!(
        "sqrt2_subdivide",
        vertices = mesh.vertex_count(),
        faces = mesh.face_count()
    )
    .entered();
    let nv = mesh.vertex_count();
    let nf = mesh.face_count();
    assert!(
        nv + nf <= u32::MAX as usize,
        "√2 subdivision: {nv} vertices + {nf} face points exceed the u32 index range"
    );
    let sides = SideBuckets::build(mesh);
    let face_point: Vec<u32> = (nv as u32..(nv + nf) as u32).collect();
    let new_faces = connect(mesh, &sides, &face_point);

    let mut positions = Vec::with_capacity(nv + nf);
    relaxed_positions(mesh, &sides, settings.vertex_relaxation, &mut positions);
    positions.par_extend((0..nf).into_par_iter().map(|f| mesh.face_centroid(f)));

    let parents = Parents::identity_then_all_faces(nv, mesh);
    let m = assemble(mesh, positions, new_faces, &face_point);
    Subdivided {
        mesh: m,
        parents,
        source_vertex_count: nv,
    }
}

/// Appends the old positions after the vertex rule (see [`sqrt2_subdivide_with`]) to `out`.
fn relaxed_positions(mesh: &PolyMesh, sides: &SideBuckets, alpha: f32, out: &mut Vec<Vec3>) {
    let p = &mesh.positions;
    if alpha == 0.0 {
        out.extend_from_slice(p);
        return;
    }
    let nv = mesh.vertex_count();
    let mut sum = vec![Vec3::ZERO; nv];
    let mut count = vec![0u32; nv];
    let mut pinned = vec![false; nv];
    sides.for_each_edge(&mesh.corner_vertex, 0..nv, |lo, hi, group| {
        let (lo, hi) = (lo as usize, hi as usize);
        if sides.is_interior_pair(group) {
            sum[lo] += p[hi];
            sum[hi] += p[lo];
            count[lo] += 1;
            count[hi] += 1;
        } else {
            pinned[lo] = true;
            pinned[hi] = true;
        }
    });
    out.par_extend((0..nv).into_par_iter().map(|v| {
        if pinned[v] || count[v] == 0 {
            p[v]
        } else {
            p[v].lerp(sum[v] / count[v] as f32, alpha)
        }
    }));
}
