//! Jump weight normalisation (Zelinka & Garland 2004, §4.5).
//!
//! Global step: the sum `S_p` of the neighbourhood differences of pixel `p`'s
//! jumps is mapped linearly and inversely onto `[α, 1]`: the pixel with the
//! smallest sum (best jumps) gets total weight `W_p = 1`, the one with the
//! largest gets `α`. Local step: the jumps of `p` share `W_p` by linear
//! filtering of their differences relative to the sum,
//! `w_j = W_p · (S_p − D_j) / ((n − 1) · S_p)` for `n >= 2` jumps, so the best
//! jump weighs most and the weights sum to exactly `W_p`; a single jump gets
//! `W_p`; jumps with all-zero differences share `W_p` equally.
//!
//! Pixels with fewer than `k` jumps (Poisson filtering may leave fewer) enter
//! the global step with `k` times their mean difference, the sum their list
//! would have with `k` jumps of the same quality; with full lists this is
//! exactly the paper's sum.

/// Computes weights for every pixel.
///
/// `diffs` holds `k` slots per pixel, of which the first `counts[p]` are the
/// neighbourhood differences (L2 distances, ≥ 0) of pixel `p`'s jumps. Returns
/// weights in the same layout (unused slots 0). Preconditions: `alpha` in
/// `[0, 1]`, differences finite and non-negative.
pub fn normalise_weights(diffs: &[f32], counts: &[u8], k: usize, alpha: f32) -> Vec<f32> {
    let sums: Vec<Option<f64>> = counts
        .iter()
        .enumerate()
        .map(|(p, &n)| {
            let n = n as usize;
            (n > 0).then(|| {
                let s: f64 = diffs[p * k..][..n].iter().map(|&d| d as f64).sum();
                s * k as f64 / n as f64
            })
        })
        .collect();
    let lo = sums.iter().flatten().copied().fold(f64::INFINITY, f64::min);
    let hi = sums
        .iter()
        .flatten()
        .copied()
        .fold(f64::NEG_INFINITY, f64::max);
    let mut out = vec![0.0f32; diffs.len()];
    for (p, s) in sums.iter().enumerate() {
        let Some(s) = *s else { continue };
        let total = if hi > lo {
            1.0 - (1.0 - alpha as f64) * (s - lo) / (hi - lo)
        } else {
            1.0
        };
        let n = counts[p] as usize;
        let d = &diffs[p * k..][..n];
        let w = &mut out[p * k..][..n];
        let local: f64 = d.iter().map(|&x| x as f64).sum();
        if n == 1 {
            w[0] = total as f32;
        } else if local <= 0.0 {
            w.fill((total / n as f64) as f32);
        } else {
            for (wj, &dj) in w.iter_mut().zip(d) {
                *wj = (total * (local - dj as f64) / ((n - 1) as f64 * local)) as f32;
            }
        }
        // Rounding to f32 must not push the sum past 1.
        let sum: f32 = w.iter().sum();
        if sum > 1.0 {
            for wj in w.iter_mut() {
                *wj /= sum * (1.0 + f32::EPSILON);
            }
        }
    }
    out
}
