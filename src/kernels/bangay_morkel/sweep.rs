//! The sweep field of Turk 2001 (§4, "sweeping"), as Bangay & Morkel 2006
//! §3.1.1 use it: a scalar per vertex that increases along the orientation
//! field from an anchor, so that sorting by it visits the surface in a
//! continuous front.

use crate::mesh::Topology;
use glam::Vec3;
use rayon::prelude::*;

/// The sweep increment across the edge `i → j`: the edge projected onto the
/// mean direction of its two ends (0 where the directions cancel).
#[inline]
fn increment(positions: &[Vec3], directions: &[Vec3], i: usize, j: usize) -> f32 {
    let dir = (directions[i] + directions[j]).normalize_or_zero();
    (positions[j] - positions[i]).dot(dir)
}

/// A sweep field over the mesh: `0` at the anchors, growing by the edge
/// length measured along the orientation `directions` (one unit tangent
/// vector per vertex, e.g. the texture's up direction).
///
/// First a breadth-first front from the anchors sets each vertex, layer by
/// layer, to the mean over its neighbours in earlier layers of
/// `sweep(j) + (p_i − p_j)·d̂ᵢⱼ` (`d̂ᵢⱼ` the mean direction of the edge's ends);
/// then [`relax_sweep`] runs `iterations` Jacobi passes of the same rule over
/// all neighbours, the anchors held at 0. A component without an anchor
/// starts from its lowest vertex id. On a plane with a constant direction
/// the result is exactly the signed distance along it from the anchor.
///
/// Deterministic; the relaxation is parallel over vertices.
///
/// Preconditions: `topo` was built for the mesh of `positions`;
/// `directions.len() == positions.len()`; anchors are vertex ids.
pub fn sweep_field(
    positions: &[Vec3],
    topo: &Topology,
    directions: &[Vec3],
    anchors: &[u32],
    iterations: u32,
) -> Vec<f32> {
    let n = positions.len();
    let mut value = vec![0.0f32; n];
    let mut layer_of = vec![u32::MAX; n];
    let mut fixed = vec![false; n];
    let mut current: Vec<u32> = Vec::new();
    let mut next: Vec<u32> = Vec::new();
    let mut seeds: Vec<u32> = anchors
        .iter()
        .copied()
        .filter(|&a| (a as usize) < n)
        .collect();
    let mut start = 0usize;
    loop {
        for &a in &seeds {
            if layer_of[a as usize] == u32::MAX {
                layer_of[a as usize] = 0;
                fixed[a as usize] = true;
                current.push(a);
            }
        }
        let mut layer = 0u32;
        while !current.is_empty() {
            next.clear();
            for &v in &current {
                for &w in topo.neighbours(v) {
                    if layer_of[w as usize] == u32::MAX {
                        layer_of[w as usize] = layer + 1;
                        next.push(w);
                    }
                }
            }
            next.sort_unstable();
            for &w in &next {
                let wi = w as usize;
                let (mut sum, mut count) = (0.0f32, 0u32);
                for &j in topo.neighbours(w) {
                    if layer_of[j as usize] <= layer {
                        sum += value[j as usize] + increment(positions, directions, j as usize, wi);
                        count += 1;
                    }
                }
                value[wi] = sum / count.max(1) as f32;
            }
            std::mem::swap(&mut current, &mut next);
            layer += 1;
        }
        // Components the anchors did not reach start at their lowest id.
        while start < n && layer_of[start] != u32::MAX {
            start += 1;
        }
        if start == n {
            break;
        }
        seeds.clear();
        seeds.push(start as u32);
    }
    relax_sweep(positions, topo, directions, &fixed, &mut value, iterations);
    value
}

/// Jacobi passes of the sweep rule over `values`:
/// `sweep(i) ← mean over neighbours j of sweep(j) + (p_i − p_j)·d̂ᵢⱼ`,
/// except where `fixed`. Used after [`sweep_field`]'s front, and on a finer
/// mesh level after values were carried down from the coarser one (the
/// hierarchical scheme of §3.1.1). Parallel and deterministic.
pub fn relax_sweep(
    positions: &[Vec3],
    topo: &Topology,
    directions: &[Vec3],
    fixed: &[bool],
    values: &mut [f32],
    iterations: u32,
) {
    let mut next = values.to_vec();
    for _ in 0..iterations {
        next.par_iter_mut().enumerate().for_each(|(i, out)| {
            let nb = topo.neighbours(i as u32);
            if fixed.get(i).copied().unwrap_or(false) || nb.is_empty() {
                *out = values[i];
                return;
            }
            let sum: f32 = nb
                .iter()
                .map(|&j| values[j as usize] + increment(positions, directions, j as usize, i))
                .sum();
            *out = sum / nb.len() as f32;
        });
        values.copy_from_slice(&next);
    }
}

/// Vertices sorted by increasing sweep value (ties by id): the synthesis
/// order of §3.1.2 on the coarsest level.
pub fn sweep_order(values: &[f32]) -> Vec<u32> {
    let mut order: Vec<u32> = (0..values.len() as u32).collect();
    order.sort_by(|&a, &b| {
        values[a as usize]
            .total_cmp(&values[b as usize])
            .then(a.cmp(&b))
    });
    order
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::PolyMesh;

    #[test]
    fn plane_sweep_is_distance_along_the_direction() {
        let n = 7;
        let p: Vec<Vec3> = (0..n * n)
            .map(|i| Vec3::new((i % n) as f32, (i / n) as f32 * 0.5, 0.0))
            .collect();
        let mut faces = Vec::new();
        for y in 0..n - 1 {
            for x in 0..n - 1 {
                let i = (y * n + x) as u32;
                faces.push([i, i + 1, i + n as u32 + 1, i + n as u32]);
            }
        }
        let m = PolyMesh::from_polygons(p.clone(), faces.iter().map(|f| &f[..]));
        let t = Topology::build(&m);
        let dirs = vec![Vec3::Y; p.len()];
        let anchor = 3 * n as u32 + 2;
        let s = sweep_field(&p, &t, &dirs, &[anchor], 10);
        for v in 0..p.len() {
            let want = p[v].y - p[anchor as usize].y;
            assert!((s[v] - want).abs() < 1e-4, "{v}: {} vs {want}", s[v]);
        }
        let order = sweep_order(&s);
        assert!(
            order
                .windows(2)
                .all(|w| s[w[0] as usize] <= s[w[1] as usize])
        );
    }
}
