//! Approximate geodesic distances: Dijkstra over mesh edges.

use crate::mesh::Topology;
use glam::Vec3;
use std::cmp::Ordering;
use std::collections::BinaryHeap;

#[derive(PartialEq)]
struct Item(f32, u32);
impl Eq for Item {}
impl PartialOrd for Item {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Item {
    fn cmp(&self, other: &Self) -> Ordering {
        // Min-heap on distance, ties broken by vertex id for determinism.
        other
            .0
            .total_cmp(&self.0)
            .then_with(|| other.1.cmp(&self.1))
    }
}

/// Edge-path distance from the nearest of `sources` to every vertex
/// (`f32::INFINITY` where unreachable, e.g. another component). Distances
/// are sums of Euclidean edge lengths, an upper bound of the geodesic distance.
/// `max_distance` stops the search early (vertices beyond stay infinite).
pub fn dijkstra(
    positions: &[Vec3],
    topo: &Topology,
    sources: &[u32],
    max_distance: f32,
) -> Vec<f32> {
    let mut dist = vec![f32::INFINITY; positions.len()];
    let mut heap = BinaryHeap::new();
    for &s in sources {
        if (s as usize) < dist.len() {
            dist[s as usize] = 0.0;
            heap.push(Item(0.0, s));
        }
    }
    while let Some(Item(d, v)) = heap.pop() {
        if d > dist[v as usize] || d > max_distance {
            continue;
        }
        let pv = positions[v as usize];
        for &w in topo.neighbours(v) {
            let nd = d + (positions[w as usize] - pv).length();
            if nd < dist[w as usize] {
                dist[w as usize] = nd;
                heap.push(Item(nd, w));
            }
        }
    }
    dist
}

/// The vertex nearest to `p` (Euclidean); `None` for an empty slice.
pub fn nearest_vertex(positions: &[Vec3], p: Vec3) -> Option<u32> {
    positions
        .iter()
        .enumerate()
        .min_by(|a, b| {
            a.1.distance_squared(p)
                .total_cmp(&b.1.distance_squared(p))
                .then(a.0.cmp(&b.0))
        })
        .map(|(i, _)| i as u32)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::PolyMesh;

    #[test]
    fn grid_distances_follow_edges() {
        // A 3x3 vertex grid of unit quads: corner to corner is 4 edges.
        let p: Vec<Vec3> = (0..9)
            .map(|i| Vec3::new((i % 3) as f32, (i / 3) as f32, 0.0))
            .collect();
        let m = PolyMesh::from_polygons(
            p.clone(),
            [
                &[0u32, 1, 4, 3][..],
                &[1, 2, 5, 4][..],
                &[3, 4, 7, 6][..],
                &[4, 5, 8, 7][..],
            ],
        );
        let t = Topology::build(&m);
        let d = dijkstra(&p, &t, &[0], f32::INFINITY);
        assert_eq!(d[8], 4.0);
        assert_eq!(d[4], 2.0);
        assert_eq!(nearest_vertex(&p, Vec3::new(2.1, 1.9, 0.0)), Some(8));
    }
}
