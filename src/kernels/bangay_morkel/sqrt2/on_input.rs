//! A √2 hierarchy that keeps the shape of its input: every level put back
//! on the input surface with the input's corners where they were
//! ([`InputSurface`]), uniform steps up to a vertex budget with the finest
//! level the one closest to it ([`levels_towards`]), and a dense input
//! remeshed coarse first so the hierarchy refines at the texture's density
//! ([`coarsened_input`]).

use super::{MAX_HIERARCHY_VERTICES, Parents, Sqrt2Settings, sqrt2_subdivide_with};
use crate::kernels::wei_levoy::retile::{
    RetileError, RetileSettings, SurfaceProjector, retile_with_progress,
};
use crate::mesh::PolyMesh;
use crate::progress::Progress;
use glam::Vec3;
use rayon::prelude::*;
use std::collections::HashSet;

/// Angle between two faces' normals above which their shared vertex is on
/// a feature of the input: 30°.
const FEATURE_COS: f32 = 0.866;

/// Most uniform steps above a coarsened input: its remesh has at least
/// `target / 2^COARSEN_STEPS` vertices.
pub const COARSEN_STEPS: u32 = 6;

/// The input surface levels are put back on, and its corners.
pub struct InputSurface {
    projector: SurfaceProjector,
    corners: HashSet<[u32; 3]>,
}

impl InputSurface {
    /// The surface of `input`.
    pub fn new(input: &PolyMesh) -> Self {
        Self {
            projector: SurfaceProjector::new(input),
            corners: corner_keys(input),
        }
    }

    /// Moves every vertex of `mesh` to the closest point of the input
    /// surface on a triangle facing the same way as the vertex normal (so a
    /// point near a thin wall is not snapped onto its far side). Parallel,
    /// deterministic.
    pub fn project(&self, mesh: &mut PolyMesh) {
        let normals = mesh.vertex_normals();
        mesh.positions
            .par_iter_mut()
            .zip(normals.par_iter())
            .for_each(|(p, &n)| {
                if let Some(hit) = self.projector.project_facing(*p, n, u32::MAX) {
                    *p = hit.point;
                }
            });
    }

    /// Puts the vertices of `after` that sat on one of the input's corners
    /// in `before` (the same ids: a √2 step keeps its old vertices' ids)
    /// back on it: the vertex rule and the projection would move a corner
    /// along the surface, rounding it off.
    pub fn keep_corners(&self, before: &PolyMesh, after: &mut PolyMesh) {
        if self.corners.is_empty() {
            return;
        }
        for (v, &p) in before.positions.iter().enumerate() {
            if self.corners.contains(&position_key(p)) {
                after.positions[v] = p;
            }
        }
    }
}

/// A position's exact bits, to find a vertex again by where it is.
fn position_key(p: Vec3) -> [u32; 3] {
    [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()]
}

/// The positions (as [`position_key`]s) of the input's corners: vertices
/// whose incident faces' normals fall into three or more directions more
/// than 30° apart (a box corner; a crease has two). Degenerate faces are
/// ignored.
fn corner_keys(mesh: &PolyMesh) -> HashSet<[u32; 3]> {
    let normals = mesh.face_normals();
    // Per vertex, up to three directions found so far.
    let mut around = vec![([Vec3::ZERO; 3], 0u8); mesh.vertex_count()];
    for (f, face) in mesh.faces().enumerate() {
        let n = normals[f];
        if !n.is_finite() || n.length_squared() < 0.5 {
            continue;
        }
        for &v in face {
            let (dirs, count) = &mut around[v as usize];
            if *count < 3
                && dirs[..*count as usize]
                    .iter()
                    .all(|c| c.dot(n) < FEATURE_COS)
            {
                dirs[*count as usize] = n;
                *count += 1;
            }
        }
    }
    around
        .iter()
        .zip(&mesh.positions)
        .filter(|((_, count), _)| *count >= 3)
        .map(|(_, &p)| position_key(p))
        .collect()
}

/// How [`levels_towards`] refines.
#[derive(Clone, Copy, Debug)]
pub struct UniformLevels {
    /// One step's vertex rule.
    pub step: Sqrt2Settings,
    /// Most steps.
    pub max_steps: u32,
    /// Vertices the finest level should have (0: no budget).
    pub target: usize,
}

/// The levels of uniform √2 steps (§3.2.1) from `coarse`, coarse to fine,
/// each with its parents in the level before (none for `coarse`), each put
/// back on `surface` when given. Steps stop after `max_steps`, at the first
/// level with `target` vertices, before a level past
/// [`MAX_HIERARCHY_VERTICES`], or at a mesh without faces; the finest level
/// is then the one closest to `target` in ratio (the step past it may
/// overshoot by up to 2×: V' = V + F). Reports to `progress` the vertices
/// each step adds, one part per step.
pub fn levels_towards(
    coarse: PolyMesh,
    settings: &UniformLevels,
    surface: Option<&InputSurface>,
    progress: &Progress,
) -> Vec<(PolyMesh, Option<Parents>)> {
    let target = settings.target;
    let mut levels: Vec<(PolyMesh, Option<Parents>)> = vec![(coarse, None)];
    for step in 0..settings.max_steps {
        let (current, _) = levels.last().expect("one level at least");
        let (nv, nf) = (current.vertex_count(), current.face_count());
        if (target > 0 && nv >= target) || nf == 0 || nv + nf > MAX_HIERARCHY_VERTICES {
            break;
        }
        progress.set_part(&format!("step {}", step + 1));
        let mut sub = sqrt2_subdivide_with(current, &settings.step);
        if let Some(surface) = surface {
            surface.project(&mut sub.mesh);
            surface.keep_corners(current, &mut sub.mesh);
        }
        progress.inc(sub.mesh.vertex_count().saturating_sub(nv) as u64);
        levels.push((sub.mesh, Some(sub.parents)));
    }
    // The finest level is the one closest to the target in ratio: the
    // step past it may overshoot by up to 2x (V' = V + F).
    if target > 0 && levels.len() >= 2 {
        let n = |i: usize| levels[i].0.vertex_count() as f64;
        let (last, prev) = (n(levels.len() - 1), n(levels.len() - 2));
        if last >= target as f64 && last / target as f64 > target as f64 / prev {
            levels.pop();
        }
    }
    levels
}

/// `input` remeshed evenly (one level of `retile`'s isotropic remesher) to
/// `target / 2^s` vertices for the largest `s ≤ COARSEN_STEPS` whose count
/// the input's connected pieces allow (at least 12 vertices), with `s`;
/// `None` when not even `target / 2` is possible. When the pieces need more
/// vertices than asked, retile names the floor, and the next try starts at
/// the first count above it rather than one step finer.
pub fn coarsened_input(
    input: &PolyMesh,
    target: usize,
    seed: u64,
    progress: &Progress,
) -> Option<(PolyMesh, u32)> {
    let mut at_least = RetileSettings::MIN_LEVEL_VERTICES as usize;
    for steps in (1..=COARSEN_STEPS).rev() {
        let n = target >> steps;
        if (n as f64) * (1.0 + RetileSettings::COUNT_TOLERANCE) < at_least as f64 {
            continue;
        }
        let settings = RetileSettings {
            levels: 1,
            seed,
            ..RetileSettings::with_vertices(n as u32)
        };
        match retile_with_progress(input, &settings, progress) {
            Ok(mut p) => {
                let level = p.levels.swap_remove(0);
                // The surface's thin parts kept it above its target: try a
                // finer base.
                if (level.mesh.vertex_count() as f64)
                    > (1.0 + RetileSettings::COUNT_TOLERANCE) * level.target_vertices as f64
                {
                    continue;
                }
                return Some((level.mesh, steps));
            }
            // Too many pieces for so few vertices: a base above their floor.
            Err(RetileError::TooManyComponents { floor, .. }) => at_least = floor,
            Err(_) => return None,
        }
    }
    None
}
