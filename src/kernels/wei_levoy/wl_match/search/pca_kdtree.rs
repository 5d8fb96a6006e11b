//! Approximate search: principal components of the exemplar neighbourhoods
//! (faer thin SVD of a centred sample, sequential), an exact kd-tree
//! over the leading components, and the nearest candidates in that space
//! re-ranked by the exact distance in the full space.
//!
//! Texture neighbourhoods concentrate their variance in a few components, so
//! the true nearest neighbour is usually among the nearest few in PCA space;
//! it is not guaranteed (the leading-component distance is only a lower
//! bound of the full one).

use faer::Mat;
use faer::Par;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::svd::{self, ComputeSvdVectors};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;
use rayon::prelude::*;

use super::{Match, NeighbourhoodSearch, rerank};
use crate::kernels::knn::{Knn, KnnScratch};
use crate::kernels::wei_levoy::wl_match::features::FeatureMatrix;

/// Dimensions of the kd-tree (kept components, zero padded).
pub(crate) const TREE_DIMS: usize = 8;
/// Rows sampled for the PCA fit at most.
pub(crate) const SAMPLE: usize = 4096;

/// PCA + kd-tree search.
pub struct PcaKdTree {
    features: FeatureMatrix,
    mean: Vec<f32>,
    /// Kept components, `components × dim`, row-major.
    basis: Vec<f32>,
    components: usize,
    /// `None` without rows or values (every row is then a candidate).
    tree: Option<Knn<TREE_DIMS>>,
    candidates: usize,
}

impl PcaKdTree {
    /// Fits `dims` (clamped to `1..=8` and the dimension) components on a
    /// sample of at most 4096 rows drawn with `seed`, and indexes every row.
    pub fn new(features: FeatureMatrix, dims: usize, candidates: usize, seed: u64) -> Self {
        let dim = features.dim;
        let rows = features.rows();
        let components = dims.clamp(1, TREE_DIMS).min(dim.max(1));
        let (mean, basis) = fit(&features, components, seed);
        let project_row = |r: &[f32]| project(r, &mean, &basis, components);
        let points: Vec<[f32; TREE_DIMS]> = (0..rows)
            .into_par_iter()
            .map(|i| project_row(features.row(i)))
            .collect();
        let tree = (rows > 0 && dim > 0).then(|| Knn::new(&points));
        Self {
            features,
            mean,
            basis,
            components,
            tree,
            candidates: candidates.max(1),
        }
    }
}

/// Mean and the leading `components` right singular vectors of a centred
/// sample (rows of the basis, each `dim` long).
#[doc(hidden)]
pub fn fit(features: &FeatureMatrix, components: usize, seed: u64) -> (Vec<f32>, Vec<f32>) {
    let (dim, rows) = (features.dim, features.rows());
    let mut basis = vec![0.0f32; components * dim];
    if rows == 0 || dim == 0 {
        return (vec![0.0; dim], basis);
    }
    let m = rows.min(SAMPLE);
    let mut idx: Vec<u32> = (0..rows as u32).collect();
    let mut rng = Pcg64Mcg::seed_from_u64(seed);
    for i in 0..m {
        let j = rng.random_range(i..rows);
        idx.swap(i, j);
    }
    let sample = &idx[..m];
    let mut mean = vec![0.0f64; dim];
    for &r in sample {
        for (a, v) in mean.iter_mut().zip(features.row(r as usize)) {
            *a += *v as f64;
        }
    }
    mean.iter_mut().for_each(|a| *a /= m as f64);
    let a = Mat::<f64>::from_fn(m, dim, |i, j| {
        features.row(sample[i] as usize)[j] as f64 - mean[j]
    });
    let size = m.min(dim);
    let mut s = faer::diag::Diag::<f64>::zeros(size);
    let mut v = Mat::<f64>::zeros(dim, size);
    let scratch = svd::svd_scratch::<f64>(
        m,
        dim,
        ComputeSvdVectors::No,
        ComputeSvdVectors::Thin,
        Par::Seq,
        Default::default(),
    );
    let ok = svd::svd(
        a.as_ref(),
        s.as_mut(),
        None,
        Some(v.as_mut()),
        Par::Seq,
        MemStack::new(&mut MemBuffer::new(scratch)),
        Default::default(),
    )
    .is_ok();
    crate::kernels::simd_state::after_faer();
    if ok {
        for c in 0..components.min(size) {
            for r in 0..dim {
                basis[c * dim + r] = v[(r, c)] as f32;
            }
        }
    } else {
        // No convergence: fall back to the first coordinates.
        for c in 0..components.min(dim) {
            basis[c * dim + c] = 1.0;
        }
    }
    (mean.into_iter().map(|x| x as f32).collect(), basis)
}

/// The leading `components` coordinates of `row` in the basis: each
/// `Σ_j (row_j − mean_j)·basis_cj`, summed in `j` order from −0 (as
/// `Iterator::sum`), the components side by side so their sums run in
/// parallel rather than one dependent chain after another.
#[inline]
#[doc(hidden)]
pub fn project(row: &[f32], mean: &[f32], basis: &[f32], components: usize) -> [f32; TREE_DIMS] {
    let dim = row.len();
    let mut out = [-0.0f32; TREE_DIMS];
    let kept = &mut out[..components.min(TREE_DIMS)];
    for (j, (x, m)) in row.iter().zip(mean).enumerate() {
        let d = x - m;
        for (c, o) in kept.iter_mut().enumerate() {
            *o += d * basis[c * dim + j];
        }
    }
    for o in out.iter_mut().skip(components) {
        *o = 0.0;
    }
    out
}

impl NeighbourhoodSearch for PcaKdTree {
    fn search(&self, queries: &[f32], out: &mut [Match]) {
        let dim = self.features.dim;
        let rows = self.features.rows() as u32;
        if dim == 0 {
            out.fill(Match {
                index: 0,
                distance: 0.0,
            });
            return;
        }
        let k = self.candidates.min(rows as usize).max(1);
        let mut scratch = KnnScratch::default();
        for (q, o) in queries.chunks_exact(dim).zip(out.iter_mut()) {
            *o = match &self.tree {
                Some(tree) => {
                    let p = project(q, &self.mean, &self.basis, self.components);
                    let found = tree.nearest(&p, k, &mut scratch);
                    rerank(&self.features, q, found.iter().map(|&(_, i)| i))
                }
                None => rerank(&self.features, q, 0..rows),
            };
        }
    }

    fn dim(&self) -> usize {
        self.features.dim
    }

    fn len(&self) -> usize {
        self.features.rows()
    }
}
