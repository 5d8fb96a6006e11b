//! Exact k nearest neighbours among points of a few dimensions (the 8
//! leading principal components of Wei–Levoy's PCA search and of the
//! coherent appearance space): a kd-tree of boxes over every dimension,
//! leaves of at most [`LEAF`] points stored eight to a block, one vector
//! lane per point.
//!
//! A query descends nearer child first and skips a node whose box is
//! farther than its `k`-th best so far; a leaf's points are compared eight
//! at a time. Distances are summed dimension by dimension from zero, as
//! `Σ (aᵢ − bᵢ)²` one term after another, so each equals a scalar loop's
//! bit for bit; the `k` nearest are ranked by (distance, index), so the
//! result is one well-defined set whatever the visiting order.
//!
//! Why not kiddo's `nearest_n`: it held a third of a Wei–Levoy run and a
//! quarter of a coherent one (branchy descent, a binary heap per query);
//! this visits fewer nodes per query and compares points in vector lanes.
//!
//! `cargo bench --bench knn` times it on PCA-like points; most of a query is
//! the candidates' insertion into the sorted `k` best and the box bounds, so
//! leaves are large (64: 15.3 ms for 4,096 queries of 16 against 19.6 ms at
//! 32 with `Vec::insert`).

/// Most points per leaf.
pub const LEAF: usize = 64;
/// Coordinate of the padding lanes of a leaf's last block: far from every
/// point, so never among the nearest.
const FAR: f32 = 1.0e18;

/// Exact nearest-neighbour index over points of `D` coordinates.
#[derive(Clone, Debug)]
pub struct Knn<const D: usize> {
    nodes: Vec<Node<D>>,
    /// Per block: `D` rows of eight coordinates (one lane per point).
    blocks: Vec<[[f32; 8]; D]>,
    /// Per block: each lane's point index (`u32::MAX` for padding).
    ids: Vec<[u32; 8]>,
    len: usize,
}

#[derive(Clone, Copy, Debug)]
struct Node<const D: usize> {
    lo: [f32; D],
    hi: [f32; D],
    /// Leaf: `first` block and `count` blocks. Inner: `first` is the left
    /// child's node index, the right child follows its whole subtree at
    /// `count`.
    first: u32,
    count: u32,
    leaf: bool,
}

/// Reusable buffers of a query, one per thread.
#[derive(Clone, Debug, Default)]
pub struct KnnScratch {
    stack: Vec<(f32, u32)>,
    best: Vec<(f32, u32)>,
}

impl<const D: usize> Knn<D> {
    /// Indexes `points` (non-finite coordinates are allowed but never near).
    pub fn new(points: &[[f32; D]]) -> Self {
        let mut order: Vec<u32> = (0..points.len() as u32).collect();
        let mut index = Self {
            nodes: Vec::new(),
            blocks: Vec::new(),
            ids: Vec::new(),
            len: points.len(),
        };
        if !points.is_empty() {
            index.build(points, &mut order, 0);
        }
        index
    }

    /// Number of points.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether there are no points.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Builds the subtree over `order` (a slice of the point indices) and
    /// returns its node index.
    fn build(&mut self, points: &[[f32; D]], order: &mut [u32], depth: u32) -> u32 {
        let (lo, hi) = bounding_box::<D, D>(points, order);
        let at = self.nodes.len() as u32;
        if order.len() <= LEAF || depth >= 48 {
            let first = self.blocks.len() as u32;
            for chunk in order.chunks(8) {
                let mut ids = [u32::MAX; 8];
                ids[..chunk.len()].copy_from_slice(chunk);
                self.blocks.push(lanes(points, chunk, FAR));
                self.ids.push(ids);
            }
            self.nodes.push(Node {
                lo,
                hi,
                first,
                count: self.blocks.len() as u32 - first,
                leaf: true,
            });
            return at;
        }
        let mid = split_widest(points, order, &lo, &hi);
        self.nodes.push(Node {
            lo,
            hi,
            first: 0,
            count: 0,
            leaf: false,
        });
        let (left, right) = order.split_at_mut(mid);
        let l = self.build(points, left, depth + 1);
        let r = self.build(points, right, depth + 1);
        self.nodes[at as usize].first = l;
        self.nodes[at as usize].count = r;
        at
    }

    /// The `k` nearest points to `query` as `(squared distance, index)`,
    /// ascending by distance then index (fewer when there are fewer
    /// points).
    ///
    /// Compiled twice, for the baseline and for AVX2 (chosen once per call
    /// by the processor): both do the same IEEE operations in the same
    /// order (no fused multiply-add), so the results are identical; AVX2
    /// compares a block's eight lanes in one instruction instead of two.
    pub fn nearest<'s>(
        &self,
        query: &[f32; D],
        k: usize,
        scratch: &'s mut KnnScratch,
    ) -> &'s [(f32, u32)] {
        #[cfg(target_arch = "x86_64")]
        {
            if std::is_x86_feature_detected!("avx2") {
                // SAFETY: the processor supports AVX2 (checked just above).
                unsafe { self.nearest_avx2(query, k, scratch) };
                return &scratch.best;
            }
        }
        self.nearest_generic(query, k, scratch);
        &scratch.best
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn nearest_avx2(&self, query: &[f32; D], k: usize, scratch: &mut KnnScratch) {
        self.nearest_generic(query, k, scratch)
    }

    #[inline(always)]
    fn nearest_generic(&self, query: &[f32; D], k: usize, scratch: &mut KnnScratch) {
        scratch.best.clear();
        scratch.stack.clear();
        if self.nodes.is_empty() || k == 0 {
            return;
        }
        scratch.stack.push((0.0, 0));
        while let Some((bound, node)) = scratch.stack.pop() {
            if scratch.best.len() == k && bound > scratch.best[k - 1].0 {
                continue;
            }
            let n = &self.nodes[node as usize];
            if n.leaf {
                let range = n.first as usize..(n.first + n.count) as usize;
                for (block, ids) in self.blocks[range.clone()].iter().zip(&self.ids[range]) {
                    let mut acc = [0.0f32; 8];
                    for (row, &qa) in block.iter().zip(query) {
                        for (a, &x) in acc.iter_mut().zip(row) {
                            let d = x - qa;
                            *a += d * d;
                        }
                    }
                    let worst = if scratch.best.len() == k {
                        scratch.best[k - 1].0
                    } else {
                        f32::INFINITY
                    };
                    // Is any lane within the k-th best (a lane at the same
                    // distance may still win on its index)? An OR of
                    // compares, which vectorises; most blocks stop here.
                    if !acc.iter().fold(false, |near, &a| near | (a <= worst)) {
                        continue;
                    }
                    // Those lanes, as a bit mask.
                    let mut near = acc
                        .iter()
                        .enumerate()
                        .fold(0u32, |m, (i, &a)| m | (u32::from(a <= worst) << i));
                    while near != 0 {
                        let lane = near.trailing_zeros() as usize;
                        near &= near - 1;
                        if ids[lane] != u32::MAX {
                            insert(&mut scratch.best, k, (acc[lane], ids[lane]));
                        }
                    }
                }
                continue;
            }
            let (l, r) = (n.first, n.count);
            let (bl, br) = (self.box_distance(l, query), self.box_distance(r, query));
            // Farther child first on the stack, so the nearer pops first.
            if bl <= br {
                scratch.stack.push((br, r));
                scratch.stack.push((bl, l));
            } else {
                scratch.stack.push((bl, l));
                scratch.stack.push((br, r));
            }
        }
    }

    /// Squared distance from `query` to the box of `node` ([`box_distance`]).
    #[inline]
    fn box_distance(&self, node: u32, query: &[f32; D]) -> f32 {
        let n = &self.nodes[node as usize];
        box_distance(&n.lo, &n.hi, query)
    }
}

/// The coordinates of the (at most eight) points `chunk` as `D` rows of
/// eight lanes, one lane per point; the lanes beyond them at `far`.
pub(crate) fn lanes<const D: usize>(points: &[[f32; D]], chunk: &[u32], far: f32) -> [[f32; 8]; D] {
    let mut lanes = [[far; 8]; D];
    for (l, &i) in chunk.iter().enumerate() {
        for (row, &v) in lanes.iter_mut().zip(&points[i as usize]) {
            row[l] = v;
        }
    }
    lanes
}

/// The bounding box of `points[members]` over their first `B` coordinates.
pub(crate) fn bounding_box<const D: usize, const B: usize>(
    points: &[[f32; D]],
    members: &[u32],
) -> ([f32; B], [f32; B]) {
    let mut lo = [f32::INFINITY; B];
    let mut hi = [f32::NEG_INFINITY; B];
    for &i in members {
        for ((l, h), &v) in lo.iter_mut().zip(&mut hi).zip(&points[i as usize]) {
            *l = l.min(v);
            *h = h.max(v);
        }
    }
    (lo, hi)
}

/// Squared distance from `query` to the box `lo..hi` over the box's
/// coordinates: a lower bound of every point's in it (each term is at most
/// the point's).
#[inline]
pub(crate) fn box_distance(lo: &[f32], hi: &[f32], query: &[f32]) -> f32 {
    let mut d = 0.0f32;
    for ((lo, hi), x) in lo.iter().zip(hi).zip(query) {
        let gap = (lo - x).max(x - hi).max(0.0);
        d += gap * gap;
    }
    d
}

/// Splits `order` at the median of the widest of the first `lo.len()`
/// coordinates (the first of equals; ties by index), the smaller half
/// first; returns the median's position.
pub(crate) fn split_widest<const D: usize>(
    points: &[[f32; D]],
    order: &mut [u32],
    lo: &[f32],
    hi: &[f32],
) -> usize {
    let mut axis = 0;
    for a in 1..lo.len().min(D) {
        if hi[a] - lo[a] > hi[axis] - lo[axis] {
            axis = a;
        }
    }
    let mid = order.len() / 2;
    order.select_nth_unstable_by(mid, |&a, &b| {
        points[a as usize][axis]
            .total_cmp(&points[b as usize][axis])
            .then(a.cmp(&b))
    });
    mid
}

/// Inserts `c` into `best` (ascending by distance then index), keeping at
/// most `k`: shifted in from the end, where most candidates land (a
/// `Vec::insert` calls `memmove` for a few bytes, which held a tenth of a
/// query).
#[inline]
fn insert(best: &mut Vec<(f32, u32)>, k: usize, c: (f32, u32)) {
    let key = |a: &(f32, u32)| (a.0, a.1);
    if c.0.is_nan() {
        return;
    }
    if best.len() == k {
        if key(&c) >= key(&best[k - 1]) {
            return;
        }
        best.pop();
    }
    best.push(c);
    let mut i = best.len() - 1;
    while i > 0 && key(&best[i - 1]) > key(&c) {
        best[i] = best[i - 1];
        i -= 1;
    }
    best[i] = c;
}

#[cfg(test)]
mod tests {
    use super::*;

    fn points<const D: usize>(n: usize, seed: u64, grid: bool) -> Vec<[f32; D]> {
        let mut s = seed.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
        (0..n)
            .map(|_| {
                std::array::from_fn(|_| {
                    s ^= s << 13;
                    s ^= s >> 7;
                    s ^= s << 17;
                    let v = (s % 10_000) as f32 / 10_000.0;
                    // A coarse grid makes many exact ties.
                    if grid { (v * 4.0).floor() / 4.0 } else { v }
                })
            })
            .collect()
    }

    fn brute<const D: usize>(pts: &[[f32; D]], q: &[f32; D], k: usize) -> Vec<(f32, u32)> {
        let mut all: Vec<(f32, u32)> = pts
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let d = p
                    .iter()
                    .zip(q)
                    .map(|(a, b)| (a - b) * (a - b))
                    .fold(0.0f32, |acc, t| acc + t);
                (d, i as u32)
            })
            .collect();
        all.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        all.truncate(k);
        all
    }

    #[test]
    fn equals_a_sorted_scan_bit_for_bit_with_and_without_ties() {
        for (n, grid) in [
            (1usize, false),
            (7, false),
            (300, false),
            (5000, false),
            (2000, true),
        ] {
            let pts = points::<8>(n, n as u64, grid);
            let index = Knn::new(&pts);
            let mut scratch = KnnScratch::default();
            for (qi, q) in points::<8>(25, 99, grid).iter().enumerate() {
                for k in [1usize, 5, 24, 40] {
                    let fast = index.nearest(q, k, &mut scratch).to_vec();
                    assert_eq!(
                        fast,
                        brute(&pts, q, k),
                        "n {n} grid {grid} query {qi} k {k}"
                    );
                }
            }
        }
    }

    #[test]
    fn other_dimensions_and_empty() {
        let pts = points::<3>(500, 3, false);
        let index = Knn::new(&pts);
        let mut scratch = KnnScratch::default();
        let q = [0.5f32, 0.25, 0.75];
        assert_eq!(
            index.nearest(&q, 10, &mut scratch).to_vec(),
            brute(&pts, &q, 10)
        );
        let empty = Knn::<4>::new(&[]);
        assert!(empty.is_empty());
        assert!(empty.nearest(&[0.0; 4], 3, &mut scratch).is_empty());
    }
}
