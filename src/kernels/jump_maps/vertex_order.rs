//! Vertex orderings for surface synthesis (Zelinka & Garland 2004 §6.2).

use crate::mesh::Topology;
use rand::{Rng, SeedableRng, seq::SliceRandom};

/// Which order vertices are synthesized in.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum VertexOrder {
    /// Greedy: next is the vertex with the highest proportion of
    /// already-synthesized neighbours (§6.2).
    #[default]
    EmergingFront,
    /// Breadth-first from a random vertex of each component.
    BreadthFirst,
    /// A uniformly random permutation (a baseline for comparison).
    Random,
}

/// Quantisation of the synthesized-neighbour proportion in the emerging front.
const LEVELS: usize = 64;

/// The order of `vertex_count` vertices; every vertex appears exactly once.
pub fn vertex_order(topo: &Topology, order: VertexOrder, seed: u64) -> Vec<u32> {
    let n = topo.vertex_count();
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(seed);
    // Component starts come from one random permutation.
    let mut starts: Vec<u32> = (0..n as u32).collect();
    starts.shuffle(&mut rng);
    match order {
        VertexOrder::Random => starts,
        VertexOrder::BreadthFirst => {
            let mut done = vec![false; n];
            let mut out = Vec::with_capacity(n);
            let mut head = 0;
            for &s in &starts {
                if done[s as usize] {
                    continue;
                }
                done[s as usize] = true;
                out.push(s);
                while head < out.len() {
                    let v = out[head];
                    head += 1;
                    for &w in topo.neighbours(v) {
                        if !done[w as usize] {
                            done[w as usize] = true;
                            out.push(w);
                        }
                    }
                }
            }
            out
        }
        VertexOrder::EmergingFront => emerging_front(topo, &starts, &mut rng),
    }
}

/// Bucket queue over quantised proportions; stale entries are skipped when
/// popped, so each update is O(1).
fn emerging_front(topo: &Topology, starts: &[u32], rng: &mut impl Rng) -> Vec<u32> {
    let n = topo.vertex_count();
    let mut done = vec![false; n];
    let mut synthesized_nbrs = vec![0u32; n];
    let mut level = vec![0u8; n];
    let mut buckets: Vec<Vec<u32>> = vec![Vec::new(); LEVELS + 1];
    let mut top = 0usize;
    let mut out = Vec::with_capacity(n);
    let mut next_start = 0usize;
    let _ = rng;
    while out.len() < n {
        // Pop the best live entry.
        let mut picked = None;
        loop {
            while top > 0 && buckets[top].is_empty() {
                top -= 1;
            }
            let Some(v) = buckets[top].pop() else {
                break;
            };
            if !done[v as usize] && level[v as usize] as usize == top {
                picked = Some(v);
                break;
            }
        }
        let v = match picked {
            Some(v) => v,
            None => {
                // A new component (or the first vertex): next unvisited start.
                while done[starts[next_start] as usize] {
                    next_start += 1;
                }
                starts[next_start]
            }
        };
        done[v as usize] = true;
        out.push(v);
        for &w in topo.neighbours(v) {
            let wi = w as usize;
            if done[wi] {
                continue;
            }
            synthesized_nbrs[wi] += 1;
            let deg = topo.neighbours(w).len().max(1);
            let l = (synthesized_nbrs[wi] as usize * LEVELS / deg).min(LEVELS);
            if l as u8 != level[wi] || l == 0 {
                level[wi] = l as u8;
                buckets[l].push(w);
                top = top.max(l);
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::PolyMesh;
    use glam::Vec3;

    fn two_component_mesh() -> PolyMesh {
        let mut p = Vec::new();
        let mut faces: Vec<Vec<u32>> = Vec::new();
        for c in 0..2u32 {
            let base = p.len() as u32;
            for i in 0..25 {
                p.push(Vec3::new(
                    (i % 5) as f32 + 10.0 * c as f32,
                    (i / 5) as f32,
                    0.0,
                ));
            }
            for y in 0..4 {
                for x in 0..4 {
                    let i = base + y * 5 + x;
                    faces.push(vec![i, i + 1, i + 6, i + 5]);
                }
            }
        }
        PolyMesh::from_polygons(p, faces.iter().map(|f| f.as_slice()))
    }

    #[test]
    fn every_order_is_a_permutation_across_components() {
        let m = two_component_mesh();
        let t = Topology::build(&m);
        for order in [
            VertexOrder::EmergingFront,
            VertexOrder::BreadthFirst,
            VertexOrder::Random,
        ] {
            let mut o = vertex_order(&t, order, 3);
            o.sort();
            assert_eq!(o, (0..50).collect::<Vec<u32>>(), "{order:?}");
        }
    }

    #[test]
    fn emerging_front_grows_a_connected_region() {
        let m = two_component_mesh();
        let t = Topology::build(&m);
        let o = vertex_order(&t, VertexOrder::EmergingFront, 9);
        let mut done = [false; 50];
        // After the first vertex of a component, every next vertex of the
        // same component touches an already-synthesized one.
        let mut with_nbr = 0;
        for &v in &o {
            if t.neighbours(v).iter().any(|&w| done[w as usize]) {
                with_nbr += 1;
            }
            done[v as usize] = true;
        }
        assert_eq!(
            with_nbr, 48,
            "only the two component starts lack a synthesized neighbour"
        );
    }
}
