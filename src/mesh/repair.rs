//! Load-time repairs: what every loaded mesh goes through before the
//! pipeline sees it, and the [`LoadReport`] that counts what was changed.
//!
//! In order:
//! 1. (opt-in, [`LoadOptions::merge_duplicates`]) merge vertices closer than
//!    `merge_tolerance × bbox diagonal` ([`merge_vertices`]);
//! 2. drop degenerate faces: fewer than three corners or a repeated vertex
//!    ([`drop_degenerate_faces`]). A polygon with a repeated vertex is dropped
//!    whole, not collapsed, since its intended shape is unknown;
//! 3. drop zero-area faces: area `<= 1e-12 × bbox_diagonal²`
//!    ([`drop_zero_area_faces`]);
//! 4. split faces of more than [`MAX_FACE_CORNERS`] corners into triangles
//!    ([`triangulate_large_faces`]);
//! 5. drop vertices no face uses, remapping face indices
//!    ([`drop_unused_vertices`]).
//!
//! Non-manifold edges, boundaries and several components are legal and kept.
//! The functions work on any [`PolyMesh`] whose indices are in range, even one
//! with faces of fewer than three corners (which only step 2 removes).

use super::PolyMesh;
use super::io::LoadOptions;
use glam::{DVec3, Vec3};
use std::collections::HashMap;

/// Faces with area at most this times the squared bounding-box diagonal count
/// as zero-area.
pub const ZERO_AREA_FACTOR: f64 = 1e-12;

/// Largest face degree the loaders keep; larger polygons are triangulated.
///
/// 255 is the largest corner count a PLY `uchar` list holds, the layout most
/// PLY readers expect, and well beyond the polygons modelling tools make
/// (n-gon caps of cylinders and discs have tens of corners). Stages walk a
/// face's corners in loops that are quadratic in the degree here and there,
/// so a 10⁶-corner polygon would stall them; triangles never do.
pub const MAX_FACE_CORNERS: usize = 255;

/// What the loader changed in a mesh. All counts are zero for a clean mesh.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LoadReport {
    /// Vertices in the file (after STL welding, before repairs).
    pub input_vertices: usize,
    /// Faces in the file, before repairs.
    pub input_faces: usize,
    /// Vertices merged into another one (only with `merge_duplicates`).
    pub merged_vertices: usize,
    /// Faces dropped for having fewer than three corners or a repeated vertex.
    pub dropped_degenerate_faces: usize,
    /// Faces dropped for (near-)zero area.
    pub dropped_zero_area_faces: usize,
    /// Vertices dropped because no face used them.
    pub dropped_unused_vertices: usize,
    /// Faces of more than [`MAX_FACE_CORNERS`] corners split into triangles.
    pub triangulated_faces: usize,
}

impl LoadReport {
    /// True when the repairs changed nothing.
    pub fn is_clean(&self) -> bool {
        self.merged_vertices == 0
            && self.dropped_degenerate_faces == 0
            && self.dropped_zero_area_faces == 0
            && self.dropped_unused_vertices == 0
            && self.triangulated_faces == 0
    }

    /// One line for the log, e.g. `read 1839 vertices, 3674 faces; no repairs
    /// needed` or `read 10 vertices, 12 faces; merged 2 duplicate vertices,
    /// dropped 1 degenerate face`.
    pub fn summary(&self) -> String {
        let plural =
            |n: usize, one: &str, many: &str| format!("{n} {}", if n == 1 { one } else { many });
        let mut s = format!(
            "read {}, {}; ",
            plural(self.input_vertices, "vertex", "vertices"),
            plural(self.input_faces, "face", "faces")
        );
        if self.is_clean() {
            s.push_str("no repairs needed");
            return s;
        }
        let mut parts = Vec::new();
        if self.merged_vertices > 0 {
            parts.push(format!(
                "merged {}",
                plural(
                    self.merged_vertices,
                    "duplicate vertex",
                    "duplicate vertices"
                )
            ));
        }
        let mut dropped = Vec::new();
        if self.dropped_degenerate_faces > 0 {
            dropped.push(plural(
                self.dropped_degenerate_faces,
                "degenerate face",
                "degenerate faces",
            ));
        }
        if self.dropped_zero_area_faces > 0 {
            dropped.push(plural(
                self.dropped_zero_area_faces,
                "zero-area face",
                "zero-area faces",
            ));
        }
        if self.dropped_unused_vertices > 0 {
            dropped.push(plural(
                self.dropped_unused_vertices,
                "unused vertex",
                "unused vertices",
            ));
        }
        if !dropped.is_empty() {
            parts.push(format!("dropped {}", dropped.join(", ")));
        }
        if self.triangulated_faces > 0 {
            parts.push(format!(
                "triangulated {} of more than {MAX_FACE_CORNERS} corners",
                plural(self.triangulated_faces, "face", "faces")
            ));
        }
        s.push_str(&parts.join("; "));
        s
    }
}

impl std::fmt::Display for LoadReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.summary())
    }
}

/// Runs all repairs (see the module docs) and reports what changed.
///
/// Precondition: every index of `mesh` is `< positions.len()` and every
/// position is finite (the loaders check both).
pub fn repair_mesh(mesh: &mut PolyMesh, options: &LoadOptions) -> LoadReport {
    let mut report = LoadReport {
        input_vertices: mesh.vertex_count(),
        input_faces: mesh.face_count(),
        ..LoadReport::default()
    };
    let diag = bounding_box_diagonal(&mesh.positions);
    if options.merge_duplicates {
        let tol = (options.merge_tolerance as f64 * diag) as f32;
        report.merged_vertices = merge_vertices(mesh, tol);
    }
    report.dropped_degenerate_faces = drop_degenerate_faces(mesh);
    report.dropped_zero_area_faces = drop_zero_area_faces(mesh, ZERO_AREA_FACTOR * diag * diag);
    report.triangulated_faces = triangulate_large_faces(mesh, MAX_FACE_CORNERS);
    report.dropped_unused_vertices = drop_unused_vertices(mesh);
    report
}

/// Length of the bounding-box diagonal of `positions` (0 when empty).
pub fn bounding_box_diagonal(positions: &[Vec3]) -> f64 {
    let Some(&first) = positions.first() else {
        return 0.0;
    };
    let (lo, hi) = positions
        .iter()
        .fold((first, first), |(lo, hi), &p| (lo.min(p), hi.max(p)));
    (hi.as_dvec3() - lo.as_dvec3()).length()
}

/// Welds bit-identical positions (`-0.0` equals `0.0`). Returns the unique
/// positions in order of first occurrence and, per input position, its new
/// index. Deterministic; O(n log n).
pub fn weld_exact(positions: &[Vec3]) -> (Vec<Vec3>, Vec<u32>) {
    // Adding 0.0 turns -0.0 into +0.0, so both get the same bits.
    let key = |p: Vec3| (p + Vec3::ZERO).to_array().map(f32::to_bits);
    let mut order: Vec<u32> = (0..positions.len() as u32).collect();
    order.sort_unstable_by_key(|&i| (key(positions[i as usize]), i));
    // representative[i] = first index with the same position.
    let mut representative: Vec<u32> = (0..positions.len() as u32).collect();
    for run in order.chunk_by(|&a, &b| key(positions[a as usize]) == key(positions[b as usize])) {
        for &i in run {
            representative[i as usize] = run[0];
        }
    }
    let mut unique = Vec::new();
    let mut remap = vec![0u32; positions.len()];
    for i in 0..positions.len() {
        let r = representative[i] as usize;
        remap[i] = if r == i {
            unique.push(positions[i]);
            unique.len() as u32 - 1
        } else {
            remap[r]
        };
    }
    (unique, remap)
}

/// Merges vertices within distance `tolerance` (absolute, in model units;
/// `0.0` merges bit-identical positions only). Greedy in vertex order: each
/// vertex joins the earliest kept vertex within `tolerance`, else it is
/// kept. Kept vertices stay in order; faces are remapped. Returns the number of
/// vertices removed. Faces may become degenerate; run
/// [`drop_degenerate_faces`] afterwards.
pub fn merge_vertices(mesh: &mut PolyMesh, tolerance: f32) -> usize {
    let n = mesh.vertex_count();
    let (positions, remap) = if tolerance > 0.0 && tolerance.is_finite() {
        merge_within(&mesh.positions, tolerance)
    } else {
        weld_exact(&mesh.positions)
    };
    let merged = n - positions.len();
    if merged > 0 {
        mesh.positions = positions;
        for v in &mut mesh.corner_vertex {
            *v = remap[*v as usize];
        }
    }
    merged
}

/// Greedy tolerance merge on a uniform grid with cell size `tol`.
fn merge_within(positions: &[Vec3], tol: f32) -> (Vec<Vec3>, Vec<u32>) {
    let inv = 1.0 / tol as f64;
    // `as i64` saturates, so huge coordinates cannot overflow.
    let cell = |p: Vec3| (p.as_dvec3() * inv).floor().to_array().map(|c| c as i64);
    // Each cell heads a chain (through `next`) of kept vertices (new ids).
    let mut head: HashMap<[i64; 3], u32> = HashMap::new();
    let mut next: Vec<u32> = Vec::new();
    let mut kept: Vec<Vec3> = Vec::new();
    let mut remap = Vec::with_capacity(positions.len());
    let tol2 = tol * tol;
    for &p in positions {
        let c = cell(p);
        // The earliest kept vertex within reach, whatever cell it is in.
        let mut found: Option<u32> = None;
        for dx in -1..=1i64 {
            for dy in -1..=1i64 {
                for dz in -1..=1i64 {
                    let key = [
                        c[0].saturating_add(dx),
                        c[1].saturating_add(dy),
                        c[2].saturating_add(dz),
                    ];
                    let mut k = head.get(&key).copied().unwrap_or(u32::MAX);
                    while k != u32::MAX {
                        if kept[k as usize].distance_squared(p) <= tol2
                            && found.is_none_or(|f| k < f)
                        {
                            found = Some(k);
                        }
                        k = next[k as usize];
                    }
                }
            }
        }
        let id = match found {
            Some(k) => k,
            None => {
                let id = kept.len() as u32;
                kept.push(p);
                next.push(head.insert(c, id).unwrap_or(u32::MAX));
                id
            }
        };
        remap.push(id);
    }
    (kept, remap)
}

/// Removes faces for which `keep(face_index, vertices)` is false, in place.
/// Returns the number removed.
pub fn retain_faces(mesh: &mut PolyMesh, mut keep: impl FnMut(usize, &[u32]) -> bool) -> usize {
    let nf = mesh.face_count();
    let mut write_corner = 0usize;
    let mut write_face = 0usize;
    for f in 0..nf {
        let (a, b) = (mesh.face_start[f] as usize, mesh.face_start[f + 1] as usize);
        if keep(f, &mesh.corner_vertex[a..b]) {
            mesh.corner_vertex.copy_within(a..b, write_corner);
            write_corner += b - a;
            write_face += 1;
            mesh.face_start[write_face] = write_corner as u32;
        }
    }
    mesh.corner_vertex.truncate(write_corner);
    mesh.face_start.truncate(write_face + 1);
    nf - write_face
}

/// Drops faces with fewer than three corners or a repeated vertex index.
/// Returns the number dropped.
pub fn drop_degenerate_faces(mesh: &mut PolyMesh) -> usize {
    let mut scratch: Vec<u32> = Vec::new();
    retain_faces(mesh, |_, face| {
        if face.len() < 3 {
            return false;
        }
        if face.len() <= 16 {
            // Quadratic scan beats sorting for the usual small faces.
            !face
                .iter()
                .enumerate()
                .any(|(i, v)| face[i + 1..].contains(v))
        } else {
            scratch.clear();
            scratch.extend_from_slice(face);
            scratch.sort_unstable();
            scratch.windows(2).all(|w| w[0] != w[1])
        }
    })
}

/// Area of a polygon by its fan around the first corner, in `f64` and
/// relative to that corner (so far-from-origin meshes keep their precision).
pub fn polygon_area(positions: &[Vec3], face: &[u32]) -> f64 {
    let Some(&first) = face.first() else {
        return 0.0;
    };
    let p0: DVec3 = positions[first as usize].as_dvec3();
    let mut n = DVec3::ZERO;
    for w in face[1..].windows(2) {
        let a = positions[w[0] as usize].as_dvec3() - p0;
        let b = positions[w[1] as usize].as_dvec3() - p0;
        n += a.cross(b);
    }
    0.5 * n.length()
}

/// Drops faces whose area is `<= threshold` (absolute, squared model units).
/// Returns the number dropped.
pub fn drop_zero_area_faces(mesh: &mut PolyMesh, threshold: f64) -> usize {
    let positions = std::mem::take(&mut mesh.positions);
    let dropped = retain_faces(mesh, |_, face| polygon_area(&positions, face) > threshold);
    mesh.positions = positions;
    dropped
}

/// Splits every face of more than `max_corners` corners into triangles, in
/// place of the face (face order otherwise kept); returns the number split.
///
/// The split is a zigzag strip: triangles `(l, l+1, r)` and `(l, r-1, r)`
/// alternately, walking the two ends of the corner list towards each other.
/// It is O(n) (ear clipping is O(n²): 10¹⁰ steps for a 10⁵-corner face),
/// adds no vertex, keeps the polygon's winding, and is exact for convex
/// polygons, which large polygons in practice are (caps, discs, hole fills);
/// unlike a fan it gives no vertex a valence of n, and it makes no zero-area
/// triangle on a side with collinear corners unless the opposite corner lies
/// on the same line. A strongly non-convex polygon may get overlapping
/// triangles.
pub fn triangulate_large_faces(mesh: &mut PolyMesh, max_corners: usize) -> usize {
    if mesh.faces().all(|f| f.len() <= max_corners) {
        return 0;
    }
    let mut out = PolyMesh {
        positions: std::mem::take(&mut mesh.positions),
        face_start: Vec::with_capacity(mesh.face_start.len()),
        corner_vertex: Vec::with_capacity(mesh.corner_vertex.len() * 3),
    };
    out.face_start.push(0);
    let mut split = 0;
    for face in mesh.faces() {
        if face.len() <= max_corners {
            out.push_face(face);
            continue;
        }
        split += 1;
        let (mut l, mut r) = (0, face.len() - 1);
        let mut advance_left = true;
        while r - l >= 2 {
            if advance_left {
                out.push_face(&[face[l], face[l + 1], face[r]]);
                l += 1;
            } else {
                out.push_face(&[face[l], face[r - 1], face[r]]);
                r -= 1;
            }
            advance_left = !advance_left;
        }
    }
    *mesh = out;
    split
}

/// Drops vertices that no face uses, keeping the others in order, and remaps
/// the faces. Returns the number dropped.
pub fn drop_unused_vertices(mesh: &mut PolyMesh) -> usize {
    let n = mesh.vertex_count();
    let mut new_index = vec![u32::MAX; n];
    for &v in &mesh.corner_vertex {
        new_index[v as usize] = 0;
    }
    let mut kept = 0u32;
    for (v, slot) in new_index.iter_mut().enumerate() {
        if *slot == 0 {
            *slot = kept;
            mesh.positions[kept as usize] = mesh.positions[v];
            kept += 1;
        }
    }
    mesh.positions.truncate(kept as usize);
    for v in &mut mesh.corner_vertex {
        *v = new_index[*v as usize];
    }
    n - kept as usize
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn large_polygons_become_a_strip_of_triangles() {
        let n = 1000u32;
        let positions: Vec<Vec3> = (0..n)
            .map(|i| {
                let a = i as f32 / n as f32 * std::f32::consts::TAU;
                Vec3::new(a.cos(), a.sin(), 0.0)
            })
            .collect();
        let ring: Vec<u32> = (0..n).collect();
        let mut m = PolyMesh::from_polygons(positions, [&ring[..], &[0, 1, 2][..]]);
        let area = polygon_area(&m.positions, &ring);
        assert_eq!(triangulate_large_faces(&mut m, MAX_FACE_CORNERS), 1);
        assert_eq!(m.face_count(), n as usize - 2 + 1);
        assert!(m.faces().all(|f| f.len() == 3));
        // Same area, same winding (every triangle's normal is +z).
        let tris: f64 = m
            .faces()
            .take(n as usize - 2)
            .map(|f| polygon_area(&m.positions, f))
            .sum();
        assert!((tris - area).abs() < 1e-6 * area, "{tris} vs {area}");
        for f in m.faces() {
            let [a, b, c] = [f[0], f[1], f[2]].map(|v| m.positions[v as usize]);
            assert!((b - a).cross(c - a).z > 0.0, "{f:?}");
        }
        // No vertex gets a large valence.
        let mut valence = vec![0usize; n as usize];
        for &v in &m.corner_vertex {
            valence[v as usize] += 1;
        }
        assert!(
            valence.iter().all(|&k| k <= 5),
            "{:?}",
            valence.iter().max()
        );
    }

    fn quad_pair() -> PolyMesh {
        // Two unit squares side by side whose shared edge is duplicated.
        let p = vec![
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(2.0, 0.0, 0.0),
            Vec3::new(2.0, 1.0, 0.0),
            Vec3::new(1.0 + 1e-5, 1.0, 0.0),
        ];
        PolyMesh::from_polygons(p, [&[0u32, 1, 2, 3][..], &[4, 5, 6, 7][..]])
    }

    #[test]
    fn clean_mesh_reports_nothing() {
        let mut m = PolyMesh::from_triangles(vec![Vec3::ZERO, Vec3::X, Vec3::Y], &[[0, 1, 2]]);
        let r = repair_mesh(&mut m, &LoadOptions::default());
        assert!(r.is_clean());
        assert_eq!(r.summary(), "read 3 vertices, 1 face; no repairs needed");
    }

    #[test]
    fn merge_is_opt_in_and_respects_tolerance() {
        let mut m = quad_pair();
        let r = repair_mesh(&mut m, &LoadOptions::default());
        assert_eq!((r.merged_vertices, m.vertex_count()), (0, 8));

        let mut m = quad_pair();
        let exact = LoadOptions {
            merge_duplicates: true,
            merge_tolerance: 0.0,
        };
        let r = repair_mesh(&mut m, &exact);
        assert_eq!(r.merged_vertices, 1);
        assert_eq!(m.face(1), &[1, 4, 5, 6]);

        let mut m = quad_pair();
        let loose = LoadOptions {
            merge_duplicates: true,
            merge_tolerance: 1e-4,
        };
        let r = repair_mesh(&mut m, &loose);
        assert_eq!(r.merged_vertices, 2);
        assert_eq!(m.vertex_count(), 6);
        assert_eq!(m.face(1), &[1, 4, 5, 2]);
        assert!(r.summary().contains("merged 2 duplicate vertices"), "{r}");
    }

    #[test]
    fn merging_can_create_degenerate_faces() {
        let p = vec![Vec3::ZERO, Vec3::X, Vec3::new(1e-7, 0.0, 0.0), Vec3::Y];
        let mut m = PolyMesh::from_polygons(p, [&[0u32, 1, 3][..], &[0, 2, 3][..]]);
        let opts = LoadOptions {
            merge_duplicates: true,
            merge_tolerance: 1e-3,
        };
        let r = repair_mesh(&mut m, &opts);
        assert_eq!(r.merged_vertices, 1);
        assert_eq!(r.dropped_degenerate_faces, 1);
        assert_eq!(m.face_count(), 1);
        assert_eq!(m.vertex_count(), 3);
    }

    #[test]
    fn degenerate_zero_area_and_unused() {
        let p = vec![
            Vec3::ZERO,
            Vec3::X,
            Vec3::Y,
            Vec3::new(2.0, 0.0, 0.0), // collinear with 0 and 1
            Vec3::new(9.0, 9.0, 9.0), // unused
            Vec3::new(0.0, 2.0, 0.0),
        ];
        let faces: [&[u32]; 5] = [&[0, 1, 2], &[0, 1, 3], &[0, 1, 1, 2], &[0, 1], &[1, 5, 2]];
        let mut m = PolyMesh::from_polygons(p, faces);
        let r = repair_mesh(&mut m, &LoadOptions::default());
        assert_eq!(r.dropped_degenerate_faces, 2);
        assert_eq!(r.dropped_zero_area_faces, 1);
        assert_eq!(r.dropped_unused_vertices, 2);
        assert_eq!(m.vertex_count(), 4);
        assert_eq!(m.face(0), &[0, 1, 2]);
        assert_eq!(m.face(1), &[1, 3, 2]);
        assert_eq!(m.positions[3], Vec3::new(0.0, 2.0, 0.0));
        let s = r.summary();
        assert!(
            s.contains("2 degenerate faces") && s.contains("1 zero-area face"),
            "{s}"
        );
    }

    #[test]
    fn weld_exact_treats_signed_zero_as_equal() {
        let (u, remap) =
            weld_exact(&[Vec3::new(-0.0, 1.0, 0.0), Vec3::X, Vec3::new(0.0, 1.0, 0.0)]);
        assert_eq!(u.len(), 2);
        assert_eq!(remap, vec![0, 1, 0]);
    }

    #[test]
    fn large_polygons_use_the_sorted_check() {
        let p: Vec<Vec3> = (0..20)
            .map(|i| {
                let a = i as f32 / 20.0 * std::f32::consts::TAU;
                Vec3::new(a.cos(), a.sin(), 0.0)
            })
            .collect();
        let ok: Vec<u32> = (0..20).collect();
        let mut bad = ok.clone();
        bad[17] = 3;
        let mut m = PolyMesh::from_polygons(p, [&ok[..], &bad[..]]);
        assert_eq!(drop_degenerate_faces(&mut m), 1);
        assert_eq!(m.face(0).len(), 20);
    }
}
