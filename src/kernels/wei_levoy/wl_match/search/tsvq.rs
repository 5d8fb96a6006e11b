//! Tree-structured vector quantisation (Wei & Levoy 2000 §4, used by Wei &
//! Levoy 2001 §4): the exemplar neighbourhoods are split recursively in two
//! by 2-means (Lloyd's algorithm, the generalized Lloyd algorithm of TSVQ
//! codebook training) until a cluster holds at most `leaf_size` vectors. A
//! query descends towards the nearer child centroid; with `leaves > 1` the
//! descent is best-first over the nearest unexplored branches until that many
//! leaves are searched. The leaves' vectors are compared exactly.

use std::cmp::Reverse;
use std::collections::BinaryHeap;

use super::{Match, NeighbourhoodSearch, better};
use crate::kernels::dist2;
use crate::kernels::wei_levoy::wl_match::features::FeatureMatrix;

/// Lloyd iterations per split.
const LLOYD_ITERATIONS: usize = 8;

#[derive(Clone, Copy, Debug)]
struct Node {
    /// Children (inner node) or `u32::MAX` (leaf).
    left: u32,
    right: u32,
    /// Leaf: the slice of `order` it holds.
    start: u32,
    count: u32,
}

/// TSVQ search.
pub struct Tsvq {
    features: FeatureMatrix,
    nodes: Vec<Node>,
    /// Per node, the mean of its vectors (`dim` values).
    centroids: Vec<f32>,
    /// Rows in leaf order.
    order: Vec<u32>,
    leaves: usize,
}

impl Tsvq {
    /// Builds the tree over `features` (deterministic; `_seed` is unused, the
    /// splits start from the farthest points).
    pub fn new(features: FeatureMatrix, leaf_size: usize, leaves: usize, _seed: u64) -> Self {
        let rows = features.rows();
        let mut s = Self {
            nodes: Vec::new(),
            centroids: Vec::new(),
            order: (0..rows as u32).collect(),
            leaves: leaves.max(1),
            features,
        };
        if rows > 0 && s.features.dim > 0 {
            let mut order = std::mem::take(&mut s.order);
            let (nodes, centroids) = build(&s.features, &mut order, 0, leaf_size.max(1));
            s.nodes = nodes;
            s.centroids = centroids;
            s.order = order;
        }
        s
    }

    #[inline]
    fn centroid(&self, node: u32) -> &[f32] {
        let dim = self.features.dim;
        &self.centroids[node as usize * dim..(node as usize + 1) * dim]
    }
}

/// Clusters with more rows than this split their two halves in parallel.
const PARALLEL_ROWS: usize = 256;

/// The subtree over `rows` (which start at `offset` in the final order), in
/// pre-order (root, left subtree, right subtree) with node indices relative
/// to its root, and its centroids. Subtrees of large clusters are built in
/// parallel; the layout is the same as a sequential build's.
fn build(
    features: &FeatureMatrix,
    rows: &mut [u32],
    offset: u32,
    leaf_size: usize,
) -> (Vec<Node>, Vec<f32>) {
    let centroid = mean_of(features, rows);
    let leaf = Node {
        left: u32::MAX,
        right: u32::MAX,
        start: offset,
        count: rows.len() as u32,
    };
    if rows.len() <= leaf_size {
        return (vec![leaf], centroid);
    }
    let split = two_means(features, rows, &centroid);
    if split == 0 || split == rows.len() {
        return (vec![leaf], centroid);
    }
    let (l, r) = rows.split_at_mut(split);
    let right_offset = offset + split as u32;
    let ((mut nodes_l, cent_l), (nodes_r, cent_r)) = if rows_len(l, r) > PARALLEL_ROWS {
        rayon::join(
            || build(features, l, offset, leaf_size),
            || build(features, r, right_offset, leaf_size),
        )
    } else {
        (
            build(features, l, offset, leaf_size),
            build(features, r, right_offset, leaf_size),
        )
    };
    let shift = |n: Node, by: u32| Node {
        left: if n.left == u32::MAX {
            n.left
        } else {
            n.left + by
        },
        right: if n.right == u32::MAX {
            n.right
        } else {
            n.right + by
        },
        ..n
    };
    let left_len = nodes_l.len() as u32;
    let mut nodes = Vec::with_capacity(1 + nodes_l.len() + nodes_r.len());
    nodes.push(Node {
        left: 1,
        right: 1 + left_len,
        ..leaf
    });
    nodes.extend(nodes_l.drain(..).map(|n| shift(n, 1)));
    nodes.extend(nodes_r.into_iter().map(|n| shift(n, 1 + left_len)));
    let mut centroids = centroid;
    centroids.extend_from_slice(&cent_l);
    centroids.extend_from_slice(&cent_r);
    (nodes, centroids)
}

fn rows_len(l: &[u32], r: &[u32]) -> usize {
    l.len() + r.len()
}

fn mean_of(features: &FeatureMatrix, rows: &[u32]) -> Vec<f32> {
    let dim = features.dim;
    let mut acc = vec![0.0f64; dim];
    for &r in rows {
        for (a, v) in acc.iter_mut().zip(features.row(r as usize)) {
            *a += *v as f64;
        }
    }
    let n = rows.len().max(1) as f64;
    acc.into_iter().map(|a| (a / n) as f32).collect()
}

/// Splits `rows` in place into two clusters by Lloyd's 2-means, started from
/// the row farthest from the mean and the row farthest from that one.
/// Returns the size of the first cluster (0 or `len` when no split exists).
fn two_means(features: &FeatureMatrix, rows: &mut [u32], mean: &[f32]) -> usize {
    let farthest = |from: &[f32], rows: &[u32]| -> u32 {
        let mut best = (f32::NEG_INFINITY, u32::MAX);
        for &r in rows {
            let d = dist2(from, features.row(r as usize));
            if d > best.0 || (d == best.0 && r < best.1) {
                best = (d, r);
            }
        }
        best.1
    };
    let a = farthest(mean, rows);
    let b = farthest(features.row(a as usize), rows);
    let mut c0 = features.row(a as usize).to_vec();
    let mut c1 = features.row(b as usize).to_vec();
    if dist2(&c0, &c1) == 0.0 {
        return 0;
    }
    let mut side = vec![false; rows.len()];
    for _ in 0..LLOYD_ITERATIONS {
        let mut changed = false;
        for (s, &r) in side.iter_mut().zip(rows.iter()) {
            let p = features.row(r as usize);
            let right = dist2(p, &c1) < dist2(p, &c0);
            changed |= right != *s;
            *s = right;
        }
        let (l, r): (Vec<u32>, Vec<u32>) = {
            let mut l = Vec::new();
            let mut r = Vec::new();
            for (&s, &row) in side.iter().zip(rows.iter()) {
                if s { r.push(row) } else { l.push(row) }
            }
            (l, r)
        };
        if l.is_empty() || r.is_empty() {
            break;
        }
        c0 = mean_of(features, &l);
        c1 = mean_of(features, &r);
        if !changed {
            break;
        }
    }
    // Stable partition: left cluster first, each in its original order.
    let mut left: Vec<u32> = Vec::with_capacity(rows.len());
    let mut right: Vec<u32> = Vec::new();
    for (&s, &row) in side.iter().zip(rows.iter()) {
        if s {
            right.push(row);
        } else {
            left.push(row);
        }
    }
    let split = left.len();
    rows[..split].copy_from_slice(&left);
    rows[split..].copy_from_slice(&right);
    split
}

impl NeighbourhoodSearch for Tsvq {
    fn search(&self, queries: &[f32], out: &mut [Match]) {
        let dim = self.features.dim;
        if dim == 0 || self.nodes.is_empty() {
            out.fill(Match {
                index: 0,
                distance: 0.0,
            });
            return;
        }
        let mut heap: BinaryHeap<Reverse<(u32, u32)>> = BinaryHeap::new();
        for (q, o) in queries.chunks_exact(dim).zip(out.iter_mut()) {
            let mut best = Match {
                index: 0,
                distance: f32::INFINITY,
            };
            heap.clear();
            heap.push(Reverse((0, 0)));
            let mut searched = 0;
            while let Some(Reverse((_, ni))) = heap.pop() {
                let mut node = self.nodes[ni as usize];
                // Greedy descent; the other branch waits in the heap.
                while node.left != u32::MAX {
                    let dl = dist2(q, self.centroid(node.left));
                    let dr = dist2(q, self.centroid(node.right));
                    let (near, far, dfar) = if dr < dl {
                        (node.right, node.left, dl)
                    } else {
                        (node.left, node.right, dr)
                    };
                    if self.leaves > 1 {
                        heap.push(Reverse((dfar.to_bits(), far)));
                    }
                    node = self.nodes[near as usize];
                }
                for &r in &self.order[node.start as usize..(node.start + node.count) as usize] {
                    let m = Match {
                        index: r,
                        distance: dist2(q, self.features.row(r as usize)),
                    };
                    if better(m, best) {
                        best = m;
                    }
                }
                searched += 1;
                if searched >= self.leaves {
                    break;
                }
            }
            *o = best;
        }
    }

    fn dim(&self) -> usize {
        self.features.dim
    }

    fn len(&self) -> usize {
        self.features.rows()
    }
}
