//! A √2 mesh hierarchy: repeated uniform steps (Bangay & Morkel 2006 §3.2.1).

use super::{Subdivided, sqrt2_subdivide};
use crate::mesh::PolyMesh;

/// Hard cap on the steps [`subdivide_to`] takes. The vertex count roughly
/// doubles per step, so 16 steps multiply it by about 65 000: past any useful
/// hierarchy (Bangay & Morkel use a handful of levels).
pub const MAX_HIERARCHY_LEVELS: u32 = 16;

/// [`subdivide_to`] takes no step whose result would have more vertices than
/// this (2²⁶ ≈ 67 million, a few GB of mesh), so a huge `target_vertices`
/// ends in bounded time and memory instead of running out of memory.
pub const MAX_HIERARCHY_VERTICES: usize = 1 << 26;

/// Subdivides `mesh` repeatedly with [`sqrt2_subdivide`]; element `i` of the
/// result is level `i + 1`, its parents referring to level `i` (level 0 is
/// `mesh` itself), so attributes travel down the hierarchy one level at a time.
///
/// Stopping rules, whichever comes first:
/// * `levels: Some(n)`: after `n` steps;
/// * `target_vertices: Some(t)`: at the first level with at least `t`
///   vertices (no step at all when `mesh` already has `t`);
/// * after [`MAX_HIERARCHY_LEVELS`] steps;
/// * before a step whose result would exceed [`MAX_HIERARCHY_VERTICES`];
/// * when a step would add nothing (a mesh without faces).
///
/// With both `levels` and `target_vertices` `None` there is no stopping rule
/// asked for, and the result is empty.
pub fn subdivide_to(
    mesh: &PolyMesh,
    levels: Option<u32>,
    target_vertices: Option<usize>,
) -> Vec<Subdivided> {
    let mut out: Vec<Subdivided> = Vec::new();
    if levels.is_none() && target_vertices.is_none() {
        return out;
    }
    let max_steps = levels
        .unwrap_or(MAX_HIERARCHY_LEVELS)
        .min(MAX_HIERARCHY_LEVELS);
    for _ in 0..max_steps {
        let current = out.last().map_or(mesh, |s| &s.mesh);
        let (nv, nf) = (current.vertex_count(), current.face_count());
        if target_vertices.is_some_and(|t| nv >= t) || nf == 0 || nv + nf > MAX_HIERARCHY_VERTICES {
            break;
        }
        let next = sqrt2_subdivide(current);
        out.push(next);
    }
    out
}
