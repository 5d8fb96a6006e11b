//! Adaptive √2 subdivision towards even face areas (Bangay & Morkel 2006
//! §3.2.2, Figs. 5 and 6).

use super::split::{KEPT, SideBuckets, assemble, connect};
use super::{Parents, Subdivided};
use crate::mesh::PolyMesh;
use rayon::prelude::*;

/// Spread of face areas, the measure of Bangay & Morkel Fig. 6. Computed in
/// `f64`; areas in squared mesh units.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct AreaStats {
    /// Number of faces.
    pub faces: usize,
    /// Sum of face areas.
    pub total: f64,
    /// Mean face area (0 without faces).
    pub mean: f64,
    /// Population standard deviation of face areas.
    pub std_dev: f64,
    /// `100 · std_dev / mean`, in percent (0 when the mean is 0).
    pub std_percent_of_mean: f64,
}

impl AreaStats {
    /// Statistics of the face areas of `mesh` (Newell areas, [`PolyMesh::face_area`]).
    pub fn of(mesh: &PolyMesh) -> Self {
        Self::of_areas(&face_areas(mesh))
    }

    fn of_areas(areas: &[f32]) -> Self {
        let n = areas.len();
        if n == 0 {
            return Self::default();
        }
        let total: f64 = areas.iter().map(|&a| a as f64).sum();
        let mean = total / n as f64;
        let var = areas
            .iter()
            .map(|&a| (a as f64 - mean).powi(2))
            .sum::<f64>()
            / n as f64;
        let std_dev = var.sqrt();
        Self {
            faces: n,
            total,
            mean,
            std_dev,
            std_percent_of_mean: if mean > 0.0 {
                100.0 * std_dev / mean
            } else {
                0.0
            },
        }
    }
}

fn face_areas(mesh: &PolyMesh) -> Vec<f32> {
    (0..mesh.face_count())
        .into_par_iter()
        .map(|f| mesh.face_area(f))
        .collect()
}

/// Result of [`adaptive_sqrt2`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct AdaptiveSqrt2 {
    /// The refined mesh; its parents refer to the input mesh's vertices, with
    /// the weights of all passes composed.
    pub subdivided: Subdivided,
    /// Face-area statistics of the input mesh.
    pub before: AreaStats,
    /// Face-area statistics of the result.
    pub after: AreaStats,
    /// Faces refined in each pass that ran (passes stop early once no face
    /// is above the threshold).
    pub refined_per_pass: Vec<usize>,
}

/// Adaptive √2 subdivision (Bangay & Morkel 2006 §3.2.2): in each of `passes`
/// passes, refine exactly the faces with area `a_i > area_factor · ā`, `ā` the
/// mean face area of the current mesh (the paper finds `area_factor ≈ 1.5`
/// good for most models). Stops early when no face is selected; a NaN factor
/// selects nothing.
///
/// **Refined faces** get a face point (their centroid) and split as in the
/// uniform step: an edge between two refined faces becomes the quad
/// `[a, F1, b, F0]`, and a boundary edge of a refined face the triangle
/// `[a, b, F]`. Old vertices keep their positions (no relaxation): relaxing
/// only inside the refined region would pull it away from the kept faces
/// around it. Each new triangle lies in the face it came from; the quad
/// `[a, F1, b, F0]` is folded along `a–b` where the mesh bends, and the fan
/// triangulation from its first corner splits it exactly there. So on planar
/// input the surface and its area do not change at all; on curved input one
/// pass keeps the surface as a triangulated set, and later passes, whose face
/// points are centroids of folded quads, chamfer the folds slightly. (The
/// Newell area of a folded quad is its projected area, smaller than the two
/// triangles, so [`AreaStats`] reads a little low on curved meshes.)
///
/// **Transition rule** (Fig. 5: "triangular faces are used to ensure
/// connectivity between the subdivided region and the remainder of the
/// mesh"). On an edge `a–b` between a refined face `f` and a kept face `g`
/// the quad would need `g`'s face point, which does not exist. Instead `f`'s
/// side becomes the triangle `[a, b, F]` and `g` stays as it is:
///
/// ```text
///      g (kept)                      g (kept, unchanged)
///   a ─────────── b               a ─────────── b
///   │             │               │ ╲         ╱ │   triangle [a, b, F]
///   │      f      │       ⇒       │   ╲     ╱   │   shares a–b with g
///   │  (refined)  │               │     F       │   (quads to f's other
///   │             │               │   ╱   ╲     │    refined neighbours)
/// ```
///
/// √2 never inserts a vertex on an edge: every old edge either disappears
/// (becoming a quad's diagonal, when both sides are refined) or survives whole
/// with one new triangle against it. So there are no T-junctions or cracks,
/// each interior edge keeps exactly two faces, boundary edges stay boundary
/// edges (a closed mesh stays closed), non-manifold edges keep their face
/// count, and `V − E + F` is unchanged. The kept neighbour needs no split.
/// As the paper notes, faces of very different levels may meet (we, like the
/// paper, do not limit neighbours to one level apart), and a large isolated
/// face refined again and again turns into slivers around its old corners.
///
/// New vertex ids: each pass appends one face point per refined face, in face
/// order; old vertices keep their ids. Kept faces follow the new faces in the
/// output face list, in their previous order.
///
/// # Panics
/// When a pass would exceed the `u32` index range.
pub fn adaptive_sqrt2(mesh: &PolyMesh, area_factor: f32, passes: u32) -> AdaptiveSqrt2 {
    let _span = tracing::debug_span!("adaptive_sqrt2", area_factor, passes).entered();
    let mut areas = face_areas(mesh);
    let before = AreaStats::of_areas(&areas);
    let mut current = mesh.clone();
    let mut parents = Parents::identity(mesh.vertex_count());
    let mut refined_per_pass = Vec::new();
    for _ in 0..passes {
        let mean = AreaStats::of_areas(&areas).mean;
        let threshold = area_factor as f64 * mean;
        let selected: Vec<u32> = (0..areas.len() as u32)
            .filter(|&f| areas[f as usize] as f64 > threshold)
            .collect();
        if selected.is_empty() {
            break;
        }
        let (next, step) = refine_faces(&current, &selected);
        parents = step.compose(&parents);
        refined_per_pass.push(selected.len());
        current = next;
        areas = face_areas(&current);
    }
    let after = AreaStats::of_areas(&areas);
    AdaptiveSqrt2 {
        subdivided: Subdivided {
            mesh: current,
            parents,
            source_vertex_count: mesh.vertex_count(),
        },
        before,
        after,
        refined_per_pass,
    }
}

/// One adaptive pass: refines the listed faces (ascending ids), keeps the
/// others. Returns the new mesh and its parents in `mesh`.
fn refine_faces(mesh: &PolyMesh, selected: &[u32]) -> (PolyMesh, Parents) {
    let nv = mesh.vertex_count();
    assert!(
        nv + selected.len() <= u32::MAX as usize,
        "adaptive √2 subdivision: vertex count exceeds the u32 index range"
    );
    let mut face_point = vec![KEPT; mesh.face_count()];
    for (k, &f) in selected.iter().enumerate() {
        face_point[f as usize] = (nv + k) as u32;
    }
    let sides = SideBuckets::build(mesh);
    let new_faces = connect(mesh, &sides, &face_point);
    let mut positions = Vec::with_capacity(nv + selected.len());
    positions.extend_from_slice(&mesh.positions);
    positions.par_extend(selected.par_iter().map(|&f| mesh.face_centroid(f as usize)));
    let parents = Parents::identity_then_faces(nv, mesh, selected);
    (assemble(mesh, positions, new_faces, &face_point), parents)
}
