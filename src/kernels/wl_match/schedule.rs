//! Random visiting order (Wei & Levoy 2001 §3.2) and its parallel schedule.
//!
//! Within a pass that reads the current level, each vertex must see the
//! colours its predecessors in the random order already wrote. Two vertices
//! conflict when either one's neighbourhood reads the other. Giving each
//! vertex the batch `1 + max(batch of earlier conflicting vertices)` (a level
//! schedule of the order) puts conflicting vertices in increasing batches in
//! the order they come, and no two vertices of a batch conflict; running the
//! batches one after another, each in parallel, therefore gives exactly the
//! result of the sequential random order, for any thread count.

use rand::SeedableRng;
use rand::seq::SliceRandom;

/// A uniformly random permutation of `0..count` from a PCG seeded by `seed`.
pub fn random_order(count: usize, seed: u64) -> Vec<u32> {
    let mut order: Vec<u32> = (0..count as u32).collect();
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(seed);
    order.shuffle(&mut rng);
    order
}

/// The batches of `order` given which vertices each vertex reads
/// (`reads(v)`, any order, may contain `v` itself or repeats). Each batch
/// lists its vertices in their order of `order`. O(total reads).
pub fn dependency_batches<'a>(order: &[u32], reads: impl Fn(u32) -> &'a [u32]) -> Vec<Vec<u32>> {
    dependency_batches_of(order, order.len(), reads)
}

/// [`dependency_batches`] for an `order` that lists some of
/// `vertex_count` vertices (the others are not written, so they order
/// nothing). O(vertex count + reads of the listed vertices).
pub fn dependency_batches_of<'a>(
    order: &[u32],
    vertex_count: usize,
    reads: impl Fn(u32) -> &'a [u32],
) -> Vec<Vec<u32>> {
    let n = vertex_count;
    const ABSENT: u32 = u32::MAX;
    let mut position = vec![ABSENT; n];
    for (i, &v) in order.iter().enumerate() {
        position[v as usize] = i as u32;
    }
    let listed = |u: u32| (u as usize) < n && position[u as usize] != ABSENT;
    // Who reads each listed vertex: the transpose of `reads`, by counting.
    let mut start = vec![0u32; n + 1];
    for &v in order {
        for &u in reads(v) {
            if listed(u) {
                start[u as usize + 1] += 1;
            }
        }
    }
    for i in 0..n {
        start[i + 1] += start[i];
    }
    let mut fill = start.clone();
    let mut readers = vec![0u32; start[n] as usize];
    for &v in order {
        for &u in reads(v) {
            if listed(u) {
                readers[fill[u as usize] as usize] = v;
                fill[u as usize] += 1;
            }
        }
    }
    let mut batch = vec![0u32; n];
    let mut batches: Vec<Vec<u32>> = Vec::new();
    for &v in order {
        let pv = position[v as usize];
        let mut b = 0u32;
        let read_by = &readers[start[v as usize] as usize..start[v as usize + 1] as usize];
        for &u in reads(v).iter().chain(read_by) {
            if listed(u) && position[u as usize] < pv {
                b = b.max(batch[u as usize] + 1);
            }
        }
        batch[v as usize] = b;
        if batches.len() <= b as usize {
            batches.resize_with(b as usize + 1, Vec::new);
        }
        batches[b as usize].push(v);
    }
    batches
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn batches_respect_the_order_of_conflicting_vertices() {
        // A path 0-1-2-...-9 where each vertex reads its two neighbours.
        let n = 10u32;
        let reads: Vec<Vec<u32>> = (0..n)
            .map(|v| {
                [v.wrapping_sub(1), v + 1]
                    .into_iter()
                    .filter(|&u| u < n)
                    .collect()
            })
            .collect();
        let order = random_order(n as usize, 4);
        let batches = dependency_batches(&order, |v| &reads[v as usize]);
        let mut batch_of = vec![0usize; n as usize];
        for (b, vs) in batches.iter().enumerate() {
            for &v in vs {
                batch_of[v as usize] = b;
            }
        }
        assert_eq!(batches.iter().map(Vec::len).sum::<usize>(), n as usize);
        let pos = |v: u32| order.iter().position(|&x| x == v).unwrap();
        for v in 0..n - 1 {
            let (a, b) = (v, v + 1);
            assert_ne!(batch_of[a as usize], batch_of[b as usize]);
            assert_eq!(
                pos(a) < pos(b),
                batch_of[a as usize] < batch_of[b as usize],
                "conflicting vertices keep their order"
            );
        }
    }
}
