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
    let mut position = vec![u32::MAX; order.len()];
    for (i, &v) in order.iter().enumerate() {
        if let Some(p) = position.get_mut(v as usize) {
            *p = i as u32;
        }
    }
    dependency_batches_of(
        order,
        |u| position.get(u as usize).copied().filter(|&p| p != u32::MAX),
        reads,
    )
}

/// [`dependency_batches`] for an `order` that lists some of the vertices:
/// `position(u)` is `u`'s index in `order`, `None` for a vertex not listed
/// (not written, so it orders nothing). O(listed vertices + their reads):
/// no array the size of the mesh.
pub fn dependency_batches_of<'a>(
    order: &[u32],
    position: impl Fn(u32) -> Option<u32>,
    reads: impl Fn(u32) -> &'a [u32],
) -> Vec<Vec<u32>> {
    // One pass in order. `level[p]` is the batch of the `p`-th vertex once
    // it is placed, and before that the least batch the earlier vertices
    // that read it allow: placing a vertex raises the bound of every later
    // vertex it reads, so a vertex meets both kinds of conflict (earlier
    // vertices it reads, earlier vertices that read it) without the
    // transpose of `reads`.
    let mut level = vec![0u32; order.len()];
    let mut later: Vec<usize> = Vec::new();
    let mut batches: Vec<Vec<u32>> = Vec::new();
    for (pv, &v) in order.iter().enumerate() {
        let mut b = level[pv];
        later.clear();
        for &u in reads(v) {
            if let Some(pu) = position(u) {
                let pu = pu as usize;
                if pu < pv {
                    b = b.max(level[pu] + 1);
                } else if pu > pv {
                    later.push(pu);
                }
            }
        }
        level[pv] = b;
        for &pu in &later {
            level[pu] = level[pu].max(b + 1);
        }
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
