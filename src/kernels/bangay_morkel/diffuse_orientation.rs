//! Orientation by diffusion from key vertices (Bangay & Morkel 2006
//! §3.1.1, after Turk 2001): repeated passes set each vertex's orientation
//! to the average of its neighbours', projected onto its tangent plane and
//! normalised, until every vertex has one. On a hierarchy: the keys
//! completed per connected component ([`complete_keys`]) and each level's
//! sweep field ([`level_sweep`]).

use crate::kernels::bangay_morkel::sweep::{relax_sweep, sweep_field};
use crate::kernels::surface::component_fallback::{
    Components, FallbackKey, chain_components, fallback_keys, one_per_component,
};
use crate::kernels::surface::frames::TangentFrame;
use crate::mesh::Topology;
use glam::Vec3;
use rayon::prelude::*;

/// Result of [`diffuse_orientation`].
#[derive(Clone, Debug, PartialEq)]
pub struct DiffusedOrientation {
    /// One unit tangent vector per vertex.
    pub directions: Vec<Vec3>,
    /// Passes it took until no vertex was left without a direction (0 when
    /// every vertex had one from the start).
    pub fill_passes: u32,
    /// Vertices no key reached (components without a key), which took the
    /// fallback direction.
    pub fallback_vertices: usize,
}

/// `v` projected onto the plane of `n` and normalised; `None` when nothing
/// is left.
#[inline]
fn tangent(v: Vec3, n: Vec3) -> Option<Vec3> {
    let p = v - n * n.dot(v);
    (p.length_squared() > 1e-20).then(|| p.normalize())
}

/// Diffuses the orientation given at key vertices over the mesh.
///
/// * `normals` — unit vertex normals (the tangent planes);
/// * `keys` — `(vertex, direction)` pairs set by the user; the direction
///   is projected onto the vertex's tangent plane and held fixed;
/// * `initial` — a direction for every vertex to start from (values carried
///   down from a coarser level, §3.1.1 "diffusing them to the higher
///   resolution meshes"), or `None` to start with only the keys defined;
/// * `smoothing_passes` — passes to run after every vertex has a direction;
/// * `fallback` — direction for vertices no key reaches.
///
/// One pass, Jacobi style (parallel, deterministic): a vertex without a
/// direction takes the mean of its neighbours that have one; a vertex with
/// one takes the mean of its own and its neighbours' mean (the "lazy"
/// average, which on a bipartite quad mesh damps the oscillation a pure
/// neighbour average would keep); either result is projected onto the
/// tangent plane and normalised, and left unchanged where the mean
/// vanishes. Filling stops when a pass defines no new vertex.
///
/// Preconditions: `topo` was built for the mesh; `normals` has one entry
/// per vertex; key vertex ids are in range (others are ignored);
/// `initial`, if given, has one entry per vertex.
pub fn diffuse_orientation(
    normals: &[Vec3],
    topo: &Topology,
    keys: &[(u32, Vec3)],
    initial: Option<&[Vec3]>,
    smoothing_passes: u32,
    fallback: Vec3,
) -> DiffusedOrientation {
    let n = normals.len();
    let mut fixed: Vec<Option<Vec3>> = vec![None; n];
    for &(v, d) in keys {
        if let Some(slot) = fixed.get_mut(v as usize) {
            *slot = tangent(d, normals[v as usize]).or(*slot);
        }
    }
    let mut dir: Vec<Option<Vec3>> = match initial {
        Some(init) => (0..n).map(|v| tangent(init[v], normals[v])).collect(),
        None => vec![None; n],
    };
    for v in 0..n {
        if fixed[v].is_some() {
            dir[v] = fixed[v];
        }
    }
    let mut next = dir.clone();
    let pass = |dir: &[Option<Vec3>], next: &mut [Option<Vec3>]| {
        next.par_iter_mut().enumerate().for_each(|(v, out)| {
            if fixed[v].is_some() {
                *out = fixed[v];
                return;
            }
            let mut sum = Vec3::ZERO;
            let mut count = 0u32;
            for &w in topo.neighbours(v as u32) {
                if let Some(d) = dir[w as usize] {
                    sum += d;
                    count += 1;
                }
            }
            if count == 0 {
                *out = dir[v];
                return;
            }
            let mean = sum / count as f32;
            let blended = match dir[v] {
                Some(own) => (own + mean) * 0.5,
                None => mean,
            };
            *out = tangent(blended, normals[v]).or(dir[v]);
        });
    };
    let mut fill_passes = 0;
    let mut undefined = dir.iter().filter(|d| d.is_none()).count();
    while undefined > 0 {
        pass(&dir, &mut next);
        std::mem::swap(&mut dir, &mut next);
        let now = dir.iter().filter(|d| d.is_none()).count();
        fill_passes += 1;
        if now == undefined {
            break;
        }
        undefined = now;
    }
    for _ in 0..smoothing_passes {
        pass(&dir, &mut next);
        std::mem::swap(&mut dir, &mut next);
    }
    let mut fallback_vertices = 0;
    let directions = dir
        .iter()
        .zip(normals)
        .map(|(d, &nrm)| {
            d.unwrap_or_else(|| {
                fallback_vertices += 1;
                tangent(fallback, nrm).unwrap_or_else(|| nrm.any_orthonormal_vector())
            })
        })
        .collect();
    DiffusedOrientation {
        directions,
        fill_passes,
        fallback_vertices,
    }
}

/// The keys of a diffusion over a mesh whose every connected component has
/// one ([`complete_keys`]).
#[derive(Clone, Debug, PartialEq)]
pub struct CompletedKeys {
    /// The user's keys, then one automatic key per component none of them
    /// is on.
    pub keys: Vec<(u32, Vec3)>,
    /// The automatic keys.
    pub automatic: Vec<FallbackKey>,
    /// Where the sweep is 0.
    pub anchor: u32,
    /// One sweep start per component: the anchor, else the component's
    /// first key (user keys before automatic ones).
    pub sweep_starts: Vec<u32>,
}

/// Completes the user's `keys` on a mesh (the coarsest level): every
/// connected component no key is on gets one automatic key
/// ([`fallback_keys`], direction `fallback` projected there), so the field
/// is diffused there too; every component gets one sweep start.
///
/// Preconditions: `topo` was built for the mesh; `normals` has one entry
/// per vertex.
pub fn complete_keys(
    positions: &[Vec3],
    normals: &[Vec3],
    topo: &Topology,
    mut keys: Vec<(u32, Vec3)>,
    anchor: u32,
    fallback: Vec3,
) -> CompletedKeys {
    let (count, of_vertex) = topo.components();
    let components = Components {
        count,
        of_vertex: &of_vertex,
    };
    let user_keys: Vec<u32> = keys.iter().map(|k| k.0).collect();
    let automatic = fallback_keys(positions, normals, components, &user_keys, fallback);
    keys.extend(automatic.iter().map(|k| (k.vertex, k.direction)));
    let preferred: Vec<u32> = std::iter::once(anchor)
        .chain(keys.iter().map(|k| k.0))
        .collect();
    let sweep_starts = one_per_component(components, &preferred);
    CompletedKeys {
        keys,
        automatic,
        anchor,
        sweep_starts,
    }
}

/// The sweep field of one level of a hierarchy: grown from the sweep
/// starts ([`sweep_field`], `iterations` passes) on the coarsest level,
/// else the values `carried` down from the level above relaxed for
/// `refine_passes` with the starts held ([`relax_sweep`]); then the
/// anchor's component first and the others continuing after it
/// ([`chain_components`], a no-op on a connected mesh).
pub fn level_sweep(
    positions: &[Vec3],
    topo: &Topology,
    directions: &[Vec3],
    keys: &CompletedKeys,
    carried: Option<Vec<f32>>,
    iterations: u32,
    refine_passes: u32,
) -> Vec<f32> {
    let mut sweep = match carried {
        None => sweep_field(positions, topo, directions, &keys.sweep_starts, iterations),
        Some(mut s) => {
            let mut fixed = vec![false; s.len()];
            for &a in &keys.sweep_starts {
                if let Some(f) = fixed.get_mut(a as usize) {
                    *f = true;
                }
            }
            relax_sweep(positions, topo, directions, &fixed, &mut s, refine_passes);
            s
        }
    };
    let (count, of_vertex) = topo.components();
    let first = of_vertex.get(keys.anchor as usize).copied();
    chain_components(
        &mut sweep,
        Components {
            count,
            of_vertex: &of_vertex,
        },
        first,
    );
    sweep
}

/// Frames whose up axis `t` is each vertex's diffused direction (`s = t × n`).
pub fn frames_from_directions(normals: &[Vec3], directions: &[Vec3]) -> Vec<TangentFrame> {
    normals
        .iter()
        .zip(directions)
        .map(|(&n, &d)| TangentFrame::from_up(n, d))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::PolyMesh;

    #[test]
    fn keys_spread_over_a_plane_and_stay_put() {
        let n = 6;
        let p: Vec<Vec3> = (0..n * n)
            .map(|i| Vec3::new((i % n) as f32, (i / n) as f32, 0.0))
            .collect();
        let mut faces = Vec::new();
        for y in 0..n - 1 {
            for x in 0..n - 1 {
                let i = (y * n + x) as u32;
                faces.push([i, i + 1, i + n as u32 + 1, i + n as u32]);
            }
        }
        let m = PolyMesh::from_polygons(p, faces.iter().map(|f| &f[..]));
        let t = Topology::build(&m);
        let normals = m.vertex_normals();
        let r = diffuse_orientation(
            &normals,
            &t,
            &[(0, Vec3::new(1.0, 1.0, 5.0))],
            None,
            3,
            Vec3::X,
        );
        assert_eq!(r.fallback_vertices, 0);
        assert_eq!(r.fill_passes, 10, "corner to corner is 10 edges");
        let want = Vec3::new(1.0, 1.0, 0.0).normalize();
        for d in &r.directions {
            assert!((*d - want).length() < 1e-5, "{d:?}");
        }
    }
}
