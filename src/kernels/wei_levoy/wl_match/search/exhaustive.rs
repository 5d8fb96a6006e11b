//! Exact exhaustive search: for a block of queries, the score
//! `|p|² − 2 q·p` of every exemplar vector `p` comes from one matrix product
//! of `[−2q, 1]` with `[p, |p|²]` per tile of exemplar vectors (faer's SIMD
//! matrix multiply, sequential within a block), the best few scores of each
//! query are kept, and those are re-ranked by the directly computed distance
//! (the expansion loses precision near the minimum).
//!
//! Work per query: `rows × (dim + 1)` multiply-adds in the product, plus the
//! re-rank; this is the "exhaustive" cost of Wei & Levoy Table 3 lines 14–17.

use faer::{Accum, MatMut, MatRef, Par};

use super::{Match, NeighbourhoodSearch, better, rerank};
use crate::kernels::wei_levoy::wl_match::features::FeatureMatrix;

/// Exemplar vectors per matrix-product tile.
const TILE: usize = 1024;
/// Queries per matrix product (larger blocks are split).
const QUERY_BLOCK: usize = 64;
/// Best scores per query kept for the exact re-rank.
const KEEP: usize = 4;

/// Exhaustive exact L2 search.
pub struct Exhaustive {
    features: FeatureMatrix,
    /// `[p, |p|²]` rows, `dim + 1` values each.
    augmented: Vec<f32>,
}

impl Exhaustive {
    /// Prepares the search over `features`.
    pub fn new(features: FeatureMatrix) -> Self {
        let dim = features.dim;
        let mut augmented = vec![0.0f32; features.rows() * (dim + 1)];
        for (a, p) in augmented
            .chunks_exact_mut(dim + 1)
            .zip(features.data.chunks_exact(dim.max(1)))
        {
            a[..dim].copy_from_slice(p);
            a[dim] = p.iter().map(|x| x * x).sum();
        }
        Self {
            features,
            augmented,
        }
    }
}

impl NeighbourhoodSearch for Exhaustive {
    fn search(&self, queries: &[f32], out: &mut [Match]) {
        let dim = self.features.dim;
        let rows = self.features.rows();
        if rows == 0 {
            return;
        }
        if dim == 0 {
            out.fill(Match {
                index: 0,
                distance: 0.0,
            });
            return;
        }
        let da = dim + 1;
        let mut aug_q = vec![0.0f32; QUERY_BLOCK.min(out.len()) * da];
        let mut scores = vec![0.0f32; QUERY_BLOCK.min(out.len()) * TILE.min(rows)];
        let mut keep: Vec<[(f32, u32); KEEP]> = Vec::new();
        for (qb, ob) in queries
            .chunks(QUERY_BLOCK * dim)
            .zip(out.chunks_mut(QUERY_BLOCK))
        {
            let nq = ob.len();
            for (a, q) in aug_q.chunks_exact_mut(da).zip(qb.chunks_exact(dim)) {
                for (x, y) in a.iter_mut().zip(q) {
                    *x = -2.0 * y;
                }
                a[dim] = 1.0;
            }
            keep.clear();
            keep.resize(nq, [(f32::INFINITY, u32::MAX); KEEP]);
            let lhs = MatRef::from_row_major_slice(&aug_q[..nq * da], nq, da);
            for t0 in (0..rows).step_by(TILE) {
                let tn = TILE.min(rows - t0);
                let rhs =
                    MatRef::from_row_major_slice(&self.augmented[t0 * da..(t0 + tn) * da], tn, da);
                let dst = MatMut::from_row_major_slice_mut(&mut scores[..nq * tn], nq, tn);
                faer::linalg::matmul::matmul(
                    dst,
                    Accum::Replace,
                    lhs,
                    rhs.transpose(),
                    1.0f32,
                    Par::Seq,
                );
                crate::kernels::simd_state::after_faer();
                for (k, best) in keep.iter_mut().enumerate() {
                    let row = &scores[k * tn..(k + 1) * tn];
                    let mut worst = best[KEEP - 1].0;
                    for (j, &s) in row.iter().enumerate() {
                        if s < worst {
                            insert(best, (s, (t0 + j) as u32));
                            worst = best[KEEP - 1].0;
                        }
                    }
                }
            }
            for ((best, q), o) in keep.iter().zip(qb.chunks_exact(dim)).zip(ob.iter_mut()) {
                *o = rerank(
                    &self.features,
                    q,
                    best.iter().filter(|c| c.1 != u32::MAX).map(|c| c.1),
                );
            }
        }
    }

    fn dim(&self) -> usize {
        self.features.dim
    }

    fn len(&self) -> usize {
        self.features.rows()
    }
}

/// Inserts `c` into the ascending list `best`, dropping its last entry.
#[inline]
fn insert(best: &mut [(f32, u32); KEEP], c: (f32, u32)) {
    let mut i = KEEP - 1;
    best[i] = c;
    while i > 0
        && better(
            Match {
                index: best[i].1,
                distance: best[i].0,
            },
            Match {
                index: best[i - 1].1,
                distance: best[i - 1].0,
            },
        )
    {
        best.swap(i, i - 1);
        i -= 1;
    }
}
