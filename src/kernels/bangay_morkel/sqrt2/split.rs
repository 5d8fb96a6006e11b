//! The √2 split operator's connectivity: face sides grouped by undirected
//! edge, and the faces every edge turns into. Shared by the uniform step and
//! the adaptive passes; positions are the callers' business.

use crate::mesh::PolyMesh;
use rayon::prelude::*;
use std::ops::Range;

/// Marks a face that keeps its shape in this step (adaptive passes).
pub(super) const KEPT: u32 = u32::MAX;

/// Face sides bucketed by their smaller end vertex, each bucket sorted by
/// (larger end, corner), so consecutive entries with the same larger end are
/// the sides of one undirected edge, in face order. A counting sort over
/// vertices: linear in the corner count, deterministic, and it enumerates
/// edges in the same `(lo, hi)` order as [`crate::mesh::Topology`].
///
/// Sides whose two ends are the same vertex (a face repeating a vertex
/// consecutively) are left out: they span no edge.
pub(super) struct SideBuckets {
    /// Per corner: the vertex of the next corner of its face (the side's head).
    pub head: Vec<u32>,
    /// Per corner: the face it belongs to.
    pub face: Vec<u32>,
    /// CSR offsets over vertices into `corners`.
    pub start: Vec<u32>,
    /// Corners (= sides, by their tail corner), grouped as described above.
    pub corners: Vec<u32>,
}

impl SideBuckets {
    pub fn build(mesh: &PolyMesh) -> Self {
        let nv = mesh.vertex_count();
        let nc = mesh.corner_count();
        let cv = &mesh.corner_vertex;
        let mut head = vec![0u32; nc];
        let mut face = vec![0u32; nc];
        // Per-corner face ids and side heads, over chunks of whole faces
        // (disjoint corner ranges) in parallel.
        let nf = mesh.face_count();
        let face_chunk = (nf / 64).max(4096);
        let mut jobs: Vec<(Range<usize>, &mut [u32], &mut [u32])> = Vec::new();
        let (mut head_rest, mut face_rest) = (head.as_mut_slice(), face.as_mut_slice());
        for f0 in (0..nf).step_by(face_chunk) {
            let fr = f0..(f0 + face_chunk).min(nf);
            let len = (mesh.face_start[fr.end] - mesh.face_start[fr.start]) as usize;
            let (h, h_tail) = head_rest.split_at_mut(len);
            let (fc, f_tail) = face_rest.split_at_mut(len);
            jobs.push((fr, h, fc));
            (head_rest, face_rest) = (h_tail, f_tail);
        }
        jobs.into_par_iter().for_each(|(fr, head, face)| {
            let base = mesh.face_start[fr.start] as usize;
            for f in fr {
                let r = mesh.face_corners(f);
                let local = r.start - base..r.end - base;
                face[local.clone()].fill(f as u32);
                // Each side runs to the next corner; the last one wraps to the first.
                if let Some(last) = local.end.checked_sub(1).filter(|&l| l >= local.start) {
                    head[local.start..last].copy_from_slice(&cv[r.start + 1..r.end]);
                    head[last] = cv[r.start];
                }
            }
        });

        // Counting sort by smaller end: counts, inclusive prefix sums (bucket
        // ends), then corners placed back to front so each bucket ends up in
        // ascending corner order and `start` ends up holding bucket starts.
        let mut start = vec![0u32; nv + 1];
        for c in 0..nc {
            let (a, b) = (cv[c], head[c]);
            if a != b {
                start[a.min(b) as usize] += 1;
            }
        }
        for v in 0..nv {
            start[v + 1] += start[v];
        }
        let mut corners = vec![0u32; start[nv] as usize];
        for c in (0..nc).rev() {
            let (a, b) = (cv[c], head[c]);
            if a != b {
                let lo = a.min(b) as usize;
                start[lo] -= 1;
                corners[start[lo] as usize] = c as u32;
            }
        }

        // Buckets were filled in corner order; order each by its larger end.
        // Chunks of whole buckets are disjoint slices, sorted in parallel.
        let mut jobs: Vec<(Range<usize>, &mut [u32])> = Vec::new();
        let mut rest = corners.as_mut_slice();
        for vr in vertex_chunks(nv) {
            let len = (start[vr.end] - start[vr.start]) as usize;
            let (here, tail) = rest.split_at_mut(len);
            jobs.push((vr, here));
            rest = tail;
        }
        jobs.into_par_iter().for_each(|(vr, slice)| {
            let base = start[vr.start] as usize;
            for v in vr {
                let r = start[v] as usize - base..start[v + 1] as usize - base;
                // (larger end, corner) is unique, so an unstable sort is deterministic.
                slice[r].sort_unstable_by_key(|&c| (cv[c as usize].max(head[c as usize]), c));
            }
        });

        Self {
            head,
            face,
            start,
            corners,
        }
    }

    /// Calls `visit(lo, hi, sides)` for every undirected edge whose smaller
    /// end lies in `vertices`, in `(lo, hi)` order; `sides` are the tail
    /// corners of the edge's sides, in face order.
    pub fn for_each_edge(
        &self,
        cv: &[u32],
        vertices: Range<usize>,
        mut visit: impl FnMut(u32, u32, &[u32]),
    ) {
        for lo in vertices {
            let bucket = &self.corners[self.start[lo] as usize..self.start[lo + 1] as usize];
            let mut i = 0;
            while i < bucket.len() {
                let c = bucket[i] as usize;
                let hi = cv[c].max(self.head[c]);
                let mut j = i + 1;
                while j < bucket.len() {
                    let d = bucket[j] as usize;
                    if cv[d].max(self.head[d]) != hi {
                        break;
                    }
                    j += 1;
                }
                visit(lo as u32, hi, &bucket[i..j]);
                i = j;
            }
        }
    }

    /// True when the sides form an ordinary interior edge: exactly two
    /// sides, from two different faces.
    #[inline]
    pub fn is_interior_pair(&self, sides: &[u32]) -> bool {
        sides.len() == 2 && self.face[sides[0] as usize] != self.face[sides[1] as usize]
    }
}

/// Vertex ranges for parallel work: whole buckets per chunk, and enough
/// chunks to balance two to a few dozen threads. The chunking never changes
/// results, only how the work is split.
pub(super) fn vertex_chunks(nv: usize) -> Vec<Range<usize>> {
    let size = (nv / 64).max(4096);
    (0..nv.div_ceil(size).max(1))
        .map(|k| (k * size).min(nv)..((k + 1) * size).min(nv))
        .collect()
}

/// New faces of one split, in CSR form (`face_start` starts with 0).
pub(super) struct NewFaces {
    pub face_start: Vec<u32>,
    pub corners: Vec<u32>,
}

/// The faces the √2 split creates, given `face_point[f]`, the new vertex id of
/// face `f`'s point, or [`KEPT`] when `f` is not refined. Per edge:
///
/// * two sides from two refined faces: the quad `[a, F1, b, F0]`, where
///   `a → b` is the side in the first face (F0) of the pair;
/// * otherwise, one triangle `[a, b, F]` per side `a → b` of a refined face
///   F. This covers boundary edges (one side), the transition to a kept face
///   (the kept face still owns `a–b`, so the triangle is its neighbour),
///   non-manifold edges (three or more sides: a fan of triangles that keeps
///   the edge and its face count) and an edge met twice by the same face;
/// * sides of kept faces produce nothing: the caller copies kept faces.
///
/// Both cases list corners so that, on an oriented mesh, every new face is
/// oriented like the faces it came from: the quad's side `F0 → a` is the
/// reverse of `a → F0` in the face made from the side entering `a` in F0.
///
/// Two parallel passes over vertex chunks: one counts each chunk's faces and
/// corners, the other writes them straight into their final place.
///
/// # Panics
/// When the corner count exceeds the `u32` index range.
pub(super) fn connect(mesh: &PolyMesh, sides: &SideBuckets, face_point: &[u32]) -> NewFaces {
    let cv = &mesh.corner_vertex;
    let chunks = vertex_chunks(mesh.vertex_count());
    let counts: Vec<(usize, usize)> = chunks
        .par_iter()
        .map(|vr| {
            let (mut faces, mut corners) = (0, 0);
            new_faces_of(sides, cv, face_point, vr.clone(), |face| {
                faces += 1;
                corners += face.len();
            });
            (faces, corners)
        })
        .collect();
    let total_faces: usize = counts.iter().map(|c| c.0).sum();
    let total_corners: usize = counts.iter().map(|c| c.1).sum();
    assert!(
        total_corners <= u32::MAX as usize,
        "√2 subdivision: {total_corners} corners exceed the u32 index range"
    );
    let mut face_start = vec![0u32; total_faces + 1];
    let mut corners = vec![0u32; total_corners];
    let mut jobs = Vec::with_capacity(chunks.len());
    let (mut fs_rest, mut c_rest) = (&mut face_start[1..], corners.as_mut_slice());
    let mut base = 0;
    for (vr, &(nf, nc)) in chunks.into_iter().zip(&counts) {
        let (fs, fs_tail) = fs_rest.split_at_mut(nf);
        let (cs, c_tail) = c_rest.split_at_mut(nc);
        jobs.push((vr, fs, cs, base));
        (fs_rest, c_rest) = (fs_tail, c_tail);
        base += nc;
    }
    jobs.into_par_iter().for_each(|(vr, fs, cs, base)| {
        let (mut k, mut at) = (0, 0);
        new_faces_of(sides, cv, face_point, vr, |face| {
            cs[at..at + face.len()].copy_from_slice(face);
            at += face.len();
            fs[k] = (base + at) as u32;
            k += 1;
        });
    });
    NewFaces {
        face_start,
        corners,
    }
}

/// Calls `emit` with every new face of the edges whose smaller end lies in
/// `vertices` (the rule is documented on [`connect`]).
#[inline]
fn new_faces_of(
    sides: &SideBuckets,
    cv: &[u32],
    face_point: &[u32],
    vertices: Range<usize>,
    mut emit: impl FnMut(&[u32]),
) {
    sides.for_each_edge(cv, vertices, |_, _, group| {
        if sides.is_interior_pair(group) {
            let (c0, c1) = (group[0] as usize, group[1] as usize);
            let p0 = face_point[sides.face[c0] as usize];
            let p1 = face_point[sides.face[c1] as usize];
            if p0 != KEPT && p1 != KEPT {
                emit(&[cv[c0], p1, sides.head[c0], p0]);
                return;
            }
        }
        for &c in group {
            let c = c as usize;
            let p = face_point[sides.face[c] as usize];
            if p != KEPT {
                emit(&[cv[c], sides.head[c], p]);
            }
        }
    });
}

/// Assembles a mesh from positions, the new faces and then the kept faces of
/// `mesh` (those with `face_point[f] == KEPT`) in their original order.
///
/// # Panics
/// When the corner count exceeds the `u32` index range.
pub(super) fn assemble(
    mesh: &PolyMesh,
    positions: Vec<glam::Vec3>,
    new_faces: NewFaces,
    face_point: &[u32],
) -> PolyMesh {
    let NewFaces {
        mut face_start,
        corners: mut corner_vertex,
    } = new_faces;
    let kept: Vec<usize> = (0..mesh.face_count())
        .filter(|&f| face_point[f] == KEPT)
        .collect();
    let kept_corners: usize = kept.iter().map(|&f| mesh.face_corners(f).len()).sum();
    let total = corner_vertex.len() + kept_corners;
    assert!(
        total <= u32::MAX as usize,
        "√2 subdivision: {total} corners exceed the u32 index range"
    );
    face_start.reserve(kept.len());
    corner_vertex.reserve(kept_corners);
    for f in kept {
        corner_vertex.extend_from_slice(mesh.face(f));
        face_start.push(corner_vertex.len() as u32);
    }
    PolyMesh {
        positions,
        face_start,
        corner_vertex,
    }
}
