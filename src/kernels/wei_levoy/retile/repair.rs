//! Repairs the few triangles that face away from the input surface where
//! their centroid projects, after a level has been remeshed and snapped.
//!
//! The remesher keeps each triangle facing the way the input does at its
//! corners (and, across creases, at its centroid) whenever it changes one,
//! but a vertex exactly on a ridge of the input sees only one side of it, and
//! the final snap onto the surface is not checked. A handful of triangles per
//! level on a coarse, faceted input can end up edge-on to one side of a
//! ridge. Each is repaired by the first of these edits that leaves every
//! triangle it touches facing the input at its centroid: flipping one of its
//! edges; collapsing one of its edges (the kept vertex projected onto the
//! surface); splitting one of its edges (the new vertex projected onto the
//! surface). Collapses and splits change the vertex count by one each; they
//! are capped at [`MAX_COUNT_CHANGE`] of the level's target.

use super::project::SurfacePoint;
use super::project::SurfaceProjector;
use super::remesh::{Scratch, collapse_ok, collapse_plan, flip_allowed};
use super::trimesh::{NONE, TriMesh, next, prev};
use glam::Vec3;
use rayon::prelude::*;

/// Rounds of detection and repair.
const ROUNDS: usize = 4;

/// Most collapses plus splits per level, as a fraction of its target count.
pub(crate) const MAX_COUNT_CHANGE: f64 = 0.02;

/// Whether the triangle `(a, b, c)` faces the way the input does at the
/// projection of its centroid (searched near input face `hint`).
fn faces_input(proj: &SurfaceProjector, [a, b, c]: [Vec3; 3], hint: u32) -> bool {
    let n = (b - a).cross(c - a);
    proj.project_near((a + b + c) / 3.0, hint)
        .is_none_or(|sp| n.dot(proj.face_normal(sp.face)) > 0.0)
}

fn face_corners(mesh: &TriMesh, f: u32) -> [Vec3; 3] {
    [0, 1, 2].map(|i| mesh.pos[mesh.vert[(3 * f + i) as usize] as usize])
}

/// Repairs triangles of `mesh` facing away from `proj` at their centroid;
/// returns how many are left. Edges shorter than `min_split` are not split,
/// and no new edge may be longer than `max_len`.
pub(crate) fn repair_flipped_faces(
    mesh: &mut TriMesh,
    proj: &SurfaceProjector,
    min_split: f32,
    max_len: f32,
    max_count_change: usize,
) -> usize {
    let mut left = 0;
    let mut budget = max_count_change;
    let mut scratch = Scratch::default();
    for _ in 0..ROUNDS {
        let bad: Vec<u32> = {
            let m = &*mesh;
            (0..m.halfedge_slots() as u32 / 3)
                .into_par_iter()
                .filter(|&f| {
                    let h = 3 * f;
                    m.alive_halfedge(h)
                        && !faces_input(
                            proj,
                            face_corners(m, f),
                            m.src_face[m.vert[h as usize] as usize],
                        )
                })
                .collect()
        };
        left = bad.len();
        if bad.is_empty() {
            break;
        }
        for f in bad {
            let h = 3 * f;
            if !mesh.alive_halfedge(h)
                || faces_input(
                    proj,
                    face_corners(mesh, f),
                    mesh.src_face[mesh.vert[h as usize] as usize],
                )
            {
                continue;
            }
            if try_flips(mesh, proj, h) {
                continue;
            }
            if budget > 0
                && (try_collapses(mesh, proj, h, max_len, &mut scratch)
                    || try_splits(mesh, proj, h, min_split))
            {
                budget -= 1;
            }
        }
    }
    left
}

/// The three half-edges of the face of `h`, shortest first.
fn sides_by_length(mesh: &TriMesh, h: u32) -> [u32; 3] {
    let mut sides = [h, next(h), prev(h)];
    sides.sort_by(|&x, &y| mesh.edge_length(x).total_cmp(&mesh.edge_length(y)));
    sides
}

/// Flips the first edge of the face of `h` whose flip is allowed and leaves
/// both new triangles facing the input.
fn try_flips(mesh: &mut TriMesh, proj: &SurfaceProjector, h: u32) -> bool {
    for g in [h, next(h), prev(h)] {
        let t = mesh.twin[g as usize];
        if t == NONE || !flip_allowed(mesh, proj, g) {
            continue;
        }
        let p = |v: u32| mesh.pos[v as usize];
        let a = mesh.vert[g as usize];
        let b = mesh.to(g);
        let c = mesh.vert[prev(g) as usize];
        let d = mesh.vert[prev(t) as usize];
        let hint = mesh.src_face[a as usize];
        if faces_input(proj, [p(d), p(c), p(a)], hint)
            && faces_input(proj, [p(c), p(d), p(b)], hint)
        {
            mesh.flip(g);
            return true;
        }
    }
    false
}

/// Where a vertex at `p` on boundary loop `loop_id` (or inside, facing
/// `normal`) lands on the surface.
fn land(
    proj: &SurfaceProjector,
    p: Vec3,
    loop_id: u32,
    normal: Vec3,
    hint: u32,
) -> Option<SurfacePoint> {
    if loop_id != NONE {
        proj.project_to_boundary(p, loop_id)
    } else {
        proj.project_facing(p, normal, hint)
    }
}

fn place(mesh: &mut TriMesh, proj: &SurfaceProjector, v: u32, sp: SurfacePoint) {
    let i = v as usize;
    mesh.pos[i] = sp.point;
    mesh.src_face[i] = sp.face;
    mesh.src_bary[i] = sp.bary;
    mesh.ref_normal[i] = proj.face_normal(sp.face);
}

/// Collapses the shortest edge of the face of `h` whose collapse (with the
/// kept vertex projected onto the surface) is allowed and leaves every
/// triangle around it facing the input.
fn try_collapses(
    mesh: &mut TriMesh,
    proj: &SurfaceProjector,
    h: u32,
    max_len: f32,
    scratch: &mut Scratch,
) -> bool {
    let normal = mesh.face_normal_scaled(h).normalize_or_zero();
    for side in sides_by_length(mesh, h) {
        let Some((g, p)) = collapse_plan(mesh, side) else {
            continue;
        };
        let (a, b) = (mesh.vert[g as usize], mesh.to(g));
        let loop_id = if mesh.on_boundary[b as usize] && mesh.twin[g as usize] == NONE {
            mesh.loop_id[b as usize]
        } else {
            NONE
        };
        let sp = if p == mesh.pos[b as usize] {
            None
        } else {
            land(proj, p, loop_id, normal, mesh.src_face[b as usize])
        };
        let q = sp.map_or(p, |sp| sp.point);
        if !collapse_ok(mesh, proj, g, q, max_len, scratch) {
            continue;
        }
        let t = mesh.twin[g as usize];
        let skip = [g / 3, if t == NONE { NONE } else { t / 3 }];
        let ok = [a, b].iter().all(|&v| {
            mesh.fan(v).all(|k| {
                if k / 3 == skip[0] || k / 3 == skip[1] {
                    return true;
                }
                let x = mesh.to(k);
                let y = mesh.vert[prev(k) as usize];
                faces_input(
                    proj,
                    [q, mesh.pos[x as usize], mesh.pos[y as usize]],
                    mesh.src_face[x as usize],
                )
            })
        });
        if ok {
            mesh.collapse(g, q);
            if let Some(sp) = sp {
                place(mesh, proj, b, sp);
            }
            return true;
        }
    }
    false
}

/// Splits the longest edge (longer than `min_split`) of the face of `h` whose
/// split, with the new vertex projected onto the surface, leaves the new
/// triangles facing the input.
fn try_splits(mesh: &mut TriMesh, proj: &SurfaceProjector, h: u32, min_split: f32) -> bool {
    let normal = mesh.face_normal_scaled(h).normalize_or_zero();
    for g in sides_by_length(mesh, h).into_iter().rev() {
        if mesh.edge_length(g) <= min_split {
            break;
        }
        let t = mesh.twin[g as usize];
        let a = mesh.vert[g as usize];
        let b = mesh.to(g);
        let p = |v: u32| mesh.pos[v as usize];
        let loop_id = if t == NONE {
            mesh.loop_id[a as usize]
        } else {
            NONE
        };
        let Some(sp) = land(
            proj,
            0.5 * (p(a) + p(b)),
            loop_id,
            normal,
            mesh.src_face[a as usize],
        ) else {
            continue;
        };
        let m = sp.point;
        let c = mesh.vert[prev(g) as usize];
        let hint = mesh.src_face[a as usize];
        let mut ok =
            faces_input(proj, [p(a), m, p(c)], hint) && faces_input(proj, [m, p(b), p(c)], hint);
        if t != NONE {
            let d = mesh.vert[prev(t) as usize];
            ok = ok
                && faces_input(proj, [p(b), m, p(d)], hint)
                && faces_input(proj, [m, p(a), p(d)], hint);
        }
        if ok {
            let v = mesh.split(g);
            place(mesh, proj, v, sp);
            return true;
        }
    }
    false
}
