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
//! 4. cut into triangles every non-convex face (in its best-fit plane, by
//!    ear clipping) and every face of more than [`MAX_FACE_CORNERS`] corners
//!    ([`triangulate_faces`]), so that every face left is convex and the
//!    fan each kernel cuts it into ([`PolyMesh::triangulate_corners`])
//!    covers it once; a face that cannot be cut (it crosses itself) is a
//!    [`BadFace`];
//! 5. drop vertices no face uses, remapping face indices
//!    ([`drop_unused_vertices`]).
//!
//! Non-manifold edges, boundaries and several components are legal and kept.
//! The functions work on any [`PolyMesh`] whose indices are in range, even one
//! with faces of fewer than three corners (which only step 2 removes).

use super::PolyMesh;
use super::io::LoadOptions;
use glam::{DVec2, DVec3, Vec3};
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

/// Largest corner count of a non-convex face the loader cuts into
/// triangles. Ear clipping costs about corners × reflex corners point
/// tests: 10⁸ here, well under a second; a 10⁶-corner non-convex face
/// would take hours. Convex faces of any size are cut in linear time.
pub const MAX_NON_CONVEX_CORNERS: usize = 16_384;

/// A face the loader cannot keep, with its index among the input's faces.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BadFace {
    /// 0-based, among the faces as read (before any repair).
    pub face: usize,
    /// Its corner count.
    pub corners: usize,
    /// What is wrong with it.
    pub problem: FaceProblem,
}

/// Why a face cannot be cut into triangles.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FaceProblem {
    /// Ear clipping finds no corner to cut off: the polygon crosses or
    /// folds onto itself in its plane.
    CrossesItself,
    /// A non-convex face of more than [`MAX_NON_CONVEX_CORNERS`] corners.
    TooManyCorners,
}

impl BadFace {
    /// What is wrong and what is allowed, for an error naming the face's
    /// place in the file.
    pub fn message(&self) -> String {
        let n = self.corners;
        match self.problem {
            FaceProblem::CrossesItself => format!(
                "a face of {n} corners cannot be cut into triangles: in its plane it crosses or folds onto itself \
                 (no corner can be cut off without overlapping the rest); allowed: simple polygons, whose sides \
                 meet only at their shared corners (split the face in two, or triangulate it in the modeller)"
            ),
            FaceProblem::TooManyCorners => format!(
                "a non-convex face of {n} corners cannot be cut into triangles here; allowed: non-convex faces \
                 of at most {MAX_NON_CONVEX_CORNERS} corners (convex ones of any size): split it, or triangulate \
                 it in the modeller"
            ),
        }
    }
}

/// What the loader changed in a mesh. All counts are zero for a clean mesh.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
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
    /// Convex faces of more than [`MAX_FACE_CORNERS`] corners split into
    /// triangles.
    pub triangulated_faces: usize,
    /// Non-convex faces cut into triangles (ear clipping in their plane).
    pub triangulated_non_convex_faces: usize,
    /// When every face was dropped for zero area because one vertex lies
    /// far from all the others (its distance makes the bounding box, and
    /// with it the zero-area threshold, huge): that vertex.
    pub far_vertex: Option<FarVertex>,
}

/// A vertex far from every other one of its mesh ([`far_vertex`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FarVertex {
    /// 0-based, among the vertices as read.
    pub index: usize,
    /// Its position.
    pub position: Vec3,
    /// The bounding-box diagonal with it.
    pub diagonal: f64,
    /// The bounding-box diagonal of the other vertices.
    pub others_diagonal: f64,
}

/// How many times the bounding-box diagonal a vertex must stretch to count
/// as far from the others.
const FAR_FACTOR: f64 = 1e3;

/// The vertex farthest from the per-axis median of `positions`, when the
/// bounding box with it is more than [`FAR_FACTOR`] times the one without
/// it (a stray coordinate such as 1e30 in a mesh of unit size).
pub fn far_vertex(positions: &[Vec3]) -> Option<FarVertex> {
    if positions.len() < 2 {
        return None;
    }
    let median = |axis: usize| {
        let mut v: Vec<f32> = positions.iter().map(|p| p[axis]).collect();
        let mid = v.len() / 2;
        *v.select_nth_unstable_by(mid, f32::total_cmp).1
    };
    let m = Vec3::new(median(0), median(1), median(2));
    let (index, &position) = positions.iter().enumerate().max_by(|(_, a), (_, b)| {
        let d = |p: &Vec3| (p.as_dvec3() - m.as_dvec3()).abs().max_element();
        d(a).total_cmp(&d(b))
    })?;
    let others: Vec<Vec3> = positions
        .iter()
        .enumerate()
        .filter(|&(i, _)| i != index)
        .map(|(_, &p)| p)
        .collect();
    let diagonal = bounding_box_diagonal(positions);
    let others_diagonal = bounding_box_diagonal(&others);
    (diagonal > FAR_FACTOR * others_diagonal).then_some(FarVertex {
        index,
        position,
        diagonal,
        others_diagonal,
    })
}

impl LoadReport {
    /// True when the repairs changed nothing.
    pub fn is_clean(&self) -> bool {
        self.merged_vertices == 0
            && self.dropped_degenerate_faces == 0
            && self.dropped_zero_area_faces == 0
            && self.dropped_unused_vertices == 0
            && self.triangulated_faces == 0
            && self.triangulated_non_convex_faces == 0
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
        if self.triangulated_non_convex_faces > 0 {
            parts.push(format!(
                "triangulated {}",
                plural(
                    self.triangulated_non_convex_faces,
                    "non-convex face",
                    "non-convex faces"
                )
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
///
/// # Errors
/// A [`BadFace`] (with its index among the faces of `mesh` as given) for a
/// face that cannot be cut into triangles.
pub fn repair_mesh(mesh: &mut PolyMesh, options: &LoadOptions) -> Result<LoadReport, BadFace> {
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
    // The input index of each face kept, to name a bad face's place: steps
    // 2 and 3 (`drop_degenerate_faces`, `drop_zero_area_faces`), noting it.
    let mut origin: Vec<u32> = (0..mesh.face_count() as u32).collect();
    let mut kept = Vec::with_capacity(origin.len());
    let mut scratch = Vec::new();
    report.dropped_degenerate_faces = retain_faces(mesh, |f, face| {
        let keep = !is_degenerate(face, &mut scratch);
        if keep {
            kept.push(origin[f]);
        }
        keep
    });
    std::mem::swap(&mut origin, &mut kept);
    kept.clear();
    let threshold = ZERO_AREA_FACTOR * diag * diag;
    let positions = std::mem::take(&mut mesh.positions);
    report.dropped_zero_area_faces = retain_faces(mesh, |f, face| {
        let keep = polygon_area(&positions, face) > threshold;
        if keep {
            kept.push(origin[f]);
        }
        keep
    });
    if mesh.face_count() == 0 && report.dropped_zero_area_faces > 0 && !options.merge_duplicates {
        report.far_vertex = far_vertex(&positions);
    }
    mesh.positions = positions;
    origin = kept;
    let counts =
        triangulate_faces(mesh, MAX_FACE_CORNERS).map_err(|(f, corners, problem)| BadFace {
            face: origin.get(f).map_or(f, |&o| o as usize),
            corners,
            problem,
        })?;
    report.triangulated_faces = counts.large;
    report.triangulated_non_convex_faces = counts.non_convex;
    report.dropped_unused_vertices = drop_unused_vertices(mesh);
    Ok(report)
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
    retain_faces(mesh, |_, face| !is_degenerate(face, &mut scratch))
}

/// Whether `face` has fewer than three corners or a repeated vertex.
fn is_degenerate(face: &[u32], scratch: &mut Vec<u32>) -> bool {
    if face.len() < 3 {
        return true;
    }
    if face.len() <= 16 {
        // Quadratic scan beats sorting for the usual small faces.
        face.iter()
            .enumerate()
            .any(|(i, v)| face[i + 1..].contains(v))
    } else {
        scratch.clear();
        scratch.extend_from_slice(face);
        scratch.sort_unstable();
        scratch.windows(2).any(|w| w[0] == w[1])
    }
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

/// What [`triangulate_faces`] cut.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Triangulated {
    /// Convex faces of more than the corner limit (zigzag strips).
    pub large: usize,
    /// Non-convex faces (ear clipping).
    pub non_convex: usize,
}

/// Cuts into triangles, in place of the face (face order otherwise kept),
/// every face that is not convex in its best-fit plane and every convex
/// face of more than `max_corners` corners. Convex faces up to
/// `max_corners` are kept as they are, so a mesh of convex faces is
/// unchanged, and every face left is convex: the fan each kernel cuts a
/// face into ([`PolyMesh::triangulate_corners`]) covers it exactly once.
///
/// A face is convex when, projected onto the plane of its Newell normal,
/// every corner turns the same way (within `1e-10 ×` its squared extent, so
/// float noise on nearly straight corners does not count) and the turns
/// add up to one revolution (a pentagram turns one way twice).
///
/// A large convex face becomes a zigzag strip: triangles `(l, l+1, r)` and
/// `(l, r-1, r)` alternately, walking the two ends of the corner list
/// towards each other. It is O(n), adds no vertex, keeps the polygon's
/// winding, and unlike a fan it gives no vertex a valence of n; it makes no
/// zero-area triangle on a side with collinear corners unless the opposite
/// corner lies on the same line.
///
/// A non-convex face is cut by ear clipping in that plane (O(n · reflex
/// corners)): a corner is cut off when it turns the polygon's way and no
/// other corner that does not lies in or on its triangle; the triangles
/// keep the face's winding and cover it once.
///
/// # Errors
/// `(face, corners, problem)` for the first face that cannot be cut: ear
/// clipping finds no corner to cut off (the face crosses itself), or a
/// non-convex face has more than [`MAX_NON_CONVEX_CORNERS`] corners.
pub fn triangulate_faces(
    mesh: &mut PolyMesh,
    max_corners: usize,
) -> Result<Triangulated, (usize, usize, FaceProblem)> {
    let mut counts = Triangulated::default();
    // The faces to replace, with their triangles (vertex ids).
    let mut replaced: Vec<(usize, Vec<[u32; 3]>)> = Vec::new();
    for (f, face) in mesh.faces().enumerate() {
        if face.len() == 3 {
            continue;
        }
        let plane = FacePlane::new(&mesh.positions, face);
        if plane.as_ref().is_none_or(FacePlane::is_convex) {
            // Convex (or without a plane: zero area, which the loader
            // drops before; kept as it was).
            if face.len() > max_corners {
                counts.large += 1;
                replaced.push((f, zigzag(face)));
            }
            continue;
        }
        if face.len() > MAX_NON_CONVEX_CORNERS {
            return Err((f, face.len(), FaceProblem::TooManyCorners));
        }
        let corners = plane.and_then(|p| p.ear_clip());
        let Some(corners) = corners else {
            return Err((f, face.len(), FaceProblem::CrossesItself));
        };
        counts.non_convex += 1;
        replaced.push((f, corners.iter().map(|t| t.map(|c| face[c])).collect()));
    }
    if replaced.is_empty() {
        return Ok(counts);
    }
    let mut out = PolyMesh {
        positions: std::mem::take(&mut mesh.positions),
        face_start: Vec::with_capacity(mesh.face_start.len()),
        corner_vertex: Vec::with_capacity(mesh.corner_vertex.len() * 3),
    };
    out.face_start.push(0);
    let mut next = replaced.iter().peekable();
    for (f, face) in mesh.faces().enumerate() {
        match next.peek() {
            Some((g, tris)) if *g == f => {
                for t in tris {
                    out.push_face(t);
                }
                next.next();
            }
            _ => out.push_face(face),
        }
    }
    *mesh = out;
    Ok(counts)
}

/// The zigzag strip of [`triangulate_faces`] over `face`'s vertex ids.
fn zigzag(face: &[u32]) -> Vec<[u32; 3]> {
    let mut tris = Vec::with_capacity(face.len().saturating_sub(2));
    if face.len() < 3 {
        return tris;
    }
    let (mut l, mut r) = (0, face.len() - 1);
    let mut advance_left = true;
    while r - l >= 2 {
        if advance_left {
            tris.push([face[l], face[l + 1], face[r]]);
            l += 1;
        } else {
            tris.push([face[l], face[r - 1], face[r]]);
            r -= 1;
        }
        advance_left = !advance_left;
    }
    tris
}

/// A face's corners in 2D coordinates of its best-fit plane, relative to
/// its first corner, in `f64`, counter-clockwise about its Newell normal.
struct FacePlane {
    q: Vec<DVec2>,
    /// Twice a triangle's area below which a corner counts as straight.
    tol: f64,
}

impl FacePlane {
    /// `None` when the face has no plane (a zero Newell normal).
    fn new(positions: &[Vec3], face: &[u32]) -> Option<Self> {
        let p0 = positions[*face.first()? as usize].as_dvec3();
        let rel: Vec<DVec3> = face
            .iter()
            .map(|&v| positions[v as usize].as_dvec3() - p0)
            .collect();
        let mut normal = DVec3::ZERO;
        for w in rel.windows(2) {
            normal += w[0].cross(w[1]);
        }
        let n = normal.try_normalize()?;
        // (u, v, n) right-handed: counter-clockwise about n stays so in (u, v).
        let u = n.any_orthonormal_vector();
        let v = n.cross(u);
        let q: Vec<DVec2> = rel.iter().map(|r| DVec2::new(r.dot(u), r.dot(v))).collect();
        let (lo, hi) = q
            .iter()
            .fold((q[0], q[0]), |(lo, hi), &p| (lo.min(p), hi.max(p)));
        let extent = (hi - lo).max_element();
        Some(Self {
            q,
            tol: 1e-10 * extent * extent,
        })
    }

    /// Twice the signed area of the triangle of corners `a`, `b`, `c`.
    fn area2(&self, a: usize, b: usize, c: usize) -> f64 {
        (self.q[b] - self.q[a]).perp_dot(self.q[c] - self.q[a])
    }

    /// See [`triangulate_faces`].
    fn is_convex(&self) -> bool {
        let n = self.q.len();
        let mut turning = 0.0;
        for i in 0..n {
            let (a, b, c) = (self.q[(i + n - 1) % n], self.q[i], self.q[(i + 1) % n]);
            let (d0, d1) = (b - a, c - b);
            let cross = d0.perp_dot(d1);
            if cross < -self.tol {
                return false;
            }
            turning += cross.atan2(d0.dot(d1));
        }
        turning < 3.0 * std::f64::consts::PI
    }

    /// Ear clipping; triangles as corner indices, or `None` when no corner
    /// can be cut off.
    fn ear_clip(&self) -> Option<Vec<[usize; 3]>> {
        let n = self.q.len();
        let mut ring = Ring {
            prev: (0..n).map(|i| (i + n - 1) % n).collect(),
            next: (0..n).map(|i| (i + 1) % n).collect(),
            alive: vec![true; n],
            blocking: vec![false; n],
            blockers: Vec::new(),
        };
        for i in 0..n {
            ring.update_blocking(self, i);
        }
        let mut ear: Vec<bool> = (0..n).map(|i| ring.is_ear(self, i)).collect();
        let mut tris = Vec::with_capacity(n - 2);
        let (mut remaining, mut cur, mut stall) = (n, 0, 0);
        let mut recomputed = false;
        while remaining > 3 {
            if !ear[cur] {
                cur = ring.next[cur];
                stall += 1;
                if stall <= remaining {
                    continue;
                }
                // No ear in a whole round. Once, recompute every flag; then
                // cut off a straight corner (a zero-area triangle) if any.
                stall = 0;
                if !recomputed {
                    recomputed = true;
                    for i in (0..n).filter(|&i| ring.alive[i]) {
                        ear[i] = ring.is_ear(self, i);
                    }
                    continue;
                }
                cur = (0..n).find(|&i| {
                    ring.alive[i] && self.area2(ring.prev[i], i, ring.next[i]).abs() <= self.tol
                })?;
            }
            let (a, c) = (ring.prev[cur], ring.next[cur]);
            tris.push([a, cur, c]);
            ring.next[a] = c;
            ring.prev[c] = a;
            ring.alive[cur] = false;
            remaining -= 1;
            ring.update_blocking(self, a);
            ring.update_blocking(self, c);
            ear[a] = ring.is_ear(self, a);
            ear[c] = ring.is_ear(self, c);
            cur = c;
            stall = 0;
        }
        let (a, b) = (cur, ring.next[cur]);
        let c = ring.next[b];
        if self.area2(a, b, c) < -self.tol {
            return None;
        }
        tris.push([a, b, c]);
        Some(tris)
    }
}

/// The corners left during ear clipping: a doubly linked ring.
struct Ring {
    prev: Vec<usize>,
    next: Vec<usize>,
    alive: Vec<bool>,
    /// Corners that do not turn the polygon's way: the only ones that can
    /// lie in an ear's triangle.
    blocking: Vec<bool>,
    /// Every corner that was ever blocking (the flag tells which still are).
    blockers: Vec<usize>,
}

impl Ring {
    fn update_blocking(&mut self, plane: &FacePlane, i: usize) {
        let blocking = plane.area2(self.prev[i], i, self.next[i]) <= plane.tol;
        if blocking && !self.blocking[i] {
            self.blockers.push(i);
        }
        self.blocking[i] = blocking;
    }

    /// Whether corner `i` turns the polygon's way and no blocking corner
    /// lies in or on its triangle (a corner at the same position as one of
    /// the triangle's, as where a polygon meets itself, does not block).
    fn is_ear(&self, plane: &FacePlane, i: usize) -> bool {
        let (a, c) = (self.prev[i], self.next[i]);
        if plane.area2(a, i, c) <= plane.tol {
            return false;
        }
        let corners = [plane.q[a], plane.q[i], plane.q[c]];
        !self.blockers.iter().any(|&j| {
            self.alive[j]
                && self.blocking[j]
                && j != a
                && j != i
                && j != c
                && !corners.contains(&plane.q[j])
                && plane.area2(a, i, j) >= 0.0
                && plane.area2(i, c, j) >= 0.0
                && plane.area2(c, a, j) >= 0.0
        })
    }
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
        let counts = triangulate_faces(&mut m, MAX_FACE_CORNERS).unwrap();
        assert_eq!((counts.large, counts.non_convex), (1, 0));
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

    /// A star-shaped simple polygon of `n` corners at random angles and radii
    /// (seeded), tilted and moved off the origin, reversed when `reverse`.
    fn random_polygon(seed: u64, n: usize, reverse: bool) -> Vec<Vec3> {
        let mut state = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut angles: Vec<f64> = (0..n).map(|_| next() * std::f64::consts::TAU).collect();
        angles.sort_by(f64::total_cmp);
        let rotation = glam::DQuat::from_euler(glam::EulerRot::XYZ, next(), next(), next());
        let mut points: Vec<Vec3> = angles
            .iter()
            .map(|&a| {
                let r = 0.2 + 0.8 * next();
                let p = rotation * DVec3::new(r * a.cos(), r * a.sin(), 0.0);
                (p + DVec3::new(3.0, -2.0, 7.0)).as_vec3()
            })
            .collect();
        if reverse {
            points.reverse();
        }
        points
    }

    #[test]
    fn ear_clipping_covers_random_simple_polygons_once() {
        let mut cut = 0;
        for seed in 0..300u64 {
            let n = 4 + (seed as usize * 7) % 60;
            let points = random_polygon(seed, n, seed % 3 == 0);
            let ring: Vec<u32> = (0..n as u32).collect();
            let normal = area_vector_f64(&points, &ring);
            let area = 0.5 * normal.length();
            let mut m = PolyMesh::from_polygons(points, [&ring[..]]);
            let counts = triangulate_faces(&mut m, MAX_FACE_CORNERS).expect("a simple polygon");
            cut += counts.non_convex;
            let tris = m.triangulated();
            assert_eq!(tris.face_count(), n - 2, "seed {seed}");
            let mut sum = 0.0;
            for f in tris.faces() {
                let t = area_vector_f64(&tris.positions, f);
                assert!(
                    t.dot(normal) >= -1e-9 * area * normal.length(),
                    "seed {seed}: a triangle faces against the polygon"
                );
                sum += 0.5 * t.length();
            }
            assert!(
                (sum - area).abs() <= 1e-5 * area,
                "seed {seed}: {sum} vs {area}"
            );
        }
        assert!(cut > 250, "most random polygons are non-convex: {cut}");
    }

    fn area_vector_f64(positions: &[Vec3], face: &[u32]) -> DVec3 {
        let p0 = positions[face[0] as usize].as_dvec3();
        face.windows(2).fold(DVec3::ZERO, |n, w| {
            n + (positions[w[0] as usize].as_dvec3() - p0)
                .cross(positions[w[1] as usize].as_dvec3() - p0)
        })
    }

    #[test]
    fn a_face_crossing_itself_or_too_large_is_reported() {
        // A bow tie with lobes of different size.
        let p = vec![
            Vec3::ZERO,
            Vec3::new(2.0, 2.0, 0.0),
            Vec3::new(2.0, 0.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
        ];
        let mut m = PolyMesh::from_polygons(p.clone(), [&[0u32, 1, 2][..], &[0, 1, 2, 3][..]]);
        assert_eq!(
            triangulate_faces(&mut m, MAX_FACE_CORNERS),
            Err((1, 4, FaceProblem::CrossesItself))
        );
        // Named by its index among the faces as read, before the repairs
        // dropped the degenerate one in front of it.
        let mut m =
            PolyMesh::from_polygons(p, [&[0u32, 0, 1][..], &[0, 1, 2][..], &[0, 1, 2, 3][..]]);
        assert_eq!(
            repair_mesh(&mut m, &LoadOptions::default()),
            Err(BadFace {
                face: 2,
                corners: 4,
                problem: FaceProblem::CrossesItself
            })
        );
        // A non-convex star of more corners than ear clipping takes.
        let n = MAX_NON_CONVEX_CORNERS + 2;
        let star: Vec<Vec3> = (0..n)
            .map(|i| {
                let a = i as f32 / n as f32 * std::f32::consts::TAU;
                let r = if i % 2 == 0 { 1.0 } else { 0.5 };
                Vec3::new(r * a.cos(), r * a.sin(), 0.0)
            })
            .collect();
        let ring: Vec<u32> = (0..n as u32).collect();
        let mut m = PolyMesh::from_polygons(star, [&ring[..]]);
        assert_eq!(
            triangulate_faces(&mut m, MAX_FACE_CORNERS),
            Err((0, n, FaceProblem::TooManyCorners))
        );
    }

    #[test]
    fn the_largest_non_convex_face_is_cut_in_time() {
        let n = MAX_NON_CONVEX_CORNERS;
        let star: Vec<Vec3> = (0..n)
            .map(|i| {
                let a = i as f64 / n as f64 * std::f64::consts::TAU;
                let r = if i % 2 == 0 { 1.0 } else { 0.9 };
                Vec3::new((r * a.cos()) as f32, (r * a.sin()) as f32, 0.0)
            })
            .collect();
        let ring: Vec<u32> = (0..n as u32).collect();
        let mut m = PolyMesh::from_polygons(star, [&ring[..]]);
        let started = std::time::Instant::now();
        let counts = triangulate_faces(&mut m, MAX_FACE_CORNERS).unwrap();
        assert_eq!((counts.non_convex, m.face_count()), (1, n - 2));
        assert!(
            started.elapsed() < std::time::Duration::from_secs(20),
            "{:?}",
            started.elapsed()
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
        let r = repair_mesh(&mut m, &LoadOptions::default()).unwrap();
        assert!(r.is_clean());
        assert_eq!(r.summary(), "read 3 vertices, 1 face; no repairs needed");
    }

    #[test]
    fn merge_is_opt_in_and_respects_tolerance() {
        let mut m = quad_pair();
        let r = repair_mesh(&mut m, &LoadOptions::default()).unwrap();
        assert_eq!((r.merged_vertices, m.vertex_count()), (0, 8));

        let mut m = quad_pair();
        let exact = LoadOptions {
            merge_duplicates: true,
            merge_tolerance: 0.0,
        };
        let r = repair_mesh(&mut m, &exact).unwrap();
        assert_eq!(r.merged_vertices, 1);
        assert_eq!(m.face(1), &[1, 4, 5, 6]);

        let mut m = quad_pair();
        let loose = LoadOptions {
            merge_duplicates: true,
            merge_tolerance: 1e-4,
        };
        let r = repair_mesh(&mut m, &loose).unwrap();
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
        let r = repair_mesh(&mut m, &opts).unwrap();
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
        let r = repair_mesh(&mut m, &LoadOptions::default()).unwrap();
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
