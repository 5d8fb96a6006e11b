//! (1+ε)-approximate k nearest neighbours in PCA space (Zelinka & Garland
//! 2004, §4.2; the paper used Mount's ANN with ε = 10%), for all points at
//! once. Two searches, both meeting the ANN guarantee that the i-th returned
//! distance is at most `1 + ε` times the true i-th nearest distance:
//!
//! - [`AnnSearch::KdTree`]: a kiddo kd-tree indexes the first [`TREE_DIMS`]
//!   PCA coordinates (zero padded when there are fewer); kiddo is fast at low
//!   dimension and degrades to brute force beyond ~10. PCA coordinates are
//!   orthonormal, so the distance over the leading coordinates is a lower
//!   bound of the full PCA distance. Candidates are drawn from the tree in
//!   increasing order of that bound, their full distances computed, and the
//!   search stops once the next bound times `1 + ε` reaches the current m-th
//!   best full distance ("filter and refine"); no unseen point can then beat
//!   the m-th best by more than the factor `1 + ε`. When a batch of candidates
//!   runs out first, a four times larger one is requested. Exact when all
//!   components fit in the tree.
//! - [`AnnSearch::Exhaustive`]: blocked brute force, distances from one faer
//!   matrix product per block (`|q|² + |p|² − 2 q·p`), the `m` best re-ranked
//!   with directly computed distances. Exact up to f32 rounding, hence within
//!   any ε. At the 20–60 components natural textures need, the lower bound of
//!   the kd-tree search is loose and this is much faster.
//!
//! [`AnnSearch::Auto`] uses the kd-tree when there are at most [`TREE_DIMS`]
//! components and at least [`KD_MIN_POINTS`] points, the exhaustive search
//! otherwise. Measured on one core: at 128² pixels the exhaustive search takes
//! about 0.1–0.2 s whatever the dimension and the kd-tree is no faster even at
//! 3 components; at 256² the kd-tree wins below ~8 components (1.2 s against
//! 1.9 s) and loses badly above (19 s against 3.6 s at 33 components).
//!
//! Both run in parallel over fixed blocks of queries with sequential inner
//! work, so results do not depend on the thread count.

use std::num::NonZeroUsize;

use faer::{Accum, MatMut, MatRef, Par};
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use rayon::prelude::*;

use crate::kernels::dist2;
use crate::progress::Progress;

/// Number of leading PCA coordinates indexed by the kd-tree.
pub const TREE_DIMS: usize = 8;
/// Fewest points for which [`AnnSearch::Auto`] picks the kd-tree.
pub const KD_MIN_POINTS: usize = 32768;

/// Which nearest-neighbour search the analysis uses.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum AnnSearch {
    /// The kd-tree for large exemplars whose components all fit in it, else
    /// exhaustive (see the module docs).
    #[default]
    Auto,
    /// Filter and refine over a kiddo kd-tree on the leading components.
    KdTree,
    /// Blocked brute force (exact).
    Exhaustive,
}

/// Queries per parallel task, fixed so results do not depend on the thread
/// count.
const QUERY_BLOCK: usize = 256;
/// Points per matrix-product tile of the exhaustive search (256: a tile of
/// scores, 256 × 256, stays in L2 between the product and its scan; 143 ms
/// against 152 at 512 and 166 at 1024 for the stones analysis).
pub const POINT_TILE: usize = 256;

/// The `m` approximate nearest neighbours (itself included, at distance 0)
/// of every point of `points` (rows of `dim`, row-major), nearest first: row
/// `i` of the result holds `min(m, n)` entries starting at `i · min(m, n)`.
/// `eps >= 0` is the ANN tolerance ε.
///
/// Preconditions: `dim > 0`, at least one point, finite coordinates.
pub fn all_knn(
    points: &[f32],
    dim: usize,
    m: usize,
    eps: f32,
    search: AnnSearch,
) -> Vec<Neighbour> {
    all_knn_with_progress(points, dim, m, eps, search, &Progress::hidden())
}

/// [`all_knn`], advancing `progress` by one step per point whose
/// neighbours are found (a query block at a time).
pub fn all_knn_with_progress(
    points: &[f32],
    dim: usize,
    m: usize,
    eps: f32,
    search: AnnSearch,
    progress: &Progress,
) -> Vec<Neighbour> {
    let knn = KnnSearch::new(points, dim, m, eps, search);
    let m = knn.m();
    let mut out = vec![
        Neighbour {
            index: 0,
            dist2: 0.0
        };
        knn.len() * m
    ];
    if m == 0 {
        return out;
    }
    out.par_chunks_mut(QUERY_BLOCK * m)
        .enumerate()
        .for_each(|(b, o)| {
            knn.block(b, o);
            progress.inc((o.len() / m) as u64);
        });
    out
}

/// The search of [`all_knn`] one block of [`QUERY_BLOCK`] queries at a
/// time ([`KnnSearch::block`]), so a caller can use each block's
/// neighbours and drop them (the analysis filters them at once instead of
/// holding `m` neighbours of every pixel).
pub struct KnnSearch<'a> {
    points: &'a [f32],
    /// Per point, `|p|²` (the exhaustive search's augmented column),
    /// computed once rather than per block of queries; empty with the tree.
    norms: Vec<f32>,
    dim: usize,
    n: usize,
    m: usize,
    eps: f32,
    tree: Option<AnnIndex<'a>>,
}

impl<'a> KnnSearch<'a> {
    /// Prepares the search of [`all_knn`] (builds the kd-tree when `search`
    /// picks it).
    ///
    /// Preconditions: as [`all_knn`].
    pub fn new(points: &'a [f32], dim: usize, m: usize, eps: f32, search: AnnSearch) -> Self {
        let n = points.len() / dim;
        let kd = match search {
            AnnSearch::Auto => dim <= TREE_DIMS && n >= KD_MIN_POINTS,
            AnnSearch::KdTree => true,
            AnnSearch::Exhaustive => false,
        };
        let m = m.min(n);
        let norms = if kd || m == 0 {
            Vec::new()
        } else {
            points
                .par_chunks_exact(dim)
                .map(|p| p.iter().map(|x| x * x).sum())
                .collect()
        };
        Self {
            points,
            norms,
            dim,
            n,
            m,
            eps,
            tree: (kd && m > 0).then(|| AnnIndex::new(points, dim)),
        }
    }

    /// Whether the kd-tree is used (else the exhaustive search).
    pub fn uses_tree(&self) -> bool {
        self.tree.is_some()
    }

    /// Points searched (and queried).
    pub fn len(&self) -> usize {
        self.n
    }

    /// Whether there are no points.
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// Neighbours per query: `min(m, n)`.
    pub fn m(&self) -> usize {
        self.m
    }

    /// Queries per block.
    pub const BLOCK: usize = QUERY_BLOCK;

    /// Blocks of queries.
    pub fn blocks(&self) -> usize {
        self.n.div_ceil(QUERY_BLOCK)
    }

    /// The neighbours of queries `b·BLOCK ..` (as many as `out` holds rows
    /// of [`Self::m`]) into `out`, each row nearest first.
    pub fn block(&self, b: usize, out: &mut [Neighbour]) {
        let m = self.m;
        if m == 0 {
            return;
        }
        match &self.tree {
            Some(index) => {
                let mut list = Vec::with_capacity(m);
                for (i, row) in out.chunks_exact_mut(m).enumerate() {
                    index.knn(b * QUERY_BLOCK + i, m, self.eps, &mut list);
                    row.copy_from_slice(&list);
                }
            }
            None => exhaustive_block(self.points, &self.norms, self.dim, m, b, out),
        }
    }
}

/// Blocked brute-force k nearest neighbours of the queries of block `b`
/// into `out` (`m` per query).
///
/// Ranking uses the score `|p|² − 2 q·p` (the squared distance minus the
/// constant `|q|²`), obtained for a whole tile by one product of the augmented
/// matrices `[−2q, 1]` and `[p, |p|²]` (a tile's `[p, |p|²]` built as it is
/// visited from the points and their `norms`, not held for all points);
/// the scan over a tile is then a
/// vectorised compare against the current m-th best. Tiles are visited
/// starting with the query block's own (image neighbours are similar, so the
/// threshold drops fast).
fn exhaustive_block(
    points: &[f32],
    norms: &[f32],
    dim: usize,
    m: usize,
    b: usize,
    o: &mut [Neighbour],
) {
    let n = points.len() / dim;
    let da = dim + 1;
    let tiles = n.div_ceil(POINT_TILE);
    let q0 = b * QUERY_BLOCK;
    let qn = o.len() / m;
    let mut aug_q = vec![0.0f32; qn * da];
    for (a, p) in aug_q
        .chunks_exact_mut(da)
        .zip(points[q0 * dim..].chunks_exact(dim))
    {
        for (x, y) in a.iter_mut().zip(p) {
            *x = -2.0 * y;
        }
        a[dim] = 1.0;
    }
    let q = MatRef::from_row_major_slice(&aug_q, qn, da);
    let mut aug_p = vec![0.0f32; POINT_TILE.min(n) * da];
    let mut g = vec![0.0f32; qn * POINT_TILE.min(n)];
    let mut lists: Vec<Vec<Neighbour>> = vec![Vec::with_capacity(4 * m); qn];
    let mut thrs = vec![f32::INFINITY; qn];
    let first = q0 / POINT_TILE;
    for t in 0..tiles {
        let t0 = ((first + t) % tiles) * POINT_TILE;
        let tn = POINT_TILE.min(n - t0);
        for ((a, p), &norm) in aug_p[..tn * da]
            .chunks_exact_mut(da)
            .zip(points[t0 * dim..(t0 + tn) * dim].chunks_exact(dim))
            .zip(&norms[t0..t0 + tn])
        {
            a[..dim].copy_from_slice(p);
            a[dim] = norm;
        }
        let p = MatRef::from_row_major_slice(&aug_p[..tn * da], tn, da);
        let gm = MatMut::from_row_major_slice_mut(&mut g[..qn * tn], qn, tn);
        faer::linalg::matmul::matmul(gm, Accum::Replace, q, p.transpose(), 1.0f32, Par::Seq);
        crate::kernels::simd_state::after_faer();
        scan_tile(&g[..qn * tn], tn, t0, &mut lists, &mut thrs, m);
    }
    // Re-rank with directly computed distances (the expansion above loses
    // precision for near neighbours).
    for (i, (list, row)) in lists.iter_mut().zip(o.chunks_exact_mut(m)).enumerate() {
        prune(list, m);
        let qi = &points[(q0 + i) * dim..][..dim];
        for nb in list.iter_mut() {
            nb.dist2 = dist2(qi, &points[nb.index as usize * dim..][..dim]);
        }
        list.sort_by(|a, b| a.dist2.total_cmp(&b.dist2).then(a.index.cmp(&b.index)));
        row.copy_from_slice(list);
    }
}

/// Scans a tile of scores (`g`: one row of `tn` per query, points from
/// `t0` on) into the queries' candidate lists ([`scan`]).
///
/// Compiled twice, for the baseline and for AVX2 (chosen by the processor):
/// compares only, so the results are identical; AVX2 tests sixteen scores
/// in two instructions instead of four.
fn scan_tile(
    g: &[f32],
    tn: usize,
    t0: usize,
    lists: &mut [Vec<Neighbour>],
    thrs: &mut [f32],
    m: usize,
) {
    #[cfg(target_arch = "x86_64")]
    {
        if std::is_x86_feature_detected!("avx2") {
            // SAFETY: the processor supports AVX2 (checked just above).
            unsafe { scan_tile_avx2(g, tn, t0, lists, thrs, m) };
            return;
        }
    }
    scan_tile_generic(g, tn, t0, lists, thrs, m);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn scan_tile_avx2(
    g: &[f32],
    tn: usize,
    t0: usize,
    lists: &mut [Vec<Neighbour>],
    thrs: &mut [f32],
    m: usize,
) {
    scan_tile_generic(g, tn, t0, lists, thrs, m);
}

#[inline(always)]
fn scan_tile_generic(
    g: &[f32],
    tn: usize,
    t0: usize,
    lists: &mut [Vec<Neighbour>],
    thrs: &mut [f32],
    m: usize,
) {
    for (row, (list, thr)) in g.chunks_exact(tn).zip(lists.iter_mut().zip(thrs)) {
        let mut chunks = row.chunks_exact(16);
        let mut j0 = t0;
        for c in &mut chunks {
            let mut any = false;
            for &x in c {
                any |= x < *thr;
            }
            if any {
                scan(c, j0, list, m, thr);
            }
            j0 += 16;
        }
        scan(chunks.remainder(), j0, list, m, thr);
    }
}

/// Pushes the scores of `c` (points from `j0` on) that beat `thr`; when the
/// buffer holds `4m`, keeps its `m` best and lowers `thr` to the worst of them.
#[inline(always)]
fn scan(c: &[f32], j0: usize, list: &mut Vec<Neighbour>, m: usize, thr: &mut f32) {
    // The scores below the threshold as a bit mask (compares that
    // vectorise), then only those.
    let mut below = c
        .iter()
        .enumerate()
        .fold(0u32, |mask, (jj, &x)| mask | (u32::from(x < *thr) << jj));
    while below != 0 {
        let jj = below.trailing_zeros() as usize;
        below &= below - 1;
        let x = c[jj];
        // The threshold may have dropped since the mask was taken.
        if x < *thr {
            list.push(Neighbour {
                index: (j0 + jj) as u32,
                dist2: x,
            });
            if list.len() == 4 * m {
                prune(list, m);
                *thr = list[m - 1].dist2;
            }
        }
    }
}

/// Keeps the `m` best of `list` by (score, index), the worst of them last.
fn prune(list: &mut Vec<Neighbour>, m: usize) {
    if list.len() > m {
        list.select_nth_unstable_by(m - 1, |a, b| {
            a.dist2.total_cmp(&b.dist2).then(a.index.cmp(&b.index))
        });
        list.truncate(m);
    }
    if let Some(w) = (0..list.len()).max_by(|&a, &b| {
        list[a]
            .dist2
            .total_cmp(&list[b].dist2)
            .then(list[a].index.cmp(&list[b].index))
    }) {
        let last = list.len() - 1;
        list.swap(w, last);
    }
}

/// An index over points in PCA space.
pub struct AnnIndex<'a> {
    tree: ImmutableKdTree<f32, TREE_DIMS>,
    points: &'a [f32],
    dim: usize,
    len: usize,
}

/// One neighbour: the point's row and its squared distance in PCA space.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Neighbour {
    /// Row of the point.
    pub index: u32,
    /// Squared Euclidean distance over all PCA coordinates.
    pub dist2: f32,
}

fn prefix(p: &[f32]) -> [f32; TREE_DIMS] {
    let mut a = [0.0f32; TREE_DIMS];
    let n = p.len().min(TREE_DIMS);
    a[..n].copy_from_slice(&p[..n]);
    a
}

impl<'a> AnnIndex<'a> {
    /// Builds the index over `points` (rows of `dim`, row-major). Sequential
    /// construction, so the tree does not depend on the thread count.
    ///
    /// Preconditions: `dim > 0`, at least one point, all coordinates finite.
    pub fn new(points: &'a [f32], dim: usize) -> Self {
        let len = points.len() / dim;
        let prefixes: Vec<[f32; TREE_DIMS]> = points.chunks_exact(dim).map(prefix).collect();
        let tree = ImmutableKdTree::new_from_slice(&prefixes)
            .expect("finite, non-empty points build a kd-tree");
        Self {
            tree,
            points,
            dim,
            len,
        }
    }

    /// Number of indexed points.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether the index is empty.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The `m` approximate nearest neighbours of indexed point `query`
    /// (including itself, at distance 0), nearest first, into `out` (cleared).
    /// `eps` is the ANN tolerance ε ≥ 0.
    pub fn knn(&self, query: usize, m: usize, eps: f32, out: &mut Vec<Neighbour>) {
        out.clear();
        let m = m.min(self.len);
        if m == 0 {
            return;
        }
        let q = &self.points[query * self.dim..][..self.dim];
        let qp = prefix(q);
        let tail = self.dim.saturating_sub(TREE_DIMS);
        let shrink = 1.0 / ((1.0 + eps) * (1.0 + eps));
        let mut batch = (2 * m).min(self.len);
        loop {
            out.clear();
            let cands = self
                .tree
                .query(&qp)
                .nearest_n::<SquaredEuclidean<f32>>(NonZeroUsize::new(batch).expect("batch > 0"))
                .execute();
            let mut done = false;
            for c in &cands {
                if out.len() == m && c.distance >= out[m - 1].dist2 * shrink {
                    done = true;
                    break;
                }
                let i = c.item as usize;
                let mut d2 = c.distance;
                if tail > 0 {
                    let p = &self.points[i * self.dim + TREE_DIMS..][..tail];
                    d2 += dist2(&q[TREE_DIMS..], p);
                }
                insert(
                    out,
                    m,
                    Neighbour {
                        index: c.item,
                        dist2: d2,
                    },
                );
            }
            if done || batch >= self.len {
                return;
            }
            batch = (batch * 4).min(self.len);
        }
    }
}

/// Inserts into a list sorted by (distance, index), keeping at most `m`.
#[inline]
fn insert(list: &mut Vec<Neighbour>, m: usize, n: Neighbour) {
    let key = |a: &Neighbour| (a.dist2, a.index);
    if list.len() == m && key(&n) >= key(&list[m - 1]) {
        return;
    }
    let pos = list.partition_point(|a| key(a) < key(&n));
    if list.len() == m {
        list.pop();
    }
    list.insert(pos, n);
}
