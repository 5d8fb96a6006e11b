//! Nearest-neighbourhood search back-ends (the `FindBestMatch` loop of Wei &
//! Levoy 2001 Table 3): one trait, chosen by [`SearchKind`].
//!
//! - [`Exhaustive`]: every exemplar neighbourhood, exact L2 (blocked matrix
//!   products, then an exact re-rank of the best few).
//! - [`PcaKdTree`]: principal components of the exemplar neighbourhoods, a
//!   kd-tree over the leading ones, the nearest candidates re-ranked by the
//!   exact distance. Approximate.
//! - [`Tsvq`]: tree-structured vector quantisation, as Wei & Levoy 2000 §4
//!   accelerate the search: a binary tree of 2-means clusters, descended
//!   greedily (or best-first over a few leaves). Approximate.
//!
//! Every back-end answers a block of queries sequentially, so results never
//! depend on the thread count. Ties go to the lower exemplar index.

mod exhaustive;
#[doc(hidden)] // `fit` and `project` are benchmarked (benches/roofline.rs).
pub mod pca_kdtree;
mod tsvq;

pub use exhaustive::Exhaustive;
pub use pca_kdtree::PcaKdTree;
pub use tsvq::Tsvq;

use super::features::FeatureMatrix;
use crate::kernels::dist2;

/// The best exemplar neighbourhood for a query.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Match {
    /// Row of the exemplar neighbourhood (its pixel, `y · width + x`).
    pub index: u32,
    /// Exact squared L2 distance to the query.
    pub distance: f32,
}

/// A nearest-neighbourhood search over a fixed set of exemplar vectors.
pub trait NeighbourhoodSearch: Send + Sync {
    /// The best match of each query of `queries` (rows of [`Self::dim`]
    /// values, row-major) into `out` (one per query). Each call runs
    /// sequentially, so answers never depend on the thread count. The
    /// approximate back-ends answer each query on its own; the exhaustive one
    /// preselects candidates with a matrix product whose rounding may depend
    /// on the block's size, which can only matter between near-equal
    /// candidates (the final ranking uses exact distances).
    fn search(&self, queries: &[f32], out: &mut [Match]);

    /// Values per vector.
    fn dim(&self) -> usize;

    /// Exemplar vectors searched.
    fn len(&self) -> usize;

    /// True when there is nothing to search.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// Which search back-end to use, and its parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SearchKind {
    /// Exact exhaustive search.
    Exhaustive,
    /// PCA to `dims` components (at most 16), kd-tree, `candidates` nearest
    /// in PCA space re-ranked exactly.
    PcaKdTree {
        /// Kept principal components, 1..=16.
        dims: usize,
        /// Candidates taken from the tree, ≥ 1.
        candidates: usize,
    },
    /// Tree-structured VQ with leaves of at most `leaf_size` vectors;
    /// `leaves` leaves visited best-first (1: the paper's greedy descent).
    Tsvq {
        /// Largest leaf, ≥ 1.
        leaf_size: usize,
        /// Leaves searched per query, ≥ 1.
        leaves: usize,
    },
}

/// Builds the back-end `kind` over `features`; `seed` drives any sampling.
pub fn build_search(
    kind: SearchKind,
    features: FeatureMatrix,
    seed: u64,
) -> Box<dyn NeighbourhoodSearch> {
    match kind {
        SearchKind::Exhaustive => Box::new(Exhaustive::new(features)),
        SearchKind::PcaKdTree { dims, candidates } => {
            Box::new(PcaKdTree::new(features, dims, candidates, seed))
        }
        SearchKind::Tsvq { leaf_size, leaves } => {
            Box::new(Tsvq::new(features, leaf_size, leaves, seed))
        }
    }
}

/// The better of two matches: smaller distance, then lower index.
#[inline]
pub(crate) fn better(a: Match, b: Match) -> bool {
    a.distance < b.distance || (a.distance == b.distance && a.index < b.index)
}

/// Exact best of the rows `candidates` of `features` for `query`.
#[inline]
pub(crate) fn rerank(
    features: &FeatureMatrix,
    query: &[f32],
    candidates: impl IntoIterator<Item = u32>,
) -> Match {
    let mut best = Match {
        index: 0,
        distance: f32::INFINITY,
    };
    for c in candidates {
        let m = Match {
            index: c,
            distance: dist2(query, features.row(c as usize)),
        };
        if better(m, best) {
            best = m;
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pseudo_random(len: usize, seed: u32) -> Vec<f32> {
        let mut s = seed.wrapping_mul(2_654_435_761).wrapping_add(1);
        (0..len)
            .map(|_| {
                s ^= s << 13;
                s ^= s >> 17;
                s ^= s << 5;
                (s % 1000) as f32 / 1000.0
            })
            .collect()
    }

    #[test]
    fn back_ends_find_planted_rows_and_exhaustive_is_exact() {
        let (rows, dim) = (700usize, 27usize);
        // Clustered data, like texture neighbourhoods.
        let centres = pseudo_random(8 * dim, 5);
        let noise = pseudo_random(rows * dim, 9);
        let data: Vec<f32> = (0..rows * dim)
            .map(|i| centres[(i / dim % 8) * dim + i % dim] + 0.2 * noise[i])
            .collect();
        let features = FeatureMatrix { dim, data };
        let queries: Vec<f32> = (0..40)
            .flat_map(|k| {
                let r = (k * 17) % rows;
                let jitter = pseudo_random(dim, 100 + k as u32);
                features
                    .row(r)
                    .iter()
                    .zip(jitter)
                    .map(|(x, j)| x + 0.01 * j)
                    .collect::<Vec<_>>()
            })
            .collect();
        let nq = queries.len() / dim;
        let brute: Vec<Match> = queries
            .chunks_exact(dim)
            .map(|q| rerank(&features, q, 0..rows as u32))
            .collect();
        for kind in [
            SearchKind::Exhaustive,
            SearchKind::PcaKdTree {
                dims: 8,
                candidates: 16,
            },
            SearchKind::Tsvq {
                leaf_size: 8,
                leaves: 4,
            },
        ] {
            let s = build_search(kind, features.clone(), 1);
            assert_eq!((s.dim(), s.len()), (dim, rows));
            let mut out = vec![
                Match {
                    index: 0,
                    distance: 0.0
                };
                nq
            ];
            s.search(&queries, &mut out);
            let mut exact = 0;
            for (k, (m, b)) in out.iter().zip(&brute).enumerate() {
                // Reported distances are exact for the reported row.
                let d = dist2(
                    &queries[k * dim..(k + 1) * dim],
                    features.row(m.index as usize),
                );
                assert!((d - m.distance).abs() <= 1e-5 * d.max(1.0));
                assert!(m.distance >= b.distance - 1e-5);
                exact += (m.index == b.index) as usize;
            }
            if kind == SearchKind::Exhaustive {
                assert_eq!(exact, nq, "exhaustive is exact");
            } else {
                assert!(exact * 10 >= nq * 8, "{kind:?}: {exact} of {nq} exact");
            }
            // Answers do not depend on the block they come in.
            let mut single = out.clone();
            for (k, q) in queries.chunks_exact(dim).enumerate() {
                s.search(q, &mut single[k..k + 1]);
            }
            assert_eq!(single, out, "{kind:?}");
        }
    }
}
