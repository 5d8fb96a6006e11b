//! Exact nearest-window search for the result metrics, much faster than the
//! exhaustive scan of [`super::nearest`] and giving the same minimum.
//!
//! Every window (an `n`×`n`×`channels` vector) is projected on the
//! [`AXES`] leading principal axes of a sample of the windows. The axes are
//! orthonormal, so the squared distance between two projections is a lower
//! bound of the squared distance between the windows. The windows are
//! grouped in leaves of at most [`LEAF`] by median splits on the leading
//! [`BOX_AXES`] axes, each leaf with its bounding box there, and pairs of
//! consecutive boxes are bounded again up to one box over all. A query
//! descends that hierarchy depth first, the nearer box of each pair first,
//! and skips a box, or a window, whose projected distance already reaches
//! the best full distance found; it computes the full distance of the
//! other windows directly from the image (with a partial-distance exit per
//! window row). So the minimum is the exhaustive one: the bounds only
//! decide which windows need not be computed, with a margin for the
//! rounding of the projections ([`threshold`]).
//!
//! Texture windows hold most of their variance in a few axes, so a query
//! computes the full distance of a few dozen windows instead of all of
//! them.

use std::ops::Range;

use rayon::prelude::*;
use wide::f32x8;

use crate::image::Image;
use crate::kernels::knn::{bounding_box, box_distance, lanes, split_widest};

/// Principal axes the windows are projected on (fewer when a window has
/// fewer values).
pub const AXES: usize = 16;
/// Leading axes of the leaves' bounding boxes.
pub const BOX_AXES: usize = 8;
/// Most windows per leaf.
pub const LEAF: usize = 64;
/// Windows sampled for the principal axes at most.
const SAMPLE: usize = 1024;
/// Projection of the padding lanes of a leaf's last block: far from any
/// window with values in `[0, 1]`, so they are never computed.
const FAR: f32 = 1.0e15;

/// Windows of an image, indexed for exact nearest-window queries.
#[derive(Clone, Debug)]
pub struct WindowIndex {
    /// Values the windows are read from: rows of `row_stride` values.
    values: Vec<f32>,
    row_stride: usize,
    /// Window side and values per window row (`n · channels`).
    n: usize,
    row_len: usize,
    /// The basis by window value: per value, its weight on each axis (zero
    /// beyond the axes in use).
    basis: Vec<[f32x8; 2]>,
    /// Leaves in splitting order; their blocks of eight windows.
    leaves: Vec<Leaf>,
    /// Boxes over consecutive leaves: level `k + 1` box `i` bounds level
    /// `k` boxes `2i` and `2i + 1` (level 0: the leaves'); the last level
    /// holds one box.
    levels: Vec<Vec<Bounds>>,
    /// Per block: `AXES` rows of eight projected values.
    blocks: Vec<[f32x8; AXES]>,
    /// Per block: the offset in `values` of each lane's window (`usize::MAX`
    /// for padding).
    origins: Vec<[usize; 8]>,
}

/// A box on the leading [`BOX_AXES`] axes.
#[derive(Clone, Copy, Debug)]
struct Bounds {
    lo: [f32; BOX_AXES],
    hi: [f32; BOX_AXES],
}

impl Bounds {
    /// Squared distance from `q` to the box ([`box_distance`]).
    #[inline]
    fn distance(&self, q: &[f32; AXES]) -> f32 {
        box_distance(&self.lo, &self.hi, q)
    }

    /// The smallest box holding both.
    fn union(&self, other: &Bounds) -> Bounds {
        Bounds {
            lo: std::array::from_fn(|a| self.lo[a].min(other.lo[a])),
            hi: std::array::from_fn(|a| self.hi[a].max(other.hi[a])),
        }
    }
}

/// A leaf's blocks of eight windows (its box is in level 0 of
/// [`WindowIndex::levels`]).
#[derive(Clone, Copy, Debug)]
struct Leaf {
    first_block: u32,
    blocks: u32,
}

/// Reusable buffers of a query, one per thread.
#[derive(Clone, Debug, Default)]
pub struct IndexScratch {
    /// Boxes to visit: (bound, level, index).
    stack: Vec<(f32, u32, u32)>,
}

/// Most windows one index holds: an image with more is searched one band
/// of window rows at a time ([`BandedIndex`]), so an index
/// takes at most about 150 MB whatever the image's size.
pub const BAND_WINDOWS: usize = 1 << 20;

/// Bytes an index takes per window at its peak (the projections twice while
/// the leaves are built, the window offsets, the order).
pub const BYTES_PER_WINDOW: usize = 2 * AXES * 4 + 2 * 8 + 4;

/// The bands of window rows `0..rows` (of `columns` windows each) that one
/// index each searches: at most `per_band` windows a band, at least one
/// row.
pub fn bands(rows: usize, columns: usize, per_band: usize) -> Vec<Range<usize>> {
    let per = (per_band / columns.max(1)).max(1);
    (0..rows)
        .step_by(per)
        .map(|start| start..(start + per).min(rows))
        .collect()
}

/// Windows searched band by band ([`bands`]): an image of at most
/// [`BAND_WINDOWS`] windows is one index built once; a larger one is built
/// again one band at a time for each call of [`Self::nearest`], so memory
/// stays bounded whatever the image's size.
pub struct BandedIndex<F: Fn(Range<usize>) -> WindowIndex> {
    bands: Vec<Range<usize>>,
    make: F,
    single: Option<WindowIndex>,
}

impl<F: Fn(Range<usize>) -> WindowIndex> BandedIndex<F> {
    /// The windows of `rows` rows of `columns`, each band's index made by
    /// `make`, bands of at most [`BAND_WINDOWS`] windows.
    pub fn new(rows: usize, columns: usize, make: F) -> Self {
        Self::with_band_windows(rows, columns, BAND_WINDOWS, make)
    }

    /// As [`Self::new`] with bands of at most `per_band` windows.
    pub fn with_band_windows(rows: usize, columns: usize, per_band: usize, make: F) -> Self {
        let bands = bands(rows, columns, per_band);
        let single = (bands.len() == 1).then(|| make(bands[0].clone()));
        Self {
            bands,
            make,
            single,
        }
    }

    /// The smallest squared distance from each query (`dim` values each,
    /// one after another in `queries`) to any window: every query's best so
    /// far lowered by each band in turn (parallel over queries). Bands do
    /// not change the values: each is the minimum over all windows.
    pub fn nearest(&self, queries: &[f32], dim: usize) -> Vec<f32> {
        let mut best = vec![f32::INFINITY; queries.len() / dim.max(1)];
        match &self.single {
            Some(index) => index.lower_all(queries, &mut best),
            None => {
                for band in &self.bands {
                    (self.make)(band.clone()).lower_all(queries, &mut best);
                }
            }
        }
        best
    }
}

impl WindowIndex {
    /// The `n`×`n` windows of `exemplar`, addressed toroidally, whose
    /// top-left corner is in the pixel rows `rows` (one window per pixel).
    ///
    /// Preconditions: `n >= 1`; the exemplar has pixels; `rows` within its
    /// height.
    pub fn toroidal(exemplar: &Image, n: u32, rows: Range<usize>) -> Self {
        let (n, (w, h, ch)) = (n.max(1) as usize, sizes(exemplar));
        let pw = w + n - 1;
        let band = rows.len();
        let mut values = Vec::with_capacity(pw * (band + n - 1) * ch);
        for y in rows.start..rows.end + n - 1 {
            for x in 0..pw {
                values.extend_from_slice(exemplar.pixel((x % w) as u32, (y % h) as u32));
            }
        }
        let origins = (0..band).flat_map(|y| (0..w).map(move |x| (y * pw + x) * ch));
        Self::build(values, pw * ch, n, ch, origins.collect())
    }

    /// The `n`×`n` windows wholly inside `image` (no wrap-around) whose
    /// top-left corner is in the rows `rows` (of `0..=h − n`).
    ///
    /// Preconditions: `1 <= n <= min(width, height)`; `rows.end <= h − n + 1`.
    pub fn interior(image: &Image, n: u32, rows: Range<usize>) -> Self {
        let (n, (w, h, ch)) = (n.max(1) as usize, sizes(image));
        assert!(n <= w && n <= h, "window larger than the image");
        assert!(rows.end <= h - n + 1, "window rows beyond the image");
        let values = image.data[rows.start * w * ch..(rows.end + n - 1) * w * ch].to_vec();
        let origins = (0..rows.len()).flat_map(|y| (0..=w - n).map(move |x| (y * w + x) * ch));
        Self::build(values, w * ch, n, ch, origins.collect())
    }

    /// Windows given as vectors, `n·n·channels` values each in the query
    /// layout (rows of `n · channels` values).
    ///
    /// Preconditions: `vectors.len()` is a multiple of `n·n·channels > 0`.
    pub fn vectors(vectors: Vec<f32>, n: u32, channels: u32) -> Self {
        let (n, ch) = (n.max(1) as usize, channels.max(1) as usize);
        let dim = n * n * ch;
        let origins = (0..vectors.len() / dim).map(|i| i * dim).collect();
        Self::build(vectors, n * ch, n, ch, origins)
    }

    fn build(
        values: Vec<f32>,
        row_stride: usize,
        n: usize,
        channels: usize,
        origins: Vec<usize>,
    ) -> Self {
        let row_len = n * channels;
        let dim = n * row_len;
        let axes = AXES.min(dim);
        let window = |o: usize, out: &mut Vec<f32>| {
            out.clear();
            for r in 0..n {
                out.extend_from_slice(&values[o + r * row_stride..][..row_len]);
            }
        };
        let span = tracing::debug_span!("window_axes").entered();
        let basis = principal_axes(&origins, dim, axes, &window);
        drop(span);
        let _span = tracing::debug_span!("window_tree").entered();
        let points = project_all(&origins, dim, &basis, &window);
        let mut order: Vec<u32> = (0..origins.len() as u32).collect();
        let mut leaves = Vec::new();
        split(&points, &mut order, &mut leaves);
        let mut blocks = Vec::new();
        let mut block_origins = Vec::new();
        let (leaves, leaf_bounds): (Vec<Leaf>, Vec<Bounds>) = leaves
            .into_iter()
            .map(|(start, end)| {
                let members = &order[start..end];
                let first_block = blocks.len() as u32;
                for chunk in members.chunks(8) {
                    let mut lane_origins = [usize::MAX; 8];
                    for (o, &i) in lane_origins.iter_mut().zip(chunk) {
                        *o = origins[i as usize];
                    }
                    blocks.push(lanes(&points, chunk, FAR).map(f32x8::new));
                    block_origins.push(lane_origins);
                }
                let (lo, hi) = bounding_box(&points, members);
                let leaf = Leaf {
                    first_block,
                    blocks: blocks.len() as u32 - first_block,
                };
                (leaf, Bounds { lo, hi })
            })
            .unzip();
        let mut levels = vec![leaf_bounds];
        while levels.last().is_some_and(|l| l.len() > 1) {
            let below = levels.last().expect("a level");
            let up = below
                .chunks(2)
                .map(|pair| pair.iter().skip(1).fold(pair[0], |b, o| b.union(o)))
                .collect();
            levels.push(up);
        }
        Self {
            values,
            row_stride,
            n,
            row_len,
            basis,
            leaves,
            levels,
            blocks,
            origins: block_origins,
        }
    }

    /// Number of windows indexed.
    pub fn len(&self) -> usize {
        self.origins
            .iter()
            .map(|o| o.iter().filter(|&&x| x != usize::MAX).count())
            .sum()
    }

    /// Whether no window is indexed.
    pub fn is_empty(&self) -> bool {
        self.leaves.is_empty()
    }

    /// Smallest sum of squared differences between `query` (`n·n·channels`
    /// values, rows of `n · channels`) and any indexed window; infinity when
    /// there is none. The same value as the exhaustive search
    /// ([`super::ExemplarNeighbourhoods::nearest_sq_distance`]), up to the
    /// rounding of the sums (which run in another order).
    pub fn nearest_sq_distance(&self, query: &[f32], scratch: &mut IndexScratch) -> f32 {
        self.nearest_below(query, f32::INFINITY, scratch)
    }

    /// Lowers each query's `best` (one per query, `queries` one after
    /// another) to its distance to the nearest indexed window
    /// ([`Self::nearest_below`]), in parallel over queries.
    pub fn lower_all(&self, queries: &[f32], best: &mut [f32]) {
        let dim = (self.n * self.row_len).max(1);
        best.par_iter_mut()
            .zip(queries.par_chunks_exact(dim))
            .for_each_init(IndexScratch::default, |scratch, (b, q)| {
                *b = self.nearest_below(q, *b, scratch);
            });
    }

    /// The smaller of `best` and the smallest squared distance from `query`
    /// to an indexed window (as [`Self::nearest_sq_distance`]).
    pub fn nearest_below(&self, query: &[f32], best: f32, scratch: &mut IndexScratch) -> f32 {
        assert_eq!(query.len(), self.n * self.row_len, "query size");
        let q = project(query, &self.basis);
        let mut best = best;
        let stack = &mut scratch.stack;
        stack.clear();
        if let Some(root) = self.levels.last().and_then(|l| l.first()) {
            stack.push((root.distance(&q), self.levels.len() as u32 - 1, 0));
        }
        // Depth first, the nearer box of each pair first.
        while let Some((bound, level, i)) = stack.pop() {
            if prunes(bound, best) {
                continue;
            }
            if level == 0 {
                best = self.scan_leaf(i as usize, query, &q, best);
                continue;
            }
            let below = &self.levels[level as usize - 1];
            let (a, b) = (2 * i as usize, 2 * i as usize + 1);
            let da = below[a].distance(&q);
            match below.get(b).map(|bb| bb.distance(&q)) {
                Some(db) if db < da => {
                    stack.push((da, level - 1, a as u32));
                    stack.push((db, level - 1, b as u32));
                }
                Some(db) => {
                    stack.push((db, level - 1, b as u32));
                    stack.push((da, level - 1, a as u32));
                }
                None => stack.push((da, level - 1, a as u32)),
            }
        }
        best
    }

    /// `best` lowered by the windows of `leaf` nearer to `query`.
    fn scan_leaf(&self, leaf: usize, query: &[f32], q: &[f32; AXES], mut best: f32) -> f32 {
        let leaf = &self.leaves[leaf];
        let qv: [f32x8; AXES] = q.map(f32x8::splat);
        let range = leaf.first_block as usize..(leaf.first_block + leaf.blocks) as usize;
        for (block, origins) in self.blocks[range.clone()].iter().zip(&self.origins[range]) {
            let mut acc = f32x8::ZERO;
            for a in 0..BOX_AXES {
                let d = block[a] - qv[a];
                acc += d * d;
            }
            if acc.simd_ge(f32x8::splat(threshold(best))).all() {
                continue;
            }
            for a in BOX_AXES..AXES {
                let d = block[a] - qv[a];
                acc += d * d;
            }
            for (&bound, &o) in acc.to_array().iter().zip(origins) {
                if o == usize::MAX || prunes(bound, best) {
                    continue;
                }
                best = best.min(self.distance(o, query, best));
            }
        }
        best
    }

    /// Squared distance from `query` to the window at `origin`, summed row
    /// by row; stops (returning at least `best`) once a row's partial sum
    /// reaches `best`.
    fn distance(&self, origin: usize, query: &[f32], best: f32) -> f32 {
        let mut d = 0.0f32;
        for r in 0..self.n {
            let w = &self.values[origin + r * self.row_stride..][..self.row_len];
            let q = &query[r * self.row_len..][..self.row_len];
            d += row_distance(w, q);
            if d >= best {
                return d;
            }
        }
        d
    }
}

/// Squared distance of two rows of equal length: eight values at a time,
/// the rest one by one.
#[inline]
fn row_distance(a: &[f32], b: &[f32]) -> f32 {
    let mut acc = f32x8::ZERO;
    let (ca, cb) = (a.chunks_exact(8), b.chunks_exact(8));
    let tail: f32 = (ca.remainder().iter().zip(cb.remainder()))
        .map(|(x, y)| (x - y) * (x - y))
        .sum();
    for (x, y) in ca.zip(cb) {
        let d = f32x8::new(x.try_into().expect("8 values"))
            - f32x8::new(y.try_into().expect("8 values"));
        acc = d.mul_add(d, acc);
    }
    acc.reduce_add() + tail
}

/// Width, height and channels of `image`.
fn sizes(image: &Image) -> (usize, usize, usize) {
    (
        image.width as usize,
        image.height as usize,
        image.channels as usize,
    )
}

/// Whether a projected (lower-bound) squared distance `bound` proves a
/// window no nearer than `best`.
#[inline]
fn prunes(bound: f32, best: f32) -> bool {
    bound >= threshold(best)
}

/// The smallest projected squared distance that proves a window no nearer
/// than `best`: `best` plus a margin for the rounding of the projections
/// (relative 2·10⁻⁴ and absolute 10⁻⁴ for values in `[0, 1]`, where the
/// rounding is about 10⁻⁶), so no window is skipped for it.
#[inline]
fn threshold(best: f32) -> f32 {
    best * (1.0 + 2.0e-4) + 1.0e-4
}

/// The leading `axes` principal axes (orthonormal) of an evenly spaced
/// sample of at most [`SAMPLE`] of the windows at `origins`, read by
/// `window`, by window value: entry `j` holds value `j`'s weight on each
/// axis (zero beyond `axes`). Found in `f64` by a randomised range finder
/// ([`leading_axes_randomised`]), or for a small sample by the covariance's
/// eigenvectors; without convergence the axes are the first coordinates
/// (still orthonormal, so the bounds stay exact; only slower).
fn principal_axes(
    origins: &[usize],
    dim: usize,
    axes: usize,
    window: &(dyn Fn(usize, &mut Vec<f32>) + Sync),
) -> Vec<[f32x8; 2]> {
    let mut basis = vec![[0.0f32; AXES]; dim];
    let fallback = |basis: &mut Vec<[f32; AXES]>| {
        for (a, b) in basis.iter_mut().enumerate().take(axes) {
            b[a] = 1.0;
        }
    };
    let step = origins.len().div_ceil(SAMPLE).max(1);
    let sample: Vec<usize> = origins.iter().step_by(step).copied().collect();
    // One column per sampled window (column-major: each written
    // contiguously), centred; the sample is its transpose.
    let mut buf = Vec::with_capacity(dim);
    let mut cols = faer::Mat::<f64>::zeros(dim, sample.len());
    let mut mean = vec![0.0f64; dim];
    for (i, &o) in sample.iter().enumerate() {
        window(o, &mut buf);
        for (j, (&v, m)) in buf.iter().zip(&mut mean).enumerate() {
            cols[(j, i)] = f64::from(v);
            *m += f64::from(v);
        }
    }
    let m = sample.len().max(1) as f64;
    for i in 0..sample.len() {
        for (j, &mu) in mean.iter().enumerate() {
            cols[(j, i)] -= mu / m;
        }
    }
    let rows = cols.transpose();
    let leading = if sample.len() >= 4 * (axes + OVERSAMPLING) {
        leading_axes_randomised(rows, axes)
    } else {
        leading_axes_eigen(rows, axes)
    };
    crate::kernels::simd_state::after_faer();
    match leading {
        Some(v) => {
            for (j, b) in basis.iter_mut().enumerate() {
                for (a, w) in b.iter_mut().enumerate().take(axes) {
                    *w = v[(j, a)] as f32;
                }
            }
        }
        None => fallback(&mut basis),
    }
    basis
        .into_iter()
        .map(|b| {
            let (lo, hi) = b.split_at(8);
            [
                f32x8::new(lo.try_into().expect("8 axes")),
                f32x8::new(hi.try_into().expect("8 axes")),
            ]
        })
        .collect()
}

/// Extra directions the randomised range finder carries beyond the axes.
const OVERSAMPLING: usize = 8;

/// The leading `axes` right singular vectors of the centred sample `rows`
/// (`dim × axes`, orthonormal columns), by a randomised range finder with
/// one power iteration (Halko, Martinsson & Tropp 2011, algorithms 4.4 and
/// 5.1): five products of the sample with `axes + 8` columns instead of
/// its `dim × dim` covariance and that matrix's eigen-decomposition (at
/// 15 × 15 × 3 values, a fifth of the measures' time). The axes only
/// decide what the exact search may skip, so an approximation of the
/// principal ones changes no result, only how much is skipped. `None`
/// when the decomposition fails.
fn leading_axes_randomised(rows: faer::MatRef<f64>, axes: usize) -> Option<faer::Mat<f64>> {
    use faer::Mat;
    let (m, dim) = (rows.nrows(), rows.ncols());
    let l = (axes + OVERSAMPLING).min(dim).min(m);
    // A fixed pseudo-random test matrix: the axes do not depend on a seed.
    let mut state = 0x9E37_79B9_7F4A_7C15u64;
    let omega = Mat::<f64>::from_fn(dim, l, |_, _| {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    });
    let q = product(rows, omega.as_ref(), 1.0).qr().compute_thin_Q();
    let z = product(rows.transpose(), q.as_ref(), 1.0)
        .qr()
        .compute_thin_Q();
    let q = product(rows, z.as_ref(), 1.0).qr().compute_thin_Q();
    let b = product(q.transpose(), rows, 1.0);
    let svd = b.thin_svd().ok()?;
    let v = svd.V();
    let ok = v.ncols() >= axes && (0..axes).all(|a| (0..dim).all(|j| v[(j, a)].is_finite()));
    ok.then(|| Mat::<f64>::from_fn(dim, axes, |j, a| v[(j, a)]))
}

/// `alpha · a · b`, one faer product on this thread.
fn product(a: faer::MatRef<f64>, b: faer::MatRef<f64>, alpha: f64) -> faer::Mat<f64> {
    let mut c = faer::Mat::<f64>::zeros(a.nrows(), b.ncols());
    faer::linalg::matmul::matmul(
        c.as_mut(),
        faer::Accum::Replace,
        a,
        b,
        alpha,
        faer::Par::Seq,
    );
    c
}

/// [`leading_axes_randomised`] for a small sample: the eigenvectors of the
/// `dim × dim` covariance, largest first.
fn leading_axes_eigen(rows: faer::MatRef<f64>, axes: usize) -> Option<faer::Mat<f64>> {
    let (m, dim) = (rows.nrows(), rows.ncols());
    if m == 0 {
        return None;
    }
    let cov = product(rows.transpose(), rows, 1.0 / m as f64);
    let e = cov.self_adjoint_eigen(faer::Side::Lower).ok()?;
    // Eigenvalues ascend: the leading axes are the last columns.
    let u = e.U();
    Some(faer::Mat::<f64>::from_fn(dim, axes, |j, a| {
        u[(j, dim - 1 - a)]
    }))
}

/// Windows projected per parallel task of [`project_all`].
const PROJECT_BLOCK: usize = 256;

/// The coordinates on `basis` of the windows at `origins` (read by
/// `window`), a block of [`PROJECT_BLOCK`] windows at a time as one faer
/// product (`windows × dim · dim × AXES`) instead of one window at a time
/// ([`project`], which the queries use). The two round differently, by
/// about 10⁻⁶ of a coordinate: the bounds' margin ([`threshold`]) is two
/// hundred times that, so no window that could be nearest is skipped.
fn project_all(
    origins: &[usize],
    dim: usize,
    basis: &[[f32x8; 2]],
    window: &(dyn Fn(usize, &mut Vec<f32>) + Sync),
) -> Vec<[f32; AXES]> {
    use faer::{Accum, Mat, MatMut, MatRef, Par, linalg::matmul::matmul};
    let b = Mat::<f32>::from_fn(dim, AXES, |j, a| basis[j][a / 8].to_array()[a % 8]);
    let mut points = vec![[0.0f32; AXES]; origins.len()];
    points
        .par_chunks_mut(PROJECT_BLOCK)
        .zip(origins.par_chunks(PROJECT_BLOCK))
        .for_each_init(
            || (Vec::new(), Vec::new()),
            |(buf, rows): &mut (Vec<f32>, Vec<f32>), (out, block)| {
                rows.clear();
                for &o in block {
                    window(o, buf);
                    rows.extend_from_slice(buf);
                }
                let w = MatRef::from_row_major_slice(rows, block.len(), dim);
                let p = MatMut::from_row_major_slice_mut(out.as_flattened_mut(), block.len(), AXES);
                matmul(p, Accum::Replace, w, b.as_ref(), 1.0f32, Par::Seq);
                crate::kernels::simd_state::after_faer();
            },
        );
    points
}

/// Coordinates of `v` on the axes of `basis` ([`principal_axes`]).
#[inline]
fn project(v: &[f32], basis: &[[f32x8; 2]]) -> [f32; AXES] {
    let (mut lo, mut hi) = (f32x8::ZERO, f32x8::ZERO);
    for (&x, b) in v.iter().zip(basis) {
        let x = f32x8::splat(x);
        lo = x.mul_add(b[0], lo);
        hi = x.mul_add(b[1], hi);
    }
    let mut out = [0.0f32; AXES];
    out[..8].copy_from_slice(&lo.to_array());
    out[8..].copy_from_slice(&hi.to_array());
    out
}

/// Splits `order[..]` into leaves of at most [`LEAF`] points by medians
/// along the box axis of largest spread; pushes each leaf's range.
fn split(points: &[[f32; AXES]], order: &mut [u32], leaves: &mut Vec<(usize, usize)>) {
    // Explicit stack of (start, end), so depth is no concern.
    let mut stack = vec![(0usize, order.len())];
    let mut out = Vec::new();
    while let Some((start, end)) = stack.pop() {
        if end - start <= LEAF {
            if end > start {
                out.push((start, end));
            }
            continue;
        }
        let members = &mut order[start..end];
        let (lo, hi) = bounding_box::<AXES, BOX_AXES>(points, members);
        let mid = split_widest(points, members, &lo, &hi);
        // Right half pushed first so leaves come out left to right.
        stack.push((start + mid, end));
        stack.push((start, start + mid));
    }
    leaves.extend(out);
}

#[cfg(test)]
mod tests {
    use super::super::nearest::tests::pseudo_random;
    use super::super::nearest::{ExemplarNeighbourhoods, QueryScratch};
    use super::*;

    /// A smooth image with structure (so the principal axes matter).
    fn waves(w: u32, h: u32, ch: u32, seed: u32) -> Image {
        let noise = pseudo_random((w * h * ch) as usize, seed);
        let mut img = Image::new(w, h, ch);
        for y in 0..h {
            for x in 0..w {
                for c in 0..ch {
                    let i = ((y * w + x) * ch + c) as usize;
                    let v = 0.5
                        + 0.3 * ((x as f32 * 0.7 + c as f32).sin() * (y as f32 * 0.4).cos())
                        + 0.2 * (noise[i] - 0.5);
                    img.pixel_mut(x, y)[c as usize] = v;
                }
            }
        }
        img
    }

    fn query_at(img: &Image, x: i64, y: i64, n: usize) -> Vec<f32> {
        let ch = img.channels as usize;
        let mut q = vec![0.0; n * n * ch];
        for dy in 0..n {
            for dx in 0..n {
                let p = img.texel(
                    x + dx as i64,
                    y + dy as i64,
                    crate::image::sample::Wrap::Repeat,
                );
                q[(dy * n + dx) * ch..][..ch].copy_from_slice(p);
            }
        }
        q
    }

    #[test]
    fn toroidal_and_interior_equal_the_exhaustive_search() {
        for (w, h, ch, n) in [
            (37u32, 29u32, 3u32, 5u32),
            (64, 64, 3, 7),
            (20, 31, 1, 3),
            (9, 9, 4, 9),
        ] {
            let ex = waves(w, h, ch, w + n);
            let other = waves(w + 5, h + 3, ch, 7 * w);
            let fast = WindowIndex::toroidal(&ex, n, 0..h as usize);
            let slow = ExemplarNeighbourhoods::new(&ex, n);
            let fast_in = WindowIndex::interior(&other, n, 0..(h + 3 - n + 1) as usize);
            let slow_in = ExemplarNeighbourhoods::interior(&other, n);
            assert_eq!(fast.len(), (w * h) as usize);
            let (mut s1, mut s2) = (IndexScratch::default(), QueryScratch::default());
            for k in 0..40u32 {
                // Windows of another image, random vectors and exact copies.
                let q = match k % 3 {
                    0 => query_at(&other, k as i64 * 3, k as i64 * 5, n as usize),
                    1 => pseudo_random((n * n * ch) as usize, 300 + k),
                    _ => query_at(&ex, k as i64 * 7 - 4, k as i64, n as usize),
                };
                for (a, b) in [
                    (
                        fast.nearest_sq_distance(&q, &mut s1),
                        slow.nearest_sq_distance(&q, None, &mut s2),
                    ),
                    (
                        fast_in.nearest_sq_distance(&q, &mut s1),
                        slow_in.nearest_sq_distance(&q, None, &mut s2),
                    ),
                ] {
                    assert!(
                        (a - b).abs() <= 1e-5 * b.max(1.0),
                        "{w}x{h}x{ch} n{n} query {k}: {a} vs {b}"
                    );
                }
                if k % 3 == 2 {
                    assert_eq!(fast.nearest_sq_distance(&q, &mut s1), 0.0);
                }
            }
        }
    }

    #[test]
    fn vectors_equal_a_scan_of_them() {
        let (n, ch) = (3usize, 3usize);
        let dim = n * n * ch;
        let data = pseudo_random(dim * 500, 9);
        let index = WindowIndex::vectors(data.clone(), n as u32, ch as u32);
        let mut s = IndexScratch::default();
        for k in 0..30 {
            let q = pseudo_random(dim, 1000 + k);
            let brute = data
                .chunks_exact(dim)
                .map(|v| {
                    v.iter()
                        .zip(&q)
                        .map(|(a, b)| (a - b) * (a - b))
                        .sum::<f32>()
                })
                .fold(f32::INFINITY, f32::min);
            let fast = index.nearest_sq_distance(&q, &mut s);
            assert!(
                (fast - brute).abs() <= 1e-5 * brute.max(1.0),
                "{fast} vs {brute}"
            );
        }
        let empty = WindowIndex::vectors(Vec::new(), n as u32, ch as u32);
        assert!(empty.is_empty());
        assert_eq!(
            empty.nearest_sq_distance(&vec![0.5; dim], &mut s),
            f32::INFINITY
        );
    }
}

#[cfg(test)]
mod band_tests {
    use super::*;

    #[test]
    fn bands_cover_the_rows_once_and_give_the_single_index_minimum() {
        assert_eq!(
            bands(10, BAND_WINDOWS, BAND_WINDOWS),
            (0..10).map(|y| y..y + 1).collect::<Vec<_>>()
        );
        assert_eq!(bands(3, 7, BAND_WINDOWS), vec![0..3]);
        let per = BAND_WINDOWS / 1000;
        let b = bands(2500, 1000, BAND_WINDOWS);
        assert_eq!(b.first(), Some(&(0..per)));
        assert_eq!(b.last().map(|r| r.end), Some(2500));
        assert!(b.windows(2).all(|p| p[0].end == p[1].start));

        // Windows of a 40 x 30 image searched whole and in bands of 4 rows.
        let (w, h, n, ch) = (40usize, 30usize, 5usize, 3usize);
        let data: Vec<f32> = (0..w * h * ch)
            .map(|i| ((i * 7919) % 1000) as f32 / 1000.0)
            .collect();
        let img = Image::from_data(w as u32, h as u32, ch as u32, data).unwrap();
        let dim = n * n * ch;
        let queries: Vec<f32> = (0..20 * dim)
            .map(|i| ((i * 104_729) % 997) as f32 / 997.0)
            .collect();
        let rows = h - n + 1;
        let search = |bands: &[Range<usize>], torus: bool| {
            let mut best = vec![f32::INFINITY; 20];
            let mut scratch = IndexScratch::default();
            for band in bands {
                let index = if torus {
                    WindowIndex::toroidal(&img, n as u32, band.clone())
                } else {
                    WindowIndex::interior(&img, n as u32, band.clone())
                };
                for (b, q) in best.iter_mut().zip(queries.chunks_exact(dim)) {
                    *b = index.nearest_below(q, *b, &mut scratch);
                }
            }
            best
        };
        let banded: Vec<Range<usize>> =
            (0..rows).step_by(4).map(|y| y..(y + 4).min(rows)).collect();
        let whole = search(std::slice::from_ref(&(0..rows)), false);
        assert_eq!(whole, search(&banded, false));
        let one = BandedIndex::new(rows, w - n + 1, |r| {
            WindowIndex::interior(&img, n as u32, r)
        });
        assert_eq!(whole, one.nearest(&queries, dim));
        let four = BandedIndex::with_band_windows(rows, w - n + 1, 4 * (w - n + 1), |r| {
            WindowIndex::interior(&img, n as u32, r)
        });
        assert_eq!(four.bands.len(), rows.div_ceil(4));
        assert_eq!(whole, four.nearest(&queries, dim));
        let torus = search(std::slice::from_ref(&(0..h)), true);
        assert_eq!(torus, search(&[0..7, 7..h], true));
        assert!(torus.iter().zip(&whole).all(|(t, i)| t <= i));
    }
}
