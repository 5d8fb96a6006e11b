//! Principal component analysis of neighbourhood vectors (Zelinka & Garland
//! 2004, §4.2): components from a random sample of the vectors, enough of them
//! to explain a given fraction of the sample's variance.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::svd::{self, ComputeSvdVectors};
use faer::{Accum, Mat, MatMut, MatRef, Par};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;
use rayon::prelude::*;

use super::JumpMapError;

/// Rows projected per parallel task; fixed so results do not depend on the
/// thread count.
pub const PROJECT_CHUNK: usize = 256;

/// A fitted PCA basis.
#[derive(Clone, Debug, PartialEq)]
pub struct Pca {
    /// Input dimension.
    pub dim: usize,
    /// Mean of the sample, `dim` values.
    pub mean: Vec<f32>,
    /// Kept components, column-major `dim × components` (orthonormal columns,
    /// largest variance first).
    pub basis: Vec<f32>,
    /// Number of kept components.
    pub components: usize,
    /// Fraction of the sample's variance the kept components explain.
    pub explained: f64,
    /// Number of vectors in the sample.
    pub sample_size: usize,
}

/// The rows of a PCA sample of `n` vectors: `max(round(fraction·n),
/// min(256, n))` distinct rows (at most `n`), the first entries of a
/// partial Fisher-Yates shuffle by a PCG seeded with `seed`, in that order.
pub fn sample_rows(n: usize, fraction: f32, seed: u64) -> Vec<u32> {
    let m = sample_size(n, fraction);
    // Partial Fisher-Yates: the first m entries become a uniform sample.
    let mut idx: Vec<u32> = (0..n as u32).collect();
    let mut rng = Pcg64Mcg::seed_from_u64(seed);
    for i in 0..m {
        let j = rng.random_range(i..n);
        idx.swap(i, j);
    }
    idx.truncate(m);
    idx.shrink_to_fit();
    idx
}

/// Rows in the PCA sample of `n` vectors ([`sample_rows`]).
pub fn sample_size(n: usize, fraction: f32) -> usize {
    ((fraction as f64 * n as f64).round() as usize)
        .max(n.min(256))
        .min(n)
}

/// Bytes [`fit_sample`] holds for `m` rows of `dim` beside the sample
/// itself: the centred sample in `f64`, the right singular vectors, the
/// singular values and faer's SVD workspace (asked of faer, so it follows
/// its algorithm: with more dimensions than rows it is several times the
/// sample, 1.8 GB for 1716 rows of 8649 dimensions).
pub fn fit_bytes(m: usize, dim: usize) -> u64 {
    if m == 0 || dim == 0 {
        return 0;
    }
    let size = m.min(dim) as u64;
    let scratch = svd::svd_scratch::<f64>(
        m,
        dim,
        ComputeSvdVectors::No,
        ComputeSvdVectors::Thin,
        Par::Seq,
        Default::default(),
    )
    .unaligned_bytes_required() as u64;
    let (m, dim) = (m as u64, dim as u64);
    (m * dim * 8)
        .saturating_add(dim * size * 8)
        .saturating_add(size * 8 + dim * 8)
        .saturating_add(scratch)
}

/// Fits the components of `vectors` (`n` rows of `dim`, row-major).
///
/// A random sample of `max(round(fraction·n), min(256, n))` distinct rows is
/// drawn with a PCG seeded by `seed` ([`sample_rows`]) and fitted by
/// [`fit_sample`].
///
/// Preconditions: `dim > 0`, `vectors.len()` a non-zero multiple of `dim`,
/// `fraction` and `variance` in `(0, 1]`.
///
/// # Errors
/// [`JumpMapError::Pca`] when the SVD does not converge.
pub fn fit(
    vectors: &[f32],
    dim: usize,
    fraction: f32,
    variance: f32,
    max_components: usize,
    seed: u64,
) -> Result<Pca, JumpMapError> {
    let n = vectors.len() / dim;
    let sample: Vec<f32> = sample_rows(n, fraction, seed)
        .iter()
        .flat_map(|&r| &vectors[r as usize * dim..][..dim])
        .copied()
        .collect();
    fit_sample(&sample, dim, variance, max_components)
}

/// Fits the components of a sample of vectors (`m` rows of `dim`,
/// row-major, in sample order): the sample is centred and decomposed by a
/// thin SVD (faer, sequential so the result never depends on the thread
/// count); the fewest leading components whose squared singular values
/// reach `variance` of the total are kept, at least 1 and at most
/// `max_components`. A sample with no variance keeps one (arbitrary)
/// component. Memory: the sample in `f64` (`8·m·dim` bytes) and the SVD's
/// work ([`fit_bytes`]).
///
/// Preconditions: `dim > 0`, `sample.len()` a non-zero multiple of `dim`,
/// `variance` in `(0, 1]`.
///
/// # Errors
/// [`JumpMapError::Pca`] when the SVD does not converge.
pub fn fit_sample(
    sample: &[f32],
    dim: usize,
    variance: f32,
    max_components: usize,
) -> Result<Pca, JumpMapError> {
    let m = sample.len() / dim;
    let mut mean = vec![0.0f64; dim];
    for row in sample.chunks_exact(dim) {
        for (a, v) in mean.iter_mut().zip(row) {
            *a += *v as f64;
        }
    }
    for a in &mut mean {
        *a /= m as f64;
    }
    let a = Mat::<f64>::from_fn(m, dim, |i, j| sample[i * dim + j] as f64 - mean[j]);
    let size = m.min(dim);
    let mut s = faer::diag::Diag::<f64>::zeros(size);
    let mut v = Mat::<f64>::zeros(dim, size);
    let par = Par::Seq;
    let scratch = svd::svd_scratch::<f64>(
        m,
        dim,
        ComputeSvdVectors::No,
        ComputeSvdVectors::Thin,
        par,
        Default::default(),
    );
    let done = svd::svd(
        a.as_ref(),
        s.as_mut(),
        None,
        Some(v.as_mut()),
        par,
        MemStack::new(&mut MemBuffer::new(scratch)),
        Default::default(),
    );
    crate::kernels::simd_state::after_faer();
    done.map_err(|e| JumpMapError::Pca(format!("{e:?}")))?;
    let var: Vec<f64> = s.column_vector().iter().map(|x| x * x).collect();
    let total: f64 = var.iter().sum();
    let cap = max_components.clamp(1, size.max(1));
    let mut components = cap;
    let mut explained = 1.0;
    if total > 0.0 {
        let mut acc = 0.0;
        for (i, x) in var.iter().enumerate() {
            acc += x;
            if acc >= variance as f64 * total || i + 1 == cap {
                components = i + 1;
                explained = acc / total;
                break;
            }
        }
    } else {
        components = 1;
    }
    let mut basis = vec![0.0f32; dim * components];
    for c in 0..components {
        for r in 0..dim {
            basis[c * dim + r] = v[(r, c)] as f32;
        }
    }
    Ok(Pca {
        dim,
        mean: mean.into_iter().map(|x| x as f32).collect(),
        basis,
        components,
        explained,
        sample_size: m,
    })
}

impl Pca {
    /// Projects `vectors` (rows of `dim`) onto the kept components: returns
    /// rows of `components` values, `(v - mean) · basis`. Rows are processed
    /// in parallel in fixed chunks, each by a sequential faer product, so the
    /// output does not depend on the thread count.
    pub fn project(&self, vectors: &[f32]) -> Vec<f32> {
        let n = vectors.len() / self.dim;
        let k = self.components;
        let mut out = vec![0.0f32; n * k];
        let basis = MatRef::from_column_major_slice(&self.basis, self.dim, k);
        out.par_chunks_mut(PROJECT_CHUNK * k)
            .zip(vectors.par_chunks(PROJECT_CHUNK * self.dim))
            .for_each(|(o, v)| {
                let rows = v.len() / self.dim;
                let mut centred = v.to_vec();
                for row in centred.chunks_exact_mut(self.dim) {
                    for (x, m) in row.iter_mut().zip(&self.mean) {
                        *x -= m;
                    }
                }
                let lhs = MatRef::from_row_major_slice(&centred, rows, self.dim);
                let dst = MatMut::from_row_major_slice_mut(o, rows, k);
                faer::linalg::matmul::matmul(dst, Accum::Replace, lhs, basis, 1.0f32, Par::Seq);
                crate::kernels::simd_state::after_faer();
            });
        out
    }
}
